//! Format 2's and 3's coefficient sections decoded on the GPU as the file codes them
//! (`lanes.wgsl`): the decoder thread hands each section's words on as they are
//! (`coded.rs`), and five or six dispatches decode them into the dense plane that the
//! keyframe and bubble passes read, as a parse of version 1's pairs leaves it: per batch
//! of a keyframe's planes or of a segment's bubble planes (each at its own place in the
//! dense plane, which holds a keyframe's planes side by side: [`lane_blocks`],
//! `Gpu::lane_batches`). Once per
//! section, `slots` builds the tables of the histograms the chunk sent itself; the file's
//! histograms and context maps go to the GPU once, when the stream opens.
//!
//! A plane must fit the dense plane whole (up to WebGPU's default binding size: planes of
//! about 5800² texels): the odd blocks' contexts read their neighbours anywhere in the
//! plane. A larger stream's sections go to the GPU as pairs, decoded by the decoder
//! thread ([`decodes_lanes`]).

use vbim_format::plane2::{
    file_histograms, ContextMap, CONTEXTS, FAMILIES, GROUP, MAX_STATES, REGION,
};
use vbim_format::Header;

use super::job::BATCH_PLANES;
use super::ops::Op;
use super::Gpu;
use crate::coded::{LanePlane, PlaneSpan, SectionSpan};

/// One plane of a batch decoded by the same dispatches ([`Gpu::lane_ops`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct LaneMember {
    pub span: PlaneSpan,
    pub lanes: LanePlane,
    /// Where its block 0 lies in the dense plane (a multiple of 64 blocks).
    pub dense_at: u32,
}

/// One pass of a lanes decode (an entry point of `lanes.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LanePass {
    Slots,
    Prepare,
    Flags,
    Middle,
    Blocks,
    DcRows,
    DcCols,
    DcTiles,
}

impl LanePass {
    pub const ALL: [LanePass; 8] = [
        LanePass::Slots,
        LanePass::Prepare,
        LanePass::Flags,
        LanePass::Middle,
        LanePass::Blocks,
        LanePass::DcRows,
        LanePass::DcCols,
        LanePass::DcTiles,
    ];

    /// Its entry point in `lanes.wgsl`.
    pub fn entry(self) -> &'static str {
        match self {
            LanePass::Slots => "slots",
            LanePass::Prepare => "prepare",
            LanePass::Flags => "flags",
            LanePass::Middle => "middle",
            LanePass::Blocks => "blocks",
            LanePass::DcRows => "dc_rows",
            LanePass::DcCols => "dc_cols",
            LanePass::DcTiles => "dc_tiles",
        }
    }

    /// Its timestamps' label (`vbim bench decode --gpu`).
    pub fn label(self) -> &'static str {
        match self {
            LanePass::Slots => "lane_slots",
            LanePass::Prepare => "lane_prepare",
            LanePass::Flags => "lane_flags",
            LanePass::Middle => "lane_middle",
            LanePass::Blocks => "lane_blocks",
            LanePass::DcRows => "lane_dc_rows",
            LanePass::DcCols => "lane_dc_cols",
            LanePass::DcTiles => "lane_dc_tiles",
        }
    }
}

/// Where the lanes' tables and scratch buffers hold what (in words; `lanes.wgsl`
/// describes each): the tables (maps, histograms' slot tables), which the lane
/// passes only read, then the scratch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Scratch {
    slots: u64,
    /// The tables' words.
    tables: u64,
    groups: u64,
    info: u64,
    lane_states: u64,
    /// Words between two planes' groups in a batch: a plane's groups' flags, then its
    /// tiles' ranks.
    pub group_stride: u64,
    /// The streams whose states the scratch holds: those of one plane of the most a
    /// plane may have, shared by a batch's planes.
    pub streams: u64,
    /// Blocks of the dense plane the lanes decode into ([`lane_blocks`]).
    pub dense: u32,
    fault: u64,
    words: u64,
    /// Histograms the tables hold room for: the file's, then a section's own (at most
    /// one per cluster of its kind's two families).
    histograms: u64,
    /// The file's histograms.
    pub file_histograms: u32,
}

impl Scratch {
    /// The scratch of a version 2 stream whose planes fit the dense plane whole; `None`
    /// for any other (its planes go to the GPU as pairs).
    pub fn for_stream(h: &Header) -> Option<Scratch> {
        let (pw, ph) = vbim_format::chunk::padded_size(h);
        let geometry = (
            [pw as u32, ph as u32],
            h.tile_size as u32,
            h.channels as u32,
        );
        Scratch::new(geometry, h.context_maps()?)
    }

    /// The scratch for `channels` planes of `plane` texels in tiles of `tile`² coded with
    /// `maps`; `None` if a plane is larger than the dense plane.
    pub fn new(
        (plane, tile, channels): ([u32; 2], u32, u32),
        maps: &[ContextMap],
    ) -> Option<Scratch> {
        if !crate::coded::fits_dense_plane(plane) {
            return None;
        }
        let dense = lane_blocks(plane, channels);
        let [pw, ph] = plane;
        let (bw, bh) = (pw as u64 / 8, ph as u64 / 8);
        let file = file_histograms(maps).count() as u64;
        // A section's planes are of one kind (its luma and chroma families): it sends at
        // most one histogram per cluster of those two.
        let clusters = |f: usize| maps.get(f).map_or(0, |m| m.clusters as u64);
        let own = (0..FAMILIES / 2)
            .map(|k| clusters(2 * k) + clusters(2 * k + 1))
            .max()
            .unwrap_or(0);
        let ts = (tile as u64).max(1);
        let tiles = (pw as u64 / ts) * (ph as u64 / ts);
        let groups = (bw.div_ceil(GROUP as u64)) * bh.div_ceil(GROUP as u64);
        // Version 3's lanes have up to MAX_STATES streams each (version 2's one): room for
        // as many planes' as the dense plane holds.
        let planes = (dense as u64).div_ceil((bw * bh).max(1));
        let regions = bw.div_ceil(REGION as u64) * bh.div_ceil(REGION as u64);
        let streams = regions * MAX_STATES as u64 * planes;
        let histograms = file + own;
        let slots = 2 * (FAMILIES * CONTEXTS) as u64;
        let tables = slots + histograms * 4096;
        // A batch's planes (`BATCH_PLANES`, `Gpu::lane_batches`) each have their groups
        // and ranks; their residuals and counts lie at their places in the dense plane
        // and their states one after another.
        let group_stride = groups + tiles;
        let info = BATCH_PLANES as u64 * group_stride;
        let lane_states = info + 2 * dense as u64;
        let fault = lane_states + 4 * streams;
        Some(Scratch {
            slots,
            tables,
            groups: 0,
            info,
            lane_states,
            group_stride,
            streams,
            dense,
            fault,
            words: fault + 1,
            histograms,
            file_histograms: file as u32,
        })
    }

    /// Bytes of the tables and the scratch buffer.
    pub fn bytes(&self) -> u64 {
        (self.tables + self.words) * 4
    }

    /// The WGSL constants `lanes.wgsl` reads its layout from; the sets of blocks with a
    /// coefficient start at byte `sets` of the mask buffer.
    fn constants(&self, sets: u64) -> String {
        format!(
            "const CONTEXTS: u32 = {CONTEXTS}u;\nconst SLOTS: u32 = {}u;\n\
             const INFO: u32 = {}u;\nconst FAULT: u32 = {}u;\n\
             const HISTOGRAMS: u32 = {}u;\nconst FILE_HISTOGRAMS: u32 = {}u;\n\
             const SETS: u32 = {}u;\nconst BATCH_PLANES: u32 = {BATCH_PLANES}u;\n",
            self.slots,
            self.info,
            self.fault,
            self.histograms,
            self.file_histograms,
            sets / 4
        )
    }

    /// The room a batch of planes has ([`lane_batches`]): the dense plane's blocks, and
    /// the scratch's states.
    ///
    /// [`lane_batches`]: super::batch::lane_batches
    pub fn room(&self) -> (u32, u64) {
        (self.dense, self.streams)
    }

    /// Where the lanes' sets of blocks with a coefficient start in the mask buffer, in
    /// bytes: after the masks of the dense plane's blocks.
    pub fn sets_offset(&self) -> u64 {
        super::plan::groups_offset(self.dense)
    }

    /// The first word of the groups of plane `k` of a batch.
    fn groups_at(&self, k: usize) -> u32 {
        (self.groups + k as u64 * self.group_stride) as u32
    }

    /// The first word of the states of a batch's streams from its `first`.
    fn states_at(&self, first: u32) -> u32 {
        (self.lane_states + 4 * first as u64) as u32
    }

    /// Where the fault flag lies, in bytes.
    #[cfg_attr(not(test), allow(dead_code))]
    pub fn fault_offset(&self) -> u64 {
        self.fault * 4
    }
}

/// Bytes the lanes need beside the rest of the GPU state (0 where a stream's planes go as
/// pairs): their tables and scratch, the dense plane's coefficients beyond one plane's
/// ([`lane_blocks`]), and its masks and sets (counted whole, though the ring of masks may
/// already hold them).
pub(crate) fn lanes_bytes(h: &Header) -> u64 {
    let Some(plan) = Scratch::for_stream(h) else {
        return 0;
    };
    let (pw, ph) = vbim_format::chunk::padded_size(h);
    let part = crate::coded::part_blocks([pw as u32, ph as u32]);
    let more = plan.dense.saturating_sub(part) as u64;
    plan.bytes() + more * 256 + super::plan::mask_bytes(plan.dense)
}

/// The room a batch of stream `h`'s planes decoded as coded has (`Scratch::room`);
/// `None` where its planes go as pairs. (For `vbim bench decode`.)
#[cfg(feature = "bench")]
pub fn lane_room(h: &Header) -> Option<(u32, u64)> {
    Scratch::for_stream(h).map(|s| s.room())
}

/// Blocks of the dense plane the lanes decode into, for planes of `plane` texels: as many
/// as `channels` planes side by side (each from a multiple of 64 blocks), so that a
/// keyframe's planes go in one batch ([`Gpu::lane_batches`]), or as many as one storage
/// binding of WebGPU's default limits holds (two at 4096²); at least one plane's.
fn lane_blocks(plane: [u32; 2], channels: u32) -> u32 {
    let one = ((plane[0] / 8) as u64 * (plane[1] / 8) as u64).next_multiple_of(64);
    let binding = wgpu::Limits::default().max_storage_buffer_binding_size / 256;
    let planes = (binding / one.max(1)).clamp(1, channels.max(1) as u64);
    (planes * one).min(u32::MAX as u64) as u32
}

super::job::uniform_struct! {
    /// One lanes pass's parameters (`LaneJob` in lanes.wgsl), in the jobs buffer.
    LaneJob, LANE_JOB_WGSL, LANE_FIELDS;
    /// Blocks across and down the plane.
    bw: u32 => "u32",
    /// (See `bw`.)
    bh: u32 => "u32",
    /// Groups (4 × 4 blocks) across and down.
    gw: u32 => "u32",
    /// (See `gw`.)
    gh: u32 => "u32",
    /// Regions (16 × 16 blocks) across.
    rw: u32 => "u32",
    /// Blocks across a tile for a bubble plane (its DC prediction stays in the tile); 0
    /// for a keyframe plane.
    tile: u32 => "u32",
    /// The plane's streams (its lanes' states: one a lane in version 2).
    lanes: u32 => "u32",
    /// 1 for version 3's blocks (a residual and whether a coefficient follows in one
    /// symbol; group by group), 0 for version 2's.
    v3: u32 => "u32",
    /// The section's lanes' words: first word in the segment's words.
    words: u32 => "u32",
    /// The plane's streams: two words each (its lane's first region | its place among
    /// the lane's states << 16 | their number less one << 22; its first word from the
    /// section's first), then the end of the words.
    table: u32 => "u32",
    /// Its family (which context map codes it).
    family: u32 => "u32",
    /// Its blocks.
    blocks: u32 => "u32",
    /// A bubble plane's tiles across and down (0 for a keyframe plane).
    tiles_x: u32 => "u32",
    /// (See `tiles_x`.)
    tiles_y: u32 => "u32",
    /// A bubble plane's member spans: first word and number.
    spans: u32 => "u32",
    /// (See `spans`.)
    span_count: u32 => "u32",
    /// A bubble plane's member tiles.
    members: u32 => "u32",
    /// `slots`: the histograms the section sent itself, first word and number.
    own: u32 => "u32",
    /// (See `own`.)
    own_count: u32 => "u32",
    /// Where the plane's block 0 lies in the dense plane (its coefficients, masks, sets
    /// and the scratch's residuals and counts), in blocks: 0, or its place among a
    /// batch's planes (a multiple of 64).
    dense_at: u32 => "u32",
    /// The first word of its streams' states in the scratch.
    states_at: u32 => "u32",
    /// The first word of its groups' flags (then its tiles' ranks) in the scratch.
    groups_at: u32 => "u32",
    /// (Padding.)
    _pad0: u32 => "u32",
    /// (Padding.)
    _pad1: u32 => "u32",
    /// `slots`: per family the first word of its clusters' histograms (NONE: not used).
    places: [u32; 8] => "array<vec4<u32>, 2>",
}

/// The lanes decode's pipelines and state.
pub(crate) struct LanesGpu {
    /// States a workgroup of the lane passes (`DecodeShape::lane_group`).
    group: u32,
    /// The lane passes' bind group layout, and `slots`' (which writes the tables).
    layouts: [wgpu::BindGroupLayout; 2],
    pipelines: Vec<wgpu::ComputePipeline>,
    tables: wgpu::Buffer,
    scratch: wgpu::Buffer,
    pub plan: Scratch,
    /// Its bind groups over the jobs, streams, scratch, tables and dense plane (the lane
    /// passes'), and over the jobs, streams and tables (`slots`'): remade with the
    /// others, `Gpu::bind_decode`.
    groups: Option<[wgpu::BindGroup; 2]>,
}

impl LanesGpu {
    /// The pipelines and scratch for planes of `geometry` (texels, tile side and
    /// channels) coded with `maps` (`None` where they go as pairs, [`Scratch::new`]), with
    /// the file's maps and histograms written; the sets of the dense plane start at byte
    /// [`Scratch::sets_offset`] of its mask buffer. `shape` (as [`Gpu::set_decode_shape`] keeps it) gives the states a
    /// workgroup and where the job is read from.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        (geometry, maps): (([u32; 2], u32, u32), &[ContextMap]),
        shape: &crate::DecodeShape,
    ) -> Option<LanesGpu> {
        let plan = Scratch::new(geometry, maps)?;
        let sets = plan.sets_offset();
        let group = shape.lane_group;
        let (job, space) = match shape.lane_job_storage {
            true => (
                wgpu::BufferBindingType::Storage { read_only: true },
                "storage, read",
            ),
            false => (wgpu::BufferBindingType::Uniform, "uniform"),
        };
        let layouts = [
            layout(device, job, &LANE_BINDINGS),
            layout(device, job, &SLOT_BINDINGS),
        ];
        let source = format!(
            "{}const LANE_GROUP: u32 = {group}u;\n{LANE_JOB_WGSL}{}",
            plan.constants(sets),
            include_str!("lanes.wgsl").replace("var<JOB>", &format!("var<{space}>"))
        );
        let pipelines = LanePass::ALL
            .iter()
            .map(|&p| {
                let layout = &layouts[(p == LanePass::Slots) as usize];
                super::layouts::compute_pipeline(device, "vbim lanes", &source, layout, p.entry())
            })
            .collect();
        let buffer = |label, words: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: words.max(1) * 4,
                // (COPY_SRC: tests read the fault flag back.)
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let tables = buffer("vbim lanes tables", plan.tables);
        let scratch = buffer("vbim lanes scratch", plan.words);
        // The file's part of the tables: each family's cluster of each context, and each
        // file histogram's entries and slots.
        let of: Vec<u32> = (0..FAMILIES)
            .flat_map(|f| (0..CONTEXTS).map(move |c| maps.get(f).map_or(0, |m| m.of[c] as u32)))
            .collect();
        queue.write_buffer(&tables, 0, bytemuck::cast_slice(&of));
        let slots: Vec<u32> = file_histograms(maps)
            .flat_map(|(_, _, hist)| hist.slot_table())
            .collect();
        if !slots.is_empty() {
            queue.write_buffer(&tables, plan.slots * 4, bytemuck::cast_slice(&slots));
        }
        Some(LanesGpu {
            group,
            layouts,
            pipelines,
            tables,
            scratch,
            plan,
            groups: None,
        })
    }

    fn pipeline(&self, pass: LanePass) -> &wgpu::ComputePipeline {
        &self.pipelines[LanePass::ALL.iter().position(|&p| p == pass).unwrap_or(0)]
    }

    /// GPU memory it holds, in bytes.
    pub fn bytes(&self) -> u64 {
        self.tables.size() + self.scratch.size()
    }

    /// The bind groups over `jobs`, `words`, the tables, the scratch and the dense plane.
    pub fn bind(
        &mut self,
        device: &wgpu::Device,
        jobs: &wgpu::Buffer,
        words: &wgpu::Buffer,
        (coefs, masks): (&wgpu::Buffer, &wgpu::Buffer),
    ) {
        let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
        let job = || {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: jobs,
                offset: 0,
                size: wgpu::BufferSize::new(super::job::JOB_BINDING),
            })
        };
        let lanes = [
            entry(0, job()),
            entry(1, words.as_entire_binding()),
            entry(2, self.scratch.as_entire_binding()),
            entry(3, coefs.as_entire_binding()),
            entry(4, masks.as_entire_binding()),
            entry(5, self.tables.as_entire_binding()),
        ];
        let slots = [
            entry(0, job()),
            entry(1, words.as_entire_binding()),
            entry(6, self.tables.as_entire_binding()),
        ];
        let group = |layout, entries: &[wgpu::BindGroupEntry]| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("vbim lanes"),
                layout,
                entries,
            })
        };
        self.groups = Some([
            group(&self.layouts[0], &lanes),
            group(&self.layouts[1], &slots),
        ]);
    }
}

/// The lane passes' bindings after the job's (binding 0): the segment's words, the
/// scratch, the dense plane (coefficients, masks) and the tables, read-only.
const LANE_BINDINGS: [(u32, wgpu::BufferBindingType); 5] = [
    (1, wgpu::BufferBindingType::Storage { read_only: true }),
    (2, wgpu::BufferBindingType::Storage { read_only: false }),
    (3, wgpu::BufferBindingType::Storage { read_only: false }),
    (4, wgpu::BufferBindingType::Storage { read_only: false }),
    (5, wgpu::BufferBindingType::Storage { read_only: true }),
];

/// `slots`' bindings after the job's: the segment's words and the tables, which it
/// writes.
const SLOT_BINDINGS: [(u32, wgpu::BufferBindingType); 2] = [
    (1, wgpu::BufferBindingType::Storage { read_only: true }),
    (6, wgpu::BufferBindingType::Storage { read_only: false }),
];

/// A bind group layout of the job's binding (0, of type `job`, at a dynamic offset) and
/// `bindings`.
fn layout(
    device: &wgpu::Device,
    job: wgpu::BufferBindingType,
    bindings: &[(u32, wgpu::BufferBindingType)],
) -> wgpu::BindGroupLayout {
    let entry = |binding: u32, ty| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: binding == 0,
            min_binding_size: None,
        },
        count: None,
    };
    let entries: Vec<_> = std::iter::once((0, job))
        .chain(bindings.iter().copied())
        .map(|(b, ty)| entry(b, ty))
        .collect();
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("vbim lanes"),
        entries: &entries,
    })
}

impl Gpu {
    /// The ops that decode version 2 or 3 planes `batch` (of one section, each at its
    /// place in the dense plane) into the dense plane: the section's tables first if the
    /// planes before were of another section (`planned_section`), then the five passes
    /// (six for keyframe planes, whose DC takes two scans), each one dispatch over the
    /// batch's planes (`workgroup_id.z`, each with its own job). A lane pass lasts as long
    /// as the longest lane it runs, so planes side by side cost the longest of their
    /// chains, not the sum, and a step's latency once.
    pub(super) fn lane_ops(
        &mut self,
        ops: &mut Vec<Op>,
        batch: &[LaneMember],
        sections: &[SectionSpan],
        channel: u32,
    ) {
        let Some(first) = batch.first() else {
            return;
        };
        let Some(section) = sections.get(first.lanes.section as usize) else {
            debug_assert!(false, "a plane of no section");
            return;
        };
        debug_assert!(batch.iter().all(|m| m.lanes.section == first.lanes.section));
        let Some((plan, group)) = self.lanes.as_ref().map(|l| (l.plan, l.group)) else {
            return;
        };
        let [pw, ph] = self.plane;
        let (bw, bh) = (pw / 8, ph / 8);
        let (gw, gh) = (bw.div_ceil(GROUP as u32), bh.div_ceil(GROUP as u32));
        let mut places = [crate::coded::NONE; 8];
        places[..FAMILIES].copy_from_slice(&section.places);
        let mut streams = 0;
        let jobs: Vec<LaneJob> = batch
            .iter()
            .enumerate()
            .map(|(k, m)| {
                let (span, lanes) = (&m.span, &m.lanes);
                let ts = if lanes.tiled { self.per } else { 0 };
                let (tiles_x, tiles_y) = if lanes.tiled {
                    (bw / ts, bh / ts)
                } else {
                    (0, 0)
                };
                let states_at = plan.states_at(streams);
                streams += lanes.count;
                LaneJob {
                    bw,
                    bh,
                    gw,
                    gh,
                    rw: bw.div_ceil(REGION as u32),
                    tile: ts,
                    lanes: lanes.count,
                    v3: section.v3 as u32,
                    words: section.words,
                    table: lanes.table,
                    family: lanes.family,
                    blocks: span.blocks,
                    tiles_x,
                    tiles_y,
                    spans: span.members,
                    span_count: span.member_count,
                    members: if ts > 0 { span.blocks / (ts * ts) } else { 0 },
                    own: section.own,
                    own_count: section.own_count,
                    dense_at: m.dense_at,
                    states_at,
                    groups_at: plan.groups_at(k),
                    _pad0: 0,
                    _pad1: 0,
                    places,
                }
            })
            .collect();
        debug_assert!(streams as u64 <= plan.streams && jobs.len() <= BATCH_PLANES as usize);
        // The batch's jobs one after another; `slots` reads the first's section.
        let at = self.push_jobs(&jobs);
        if self.planned_section != Some(first.lanes.section) {
            self.planned_section = Some(first.lanes.section);
            let n = (FAMILIES * CONTEXTS) as u32 + section.own_count * 1024;
            let groups = [n.div_ceil(64), 1];
            ops.push(Op::lanes(
                LanePass::Slots,
                at,
                groups,
                channel,
                n as u64 / 16,
            ));
        }
        let z = jobs.len() as u32;
        // Per pass: the workgroups of its largest plane, and its units (the planes' work
        // summed; for a lane pass its longest lane, the serial chain the others run
        // beside).
        let most = |f: &dyn Fn(&LaneJob, &LaneMember) -> u64| {
            jobs.iter()
                .zip(batch)
                .map(|(j, m)| f(j, m))
                .max()
                .unwrap_or(0)
        };
        let sum = |f: &dyn Fn(&LaneJob, &LaneMember) -> u64| {
            jobs.iter().zip(batch).map(|(j, m)| f(j, m)).sum::<u64>()
        };
        // `prepare` also clears the dense plane's masks and sets (two words per group of
        // 64 blocks).
        let cells = most(&|j, _| {
            let sets = 2 * j.blocks.div_ceil(64);
            let cells = (gw * gh).max(j.tiles_x * j.tiles_y).max(j.blocks);
            cells.max(j.lanes).max(sets) as u64
        });
        let by_lane = most(&|j, _| j.lanes.div_ceil(group) as u64) as u32;
        let blocks = sum(&|j, _| j.blocks as u64);
        let words = most(&|_, m| m.lanes.longest as u64);
        let mut passes = vec![
            (LanePass::Prepare, cells.div_ceil(64) as u32, blocks),
            (LanePass::Flags, by_lane, (gw * gh) as u64 / 2),
            (LanePass::Middle, by_lane, words / 2),
            (LanePass::Blocks, by_lane, words - words / 2),
        ];
        if first.lanes.tiled {
            let tiles = most(&|j, _| (j.tiles_x * j.tiles_y) as u64) as u32;
            passes.push((LanePass::DcTiles, tiles.div_ceil(64), blocks));
        } else {
            passes.push((LanePass::DcRows, bh.div_ceil(64), blocks));
            passes.push((LanePass::DcCols, bw.div_ceil(64), blocks));
        }
        for (pass, groups, units) in passes {
            ops.push(Op::lanes(pass, at, [groups, z], channel, units));
        }
    }

    /// Records a lanes op into `pass`.
    pub(super) fn dispatch_lanes(&self, pass: &mut wgpu::ComputePass, op: &Op, which: LanePass) {
        let Some(lanes) = &self.lanes else {
            return;
        };
        let Some(groups) = &lanes.groups else {
            return;
        };
        pass.set_pipeline(lanes.pipeline(which));
        let group = &groups[(which == LanePass::Slots) as usize];
        pass.set_bind_group(0, group, &[op.job]);
        if op.groups[0] > 0 {
            pass.dispatch_workgroups(op.groups[0], 1, op.groups[2].max(1));
        }
        self.mark(pass, which.label());
    }

    /// Whether a lane of a version 2 plane decoded since the last call read past its words
    /// or decoded a symbol out of range (a damaged or crafted section); clears the flag.
    /// Blocks until the GPU is done: for tests and checks, never per frame.
    #[cfg(test)]
    pub fn lanes_faulted(&self) -> bool {
        let Some(lanes) = &self.lanes else {
            return false;
        };
        let raw = crate::readback::read_buffer_range(
            &self.device,
            &self.queue,
            &lanes.scratch,
            lanes.plan.fault_offset(),
            4,
        );
        self.queue
            .write_buffer(&lanes.scratch, lanes.plan.fault_offset(), &[0; 4]);
        raw.iter().any(|&b| b != 0)
    }
}

#[cfg(test)]
#[test]
fn the_wgsl_lane_job_has_the_rust_layout() {
    super::job::check_layout(LANE_FIELDS, std::mem::size_of::<LaneJob>());
    let declared = |l: &str| l.trim_start().starts_with("struct LaneJob");
    assert!(
        !include_str!("lanes.wgsl").lines().any(declared),
        "declared twice"
    );
}
