//! Decoding a segment a slice at a time while the one before it plays: which slot and
//! set it fills, how much of it each frame records under the budget, and showing it once
//! it is done and due.

use std::io::{Read, Seek};

use super::Player;
use crate::decoder::SegmentData;
use crate::gpu::{Op, Target, BUBBLE_SETS, KEY_SLOTS};
use crate::slots::{place, Placement, Resident, MAX_BUBBLE_PLANES};
use crate::time::MediaTime;

/// A segment being decoded into the GPU's spare slot and set, a slice at a time.
pub(super) struct Decoding {
    /// The box, until its upload is recorded.
    data: Option<Box<SegmentData>>,
    ops: Vec<Op>,
    /// Ops chosen for a frame so far.
    next: usize,
    /// The segment it will show (`None`: keyframes only).
    show: Option<Resident>,
    /// Its absolute media range.
    range: (MediaTime, MediaTime),
    /// The keyframes it builds, and the slot it packs into with the keyframe that goes
    /// there, once its ops are recorded.
    steps: Vec<crate::decoder::KeyStep>,
    packs: Option<(u32, usize)>,
    /// The ops up to the last that packs (the pack is done once they are chosen).
    pack_end: usize,
    /// The cost of the ops not yet chosen, blocks.
    left: u64,
    /// The cost of all its ops, blocks.
    total: u64,
    /// Work allowed but not yet spent, blocks: an op is chosen once the frames' shares
    /// add up to its cost, so that a decode spread thinly (a slow day, many frames before
    /// it is due) records an op every few frames, not one every frame.
    credit: u64,
    /// It arrived before it was due: a frame that finds it unfinished is the budget's.
    early: bool,
}

impl<R: Read + Seek + Send + 'static> Player<R> {
    /// Starts decoding an arrived segment into what the display does not read (see
    /// `slots.rs`): its keyframes onto the head, the head packed first into a slot the
    /// display does not read (the segment on screen reads its K_{s+1} there from then
    /// on), its bubble planes into the other set unless it is already in the past.
    /// Returns the bytes its decode uploads.
    pub(super) fn start_decode(
        &mut self,
        b: Box<SegmentData>,
        pos: MediaTime,
        n: MediaTime,
    ) -> u64 {
        let base = b.pass as u64 * n;
        let range = (
            base + ((b.start as u64) << 32),
            base + ((b.end as u64) << 32),
        );
        if let Err(e) = self.gpu.fits(&b) {
            self.totals.damaged += 1;
            self.totals.last_error = Some(e);
            self.pipeline.give_back(b);
            return 0;
        }
        if let Err(k) = self.keys.check(&b.steps) {
            // The GPU's keyframes are not the ones this segment's chain continues (it
            // follows one that never reached the GPU): read again from an intra keyframe.
            self.totals.last_error = Some(format!(
                "keyframe {k} does not follow the keyframes on the GPU: re-reading from an intra keyframe"
            ));
            self.pipeline.give_back(b);
            self.seek(pos);
            return 0;
        }
        self.known_end = range.1;
        let past = place(None, range, pos, n, self.header.looping) == Placement::Drop;
        // A segment whose own data was damaged cannot be shown; its keyframes are built.
        let mut show = !past && !b.keys_only;
        let k0 = b.keys[0];
        let steady =
            b.steps.len() == 1 && (self.keys.head() == Some(k0) || self.keys.slot_of(k0).is_some());
        let mut target = Target::default();
        let (mut slot0, mut packs) = (0, None);
        if steady {
            match self.keys.slot_of(k0) {
                Some(s) => slot0 = s,
                None => {
                    // The slots the segment on screen reads; with both taken it gives way
                    // (a segment past its end, which the display holds).
                    let keys = &self.keys;
                    let reads =
                        |r: &Resident, s: u32| r.slot0 == s || keys.slot_of(r.keys[1]) == Some(s);
                    let free =
                        (0..KEY_SLOTS).find(|&s| !self.resident.is_some_and(|r| reads(&r, s)));
                    let f = free.unwrap_or_else(|| {
                        self.resident = None;
                        0
                    });
                    target.pack_first = Some(f);
                    (slot0, packs) = (f, Some((f, k0)));
                }
            }
        } else {
            // A chain (after a seek, a drop or damage) takes the slots the display read;
            // its K_s is packed before its last step.
            self.resident = None;
            let before_last = b.steps.len().checked_sub(2).map(|i| b.steps[i].number);
            if before_last == Some(k0) {
                target.pack_before_last = Some(0);
                packs = Some((0, k0));
            } else {
                show = false;
            }
        }
        let set = self.resident.map_or(0, |r| (r.set + 1) % BUBBLE_SETS);
        if show {
            target.set = Some(set);
        }
        let mut ops = std::mem::take(&mut self.spare.0);
        let bytes = self.gpu.plan_decode(&b, target, &mut ops);
        let mut key_steps = std::mem::take(&mut self.spare.1);
        key_steps.clear();
        key_steps.extend_from_slice(&b.steps);
        let mut steps = [0f32; MAX_BUBBLE_PLANES];
        for (s, p) in steps.iter_mut().zip(&b.planes[b.bubbles..]) {
            *s = p.step;
        }
        let shows = show.then_some(Resident {
            index: b.index,
            keys: b.keys,
            slot0,
            set,
            start: range.0,
            end: range.1,
            layers: b.layers,
            steps,
        });
        let early =
            place(self.resident.as_ref(), range, pos, n, self.header.looping) == Placement::NotYet;
        let pack_end = ops.iter().rposition(|o| o.packs).map_or(0, |i| i + 1);
        let left = ops.iter().map(|o| o.cost).sum();
        self.decoding = Some(Decoding {
            early,
            pack_end,
            left,
            total: left,
            credit: 0,
            steps: key_steps,
            data: Some(b),
            ops,
            next: 0,
            show: shows,
            range,
            packs,
        });
        self.last_eval = None;
        bytes
    }

    /// Gives a finished or abandoned decode's box back and keeps its buffers (no
    /// allocation per segment).
    pub(super) fn retire(&mut self, d: Decoding) {
        if let Some(b) = d.data {
            self.pipeline.give_back(b);
        }
        self.spare = (d.ops, d.steps);
    }

    /// Chooses the decode ops this frame records (into `frame_ops`) under the budget, and
    /// shows the decoded segment once it is done and due. `per_frame` is the media time
    /// one displayed frame advances. Returns the work chosen, in blocks.
    pub(super) fn step_decode(
        &mut self,
        pos: MediaTime,
        per_frame: MediaTime,
        n: MediaTime,
    ) -> u64 {
        self.frame_ops.clear();
        let looping = self.header.looping;
        let Some(d) = self.decoding.as_mut() else {
            return 0;
        };
        let needed = place(self.resident.as_ref(), d.range, pos, n, looping) != Placement::NotYet;
        let remaining = d.left;
        let allowance = match self.budget {
            Some(b) => b,
            None if needed => u64::MAX,
            // Spread evenly over the frames left before it is due but the last, which is
            // kept as a margin for the display's rate wandering. The frames left are the
            // time left in frame times rounded to the nearest: a display position a hair
            // off the media grid (8 frames and 1e-9 left, or 1e-9 short) must not make
            // the count jump by one between frames, which left the last frame before the
            // margin twice the others' share on lavapipe.
            None => {
                let pf = per_frame.max(1);
                let frames = (d.range.0.saturating_sub(pos) + pf / 2) / pf;
                remaining.div_ceil(frames.saturating_sub(1).max(1))
            }
        };
        // With a budget, the work not recorded carries over as credit, up to the budget
        // (spreading needs none: each frame's share is taken from what is left).
        if let Some(b) = self.budget {
            d.credit = d.credit.saturating_add(allowance).min(b);
        }
        let (start, mut work) = (d.next, 0u64);
        while d.next < d.ops.len() {
            let cost = d.ops[d.next].cost;
            match self.budget {
                // Spreading: the steps nearest the frame's share, at least one. Steps
                // are coarse (a slice of a pass); recording only those within the
                // share left a frame idle whenever the next step was larger than what
                // remained of it, and the frame after with two shares. The shares that
                // follow are taken from what is left, so an overshoot evens out.
                None if work > 0 && work + cost / 2 > allowance => break,
                None => {}
                Some(b) if cost > d.credit => {
                    // One step costs more than the budget: it runs alone, first in a
                    // frame (whose credit is then the whole budget), and is reported.
                    if cost <= b || work > 0 {
                        break;
                    }
                    self.totals.over_budget += 1;
                    self.totals.last_error = Some(format!(
                        "segment {}: one step of its decode costs {cost} blocks, more than the budget of {allowance} per frame: the budget is too small for this stream",
                        d.show.map_or(0, |r| r.index)
                    ));
                }
                Some(_) => {}
            }
            work += cost;
            d.credit = d.credit.saturating_sub(cost);
            d.next += 1;
        }
        d.left -= work;
        let chosen = &d.ops[start..d.next];
        self.frame_ops.extend_from_slice(chosen);
        if chosen.iter().any(|o| o.needs_box()) {
            self.frame_box = d.data.take();
        }
        // Once its last pack is recorded, the slot holds the keyframe (the display reads
        // it there from this frame on: the head changes after it).
        if let Some((slot, k)) = d.packs {
            if d.next >= d.pack_end {
                self.keys.packed(slot, k);
                d.packs = None;
                self.last_eval = None;
            }
        }
        let done = d.next == d.ops.len();
        if done && start < d.next {
            // Its last op is recorded this frame: the head is its last keyframe.
            self.keys.built(&d.steps);
        }
        if needed && done {
            let d = self.decoding.take().expect("decoding");
            match d.show {
                Some(r) if place(None, d.range, pos, n, looping) != Placement::Drop => {
                    self.resident = Some(r);
                    self.totals.segments_uploaded += 1;
                }
                _ => self.totals.segments_dropped += 1,
            }
            self.last_eval = None;
            self.retire(d);
        } else if !done
            && d.early
            && needed
            && self.budget.is_some_and(|b| {
                // The budget's fault only if a segment's own length of frames at the budget
                // could not have decoded it; one that arrived late (a stall, a seek's
                // rebuild before it) is the read's, and the frames' states show it.
                let frames = (d.range.1 - d.range.0) / per_frame.max(1);
                d.total > b.saturating_mul(frames.saturating_sub(1))
            })
        {
            self.totals.budget_late += 1;
            self.totals.last_error = Some(format!(
                "a segment was due with {} blocks of its decode left under a budget of {} per frame: the budget is too small for this stream at this display rate",
                d.left, allowance
            ));
        }
        work
    }
}
