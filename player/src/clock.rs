//! Playback clocks in integer ticks (nanoseconds): never accumulated floating-point seconds.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A source of time for the reader's pacing and the render thread's frames.
pub trait Clock: Send + Sync {
    /// Nanoseconds since the clock started.
    fn now_ns(&self) -> u64;
    /// Blocks the calling thread until `now_ns() >= t` or `give_up()` says stop; returns
    /// whether the time was reached. Whoever makes `give_up()` true should unpark the
    /// thread (`Thread::unpark`) so that it sees it at once.
    fn sleep_until(&self, t: u64, give_up: &dyn Fn() -> bool) -> bool;
}

/// Wall-clock time.
pub struct SystemClock {
    start: Instant,
}

impl SystemClock {
    /// A clock whose zero is now.
    pub fn new() -> SystemClock {
        SystemClock {
            start: Instant::now(),
        }
    }
}

impl Default for SystemClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for SystemClock {
    fn now_ns(&self) -> u64 {
        self.start.elapsed().as_nanos() as u64
    }
    fn sleep_until(&self, t: u64, give_up: &dyn Fn() -> bool) -> bool {
        loop {
            let now = self.now_ns();
            if now >= t {
                return true;
            }
            if give_up() {
                return false;
            }
            // Parked, not asleep: a stop or a seek unparks the thread. (Naps of 5 ms woke
            // it 200 times a second while it waited.) The timeout bounds a missed unpark.
            std::thread::park_timeout(Duration::from_nanos((t - now).min(200_000_000)));
        }
    }
}

/// Simulated time, advanced explicitly by a test or a benchmark. Cheap to clone.
#[derive(Clone, Default)]
pub struct SimClock {
    now: Arc<AtomicU64>,
}

impl SimClock {
    /// A clock at zero.
    pub fn new() -> SimClock {
        SimClock::default()
    }
    /// Moves the clock forward by `dt` ns.
    pub fn advance(&self, dt: u64) {
        self.now.fetch_add(dt, Ordering::SeqCst);
    }
    /// Sets the clock to `t` ns.
    pub fn set(&self, t: u64) {
        self.now.store(t, Ordering::SeqCst);
    }
}

impl Clock for SimClock {
    fn now_ns(&self) -> u64 {
        self.now.load(Ordering::SeqCst)
    }
    fn sleep_until(&self, t: u64, give_up: &dyn Fn() -> bool) -> bool {
        while self.now_ns() < t {
            if give_up() {
                return false;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        true
    }
}
