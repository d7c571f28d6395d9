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
pub mod fuzz;
pub mod header;
pub mod index;
pub mod limits;
pub mod memory;
pub mod metrics;
pub mod plane;
pub mod reader;
pub mod scan;
pub mod varint;
pub mod writer;

pub use error::{FormatError, Result};
pub use header::{ColorEncoding, Header, ReadAhead, Transfer, MAGIC, VERSION_MAJOR, VERSION_MINOR};
pub use index::{ChunkKind, IndexEntry};
pub use memory::Limits;
pub use reader::Reader;
pub use writer::Writer;
