// The lightmap beneath objects, for the CPU: the package's lightmap output averaged over
// blocks of `factor` × `factor` texels into a small buffer that is copied to a mappable
// one and read a frame or two later (probe.rs). Linear RGB, the lightmap's units.

struct Params {
    // the small grid's width and height, the block's side, 0
    size: vec4<u32>,
}

@group(0) @binding(0) var lightmap: texture_2d<f32>;
@group(0) @binding(1) var<storage, read_write> small: array<vec4<f32>>;
@group(0) @binding(2) var<uniform> params: Params;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let w = params.size.x;
    let h = params.size.y;
    let f = params.size.z;
    if id.x >= w || id.y >= h {
        return;
    }
    let dims = textureDimensions(lightmap);
    var sum = vec3<f32>(0.0);
    var n = 0.0;
    for (var y = id.y * f; y < min((id.y + 1u) * f, dims.y); y++) {
        for (var x = id.x * f; x < min((id.x + 1u) * f, dims.x); x++) {
            sum += textureLoad(lightmap, vec2<u32>(x, y), 0).rgb;
            n += 1.0;
        }
    }
    small[id.y * w + id.x] = vec4<f32>(sum / max(n, 1.0), 1.0);
}
