//! Media time as fixed point: frames in the high 32 bits, a 32-bit fraction in the low,
//! converted from clock ticks with integer arithmetic only.

/// Media position in frames × 2³².
pub type MediaTime = u64;

pub const ONE_FRAME: MediaTime = 1 << 32;

/// Clock ticks (ns) → media time at `num/den` frames per second.
pub fn ticks_to_media(ticks: u64, num: u32, den: u32) -> MediaTime {
    ((ticks as u128 * num as u128) << 32)
        .checked_div(den as u128 * 1_000_000_000)
        .unwrap_or(0) as u64
}

/// Media time → clock ticks (ns), rounded down.
pub fn media_to_ticks(t: MediaTime, num: u32, den: u32) -> u64 {
    ((t as u128 * den as u128 * 1_000_000_000) >> 32)
        .checked_div(num as u128)
        .unwrap_or(0) as u64
}

/// Media time as fractional frames (for display and basis weights only).
pub fn frames_f64(t: MediaTime) -> f64 {
    (t >> 32) as f64 + (t & 0xffff_ffff) as f64 / 4_294_967_296.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hundred_hours_at_24_fps_is_exact() {
        let ticks = 100 * 3600 * 1_000_000_000u64;
        let t = ticks_to_media(ticks, 24, 1);
        assert_eq!(t, (100 * 3600 * 24u64) << 32);
        assert_eq!(media_to_ticks(t, 24, 1), ticks);
        assert_eq!(
            t % (240 << 32),
            0,
            "100 hours are whole loops of 240 frames"
        );
        // A display step of 16 666 667 ns (60 Hz rounded up) summed 10⁶ times is exactly
        // the product: integer ticks never drift.
        let step = 16_666_667u64;
        let t2 = ticks_to_media(step * 1_000_000, 24, 1);
        assert_eq!(
            t2,
            (((step as u128 * 1_000_000 * 24) << 32) / 1_000_000_000) as u64
        );
        assert!((frames_f64(t2) - 400_000.008).abs() < 1e-3);
    }
}
