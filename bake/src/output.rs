//! Writing a bake: frames (EXR half RGB, or PNG), the manifest and the contact sheet. Every
//! file is written under a temporary name and renamed, so an interrupted bake never leaves
//! a truncated file under a final name.

use std::path::Path;

use half::f16;
use vbim_format::curve::export_curve;

use crate::error::out_err;
use crate::light::{self, Precomputed};
use crate::scene::Scene;
use crate::BakeError;
use vbim_files::{write_atomic, FrameFormat};

/// Writes `text` to `path` through [`write_file`].
pub fn write_text(path: &Path, text: &str) -> Result<(), BakeError> {
    vbim_files::write_text(path, text).map_err(|e| out_err(path, e))
}

/// [`write_atomic`] for a writer whose errors are messages: errors name `path`.
pub fn write_file(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), BakeError> {
    write_atomic(
        path,
        |tmp| write(tmp).map_err(|e| out_err(path, e)),
        |e| out_err(path, e),
    )
}

/// The protocol's 8-bit export of a linear RGB buffer.
pub fn to_png8(rgb: &[f32], exposure: f32) -> Vec<u8> {
    rgb.iter()
        .map(|&v| {
            (export_curve(v, exposure) * 255.0)
                .round()
                .clamp(0.0, 255.0) as u8
        })
        .collect()
}

pub fn write_frame(
    path: &Path,
    w: usize,
    h: usize,
    rgb: &[f32],
    format: FrameFormat,
    exposure: Option<f32>,
    png16_scale: Option<f32>,
) -> Result<(), BakeError> {
    write_file(path, |tmp| match format {
        // One thread per file: exr's parallel writer stores the blocks in the order its
        // threads finish them, so the same frame came out as different bytes from run to
        // run. Callers write frames in parallel already.
        FrameFormat::Exr => {
            use exr::prelude::{Image, SpecificChannels, Vec2, WritableImage};
            let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
                let i = (y * w + x) * 3;
                (
                    f16::from_f32(rgb[i]),
                    f16::from_f32(rgb[i + 1]),
                    f16::from_f32(rgb[i + 2]),
                )
            });
            Image::from_channels((w, h), channels)
                .write()
                .non_parallel()
                .to_file(tmp)
                .map_err(|e| e.to_string())
        }
        FrameFormat::Png8 => {
            let px = to_png8(rgb, exposure.unwrap_or(1.0));
            image::RgbImage::from_raw(w as u32, h as u32, px)
                .expect("buffer size matches")
                .save(tmp)
                .map_err(|e| e.to_string())
        }
        FrameFormat::Png16 => {
            let s = png16_scale.unwrap_or(1.0);
            let px: Vec<u16> = rgb
                .iter()
                .map(|&v| (v * s).round().clamp(0.0, 65535.0) as u16)
                .collect();
            image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w as u32, h as u32, px)
                .expect("buffer size matches")
                .save(tmp)
                .map_err(|e| e.to_string())
        }
    })
}

/// A 4 × 3 grid of 12 moments of the day (every 2 hours from midnight), each tile a
/// downscaled frame through the 8-bit export curve, separated by thin dark lines.
pub fn contact_sheet(
    pre: &Precomputed,
    scene: &Scene,
    weather: Option<&light::WeatherLight>,
    exposure: f32,
    path: &Path,
) -> Result<(), BakeError> {
    let n = scene.size;
    let tile = 160usize.min(n);
    let gap = 2;
    let (cols, rows) = (4usize, 3usize);
    let (w, h) = (
        cols * tile + (cols + 1) * gap,
        rows * tile + (rows + 1) * gap,
    );
    let mut img = image::RgbImage::from_pixel(w as u32, h as u32, image::Rgb([24, 24, 28]));
    let mut buf = vec![0f32; n * n * 3];
    for k in 0..12 {
        let i = (k * scene.frames) / 12;
        light::light_frame_in(pre, scene, weather, i, &mut buf);
        let (ox, oy) = (
            gap + (k % cols) * (tile + gap),
            gap + (k / cols) * (tile + gap),
        );
        for ty in 0..tile {
            for tx in 0..tile {
                // Box filter over the source texels this tile pixel covers.
                let (x0, x1) = (tx * n / tile, ((tx + 1) * n / tile).max(tx * n / tile + 1));
                let (y0, y1) = (ty * n / tile, ((ty + 1) * n / tile).max(ty * n / tile + 1));
                let mut acc = [0f32; 3];
                for y in y0..y1 {
                    for x in x0..x1 {
                        for c in 0..3 {
                            acc[c] += buf[(y * n + x) * 3 + c];
                        }
                    }
                }
                let cnt = ((x1 - x0) * (y1 - y0)) as f32;
                let px = acc.map(|a| (export_curve(a / cnt, exposure) * 255.0).round() as u8);
                img.put_pixel((ox + tx) as u32, (oy + ty) as u32, image::Rgb(px));
            }
        }
    }
    write_file(path, |tmp| img.save(tmp).map_err(|e| e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame written twice is the same bytes (exr's parallel writer stored blocks in
    /// whatever order its threads finished, so this failed before the writer was made
    /// single-threaded per file).
    #[test]
    fn exr_frames_are_reproducible_bytes() {
        let (w, h) = (96, 80);
        let rgb: Vec<f32> = (0..w * h * 3).map(|i| (i % 997) as f32 / 97.0).collect();
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str| {
            let p = dir.path().join(name);
            write_frame(&p, w, h, &rgb, FrameFormat::Exr, None, None).unwrap();
            std::fs::read(p).unwrap()
        };
        let first = write("a.exr");
        for k in 0..8 {
            assert!(first == write(&format!("b{k}.exr")), "write {k} differs");
        }
    }
}
