
// Parses one plane's coefficient stream into the dense plane (see decode.wgsl for the
// stream and what reads the dense plane).

// The dense plane of the part's coefficients, block d's at 64 · d …, and a 64-bit mask
// of each block's non-zero coefficients. (Atomic here, where invocations parsing
// different frequencies of a block set its bits; plain in decode.wgsl, which reads them.)
@group(0) @binding(6) var<storage, read_write> coefs: array<i32>;
@group(0) @binding(7) var<storage, read_write> masks: array<atomic<u32>>;
// Per group of 64 blocks, which have a coefficient (a 64-bit set): the block passes visit
// only those.
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
        atomicOr(&groups[pending_at], pending);
        pending = 0u;
    }
}

// Coefficient f of block b, if the block is in this part and the value is not zero.
// No atomic's result is waited for: on a GPU an atomic that returns a value stalls the
// invocation for a round trip to memory, one that does not is sent and forgotten.
fn put(b: u32, f: u32, v: i32) {
    if (v == 0 || b < job.lo || b >= job.hi) {
        return;
    }
    let d = b - job.lo;
    coefs[d * 64u + f] = v;
    atomicOr(&masks[d * 2u + f / 32u], 1u << (f % 32u));
    let w = d / 32u;
    if (w != pending_at) {
        flush_groups();
        pending_at = w;
    }
    pending = pending | (1u << (d % 32u));
}

// Parses the piece of the stream from one entry point: from its first position (`from`)
// to where the next piece starts (vbim_format::scan: at most ENTRY_PAIRS pairs, and at
// most FILL_BLOCKS blocks whose DC a zero run repeats), or to the end.
@compute @workgroup_size(64)
fn parse(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
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
        let v = bitcast<i32>(u >> 1u) ^ -bitcast<i32>(u & 1u);
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
