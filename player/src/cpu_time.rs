//! The calling thread's own CPU time: what the decoder's and the render thread's work
//! costs, without the time the thread sat preempted (on a machine where a software GPU
//! shares the cores, the wall clock of a decode includes other threads' work).

/// Nanoseconds of CPU time the calling thread has used; on platforms without a per-thread
/// clock, a monotonic wall clock instead (differences stay meaningful either way).
pub fn thread_cpu_ns() -> u64 {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: a valid clock id and a pointer to a timespec we own.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64;
        }
    }
    use std::sync::OnceLock;
    static START: OnceLock<std::time::Instant> = OnceLock::new();
    START
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_nanos() as u64
}
