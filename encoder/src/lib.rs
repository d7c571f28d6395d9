//! vbim-encoder: turns a sequence of lightmaps into a `.vbim` stream — compressed keyframes
//! plus a per-tile polynomial-in-time model using only as many terms as each part of the
//! scene needs under the user's error budget (`docs/MODEL.md`).
//!
//! The public API is data: an [`EncoderConfig`] (built from a [`Preset`] and adjusted knob
//! by knob), [`encode`] into any `Write + Seek` or [`encode_file`] to a path (atomically),
//! the [`EncodeReport`] they return, and [`EncodeReport::verify`] to measure the stream
//! against its input. [`encode_to_tolerance`] holds the tolerance by measuring.
//!
//! Inside, in the order a frame meets them: `input` (reading and validating frames),
//! `domain` (the coded domain), `encode` (the pass over the sequence), `segment` (segment
//! lengths), `keyframe` (keyframe coding), `model` (a segment's per-tile model), `output`
//! (the header and writing), `report` (what an encode did), `aim` (the internal budget
//! that delivers the tolerance, found on a sample before coding), `calibrate` (`--exact`)
//! and `secant` (the search both of those share).

mod aim;
mod calibrate;
mod config;
mod domain;
mod encode;
mod input;
mod keyframe;
mod model;
mod output;
mod plan;
mod report;
mod secant;
mod segment;
mod sparse;

use std::io::{Seek, Write};
use std::path::{Path, PathBuf};

pub use aim::{Aim, SamplePass, SAMPLE_TEXELS};
pub use calibrate::{encode_to_tolerance, BAND_DB};
pub use config::{ConfigError, EncoderConfig, Preset, SegmentMode, DEFAULT_MEMORY_LIMIT};
pub use input::{Frame, FrameSet, FrameSource, InputKind, MemorySource, SourceInfo};
pub use report::{lossless_baseline, EncodeReport};
/// Progress callback: (stage, done, total) — the bake's, so one bar serves both.
pub use vbim_bake::Progress;

/// Why an encode failed.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// A frame or the metadata cannot be used; the message names the file and texel.
    #[error("{0}")]
    Input(String),
    /// The output cannot be written.
    #[error("{path}: {msg}")]
    Output {
        /// The output's path.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
    /// A setting out of range.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Writing the container failed (I/O, or a bug that made an invalid stream).
    #[error("{0}")]
    Format(#[from] vbim_format::FormatError),
}

/// Encodes `src` with `cfg` into `out`. With `cfg.aim` (the default) it first finds, on a
/// sample of the sequence, the internal budget that delivers `cfg.tolerance_db` (module
/// `aim`). The report's error fields stay empty until [`EncodeReport::verify`] measures
/// the stream.
pub fn encode<W: Write + Seek>(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    out: W,
    progress: Progress,
) -> Result<EncodeReport, EncodeError> {
    let t_start = std::time::Instant::now();
    cfg.validate()?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads)
        .build()
        .map_err(|e| ConfigError::Threads {
            threads: cfg.threads,
            reason: e.to_string(),
        })?;
    // The sample passes and the coding run in the pool; the writing, which needs `out`,
    // outside it (`out` need not be `Send`).
    let (c, aimed, coded) = pool.install(|| {
        // A memory limit that cannot hold one band is refused before any work.
        encode::check_shape(&src.info())?;
        plan::plan(&src.info(), cfg, rayon::current_num_threads())?;
        let (c, aimed, validated) = if cfg.aim {
            let (a, validated) = aim::aim(src, cfg, progress)?;
            let c = EncoderConfig {
                tolerance_db: a.internal_db,
                aim: false,
                frame_raise_db: a.frame_raise_db.clone(),
                ..cfg.clone()
            };
            (c, Some(a), validated)
        } else {
            (cfg.clone(), None, None)
        };
        let coded = encode::code_sequence(src, &c, validated, progress)?;
        Ok::<_, EncodeError>((c, aimed, coded))
    })?;
    let mut rep = write_coded(src, &c, coded, out, t_start)?;
    rep.tolerance_db = cfg.tolerance_db;
    rep.aim = aimed;
    Ok(rep)
}

/// One encode at `cfg`'s budget as it is (inside the worker pool). `validated`: the
/// frames were checked already and this is the exposure to code them at (a sample must
/// be measured as the whole sequence is).
pub(crate) fn encode_in_pool<W: Write + Seek>(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    validated: Option<f32>,
    out: W,
    progress: Progress,
) -> Result<EncodeReport, EncodeError> {
    let t_start = std::time::Instant::now();
    let coded = encode::code_sequence(src, cfg, validated, progress)?;
    write_coded(src, cfg, coded, out, t_start)
}

/// Writes a coded sequence and reports on it.
fn write_coded<W: Write + Seek>(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    coded: encode::Coded,
    out: W,
    t_start: std::time::Instant,
) -> Result<EncodeReport, EncodeError> {
    let header = output::write_chunks(out, coded.header, &coded.chunks)?;
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

/// [`encode`] into the file at `path`, written under a temporary name beside it, synced
/// and renamed when complete: an interrupted or failed encode leaves no partial file.
pub fn encode_file(
    src: &dyn FrameSource,
    cfg: &EncoderConfig,
    path: &Path,
    progress: Progress,
) -> Result<EncodeReport, EncodeError> {
    // Writing over an input frame would destroy it before the encode reads it.
    if let Ok(out) = std::fs::canonicalize(path) {
        let input = src
            .files()
            .iter()
            .any(|f| std::fs::canonicalize(f).is_ok_and(|f| f == out));
        if input {
            return Err(EncodeError::Output {
                path: path.to_path_buf(),
                msg: "is one of the input frames".into(),
            });
        }
    }
    output::write_atomic(path, |out| encode(src, cfg, out, progress))
}
