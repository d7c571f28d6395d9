// What the decode passes share (decode.wgsl and parse.wgsl are each appended to this):
// one job's parameters (`struct Job`, declared in player/src/gpu/job.rs and put before
// this file), the coefficient streams and the dispatch's layout.


// The jobs of the dispatch: one, or for a dispatch over several planes at once (a batch
// of a segment's bubble planes, player/src/gpu/decode.rs) one per plane, the plane
// `workgroup_id.z`, JOB_STRIDE (256) bytes apart. Each entry point first takes its own
// (`take_job`) into `job`, which everything else reads.
struct PlaneJob {
    job: Job,
    // (To JOB_STRIDE: the 96 bytes of a Job and 160 more.)
    pad: array<vec4<u32>, 10>,
}
@group(0) @binding(0) var<uniform> jobs: array<PlaneJob, BATCH_PLANES>;
var<private> job: Job;

fn take_job(wg: vec3<u32>) {
    job = jobs[wg.z].job;
}
// The slice of the pass this dispatch runs: its first workgroup (x), from a buffer of
// every slice's, written once (player/src/gpu/decode.rs, SLICE_GROUPS).
@group(0) @binding(11) var<uniform> slice: vec4<u32>;
// The segment's coefficient streams, entry points and member spans (player/src/coded.rs).
@group(0) @binding(2) var<storage, read> words: array<u32>;

fn group_index(wg: vec3<u32>) -> u32 {
    return slice.x + wg.y * job.groups_x + wg.x;
}
