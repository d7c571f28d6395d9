//! Obscurance (paper 000): W(P) = (1/π) ∫ ρ(L(P, ω)) cos θ dω, with ρ(L) = 1 − e^(−L/τ)
//! for L < L_max and 1 beyond, L the distance to the first terrain hit along ω.
//!
//! On a height field, along each azimuth the directions that hit terrain within L_max are
//! those below the running maximum elevation of the terrain profile. Walking the profile
//! outwards, each rise of that maximum from β_{k−1} to β_k marks the band of elevations
//! that hits at distance d_k, and the band's weight ∫ cos θ dω is the difference of two
//! Eq. 4 sector vectors (see [`crate::sky`]). Directions above the last maximum are open
//! (ρ = 1). A flat open plane gets W = 1.

use rayon::prelude::*;

use crate::heightfield::HeightField;
use crate::horizon::azimuth;
use crate::sky::Sector;

#[derive(Clone, Copy, Debug)]
pub struct ObscuranceParams {
    /// Number of azimuths sampled.
    pub azimuths: usize,
    /// L_max in metres.
    pub l_max: f64,
    /// τ in metres.
    pub tau: f64,
}

pub fn compute(hf: &HeightField, normals: &[[f32; 3]], p: ObscuranceParams) -> Vec<f32> {
    let n = p.azimuths;
    let half = std::f64::consts::PI / n as f64;
    let dirs: Vec<(Sector, f64, f64)> = (0..n)
        .map(|a| {
            let phi = azimuth(a, n);
            (Sector::new(phi - half, phi + half), phi.cos(), phi.sin())
        })
        .collect();
    let rho = |l: f64| {
        if l >= p.l_max {
            1.0
        } else {
            1.0 - (-l / p.tau).exp()
        }
    };
    let mut out = vec![0f32; hf.w * hf.h];
    out.par_chunks_mut(hf.w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let i = y * hf.w + x;
            let nrm = &normals[i];
            let z0 = hf.at(x, y) as f64;
            let mut w = 0.0;
            for (sector, dx, dy) in &dirs {
                let (dx, dy) = (*dx, *dy);
                // Start at the tangent plane's elevation in this direction.
                let mut beta = (-(nrm[0] as f64 * dx + nrm[1] as f64 * dy) / nrm[2] as f64).atan();
                let mut prev_vis = sector.visible(nrm, beta);
                let mut k = 1.0;
                loop {
                    let (sx, sy) = (x as f64 + dx * k, y as f64 + dy * k);
                    let d = ((dx * k * hf.cell_x).powi(2) + (dy * k * hf.cell_y).powi(2)).sqrt();
                    if d >= p.l_max
                        || sx < 0.0
                        || sy < 0.0
                        || sx > (hf.w - 1) as f64
                        || sy > (hf.h - 1) as f64
                    {
                        break;
                    }
                    let b = ((hf.sample(sx as f32, sy as f32) as f64 - z0) / d).atan();
                    if b > beta {
                        let vis = sector.visible(nrm, b);
                        w += rho(d) * (prev_vis - vis);
                        prev_vis = vis;
                        beta = b;
                    }
                    k += 1.0;
                }
                w += prev_vis;
            }
            *o = (w / std::f64::consts::PI).clamp(0.0, 1.0) as f32;
        }
    });
    out
}
