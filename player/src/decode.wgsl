// Decodes a segment's coefficients on the GPU: dequantises the quantised DCT terms of
// one plane (a "job") and inverse-transforms them into its resident texture.
//
// A job's blocks come in runs (player/src/compact.rs), a record of two words each:
//   word 0: first block column | block row << 11 | (blocks − 1) << 22
//   word 1: where the run's entries start, in u16 units from the job's first entry
// and the blocks' terms as a stream of u16 entries, each block's last entry flagged:
//   zig-zag index << 10 | last << 9 | value (9-bit two's complement), or, for a value
//   outside −255…255, index << 10 | last << 9 | 0x100 followed by the value's low and
//   high halves; an empty block is one entry of value 0 with `last` set.
// One workgroup decodes one run, block after block; each texel sums its block's terms in
// increasing zig-zag order, (value · step · T[ky][y]) · T[kx][x], as the reference
// decoder's sparse path does.

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
// A plane of the chain's head keyframe (f32).
@group(0) @binding(3) var key_plane: texture_storage_2d<r32float, read_write>;
// 16-bit planes, two texels per R32Uint texel: the bubble planes (one layer per term and
// plane) in the bubble passes, the previous keyframe's planes in `key_pack`.
@group(0) @binding(4) var planes16: texture_storage_2d_array<r32uint, write>;
// The previous keyframe's range per region of REGION² texels and plane: (lowest value,
// step), region (x, y) of plane p at (p · regions.y + y) · regions.x + x.
@group(0) @binding(5) var<storage, read_write> ranges: array<vec2<f32>>;

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

// The sums at two texels of a block, (x, y) and (x + 1, y), onto `acc`, and where the
// next block's entries start. (One texel is the pair's first with `pair` false.)
struct Sums {
    a: f32,
    b: f32,
    next: u32,
}

// Adds the terms of the block whose entries start at `start` at samples (x, y) and, with
// `pair`, (x + 1, y).
fn block_sum(start: u32, x: u32, y: u32, acc: f32, pair: bool) -> Sums {
    var a = acc;
    var b = 0.0;
    var i = start;
    var more = true;
    while (more) {
        let e = term16(i);
        i = i + 1u;
        var q = i32(e & 0x1FFu);
        if (q == 0x100) {
            q = bitcast<i32>(term16(i) | (term16(i + 1u) << 16u));
            i = i + 2u;
        } else if (q > 0x100) {
            q = q - 0x200;
        }
        if (q != 0) {
            let pos = zigzag(e >> 10u);
            let kx = pos % 8u;
            let c = f32(q) * job.step * basis(pos / 8u, y);
            a = a + c * basis(kx, x);
            if (pair) {
                b = b + c * basis(kx, x + 1u);
            }
        }
        more = (e & 0x200u) == 0u;
    }
    return Sums(a, b, i);
}

struct Run {
    x0: u32,
    y0: u32,
    blocks: u32,
    first: u32,
}

fn run_of(r: u32) -> Run {
    let w = words[job.records + 2u * r];
    let first = job.terms + words[job.records + 2u * r + 1u];
    return Run((w & 0x7FFu) * 8u, ((w >> 11u) & 0x7FFu) * 8u, (w >> 22u) + 1u, first);
}

// A keyframe plane's blocks added onto what the plane holds: the reference keyframe
// (copied there first) for a predicted keyframe, zeros for an intra one.
@compute @workgroup_size(8, 8)
fn key_add(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>) {
    let r = record_index(wg);
    if (r >= job.count) {
        return;
    }
    let run = run_of(r);
    var i = run.first;
    for (var j = 0u; j < run.blocks; j = j + 1u) {
        let xy = vec2<u32>(run.x0 + j * 8u + l.x, run.y0 + l.y);
        let s = block_sum(i, l.x, l.y, textureLoad(key_plane, xy).x, false);
        textureStore(key_plane, xy, vec4<f32>(s.a, 0.0, 0.0, 0.0));
        i = s.next;
    }
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
// of the first four columns of invocations makes two horizontally adjacent texels, one
// R32Uint texel of the layer. (Eight columns, half of them idle: with a workgroup of 4 × 8
// lavapipe ran the loop over a run's blocks once only. Idle lanes cost what working ones
// do on a SIMD machine, so the work is the same as 64 invocations of one texel.)
@compute @workgroup_size(8, 8)
fn bubble_write(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>) {
    let r = record_index(wg);
    if (r >= job.count || l.x >= 4u) {
        return;
    }
    let run = run_of(r);
    let x = 2u * l.x;
    var i = run.first;
    for (var j = 0u; j < run.blocks; j = j + 1u) {
        let s = block_sum(i, x, l.y, 0.0, true);
        let at = vec2<u32>(run.x0 / 2u + j * 4u + l.x, run.y0 + l.y);
        let packed = quantize(s.a) | (quantize(s.b) << 16u);
        textureStore(planes16, at, job.layer, vec4<u32>(packed, 0u, 0u, 0u));
        i = s.next;
    }
}

// Zeros the first `job.layer` layers of the bubble planes (`job.size` R32Uint texels each).
@compute @workgroup_size(8, 8)
fn bubble_zero(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= job.size.x || id.y >= job.size.y || id.z >= job.layer) {
        return;
    }
    textureStore(planes16, id.xy, id.z, vec4<u32>(0u));
}

// The side of a region of the previous keyframe with its own range. Small enough that a
// region's range stays near the local contrast (the rounding is range / 131070), large
// enough that the ranges cost nothing (8 bytes per 1024 texels and plane).
const REGION: u32 = 32u;

// Packs plane `job.layer` of the head keyframe into the previous keyframe's 16-bit plane:
// one invocation per region reads the region twice, first for its range, then to round
// each pair of texels to 16-bit steps of it. (No workgroup memory or barriers: a reduction
// in workgroup memory cost lavapipe, which runs a workgroup's invocations in turns
// between barriers, more than the reads it saved.) The head is only read: the next
// keyframe is added onto it afterwards.
@compute @workgroup_size(64)
fn key_pack(@builtin(global_invocation_id) id: vec3<u32>) {
    let regions = (job.size + vec2<u32>(REGION - 1u)) / REGION;
    if (id.x >= regions.x * regions.y) {
        return;
    }
    let region = vec2<u32>(id.x % regions.x, id.x / regions.x);
    let origin = region * REGION;
    let end = min(origin + vec2<u32>(REGION), job.size);
    var lo = 3.4e38;
    var hi = -3.4e38;
    for (var y = origin.y; y < end.y; y = y + 1u) {
        for (var x = origin.x; x < end.x; x = x + 1u) {
            let v = textureLoad(key_plane, vec2<u32>(x, y)).x;
            lo = min(lo, v);
            hi = max(hi, v);
        }
    }
    let step = (hi - lo) / 65535.0;
    var inv = 0.0;
    if (step > 0.0) {
        inv = 1.0 / step;
    }
    ranges[(job.layer * regions.y + region.y) * regions.x + region.x] = vec2<f32>(lo, step);
    // Planes are whole tiles, so a region's width is even: texels go in pairs.
    for (var y = origin.y; y < end.y; y = y + 1u) {
        for (var x = origin.x; x < end.x; x = x + 2u) {
            let a = textureLoad(key_plane, vec2<u32>(x, y)).x;
            let b = textureLoad(key_plane, vec2<u32>(x + 1u, y)).x;
            let qa = u32(clamp(round((a - lo) * inv), 0.0, 65535.0));
            let qb = u32(clamp(round((b - lo) * inv), 0.0, 65535.0));
            textureStore(planes16, vec2<u32>(x / 2u, y), job.layer, vec4<u32>(qa | (qb << 16u), 0u, 0u, 0u));
        }
    }
}
