use std::io;

/// Everything that can go wrong reading or writing a `.vbim` stream. Messages name the
/// chunk and frames involved, so that a damaged file is reported, never decoded into garbage.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("I/O error: {0}")]
    Io(#[from] io::Error),
    #[error("not a .vbim file (bad magic bytes)")]
    BadMagic,
    #[error("unsupported .vbim major version {found} (this reader knows version {known})")]
    UnsupportedVersion { found: u16, known: u16 },
    #[error("invalid header: {0}")]
    InvalidHeader(String),
    #[error("header checksum mismatch: the header is damaged")]
    HeaderChecksum,
    #[error("index checksum mismatch: the chunk index is damaged")]
    IndexChecksum,
    #[error("invalid index: {0}")]
    InvalidIndex(String),
    #[error("file truncated: {0}")]
    Truncated(String),
    #[error("chunk {chunk}, frames {first}–{last}: checksum mismatch")]
    ChunkChecksum { chunk: usize, first: u32, last: u32 },
    #[error("chunk {chunk}, frames {first}–{last}: {what}")]
    BadChunk {
        chunk: usize,
        first: u32,
        last: u32,
        what: String,
    },
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T> = std::result::Result<T, FormatError>;
