// Format 2's and 3's coefficient sections decoded on the GPU, straight into the dense plane
// the decode passes read (decode.wgsl): one invocation per rANS stream (a lane in version
// 2; one of a lane's states in version 3, which takes the lane's groups k, k + s, … of
// its regions, 16 a region), the passes of
// `vbim_format::plane2`, whose module documentation is the specification; this follows it
// step for step. Dispatches (player/src/gpu/lanes.rs): `slots` once per section (each
// family's histogram of each context, and the slot tables of the histograms the chunk
// sent itself; the file's were written when the stream opened), then per plane `prepare`
// (lanes' states, each tile's rank, each group's flags, the blocks' residuals and the
// dense plane's masks cleared), `flags` (the even groups), `middle` (the odd groups, then
// the even blocks), `blocks` (the odd blocks), and the DC: `dc_tiles` for a bubble plane,
// `dc_rows` then `dc_cols` for a keyframe plane. Each stream keeps its state in the
// scratch buffer between dispatches.
//
// llvmpipe (lavapipe) ends every loop of an invocation once its loops have run 65,535
// iterations in all: so no loop per symbol here (a slot table finds the token, raw bits
// and neighbours are unrolled), blocks are visited by the rows of groups that hold
// something, and the file bounds a lane's regions (the decoder thread refuses more than
// `plane2::MAX_LANE_REGIONS`) and the encoder its symbols.
//
// Out-of-range input (a crafted section whose checksums hold) decodes to other
// coefficients, never to reads or writes outside the plane: a lane stops at its last
// word, a block's position comes from the grid. A lane that read past its words, decoded
// a symbol out of range or did not end as the specification's decoder requires (every
// word read, the state back at 2^16) sets FAULT.

// `struct LaneJob`, the passes' parameters, is declared before this file
// (player/src/gpu/lanes.rs, from the Rust struct's fields), in a uniform buffer on a GPU
// and a storage one on a CPU adapter (`var<JOB>`: `DecodeShape::lane_job_storage` says
// why).
// A dispatch covers a batch of planes (player/src/gpu/lanes.rs, `lane_ops`), the plane
// `workgroup_id.z`, each with its job, 256 bytes apart; an entry point first takes its own
// (`take_job`) into `prm`, which everything else reads.
struct LanePlaneJob {
    job: LaneJob,
    // (To 256 bytes: the 128 of a LaneJob and 128 more.)
    pad: array<vec4<u32>, 8>,
}
@group(0) @binding(0) var<JOB> lane_jobs: array<LanePlaneJob, BATCH_PLANES>;
var<private> prm: LaneJob;

fn take_job(wg: vec3<u32>) {
    prm = lane_jobs[wg.z].job;
}
// The segment's words (player/src/coded.rs).
@group(0) @binding(1) var<storage, read> seg: array<u32>;
// The decode's own state, at the offsets below (player/src/gpu/lanes.rs sizes it).
@group(0) @binding(2) var<storage, read_write> scratch: array<u32>;
// The symbols' tables (the file's maps and histograms, a section's own), read-only in the
// lane passes, so that a GPU may keep them in its caches nearest the cores; `slots` writes
// them through `tables_w`, the same buffer bound read-write in a bind group of its own.
// (With a symbol's one load from them and its context's histogram from workgroup memory,
// an H100 decoded 2–4% faster than with three loads: a lane waits on its own chain.)
@group(0) @binding(5) var<storage, read> tables: array<u32>;
@group(0) @binding(6) var<storage, read_write> tables_w: array<u32>;
// The dense plane: block b's coefficients at 64 · b …, valid where its mask has the bit
// (only the non-zero ones are written; never cleared), ...
@group(0) @binding(3) var<storage, read_write> coefs: array<i32>;
// ... its mask at words 2b and 2b + 1, then from SETS a bit per block that has a
// coefficient (both cleared before the plane).
@group(0) @binding(4) var<storage, read_write> marks: array<atomic<u32>>;

// Tables: per family the cluster of each context (the file's maps, written once) ...
const MAPS: u32 = 0u;
// ... per family the histogram of each context (NONE: the chunk sent none), by `slots` ...
const HIST_OF: u32 = MAPS + FAMILIES * CONTEXTS;
// ... per histogram (the file's, then a section's own) each of its 4096 slots' token |
// the token's frequency << 7 | the slot's offset from the token's first slot << 20
// (SLOTS: a symbol's one load). Scratch: per plane of a batch its groups' flags, then
// its tiles' ranks (from the job's `groups_at`); per block of the dense plane its DC
// residual and coefficient count (INFO, a plane's blocks from the job's `dense_at`); per
// stream its state (from the job's `states_at`); and FAULT, set by a lane that read past
// its words or decoded a symbol out of range. (Declared before this file: SLOTS, INFO,
// FAULT, HISTOGRAMS, FILE_HISTOGRAMS, SETS, BATCH_PLANES, and CONTEXTS, a family's:
// `vbim_format::plane2`'s.)

const NONE: u32 = 0xFFFFFFFFu;
// LANE_GROUP, the states per workgroup of the lane passes (`flags`, `middle`, `blocks`),
// is declared before this file: one on a GPU, where a state is a serial chain whose
// branches follow its own symbols and states that share a warp wait for each other (on an
// H100 eight to a workgroup took twice as long: a 2048² segment 61.9 ms against 31.5);
// eight on a CPU adapter, whose SIMD runs a workgroup's invocations side by side
// (`DecodeShape::lane_group`).
const FAMILIES: u32 = 6u;
const FLAG: u32 = 0u;
const DC: u32 = 6u;
const COUNT: u32 = 11u;
const AC_EVEN: u32 = 22u;
const AC_ODD: u32 = 142u;
const JOINT_BUSY: u32 = 502u;
// Version 3's joint symbol holds folded residuals below this; a larger one is this, then
// the rest.
const ESCAPE: u32 = 0x7FFFFFFFu;
const REGION: u32 = 16u;
const GROUP: u32 = 4u;

var<private> x: u32;
var<private> at: u32;
var<private> end: u32;
var<private> failed: u32;
// The stream's place among its lane's states, and their number: it codes the lane's
// groups whose place in the lane (16 a region) is `pick` modulo `picks`.
var<private> pick: u32;
var<private> picks: u32;

fn fail() {
    failed = 1u;
}

// Word i of the section's lanes (16-bit).
fn word(i: u32) -> u32 {
    let w = seg[prm.words + (i >> 1u)];
    return select(w & 0xFFFFu, w >> 16u, (i & 1u) == 1u);
}

// One rANS step: the symbol of frequency f, the state's slot `offset` past its first,
// leaves the state.
fn step(f: u32, offset: u32) {
    x = f * (x >> 12u) + offset;
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
    let e = tables[SLOTS + h * 4096u + (x & 4095u)];
    let f = (e >> 7u) & 0x1FFFu;
    if (f == 0u) {
        fail();
    } else {
        step(f, e >> 20u);
    }
    return e & 0x7Fu;
}

// The next k ≤ 12 raw bits: the slot's top k bits, each value 2^(12 − k) slots wide.
fn piece(k: u32) -> u32 {
    let p = (x & 4095u) >> (12u - k);
    step(1u << (12u - k), (x & 4095u) - (p << (12u - k)));
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

// The plane's family's histogram of each context, for the lane passes: read once per
// workgroup (`load_contexts`), then a symbol's first lookup is to workgroup memory.
var<workgroup> hist_of: array<u32, CONTEXTS>;

// Fills `hist_of`; every invocation of the workgroup calls it, before any returns.
fn load_contexts(local: u32) {
    for (var c = local; c < CONTEXTS; c = c + LANE_GROUP) {
        hist_of[c] = tables[HIST_OF + prm.family * CONTEXTS + c];
    }
    workgroupBarrier();
}

// The value of the next symbol, coded in context ctx of the plane's family.
fn symbol(ctx: u32) -> u32 {
    let h = hist_of[ctx];
    var r = 0u;
    if (h >= HISTOGRAMS) {
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
        return prm.dense_at + y * prm.bw + x;
    }
    let r = scratch[prm.groups_at + prm.gw * prm.gh + (y / prm.tile) * prm.tiles_x + x / prm.tile];
    if (r == NONE) {
        return NONE;
    }
    return prm.dense_at + (r * prm.tile + y % prm.tile) * prm.tile + x % prm.tile;
}

// The rank of tile t among a bubble plane's members, NONE if it is not one: the last
// span whose first tile is at most t, if t is within its length (a binary search of at
// most 32 steps).
fn rank_of(t: u32) -> u32 {
    var lo = 0u;
    var hi = prm.span_count;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (seg[prm.spans + 2u * mid] <= t) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    if (lo == 0u) {
        return NONE;
    }
    let first = seg[prm.spans + 2u * (lo - 1u)];
    let rank = seg[prm.spans + 2u * (lo - 1u) + 1u];
    var next = prm.members;
    if (lo < prm.span_count) {
        next = seg[prm.spans + 2u * lo + 1u];
    }
    let r = rank + (t - first);
    return select(NONE, r, r < next);
}

// Frequency of token t of the section's own histogram h: a word per histogram (where its
// frequencies start << 8 | how many tokens they cover), then the frequencies, two to a
// word (player/src/coded.rs).
fn own_frequency(h: u32, t: u32) -> u32 {
    let head = seg[prm.own + h];
    if (t >= (head & 0xFFu)) {
        return 0u;
    }
    let w = seg[prm.own + (head >> 8u) + t / 2u];
    return select(w & 0xFFFFu, w >> 16u, (t & 1u) == 1u);
}

// Once per section: each family's histogram of each context (for the families the
// section uses), then the slot tables of the histograms it sent itself.
@compute @workgroup_size(64)
fn slots(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    take_job(wg);
    let i = id.x;
    if (i < FAMILIES * CONTEXTS) {
        let f = i / CONTEXTS;
        let first = prm.places[f / 4u][f % 4u];
        if (first != NONE) {
            tables_w[HIST_OF + i] = seg[first + tables_w[MAPS + i]];
        }
        return;
    }
    let k = i - FAMILIES * CONTEXTS;
    if (k >= prm.own_count * 1024u) {
        return;
    }
    // Four slots of histogram h: each one's token the first whose cumulative range holds
    // it (127 past the frequencies' sum, where a crafted histogram stops short).
    let h = k / 1024u;
    var t = 0u;
    var cum = 0u;
    let into = SLOTS + (FILE_HISTOGRAMS + h) * 4096u;
    for (var s = 0u; s < 4u; s = s + 1u) {
        let slot = (k % 1024u) * 4u + s;
        loop {
            let f = own_frequency(h, t);
            if (cum + f > slot || t >= 127u) {
                break;
            }
            cum = cum + f;
            t = t + 1u;
        }
        let f = own_frequency(h, t) & 0x1FFFu;
        tables_w[into + slot] = t | (f << 7u) | ((slot - cum) << 20u);
    }
}

// Per plane, before its lanes: each lane's state from its first words, each tile's rank
// (a bubble plane), each group's flags (bit 0 if it has a block, bit 1 cleared), each
// block's residual and count cleared (blocks of groups that hold nothing are never
// decoded, and their neighbours read them as zeros), and the dense plane's masks and
// sets cleared (one dispatch, not a clear and a dispatch).
@compute @workgroup_size(64)
fn prepare(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    take_job(wg);
    let i = id.x;
    if (i < prm.lanes) {
        // A stream's words end where the next one's start, the last at the table's end.
        let w0 = seg[prm.table + 2u * i + 1u];
        let w1 = seg[prm.table + 2u * (i + 1u) + select(0u, 1u, i + 1u < prm.lanes)];
        var state = vec4<u32>(0u, w0 + 2u, w1, 1u);
        if (w1 >= w0 + 2u) {
            state.x = (word(w0) << 16u) | word(w0 + 1u);
            state.w = select(0u, 1u, state.x < 65536u);
        }
        let s = prm.states_at + 4u * i;
        scratch[s] = state.x;
        scratch[s + 1u] = state.y;
        scratch[s + 2u] = state.z;
        scratch[s + 3u] = state.w;
    }
    if (i < prm.blocks) {
        let b = prm.dense_at + i;
        scratch[INFO + 2u * b] = 0u;
        scratch[INFO + 2u * b + 1u] = 0u;
        atomicStore(&marks[2u * b], 0u);
        atomicStore(&marks[2u * b + 1u], 0u);
    }
    // The sets, as the passes after read them: two words per group of 64 blocks.
    if (i < 2u * ((prm.blocks + 63u) / 64u)) {
        atomicStore(&marks[SETS + prm.dense_at / 32u + i], 0u);
    }
    if (prm.tile != 0u && i < prm.tiles_x * prm.tiles_y) {
        scratch[prm.groups_at + prm.gw * prm.gh + i] = rank_of(i);
    }
    if (i >= prm.gw * prm.gh) {
        return;
    }
    let gx = i % prm.gw;
    let gy = i / prm.gw;
    var has = 1u;
    if (prm.tile != 0u) {
        // The tiles the group's blocks lie in (their ranks are being written by this
        // dispatch: found again).
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
    scratch[prm.groups_at + i] = has;
}

// Stream `lane`'s state into the private variables; returns its lane's regions [first,
// end).
fn load(lane: u32) -> vec2<u32> {
    let s = prm.states_at + 4u * lane;
    x = scratch[s];
    at = scratch[s + 1u];
    end = scratch[s + 2u];
    failed = scratch[s + 3u];
    let place = seg[prm.table + 2u * lane];
    pick = (place >> 16u) & 63u;
    picks = (place >> 22u) + 1u;
    // The lane ends where the next one starts (its first stream's), the last at the
    // plane's last region.
    let next = lane + picks - pick;
    var last = prm.rw * ((prm.bh + REGION - 1u) / REGION);
    if (next < prm.lanes) {
        last = seg[prm.table + 2u * next] & 0xFFFFu;
    }
    return vec2<u32>(place & 0xFFFFu, max(last, place & 0xFFFFu));
}

// Group `place` of the lane whose regions start at `first` (16 a region, in raster order
// within it): its place on the group grid (beyond the grid at the plane's edges).
fn group_at(first: u32, place: u32) -> vec2<u32> {
    let per = REGION / GROUP;
    let region = first + place / (per * per);
    let local = place % (per * per);
    return vec2<u32>((region % prm.rw) * per + local % per, (region / prm.rw) * per + local / per);
}

fn save(lane: u32) {
    let s = prm.states_at + 4u * lane;
    scratch[s] = x;
    scratch[s + 1u] = at;
    scratch[s + 2u] = end;
    scratch[s + 3u] = failed;
    if (failed != 0u) {
        scratch[FAULT] = 1u;
    }
}

// Group (gx, gy)'s flags as seen from a neighbour: 0 outside the grid.
fn group_bits(gx: i32, gy: i32) -> u32 {
    if (gx < 0 || gy < 0 || gx >= i32(prm.gw) || gy >= i32(prm.gh)) {
        return 0u;
    }
    return scratch[prm.groups_at + u32(gy) * prm.gw + u32(gx)];
}

// The groups' flags of parity `parity` among the stream's groups of its lane's regions
// `span`: places pick, pick + picks, … (every place in version 2).
fn flags_of(span: vec2<u32>, parity: u32) {
    let places = (span.y - span.x) * GROUP * GROUP;
    for (var p = pick; p < places; p = p + picks) {
        let cell = group_at(span.x, p);
        let gx = cell.x;
        let gy = cell.y;
        if (gx >= prm.gw || gy >= prm.gh) {
            continue;
        }
        let g = prm.groups_at + gy * prm.gw + gx;
        if ((scratch[g] & 1u) == 0u || (gx + gy) % 2u != parity) {
            continue;
        }
        var ctx = 0u;
        if (parity == 1u) {
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
        scratch[g] = (scratch[g] & 1u) | select(0u, 2u, f == 1u);
    }
}

// Pass 1: the even groups' flags.
@compute @workgroup_size(LANE_GROUP)
fn flags(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    take_job(wg);
    load_contexts(local);
    let lane = id.x;
    if (lane >= prm.lanes) {
        return;
    }
    flags_of(load(lane), 0u);
    save(lane);
}

// Passes 2 and 3 in one dispatch: the odd groups' flags (their contexts read the even
// groups around them, decoded by the dispatch before), then the even blocks, whose
// contexts read only the block itself and whose groups' flags are all the lane's own
// (groups lie inside regions).
@compute @workgroup_size(LANE_GROUP)
fn middle(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    take_job(wg);
    load_contexts(local);
    let lane = id.x;
    if (lane >= prm.lanes) {
        return;
    }
    let span = load(lane);
    flags_of(span, 1u);
    blocks_in(span, 0u);
    save(lane);
}

// Block (bx, by)'s four neighbours (blocks of the other parity), packed first; returns
// how many there are.
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

// Block b's mask (decoded by an earlier dispatch); none for NONE.
fn mask_of(b: u32) -> vec2<u32> {
    if (b == NONE) {
        return vec2<u32>(0u, 0u);
    }
    return vec2<u32>(atomicLoad(&marks[2u * b]), atomicLoad(&marks[2u * b + 1u]));
}

fn residual(b: u32) -> i32 {
    return bitcast<i32>(scratch[INFO + 2u * b]);
}

fn count(b: u32) -> u32 {
    return scratch[INFO + 2u * b + 1u];
}

// Decodes block b at (bx, by), of parity `parity`.
fn block(b: u32, bx: u32, by: u32, parity: u32) {
    var four = array<u32, 4>(NONE, NONE, NONE, NONE);
    let n4 = neighbours(bx, by, &four);
    let odd = parity == 1u && n4 > 0u;
    var dc_ctx = 0u;
    var count_ctx = 0u;
    // (Version 3: whether a neighbour has a coefficient, from their counts.)
    var busy = false;
    if (odd) {
        var sizes = 0u;
        var counts = 0u;
        if (n4 > 0u) { sizes += size_class(residual(four[0])); counts += count(four[0]); }
        if (n4 > 1u) { sizes += size_class(residual(four[1])); counts += count(four[1]); }
        if (n4 > 2u) { sizes += size_class(residual(four[2])); counts += count(four[2]); }
        if (n4 > 3u) { sizes += size_class(residual(four[3])); counts += count(four[3]); }
        dc_ctx = 1u + min(2u * sizes / n4, 3u);
        count_ctx = 3u + count_bucket((counts + n4 / 2u) / n4);
        busy = counts > 0u;
    }
    var r = 0i;
    var nz = 0u;
    if (prm.v3 == 0u) {
        r = unpack(symbol(DC + dc_ctx));
        if (!odd) {
            count_ctx = size_class(r);
        }
        nz = symbol(COUNT + count_ctx);
    } else {
        // Version 3: the residual and whether a coefficient follows in one symbol, in a
        // context of whether a neighbour has one; then the count less one.
        let ctx = select(DC, JOINT_BUSY, busy) + dc_ctx;
        let j = symbol(ctx);
        var folded = j >> 1u;
        if (folded == ESCAPE) {
            let rest = symbol(ctx);
            if (rest > 0xFFFFFFFFu - ESCAPE) {
                fail();
            }
            folded = ESCAPE + rest;
        }
        r = unpack(folded);
        if (!odd) {
            count_ctx = size_class(r);
        }
        if ((j & 1u) == 1u) {
            nz = min(symbol(COUNT + count_ctx), 63u) + 1u;
        }
    }
    if (nz >= 64u) {
        fail();
        nz = 0u;
    }
    scratch[INFO + 2u * b] = bitcast<u32>(r);
    scratch[INFO + 2u * b + 1u] = nz;
    var mask = vec2<u32>(0u, 0u);
    var left = nz;
    // An odd block's coefficient at position i is coded in a context of how many of its
    // neighbours have one there, h of n4: none, up to half, or more (⌈2h / n4⌉ capped at
    // 2). Per position, as two masks made once per block: any, and more than half.
    var any = vec2<u32>(0u, 0u);
    var most = any;
    if (odd && nz > 0u) {
        // The neighbours' masks (unused slots are NONE: no bits).
        let m0 = mask_of(four[0]);
        let m1 = mask_of(four[1]);
        let m2 = mask_of(four[2]);
        let m3 = mask_of(four[3]);
        any = m0 | m1 | m2 | m3;
        switch (n4) {
            case 1u: { most = m0; }
            case 2u: { most = m0 & m1; }
            case 3u: { most = (m0 & m1) | (m0 & m2) | (m1 & m2); }
            default: { most = (m0 & m1 & (m2 | m3)) | (m2 & m3 & (m0 | m1)); }
        }
    }
    let base = select(AC_EVEN, AC_ODD, odd);
    for (var i = 1u; i < 64u && left > 0u; i = i + 1u) {
        // (For an even block, any and most are 0: level 0.)
        let half = i / 32u;
        let bit = i % 32u;
        let level = ((any[half] >> bit) & 1u) + ((most[half] >> bit) & 1u);
        let ctx = base + level * 120u + left_bucket(left) * 12u + band(i);
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

// Version 2: the blocks of parity `parity` in the lane's regions `span`, each region's in
// raster order.
fn blocks_of(span: vec2<u32>, parity: u32) {
    let per = REGION / GROUP;
    for (var region = span.x; region < span.y; region = region + 1u) {
        let rx = (region % prm.rw) * per;
        let ry = (region / prm.rw) * per;
        // Blocks in raster order of the region, by the groups that hold something: a
        // row of groups that holds nothing costs one iteration (lavapipe's budget of
        // loop iterations), not one per block row.
        for (var gy = ry; gy < min(ry + per, prm.gh); gy = gy + 1u) {
            let row = prm.groups_at + gy * prm.gw;
            var full = 0u;
            if (rx < prm.gw && (scratch[row + rx] & 2u) != 0u) { full |= 1u; }
            if (rx + 1u < prm.gw && (scratch[row + rx + 1u] & 2u) != 0u) { full |= 2u; }
            if (rx + 2u < prm.gw && (scratch[row + rx + 2u] & 2u) != 0u) { full |= 4u; }
            if (rx + 3u < prm.gw && (scratch[row + rx + 3u] & 2u) != 0u) { full |= 8u; }
            if (full == 0u) {
                continue;
            }
            for (var cy = gy * GROUP; cy < min((gy + 1u) * GROUP, prm.bh); cy = cy + 1u) {
                var left = full;
                while (left != 0u) {
                    let k = firstTrailingBit(left);
                    left = left & (left - 1u);
                    let gx = rx + k;
                    let x0 = gx * GROUP + (gx * GROUP + cy + parity) % 2u;
                    for (var bx = x0; bx < min((gx + 1u) * GROUP, prm.bw); bx = bx + 2u) {
                        let b = block_at(i32(bx), i32(cy));
                        if (b != NONE) {
                            block(b, bx, cy, parity);
                        }
                    }
                }
            }
        }
    }
}

// Version 3: the blocks of parity `parity` of the stream's groups (places pick, pick +
// picks, … of its lane's regions `span`) that hold something, group by group, each
// group's in raster order.
fn blocks_by_group(span: vec2<u32>, parity: u32) {
    let places = (span.y - span.x) * GROUP * GROUP;
    for (var p = pick; p < places; p = p + picks) {
        let cell = group_at(span.x, p);
        if (cell.x >= prm.gw || cell.y >= prm.gh
            || (scratch[prm.groups_at + cell.y * prm.gw + cell.x] & 2u) == 0u) {
            continue;
        }
        for (var cy = cell.y * GROUP; cy < min((cell.y + 1u) * GROUP, prm.bh); cy = cy + 1u) {
            let x0 = cell.x * GROUP + (cell.x * GROUP + cy + parity) % 2u;
            for (var bx = x0; bx < min((cell.x + 1u) * GROUP, prm.bw); bx = bx + 2u) {
                let b = block_at(i32(bx), i32(cy));
                if (b != NONE) {
                    block(b, bx, cy, parity);
                }
            }
        }
    }
}

// The blocks of parity `parity` of the stream (its lane's regions `span`), in its
// version's order.
fn blocks_in(span: vec2<u32>, parity: u32) {
    if (prm.v3 == 1u) {
        blocks_by_group(span, parity);
    } else {
        blocks_of(span, parity);
    }
}

// Pass 4: the odd blocks, whose contexts read their even neighbours (decoded by the
// dispatch before). The lane's last: it must end on every word read and the state it
// started from, as the specification's decoder checks.
@compute @workgroup_size(LANE_GROUP)
fn blocks(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    take_job(wg);
    load_contexts(local);
    let lane = id.x;
    if (lane >= prm.lanes) {
        return;
    }
    blocks_in(load(lane), 1u);
    if (at != end || x != 65536u) {
        fail();
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
fn dc_rows(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    take_job(wg);
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
            acc = acc + residual(b);
            coefs[b * 64u] = acc;
        }
    }
}

@compute @workgroup_size(64)
fn dc_cols(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    take_job(wg);
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
            finish_block(b, acc);
        }
    }
}

// Block b's last step, once its DC is known: the DC's bit in its mask, and its bit in the
// sets if it has any coefficient.
fn finish_block(b: u32, dc: i32) {
    var low = atomicLoad(&marks[2u * b]);
    if (dc != 0) {
        low = low | 1u;
        atomicStore(&marks[2u * b], low);
    }
    if ((low | atomicLoad(&marks[2u * b + 1u])) != 0u) {
        atomicOr(&marks[SETS + b / 32u], 1u << (b % 32u));
    }
}

// A bubble plane's DC in one dispatch: its predictions stay inside its tiles, so an
// invocation per member tile runs the specification's raster recurrence over the tile's
// cells (left + up − up-left), in place of the two scans.
@compute @workgroup_size(64)
fn dc_tiles(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    take_job(wg);
    let t = id.x;
    if (t >= prm.tiles_x * prm.tiles_y) {
        return;
    }
    let rank = scratch[prm.groups_at + prm.gw * prm.gh + t];
    if (rank == NONE) {
        return;
    }
    let n = prm.tile;
    let first = prm.dense_at + rank * n * n;
    for (var c = 0u; c < n * n; c = c + 1u) {
        let cx = c % n;
        let cy = c / n;
        let b = first + c;
        var dc = residual(b);
        if (cx > 0u) {
            dc = dc + coefs[(b - 1u) * 64u];
        }
        if (cy > 0u) {
            dc = dc + coefs[(b - n) * 64u];
        }
        if (cx > 0u && cy > 0u) {
            dc = dc - coefs[(b - n - 1u) * 64u];
        }
        coefs[b * 64u] = dc;
        finish_block(b, dc);
    }
}
