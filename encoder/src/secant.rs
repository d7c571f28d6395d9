//! The search for an internal tolerance that delivers a mean PSNR inside a band, shared by
//! the sample passes of `aim` and the full passes of `calibrate` (`--exact`).

/// One pass: (internal tolerance, delivered mean PSNR, bytes).
pub(crate) type Pass = (f64, f64, u64);

/// The next internal tolerance to try, given every pass so far as (internal tolerance,
/// delivered mean PSNR, bytes), for a delivered PSNR in `lo..=hi`. The delivered PSNR rises
/// with the internal tolerance, but in steps (segment lengths change discretely): secant
/// steps until the band is bracketed, then regula falsi kept a little away from the
/// bracket's ends (so that it never hugs one; bisecting instead took two more passes where
/// a first step along the typical slope had bracketed the band widely but close to one end).
pub(crate) fn next_tolerance(passes: &[Pass], lo: f64, hi: f64) -> f64 {
    let aim = 0.5 * (lo + hi);
    match bracket(passes, lo, hi) {
        (Some(&(t0, p0, _)), Some(&(t1, p1, _))) => {
            let x = t0 + (aim - p0) * (t1 - t0) / (p1 - p0);
            // (The encoder's noise can put the pass below the band at the higher
            // tolerance of the two.)
            let (a, b) = (t0.min(t1), t0.max(t1));
            let margin = 0.15 * (b - a);
            x.clamp(a + margin, b - margin)
        }
        _ => {
            let n = passes.len();
            let (internal, p, _) = passes[n - 1];
            let slope = |(t0, p0, _): Pass, (t1, p1, _): Pass| (p1 - p0) / (t1 - t0);
            if n < 2 {
                return internal + (aim - p) / FIRST_SLOPE;
            }
            // Two passes closer together than the encoder's own noise (its segment
            // lengths move in steps) give a slope of noise, even a negative one: then the
            // slope across the widest span of passes.
            // (A slope that is not finite, from two passes at one tolerance, is noise too.)
            let mut s = slope(passes[n - 2], passes[n - 1]);
            if !s.is_finite() || s < MIN_SLOPE {
                s = span_slope(passes).unwrap_or(1.0);
            }
            internal + (aim - p) / s
        }
    }
}

/// The slope across the widest span of `passes` (dB delivered per dB of tolerance),
/// within what a secant step trusts; `None` from fewer than two distinct passes.
pub(crate) fn span_slope(passes: &[Pass]) -> Option<f64> {
    let by_t = |a: &&Pass, b: &&Pass| a.0.total_cmp(&b.0);
    let lo = passes.iter().min_by(by_t)?;
    let hi = passes.iter().max_by(by_t)?;
    let s = (hi.1 - lo.1) / (hi.0 - lo.0);
    (s.is_finite() && hi.0 > lo.0).then(|| s.clamp(MIN_SLOPE, MAX_SLOPE))
}

/// The least and the most rise in delivered PSNR per dB of internal tolerance a secant
/// step through the widest span trusts (the seven days measured rise 0.58–0.89 dB per dB).
const MIN_SLOPE: f64 = 0.25;
const MAX_SLOPE: f64 = 1.5;
/// The rise a step from a single pass assumes: the middle of the seven days' (a step of a
/// dB for a dB fell short on every one of them, and took a pass more).
pub(crate) const FIRST_SLOPE: f64 = 0.75;

/// The passes around the band `lo..=hi`: the one at the highest internal tolerance that
/// delivered below `lo`, and the one at the lowest that delivered above `hi`.
pub(crate) fn bracket(passes: &[Pass], lo: f64, hi: f64) -> (Option<&Pass>, Option<&Pass>) {
    let below = passes
        .iter()
        .filter(|q| q.1 < lo)
        .max_by(|a, b| a.0.total_cmp(&b.0));
    let above = passes
        .iter()
        .filter(|q| q.1 > hi)
        .min_by(|a, b| a.0.total_cmp(&b.0));
    (below, above)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_secant_steps_along_the_slope_of_its_last_two_passes() {
        let next = next_tolerance(&[(50.0, 52.0, 0), (48.0, 50.5, 0)], 49.9, 50.1);
        // Slope 0.75: 0.5 dB to go is 0.667 dB of tolerance.
        assert!((next - (48.0 - 0.5 / 0.75)).abs() < 1e-9, "{next}");
    }

    #[test]
    fn a_wide_bracket_steps_by_regula_falsi_kept_off_its_ends() {
        // Bracketed 4.3 dB wide, T near the lower pass: close to it, not halfway.
        let wide = [(45.0, 49.175, 0), (39.434, 44.866, 0)];
        let next = next_tolerance(&wide, 44.9, 45.1);
        let x = 39.434 + (45.0 - 44.866) * (45.0 - 39.434) / (49.175 - 44.866);
        assert_eq!(next, 39.434 + 0.15 * (45.0 - 39.434));
        assert!(x < next && next < 40.3, "{next}");
        // Inside the margins: regula falsi itself.
        let mid = [(40.0, 44.0, 0), (42.0, 46.0, 0)];
        assert!((next_tolerance(&mid, 44.9, 45.1) - 41.0).abs() < 1e-12);
        // The noise's crossing (the lower pass at the higher tolerance) does not panic.
        let crossed = [(42.0, 44.0, 0), (40.0, 46.0, 0)];
        let t = next_tolerance(&crossed, 44.9, 45.1);
        assert!((40.3..=41.7).contains(&t), "{t}");
    }

    #[test]
    fn two_passes_within_the_noise_step_along_the_widest_span_instead() {
        // The last two passes rise the wrong way (noise): the widest span's slope, 0.72.
        let passes = [
            (50.0, 52.498, 0),
            (47.502, 50.496, 0),
            (46.883, 50.108, 0),
            (46.711, 50.128, 0),
        ];
        let next = next_tolerance(&passes, 49.9, 50.1);
        let s = (52.498 - 50.128) / (50.0 - 46.711);
        assert!((next - (46.711 - 0.128 / s)).abs() < 1e-9, "{next}");
        assert!(next < 46.711 && next > 46.4, "{next}");
        // Flat everywhere (a staircase's step): along the least slope trusted, a long step.
        let flat = [(40.0, 45.0, 0), (41.0, 45.0, 0)];
        assert_eq!(next_tolerance(&flat, 45.9, 46.1), 41.0 + 1.0 / MIN_SLOPE);
        // One pass: along the typical slope.
        assert_eq!(
            next_tolerance(&[(40.0, 45.0, 0)], 45.4, 45.6),
            40.0 + 0.5 / FIRST_SLOPE
        );
        assert_eq!(span_slope(&passes), Some(s));
        assert_eq!(span_slope(&flat), Some(MIN_SLOPE));
        assert_eq!(span_slope(&passes[..1]), None);
    }
}
