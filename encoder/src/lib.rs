//! vbim-encoder: turns a sequence of lightmaps into a `.vbim` file — compressed keyframes
//! plus a per-tile polynomial-in-time model using only as many terms as each part of the
//! scene needs under the user's error budget (`docs/MODEL.md`).
//!
//! The public API is data: an [`EncoderConfig`] (built from a [`Preset`] and adjusted
//! knob by knob), [`encode`], and the [`EncodeReport`] it returns.

pub mod calibrate;
pub mod domain;
pub mod input;
pub mod model;
pub mod report;

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;
use vbim_format::chunk;
use vbim_format::curve::exposure_from_max_greens;
use vbim_format::header::{ReadAhead, READ_AHEAD_POINTS};
use vbim_format::index::{FLAG_INTRA, FLAG_OPTIONAL};
use vbim_format::metrics::Metric;
use vbim_format::plane::Plane;
use vbim_format::{ChunkKind, ColorEncoding, Header, Transfer, Writer};

pub use calibrate::encode_to_tolerance;
pub use input::{FrameSet, FrameSource, InputKind, MemorySource, SourceInfo};
use model::{CodedFrame, Projectors, SegmentParams};
pub use report::EncodeReport;

#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    #[error("{0}")]
    Input(String),
    #[error("{path}: {msg}")]
    Output { path: PathBuf, msg: String },
    #[error("{0}")]
    Config(String),
    #[error("internal: {0}")]
    Format(#[from] vbim_format::FormatError),
}

/// How segment boundaries are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentMode {
    /// Adaptive: as long as the fit meets the budget, up to this many frames.
    Auto { max: u32 },
    /// Every segment this many frames (the last may be shorter).
    Fixed(u32),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    Fast,
    Default,
    Best,
}

/// Every knob of the encoder; `docs/MODEL.md` gives each one's measured effect.
#[derive(Clone, Debug)]
pub struct EncoderConfig {
    /// Error budget: the target mean PSNR in dB of the protocol's metric.
    pub tolerance_db: f64,
    /// Highest polynomial degree in time (1 = keyframe interpolation only).
    pub max_degree: usize,
    pub segment: SegmentMode,
    pub zstd_level: i32,
    /// Worker threads (0 = one per core). The output does not depend on it.
    pub threads: usize,
    /// Largest distance between independently decodable keyframes, in media seconds.
    pub intra_interval_s: f64,
    pub tile_size: usize,
    /// Media frame rate (num, den).
    pub rate: (u32, u32),
    pub looping: bool,
    /// JSON stored in the metadata chunk.
    pub metadata: Option<String>,
    /// Sub-sampling stride of the segment-length search (1 = every texel).
    pub search_stride: usize,
    /// Dead zone of the quantiser, in steps beyond the half step.
    pub deadzone: f32,
    /// Chroma steps relative to luma.
    pub chroma_step_factor: f32,
}

impl EncoderConfig {
    pub fn preset(p: Preset) -> EncoderConfig {
        let base = EncoderConfig {
            tolerance_db: 45.0,
            max_degree: 4,
            // Longer segments fit the budget but cost more than they save (measured).
            segment: SegmentMode::Auto { max: 32 },
            zstd_level: 9,
            threads: 0,
            intra_interval_s: 4.0,
            tile_size: 16,
            rate: (24, 1),
            looping: true,
            metadata: None,
            search_stride: 4,
            deadzone: 0.2,
            chroma_step_factor: 1.5,
        };
        match p {
            Preset::Fast => EncoderConfig {
                max_degree: 3,
                segment: SegmentMode::Auto { max: 24 },
                zstd_level: 3,
                search_stride: 8,
                ..base
            },
            Preset::Default => base,
            // Degree 6 or 64-frame segments were measured to cost bytes: best spends its
            // time on the entropy coder and a denser segment search instead.
            Preset::Best => EncoderConfig {
                zstd_level: 19,
                search_stride: 2,
                ..base
            },
        }
    }

    pub fn validate(&self) -> Result<(), EncodeError> {
        let bad = |m: String| Err(EncodeError::Config(m));
        if !(10.0..=99.0).contains(&self.tolerance_db) {
            return bad(format!("--tolerance {} dB (10 to 99)", self.tolerance_db));
        }
        if !(1..=vbim_format::limits::MAX_DEGREE as usize).contains(&self.max_degree) {
            return bad(format!(
                "--max-degree {} (1 to {})",
                self.max_degree,
                vbim_format::limits::MAX_DEGREE
            ));
        }
        match self.segment {
            SegmentMode::Auto { max: 0 } | SegmentMode::Fixed(0) => {
                return bad("--segment must be at least 1 frame".into())
            }
            _ => {}
        }
        if !(1..=22).contains(&self.zstd_level) {
            return bad(format!("--zstd-level {} (1 to 22)", self.zstd_level));
        }
        if self.intra_interval_s.is_nan() || self.intra_interval_s <= 0.0 {
            return bad(format!(
                "--intra-interval {} s (must be positive)",
                self.intra_interval_s
            ));
        }
        if !(8..=256).contains(&self.tile_size) || !self.tile_size.is_multiple_of(8) {
            return bad(format!(
                "tile size {} (a multiple of 8 from 8 to 256)",
                self.tile_size
            ));
        }
        if self.rate.0 == 0 || self.rate.1 == 0 {
            return bad("frame rate must be positive".into());
        }
        if self.search_stride == 0 {
            return bad("search stride 0".into());
        }
        Ok(())
    }

    /// The intra interval in frames (at least 1).
    pub fn intra_interval_frames(&self) -> u32 {
        ((self.intra_interval_s * self.rate.0 as f64 / self.rate.1 as f64).floor() as u32).max(1)
    }
}

pub type Progress<'a> = &'a (dyn Fn(&str, u64, u64) + Sync);

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
/// How far above the fit budget a single tile may be when choosing a segment's length
/// (the metric pools all texels; a worst frame of 38 dB allows local peaks).
const WORST_TILE_FACTOR: f64 = 3.0;
/// How far above the fit budget a single frame of a segment may be: keeps the error even
/// in time, so that fast transitions (sunrise, sunset, a loop seam there) are not where
/// the worst frames gather.
const WORST_FRAME_FACTOR: f64 = 1.25;

struct PendingChunk {
    kind: ChunkKind,
    flags: u16,
    number: u32,
    frames: (u32, u32),
    bytes: Vec<u8>,
}

/// Encodes `frames` into `out` (written atomically) and verifies the result against the
/// input unless `verify` is false.
pub fn encode(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    out: &Path,
    verify: bool,
    progress: Progress,
) -> Result<EncodeReport, EncodeError> {
    cfg.validate()?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads)
        .build()
        .map_err(|e| EncodeError::Config(e.to_string()))?;
    pool.install(|| encode_in_pool(src, cfg, out, verify, progress))
}

fn encode_in_pool(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    out: &Path,
    verify: bool,
    progress: Progress,
) -> Result<EncodeReport, EncodeError> {
    let t_start = Instant::now();
    let info = src.info();
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
    // Pass 1: validate every frame before any work, and learn the exposure.
    let done = std::sync::atomic::AtomicU64::new(0);
    let greens: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|i| {
            let f = src.read(i)?;
            progress(
                "validate",
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                n as u64,
            );
            Ok(vbim_format::curve::max_green(&f.data, f.channels))
        })
        .collect::<Result<_, EncodeError>>()?;
    let (color, transfer, metric) = match info.kind {
        InputKind::Srgb8 => (ColorEncoding::Srgb8, Transfer::Srgb, Metric::Srgb8),
        InputKind::Hdr => {
            let e = exposure_from_max_greens(&greens);
            (
                ColorEncoding::LinearHdr,
                Transfer::LogToe {
                    v0: (2.0f32).powi(-10) / e,
                },
                Metric::Hdr { exposure: e },
            )
        }
    };
    let ts = cfg.tile_size;
    let dom = domain::Domain::new(transfer, metric, info.channels, info.width, info.height, ts);
    let eps = 10f64.powf(-cfg.tolerance_db / 20.0);
    let sp = SegmentParams {
        max_degree: cfg.max_degree,
        fit_budget: FIT_SHARE * eps,
        quant_budget: BUBBLE_SHARE * eps,
        chroma_step_factor: cfg.chroma_step_factor,
        deadzone: cfg.deadzone,
        zstd_level: cfg.zstd_level,
    };
    let t_encode = Instant::now();

    // Pass 2: segments, keyframes and models, front to back over a window of frames.
    let looping = cfg.looping;
    let end = if looping { n } else { n - 1 } as u32;
    let intra_every = cfg.intra_interval_frames();
    let mut window: BTreeMap<u32, Arc<CodedFrame>> = BTreeMap::new();
    // Frames are read once, in order: `next` is the first never loaded. (Frames behind the
    // current boundary leave the window and are never needed again, so the window — and
    // the encoder's memory — stays at one segment's worth of frames.)
    let mut next = 0u32;
    let mut load =
        |window: &mut BTreeMap<u32, Arc<CodedFrame>>, upto: u32| -> Result<(), EncodeError> {
            let upto = upto.min(end);
            if upto < next {
                return Ok(());
            }
            let missing: Vec<u32> = (next..=upto).collect();
            next = upto + 1;
            let fresh: Vec<(u32, CodedFrame)> = missing
                .par_iter()
                .map(|&i| {
                    let f = src.read(i as usize % n)?;
                    let (planes, sens) = dom.code(&f.data);
                    Ok((i, CodedFrame { planes, sens }))
                })
                .collect::<Result<_, EncodeError>>()?;
            for (i, f) in fresh {
                window.insert(i, Arc::new(f));
            }
            Ok(())
        };
    let mut chunks: Vec<PendingChunk> = Vec::new();
    if let Some(m) = &cfg.metadata {
        chunks.push(PendingChunk {
            kind: ChunkKind::Metadata,
            flags: FLAG_OPTIONAL,
            number: 0,
            frames: (0, 0),
            bytes: pack_metadata(m, cfg.zstd_level)?,
        });
    }
    load(&mut window, 0)?;
    let header0 = header_for(src, cfg, color, transfer, 0, 0, 1);
    let key_raw = model::code_keyframe(
        &window[&0],
        None,
        KEY_SHARE * eps,
        cfg.chroma_step_factor,
        cfg.deadzone,
    );
    let k0: Arc<Vec<Plane>> = Arc::new(chunk::read_keyframe_raw(&header0, &key_raw, None)?);
    let key_bytes = model::compress(&key_raw, cfg.zstd_level);
    chunks.push(PendingChunk {
        kind: ChunkKind::Keyframe,
        flags: FLAG_INTRA,
        number: 0,
        frames: (0, 0),
        bytes: key_bytes,
    });
    let mut boundaries = vec![0u32];
    let mut projectors = Projectors::default();
    let mut prev_key = k0.clone();
    let mut last_intra = 0u32;
    let mut intra_keyframes = 1; // keyframe 0
    let mut tilemaps = Vec::new();
    let mut b = 0u32;
    while b < end {
        let max_len = match cfg.segment {
            SegmentMode::Fixed(l) => l,
            SegmentMode::Auto { max } => max,
        }
        .min(end - b);
        load(&mut window, b + max_len)?;
        let len = match cfg.segment {
            SegmentMode::Fixed(_) => max_len,
            SegmentMode::Auto { .. } => {
                choose_length(&dom, ts, &window, b, max_len, cfg, &sp, &mut projectors)
            }
        };
        let e = b + len;
        let s = boundaries.len() as u32 - 1;
        // The keyframe closing this segment (keyframe 0 again at a loop's end).
        let k1 = if looping && e == end {
            k0.clone()
        } else {
            // Intra, or predicted from the previous keyframe while the intra interval
            // allows it — whichever is smaller. Both quantise with the same step, but a
            // residual carries the reference's quantisation noise as well as the change,
            // and a change that falls in the dead zone is dropped: where the light moves
            // fast (sunrise, sunset) the intra frame is often the smaller, and the more
            // accurate (BENCHMARKS.md, "Keyframe modes"). The two are compared before
            // zstd, which ranks them as zstd does at a fraction of the time.
            let code = |prev: Option<&[Plane]>| {
                model::code_keyframe(
                    &window[&e],
                    prev,
                    KEY_SHARE * eps,
                    cfg.chroma_step_factor,
                    cfg.deadzone,
                )
            };
            let (predicted, raw) = if e - last_intra <= intra_every {
                let (p, i) = rayon::join(|| code(Some(prev_key.as_slice())), || code(None));
                if p.len() <= i.len() {
                    (true, p)
                } else {
                    (false, i)
                }
            } else {
                (false, code(None))
            };
            let prev = predicted.then(|| prev_key.as_slice());
            let decoded = Arc::new(chunk::read_keyframe_raw(&header0, &raw, prev)?);
            let bytes = model::compress(&raw, cfg.zstd_level);
            if !predicted {
                last_intra = e;
                intra_keyframes += 1;
            }
            chunks.push(PendingChunk {
                kind: ChunkKind::Keyframe,
                flags: if predicted { 0 } else { FLAG_INTRA },
                number: s + 1,
                frames: (e, e),
                bytes,
            });
            decoded
        };
        let inner: Vec<&CodedFrame> = (b + 1..e).map(|i| window[&i].as_ref()).collect();
        let code = model::code_segment(&dom, ts, &prev_key, &k1, &inner, &mut projectors, &sp);
        chunks.push(PendingChunk {
            kind: ChunkKind::TileMap,
            flags: 0,
            number: s,
            frames: (b, e),
            bytes: code.tilemap_bytes,
        });
        chunks.push(PendingChunk {
            kind: ChunkKind::Coefficients,
            flags: 0,
            number: s,
            frames: (b, e),
            bytes: code.coeff_bytes,
        });
        tilemaps.push(code.tiles);
        boundaries.push(e);
        prev_key = k1;
        // Frames before the new boundary are done (frame 0 stays for a loop's end).
        let keep_from = e;
        window.retain(|&i, _| i >= keep_from || i == 0);
        b = e;
        progress("encode", b as u64, end as u64);
    }
    let segments = boundaries.len() as u32 - 1;
    let keyframes = if looping { segments } else { segments + 1 };
    let header = header_for(
        src,
        cfg,
        color,
        transfer,
        segments,
        keyframes,
        chunks.len() as u32,
    );
    let final_header = write_atomic(out, header, &chunks)?;
    let encode_s = t_encode.elapsed().as_secs_f64();
    let total_s = t_start.elapsed().as_secs_f64();
    let mut rep = report::EncodeReport::new(
        src,
        cfg,
        &final_header,
        &boundaries,
        &tilemaps,
        encode_s,
        total_s,
        metric,
    );
    rep.intra_keyframes = intra_keyframes;
    if verify {
        rep.verify(src, out, progress)?;
    }
    Ok(rep)
}

/// The longest segment from `b` (up to `max_len`) whose fit with all bubbles meets the fit
/// budget over the frame and stays within `WORST_TILE_FACTOR` of it on every tile: grow
/// geometrically until a length fails, then bisect.
#[allow(clippy::too_many_arguments)]
fn choose_length(
    dom: &domain::Domain,
    ts: usize,
    window: &BTreeMap<u32, Arc<CodedFrame>>,
    b: u32,
    max_len: u32,
    cfg: &EncoderConfig,
    sp: &SegmentParams,
    projectors: &mut Projectors,
) -> u32 {
    let mut ok = |len: u32| -> bool {
        if len as usize <= cfg.max_degree {
            return true; // as many bubbles as interior frames: an exact fit
        }
        let frames: Vec<&CodedFrame> = (b..=b + len).map(|i| window[&i].as_ref()).collect();
        let p = projectors.get(len, cfg.max_degree);
        let (rms, worst_tile, worst_frame) =
            model::fit_error(dom, ts, cfg.search_stride, &frames, &p);
        rms <= sp.fit_budget
            && worst_tile <= WORST_TILE_FACTOR * sp.fit_budget
            && worst_frame <= WORST_FRAME_FACTOR * sp.fit_budget
    };
    let (mut good, mut bad) = (1u32, None);
    let mut l = 2u32;
    while l <= max_len {
        if ok(l) {
            good = l;
            l = if l < 4 { l + 1 } else { l + l / 2 };
        } else {
            bad = Some(l);
            break;
        }
    }
    match bad {
        None if good < max_len && ok(max_len) => max_len,
        None => good,
        Some(mut hi) => {
            while hi - good > 1 {
                let mid = good + (hi - good) / 2;
                if ok(mid) {
                    good = mid;
                } else {
                    hi = mid;
                }
            }
            good
        }
    }
}

/// The metadata chunk's payload: the JSON made compact (when it parses) and zstd'd. A
/// bake manifest is ~160 kB as written and ~20 kB packed — bytes that count against the
/// file's rate like any other.
fn pack_metadata(text: &str, level: i32) -> Result<Vec<u8>, EncodeError> {
    let compact = serde_json::from_str::<serde_json::Value>(text)
        .map(|v| v.to_string())
        .unwrap_or_else(|_| text.to_string());
    if compact.len() as u64 > vbim_format::limits::MAX_METADATA {
        return Err(EncodeError::Input(format!(
            "metadata of {} bytes (at most {})",
            compact.len(),
            vbim_format::limits::MAX_METADATA
        )));
    }
    Ok(zstd::bulk::compress(compact.as_bytes(), level.max(19)).expect("zstd"))
}

fn header_for(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    color: ColorEncoding,
    transfer: Transfer,
    segments: u32,
    keyframes: u32,
    chunks: u32,
) -> Header {
    let info = src.info();
    Header {
        version_minor: vbim_format::VERSION_MINOR,
        width: info.width as u32,
        height: info.height as u32,
        channels: info.channels as u8,
        color,
        looping: cfg.looping,
        frame_count: info.frames as u32,
        rate_num: cfg.rate.0,
        rate_den: cfg.rate.1,
        tile_size: cfg.tile_size as u16,
        max_degree: cfg.max_degree as u8,
        transfer,
        segment_count: segments,
        keyframe_count: keyframes,
        intra_interval: cfg.intra_interval_frames(),
        chunk_count: chunks,
        index_offset: 0,
        file_size: 0,
        read_ahead: [ReadAhead::default(); READ_AHEAD_POINTS],
        index_checksum: 0,
    }
}

/// Writes the file under a temporary name beside `out`, then renames it: an interrupted or
/// failed encode never leaves a partial file under the final name.
fn write_atomic(
    out: &Path,
    header: Header,
    chunks: &[PendingChunk],
) -> Result<Header, EncodeError> {
    let oerr = |m: String| EncodeError::Output {
        path: out.to_path_buf(),
        msg: m,
    };
    let dir = out
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = out
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| oerr("not a file name".into()))?;
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| {
        let f = std::fs::File::create(&tmp).map_err(|e| oerr(e.to_string()))?;
        let mut w = Writer::new(BufWriter::new(f), header)?;
        for c in chunks {
            w.write_chunk(c.kind, c.flags, c.number, c.frames, &c.bytes)?;
        }
        let (h, buf) = w.finish()?;
        let f = buf.into_inner().map_err(|e| oerr(e.to_string()))?;
        f.sync_all().map_err(|e| oerr(e.to_string()))?;
        std::fs::rename(&tmp, out).map_err(|e| oerr(e.to_string()))?;
        Ok(h)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
