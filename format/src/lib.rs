//! The `.vbim` container shared by the encoder and the player.
//!
//! A file is a fixed-size [`Header`], an index of chunks ([`IndexEntry`]) and the chunks
//! themselves, in playback order. `docs/FORMAT.md` specifies every byte; this crate is the
//! executable version of that document.
//!
//! - **Reading and writing a file**: [`Reader`] (header, index, checksummed chunks, with
//!   [`Limits`] counted before anything is allocated), [`Writer`], [`Header`] and its
//!   parts, [`ChunkKind`], [`FormatError`].
//! - **What both sides must agree on bit for bit**, one module each: the temporal basis
//!   ([`basis`]), the coding curves ([`curve`]), the colour transform ([`color`]), the 8×8
//!   transform ([`dct`]), plane coding ([`plane`]), chunk payloads ([`chunk`], with the
//!   entry points a parallel parser starts from), the index's flags ([`index`]), the
//!   buffer model ([`buffer_model`]), the format's bounds ([`limits`]), the error metrics
//!   ([`metrics`]), and the CPU reference decoder ([`decode`]) that the GPU reconstruction
//!   is tested against.
//! - **Packages** ([`package`]): several files on one timeline (weathers, each a lightmap
//!   and a sky track), tied by a small JSON file that this module parses and checks;
//!   [`irradiance`] defines what an irradiance track's frames mean (light for objects).
//! - **Format 2's coefficient coding**, not yet used by any chunk: [`ans`] (rANS with
//!   static 12-bit probabilities over 16-bit words, hybrid-uint tokens, histograms) and
//!   [`plane2`] (a chunk's planes in rANS lanes and four passes a GPU can run).
//! - **Hostile input**: with the `fuzz` feature, [`fuzz`](crate#features) holds the fuzz
//!   targets' bodies, which `cargo test` also replays on the saved corpus.
//!
//! No threads, no GPU and no I/O beyond `Read`/`Write`/`Seek`.
//!
//! # Features
//! - `fuzz`: the module `fuzz`, entry points for the fuzz targets (`fuzz/`) and the
//!   tests that replay their corpus.
#![deny(missing_docs)]

pub mod ans;
pub mod basis;
pub mod buffer_model;
mod checksum;
pub mod chunk;
pub mod color;
pub mod curve;
pub mod dct;
pub mod decode;
mod error;
#[cfg(feature = "fuzz")]
pub mod fuzz;
mod head;
mod header;
pub mod index;
pub mod irradiance;
pub mod limits;
mod memory;
pub mod metrics;
pub mod package;
pub mod payload2;
pub mod plane;
pub mod plane2;
mod reader;
mod scan;
mod varint;
mod writer;

pub use checksum::xxh3;
pub use error::{FormatError, Result};
pub use header::{
    Coding, ColorEncoding, Header, ReadAhead, Transfer, HEADER_SIZE, MAGIC, READ_AHEAD_POINTS,
    VERSION_MAJOR, VERSION_MINOR,
};
pub use index::{ChunkKind, IndexEntry};
pub use memory::{decoder_memory, largest_payload, section_memory, Limits};
pub use reader::{verify_chunk, Reader};
pub use writer::{rewrite, Writer};
