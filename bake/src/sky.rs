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
/// `elevation[s * texels + i]` is the sector's mean horizon above the horizontal in steps of
/// [`ELEVATION_STEP`] (0 to 90°): an analytic sky, brighter at the horizon than overhead,
/// gives a texel in a valley the radiance of the sky it sees ([`SectorSky`]).
pub struct SkyVisibility {
    pub coef: Vec<f32>,
    pub total: Vec<f32>,
    pub elevation: Vec<u8>,
}

/// The angle of one step of [`SkyVisibility::elevation`]: 90° in 255 steps.
pub const ELEVATION_STEP: f64 = std::f64::consts::FRAC_PI_2 / 255.0;

/// Samples of [`SectorSky`]'s table over the horizon elevation, 0 to 90°.
const TABLE: usize = 33;

/// One frame's sky radiance per sector as the ground receives it, as a function of the
/// sector's horizon: `at(s, e)` is the mean radiance of sector s's sky above elevation `e`,
/// weighted as an open flat texel weighs it (N·v cos e on the sphere). A sky of constant
/// radiance per sector gives that radiance at every horizon.
pub struct SectorSky {
    table: [[[f32; 3]; TABLE]; SECTORS],
}

impl SectorSky {
    /// Radiance `l[s]` in every direction of sector s (paper 001's sector sky).
    pub fn constant(l: [[f32; 3]; SECTORS]) -> SectorSky {
        SectorSky {
            table: l.map(|c| [c; TABLE]),
        }
    }

    /// The sectors of a sky `radiance(direction)` (map-frame unit vector), for a horizon map
    /// of `azimuths` directions.
    pub fn of(azimuths: usize, radiance: impl Fn([f64; 3]) -> [f64; 3]) -> SectorSky {
        let per = azimuths / SECTORS;
        let half = std::f64::consts::PI / azimuths as f64;
        let (na, ne) = (4 * per, 8 * (TABLE - 1));
        let mut table = [[[0f32; 3]; TABLE]; SECTORS];
        for (s, row) in table.iter_mut().enumerate() {
            let a0 = azimuth(s * per, azimuths) - half;
            let width = 2.0 * half * per as f64;
            // Cumulative weighted sums from the zenith down, read at each table elevation.
            let (mut sum, mut weight) = ([0.0f64; 3], 0.0f64);
            for j in (0..ne).rev() {
                let (lo, hi) = (
                    std::f64::consts::FRAC_PI_2 * j as f64 / ne as f64,
                    std::f64::consts::FRAC_PI_2 * (j + 1) as f64 / ne as f64,
                );
                let e = 0.5 * (lo + hi);
                // ∫ sin e cos e de over the band, the weight of a flat texel.
                let w = 0.5 * (hi.sin().powi(2) - lo.sin().powi(2));
                for i in 0..na {
                    let a = a0 + width * (i as f64 + 0.5) / na as f64;
                    let r = radiance(crate::atmosphere::direction(a, e));
                    for k in 0..3 {
                        sum[k] += r[k] * w;
                    }
                    weight += w;
                }
                if j % 8 == 0 {
                    row[j / 8] = sum.map(|v| (v / weight) as f32);
                }
            }
            // The zenith itself: the radiance just below it.
            row[TABLE - 1] = row[TABLE - 2];
        }
        SectorSky { table }
    }

    /// Sector `s`'s radiance for a horizon of `step` [`ELEVATION_STEP`]s.
    #[inline]
    pub fn at(&self, s: usize, step: u8) -> [f32; 3] {
        let t = step as f32 * ((TABLE - 1) as f32 / 255.0);
        let i = (t as usize).min(TABLE - 2);
        let f = t - i as f32;
        let (a, b) = (self.table[s][i], self.table[s][i + 1]);
        [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * f)
    }
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
        let per_texel: Vec<([f32; SECTORS], f32, [u8; SECTORS])> = (0..texels)
            .into_par_iter()
            .map(|i| {
                let mut c = [0f32; SECTORS];
                let mut e = [0u8; SECTORS];
                let mut sum = 0.0;
                for (s, cs) in c.iter_mut().enumerate() {
                    let v: f64 = (s * per..(s + 1) * per)
                        .map(|a| sectors[a].visible(&normals[i], horizons.plane(a)[i] as f64))
                        .sum();
                    *cs = v.max(0.0) as f32;
                    sum += v.max(0.0);
                    let mean: f64 = (s * per..(s + 1) * per)
                        .map(|a| (horizons.plane(a)[i] as f64).max(0.0))
                        .sum::<f64>()
                        / per as f64;
                    e[s] = (mean / ELEVATION_STEP).round().clamp(0.0, 255.0) as u8;
                }
                (c, sum.clamp(0.0, std::f64::consts::PI) as f32, e)
            })
            .collect();
        let mut coef = vec![0f32; SECTORS * texels];
        let mut total = vec![0f32; texels];
        let mut elevation = vec![0u8; SECTORS * texels];
        for (i, (c, t, e)) in per_texel.iter().enumerate() {
            for s in 0..SECTORS {
                coef[s * texels + i] = c[s];
                elevation[s * texels + i] = e[s];
            }
            total[i] = *t;
        }
        SkyVisibility {
            coef,
            total,
            elevation,
        }
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

    /// A constant sky gives its radiance at any horizon; a sky brighter towards the horizon
    /// gives a deep valley (horizon at 60°) less than an open texel, and an open flat texel
    /// the cosine-weighted mean of the dome.
    #[test]
    fn sector_tables_weigh_the_sky_a_texel_sees() {
        let c = SectorSky::of(32, |_| [0.5, 0.25, 0.125]);
        for s in 0..SECTORS {
            for step in [0u8, 17, 128, 255] {
                let v = c.at(s, step);
                assert!(
                    (v[0] - 0.5).abs() < 1e-6 && (v[2] - 0.125).abs() < 1e-6,
                    "{v:?}"
                );
            }
        }
        // L = 1 + 2 (1 − sin e): the flat texel's mean is 1 + 2 (1 − 2/3) = 5/3.
        let sky = SectorSky::of(32, |v| [1.0 + 2.0 * (1.0 - v[2]); 3]);
        let open: f32 = (0..SECTORS).map(|s| sky.at(s, 0)[0]).sum::<f32>() / SECTORS as f32;
        assert!((open - 5.0 / 3.0).abs() < 2e-3, "{open}");
        let valley = sky.at(3, (60f64.to_radians() / ELEVATION_STEP) as u8)[0];
        assert!(valley < open && valley > 1.0, "{valley}");
    }
}
