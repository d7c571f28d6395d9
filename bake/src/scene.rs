//! Scene files (TOML): everything a bake needs. Every field has a default, so a scene file
//! needs only its height field.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::BakeError;

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    #[serde(default = "d_name")]
    pub name: String,
    /// Height field path, relative to the scene file.
    pub heightfield: PathBuf,
    /// Degrees north.
    #[serde(default = "d_lat")]
    pub latitude: f64,
    /// 1–365.
    #[serde(default = "d_doy")]
    pub day_of_year: f64,
    /// Frames per day.
    #[serde(default = "d_frames")]
    pub frames: usize,
    /// Bake resolution (texels per side).
    #[serde(default = "d_size")]
    pub size: usize,
    /// Media frame rate "num/den" (frames per second of playback).
    #[serde(default = "d_fps")]
    pub fps: String,
    /// Terrain albedo C of the Stewart–Langer interreflection term.
    #[serde(default = "d_albedo")]
    pub albedo: f64,
    /// Azimuths of the horizon map.
    #[serde(default = "d_azimuths")]
    pub azimuths: usize,
    #[serde(default)]
    pub sun: SunParams,
    #[serde(default)]
    pub sky: SkyParams,
    #[serde(default)]
    pub obscurance: ObscuranceParams,
    #[serde(default)]
    pub clouds: CloudParams,
    /// Fractal detail below the height field's resolution (off unless asked for).
    #[serde(default)]
    pub detail: crate::detail::DetailParams,
    /// How `vbim play --scene` shows the terrain (not used by the bake).
    #[serde(default)]
    pub view: ViewParams,
    /// The irradiance track (light for objects on the terrain) of each weather.
    #[serde(default)]
    pub objects: ObjectParams,
    /// The weathers of the day (`[[weather]]` tables). With none, the bake lights one day
    /// under the sector sky of `[sky]` and the clouds of `[clouds]`; with some, it lights
    /// the day once per weather under its analytic sky and writes that sky beside it.
    #[serde(default, rename = "weather", skip_serializing_if = "Vec::is_empty")]
    pub weathers: Vec<WeatherParams>,
}

/// One weather of the day: its analytic sky (`docs/BAKE.md`, "Weathers and the analytic
/// sky").
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WeatherParams {
    /// The weather's name: its folder in the bake's output, its track in a package.
    pub name: String,
    /// Cloud cover, 0 (clear, Preetham's sky) to 1 (overcast, the CIE overcast sky).
    #[serde(default)]
    pub cover: f64,
    /// The clear sky's turbidity, 1.7 (very clear) to 10 (hazy).
    #[serde(default = "d_turbidity")]
    pub turbidity: f64,
}

fn d_turbidity() -> f64 {
    2.5
}

/// The sky map's width, texels (its height is a quarter of it: 90° of elevation).
pub const SKY_MAP_WIDTH: usize = 128;

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ViewParams {
    /// Vertical exaggeration of the terrain mesh.
    pub vertical_exaggeration: f64,
    /// Normalised elevation (0–1) above which flat ground is snow; above 1: no snow.
    pub snow_line: f64,
}
impl Default for ViewParams {
    fn default() -> Self {
        ViewParams {
            vertical_exaggeration: 2.0,
            snow_line: 1.1,
        }
    }
}

/// The irradiance grid a bake with weathers writes beside each weather's lightmap
/// (`docs/BAKE.md`, "Light for objects").
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectParams {
    /// Whether a bake with weathers writes irradiance tracks.
    pub enabled: bool,
    /// Cells along each side of the map (a multiple of 8 from 8 to 128, so that the
    /// track's layers sit on the codec's 8 × 8 blocks; 16 to 64 is the useful range; at
    /// most one a texel: a smaller bake has the most multiple of 8 it can).
    pub cells: usize,
    /// The height above the ground the grid's points stand at, metres.
    pub height_m: f64,
}
impl Default for ObjectParams {
    fn default() -> Self {
        ObjectParams {
            enabled: true,
            cells: 32,
            height_m: 2.0,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SunParams {
    /// Angular diameter of the sun disc used for soft shadows, degrees.
    pub angular_diameter_deg: f64,
    /// Texel value of the sun at normal incidence above the atmosphere.
    pub strength: f64,
}
impl Default for SunParams {
    fn default() -> Self {
        SunParams {
            angular_diameter_deg: 1.5,
            strength: 1.15,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SkyParams {
    /// Zenith sky radiance at full day (texel units).
    pub strength: f64,
    /// Sun-side glow at sunrise and sunset (texel units).
    pub glow: f64,
    /// Night sky radiance (texel units).
    pub night: f64,
    /// Constant ambient floor (texel units), modulated by obscurance when enabled.
    pub ambient: f64,
}
impl Default for SkyParams {
    fn default() -> Self {
        SkyParams {
            strength: 0.11,
            glow: 0.10,
            night: 3e-4,
            ambient: 5e-5,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObscuranceParams {
    pub enabled: bool,
    /// L_max in cells of the bake.
    pub l_max_cells: f64,
    /// τ in cells (default L_max / 3).
    pub tau_cells: Option<f64>,
    /// Whether obscurance modulates the interreflected sky light and the ambient floor.
    pub modulate_interreflection: bool,
}
impl Default for ObscuranceParams {
    fn default() -> Self {
        ObscuranceParams {
            enabled: true,
            l_max_cells: 20.0,
            tau_cells: None,
            modulate_interreflection: true,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CloudParams {
    pub enabled: bool,
    /// Share of the map under cloud (density ≥ 0.5).
    pub coverage: f64,
    /// Height of the cloud layer, metres above sea level.
    pub height_m: f64,
    pub seed: u32,
}
impl Default for CloudParams {
    fn default() -> Self {
        CloudParams {
            enabled: false,
            coverage: 0.45,
            height_m: 2500.0,
            seed: 1,
        }
    }
}

fn d_name() -> String {
    "scene".into()
}
fn d_lat() -> f64 {
    40.0
}
fn d_doy() -> f64 {
    172.0
}
fn d_frames() -> usize {
    240
}
fn d_size() -> usize {
    512
}
fn d_fps() -> String {
    "1/6".into()
}
fn d_albedo() -> f64 {
    0.25
}
fn d_azimuths() -> usize {
    32
}

impl Scene {
    /// Reads a scene file; the height field path becomes absolute (relative to the file).
    pub fn load(path: &Path) -> Result<Scene, BakeError> {
        let text = std::fs::read_to_string(path).map_err(|e| BakeError::input(path, e))?;
        let mut s: Scene = toml::from_str(&text).map_err(|e| BakeError::input(path, e))?;
        if s.heightfield.is_relative() {
            s.heightfield = path.parent().unwrap_or(Path::new(".")).join(&s.heightfield);
        }
        s.validate().map_err(|e| BakeError::input(path, e))?;
        Ok(s)
    }

    /// Media frame rate as (num, den).
    pub fn rate(&self) -> Result<(u32, u32), String> {
        parse_rate(&self.fps)
    }

    pub fn validate(&self) -> Result<(), String> {
        if !(1..=100_000).contains(&self.frames) {
            return Err(format!("frames = {} (1 to 100000)", self.frames));
        }
        if !(8..=8192).contains(&self.size) {
            return Err(format!("size = {} (8 to 8192)", self.size));
        }
        if !(-90.0..=90.0).contains(&self.latitude) {
            return Err(format!("latitude = {} (−90 to 90)", self.latitude));
        }
        if !(0.0..1.0).contains(&self.albedo) {
            return Err(format!("albedo = {} (0 to below 1)", self.albedo));
        }
        if self.azimuths < 8 || !self.azimuths.is_multiple_of(8) || self.azimuths > 256 {
            return Err(format!(
                "azimuths = {} (a multiple of 8 from 8 to 256)",
                self.azimuths
            ));
        }
        if !(self.sun.angular_diameter_deg > 0.0 && self.sun.angular_diameter_deg < 20.0) {
            return Err(format!(
                "sun.angular_diameter_deg = {}",
                self.sun.angular_diameter_deg
            ));
        }
        if self.obscurance.l_max_cells.is_nan() || self.obscurance.l_max_cells < 1.0 {
            return Err(format!(
                "obscurance.l_max_cells = {}",
                self.obscurance.l_max_cells
            ));
        }
        if !(0.0..=0.95).contains(&self.clouds.coverage) {
            return Err(format!(
                "clouds.coverage = {} (0 to 0.95)",
                self.clouds.coverage
            ));
        }
        for (i, w) in self.weathers.iter().enumerate() {
            let ok_name = !w.name.is_empty()
                && w.name.len() <= 64
                && w.name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
            if !ok_name {
                return Err(format!(
                    "weather {}: name {:?} (1 to 64 letters, digits, '-' or '_': it names a folder)",
                    i + 1,
                    w.name
                ));
            }
            if self.weathers[..i].iter().any(|o| o.name == w.name) {
                return Err(format!("weather {:?} is named twice", w.name));
            }
            if !(0.0..=1.0).contains(&w.cover) {
                return Err(format!(
                    "weather {:?}: cover = {} (0 to 1)",
                    w.name, w.cover
                ));
            }
            if !(1.7..=10.0).contains(&w.turbidity) {
                return Err(format!(
                    "weather {:?}: turbidity = {} (1.7 to 10)",
                    w.name, w.turbidity
                ));
            }
        }
        let o = &self.objects;
        if !(8..=128).contains(&o.cells) || !o.cells.is_multiple_of(8) {
            return Err(format!(
                "objects.cells = {} (a multiple of 8 from 8 to 128: a track's layers then sit \
                 on the codec's 8 × 8 blocks)",
                o.cells
            ));
        }
        if !(0.0..=10_000.0).contains(&o.height_m) {
            return Err(format!("objects.height_m = {} (0 to 10000)", o.height_m));
        }
        self.detail.validate()?;
        self.rate().map(|_| ())
    }
}

/// Parses "24", "24/1" or "1/6" into a positive rational.
pub fn parse_rate(s: &str) -> Result<(u32, u32), String> {
    let (n, d) = match s.split_once('/') {
        Some((n, d)) => (n.trim(), d.trim()),
        None => (s.trim(), "1"),
    };
    match (n.parse::<u32>(), d.parse::<u32>()) {
        (Ok(n), Ok(d))
            if n > 0 && d > 0 && (1.0 / 86_400.0..=1000.0).contains(&(n as f64 / d as f64)) =>
        {
            Ok((n, d))
        }
        _ => Err(format!(
            "frame rate {s:?} (expected a rational such as 24/1 or 1/6, from 1/86400 to 1000)"
        )),
    }
}

impl Scene {
    /// A scene with every default, for the given height field.
    pub fn with_heightfield(path: impl Into<PathBuf>) -> Scene {
        let mut s: Scene = toml::from_str("heightfield = \"-\"").expect("defaults parse");
        s.heightfield = path.into();
        s
    }
}
