//! What the GPU holds, as bookkeeping tested without a GPU: which keyframes are the
//! chain's head and in the 16-bit slots, which segment is on screen, and what to do with
//! an arriving segment. `gpu` records the passes a decision asks for.
//!
//! The next segment decodes while the one on screen plays, a slice at a time, so the GPU
//! holds two bubble sets and two 16-bit keyframe slots beside the f32 head of the chain.
//! The segment on screen reads K_s from a slot and K_{s+1} from the head; the next
//! segment's decode first packs the head into the other slot (the display reads it there
//! from then on), then adds its residual onto the head to build K_{s+2}, and decodes its
//! bubble planes into the other set. Showing it is then only a change of parameters. A
//! segment that arrives too late to show still has its keyframes built (the next one
//! starts from its K_{s+1}); a chain rebuilt after a seek or damage takes the slots the
//! display used, and the display keeps the last image it showed until it is done.

use crate::decoder::KeyStep;
use crate::time::{MediaTime, ONE_FRAME};

/// Largest number of bubble planes (7 terms of 3 planes: `reconstruct.wgsl` holds 9
/// weights, two keyframes' and 7 bubble terms', and their steps in 6 vec4s).
pub(crate) const MAX_BUBBLE_PLANES: usize = 24;

/// The resident keyframes: the chain's head (f32, built in place) and the 16-bit slots.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct KeySlots {
    head: Option<usize>,
    slots: [Option<usize>; 2],
}

impl KeySlots {
    /// Forgets what the slots hold (after a seek).
    pub fn clear(&mut self) {
        *self = KeySlots::default();
    }

    /// The head's keyframe.
    pub fn head(&self) -> Option<usize> {
        self.head
    }

    /// The slot holding keyframe `k`, if one does.
    pub fn slot_of(&self, k: usize) -> Option<u32> {
        self.slots
            .iter()
            .position(|&s| s == Some(k))
            .map(|s| s as u32)
    }

    /// Whether `steps` can be built in turn on the head: `Err(k)` where predicted keyframe
    /// `k` does not follow the keyframe before it (the GPU's chain is not the decoder's).
    pub fn check(&self, steps: &[KeyStep]) -> Result<(), usize> {
        let mut head = self.head;
        for st in steps {
            let follows = st.number > 0 && head == Some(st.number - 1);
            if !st.intra && !follows {
                return Err(st.number);
            }
            head = Some(st.number);
        }
        Ok(())
    }

    /// `steps` were built: the head is the last.
    pub fn built(&mut self, steps: &[KeyStep]) {
        if let Some(st) = steps.last() {
            self.head = Some(st.number);
        }
    }

    /// Slot `slot` now holds keyframe `k`.
    pub fn packed(&mut self, slot: u32, k: usize) {
        self.slots[slot as usize] = Some(k);
    }
}

/// The segment the GPU can show, with its absolute media range (pass · N + frames): K_s
/// in slot `slot0`, K_{s+1} (keyframe `keys[1]`) in the head or a slot, its bubble planes
/// in set `set`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Resident {
    pub index: usize,
    pub keys: [usize; 2],
    pub slot0: u32,
    pub set: u32,
    pub start: MediaTime,
    pub end: MediaTime,
    pub layers: usize,
    /// Quantiser step of each bubble plane (the reconstruction scales a block's 16-bit
    /// terms by it).
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
            keys: [s as usize, s as usize + 1],
            slot0: 0,
            set: 0,
            start: s * 10 * F,
            end: (s + 1) * 10 * F,
            layers: 4,
            steps: [0.0; MAX_BUBBLE_PLANES],
        }
    }

    #[test]
    fn a_chain_is_checked_against_the_head_and_slots_remember_what_they_hold() {
        let mut k = KeySlots::default();
        // After a seek into segment 3: intra keyframe 1, then 2, 3 and the closing 4.
        let steps = [
            step(1, true),
            step(2, false),
            step(3, false),
            step(4, false),
        ];
        assert_eq!(k.check(&steps), Ok(()));
        k.built(&steps);
        assert_eq!(k.head(), Some(4));
        k.packed(0, 3);
        assert_eq!(k.slot_of(3), Some(0));
        assert_eq!(k.slot_of(4), None);
        // The next segment carries only its closing keyframe, built on the head.
        assert_eq!(k.check(&[step(5, false)]), Ok(()));
        // One that skips a keyframe does not follow; nothing changes.
        let before = k;
        assert_eq!(k.check(&[step(6, false)]), Err(6));
        assert_eq!(k, before);
        assert_eq!(KeySlots::default().check(&[step(0, false)]), Err(0));
        // A loop: the last segment closes on keyframe 0 (intra).
        assert_eq!(k.check(&[step(0, true)]), Ok(()));
        k.clear();
        assert_eq!(k.head(), None);
        assert_eq!(k.slot_of(3), None);
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
