//! Sky visibility: the Stewart–Langer integral I(p) of paper 001 (Eq. 4), per sky sector.
//!
//! For an azimuth sector [a₁, a₂] whose horizon is at zenith angle φ, the integral of the
//! direction vector v over the visible sky of the sector is
//!     V(φ) = ½ ((φ − sin 2φ / 2) Δsin, (φ − sin 2φ / 2) Δcos, (a₂ − a₁) sin²φ),
//! with Δsin = sin a₂ − sin a₁ and Δcos = cos a₁ − cos a₂ (for eight sectors, a₂ − a₁ = π/4
//! and this is exactly Eq. 4). N·V(φ) is the sector's share of I(p) = ∫_D N·v dΩ; a flat
//! open plane gets I = π.

use rayon::prelude::*;

use crate::horizon::{azimuth, HorizonMap};

/// Number of sky sectors whose radiance can differ (the sun-side glow is per sector).
pub const SECTORS: usize = 8;

/// Eq. 4's vector for a sector [a1, a2] with horizon at zenith angle `phi`, as the paper
/// writes it ([`Sector::visible`] is the same in the horizon's elevation; a test checks).
#[cfg(test)]
fn sector_vector(a1: f64, a2: f64, phi: f64) -> [f64; 3] {
    let t = phi - (2.0 * phi).sin() / 2.0;
    [
        0.5 * t * (a2.sin() - a1.sin()),
        0.5 * t * (a1.cos() - a2.cos()),
        0.5 * (a2 - a1) * phi.sin().powi(2),
    ]
}

/// A sector's constant factors of Eq. 4: Δsin, Δcos and its width.
#[derive(Clone, Copy, Debug)]
pub struct Sector {
    pub dsin: f64,
    pub dcos: f64,
    pub width: f64,
}

impl Sector {
    pub fn new(a1: f64, a2: f64) -> Sector {
        Sector {
            dsin: a2.sin() - a1.sin(),
            dcos: a1.cos() - a2.cos(),
            width: a2 - a1,
        }
    }

    /// N·V for the horizon elevation `beta` (radians above the horizontal): with
    /// φ = π/2 − β, φ − sin 2φ / 2 = π/2 − β − sin 2β / 2 and sin²φ = cos²β.
    #[inline]
    pub fn visible(&self, n: &[f32; 3], beta: f64) -> f64 {
        let b = beta.clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
        let (sb, cb) = b.sin_cos();
        let t = std::f64::consts::FRAC_PI_2 - b - sb * cb;
        let v = [t * self.dsin, t * self.dcos, self.width * cb * cb];
        0.5 * (n[0] as f64 * v[0] + n[1] as f64 * v[1] + n[2] as f64 * v[2])
    }
}

/// N·V for the horizon elevation `beta` of the sector [a1, a2].
#[cfg(test)]
fn visible(normal: &[f32; 3], a1: f64, a2: f64, beta: f64) -> f64 {
    Sector::new(a1, a2).visible(normal, beta)
}

/// Per-texel sky coefficients: `coef[s * texels + i]` is sector s's share of I(p) (so that a
/// sky of radiance L_s per sector gives E = Σ L_s coef_s), and `total[i]` = I(p) in [0, π].
pub struct SkyVisibility {
    pub coef: Vec<f32>,
    pub total: Vec<f32>,
}

impl SkyVisibility {
    pub fn compute(horizons: &HorizonMap, normals: &[[f32; 3]]) -> SkyVisibility {
        let n = horizons.azimuths;
        let texels = horizons.texels;
        let per = n / SECTORS;
        assert!(
            per >= 1 && n.is_multiple_of(SECTORS),
            "azimuth count must be a multiple of {SECTORS}"
        );
        let half = std::f64::consts::PI / n as f64;
        let sectors: Vec<Sector> = (0..n)
            .map(|a| Sector::new(azimuth(a, n) - half, azimuth(a, n) + half))
            .collect();
        let per_texel: Vec<([f32; SECTORS], f32)> = (0..texels)
            .into_par_iter()
            .map(|i| {
                let mut c = [0f32; SECTORS];
                let mut sum = 0.0;
                for (s, cs) in c.iter_mut().enumerate() {
                    let v: f64 = (s * per..(s + 1) * per)
                        .map(|a| sectors[a].visible(&normals[i], horizons.plane(a)[i] as f64))
                        .sum();
                    *cs = v.max(0.0) as f32;
                    sum += v.max(0.0);
                }
                (c, sum.clamp(0.0, std::f64::consts::PI) as f32)
            })
            .collect();
        let mut coef = vec![0f32; SECTORS * texels];
        let mut total = vec![0f32; texels];
        for (i, (c, t)) in per_texel.iter().enumerate() {
            for s in 0..SECTORS {
                coef[s * texels + i] = c[s];
            }
            total[i] = *t;
        }
        SkyVisibility { coef, total }
    }
}

/// The map-frame azimuth at the centre of sector `s`.
pub fn sector_centre(s: usize, azimuths: usize) -> f64 {
    let per = azimuths / SECTORS;
    azimuth(s * per, azimuths) + std::f64::consts::PI * (per as f64 - 1.0) / azimuths as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_open_plane_sees_pi() {
        let n = [0.0, 0.0, 1.0];
        let k = 32;
        let half = std::f64::consts::PI / k as f64;
        let i: f64 = (0..k)
            .map(|a| visible(&n, azimuth(a, k) - half, azimuth(a, k) + half, 0.0))
            .sum();
        assert!((i - std::f64::consts::PI).abs() < 1e-12, "{i}");
    }

    /// The sector's factored form is Eq. 4's vector dotted with the normal.
    #[test]
    fn the_factored_sector_is_eq_4() {
        let n = [0.3f32, -0.2, 0.93];
        for (a1, a2, beta) in [(0.0, 0.7, 0.1), (1.0, 1.4, -0.3), (-2.0, -1.2, 0.9)] {
            let v = sector_vector(a1, a2, std::f64::consts::FRAC_PI_2 - beta);
            let eq4: f64 = (0..3).map(|i| n[i] as f64 * v[i]).sum();
            let got = Sector::new(a1, a2).visible(&n, beta);
            assert!((eq4 - got).abs() < 1e-12, "{eq4} against {got}");
        }
    }
}
