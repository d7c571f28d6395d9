//! The search for an internal tolerance that delivers a mean PSNR inside a band, shared by
//! the sample passes of `aim` and the full passes of `calibrate` (`--exact`).

/// The next internal tolerance to try, given every pass so far as (internal tolerance,
/// delivered mean PSNR, bytes), for a delivered PSNR in `lo..=hi`. The delivered PSNR rises
/// with the internal tolerance, but in steps (segment lengths change discretely): secant
/// steps until the band is bracketed, then regula falsi kept away from the bracket's ends
/// (bisection when the secant would hug one).
pub(crate) fn next_tolerance(passes: &[(f64, f64, u64)], lo: f64, hi: f64) -> f64 {
    let aim = 0.5 * (lo + hi);
    let below = passes
        .iter()
        .filter(|q| q.1 < lo)
        .max_by(|a, b| a.0.total_cmp(&b.0));
    let above = passes
        .iter()
        .filter(|q| q.1 > hi)
        .min_by(|a, b| a.0.total_cmp(&b.0));
    match (below, above) {
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
