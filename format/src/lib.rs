//! The `.vbim` container shared by the encoder and the player.
//!
//! A file is a fixed-size [`Header`], an index of chunks ([`IndexEntry`]) and the chunks
//! themselves, in playback order. `docs/FORMAT.md` specifies every byte; this crate is the
//! executable version of that document. It also holds everything both sides must agree on
//! bit for bit: the temporal basis ([`basis`]), the coding curves ([`curve`]), the colour
//! transform ([`color`]), the spatial transform and plane coding ([`plane`]), and the CPU
//! reference decoder ([`decode`]) that the GPU reconstruction is tested against.
//!
//! No threads, no GPU and no I/O beyond `Read`/`Write`/`Seek`.
#![deny(missing_docs)]

pub mod basis;
pub mod buffer_model;
pub mod checksum;
pub mod chunk;
pub mod color;
pub mod curve;
pub mod dct;
pub mod decode;
mod error;
pub mod header;
pub mod index;
pub mod metrics;
pub mod plane;
pub mod reader;
pub mod varint;
pub mod writer;

pub use error::{FormatError, Result};
pub use header::{ColorEncoding, Header, ReadAhead, Transfer, MAGIC, VERSION_MAJOR, VERSION_MINOR};
pub use index::{ChunkKind, IndexEntry};
pub use reader::Reader;
pub use writer::Writer;

/// Hard limits checked before anything is allocated. They bound what a hostile or damaged
/// header can make a reader do; real files are far below them.
pub mod limits {
    /// Largest width or height (the largest 2D texture wgpu guarantees on desktop is 16384).
    pub const MAX_DIMENSION: u32 = 16_384;
    /// Largest number of frames in one sequence.
    pub const MAX_FRAMES: u32 = 10_000_000;
    /// Largest number of chunks (the index is read whole, 40 bytes an entry: 160 MB at most).
    pub const MAX_CHUNKS: u32 = 4_000_000;
    /// Largest decompressed payload of one chunk: four f32 planes of the largest texture.
    pub const MAX_CHUNK_DECODED: u64 = 4 * 4 * (MAX_DIMENSION as u64) * (MAX_DIMENSION as u64);
    /// Largest polynomial degree in time.
    pub const MAX_DEGREE: u8 = 8;
    /// Largest size of the metadata chunk.
    pub const MAX_METADATA: u64 = 64 << 20;
}
