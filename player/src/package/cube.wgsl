// The sky map resampled into a cube map, each texel along its own direction, for
// renderers whose skyboxes and environment maps take cubes (Bevy's `Skybox`). The cube's
// directions are (east, up, north), the faces in WebGPU's order (+x, −x, +y, −y, +z, −z);
// below the horizon each direction takes the horizon's radiance at its azimuth.

// The sky map: equirectangular over the upper hemisphere, column c at azimuth 360° (c + ½)
// / width clockwise from north, row r at elevation 90° (1 − (r + ½) / height).
@group(0) @binding(0) var sky: texture_2d<f32>;
@group(0) @binding(1) var cube: texture_storage_2d_array<rgba16float, write>;

const TAU: f32 = 6.283185307179586;
const HALF_PI: f32 = 1.5707963267948966;

// Direction of texel `xy` of face `face` of an `n`² cube (WebGPU's and Vulkan's layout).
fn face_direction(xy: vec2<u32>, face: u32, n: u32) -> vec3<f32> {
    let s = 2.0 * (f32(xy.x) + 0.5) / f32(n) - 1.0;
    let t = 2.0 * (f32(xy.y) + 0.5) / f32(n) - 1.0;
    switch face {
        case 0u: { return vec3<f32>(1.0, -t, -s); }
        case 1u: { return vec3<f32>(-1.0, -t, s); }
        case 2u: { return vec3<f32>(s, 1.0, t); }
        case 3u: { return vec3<f32>(s, -1.0, -t); }
        case 4u: { return vec3<f32>(s, -t, 1.0); }
        default: { return vec3<f32>(-s, -t, -1.0); }
    }
}

fn texel(c: i32, r: i32, size: vec2<i32>) -> vec3<f32> {
    let col = ((c % size.x) + size.x) % size.x;
    let row = clamp(r, 0, size.y - 1);
    return textureLoad(sky, vec2<i32>(col, row), 0).rgb;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = textureDimensions(cube).x;
    if (id.x >= n || id.y >= n || id.z >= 6u) {
        return;
    }
    let d = normalize(face_direction(id.xy, id.z, n));
    // Azimuth clockwise from north (towards east), elevation above the horizon.
    let azimuth = atan2(d.x, d.z);
    let elevation = max(asin(clamp(d.y, -1.0, 1.0)), 0.0);
    let size = vec2<i32>(textureDimensions(sky));
    // Bilinear between texel centres: across in azimuth (wrapping), down in elevation
    // (clamped to the zenith's and the horizon's rows).
    let u = fract(azimuth / TAU) * f32(size.x) - 0.5;
    let v = (1.0 - elevation / HALF_PI) * f32(size.y) - 0.5;
    let c0 = floor(u);
    let r0 = floor(v);
    let f = vec2<f32>(u - c0, v - r0);
    let c = i32(c0);
    let r = i32(r0);
    let top = mix(texel(c, r, size), texel(c + 1, r, size), f.x);
    let bottom = mix(texel(c, r + 1, size), texel(c + 1, r + 1, size), f.x);
    textureStore(cube, id.xy, i32(id.z), vec4<f32>(mix(top, bottom, f.y), 1.0));
}
