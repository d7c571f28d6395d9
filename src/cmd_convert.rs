//! `vbim convert FILE -o OUT [--format-version 1|2|3]`: a stream rewritten in another format
//! version, decoding to the same frames bit for bit (`vbim_encoder::convert`).

use std::io::BufReader;

use crate::cli::ConvertArgs;
use crate::progress::Stages;

pub fn run(a: ConvertArgs) -> Result<(), String> {
    let name = a.file.display().to_string();
    let f = crate::sequence::open_input(&a.file)?;
    let version = crate::cli::format_version(a.format_version);
    let lanes = vbim_encoder::Lanes {
        bytes: a.lane_bytes,
        symbols_per_state: a.symbols_per_state,
    };
    let stages = Stages::new();
    let progress = |stage: &str, done: u64, total: u64| stages.report(stage, done, total);
    let oerr = |e: std::io::Error| format!("{}: {e}", a.out.display());
    let header = vbim_files::write_atomic(
        &a.out,
        |tmp| {
            let out = std::fs::File::create(tmp).map_err(oerr)?;
            let mut out = std::io::BufWriter::new(out);
            let h = vbim_encoder::convert(
                &name,
                BufReader::new(f),
                &mut out,
                version,
                (a.zstd_level, lanes),
                &progress,
            )
            .map_err(|e| e.to_string())?;
            std::io::Write::flush(&mut out).map_err(oerr)?;
            Ok(h)
        },
        oerr,
    )?;
    stages.finish();
    let before = std::fs::metadata(&a.file)
        .map_err(|e| format!("{name}: {e}"))?
        .len();
    println!(
        "{}: .vbim {}.{}, {} bytes ({:.3}× {name}'s {before})",
        a.out.display(),
        header.version_major(),
        header.version_minor,
        header.file_size,
        header.file_size as f64 / before.max(1) as f64
    );
    Ok(())
}
