//! The bake's manifest (`manifest.json` beside the frames, and the metadata chunk of a
//! `.vbim` encoded from them): what a sequence of frames is. The bake writes it; the
//! encoder's input, `vbim decode`, `play` and `compare`, and the scene's sky read it —
//! all through this one type, never by string key.
//!
//! Reading is lenient: a manifest written by another tool may lack any field (each
//! defaults to absent or empty), so that what it does say is still used.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::atomic::write_text;

/// What a baked sequence is: its shape, timing, units, and each frame's sun and sky.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct Manifest {
    /// The program that wrote it.
    pub generator: String,
    /// The scene file's settings the bake ran with.
    pub scene: Option<serde_json::Value>,
    /// Frame width, texels.
    pub width: usize,
    /// Frame height, texels.
    pub height: usize,
    /// Frames in the day.
    pub frames: usize,
    /// Media frame rate as a rational (`24/1`, `1/6`).
    pub fps: Option<String>,
    /// Whether the day loops (frame N−1 is followed by frame 0).
    pub looping: bool,
    /// How the frames are stored.
    pub format: Option<FrameFormat>,
    /// What a texel holds (the project's CONVENTIONS.md).
    pub units: String,
    /// The 8-bit export curve's exposure e = 1.5 / median of per-frame max green.
    pub exposure: Option<f32>,
    /// 16-bit PNG frames: stored value = linear × this scale.
    pub png16_scale: Option<f32>,
    /// The frame files, in order.
    pub files: Vec<String>,
    /// Each frame's sun and sky.
    pub per_frame: Vec<FrameInfo>,
    /// What the frames are: absent for a lightmap, `"sky"` for a sky track (the sky's
    /// radiance over the upper hemisphere, `docs/BAKE.md`), `"irradiance"` for light for
    /// objects.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub track: Option<String>,
    /// The weather the frames belong to, for a bake with weathers.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weather: Option<String>,
    /// A lightmap's sky track: its folder, relative to this manifest's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sky: Option<String>,
    /// An irradiance track's grid (`vbim_format::irradiance::GridInfo`: cells, height
    /// above the ground, albedo).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub irradiance_grid: Option<serde_json::Value>,
}

impl Manifest {
    /// The manifest's file name beside the frames.
    pub const FILE_NAME: &'static str = "manifest.json";

    /// Parses a manifest's JSON text.
    pub fn parse(json: &str) -> Result<Manifest, String> {
        serde_json::from_str(json).map_err(|e| format!("manifest: {e}"))
    }

    /// Reads the manifest at `path`.
    pub fn read(path: &Path) -> Result<Manifest, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Manifest::parse(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Writes it as `dir/manifest.json` (atomically); returns the path.
    pub fn write(&self, dir: &Path) -> std::io::Result<PathBuf> {
        let path = dir.join(Self::FILE_NAME);
        let text = serde_json::to_string_pretty(self).expect("a manifest serialises");
        write_text(&path, &text)?;
        Ok(path)
    }

    /// The sky colours of each frame: (zenith, horizon on the sun's side), RGB.
    pub fn sky(&self) -> impl Iterator<Item = ([f32; 3], [f32; 3])> + '_ {
        let f = |c: [f64; 3]| c.map(|v| v as f32);
        self.per_frame
            .iter()
            .map(move |i| (f(i.sky_color), f(i.sky_horizon_sun_side)))
    }
}

/// How a bake's frames are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameFormat {
    /// Half-float RGB OpenEXR, linear.
    Exr,
    /// 8-bit sRGB PNG through the protocol's export curve.
    Png8,
    /// 16-bit PNG of the linear value times the manifest's `png16_scale`.
    Png16,
}

impl std::str::FromStr for FrameFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "exr" => Ok(FrameFormat::Exr),
            "png8" => Ok(FrameFormat::Png8),
            "png16" => Ok(FrameFormat::Png16),
            _ => Err(format!("unknown format {s:?} (exr, png8 or png16)")),
        }
    }
}

/// The file name of frame `i` stored as `f`.
pub fn frame_name(i: usize, f: FrameFormat) -> String {
    match f {
        FrameFormat::Exr => format!("frame_{i:04}.exr"),
        FrameFormat::Png8 | FrameFormat::Png16 => format!("frame_{i:04}.png"),
    }
}

/// One frame's sun and sky, as the bake lit it.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct FrameInfo {
    /// The frame's number in the day.
    pub index: usize,
    /// Local solar time, hours.
    pub hours: f64,
    /// The sun's elevation above the horizon, degrees.
    pub sun_elevation_deg: f64,
    /// The sun's azimuth, degrees clockwise from north.
    pub sun_azimuth_deg: f64,
    /// Unit vector towards the sun, map frame (x east, y south, z up).
    pub sun_dir: [f64; 3],
    /// Texel value of the direct sun at normal incidence (after the atmosphere), RGB.
    pub sun_color: [f64; 3],
    /// Sky radiance at the zenith, RGB, texel units.
    pub sky_color: [f64; 3],
    /// Sky radiance on the sun's side of the horizon, RGB, texel units.
    pub sky_horizon_sun_side: [f64; 3],
    /// Largest green value of the frame (for the 8-bit export's exposure).
    pub max_green: f32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sparse_manifest_still_gives_what_it_says() {
        let m = Manifest::parse(r#"{"exposure": 2.5, "fps": "1/6", "other": 1}"#).unwrap();
        assert_eq!(m.exposure, Some(2.5));
        assert_eq!(m.fps.as_deref(), Some("1/6"));
        assert_eq!(m.png16_scale, None);
        assert!(m.per_frame.is_empty());
        assert!(Manifest::parse("[1, 2]").is_err());
    }
}
