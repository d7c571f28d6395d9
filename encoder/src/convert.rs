//! A stream rewritten in another format version without coding it again: every keyframe
//! and coefficient payload decoded to its blocks and coded for the new version; every other
//! chunk, the index's frames and flags, and what a decoder reconstructs stay as they were.

use std::io::{Read, Seek, Write};

use vbim_format::chunk::{self, Payload, TileMap};
use vbim_format::{ChunkKind, Header, Reader};

use crate::output::{write_chunks, PendingChunk};
use crate::{EncodeError, FormatVersion, Progress};

/// Reads the stream `src` (named `name` in errors) and writes it to `out` in `version`
/// (`zstd_level` for version 1's payloads, `lanes` for version 2's and 3's:
/// `EncoderConfig::lanes`). Returns the header written. The output decodes
/// to the same planes as the input, bit for bit.
pub fn convert<R: Read + Seek, W: Write + Seek>(
    name: &str,
    src: R,
    out: W,
    version: FormatVersion,
    (zstd_level, lanes): (i32, crate::Lanes),
    progress: Progress,
) -> Result<Header, EncodeError> {
    let verify = |source| EncodeError::Verify {
        stream: name.to_string(),
        source,
    };
    let mut r = Reader::open(src).map_err(verify)?;
    let mut header = r.header().clone();
    let entries = r.entries().to_vec();
    let limit = header
        .largest_payload
        .unwrap_or(vbim_format::limits::MAX_CHUNK_DECODED) as usize;
    let mut tiles: Vec<TileMap> = Vec::new();
    let mut chunks = Vec::with_capacity(entries.len());
    for (i, e) in entries.iter().enumerate() {
        progress("read", i as u64 + 1, entries.len() as u64);
        let bytes = r.read_chunk(i).map_err(verify)?;
        let chunk_error = |what: vbim_format::FormatError| {
            verify(vbim_format::FormatError::BadChunk {
                chunk: i,
                first: e.first_frame,
                last: e.last_frame,
                what: what.to_string(),
            })
        };
        let what = match e.kind {
            ChunkKind::Keyframe => Some(Payload::Keyframe),
            ChunkKind::Coefficients => {
                let t = tiles.get(e.number as usize).ok_or_else(|| {
                    chunk_error(vbim_format::FormatError::Invalid(
                        "coefficients before their tile map".into(),
                    ))
                })?;
                Some(Payload::Coefficients(t))
            }
            ChunkKind::TileMap => {
                let len = e.last_frame - e.first_frame;
                let t = chunk::read_tilemap(&header, &bytes, len).map_err(chunk_error)?;
                if e.number as usize != tiles.len() {
                    return Err(chunk_error(vbim_format::FormatError::Invalid(format!(
                        "tile map of segment {} after {} others",
                        e.number,
                        tiles.len()
                    ))));
                }
                tiles.push(t);
                None
            }
            _ => None,
        };
        let (bytes, raw) = match what {
            Some(what) => (
                chunk::payload(&header, what, &bytes, limit).map_err(chunk_error)?,
                true,
            ),
            None => (bytes, false),
        };
        chunks.push(PendingChunk {
            kind: e.kind,
            flags: e.flags,
            number: e.number,
            frames: (e.first_frame, e.last_frame),
            bytes,
            raw,
        });
    }
    crate::payloads::code(
        &mut header,
        &mut chunks,
        &tiles,
        version,
        (zstd_level, lanes),
        progress,
    )?;
    write_chunks(out, header, &chunks)
}
