// What the decode passes share (decode.wgsl and parse.wgsl are each appended to this):
// one job's parameters (`struct Job`, declared in player/src/gpu/job.rs and put before
// this file), the coefficient streams and the dispatch's layout.


@group(0) @binding(0) var<uniform> job: Job;
// The slice of the pass this dispatch runs: its first workgroup (x), from a buffer of
// every slice's, written once (player/src/gpu/decode.rs, SLICE_GROUPS).
@group(0) @binding(11) var<uniform> slice: vec4<u32>;
// The segment's coefficient streams, entry points and member spans (player/src/coded.rs).
@group(0) @binding(2) var<storage, read> words: array<u32>;

fn group_index(wg: vec3<u32>) -> u32 {
    return slice.x + wg.y * job.groups_x + wg.x;
}
