//! The display's clock and the stall policies: given whether the data for the target time
//! is resident, what each displayed frame shows. Pure state on integer time, so it is
//! tested without a GPU or a stream.
//!
//! - Before the first frame the player buffers (the pre-roll): nothing is shown, and the
//!   clock has not started, so buffering is not drift.
//! - When the data is late, every policy holds what is on screen. `wait` also pauses the
//!   clock there; `interpolate` and `skip` let it run on.
//! - When the data arrives, `skip` jumps to the true state; `interpolate` blends from the
//!   held image to it over the catch-up window, and the lag the data arrived with fades out
//!   with the blend.

use crate::config::Policy;
use crate::record::FrameState;
use crate::time::{media_to_ticks, ticks_to_media, MediaTime};

/// What one displayed frame shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Step {
    /// Still buffering: nothing is shown yet.
    Preroll,
    /// A frame.
    Show {
        /// What kind of frame it is.
        state: FrameState,
        /// The media time shown.
        shown: MediaTime,
        /// Blend weight of the true state (1: the true state alone).
        alpha: f32,
        /// Keep the image on screen as the blend's start before drawing (the data just
        /// arrived under `interpolate`).
        hold_first: bool,
        /// This frame starts a stall (the frame before was not late).
        new_stall: bool,
    },
}

/// The display's clock and what the policy remembers between frames.
#[derive(Clone, Debug)]
pub(crate) struct Display {
    policy: Policy,
    catch_up_ns: u64,
    /// Buffering before the first frame, ns.
    preroll_ns: u64,
    /// Playback clock at the first frame shown (the pre-roll is not drift).
    startup: u64,
    /// Clock time the `wait` policy has paused for.
    paused: u64,
    started: bool,
    /// Start of a catch-up (clock) and the lag the data arrived with.
    catch_start: Option<(u64, MediaTime)>,
    last_shown: MediaTime,
    was_missing: bool,
    /// The time the clock jumped to (`set_time`), until its data has been shown.
    jump: Option<MediaTime>,
    /// Frames stepped so far, pre-roll included.
    steps: u64,
}

impl Display {
    /// A display that buffers for `preroll_ns` before its first frame.
    pub fn new(policy: Policy, catch_up_ns: u64, preroll_ns: u64) -> Display {
        Display {
            policy,
            catch_up_ns,
            preroll_ns,
            startup: 0,
            paused: 0,
            started: false,
            catch_start: None,
            last_shown: 0,
            was_missing: false,
            jump: None,
            steps: 0,
        }
    }

    /// The policy in force.
    pub fn policy(&self) -> Policy {
        self.policy
    }

    /// Changes the policy from the next frame on.
    pub fn set_policy(&mut self, p: Policy) {
        self.policy = p;
    }

    /// Restarts the clock at zero (a jump to a new time: no pre-roll offset, no pause).
    /// Until the new time's data is resident, the screen holds the old image; `wait` pauses
    /// the clock at the new time (not at the old image's), and when the data arrives every
    /// policy cuts to it without a blend: a blend would need the clock to run, and a game
    /// that seeks while paused must still see the new time.
    pub fn restart_clock(&mut self, at: MediaTime) {
        self.paused = 0;
        self.startup = 0;
        self.jump = Some(at);
        self.catch_start = None;
    }

    /// Sets the pre-roll (before the first frame only: after it, it has no effect).
    pub fn set_preroll(&mut self, ns: u64) {
        self.preroll_ns = ns;
    }

    /// Joins a running timeline: the clock runs from now with the playback position at
    /// `position` ns at clock `ticks`, without a pre-roll; until the data for `at` (the
    /// time the data restarts for) is resident the display holds, then cuts to it.
    pub fn join(&mut self, ticks: u64, position: u64, at: MediaTime) {
        self.started = true;
        self.startup = ticks.saturating_sub(position);
        self.paused = 0;
        self.catch_start = None;
        self.jump = Some(at);
    }

    /// The playback position at clock `ticks`, ns (the clock less the start-up offset
    /// and the pauses).
    pub fn position(&self, ticks: u64) -> u64 {
        ticks
            .saturating_sub(self.startup)
            .saturating_sub(self.paused)
    }

    /// The media time shown last.
    pub fn last_shown(&self) -> MediaTime {
        self.last_shown
    }

    /// At playback clock `ticks`, at frame rate `num / den`: the target media time (what
    /// the clock asks for) and the playback position (behind it by the `wait` policy's
    /// pauses).
    pub fn clock(&self, ticks: u64, (num, den): (u32, u32)) -> (MediaTime, MediaTime) {
        let run = ticks - self.startup;
        (
            ticks_to_media(run, num, den),
            ticks_to_media(run - self.paused, num, den),
        )
    }

    /// The frame at clock `ticks` with the playback position at `pos`. `held`: `None` when
    /// the data for `pos` is resident; else the media time a stall holds (what is on
    /// screen).
    pub fn step(
        &mut self,
        ticks: u64,
        pos: MediaTime,
        held: Option<MediaTime>,
        (num, den): (u32, u32),
    ) -> Step {
        let first = self.steps == 0;
        self.steps += 1;
        if !self.started && (held.is_some() || ticks < self.preroll_ns) {
            // Start-up: the buffer model's pre-roll, and at least the first segment,
            // before the clock starts, whatever the policy. The clock then starts at the
            // start, or at the time jumped to before the first frame.
            let at = self.jump.map_or(0, |j| media_to_ticks(j, num, den));
            self.startup = ticks.saturating_sub(at);
            self.was_missing = false;
            return Step::Preroll;
        }
        self.started = true;
        let (mut state, mut shown, mut alpha) = (FrameState::Exact, pos, 1.0f32);
        let (mut hold_first, mut new_stall) = (false, false);
        match held {
            Some(held) => {
                new_stall = !self.was_missing;
                shown = held.min(pos);
                if self.policy == Policy::Wait {
                    // Pause the clock at the held time (after a jump: at the time jumped
                    // to, whose data is awaited).
                    let at = self.jump.unwrap_or(shown);
                    let run = ticks - self.startup;
                    self.paused = run - media_to_ticks(at, num, den).min(run);
                    state = FrameState::Waiting;
                } else {
                    state = FrameState::Held;
                }
                self.catch_start = None;
            }
            None => {
                if self.was_missing
                    && self.policy == Policy::Interpolate
                    && !first
                    && self.jump.is_none()
                {
                    // The data arrived: blend from the held image over the catch-up window.
                    self.catch_start = Some((ticks, pos.saturating_sub(self.last_shown)));
                    hold_first = true;
                }
                if let Some((start, lag)) = self.catch_start {
                    let a = ((ticks - start) as f64 / self.catch_up_ns.max(1) as f64).min(1.0);
                    if a >= 1.0 {
                        self.catch_start = None;
                    } else {
                        alpha = a.max(1e-3) as f32;
                        state = FrameState::CatchingUp;
                        // The lag the data arrived with fades out with the blend: a short
                        // stall leaves a short lag, however long the blend.
                        shown = pos.saturating_sub(((1.0 - a) * lag as f64) as u64);
                    }
                }
            }
        }
        if held.is_none() {
            self.jump = None;
        }
        self.was_missing = held.is_some();
        self.last_shown = shown;
        Step::Show {
            state,
            shown,
            alpha,
            hold_first,
            new_stall,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::ONE_FRAME;

    const RATE: (u32, u32) = (24, 1);
    /// Clock ticks of one media frame at 24 fps (rounded up, as a display step would be).
    const FRAME_NS: u64 = 41_666_667;

    /// Steps `d` from clock `t0` for `frames` display frames of one media frame each, with
    /// the data missing while `late(i)`; returns every step and the clock after.
    fn run(
        d: &mut Display,
        t0: u64,
        frames: u64,
        late: impl Fn(u64) -> bool,
    ) -> (Vec<(MediaTime, MediaTime, Step)>, u64) {
        let mut out = Vec::new();
        let mut t = t0;
        for i in 0..frames {
            t += FRAME_NS;
            let (wall, pos) = d.clock(t, RATE);
            let held = late(i).then(|| d.last_shown());
            out.push((wall, pos, d.step(t, pos, held, RATE)));
        }
        (out, t)
    }

    fn state(s: &Step) -> Option<FrameState> {
        match s {
            Step::Show { state, .. } => Some(*state),
            Step::Preroll => None,
        }
    }

    fn shown(s: &Step) -> MediaTime {
        match s {
            Step::Show { shown, .. } => *shown,
            Step::Preroll => 0,
        }
    }

    #[test]
    fn the_preroll_shows_nothing_and_is_not_drift() {
        let mut d = Display::new(Policy::Interpolate, 500_000_000, 200_000_000);
        let (steps, _) = run(&mut d, 0, 10, |i| i < 2);
        // Four frames inside the 200 ms pre-roll (the first two also without data).
        assert!(steps[..4].iter().all(|s| s.2 == Step::Preroll));
        // Then the clock starts from zero: the first frame shown is exact, at the start.
        let (wall, pos, first) = steps[4];
        assert_eq!(state(&first), Some(FrameState::Exact));
        assert_eq!(wall, pos);
        assert!(wall < 2 * ONE_FRAME, "pre-roll counted as drift: {wall}");
    }

    #[test]
    fn interpolate_holds_then_blends_back_and_the_lag_fades() {
        let mut d = Display::new(Policy::Interpolate, 500_000_000, 0);
        let (steps, _) = run(&mut d, 0, 60, |i| (10..20).contains(&i));
        let held: Vec<_> = steps[10..20].iter().map(|s| state(&s.2)).collect();
        assert!(held.iter().all(|s| *s == Some(FrameState::Held)));
        // Only the first late frame starts a stall.
        let stalls = steps
            .iter()
            .filter(|s| {
                matches!(
                    s.2,
                    Step::Show {
                        new_stall: true,
                        ..
                    }
                )
            })
            .count();
        assert_eq!(stalls, 1);
        // The clock ran on: the target is 20 frames on, the display held at frame ~10.
        let Step::Show {
            hold_first, alpha, ..
        } = steps[20].2
        else {
            panic!("a frame")
        };
        assert!(
            hold_first && alpha < 0.01,
            "the blend starts from the held image"
        );
        // Over the 0.5 s (12 frames) window the weight rises and what is shown catches up.
        let mut last = (0.0f32, 0u64);
        for s in &steps[21..32] {
            let Step::Show {
                state,
                alpha,
                shown,
                ..
            } = s.2
            else {
                panic!()
            };
            assert_eq!(state, FrameState::CatchingUp);
            assert!(alpha > last.0 && shown > last.1 && shown <= s.1);
            last = (alpha, shown);
        }
        assert_eq!(state(&steps[33].2), Some(FrameState::Exact));
        assert_eq!(shown(&steps[33].2), steps[33].1);
    }

    #[test]
    fn wait_pauses_the_clock_and_resumes_where_it_stopped() {
        let mut d = Display::new(Policy::Wait, 500_000_000, 0);
        let (steps, _) = run(&mut d, 0, 40, |i| (10..20).contains(&i));
        assert!(steps[10..20]
            .iter()
            .all(|s| state(&s.2) == Some(FrameState::Waiting)));
        // Playback resumes right after what was held, with the wall clock ahead by the
        // time spent waiting: drift, but nothing skipped.
        let (wall, pos, s) = steps[20];
        assert_eq!(state(&s), Some(FrameState::Exact));
        assert!(
            pos - shown(&steps[19].2) <= 2 * ONE_FRAME,
            "playback jumped"
        );
        assert!(wall - pos >= 9 * ONE_FRAME, "the clock did not pause");
    }

    #[test]
    fn skip_jumps_to_the_true_state_when_the_data_arrives() {
        let mut d = Display::new(Policy::Skip, 500_000_000, 0);
        let (steps, _) = run(&mut d, 0, 30, |i| (10..20).contains(&i));
        assert_eq!(state(&steps[15].2), Some(FrameState::Held));
        let (wall, pos, s) = steps[20];
        assert_eq!(state(&s), Some(FrameState::Exact));
        assert_eq!((shown(&s), wall), (pos, pos), "no lag left after a skip");
    }

    #[test]
    fn restarting_the_clock_forgets_pauses() {
        let mut d = Display::new(Policy::Wait, 500_000_000, 0);
        let (_, t) = run(&mut d, 0, 30, |i| (5..25).contains(&i));
        let (wall, pos) = d.clock(t, RATE);
        assert!(wall > pos);
        d.restart_clock(ticks_to_media(t, RATE.0, RATE.1));
        let (wall, pos) = d.clock(t, RATE);
        assert_eq!(wall, pos);
    }

    /// A jump (`set_time`) to a time whose data is not resident, stepped with the clock
    /// stopped (a paused game seeking): every policy holds the old image, then shows the
    /// new time exactly once its data is there, without waiting for a blend that a stopped
    /// clock would never finish.
    #[test]
    fn a_jump_with_the_clock_stopped_shows_the_new_time_under_every_policy() {
        for policy in Policy::ALL {
            let mut d = Display::new(policy, 500_000_000, 0);
            let (_, t) = run(&mut d, 0, 30, |_| false);
            let before = d.last_shown();
            let jump = 80 * FRAME_NS;
            let target = ticks_to_media(jump, RATE.0, RATE.1);
            d.restart_clock(target);
            for i in 0..10 {
                let (_, pos) = d.clock(jump, RATE);
                assert!(near(pos, target), "{policy:?}: the position is the jump's");
                let late = i < 6;
                let step = d.step(jump, pos, late.then(|| d.last_shown()), RATE);
                if late {
                    assert_eq!(shown(&step), before, "{policy:?}: the old image is held");
                } else {
                    let Step::Show {
                        state,
                        shown,
                        alpha,
                        ..
                    } = step
                    else {
                        panic!("a frame")
                    };
                    assert_eq!((state, alpha), (FrameState::Exact, 1.0), "{policy:?}");
                    assert!(near(shown, target), "{policy:?}");
                }
            }
            assert!(t < jump);
        }
    }

    /// A jump before the first frame (a game that opens a day at noon): the pre-roll waits
    /// for the new time's data, and the clock starts there.
    #[test]
    fn a_jump_before_the_first_frame_starts_the_clock_there() {
        for policy in Policy::ALL {
            let mut d = Display::new(policy, 500_000_000, 0);
            let jump = 80 * FRAME_NS;
            let target = ticks_to_media(jump, RATE.0, RATE.1);
            d.restart_clock(target);
            for i in 0..6 {
                let (_, pos) = d.clock(jump, RATE);
                assert!(near(pos, target), "{policy:?} step {i}");
                let late = i < 4;
                let step = d.step(jump, pos, late.then_some(0), RATE);
                if late {
                    assert_eq!(step, Step::Preroll);
                } else {
                    assert_eq!(state(&step), Some(FrameState::Exact), "{policy:?}");
                    assert!(near(shown(&step), target), "{policy:?}");
                }
            }
        }
    }

    /// With the clock running, `wait` pauses at the time jumped to while its data is late
    /// (not at the old image's time, which would send playback back there).
    #[test]
    fn wait_after_a_jump_pauses_at_the_new_time() {
        let mut d = Display::new(Policy::Wait, 500_000_000, 0);
        run(&mut d, 0, 30, |_| false);
        let mut t = 80 * FRAME_NS;
        let target = ticks_to_media(t, RATE.0, RATE.1);
        d.restart_clock(target);
        for i in 0..8 {
            t += FRAME_NS;
            let (_, pos) = d.clock(t, RATE);
            let step = d.step(t, pos, Some(d.last_shown()), RATE);
            assert_eq!(state(&step), Some(FrameState::Waiting));
            let (_, after) = d.clock(t, RATE);
            assert!(near(after, target), "frame {i}: paused at the jump");
        }
        t += FRAME_NS;
        let (_, pos) = d.clock(t, RATE);
        let step = d.step(t, pos, None, RATE);
        // The data arrived: shown from the jump on (one display frame of clock later).
        assert_eq!(state(&step), Some(FrameState::Exact));
        assert!(shown(&step) >= target && shown(&step) - target <= ONE_FRAME);
    }

    /// Media times equal up to the clock's nanosecond rounding.
    fn near(a: MediaTime, b: MediaTime) -> bool {
        a.abs_diff(b) < ONE_FRAME / 1_000_000
    }
}
