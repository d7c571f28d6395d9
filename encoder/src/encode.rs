//! The encode itself: validate every frame, choose the coded domain, then walk the
//! sequence front to back — segment length (one segment ahead), closing keyframe, the
//! segment's model — over a window of frames that holds two segments' worth at a time:
//! subsampled for the search, and whole (as far as the memory limit allows) or a band of
//! tile rows at a time for the model (module `plan`).

use std::collections::BTreeMap;
use std::io::{Seek, Write};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;
use vbim_format::chunk::TileMap;
use vbim_format::curve::exposure_from_max_greens;
use vbim_format::index::{FLAG_INTRA, FLAG_OPTIONAL};
use vbim_format::metrics::Metric;
use vbim_format::{ChunkKind, ColorEncoding, Header, Transfer};

use crate::domain::Domain;
use crate::keyframe::{self, KeyParams};
use crate::model::{self, CodedFrame, Projectors, Rows, SegmentInput, SegmentParams};
use crate::output::{header_for, pack_metadata, PendingChunk};
use crate::plan::Plan;
use crate::reach;
use crate::segment::Search;
use crate::{
    ConfigError, EncodeError, EncodeReport, EncoderConfig, FrameSource, InputKind, Progress,
    SegmentMode,
};

/// Error budgets, as shares of the total RMS error the tolerance allows. They were set by
/// measurement (BENCHMARKS.md, "What moved the encoder …"): a tight fit (long segments
/// only where the curve really is smooth) with coarsely quantised bubble planes gives the
/// fewest bytes at a given mean PSNR. The bubble share exceeds 1 because dead-zone
/// quantisation of sparse planes errs far below the step²/12 the step is computed from;
/// the measured error still stays under the tolerance (`--tolerance T` delivers T + 3 to
/// 5 dB on the benchmark days, whose nights sit far below the budget).
const FIT_SHARE: f64 = 0.3;
const KEY_SHARE: f64 = 0.6;
const BUBBLE_SHARE: f64 = 1.2;

/// A coded sequence, ready to write.
pub(crate) struct Coded {
    /// The header, before the writer fills in sizes and checksums.
    pub header: Header,
    pub chunks: Vec<PendingChunk>,
    /// Segment boundaries, frames (first 0, last the end).
    pub boundaries: Vec<u32>,
    /// Each segment's tile degrees.
    pub tilemaps: Vec<TileMap>,
    pub intra_keyframes: usize,
    pub metric: Metric,
    /// How the frames were held.
    pub plan: Plan,
    /// When coding started (after validation).
    pub started: Instant,
}

/// Frames coded once and kept for later encodes of the same frames at the same exposure:
/// the aim codes its sample a few times at different budgets, and coding a frame (its
/// transfer curve, colour transform and sensitivity) is a fifth of an encode's work.
pub(crate) struct CodedCache {
    /// The exposure the frames were coded at (the domain's curve depends on it).
    exposure: f32,
    /// Frame by number; frames past the end are not kept (the memory it may hold).
    frames: Vec<std::sync::OnceLock<Arc<CodedFrame>>>,
}

impl CodedCache {
    /// A cache for `src` coded at `exposure` in tiles of `tile` texels, keeping its first
    /// frames within `bytes`.
    pub fn new(src: &dyn FrameSource, exposure: f32, tile: usize, bytes: usize) -> CodedCache {
        let i = src.info();
        // A coded frame: its planes and its sensitivity, f32, padded to whole tiles.
        let padded = i.width.div_ceil(tile) * tile * i.height.div_ceil(tile) * tile;
        let per_frame = (padded * (i.channels + 1) * 4).max(1);
        let kept = (bytes / per_frame).min(i.frames);
        CodedCache {
            exposure,
            frames: (0..kept).map(|_| std::sync::OnceLock::new()).collect(),
        }
    }
}

/// Codes `src` with `cfg` (inside the worker pool). `validated`: every frame was already
/// read and checked, and this is the sequence's exposure (used for HDR); `None` reads and
/// checks them first.
pub(crate) fn code_sequence(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    validated: Option<f32>,
    cache: Option<&CodedCache>,
    progress: Progress,
) -> Result<Coded, EncodeError> {
    let info = src.info();
    let cache = cache.filter(|c| Some(c.exposure) == validated);
    let n = info.frames;
    check_shape(&info)?;
    let raise = Raise::new(&cfg.frame_raise_db, n)?;
    let plan = crate::plan::plan(&info, cfg, rayon::current_num_threads())?;
    // Pass 1: validate every frame before any work, and learn the exposure (unless a
    // sample's reading did both).
    let e = match validated {
        Some(e) => e,
        None => {
            let done = AtomicU64::new(0);
            let greens = crate::plan::read_frames(n, plan.readers, |i| {
                let f = src.read(i)?;
                progress(
                    "validate",
                    done.fetch_add(1, Ordering::Relaxed) + 1,
                    n as u64,
                );
                Ok(vbim_format::curve::max_green(&f.data, f.channels))
            })?;
            exposure_from_max_greens(&greens)
        }
    };
    let (color, transfer, metric) = match info.kind {
        InputKind::Srgb8 => (ColorEncoding::Srgb8, Transfer::Srgb, Metric::Srgb8),
        InputKind::Hdr => (
            ColorEncoding::LinearHdr,
            Transfer::LogToe {
                v0: (2.0f32).powi(-10) / e,
            },
            Metric::Hdr { exposure: e },
        ),
    };
    let dom = Domain::new(
        transfer,
        metric,
        info.channels,
        info.width,
        info.height,
        cfg.tile_size,
    );
    let eps = 10f64.powf(-cfg.tolerance_db / 20.0);
    let sp = SegmentParams {
        max_degree: cfg.max_degree,
        fit_budget: FIT_SHARE * eps,
        quant_budget: BUBBLE_SHARE * eps,
        chroma_step_factor: cfg.chroma_step_factor,
        deadzone: cfg.deadzone(),
        rate_lambda: cfg.rate_lambda(),
        zstd_level: cfg.zstd_level,
    };
    let kp = KeyParams {
        budget: KEY_SHARE * eps,
        chroma_step_factor: cfg.chroma_step_factor,
        deadzone: cfg.deadzone(),
        rate_lambda: cfg.rate_lambda(),
    };
    let started = Instant::now();

    // Pass 2: segments, keyframes and models, front to back over a window of frames.
    let looping = cfg.looping;
    let end = if looping { n } else { n - 1 } as u32;
    let intra_every = cfg.intra_interval_frames();
    let sub_dom = dom.subsampled(cfg.tile_size, cfg.search_stride);
    let bands = (dom.ph / cfg.tile_size).div_ceil(plan.band_tiles) as u64;
    let mut window = Window::new(src, &dom, cfg, plan, end, cache);
    let mut chunks: Vec<PendingChunk> = Vec::new();
    if let Some(m) = &cfg.metadata {
        chunks.push(PendingChunk {
            kind: ChunkKind::Metadata,
            flags: FLAG_OPTIONAL,
            number: 0,
            frames: (0, 0),
            bytes: pack_metadata(m, cfg.zstd_level)?,
            raw: false,
        });
    }
    // The header keyframes are decoded against (their shape and curve only).
    let key_header = header_for(&info, cfg, (color, transfer), 0, 0, 1);
    let mut projectors = Projectors::default();
    // Each segment's length is found one segment ahead: a keyframe is coded once the
    // segments on both sides of it are known, for its error reaches into both (`reach`).
    let longest = match cfg.segment {
        SegmentMode::Fixed(l) => l,
        SegmentMode::Auto { max } => max,
    };
    let length = |window: &mut Window, projectors: &mut Projectors, b: u32| {
        let max_len = longest.min(end - b);
        window.load(b + max_len)?;
        let len = match cfg.segment {
            SegmentMode::Fixed(_) => max_len,
            SegmentMode::Auto { .. } => Search {
                dom: &sub_dom,
                tile: Domain::sub_tile(cfg.tile_size, cfg.search_stride),
                window: &window.subs,
                cfg,
                params: &sp,
            }
            .length(b, max_len, projectors),
        };
        // The search is done with the segment's inner frames: its keyframe needs only
        // their sensitivity.
        window.keep_sensitivity_only(b + 1..b + len);
        Ok::<u32, EncodeError>(len)
    };
    window.load(0)?;
    let mut next_len = length(&mut window, &mut projectors, 0)?;
    // Keyframe 0 of a loop also closes the last segment, not known yet: taken as the
    // longest one allowed.
    let loop_end = match looping {
        true => window.loop_end(longest.min(n as u32))?,
        false => Vec::new(),
    };
    let sens = window.key_sensitivity(0, None, next_len, &loop_end);
    drop(loop_end);
    let first = keyframe::code(&*window.full(0)?, None, &key_header, raise.key(kp, 0), sens)?;
    let k0 = first.decoded.clone();
    chunks.push(keyframe_chunk(first, 0, 0));
    let mut boundaries = vec![0u32];
    let mut prev_key = k0.clone();
    let mut last_intra = 0u32;
    let mut intra_keyframes = 1; // keyframe 0
    let mut tilemaps = Vec::new();
    let mut b = 0u32;
    while b < end {
        let len = next_len;
        let e = b + len;
        let s = boundaries.len() as u32 - 1;
        next_len = if e < end {
            length(&mut window, &mut projectors, e)?
        } else {
            0
        };
        // The keyframe closing this segment (keyframe 0 again at a loop's end): predicted
        // from the previous one while the intra interval allows it.
        let k1 = if looping && e == end {
            k0.clone()
        } else {
            let prev = (e - last_intra <= intra_every).then(|| prev_key.as_slice());
            let sens = window.key_sensitivity(e, Some(b), next_len, &[]);
            let k = keyframe::code(&*window.full(e)?, prev, &key_header, raise.key(kp, e), sens)?;
            if k.intra {
                last_intra = e;
                intra_keyframes += 1;
            }
            let decoded = k.decoded.clone();
            chunks.push(keyframe_chunk(k, s + 1, e));
            decoded
        };
        let input = SegmentInput {
            k0: &prev_key,
            k1: &k1,
            inner: (e - b).saturating_sub(1) as usize,
            frame_sens_sq: (b + 1..e).map(|i| window.sens_sq[&i]).collect(),
            band_tiles: plan.band_tiles,
            rows: |rows: std::ops::Range<usize>| {
                // Progress in frames × bands: a segment of a large frame takes a while.
                let band = (rows.start / (plan.band_tiles * cfg.tile_size)) as u64;
                let done = b as u64 * bands + (e - b) as u64 * band;
                progress("encode", done, end as u64 * bands);
                window.rows(b + 1..e, rows)
            },
        };
        let scaled = raise.segment(&sp, b..=e);
        let code = model::code_segment(&dom, cfg.tile_size, input, &mut projectors, &scaled)?;
        // Playback order: a segment's tile map and coefficients follow its closing keyframe.
        let parts = [
            (ChunkKind::TileMap, code.tilemap_bytes),
            (ChunkKind::Coefficients, code.coeff_bytes),
        ];
        for (kind, bytes) in parts {
            chunks.push(PendingChunk {
                kind,
                flags: 0,
                number: s,
                frames: (b, e),
                raw: kind == ChunkKind::Coefficients,
                bytes,
            });
        }
        tilemaps.push(code.tiles);
        boundaries.push(e);
        prev_key = k1;
        // Frames before the new boundary are done (frame 0 stays for a loop's end).
        window.forget_before(e);
        b = e;
        progress("encode", b as u64 * bands, end as u64 * bands);
    }
    let segments = boundaries.len() as u32 - 1;
    let keyframes = if looping { segments } else { segments + 1 };
    let mut header = header_for(
        &info,
        cfg,
        (color, transfer),
        segments,
        keyframes,
        chunks.len() as u32,
    );
    crate::payloads::code(
        &mut header,
        &mut chunks,
        &tilemaps,
        cfg.format,
        (cfg.zstd_level, cfg.lanes),
        progress,
    )?;
    Ok(Coded {
        header,
        chunks,
        boundaries,
        tilemaps,
        intra_keyframes,
        metric,
        plan,
        started,
    })
}

/// The budgets' scale for frames raised by [`EncoderConfig::frame_raise_db`]: the
/// quantisation budgets of the keyframe at a frame and of the bubble planes of the segment
/// around it; a segment takes the largest raise among its frames. The fit budget, which
/// sets segment lengths, is left alone: tightening it too moved the worst frame less
/// and erratically (shorter segments, more keyframes; BENCHMARKS.md, "The worst-frame floor").
struct Raise<'a> {
    db: &'a [f64],
}

impl<'a> Raise<'a> {
    fn new(db: &'a [f64], frames: usize) -> Result<Self, ConfigError> {
        if !db.is_empty() && db.len() != frames {
            return Err(ConfigError::FrameRaiseLength {
                given: db.len(),
                frames,
            });
        }
        Ok(Raise { db })
    }

    /// The budget factor of the frames in `f` (frame numbers run past the end at a loop's
    /// seam).
    fn scale(&self, f: std::ops::RangeInclusive<u32>) -> f64 {
        if self.db.is_empty() {
            return 1.0;
        }
        let n = self.db.len();
        let most = f.map(|i| self.db[i as usize % n]).fold(0.0, f64::max);
        10f64.powf(-most / 20.0)
    }

    /// Keyframe `e`'s parameters (its own frame's raise: its error is whole there, and
    /// fades into the segments on either side).
    fn key(&self, kp: KeyParams, e: u32) -> KeyParams {
        KeyParams {
            budget: kp.budget * self.scale(e..=e),
            ..kp
        }
    }

    /// The parameters of the segment over frames `f` (its bubble planes' budget).
    fn segment(&self, sp: &SegmentParams, f: std::ops::RangeInclusive<u32>) -> SegmentParams {
        let s = self.scale(f);
        SegmentParams {
            quant_budget: sp.quant_budget * s,
            ..*sp
        }
    }
}

/// Refuses a sequence longer or larger than the format allows (before reading a frame).
pub(crate) fn check_shape(info: &crate::SourceInfo) -> Result<(), EncodeError> {
    let n = info.frames;
    if n > vbim_format::limits::MAX_FRAMES as usize {
        return Err(EncodeError::Input(format!(
            "{n} frames (at most {})",
            vbim_format::limits::MAX_FRAMES
        )));
    }
    if info.width > vbim_format::limits::MAX_DIMENSION as usize
        || info.height > vbim_format::limits::MAX_DIMENSION as usize
    {
        return Err(EncodeError::Input(format!(
            "{}: {}×{} is larger than 16384²",
            info.name, info.width, info.height
        )));
    }
    Ok(())
}

/// Keyframe `number`'s chunk, at frame `frame`.
fn keyframe_chunk(k: keyframe::CodedKeyframe, number: u32, frame: u32) -> PendingChunk {
    PendingChunk {
        kind: ChunkKind::Keyframe,
        flags: if k.intra { FLAG_INTRA } else { 0 },
        number,
        frames: (frame, frame),
        bytes: k.bytes,
        raw: true,
    }
}

/// The frames the encoder holds: read in order, and dropped once behind the current
/// boundary, so that memory stays at one segment's worth of frames — subsampled for the
/// search always, whole only when the plan allows it.
struct Window<'a> {
    src: &'a dyn FrameSource,
    dom: &'a Domain,
    tile: usize,
    stride: usize,
    plan: Plan,
    /// Each frame as the search reads it.
    subs: BTreeMap<u32, Arc<CodedFrame>>,
    /// Each frame whole (when the plan holds them).
    full: BTreeMap<u32, Arc<CodedFrame>>,
    /// Each frame's sum of squared sensitivities over the whole frame.
    sens_sq: BTreeMap<u32, f64>,
    /// Frames in the sequence (the window's frame numbers run past it at a loop's end).
    frames_in_source: usize,
    /// The first frame never loaded.
    next: u32,
    /// The last frame there is (frame 0 again at a loop's end).
    end: u32,
    /// Frames coded by an earlier encode of the same frames.
    cache: Option<&'a CodedCache>,
}

impl<'a> Window<'a> {
    fn new(
        src: &'a dyn FrameSource,
        dom: &'a Domain,
        cfg: &EncoderConfig,
        plan: Plan,
        end: u32,
        cache: Option<&'a CodedCache>,
    ) -> Self {
        Window {
            src,
            dom,
            tile: cfg.tile_size,
            stride: cfg.search_stride,
            plan,
            subs: BTreeMap::new(),
            full: BTreeMap::new(),
            sens_sq: BTreeMap::new(),
            frames_in_source: src.info().frames,
            next: 0,
            end,
            cache,
        }
    }

    /// Frame `i` of the window, read whole and coded (or as the cache kept it).
    fn read_full(&self, i: u32) -> Result<Arc<CodedFrame>, EncodeError> {
        let i = i as usize % self.frames_in_source;
        let kept = self.cache.and_then(|c| c.frames.get(i));
        if let Some(f) = kept.and_then(|k| k.get()) {
            return Ok(f.clone());
        }
        let f = self.src.read(i)?;
        let (planes, sens) = self.dom.code(&f.data);
        let f = Arc::new(CodedFrame { planes, sens });
        Ok(match kept {
            Some(k) => k.get_or_init(|| f).clone(),
            None => f,
        })
    }

    /// Reads and codes every frame up to `upto` not read yet (in parallel, as many at
    /// once as the plan allows).
    fn load(&mut self, upto: u32) -> Result<(), EncodeError> {
        let upto = upto.min(self.end);
        if upto < self.next {
            return Ok(());
        }
        let missing: Vec<u32> = (self.next..=upto).collect();
        self.next = upto + 1;
        for group in missing.chunks(self.plan.readers.max(1)) {
            let fresh: Vec<(u32, f64, CodedFrame, Arc<CodedFrame>)> = group
                .par_iter()
                .map(|&i| {
                    let f = self.read_full(i)?;
                    let sens_sq = f.sens.iter().map(|v| (*v as f64).powi(2)).sum::<f64>();
                    let (planes, sens) =
                        self.dom
                            .subsample(&f.planes, &f.sens, self.tile, self.stride);
                    Ok((i, sens_sq, CodedFrame { planes, sens }, f))
                })
                .collect::<Result<_, EncodeError>>()?;
            for (i, sens_sq, sub, full) in fresh {
                self.subs.insert(i, Arc::new(sub));
                self.sens_sq.insert(i, sens_sq);
                // Whole: held while there is room (in order, so the segment being coded
                // comes first); the rest is read again when its segment is coded.
                if self.plan.whole && self.full.len() < self.plan.whole_frames {
                    self.full.insert(i, full);
                }
            }
        }
        Ok(())
    }

    /// Frame `i` whole: held, or read again.
    fn full(&self, i: u32) -> Result<Arc<CodedFrame>, EncodeError> {
        match self.full.get(&i) {
            Some(f) => Ok(f.clone()),
            None => self.read_full(i),
        }
    }

    /// Frames `frames`, cut to padded rows `rows`: the held frames when whole, else read
    /// from the input.
    fn rows(
        &self,
        frames: std::ops::Range<u32>,
        rows: std::ops::Range<usize>,
    ) -> Result<Rows, EncodeError> {
        if self.plan.whole {
            debug_assert_eq!(rows, 0..self.dom.ph);
            let idx: Vec<u32> = frames.collect();
            return Ok(Rows {
                first: 0,
                frames: idx
                    .par_iter()
                    .map(|&i| self.full(i))
                    .collect::<Result<_, EncodeError>>()?,
            });
        }
        let src_rows = self.dom.source_rows(&rows);
        let idx: Vec<u32> = frames.collect();
        let frames = idx
            .par_iter()
            .map(|&i| {
                let f = self
                    .src
                    .read_rows(i as usize % self.frames_in_source, src_rows.clone())?;
                let (planes, sens) = self.dom.code_rows(&f.data, src_rows.start, rows.clone());
                Ok(Arc::new(CodedFrame { planes, sens }))
            })
            .collect::<Result<_, EncodeError>>()?;
        Ok(Rows {
            first: rows.start,
            frames,
        })
    }

    /// The RMS sensitivity keyframe `e`'s error is seen at ([`reach::keyframe`]): the
    /// segment from `before` ends at it, one of `after` frames starts there, and `more`
    /// frames (weight, subsampled sensitivity) reach it too.
    fn key_sensitivity(
        &self,
        e: u32,
        before: Option<u32>,
        after: u32,
        more: &[(f32, Vec<f32>)],
    ) -> f64 {
        let sens = |j: u32| self.subs[&j].sens.as_slice();
        let mut reached: Vec<(f32, &[f32])> = Vec::new();
        if let Some(b) = before {
            reached.extend(reach::weights(e - b, false).map(|(j, w)| (w, sens(b + j))));
        }
        reached.extend(reach::weights(after, true).map(|(j, w)| (w, sens(e + j))));
        reached.extend(more.iter().map(|(w, s)| (*w, s.as_slice())));
        let own = (self.sens_sq[&e] / (self.dom.pw * self.dom.ph) as f64).sqrt();
        reach::keyframe(sens(e), own, &reached)
    }

    /// The subsampled sensitivity of the last `len − 1` frames of the sequence, as the
    /// segment of `len` frames that a loop's end would close at keyframe 0 weighs them:
    /// keyframe 0 is coded first, before that segment is known (the frames are read
    /// once more when their turn comes).
    fn loop_end(&self, len: u32) -> Result<Vec<(f32, Vec<f32>)>, EncodeError> {
        let n = self.frames_in_source as u32;
        let frames: Vec<(u32, f32)> = reach::weights(len, false)
            .map(|(j, w)| (n - len + j, w))
            .collect();
        crate::plan::read_frames(frames.len(), self.plan.readers, |k| {
            let (i, w) = frames[k];
            if let Some(f) = self.subs.get(&i) {
                return Ok((w, f.sens.clone()));
            }
            let f = self.read_full(i)?;
            let (_, sens) = self
                .dom
                .subsample(&f.planes, &f.sens, self.tile, self.stride);
            Ok((w, sens))
        })
    }

    /// Drops the subsampled planes of `frames`, keeping their sensitivity.
    fn keep_sensitivity_only(&mut self, frames: std::ops::Range<u32>) {
        for i in frames {
            if let Some(f) = self.subs.get_mut(&i) {
                match Arc::get_mut(f) {
                    Some(f) => f.planes = Vec::new(),
                    None => {
                        *f = Arc::new(CodedFrame {
                            planes: Vec::new(),
                            sens: f.sens.clone(),
                        })
                    }
                }
            }
        }
    }

    /// Drops the frames before `b`, except frame 0's subsample (a loop's end needs it).
    fn forget_before(&mut self, b: u32) {
        self.subs.retain(|&i, _| i >= b || i == 0);
        self.full.retain(|&i, _| i >= b);
        self.sens_sq.retain(|&i, _| i >= b);
    }
}

/// One encode at `cfg`'s budget as it is (inside the worker pool). `validated`: the
/// frames were checked already and this is the exposure to code them at (a sample must
/// be measured as the whole sequence is).
pub(crate) fn encode_in_pool<W: Write + Seek>(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    validated: Option<f32>,
    cache: Option<&CodedCache>,
    out: W,
    progress: Progress,
) -> Result<EncodeReport, EncodeError> {
    let t_start = std::time::Instant::now();
    let coded = code_sequence(src, cfg, validated, cache, progress)?;
    write_coded(src, cfg, coded, out, t_start)
}

/// Writes a coded sequence and reports on it.
pub(crate) fn write_coded<W: Write + Seek>(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    coded: Coded,
    out: W,
    t_start: std::time::Instant,
) -> Result<EncodeReport, EncodeError> {
    let header = crate::output::write_chunks(out, coded.header, &coded.chunks)?;
    let mut rep = EncodeReport::new(
        src,
        cfg,
        &header,
        &coded.boundaries,
        &coded.tilemaps,
        coded.started.elapsed().as_secs_f64(),
        t_start.elapsed().as_secs_f64(),
        coded.metric,
    );
    rep.intra_keyframes = coded.intra_keyframes;
    rep.band_tiles = (!coded.plan.whole).then_some(coded.plan.band_tiles);
    rep.memory_estimate = coded.plan.estimate;
    Ok(rep)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MemorySource;

    /// A small HDR day: light rising and setting with a moving edge.
    fn day(w: usize, h: usize, n: usize) -> MemorySource {
        let frames = (0..n)
            .map(|t| {
                let sun = (std::f32::consts::PI * t as f32 / n as f32).sin();
                (0..w * h)
                    .flat_map(|i| {
                        let (x, y) = ((i % w) as f32, (i / w) as f32);
                        let edge = 1.0 / (1.0 + (-(x - 3.0 * t as f32) * 0.5).exp());
                        let v = 1e-3 + sun * (0.2 + 0.6 * edge) * (0.9 + 0.1 * (y * 0.2).sin());
                        [v, 0.9 * v, 0.7 * v]
                    })
                    .collect()
            })
            .collect();
        MemorySource::new("cache", w, h, 3, InputKind::Hdr, frames)
    }

    fn encoded(src: &MemorySource, e: f32, cache: Option<&CodedCache>) -> Vec<u8> {
        let cfg = EncoderConfig {
            aim: false,
            ..EncoderConfig::preset(crate::Preset::Default)
        };
        let mut out = std::io::Cursor::new(Vec::new());
        encode_in_pool(src, &cfg, Some(e), cache, &mut out, &|_, _, _| {}).unwrap();
        out.into_inner()
    }

    #[test]
    fn frames_coded_once_give_the_same_file_as_frames_coded_again() {
        let src = day(48, 32, 20);
        let greens: Vec<f32> = (0..20)
            .map(|i| vbim_format::curve::max_green(&src.read(i).unwrap().data, 3))
            .collect();
        let e = exposure_from_max_greens(&greens);
        let plain = encoded(&src, e, None);
        // Room for half the frames: the rest are coded every time.
        let per_frame = 48 * 32 * 4 * 4;
        let cache = CodedCache::new(&src, e, 16, 10 * per_frame);
        assert_eq!(cache.frames.len(), 10);
        assert_eq!(encoded(&src, e, Some(&cache)), plain, "filling the cache");
        assert!(cache.frames.iter().all(|f| f.get().is_some()));
        assert_eq!(encoded(&src, e, Some(&cache)), plain, "reading the cache");
        // Frames coded at another exposure are not used.
        let other = CodedCache::new(&src, 2.0 * e, 16, usize::MAX);
        let at_other = encoded(&src, 2.0 * e, Some(&other));
        assert_eq!(encoded(&src, e, Some(&other)), plain);
        assert_ne!(at_other, plain);
    }
}
