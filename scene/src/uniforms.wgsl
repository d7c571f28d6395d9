// The scene's uniforms, shared by the terrain's and the objects' shaders (lib.rs prepends
// this file to both).

struct Uniforms {
    view_proj: mat4x4<f32>,
    inv_view_proj: mat4x4<f32>,
    // x: exposure, y: detail texture repeats across the map, z: detail strength,
    // w: 1 when the sky map is bound.
    params: vec4<f32>,
    sky_zenith: vec4<f32>,
    sky_horizon: vec4<f32>,
    // The camera (world), and the sun: direction (world) with w = cos of the disc's
    // angular radius, and colour (the direct sun's texel value at normal incidence).
    eye: vec4<f32>,
    sun_dir: vec4<f32>,
    sun_color: vec4<f32>,
}

@group(0) @binding(0) var<uniform> u: Uniforms;
