//! vbim-encoder: turns a sequence of lightmaps into a `.vbim` stream — compressed keyframes
//! plus a per-tile polynomial-in-time model using only as many terms as each part of the
//! scene needs under the user's error budget (`docs/MODEL.md`).
//!
//! The public API is data: an [`EncoderConfig`] (built from a [`Preset`] and adjusted knob
//! by knob), [`encode`] into any `Write + Seek` or [`encode_file`] to a path (atomically),
//! the [`EncodeReport`] they return, and [`EncodeReport::verify`] to measure the stream
//! against its input. [`encode_to_tolerance`] holds the tolerance by measuring.
//! [`convert`] rewrites a stream in another format version without coding it again.
//!
//! Inside, in the order a frame meets them: `input` (reading and validating frames),
//! `domain` (the coded domain), `encode` (the pass over the sequence), `segment` (segment
//! lengths), `keyframe` (keyframe coding), `model` (a segment's per-tile model),
//! `payloads` (every payload coded for the file's version once all are known: version 2's
//! context maps are learnt from all of them), `output` (the header and writing), `report`
//! (what an encode did), `aim` (the internal budget that delivers the tolerance, found on a
//! sample before coding), `calibrate` (`--exact`) and `secant` (the search both of those
//! share); `run` holds the entry points themselves (the worker pool, the aim, the coding
//! and the writing of one encode).

#![deny(missing_docs)]

mod aim;
mod calibrate;
mod config;
mod convert;
mod domain;
mod encode;
mod input;
mod keyframe;
mod model;
mod output;
mod payloads;
mod plan;
mod rdoq;
mod reach;
mod report;
mod run;
mod secant;
mod segment;
mod sparse;
#[cfg(feature = "bench")]
mod tap;

use std::path::PathBuf;

pub use aim::{Aim, SamplePass};
pub use calibrate::{encode_to_tolerance, BAND_DB};
pub use config::{
    ConfigError, EncoderConfig, FormatVersion, Preset, SegmentMode, DEFAULT_MEMORY_LIMIT,
};
pub use convert::convert;
pub use input::{Frame, FrameSet, FrameSource, InputKind, MemorySource, SourceInfo};
pub use payloads::{Lanes, LANE_BYTES, LANE_BYTES_3, SYMBOLS_PER_STATE};
pub use report::{lossless_baseline, EncodeReport, Measured};
pub use run::{encode, encode_file};
/// Progress callback: (stage, done, total) — the bake's, so one bar serves both.
pub use vbim_files::Progress;

/// What `vbim bench` measures of the encoder's internals (the `bench` feature).
#[cfg(feature = "bench")]
pub mod bench {
    pub use crate::model::PLANE_WEIGHT;
    pub use crate::payloads::{cluster, HISTOGRAMS};
    /// What the quantiser is handed, recorded for `vbim bench transforms` and `bench intra`.
    pub mod tap {
        pub use crate::tap::{start, take, PlaneKind, TappedPlane};
    }
}

/// Why an encode failed.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// A frame or the metadata cannot be used; the message names the file and texel.
    #[error("{0}")]
    Input(String),
    /// The sequence cannot be encoded within the memory limit, even a band of one tile
    /// row at a time: a caller may raise [`EncoderConfig::memory_limit`] to `need` and
    /// try again.
    #[error(
        "{sequence} needs about {} to encode in bands of one tile row, more than the memory \
         limit of {}; raise --memory-limit, or shorten --segment or --tile",
        vbim_format::limits::human_bytes(*need),
        vbim_format::limits::human_bytes(*limit)
    )]
    OverMemory {
        /// The sequence and what makes it large (size, channels, segment lengths).
        sequence: String,
        /// Bytes it needs, about.
        need: u64,
        /// The limit, bytes.
        limit: u64,
    },
    /// The output cannot be written.
    #[error("{}: {source}", path.display())]
    Output {
        /// The output's path.
        path: PathBuf,
        /// What went wrong.
        #[source]
        source: std::io::Error,
    },
    /// The stream just written could not be decoded again to measure it (a bug, or the
    /// file changed under the encoder).
    #[error("{stream}: {source}")]
    Verify {
        /// The stream's name (its path, or a pass's).
        stream: String,
        /// What the reader or the reference decoder said.
        #[source]
        source: vbim_format::FormatError,
    },
    /// A setting out of range.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Writing the container failed (I/O, or a bug that made an invalid stream).
    #[error("{0}")]
    Format(#[from] vbim_format::FormatError),
}
