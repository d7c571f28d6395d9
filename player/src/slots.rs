//! What the GPU holds, as bookkeeping tested without a GPU: which keyframe each of the
//! two keyframe slots holds, which segment the bubble planes hold, and what to do with
//! an arriving segment. `gpu.rs` records the passes a decision asks for.
//!
//! The GPU builds a segment's keyframes and decodes its bubble planes in the frame that
//! first shows it, in the same submission as the reconstruction, so one bubble set and
//! two keyframe slots are enough: K_{s+2} is built from K_{s+1} in the slot K_s held,
//! once segment s is over. A segment that arrives too late to show still has its
//! keyframes built (the next one starts from its K_{s+1}); the segment on screen then
//! loses its keyframes, and the display keeps the last image it showed until the next
//! segment arrives.

use crate::decoder::KeyStep;
use crate::time::{MediaTime, ONE_FRAME};

/// Largest number of bubble planes (7 terms of 3 planes; `decode.wgsl` and
/// `reconstruct.wgsl` hold their scales in 6 vec4s).
pub(crate) const MAX_BUBBLE_PLANES: usize = 24;

/// The two keyframe slots: the keyframe each holds, and which was built last.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct KeySlots {
    held: [Option<usize>; 2],
    latest: usize,
}

impl KeySlots {
    /// Forgets what the slots hold (after a seek).
    pub fn clear(&mut self) {
        *self = KeySlots::default();
    }

    /// The slot the next keyframe is built in: never the one built last, which a
    /// predicted keyframe starts from.
    pub fn next_slot(&self) -> usize {
        1 - self.latest
    }

    /// Builds `steps` in turn, alternating slots. `Err(k)`: predicted keyframe `k` does
    /// not follow the keyframe built last (the GPU's chain is not the decoder's); nothing
    /// changes then.
    pub fn build(&mut self, steps: &[KeyStep]) -> Result<(), usize> {
        let mut t = *self;
        for st in steps {
            let follows = st.number > 0 && t.held[t.latest] == Some(st.number - 1);
            if !st.intra && !follows {
                return Err(st.number);
            }
            t.latest = 1 - t.latest;
            t.held[t.latest] = Some(st.number);
        }
        *self = t;
        Ok(())
    }

    /// The slots holding keyframes `k0` and `k1`, if both are resident and `k1` was
    /// built last.
    pub fn slots_of(&self, [k0, k1]: [usize; 2]) -> Option<[usize; 2]> {
        let (last, other) = (self.latest, 1 - self.latest);
        (self.held[last] == Some(k1) && self.held[other] == Some(k0)).then_some([other, last])
    }
}

/// The segment whose bubble planes the GPU holds, with its absolute media range
/// (pass · N + frames) and the keyframe slots of its K_s and K_{s+1}.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Resident {
    pub index: usize,
    pub start: MediaTime,
    pub end: MediaTime,
    pub layers: usize,
    pub keys: [usize; 2],
    /// Scale of each bubble plane.
    pub scales: [f32; MAX_BUBBLE_PLANES],
}

/// What to do with an arrived segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Placement {
    /// The segment on screen is still playing and this one comes after it: wait.
    NotYet,
    /// Build its keyframes and decode its bubbles: it goes on screen.
    Show,
    /// Already in the past: build its keyframes only (the next segment needs them).
    Drop,
}

/// Decides what an arrival covering `[start, end)` gets at media time `pos`, with
/// `resident` on the GPU, in a sequence of `n` media units per pass.
pub(crate) fn place(
    resident: Option<&Resident>,
    (start, end): (MediaTime, MediaTime),
    pos: MediaTime,
    n: MediaTime,
    looping: bool,
) -> Placement {
    // The last segment of a sequence that does not loop stays shown once it is over.
    let last_of_still = !looping && end >= n - ONE_FRAME;
    if end <= pos && !last_of_still {
        return Placement::Drop;
    }
    match resident {
        Some(r) if r.end > pos && start > pos && r.start <= start => Placement::NotYet,
        _ => Placement::Show,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const F: MediaTime = ONE_FRAME;
    const N: MediaTime = 1000 * F;

    fn step(number: usize, intra: bool) -> KeyStep {
        KeyStep {
            number,
            intra,
            plane: 0,
        }
    }

    fn resident(s: u64) -> Resident {
        Resident {
            index: s as usize,
            start: s * 10 * F,
            end: (s + 1) * 10 * F,
            layers: 4,
            keys: [0, 1],
            scales: [0.0; MAX_BUBBLE_PLANES],
        }
    }

    #[test]
    fn a_chain_alternates_slots_and_ends_with_the_segments_keyframes() {
        let mut k = KeySlots::default();
        // After a seek into segment 3: intra keyframe 1, then 2, 3 and the closing 4.
        let steps = [
            step(1, true),
            step(2, false),
            step(3, false),
            step(4, false),
        ];
        k.build(&steps).unwrap();
        let [a, b] = k.slots_of([3, 4]).expect("K_3 and K_4 resident");
        assert_ne!(a, b);
        // The next segment carries only its closing keyframe, built where K_3 was.
        assert_eq!(k.next_slot(), a);
        k.build(&[step(5, false)]).unwrap();
        assert_eq!(k.slots_of([4, 5]), Some([b, a]));
        assert_eq!(k.slots_of([3, 4]), None);
    }

    #[test]
    fn a_predicted_keyframe_that_does_not_follow_the_last_one_changes_nothing() {
        let mut k = KeySlots::default();
        k.build(&[step(0, true), step(1, false)]).unwrap();
        let before = k;
        assert_eq!(k.build(&[step(3, false)]), Err(3));
        assert_eq!(k, before);
        assert_eq!(KeySlots::default().build(&[step(0, false)]), Err(0));
        // A loop: the last segment closes on keyframe 0 (intra), segment 0 follows.
        k.build(&[step(0, true)]).unwrap();
        k.build(&[step(1, false)]).unwrap();
        assert_eq!(k.slots_of([0, 1]).map(|s| s[0] != s[1]), Some(true));
    }

    #[test]
    fn arrivals_wait_show_or_drop() {
        let r = resident(1);
        let seg = |s: u64| (s * 10 * F, (s + 1) * 10 * F);
        // Segment 2 while 1 plays: wait; once 1 is over: show.
        assert_eq!(place(Some(&r), seg(2), 15 * F, N, true), Placement::NotYet);
        assert_eq!(place(Some(&r), seg(2), 20 * F, N, true), Placement::Show);
        // Nothing resident: show at once, even ahead of time.
        assert_eq!(place(None, seg(2), 15 * F, N, true), Placement::Show);
        // Already over: drop.
        assert_eq!(place(Some(&r), seg(2), 31 * F, N, true), Placement::Drop);
        // The last segment of a still sequence is never in the past.
        let n = 30 * F;
        assert_eq!(place(Some(&r), seg(2), 40 * F, n, false), Placement::Show);
        // A segment before the resident one (a seek backwards is a new generation, so
        // only the next pass's segments can start before it): shown.
        assert_eq!(place(Some(&r), seg(0), 5 * F, N, true), Placement::Show);
    }
}
