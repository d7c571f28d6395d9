//! The lighting of one frame from the precomputed maps (`docs/BAKE.md`).
//!
//! texel = sun + sky, in units of irradiance / π:
//!   sun = L_sun · O_sun(p) · max(0, N·v_sun) · T_cloud(p)           (paper 001)
//!   D   = Σ_s L_sky,s · I_s(p) / π                                  (direct sky, Eq. 4)
//!   sky = D / (1 − C (1 − I/π)) + A                                 (Stewart–Langer)
//! or, with obscurance W(p) modulating the interreflected part and the ambient floor A:
//!   sky = D + D · (1 / (1 − C (1 − I/π)) − 1) · W + A · W           (paper 000, Eq. 5)

use rayon::prelude::*;

use crate::atmosphere::{direct_share, direction, SkyDome, SkyWeather};
use crate::clouds::CloudLayer;
use crate::heightfield::HeightField;
use crate::horizon::HorizonMap;
use crate::obscurance;
use crate::scene::Scene;
use crate::sky::{sector_centre, SectorSky, SkyVisibility, SECTORS};
use crate::sun::{sun_at, SkyModel, SunState};
use crate::FrameInfo;

/// Everything about the terrain that does not change over the day.
pub struct Precomputed {
    pub hf: HeightField,
    pub normals: Vec<[f32; 3]>,
    pub horizons: HorizonMap,
    pub sky: SkyVisibility,
    pub obscurance: Vec<f32>,
    pub clouds: Option<CloudLayer>,
}

impl Precomputed {
    pub fn compute(hf: HeightField, scene: &Scene) -> Precomputed {
        let normals = hf.normals();
        let horizons = HorizonMap::compute(&hf, &normals, scene.azimuths);
        let sky = SkyVisibility::compute(&horizons, &normals);
        let obscurance = if scene.obscurance.enabled {
            let cell = 0.5 * (hf.cell_x + hf.cell_y);
            let l_max = scene.obscurance.l_max_cells * cell;
            let tau = scene.obscurance.tau_cells.map_or(l_max / 3.0, |t| t * cell);
            obscurance::compute(
                &hf,
                &normals,
                obscurance::ObscuranceParams {
                    azimuths: 16,
                    l_max,
                    tau,
                },
            )
        } else {
            vec![1.0; hf.w * hf.h]
        };
        let clouds = Self::clouds_for(&hf, scene);
        Precomputed {
            hf,
            normals,
            horizons,
            sky,
            obscurance,
            clouds,
        }
    }

    pub fn clouds_for(hf: &HeightField, scene: &Scene) -> Option<CloudLayer> {
        scene
            .clouds
            .enabled
            .then(|| CloudLayer::new(hf.w.max(hf.h), scene.clouds.coverage, scene.clouds.seed))
    }
}

/// A weather's light: its analytic sky and its cloud layer (the same seed in every weather
/// of a scene, so that a fade between two keeps the clouds where they were).
pub struct WeatherLight {
    pub sky: SkyWeather,
    pub clouds: Option<CloudLayer>,
}

impl WeatherLight {
    /// The light of `weather` over the terrain `hf` of `scene`.
    pub fn new(hf: &HeightField, scene: &Scene, weather: &crate::scene::WeatherParams) -> Self {
        let cover = weather.cover;
        // Broken cloud casts moving shadows; a clear sky none, an overcast one no sun at all.
        let clouds = (cover > 0.0 && direct_share(cover) > 0.0)
            .then(|| CloudLayer::new(hf.w.max(hf.h), cover.min(0.95), scene.clouds.seed));
        WeatherLight {
            sky: SkyWeather {
                cover,
                turbidity: weather.turbidity,
            },
            clouds,
        }
    }

    /// The sun of frame `i` through this weather's haze (`sun::hazed`).
    pub fn sun(&self, scene: &Scene, i: usize) -> SunState {
        crate::sun::hazed(sun_for_frame(scene, i), self.sky.turbidity)
    }

    /// The sky dome at sun `sun`.
    pub fn dome(&self, scene: &Scene, sun: &SunState) -> SkyDome {
        SkyDome::new(sun, scene.sun.strength, self.sky, scene.sky.night)
    }
}

/// What the manifest records about each frame.
pub fn frame_time(scene: &Scene, i: usize) -> f64 {
    24.0 * i as f64 / scene.frames as f64
}

pub fn sun_for_frame(scene: &Scene, i: usize) -> SunState {
    sun_at(
        scene.latitude,
        scene.day_of_year,
        frame_time(scene, i),
        scene.sun.strength,
    )
}

/// The sun of frame `i` under `weather` (through its haze), or the scene's for `None`.
pub fn sun_in(scene: &Scene, weather: Option<&WeatherLight>, i: usize) -> SunState {
    weather.map_or_else(|| sun_for_frame(scene, i), |w| w.sun(scene, i))
}

pub fn sky_model(scene: &Scene) -> SkyModel {
    SkyModel {
        strength: scene.sky.strength,
        glow: scene.sky.glow,
        night: scene.sky.night,
    }
}

/// The direct-sun visibility O_sun for a horizon angle `phi` (paper 001): the share of the
/// sun disc of angular diameter `alpha` centred at elevation `centre` above the horizon.
pub fn sun_visibility(centre: f64, alpha: f64, phi: f64) -> f64 {
    ((centre + 0.5 * alpha - phi) / alpha).clamp(0.0, 1.0)
}

/// Lights frame `i` into `out` (RGB interleaved, linear) under the scene's sector sky.
pub fn light_frame(pre: &Precomputed, scene: &Scene, i: usize, out: &mut [f32]) -> FrameInfo {
    light_frame_in(pre, scene, None, i, out)
}

/// Lights frame `i` into `out` under `weather`'s analytic sky, or the scene's sector sky
/// and clouds for `None`.
pub fn light_frame_in(
    pre: &Precomputed,
    scene: &Scene,
    weather: Option<&WeatherLight>,
    i: usize,
    out: &mut [f32],
) -> FrameInfo {
    let sun = sun_in(scene, weather, i);
    light_with_sun_in(pre, scene, weather, &sun, i, out);
    let (zenith, horizon) = match weather {
        None => {
            let sky = sky_model(scene);
            let base = sky.base(sun.elevation);
            let glow = sky.glow(sun.elevation);
            (base, [0, 1, 2].map(|c| base[c] + glow[c]))
        }
        Some(w) => {
            let dome = w.dome(scene, &sun);
            let sun_az = sun.dir[1].atan2(sun.dir[0]);
            (
                dome.radiance([0.0, 0.0, 1.0]),
                dome.radiance(direction(sun_az, 0.0)),
            )
        }
    };
    let max_green = out.chunks_exact(3).map(|p| p[1]).fold(0.0, f32::max);
    FrameInfo {
        index: i,
        hours: frame_time(scene, i),
        sun_elevation_deg: sun.elevation.to_degrees(),
        sun_azimuth_deg: sun.azimuth_north.to_degrees(),
        sun_dir: sun.dir,
        sun_color: sun.color,
        sky_color: zenith,
        sky_horizon_sun_side: horizon,
        max_green,
    }
}

/// Lights one frame for an explicit sun (tests use this to place the sun exactly).
pub fn light_with_sun(pre: &Precomputed, scene: &Scene, sun: &SunState, i: usize, out: &mut [f32]) {
    light_with_sun_in(pre, scene, None, sun, i, out)
}

/// The sector sky of paper 001: a uniform dome with a glow on the sun's side per sector.
fn sector_sky(scene: &Scene, sun: &SunState, azimuths: usize) -> SectorSky {
    SectorSky::constant(sector_values(scene, sun, azimuths))
}

/// The sector sky's radiance / π per sector (for a horizon map of `azimuths` directions).
pub(crate) fn sector_values(scene: &Scene, sun: &SunState, azimuths: usize) -> [[f32; 3]; SECTORS] {
    let sun_az = sun.dir[1].atan2(sun.dir[0]);
    let model = sky_model(scene);
    let base = model.base(sun.elevation);
    let glow = model.glow(sun.elevation);
    let mut sector = [[0f32; 3]; SECTORS];
    for (s, l) in sector.iter_mut().enumerate() {
        let w = (sector_centre(s, azimuths) - sun_az).cos().max(0.0).powi(2);
        for c in 0..3 {
            l[c] = ((base[c] + glow[c] * w) / std::f64::consts::PI) as f32;
        }
    }
    sector
}

/// [`light_with_sun`] under `weather`'s sky (or the scene's sector sky for `None`).
pub fn light_with_sun_in(
    pre: &Precomputed,
    scene: &Scene,
    weather: Option<&WeatherLight>,
    sun: &SunState,
    i: usize,
    out: &mut [f32],
) {
    let hf = &pre.hf;
    let texels = hf.w * hf.h;
    assert_eq!(out.len(), texels * 3);
    let alpha = scene.sun.angular_diameter_deg.to_radians();
    let sun_az = sun.dir[1].atan2(sun.dir[0]);
    // The sun's upper limb below the astronomical horizon: no direct light anywhere.
    let (a0, a1, fa) = pre.horizons.bracket(sun_az);
    let (h0, h1) = (pre.horizons.plane(a0), pre.horizons.plane(a1));
    let azimuths = pre.horizons.azimuths;
    let (ground, direct_scale, clouds) = match weather {
        None => (sector_sky(scene, sun, azimuths), 1.0, pre.clouds.as_ref()),
        Some(w) => {
            let dome = w.dome(scene, sun);
            let ground = SectorSky::of(azimuths, |v| {
                dome.radiance(v).map(|c| c / std::f64::consts::PI)
            });
            (ground, direct_share(w.sky.cover) as f32, w.clouds.as_ref())
        }
    };
    let sun_up = sun.elevation + 0.5 * alpha > 0.0 && direct_scale > 0.0;
    let c_albedo = scene.albedo as f32;
    let ambient = scene.sky.ambient as f32;
    let modulate = scene.obscurance.enabled && scene.obscurance.modulate_interreflection;
    let lift_scale = 1.0 / (0.5 * (hf.cell_x + hf.cell_y)) as f32;
    let cloud_h = scene.clouds.height_m as f32;
    let frames = scene.frames;
    let sun_color = sun.color.map(|c| c as f32 * direct_scale);
    let sdir = sun.dir.map(|c| c as f32);
    out.par_chunks_mut(hf.w * 3)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..hf.w {
                let p = y * hf.w + x;
                let n = pre.normals[p];
                let mut direct = 0.0f32;
                if sun_up {
                    let phi = h0[p] * (1.0 - fa) + h1[p] * fa;
                    let o = sun_visibility(sun.elevation, alpha, phi as f64) as f32;
                    let ndotl = (n[0] * sdir[0] + n[1] * sdir[1] + n[2] * sdir[2]).max(0.0);
                    direct = o * ndotl;
                    if direct > 0.0 {
                        if let Some(cl) = clouds {
                            let lift = (cloud_h - hf.z[p]).max(0.0) * lift_scale;
                            direct *= cl.transmission(x as f32, y as f32, i, frames, sun.dir, lift);
                        }
                    }
                }
                let total_i = pre.sky.total[p];
                let f = 1.0 / (1.0 - c_albedo * (1.0 - total_i / std::f32::consts::PI));
                let w = pre.obscurance[p];
                let mut l = [[0f32; 3]; SECTORS];
                for (s, ls) in l.iter_mut().enumerate() {
                    *ls = ground.at(s, pre.sky.elevation[s * texels + p]);
                }
                for c in 0..3 {
                    let mut d = 0.0f32;
                    for (s, ls) in l.iter().enumerate() {
                        d += ls[c] * pre.sky.coef[s * texels + p];
                    }
                    let sky = if modulate {
                        d + d * (f - 1.0) * w + ambient * w
                    } else {
                        d * f + ambient
                    };
                    row[x * 3 + c] = sun_color[c] * direct + sky;
                }
            }
        });
}
