//! Fractal detail below a height field's own resolution. A 4096² bake of a 400² height
//! field is a ten-times bilinear blow-up: smooth inside every source cell, with shadow
//! edges as soft as the interpolation. Real terrain keeps its roughness at smaller scales,
//! and over the range height fields are measured at it is close to self-affine: the
//! mean squared height difference over a distance r grows as r^(2H) (H, the Hurst
//! exponent, is typically 0.5–0.9 for eroded terrain).
//!
//! So the detail is measured, not invented: H and the roughness at one source cell come
//! from the height field's own structure function at lags of 1, 2 and 4 cells, and the
//! detail is fractional Brownian motion — octaves of gradient noise, each half the
//! wavelength of the one before and 2^(−H) of its amplitude — starting at half a source
//! cell, where the data stops, and ending at two texels of the bake. One scale for all
//! octaves makes the detailed field's mean squared difference at two texels what the
//! measured law gives there (the resampled field's own slopes included), so the field's
//! structure function continues the source's below its cell size. It is deterministic
//! (a seed), evaluated texel by texel, and leaves the field at the source's scale as it
//! was: the noise has zero mean, and its octaves are all shorter than a source cell.

use serde::{Deserialize, Serialize};

use crate::heightfield::HeightField;

/// The scene's `[detail]` table.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DetailParams {
    /// Add detail where the bake is finer than the height field.
    pub enabled: bool,
    /// Seed of the noise.
    pub seed: u32,
    /// Hurst exponent; 0 = measured from the height field.
    pub hurst: f64,
    /// Amplitude as a multiple of what the measured roughness law gives.
    pub strength: f64,
}

impl Default for DetailParams {
    fn default() -> Self {
        DetailParams {
            enabled: false,
            seed: 1,
            hurst: 0.0,
            strength: 1.0,
        }
    }
}

impl DetailParams {
    /// Checks the ranges; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.hurst == 0.0 || (0.1..=1.0).contains(&self.hurst)) {
            return Err(format!(
                "detail.hurst = {} (0 to measure it, else 0.1 to 1)",
                self.hurst
            ));
        }
        if !(0.0..=10.0).contains(&self.strength) {
            return Err(format!("detail.strength = {} (0 to 10)", self.strength));
        }
        Ok(())
    }
}

/// A height field's roughness law: mean squared height difference `d1` (m²) between
/// cells one cell apart, and the Hurst exponent `hurst` with which it grows with distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roughness {
    pub d1: f64,
    pub hurst: f64,
}

/// Measures `hf`'s structure function at lags of 1, 2 and 4 cells (along both axes) and
/// fits log D(r) = log d1 + 2H log r. H is kept to 0.1–1 (a flat or synthetic field can
/// give anything).
pub fn roughness(hf: &HeightField) -> Roughness {
    let d = |r: usize| -> f64 {
        let (mut sum, mut n) = (0.0f64, 0u64);
        for y in 0..hf.h {
            for x in 0..hf.w {
                let z = hf.at(x, y) as f64;
                if x + r < hf.w {
                    sum += (hf.at(x + r, y) as f64 - z).powi(2);
                    n += 1;
                }
                if y + r < hf.h {
                    sum += (hf.at(x, y + r) as f64 - z).powi(2);
                    n += 1;
                }
            }
        }
        sum / n.max(1) as f64
    };
    let pts: Vec<(f64, f64)> = [1usize, 2, 4]
        .iter()
        .map(|&r| ((r as f64).ln(), d(r).max(1e-12).ln()))
        .collect();
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / 3.0;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / 3.0;
    let slope = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>()
        / pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
    Roughness {
        d1: (my - slope * mx).exp(),
        hurst: (slope / 2.0).clamp(0.1, 1.0),
    }
}

/// Adds fractal detail to `fine`, a resampling of `source` to a finer grid, following
/// `source`'s roughness law (or `p.hurst`). Does nothing where the bake is not at least
/// four times finer than the source (no octave fits between half a source cell and two
/// texels).
pub fn add_detail(fine: &mut HeightField, source: &HeightField, p: &DetailParams) {
    let law = roughness(source);
    let hurst = if p.hurst > 0.0 { p.hurst } else { law.hurst };
    // Source cells per fine texel along each axis, and the octaves: wavelengths (in
    // source cells) 1/2, 1/4, … down to two texels.
    let (sx, sy) = (
        source.w as f64 / fine.w as f64,
        source.h as f64 / fine.h as f64,
    );
    let texel = sx.max(sy);
    let mut octaves = Vec::new();
    let mut wavelength = 0.5f64;
    let mut k = 0u32;
    while wavelength >= 2.0 * texel {
        octaves.push((
            wavelength,
            wavelength.powf(hurst) as f32,
            p.seed.wrapping_add(k),
        ));
        wavelength /= 2.0;
        k += 1;
    }
    if octaves.is_empty() {
        return;
    }
    let noise = |u: f64, v: f64| -> f64 {
        octaves
            .iter()
            .map(|&(wl, a, seed)| (a * gradient_noise(u / wl, v / wl, seed)) as f64)
            .sum()
    };
    // One scale for all octaves: the detailed field's mean squared difference at two
    // texels is the law's there. The resampled field already has some (its bilinear
    // slopes); the noise adds the rest, being independent of it.
    let (rx, ry) = (2.0 * sx, 2.0 * sy);
    let want = 0.5 * law.d1 * (rx.powf(2.0 * hurst) + ry.powf(2.0 * hurst));
    let has = {
        let (mut s, mut n) = (0.0f64, 0u64);
        for y in (0..fine.h.saturating_sub(2)).step_by(4) {
            for x in (0..fine.w.saturating_sub(2)).step_by(4) {
                let z = fine.at(x, y) as f64;
                s +=
                    (fine.at(x + 2, y) as f64 - z).powi(2) + (fine.at(x, y + 2) as f64 - z).powi(2);
                n += 2;
            }
        }
        s / n.max(1) as f64
    };
    let unit = {
        let mut s = 0.0f64;
        let n = 4096;
        for i in 0..n {
            let (u, v) = ((i % 64) as f64 * 0.37 + 0.11, (i / 64) as f64 * 0.41 + 0.23);
            let z = noise(u, v);
            s += (noise(u + rx, v) - z).powi(2) + (noise(u, v + ry) - z).powi(2);
        }
        s / (2 * n) as f64
    };
    let scale = (p.strength * ((want - has).max(0.0) / unit.max(1e-30)).sqrt()) as f32;
    use rayon::prelude::*;
    let w = fine.w;
    fine.z.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let v = (y as f64 + 0.5) * sy;
        for (x, z) in row.iter_mut().enumerate() {
            *z += scale * noise((x as f64 + 0.5) * sx, v) as f32;
        }
    });
}

/// 2-D gradient (Perlin) noise: zero at lattice points, a hashed unit gradient at each,
/// quintic fade. Zero mean.
fn gradient_noise(x: f64, y: f64, seed: u32) -> f32 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let grad = |i: i64, j: i64, dx: f64, dy: f64| -> f64 {
        let mut h = (i as u32).wrapping_mul(0x8da6_b343)
            ^ (j as u32).wrapping_mul(0xd816_3841)
            ^ seed.wrapping_mul(0xcb1a_b31f);
        h ^= h >> 15;
        h = h.wrapping_mul(0x2c1b_3c6d);
        h ^= h >> 12;
        let angle = (h >> 8) as f64 * (std::f64::consts::TAU / (1u32 << 24) as f64);
        angle.cos() * dx + angle.sin() * dy
    };
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v) = (fade(fx), fade(fy));
    let a = grad(ix, iy, fx, fy);
    let b = grad(ix + 1, iy, fx - 1.0, fy);
    let c = grad(ix, iy + 1, fx, fy - 1.0);
    let d = grad(ix + 1, iy + 1, fx - 1.0, fy - 1.0);
    let top = a + (b - a) * u;
    let bottom = c + (d - c) * u;
    (top + (bottom - top) * v) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A self-affine field of known H: fBm by the same noise at many octaves.
    fn synthetic(w: usize, hurst: f64) -> HeightField {
        let mut z = vec![0f32; w * w];
        for (i, v) in z.iter_mut().enumerate() {
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            let mut wl = 256.0f64;
            while wl >= 0.5 {
                *v += (100.0 * (wl / 256.0).powf(hurst)) as f32
                    * gradient_noise(x / wl, y / wl, wl as u32);
                wl /= 2.0;
            }
        }
        HeightField {
            w,
            h: w,
            cell_x: 30.0,
            cell_y: 30.0,
            z,
        }
    }

    #[test]
    fn the_noise_has_zero_mean() {
        let (mut s, mut s2, n) = (0.0f64, 0.0f64, 200_000);
        for i in 0..n {
            let (x, y) = ((i % 443) as f64 * 0.731, (i / 443) as f64 * 0.619);
            let v = gradient_noise(x, y, 7) as f64;
            s += v;
            s2 += v * v;
        }
        let mean = s / n as f64;
        let std = (s2 / n as f64 - mean * mean).sqrt();
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!(std > 0.1, "std {std}");
    }

    #[test]
    fn the_roughness_law_is_measured_from_the_field() {
        for h in [0.5, 0.8] {
            let law = roughness(&synthetic(256, h));
            assert!(
                (law.hurst - h).abs() < 0.15,
                "H {h}: measured {}",
                law.hurst
            );
        }
    }

    #[test]
    fn detail_continues_the_source_law_below_its_cell_and_keeps_its_shape() {
        let source = synthetic(64, 0.7);
        let law = roughness(&source);
        let plain = source.resample(512, 512);
        let mut fine = plain.clone();
        let p = DetailParams {
            enabled: true,
            ..DetailParams::default()
        };
        add_detail(&mut fine, &source, &p);
        // At a quarter of a source cell (2 texels), the law wants d1 · (1/4)^(2H); the
        // bilinear field has far less.
        let lag_d = |f: &HeightField, r: usize| {
            let mut s = 0.0f64;
            let mut n = 0;
            for y in 0..f.h {
                for x in 0..f.w - r {
                    s += (f.at(x + r, y) as f64 - f.at(x, y) as f64).powi(2);
                    n += 1;
                }
            }
            s / n as f64
        };
        let want = law.d1 * 0.25f64.powf(2.0 * law.hurst);
        let (before, after) = (lag_d(&plain, 2), lag_d(&fine, 2));
        assert!(before < 0.5 * want, "bilinear {before} vs {want}");
        assert!(
            after > 0.85 * want && after < 1.15 * want,
            "detailed {after} vs {want}"
        );
        // At the source's scale the field is as it was: averaged over source cells, the
        // detail is a small part of the roughness.
        let mut diff = 0.0f64;
        for cy in 0..64 {
            for cx in 0..64 {
                let mut s = 0.0f64;
                for y in 0..8 {
                    for x in 0..8 {
                        let i = (cy * 8 + y) * 512 + cx * 8 + x;
                        s += (fine.z[i] - plain.z[i]) as f64;
                    }
                }
                diff += (s / 64.0).powi(2);
            }
        }
        let rms = (diff / 4096.0).sqrt();
        assert!(rms < 0.1 * law.d1.sqrt(), "cell means move {rms} m");
        // Deterministic; another seed, another field.
        let mut again = plain.clone();
        add_detail(&mut again, &source, &p);
        assert_eq!(again.z, fine.z);
        let mut other = plain.clone();
        add_detail(&mut other, &source, &DetailParams { seed: 2, ..p });
        assert_ne!(other.z, fine.z);
    }
}
