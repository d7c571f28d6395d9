//! `vbim encode INPUT --out FILE.vbim`

use vbim_bake::Manifest;
use vbim_encoder::{
    encode_file, encode_to_tolerance, ConfigError, EncoderConfig, FrameSet, Preset,
};

use crate::cli::EncodeArgs;
use crate::progress::Stages;
use crate::units::parse_rate;

pub fn run(a: EncodeArgs) -> Result<(), String> {
    let frames = FrameSet::open(&a.input).map_err(|e| e.to_string())?;
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
        encode_to_tolerance(&frames, &cfg, &a.out, &progress)
    } else {
        encode_file(&frames, &cfg, &a.out, &progress).and_then(|mut rep| {
            if !a.no_verify {
                rep.verify_file(&frames, &a.out, &progress)?;
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
        a.out.display()
    );
    println!("{rep}");
    if let Some(p) = &a.degree_map {
        rep.write_degree_map(p)?;
        println!("degree map  {}", p.display());
    }
    if let Some(p) = &a.report {
        std::fs::write(p, serde_json::to_string_pretty(&rep).unwrap())
            .map_err(|e| format!("{}: {e}", p.display()))?;
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
        _ => "settings",
    }
}
