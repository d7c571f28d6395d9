// Decodes a segment's coefficients on the GPU, one plane (a "job") at a time: parses the
// plane's coefficient stream as the file codes it, then dequantises and inverse-transforms
// its blocks into the resident textures.
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
// block, and sets its bit in the block's 64-bit mask; the plane was cleared before it
// (`clear_buffer`, a memset on lavapipe: putting each block back to zero after use in the
// shaders needed barriers, which cost lavapipe more). The passes after it visit only a
// block's set bits, in increasing zig-zag order: each texel sums
// (value · step · T[ky][y]) · T[kx][x] in that order, as the reference decoder's sparse
// path does.
//
// A plane of more blocks than one storage binding holds (8192² and up) goes in parts of
// blocks [lo, hi): each part parses the whole stream and keeps the blocks in its range.

// The DCT basis T[k][n] (row k, sample n) and the zig-zag order, from the reference
// decoder's own tables, so that both use the same f32 values; and each basis row's
// largest magnitude (the bubble bound's).
struct Tables {
    basis: array<vec4<f32>, 16>,
    zigzag: array<vec4<u32>, 16>,
    row_max: array<vec4<f32>, 2>,
}

@group(0) @binding(1) var<uniform> tables: Tables;
// A plane of the chain's head keyframe (f32).
@group(0) @binding(3) var key_plane: texture_storage_2d<r32float, read_write>;
// 16-bit planes, two texels per R32Uint texel: the bubble planes (one layer per term and
// plane) in the bubble passes, the previous keyframe's planes in `key_pack`.
@group(0) @binding(4) var planes16: texture_storage_2d_array<r32uint, write>;
// The previous keyframe's range per region of REGION² texels and plane: (lowest value,
// step), region (x, y) of plane p at (p · regions.y + y) · regions.x + x.
@group(0) @binding(5) var<storage, read_write> ranges: array<vec2<f32>>;
// The dense plane `parse` filled: block d's coefficients at 64 · d …, its mask at d.
@group(0) @binding(6) var<storage, read> coefs: array<i32>;
@group(0) @binding(7) var<storage, read> masks: array<vec2<u32>>;
// Per group of GROUP_BLOCKS blocks, which have a coefficient (a 64-bit set, from `parse`):
// a workgroup visits only those. (Checking every block in every invocation cost lavapipe,
// which runs a workgroup's invocations eight at a time, more than decoding the blocks of
// a sparse predicted keyframe; so did sharing the check through workgroup memory, whose
// barriers lavapipe pays for per workgroup.)
@group(0) @binding(10) var<storage, read> groups: array<vec2<u32>>;
// Per bubble layer, the largest |texel| / step of its blocks (f32 bits: for values ≥ 0
// their order is the u32 order, so `atomicMax` takes the largest).
@group(0) @binding(8) var<storage, read_write> bounds: array<atomic<u32>>;
// Per bubble set, plane and tile (row-major), the tile's degree: the largest term k of
// the set's bubble planes with a coefficient in the tile, 0 where none has
// (`bubble_write`).
@group(0) @binding(9) var<storage, read_write> degrees: array<atomic<u32>>;

// Blocks one workgroup of a block pass decodes, one after another: 64, one per
// invocation to look at first.
const GROUP_BLOCKS: u32 = 64u;

fn basis(k: u32, n: u32) -> f32 {
    let i = k * 8u + n;
    return tables.basis[i / 4u][i % 4u];
}

fn zigzag(i: u32) -> u32 {
    return tables.zigzag[i / 4u][i % 4u];
}

fn row_max(k: u32) -> f32 {
    return tables.row_max[k / 4u][k % 4u];
}


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
    return masks[d];
}

// A 64-bit set being visited in increasing order: the word still to visit, the high word
// after it, and the first bit's number in `bits` (0 or 32). One loop over the 64 bits:
// two nested loops, one per word, cost lavapipe more.
struct Bits {
    bits: u32,
    high: u32,
    base: u32,
}

fn bits_of(m: vec2<u32>) -> Bits {
    return Bits(m.x, m.y, 0u);
}

// The next set bit of `*s`, taken out of it; 64 when none is left.
fn next_bit(s: ptr<function, Bits>) -> u32 {
    if ((*s).bits == 0u) {
        if ((*s).high == 0u) {
            return 64u;
        }
        *s = Bits((*s).high, 0u, 32u);
    }
    let i = (*s).base + firstTrailingBit((*s).bits);
    (*s).bits = (*s).bits & ((*s).bits - 1u);
    return i;
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
        let c = f32(coefs[d * 64u + i]) * job.step * basis(pos / 8u, y);
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
    return Share(g, bits_of(groups[g] & keep), bits_of(keep & inside));
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

// The scale of a bubble plane whose texels are at most `bound` in magnitude: 16-bit
// signed steps that reach just past it (sums in f32 may exceed the bound by a little).
// reconstruct.wgsl computes the same.
fn bubble_scale(bound: f32) -> f32 {
    if (bound > 0.0 && bound <= 3.4e38) {
        return bound * 1.001 / 32767.0;
    }
    return 1.0;
}

// A bubble plane's bound, one invocation per block: the block's columns of the inverse
// transform (exact), then each row's largest possible value,
// |Σ_kx col[kx][y] · T[kx][x]| ≤ Σ_kx |col[kx][y]| · max |T[kx]|, in units of the step.
// With more than one part, `bubble_write` parses each part again once the bound is known.
@compute @workgroup_size(64)
fn bubble_bound(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let b = job.lo + group_index(wg) * 64u + li;
    if (b >= job.hi) {
        return;
    }
    let d = b - job.lo;
    let m = mask(d);
    if ((m.x | m.y) == 0u) {
        return;
    }
    var col: array<f32, 64>;
    var touched = 0u;
    var terms = bits_of(m);
    loop {
        let i = next_bit(&terms);
        if (i == 64u) {
            break;
        }
        let pos = zigzag(i);
        let ky = pos / 8u;
        let kx = pos % 8u;
        touched = touched | (1u << kx);
        let v = f32(coefs[d * 64u + i]);
        for (var y = 0u; y < 8u; y = y + 1u) {
            col[kx * 8u + y] = col[kx * 8u + y] + v * basis(ky, y);
        }
    }
    var rows: array<f32, 8>;
    while (touched != 0u) {
        let kx = firstTrailingBit(touched);
        touched = touched & (touched - 1u);
        for (var y = 0u; y < 8u; y = y + 1u) {
            rows[y] = rows[y] + abs(col[kx * 8u + y]) * row_max(kx);
        }
    }
    var peak = 0.0;
    for (var y = 0u; y < 8u; y = y + 1u) {
        peak = max(peak, rows[y]);
    }
    atomicMax(&bounds[job.layer], bitcast<u32>(peak));
}

fn quantize(x: f32, inv_scale: f32) -> u32 {
    let q = i32(clamp(round(x * inv_scale), -32767.0, 32767.0));
    return bitcast<u32>(q) & 0xFFFFu;
}

// A bubble plane's blocks, written whole (the zero pass cleared the rest): each of the
// first four columns of invocations makes two horizontally adjacent texels, one R32Uint
// texel of the layer. (Eight columns, half of them idle: with a workgroup of 4 × 8
// lavapipe ran the loop over a workgroup's blocks once only. Idle lanes cost what working
// ones do on a SIMD machine, so the work is the same as 64 invocations of one texel.)
// Each block marks its tile's degree in the set with this plane's term (`degrees`,
// cleared before the set's first plane): the reconstruction reads a tile's terms up to
// the last with a coefficient in it, the layers beyond holding zeros there. (Writing every
// block of a plane's tiles instead, zeros and all, so that no zero pass was needed, made a
// 512² segment's `bubble_write` 2.7 times as long on lavapipe.)
@compute @workgroup_size(8, 8)
fn bubble_write(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) l: vec3<u32>,
) {
    let share = group_share(wg);
    let first = job.lo + share.group * GROUP_BLOCKS;
    var present = share.present;
    if (l.x >= 4u) {
        return;
    }
    let bound = bitcast<f32>(atomicLoad(&bounds[job.layer])) * job.step;
    let inv_scale = 1.0 / bubble_scale(bound);
    let x = 2u * l.x;
    var span = first_span(first);
    // The tile this workgroup marked last: a tile's blocks come one after another, so a
    // tile is marked once per workgroup, not once per block (atomics cost lavapipe).
    var marked = 0xFFFFFFFFu;
    loop {
        let j = next_bit(&present);
        if (j == 64u) {
            break;
        }
        let b = first + j;
        let m = mask(b - job.lo);
        let s = block_sum(b - job.lo, m, x, l.y, 0.0, true);
        let o = block_origin(b, &span);
        let at = vec2<u32>(o.x / 2u + l.x, o.y + l.y);
        let packed = quantize(s.x, inv_scale) | (quantize(s.y, inv_scale) << 16u);
        textureStore(planes16, at, job.layer, vec4<u32>(packed, 0u, 0u, 0u));
        let rank = b / (job.per * job.per);
        if (l.x == 0u && l.y == 0u && rank != marked) {
            marked = rank;
            let side = job.per * 8u;
            let tile = (o.y / side) * job.tiles_x + o.x / side;
            atomicMax(&degrees[job.base + tile], job.term);
        }
    }
}

// Rows each invocation of `bubble_zero` zeros, 8 apart (`ZERO_ROWS` in decode.rs): a
// workgroup zeros 8 × 64 texels. With one texel per invocation the pass was a stream of
// tiny workgroups, and an H100 stored 410 GB/s.
const ZERO_ROWS: u32 = 8u;

// Zeros layers `job.base` + z of the bubble planes (`job.size` R32Uint texels each; one
// dispatch for a slice's worth of layers, whose latency is most of its cost on a GPU),
// `slice.x` rows of workgroups down (a slice of rows).
@compute @workgroup_size(8, 8)
fn bubble_zero(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) l: vec3<u32>,
) {
    if (id.x >= job.size.x) {
        return;
    }
    // (A slice starts slice.x / ZERO_ROWS rows of workgroups down: decode.rs sizes
    // slices of this pass by the texels, not the workgroups.)
    let top = (wg.y + slice.x / ZERO_ROWS) * 8u * ZERO_ROWS + l.y;
    for (var r = 0u; r < ZERO_ROWS; r = r + 1u) {
        let y = top + r * 8u;
        if (y < job.size.y) {
            textureStore(planes16, vec2<u32>(id.x, y), job.base + id.z, vec4<u32>(0u));
        }
    }
}

// The side of a region of the previous keyframe with its own range. Small enough that a
// region's range stays near the local contrast (the rounding is range / 131070), large
// enough that the ranges cost nothing (8 bytes per 1024 texels and plane).
const REGION: u32 = 32u;

// A plane of the head keyframe packed into layer `job.layer` of the 16-bit keyframes
// (slot · channels + plane) in two passes, one invocation per row of a region each, so
// that a plane is spread over 32 invocations per region (one invocation per region
// reading it whole, twice, left an H100 waiting on 2048 loads in a row). `key_range`
// finds each region's range: a row's lowest and highest value, merged by `atomicMax`
// into the region's extent, words `job.base` + 2 · region (the bounds buffer, cleared
// before: an extent of zeros is empty). `key_pack` then rounds each pair of texels of
// the row to 16-bit steps of the range, and the row 0 invocation writes the region's
// (lowest value, step). The head is only read: the next keyframe is added onto it
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

@compute @workgroup_size(64)
fn key_range(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let regions = (job.size + vec2<u32>(REGION - 1u)) / REGION;
    let rr = region_row(wg, li);
    if (rr.x >= regions.x * regions.y) {
        return;
    }
    let origin = vec2<u32>(rr.x % regions.x, rr.x / regions.x) * REGION;
    let y = origin.y + rr.y;
    if (y >= job.size.y) {
        return;
    }
    let end = min(origin.x + REGION, job.size.x);
    var lo = 3.4e38;
    var hi = -3.4e38;
    for (var x = origin.x; x < end; x = x + 1u) {
        let v = textureLoad(key_plane, vec2<u32>(x, y)).x;
        lo = min(lo, v);
        hi = max(hi, v);
    }
    atomicMax(&bounds[job.base + 2u * rr.x], ~ordered(lo));
    atomicMax(&bounds[job.base + 2u * rr.x + 1u], ordered(hi));
}

@compute @workgroup_size(64)
fn key_pack(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let regions = (job.size + vec2<u32>(REGION - 1u)) / REGION;
    let rr = region_row(wg, li);
    if (rr.x >= regions.x * regions.y) {
        return;
    }
    let region = vec2<u32>(rr.x % regions.x, rr.x / regions.x);
    let origin = region * REGION;
    let y = origin.y + rr.y;
    if (y >= job.size.y) {
        return;
    }
    let lo = unordered(~atomicLoad(&bounds[job.base + 2u * rr.x]));
    let hi = unordered(atomicLoad(&bounds[job.base + 2u * rr.x + 1u]));
    let step = (hi - lo) / 65535.0;
    var inv = 0.0;
    if (step > 0.0) {
        inv = 1.0 / step;
    }
    if (rr.y == 0u) {
        ranges[(job.layer * regions.y + region.y) * regions.x + region.x] = vec2<f32>(lo, step);
    }
    // Planes are whole tiles, so a region's width is even: texels go in pairs.
    let end = min(origin.x + REGION, job.size.x);
    for (var x = origin.x; x < end; x = x + 2u) {
        let a = textureLoad(key_plane, vec2<u32>(x, y)).x;
        let b = textureLoad(key_plane, vec2<u32>(x + 1u, y)).x;
        let qa = u32(clamp(round((a - lo) * inv), 0.0, 65535.0));
        let qb = u32(clamp(round((b - lo) * inv), 0.0, 65535.0));
        textureStore(planes16, vec2<u32>(x / 2u, y), job.layer, vec4<u32>(qa | (qb << 16u), 0u, 0u, 0u));
    }
}
