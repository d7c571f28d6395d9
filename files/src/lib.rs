//! vbim-files: what the offline tools (the baker, the encoder and the `vbim` command)
//! share, so that none of them depends on another for it.
//!
//! - [`write_atomic`]: every output file is written under a temporary name beside it and
//!   renamed, so an interrupted run never leaves a truncated file under a final name; the
//!   temporaries are registered ([`Temporary`]) so that an interrupt handler can remove
//!   them ([`remove_temporaries`]).
//! - [`Manifest`]: what a baked sequence of frames is (`manifest.json` beside the frames,
//!   and the metadata chunk of a `.vbim` encoded from them), with each frame's sun and sky
//!   ([`FrameInfo`]) and how the frames are stored ([`FrameFormat`]).
//! - [`Progress`]: how long work reports how far it is.
//!
//! The runtime (`vbim-format`, `vbim-player`) never depends on this crate.
#![deny(missing_docs)]

mod atomic;
mod manifest;

pub use atomic::{check_output, remove_temporaries, write_atomic, write_text, Temporary};
pub use manifest::{frame_name, FrameFormat, FrameInfo, Manifest};

/// Progress reports: a stage name, units done, units in all.
pub type Progress<'a> = &'a (dyn Fn(&str, u64, u64) + Sync);
