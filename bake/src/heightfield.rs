//! Height fields: a 16-bit PNG (or raw little-endian f32) plus a JSON sidecar, resampled
//! (bilinear) to the bake's resolution.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::BakeError;

/// The sidecar describing how to read a height field (the format of `samples/dem/*.json`).
#[derive(Clone, Debug, Deserialize)]
pub struct Sidecar {
    pub width: u32,
    pub height: u32,
    pub min_elevation_m: f64,
    pub max_elevation_m: f64,
    pub meters_per_pixel_x: f64,
    pub meters_per_pixel_y: f64,
}

/// Heights in metres on a regular grid; row 0 is north, x grows east, y grows south.
#[derive(Clone, Debug)]
pub struct HeightField {
    pub w: usize,
    pub h: usize,
    /// Cell size in metres along x (east) and y (south).
    pub cell_x: f64,
    pub cell_y: f64,
    pub z: Vec<f32>,
}

impl HeightField {
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.z[y * self.w + x]
    }

    /// Bilinear sample at continuous texel coordinates, clamped to the grid.
    pub fn sample(&self, x: f32, y: f32) -> f32 {
        let x = x.clamp(0.0, (self.w - 1) as f32);
        let y = y.clamp(0.0, (self.h - 1) as f32);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.w - 1), (y0 + 1).min(self.h - 1));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let a = self.at(x0, y0) * (1.0 - fx) + self.at(x1, y0) * fx;
        let b = self.at(x0, y1) * (1.0 - fx) + self.at(x1, y1) * fx;
        a * (1.0 - fy) + b * fy
    }

    /// Resamples (bilinear, texel centres aligned) to `w × h`, keeping the covered extent.
    pub fn resample(&self, w: usize, h: usize) -> HeightField {
        let sx = self.w as f32 / w as f32;
        let sy = self.h as f32 / h as f32;
        let mut z = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                z.push(self.sample((x as f32 + 0.5) * sx - 0.5, (y as f32 + 0.5) * sy - 0.5));
            }
        }
        HeightField {
            w,
            h,
            cell_x: self.cell_x * self.w as f64 / w as f64,
            cell_y: self.cell_y * self.h as f64 / h as f64,
            z,
        }
    }

    /// Unit normals (x east, y south, z up) from central differences.
    pub fn normals(&self) -> Vec<[f32; 3]> {
        let mut n = Vec::with_capacity(self.w * self.h);
        for y in 0..self.h {
            for x in 0..self.w {
                let (xl, xr) = (x.saturating_sub(1), (x + 1).min(self.w - 1));
                let (yu, yd) = (y.saturating_sub(1), (y + 1).min(self.h - 1));
                let dzdx = (self.at(xr, y) - self.at(xl, y))
                    / (((xr - xl).max(1)) as f64 * self.cell_x) as f32;
                let dzdy = (self.at(x, yd) - self.at(x, yu))
                    / (((yd - yu).max(1)) as f64 * self.cell_y) as f32;
                let v = [-dzdx, -dzdy, 1.0];
                let len = (v[0] * v[0] + v[1] * v[1] + 1.0).sqrt();
                n.push([v[0] / len, v[1] / len, v[2] / len]);
            }
        }
        n
    }

    /// Loads a height field: `path` is a 16-bit PNG or a raw f32 file (`.f32`/`.raw`), with
    /// its sidecar at the same path with the extension `.json`.
    pub fn load(path: &Path) -> Result<HeightField, BakeError> {
        let sidecar_path: PathBuf = path.with_extension("json");
        let text = std::fs::read_to_string(&sidecar_path)
            .map_err(|e| BakeError::input(&sidecar_path, e))?;
        let sc: Sidecar =
            serde_json::from_str(&text).map_err(|e| BakeError::input(&sidecar_path, e))?;
        let (w, h) = (sc.width as usize, sc.height as usize);
        if !(2..=16384).contains(&w) || !(2..=16384).contains(&h) {
            return Err(BakeError::input(&sidecar_path, format!("size {w}×{h}")));
        }
        if !(sc.meters_per_pixel_x > 0.0 && sc.meters_per_pixel_y > 0.0) {
            return Err(BakeError::input(
                &sidecar_path,
                "cell size must be positive",
            ));
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let z: Vec<f32> = if ext == "f32" || ext == "raw" {
            let bytes = std::fs::read(path).map_err(|e| BakeError::input(path, e))?;
            if bytes.len() != w * h * 4 {
                return Err(BakeError::input(
                    path,
                    format!(
                        "{} bytes, the sidecar's {w}×{h} f32 grid needs {}",
                        bytes.len(),
                        w * h * 4
                    ),
                ));
            }
            bytes
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect()
        } else {
            let img = image::open(path).map_err(|e| BakeError::input(path, e))?;
            if img.width() as usize != w || img.height() as usize != h {
                return Err(BakeError::input(
                    path,
                    format!(
                        "image is {}×{}, the sidecar says {w}×{h}",
                        img.width(),
                        img.height()
                    ),
                ));
            }
            let g = img.into_luma16();
            let (lo, hi) = (sc.min_elevation_m, sc.max_elevation_m);
            g.pixels()
                .map(|p| (lo + p.0[0] as f64 / 65535.0 * (hi - lo)) as f32)
                .collect()
        };
        if let Some(i) = z.iter().position(|v| !v.is_finite()) {
            return Err(BakeError::input(
                path,
                format!("cell ({}, {}) is not finite", i % w, i / w),
            ));
        }
        Ok(HeightField {
            w,
            h,
            cell_x: sc.meters_per_pixel_x,
            cell_y: sc.meters_per_pixel_y,
            z,
        })
    }
}
