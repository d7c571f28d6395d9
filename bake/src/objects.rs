//! Light for objects: a weather's irradiance track, what an object standing on the terrain
//! receives on a coarse grid, frame by frame (`docs/BAKE.md`, "Light for objects";
//! `vbim_format::irradiance` defines the frames).
//!
//! Each cell stands for a point `height_m` above the ground at its centre. Its horizon is
//! marched through the height field once per bake, unclamped by any surface (an object
//! has every normal). Each frame then gives it:
//! - the sun's transmission: the clouds' (and the weather's direct share) at the point.
//!   The terrain's share of the sun is not coded: the points' horizons go into the track's
//!   metadata and a reader computes the disc's share above them for each frame's sun
//!   (`GridInfo::visibility`, soft as the ground's sun, paper 001);
//! - sky and bounce as order-2 spherical harmonics: the sky radiance of the very dome the
//!   lightmap was lit by, over the directions above the horizon; the ground (albedo times
//!   the lit lightmap, averaged over the cell) everywhere below it — below the horizontal
//!   and behind ridges alike; and the ambient floor, uniform.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use rayon::prelude::*;
use vbim_format::irradiance::{sh_basis, Cell, Grid, GridInfo, COSINE_LOBE, HORIZON_STEP};

use crate::atmosphere::{direct_share, direction};
use crate::clouds::CloudLayer;
use crate::heightfield::HeightField;
use crate::horizon::bracket;
use crate::light::{sector_values, Precomputed, WeatherLight};
use crate::scene::Scene;
use crate::sky::SECTORS;
use crate::sun::SunState;

/// The irradiance track's folder inside its weather's folder.
pub const DIR: &str = "irradiance";

/// Elevation bands of the sky integral, horizon to zenith.
const BANDS: usize = 32;
/// Azimuth columns of the sky integral per horizon azimuth.
const COLUMNS_PER_AZIMUTH: usize = 2;

/// One point of the grid: where it stands and its horizon.
struct Point {
    /// Texel coordinates of the cell's centre (texel centres at integers).
    x: f32,
    y: f32,
    /// Height above sea level, metres (the ground's plus the grid's height).
    z: f32,
    /// The horizon's elevation towards each azimuth of the horizon map, radians, ≥ 0.
    horizon: Vec<f32>,
    /// The lightmap texels the cell covers: x0..x1, y0..y1.
    footprint: [usize; 4],
}

/// The grid of a terrain, with everything about it that does not change over the day.
pub struct ObjectGrid {
    /// The grid as the track's metadata states it (cells, azimuths), with the horizons
    /// quantised as a reader sees them.
    info: GridInfo,
    points: Vec<Point>,
    /// Per column, per band: Y_j(v) dΩ at the band's centre direction.
    basis: Vec<[[f64; 9]; BANDS]>,
    /// Per column, per band: the direction.
    dirs: Vec<[[f64; 3]; BANDS]>,
}

impl ObjectGrid {
    /// The grid of `scene.objects` over the precomputed terrain.
    pub fn new(pre: &Precomputed, scene: &Scene) -> ObjectGrid {
        let hf = &pre.hf;
        // At most one cell a texel, in multiples of 8 (a bake is at least 8 texels a side).
        let fit = |texels: usize| scene.objects.cells.min(texels / 8 * 8).max(8);
        let (nx, ny) = (fit(hf.w), fit(hf.h));
        let azimuths = scene.azimuths;
        let height_m = scene.objects.height_m;
        let points: Vec<Point> = (0..nx * ny)
            .into_par_iter()
            .map(|k| {
                let (i, j) = (k % nx, k / nx);
                let span = |c: usize, cells: usize, texels: usize| {
                    (
                        c * texels / cells,
                        ((c + 1) * texels / cells).max(c * texels / cells + 1),
                    )
                };
                let (x0, x1) = span(i, nx, hf.w);
                let (y0, y1) = span(j, ny, hf.h);
                let x = ((i as f64 + 0.5) * hf.w as f64 / nx as f64 - 0.5) as f32;
                let y = ((j as f64 + 0.5) * hf.h as f64 / ny as f64 - 0.5) as f32;
                let z = hf.sample(x, y) + height_m as f32;
                let horizon = (0..azimuths)
                    .map(|a| march(hf, x, y, z, TAU * a as f64 / azimuths as f64))
                    .collect();
                Point {
                    x,
                    y,
                    z,
                    horizon,
                    footprint: [x0, x1, y0, y1],
                }
            })
            .collect();
        let cells = nx * ny;
        let mut horizons = vec![0u8; azimuths * cells];
        for (c, p) in points.iter().enumerate() {
            for (a, h) in p.horizon.iter().enumerate() {
                horizons[a * cells + c] =
                    (*h as f64 / HORIZON_STEP).round().clamp(0.0, 255.0) as u8;
            }
        }
        let info = GridInfo {
            cells: [nx, ny],
            height_m: height_m as f32,
            albedo: scene.albedo as f32,
            sun_diameter_deg: scene.sun.angular_diameter_deg as f32,
            azimuths,
            horizons,
        };
        let columns = azimuths * COLUMNS_PER_AZIMUTH;
        let da = TAU / columns as f64;
        let de = FRAC_PI_2 / BANDS as f64;
        let mut basis = Vec::with_capacity(columns);
        let mut dirs = Vec::with_capacity(columns);
        for c in 0..columns {
            let a = da * (c as f64 + 0.5);
            let mut b = [[0f64; 9]; BANDS];
            let mut d = [[0f64; 3]; BANDS];
            for k in 0..BANDS {
                let (lo, hi) = (de * k as f64, de * (k + 1) as f64);
                let v = direction(a, 0.5 * (lo + hi));
                let omega = da * (hi.sin() - lo.sin());
                b[k] = sh_basis(v).map(|y| y * omega);
                d[k] = v;
            }
            basis.push(b);
            dirs.push(d);
        }
        ObjectGrid {
            info,
            points,
            basis,
            dirs,
        }
    }

    /// What the track's manifest says about the grid: the horizons included for a weather
    /// with direct sun, none for one without (its layer 0 is 0 everywhere).
    pub fn info(&self, weather: Option<&WeatherLight>) -> GridInfo {
        let direct = weather.is_none_or(|w| direct_share(w.sky.cover) > 0.0);
        let mut info = self.info.clone();
        if !direct {
            info.horizons.clear();
        }
        info
    }

    /// The horizon of point `p` towards map-frame azimuth `a`, linear between azimuths.
    fn horizon(&self, p: &Point, a: f64) -> f64 {
        let (a0, a1, f) = bracket(a, self.info.azimuths);
        let f = f as f64;
        p.horizon[a0] as f64 * (1.0 - f) + p.horizon[a1] as f64 * f
    }

    /// The grid of frame `i` under `weather` (the scene's sector sky and clouds for
    /// `None`), at sun `sun`, whose lightmap `lit` (RGB, the terrain's size) is already lit,
    /// and each cell's sun transmission (layer 0 of the track's frame).
    pub fn frame(
        &self,
        pre: &Precomputed,
        scene: &Scene,
        weather: Option<&WeatherLight>,
        sun: &SunState,
        i: usize,
        lit: &[f32],
    ) -> (Grid, Vec<f32>) {
        let hf = &pre.hf;
        // The sky's true radiance towards each column and band.
        let (direct, clouds, radiance): (f64, Option<&CloudLayer>, Vec<[[f64; 3]; BANDS]>) =
            match weather {
                Some(w) => {
                    let dome = w.dome(scene, sun);
                    let r = self
                        .dirs
                        .iter()
                        .map(|col| col.map(|v| dome.radiance(v)))
                        .collect();
                    (direct_share(w.sky.cover), w.clouds.as_ref(), r)
                }
                None => {
                    let sectors = sector_values(scene, sun, pre.horizons.azimuths);
                    let half = PI / pre.horizons.azimuths as f64;
                    let r = self
                        .dirs
                        .iter()
                        .map(|col| {
                            let a = col[0][1].atan2(col[0][0]);
                            let s = (((a + half).rem_euclid(TAU)) / (TAU / SECTORS as f64))
                                as usize
                                % SECTORS;
                            [sectors[s].map(|l| l as f64 * PI); BANDS]
                        })
                        .collect();
                    (1.0, pre.clouds.as_ref(), r)
                }
            };
        // Σ over the bands from the zenith down to band k: sky L·Y dΩ and ground Y dΩ.
        let columns = self.basis.len();
        let mut sky_cum = vec![[[[0f64; 3]; 9]; BANDS + 1]; columns];
        let mut ground_cum = vec![[[0f64; 9]; BANDS + 1]; columns];
        for c in 0..columns {
            for k in (0..BANDS).rev() {
                for j in 0..9 {
                    let y = self.basis[c][k][j];
                    ground_cum[c][k][j] = ground_cum[c][k + 1][j] + y;
                    for ch in 0..3 {
                        sky_cum[c][k][j][ch] = sky_cum[c][k + 1][j][ch] + radiance[c][k][ch] * y;
                    }
                }
            }
        }
        // ∫ Y dΩ over the lower hemisphere: Y00 · 2π and Y10 · (−π); the rest vanish.
        let mut lower = [0f64; 9];
        let y = sh_basis([0.0, 0.0, 1.0]);
        lower[0] = y[0] * TAU;
        lower[2] = -y[2] * PI;

        let alpha = scene.sun.angular_diameter_deg.to_radians();
        let sun_up = sun.elevation + 0.5 * alpha > 0.0 && direct > 0.0;
        let sun_dir = sun.dir.map(|c| c as f32);
        let cloud_frame = if sun_up {
            (i, sun.dir)
        } else {
            last_sun_up(scene, i, alpha)
        };
        let lift_scale = 1.0 / (0.5 * (hf.cell_x + hf.cell_y)) as f32;
        let cloud_h = scene.clouds.height_m as f32;
        let albedo = scene.albedo;
        let ambient = scene.sky.ambient * 2.0 * PI.sqrt();
        let de = FRAC_PI_2 / BANDS as f64;
        let (cells, transmission): (Vec<Cell>, Vec<f32>) = self
            .points
            .par_iter()
            .enumerate()
            .map(|(k, p)| {
                let mut t = direct;
                if let Some(cl) = clouds {
                    // Clouds under a set sun do nothing: the night keeps the evening's
                    // field (cheap to code, and no step at sunset).
                    let (ci, cdir) = cloud_frame;
                    let lift = (cloud_h - p.z).max(0.0) * lift_scale;
                    t *= cl.transmission(p.x, p.y, ci, scene.frames, cdir, lift) as f64;
                }
                let mut sun_rgb = [0f32; 3];
                if sun_up {
                    let o = self.info.visibility(k, sun_dir) as f64;
                    sun_rgb = sun.color.map(|c| (c * o * t) as f32);
                }
                let g = mean(lit, hf.w, p.footprint).map(|v| v * albedo);
                let mut sky = [[0f64; 3]; 9];
                let mut ground = lower;
                for c in 0..columns {
                    let a = TAU * (c as f64 + 0.5) / columns as f64;
                    let beta = self.horizon(p, a).clamp(0.0, FRAC_PI_2);
                    let k = ((beta / de) as usize).min(BANDS - 1);
                    let (lo, hi) = (de * k as f64, de * (k + 1) as f64);
                    // The part of band k above the horizon, in the band's solid angle.
                    let f = (hi.sin() - beta.sin()) / (hi.sin() - lo.sin());
                    for j in 0..9 {
                        let y = self.basis[c][k][j];
                        let vis = ground_cum[c][k + 1][j] + f * y;
                        ground[j] += ground_cum[c][0][j] - vis;
                        for ch in 0..3 {
                            sky[j][ch] += sky_cum[c][k + 1][j][ch] + f * radiance[c][k][ch] * y;
                        }
                    }
                }
                let mut sh = [[0f32; 3]; 9];
                for j in 0..9 {
                    for ch in 0..3 {
                        let l = sky[j][ch] + g[ch] * ground[j];
                        sh[j][ch] = (COSINE_LOBE[j] * l) as f32;
                    }
                }
                for v in sh[0].iter_mut() {
                    *v += ambient as f32;
                }
                (Cell { sun: sun_rgb, sh }, t as f32)
            })
            .unzip();
        let [nx, ny] = self.info.cells;
        let grid = Grid {
            nx,
            ny,
            cells,
            sun_dir,
        };
        (grid, transmission)
    }
}

/// The last frame at or before `i` (cyclically) with the sun's disc above the astronomical
/// horizon, and its sun's direction; `i` itself if the day has none.
fn last_sun_up(scene: &Scene, i: usize, alpha: f64) -> (usize, [f64; 3]) {
    let n = scene.frames;
    (0..n)
        .map(|back| (i + n - back) % n)
        .map(|k| (k, crate::light::sun_for_frame(scene, k)))
        .find(|(_, s)| s.elevation + 0.5 * alpha > 0.0)
        .map_or((i, [0.0, 0.0, 1.0]), |(k, s)| (k, s.dir))
}

/// The mean of RGB image `lit` (`w` texels a row) over texels x0..x1, y0..y1.
fn mean(lit: &[f32], w: usize, [x0, x1, y0, y1]: [usize; 4]) -> [f64; 3] {
    let mut s = [0f64; 3];
    for y in y0..y1 {
        for px in lit[(y * w + x0) * 3..(y * w + x1) * 3].chunks_exact(3) {
            for c in 0..3 {
                s[c] += px[c] as f64;
            }
        }
    }
    let n = ((x1 - x0) * (y1 - y0)).max(1) as f64;
    s.map(|v| v / n)
}

/// The horizon's elevation seen from (x, y) at height `z` towards map-frame azimuth `a`
/// (radians, at least 0): the height field marched to its edge in steps that grow with
/// the distance (a twentieth of it: finer than the elevation's own change).
fn march(hf: &HeightField, x: f32, y: f32, z: f32, a: f64) -> f32 {
    let (dx, dy) = (a.cos(), a.sin());
    let metres = ((dx * hf.cell_x).powi(2) + (dy * hf.cell_y).powi(2)).sqrt();
    let (w, h) = ((hf.w - 1) as f64, (hf.h - 1) as f64);
    let mut best = 0f64;
    let mut d = 0.5f64;
    loop {
        let (px, py) = (x as f64 + dx * d, y as f64 + dy * d);
        if px < 0.0 || py < 0.0 || px > w || py > h {
            break;
        }
        let rise = hf.sample(px as f32, py as f32) as f64 - z as f64;
        best = best.max(rise / (d * metres));
        d += (d * 0.05).max(0.5);
    }
    best.atan() as f32
}

#[cfg(test)]
mod tests;
