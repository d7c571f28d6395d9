//! How a player is set up: the stall policy, the reader's throttle, ring and pre-roll
//! sizes, and whether the reader and decoder run on threads or inline.

use std::sync::Arc;

use crate::clock::{Clock, SystemClock};
use crate::shape::DecodeShape;
use crate::throttle::Throttle;
use vbim_format::Limits;

/// What the display does when the next segment's data is late.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Policy {
    /// The clock runs on; the last resident state is held, and when the data arrives the
    /// display blends from what is shown to the true state over the catch-up window.
    Interpolate,
    /// The clock pauses until the data is there: drift accumulates, no error is shown.
    Wait,
    /// The display holds, then jumps to the true state when the data arrives.
    Skip,
}

impl Policy {
    /// Every policy, in the order reports list them.
    pub const ALL: [Policy; 3] = [Policy::Interpolate, Policy::Wait, Policy::Skip];

    /// The policy's name, as `--policy` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Policy::Interpolate => "interpolate",
            Policy::Wait => "wait",
            Policy::Skip => "skip",
        }
    }
}

impl std::str::FromStr for Policy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "interpolate" => Ok(Policy::Interpolate),
            "wait" => Ok(Policy::Wait),
            "skip" => Ok(Policy::Skip),
            _ => Err(format!("policy {s:?} (interpolate, wait or skip)")),
        }
    }
}

/// How a player is set up. `PlayerConfig::default()` plays at full speed on threads, with
/// the `interpolate` policy and a 0.5 s catch-up.
#[derive(Clone)]
pub struct PlayerConfig {
    /// What the display does when data is late.
    pub policy: Policy,
    /// Catch-up window, ns of playback.
    pub catch_up_ns: u64,
    /// The reader's bandwidth cap and stall pattern.
    pub throttle: Throttle,
    /// Ring capacity in bytes; `None`: the header's read-ahead at the throttle's rate (the
    /// largest tabulated point when unthrottled), and never less than the largest chunk.
    pub ring_bytes: Option<usize>,
    /// Run reader and decoder on their own threads (the default), or step them inside
    /// `advance` — deterministic, for simulated time.
    pub threaded: bool,
    /// The clock that paces the reader thread (threaded mode).
    pub clock: Arc<dyn Clock>,
    /// How long to buffer before the first frame; `None`: the header's buffer model at the
    /// throttle's rate (no wait when unthrottled).
    pub preroll_ns: Option<u64>,
    /// Added to the pre-roll. The buffer model's pre-roll assumes a reader that never
    /// stalls; while the ring is still filling after it, a stall can make the first
    /// transition late. A margin as long as the stall to survive buys that back with
    /// start-up time (measured in BENCHMARKS.md).
    pub preroll_margin_ns: u64,
    /// The most segment decode work one displayed frame records, in blocks (the time of
    /// an 8×8 block's 64 texel sums of one term, each pass weighted by its measured cost
    /// ([`DecodeShape::weights`]), and each step of the decode [`DecodeShape::step_cost`] more;
    /// [`FrameRecord::decode_work`]). `None`: each segment's decode is spread evenly over
    /// the frames before it is shown but the last, at the display rate the frames so far
    /// give, from the frame the segment before it goes on screen, each frame recording
    /// the steps nearest its share (at least one; a frame may exceed its share by half a
    /// step), and a segment needed at once (the first, or after a seek) is decoded at
    /// once. With a budget, a segment needed before its decode is done is late (the
    /// display holds or waits, as the policy says) and, where a segment's own length of
    /// frames at the budget would not have decoded it either, [`Totals::budget_late`]
    /// counts it: the budget is too small for the stream. A step that costs more than the budget
    /// (on a GPU, any step once the budget is below the step cost) runs alone in its
    /// frame and [`Totals::over_budget`] counts it.
    ///
    /// [`FrameRecord::decode_work`]: crate::FrameRecord::decode_work
    /// [`Totals::budget_late`]: crate::Totals::budget_late
    /// [`Totals::over_budget`]: crate::Totals::over_budget
    pub decode_budget: Option<u64>,
    /// How the GPU decode is cut into dispatches and what each costs
    /// ([`DecodeShape`]); `None`: the adapter's ([`DecodeShape::for_adapter`]: on a GPU,
    /// large dispatches, the wide parse and a cost per step for its latency; on a CPU
    /// adapter such as lavapipe, small dispatches whose cost is their work).
    pub decode_shape: Option<DecodeShape>,
    /// How far a part of the lightmap may lag the exact image before it is evaluated
    /// again, as a share of the protocol's bound on the GPU against the reference decoder
    /// (2^-10 relative for HDR, 0.5/255 for 8-bit). The reconstruction evaluates a tile
    /// of 16² texels only when the time has moved enough to change it by more than that
    /// (bounded from the weights it was last evaluated with and what its terms hold);
    /// otherwise the lightmap keeps what it has there, and the tile costs one read of 80
    /// bytes. Default 0.25: with the evaluation's own rounding (half a half-float step,
    /// 0.5 of the bound) every texel stays within the bound. 0: every texel every frame;
    /// larger shares trade accuracy for GPU time (BENCHMARKS.md). The output texture must
    /// keep what the player wrote into it.
    pub reuse_share: f32,
    /// Where the last frame that decided which tiles to keep ([`reuse_share`]) kept under
    /// one tile in 16, the frames after it evaluate every tile without deciding (the
    /// decision reads each tile's state and bounds: overhead where nothing is kept, as at
    /// a file's own 24 fps), and every this many frames, and right after the first frame of
    /// new keyframes or bubble planes, one decides again. Default 8: on lavapipe 3–4% off
    /// the demo's frame at 24 fps, the same at a day's pace (BENCHMARKS.md, "The runtime's
    /// speed–accuracy trade"). 0: every frame decides.
    ///
    /// [`reuse_share`]: PlayerConfig::reuse_share
    pub reuse_probe: u32,
    /// The memory the stream may take, GPU and CPU together ([`Player::open`] refuses a
    /// stream that could need more, before creating anything for it).
    ///
    /// [`Player::open`]: crate::Player::open
    pub limits: Limits,
}

impl Default for PlayerConfig {
    fn default() -> Self {
        PlayerConfig {
            policy: Policy::Interpolate,
            catch_up_ns: 500_000_000,
            throttle: Throttle::UNLIMITED,
            ring_bytes: None,
            threaded: true,
            clock: Arc::new(SystemClock::new()),
            preroll_ns: None,
            preroll_margin_ns: 0,
            decode_budget: None,
            decode_shape: None,
            reuse_share: 0.25,
            reuse_probe: 8,
            limits: Limits::default(),
        }
    }
}
