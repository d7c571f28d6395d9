// A weather switch's cross-fade: out = from + (to − from) · w, texel by texel, for two
// tracks of the same size (the lightmaps, or the skies, of two weathers).

struct Fade {
    w: f32,
    width: u32,
    height: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> fade: Fade;
@group(0) @binding(1) var from_tex: texture_2d<f32>;
@group(0) @binding(2) var to_tex: texture_2d<f32>;
@group(0) @binding(3) var out_tex: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= fade.width || id.y >= fade.height) {
        return;
    }
    let p = vec2<i32>(id.xy);
    let a = textureLoad(from_tex, p, 0);
    let b = textureLoad(to_tex, p, 0);
    textureStore(out_tex, p, vec4<f32>(mix(a.rgb, b.rgb, fade.w), 1.0));
}
