//! Reading a `.vbim` stream: the header and index up front, then any chunk on demand,
//! each verified against its checksum before anyone decodes it.

use std::io::{Read, Seek, SeekFrom};

use crate::checksum::xxh3;
use crate::header::{Header, HEADER_SIZE};
use crate::index::{self, IndexEntry, Layout, ENTRY_SIZE};
use crate::{FormatError, Result};

/// A `.vbim` stream open for reading: header and index validated, chunks read on demand and verified against their checksums.
pub struct Reader<R> {
    src: R,
    header: Header,
    entries: Vec<IndexEntry>,
    layout: Layout,
}

impl<R: Read + Seek> Reader<R> {
    /// Reads and validates the header and the index. Nothing is allocated before the sizes
    /// it depends on have been checked against the file's real length.
    pub fn open(mut src: R) -> Result<Self> {
        let len = src.seek(SeekFrom::End(0))?;
        src.seek(SeekFrom::Start(0))?;
        let mut head = vec![0u8; HEADER_SIZE.min(len as usize)];
        src.read_exact(&mut head)?;
        if head.len() >= 16 && head[..8] == crate::MAGIC {
            // A later minor version may have a longer header: read the rest before parsing.
            let size = u32::from_le_bytes(head[12..16].try_into().unwrap()) as u64;
            if size > HEADER_SIZE as u64 && size <= (1 << 16) && size <= len {
                head.resize(size as usize, 0);
                src.read_exact(&mut head[HEADER_SIZE..])?;
            }
        }
        let header = Header::from_bytes(&head)?;
        if len < header.file_size {
            return Err(FormatError::Truncated(format!(
                "{len} bytes, the header says {} bytes",
                header.file_size
            )));
        }
        let n = header.chunk_count as usize;
        let mut raw = vec![0u8; n * ENTRY_SIZE];
        src.seek(SeekFrom::Start(header.index_offset))?;
        src.read_exact(&mut raw)?;
        if xxh3(&raw) != header.index_checksum {
            return Err(FormatError::IndexChecksum);
        }
        let entries: Vec<IndexEntry> = raw.chunks_exact(ENTRY_SIZE).map(IndexEntry::read).collect();
        let layout = index::validate(&header, &entries, header.index_offset + raw.len() as u64)?;
        Ok(Reader {
            src,
            header,
            entries,
            layout,
        })
    }

    /// The stream's header.
    pub fn header(&self) -> &Header {
        &self.header
    }
    /// The index, in playback order.
    pub fn entries(&self) -> &[IndexEntry] {
        &self.entries
    }
    /// The index's meaning: segment boundaries, keyframes and each segment's chunks.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }
    /// The stream underneath.
    pub fn into_inner(self) -> R {
        self.src
    }

    /// Reads chunk `i`'s stored bytes and checks them against the index's checksum.
    pub fn read_chunk(&mut self, i: usize) -> Result<Vec<u8>> {
        let e = *self
            .entries
            .get(i)
            .ok_or_else(|| FormatError::Invalid(format!("no chunk {i}")))?;
        self.src.seek(SeekFrom::Start(e.offset))?;
        let mut buf = vec![0u8; e.length as usize];
        self.src
            .read_exact(&mut buf)
            .map_err(|err| match err.kind() {
                std::io::ErrorKind::UnexpectedEof => FormatError::Truncated(format!(
                    "chunk {i}, frames {}–{}: ends past the end of the file",
                    e.first_frame, e.last_frame
                )),
                _ => err.into(),
            })?;
        verify_chunk(i, &e, &buf)?;
        Ok(buf)
    }

    /// The metadata chunk's JSON text, if the file has one.
    pub fn metadata(&mut self) -> Result<Option<String>> {
        let Some(i) = self.layout.metadata else {
            return Ok(None);
        };
        let packed = self.read_chunk(i)?;
        let e = self.entries[i];
        let bad = |what: String| FormatError::BadChunk {
            chunk: i,
            first: e.first_frame,
            last: e.last_frame,
            what,
        };
        let bytes = crate::chunk::decompress(&packed, crate::limits::MAX_METADATA as usize)
            .map_err(|err| bad(format!("metadata: {err}")))?;
        String::from_utf8(bytes)
            .map(Some)
            .map_err(|_| FormatError::BadChunk {
                chunk: i,
                first: e.first_frame,
                last: e.last_frame,
                what: "metadata is not UTF-8".into(),
            })
    }
}

/// Checks a chunk's bytes against its index entry.
pub fn verify_chunk(i: usize, e: &IndexEntry, bytes: &[u8]) -> Result<()> {
    if bytes.len() as u64 != e.length || xxh3(bytes) != e.checksum {
        return Err(FormatError::ChunkChecksum {
            chunk: i,
            first: e.first_frame,
            last: e.last_frame,
        });
    }
    Ok(())
}

impl<R> std::fmt::Debug for Reader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Reader")
            .field("header", &self.header)
            .field("chunks", &self.entries.len())
            .finish()
    }
}
