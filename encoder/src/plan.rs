//! How much of the sequence the encoder holds at once. The segment search reads only a
//! subsample of each frame, and everything after it is local to a tile, so only three
//! things span the whole frame: the search's window of subsampled frames (and the
//! sensitivity of the segment before it: a keyframe is coded once the segments on both
//! sides are known, `reach`), the decoded keyframes, and the keyframe being coded. The inner frames of a segment, which are most
//! of what the encoder would hold, are held whole when they fit the memory limit and
//! otherwise read from the input one band of tile rows at a time. Held whole, the frames
//! of the segment after are kept too as far as the limit allows, and read again when
//! their segment is coded where it does not. The output is the same either way.

use crate::domain::Domain;
use crate::{EncodeError, EncoderConfig, SegmentMode, SourceInfo};

/// How the encode holds the sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Plan {
    /// Tile rows per band (all of them when `whole`).
    pub band_tiles: usize,
    /// The segment's inner frames are held whole (read once); else read a band at a
    /// time (each read twice: once whole for the search, once by bands).
    pub whole: bool,
    /// Frames read at once while loading the search's window.
    pub readers: usize,
    /// When `whole`: frames the window may hold whole (at least a segment's worth; those
    /// of the next segment beyond it are read again when it is coded).
    pub whole_frames: usize,
    /// What the plan expects the encode to hold at its peak, bytes.
    pub estimate: u64,
}

/// Chooses how to hold `info`'s frames within `cfg.memory_limit` (or `cfg.band_tiles`).
pub(crate) fn plan(
    info: &SourceInfo,
    cfg: &EncoderConfig,
    threads: usize,
) -> Result<Plan, EncodeError> {
    let ts = cfg.tile_size;
    let (pw, ph) = (info.width.div_ceil(ts) * ts, info.height.div_ceil(ts) * ts);
    let (tiles_x, tiles_y) = ((pw / ts) as u64, (ph / ts) as u64);
    let t = (pw * ph) as u64;
    let ch = info.channels as u64;
    let nb = cfg.max_degree.saturating_sub(1) as u64;
    let longest = match cfg.segment {
        SegmentMode::Auto { max } | SegmentMode::Fixed(max) => max as u64,
    }
    .min(info.frames as u64);
    // A coded frame: its planes and the sensitivity plane, f32.
    let frame = t * (ch + 1) * 4;
    let st = Domain::sub_tile(ts, cfg.search_stride) as u64;
    // Held throughout: the search's window of subsampled frames (and of the segment
    // before it, their sensitivity alone, for the keyframe between), the decoded keyframes
    // at both ends of the segment and keyframe 0 (for the loop), and the quantised
    // streams held sparse until a segment is written (an allowance: about 2 bytes a
    // coefficient at most at the tolerances of interest).
    let sub = tiles_x * tiles_y * st * st * 4;
    let window = (longest + 2) * sub * (ch + 1) + longest * sub;
    let held = window + 3 * t * ch * 4 + t * ch * nb * 2;
    // The phases, one at a time on top of that. Reading a frame: the decoded file (f32
    // interleaved) and the coded frame it becomes. Coding a keyframe: the coded frame, a
    // residual plane and both candidate payloads' blocks. A band: per padded row, z = Qᵀr (f64), the bubble planes and one stream's
    // dense blocks per term and plane, and in band mode the inner frames' rows.
    let read = t * ch * 4 + frame;
    let keyframe = read.max(frame + t * 4 + 2 * t * ch * 4);
    let work_row = pw as u64 * nb * ch * (8 + 4 + 4);
    let band_row = work_row + pw as u64 * longest.saturating_sub(1) * (ch + 1) * 4;
    let limit = cfg.memory_limit;
    let threads = threads.max(1) as u64;
    let readers = |room: u64| (room / read.max(1)).clamp(1, threads) as usize;
    // Whole: the window also holds every frame of the segment whole, and as many of the
    // next segment's as the limit leaves room for.
    let whole_work = held + keyframe.max(threads * read).max(ph as u64 * work_row);
    let whole_cost = whole_work + (longest + 1) * frame;
    let whole_frames = (limit.saturating_sub(whole_work) / frame.max(1)).min(2 * longest + 1);
    let whole_estimate = whole_work + whole_frames * frame;
    let band_cost = |tiles: usize| held + keyframe.max(read).max((tiles * ts) as u64 * band_row);
    if let Some(b) = cfg.band_tiles {
        let b = b.min(tiles_y as usize);
        let whole = b == tiles_y as usize && whole_cost <= limit;
        return Ok(Plan {
            band_tiles: b,
            whole,
            readers: if whole {
                threads as usize
            } else {
                readers(limit.saturating_sub(held))
            },
            whole_frames: if whole { whole_frames as usize } else { 0 },
            estimate: if whole { whole_estimate } else { band_cost(b) },
        });
    }
    if whole_cost <= limit {
        return Ok(Plan {
            band_tiles: tiles_y as usize,
            whole: true,
            readers: threads as usize,
            whole_frames: whole_frames as usize,
            estimate: whole_estimate,
        });
    }
    // Bands: as many tile rows as the room left by what is held allows.
    let room = limit.saturating_sub(held);
    let band_tiles = (room / (ts as u64 * band_row).max(1)).min(tiles_y) as usize;
    if band_tiles == 0 || band_cost(band_tiles) > limit {
        let need = band_cost(1);
        return Err(EncodeError::OverMemory {
            sequence: format!(
                "{}: {}×{} with {} channel(s) ({} segments of up to {longest} frames)",
                info.name,
                info.width,
                info.height,
                info.channels,
                match cfg.segment {
                    SegmentMode::Auto { .. } => "adaptive",
                    SegmentMode::Fixed(_) => "fixed",
                },
            ),
            need,
            limit,
        });
    }
    Ok(Plan {
        band_tiles,
        whole: false,
        readers: readers(room),
        whole_frames: 0,
        estimate: band_cost(band_tiles),
    })
}

/// `f(i)` for every frame `i < n`, at most `readers` at once: each call reads a frame
/// whole, so the readers a plan allows (not the worker threads, which may be many more
/// on a large machine) bound what the reads hold. Results in frame order.
pub(crate) fn read_frames<T: Send>(
    n: usize,
    readers: usize,
    f: impl Fn(usize) -> Result<T, EncodeError> + Sync,
) -> Result<Vec<T>, EncodeError> {
    use rayon::prelude::*;
    let readers = readers.max(1);
    let mut out = Vec::with_capacity(n);
    for start in (0..n).step_by(readers) {
        out.extend(
            (start..(start + readers).min(n))
                .into_par_iter()
                .map(&f)
                .collect::<Result<Vec<T>, EncodeError>>()?,
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{InputKind, Preset};

    fn info(side: usize, channels: usize) -> SourceInfo {
        SourceInfo {
            width: side,
            height: side,
            channels,
            kind: InputKind::Hdr,
            frames: 240,
            name: "day".into(),
        }
    }

    #[test]
    fn frames_are_whole_until_the_limit_and_in_bands_within_it_after() {
        let cfg = EncoderConfig::preset(Preset::Default);
        for side in [512, 1024, 2048] {
            let p = plan(&info(side, 3), &cfg, 2).unwrap();
            assert!(p.whole && p.estimate <= cfg.memory_limit, "{side}²: {p:?}");
            // A segment's frames at least; two segments' where they fit (2048² 3-channel
            // frames take 67 MB: not all 65 of them within 4 GB).
            assert!(
                p.whole_frames > 32 && p.whole_frames <= 65,
                "{side}²: {p:?}"
            );
            assert_eq!(p.whole_frames == 65, side < 2048, "{side}²: {p:?}");
        }
        let p = plan(&info(4096, 3), &cfg, 2).unwrap();
        assert!(!p.whole && p.estimate <= cfg.memory_limit, "4096²: {p:?}");
        assert!(p.band_tiles >= 1 && p.readers >= 1);
        // 8192² holds more than 4 GB before any band (the window and the keyframes):
        // refused, naming what it needs; within 10 GB, in bands.
        let e = plan(&info(8192, 3), &cfg, 2).unwrap_err().to_string();
        assert!(e.contains("8192×8192") && e.contains("GB"), "{e}");
        let at = |gb: u64| EncoderConfig {
            memory_limit: gb * 1_000_000_000,
            ..cfg.clone()
        };
        let (a, b) = (
            plan(&info(8192, 3), &at(10), 2).unwrap(),
            plan(&info(8192, 3), &at(20), 2).unwrap(),
        );
        assert!(!a.whole && a.estimate <= 10_000_000_000, "{a:?}");
        // More room, wider bands; no more threads than asked read at once.
        assert!(b.band_tiles > a.band_tiles && b.readers <= 2, "{a:?} {b:?}");
    }

    #[test]
    fn frames_are_read_at_most_readers_at_once_in_order() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(8)
            .build()
            .unwrap();
        for readers in [1, 3] {
            let (now, most) = (AtomicUsize::new(0), AtomicUsize::new(0));
            let out = pool
                .install(|| {
                    read_frames(20, readers, |i| {
                        let n = now.fetch_add(1, Ordering::SeqCst) + 1;
                        most.fetch_max(n, Ordering::SeqCst);
                        std::thread::sleep(std::time::Duration::from_millis(2));
                        now.fetch_sub(1, Ordering::SeqCst);
                        Ok(i * 10)
                    })
                })
                .unwrap();
            assert_eq!(out, (0..20).map(|i| i * 10).collect::<Vec<_>>());
            assert!(most.load(Ordering::SeqCst) <= readers, "{readers}");
        }
        let e = read_frames(5, 2, |i| match i {
            3 => Err(EncodeError::Input("frame 3: bad".into())),
            _ => Ok(i),
        })
        .unwrap_err();
        assert!(e.to_string().contains("frame 3"), "{e}");
    }
}
