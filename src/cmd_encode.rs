//! `vbim encode INPUT --out FILE.vbim`, or a bake with weathers into a package:
//! `vbim encode BAKE --out DAY.vbimpkg` (each weather's lightmap and sky track coded with
//! the same settings into `DAY-NAME.vbim`, `DAY-NAME-sky.vbim` and
//! `DAY-NAME-irradiance.vbim` beside it).

use std::path::{Path, PathBuf};

use vbim_bake::Manifest;
use vbim_encoder::{
    encode_file, encode_to_tolerance, ConfigError, EncoderConfig, FrameSet, Preset,
};

use vbim_format::package::Package;

use crate::cli::EncodeArgs;
use crate::progress::Stages;
use crate::units::parse_rate;

pub fn run(a: EncodeArgs) -> Result<(), String> {
    let bake_package = Path::new(&a.input).join(vbim_bake::PACKAGE_FILE);
    if bake_package.is_file() {
        return encode_package(&a, &bake_package);
    }
    encode_one(&a, &a.input, &a.out)
}

/// Codes every track of a bake's package (folders of frames) and writes the package of
/// files, last, so that it only ever names complete tracks.
fn encode_package(a: &EncodeArgs, bake_package: &Path) -> Result<(), String> {
    let text = std::fs::read_to_string(bake_package)
        .map_err(|e| format!("{}: {e}", bake_package.display()))?;
    let baked = Package::parse(&text).map_err(|e| format!("{}: {e}", bake_package.display()))?;
    if a.out.extension().and_then(|e| e.to_str()) != Some("vbimpkg") {
        return Err(format!(
            "{} is a bake with weathers: its package goes to a .vbimpkg file (--out DAY.vbimpkg)",
            a.input
        ));
    }
    if a.meta.is_some() || a.degree_map.is_some() || a.report.is_some() {
        return Err(
            "--meta, --degree-map and --report name one file: not with a bake of weathers \
             (each track keeps its own manifest; encode a weather's folder alone for its map \
             or report)"
                .into(),
        );
    }
    let stem = a
        .out
        .file_stem()
        .and_then(|s| s.to_str())
        .ok_or_else(|| format!("{}: the package's name is not UTF-8", a.out.display()))?;
    let dir = a.out.parent().unwrap_or(Path::new(""));
    let base = bake_package.parent().unwrap_or(Path::new("."));
    let input = |rel: &str| -> Result<String, String> {
        base.join(rel)
            .to_str()
            .map(str::to_string)
            .ok_or_else(|| format!("{}: not UTF-8", base.join(rel).display()))
    };
    let package = baked.coded_as(stem);
    for (w, coded) in baked.weathers.iter().zip(&package.weathers) {
        for ((_, frames), (_, file)) in w.tracks().zip(coded.tracks()) {
            encode_one(a, &input(frames)?, &dir.join(file))?;
        }
    }
    vbim_files::write_text(&a.out, &package.to_json())
        .map_err(|e| format!("{}: {e}", a.out.display()))?;
    println!(
        "package {}: {} weather(s), {}",
        a.out.display(),
        package.weathers.len(),
        package
            .weathers
            .iter()
            .map(|w| w.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

/// Codes the frames at `input` into `out`.
fn encode_one(a: &EncodeArgs, input: &str, out: &Path) -> Result<(), String> {
    let out: PathBuf = out.to_path_buf();
    let frames = FrameSet::open(input).map_err(|e| e.to_string())?;
    for note in &frames.notes {
        eprintln!("note: {note}");
    }
    let preset = if a.fast {
        Preset::Fast
    } else if a.best {
        Preset::Best
    } else {
        Preset::Default
    };
    let mut cfg = EncoderConfig::preset(preset);
    // The bake's manifest supplies the frame rate and the metadata unless told otherwise.
    let manifest_text = match (&a.meta, &frames.manifest) {
        (Some(p), _) => {
            Some(std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?)
        }
        (None, Some(p)) => std::fs::read_to_string(p).ok(),
        (None, None) => None,
    };
    // Any JSON may be stored; a bake's manifest also gives the frame rate.
    let manifest = match &manifest_text {
        Some(t) => {
            serde_json::from_str::<serde::de::IgnoredAny>(t)
                .map_err(|e| format!("metadata JSON: {e}"))?;
            Manifest::parse(t).ok()
        }
        None => None,
    };
    cfg.metadata = manifest_text;
    cfg.rate = match (a.fps, manifest.as_ref().and_then(|m| m.fps.as_deref())) {
        (Some(f), _) => f,
        (None, Some(f)) => parse_rate(f).map_err(|e| format!("the manifest's fps: {e}"))?,
        (None, None) => (24, 1),
    };
    if let Some(t) = a.tolerance {
        cfg.tolerance_db = t;
    }
    cfg.aim = !a.no_aim;
    if let Some(m) = a.worst_margin {
        cfg.worst_margin_db = m;
    }
    if let Some(d) = a.max_degree {
        cfg.max_degree = d;
    }
    if let Some(s) = a.segment {
        cfg.segment = s.mode(cfg.segment);
    }
    if let Some(z) = a.zstd_level {
        cfg.zstd_level = z;
    }
    cfg.lanes = vbim_encoder::Lanes {
        bytes: a.lane_bytes,
        symbols_per_state: a.symbols_per_state,
    };
    cfg.format = crate::cli::format_version(a.format_version);
    cfg.rate_lambda = a.rate_lambda;
    if let Some(i) = a.intra_interval {
        cfg.intra_interval_s = i;
    }
    if a.looping || a.no_loop {
        cfg.looping = !a.no_loop;
    }
    if let Some(t) = a.tile {
        cfg.tile_size = t;
    }
    cfg.threads = a.threads;
    cfg.memory_limit = a.memory_limit.memory;
    cfg.band_tiles = a.band;
    let stages = Stages::new();
    let progress = |s: &str, d: u64, t: u64| stages.report(s, d, t);
    if let Err(e) = cfg.validate() {
        // A setting out of range is a bad argument: clap's message and exit status 2.
        use clap::CommandFactory;
        crate::Cli::command()
            .error(
                clap::error::ErrorKind::ValueValidation,
                format!("{}: {e}", flag_of(&e)),
            )
            .exit();
    }
    let rep = if a.exact {
        encode_to_tolerance(&frames, &cfg, &out, &progress)
    } else {
        encode_file(&frames, &cfg, &out, &progress).and_then(|mut rep| {
            if !a.no_verify {
                rep.verify_file(&frames, &out, &progress)?;
            }
            Ok(rep)
        })
    }
    .map_err(|e| e.to_string())?;
    stages.finish();
    println!(
        "encoded {} frames of {}×{} into {}",
        rep.frames,
        rep.width,
        rep.height,
        out.display()
    );
    println!("{rep}");
    // What was asked and not delivered goes to stderr, where a script's log keeps it, and
    // into the JSON report; the file is valid either way, so the command still succeeds.
    let shortfalls = rep.shortfalls();
    for s in &shortfalls {
        eprintln!("warning: {s}");
    }
    if let Some(p) = &a.degree_map {
        rep.write_degree_map(p)?;
        println!("degree map  {}", p.display());
    }
    if let Some(p) = &a.report {
        let mut json = serde_json::to_value(&rep).map_err(|e| e.to_string())?;
        json["shortfalls"] = shortfalls.into();
        let text = serde_json::to_string_pretty(&json).map_err(|e| e.to_string())?;
        vbim_bake::write_file(p, |tmp| {
            std::fs::write(tmp, &text).map_err(|e| e.to_string())
        })
        .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The flag that sets the setting a configuration error names.
fn flag_of(e: &ConfigError) -> &'static str {
    match e {
        ConfigError::Tolerance(_) => "--tolerance",
        ConfigError::WorstMargin(_) => "--worst-margin",
        ConfigError::MaxDegree(_) => "--max-degree",
        ConfigError::EmptySegments => "--segment",
        ConfigError::ZstdLevel(_) => "--zstd-level",
        ConfigError::IntraInterval(_) => "--intra-interval",
        ConfigError::TileSize(_) => "--tile",
        ConfigError::Rate(..) => "--fps",
        ConfigError::Threads { .. } => "--threads",
        ConfigError::EmptyBands => "--band",
        ConfigError::RateLambda(_) => "--rate-lambda",
        _ => "settings",
    }
}
