//! Output: the header a stream gets, its metadata chunk, and writing the chunks — to any
//! `Write + Seek`, or to a path atomically (temporary name, sync, rename: the bake's
//! `write_atomic`), so that an interrupted or failed encode never leaves a partial file
//! under the final name.

use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use vbim_format::{ChunkKind, ColorEncoding, Header, Transfer, Writer};
use vbim_format::{ReadAhead, READ_AHEAD_POINTS};

use crate::{EncodeError, EncoderConfig, SourceInfo};

/// A chunk coded but not yet written.
pub(crate) struct PendingChunk {
    pub kind: ChunkKind,
    pub flags: u16,
    pub number: u32,
    pub frames: (u32, u32),
    pub bytes: Vec<u8>,
    /// `bytes` is a keyframe or coefficient payload as version 1 has it before zstd, to be
    /// coded for the file's version once every payload is known (`payloads::code`).
    pub raw: bool,
}

/// The metadata chunk's payload: the JSON made compact (when it parses) and zstd'd. A
/// bake manifest is ~160 kB as written and ~20 kB packed — bytes that count against the
/// file's rate like any other.
pub(crate) fn pack_metadata(text: &str, level: i32) -> Result<Vec<u8>, EncodeError> {
    let compact = serde_json::from_str::<serde_json::Value>(text)
        .map(|v| v.to_string())
        .unwrap_or_else(|_| text.to_string());
    if compact.len() as u64 > vbim_format::limits::MAX_METADATA {
        return Err(EncodeError::Input(format!(
            "metadata of {} bytes (at most {})",
            compact.len(),
            vbim_format::limits::MAX_METADATA
        )));
    }
    Ok(zstd::bulk::compress(compact.as_bytes(), level.max(19)).expect("zstd"))
}

/// The header of a stream of `info`'s frames coded with `cfg`; the writer fills in the
/// index offset, file size, buffer model and checksums.
pub(crate) fn header_for(
    info: &SourceInfo,
    cfg: &EncoderConfig,
    (color, transfer): (ColorEncoding, Transfer),
    segments: u32,
    keyframes: u32,
    chunks: u32,
) -> Header {
    Header {
        version_minor: vbim_format::VERSION_MINOR,
        // Set with the payloads' coding (`payloads::code`).
        coding: vbim_format::Coding::Pairs,
        width: info.width as u32,
        height: info.height as u32,
        channels: info.channels as u8,
        color,
        looping: cfg.looping,
        frame_count: info.frames as u32,
        rate_num: cfg.rate.0,
        rate_den: cfg.rate.1,
        tile_size: cfg.tile_size as u16,
        max_degree: cfg.max_degree as u8,
        transfer,
        segment_count: segments,
        keyframe_count: keyframes,
        intra_interval: cfg.intra_interval_frames(),
        chunk_count: chunks,
        index_offset: 0,
        file_size: 0,
        read_ahead: [ReadAhead::default(); READ_AHEAD_POINTS],
        index_checksum: 0,
        largest_payload: None,
    }
}

/// Writes `chunks` after `header` into `out`; returns the header as written.
pub(crate) fn write_chunks<W: Write + Seek>(
    out: W,
    header: Header,
    chunks: &[PendingChunk],
) -> Result<Header, EncodeError> {
    let mut w = Writer::new(out, header)?;
    for c in chunks {
        w.write_chunk(c.kind, c.flags, c.number, c.frames, &c.bytes)?;
    }
    let (h, mut out) = w.finish()?;
    out.flush().map_err(vbim_format::FormatError::Io)?;
    Ok(h)
}

/// Runs `write` on a new file that replaces `out` atomically when `write` succeeds
/// (`vbim_files::write_atomic`); on failure `out` is untouched.
pub(crate) fn write_atomic<T>(
    out: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<T, EncodeError>,
) -> Result<T, EncodeError> {
    let oerr = |source: std::io::Error| EncodeError::Output {
        path: out.to_path_buf(),
        source,
    };
    vbim_files::write_atomic(
        out,
        |tmp| {
            let mut buf = BufWriter::new(File::create(tmp).map_err(oerr)?);
            let value = write(&mut buf)?;
            buf.flush().map_err(oerr)?;
            Ok(value)
        },
        oerr,
    )
}
