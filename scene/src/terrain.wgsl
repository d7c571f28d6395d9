// The terrain scene: base colour × streamed lightmap × repeating detail texture, lit in
// linear light and tone-mapped once, at the end (x·e / (1 + x·e), then the sRGB target
// encodes). The sky behind is a gradient between the frame's horizon and zenith colours.

struct Uniforms {
    view_proj: mat4x4<f32>,
    // x: exposure, y: detail texture repeats across the map, z: detail strength, w: unused.
    params: vec4<f32>,
    sky_zenith: vec4<f32>,
    sky_horizon: vec4<f32>,
}

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var lightmap: texture_2d<f32>;
@group(0) @binding(2) var lightmap_sampler: sampler;
@group(0) @binding(3) var detail: texture_2d<f32>;
@group(0) @binding(4) var detail_sampler: sampler;

struct VsOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) base: vec3<f32>,
}

@vertex
fn vs_terrain(@location(0) pos: vec3<f32>, @location(1) uv: vec2<f32>, @location(2) base: vec3<f32>) -> VsOut {
    var o: VsOut;
    o.pos = u.view_proj * vec4<f32>(pos, 1.0);
    o.uv = uv;
    o.base = base;
    return o;
}

fn tonemap(c: vec3<f32>) -> vec3<f32> {
    let x = c * u.params.x;
    return x / (vec3<f32>(1.0) + x);
}

@fragment
fn fs_terrain(i: VsOut) -> @location(0) vec4<f32> {
    let light = textureSample(lightmap, lightmap_sampler, i.uv).rgb;
    let d = textureSample(detail, detail_sampler, i.uv * u.params.y).r;
    let detail_factor = mix(1.0, 2.0 * d, u.params.z);
    return vec4<f32>(tonemap(i.base * light * detail_factor), 1.0);
}

struct SkyOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) t: f32,
}

@vertex
fn vs_sky(@builtin(vertex_index) i: u32) -> SkyOut {
    // One triangle covering the screen.
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u)) * 2.0 - 1.0;
    var o: SkyOut;
    o.pos = vec4<f32>(p, 1.0, 1.0);
    o.t = clamp(p.y * 0.5 + 0.5, 0.0, 1.0);
    return o;
}

@fragment
fn fs_sky(i: SkyOut) -> @location(0) vec4<f32> {
    let c = mix(u.sky_horizon.rgb, u.sky_zenith.rgb, pow(i.t, 0.6));
    return vec4<f32>(tonemap(c), 1.0);
}
