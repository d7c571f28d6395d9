// Format 2's coefficient coding decoded on the GPU: one invocation per rANS lane, the
// passes of `vbim_format::plane2` (its module documentation is the specification; this
// follows it step for step). Dispatches: `slots` once per section (the slot tables from
// the histograms' frequencies), then per plane `prepare` (each tile's rank, each group's
// flag cleared and whether it has a block), `flags` with parity 0 then 1, `blocks` with
// parity 0 then 1, then `dc_rows` and `dc_cols`. Each lane keeps its state between
// dispatches in `lanes`. The host uploads what the player's decode uploads for a plane:
// its words, lanes and histograms, and a bubble plane's member spans; nothing per block
// or per slot.
//
// llvmpipe (lavapipe) ends every loop of an invocation once its loops have run 65,535
// iterations in all: so no loop per symbol here (a slot table finds the token, raw bits
// and neighbours are unrolled), blocks are visited by the groups that hold something,
// and the encoder bounds a lane's symbols and regions (`vbim_format::plane2`).

struct Params {
    // Blocks across and down the plane; groups across and down; regions across.
    bw: u32,
    bh: u32,
    gw: u32,
    gh: u32,
    rw: u32,
    // Blocks across a tile for a bubble plane (its DC prediction stays in the tile); 0 for
    // a keyframe plane.
    tile: u32,
    lanes: u32,
    parity: u32,
    // Where the slot tables start in `tables`.
    slots: u32,
    // Where the sets of blocks with a coefficient start in `marks`.
    sets: u32,
    // A bubble plane's tiles across and down, member spans and member tiles (0 for a
    // keyframe plane); the section's histograms.
    tiles_x: u32,
    tiles_y: u32,
    span_count: u32,
    members: u32,
    histograms: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> prm: Params;
// The lanes' 16-bit words, two to a u32 (the first in the low half).
@group(0) @binding(1) var<storage, read> words: array<u32>;
// Two entries per lane: (state, next word, end word, failed: non-zero once the lane read
// past its words or decoded a symbol out of range), then its regions [first, end).
@group(0) @binding(2) var<storage, read_write> lanes: array<vec4<u32>>;
// Per context its histogram (0xFFFF: none sent); then per histogram 128 entries,
// frequency | cumulative frequency << 16; then from `prm.slots` per histogram the token
// of each of the 4096 slots, four to a word (written by `slots`).
@group(0) @binding(3) var<storage, read_write> tables: array<u32>;
// A bubble plane's member spans, as the player's decode reads them
// (player/src/coded.rs): the span's first tile (raster order over the plane's tiles) and
// that tile's rank among the members, spans in raster order.
@group(0) @binding(4) var<storage, read> spans: array<vec2<u32>>;
// Per group: bit 0, it has a block; bit 1, it holds something (both written by
// `prepare`, bit 1 then by `flags`). Then, from word gw · gh, a bubble plane's rank of
// each tile among its members (NONE: not a member), also written by `prepare`: the lookup
// from a cell to its block without a loop (llvmpipe's budget of loop iterations per
// invocation, above) and without a table per cell from the host. (One buffer for both:
// WebGPU's default limit is 8 storage buffers a stage.)
@group(0) @binding(5) var<storage, read_write> groups: array<u32>;
// Per block: its DC residual and its count of coefficients.
@group(0) @binding(6) var<storage, read_write> info: array<vec2<i32>>;
// The dense plane as the player's decode passes read it (player/src/gpu/decode.wgsl):
// block b's coefficients at 64 · b …, valid where its mask has the bit (never cleared:
// only the non-zero ones are written), ...
@group(0) @binding(7) var<storage, read_write> coefs: array<i32>;
// ... its mask at words 2b and 2b + 1, then from `prm.sets` a bit per block that has a
// coefficient (cleared before the first pass).
@group(0) @binding(8) var<storage, read_write> marks: array<atomic<u32>>;

const NONE: u32 = 0xFFFFFFFFu;
const CONTEXTS: u32 = 502u;
const FLAG: u32 = 0u;
const DC: u32 = 6u;
const COUNT: u32 = 11u;
const AC_EVEN: u32 = 22u;
const AC_ODD: u32 = 142u;
const REGION: u32 = 16u;
const GROUP: u32 = 4u;

var<private> x: u32;
var<private> at: u32;
var<private> end: u32;
var<private> failed: u32;

fn fail() {
    failed = 1u;
}

fn word(i: u32) -> u32 {
    let w = words[i >> 1u];
    return select(w & 0xFFFFu, w >> 16u, (i & 1u) == 1u);
}

// One rANS step: the symbol of frequency f starting at slot c leaves the state.
fn step(f: u32, c: u32) {
    let slot = x & 4095u;
    x = f * (x >> 12u) + slot - c;
    if (x < 65536u) {
        if (at < end) {
            x = (x << 16u) | word(at);
            at = at + 1u;
        } else {
            fail();
        }
    }
}

// The token of histogram h whose slots hold the state's, from the slot table.
fn token(h: u32) -> u32 {
    let slot = x & 4095u;
    let w = tables[prm.slots + h * 1024u + (slot >> 2u)];
    let t = (w >> ((slot & 3u) * 8u)) & 0xFFu;
    let e = tables[CONTEXTS + h * 128u + t];
    if ((e & 0xFFFFu) == 0u) {
        fail();
    } else {
        step(e & 0xFFFFu, e >> 16u);
    }
    return t;
}

// The next k ≤ 12 raw bits.
fn piece(k: u32) -> u32 {
    let p = (x & 4095u) >> (12u - k);
    step(1u << (12u - k), p << (12u - k));
    return p;
}

// The next `bits` raw bits (at most 36), in pieces of 12 from the top.
fn raw(bits: u32) -> u32 {
    if (bits == 0u) {
        return 0u;
    }
    if (bits <= 12u) {
        return piece(bits);
    }
    let a = piece(12u);
    if (bits <= 24u) {
        let b = piece(bits - 12u);
        return (a << (bits - 12u)) | b;
    }
    let b = piece(12u);
    let c = piece(bits - 24u);
    return (((a << 12u) | b) << (bits - 24u)) | c;
}

// The value of the next symbol, coded in context ctx.
fn symbol(ctx: u32) -> u32 {
    let h = tables[ctx];
    var r = 0u;
    if (h == 0xFFFFu) {
        fail();
    } else {
        let t = token(h);
        if (t < 16u) {
            r = t;
        } else {
            let n = (t - 16u) / 4u + 4u;
            let m = (t - 16u) % 4u;
            r = ((4u | m) << (n - 2u)) | raw(n - 2u);
        }
    }
    return r;
}

fn unpack(u: u32) -> i32 {
    return bitcast<i32>(u >> 1u) ^ -bitcast<i32>(u & 1u);
}

fn size_class(v: i32) -> u32 {
    let a = u32(abs(v));
    return select(select(2u, 1u, a <= 2u), 0u, a == 0u);
}

fn count_bucket(n: u32) -> u32 {
    if (n <= 2u) { return n; }
    if (n <= 4u) { return 3u; }
    if (n <= 8u) { return 4u; }
    if (n <= 16u) { return 5u; }
    if (n <= 32u) { return 6u; }
    return 7u;
}

fn left_bucket(n: u32) -> u32 {
    if (n <= 4u) { return n - 1u; }
    if (n <= 6u) { return 4u; }
    if (n <= 8u) { return 5u; }
    if (n <= 12u) { return 6u; }
    if (n <= 16u) { return 7u; }
    if (n <= 24u) { return 8u; }
    return 9u;
}

fn band(i: u32) -> u32 {
    if (i <= 5u) { return i; }
    if (i <= 7u) { return 6u; }
    if (i <= 10u) { return 7u; }
    if (i <= 15u) { return 8u; }
    if (i <= 23u) { return 9u; }
    if (i <= 35u) { return 10u; }
    return 11u;
}

// The block at cell (cx, cy), NONE where there is none: raster order for a keyframe
// plane; for a bubble plane, its tile's rank among the members times the blocks of a
// tile, then raster order within the tile (the plane is whole tiles).
fn block_at(cx: i32, cy: i32) -> u32 {
    if (cx < 0 || cy < 0 || cx >= i32(prm.bw) || cy >= i32(prm.bh)) {
        return NONE;
    }
    let x = u32(cx);
    let y = u32(cy);
    if (prm.tile == 0u) {
        return y * prm.bw + x;
    }
    let r = groups[prm.gw * prm.gh + (y / prm.tile) * prm.tiles_x + x / prm.tile];
    if (r == NONE) {
        return NONE;
    }
    return (r * prm.tile + y % prm.tile) * prm.tile + x % prm.tile;
}

// The rank of tile t among a bubble plane's members, NONE if it is not one: the last
// span whose first tile is at most t, if t is within its length (a binary search of at
// most 32 steps).
fn rank_of(t: u32) -> u32 {
    var lo = 0u;
    var hi = prm.span_count;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (spans[mid].x <= t) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    if (lo == 0u) {
        return NONE;
    }
    let s = spans[lo - 1u];
    var next = prm.members;
    if (lo < prm.span_count) {
        next = spans[lo].y;
    }
    let r = s.y + (t - s.x);
    return select(NONE, r, r < next);
}

// The slot tables: invocation i fills word i of them (four slots of histogram i / 1024),
// each slot's token the last whose cumulative frequency is at most the slot (tokens of
// frequency 0 share the next one's, which comes after them).
@compute @workgroup_size(64)
fn slots(@builtin(global_invocation_id) id: vec3<u32>) {
    let h = id.x / 1024u;
    if (h >= prm.histograms) {
        return;
    }
    var w = 0u;
    for (var k = 0u; k < 4u; k = k + 1u) {
        let slot = (id.x % 1024u) * 4u + k;
        var lo = 0u;
        var hi = 128u;
        while (lo < hi) {
            let mid = (lo + hi) / 2u;
            if ((tables[CONTEXTS + h * 128u + mid] >> 16u) <= slot) {
                lo = mid + 1u;
            } else {
                hi = mid;
            }
        }
        w = w | ((max(lo, 1u) - 1u) << (k * 8u));
    }
    tables[prm.slots + id.x] = w;
}

// Per plane, before its lanes: each tile's rank (a bubble plane), and each group's
// flags: bit 0 if it has a block, bit 1 cleared (the plane before may have set it).
@compute @workgroup_size(64)
fn prepare(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (prm.tile != 0u && i < prm.tiles_x * prm.tiles_y) {
        groups[prm.gw * prm.gh + i] = rank_of(i);
    }
    if (i >= prm.gw * prm.gh) {
        return;
    }
    let gx = i % prm.gw;
    let gy = i / prm.gw;
    var has = 1u;
    if (prm.tile != 0u) {
        // The tiles the group's blocks lie in (its own ranks are not written yet: this
        // dispatch writes them).
        has = 0u;
        let x1 = min((gx + 1u) * GROUP, prm.bw) - 1u;
        let y1 = min((gy + 1u) * GROUP, prm.bh) - 1u;
        for (var ty = gy * GROUP / prm.tile; ty <= y1 / prm.tile; ty = ty + 1u) {
            for (var tx = gx * GROUP / prm.tile; tx <= x1 / prm.tile; tx = tx + 1u) {
                if (rank_of(ty * prm.tiles_x + tx) != NONE) {
                    has = 1u;
                }
            }
        }
    }
    groups[i] = has;
}

fn load(lane: u32) -> vec2<u32> {
    let s = lanes[2u * lane];
    x = s.x;
    at = s.y;
    end = s.z;
    failed = s.w;
    return lanes[2u * lane + 1u].xy;
}

fn save(lane: u32) {
    lanes[2u * lane] = vec4<u32>(x, at, end, failed);
}

// Whether group (gx, gy) has a block and, if so, holds something (bit 0, bit 1), as seen
// from a neighbour: 0 outside the grid.
fn group_bits(gx: i32, gy: i32) -> u32 {
    if (gx < 0 || gy < 0 || gx >= i32(prm.gw) || gy >= i32(prm.gh)) {
        return 0u;
    }
    return groups[u32(gy) * prm.gw + u32(gx)];
}

@compute @workgroup_size(64)
fn flags(@builtin(global_invocation_id) id: vec3<u32>) {
    let lane = id.x;
    if (lane >= prm.lanes) {
        return;
    }
    let span = load(lane);
    let per = REGION / GROUP;
    for (var region = span.x; region < span.y; region = region + 1u) {
        let rx = (region % prm.rw) * per;
        let ry = (region / prm.rw) * per;
        for (var gy = ry; gy < min(ry + per, prm.gh); gy = gy + 1u) {
            for (var gx = rx; gx < min(rx + per, prm.gw); gx = gx + 1u) {
                let g = gy * prm.gw + gx;
                if ((groups[g] & 1u) == 0u || (gx + gy) % 2u != prm.parity) {
                    continue;
                }
                var ctx = 0u;
                if (prm.parity == 1u) {
                    // The neighbouring groups (even, decoded in the first pass).
                    let l = group_bits(i32(gx) - 1, i32(gy));
                    let r = group_bits(i32(gx) + 1, i32(gy));
                    let u = group_bits(i32(gx), i32(gy) - 1);
                    let d = group_bits(i32(gx), i32(gy) + 1);
                    let around = (l & 1u) + (r & 1u) + (u & 1u) + (d & 1u);
                    let full = (l >> 1u) + (r >> 1u) + (u >> 1u) + (d >> 1u);
                    if (around > 0u) {
                        ctx = 1u + around - full;
                    }
                }
                let f = symbol(FLAG + ctx);
                if (f > 1u) {
                    fail();
                }
                groups[g] = (groups[g] & 1u) | select(0u, 2u, f == 1u);
            }
        }
    }
    save(lane);
}

// Block (bx, by)'s four neighbours (blocks of the other parity), NONE where there is none,
// packed first; returns how many there are.
fn neighbours(bx: u32, by: u32, four: ptr<function, array<u32, 4>>) -> u32 {
    var n = 0u;
    let l = block_at(i32(bx) - 1, i32(by));
    if (l != NONE) { (*four)[n] = l; n = n + 1u; }
    let r = block_at(i32(bx) + 1, i32(by));
    if (r != NONE) { (*four)[n] = r; n = n + 1u; }
    let u = block_at(i32(bx), i32(by) - 1);
    if (u != NONE) { (*four)[n] = u; n = n + 1u; }
    let d = block_at(i32(bx), i32(by) + 1);
    if (d != NONE) { (*four)[n] = d; n = n + 1u; }
    return n;
}

// How many of the first n of four have a coefficient at frequency i.
fn hits(four: ptr<function, array<u32, 4>>, n: u32, i: u32) -> u32 {
    var h = 0u;
    if (n > 0u && has((*four)[0], i)) { h = h + 1u; }
    if (n > 1u && has((*four)[1], i)) { h = h + 1u; }
    if (n > 2u && has((*four)[2], i)) { h = h + 1u; }
    if (n > 3u && has((*four)[3], i)) { h = h + 1u; }
    return h;
}

// Whether block b (decoded by an earlier dispatch) has a coefficient at frequency i.
fn has(b: u32, i: u32) -> bool {
    return ((atomicLoad(&marks[2u * b + i / 32u]) >> (i % 32u)) & 1u) != 0u;
}

// Decodes block b at (bx, by), of this pass's parity.
fn block(b: u32, bx: u32, by: u32) {
    var four = array<u32, 4>(NONE, NONE, NONE, NONE);
    let n4 = neighbours(bx, by, &four);
    let odd = prm.parity == 1u && n4 > 0u;
    var dc_ctx = 0u;
    var count_ctx = 0u;
    if (odd) {
        var sizes = 0u;
        var counts = 0u;
        if (n4 > 0u) { sizes += size_class(info[four[0]].x); counts += u32(info[four[0]].y); }
        if (n4 > 1u) { sizes += size_class(info[four[1]].x); counts += u32(info[four[1]].y); }
        if (n4 > 2u) { sizes += size_class(info[four[2]].x); counts += u32(info[four[2]].y); }
        if (n4 > 3u) { sizes += size_class(info[four[3]].x); counts += u32(info[four[3]].y); }
        dc_ctx = 1u + min(2u * sizes / n4, 3u);
        count_ctx = 3u + count_bucket((counts + n4 / 2u) / n4);
    }
    let r = unpack(symbol(DC + dc_ctx));
    if (!odd) {
        count_ctx = size_class(r);
    }
    var nz = symbol(COUNT + count_ctx);
    if (nz >= 64u) {
        fail();
        nz = 0u;
    }
    info[b] = vec2<i32>(r, i32(nz));
    var mask = vec2<u32>(0u, 0u);
    var left = nz;
    for (var i = 1u; i < 64u && left > 0u; i = i + 1u) {
        var ctx = left_bucket(left) * 12u + band(i);
        if (odd) {
            ctx = AC_ODD + min((2u * hits(&four, n4, i) + n4 - 1u) / n4, 2u) * 120u + ctx;
        } else {
            ctx = AC_EVEN + ctx;
        }
        let v = unpack(symbol(ctx));
        if (v != 0) {
            coefs[b * 64u + i] = v;
            mask[i / 32u] = mask[i / 32u] | (1u << (i % 32u));
            left = left - 1u;
        }
    }
    if (left > 0u) {
        fail();
    }
    // The DC's bit comes with the DC (`dc_cols`).
    atomicStore(&marks[2u * b], mask.x);
    atomicStore(&marks[2u * b + 1u], mask.y);
}

@compute @workgroup_size(64)
fn blocks(@builtin(global_invocation_id) id: vec3<u32>) {
    let lane = id.x;
    if (lane >= prm.lanes) {
        return;
    }
    let span = load(lane);
    let per = REGION / GROUP;
    for (var region = span.x; region < span.y; region = region + 1u) {
        let rx = (region % prm.rw) * per;
        let ry = (region / prm.rw) * per;
        // Blocks in raster order of the region, by the groups that hold something: a
        // group's blocks are a run of each of its rows.
        for (var cy = ry * GROUP; cy < min((ry + per) * GROUP, prm.bh); cy = cy + 1u) {
            for (var gx = rx; gx < min(rx + per, prm.gw); gx = gx + 1u) {
                if ((groups[(cy / GROUP) * prm.gw + gx] & 2u) == 0u) {
                    continue;
                }
                for (var bx = gx * GROUP; bx < min((gx + 1u) * GROUP, prm.bw); bx = bx + 1u) {
                    let b = block_at(i32(bx), i32(cy));
                    if (b != NONE && (bx + cy) % 2u == prm.parity) {
                        block(b, bx, cy);
                    }
                }
            }
        }
    }
    save(lane);
}

// The DC: the residuals' 2-D prefix sum (left + up − up-left, 0 outside the plane or, for
// a bubble plane, outside the tile), as a scan of each row (`dc_rows`: into the block's
// DC slot) and then of each column (`dc_cols`: in place), one invocation per row or
// column, restarting at each tile's edge. The two scans equal the raster recurrence of
// the specification because every cell that a prediction reaches has a block: a
// keyframe plane has them all, and a bubble plane's predictions stay inside its tiles,
// which have all their blocks or none (the cells of a tile with none hold 0 both ways).
// Wrapping i32 sums, as the specification's, in any order.
fn restarts(i: u32) -> bool {
    return i == 0u || (prm.tile != 0u && i % prm.tile == 0u);
}

@compute @workgroup_size(64)
fn dc_rows(@builtin(global_invocation_id) id: vec3<u32>) {
    let by = id.x;
    if (by >= prm.bh) {
        return;
    }
    var acc = 0i;
    for (var bx = 0u; bx < prm.bw; bx = bx + 1u) {
        if (restarts(bx)) {
            acc = 0i;
        }
        let b = block_at(i32(bx), i32(by));
        if (b != NONE) {
            acc = acc + info[b].x;
            coefs[b * 64u] = acc;
        }
    }
}

@compute @workgroup_size(64)
fn dc_cols(@builtin(global_invocation_id) id: vec3<u32>) {
    let bx = id.x;
    if (bx >= prm.bw) {
        return;
    }
    var acc = 0i;
    for (var by = 0u; by < prm.bh; by = by + 1u) {
        if (restarts(by)) {
            acc = 0i;
        }
        let b = block_at(i32(bx), i32(by));
        if (b != NONE) {
            acc = acc + coefs[b * 64u];
            coefs[b * 64u] = acc;
            // The block's last pass: its DC's bit, and its bit in the sets.
            var low = atomicLoad(&marks[2u * b]);
            if (acc != 0) {
                low = low | 1u;
                atomicStore(&marks[2u * b], low);
            }
            if ((low | atomicLoad(&marks[2u * b + 1u])) != 0u) {
                atomicOr(&marks[prm.sets + b / 32u], 1u << (b % 32u));
            }
        }
    }
}
