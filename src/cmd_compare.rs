//! `vbim compare A B [--csv FILE]`: the protocol's metrics between two sequences.

use std::io::Write;

use vbim_format::metrics::{Metric, SequenceError};

use crate::cli::CompareArgs;
use crate::progress::Stages;
use crate::sequence::{to_rgb, Sequence};

pub fn run(a: CompareArgs) -> Result<(), String> {
    let limits = a.memory.limits;
    let mut sa = Sequence::open(&a.a, limits)?;
    let mut sb = Sequence::open(&a.b, limits)?;
    let (wa, ha, ca, srgb_a) = sa.shape();
    let (wb, hb, cb, srgb_b) = sb.shape();
    // An HDR reference against an 8-bit sequence compares the reference's 8-bit export
    // (unrounded) with the 8-bit values: how the protocol scores the anchor codecs, which
    // encode the PNG export.
    let export_b = !srgb_a && srgb_b;
    if (wa, ha) != (wb, hb) || sa.len() != sb.len() || (srgb_a && !srgb_b) {
        return Err(format!(
            "{} is {wa}×{ha}×{} frames ({}), {} is {wb}×{hb}×{} frames ({}): not comparable",
            a.a,
            sa.len(),
            if srgb_a { "8-bit" } else { "HDR" },
            a.b,
            sb.len(),
            if srgb_b { "8-bit" } else { "HDR" }
        ));
    }
    let n = sa.len();
    let stages = Stages::new();
    let metric = if srgb_a {
        Metric::Srgb8
    } else {
        let exposure = match a.exposure {
            Some(e) => e,
            None => sa.exposure(&stages)?,
        };
        Metric::Hdr { exposure }
    };
    let mut seq = SequenceError::default();
    for i in 0..n {
        let mut x = to_rgb(&sa.read(i)?, ca);
        let y = to_rgb(&sb.read(i)?, cb);
        match (export_b, metric) {
            (true, Metric::Hdr { exposure }) => {
                for v in x.iter_mut() {
                    *v = vbim_format::curve::export_curve(*v, exposure);
                }
                seq.add(Metric::Srgb8, &x, &y)
            }
            _ => seq.add(metric, &x, &y),
        }
        stages.report("compare", i as u64 + 1, n as u64);
    }
    stages.finish();
    if let Some(i) = seq.first_not_a_number() {
        // A NaN or an infinity has no PSNR: reporting one would call garbage a match.
        return Err(format!(
            "frame {i}: {} or {} holds values that are not finite numbers (NaN or infinity)",
            a.a, a.b
        ));
    }
    if let Some(path) = &a.csv {
        let mut text = String::from("frame,psnr_db,max_abs_error,max_rel_error\n");
        for (i, f) in seq.frames.iter().enumerate() {
            text += &format!("{i},{:.4},{:.6},{:.6}\n", f.psnr(), f.max_abs, f.max_rel);
        }
        if path == "-" {
            std::io::stdout()
                .write_all(text.as_bytes())
                .map_err(|e| e.to_string())?;
        } else {
            std::fs::write(path, text).map_err(|e| format!("{path}: {e}"))?;
        }
    }
    let (wf, wp) = seq.worst();
    println!(
        "frames      {n} ({})",
        match metric {
            Metric::Srgb8 => "8-bit sRGB, PSNR on 0–255 after rounding".to_string(),
            Metric::Hdr { exposure } =>
                format!("HDR, PSNR on the export curve with exposure {exposure:.4}"),
        }
    );
    println!("mean PSNR   {:.3} dB", seq.mean_psnr());
    println!("worst frame {wp:.3} dB (frame {wf})");
    println!(
        "max error   {:.5} (on the 0–1 scale), {:.2} levels of 255",
        seq.max_abs(),
        seq.max_abs() * 255.0
    );
    println!(
        "p99.9 error {:.4} levels of 255 (every value of every frame)",
        seq.p999_levels()
    );
    if let Metric::Hdr { .. } = metric {
        println!(
            "max rel.    {:.3}% (texels brighter than 1% of white)",
            seq.max_rel() * 100.0
        );
    }
    Ok(())
}
