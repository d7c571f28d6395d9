//! vbim-player: the run-time half of vbim — what a game ships.
//!
//! Open a `.vbim` stream (any `Read + Seek`) with a `wgpu::Device` and `Queue`, call
//! [`Player::advance`] once per displayed frame with the frame's time step in integer
//! nanoseconds, and sample [`Player::view`] — the reconstructed lightmap, linear RGB in an
//! `Rgba16Float` texture the player owns. Reading and decoding run on two threads of their
//! own (paper 001's figure 13): a reader pulls chunks into a bounded ring of compressed
//! bytes, reading ahead and wrapping at the loop point; a decoder verifies and decompresses
//! them and scans each coefficient stream for entry points; the render thread uploads a
//! segment's streams when it goes on screen, and compute shaders parse them, dequantise,
//! inverse-transform and build the predicted keyframes into compact resident textures,
//! then evaluate the time basis. When data is
//! late the chosen [`Policy`] decides what is shown, and every frame's [`FrameRecord`] says
//! how bandwidth turned into drift. A renderer that submits once per frame records the
//! player's work into its own encoder with [`Player::advance_into`] and calls
//! [`Player::submitted`] after its submission.
//!
//! The player depends on `vbim-format` only, never on the encoder.
//!
//! Modules, in the order a chunk meets them: `reader` (source → ring), `decoder` (ring →
//! scanned coefficient streams, in the form of `coded`), `pipeline` (the two threads and the
//! boxes between them), `slots` (what the GPU holds), `gpu` (a folder by concern: the
//! device, the memory plan, the resources, the decode and reconstruction passes),
//! `display` (the clock and the stall policies), `player` (the render thread's frame);
//! `config`, `record` and `stats` are its inputs and outputs; `readback` reads GPU data
//! back (tests, benchmarks, headless capture).
//!
//! A [`PackagePlayer`] plays a package of weathers (`vbim_format::package`): the shown
//! weather's lightmap and sky tracks in step, each a [`Player`], into two textures of its
//! own, and [`PackagePlayer::switch_weather`] cross-fades to another weather without a pop.
//! Its irradiance tracks light objects on the terrain: [`PackagePlayer::irradiance`]
//! answers on the CPU, and [`irradiance_wgsl`] evaluates the same grid in a shader
//! (module `irradiance`: the track's decoder thread, the answer, the buffer).
//!
//! Besides the player: [`headless_device`] opens a device where there is no window,
//! [`lightmap_descriptor`] describes a texture the player can write into
//! ([`Player::set_output`]), [`read_texture`] reads one back, and [`thread_cpu_ns`] is the
//! clock the player's CPU figures use.
//!
//! # Features
//! - `bench`: the decoder alone and the GPU decode alone ([`bench`](crate#features)), for
//!   `vbim bench decode`, the fuzz target and the tests of what the decoder stages.
#![deny(missing_docs)]

mod clock;
mod coded;
mod config;
mod cpu_time;
mod decoder;
mod display;
#[cfg(feature = "bench")]
mod fuzz;
mod gpu;
mod irradiance;
#[cfg(feature = "bench")]
mod marks;
mod package;
mod pipeline;
mod player;
mod readback;
mod reader;
mod record;
mod shape;
mod slots;
mod stats;
mod throttle;
mod time;

pub use clock::{Clock, SimClock, SystemClock};
pub use config::{PlayerConfig, Policy};
pub use cpu_time::thread_cpu_ns;
pub use gpu::{
    headless_device, headless_device_on, lightmap_descriptor, DeviceError, Headless, OutputError,
};
pub use irradiance::{irradiance_wgsl, Irradiance};
pub use package::{
    sky_cube_texel, LightmapSample, LightmapSampling, ObjectsRecord, PackageFile, PackagePlayer,
    PackageRecord, SwitchMode, SwitchRecord, TrackInfo, TrackKind,
};
pub use player::Player;
pub use readback::{read_texture, read_texture_layer};
pub use record::{Frame, FrameRecord, FrameState, Totals};
pub use shape::{DecodeShape, PassWeights};
pub use stats::{frames_csv, Summary};
pub use throttle::{Stall, Throttle};
/// The memory a stream may take ([`PlayerConfig::limits`]).
pub use vbim_format::Limits;

/// The decoder alone, without threads or a GPU, and the GPU decode alone, for
/// `vbim bench decode`, the tests that check what it stages and the fuzz target. Not a
/// stable API.
#[cfg(feature = "bench")]
pub mod bench {
    pub use crate::decoder::{DecoderCore, Event, KeyStep, SegmentData};
    pub use crate::fuzz::decoder as fuzz_decoder;
    pub use crate::gpu::PASS_CHANGES;
    pub use crate::gpu::{lane_batches, lane_room, timing_device, GpuDecoder};
}

/// Why a player could not be opened or stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlayerError {
    /// The stream's header or index is invalid.
    #[error(transparent)]
    Format(#[from] vbim_format::FormatError),
    /// A one-frame stream that does not loop: there is no time to play.
    #[error("a single-frame sequence that does not loop has nothing to play")]
    NothingToPlay,
    /// A reader or decoder thread could not be started.
    #[error("cannot start a player thread: {0}")]
    Thread(#[source] std::io::Error),
    /// A player thread did not stop in time.
    #[error("thread {thread} did not stop within {deadline:?}")]
    Stuck {
        /// The thread's name.
        thread: String,
        /// How long it was given.
        deadline: std::time::Duration,
    },
    /// The stream needs textures larger than the device allows.
    #[error(
        "a {width}×{height} stream (coded on {}×{}) needs textures larger than this \
         device's {max_side} (wgpu::Limits::max_texture_dimension_2d)",
        coded[0],
        coded[1]
    )]
    TooLarge {
        /// The stream's width.
        width: u32,
        /// The stream's height.
        height: u32,
        /// The padded planes it is coded on (whole tiles).
        coded: [usize; 2],
        /// The device's largest texture side.
        max_side: u32,
    },
    /// A texture given to [`Player::set_output`] does not fit the stream.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// A package file that cannot be played, or one of its tracks that cannot be opened.
    #[error("{}: {reason}", path.display())]
    Package {
        /// The package or track file.
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A texture given to [`PackagePlayer::set_sky_cube`] that cannot hold the sky's cube.
    #[error("{0}")]
    SkyCube(String),
    /// A package's track that the player refuses.
    #[error("{}: {source}", path.display())]
    Track {
        /// The track's file.
        path: std::path::PathBuf,
        /// Why.
        source: Box<PlayerError>,
    },
    /// A player thread panicked (a bug).
    #[error("thread {thread} panicked")]
    Panicked {
        /// The thread's name.
        thread: String,
    },
}
