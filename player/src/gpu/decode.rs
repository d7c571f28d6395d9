//! The segment decode: a segment's keyframe steps and bubble planes, recorded as compute
//! passes over the coefficient streams (`job.wgsl`, `parse.wgsl`, `decode.wgsl`).

use super::job::{Job, JOB_STRIDE};
use super::plan::*;
use super::Gpu;
use crate::coded::Coded;
use crate::decoder::SegmentData;

impl Gpu {
    /// Whether a segment's coefficients fit one storage binding of this device.
    pub fn fits(&self, seg: &SegmentData) -> Result<(), String> {
        let limit = self.device.limits().max_storage_buffer_binding_size;
        let need = seg.bytes();
        if need > limit {
            return Err(format!(
                "segment {}: {need} bytes of coefficients, more than one storage binding holds ({limit})",
                seg.index
            ));
        }
        Ok(())
    }

    /// Blocks the dense plane holds (a plane of more goes in parts).
    pub fn part(&self) -> u32 {
        self.part
    }

    /// Records the decode of `seg` into `enc`: its keyframe steps, built in turn on the
    /// head (the head packed into the previous keyframe before the last step), then
    /// (with `bubbles`) its bubble planes. Each plane is parsed into the dense plane, part
    /// by part, and read from there. The streams go through `Queue::write_buffer`, which
    /// takes effect at the queue's next submission: the one that carries `enc`. It
    /// uploads [`upload_bytes`].
    pub fn decode(&mut self, enc: &mut wgpu::CommandEncoder, seg: &SegmentData, bubbles: bool) {
        let ch = self.channels as usize;
        let words = seg.bytes();
        let planes = decoded_planes(seg, bubbles);
        let jobs = job_bytes(seg, bubbles, self.part);
        if words > self.words.size() || jobs > self.jobs.size() {
            use wgpu::BufferUsages as B;
            if words > self.words.size() {
                self.words = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("vbim coefficient streams"),
                    size: grown(words),
                    usage: B::STORAGE | B::COPY_DST,
                    mapped_at_creation: false,
                });
            }
            if jobs > self.jobs.size() {
                self.jobs = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("vbim decode jobs"),
                    size: grown(jobs),
                    usage: B::UNIFORM | B::COPY_DST,
                    mapped_at_creation: false,
                });
            }
            self.bind_decode();
        }
        match &seg.staged {
            // Written into a staging buffer by the decoder thread: a copy on the GPU, no
            // bytes through this thread.
            Some(staged) => {
                enc.copy_buffer_to_buffer(&staged.buffer, 0, &self.words, 0, staged.bytes)
            }
            None => self.write_words(&seg.data),
        }
        let (pw, ph) = (self.plane[0], self.plane[1]);
        // Each plane's first job; its parts follow.
        let mut first_job = std::mem::take(&mut self.first_job);
        first_job.clear();
        self.job_bytes.clear();
        for (i, span) in seg.planes[..planes].iter().enumerate() {
            first_job.push(self.job_bytes.len() as u64);
            let n = parts(span.blocks, self.part);
            for k in 0..n {
                let lo = k * self.part;
                self.push_job(Job {
                    step: span.step,
                    // A bubble plane's layer; a keyframe plane's channel, the layer of the
                    // previous keyframe `key_pack` writes (the head's passes write the
                    // layer their binding views).
                    layer: if i < seg.bubbles {
                        i % ch
                    } else {
                        i - seg.bubbles
                    } as u32,
                    stream: span.stream,
                    entries: span.entries,
                    count: span.count,
                    blocks: span.blocks,
                    lo,
                    hi: (lo + self.part).min(span.blocks),
                    members: span.members,
                    member_count: span.member_count,
                    groups_x: GROUPS_X,
                    blocks_x: pw / 8,
                    per: self.per,
                    tiles_x: self.tiles_x,
                    size: [pw, ph],
                    pad: [0; 2],
                });
            }
        }
        let zero_job = self.job_bytes.len() as u64;
        let bubble_layers = ((seg.layers.saturating_sub(2)) * ch) as u32;
        self.push_job(Job {
            layer: bubble_layers,
            size: [pw / 2, ph],
            ..Job::default()
        });
        self.queue.write_buffer(&self.jobs, 0, &self.job_bytes);
        let dispatch = |pass: &mut wgpu::ComputePass, count: u32| {
            if count > 0 {
                pass.dispatch_workgroups(count.min(GROUPS_X), count.div_ceil(GROUPS_X), 1);
            }
        };
        // The parts of plane `plane`: (job offset, blocks in the part, entry points).
        let jobs_of = &first_job;
        let part_jobs = |plane: usize| {
            let span = &seg.planes[plane];
            let part = self.part;
            (0..parts(span.blocks, part)).map(move |k| {
                let lo = k * part;
                let blocks = (lo + part).min(span.blocks) - lo.min(span.blocks);
                let job = jobs_of[plane] + k as u64 * JOB_STRIDE;
                (job as u32, blocks, span.count)
            })
        };
        let bubble_group = self.bubble_group.as_ref().expect("made at creation");
        let last = seg.steps.len().saturating_sub(1);
        for (n, st) in seg.steps.iter().enumerate() {
            for p in 0..ch {
                let plane = st.plane + p;
                for (k, (job, blocks, entries)) in part_jobs(plane).enumerate() {
                    let mut pass = self.parse_part(enc, job, blocks, entries);
                    pass.set_bind_group(0, &self.key_groups[p], &[job]);
                    if k == 0 && n == last {
                        // The head becomes the previous keyframe (the earlier steps' heads
                        // are never shown).
                        // (One invocation per region, 64 to a workgroup.)
                        pass.set_pipeline(&self.key_pack);
                        let [rx, ry] = self.regions;
                        pass.dispatch_workgroups((rx * ry).div_ceil(64), 1, 1);
                        self.mark(&mut pass, "key_pack");
                    }
                    if k == 0 && st.intra {
                        pass.set_pipeline(&self.key_zero);
                        pass.dispatch_workgroups(pw.div_ceil(8), ph.div_ceil(8), 1);
                        self.mark(&mut pass, "key_zero");
                    }
                    // A predicted keyframe is added onto the head: the keyframe it follows.
                    pass.set_pipeline(&self.key_add);
                    dispatch(&mut pass, blocks.div_ceil(GROUP_BLOCKS));
                    self.mark(&mut pass, "key_add");
                }
            }
        }
        if bubbles {
            enc.clear_buffer(&self.bounds, 0, None);
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                self.mark(&mut pass, "clears and pass changes");
                pass.set_bind_group(0, bubble_group, &[zero_job as u32]);
                pass.set_pipeline(&self.bubble_zero);
                if bubble_layers > 0 {
                    pass.dispatch_workgroups((pw / 2).div_ceil(8), ph.div_ceil(8), bubble_layers);
                }
                self.mark(&mut pass, "bubble_zero");
            }
            for plane in seg.bubbles..planes {
                // The bound first (over every part), then the blocks, parsed again if the
                // plane went in parts.
                let whole = parts(seg.planes[plane].blocks, self.part) == 1;
                for (job, blocks, entries) in part_jobs(plane) {
                    if blocks == 0 {
                        continue;
                    }
                    let mut pass = self.parse_part(enc, job, blocks, entries);
                    pass.set_bind_group(0, bubble_group, &[job]);
                    pass.set_pipeline(&self.bubble_bound);
                    dispatch(&mut pass, blocks.div_ceil(64));
                    self.mark(&mut pass, "bubble_bound");
                    if whole {
                        pass.set_pipeline(&self.bubble_write);
                        dispatch(&mut pass, blocks.div_ceil(GROUP_BLOCKS));
                        self.mark(&mut pass, "bubble_write");
                    }
                }
                if whole {
                    continue;
                }
                for (job, blocks, entries) in part_jobs(plane) {
                    let mut pass = self.parse_part(enc, job, blocks, entries);
                    pass.set_bind_group(0, bubble_group, &[job]);
                    pass.set_pipeline(&self.bubble_write);
                    dispatch(&mut pass, blocks.div_ceil(GROUP_BLOCKS));
                    self.mark(&mut pass, "bubble_write");
                }
            }
        }
        self.first_job = first_job;
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

    /// Clears the masks and sets of the dense plane's first `blocks` blocks, then parses a
    /// part (job at `job`) into it from its `entries` entry points: a pass that goes on
    /// with the passes that read it. (The coefficients themselves need no clearing: only
    /// those whose mask bit the parse sets are ever read.)
    fn parse_part<'e>(
        &self,
        enc: &'e mut wgpu::CommandEncoder,
        job: u32,
        blocks: u32,
        entries: u32,
    ) -> wgpu::ComputePass<'e> {
        let sets = groups_offset(self.part) + group_bytes(blocks);
        enc.clear_buffer(&self.masks, 0, Some(sets));
        let mut pass = enc.begin_compute_pass(&Default::default());
        self.mark(&mut pass, "clears and pass changes");
        pass.set_pipeline(&self.parse);
        let group = self.parse_group.as_ref().expect("made at creation");
        pass.set_bind_group(0, group, &[job]);
        let groups = entries.div_ceil(64);
        pass.dispatch_workgroups(groups.min(GROUPS_X), groups.div_ceil(GROUPS_X), 1);
        self.mark(&mut pass, "parse");
        pass
    }

    fn push_job(&mut self, job: Job) {
        let at = self.job_bytes.len();
        self.job_bytes.extend_from_slice(bytemuck::bytes_of(&job));
        self.job_bytes.resize(at + JOB_STRIDE as usize, 0);
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
