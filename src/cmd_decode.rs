//! `vbim decode FILE --out DIR [--format exr|png8|png16]`

use vbim_bake::output::{frame_name, write_atomic, write_frame};
use vbim_bake::FrameFormat;
use vbim_format::curve::{exposure_from_max_greens, srgb_to_linear};

use crate::cli::DecodeArgs;
use crate::progress::Stages;
use crate::sequence::{to_rgb, Sequence};

pub fn run(a: DecodeArgs) -> Result<(), String> {
    let format: FrameFormat = a.format.parse()?;
    let name = a.file.display().to_string();
    let mut seq = Sequence::open(&name)?;
    if !name.ends_with(".vbim") {
        return Err(format!("{name}: not a .vbim file"));
    }
    let (w, h, ch, srgb8) = seq.shape();
    std::fs::create_dir_all(&a.out).map_err(|e| format!("{}: {e}", a.out.display()))?;
    let meta = seq.metadata();
    let stages = Stages::new();
    let n = seq.len();
    // The HDR 8-bit export needs the day's exposure: from the bake's manifest, or a first pass.
    let mut exposure = meta
        .as_ref()
        .and_then(|m| m.get("exposure"))
        .and_then(|v| v.as_f64())
        .map(|v| v as f32);
    let mut png16_scale = meta
        .as_ref()
        .and_then(|m| m.get("png16_scale"))
        .and_then(|v| v.as_f64())
        .map(|v| v as f32);
    if !srgb8 && format != FrameFormat::Exr && (exposure.is_none() || png16_scale.is_none()) {
        let (mut greens, mut max) = (Vec::with_capacity(n), 0f32);
        for i in 0..n {
            let rgb = to_rgb(&seq.read(i)?, ch);
            greens.push(vbim_format::curve::max_green(&rgb, 3));
            max = rgb.iter().copied().fold(max, f32::max);
            stages.report("measure", i as u64 + 1, n as u64);
        }
        exposure.get_or_insert(exposure_from_max_greens(&greens));
        png16_scale.get_or_insert(if max > 0.0 { 65535.0 / max } else { 1.0 });
    }
    for i in 0..n {
        let stored = to_rgb(&seq.read(i)?, ch);
        let path = a.out.join(frame_name(i, format));
        if srgb8 && format == FrameFormat::Png8 {
            // 8-bit files decode to their own code values.
            let px: Vec<u8> = stored
                .iter()
                .map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
                .collect();
            write_atomic(&path, |tmp| {
                image::RgbImage::from_raw(w as u32, h as u32, px)
                    .unwrap()
                    .save(tmp)
                    .map_err(|e| e.to_string())
            })
            .map_err(|e| e.to_string())?;
        } else {
            let linear: Vec<f32> = if srgb8 {
                stored.iter().map(|&c| srgb_to_linear(c)).collect()
            } else {
                stored
            };
            let scale = if srgb8 { Some(65535.0) } else { png16_scale };
            write_frame(&path, w, h, &linear, format, exposure, scale)
                .map_err(|e| e.to_string())?;
        }
        stages.report("decode", i as u64 + 1, n as u64);
    }
    stages.finish();
    println!("decoded {n} frames of {w}×{h} into {}", a.out.display());
    Ok(())
}
