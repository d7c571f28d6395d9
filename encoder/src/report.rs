//! What an encode did: size, rate, timing, how the terms were spent, and — measured by
//! decoding the file with the reference decoder — the error against the input.

use std::io::{Read, Seek};
use std::path::Path;

use serde::Serialize;
use vbim_format::chunk::TileMap;
use vbim_format::decode::{Decoder, Output};
use vbim_format::metrics::{Metric, SequenceError};
use vbim_format::{ColorEncoding, Header, Reader};

use crate::config::{MAX_TOLERANCE_DB, MIN_TOLERANCE_DB, PROMISE_DB, SAMPLE_ERROR_DB};
use crate::{EncodeError, EncoderConfig, FrameSource, InputKind, Progress};

/// What an encode did, as data: the stream's size and rate, how long it took, the budget it
/// was coded at (and how the aim found it), how the model spent its terms, and — once
/// [`EncodeReport::verify`] has decoded the stream — its error against the input
/// ([`Measured`]). `Display` prints it for people; serialised (JSON) it is the command's
/// `--report`.
#[derive(Clone, Debug, Serialize)]
pub struct EncodeReport {
    /// Frames encoded.
    pub frames: usize,
    /// Frame width, texels.
    pub width: usize,
    /// Frame height, texels.
    pub height: usize,
    /// The stream's size, bytes.
    pub bytes: u64,
    /// Bits per texel per frame.
    pub bpp: f64,
    /// Raw size (8-bit: 1 byte per value; HDR: half floats) over the file's size.
    pub ratio_to_raw: f64,
    /// Seconds spent coding (the pass over the sequence).
    pub encode_s: f64,
    /// Seconds in all, the aim's sample passes and the writing included.
    pub total_s: f64,
    /// Texel-frames encoded per second of encode time.
    pub texel_frames_per_s: f64,
    /// The tolerance asked for: the mean PSNR to deliver, dB.
    pub tolerance_db: f64,
    /// The budget the kept encode used, dB (the tolerance itself without `aim`).
    pub internal_tolerance_db: f64,
    /// What the analysis on a sample found (with `aim`).
    pub aim: Option<crate::Aim>,
    /// With `--exact`: every pass as (internal tolerance, delivered mean PSNR, bytes).
    pub calibration: Vec<(f64, f64, u64)>,
    /// How far below the tolerance the aim holds every frame, dB
    /// ([`EncoderConfig::worst_margin_db`]; infinite, `null` in JSON: no floor).
    pub worst_margin_db: f64,
    /// The highest polynomial degree in time a tile could take.
    pub max_degree: usize,
    /// Tiles × segments per luma degree (index = degree).
    pub degree_histogram: Vec<u64>,
    /// Tiles × segments per chroma degree (index = degree).
    pub chroma_degree_histogram: Vec<u64>,
    /// Share of tiles with curvature (luma degree > 1) whose chroma is linear (LRGB).
    pub lrgb_share: f64,
    /// Each segment's length, frames.
    pub segment_lengths: Vec<u32>,
    /// Keyframes in the stream.
    pub keyframes: u32,
    /// Of which intra (independently decodable).
    pub intra_keyframes: usize,
    /// Tile rows per band where the frames were coded a band at a time (the frames did
    /// not fit `memory_limit` whole); `None`: whole frames.
    pub band_tiles: Option<usize>,
    /// What the encode expected to hold at its peak, bytes (the plan's estimate).
    pub memory_estimate: u64,
    /// The stream's error against the input, once [`EncodeReport::verify`] has measured
    /// it (its fields appear at the top level of the JSON).
    #[serde(flatten)]
    pub measured: Option<Measured>,
    /// Luma degree of every tile in every segment: `tile_degrees[segment][tile]`, tiles in
    /// raster order of a `tiles.0 × tiles.1` grid (left out of the JSON report).
    #[serde(skip)]
    pub tile_degrees: Vec<Vec<u8>>,
    /// Tiles across and down.
    pub tiles: (usize, usize),
    /// The metric the error is measured in (from the input's kind).
    #[serde(skip)]
    pub(crate) metric: Metric,
}

/// A stream's error against its input, with the protocol's metrics (docs/CONVENTIONS.md):
/// what [`EncodeReport::verify`] measures by decoding the stream with the reference
/// decoder.
#[derive(Clone, Debug, Serialize)]
pub struct Measured {
    /// Mean PSNR over the frames, dB.
    pub mean_psnr: f64,
    /// The worst frame's PSNR, dB.
    pub worst_psnr: f64,
    /// The worst frame's number.
    pub worst_frame: usize,
    /// Largest error on the metric's 0–1 scale.
    pub max_abs_error: f64,
    /// HDR: largest relative error over texels brighter than 1% of white.
    pub max_rel_error: Option<f64>,
    /// The 99.9th percentile of every value's error, in 8-bit levels of the metric.
    pub p999_levels: f64,
    /// Each frame's PSNR, dB.
    pub frame_psnr: Vec<f64>,
}

impl EncodeReport {
    /// The report of an encode whose stream has header `h`, before any measurement.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        src: &dyn FrameSource,
        cfg: &EncoderConfig,
        h: &Header,
        boundaries: &[u32],
        tilemaps: &[TileMap],
        encode_s: f64,
        total_s: f64,
        metric: Metric,
    ) -> EncodeReport {
        let info = src.info();
        let texel_frames = (info.width * info.height * info.frames) as f64;
        let raw = texel_frames
            * info.channels as f64
            * if h.color == ColorEncoding::Srgb8 {
                1.0
            } else {
                2.0
            };
        let mut hist = vec![0u64; cfg.max_degree + 1];
        let mut chist = vec![0u64; cfg.max_degree + 1];
        let (mut curved, mut lrgb) = (0u64, 0u64);
        for t in tilemaps {
            for (l, c) in t.luma.iter().zip(&t.chroma) {
                hist[*l as usize] += 1;
                chist[*c as usize] += 1;
                if *l > 1 {
                    curved += 1;
                    if *c == 1 && info.channels == 3 {
                        lrgb += 1;
                    }
                }
            }
        }
        EncodeReport {
            frames: info.frames,
            width: info.width,
            height: info.height,
            bytes: h.file_size,
            bpp: h.file_size as f64 * 8.0 / texel_frames,
            ratio_to_raw: raw / h.file_size as f64,
            encode_s,
            total_s,
            texel_frames_per_s: texel_frames / encode_s.max(1e-9),
            tolerance_db: cfg.tolerance_db,
            internal_tolerance_db: cfg.tolerance_db,
            aim: None,
            calibration: Vec::new(),
            worst_margin_db: cfg.worst_margin_db,
            band_tiles: None,
            memory_estimate: 0,
            max_degree: cfg.max_degree,
            degree_histogram: hist,
            chroma_degree_histogram: chist,
            lrgb_share: if curved > 0 {
                lrgb as f64 / curved as f64
            } else {
                0.0
            },
            segment_lengths: boundaries.windows(2).map(|w| w[1] - w[0]).collect(),
            keyframes: h.keyframe_count,
            intra_keyframes: 0,
            measured: None,
            tile_degrees: tilemaps.iter().map(|t| t.luma.clone()).collect(),
            tiles: (
                info.width.div_ceil(cfg.tile_size),
                info.height.div_ceil(cfg.tile_size),
            ),
            metric,
        }
    }

    /// Decodes the encoded stream with the reference decoder and measures it against the
    /// input, filling in [`EncodeReport::measured`]. `name` names the stream in errors.
    pub fn verify<R: Read + Seek>(
        &mut self,
        src: &dyn FrameSource,
        encoded: R,
        name: &str,
        progress: Progress,
    ) -> Result<(), EncodeError> {
        let seq = measure(
            src,
            encoded,
            0..src.info().frames,
            name,
            self.metric,
            Tally::Levels,
            progress,
        )?;
        self.take(seq);
        Ok(())
    }

    /// [`EncodeReport::verify`] on the file at `path`, in parallel: the file is opened once
    /// per worker, and each worker decodes a run of frames.
    pub fn verify_file(
        &mut self,
        src: &dyn FrameSource,
        path: &Path,
        progress: Progress,
    ) -> Result<(), EncodeError> {
        let name = path.display().to_string();
        let open = || {
            std::fs::File::open(path)
                .map(std::io::BufReader::new)
                .map_err(|e| EncodeError::Verify {
                    stream: name.clone(),
                    source: e.into(),
                })
        };
        let seq = measure_parallel(src, &open, &name, self.metric, Tally::Levels, progress)?;
        self.take(seq);
        Ok(())
    }

    /// [`EncodeReport::verify`] on a stream in memory, in parallel.
    pub fn verify_bytes(
        &mut self,
        src: &dyn FrameSource,
        bytes: &[u8],
        name: &str,
        progress: Progress,
    ) -> Result<(), EncodeError> {
        self.verify_in_memory(src, bytes, name, Tally::Levels, progress)
    }

    /// [`EncodeReport::verify_bytes`]; with `Tally::Psnr` only the frames' PSNR is
    /// measured (the percentile is 0): what the aim's sample passes need, without a
    /// histogram count per value.
    pub(crate) fn verify_in_memory(
        &mut self,
        src: &dyn FrameSource,
        bytes: &[u8],
        name: &str,
        tally: Tally,
        progress: Progress,
    ) -> Result<(), EncodeError> {
        let open = || Ok(std::io::Cursor::new(bytes));
        let seq = measure_parallel(src, &open, name, self.metric, tally, progress)?;
        self.take(seq);
        Ok(())
    }

    /// What the encode promised and did not deliver, a sentence each for the user: with
    /// the aim, a mean PSNR further from T than the promise (about ±0.5 dB: beyond it by
    /// more than the sample's own error, 0.3 dB) or a worst frame that far below the floor
    /// ([`EncodeReport::worst_margin_db`] under T, which the aim sets for `--exact` too);
    /// with `--exact`, which measures the file itself, a mean below T. Each says why where
    /// the budget search ran into one of its bounds. Empty where everything holds, without
    /// the aim (the budget as it is promises nothing), or before [`EncodeReport::verify`].
    /// The file is written either way: it is a valid stream, only not the one asked for.
    pub fn shortfalls(&self) -> Vec<String> {
        let Some(m) = &self.measured else {
            return Vec::new();
        };
        let aim = self.aim.as_ref().filter(|a| a.skipped.is_none());
        let exact = !self.calibration.is_empty();
        if aim.is_none() && !exact {
            return Vec::new();
        }
        let t = self.tolerance_db;
        let budget = self.internal_tolerance_db;
        // The budget search stops at the budgets the encoder takes. At the finest, what is
        // left is what the curves in time miss (a segment too long for its degree: only
        // the settings change that) or the coded values' own precision (beyond about 90 dB).
        let finest = budget >= MAX_TOLERANCE_DB - 1e-6;
        let why_finest = format!(
            "the finest budget the encoder takes ({MAX_TOLERANCE_DB:.0} dB) delivers no more \
             with these settings (segments of {} frames, degree {} at most: shorter segments \
             or a higher `--max-degree` let the curves in time follow the light more closely)",
            self.segment_span(),
            self.max_degree
        );
        let mut out = Vec::new();
        // (`--exact` keeps a mean above T + 0.5 where the delivered PSNR steps over the
        // band: it promises T, and the band only when the steps allow.)
        let (low, high) = match exact {
            true => (t, f64::INFINITY),
            false => (
                t - PROMISE_DB - SAMPLE_ERROR_DB,
                t + PROMISE_DB + SAMPLE_ERROR_DB,
            ),
        };
        let mean = m.mean_psnr;
        if mean < low || mean > high {
            let mut s = format!(
                "the mean PSNR is {mean:.2} dB against the {t:.2} dB asked ({}{:.2} dB)",
                if mean > t { "+" } else { "−" },
                (mean - t).abs()
            );
            if mean < low && finest {
                s += &format!(": {why_finest}");
            } else if mean > high && budget <= MIN_TOLERANCE_DB + 1e-6 {
                s += &format!(
                    ": even the coarsest budget ({MIN_TOLERANCE_DB:.0} dB) codes it this finely"
                );
            } else if let Some(a) = aim.filter(|_| !exact) {
                s += &format!(
                    ": the sample predicted {:.2} dB (`--exact` encodes again until the mean \
                     holds)",
                    a.predicted_db
                );
            }
            out.push(s);
        }
        let floor = t - self.worst_margin_db;
        if m.worst_psnr < floor - SAMPLE_ERROR_DB {
            let mut s = format!(
                "the worst frame (frame {}) is {:.2} dB, below the floor of {floor:.2} dB \
                 (`--worst-margin` {:.1} dB under the tolerance)",
                m.worst_frame, m.worst_psnr, self.worst_margin_db
            );
            if finest && out.is_empty() {
                s += &format!(": {why_finest}");
            }
            out.push(s);
        }
        out
    }

    /// The segments' lengths as a span: `72` or `8–32`.
    fn segment_span(&self) -> String {
        let lo = self.segment_lengths.iter().min().copied().unwrap_or(0);
        let hi = self.segment_lengths.iter().max().copied().unwrap_or(0);
        match lo == hi {
            true => format!("{lo}"),
            false => format!("{lo}–{hi}"),
        }
    }

    /// The mean PSNR measured, dB (`None` before [`EncodeReport::verify`]).
    pub fn mean_psnr(&self) -> Option<f64> {
        self.measured.as_ref().map(|m| m.mean_psnr)
    }

    /// The worst frame's PSNR measured, dB (`None` before [`EncodeReport::verify`]).
    pub fn worst_psnr(&self) -> Option<f64> {
        self.measured.as_ref().map(|m| m.worst_psnr)
    }

    fn take(&mut self, seq: SequenceError) {
        let (worst_frame, worst_psnr) = seq.worst();
        self.measured = Some(Measured {
            mean_psnr: seq.mean_psnr(),
            worst_psnr,
            worst_frame,
            max_abs_error: seq.max_abs(),
            max_rel_error: matches!(self.metric, Metric::Hdr { .. }).then(|| seq.max_rel()),
            p999_levels: seq.p999_levels(),
            frame_psnr: seq.frames.iter().map(|f| f.psnr()).collect(),
        });
    }
}

impl EncodeReport {
    /// A PNG of how the terms were spent: one cell per tile, one row of maps per segment
    /// (left to right, top to bottom), coloured by luma degree from 1 (dark blue) to the
    /// maximum (yellow).
    pub fn write_degree_map(&self, path: &Path) -> Result<(), String> {
        let (tx, ty) = self.tiles;
        let segs = self.tile_degrees.len().max(1);
        let cols = (segs as f64).sqrt().ceil() as usize;
        let rows = segs.div_ceil(cols);
        let cell = (256 / tx.max(ty)).clamp(1, 8) as u32;
        let (mw, mh) = (tx as u32 * cell, ty as u32 * cell);
        let gap = 4u32;
        let w = cols as u32 * (mw + gap) + gap;
        let h = rows as u32 * (mh + gap) + gap;
        let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
        let dmax = self.max_degree.max(2) as f32;
        let colour = |d: u8| {
            let t = (d as f32 - 1.0) / (dmax - 1.0);
            let lerp = |a: f32, b: f32| (a + (b - a) * t).round() as u8;
            image::Rgb([lerp(30.0, 250.0), lerp(40.0, 220.0), lerp(120.0, 40.0)])
        };
        for (s, degs) in self.tile_degrees.iter().enumerate() {
            let (ox, oy) = (
                gap + (s % cols) as u32 * (mw + gap),
                gap + (s / cols) as u32 * (mh + gap),
            );
            for (t, &d) in degs.iter().enumerate() {
                let (cx, cy) = ((t % tx) as u32 * cell, (t / tx) as u32 * cell);
                for y in 0..cell {
                    for x in 0..cell {
                        img.put_pixel(ox + cx + x, oy + cy + y, colour(d));
                    }
                }
            }
        }
        // Through a temporary file, as every output: an interrupted run leaves no half
        // of it.
        vbim_files::write_atomic(
            path,
            |tmp| {
                img.save(tmp)
                    .map_err(|e| format!("{}: {e}", path.display()))
            },
            |e| format!("{}: {e}", path.display()),
        )
    }
}

/// Texel-frames of decoder state per worker, at most, when measuring in parallel: each
/// worker holds a decoder (its keyframes and terms), so large frames take fewer workers.
const PARALLEL_TEXELS: usize = 1 << 26;

/// What a verification measures.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Tally {
    /// Every frame's error and every value's, for the percentiles.
    Levels,
    /// Every frame's error alone.
    Psnr,
}

/// [`measure`] split into runs of frames, one decoder per run, on the worker pool (a run
/// starting mid-chain decodes its keyframes from the last intra one, as a seek does).
fn measure_parallel<R: Read + Seek + Send>(
    src: &dyn FrameSource,
    open: &(dyn Fn() -> Result<R, EncodeError> + Sync),
    name: &str,
    metric: Metric,
    tally: Tally,
    progress: Progress,
) -> Result<SequenceError, EncodeError> {
    use rayon::prelude::*;
    let info = src.info();
    let n = info.frames;
    let by_memory = (PARALLEL_TEXELS / (info.width * info.height).max(1)).max(1);
    let runs = rayon::current_num_threads().min(by_memory).min(n).max(1);
    let done = std::sync::atomic::AtomicU64::new(0);
    let counted = |_: &str, _: u64, _: u64| {
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress("verify", d, n as u64);
    };
    // Every run's reader is opened before any work: a file removed while it is being
    // measured (an interrupt removes an `--exact` pass) stays readable through them.
    let readers: Vec<R> = (0..runs).map(|_| open()).collect::<Result<_, _>>()?;
    let parts: Vec<SequenceError> = readers
        .into_par_iter()
        .enumerate()
        .map(|(k, reader)| {
            measure(
                src,
                reader,
                k * n / runs..(k + 1) * n / runs,
                name,
                metric,
                tally,
                &counted,
            )
        })
        .collect::<Result<_, _>>()?;
    let mut seq = SequenceError::default();
    for p in parts {
        seq.frames.extend(p.frames);
        seq.levels.merge(&p.levels);
    }
    Ok(seq)
}

/// Decodes frames `frames` of `encoded` and compares them with the source frames.
fn measure<R: Read + Seek>(
    src: &dyn FrameSource,
    encoded: R,
    frames: std::ops::Range<usize>,
    name: &str,
    metric: Metric,
    tally: Tally,
    progress: Progress,
) -> Result<SequenceError, EncodeError> {
    let info = src.info();
    let verify = |source| EncodeError::Verify {
        stream: name.to_string(),
        source,
    };
    let reader = Reader::open(encoded).map_err(verify)?;
    let h = reader.header().clone();
    if h.frame_count as usize != info.frames
        || h.width as usize != info.width
        || h.height as usize != info.height
    {
        return Err(verify(vbim_format::FormatError::Invalid(format!(
            "{}×{}×{} frames, the input is {}×{}×{}",
            h.width, h.height, h.frame_count, info.width, info.height, info.frames
        ))));
    }
    // The file was just written by this encoder: no limit (a large encode's verification
    // may need more than a player's default).
    let unlimited = vbim_format::Limits { memory: u64::MAX };
    let mut dec = Decoder::with_limits(reader, unlimited).map_err(verify)?;
    let mut seq = SequenceError::default();
    let mut out = vec![0f32; h.texel_count() * h.channels as usize];
    for i in frames {
        dec.frame(i as f64, Output::Stored, &mut out)
            .map_err(verify)?;
        let src = src.read(i)?;
        match tally {
            Tally::Levels => seq.add(metric, &src.data, &out),
            Tally::Psnr => seq.push(metric.compare(&src.data, &out)),
        }
        progress("verify", i as u64 + 1, info.frames as u64);
    }
    Ok(seq)
}

impl std::fmt::Display for EncodeReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "size        {} bytes, {:.4} bpp, {:.1}× smaller than raw",
            self.bytes, self.bpp, self.ratio_to_raw
        )?;
        if let Some(e) = &self.measured {
            let (m, w, wf) = (e.mean_psnr, e.worst_psnr, e.worst_frame);
            let max = e.max_abs_error * 255.0;
            let p999 = e.p999_levels;
            write!(f, "error       mean PSNR {m:.2} dB, worst frame {w:.2} dB (frame {wf}), largest error {max:.2} levels of 255 (p99.9 {p999:.3})")?;
            if let Some(r) = e.max_rel_error {
                write!(
                    f,
                    ", largest relative error {:.2}% (texels > 1% of white)",
                    r * 100.0
                )?;
            }
            writeln!(f)?;
        }
        writeln!(
            f,
            "time        encode {:.2} s ({:.2} M texel-frames/s), total {:.2} s",
            self.encode_s,
            self.texel_frames_per_s / 1e6,
            self.total_s
        )?;
        let total: u64 = self.degree_histogram.iter().sum();
        let hist: Vec<String> = self
            .degree_histogram
            .iter()
            .enumerate()
            .skip(1)
            .map(|(d, n)| format!("{d}: {:.1}%", 100.0 * *n as f64 / total.max(1) as f64))
            .collect();
        writeln!(
            f,
            "degrees     luma, share of tiles × segments: {}",
            hist.join("  ")
        )?;
        writeln!(
            f,
            "colour      LRGB (one luma curve + chroma from keyframes) on {:.1}% of curved tiles",
            self.lrgb_share * 100.0
        )?;
        let (mn, mx) = (
            self.segment_lengths.iter().min().unwrap_or(&0),
            self.segment_lengths.iter().max().unwrap_or(&0),
        );
        let mut lens: BTreeCount = BTreeCount::default();
        for l in &self.segment_lengths {
            lens.add(*l);
        }
        writeln!(
            f,
            "segments    {} ({}–{} frames; length×count {})",
            self.segment_lengths.len(),
            mn,
            mx,
            lens
        )?;
        writeln!(
            f,
            "keyframes   {} ({} intra)",
            self.keyframes, self.intra_keyframes
        )?;
        let held = match self.band_tiles {
            Some(b) => format!(
                "in bands of {b} tile row(s) of {} ({} bands)",
                self.tiles.1,
                self.tiles.1.div_ceil(b)
            ),
            None => "whole frames".into(),
        };
        write!(
            f,
            "memory      {held}, about {:.2} GB at the peak (estimated)",
            self.memory_estimate as f64 / 1e9
        )?;
        if let Some(why) = self.aim.as_ref().and_then(|a| a.skipped.as_ref()) {
            write!(
                f,
                "\naim         skipped ({why}): the tolerance is the budget as it is"
            )?;
        } else if let Some(a) = &self.aim {
            write!(
                f,
                "\naim         tolerance {:.2} dB: internal budget {:.2} dB, {:.2} dB on a sample of {} texels a frame after {} pass(es){}",
                self.tolerance_db,
                a.internal_db,
                a.predicted_db,
                a.sample_texels,
                a.passes.len(),
                match a.raised_frames {
                    0 => String::new(),
                    n => format!(
                        ", {n} frame(s) raised by up to {:.1} dB for the worst frame",
                        a.max_raise_db
                    ),
                }
            )?;
        }
        if !self.calibration.is_empty() {
            let p: Vec<String> = self
                .calibration
                .iter()
                .map(|(t, p, b)| format!("{t:.2} → {p:.2} dB, {b} B"))
                .collect();
            write!(
                f,
                "\nexact       tolerance {:.2} dB after {} pass(es): {}",
                self.tolerance_db,
                self.calibration.len(),
                p.join("; ")
            )?;
        }
        Ok(())
    }
}

#[derive(Default)]
struct BTreeCount(std::collections::BTreeMap<u32, u32>);
impl BTreeCount {
    fn add(&mut self, k: u32) {
        *self.0.entry(k).or_default() += 1;
    }
}
impl std::fmt::Display for BTreeCount {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v: Vec<String> = self.0.iter().map(|(k, n)| format!("{k}×{n}")).collect();
        write!(f, "{}", v.join(" "))
    }
}

/// Bytes of the lossless baseline the reports compare with: every frame on its own
/// through zstd at `level`, as half floats (HDR) or as its 8-bit code values (8-bit
/// input, exactly what it holds).
pub fn lossless_baseline(
    src: &dyn FrameSource,
    level: i32,
    progress: Progress,
) -> Result<u64, EncodeError> {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicU64, Ordering};
    let info = src.info();
    let done = AtomicU64::new(0);
    let sizes: Vec<u64> = (0..info.frames)
        .into_par_iter()
        .map(|i| {
            let f = src.read(i)?;
            let bytes: Vec<u8> = match info.kind {
                InputKind::Srgb8 => f.data.iter().map(|v| (v * 255.0).round() as u8).collect(),
                InputKind::Hdr => f
                    .data
                    .iter()
                    .flat_map(|v| half::f16::from_f32(*v).to_le_bytes())
                    .collect(),
            };
            let z = zstd::bulk::compress(&bytes, level)
                .map_err(|e| EncodeError::Input(format!("zstd: {e}")))?;
            progress(
                "lossless",
                done.fetch_add(1, Ordering::Relaxed) + 1,
                info.frames as u64,
            );
            Ok(z.len() as u64)
        })
        .collect::<Result<_, EncodeError>>()?;
    Ok(sizes.iter().sum())
}
