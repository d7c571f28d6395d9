//! The reader's bandwidth model: a byte rate cap and periodic stalls (`--bandwidth 2MB/s`,
//! `--stall 300ms@5s`), as arrival times on the playback clock. Pure arithmetic, so that a
//! simulated clock gives the same schedule every run.

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Throttle {
    /// Bytes per second; `None` = unlimited.
    pub rate: Option<u64>,
    /// A stall of `stall.0` ns every `stall.1` ns of clock time, starting at `stall.1`.
    pub stall: Option<(u64, u64)>,
}

impl Throttle {
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
        let mut t = start;
        let Some((d, p)) = self.stall.filter(|s| s.0 > 0 && s.1 > s.0) else {
            return t + need;
        };
        loop {
            // Inside a stall window [k·p, k·p + d) (k ≥ 1) nothing arrives.
            let k = t / p;
            if k >= 1 && t < k * p + d {
                t = k * p + d;
            }
            let next = (t / p + 1) * p;
            if t + need <= next {
                return t + need;
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
        let t = Throttle {
            rate: Some(1_000_000),
            stall: None,
        };
        assert_eq!(t.arrival(0, 500_000), 500_000_000);
        let t = Throttle {
            rate: Some(1_000_000),
            stall: Some((300_000_000, 5_000_000_000)),
        };
        // 6 MB from 0: 5 s of reading, a 0.3 s stall, 1 s more.
        assert_eq!(t.arrival(0, 6_000_000), 6_300_000_000);
        // Starting inside a stall waits for its end.
        assert_eq!(t.arrival(5_100_000_000, 1_000), 5_301_000_000);
        assert_eq!(Throttle::UNLIMITED.arrival(7, 1 << 40), 7);
    }
}
