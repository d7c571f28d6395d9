//! What the GPU holds, as bookkeeping tested without a GPU: which keyframes are the
//! chain's head and the one before it, which segment the bubble planes hold, and what to do with
//! an arriving segment. `gpu` records the passes a decision asks for.
//!
//! The GPU builds a segment's keyframes and decodes its bubble planes in the frame that
//! first shows it, in the same submission as the reconstruction, so one bubble set and
//! two keyframes are enough: the head of the chain, K_{s+1}, in f32 (the next predicted
//! keyframe is built on it in place), and the one before it, K_s, in 16 bits with a range
//! per region (only the display reads it). Building K_{s+2} first packs K_{s+1} into the
//! 16-bit slot, then adds the residual onto the head. A segment that arrives too late to
//! show still has its keyframes built (the next one starts from its K_{s+1}); the segment
//! on screen then loses its keyframes, and the display keeps the last image it showed
//! until the next segment arrives.

use crate::decoder::KeyStep;
use crate::time::{MediaTime, ONE_FRAME};

/// Largest number of bubble planes (7 terms of 3 planes; `reconstruct.wgsl` holds their
/// steps in 6 vec4s).
pub(crate) const MAX_BUBBLE_PLANES: usize = 24;

/// The two resident keyframes: the chain's head (f32) and the one before it (16-bit).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct KeySlots {
    head: Option<usize>,
    previous: Option<usize>,
}

impl KeySlots {
    /// Forgets what the slots hold (after a seek).
    pub fn clear(&mut self) {
        *self = KeySlots::default();
    }

    /// Builds `steps` in turn, each on the head, the head before it becoming the previous
    /// keyframe. `Err(k)`: predicted keyframe `k` does not follow the head (the GPU's
    /// chain is not the decoder's); nothing changes then.
    pub fn build(&mut self, steps: &[KeyStep]) -> Result<(), usize> {
        let mut t = *self;
        for st in steps {
            let follows = st.number > 0 && t.head == Some(st.number - 1);
            if !st.intra && !follows {
                return Err(st.number);
            }
            t.previous = t.head;
            t.head = Some(st.number);
        }
        *self = t;
        Ok(())
    }

    /// Whether keyframes `k0` (the previous one) and `k1` (the head) are resident.
    pub fn holds(&self, [k0, k1]: [usize; 2]) -> bool {
        self.previous == Some(k0) && self.head == Some(k1)
    }
}

/// The segment whose bubble planes the GPU holds, with its absolute media range
/// (pass · N + frames). Its K_s and K_{s+1} are the resident keyframes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Resident {
    pub index: usize,
    pub start: MediaTime,
    pub end: MediaTime,
    pub layers: usize,
    /// Quantiser step of each bubble plane.
    pub steps: [f32; MAX_BUBBLE_PLANES],
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
            steps: [0.0; MAX_BUBBLE_PLANES],
        }
    }

    #[test]
    fn a_chain_ends_with_the_segments_keyframes() {
        let mut k = KeySlots::default();
        // After a seek into segment 3: intra keyframe 1, then 2, 3 and the closing 4.
        let steps = [
            step(1, true),
            step(2, false),
            step(3, false),
            step(4, false),
        ];
        k.build(&steps).unwrap();
        assert!(k.holds([3, 4]));
        // The next segment carries only its closing keyframe, built on the head.
        k.build(&[step(5, false)]).unwrap();
        assert!(k.holds([4, 5]));
        assert!(!k.holds([3, 4]));
    }

    #[test]
    fn a_predicted_keyframe_that_does_not_follow_the_head_changes_nothing() {
        let mut k = KeySlots::default();
        k.build(&[step(0, true), step(1, false)]).unwrap();
        let before = k;
        assert_eq!(k.build(&[step(3, false)]), Err(3));
        assert_eq!(k, before);
        assert_eq!(KeySlots::default().build(&[step(0, false)]), Err(0));
        // A loop: the last segment closes on keyframe 0 (intra), segment 0 follows.
        k.build(&[step(0, true)]).unwrap();
        assert!(k.holds([1, 0]));
        k.build(&[step(1, false)]).unwrap();
        assert!(k.holds([0, 1]));
        // After a seek nothing is held: the first intra keyframe alone shows nothing.
        k.clear();
        k.build(&[step(4, true)]).unwrap();
        assert!(!k.holds([3, 4]));
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
