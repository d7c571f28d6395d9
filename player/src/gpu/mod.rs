//! The GPU side: what stays resident — the chain's head keyframe (R32Float, one layer
//! per plane), two slots of 16-bit keyframes (16-bit steps of a range per 32² region, two
//! to an R32Uint texel), two sets of bubble terms kept as DCT coefficients (per block and
//! layer its mask, first term and where the rest are, in an Rgba32Uint texel; the rest in
//! a buffer per set), the display texture the renderer samples and a held copy for
//! catch-up blending (RGB9E5 in an R32Uint texel) — and the passes that fill them: the
//! segment decode of `decode.wgsl` (parsing the coefficient streams, dequantisation,
//! inverse DCT and predicted keyframes for the keyframes, a gather of each block's terms
//! for the bubble planes) and the per-frame reconstruction of `reconstruct.wgsl`, which
//! sums a block's bubble terms itself. The segment on screen reads one slot (K_s), the
//! head or the other slot (K_{s+1}) and one bubble set; the next segment decodes into the
//! rest, a slice at a time, while it plays (`decode.rs`). The decode parses each plane
//! into a dense plane of i32 coefficients with a 64-bit mask per block (4 bytes per texel
//! of one plane, reused plane after plane), which the passes after it read.
//!
//! The head stays f32: the next predicted keyframe is built on it, and a 16-bit head
//! would add its rounding at every step of the chain (docs/FORMAT.md, "What the GPU
//! decoder guarantees"). The 16-bit keyframes are only displayed, each packed once from
//! the f32 head, so each carries one rounding. Bubble terms are sparse (most blocks of a
//! bubble plane hold one coefficient or none), so a set kept as coefficients takes about
//! 3 bytes per texel where 16-bit texels took 18, and the reconstruction reads less.
//!
//! By concern: `device` (opening one headless), `plan` (what the state holds, in bytes, before
//! it exists), `resources` (creating it), `layouts` (the passes' bind group layouts and pipelines), `job` (a decode pass's parameters, as the shader
//! declares them), `decode` (recording a segment's decode), `reconstruct` (recording a
//! frame's reconstruction and the hold pass), `bench` (the decode alone, timed), `ops`
//! (one step of a decode and its cost), `lanes` (version 2's sections decoded as coded,
//! `lanes.wgsl`).

mod batch;
#[cfg(feature = "bench")]
mod bench;
mod decode;
mod device;
mod job;
mod lanes;
#[cfg(test)]
mod lanes_tests;
mod layouts;
mod ops;
mod plan;
mod reconstruct;
mod resources;
#[cfg(test)]
mod tests;

#[cfg(feature = "bench")]
pub use batch::lane_batches;
#[cfg(feature = "bench")]
pub use bench::GpuDecoder;
pub(crate) use decode::Target;
#[cfg(feature = "bench")]
pub use decode::PASS_CHANGES;
#[cfg(feature = "bench")]
pub use device::timing_device;
pub use device::{headless_device, headless_device_on, DeviceError, Headless};
#[cfg(feature = "bench")]
pub use lanes::lane_room;
pub(crate) use lanes::lanes_bytes;
pub(crate) use layouts::compute_pipeline;
pub(crate) use ops::Op;
pub use plan::lightmap_descriptor;
pub(crate) use plan::{min_array_layers, planned_texture_bytes, BUBBLE_SETS, KEY_SLOTS};
pub use reconstruct::OutputError;
pub(crate) use reconstruct::Params;

pub(crate) struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    /// The reconstruction's first frame of a generation (`main_fresh`).
    pipeline_fresh: wgpu::ComputePipeline,
    /// Packs what is on screen into `held` (from the display, or the caller's output).
    hold: wgpu::ComputePipeline,
    hold_layout: wgpu::BindGroupLayout,
    hold_group: wgpu::BindGroup,
    parse: wgpu::ComputePipeline,
    /// The parse with a workgroup per piece (`parse_wide` in parse.wgsl).
    parse_wide: wgpu::ComputePipeline,
    key_add: wgpu::ComputePipeline,
    key_pack: wgpu::ComputePipeline,
    bubble_gather: wgpu::ComputePipeline,
    key_layout: wgpu::BindGroupLayout,
    pack_layout: wgpu::BindGroupLayout,
    bubble_layout: wgpu::BindGroupLayout,
    parse_layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    tables: wgpu::Buffer,
    /// Decode pass parameters, `JOB_STRIDE` apart; grows with the longest keyframe chain.
    jobs: wgpu::Buffer,
    /// A batch of bubble planes' jobs being planned (`Gpu::plan_decode`), kept so that
    /// planning allocates nothing.
    batch: Vec<job::Job>,
    /// The batch being planned from those (`Gpu::batches`).
    batch_out: Vec<job::Job>,
    /// A segment's bubble planes decoded as coded (`Gpu::lane_batches`), and the members
    /// of a batch of them.
    lane_planes: Vec<(job::Job, crate::coded::PlaneSpan)>,
    lane_members: Vec<lanes::LaneMember>,
    /// A segment's streams, entry points and member spans; grows with the largest segment.
    words: wgpu::Buffer,
    /// Each slice's first workgroup (`resources::slice_buffer`); grows with the longest pass.
    slices: wgpu::Buffer,
    /// The dense plane: `part` blocks of 64 i32 coefficients; and the ring of masks,
    /// `mask_slots` slots ([`plan::mask_slots`]) each with a part's masks, then per group
    /// of [`GROUP_BLOCKS`] blocks which have a coefficient ([`groups_offset`]). A segment's
    /// decode clears the ring before its first parse, and again each time it comes round;
    /// the coefficients are never cleared (only those a mask names are read).
    coefs: wgpu::Buffer,
    masks: wgpu::Buffer,
    mask_slots: u32,
    part: u32,
    /// Each reconstruction tile's generation and weights, in two copies, and its bounds
    /// (reconstruct.wgsl).
    tiles: wgpu::Buffer,
    peaks: wgpu::Buffer,
    /// The parameters' generation, and the last parameters recorded.
    gen: u32,
    last_params: Option<Params>,
    /// Which copy of the tiles' state the next reconstruction writes.
    parity: u32,
    /// The next frame's place in the cycle of three counters of kept tiles, and every how
    /// many frames one decides which tiles to keep whatever the last deciding frame kept
    /// (0: every frame decides; `PlayerConfig::reuse_probe`).
    frame3: u32,
    pub(crate) reuse_probe: u32,
    /// Frames since the last that decided, and whether the last was a generation's first.
    since_probe: u64,
    after_first: bool,
    /// The chain's head keyframe K_{s+1}, f32.
    keys: wgpu::Texture,
    /// One view per plane of the head, for the decode passes.
    key_views: Vec<wgpu::TextureView>,
    /// The 16-bit keyframes ([`KEY_SLOTS`] slots of `channels` layers: K_s of the segment
    /// on screen, and K_{s+1} once the next decode packed it), and each region's range.
    packed: wgpu::Texture,
    packed_view: wgpu::TextureView,
    ranges: wgpu::Buffer,
    regions: [u32; 2],
    /// The bubble sets' blocks: per block of 8 × 8 texels and layer (set · `set_layers` +
    /// (k − 2) · channels + plane), its mask, where its terms after the first start in the
    /// set's `terms`, and the first (`bubble_gather` in decode.wgsl).
    bubble_blocks: wgpu::Texture,
    bubble_view: wgpu::TextureView,
    /// Each bubble set's terms after each block's first (16-bit integers two to a word, or
    /// dequantised f32 where one does not fit); grows with the segments' terms.
    terms: [wgpu::Buffer; BUBBLE_SETS as usize],
    display: wgpu::Texture,
    pub display_view: wgpu::TextureView,
    held: wgpu::Texture,
    /// The reconstruction's bind group for each bubble set.
    bind_groups: Vec<wgpu::BindGroup>,
    /// The reconstruction's layout and inputs, for a bind group over a caller's texture.
    reconstruct_layout: wgpu::BindGroupLayout,
    keys_view: wgpu::TextureView,
    held_view: wgpu::TextureView,
    /// A texture of the caller's that the reconstruction writes instead of `display`, with
    /// the reconstruction's (per bubble set) and the hold pass's bind groups over it.
    output: Option<(wgpu::Texture, Vec<wgpu::BindGroup>, wgpu::BindGroup)>,
    /// Decode bind groups (per keyframe layer, and per bubble set): remade when `words`,
    /// `jobs` or a set's `terms` grow.
    key_groups: Vec<wgpu::BindGroup>,
    /// `key_pack`'s bind group (the head whole).
    pack_group: Option<wgpu::BindGroup>,
    bubble_groups: Vec<wgpu::BindGroup>,
    parse_group: Option<wgpu::BindGroup>,
    /// Scratch for the jobs of one segment (kept: no allocation per segment).
    job_bytes: Vec<u8>,
    /// The decode's shape ([`Gpu::set_decode_shape`], its group split a power of two),
    /// and its slice in [`SLICE_GROUPS`] of workgroups.
    ///
    /// [`SLICE_GROUPS`]: decode::SLICE_GROUPS
    shape: crate::DecodeShape,
    slice_span: u32,
    /// Bubble layers of one set ([`BUBBLE_SETS`] sets, one after the other).
    pub set_layers: u32,
    /// Timestamps between the decode's dispatches (`vbim bench decode --gpu`).
    #[cfg(feature = "bench")]
    marks: Option<crate::marks::Marks>,
    pub width: u32,
    pub height: u32,
    /// The padded planes' size (whole tiles).
    plane: [u32; 2],
    pub channels: u32,
    /// Blocks across a tile, and tiles across a plane.
    per: u32,
    tiles_x: u32,
    /// Tiles in a plane.
    tile_count: u32,
    /// Each tile's degree per bubble set and plane (`degrees` in decode.wgsl).
    degrees: wgpu::Buffer,
    /// A version 2 stream's decode of its sections as coded (`lanes.wgsl`); `None`
    /// where planes come as pairs.
    lanes: Option<lanes::LanesGpu>,
    /// The section whose tables the decode being planned last built.
    planned_section: Option<u32>,
}

impl Gpu {
    /// Waits for the GPU to finish what was submitted.
    pub fn wait(&self) {
        let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
    }
}
