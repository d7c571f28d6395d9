//! The segment decode: a segment's keyframe steps and bubble planes as a list of passes
//! over the coefficient streams (`job.wgsl`, `parse.wgsl`, `decode.wgsl`), planned at once
//! and recorded a few at a time, so that the player can spread a segment's decode over the
//! frames before it is shown ([`Op`], [`Gpu::plan_decode`], [`Gpu::record`]).

use super::batch::Then;
use super::job::{Job, JOB_BINDING, JOB_STRIDE};
use super::ops::{Kind, Op};
use super::plan::*;
use super::resources::slice_buffer;
use super::Gpu;
use crate::coded::Coded;
use crate::decoder::SegmentData;
use crate::DecodeShape;

/// Workgroups of one slice of a pass: a pass over more goes in several dispatches, which
/// may land in different frames. (32 workgroups of 64 blocks: 131 072 texels of a plane.)
pub(crate) const SLICE_GROUPS: u32 = 32;

/// The most workgroups a decode dispatch may cover ([`DecodeShape::slice_groups`]): a
/// parse slice ([`PARSE_SPAN`] of them) stays within WebGPU's 65 535 workgroups per
/// dimension.
pub(crate) const MAX_SLICE_GROUPS: u32 = 16_384;

/// The label of a compute pass's first timestamp (`vbim bench decode --gpu`): the time
/// since the one before is the clears and the pass change before it, not a dispatch's.
pub const PASS_CHANGES: &str = "clears and pass changes";

/// Workgroups a block pass needs to fill a large GPU (an H100 runs about 2000 of them at
/// once): a pass with fewer groups of blocks splits each among more workgroups, up to
/// [`DecodeShape::group_split`].
const FILL_GROUPS: u32 = 4096;

/// A parse slice is this many slices' workgroups: for the serial parse, as many pairs
/// per dispatch as when a piece was 256 pairs, so that shorter pieces shorten each
/// dispatch's serial chain without making more dispatches; for the wide parse (a
/// workgroup per piece), 4096 pieces per dispatch at a GPU's slice of 2048.
pub(super) const PARSE_SPAN: u32 = (256 / vbim_format::chunk::ENTRY_PAIRS) as u32;
const _: () = assert!(256 % vbim_format::chunk::ENTRY_PAIRS == 0);
// The wide parse gives each of its 64 lanes a whole number of a piece's pairs.
const _: () = assert!(vbim_format::chunk::ENTRY_PAIRS.is_multiple_of(64));

/// The work of a whole workgroup of the heaviest kind, in quarter-blocks: 64 blocks at
/// the budget's unit (a block of 64 texel sums, 4). A cheaper pass's dispatches cover
/// more workgroups, up to this much work each ([`Gpu::cheap_span`]).
pub(crate) const FULL_GROUP: u64 = GROUP_BLOCKS as u64 * 4;

/// The bytes of a segment's bubble terms after each block's first (what a bubble set's
/// term buffer must hold for it), four bytes a word: (exact, bound). Exact for planes
/// parsed from pairs, whose scan counted them; only a bound for planes decoded from lanes,
/// whose symbols the CPU does not decode. That bound (every state's most symbols, at most
/// 63 a block) can pass one storage binding at 4096² while the terms themselves take a
/// few percent of it: the buffer is then one binding, and the gather's guard (`put_term`
/// in decode.wgsl) drops terms beyond it, never writing out of bounds.
pub(crate) fn term_bytes(seg: &SegmentData) -> (u64, u64) {
    seg.planes[seg.bubbles.min(seg.planes.len())..]
        .iter()
        .fold((0, 0), |(exact, bound), p| match p.lanes {
            Some(_) => (exact, bound + p.terms as u64 * 4),
            None => (exact + p.terms as u64 * 4, bound),
        })
}

/// Where a segment's decode puts what it builds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Target {
    /// Pack the head into this slot before building anything (the display then reads
    /// K_{s+1} from the slot and the head is free).
    pub pack_first: Option<u32>,
    /// Pack the head into this slot before the last keyframe step (a chain's K_s).
    pub pack_before_last: Option<u32>,
    /// The bubble set the bubble planes go to; `None`: keyframes only.
    pub set: Option<u32>,
}

impl Gpu {
    /// Shapes the decodes planned from then on ([`DecodeShape`]): the slice rounded up to
    /// a multiple of [`SLICE_GROUPS`] (at most [`MAX_SLICE_GROUPS`]), the group split
    /// down to a power of two (at most [`GROUP_BLOCKS`]), the lane group to 1–64. Its
    /// `lanes`, `storage_tables`, `wide_reconstruct` and lane fields choose pipelines,
    /// which [`Gpu::for_stream`] builds once: they take effect there.
    pub fn set_decode_shape(&mut self, shape: DecodeShape) {
        self.slice_span = shape
            .slice_groups
            .clamp(1, MAX_SLICE_GROUPS)
            .div_ceil(SLICE_GROUPS);
        self.shape = DecodeShape {
            group_split: 1 << shape.group_split.clamp(1, GROUP_BLOCKS).ilog2(),
            lane_group: shape.lane_group.clamp(1, 64),
            ..shape
        };
    }

    /// Whether a segment's coefficients, and the bubble terms counted from its pairs, each
    /// fit one storage binding of this device (a lane plane's terms are bounded by the
    /// buffer: [`term_bytes`]).
    pub fn fits(&self, seg: &SegmentData) -> Result<(), String> {
        let limit = self.binding_limit();
        for (need, what) in [
            (seg.bytes(), "of coefficients"),
            (term_bytes(seg).0, "of bubble terms"),
        ] {
            if need > limit {
                return Err(format!(
                    "segment {}: {need} bytes {what}, more than one storage binding holds ({limit})",
                    seg.index
                ));
            }
        }
        Ok(())
    }

    /// What a bubble set's term buffer must hold for `seg`: its terms' exact bytes and
    /// bound ([`term_bytes`]), at most one binding.
    pub(super) fn term_need(&self, seg: &SegmentData) -> u64 {
        let (exact, bound) = term_bytes(seg);
        (exact + bound).min(self.binding_limit())
    }

    /// The most bytes one storage binding of this device holds, whole words.
    fn binding_limit(&self) -> u64 {
        self.device.limits().max_storage_buffer_binding_size / 4 * 4
    }

    /// The size to give a buffer that is bound whole and must hold `need` bytes: some room
    /// to grow ([`grown`]), but never more than one binding (a `need` beyond it is refused
    /// first, [`Gpu::fits`]).
    pub(super) fn bound_size(&self, need: u64) -> u64 {
        grown(need).min(self.binding_limit().max(need))
    }

    /// Makes bubble set `set`'s term buffer hold at least `bytes` (its blocks' terms after
    /// the first), and its bind groups bind it. Only a set the display does not read is
    /// decoded into, so the new buffer needs nothing of the old.
    fn hold_terms(&mut self, set: u32, bytes: u64) {
        let s = set as usize;
        if bytes <= self.terms[s].size() {
            return;
        }
        self.terms[s] = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vbim bubble terms"),
            size: self.bound_size(bytes),
            // (COPY_SRC: tests read it back.)
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        self.bind_decode();
        self.bind_reconstruct();
    }

    /// Plans the decode of `seg` into `target` (its jobs are written when its first op,
    /// the upload, is recorded). Fills `ops` with the ops, in the order they must be recorded, and
    /// returns the bytes the decode uploads (its streams and its jobs). Each keyframe plane is parsed into
    /// the dense plane, part by part, and added onto the head; each bubble plane's is
    /// parsed and its terms gathered per block into the set, in batches of planes that
    /// fit the dense plane together (one dispatch of each pass a batch). Nothing else may use the
    /// dense plane or the stream buffer until the last op is recorded.
    pub fn plan_decode(&mut self, seg: &SegmentData, target: Target, ops: &mut Vec<Op>) -> u64 {
        let ch = self.channels;
        let words = seg.bytes();
        if words > self.words.size() {
            self.words = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("vbim coefficient streams"),
                size: self.bound_size(words),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            self.bind_decode();
        }
        let (pw, ph) = (self.plane[0], self.plane[1]);
        self.job_bytes.clear();
        self.planned_section = None;
        ops.clear();
        ops.push(Op::new(Kind::Upload, 0, [0; 3], 0, 0));
        let [rx, ry] = self.regions;
        let pack = |gpu: &mut Gpu, ops: &mut Vec<Op>, slot: u32| {
            // Every plane's regions found and packed in one dispatch (plane
            // `workgroup_id.z`, each with its job): an invocation per row of a region, 64
            // per workgroup; 8 units (1/16 of a region each) per region.
            let n = ops.len();
            let regions = rx * ry;
            let mut jobs = std::mem::take(&mut gpu.batch);
            jobs.clear();
            for p in 0..ch {
                jobs.push(Job {
                    layer: slot * ch + p,
                    size: [pw, ph],
                    ..gpu.base_job()
                });
            }
            let at = gpu.push_jobs(&jobs);
            let groups = (regions * REGION).div_ceil(64);
            let plane = |_: &Job| (groups, regions as u64 * 8);
            gpu.sliced_batch(ops, Kind::KeyPack, at, &jobs, plane, (1, 16), 0);
            gpu.batch = jobs;
            for op in &mut ops[n..] {
                op.packs = true;
            }
        };
        if let Some(slot) = target.pack_first {
            pack(self, ops, slot);
        }
        // The next slot of the ring of masks a parse takes (0: the ring is cleared first).
        let mut ring = 0;
        let last = seg.steps.len().saturating_sub(1);
        for (n, st) in seg.steps.iter().enumerate() {
            if n == last {
                if let Some(slot) = target.pack_before_last {
                    pack(self, ops, slot);
                }
            }
            // A predicted keyframe is added onto the head (the keyframe it follows); an
            // intra one is written over it, zeros and all.
            let intra = st.intra as u32;
            // Planes decoded as coded go in batches, side by side (`Gpu::lane_batches`).
            let mut lanes = std::mem::take(&mut self.lane_planes);
            lanes.clear();
            for p in 0..ch {
                let span = &seg.planes[st.plane + p as usize];
                for job in self.part_jobs(span, p) {
                    if span.lanes.is_some() {
                        lanes.push((Job { intra, ..job }, *span));
                        continue;
                    }
                    let job = self.mask_slot(ops, job, &mut ring);
                    let blocks = job.hi - job.lo.min(job.hi);
                    self.parse_ops(ops, job, p);
                    self.key_add_pass(ops, Job { intra, ..job }, blocks, p);
                }
            }
            self.lane_batches(ops, &mut lanes, &seg.sections, Then::KeyAdd);
            self.lane_planes = lanes;
        }
        if let Some(set) = target.set {
            self.hold_terms(set, self.term_need(seg));
            // The set's tile degrees and term counter cleared (the reconstruction reads a
            // tile's layers up to its degree only, which the gathers mark).
            let stride = degree_stride(self.plane, self.per * 8, ch);
            let degrees = Kind::Degrees {
                offset: (set * stride) as u64 * 4,
                bytes: stride as u64 * 4,
            };
            ops.push(Op::new(degrees, 0, [0; 3], 0, 0));
            // Planes parsed from pairs whose blocks fit the dense plane together go in
            // batches: a parse and a gather each over the batch's planes at once (the
            // plane `workgroup_id.z`), each plane at its own place in the dense plane and
            // in one slot of the ring of masks. On a GPU every step costs a latency of
            // about 17–24 µs whatever its work, and a 2048² segment's bubble planes were
            // two steps each.
            // (The batch's vector is the GPU state's, kept between segments: planning a
            // segment allocates nothing once the player runs.)
            let mut batch = std::mem::take(&mut self.batch);
            batch.clear();
            // Planes decoded as coded go in batches of their own (`Gpu::lane_batches`).
            let mut lanes = std::mem::take(&mut self.lane_planes);
            lanes.clear();
            for (i, span) in seg.planes.iter().enumerate().skip(seg.bubbles) {
                let n = (i - seg.bubbles) as u32;
                let layer = set * self.set_layers + n;
                // Term k = n / channels + 2 of plane n % channels, whose tiles' degrees
                // its jobs mark.
                let (term, p) = (n / ch + 2, n % ch);
                let base = set * stride + p * self.tile_count;
                let counter = set * stride + ch * self.tile_count;
                let alone = parts(span.blocks, self.part) > 1;
                for job in self.part_jobs(span, layer) {
                    let job = Job {
                        term,
                        base,
                        counter,
                        ..job
                    };
                    let blocks = job.hi - job.lo.min(job.hi);
                    if blocks == 0 {
                        continue;
                    }
                    if span.lanes.is_some() {
                        lanes.push((job, *span));
                        continue;
                    }
                    if !alone {
                        batch.push(job);
                        continue;
                    }
                    let job = self.mask_slot(ops, job, &mut ring);
                    self.parse_ops(ops, job, 0);
                    let units = (blocks as u64, 64);
                    let groups = blocks.div_ceil(64);
                    self.sliced(ops, Kind::BubbleGather, job, groups, set, units);
                }
            }
            self.lane_batches(ops, &mut lanes, &seg.sections, Then::Gather(set));
            self.lane_planes = lanes;
            self.batches(ops, &mut batch, set, &mut ring);
            self.batch = batch;
        }
        let slices = ops
            .iter()
            .map(|o| o.slice as u64 + JOB_STRIDE)
            .max()
            .unwrap_or(0);
        if slices > self.slices.size() {
            self.slices = slice_buffer(&self.device, grown(slices) / JOB_STRIDE + 1);
            self.bind_decode();
        }
        // Each step costs its work by the adapter's weights, and on a GPU its latency too:
        // the barrier before it and the filling and draining of the chip
        // ([`DecodeShape::step_cost`]).
        for op in ops.iter_mut() {
            op.cost = (op.units * op.kind.weight(&self.shape.weights) as u64).div_ceil(4)
                + self.shape.step_cost;
        }
        // (A dispatch binds BATCH_PLANES jobs from its own: room for them after the last.)
        let jobs = self.job_bytes.len() as u64;
        let room = jobs + JOB_BINDING - JOB_STRIDE;
        if room > self.jobs.size() {
            self.jobs = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("vbim decode jobs"),
                size: grown(room),
                // (STORAGE: the lane passes' job, `DecodeShape::lane_job_storage`.)
                usage: wgpu::BufferUsages::UNIFORM
                    | wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            self.bind_decode();
        }
        words + jobs
    }

    /// Records `ops` (a run of a planned decode, in order) into `enc`; `seg` is the box
    /// the decode was planned from, needed while the upload is among them.
    pub fn record(&self, enc: &mut wgpu::CommandEncoder, ops: &[Op], seg: Option<&SegmentData>) {
        let mut i = 0;
        while i < ops.len() {
            match ops[i].kind {
                Kind::Upload => {
                    // The jobs, through `Queue::write_buffer` (they land at the queue's next
                    // submission: the one that carries `enc`).
                    self.queue.write_buffer(&self.jobs, 0, &self.job_bytes);
                    self.upload(enc, seg);
                }
                Kind::Clear { bytes } => enc.clear_buffer(&self.masks, 0, Some(bytes)),
                Kind::Degrees { offset, bytes } => {
                    enc.clear_buffer(&self.degrees, offset, Some(bytes))
                }
                _ => {
                    // A run of dispatches: one compute pass (the time since the last mark,
                    // the clears and the pass change, goes to its first mark).
                    let mut pass = enc.begin_compute_pass(&Default::default());
                    self.mark(&mut pass, PASS_CHANGES);
                    while i < ops.len() && ops[i].dispatches() {
                        self.dispatch(&mut pass, &ops[i]);
                        i += 1;
                    }
                    continue;
                }
            }
            i += 1;
        }
    }

    /// The segment's streams into the stream buffer.
    fn upload(&self, enc: &mut wgpu::CommandEncoder, seg: Option<&SegmentData>) {
        match seg.map(|s| (&s.staged, &s.data)) {
            // Written into a staging buffer by the decoder thread: a copy on the GPU, no
            // bytes through this thread.
            Some((Some(staged), _)) => {
                enc.copy_buffer_to_buffer(&staged.buffer, 0, &self.words, 0, staged.bytes)
            }
            Some((None, data)) => self.write_words(data),
            None => debug_assert!(false, "an upload without its box"),
        }
    }

    /// Plans and records the whole decode of `seg` at once: its keyframe steps (the head
    /// packed into slot 0 before the last one) and, with `bubbles`, its bubble planes
    /// into set 0. For tests and `vbim bench decode --gpu`.
    /// Returns each dispatch's pass and work in the pass's own unit, in the order they
    /// are recorded (and marked, [`Gpu::mark`]).
    #[cfg(any(test, feature = "bench"))]
    pub fn decode(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        seg: &SegmentData,
        bubbles: bool,
    ) -> Vec<(&'static str, u64)> {
        let target = Target {
            pack_first: None,
            pack_before_last: Some(0),
            set: bubbles.then_some(0),
        };
        let mut ops = Vec::new();
        self.plan_decode(seg, target, &mut ops);
        self.record(enc, &ops, Some(seg));
        ops.iter()
            .filter_map(|o| o.kind.label().map(|l| (l, o.units)))
            .collect()
    }

    fn dispatch(&self, pass: &mut wgpu::ComputePass, op: &Op) {
        let key = self.key_groups.get(op.channel as usize);
        let (pipeline, group) = match op.kind {
            Kind::Lane(which) => return self.dispatch_lanes(pass, op, which),
            Kind::ParseWide => (&self.parse_wide, self.parse_group.as_ref()),
            Kind::Parse => (&self.parse, self.parse_group.as_ref()),
            Kind::KeyAdd => (&self.key_add, key),
            Kind::KeyPack => (&self.key_pack, self.pack_group.as_ref()),
            Kind::BubbleGather => (
                &self.bubble_gather,
                self.bubble_groups.get(op.channel as usize),
            ),
            Kind::Upload | Kind::Clear { .. } | Kind::Degrees { .. } => return,
        };
        let Some(label) = op.kind.label() else {
            return;
        };
        let group = group.expect("made at creation");
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, group, &[op.job, op.slice]);
        let [x, y, z] = op.groups;
        if x > 0 && y > 0 && z > 0 {
            pass.dispatch_workgroups(x, y, z);
        }
        self.mark(pass, label);
    }

    /// A job with the plane's geometry and nothing else.
    fn base_job(&self) -> Job {
        Job {
            split: 1,
            groups_x: GROUPS_X,
            blocks_x: self.plane[0] / 8,
            per: self.per,
            tiles_x: self.tiles_x,
            ..Job::default()
        }
    }

    /// The jobs of a plane's parts (not yet pushed): blocks [lo, hi) each.
    fn part_jobs(
        &self,
        span: &crate::coded::PlaneSpan,
        layer: u32,
    ) -> impl Iterator<Item = Job> + 'static {
        let (part, blocks) = (self.part, span.blocks);
        let base = Job {
            step: span.step,
            layer,
            stream: span.stream,
            entries: span.entries,
            count: span.count,
            blocks: span.blocks,
            members: span.members,
            member_count: span.member_count,
            size: self.plane,
            ..self.base_job()
        };
        (0..parts(blocks, part)).map(move |k| {
            let lo = k * part;
            Job {
                lo,
                hi: (lo + part).min(blocks),
                ..base
            }
        })
    }

    /// `job` with the slot of the ring of masks its part's parse fills and its block pass
    /// reads: the next one, the whole ring cleared first when `*ring` has come round to
    /// the first. (Planes decoded as coded take the lanes' dense plane instead:
    /// [`Gpu::lane_batches`].)
    pub(super) fn mask_slot(&self, ops: &mut Vec<Op>, job: Job, ring: &mut u32) -> Job {
        if *ring == 0 {
            ops.push(Op::clear(self.masks.size(), 0));
        }
        let slot = *ring;
        *ring = (*ring + 1) % self.mask_slots;
        let at = slot as u64 * slot_bytes(self.part);
        Job {
            masks_at: (at / 4) as u32,
            sets_at: ((at + groups_offset(self.part)) / 4) as u32,
            ..job
        }
    }

    /// The part of `job` parsed into the dense plane from its entry points, its masks and
    /// sets into the job's slot of the ring (cleared before: [`Gpu::mask_slot`]). (The
    /// coefficients themselves need no clearing: only those whose mask bit the parse sets
    /// are ever read.)
    fn parse_ops(&mut self, ops: &mut Vec<Op>, job: Job, channel: u32) {
        // An invocation per piece, 64 to a workgroup; or a workgroup per piece.
        let (kind, groups, per_group) = match self.shape.wide_parse {
            false => (Kind::Parse, job.count.div_ceil(64), 64),
            true => (Kind::ParseWide, job.count, 1),
        };
        let units = (job.count as u64, per_group);
        self.sliced_by(ops, kind, job, (groups, PARSE_SPAN), channel, units);
    }

    /// The keyframe block pass (`key_add`) over `blocks` blocks of `job`: a workgroup per
    /// group of [`GROUP_BLOCKS`], or [`DecodeShape::group_split`] workgroups per group.
    pub(super) fn key_add_pass(&mut self, ops: &mut Vec<Op>, job: Job, blocks: u32, channel: u32) {
        // Split only as far as the pass needs to fill a large GPU: on an H100 splitting in
        // 8 took a 512² segment's `key_add` from 0.33 to 0.09 ms, and a 4096² one's from
        // 0.45 to 0.97 ms, where 4096 groups of 64 blocks already fill it.
        let whole = blocks.div_ceil(GROUP_BLOCKS);
        let split = FILL_GROUPS
            .div_ceil(whole.max(1))
            .next_power_of_two()
            .min(self.shape.group_split);
        let job = Job { split, ..job };
        let units = (blocks as u64, (GROUP_BLOCKS / split) as u64);
        self.sliced(ops, Kind::KeyAdd, job, whole * split, channel, units);
    }

    /// `groups` workgroups of a pass over `job`, in slices of [`SLICE_GROUPS`] times the
    /// slice span ([`Gpu::set_decode_shape`]), each a dispatch that binds its slice's
    /// first workgroup. The pass costs `units` blocks in all, `per_group` in each whole
    /// workgroup.
    #[allow(clippy::too_many_arguments)]
    fn sliced(
        &mut self,
        ops: &mut Vec<Op>,
        kind: Kind,
        job: Job,
        groups: u32,
        channel: u32,
        units: (u64, u64),
    ) {
        self.sliced_by(ops, kind, job, (groups, 1), channel, units);
    }

    /// [`Gpu::sliced`] with slices at least `span` times as long (slice k binds the
    /// slices buffer's entry k · its span · the slice span). A pass whose workgroups cost
    /// less than [`FULL_GROUP`] gets slices as many times longer (up to
    /// [`MAX_SLICE_GROUPS`]), so that each slice records about the same work: on a GPU
    /// a step costs about 16 µs of latency whatever its work, and a 4096² segment's
    /// keyframe packs (a unit of work a sixteenth of a region) took 72 of its 240 steps.
    fn sliced_by(
        &mut self,
        ops: &mut Vec<Op>,
        kind: Kind,
        job: Job,
        (groups, span): (u32, u32),
        channel: u32,
        (units, per_group): (u64, u64),
    ) {
        let at = self.push_job(job);
        let plane = |_: &Job| (groups, units);
        let one = std::slice::from_ref(&job);
        self.sliced_batch(ops, kind, at, one, plane, (span, per_group), channel);
    }

    /// [`Gpu::sliced_by`] over `jobs`, pushed one after another from `at`, one a plane:
    /// `plane` gives each one's workgroups and units; a dispatch covers its slice of each
    /// plane (`workgroup_id.z`), the workgroups past a plane's own doing nothing.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn sliced_batch(
        &mut self,
        ops: &mut Vec<Op>,
        kind: Kind,
        at: u32,
        jobs: &[Job],
        plane: impl Fn(&Job) -> (u32, u64),
        (span, per_group): (u32, u64),
        channel: u32,
    ) {
        let span = span.max(self.cheap_span(kind, per_group)) * self.slice_span;
        let size = span * SLICE_GROUPS;
        let groups = jobs.iter().map(|j| plane(j).0).max().unwrap_or(0);
        let z = jobs.len() as u32;
        for k in 0..groups.div_ceil(size) {
            let from = k * size;
            let n = (groups - from).min(size);
            let work = jobs
                .iter()
                .map(|j| {
                    let (g, units) = plane(j);
                    let mine = g.saturating_sub(from).min(n) as u64 * per_group;
                    mine.min(units.saturating_sub(from as u64 * per_group))
                })
                .sum();
            ops.push(Op::new(kind, at, [n, 1, z], channel, work).in_slice(k * span));
        }
    }

    /// How many slices one dispatch of `kind` may cover for its work to stay within a
    /// slice of workgroups of [`FULL_GROUP`] each, when each workgroup records `per_group`
    /// units; never so many that a dispatch covers more than [`MAX_SLICE_GROUPS`].
    fn cheap_span(&self, kind: Kind, per_group: u64) -> u32 {
        let w = &self.shape.weights;
        let own = (per_group * kind.weight(w) as u64).max(1);
        let most = MAX_SLICE_GROUPS / (SLICE_GROUPS * self.slice_span);
        (FULL_GROUP / own).clamp(1, most.max(1) as u64) as u32
    }

    /// A timestamp after what `pass` recorded so far (`vbim bench decode --gpu`), where
    /// the device has them; nothing otherwise.
    #[inline]
    pub(super) fn mark(&self, pass: &mut wgpu::ComputePass, label: &'static str) {
        #[cfg(feature = "bench")]
        if let Some(m) = &self.marks {
            m.mark(pass, label);
        }
        #[cfg(not(feature = "bench"))]
        let _ = (pass, label);
    }

    /// Appends `job` to the jobs of the decode being planned; returns its offset.
    fn push_job(&mut self, job: Job) -> u32 {
        // The passes over one part share its job (first slices start at workgroup 0):
        // one upload of it, not one per pass.
        let job = bytemuck::bytes_of(&job);
        if let Some(last) = self.job_bytes.len().checked_sub(JOB_STRIDE as usize) {
            if self.job_bytes[last..last + job.len()] == *job {
                return last as u32;
            }
        }
        self.append_job(job)
    }

    /// Appends `jobs` (a [`Job`]'s or a lanes job's), one after another [`JOB_STRIDE`]
    /// apart (a batch's, which its dispatches read by `workgroup_id.z`); returns the
    /// first's offset.
    pub(super) fn push_jobs<T: bytemuck::Pod>(&mut self, jobs: &[T]) -> u32 {
        let at = self.job_bytes.len() as u32;
        for job in jobs {
            self.append_job(bytemuck::bytes_of(job));
        }
        at
    }

    /// Appends a job's bytes, padded to [`JOB_STRIDE`]; returns its offset.
    fn append_job(&mut self, job: &[u8]) -> u32 {
        let at = self.job_bytes.len();
        self.job_bytes.extend_from_slice(job);
        self.job_bytes.resize(at + JOB_STRIDE as usize, 0);
        at as u32
    }

    /// Uploads `data` into the stream buffer from the CPU (a box filled by a decoder
    /// without a device).
    fn write_words(&self, data: &Coded) {
        if !data.words.is_empty() {
            self.queue
                .write_buffer(&self.words, 0, bytemuck::cast_slice(&data.words));
        }
    }
}
