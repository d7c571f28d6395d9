//! Writing a `.vbim` stream: header and index space are reserved up front, chunks are
//! appended in playback order, and `finish` fills in the index, the buffer model and the
//! header. Creating the file atomically (temporary name, rename) is the caller's job.

use std::io::{Seek, SeekFrom, Write};

use crate::checksum::xxh3;
use crate::header::{Header, HEADER_SIZE};
use crate::index::{self, ChunkKind, IndexEntry, ENTRY_SIZE};
use crate::{buffer_model, FormatError, Result};

/// Writes a `.vbim` stream chunk by chunk (see the module documentation).
pub struct Writer<W> {
    out: W,
    header: Header,
    entries: Vec<IndexEntry>,
    pos: u64,
}

impl<W: Write + Seek> Writer<W> {
    /// Starts a file that will hold exactly `header.chunk_count` chunks.
    pub fn new(mut out: W, header: Header) -> Result<Self> {
        let n = header.chunk_count as usize;
        if n == 0 || n > crate::limits::MAX_CHUNKS as usize {
            return Err(FormatError::Invalid(format!("cannot write {n} chunks")));
        }
        let reserved = HEADER_SIZE + n * ENTRY_SIZE;
        out.write_all(&vec![0u8; reserved])?;
        Ok(Writer {
            out,
            header,
            entries: Vec::with_capacity(n),
            pos: reserved as u64,
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
        h.index_offset = HEADER_SIZE as u64;
        h.file_size = self.pos;
        h.index_checksum = xxh3(&raw);
        h.read_ahead = buffer_model::table(h, &self.entries);
        h.validate(HEADER_SIZE as u64)?;
        index::validate(h, &self.entries, HEADER_SIZE as u64 + raw.len() as u64)?;
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
    bytes[..HEADER_SIZE].copy_from_slice(&h.to_bytes());
    Ok(h)
}
