// The terrain scene: base colour × streamed lightmap × repeating detail texture, lit in
// linear light and tone-mapped once, at the end (x·e / (1 + x·e), then the sRGB target
// encodes). The sky behind is the sky track's map where the stream has one (an
// equirectangular upper hemisphere, the zenith's row first, column 0 towards north) with
// the sun's disc drawn over it, else a gradient between the frame's horizon and zenith
// colours.

@group(0) @binding(1) var lightmap: texture_2d<f32>;
@group(0) @binding(2) var lightmap_sampler: sampler;
@group(0) @binding(3) var detail: texture_2d<f32>;
@group(0) @binding(4) var detail_sampler: sampler;
@group(0) @binding(5) var sky_map: texture_2d<f32>;
@group(0) @binding(6) var sky_sampler: sampler;

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
    @location(0) ndc: vec2<f32>,
}

@vertex
fn vs_sky(@builtin(vertex_index) i: u32) -> SkyOut {
    // One triangle covering the screen.
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u)) * 2.0 - 1.0;
    var o: SkyOut;
    o.pos = vec4<f32>(p, 1.0, 1.0);
    o.ndc = p;
    return o;
}

const PI: f32 = 3.14159265;

@fragment
fn fs_sky(i: SkyOut) -> @location(0) vec4<f32> {
    // The view ray through this pixel, in the world (x east, y up, z south).
    let far = u.inv_view_proj * vec4<f32>(i.ndc, 1.0, 1.0);
    let d = normalize(far.xyz / far.w - u.eye.xyz);
    var c: vec3<f32>;
    if (u.params.w > 0.5) {
        // The map frame's azimuth clockwise from north (−z) and elevation; below the
        // horizon the horizon's row, darkening.
        let az = atan2(d.x, -d.z);
        let e = asin(clamp(d.y, -1.0, 1.0));
        let uv = vec2<f32>(fract(az / (2.0 * PI) + 1.0), clamp(1.0 - e / (0.5 * PI), 0.0, 1.0));
        c = textureSampleLevel(sky_map, sky_sampler, uv, 0.0).rgb;
        if (e < 0.0) {
            c = c * max(1.0 + e * 4.0, 0.3);
        }
    } else {
        c = mix(u.sky_horizon.rgb, u.sky_zenith.rgb, pow(clamp(d.y, 0.0, 1.0), 0.5));
    }
    // The sun's disc, soft-edged, far brighter than the sky around it.
    let cs = dot(d, u.sun_dir.xyz);
    // Only above the horizon: below it the ground would hide the disc.
    let edge = smoothstep(u.sun_dir.w - 2e-5, u.sun_dir.w + 2e-5, cs) * step(0.0, d.y);
    c = c + u.sun_color.rgb * 40.0 * edge;
    return vec4<f32>(tonemap(c), 1.0);
}
