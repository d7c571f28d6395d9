//! The manifest of a bake: the shared [`vbim_files::Manifest`] filled from the scene and
//! the frames' sun and sky, as the bake writes it beside its frames.

use vbim_files::{frame_name, FrameFormat, FrameInfo, Manifest};

use crate::scene::Scene;

/// The manifest of a bake of `scene` into `format` frames.
pub fn of_bake(
    scene: &Scene,
    format: FrameFormat,
    exposure: f32,
    png16_scale: Option<f32>,
    per_frame: &[FrameInfo],
) -> Manifest {
    Manifest {
        generator: concat!("vbim-bake ", env!("CARGO_PKG_VERSION")).into(),
        scene: Some(serde_json::to_value(scene).expect("a scene serialises")),
        width: scene.size,
        height: scene.size,
        frames: scene.frames,
        fps: Some(scene.fps.clone()),
        looping: true,
        format: Some(format),
        units: "linear irradiance / π, RGB; noon sun on a flat open surface ≈ 1".into(),
        exposure: Some(exposure),
        png16_scale,
        files: (0..scene.frames).map(|i| frame_name(i, format)).collect(),
        per_frame: per_frame.to_vec(),
        track: None,
        weather: None,
        sky: None,
        irradiance_grid: None,
    }
}
