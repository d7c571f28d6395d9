//! The reader's bandwidth model: a byte rate cap and periodic stalls (`--bandwidth 2MB/s`,
//! `--stall 300ms@5s`), as arrival times on the playback clock. Pure arithmetic, so that a
//! simulated clock gives the same schedule every run.

/// How fast the reader may read: a byte rate and periodic stalls.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Throttle {
    /// Bytes per second; `None` = unlimited.
    pub rate: Option<u64>,
    /// Periodic stalls; `None` = none.
    pub stall: Option<Stall>,
}

/// A stall of `length_ns` every `every_ns` of clock time, the first at `first_ns`, at most
/// one period in (`300ms@5s` starts at 5 s; `300ms@5s+2s` at 2 s, then 7 s, 12 s, …). The phase lets a
/// benchmark put the stall where the stream is busiest instead of where the period falls.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stall {
    /// How long the reader stops, ns.
    pub length_ns: u64,
    /// The period, ns.
    pub every_ns: u64,
    /// When the first stall starts, ns of playback clock.
    pub first_ns: u64,
}

impl Stall {
    /// Every `every_ns`, the first one period in.
    pub fn every(length_ns: u64, every_ns: u64) -> Stall {
        Stall {
            length_ns,
            every_ns,
            first_ns: every_ns,
        }
    }
}

impl Throttle {
    /// No cap and no stalls.
    pub const UNLIMITED: Throttle = Throttle {
        rate: None,
        stall: None,
    };

    /// When `bytes` more bytes have arrived, reading from time `start` on.
    pub fn arrival(&self, start: u64, bytes: u64) -> u64 {
        let mut need = match self.rate {
            None => 0u128,
            Some(r) => (bytes as u128 * 1_000_000_000).div_ceil(r.max(1) as u128),
        } as u64;
        let Some(s) = self
            .stall
            .filter(|s| s.length_ns > 0 && s.every_ns > s.length_ns)
        else {
            return start + need;
        };
        let (d, p) = (s.length_ns, s.every_ns);
        // Shifted so that the stalls fall at k·p, k ≥ 1, in the time `t` counts (a first
        // stall later than one period is taken as one period in).
        let shift = p - s.first_ns.min(p);
        let mut t = start + shift;
        loop {
            // Inside a stall window [k·p, k·p + d) (k ≥ 1) nothing arrives.
            let k = t / p;
            if k >= 1 && t < k * p + d {
                t = k * p + d;
            }
            let next = (t / p + 1) * p;
            if t + need <= next {
                return t + need - shift;
            }
            need -= next - t;
            t = next;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rate_and_stalls() {
        // 1 MB/s with 300 ms stalls every 5 s, the first at `first_ns`.
        let stalling = |first_ns| Throttle {
            rate: Some(1_000_000),
            stall: Some(Stall {
                first_ns,
                ..Stall::every(300_000_000, 5_000_000_000)
            }),
        };
        let t = Throttle {
            rate: Some(1_000_000),
            stall: None,
        };
        assert_eq!(t.arrival(0, 500_000), 500_000_000);
        // `every` puts the first stall one period in.
        let t = Throttle {
            rate: Some(1_000_000),
            stall: Some(Stall::every(300_000_000, 5_000_000_000)),
        };
        assert_eq!(t, stalling(5_000_000_000));
        // 6 MB from 0: 5 s of reading, a 0.3 s stall, 1 s more.
        assert_eq!(t.arrival(0, 6_000_000), 6_300_000_000);
        // Starting inside a stall waits for its end.
        assert_eq!(t.arrival(5_100_000_000, 1_000), 5_301_000_000);
        assert_eq!(Throttle::UNLIMITED.arrival(7, 1 << 40), 7);
        // The first stall at 2 s (then 7 s, 12 s): 2 s of reading, the 0.3 s stall, 4 s
        // more → 6.3 s; from 6.9 s, 0.1 s runs into the stall at 7 s and ends at 7.4 s.
        let t = stalling(2_000_000_000);
        assert_eq!(t.arrival(0, 6_000_000), 6_300_000_000);
        assert_eq!(t.arrival(6_900_000_000, 200_000), 7_400_000_000);
        assert_eq!(t.arrival(2_100_000_000, 1_000), 2_301_000_000);
        // A first stall at 0 s: time 0 is inside it.
        assert_eq!(stalling(0).arrival(0, 1_000_000), 1_300_000_000);
    }
}
