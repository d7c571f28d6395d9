//! Summaries of a playback: how bandwidth turned into drift.

use std::fmt::Write as _;

use crate::record::{FrameRecord, FrameState};

/// A playback's figures, from its frame records ([`Summary::of`]).
#[derive(Clone, Debug, Default)]
pub struct Summary {
    /// Frames displayed after the pre-roll.
    pub frames: usize,
    /// Seconds of playback clock covered.
    pub seconds: f64,
    /// Mean drift, media frames.
    pub mean_drift: f64,
    /// 99th percentile of the drift, media frames.
    pub p99_drift: f64,
    /// Largest drift, media frames.
    pub max_drift: f64,
    /// Frames late by more than one media frame (drift > 1).
    pub late_frames: usize,
    /// Transitions into a held or waiting state.
    pub stalls: usize,
    /// Frames that held the last resident state.
    pub held_frames: usize,
    /// Frames that blended from the held image to the true state.
    pub catching_up_frames: usize,
    /// Bytes read per second of playback clock.
    pub bytes_read_per_s: f64,
    /// Bytes uploaded to the GPU per second of playback clock.
    pub bytes_uploaded_per_s: f64,
    /// Mean time in `advance` on the calling thread, ms.
    pub mean_render_ms: f64,
    /// 99th percentile of that time, ms.
    pub p99_render_ms: f64,
    /// Decoder time per second of playback (share of one core).
    pub decode_core_share: f64,
    /// Reader time per second of playback (share of one core).
    pub read_core_share: f64,
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

impl Summary {
    /// Summarises displayed frames (pre-roll frames, before anything was shown, excluded).
    pub fn of(records: &[FrameRecord]) -> Summary {
        let first = records
            .iter()
            .position(|r| r.state != FrameState::Waiting || r.shown > 0.0)
            .unwrap_or(records.len());
        let rs = &records[first..];
        if rs.is_empty() {
            return Summary::default();
        }
        let mut drift: Vec<f64> = rs.iter().map(|r| r.drift).collect();
        let mut render: Vec<f64> = rs.iter().map(|r| r.render_ns as f64 * 1e-6).collect();
        let seconds =
            (rs.last().unwrap().clock_ns - records[first.saturating_sub(1)].clock_ns) as f64 * 1e-9;
        let seconds = seconds.max(1e-9);
        let mut stalls = 0;
        let mut prev = FrameState::Exact;
        for r in rs {
            let stalled = matches!(r.state, FrameState::Held | FrameState::Waiting);
            if stalled && !matches!(prev, FrameState::Held | FrameState::Waiting) {
                stalls += 1;
            }
            prev = r.state;
        }
        Summary {
            frames: rs.len(),
            seconds,
            mean_drift: drift.iter().sum::<f64>() / rs.len() as f64,
            max_drift: drift.iter().copied().fold(0.0, f64::max),
            p99_drift: percentile(&mut drift, 0.99),
            late_frames: rs.iter().filter(|r| r.drift > 1.0).count(),
            stalls,
            held_frames: rs
                .iter()
                .filter(|r| matches!(r.state, FrameState::Held | FrameState::Waiting))
                .count(),
            catching_up_frames: rs
                .iter()
                .filter(|r| r.state == FrameState::CatchingUp)
                .count(),
            bytes_read_per_s: rs.iter().map(|r| r.bytes_read as f64).sum::<f64>() / seconds,
            bytes_uploaded_per_s: rs.iter().map(|r| r.bytes_uploaded as f64).sum::<f64>() / seconds,
            mean_render_ms: render.iter().sum::<f64>() / rs.len() as f64,
            p99_render_ms: percentile(&mut render, 0.99),
            decode_core_share: rs.iter().map(|r| r.decode_ns as f64).sum::<f64>() * 1e-9 / seconds,
            read_core_share: rs.iter().map(|r| r.read_ns as f64).sum::<f64>() * 1e-9 / seconds,
        }
    }
}

/// Per-frame records as CSV.
pub fn frames_csv(records: &[FrameRecord]) -> String {
    let mut s = String::from(
        "frame,clock_ns,target_frames,shown_frames,drift_frames,state,bytes_read,bytes_uploaded,read_ns,decode_ns,render_ns,alpha,segment,u\n",
    );
    for r in records {
        let _ = writeln!(
            s,
            "{},{},{:.6},{:.6},{:.6},{},{},{},{},{},{},{:.4},{},{:.6}",
            r.index,
            r.clock_ns,
            r.target,
            r.shown,
            r.drift,
            r.state.name(),
            r.bytes_read,
            r.bytes_uploaded,
            r.read_ns,
            r.decode_ns,
            r.render_ns,
            r.alpha,
            r.segment,
            r.u
        );
    }
    s
}
