//! vbim-player: the run-time half of vbim — what a game ships.
//!
//! Open a `.vbim` stream (any `Read + Seek`) with a `wgpu::Device` and `Queue`, call
//! [`Player::advance`] once per displayed frame with the frame's time step in integer
//! nanoseconds, and sample [`Player::view`] — the reconstructed lightmap, linear RGB in an
//! `Rgba16Float` texture the player owns. Reading and decoding run on two threads of their
//! own (paper 001's figure 13): a reader pulls chunks into a bounded ring of compressed
//! bytes, reading ahead and wrapping at the loop point; a decoder writes them into one of
//! two mapped GPU staging buffers; the render thread only records the copy into the GPU
//! slot it is not sampling and evaluates the time basis in a compute shader. When data is
//! late the chosen [`Policy`] decides what is shown, and every frame's [`FrameRecord`] says
//! how bandwidth turned into drift. A renderer that submits once per frame records the
//! player's work into its own encoder with [`Player::advance_into`] and calls
//! [`Player::submitted`] after its submission.
//!
//! The player depends on `vbim-format` only, never on the encoder.

pub mod assemble;
pub mod clock;
pub mod cpu_time;
pub mod gpu;
mod player;
pub mod stats;
pub mod stream;
pub mod throttle;
pub mod time;

pub use clock::{Clock, SimClock, SystemClock};
pub use gpu::headless_device;
pub use player::{frame_ns, Frame, FrameRecord, FrameState, Player, PlayerConfig, Policy, Totals};
pub use throttle::{Stall, Throttle};

#[derive(Debug, thiserror::Error)]
pub enum PlayerError {
    #[error("{0}")]
    Format(#[from] vbim_format::FormatError),
    #[error("{0}")]
    Unsupported(String),
    #[error("{0}")]
    Thread(String),
}
