//! `vbim bench changes`: how much of the lightmap a displayed frame really changes, which is
//! what re-evaluating only the tiles that change would save (docs/PLAYER.md, "Frames that
//! change nothing").
//!
//! The reference decoder plays the stream at several media rates on a 60 Hz display. Each
//! tile of the stream keeps the value it was last evaluated at, as a player that skipped
//! it would show, and is re-evaluated when some texel of it would otherwise be further
//! from the true value than a share of the protocol's bound. The count of re-evaluations
//! is a floor on what such a player does: a real one decides from bounds on each tile's
//! change, which can only say "changed" more often.

use std::io::BufReader;

use vbim_format::decode::{Decoder, Output};
use vbim_format::{ColorEncoding, Reader};

use super::BenchChangesArgs;
use crate::progress::Stages;

pub fn run(a: BenchChangesArgs) -> Result<(), String> {
    let name = a.file.display().to_string();
    let f = std::fs::File::open(&a.file).map_err(|e| format!("{name}: {e}"))?;
    let r = Reader::open(BufReader::new(f)).map_err(|e| format!("{name}: {e}"))?;
    let mut dec = Decoder::new(r).map_err(|e| format!("{name}: {e}"))?;
    let h = dec.reader().header().clone();
    if !(a.share > 0.0 && a.share.is_finite()) {
        return Err(format!("--share {}: must be above 0", a.share));
    }
    if !(a.display_hz > 0.0 && a.display_hz.is_finite()) {
        return Err(format!("--display-hz {}: must be above 0", a.display_hz));
    }
    let (w, ht, ch) = (h.width as usize, h.height as usize, h.channels as usize);
    let tile = h.tile_size as usize;
    let (tx, ty) = (w.div_ceil(tile), ht.div_ceil(tile));
    let tiles = tx * ty;
    // The protocol's bound on a shown value: half a code of the stored 8-bit curve, or
    // 2^-10 of an HDR value (with a floor of 10^-6 below 10^-3).
    let hdr = h.color == ColorEncoding::LinearHdr;
    let mode = if hdr { Output::Linear } else { Output::Stored };
    let share = a.share as f32;
    let bound = move |v: f32| -> f32 {
        share
            * if !hdr {
                0.5 / 255.0
            } else if v < 1e-3 {
                1e-6 + v * 2f32.powi(-10)
            } else {
                v * 2f32.powi(-10)
            }
    };
    let length = dec
        .reader()
        .layout()
        .boundaries
        .last()
        .copied()
        .unwrap_or(0) as f64;
    let phases = a.phases.max(1);
    println!(
        "changes: {name}, {w}×{ht}, {ch} channel(s), {} frames at {}/{} fps, {tiles} tiles of {tile}², \
         a {} Hz display, re-evaluated beyond {} of the protocol's bound",
        h.frame_count, h.rate_num, h.rate_den, a.display_hz, a.share
    );
    println!();
    println!("| media rate | media frames per displayed frame | tiles re-evaluated per displayed frame (mean) | fewest / most in one frame | displayed frames with none |");
    println!("|---:|---:|---:|---:|---:|");
    let stages = Stages::new();
    let total = (a.rates.len() * phases * a.shown) as u64;
    let mut done = 0u64;
    let (mut last, mut now) = (vec![0f32; w * ht * ch], vec![0f32; w * ht * ch]);
    for &(num, den) in &a.rates {
        let step = num as f64 / den as f64 / a.display_hz;
        let (mut sum, mut fewest, mut most, mut idle) = (0usize, usize::MAX, 0usize, 0usize);
        for phase in 0..phases {
            let t0 = length * phase as f64 / phases as f64;
            let at = |k: usize| {
                let t = t0 + k as f64 * step;
                if h.looping && length > 0.0 {
                    t % length
                } else {
                    t.min(length)
                }
            };
            dec.frame(at(0), mode, &mut last)
                .map_err(|e| format!("{name}: {e}"))?;
            for k in 1..=a.shown {
                dec.frame(at(k), mode, &mut now)
                    .map_err(|e| format!("{name}: {e}"))?;
                let mut changed = 0;
                for t in 0..tiles {
                    let (x0, y0) = ((t % tx) * tile, (t / tx) * tile);
                    let rows = y0..(y0 + tile).min(ht);
                    let span = x0 * ch..(x0 + tile).min(w) * ch;
                    let stale = rows.clone().any(|y| {
                        let r = y * w * ch;
                        let (old, new) = (
                            &last[r + span.start..r + span.end],
                            &now[r + span.start..r + span.end],
                        );
                        old.iter().zip(new).any(|(&o, &n)| (o - n).abs() > bound(n))
                    });
                    if stale {
                        changed += 1;
                        for y in rows {
                            let r = y * w * ch;
                            last[r + span.start..r + span.end]
                                .copy_from_slice(&now[r + span.start..r + span.end]);
                        }
                    }
                }
                sum += changed;
                fewest = fewest.min(changed);
                most = most.max(changed);
                idle += (changed == 0) as usize;
                done += 1;
                stages.report("changes", done, total);
            }
        }
        let frames = phases * a.shown;
        println!(
            "| {} fps | {step:.4} | {:.1}% | {:.1}% / {:.1}% | {:.1}% |",
            if den == 1 {
                num.to_string()
            } else {
                format!("{num}/{den}")
            },
            100.0 * sum as f64 / (frames * tiles) as f64,
            100.0 * fewest as f64 / tiles as f64,
            100.0 * most as f64 / tiles as f64,
            100.0 * idle as f64 / frames as f64,
        );
    }
    stages.finish();
    Ok(())
}
