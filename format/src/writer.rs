//! Writing a `.vbim` stream: header and index space are reserved up front, chunks are
//! appended in playback order, and `finish` fills in the index, the buffer model and the
//! header. Creating the file atomically (temporary name, rename) is the caller's job.

use std::io::{Seek, SeekFrom, Write};

use crate::checksum::xxh3;
use crate::chunk::{self, Payload, TileMap};
use crate::header::{Coding, Header, HEADER_SIZE_1_1, VERSION_MINOR};
use crate::index::{self, ChunkKind, IndexEntry, ENTRY_SIZE};
use crate::{buffer_model, FormatError, Result};

/// Writes a `.vbim` stream chunk by chunk (see the module documentation).
pub struct Writer<W> {
    out: W,
    header: Header,
    entries: Vec<IndexEntry>,
    pos: u64,
    /// The largest decompressed size of a keyframe or coefficient payload so far.
    largest_payload: u64,
    /// The last tile map written (a version 2 coefficient payload is measured with it).
    tiles: Option<TileMap>,
}

/// Bytes of the header a [`Writer`] stores: 1.1's for version 1, 2.0's with its maps.
fn written_size(h: &Header) -> usize {
    match h.coding {
        Coding::Pairs => HEADER_SIZE_1_1,
        Coding::Lanes(..) => h.header_size(),
    }
}

impl<W: Write + Seek> Writer<W> {
    /// Starts a file that will hold exactly `header.chunk_count` chunks.
    pub fn new(mut out: W, header: Header) -> Result<Self> {
        let n = header.chunk_count as usize;
        if n == 0 || n > crate::limits::MAX_CHUNKS as usize {
            return Err(FormatError::Invalid(format!("cannot write {n} chunks")));
        }
        // The header this crate writes states the largest payload (1.1 or 2.0).
        let reserved = written_size(&header) + n * ENTRY_SIZE;
        out.write_all(&vec![0u8; reserved])?;
        Ok(Writer {
            out,
            header,
            entries: Vec::with_capacity(n),
            pos: reserved as u64,
            largest_payload: 0,
            tiles: None,
        })
    }

    /// Appends one chunk. `first..=last` are the media frames it covers.
    pub fn write_chunk(
        &mut self,
        kind: ChunkKind,
        flags: u16,
        number: u32,
        frames: (u32, u32),
        bytes: &[u8],
    ) -> Result<()> {
        if self.entries.len() == self.header.chunk_count as usize {
            return Err(FormatError::Invalid(
                "more chunks than the header announced".into(),
            ));
        }
        let size = match (&self.header.coding, kind) {
            (Coding::Pairs, ChunkKind::Keyframe | ChunkKind::Coefficients) => {
                Some(decompressed_size(bytes)?)
            }
            (Coding::Lanes(..), ChunkKind::TileMap) => {
                let len = frames.1.saturating_sub(frames.0);
                self.tiles = Some(chunk::read_tilemap(&self.header, bytes, len)?);
                None
            }
            // Version 2's payloads are measured as a reader will decode them, which also
            // checks that they do.
            (Coding::Lanes(..), ChunkKind::Keyframe) => {
                Some(decoded_size(&self.header, Payload::Keyframe, bytes)?)
            }
            (Coding::Lanes(..), ChunkKind::Coefficients) => {
                let tiles = self.tiles.as_ref().ok_or_else(|| {
                    FormatError::Invalid("coefficients before their tile map".into())
                })?;
                Some(decoded_size(
                    &self.header,
                    Payload::Coefficients(tiles),
                    bytes,
                )?)
            }
            _ => None,
        };
        if let Some(n) = size {
            self.largest_payload = self.largest_payload.max(n);
        }
        self.out.write_all(bytes)?;
        self.entries.push(IndexEntry {
            kind,
            flags,
            number,
            first_frame: frames.0,
            last_frame: frames.1,
            offset: self.pos,
            length: bytes.len() as u64,
            checksum: xxh3(bytes),
        });
        self.pos += bytes.len() as u64;
        Ok(())
    }

    /// Writes the index and the header, validates the result as a reader would, and returns
    /// the final header and the underlying writer.
    pub fn finish(mut self) -> Result<(Header, W)> {
        if self.entries.len() != self.header.chunk_count as usize {
            return Err(FormatError::Invalid(format!(
                "{} chunks written, the header announced {}",
                self.entries.len(),
                self.header.chunk_count
            )));
        }
        let mut raw = Vec::with_capacity(self.entries.len() * ENTRY_SIZE);
        for e in &self.entries {
            e.write(&mut raw);
        }
        let h = &mut self.header;
        h.version_minor = match h.coding {
            Coding::Pairs => 1,
            Coding::Lanes(..) => VERSION_MINOR,
        };
        h.largest_payload = Some(self.largest_payload.max(1));
        let size = h.header_size() as u64;
        h.index_offset = size;
        h.file_size = self.pos;
        h.index_checksum = xxh3(&raw);
        h.read_ahead = buffer_model::table(h, &self.entries);
        h.validate(size)?;
        index::validate(h, &self.entries, size + raw.len() as u64)?;
        self.out.seek(SeekFrom::Start(0))?;
        self.out.write_all(&h.to_bytes())?;
        self.out.write_all(&raw)?;
        self.out.seek(SeekFrom::Start(self.pos))?;
        self.out.flush()?;
        Ok((self.header, self.out))
    }
}

/// Edits the header and index of a whole stream held in memory, then stores them back with
/// their checksums recomputed (the index keeps its length). For tools and tests that craft
/// streams — a repair, a fuzzing seed, a hostile file: after it, only the semantic checks
/// stand between the bytes and a decoder.
pub fn rewrite(
    bytes: &mut [u8],
    edit: impl FnOnce(&mut Header, &mut [IndexEntry]),
) -> Result<Header> {
    let r = crate::Reader::open(std::io::Cursor::new(&*bytes))?;
    let (mut h, mut entries) = (r.header().clone(), r.entries().to_vec());
    edit(&mut h, &mut entries);
    let mut index = Vec::with_capacity(entries.len() * ENTRY_SIZE);
    entries.iter().for_each(|e| e.write(&mut index));
    let at = h.index_offset as usize;
    let room = bytes
        .get_mut(at..at + index.len())
        .ok_or_else(|| FormatError::Invalid("the index no longer fits the stream".into()))?;
    room.copy_from_slice(&index);
    h.index_checksum = xxh3(&index);
    let head = h.to_bytes();
    let stored = u32::from_le_bytes(bytes[12..16].try_into().expect("4 bytes")) as usize;
    if head.len() != stored {
        return Err(FormatError::Invalid(format!(
            "a {}-byte header cannot replace a {stored}-byte one",
            head.len()
        )));
    }
    bytes[..head.len()].copy_from_slice(&head);
    Ok(h)
}

/// The size of a version 2 payload as version 1's before zstd (what a reader decodes it to).
fn decoded_size(h: &Header, what: Payload, bytes: &[u8]) -> Result<u64> {
    let limit = crate::limits::MAX_CHUNK_DECODED as usize;
    Ok(crate::payload2::to_pairs(h, what, bytes, limit)?.len() as u64)
}

/// The decompressed size of a zstd frame: what its header states (every frame this
/// crate's encoder writes states it), or else what it decompresses to.
fn decompressed_size(bytes: &[u8]) -> Result<u64> {
    match zstd::zstd_safe::get_frame_content_size(bytes) {
        Ok(Some(n)) => Ok(n),
        _ => Ok(
            crate::chunk::decompress(bytes, crate::limits::MAX_CHUNK_DECODED as usize)?.len()
                as u64,
        ),
    }
}
