//! What the player reports: each displayed frame's record and the running totals.

use crate::gpu::Params;

/// What a displayed frame showed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameState {
    /// The true state at the target time.
    Exact,
    /// Data late: the last resident state is held.
    Held,
    /// Blending from the held image to the true state.
    CatchingUp,
    /// `wait` policy: the clock is paused for data.
    Waiting,
}

impl FrameState {
    /// The state's name in reports and CSV files.
    pub fn name(self) -> &'static str {
        match self {
            FrameState::Exact => "exact",
            FrameState::Held => "held",
            FrameState::CatchingUp => "catching_up",
            FrameState::Waiting => "waiting",
        }
    }
}

/// One displayed frame.
#[derive(Clone, Copy, Debug)]
pub struct FrameRecord {
    /// Frames since the player was opened (0 first).
    pub index: u64,
    /// Playback clock, ns.
    pub clock_ns: u64,
    /// The media time the clock asks for, frames (not wrapped at loops).
    pub target: f64,
    /// The media time shown, frames (not wrapped at loops).
    pub shown: f64,
    /// target − shown, frames.
    pub drift: f64,
    /// What was shown.
    pub state: FrameState,
    /// Bytes the reader delivered since the previous frame.
    pub bytes_read: u64,
    /// Bytes uploaded to the GPU this frame.
    pub bytes_uploaded: u64,
    /// CPU time the reader spent since the previous frame, on its thread's own clock (in
    /// inline mode: inside this frame's `advance`), ns.
    pub read_ns: u64,
    /// CPU time the decoder spent since the previous frame, likewise, ns: checksums,
    /// zstd and the scan of the coefficient streams.
    pub decode_ns: u64,
    /// Time spent in `advance` on the calling thread, ns.
    pub render_ns: u64,
    /// Blend weight of the true state while catching up (1 otherwise).
    pub alpha: f32,
    /// The segment shown.
    pub segment: usize,
    /// The normalised time within that segment, 0 to 1.
    pub u: f64,
    /// The segment decode work this frame records, in blocks (an 8×8 block of one plane
    /// through one pass: what [`PlayerConfig::decode_budget`] bounds).
    ///
    /// [`PlayerConfig::decode_budget`]: crate::PlayerConfig::decode_budget
    pub decode_work: u64,
}

/// A planned frame ([`Player::plan`](crate::Player::plan)): its record, and the GPU work
/// [`Player::render`](crate::Player::render) will record for it.
pub struct Frame {
    /// What the frame shows.
    pub record: FrameRecord,
    /// The reconstruction to run: shader parameters, and whether to keep the current
    /// image for blending first.
    pub(crate) eval: Option<(Params, bool)>,
}

/// Running totals since the player was opened.
#[derive(Clone, Debug, Default)]
pub struct Totals {
    /// Frames displayed.
    pub frames: u64,
    /// Times the data ran late (a run of held or waiting frames counts once).
    pub stalls: u64,
    /// Bytes the reader delivered.
    pub bytes_read: u64,
    /// Bytes uploaded to the GPU (parsed coefficients and the decode passes' parameters).
    pub bytes_uploaded: u64,
    /// Reader CPU time, ns.
    pub read_ns: u64,
    /// Decoder CPU time, ns.
    pub decode_ns: u64,
    /// Frames whose reconstruction was skipped: the same time over the same data as the
    /// frame before (a hold, a pause), so the lightmap already showed it.
    pub frames_unchanged: u64,
    /// Segments decoded on the GPU and shown.
    pub segments_uploaded: u64,
    /// Segments that arrived too late to be shown (or whose keyframe was gone).
    pub segments_dropped: u64,
    /// Chunks found damaged (checksum, or the source failed), and segments that could not
    /// be decoded.
    pub damaged: u64,
    /// Re-synchronisations: [`Player::set_time`](crate::Player::set_time), or a display so
    /// far behind that reading on would only deliver the past.
    pub seeks: u64,
    /// Segment decode work recorded, in blocks ([`FrameRecord::decode_work`]).
    pub decode_work: u64,
    /// The most decode work one frame recorded.
    pub decode_work_max: u64,
    /// Frames that needed a segment whose decode the per-frame budget had not let finish
    /// (the display held or waited instead), where the segment's own length of frames
    /// at the budget would not have decoded it either: the budget is too small for the
    /// stream at this display rate. (A segment late because it arrived late, after a
    /// stall or behind a seek's rebuild, is not counted here.)
    pub budget_late: u64,
    /// Frames that recorded more than the budget because one step of the decode (a
    /// slice of a pass, or the clear of a bubble layer) costs more than the budget.
    pub over_budget: u64,
    /// The last damage or budget shortfall reported, naming the chunk or segment.
    pub last_error: Option<String>,
}
