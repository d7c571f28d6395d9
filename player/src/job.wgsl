// What the decode passes share (decode.wgsl and parse.wgsl are each appended to this):
// one job's parameters, the coefficient streams and the dispatch's layout.

struct Job {
    // Quantiser step of the plane.
    step: f32,
    // Keyframe passes: the plane's channel (the layer `key_pack` writes). Bubble passes:
    // the plane's layer. Zero passes: the number of layers.
    layer: u32,
    // The stream's first word; the first entry point's first word and how many there are.
    stream: u32,
    entries: u32,
    count: u32,
    // Blocks the stream codes, and the part [lo, hi) of them this job keeps.
    blocks: u32,
    lo: u32,
    hi: u32,
    // A bubble plane's member spans (first word, number); 0 for a keyframe plane.
    members: u32,
    member_count: u32,
    // Workgroups per row of the dispatch (counts beyond 65 535 use more rows).
    groups_x: u32,
    // Blocks across a keyframe plane; blocks across a tile; tiles across the plane.
    blocks_x: u32,
    per: u32,
    tiles_x: u32,
    // Texels of the plane (zero passes).
    size: vec2<u32>,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> job: Job;
// The segment's coefficient streams, entry points and member spans (player/src/coded.rs).
@group(0) @binding(2) var<storage, read> words: array<u32>;

fn group_index(wg: vec3<u32>) -> u32 {
    return wg.y * job.groups_x + wg.x;
}
