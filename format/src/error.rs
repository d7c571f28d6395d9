use std::io;

/// Everything that can go wrong reading or writing a `.vbim` stream. Messages name the
/// chunk and frames involved, so that a damaged file is reported, never decoded into garbage.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// Reading or writing the underlying stream failed.
    #[error("I/O error: {0}")]
    Io(#[from] io::Error),
    /// The first eight bytes are not `.vbim`'s magic.
    #[error("not a .vbim file (bad magic bytes)")]
    BadMagic,
    /// A major version this reader does not know.
    #[error("unsupported .vbim major version {found} (this reader knows version {known})")]
    UnsupportedVersion {
        /// The file's major version.
        found: u16,
        /// This reader's.
        known: u16,
    },
    /// A header field out of range or inconsistent with another.
    #[error("invalid header: {0}")]
    InvalidHeader(String),
    /// The header's bytes do not match its checksum.
    #[error("header checksum mismatch: the header is damaged")]
    HeaderChecksum,
    /// The index's bytes do not match the checksum in the header.
    #[error("index checksum mismatch: the chunk index is damaged")]
    IndexChecksum,
    /// The index does not describe a playable stream (order, ranges, counts).
    #[error("invalid index: {0}")]
    InvalidIndex(String),
    /// The file ends before a part it declares.
    #[error("file truncated: {0}")]
    Truncated(String),
    /// A chunk's bytes do not match its checksum.
    #[error("chunk {chunk}, frames {first}–{last}: checksum mismatch")]
    ChunkChecksum {
        /// The chunk's position in the index.
        chunk: usize,
        /// The first media frame it covers.
        first: u32,
        /// The last media frame it covers.
        last: u32,
    },
    /// A chunk whose checksum is right but whose payload cannot be decoded.
    #[error("chunk {chunk}, frames {first}–{last}: {what}")]
    BadChunk {
        /// The chunk's position in the index.
        chunk: usize,
        /// The first media frame it covers.
        first: u32,
        /// The last media frame it covers.
        last: u32,
        /// What is wrong with it.
        what: String,
    },
    /// A request or value that makes no sense (for example, writing an invalid header).
    #[error("{0}")]
    Invalid(String),
    /// The stream needs more memory than the reader's [`crate::Limits`] allow.
    #[error(
        "{what} needs up to {} of memory, more than the limit of {} (raise it: \
         --memory-limit on the command line, Limits::memory in the API)",
        crate::limits::human_bytes(*need),
        crate::limits::human_bytes(*limit)
    )]
    OverLimit {
        /// What needs it.
        what: String,
        /// Bytes needed, at most.
        need: u64,
        /// The limit, bytes.
        limit: u64,
    },
}

/// A result whose error is a [`FormatError`].
pub type Result<T> = std::result::Result<T, FormatError>;
