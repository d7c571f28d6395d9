//! vbim-bake: day/night terrain lightmap sequences from real height fields, with the
//! analytical terrain lighting of the papers listed in `docs/REFERENCES.md` — horizon-map sun
//! shadows with a soft sun disc, Stewart–Langer sky light with interreflection, obscurance
//! ambient — and optional moving cloud shadows. `docs/BAKE.md` gives every equation.
//!
//! - **A day**: [`bake`] a [`Scene`] into frames, `manifest.json` and a contact sheet
//!   ([`BakeOptions`], [`BakeSummary`]); [`load_terrain`] gives the scene's height field at
//!   the bake's resolution.
//! - **One frame**: [`Precomputed`] (the horizon map, sky visibility and obscurance of a
//!   terrain), then [`light_frame`] (or [`light_with_sun`] under any [`SunState`]).
//! - **Weathers**: a scene's `[[weather]]` tables ([`WeatherParams`]) each light the day
//!   under an analytic [`SkyDome`] ([`WeatherLight`], [`light_frame_in`]) and write that sky
//!   as a track of its own ([`sky_map`], [`texel_direction`]), and the light an object on
//!   the terrain receives as a third ([`ObjectGrid`]).
//! - **Writing**: [`write_frame`], [`write_file`] and [`write_text`], atomic, through
//!   `vbim-files`, whose [`Manifest`], [`FrameInfo`], [`FrameFormat`] and [`Progress`] are
//!   re-exported here.
//!
//! Inside: `day` (a whole bake), `scene` (the scene file), `heightfield` and `detail` (the
//! terrain), `horizon`, `sky`, `obscurance` and `cache` (the precomputation), `sun`,
//! `atmosphere` and `clouds` (the day's light, `sky_track` its sky, `objects` the light
//! for objects), `light` (a frame), `output` and `manifest` (the files).

mod atmosphere;
mod cache;
mod clouds;
mod day;
mod detail;
mod error;
mod heightfield;
mod horizon;
mod light;
mod manifest;
mod objects;
mod obscurance;
mod output;
mod scene;
mod sky;
mod sky_track;
mod sun;

pub use atmosphere::{direct_share, direction, SkyDome, SkyWeather, OVERCAST_SHARE};
pub use day::{bake, load_terrain, BakeOptions, BakeSummary, WeatherSummary, PACKAGE_FILE};
pub use detail::DetailParams;
pub use error::BakeError;
pub use heightfield::{HeightField, Sidecar};
pub use light::{
    frame_time, light_frame, light_frame_in, light_with_sun, light_with_sun_in, sky_model,
    sun_for_frame, sun_visibility, Precomputed, WeatherLight,
};
pub use objects::{ObjectGrid, DIR as IRRADIANCE_DIR};
pub use output::{contact_sheet, to_png8, write_file, write_frame, write_text};
pub use scene::{
    parse_rate, CloudParams, ObjectParams, ObscuranceParams, Scene, SkyParams, SunParams,
    ViewParams, WeatherParams, SKY_MAP_WIDTH,
};
pub use sky_track::{sky_map, texel_direction, DIR as SKY_DIR};
pub use sun::{SkyModel, SunState};
pub use vbim_files::{frame_name, FrameFormat, FrameInfo, Manifest, Progress};
