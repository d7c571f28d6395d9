//! Horizon maps: for every texel and each of `n` azimuths, the elevation angle of the
//! terrain's horizon, clamped to the hemisphere of the texel's normal (paper 001, Fig. 7).
//!
//! Each azimuth is one sweep in the manner of Stewart's algorithm: the grid is cut into
//! parallel lines along the azimuth (one per texel row or column, sampled with linear
//! interpolation across it), and each line is walked from its far end with a stack holding
//! the upper convex hull of the terrain ahead. The horizon of a point is the hull vertex it
//! is tangent to, found by popping vertices it cannot see; each vertex is pushed and popped
//! once, so a full-length scan costs O(texels) per azimuth whatever the map's size — the
//! shadows of a sun 3° high reach across the whole map.

use rayon::prelude::*;

use crate::heightfield::HeightField;

/// Elevation angles (radians), `angles[a * texels + i]` for azimuth `a` and texel `i`.
#[derive(Clone, Debug)]
pub struct HorizonMap {
    pub azimuths: usize,
    pub texels: usize,
    pub angles: Vec<f32>,
}

/// Azimuth `a` of `n` in the map frame: angle from +x (east) towards +y (south).
pub fn azimuth(a: usize, n: usize) -> f64 {
    std::f64::consts::TAU * a as f64 / n as f64
}

impl HorizonMap {
    pub fn compute(hf: &HeightField, normals: &[[f32; 3]], n: usize) -> HorizonMap {
        let texels = hf.w * hf.h;
        let transposed = transpose(hf);
        // Each azimuth's plane is swept straight into its place in the map (collecting
        // the planes and joining them held the map twice: 4.3 GB at 4096², 32 azimuths).
        let mut angles = vec![0f32; n * texels];
        angles
            .par_chunks_mut(texels.max(1))
            .enumerate()
            .for_each(|(a, plane)| {
                let phi = azimuth(a, n);
                let (dx, dy) = (phi.cos(), phi.sin());
                if dx.abs() >= dy.abs() {
                    plane.copy_from_slice(&sweep(hf, dx, dy));
                } else {
                    // March along columns: sweep the transposed field, transpose back.
                    let t = sweep(&transposed, dy, dx);
                    for y in 0..hf.h {
                        for x in 0..hf.w {
                            plane[y * hf.w + x] = t[x * hf.h + y];
                        }
                    }
                }
                // Clamp to the normal's hemisphere: the direction (cos β·d, sin β) is in the
                // tangent plane where tan β = −(n_x d_x + n_y d_y) / n_z.
                for (v, nrm) in plane.iter_mut().zip(normals) {
                    let tan_min = -(nrm[0] as f64 * dx + nrm[1] as f64 * dy) / nrm[2] as f64;
                    *v = v.max(tan_min.atan() as f32);
                }
            });
        HorizonMap {
            azimuths: n,
            texels,
            angles,
        }
    }

    pub fn plane(&self, a: usize) -> &[f32] {
        &self.angles[a * self.texels..(a + 1) * self.texels]
    }

    /// The horizon at texel `i` towards map-frame azimuth `phi`, interpolated linearly
    /// between the two nearest computed azimuths.
    pub fn at(&self, i: usize, phi: f64) -> f32 {
        let (a0, a1, f) = self.bracket(phi);
        self.angles[a0 * self.texels + i] * (1.0 - f) + self.angles[a1 * self.texels + i] * f
    }

    /// The two azimuth planes around `phi` and the weight of the second.
    pub fn bracket(&self, phi: f64) -> (usize, usize, f32) {
        bracket(phi, self.azimuths)
    }
}

/// The two of `n` azimuths ([`azimuth`]) around map-frame azimuth `phi` and the weight of
/// the second.
pub fn bracket(phi: f64, n: usize) -> (usize, usize, f32) {
    let pos = phi.rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU * n as f64;
    let a0 = (pos.floor() as usize) % n;
    (a0, (a0 + 1) % n, (pos - pos.floor()) as f32)
}

fn transpose(hf: &HeightField) -> HeightField {
    let mut z = vec![0f32; hf.w * hf.h];
    for y in 0..hf.h {
        for x in 0..hf.w {
            z[x * hf.h + y] = hf.z[y * hf.w + x];
        }
    }
    HeightField {
        w: hf.h,
        h: hf.w,
        cell_x: hf.cell_y,
        cell_y: hf.cell_x,
        z,
    }
}

/// Horizon angles towards (dx, dy) with |dx| ≥ |dy|: lines y = j + m·x, m = dy/dx.
/// Points outside the map are open sky (no occluder); a texel with nothing ahead gets −π/2.
fn sweep(hf: &HeightField, dx: f64, dy: f64) -> Vec<f32> {
    let (w, h) = (hf.w as i64, hf.h as i64);
    let m = dy / dx;
    let step_len = (hf.cell_x * hf.cell_x + (m * hf.cell_y).powi(2)).sqrt();
    let mut out = vec![-std::f32::consts::FRAC_PI_2; hf.w * hf.h];
    let reach = (m.abs() * w as f64).ceil() as i64 + 1;
    let mut hull: Vec<(f64, f64)> = Vec::with_capacity(hf.w);
    for j in -reach..h + reach {
        hull.clear();
        // Walk from the far end (the end the azimuth points to) back towards the near end.
        let cols: Box<dyn Iterator<Item = i64>> = if dx > 0.0 {
            Box::new((0..w).rev())
        } else {
            Box::new(0..w)
        };
        for x in cols {
            let y = j as f64 + m * x as f64;
            if y < -0.5 || y > (h - 1) as f64 + 0.5 {
                continue;
            }
            let yc = y.clamp(0.0, (h - 1) as f64);
            let z = hf.sample(x as f32, yc as f32) as f64;
            // Position along the line, increasing in the direction of the azimuth.
            let s = if dx > 0.0 { x as f64 } else { -(x as f64) } * step_len;
            while hull.len() >= 2 {
                let (s1, z1) = hull[hull.len() - 1];
                let (s2, z2) = hull[hull.len() - 2];
                if (z1 - z) / (s1 - s) <= (z2 - z) / (s2 - s) {
                    hull.pop();
                } else {
                    break;
                }
            }
            let texel_row = y.round() as i64;
            if let Some(&(s1, z1)) = hull.last() {
                if (0..h).contains(&texel_row) {
                    out[(texel_row * w + x) as usize] = ((z1 - z) / (s1 - s)).atan() as f32;
                }
            }
            hull.push((s, z));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> HeightField {
        let z = (0..w * h).map(|i| f(i % w, i / w)).collect();
        HeightField {
            w,
            h,
            cell_x: 10.0,
            cell_y: 10.0,
            z,
        }
    }

    #[test]
    fn every_azimuth_sees_a_tilted_plane_exactly() {
        // z = a·x + b·y: the horizon towards (dx, dy) is atan((a·dx + b·dy) / cell) wherever
        // the plane continues ahead, in every octant of directions.
        let (a, b) = (4.0f32, -7.0f32);
        let hf = field(40, 40, |x, y| a * x as f32 + b * y as f32 + 500.0);
        let normals = vec![[0.0, 0.0, 1.0]; hf.w * hf.h];
        let n = 32;
        let map = HorizonMap::compute(&hf, &normals, n);
        for az in 0..n {
            let phi = azimuth(az, n);
            let want = ((a as f64 * phi.cos() + b as f64 * phi.sin()) / 10.0)
                .atan()
                .max(0.0);
            let got = map.plane(az)[20 * 40 + 20] as f64;
            assert!(
                (got - want).abs() < 1e-4,
                "azimuth {az}: {} vs {}",
                got.to_degrees(),
                want.to_degrees()
            );
        }
    }

    #[test]
    fn sweep_matches_brute_force_on_rough_terrain() {
        let hf = field(40, 33, |x, y| {
            ((x * 7 + y * 13) % 17) as f32 * 3.0 + (x as f32 * 0.3).sin() * 20.0
        });
        let normals = vec![[0.0, 0.0, 1.0]; hf.w * hf.h];
        let map = HorizonMap::compute(&hf, &normals, 8);
        // Azimuths 0, 2, 4, 6 are axis-aligned: compare with an exhaustive scan.
        for (a, (dx, dy)) in [
            (0usize, (1i64, 0i64)),
            (2, (0, 1)),
            (4, (-1, 0)),
            (6, (0, -1)),
        ] {
            for y in 0..hf.h as i64 {
                for x in 0..hf.w as i64 {
                    let z0 = hf.at(x as usize, y as usize) as f64;
                    let mut best = -std::f64::consts::FRAC_PI_2;
                    let mut k = 1;
                    while (0..hf.w as i64).contains(&(x + dx * k))
                        && (0..hf.h as i64).contains(&(y + dy * k))
                    {
                        let z = hf.at((x + dx * k) as usize, (y + dy * k) as usize) as f64;
                        best = best.max(((z - z0) / (k as f64 * 10.0)).atan());
                        k += 1;
                    }
                    let got = map.plane(a)[(y * hf.w as i64 + x) as usize] as f64;
                    let want = best.max(0.0); // flat normals clamp at the horizontal
                    assert!(
                        (got - want).abs() < 1e-5,
                        "az {a} at ({x},{y}): {got} vs {want}"
                    );
                }
            }
        }
    }
}
