//! `--tolerance T` in one pass: the internal budget that delivers T, found on a sample.
//!
//! The encoder's budgets are per segment (`encode.rs`), and a day's frames do not spend
//! them alike: nights fall far below, sunrise and sunset go above, so the pooled mean
//! PSNR of a budget lands anywhere from 1 dB below to 13 dB above it (BENCHMARKS.md),
//! depending on the share of frames that are dark and how much detail the light has. So before coding, the encoder codes a *sample* of the sequence — whole
//! tiles drawn one from each stratum of the frame, every frame, laid out side by side as
//! a smaller sequence — at a few internal budgets, measures each with the reference
//! decoder, and keeps the budget whose sample lands on T. Whole tiles keep everything the
//! encoder decides locally (a tile's degrees, its 8×8 blocks' quantisation) as it is in
//! the full frame, and every frame keeps the day's shape (its nights, its sunsets), so
//! the sample's PSNR follows the full encode's. What the sample cannot see exactly — the
//! frame-wide statistics the segment search and the quantiser steps use — it estimates
//! from its tiles; BENCHMARKS.md gives the measured difference between the sample's PSNR
//! and the full encode's. Then, if the sample's worst frame is more than
//! `worst_margin_db` below T, the frames below that floor are raised (their budgets
//! tightened, `EncoderConfig::frame_raise_db`) and the mean's budget found again with them
//! raised (docs/MODEL.md, "Evening the error out in time").

use std::io::Cursor;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::config::{MAX_TOLERANCE_DB, MIN_TOLERANCE_DB, PROMISE_DB};
use crate::encode::CodedCache;
use crate::report::Tally;
use crate::secant::{bracket, next_tolerance, span_slope, Pass, FIRST_SLOPE};
use crate::{EncodeError, EncoderConfig, FrameSource, MemorySource, Progress};

/// Texels in a sample frame at most: an eighth of a 512² frame. (A quarter was measured
/// to predict no better on the benchmark days, at a third more time; BENCHMARKS.md.)
pub(crate) const SAMPLE_TEXELS: usize = 32_768;
/// The sample takes one whole tile in this many, at most.
const SAMPLE_SHARE: usize = 8;
/// Memory the sample's frames may take, bytes (f32 values).
const SAMPLE_BYTES: usize = 256 << 20;
/// Fewer whole tiles than this and the sample is the sequence itself; a sample has at
/// least this over `SAMPLE_SHARE`.
const MIN_TILES: usize = 64;
/// Sample passes at most for the mean, and in all.
const MEAN_PASSES: usize = 6;
const MAX_PASSES: usize = 10;
/// The sample's PSNR is close enough to T within this, dB.
const CLOSE_DB: f64 = 0.1;
/// How far above T the worst-frame floor may raise the whole budget where raising single
/// frames does not reach it, dB (inside the ±0.5 dB the tolerance promises, with room for
/// the sample's error).
const WORST_RAISE_DB: f64 = 0.2;
/// A raised pass is taken for the encode with a mean this far above T at most, dB.
const PICK_ABOVE_DB: f64 = 0.35;
/// Rounds of raising the frames below the worst-frame floor, at most.
const RAISE_ROUNDS: usize = 3;
/// The sample's worst frame is held this far above the floor: the full encode's lands
/// within about ±[`SAMPLE_ERROR_DB`](crate::config::SAMPLE_ERROR_DB) of the sample's, dB.
const FLOOR_GUARD_DB: f64 = 0.2;
/// A frame below the floor is raised to this much above it (the sample's per-frame PSNR
/// is an estimate, and the mean's budget is lowered again after each round), dB.
const RAISE_GUARD_DB: f64 = 0.4;
/// What a frame's first raise is expected to buy it, dB per dB (afterwards each frame's
/// own, measured): its neighbours' budgets and the mean's lower budget pull it back. On
/// the benchmark days a first round's raised frames bought a median of 0.34–0.45 in four
/// rounds of six, 1.1–1.8 in the others; at 1 most first rounds fell short and took a
/// second (BENCHMARKS.md, "The worst-frame floor").
const FIRST_BUY: f64 = 0.5;
/// Two passes this close around T are interpolated between, dB.
const BRACKET_DB: f64 = 2.0;

/// What the analysis found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Aim {
    /// The internal tolerance the full encode uses, dB.
    pub internal_db: f64,
    /// The sample's mean PSNR at that tolerance (interpolated between the passes around
    /// it): the prediction of what the full encode delivers, dB.
    pub predicted_db: f64,
    /// Extra accuracy asked of single frames to keep the worst frame within the margin
    /// (the starting point's, plus what the aim added; empty: none), dB per frame.
    #[serde(skip)]
    pub frame_raise_db: Vec<f64>,
    /// Frames the aim raised for the worst-frame floor.
    pub raised_frames: usize,
    /// The largest raise, dB.
    pub max_raise_db: f64,
    /// Every sample pass.
    pub passes: Vec<SamplePass>,
    /// Texels of each sample frame (all of them when the sequence is small).
    pub sample_texels: usize,
    /// Why there was no aim (the tolerance was used as the budget as it is), if so.
    pub skipped: Option<String>,
}

/// One encode and measurement of the sample.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SamplePass {
    /// The internal tolerance it was coded at, dB.
    pub internal_db: f64,
    /// The raising round it belongs to (0: none; frames raised from 1 on).
    pub round: usize,
    /// The sample's mean PSNR, dB.
    pub mean_db: f64,
    /// The sample's worst frame, dB.
    pub worst_db: f64,
    /// The sample's bytes.
    pub bytes: u64,
    /// Each frame's PSNR on the sample, dB.
    #[serde(skip)]
    pub frame_db: Vec<f64>,
}

/// Finds the internal tolerance at which `src` coded with `cfg` delivers
/// `cfg.tolerance_db`, with no frame below `cfg.tolerance_db − cfg.worst_margin_db`
/// (run inside the encoder's worker pool). Also returns the sequence's exposure when
/// drawing the sample read and checked every frame (the full encode then need not).
pub(crate) fn aim(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    progress: Progress,
) -> Result<(Aim, Option<f32>), EncodeError> {
    let target = cfg.tolerance_db;
    let sample = Sample::draw(src, cfg, progress)?;
    let (source, validated): (&dyn FrameSource, Option<f32>) = match &sample {
        Draw::Tiles(s) => (&s.frames, Some(s.exposure)),
        Draw::Whole => (src, None),
        Draw::Skip(why) => {
            let aim = Aim {
                internal_db: target,
                predicted_db: f64::NAN,
                frame_raise_db: cfg.frame_raise_db.clone(),
                raised_frames: 0,
                max_raise_db: 0.0,
                passes: Vec::new(),
                sample_texels: 0,
                skipped: Some(why.clone()),
            };
            return Ok((aim, None));
        }
    };
    let sample_texels = {
        let i = source.info();
        i.width * i.height
    };
    let quiet: Progress = &|_, _, _| {};
    let frames = source.info().frames;
    // Every pass codes the same sample frames at the same exposure: code them once.
    let cache = validated.map(|e| CodedCache::new(source, e, cfg.tile_size, SAMPLE_BYTES));
    let done = AtomicU64::new(0);
    let run = |internal: f64, raise: &[f64], round: usize| {
        let c = EncoderConfig {
            tolerance_db: internal,
            aim: false,
            metadata: None,
            // The sample is in memory and small: code its frames whole.
            band_tiles: None,
            memory_limit: u64::MAX,
            frame_raise_db: raise.to_vec(),
            ..cfg.clone()
        };
        let mut out = Cursor::new(Vec::new());
        let mut rep =
            crate::encode::encode_in_pool(source, &c, validated, cache.as_ref(), &mut out, quiet)?;
        rep.verify_in_memory(
            source,
            out.get_ref(),
            "the tolerance's sample",
            Tally::Psnr,
            quiet,
        )?;
        progress(
            "aim",
            done.fetch_add(1, Ordering::Relaxed) + 1,
            MAX_PASSES as u64,
        );
        Ok::<_, EncodeError>(SamplePass {
            internal_db: internal,
            round,
            mean_db: rep.mean_psnr().unwrap_or(f64::INFINITY),
            worst_db: rep.worst_psnr().unwrap_or(f64::INFINITY),
            bytes: rep.bytes,
            frame_db: rep.measured.map(|m| m.frame_psnr).unwrap_or_default(),
        })
    };
    let mean = |p: &SamplePass| p.mean_db;
    let worst = |p: &SamplePass| p.worst_db;
    let start = &cfg.frame_raise_db;
    let mut passes = Vec::new();
    let mut internal_db = solve(&mut passes, target, None, mean, MEAN_PASSES, &mut |t| {
        run(t, start, 0)
    })?;
    // Where the curve is a staircase (content coded almost exactly at any budget), a pass
    // that met T with no more bytes than the chosen budget's beats it: the most accurate.
    let bytes_there = along(&passes, internal_db, |p| p.bytes as f64);
    if let Some(p) = passes
        .iter()
        .filter(|p| p.mean_db >= target - CLOSE_DB && p.bytes as f64 <= bytes_there)
        .max_by(|a, b| a.mean_db.total_cmp(&b.mean_db))
    {
        internal_db = p.internal_db;
    }
    // The worst frame: a day pooled far above its budget by dark nights puts its errors in
    // the daylight frames, most of all where the low sun's shadows sweep; the protocol
    // pairs a 45 dB mean with a 38 dB worst frame. Raising the whole budget until the
    // worst frame meets the floor costs a dB of mean or more (18% of the bytes), so only
    // the frames below it are raised — by what they miss, estimated from the sample — and
    // the mean's budget is found again with them raised, so that the mean stays at T.
    // A sequence too small to sample is its own sample: its passes are what an encode at
    // their budgets delivers, so no guard is kept against a sample's error, and a pass
    // anywhere within the tolerance's promise may be taken as it is.
    let exact = matches!(sample, Draw::Whole);
    let promise = target - PROMISE_DB..=target + PROMISE_DB;
    let guard = if exact { 0.0 } else { FLOOR_GUARD_DB };
    let floor = target - cfg.worst_margin_db + guard;
    let (for_the_mean, mean_passes) = (internal_db, passes.len());
    let mut raise = match start.is_empty() {
        true => vec![0.0; frames],
        false => start.clone(),
    };
    let mut round = 0;
    let mut at = passes.clone();
    let mut raises = vec![start.clone()];
    // The estimate and the raises a round started from.
    let mut last: Option<(Vec<f64>, Vec<f64>)> = None;
    // A raised pass that delivers T (or a little above) with its worst frame on the floor
    // is one the pick below may take: a further round would buy its excess over T back
    // (on Jacksboro's clear day at 45 and 50 dB, 0.28 dB and 3% of the bytes) at two
    // passes, a third of the aim's time.
    let band = match exact {
        true => promise.clone(),
        false => target - CLOSE_DB..=target + PICK_ABOVE_DB,
    };
    let near = |p: &SamplePass| band.contains(&p.mean_db);
    let met = |at: &[SamplePass], t: f64, round: usize| {
        along(at, t, worst) >= floor
            || (round > 0 && at.iter().any(|p| near(p) && p.worst_db >= floor))
    };
    while floor.is_finite()
        && !met(&at, internal_db, round)
        && round < RAISE_ROUNDS
        && passes.len() + 2 <= MAX_PASSES
    {
        round += 1;
        let estimate = frames_at(&at, internal_db);
        // A raise buys a frame less than its dB (its neighbours' budgets and the mean's
        // lower budget pull it back): after a round, each frame's raise is scaled by what
        // the last one bought it.
        let bought = |f: usize| match &last {
            Some((e0, r0)) if raise[f] - r0[f] > 0.05 => {
                ((estimate[f] - e0[f]) / (raise[f] - r0[f])).clamp(0.25, 1.0)
            }
            _ => FIRST_BUY,
        };
        let next: Vec<f64> = (0..frames)
            .map(|f| {
                let miss = floor + RAISE_GUARD_DB - estimate[f];
                match miss > 0.0 {
                    true => (raise[f] + miss / bought(f)).min(crate::config::MAX_FRAME_RAISE_DB),
                    false => raise[f],
                }
            })
            .collect();
        // The raises lift the mean too: the round starts where the frames' estimates, each
        // lifted by what its raise is expected to buy, pool to T.
        let lifted: Vec<f64> = (0..frames)
            .map(|f| estimate[f] + (next[f] - raise[f]) * bought(f))
            .collect();
        let lift = pooled(&lifted) - pooled(&estimate);
        let slope = span_slope(&points(&at, mean)).unwrap_or(FIRST_SLOPE);
        let start = match lift.is_finite() && lift > 0.0 {
            true => internal_db - lift / slope,
            false => internal_db,
        };
        last = Some((estimate, std::mem::replace(&mut raise, next)));
        raises.push(raise.clone());
        let most = (MAX_PASSES - passes.len()).min(3);
        let mut this = Vec::new();
        internal_db = solve(&mut this, target, Some(start), mean, most, &mut |t| {
            run(t, &raise, round)
        })?;
        passes.extend(this.iter().cloned());
        at = this;
    }
    progress("aim", MAX_PASSES as u64, MAX_PASSES as u64);
    let mut predicted_db = along(&at, internal_db, mean);
    if round > 0 {
        // Of every pass, raised or not, whose mean is T (or a little above) and whose worst
        // frame meets the floor: the smallest. Where none does, the rounds ran out before
        // the raises reached the floor: they only cost bytes, and the mean's budget is
        // kept, raised as far as a mean of T + WORST_RAISE_DB where the passes without
        // raises bracket it.
        // The last round's own answer counts as a pass too: the budget its passes
        // bracket T at, with the mean and the worst frame read off the line between them
        // (they are the same raises).
        let interpolated = SamplePass {
            internal_db,
            round,
            mean_db: predicted_db,
            worst_db: along(&at, internal_db, worst),
            bytes: along(&at, internal_db, |p| p.bytes as f64) as u64,
            frame_db: Vec::new(),
        };
        // (Not where the sample is the sequence: its passes are exact, and the line between
        // two of them is what misleads on a sequence that small.)
        let pick = passes
            .iter()
            .chain(std::iter::once(&interpolated).filter(|_| !exact))
            .filter(|p| near(p) && p.worst_db >= floor)
            .min_by_key(|p| p.bytes);
        (round, internal_db, predicted_db) = match pick {
            Some(p) => (p.round, p.internal_db, p.mean_db),
            None => {
                let plain = &passes[..mean_passes];
                let t = interpolate(&points(plain, mean), target + WORST_RAISE_DB)
                    .map_or(for_the_mean, |t| t.max(for_the_mean));
                let promised = match exact {
                    true => promise,
                    false => target - CLOSE_DB..=target + PROMISE_DB,
                };
                match held(&passes, along(plain, t, worst), floor, promised) {
                    Some(p) => (p.round, p.internal_db, p.mean_db),
                    None => (0, t, along(plain, t, mean)),
                }
            }
        };
    }
    let frame_raise_db = raises.swap_remove(round);
    let added: Vec<f64> = frame_raise_db
        .iter()
        .enumerate()
        .map(|(i, r)| r - start.get(i).copied().unwrap_or(0.0))
        .collect();
    let aim = Aim {
        internal_db,
        predicted_db,
        raised_frames: added.iter().filter(|&&r| r > 0.0).count(),
        max_raise_db: added.iter().copied().fold(0.0, f64::max),
        frame_raise_db,
        passes,
        sample_texels,
        skipped: None,
    };
    Ok((aim, validated))
}

/// Where the raising rounds ran out short of the floor and the line between the plain
/// passes puts the worst frame at `line`, below `floor`, at the budget for the mean: a pass
/// measured with a mean in `promised` (the tolerance's promise: T − `CLOSE_DB` to T +
/// `PROMISE_DB` from a sample, T ± `PROMISE_DB` where the sample is the sequence) whose
/// worst frame was higher than the line's — the smallest that met the floor, else the one
/// whose worst frame was highest. `None`: keep the line's budget.
///
/// A day whose mean and worst frame jump with the budget (a plane of DC terms alone has an
/// error that is a sawtooth in its step) makes the line between two passes mislead, not
/// the passes themselves (BENCHMARKS.md, "The worst-frame floor").
fn held(
    passes: &[SamplePass],
    line: f64,
    floor: f64,
    promised: std::ops::RangeInclusive<f64>,
) -> Option<&SamplePass> {
    if line >= floor {
        return None;
    }
    let within: Vec<&SamplePass> = (passes.iter())
        .filter(|p| promised.contains(&p.mean_db))
        .collect();
    let met = (within.iter()).filter(|p| p.worst_db >= floor);
    met.min_by_key(|p| p.bytes)
        .or_else(|| {
            within
                .iter()
                .max_by(|a, b| a.worst_db.total_cmp(&b.worst_db))
        })
        .copied()
        .filter(|p| p.worst_db > line)
}

/// The pooled PSNR of frames of equal size with these PSNRs, dB: that of their mean
/// squared error (a frame coded exactly, at +∞, adds none).
fn pooled(frame_db: &[f64]) -> f64 {
    let mse = frame_db.iter().map(|d| 10f64.powf(-d / 10.0)).sum::<f64>() / frame_db.len() as f64;
    -10.0 * mse.log10()
}

/// Each frame's PSNR at internal tolerance `t`: from the pass nearest it, moved by the
/// difference in tolerance (a frame's PSNR follows the budget about dB for dB).
fn frames_at(passes: &[SamplePass], t: f64) -> Vec<f64> {
    let p = passes
        .iter()
        .min_by(|a, b| {
            (a.internal_db - t)
                .abs()
                .total_cmp(&(b.internal_db - t).abs())
        })
        .expect("one pass at least");
    p.frame_db.iter().map(|f| f + (t - p.internal_db)).collect()
}

/// The internal tolerance at which `of` (the mean or the worst frame) reaches `goal`:
/// a pass within `CLOSE_DB` of it, or the crossing of the line between the two passes
/// around it once they are within `BRACKET_DB` (the curve is close to straight over a dB
/// or two), found with secant steps (`next_tolerance`) while fewer than `most` passes
/// ran. Without either, the pass closest to the goal.
fn solve(
    passes: &mut Vec<SamplePass>,
    goal: f64,
    first: Option<f64>,
    of: impl Fn(&SamplePass) -> f64,
    most: usize,
    run: &mut impl FnMut(f64) -> Result<SamplePass, EncodeError>,
) -> Result<f64, EncodeError> {
    loop {
        let pts = points(passes, &of);
        let closest = pts
            .iter()
            .min_by(|a, b| (a.1 - goal).abs().total_cmp(&(b.1 - goal).abs()));
        if let Some(c) = closest.filter(|c| (c.1 - goal).abs() <= CLOSE_DB || !c.1.is_finite()) {
            return Ok(c.0);
        }
        if let Some(x) = interpolate(&pts, goal) {
            return Ok(x);
        }
        let next = match pts.is_empty() {
            true => first.unwrap_or(goal),
            false => next_tolerance(&pts, goal - CLOSE_DB, goal + CLOSE_DB),
        }
        // A budget outside what the encoder takes would fail the encode.
        .clamp(MIN_TOLERANCE_DB, MAX_TOLERANCE_DB);
        if passes.len() >= most || pts.iter().any(|q| q.0 == next) {
            return Ok(closest.expect("one pass at least").0);
        }
        passes.push(run(next)?);
    }
}

/// The passes as (internal tolerance, `of`, bytes): what the secant steps read.
fn points(passes: &[SamplePass], of: impl Fn(&SamplePass) -> f64) -> Vec<Pass> {
    passes
        .iter()
        .map(|p| (p.internal_db, of(p), p.bytes))
        .collect()
}

/// `of` at internal tolerance `t`, linear between the passes nearest it on either side
/// (the nearest pass's value outside them).
fn along(passes: &[SamplePass], t: f64, of: impl Fn(&SamplePass) -> f64) -> f64 {
    let below = passes
        .iter()
        .filter(|p| p.internal_db <= t)
        .max_by(|a, b| a.internal_db.total_cmp(&b.internal_db));
    let above = passes
        .iter()
        .filter(|p| p.internal_db >= t)
        .min_by(|a, b| a.internal_db.total_cmp(&b.internal_db));
    match (below, above) {
        (Some(a), Some(b)) if b.internal_db > a.internal_db => {
            let u = (t - a.internal_db) / (b.internal_db - a.internal_db);
            of(a) + u * (of(b) - of(a))
        }
        (Some(a), _) | (None, Some(a)) => of(a),
        (None, None) => f64::NAN,
    }
}

/// The internal tolerance at which the line between the passes nearest `target` on
/// either side crosses it, when they are within `BRACKET_DB` of each other.
fn interpolate(passes: &[Pass], target: f64) -> Option<f64> {
    let (Some(&(t0, p0, _)), Some(&(t1, p1, _))) = bracket(passes, target, target) else {
        return None;
    };
    (p1 - p0 <= BRACKET_DB).then(|| t0 + (target - p0) * (t1 - t0) / (p1 - p0))
}

/// What the aim codes its passes on.
enum Draw {
    /// The sequence itself: too few whole tiles to sample.
    Whole,
    /// A sample of its tiles.
    Tiles(Sample),
    /// No aim: the sample would not fit in memory (why).
    Skip(String),
}

/// A sample of the sequence: whole tiles of every frame, side by side.
struct Sample {
    frames: MemorySource,
    /// The full sequence's exposure (used for HDR): the metric must be the full encode's.
    exposure: f32,
}

impl Sample {
    /// Draws the sample, reading every frame once.
    fn draw(
        src: &dyn FrameSource,
        cfg: &EncoderConfig,
        progress: Progress,
    ) -> Result<Draw, EncodeError> {
        let info = src.info();
        crate::encode::check_shape(&info)?;
        let ts = cfg.tile_size;
        let (tx, ty) = (info.width / ts, info.height / ts);
        let whole = tx * ty;
        if whole < MIN_TILES {
            return Ok(Draw::Whole);
        }
        let tile_bytes = ts * ts * info.channels * 4 * info.frames.max(1);
        let want = (whole / SAMPLE_SHARE)
            .min(SAMPLE_TEXELS / (ts * ts))
            .max(MIN_TILES / SAMPLE_SHARE)
            .min(SAMPLE_BYTES / tile_bytes);
        if want < MIN_TILES / SAMPLE_SHARE {
            return Ok(Draw::Skip(format!(
                "{} frames: a sample of {} tiles would hold more than {} MB",
                info.frames,
                MIN_TILES / SAMPLE_SHARE,
                SAMPLE_BYTES >> 20
            )));
        }
        // A rectangle of tiles, about square.
        let cols = (want as f64).sqrt().floor() as usize;
        let rows = want / cols;
        let chosen = stratified(whole, cols * rows);
        let (w, h, ch) = (cols * ts, rows * ts, info.channels);
        let done = AtomicU64::new(0);
        // Each read holds a frame whole: as many at once as the encode's plan allows.
        let readers = crate::plan::plan(&info, cfg, rayon::current_num_threads())?.readers;
        let read: Vec<(Vec<f32>, f32)> = crate::plan::read_frames(info.frames, readers, |i| {
            let f = src.read(i)?;
            let mut out = vec![0f32; w * h * ch];
            for (k, &t) in chosen.iter().enumerate() {
                let (sx, sy) = ((t % tx) * ts, (t / tx) * ts);
                let (dx, dy) = ((k % cols) * ts, (k / cols) * ts);
                for y in 0..ts {
                    let s = ((sy + y) * info.width + sx) * ch;
                    let d = ((dy + y) * w + dx) * ch;
                    out[d..d + ts * ch].copy_from_slice(&f.data[s..s + ts * ch]);
                }
            }
            progress(
                "sample",
                done.fetch_add(1, Ordering::Relaxed) + 1,
                info.frames as u64,
            );
            Ok((out, vbim_format::curve::max_green(&f.data, ch)))
        })?;
        let greens: Vec<f32> = read.iter().map(|r| r.1).collect();
        let exposure = vbim_format::curve::exposure_from_max_greens(&greens);
        let frames = read.into_iter().map(|r| r.0).collect();
        let name = format!("{} (sample)", info.name);
        Ok(Draw::Tiles(Sample {
            frames: MemorySource::new(&name, w, h, ch, info.kind, frames),
            exposure,
        }))
    }
}

/// `k` of the tiles `0..n` (raster order), one from each of `k` equal runs, at an offset
/// within its run that a fixed hash picks: the sample covers the whole frame, and is the
/// same on every run.
fn stratified(n: usize, k: usize) -> Vec<usize> {
    (0..k)
        .map(|i| {
            let (a, b) = (i * n / k, (i + 1) * n / k);
            a + (splitmix(i as u64) % (b - a).max(1) as u64) as usize
        })
        .collect()
}

/// SplitMix64: a well-mixed 64-bit hash of `x`.
fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_pool_by_their_mean_squared_error() {
        // Two frames at 40 and 50 dB: MSE 1e-4 and 1e-5, mean 5.5e-5.
        let p = pooled(&[40.0, 50.0]);
        assert!((p - (-10.0 * 5.5e-5f64.log10())).abs() < 1e-9, "{p}");
        // A frame coded exactly adds no error; frames alike pool to themselves.
        assert!((pooled(&[40.0, f64::INFINITY]) - (40.0 + 10.0 * 2f64.log10())).abs() < 1e-9);
        assert!((pooled(&[45.0; 7]) - 45.0).abs() < 1e-9);
    }

    /// A pass at budget t: its round, mean, worst frame and bytes.
    fn pass(t: f64, round: usize, mean_db: f64, worst_db: f64, bytes: u64) -> SamplePass {
        SamplePass {
            internal_db: t,
            round,
            mean_db,
            worst_db,
            bytes,
            frame_db: Vec::new(),
        }
    }

    #[test]
    fn a_measured_pass_beats_a_line_that_misses_the_floor() {
        // The unseen winter day at 38 dB (floor 31, guarded 31.2): the plain passes at
        // 19.55 and 18.90 bracket T + 0.2, the line between them says a worst frame of
        // 30.7 there, and the raising rounds only lowered the worst frame.
        let passes = [
            pass(38.0, 0, 51.84, 44.14, 7741),
            pass(19.55, 0, 38.47, 31.19, 2505),
            pass(18.90, 0, 37.26, 29.06, 2424),
            pass(19.17, 1, 38.05, 29.59, 2481),
            pass(18.91, 2, 38.42, 29.01, 2413),
            pass(19.30, 3, 38.46, 30.26, 2733),
        ];
        let got = held(&passes, 30.7, 31.2, sampled(38.0)).expect("a pass");
        assert_eq!(got.internal_db, 19.55);
        // Of passes that met the floor within the promise, the smallest.
        let mut more = passes.to_vec();
        more.push(pass(19.6, 0, 38.40, 31.5, 2600));
        more.push(pass(19.7, 0, 38.30, 31.3, 2550));
        assert_eq!(
            held(&more, 30.7, 31.2, sampled(38.0)).unwrap().internal_db,
            19.7
        );
        // Never one whose mean leaves the promise, nor one worse than the line, and
        // nothing where the line meets the floor.
        assert!(held(&passes[..1], 30.7, 31.2, sampled(38.0)).is_none());
        assert!(held(&passes, 31.3, 31.2, sampled(38.0)).is_none());
        assert!(held(&passes, 29.0, 31.2, sampled(38.0)).unwrap().worst_db > 29.0);
        assert!(held(&passes[2..3], 30.7, 31.2, sampled(38.0)).is_none());
    }

    /// The promise `held` keeps a sampled day's passes to (T − 0.1 to T + 0.5).
    fn sampled(t: f64) -> std::ops::RangeInclusive<f64> {
        t - CLOSE_DB..=t + PROMISE_DB
    }

    #[test]
    fn a_sequence_that_is_its_own_sample_may_take_any_pass_within_the_promise() {
        // The demo's overcast sky track (128 × 32, 24 fps: its own sample), at 45 dB with
        // a floor of 38: the plain passes' line put the worst frame at 36.1 where the
        // mean is T + 0.2, and that budget's encode delivered 44.58 dB with a worst frame
        // of 32.87 (the mean and the worst frame jump with the budget on a sequence this
        // small). Its passes, measured on the sequence itself:
        let passes = [
            pass(45.0, 0, 57.42, 52.81, 2962),
            pass(28.44, 0, 44.58, 35.33, 2361),
            pass(30.93, 0, 46.47, 37.72, 2495),
            pass(28.84, 1, 44.40, 36.33, 2386),
            pass(29.63, 1, 45.71, 38.16, 2490),
            pass(29.16, 2, 44.87, 37.72, 2431),
            pass(29.33, 2, 45.70, 38.97, 2544),
            pass(29.15, 3, 44.76, 37.64, 2436),
            pass(29.47, 3, 45.92, 38.12, 2562),
        ];
        // A sample's band (T − 0.1 …) has none of them; the promise's whole band takes the
        // one whose worst frame is highest, 0.28 dB under the floor instead of 5.
        assert!(held(&passes, 36.1, 38.0, sampled(45.0)).is_none());
        let got = held(&passes, 36.1, 38.0, 44.5..=45.5).expect("a pass");
        assert_eq!((got.internal_db, got.round), (29.16, 2));
    }

    #[test]
    fn the_strata_cover_the_frame_once_each() {
        for (n, k) in [(1024, 256), (1000, 250), (4096, 256), (64, 64)] {
            let s = stratified(n, k);
            assert_eq!(s.len(), k);
            for (i, &t) in s.iter().enumerate() {
                assert!(
                    (i * n / k..(i + 1) * n / k).contains(&t),
                    "{n} {k}: {i} → {t}"
                );
            }
        }
    }
}
