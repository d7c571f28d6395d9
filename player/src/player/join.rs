//! Joining a running timeline: a track that starts beside others already playing (a
//! weather switch's new tracks) at the shown position, without a pre-roll.
//!
//! The data must come from the last intra keyframe at or before the time it is shown at.
//! Read from there while the clock runs, a capped reader falls behind by what it has to
//! read first and, at 1.2 times the stream's mean rate, needs five times that to catch up,
//! dropping every segment that comes late meanwhile. So a join starts at the first segment
//! boundary whose data — from its intra keyframe through that segment, and the pre-roll
//! the buffer model asks at the rate — the reader can deliver before the clock gets there;
//! unthrottled, that is the position itself.

use std::io::{Read, Seek};

use super::Player;
use crate::time::{media_to_ticks, ticks_to_media, MediaTime};

impl<R: Read + Seek + Send + 'static> Player<R> {
    /// Joins a running timeline: from clock `ticks` on, this player's clock is the caller's
    /// and its playback position is `position` ns then, moving with it. Its data restarts
    /// for media time `at` (≥ the position; [`Player::earliest_join`] gives the first time
    /// it can be there): until the position reaches `at` and that data is resident the
    /// player reports [`FrameState::Held`](crate::FrameState::Held) (its lightmap is not
    /// yet worth showing), then it shows the very time its neighbours show.
    pub fn join(&mut self, ticks: u64, position: u64, at: MediaTime) {
        self.ticks = ticks;
        self.last_seek = ticks;
        self.display.join(ticks, position, at);
        self.seek(at);
    }

    /// Sets the buffering before the first frame to `ns` (tracks that start together take
    /// the longest of their pre-rolls, so that they start in step). No effect once a frame
    /// has been shown.
    pub fn set_preroll_ns(&mut self, ns: u64) {
        self.preroll = ns;
        self.display.set_preroll(ns);
    }

    /// The playback position, ns: the clock less the pre-roll and the `wait` policy's
    /// pauses (what [`Player::join`] takes to put another track at the same time).
    pub fn position(&self) -> u64 {
        self.display.position(self.ticks)
    }

    /// The first media time at or after playback position `position` (ns) whose data this
    /// player's reader can deliver in time when it starts reading now (see the module's
    /// documentation): the position itself when the reader is not capped.
    pub fn earliest_join(&self, position: u64) -> MediaTime {
        let (num, den) = (self.header.rate_num, self.header.rate_den);
        let pos = ticks_to_media(position, num, den);
        let Some(rate) = self.read_rate.filter(|&r| r > 0) else {
            return pos;
        };
        let n = self.n_frames();
        let boundaries = &self.layout.boundaries;
        let segments = boundaries.len().saturating_sub(1);
        if segments == 0 {
            return pos;
        }
        let pass = (pos >> 32) / n;
        // Candidates: the position, then every boundary after it, over two passes.
        let mut candidates = vec![pos];
        for p in pass..pass + 2 {
            for &b in &boundaries[..segments] {
                let t = (p * n + b as u64) << 32;
                if t > pos {
                    candidates.push(t);
                }
            }
        }
        for t in candidates {
            let f = ((t >> 32) % n) as u32;
            let s = boundaries
                .partition_point(|&b| b <= f)
                .saturating_sub(1)
                .min(segments - 1);
            let keys = &self.layout.keyframes;
            let k = (0..=s.min(keys.len() - 1))
                .rev()
                .find(|&k| self.entries[keys[k]].is_intra())
                .unwrap_or(0);
            // From the restart keyframe through the segment's chunks and closing keyframe.
            let next_key = keys.get(s + 1).copied().unwrap_or(0);
            let last = self.layout.segments[s].1.max(next_key);
            let bytes: u64 = self.entries[keys[k]..=last.max(keys[k])]
                .iter()
                .map(|e| e.length)
                .sum();
            let read_ns = (bytes as u128 * 1_000_000_000 / rate as u128) as u64;
            let lead = media_to_ticks(t - pos, num, den);
            if lead >= read_ns.saturating_add(self.preroll) {
                return t;
            }
        }
        // Slower than any candidate allows: a pass from now, the most the reader can need.
        pos + (n << 32)
    }
}
