//! The search for an internal tolerance that delivers a mean PSNR inside a band, shared by
//! the sample passes of `aim` and the full passes of `calibrate` (`--exact`).

/// One pass: (internal tolerance, delivered mean PSNR, bytes).
pub(crate) type Pass = (f64, f64, u64);

/// The next internal tolerance to try, given every pass so far as (internal tolerance,
/// delivered mean PSNR, bytes), for a delivered PSNR in `lo..=hi`. The delivered PSNR rises
/// with the internal tolerance, but in steps (segment lengths change discretely): secant
/// steps until the band is bracketed, then regula falsi kept away from the bracket's ends
/// (bisection when the secant would hug one).
pub(crate) fn next_tolerance(passes: &[Pass], lo: f64, hi: f64) -> f64 {
    let aim = 0.5 * (lo + hi);
    match bracket(passes, lo, hi) {
        (Some(&(t0, p0, _)), Some(&(t1, p1, _))) => {
            let x = t0 + (aim - p0) * (t1 - t0) / (p1 - p0);
            let margin = 0.15 * (t1 - t0);
            if x < t0 + margin || x > t1 - margin {
                0.5 * (t0 + t1)
            } else {
                x
            }
        }
        _ => {
            let n = passes.len();
            let (internal, p, _) = passes[n - 1];
            if n >= 2 && (passes[n - 1].1 - passes[n - 2].1).abs() > 1e-3 {
                let ((t0, p0, _), (t1, p1, _)) = (passes[n - 2], passes[n - 1]);
                t1 + (aim - p1) * (t1 - t0) / (p1 - p0)
            } else {
                internal + (aim - p)
            }
        }
    }
}

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
