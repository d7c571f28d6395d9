//! The GPU slot table: which segment each of the two bubble slots holds, which keyframe
//! each keyframe slot holds, and where an arriving segment goes. Pure bookkeeping, so it
//! is tested without a GPU; `gpu.rs` records the copies a [`Placement`] asks for.
//!
//! The rules: the slot on screen is never written (double buffering); a keyframe shared
//! by consecutive segments (K_{s+1} closes s and opens s + 1) is uploaded once; a segment
//! that arrives too late is dropped, but its closing keyframe is still kept, because the
//! decoder does not stage it again for the next segment.

use crate::gpu::{UploadPlan, KEY_SLOTS};
use crate::time::{MediaTime, ONE_FRAME};

/// A segment resident in a bubble slot, with its absolute media range (pass · N + frames).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Resident {
    pub index: usize,
    pub start: MediaTime,
    pub end: MediaTime,
    pub layers: usize,
    /// Keyframe slots holding its K_s and K_{s+1}.
    pub keys: [usize; 2],
}

/// A decoded segment waiting for a slot.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Arrival {
    pub index: usize,
    pub start: MediaTime,
    pub end: MediaTime,
    pub layers: usize,
    /// Keyframe numbers of K_s and K_{s+1}.
    pub keyframes: [usize; 2],
    /// Whether K_s is in the staging buffer (else it must already be on the GPU).
    pub k0_staged: bool,
}

/// What to do with an arrival.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Placement {
    /// The slot not on screen holds a segment still to play: offer it again next frame.
    NotYet,
    /// Upload it into the slot not on screen, as the plan says.
    Upload(UploadPlan),
    /// Dropped (already in the past, or its K_s is gone). `Some`: upload its closing
    /// keyframe into the keyframe slot the plan names.
    Dropped(Option<UploadPlan>),
}

/// The bubble slots, the keyframe slots and which bubble slot is on screen.
#[derive(Clone, Debug, Default)]
pub(crate) struct SlotTable {
    slots: [Option<Resident>; 2],
    shown: Option<usize>,
    /// Which keyframe (by number) each keyframe slot holds.
    keys: [Option<usize>; KEY_SLOTS],
}

impl SlotTable {
    /// Forgets everything (after a seek).
    pub fn clear(&mut self) {
        *self = SlotTable::default();
    }

    /// The segment in bubble slot `s`.
    pub fn slot(&self, s: usize) -> Option<Resident> {
        self.slots[s]
    }

    /// The bubble slot on screen.
    pub fn shown(&self) -> Option<usize> {
        self.shown
    }

    /// The bubble slot whose segment covers media time `pos`, which goes on screen.
    pub fn show_covering(&mut self, pos: MediaTime) -> Option<usize> {
        let s = (0..2).find(|&s| self.slots[s].is_some_and(|r| r.start <= pos && pos < r.end));
        if s.is_some() {
            self.shown = s;
        }
        s
    }

    /// The end of the latest segment resident (0 when none is).
    pub fn known_end(&self) -> MediaTime {
        self.slots
            .iter()
            .flatten()
            .map(|r| r.end)
            .max()
            .unwrap_or(0)
    }

    /// Decides where arrival `a` goes at media time `pos`, in a sequence of `n` media
    /// units per pass, and records it as resident if it is uploaded.
    pub fn place(&mut self, a: &Arrival, pos: MediaTime, n: MediaTime, looping: bool) -> Placement {
        let r = Resident {
            index: a.index,
            start: a.start,
            end: a.end,
            layers: a.layers,
            keys: [0, 0],
        };
        let free = self.shown.map_or(0, |s| 1 - s);
        // The last segment of a sequence that does not loop stays shown once it is over.
        let last_of_still = !looping && r.end >= n - ONE_FRAME;
        let past = r.end <= pos && !last_of_still;
        if !past {
            if self.slots[free]
                .is_some_and(|old| old.end > pos && r.start > pos && old.start <= r.start)
            {
                return Placement::NotYet;
            }
            let keep = [self.slots[1 - free], None];
            if let Some((mut plan, keys)) = self.place_keys(a, keep) {
                plan.bubbles = Some(free);
                self.slots[free] = Some(Resident { keys, ..r });
                return Placement::Upload(plan);
            }
            // Its K_s is neither staged nor on the GPU (only if a closing keyframe could
            // not be kept, below): drop it like a late one; the next segment plays.
        }
        let mut placed = self.place_closing(a);
        if placed.is_none() {
            // Both bubble slots' keyframes are protected: forget the one not on screen if
            // it is over (it can never be shown again).
            let other = self.shown.map_or(1, |s| 1 - s);
            if self.slots[other].is_some_and(|o| o.end <= pos) {
                self.slots[other] = None;
                placed = self.place_closing(a);
            }
        }
        Placement::Dropped(placed.filter(|p| p.key1.is_some()))
    }

    /// Keyframe slots for a dropped segment's closing keyframe, keeping both bubble
    /// slots' keyframes.
    fn place_closing(&mut self, a: &Arrival) -> Option<UploadPlan> {
        let keep = [self.slots[0], self.slots[1]];
        let (slot, copy) = self.key_slot_for(a.keyframes[1], keep, None)?;
        self.keys[slot] = Some(a.keyframes[1]);
        Some(UploadPlan {
            key0: None,
            key1: copy,
            bubbles: None,
        })
    }

    /// Keyframe slots for `a`'s K_s and K_{s+1}: where they already are, or slots that no
    /// segment in `keep` uses. `None` if K_s is neither staged nor resident.
    fn place_keys(
        &mut self,
        a: &Arrival,
        keep: [Option<Resident>; 2],
    ) -> Option<(UploadPlan, [usize; 2])> {
        let (k0, copy0) = self.key_slot_for(a.keyframes[0], keep, None)?;
        if copy0.is_some() && !a.k0_staged {
            return None;
        }
        let (k1, copy1) = self.key_slot_for(a.keyframes[1], keep, Some(k0))?;
        self.keys[k0] = Some(a.keyframes[0]);
        self.keys[k1] = Some(a.keyframes[1]);
        let plan = UploadPlan {
            key0: copy0,
            key1: copy1,
            bubbles: None,
        };
        Some((plan, [k0, k1]))
    }

    /// The keyframe slot for keyframe `k`: the one that holds it already (nothing to
    /// copy), or a free one (see [`Self::free_key_slot`]) to copy it into — `(slot, copy)`.
    fn key_slot_for(
        &self,
        k: usize,
        keep: [Option<Resident>; 2],
        avoid: Option<usize>,
    ) -> Option<(usize, Option<usize>)> {
        match self.keys.iter().position(|&x| x == Some(k)) {
            Some(s) => Some((s, None)),
            None => self.free_key_slot(keep, avoid).map(|s| (s, Some(s))),
        }
    }

    /// A keyframe slot that no segment in `keep` uses, other than `avoid`: an empty one
    /// first.
    fn free_key_slot(&self, keep: [Option<Resident>; 2], avoid: Option<usize>) -> Option<usize> {
        let usable =
            |s: usize| Some(s) != avoid && !keep.iter().flatten().any(|r| r.keys.contains(&s));
        (0..KEY_SLOTS)
            .find(|&s| usable(s) && self.keys[s].is_none())
            .or_else(|| (0..KEY_SLOTS).find(|&s| usable(s)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const F: MediaTime = ONE_FRAME;

    /// Segment `s` of a sequence cut every 10 frames, keyframe s opening it.
    fn seg(s: usize, staged: bool) -> Arrival {
        Arrival {
            index: s,
            start: (s as u64 * 10) * F,
            end: (s as u64 * 10 + 10) * F,
            layers: 4,
            keyframes: [s, s + 1],
            k0_staged: staged,
        }
    }

    /// The keyframe numbers a resident segment's keyframe slots hold.
    fn keyframes_of(t: &SlotTable, r: Resident) -> [Option<usize>; 2] {
        [t.keys[r.keys[0]], t.keys[r.keys[1]]]
    }

    const N: MediaTime = 1000 * F;

    #[test]
    fn the_first_segment_uploads_both_keyframes_into_slot_zero() {
        let mut t = SlotTable::default();
        let p = t.place(&seg(0, true), 0, N, true);
        assert_eq!(
            p,
            Placement::Upload(UploadPlan {
                key0: Some(0),
                key1: Some(1),
                bubbles: Some(0),
            })
        );
        let r = t.slot(0).unwrap();
        assert_eq!(keyframes_of(&t, r), [Some(0), Some(1)]);
    }

    #[test]
    fn a_shared_keyframe_is_uploaded_once_and_the_shown_slot_is_never_written() {
        let mut t = SlotTable::default();
        t.place(&seg(0, true), 0, N, true);
        assert_eq!(t.show_covering(0), Some(0));
        // Segment 1 shares keyframe 1 with segment 0, which is on screen.
        let Placement::Upload(p) = t.place(&seg(1, false), 0, N, true) else {
            panic!("segment 1 should be uploaded");
        };
        assert_eq!(p.key0, None, "K_1 is already resident");
        assert_eq!(p.bubbles, Some(1), "never the slot on screen");
        let k1 = p.key1.unwrap();
        assert!(
            !t.slot(0).unwrap().keys.contains(&k1),
            "K_2 overwrote a shown keyframe"
        );
        assert_eq!(keyframes_of(&t, t.slot(1).unwrap()), [Some(1), Some(2)]);
        assert_eq!(keyframes_of(&t, t.slot(0).unwrap()), [Some(0), Some(1)]);
    }

    #[test]
    fn a_segment_still_to_come_in_the_free_slot_makes_the_next_one_wait() {
        let mut t = SlotTable::default();
        t.place(&seg(0, true), 0, N, true);
        t.show_covering(0);
        t.place(&seg(1, false), 0, N, true);
        // Segment 1 has not played yet: segment 2 must not take its slot.
        assert_eq!(t.place(&seg(2, false), 5 * F, N, true), Placement::NotYet);
        // Once segment 1 is on screen, segment 2 goes into slot 0.
        assert_eq!(t.show_covering(12 * F), Some(1));
        let Placement::Upload(p) = t.place(&seg(2, false), 12 * F, N, true) else {
            panic!("segment 2 should be uploaded");
        };
        assert_eq!(p.bubbles, Some(0));
    }

    #[test]
    fn a_late_segment_is_dropped_but_its_closing_keyframe_is_kept() {
        let mut t = SlotTable::default();
        t.place(&seg(0, true), 0, N, true);
        t.show_covering(0);
        // Segment 1 arrives when it is already over.
        let p = t.place(&seg(1, false), 25 * F, N, true);
        let Placement::Dropped(Some(plan)) = p else {
            panic!("expected a dropped segment that keeps its keyframe, got {p:?}");
        };
        assert_eq!((plan.key0, plan.bubbles), (None, None));
        assert_eq!(t.keys[plan.key1.unwrap()], Some(2));
        assert!(t.slot(1).is_none());
        // Segment 2 then finds its K_s resident without staging it.
        let Placement::Upload(p) = t.place(&seg(2, false), 25 * F, N, true) else {
            panic!("segment 2 should be uploaded");
        };
        assert_eq!(p.key0, None);
    }

    #[test]
    fn a_dropped_segment_whose_keyframe_is_resident_uploads_nothing() {
        let mut t = SlotTable::default();
        t.place(&seg(0, true), 0, N, true);
        t.show_covering(0);
        // Segment 0 arriving (again) when it is over: its closing keyframe is resident.
        assert_eq!(
            t.place(&seg(0, true), 15 * F, N, true),
            Placement::Dropped(None)
        );
    }

    #[test]
    fn a_segment_whose_opening_keyframe_is_gone_is_dropped() {
        let mut t = SlotTable::default();
        t.place(&seg(0, true), 0, N, true);
        t.show_covering(0);
        // Segment 5 needs keyframe 5, which is neither resident nor staged.
        let p = t.place(&seg(5, false), 0, N, true);
        assert!(matches!(p, Placement::Dropped(_)), "{p:?}");
        assert!(t.slot(1).is_none());
    }

    #[test]
    fn the_last_segment_of_a_still_sequence_is_never_in_the_past() {
        let mut t = SlotTable::default();
        let n = 20 * F;
        t.place(&seg(0, true), 0, n, false);
        t.show_covering(0);
        // At the very end of a sequence that does not loop, its last segment still goes up.
        let p = t.place(&seg(1, false), n - F, n, false);
        assert!(matches!(p, Placement::Upload(_)), "{p:?}");
    }

    #[test]
    fn a_long_day_played_in_order_never_runs_out_of_keyframe_slots() {
        let mut t = SlotTable::default();
        for s in 0..200usize {
            let pos = (s as u64 * 10) * F;
            // Segment s arrives while s − 1 is on screen (segment 0: before anything is).
            let at = pos.saturating_sub(F);
            let p = t.place(&seg(s, s == 0), at, N, true);
            assert!(matches!(p, Placement::Upload(_)), "segment {s}: {p:?}");
            let shown = t
                .show_covering(pos)
                .expect("the segment just uploaded covers it");
            let r = t.slot(shown).unwrap();
            assert_eq!(r.index, s);
            assert_eq!(keyframes_of(&t, r), [Some(s), Some(s + 1)]);
        }
        assert!(t.known_end() == 2000 * F);
        t.clear();
        assert_eq!((t.shown(), t.known_end()), (None, 0));
    }
}
