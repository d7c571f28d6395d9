//! The buffer model: how much read-ahead a player needs at a given read rate.
//!
//! Like a video codec's leaky bucket, it simulates a reader that pulls the file front to
//! back at a constant `rate` into a ring of `bytes` capacity, and a player that starts
//! `preroll` after the first byte and takes each chunk out of the ring at the moment its
//! segment starts. A point `(rate, bytes, preroll)` promises that no chunk arrives late.
//!
//! Deadlines: a segment's tile map and coefficients, and the keyframe that ends it, are
//! needed when the segment starts; keyframe 0 and the metadata at time 0. A looping file is
//! read twice in a row (the player wraps to the start while the last segment plays); the
//! last segment's closing keyframe is keyframe 0, which the player keeps decoded from the
//! first time it read it.

use crate::header::{Header, ReadAhead, READ_AHEAD_POINTS};
use crate::index::{ChunkKind, IndexEntry};

/// Multiples of the mean bit rate at which the header tabulates the model.
pub const RATE_FACTORS: [f64; READ_AHEAD_POINTS] = [1.0, 1.2, 1.5, 2.0];

struct Need {
    end: u64,
    len: u64,
    deadline: f64,
}

fn needs(h: &Header, entries: &[IndexEntry]) -> Vec<Need> {
    let fps = h.fps();
    let duration = h.frame_count as f64 / fps;
    let file_size = entries.last().map_or(0, |e| e.offset + e.length);
    let passes = if h.looping { 2 } else { 1 };
    let mut out = Vec::new();
    for pass in 0..passes {
        let mut last_deadline = 0.0;
        for e in entries {
            if pass > 0 && e.kind == ChunkKind::Metadata {
                continue;
            }
            let frame = match e.kind {
                // Keyframe k closes segment k − 1: it is needed when that segment starts.
                ChunkKind::Keyframe if e.number > 0 => h.frame_count.min(prev_boundary(entries, e)),
                ChunkKind::Keyframe | ChunkKind::Metadata => 0,
                ChunkKind::TileMap | ChunkKind::Coefficients => e.first_frame,
                ChunkKind::Unknown(_) => u32::MAX,
            };
            let d = if frame == u32::MAX {
                last_deadline
            } else {
                frame as f64 / fps
            };
            last_deadline = d;
            out.push(Need {
                end: e.offset + e.length + pass as u64 * file_size,
                len: e.length,
                deadline: d + pass as f64 * duration,
            });
        }
    }
    out
}

fn prev_boundary(entries: &[IndexEntry], key: &IndexEntry) -> u32 {
    entries
        .iter()
        .filter(|e| e.kind == ChunkKind::Keyframe && e.number + 1 == key.number)
        .map(|e| e.first_frame)
        .next()
        .unwrap_or(0)
}

/// Whether a reader at `rate` with a ring of `cap` bytes and the given preroll meets every
/// deadline. Conservative: releases during a read are only counted once the read ends.
fn meets(needs: &[Need], rate: f64, cap: u64, preroll: f64) -> bool {
    let mut t = 0.0f64;
    let mut x = 0u64; // bytes read so far
    let mut released = 0u64;
    let mut next_release = 0usize;
    for n in needs {
        if n.len > cap {
            return false;
        }
        while x < n.end {
            while next_release < needs.len() && preroll + needs[next_release].deadline <= t {
                released += needs[next_release].len;
                next_release += 1;
            }
            let room = (released + cap).saturating_sub(x);
            if room == 0 {
                // Ring full: wait for the next release.
                match needs.get(next_release) {
                    Some(r) if preroll + r.deadline > t => t = preroll + r.deadline,
                    _ => return false,
                }
                continue;
            }
            let step = room.min(n.end - x);
            t += step as f64 / rate;
            x += step;
        }
        if t > preroll + n.deadline + 1e-9 {
            return false;
        }
    }
    true
}

/// The read rate, bytes per second, at `factor` × the mean bit rate of a file of
/// `file_size` bytes lasting `duration_s`: rounded up, as the table's points are, so that a
/// player asked for "1.2× the mean rate" finds the table's 1.2× point.
pub fn rate_at(file_size: u64, duration_s: f64, factor: f64) -> u64 {
    (file_size as f64 / duration_s * factor).ceil().max(1.0) as u64
}

/// The buffer model of several tracks read side by side (a package's lightmap and sky, or
/// two weathers' during a switch), from their own tables: at each point every track reads
/// at the same multiple of its own mean rate, so the set's rate is their sum, its ring
/// their read-aheads' sum, and it starts when the slowest has buffered (the longest
/// pre-roll). Each track then meets its own promise; a reader that shares the rate
/// otherwise may need more.
pub fn side_by_side(tables: &[[ReadAhead; READ_AHEAD_POINTS]]) -> [ReadAhead; READ_AHEAD_POINTS] {
    let mut out = [ReadAhead::default(); READ_AHEAD_POINTS];
    for (i, p) in out.iter_mut().enumerate() {
        for t in tables {
            p.rate = p.rate.saturating_add(t[i].rate);
            p.bytes = p.bytes.saturating_add(t[i].bytes);
            p.preroll_ns = p.preroll_ns.max(t[i].preroll_ns);
        }
    }
    out
}

/// Computes the header's read-ahead table for a file whose chunks are `entries`.
pub fn table(h: &Header, entries: &[IndexEntry]) -> [ReadAhead; READ_AHEAD_POINTS] {
    let needs = needs(h, entries);
    let file_size = entries.last().map_or(0, |e| e.offset + e.length).max(1);
    let duration = h.frame_count as f64 / h.fps();
    let total: u64 = needs.last().map_or(1, |n| n.end).max(1);
    let mut out = [ReadAhead::default(); READ_AHEAD_POINTS];
    for (p, f) in out.iter_mut().zip(RATE_FACTORS) {
        let rate = rate_at(file_size, duration, f) as f64;
        let preroll = needs
            .iter()
            .map(|n| n.end as f64 / rate - n.deadline)
            .fold(0.0, f64::max);
        let (mut lo, mut hi) = (needs.iter().map(|n| n.len).max().unwrap_or(1), total);
        if !meets(&needs, rate, hi, preroll) {
            hi = total;
        }
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if meets(&needs, rate, mid, preroll) {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        *p = ReadAhead {
            rate: rate as u64,
            bytes: hi,
            preroll_ns: (preroll * 1e9).ceil() as u64,
        };
    }
    out
}

#[cfg(test)]
mod side_by_side_tests {
    use super::*;

    #[test]
    fn tracks_side_by_side_add_rates_and_rings_and_wait_for_the_slowest() {
        let point = |rate, bytes, preroll_ns| ReadAhead {
            rate,
            bytes,
            preroll_ns,
        };
        let a = [
            point(100, 1000, 5),
            point(120, 900, 4),
            point(150, 800, 3),
            point(200, 700, 2),
        ];
        let b = [
            point(10, 50, 9),
            point(12, 40, 1),
            point(15, 30, 1),
            point(u64::MAX, 20, 0),
        ];
        let s = side_by_side(&[a, b]);
        assert_eq!(s[0], point(110, 1050, 9));
        assert_eq!(s[1], point(132, 940, 4));
        assert_eq!(s[3], point(u64::MAX, 720, 2));
        assert_eq!(side_by_side(&[a]), a);
        assert_eq!(side_by_side(&[]), [ReadAhead::default(); READ_AHEAD_POINTS]);
    }
}
