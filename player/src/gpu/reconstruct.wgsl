// Reconstructs the lightmap at one moment: per texel, the segment's terms weighted by the
// basis at the current normalised time (computed once per frame on the CPU, in f32, the
// same weights the reference decoder uses), then YCoCg → RGB, clamp, inverse transfer.
// While catching up after a stall, the result is blended with the image held on screen,
// which `hold` keeps in 4 bytes a texel (RGB9E5, as the texture format of that name).
//
// A workgroup's tile of 16 × 16 texels is evaluated again only when the time has moved
// enough to change it by more than `reuse` since it last was: the tile keeps the weights
// it was evaluated with and bounds of what its terms hold, so the change is bounded
// without reading them. Otherwise the lightmap keeps what it has there and the tile costs
// its decision: about 80 bytes read and 40 written. Where the last frame that decided kept
// under one tile in 16, a frame that is not a probe (`PlayerConfig::reuse_probe`)
// evaluates every tile without deciding. No barrier and no workgroup memory
// (whose zeroing is a barrier): lavapipe pays about as much for one as for the evaluation.

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
    // Regions of the 16-bit keyframes' ranges, across and down (decode.wgsl, key_pack).
    regions: vec2<u32>,
    // The first layer of K_s and of K_{s+1} among the 16-bit keyframes (slot · channels).
    keys: vec2<u32>,
    // Quantiser step of each bubble layer (term k ≥ 2, plane p: layer (k − 2)·channels + p).
    steps: array<vec4<f32>, 6>,
    // The first layer of the segment's bubble set among the bubble blocks (layer
    // set_base + (k − 2)·channels + p).
    set_base: u32,
    // 1: K_{s+1} is read from the f32 head (it is not packed yet); 0: from `keys.y`.
    head_f32: u32,
    // The parameters' generation: a tile evaluated under another (other keyframes, set,
    // output or catch-up) is evaluated again.
    gen: u32,
    // The largest change of Σ over planes of |c| (the code domain) a tile may lag by; 0:
    // every tile every frame.
    reuse: f32,
    // Which copy of the tiles' state this frame reads (the other it writes).
    parity: u32,
    // The stream's tiles: side in texels, across a plane, in a plane.
    tile: u32,
    tiles_x: u32,
    tiles: u32,
    // The first word of the bubble set's tile degrees.
    degrees: u32,
    // The frame's place in a cycle of three (which counter of kept tiles it adds to; the
    // one before it reads, the one after it clears), whether it decides which tiles to
    // keep (1) or may skip deciding when the last deciding frame kept few (0), and
    // whether the feedback is on at all (`PlayerConfig::reuse_probe`).
    frame3: u32,
    probe: u32,
    feedback: u32,
}

@group(0) @binding(0) var<uniform> p: Params;
// The DCT tables (blocks.wgsl), in the address space `TABLES` the adapter reads fastest
// (layouts.rs, `TablesIn`).
@group(0) @binding(13) var<TABLES> tables: Tables;
// The head keyframe K_{s+1} (`channels` R32Float layers), read until the decode of the next
// segment has packed it into 16 bits, and the bubble sets' blocks: per block of 8 × 8
// texels and layer, the block's 64-bit mask of DCT coefficients, where its terms after
// the first are in `terms`, and the first (f32 bits, dequantised), from decode.wgsl's
// `bubble_gather`.
@group(0) @binding(1) var head: texture_2d_array<f32>;
@group(0) @binding(2) var bubble_blocks: texture_2d_array<u32>;
@group(0) @binding(3) var held: texture_2d<u32>;
@group(0) @binding(4) var out_tex: texture_storage_2d<rgba16float, write>;
// The 16-bit keyframes, two slots: K_s, and K_{s+1} once packed: steps of their region's
// range (lowest value, step), two to an R32Uint texel, one layer per slot and plane.
@group(0) @binding(5) var packed: texture_2d_array<u32>;
@group(0) @binding(6) var<storage, read> ranges: array<vec2<f32>>;
// The segment's bubble set's terms after each block's first, a block's in increasing
// zig-zag order: two 16-bit integers to a word (the low half first), times the layer's
// step; or, for a block whose `terms` start has its top bit set, one dequantised f32 each
// (decode.wgsl, `bubble_gather`).
@group(0) @binding(9) var<storage, read> terms: array<u32>;
// Per tile (row-major, workgroups across), in two copies (a frame reads one and writes the
// other, so that no invocation sees its own workgroup's update): the generation it was
// evaluated under and the nine weights it was evaluated with.
@group(0) @binding(10) var<storage, read_write> tiles: array<u32>;
const STATE_WORDS: u32 = 10u;
// Per tile, over it: the largest Σ_planes |K1 − K0|, Σ_planes |K0| and Σ_planes |C_k| for
// each bubble term k = 2 … 8 (f32 bits: non-negative, so their order is the integers').
// Cleared before the first frame of a generation, which finds them.
@group(0) @binding(12) var<storage, read_write> peaks: array<atomic<u32>>;
const PEAK_WORDS: u32 = 9u;
// Per bubble set, plane and tile (row-major), the tile's degree: the last term k with a
// coefficient in the tile (decode.wgsl, `bubble_gather`); the layers beyond are not this
// segment's there, and a tile reads no further.
@group(0) @binding(11) var<storage, read> degrees: array<u32>;

// An invocation reconstructs QUADS quads of 2 × 2 texels side by side (put before this
// source: 1 on a CPU adapter, 2 on a GPU; `DecodeShape::wide_reconstruct`): the two
// texels across a quad share a 32-bit word of every 16-bit plane, so each word is read
// once, and a region's range, a tile's degree, a block's terms and a layer's scale are
// found once for all of them (on lavapipe, where a load costs far more than the
// arithmetic around it, quads halved the frame; on an H200 pairs of quads took 14–21%
// off a detailed day's reconstruction, whose blocks hold several terms each, while
// lavapipe's frame was 15–25% slower with them). A workgroup covers a tile of 16 × 16
// texels, so 2 × 2 workgroups lie in one region (32² texels), and its ranges are read at
// addresses uniform across it.
const REGION_GROUPS: u32 = 2u;
const GROUP_X: u32 = 8u / QUADS;

// What an invocation computes of one plane or term: the values at its quads, the second
// (x + 2 … x + 3) unused where QUADS is 1.
struct Quads {
    a: vec4<f32>,
    b: vec4<f32>,
}

fn quads_zero() -> Quads {
    return Quads(vec4<f32>(0.0), vec4<f32>(0.0));
}

// The largest value at either quad.
fn quads_max(q: Quads) -> f32 {
    if (QUADS == 2u) {
        return max(max4(q.a), max4(q.b));
    }
    return max4(q.a);
}

fn quads_abs(q: Quads) -> Quads {
    return Quads(abs(q.a), abs(q.b));
}

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

// The two words of a 16-bit layer under the quad at word `w` (its top row), as the quad's
// four 16-bit halves: (x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1).
fn halves(t: texture_2d_array<u32>, w: vec2<i32>, layer: u32) -> vec4<u32> {
    let a = textureLoad(t, w, i32(layer), 0).x;
    let b = textureLoad(t, w + vec2<i32>(0, 1), i32(layer), 0).x;
    return vec4<u32>(a & 0xFFFFu, a >> 16u, b & 0xFFFFu, b >> 16u);
}

// Layer `plane` of the 16-bit keyframes at the invocation's quads (the first's words at
// `w`, the second's one word across).
fn packed_plane(w: vec2<i32>, region: vec2<u32>, plane: u32) -> Quads {
    let r = ranges[(plane * p.regions.y + region.y) * p.regions.x + region.x];
    var q = quads_zero();
    q.a = r.x + vec4<f32>(halves(packed, w, plane)) * r.y;
    if (QUADS == 2u) {
        q.b = r.x + vec4<f32>(halves(packed, w + vec2<i32>(1, 0), plane)) * r.y;
    }
    return q;
}

fn head_plane(xy: vec2<i32>, plane: u32) -> vec4<f32> {
    let l = i32(plane);
    return vec4<f32>(
        textureLoad(head, xy, l, 0).x,
        textureLoad(head, xy + vec2<i32>(1, 0), l, 0).x,
        textureLoad(head, xy + vec2<i32>(0, 1), l, 0).x,
        textureLoad(head, xy + vec2<i32>(1, 1), l, 0).x,
    );
}

// Plane `plane` of K_{s+1} at the invocation's quads.
fn next_plane(xy: vec2<i32>, w: vec2<i32>, region: vec2<u32>, plane: u32) -> Quads {
    if (p.head_f32 == 0u) {
        return packed_plane(w, region, p.keys.y + plane);
    }
    var q = quads_zero();
    q.a = head_plane(xy, plane);
    if (QUADS == 2u) {
        q.b = head_plane(xy + vec2<i32>(2, 0), plane);
    }
    return q;
}

// Bubble layer `layer` of the segment at the invocation's quads (the first's top-left
// texel is `xy`): its block's terms summed at each texel, (c · T[ky][y]) · T[kx][x] in
// increasing zig-zag order, as the reference decoder sums a block of few terms. The
// quads lie in one block; a block with no term costs one load, one with a single term
// (three in four of the non-empty blocks of the benchmark days' bubble planes at 2048²
// and 4096²) no more. A term's four basis values at a quad are one load
// (`Tables::quad`): five loads a term, with the zig-zag lookup, made a detailed day's
// reconstruction 30% slower on an H200 and its frame 12–20% slower on lavapipe.
fn bubble_plane(xy: vec2<i32>, layer: u32) -> Quads {
    let b = textureLoad(bubble_blocks, xy / 8, i32(p.set_base + layer), 0);
    let wide = (b.z & 0x80000000u) != 0u;
    let start = b.z & 0x7FFFFFFFu;
    let step = p.steps[layer / 4u][layer % 4u];
    // The first quad's place in the block, 4 · (y / 2) + x / 2; the second is the next.
    let quad = (u32(xy.y) % 8u / 2u) * 4u + u32(xy.x) % 8u / 2u;
    var s = quads_zero();
    var c = bitcast<f32>(b.w);
    // Terms visited so far: the first is in the block's texel, the rest in `terms`.
    var j = 0u;
    var left = bits_of(b.xy);
    loop {
        let i = next_bit(&left);
        if (i == 64u) {
            break;
        }
        if (j > 0u) {
            let r = j - 1u;
            if (wide) {
                c = bitcast<f32>(terms[start + r]);
            } else {
                // The half's 16 bits, sign-extended: the same f32(value) · step the
                // reference dequantises with.
                let w = terms[start + r / 2u] >> (16u * (r % 2u));
                c = f32(bitcast<i32>(w << 16u) >> 16u) * step;
            }
        }
        j = j + 1u;
        let t = tables.quad[i * 16u + quad];
        let r0 = c * t.x;
        let r1 = c * t.y;
        s.a = s.a + vec4<f32>(r0 * t.z, r0 * t.w, r1 * t.z, r1 * t.w);
        if (QUADS == 2u) {
            // The second quad has the first's rows (r0, r1) and its own columns.
            let u = tables.quad[i * 16u + quad + 1u];
            s.b = s.b + vec4<f32>(r0 * u.z, r0 * u.w, r1 * u.z, r1 * u.w);
        }
    }
    return s;
}

fn max4(v: vec4<f32>) -> f32 {
    return max(max(v.x, v.y), max(v.z, v.w));
}

// The end of the terms of plane `plane` at the quad: its tile's degree + 1, at most the
// segment's layers. (The reference decoder adds the terms beyond it too, all zeros: the
// sum is the same.)
fn terms_end(xy: vec2<i32>, plane: u32) -> u32 {
    let t = vec2<u32>(xy) / p.tile;
    let degree = degrees[p.degrees + plane * p.tiles + t.y * p.tiles_x + t.x];
    return min(p.layers, degree + 1u);
}

// w0·K0 + w1·K1 at each quad.
fn keys_value(k0: Quads, k1: Quads) -> Quads {
    let w0 = weight(0u);
    let w1 = weight(1u);
    return Quads(w0 * k0.a + w1 * k1.a, w0 * k0.b + w1 * k1.b);
}

// `c + w · t` at each quad.
fn add_weighted(c: Quads, w: f32, t: Quads) -> Quads {
    return Quads(c.a + w * t.a, c.b + w * t.b);
}

// Plane `plane` of the segment's polynomial at the invocation's quads, in the reference
// decoder's order: w0·K0 + w1·K1, then each bubble term.
fn plane_value(xy: vec2<i32>, w: vec2<i32>, region: vec2<u32>, plane: u32) -> Quads {
    let k0 = packed_plane(w, region, p.keys.x + plane);
    let k1 = next_plane(xy, w, region, plane);
    var c = keys_value(k0, k1);
    let end = terms_end(xy, plane);
    for (var k = 2u; k < end; k = k + 1u) {
        c = add_weighted(c, weight(k), bubble_plane(xy, (k - 2u) * p.channels + plane));
    }
    return c;
}

// The same, adding the quads' largest |K1 − K0|, |K0| and |C_k| in this plane to `peak`
// (0, 1, k): what `main_fresh` finds in the first frame of a generation.
fn plane_peaks(
    xy: vec2<i32>,
    w: vec2<i32>,
    region: vec2<u32>,
    plane: u32,
    peak: ptr<function, array<f32, 9>>,
) -> Quads {
    let k0 = packed_plane(w, region, p.keys.x + plane);
    let k1 = next_plane(xy, w, region, plane);
    var c = keys_value(k0, k1);
    (*peak)[0] += quads_max(Quads(abs(k1.a - k0.a), abs(k1.b - k0.b)));
    (*peak)[1] += quads_max(quads_abs(k0));
    let end = terms_end(xy, plane);
    for (var k = 2u; k < end; k = k + 1u) {
        let term = bubble_plane(xy, (k - 2u) * p.channels + plane);
        c = add_weighted(c, weight(k), term);
        (*peak)[k] += quads_max(quads_abs(term));
    }
    return c;
}

// A bound on how much Σ_planes |c| can have changed anywhere in a tile since it was last
// evaluated (its state at `s`, its peaks at `m`): the keyframes' part w0·K0 + w1·K1
// changes by Δw1·(K1 − K0) + (Δw0 + Δw1)·K0, each bubble term by Δw_k·C_k.
fn tile_change(s: u32, m: u32) -> f32 {
    let d0 = weight(0u) - bitcast<f32>(tiles[s + 1u]);
    let d1 = weight(1u) - bitcast<f32>(tiles[s + 2u]);
    var change = abs(d1) * bitcast<f32>(atomicLoad(&peaks[m]))
        + abs(d0 + d1) * bitcast<f32>(atomicLoad(&peaks[m + 1u]));
    for (var k = 2u; k < p.layers; k = k + 1u) {
        change = change + abs(weight(k) - bitcast<f32>(tiles[s + 1u + k]))
            * bitcast<f32>(atomicLoad(&peaks[m + k]));
    }
    return change;
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

// Colour, transfer, catch-up blend and store of one texel of the quad.
fn finish(xy: vec2<i32>, c: vec3<f32>) {
    if (u32(xy.x) >= p.size.x || u32(xy.y) >= p.size.y) {
        return;
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
        rgb = mix(unpack_rgb9e5(textureLoad(held, xy, 0).x), rgb, p.alpha);
    }
    let out = vec3<f32>(nearest_half(rgb.x), nearest_half(rgb.y), nearest_half(rgb.z));
    textureStore(out_tex, xy, vec4<f32>(out, 1.0));
}

// Tile `tile`'s state: where a frame reads it and where it writes it.
fn state_at(tile: u32, count: u32) -> vec2<u32> {
    return vec2<u32>(
        (p.parity * count + tile) * STATE_WORDS,
        ((1u - p.parity) * count + tile) * STATE_WORDS,
    );
}

// Records that the tile at `at` (read, write) was evaluated now (`go`) or kept.
fn keep_state(at: vec2<u32>, go: bool) {
    tiles[at.y] = p.gen;
    for (var k = 0u; k < 9u; k = k + 1u) {
        var w = tiles[at.x + 1u + k];
        if (go) {
            w = bitcast<u32>(weight(k));
        }
        tiles[at.y + 1u + k] = w;
    }
}

fn store_quad(xy: vec2<i32>, y: vec4<f32>, co: vec4<f32>, cg: vec4<f32>) {
    finish(xy, vec3<f32>(y.x, co.x, cg.x));
    finish(xy + vec2<i32>(1, 0), vec3<f32>(y.y, co.y, cg.y));
    finish(xy + vec2<i32>(0, 1), vec3<f32>(y.z, co.z, cg.z));
    finish(xy + vec2<i32>(1, 1), vec3<f32>(y.w, co.w, cg.w));
}

fn store_quads(xy: vec2<i32>, y: Quads, co: Quads, cg: Quads) {
    store_quad(xy, y.a, co.a, cg.a);
    if (QUADS == 2u) {
        store_quad(xy + vec2<i32>(2, 0), y.b, co.b, cg.b);
    }
}

// A frame: each tile evaluated unless its state says it changed by at most `reuse`.
@compute @workgroup_size(GROUP_X, 8)
fn main(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    var go = true;
    if (p.reuse > 0.0) {
        let tile = wg.y * groups.x + wg.x;
        let count = groups.x * groups.y;
        let at = state_at(tile, count);
        // The counters of kept tiles, after the tiles' bounds: this frame's, the last
        // frame's (what the last deciding frame kept), and the next frame's, which this
        // frame clears (the frame before last added to it, the last frame read it).
        let counters = count * PEAK_WORDS;
        let mine = counters + p.frame3;
        let last = atomicLoad(&peaks[counters + (p.frame3 + 2u) % 3u]);
        let first = wg.x == 0u && wg.y == 0u && li == 0u;
        if (p.feedback == 1u && first) {
            atomicStore(&peaks[counters + (p.frame3 + 1u) % 3u], 0u);
        }
        if (p.feedback == 1u && p.probe == 0u && last * 16u < count) {
            // The last deciding frame kept under one tile in 16: evaluate every tile
            // without deciding, pass the count on, and mark the tile evaluated under no
            // generation, so that the next deciding frame evaluates it and records it.
            if (first) {
                atomicStore(&peaks[mine], last);
            }
            if (li == 0u) {
                tiles[at.y] = 0u;
            }
        } else {
            // Every invocation decides alike: it reads what no invocation of this frame writes.
            go = p.blend == 1u || tiles[at.x] != p.gen || tile_change(at.x, tile * PEAK_WORDS) > p.reuse;
            if (li == 0u) {
                keep_state(at, go);
                if (!go && p.feedback == 1u) {
                    atomicAdd(&peaks[mine], 1u);
                }
            }
        }
    }
    let xy = vec2<i32>(i32(id.x * 2u * QUADS), i32(id.y * 2u));
    if (go && u32(xy.x) < p.size.x && u32(xy.y) < p.size.y) {
        let w = vec2<i32>(i32(id.x * QUADS), xy.y);
        let region = wg.xy / REGION_GROUPS;
        let y = plane_value(xy, w, region, 0u);
        var co = quads_zero();
        var cg = quads_zero();
        if (p.channels == 3u) {
            co = plane_value(xy, w, region, 1u);
            cg = plane_value(xy, w, region, 2u);
        }
        store_quads(xy, y, co, cg);
    }
}

// The first frame of a generation (with `reuse`): every tile evaluated, and its bounds
// found (atomic maxima over the tile; cleared before).
@compute @workgroup_size(GROUP_X, 8)
fn main_fresh(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let tile = wg.y * groups.x + wg.x;
    if (li == 0u) {
        keep_state(state_at(tile, groups.x * groups.y), true);
    }
    let xy = vec2<i32>(i32(id.x * 2u * QUADS), i32(id.y * 2u));
    if (u32(xy.x) < p.size.x && u32(xy.y) < p.size.y) {
        let w = vec2<i32>(i32(id.x * QUADS), xy.y);
        let region = wg.xy / REGION_GROUPS;
        var peak: array<f32, 9>;
        let y = plane_peaks(xy, w, region, 0u, &peak);
        var co = quads_zero();
        var cg = quads_zero();
        if (p.channels == 3u) {
            co = plane_peaks(xy, w, region, 1u, &peak);
            cg = plane_peaks(xy, w, region, 2u, &peak);
        }
        store_quads(xy, y, co, cg);
        for (var k = 0u; k < max(p.layers, 2u); k = k + 1u) {
            atomicMax(&peaks[tile * PEAK_WORDS + k], bitcast<u32>(peak[k]));
        }
    }
}

// The held image: RGB with 9-bit mantissas and a shared 5-bit exponent (bias 15), the
// layout of the RGB9E5 texture format, which cannot be a storage texture. The largest
// channel keeps 9 significant bits (a 2^-9 step at worst); a blend's start is within that
// of what was on screen, where a catch-up blends towards the exact image anyway.
fn unpack_rgb9e5(w: u32) -> vec3<f32> {
    let scale = exp2(f32(w >> 27u) - 24.0);
    return vec3<f32>(f32(w & 0x1FFu), f32((w >> 9u) & 0x1FFu), f32((w >> 18u) & 0x1FFu)) * scale;
}

fn pack_rgb9e5(c: vec3<f32>) -> u32 {
    // The largest value the layout holds: (511 / 512) · 2^16.
    let v = clamp(c, vec3<f32>(0.0), vec3<f32>(65408.0));
    let m = max(v.x, max(v.y, v.z));
    // The shared exponent e: steps of 2^(e − 24) hold the largest channel in 9 bits.
    var e = max(-16.0, floor(log2(max(m, 1e-30)))) + 16.0;
    if (floor(m * exp2(24.0 - e) + 0.5) >= 512.0) {
        e = e + 1.0;
    }
    let q = vec3<u32>(floor(v * exp2(24.0 - e) + 0.5));
    return min(q.x, 511u) | (min(q.y, 511u) << 9u) | (min(q.z, 511u) << 18u) | (u32(e) << 27u);
}

@group(0) @binding(7) var shown: texture_2d<f32>;
@group(0) @binding(8) var held_out: texture_storage_2d<r32uint, write>;

// Keeps what is on screen for blending (at the start of a catch-up).
@compute @workgroup_size(8, 8)
fn hold(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(shown);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let xy = vec2<i32>(id.xy);
    textureStore(held_out, xy, vec4<u32>(pack_rgb9e5(textureLoad(shown, xy, 0).xyz), 0u, 0u, 0u));
}
