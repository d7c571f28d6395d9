// Reconstructs the lightmap at one moment: per texel, the segment's terms weighted by the
// basis at the current normalised time (computed once per frame on the CPU, in f32, the
// same weights the reference decoder uses), then YCoCg → RGB, clamp, inverse transfer.
// While catching up after a stall, the result is blended with the image held on screen.

struct Params {
    // Basis weights w0..w8 (hats, then bubbles), packed four to a vector.
    w: array<vec4<f32>, 3>,
    size: vec2<u32>,
    layers: u32,
    // 0 = sRGB code values, 1 = log toe v = v0 (2^c − 1).
    transfer: u32,
    v0: f32,
    alpha: f32,
    channels: u32,
    blend: u32,
    // Keyframe slots of K_s and K_{s+1}.
    key0: u32,
    key1: u32,
    pad0: u32,
    pad1: u32,
    // Scale of each bubble layer (term k ≥ 2, plane p: layer (k − 2)·channels + p).
    scales: array<vec4<f32>, 6>,
}

@group(0) @binding(0) var<uniform> p: Params;
// Keyframes (two slots, `channels` R32Float layers each) and the segment's bubble terms
// (term k ≥ 2 at layers (k − 2)·channels …), 16-bit signed integers times the layer's
// scale, two to an R32Uint texel.
@group(0) @binding(1) var keys: texture_2d_array<f32>;
@group(0) @binding(2) var bubbles: texture_2d_array<u32>;
@group(0) @binding(3) var held: texture_2d<f32>;
@group(0) @binding(4) var out_tex: texture_storage_2d<rgba16float, write>;

fn weight(k: u32) -> f32 {
    return p.w[k / 4u][k % 4u];
}

fn srgb_to_linear(c: f32) -> f32 {
    if (c <= 0.04045) {
        return c / 12.92;
    }
    return pow((c + 0.055) / 1.055, 2.4);
}

fn decode(c: f32) -> f32 {
    if (p.transfer == 0u) {
        return srgb_to_linear(clamp(c, 0.0, 1.0));
    }
    return p.v0 * (exp2(clamp(c, 0.0, 120.0)) - 1.0);
}

fn key(xy: vec2<i32>, slot: u32) -> vec3<f32> {
    let b = i32(slot * p.channels);
    if (p.channels == 3u) {
        return vec3<f32>(
            textureLoad(keys, xy, b, 0).x,
            textureLoad(keys, xy, b + 1, 0).x,
            textureLoad(keys, xy, b + 2, 0).x,
        );
    }
    return vec3<f32>(textureLoad(keys, xy, b, 0).x, 0.0, 0.0);
}

fn bubble_layer(xy: vec2<i32>, layer: u32) -> f32 {
    let w = textureLoad(bubbles, vec2<i32>(xy.x >> 1u, xy.y), i32(layer), 0).x;
    let half = (w >> (u32(xy.x & 1) * 16u)) & 0xFFFFu;
    let q = bitcast<i32>(half << 16u) >> 16u;
    return f32(q) * p.scales[layer / 4u][layer % 4u];
}

fn bubble(xy: vec2<i32>, k: u32) -> vec3<f32> {
    let b = (k - 2u) * p.channels;
    if (p.channels == 3u) {
        return vec3<f32>(bubble_layer(xy, b), bubble_layer(xy, b + 1u), bubble_layer(xy, b + 2u));
    }
    return vec3<f32>(bubble_layer(xy, b), 0.0, 0.0);
}

// The nearest half float, as an f32 that the Rgba16Float store converts exactly: how a
// store rounds is up to the implementation (lavapipe truncates, a whole half-float step
// of error — 2^-10 relative, the protocol's entire GPU budget for HDR), so the shader
// rounds itself and the display is within half a step of what it computed.
fn nearest_half(x: f32) -> f32 {
    if (abs(x) < 6.103515625e-5) {
        // Below the smallest normal half float: steps of 2^-24.
        return round(x * 16777216.0) / 16777216.0;
    }
    return bitcast<f32>((bitcast<u32>(x) + 0x1000u) & 0xFFFFE000u);
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.size.x || id.y >= p.size.y) {
        return;
    }
    let xy = vec2<i32>(id.xy);
    // Same order as the reference decoder: w0·K0 + w1·K1, then each bubble.
    var c = weight(0u) * key(xy, p.key0) + weight(1u) * key(xy, p.key1);
    for (var k = 2u; k < p.layers; k = k + 1u) {
        c = c + weight(k) * bubble(xy, k);
    }
    var rgb: vec3<f32>;
    if (p.channels == 3u) {
        let t = c.x - c.z;
        rgb = vec3<f32>(decode(t + c.y), decode(c.x + c.z), decode(t - c.y));
    } else {
        let v = decode(c.x);
        rgb = vec3<f32>(v, v, v);
    }
    if (p.blend == 1u) {
        rgb = mix(textureLoad(held, xy, 0).xyz, rgb, p.alpha);
    }
    let out = vec3<f32>(nearest_half(rgb.x), nearest_half(rgb.y), nearest_half(rgb.z));
    textureStore(out_tex, xy, vec4<f32>(out, 1.0));
}
