// Decodes a segment's coefficients on the GPU, one plane (a "job") at a time: parses the
// plane's coefficient stream as the file codes it, then dequantises and inverse-transforms
// a keyframe plane's blocks into the head, or gathers a bubble plane's terms per block
// for the reconstruction to sum.
//
// The stream (docs/FORMAT.md, "Coefficient streams") is a sequence of (zero run, value)
// pairs of LEB128 varints over the positions f · n + b (zig-zag index f of block b, n
// blocks), the first n positions holding each block's DC as the difference from the
// previous block's. The decoder thread scanned it and noted an entry point every 128
// pairs (byte, position, running DC, first block written), so that the parse
// (parse.wgsl) runs an invocation, or on a GPU a workgroup, per entry point. The scan
// refused malformed streams: the pairs seen here are well-formed.
//
// `parse` writes every non-zero coefficient into a dense plane of i32 coefficients, 64 per
// block, and sets its bit in the block's 64-bit mask, in the plane's slot of a ring of
// masks that the segment's decode cleared before its first parse (`clear_buffer`, a
// memset on lavapipe: putting each block back to zero after use in the shaders needed
// barriers, which cost lavapipe more; one clear a plane cost a GPU a step each). The passes after it visit only a
// block's set bits, in increasing zig-zag order: each texel sums
// (value · step · T[ky][y]) · T[kx][x] in that order, as the reference decoder's sparse
// path does (`key_add` here, the reconstruction for the bubble terms).
//
// A plane of more blocks than one storage binding holds (8192² and up) goes in parts of
// blocks [lo, hi): each part parses the whole stream and keeps the blocks in its range.

// The DCT tables (blocks.wgsl), in the address space `TABLES` the adapter reads fastest
// (layouts.rs, `TablesIn`).
@group(0) @binding(1) var<TABLES> tables: Tables;
// A plane of the chain's head keyframe (f32).
@group(0) @binding(3) var key_plane: texture_storage_2d<r32float, read_write>;
// The head keyframe whole, a plane a layer (`key_pack`, whose dispatch covers them all).
@group(0) @binding(14) var key_planes: texture_2d_array<f32>;
// The 16-bit keyframes, two texels per R32Uint texel (`key_pack`).
@group(0) @binding(4) var planes16: texture_storage_2d_array<r32uint, write>;
// The previous keyframe's range per region of REGION² texels and plane: (lowest value,
// step), region (x, y) of plane p at (p · regions.y + y) · regions.x + x.
@group(0) @binding(5) var<storage, read_write> ranges: array<vec2<f32>>;
// The dense plane `parse` filled: block d's coefficients at 64 · d …, its mask at d of
// the part's slot of the ring of masks (`job.masks_at`, in words).
@group(0) @binding(6) var<storage, read> coefs: array<i32>;
@group(0) @binding(7) var<storage, read> masks: array<vec2<u32>>;
// Per group of GROUP_BLOCKS blocks, which have a coefficient (a 64-bit set, from `parse`,
// at `job.sets_at` in words):
// a workgroup visits only those. (Checking every block in every invocation cost lavapipe,
// which runs a workgroup's invocations eight at a time, more than decoding the blocks of
// a sparse predicted keyframe; so did sharing the check through workgroup memory, whose
// barriers lavapipe pays for per workgroup.)
@group(0) @binding(10) var<storage, read> groups: array<vec2<u32>>;
// Per bubble set: per plane and tile (row-major), the tile's degree, the largest term k of
// the set's bubble planes with a coefficient in the tile, 0 where none has; then the
// set's term counter (`bubble_gather`).
@group(0) @binding(9) var<storage, read_write> degrees: array<atomic<u32>>;
// Per bubble layer (set · layers + (k − 2) · channels + plane) and block of 8 × 8 texels
// of the plane: the block's 64-bit mask of coefficients, where its terms after the first
// start in `terms`, and the first term (f32 bits, dequantised), as the reconstruction
// reads them (`bubble_gather`).
@group(0) @binding(12) var bubble_blocks: texture_storage_2d_array<rgba32uint, write>;
// The set's terms after each block's first, a block's together in increasing zig-zag
// order (`bubble_gather` says how).
@group(0) @binding(13) var<storage, read_write> terms: array<u32>;

// Blocks one workgroup of a block pass decodes, one after another: 64, one per
// invocation to look at first.
const GROUP_BLOCKS: u32 = 64u;

// The member span that holds the tile of rank r: the last whose first rank is at most r
// (a binary search, once per workgroup).
fn find_span(r: u32) -> u32 {
    var lo = 0u;
    var hi = job.member_count;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (words[job.members + 2u * mid + 1u] <= r) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// Where block b of the stream lies in the plane (its first texel): raster order over a
// keyframe plane; for a bubble plane, in the tile of rank b / per² among the members, in
// member span `*span` or one after it (blocks come in increasing order, so the span only
// moves forward).
fn block_origin(b: u32, span: ptr<function, u32>) -> vec2<u32> {
    if (job.member_count == 0u) {
        return vec2<u32>(b % job.blocks_x, b / job.blocks_x) * 8u;
    }
    let per2 = job.per * job.per;
    let r = b / per2;
    let i = b % per2;
    while (*span + 1u < job.member_count && words[job.members + 2u * (*span + 1u) + 1u] <= r) {
        *span = *span + 1u;
    }
    let s = *span;
    let tile = words[job.members + 2u * s] + (r - words[job.members + 2u * s + 1u]);
    let t = vec2<u32>(tile % job.tiles_x, tile / job.tiles_x);
    return (t * job.per + vec2<u32>(i % job.per, i / job.per)) * 8u;
}

// The span to start from for a workgroup whose first block is `first`.
fn first_span(first: u32) -> u32 {
    if (job.member_count == 0u) {
        return 0u;
    }
    return find_span(first / (job.per * job.per));
}

// Block d's mask (in the part).
fn mask(d: u32) -> vec2<u32> {
    return masks[job.masks_at / 2u + d];
}

// Coefficient i (zig-zag) of block d (in the part), from the job's place in the dense
// plane.
fn coef(d: u32, i: u32) -> i32 {
    return coefs[(job.dense_at + d) * 64u + i];
}

// The sums at texels (x, y) and, with `pair`, (x + 1, y) of block d (in the part) onto
// `acc` and 0.
fn block_sum(d: u32, m: vec2<u32>, x: u32, y: u32, acc: f32, pair: bool) -> vec2<f32> {
    var a = acc;
    var b = 0.0;
    var terms = bits_of(m);
    loop {
        let i = next_bit(&terms);
        if (i == 64u) {
            break;
        }
        let pos = zigzag(i);
        let kx = pos % 8u;
        let c = f32(coef(d, i)) * job.step * basis(pos / 8u, y);
        a = a + c * basis(kx, x);
        if (pair) {
            b = b + c * basis(kx, x + 1u);
        }
    }
    return vec2<f32>(a, b);
}

// Bits [a, b) of a 32-bit word (a ≤ b ≤ 32).
fn bits_between(a: u32, b: u32) -> u32 {
    if (b - a >= 32u) {
        return 0xFFFFFFFFu;
    }
    return ((1u << (b - a)) - 1u) << a;
}

// The group of GROUP_BLOCKS blocks a block pass's workgroup visits, and which of its
// blocks: those with a coefficient, all of them or, with `job.split` workgroups per group
// (on a GPU), this workgroup's share, so that no workgroup's chain of blocks in sequence
// is long (one workgroup per 64 blocks left an H100 waiting on the longest chains).
// `every`: the share's blocks of the part, with a coefficient or not.
struct Share {
    group: u32,
    present: Bits,
    every: Bits,
}

fn group_share(wg: vec3<u32>) -> Share {
    let i = group_index(wg);
    let split = max(job.split, 1u);
    let g = i / split;
    let width = GROUP_BLOCKS / split;
    let lo = (i % split) * width;
    let hi = lo + width;
    let keep = vec2<u32>(
        bits_between(min(lo, 32u), min(hi, 32u)),
        bits_between(max(lo, 32u) - 32u, max(hi, 32u) - 32u),
    );
    let first = job.lo + g * GROUP_BLOCKS;
    let n = select(0u, min(job.hi - first, GROUP_BLOCKS), first < job.hi);
    let inside = vec2<u32>(bits_between(0u, min(n, 32u)), bits_between(0u, max(n, 32u) - 32u));
    return Share(g, bits_of(groups[job.sets_at / 2u + g] & keep), bits_of(keep & inside));
}

// A keyframe plane's blocks added onto what the plane holds (the reference keyframe) for
// a predicted keyframe. An intra keyframe's are written over it, every block of the part,
// those without a coefficient as zeros (their masks are empty): no pass zeros the plane
// first (on an H100 such a pass stored 400 GB/s, a third of a 4096² segment's keyframe
// time), and nothing is read.
@compute @workgroup_size(8, 8)
fn key_add(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) l: vec3<u32>,
) {
    take_job(wg);
    let share = group_share(wg);
    let first = job.lo + share.group * GROUP_BLOCKS;
    var present = share.present;
    if (job.intra != 0u) {
        present = share.every;
    }
    var span = first_span(first);
    loop {
        let j = next_bit(&present);
        if (j == 64u) {
            break;
        }
        let b = first + j;
        let m = mask(b - job.lo);
        let xy = block_origin(b, &span) + l.xy;
        var acc = 0.0;
        if (job.intra == 0u) {
            acc = textureLoad(key_plane, xy).x;
        }
        let s = block_sum(b - job.lo, m, l.x, l.y, acc, false);
        textureStore(key_plane, xy, vec4<f32>(s.x, 0.0, 0.0, 0.0));
    }
}

// A bubble plane's blocks, one invocation each, as the reconstruction reads them: each
// block's mask, its first term (dequantised, f32) and where the rest go in the set's
// `terms`: two to a word as 16-bit integers (the reconstruction scales them by the
// plane's step, as the reference dequantises), or, where one of them does not fit in 16
// bits, one dequantised f32 each, the top bit of the start saying so. A workgroup's blocks
// take one run of `terms`, claimed with one atomic add on the set's counter (the order of
// the runs does not matter). Every block of the plane's tiles is written, those with
// nothing as zeros, so no pass clears the layer first: the reconstruction reads a tile's
// layers only up to its degree in the set, which this pass marks (`degrees`, cleared
// before the set's first plane) and which only a tile with a coefficient in this plane's
// stream reaches. A bubble term stays in the transform domain because bubble planes are
// sparse: at 2048² and 4096² three blocks in four hold one term or none, and a set takes
// 2–3 bytes per texel this way against 18 as 16-bit texels.
var<workgroup> words_of: array<u32, 64>;
var<workgroup> terms_of: array<u32, 64>;
var<workgroup> run_start: u32;

@compute @workgroup_size(64)
fn bubble_gather(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    take_job(wg);
    let first = job.lo + group_index(wg) * 64u;
    let b = first + li;
    let inside = b < job.hi;
    var m = vec2<u32>(0u);
    if (inside) {
        m = mask(b - job.lo);
    }
    let d = b - job.lo;
    // The terms after the first: their count, and whether each fits in 16 bits.
    var rest = bits_of(m);
    let n = countOneBits(m.x) + countOneBits(m.y);
    var wide = false;
    if (n > 1u) {
        _ = next_bit(&rest);
        loop {
            let i = next_bit(&rest);
            if (i == 64u) {
                break;
            }
            let v = coef(d, i);
            wide = wide || v < -32768 || v > 32767;
        }
    }
    let others = max(n, 1u) - 1u;
    var words = (others + 1u) / 2u;
    if (wide) {
        words = others;
    }
    words_of[li] = words;
    terms_of[li] = n;
    workgroupBarrier();
    if (li == 0u) {
        var total = 0u;
        for (var i = 0u; i < 64u; i = i + 1u) {
            total = total + words_of[i];
        }
        var at = 0u;
        if (total > 0u) {
            at = atomicAdd(&degrees[job.counter], total);
        }
        run_start = at;
    }
    workgroupBarrier();
    if (!inside) {
        return;
    }
    var at = run_start;
    for (var i = 0u; i < li; i = i + 1u) {
        at = at + words_of[i];
    }
    let start = at;
    var first_term = 0u;
    var left = bits_of(m);
    var k = 0u;
    var pending = 0u;
    loop {
        let i = next_bit(&left);
        if (i == 64u) {
            break;
        }
        let v = coef(d, i);
        if (k == 0u) {
            first_term = bitcast<u32>(f32(v) * job.step);
        } else if (wide) {
            put_term(at, bitcast<u32>(f32(v) * job.step));
            at = at + 1u;
        } else if (k % 2u == 1u) {
            pending = bitcast<u32>(v) & 0xFFFFu;
        } else {
            put_term(at, pending | (bitcast<u32>(v) << 16u));
            at = at + 1u;
        }
        k = k + 1u;
    }
    if (!wide && k > 1u && k % 2u == 0u) {
        // An odd number of terms after the first: the last word holds one.
        put_term(at, pending);
    }
    var span = first_span(b);
    let o = block_origin(b, &span) / 8u;
    let flag = select(0u, 0x80000000u, wide);
    textureStore(bubble_blocks, o, job.layer, vec4<u32>(m.x, m.y, start | flag, first_term));
    // The tile's degree, once per tile (its blocks come together, a whole tile in one
    // workgroup: per² divides 64), where any of its blocks has a coefficient.
    let per2 = job.per * job.per;
    if (li % per2 == 0u) {
        var any = 0u;
        for (var j = 0u; j < per2; j = j + 1u) {
            any = any | terms_of[li + j];
        }
        if (any != 0u) {
            let tile = (o.y / job.per) * job.tiles_x + o.x / job.per;
            atomicMax(&degrees[job.base + tile], job.term);
        }
    }
}

// Word `at` of the set's terms. (The decode sized `terms` for a bound on the segment's
// terms, one word each: a stream that breaks it loses terms, never writes out of bounds.)
fn put_term(at: u32, w: u32) {
    if (at < arrayLength(&terms)) {
        terms[at] = w;
    }
}

// The side of a region of the previous keyframe with its own range. Small enough that a
// region's range stays near the local contrast (the rounding is range / 131070), large
// enough that the ranges cost nothing (8 bytes per 1024 texels and plane).
const REGION: u32 = 32u;

// A plane of the head keyframe packed into layer `job.layer` of the 16-bit keyframes
// (slot · channels + plane) in one pass, one invocation per row of a region, two regions
// to a workgroup, so that a plane is spread over 32 invocations per region (one
// invocation per region reading it whole, twice, left an H100 waiting on 2048 loads in a
// row). Each row's lowest and highest value are merged by `atomicMax` into its region's
// extent in workgroup memory; after a barrier each row rounds its pairs of texels to
// 16-bit steps of that range, and row 0 writes the region's (lowest value, step). (Two
// passes, the extents in a storage buffer cleared before them, cost a GPU two more steps
// and a clear per plane.) The head is only read: the next keyframe is added onto it
// afterwards.

// f32 bits in an order that `atomicMax` on u32 keeps: larger values larger, and (for
// the lowest value, stored complemented) smaller values larger.
fn ordered(v: f32) -> u32 {
    let b = bitcast<u32>(v);
    if ((b & 0x80000000u) != 0u) {
        return ~b;
    }
    return b | 0x80000000u;
}

fn unordered(o: u32) -> f32 {
    if ((o & 0x80000000u) != 0u) {
        return bitcast<f32>(o & 0x7fffffffu);
    }
    return bitcast<f32>(~o);
}

// The region and row of the invocation: 64 per workgroup, 32 rows of a region, regions in
// row order. `r` is past the last region when the invocation has none.
fn region_row(wg: vec3<u32>, li: u32) -> vec2<u32> {
    let i = group_index(wg) * 64u + li;
    return vec2<u32>(i / REGION, i % REGION);
}

// The extents of the workgroup's two regions: (lowest, stored complemented; highest),
// in `ordered` form (zero: empty).
var<workgroup> extents: array<atomic<u32>, 4>;

@compute @workgroup_size(64)
fn key_pack(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    // One dispatch packs every plane of the head, plane workgroup_id.z with its own job.
    take_job(wg);
    let plane = wg.z;
    let regions = (job.size + vec2<u32>(REGION - 1u)) / REGION;
    let rr = region_row(wg, li);
    let region = vec2<u32>(rr.x % regions.x, rr.x / regions.x);
    let origin = region * REGION;
    let y = origin.y + rr.y;
    let live = rr.x < regions.x * regions.y && y < job.size.y;
    let end = min(origin.x + REGION, job.size.x);
    let side = 2u * (li / REGION);
    if (live) {
        var lo = 3.4e38;
        var hi = -3.4e38;
        for (var x = origin.x; x < end; x = x + 1u) {
            let v = textureLoad(key_planes, vec2<u32>(x, y), plane, 0).x;
            lo = min(lo, v);
            hi = max(hi, v);
        }
        atomicMax(&extents[side], ~ordered(lo));
        atomicMax(&extents[side + 1u], ordered(hi));
    }
    workgroupBarrier();
    if (!live) {
        return;
    }
    let lo = unordered(~atomicLoad(&extents[side]));
    let hi = unordered(atomicLoad(&extents[side + 1u]));
    let step = (hi - lo) / 65535.0;
    var inv = 0.0;
    if (step > 0.0) {
        inv = 1.0 / step;
    }
    if (rr.y == 0u) {
        ranges[(job.layer * regions.y + region.y) * regions.x + region.x] = vec2<f32>(lo, step);
    }
    // Planes are whole tiles, so a region's width is even: texels go in pairs.
    for (var x = origin.x; x < end; x = x + 2u) {
        let a = textureLoad(key_planes, vec2<u32>(x, y), plane, 0).x;
        let b = textureLoad(key_planes, vec2<u32>(x + 1u, y), plane, 0).x;
        let qa = u32(clamp(round((a - lo) * inv), 0.0, 65535.0));
        let qb = u32(clamp(round((b - lo) * inv), 0.0, 65535.0));
        textureStore(planes16, vec2<u32>(x / 2u, y), job.layer, vec4<u32>(qa | (qb << 16u), 0u, 0u, 0u));
    }
}
