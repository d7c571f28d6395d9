//! A weather's sky track: the sky a viewer sees, frame by frame, beside the lightmaps lit
//! by that same sky. Each frame is a small HDR map of the upper hemisphere, written as EXR
//! with a manifest of its own, so that the encoder codes it like any lightmap sequence.
//!
//! The map is equirectangular over the upper hemisphere: column c looks towards the azimuth
//! 360° · (c + ½) / W clockwise from north (the map frame's −y), row r at the elevation
//! 90° · (1 − (r + ½) / H), the zenith's row first and the horizon's last; H = W / 4, so a
//! texel spans the same angle both ways. The sun's disc is not in it: its direction and
//! colour are in each frame's metadata, for the renderer to draw.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;
use vbim_files::{frame_name, FrameFormat, Manifest};

use crate::atmosphere::SkyDome;
use crate::error::out_err;
use crate::light::WeatherLight;
use crate::scene::{Scene, WeatherParams, SKY_MAP_WIDTH};
use crate::{output, BakeError, Progress};

/// The sky track's folder inside its weather's folder.
pub const DIR: &str = "sky";

/// The map-frame direction of sky-map texel (c, r) of a `w` × `w / 4` map.
pub fn texel_direction(c: usize, r: usize, w: usize) -> [f64; 3] {
    let h = w / 4;
    let north = std::f64::consts::TAU * (c as f64 + 0.5) / w as f64;
    let e = std::f64::consts::FRAC_PI_2 * (1.0 - (r as f64 + 0.5) / h as f64);
    let (se, ce) = e.sin_cos();
    // Map frame: x east, y south; an azimuth clockwise from north.
    [north.sin() * ce, -north.cos() * ce, se]
}

/// The dome as a `w` × `w / 4` map, RGB interleaved, rows from the zenith down.
pub fn sky_map(dome: &SkyDome, w: usize) -> Vec<f32> {
    let h = w / 4;
    let mut out = Vec::with_capacity(w * h * 3);
    for r in 0..h {
        for c in 0..w {
            out.extend(dome.radiance(texel_direction(c, r, w)).map(|v| v as f32));
        }
    }
    out
}

/// Writes the sky of `weather` for every frame of the day into `dir` with its manifest,
/// whose timing and per-frame sun are the lightmap `day`'s; returns the manifest's path.
pub fn write(
    scene: &Scene,
    weather: &WeatherParams,
    light: &WeatherLight,
    day: &Manifest,
    dir: &Path,
    progress: Progress,
) -> Result<PathBuf, BakeError> {
    std::fs::create_dir_all(dir).map_err(|e| out_err(dir, e))?;
    let (w, n) = (SKY_MAP_WIDTH, scene.frames);
    let done = AtomicU64::new(0);
    let stage = format!("{} sky", weather.name);
    (0..n).into_par_iter().try_for_each(|i| {
        let dome = light.dome(scene, &light.sun(scene, i));
        let path = dir.join(frame_name(i, FrameFormat::Exr));
        output::write_frame(
            &path,
            w,
            w / 4,
            &sky_map(&dome, w),
            FrameFormat::Exr,
            None,
            None,
        )?;
        progress(&stage, done.fetch_add(1, Ordering::Relaxed) + 1, n as u64);
        Ok::<(), BakeError>(())
    })?;
    let manifest = Manifest {
        width: w,
        height: w / 4,
        format: Some(FrameFormat::Exr),
        units: "sky radiance, linear RGB in the lightmap's units (a uniform sky of value L \
                lights an open flat texel to L); equirectangular upper hemisphere: column = \
                azimuth clockwise from north, first row at the zenith, last at the horizon"
            .into(),
        png16_scale: None,
        files: (0..n).map(|i| frame_name(i, FrameFormat::Exr)).collect(),
        track: Some("sky".into()),
        weather: Some(weather.name.clone()),
        sky: None,
        // Timing, exposure and each frame's sun: the lightmap's, so that the two play in
        // step and the sky's errors are measured on the ground's display scale.
        ..day.clone()
    };
    sheet(
        scene,
        light,
        day.exposure.unwrap_or(1.0),
        &dir.join("sky_sheet.png"),
    )?;
    manifest
        .write(dir)
        .map_err(|e| out_err(&dir.join(Manifest::FILE_NAME), e))
}

/// Twelve moments of the sky (every two hours from midnight), each map twice its size,
/// in two columns, through the protocol's 8-bit curve at the day's `exposure`.
fn sheet(scene: &Scene, light: &WeatherLight, exposure: f32, path: &Path) -> Result<(), BakeError> {
    let (w, zoom, gap) = (SKY_MAP_WIDTH, 2usize, 2usize);
    let (tw, th) = (w * zoom, w / 4 * zoom);
    let (cols, rows) = (2usize, 6usize);
    let size = |n: usize, t: usize| (n * t + (n + 1) * gap) as u32;
    let mut img =
        image::RgbImage::from_pixel(size(cols, tw), size(rows, th), image::Rgb([24, 24, 28]));
    for k in 0..12 {
        let i = k * scene.frames / 12;
        let map = sky_map(&light.dome(scene, &light.sun(scene, i)), w);
        let px = output::to_png8(&map, exposure);
        let (ox, oy) = (gap + (k % cols) * (tw + gap), gap + (k / cols) * (th + gap));
        for y in 0..th {
            for x in 0..tw {
                let t = ((y / zoom) * w + x / zoom) * 3;
                let rgb = image::Rgb([px[t], px[t + 1], px[t + 2]]);
                img.put_pixel((ox + x) as u32, (oy + y) as u32, rgb);
            }
        }
    }
    output::write_file(path, |tmp| img.save(tmp).map_err(|e| e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_map_looks_north_east_south_west_from_the_zenith_down() {
        let w = 128;
        let d = texel_direction(0, 0, w);
        assert!(d[2] > 0.999, "row 0 is the zenith: {d:?}");
        let east = texel_direction(w / 4, 31, w);
        assert!(
            east[0] > 0.99 && east[2] < 0.03,
            "a quarter turn is east: {east:?}"
        );
        let south = texel_direction(w / 2, 31, w);
        assert!(south[1] > 0.99, "half a turn is south (+y): {south:?}");
    }
}
