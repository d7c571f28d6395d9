// Decodes a segment's coefficients on the GPU: dequantises the quantised DCT terms of
// one plane (a "job") and inverse-transforms them into its resident texture.
//
// A job's blocks come as records of two words, one per block that has a term:
//   word 0: block column | block row << 16 (in blocks of the padded plane)
//   word 1: where the block's terms start, in u16 units from the job's first term
// and its terms as a stream of u16, a block's terms ending where the next block's start:
//   zig-zag index << 10 | value (10-bit two's complement), or, for a value outside
//   −511…511, zig-zag index << 10 | 0x200 followed by the value's low and high halves.
// One workgroup decodes one block. Each texel sums its terms in increasing zig-zag order,
// (value · step · T[ky][y]) · T[kx][x], as the reference decoder's sparse path does.

struct Job {
    // Quantiser step of the plane.
    step: f32,
    // Bubbles: 1 / the plane's scale (stored value = round(x / scale), 16-bit signed).
    inv_scale: f32,
    // First record (word index) and number of records.
    records: u32,
    count: u32,
    // First term and the end of the last block's terms (u16 index into `words`).
    terms: u32,
    terms_end: u32,
    // Bubble layer written (the key passes write the layer their binding views).
    layer: u32,
    // Workgroups per row of the dispatch (records beyond 65 535 use more rows).
    groups_x: u32,
    // Texels of the plane (zero passes).
    size: vec2<u32>,
    pad0: u32,
    pad1: u32,
}

// The DCT basis T[k][n] (row k, sample n) and the zig-zag order, from the reference
// decoder's own tables, so that both use the same f32 values.
struct Tables {
    basis: array<vec4<f32>, 16>,
    zigzag: array<vec4<u32>, 16>,
}

@group(0) @binding(0) var<uniform> job: Job;
@group(0) @binding(1) var<uniform> tables: Tables;
@group(0) @binding(2) var<storage, read> words: array<u32>;
// A keyframe plane (one layer of the keyframe slots).
@group(0) @binding(3) var key_plane: texture_storage_2d<r32float, read_write>;
// The bubble planes: two 16-bit texels per R32Uint texel, one layer per (term, plane).
@group(0) @binding(4) var bubble_planes: texture_storage_2d_array<r32uint, write>;

fn basis(k: u32, n: u32) -> f32 {
    let i = k * 8u + n;
    return tables.basis[i / 4u][i % 4u];
}

fn zigzag(i: u32) -> u32 {
    return tables.zigzag[i / 4u][i % 4u];
}

fn term16(i: u32) -> u32 {
    return (words[i / 2u] >> ((i % 2u) * 16u)) & 0xFFFFu;
}

fn record_index(wg: vec3<u32>) -> u32 {
    return wg.y * job.groups_x + wg.x;
}

// Adds block `r`'s terms at sample (x, y) onto `acc`.
fn block_sum(r: u32, x: u32, y: u32, acc: f32) -> f32 {
    var v = acc;
    var i = job.terms + words[job.records + 2u * r + 1u];
    var end = job.terms_end;
    if (r + 1u < job.count) {
        end = job.terms + words[job.records + 2u * r + 3u];
    }
    loop {
        if (i >= end) {
            break;
        }
        let e = term16(i);
        var q = i32(e & 0x3FFu);
        i = i + 1u;
        if (q == 0x200) {
            q = bitcast<i32>(term16(i) | (term16(i + 1u) << 16u));
            i = i + 2u;
        } else if (q >= 0x200) {
            q = q - 0x400;
        }
        let pos = zigzag(e >> 10u);
        let c = f32(q) * job.step;
        v = v + (c * basis(pos / 8u, y)) * basis(pos % 8u, x);
    }
    return v;
}

// A keyframe plane's blocks added onto what the plane holds: the reference keyframe
// (copied there first) for a predicted keyframe, zeros for an intra one.
@compute @workgroup_size(8, 8)
fn key_add(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>) {
    let r = record_index(wg);
    if (r >= job.count) {
        return;
    }
    let b = words[job.records + 2u * r];
    let xy = vec2<u32>((b & 0xFFFFu) * 8u + l.x, (b >> 16u) * 8u + l.y);
    let old = textureLoad(key_plane, xy).x;
    textureStore(key_plane, xy, vec4<f32>(block_sum(r, l.x, l.y, old), 0.0, 0.0, 0.0));
}

@compute @workgroup_size(8, 8)
fn key_zero(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= job.size.x || id.y >= job.size.y) {
        return;
    }
    textureStore(key_plane, id.xy, vec4<f32>(0.0));
}

fn quantize(x: f32) -> u32 {
    let q = i32(clamp(round(x * job.inv_scale), -32767.0, 32767.0));
    return bitcast<u32>(q) & 0xFFFFu;
}

// A bubble plane's blocks, written whole (every other texel of the plane is zero): each
// invocation makes two horizontally adjacent texels, one R32Uint texel of the layer.
@compute @workgroup_size(4, 8)
fn bubble_write(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>) {
    let r = record_index(wg);
    if (r >= job.count) {
        return;
    }
    let b = words[job.records + 2u * r];
    let x0 = 2u * l.x;
    let a = block_sum(r, x0, l.y, 0.0);
    let c = block_sum(r, x0 + 1u, l.y, 0.0);
    let at = vec2<u32>((b & 0xFFFFu) * 4u + l.x, (b >> 16u) * 8u + l.y);
    textureStore(bubble_planes, at, job.layer, vec4<u32>(quantize(a) | (quantize(c) << 16u), 0u, 0u, 0u));
}

// Zeros the first `job.layer` layers of the bubble planes (`job.size` R32Uint texels each).
@compute @workgroup_size(8, 8)
fn bubble_zero(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= job.size.x || id.y >= job.size.y || id.z >= job.layer) {
        return;
    }
    textureStore(bubble_planes, id.xy, id.z, vec4<u32>(0u));
}
