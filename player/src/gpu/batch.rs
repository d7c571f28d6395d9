//! A segment's bubble planes in batches: those whose member blocks fit the dense plane
//! together are parsed and gathered by one dispatch of each pass (the plane
//! `workgroup_id.z`, each with its own job, at its own place in the dense plane and in one
//! slot of the ring of masks). On a GPU every step of a decode costs a latency of about
//! 17–24 µs whatever its work (BENCHMARKS.md, "On a hardware GPU"), and a 2048²
//! segment's bubble planes were two steps each.

use super::decode::PARSE_SPAN;
use super::job::{Job, BATCH_PLANES};
use super::ops::{Kind, Op};
use super::plan::GROUP_BLOCKS;
use super::Gpu;

impl Gpu {
    /// The bubble planes' parts in `planes` (each in one part), in batches that fit the
    /// dense plane together: the largest left first, then each one after it that still
    /// fits (first fit by decreasing size: at 512² and 4096² the cloudy days' planes are
    /// a large one and smaller ones, which in their order took a batch more a segment).
    pub(super) fn batches(
        &mut self,
        ops: &mut Vec<Op>,
        planes: &mut [Job],
        set: u32,
        ring: &mut u32,
    ) {
        planes.sort_unstable_by_key(|j| std::cmp::Reverse(j.hi - j.lo));
        let mut batch = std::mem::take(&mut self.batch_out);
        // The planes taken, a bit each, 64 at a time (a segment has at most channels ×
        // degree of them, 21).
        for planes in planes.chunks(64) {
            let all = u64::MAX >> (64 - planes.len());
            let mut taken = 0u64;
            while taken != all {
                batch.clear();
                let mut end = 0;
                let first = taken.trailing_ones() as usize;
                for (k, job) in planes.iter().enumerate().skip(first) {
                    let blocks = job.hi - job.lo;
                    let fits = end as u64 + blocks as u64 <= self.part as u64;
                    if taken >> k & 1 == 0 && fits && batch.len() < BATCH_PLANES as usize {
                        batch.push(*job);
                        taken |= 1 << k;
                        end = batch_end(end, blocks);
                    }
                }
                self.batch_ops(ops, &mut batch, set, ring);
            }
        }
        self.batch_out = batch;
    }

    /// A batch of bubble planes' parts ([`Gpu::batches`]) parsed into one slot of the ring
    /// and the dense plane, each at its place there (`Job::dense_at`), and gathered into
    /// set `set`: a dispatch of each pass covers them all, one job a plane.
    fn batch_ops(&mut self, ops: &mut Vec<Op>, batch: &mut [Job], set: u32, ring: &mut u32) {
        let Some(&first) = batch.first() else {
            return;
        };
        let slot = self.mask_slot(ops, first, false, ring);
        let mut dense = 0;
        for job in batch.iter_mut() {
            job.dense_at = dense;
            job.masks_at = slot.masks_at + 2 * dense;
            job.sets_at = slot.sets_at + dense / 32;
            dense = batch_end(dense, job.hi - job.lo);
        }
        let at = self.push_jobs(batch);
        let (kind, per_group) = match self.shape.wide_parse {
            false => (Kind::Parse, 64),
            true => (Kind::ParseWide, 1),
        };
        let parse = |j: &Job| (j.count.div_ceil(per_group as u32), j.count as u64);
        self.sliced_batch(ops, kind, at, batch, parse, (PARSE_SPAN, per_group), 0);
        let gather = |j: &Job| ((j.hi - j.lo).div_ceil(64), (j.hi - j.lo) as u64);
        self.sliced_batch(ops, Kind::BubbleGather, at, batch, gather, (1, 64), set);
    }
}

/// Where the next plane of a batch starts in the dense plane after one of `blocks` blocks
/// at `at`: at a multiple of 64 blocks, so that a group of 64 (a block pass's workgroup,
/// a word pair of the sets) is one plane's.
fn batch_end(at: u32, blocks: u32) -> u32 {
    (at + blocks).next_multiple_of(GROUP_BLOCKS)
}
