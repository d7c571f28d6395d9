
// Parses one plane's coefficient stream into the dense plane (see decode.wgsl for the
// stream and what reads the dense plane).

// The dense plane of the part's coefficients, block d's at 64 · d …, and a 64-bit mask
// of each block's non-zero coefficients, in the part's slot of the ring of masks (from
// word `job.masks_at`). (Atomic here, where invocations parsing different frequencies of
// a block set its bits; plain in decode.wgsl, which reads them.)
@group(0) @binding(6) var<storage, read_write> coefs: array<i32>;
@group(0) @binding(7) var<storage, read_write> masks: array<atomic<u32>>;
// Per group of 64 blocks, which have a coefficient (a 64-bit set, from word
// `job.sets_at`): the block passes visit only those.
@group(0) @binding(10) var<storage, read_write> groups: array<atomic<u32>>;

// The stream word that holds the bytes being read, and its index: one load per four
// bytes, not one per byte (each load is a step of the invocation's serial chain).
var<private> held_at: u32 = 0xFFFFFFFFu;
var<private> held: u32;

fn stream_byte(at: u32) -> u32 {
    let i = at >> 2u;
    if (i != held_at) {
        held_at = i;
        held = words[job.stream + i];
    }
    return (held >> ((at & 3u) * 8u)) & 0xFFu;
}

// A zig-zag coded value (0, −1, 1, −2 … as 0, 1, 2, 3 …), as the u32 bits of the i32.
fn unzigzag(u: u32) -> u32 {
    return (u >> 1u) ^ (0u - (u & 1u));
}

// One LEB128 varint at `*at`, advancing it.
fn varint(at: ptr<function, u32>) -> u32 {
    var u = 0u;
    var shift = 0u;
    loop {
        let b = stream_byte(*at);
        *at = *at + 1u;
        u = u | ((b & 0x7Fu) << shift);
        if ((b & 0x80u) == 0u) {
            break;
        }
        shift = shift + 7u;
    }
    return u;
}

// The bits of `groups[pending_at]` this invocation has yet to set: blocks come in
// increasing order within a frequency, so most marks land in the same word and one
// atomic sets them all.
var<private> pending_at: u32 = 0xFFFFFFFFu;
var<private> pending: u32 = 0u;

fn flush_groups() {
    if (pending != 0u) {
        atomicOr(&groups[job.sets_at + pending_at], pending);
        pending = 0u;
    }
}

// Coefficient f of dense block d and its mask bit. No atomic's result is waited for: on
// a GPU an atomic that returns a value stalls the invocation for a round trip to memory,
// one that does not is sent and forgotten.
fn put_coef(d: u32, f: u32, v: i32) {
    coefs[(job.dense_at + d) * 64u + f] = v;
    atomicOr(&masks[job.masks_at + d * 2u + f / 32u], 1u << (f % 32u));
}

// Coefficient f of block b, if the block is in this part and the value is not zero.
fn put(b: u32, f: u32, v: i32) {
    if (v == 0 || b < job.lo || b >= job.hi) {
        return;
    }
    let d = b - job.lo;
    put_coef(d, f, v);
    let w = d / 32u;
    if (w != pending_at) {
        flush_groups();
        pending_at = w;
    }
    pending = pending | (1u << (d % 32u));
}

// The serial parse, for a CPU adapter: one invocation per piece, reading its pairs in
// sequence. Parses the piece of the stream from one entry point: from its first position (`from`)
// to where the next piece starts (vbim_format::scan: at most ENTRY_PAIRS pairs, and at
// most FILL_BLOCKS blocks whose DC a zero run repeats), or to the end.
@compute @workgroup_size(64)
fn parse(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    take_job(wg);
    let e = group_index(wg) * 64u + li;
    if (e >= job.count) {
        return;
    }
    let base = job.entries + 4u * e;
    var at = words[base];
    var p = words[base + 1u];
    var dc = bitcast<i32>(words[base + 2u]);
    let first = words[base + 3u];
    let n = job.blocks;
    // Below 2^32: the scan refuses larger streams.
    let total = n * 64u;
    var end = total;
    if (e + 1u < job.count) {
        end = words[base + 7u];
    }
    loop {
        let run = varint(&at);
        // The blocks a zero run passes in the DC range keep the running DC: this piece
        // writes those from `first` on and before `end`. (The scan checked that no run
        // goes past the end, so p + run ≤ total.)
        if (p < n && dc != 0) {
            let stop = min(min(p + run, n), end);
            for (var b = max(p, first); b < stop; b = b + 1u) {
                put(b, 0u, dc);
            }
        }
        p = p + run;
        // A run that reaches `end` ends this piece; its value is a later piece's.
        if (p >= total || p >= end) {
            break;
        }
        let u = varint(&at);
        let v = bitcast<i32>(unzigzag(u));
        if (p < n) {
            dc = dc + v;
            put(p, 0u, dc);
        } else {
            put(p % n, p / n, v);
        }
        p = p + 1u;
        if (p >= end) {
            break;
        }
    }
    flush_groups();
}

// The wide parse, for a GPU: a workgroup per piece, its 64 lanes reading the piece's
// bytes, varints and pairs side by side, joined by scans over the lanes. The serial
// parse's chain of 2 · PIECE_PAIRS dependent varint reads per piece left a GPU idle,
// waiting on memory (BENCHMARKS.md, "On a hardware GPU"); here a piece costs
// one load per lane and a few dozen steps through workgroup memory. It writes what the
// serial parse writes: the same coefficients, masks and sets.
//
// (PIECE_PAIRS, the scan's ENTRY_PAIRS, and FILL_BLOCKS are put before this file.)

// A piece's varints, two per pair, are at most 5 bytes each (the scan refused longer
// ones): its bytes lie within PIECE_BYTES of its first, which need not start a word.
const PIECE_VARINTS: u32 = 2u * PIECE_PAIRS;
const PIECE_BYTES: u32 = 5u * PIECE_VARINTS;
const PIECE_WORDS: u32 = PIECE_BYTES / 4u + 1u;
const LANE_PAIRS: u32 = PIECE_PAIRS / 64u;

var<workgroup> piece: array<u32, PIECE_WORDS>;
var<workgroup> varints: array<u32, PIECE_VARINTS>;
// One value per lane, for the scans.
var<workgroup> lanes: array<u32, 64>;
// Per pair, the DC blocks its zero run writes: the first fill slot (over the piece's
// pairs, in order), the first block and the DC.
var<workgroup> fill_at: array<u32, PIECE_PAIRS>;
var<workgroup> fill_from: array<u32, PIECE_PAIRS>;
var<workgroup> fill_dc: array<i32, PIECE_PAIRS>;
var<workgroup> fill_total: u32;

// Byte k of the piece (its first byte is byte `lead` of the first word).
fn piece_byte(lead: u32, k: u32) -> u32 {
    let i = lead + k;
    return (piece[i >> 2u] >> ((i & 3u) * 8u)) & 0xFFu;
}

// a + b, or the largest u32 where that overflows: positions relative to a piece's start
// past the end of a well-formed piece saturate instead of wrapping back below it.
fn sat_add(a: u32, b: u32) -> u32 {
    return select(a + b, 0xFFFFFFFFu, a > 0xFFFFFFFFu - b);
}

// The sum of `x` over the lanes before this one (Hillis–Steele over 64 lanes), wrapping
// (`wrap`) or saturating. Called by every lane, in uniform control flow.
fn scan_lanes(li: u32, x: u32, wrap: bool) -> u32 {
    var v = x;
    lanes[li] = v;
    workgroupBarrier();
    for (var d = 1u; d < 64u; d = d * 2u) {
        var add = 0u;
        if (li >= d) {
            add = lanes[li - d];
        }
        workgroupBarrier();
        if (wrap) {
            v = v + add;
        } else {
            v = sat_add(v, add);
        }
        lanes[li] = v;
        workgroupBarrier();
    }
    var before = 0u;
    if (li > 0u) {
        before = lanes[li - 1u];
    }
    workgroupBarrier();
    return before;
}

@compute @workgroup_size(64)
fn parse_wide(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    take_job(wg);
    let e = group_index(wg);
    if (e >= job.count) {
        return;
    }
    let base = job.entries + 4u * e;
    let at = words[base];
    let p0 = words[base + 1u];
    // The running DC as u32: two's complement sums wrap as the reference's do.
    let dc0 = words[base + 2u];
    let first = words[base + 3u];
    let n = job.blocks;
    let total = n * 64u;
    var end = total;
    // The piece's bytes: up to the next piece's first, and the zero run there (where the
    // next piece starts inside a run this one fills from, this one reads that run too).
    // The last piece's end is not known: as many as its pairs could take.
    var bytes = PIECE_BYTES;
    if (e + 1u < job.count) {
        end = words[base + 7u];
        bytes = min(words[base + 4u] - at + 5u, PIECE_BYTES);
    }
    // Positions from here on are relative to the piece's first, p0.
    let rel_end = select(0u, end - p0, end > p0);

    // (Past the last piece's end the bytes are whatever the buffer holds, or zero past its
    // end: the pairs they make lie past the piece's end and write nothing.)
    let lead = at & 3u;
    let w0 = job.stream + (at >> 2u);
    for (var i = li; i < (lead + bytes + 3u) / 4u; i = i + 64u) {
        piece[i] = words[w0 + i];
    }
    workgroupBarrier();

    // Varints: each lane counts the varints that end in its bytes, learns from a scan how
    // many end before them, and decodes its own.
    let lane_bytes = (bytes + 63u) / 64u;
    let k0 = li * lane_bytes;
    let k1 = min(k0 + lane_bytes, bytes);
    var ends = 0u;
    for (var k = k0; k < k1; k = k + 1u) {
        ends = ends + select(0u, 1u, piece_byte(lead, k) < 0x80u);
    }
    var index = scan_lanes(li, ends, true);
    for (var k = k0; k < k1; k = k + 1u) {
        if (piece_byte(lead, k) >= 0x80u) {
            continue;
        }
        if (index < PIECE_VARINTS) {
            var s = k;
            while (s > 0u && k - s < 4u && piece_byte(lead, s - 1u) >= 0x80u) {
                s = s - 1u;
            }
            var u = 0u;
            for (var m = s; m <= k; m = m + 1u) {
                u = u | ((piece_byte(lead, m) & 0x7Fu) << (7u * (m - s)));
            }
            varints[index] = u;
        }
        index = index + 1u;
    }
    workgroupBarrier();

    // Pairs: pair j's run starts where pair j - 1's value was, plus one. Each lane sums
    // its pairs' advances; a scan places them.
    let j0 = li * LANE_PAIRS;
    var advance = 0u;
    for (var j = j0; j < j0 + LANE_PAIRS; j = j + 1u) {
        advance = sat_add(advance, sat_add(varints[2u * j], 1u));
    }
    let start = scan_lanes(li, advance, false);

    // The DC differences of the pairs whose value lands in the DC range, summed the same
    // way: the running DC before each pair.
    var rel = start;
    var dc_sum = 0u;
    for (var j = j0; j < j0 + LANE_PAIRS; j = j + 1u) {
        let at_value = sat_add(rel, varints[2u * j]);
        if (at_value < rel_end && p0 + at_value < n) {
            let u = varints[2u * j + 1u];
            dc_sum = dc_sum + unzigzag(u);
        }
        rel = sat_add(at_value, 1u);
    }
    var dc = dc0 + scan_lanes(li, dc_sum, true);

    // Each pair's value, and the DC blocks its run writes: the pair is reached if its
    // run starts before the piece's end (the first always is), its value is read if it
    // lands before the end, and in the DC range a run repeats the running DC from
    // `first` on, where that DC is not zero.
    rel = start;
    var filled = 0u;
    for (var j = j0; j < j0 + LANE_PAIRS; j = j + 1u) {
        let at_value = sat_add(rel, varints[2u * j]);
        let reached = j == 0u || rel < rel_end;
        var lo_block = 0u;
        var to = 0u;
        if (reached && p0 + rel < n && dc != 0u) {
            lo_block = max(p0 + rel, first);
            to = min(p0 + min(at_value, rel_end), n);
        }
        fill_at[j] = filled;
        fill_from[j] = lo_block;
        fill_dc[j] = bitcast<i32>(dc);
        filled = filled + select(0u, to - lo_block, to > lo_block);
        if (at_value < rel_end) {
            let u = varints[2u * j + 1u];
            let v = unzigzag(u);
            let p = p0 + at_value;
            if (p < n) {
                dc = dc + v;
                put_wide(p, 0u, bitcast<i32>(dc));
            } else {
                put_wide(p % n, p / n, bitcast<i32>(v));
            }
        }
        rel = sat_add(at_value, 1u);
    }
    let fills_before = scan_lanes(li, filled, false);
    for (var j = j0; j < j0 + LANE_PAIRS; j = j + 1u) {
        fill_at[j] = sat_add(fill_at[j], fills_before);
    }
    if (li == 63u) {
        fill_total = sat_add(fills_before, filled);
    }
    workgroupBarrier();

    // The DC blocks, one per lane at a time: slot t belongs to the last pair whose first
    // slot is at most t. (A piece writes at most FILL_BLOCKS.)
    let slots = min(fill_total, FILL_BLOCKS);
    for (var t = li; t < slots; t = t + 64u) {
        var lo = 0u;
        var hi = PIECE_PAIRS;
        while (hi - lo > 1u) {
            let mid = (lo + hi) / 2u;
            if (fill_at[mid] <= t) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        put_wide(fill_from[lo] + (t - fill_at[lo]), 0u, fill_dc[lo]);
    }
}

// `put` without the serial parse's batching of set bits (the lanes of a workgroup write
// different blocks at once).
fn put_wide(b: u32, f: u32, v: i32) {
    if (v == 0 || b < job.lo || b >= job.hi) {
        return;
    }
    let d = b - job.lo;
    put_coef(d, f, v);
    atomicOr(&groups[job.sets_at + d / 32u], 1u << (d % 32u));
}
