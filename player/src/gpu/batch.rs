//! A segment's bubble planes in batches: those whose member blocks fit the dense plane
//! together are parsed and gathered by one dispatch of each pass (the plane
//! `workgroup_id.z`, each with its own job, at its own place in the dense plane and in one
//! slot of the ring of masks). On a GPU every step of a decode costs a latency of about
//! 17–24 µs whatever its work (BENCHMARKS.md, "On a hardware GPU"), and a 2048²
//! segment's bubble planes were two steps each.

use super::decode::PARSE_SPAN;
use super::job::{Job, BATCH_PLANES};
use super::lanes::LaneMember;
use super::ops::{Kind, Op};
use super::plan::GROUP_BLOCKS;
use super::Gpu;
use crate::coded::{PlaneSpan, SectionSpan};

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
        let slot = self.mask_slot(ops, first, ring);
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

/// What follows a batch of planes decoded as coded (`Gpu::lane_batches`).
#[derive(Clone, Copy, Debug)]
pub(super) enum Then {
    /// Keyframe planes: each added onto the head (`key_add`; its job's layer is its
    /// channel).
    KeyAdd,
    /// Bubble planes: their terms gathered into this set, one dispatch for the batch.
    Gather(u32),
}

impl Gpu {
    /// The planes decoded as coded (`lanes.wgsl`) in `planes` (each whole, in one part; a
    /// keyframe step's, or a segment's bubble planes), in batches of one section's planes
    /// that fit the lanes' dense plane and scratch together, first fit by decreasing size:
    /// each batch is decoded by one dispatch of each lane pass ([`Gpu::lane_ops`]), each
    /// plane at its own place in the dense plane, and then added onto the head or
    /// gathered into a set (`then`). On a GPU a lane pass lasts as long as its longest
    /// lane, and a segment's planes, decoded one after another, summed theirs.
    pub(super) fn lane_batches(
        &mut self,
        ops: &mut Vec<Op>,
        planes: &mut [(Job, PlaneSpan)],
        sections: &[SectionSpan],
        then: Then,
    ) {
        let Some(plan) = self.lanes.as_ref().map(|l| l.plan) else {
            // (The decoder thread hands planes on as coded only where the GPU has their
            // decode: the same decode shape, `DecodeShape::lanes`.)
            debug_assert!(planes.is_empty(), "planes as coded and no lanes decode");
            return;
        };
        let lanes = |s: &PlaneSpan| s.lanes.unwrap_or_default();
        planes.sort_unstable_by_key(|(j, s)| (lanes(s).section, std::cmp::Reverse(j.hi - j.lo)));
        let mut batch = std::mem::take(&mut self.batch_out);
        let mut members = std::mem::take(&mut self.lane_members);
        let size = |k: usize| {
            let (job, span) = &planes[k];
            let l = lanes(span);
            (job.hi - job.lo, l.count as u64, l.section)
        };
        lane_batches(planes.len(), size, plan.room(), |picked| {
            batch.clear();
            members.clear();
            let mut end = 0;
            for &k in picked {
                let (job, span) = planes[k];
                batch.push(job);
                members.push(LaneMember {
                    span,
                    lanes: lanes(&span),
                    dense_at: end,
                });
                end = batch_end(end, job.hi - job.lo);
            }
            // The lanes' dense plane: its masks from the mask buffer's start, its sets
            // after them (a stream's planes are all decoded as coded or all parsed, so no
            // parse's slot of the ring is in use), which the lanes' first pass clears.
            let sets_at = (plan.sets_offset() / 4) as u32;
            for (job, m) in batch.iter_mut().zip(&members) {
                job.dense_at = m.dense_at;
                job.masks_at = 2 * m.dense_at;
                job.sets_at = sets_at + m.dense_at / 32;
            }
            match then {
                Then::KeyAdd => {
                    self.lane_ops(ops, &members, sections, batch[0].layer);
                    for job in &batch {
                        self.key_add_pass(ops, *job, job.hi - job.lo, job.layer);
                    }
                }
                Then::Gather(set) => {
                    self.lane_ops(ops, &members, sections, 0);
                    let at = self.push_jobs(&batch);
                    let gather = |j: &Job| ((j.hi - j.lo).div_ceil(64), (j.hi - j.lo) as u64);
                    self.sliced_batch(ops, Kind::BubbleGather, at, &batch, gather, (1, 64), set);
                }
            }
        });
        self.batch_out = batch;
        self.lane_members = members;
    }
}

/// The batches of planes decoded as coded, a keyframe's or a segment's bubble planes
/// (`Gpu::lane_batches`): planes `0..n`, largest first within a section, plane k of
/// `size(k)` = (blocks, rANS states, section), go in batches of one section's planes whose blocks fit `room.0`
/// blocks of the dense plane together (each from a multiple of 64) and whose states fit
/// `room.1` of the scratch, at most `BATCH_PLANES` (16) a batch, first fit; `batch` gets each
/// batch's planes. A plane that fits no batch alone goes alone (the player makes none).
/// Allocates nothing. (`vbim bench decode` packs a file's planes with it too.)
pub fn lane_batches(
    n: usize,
    size: impl Fn(usize) -> (u32, u64, u32),
    (blocks, states): (u32, u64),
    mut batch: impl FnMut(&[usize]),
) {
    let mut picked = [0usize; BATCH_PLANES as usize];
    // The planes taken, a bit each, 64 at a time.
    for from in (0..n).step_by(64) {
        let to = (from + 64).min(n);
        let all = u64::MAX >> (64 - (to - from));
        let mut taken = 0u64;
        while taken != all {
            let first = taken.trailing_ones() as usize;
            let (_, _, section) = size(from + first);
            let (mut count, mut end, mut used) = (0, 0u64, 0u64);
            for k in first..to - from {
                let (b, s, of) = size(from + k);
                let fits = end + b as u64 <= blocks as u64 && used + s <= states;
                if taken >> k & 1 == 0 && of == section && (fits || count == 0) {
                    if count == BATCH_PLANES as usize {
                        break;
                    }
                    picked[count] = from + k;
                    count += 1;
                    taken |= 1 << k;
                    used += s;
                    end = batch_end(end as u32, b) as u64;
                }
            }
            batch(&picked[..count]);
        }
    }
}

/// Where the next plane of a batch starts in the dense plane after one of `blocks` blocks
/// at `at`: at a multiple of 64 blocks, so that a group of 64 (a block pass's workgroup,
/// a word pair of the sets) is one plane's.
fn batch_end(at: u32, blocks: u32) -> u32 {
    (at + blocks).next_multiple_of(GROUP_BLOCKS)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The batches `lane_batches` makes of planes of `sizes` in `room`.
    fn packed(sizes: &[(u32, u64, u32)], room: (u32, u64)) -> Vec<Vec<usize>> {
        let mut out = Vec::new();
        lane_batches(sizes.len(), |k| sizes[k], room, |b| out.push(b.to_vec()));
        out
    }

    #[test]
    fn lane_batches_fit_the_dense_plane_the_states_and_one_section() {
        // Blocks from multiples of 64: 200 leaves no room; 100 (to 128) and 60 share; a
        // plane of another section goes with its own.
        let sizes = [(200, 1, 0), (100, 1, 0), (60, 1, 0), (50, 1, 1), (10, 1, 1)];
        assert_eq!(packed(&sizes, (256, 10)), [vec![0], vec![1, 2], vec![3, 4]]);
        // States: two a batch.
        assert_eq!(packed(&[(1, 1, 0); 3], (256, 2)), [vec![0, 1], vec![2]]);
        // At most BATCH_PLANES planes a batch, and more than 64 planes.
        let many = packed(&[(1, 0, 0); 70], (1 << 20, 1));
        let lengths: Vec<usize> = many.iter().map(|b| b.len()).collect();
        assert_eq!(lengths, [16, 16, 16, 16, 6]);
        // A plane larger than the room goes alone.
        assert_eq!(
            packed(&[(300, 1, 0), (1, 1, 0)], (256, 10)),
            [vec![0], vec![1]]
        );
    }
}
