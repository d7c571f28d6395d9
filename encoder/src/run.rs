//! One encode from start to end: the worker pool, the aim on a sample, the pass over the
//! sequence and the writing, into a writer or (atomically) a file.

use std::io::{Seek, Write};
use std::path::Path;

use crate::{aim, output, plan};
use crate::{ConfigError, EncodeError, EncodeReport, EncoderConfig, FrameSource, Progress};

/// Encodes `src` with `cfg` into `out`. With `cfg.aim` (the default) it first finds, on a
/// sample of the sequence, the internal budget that delivers `cfg.tolerance_db` (module
/// `aim`). The report's `measured` stays `None` until [`EncodeReport::verify`] measures
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
        crate::encode::check_shape(&src.info())?;
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
        let coded = crate::encode::code_sequence(src, &c, validated, None, progress)?;
        Ok::<_, EncodeError>((c, aimed, coded))
    })?;
    let mut rep = crate::encode::write_coded(src, &c, coded, out, t_start)?;
    rep.tolerance_db = cfg.tolerance_db;
    rep.aim = aimed;
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
                source: std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    "is one of the input frames",
                ),
            });
        }
    }
    output::write_atomic(path, |out| encode(src, cfg, out, progress))
}
