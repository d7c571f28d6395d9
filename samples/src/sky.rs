//! Sky visibility: the Stewart–Langer integral I(p) of paper 001 (Eq. 4), per sky sector.
//!
//! For an azimuth sector [a₁, a₂] whose horizon is at zenith angle φ, the integral of the
//! direction vector v over the visible sky of the sector is
//!     V(φ) = ½ ((φ − sin 2φ / 2) Δsin, (φ − sin 2φ / 2) Δcos, (a₂ − a₁) sin²φ),
//! with Δsin = sin a₂ − sin a₁ and Δcos = cos a₁ − cos a₂ (for eight sectors, a₂ − a₁ = π/4
//! and this is exactly Eq. 4). N·V(φ) is the sector's share of I(p) = ∫_D N·v dΩ; a flat
//! open plane gets I = π.

use crate::horizon::{azimuth, HorizonMap};

/// Number of sky sectors whose radiance can differ (the sun-side glow is per sector).
pub const SECTORS: usize = 8;

/// Eq. 4's vector for a sector [a1, a2] with horizon at zenith angle `phi`.
pub fn sector_vector(a1: f64, a2: f64, phi: f64) -> [f64; 3] {
    let t = phi - (2.0 * phi).sin() / 2.0;
    [
        0.5 * t * (a2.sin() - a1.sin()),
        0.5 * t * (a1.cos() - a2.cos()),
        0.5 * (a2 - a1) * phi.sin().powi(2),
    ]
}

/// N·V for the horizon elevation `beta` (radians above the horizontal) of a sub-sector.
pub fn visible(normal: &[f32; 3], a1: f64, a2: f64, beta: f64) -> f64 {
    let phi = std::f64::consts::FRAC_PI_2
        - beta.clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
    let v = sector_vector(a1, a2, phi);
    normal[0] as f64 * v[0] + normal[1] as f64 * v[1] + normal[2] as f64 * v[2]
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
            per >= 1 && n % SECTORS == 0,
            "azimuth count must be a multiple of {SECTORS}"
        );
        let half = std::f64::consts::PI / n as f64;
        let mut coef = vec![0f32; SECTORS * texels];
        let mut total = vec![0f32; texels];
        for i in 0..texels {
            let mut sum = 0.0;
            for s in 0..SECTORS {
                let mut c = 0.0;
                for a in s * per..(s + 1) * per {
                    let phi = azimuth(a, n);
                    c += visible(
                        &normals[i],
                        phi - half,
                        phi + half,
                        horizons.plane(a)[i] as f64,
                    );
                }
                let c = c.max(0.0);
                coef[s * texels + i] = c as f32;
                sum += c;
            }
            total[i] = sum.clamp(0.0, std::f64::consts::PI) as f32;
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
}
