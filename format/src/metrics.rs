//! The protocol's error metrics (docs/CONVENTIONS.md, "Error metrics").
//!
//! 8-bit sequences: PSNR over all RGB values on the 0–255 scale after rounding the decoded
//! values to 8 bits. HDR sequences: the same PSNR on the 8-bit export curve applied to both
//! sides (peak 1, no rounding), plus the largest relative error over texels brighter than
//! 1% of the exposure's white (the value the exposure maps to x = 1). Mean PSNR pools the
//! squared error of all frames; identical frames count as 99 dB.

use crate::curve::ExportCurve;

/// How values are compared.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Metric {
    /// Values are sRGB code values / 255 (decoded ones are rounded to 8 bits).
    Srgb8,
    /// Values are linear light, compared through the export curve with this exposure.
    Hdr {
        /// The export curve's exposure e.
        exposure: f32,
    },
}

/// The PSNR given to identical frames.
pub const IDENTICAL_DB: f64 = 99.0;

/// PSNR in dB of a mean squared error on a 0–1 scale ([`IDENTICAL_DB`] for 0). NaN when
/// the error is NaN: values that are not numbers (an infinity through the export curve is
/// one) never pass for a perfect match.
pub fn psnr(mse: f64) -> f64 {
    if mse.is_nan() {
        f64::NAN
    } else if mse <= 0.0 {
        IDENTICAL_DB
    } else {
        (10.0 * (1.0 / mse).log10()).min(IDENTICAL_DB)
    }
}

/// One frame's comparison.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameError {
    /// Sum of squared errors on the 0–1 scale.
    pub sse: f64,
    /// Values compared.
    pub count: u64,
    /// Largest absolute error on the metric's 0–1 scale.
    pub max_abs: f64,
    /// HDR only: largest relative error over texels brighter than 1% of white.
    pub max_rel: f64,
}

impl FrameError {
    /// The frame's PSNR, dB.
    pub fn psnr(&self) -> f64 {
        psnr(self.sse / self.count.max(1) as f64)
    }
}

impl Metric {
    /// The value on the metric's 0–1 scale.
    #[inline]
    pub fn display(self, v: f32, decoded: bool) -> f64 {
        match self {
            Metric::Srgb8 => {
                let c = v.clamp(0.0, 1.0) as f64;
                if decoded {
                    (c * 255.0).round() / 255.0
                } else {
                    c
                }
            }
            Metric::Hdr { exposure } => ExportCurve::new(exposure).apply(v) as f64,
        }
    }

    /// Compares a source frame with a decoded one, value by value.
    pub fn compare(self, src: &[f32], dec: &[f32]) -> FrameError {
        self.compare_with(src, dec, |_| {})
    }

    /// [`Metric::compare`], also counting every value's error in `levels` (for the
    /// percentiles of a whole sequence, [`SequenceError::add`]).
    pub fn compare_counted(
        self,
        src: &[f32],
        dec: &[f32],
        levels: &mut ErrorHistogram,
    ) -> FrameError {
        self.compare_with(src, dec, |d| levels.record(d))
    }

    fn compare_with(self, src: &[f32], dec: &[f32], mut each: impl FnMut(f64)) -> FrameError {
        assert_eq!(src.len(), dec.len());
        // In runs: the curve's evaluations of a run are independent of each other, so they
        // overlap in the pipeline, and the sums and maxima are taken after them in lanes
        // (one running sum waited on every value: most of a sample pass's verification).
        const RUN: usize = 256;
        const LANES: usize = 4;
        let bright = match self {
            Metric::Hdr { exposure } => 0.01 / exposure,
            Metric::Srgb8 => f32::INFINITY,
        };
        let curve = match self {
            Metric::Hdr { exposure } => Some(ExportCurve::new(exposure)),
            Metric::Srgb8 => None,
        };
        let mut diff = [0f64; RUN];
        let (mut sse, mut max_abs, mut max_rel) = ([0f64; LANES], [0f64; LANES], 0f64);
        let mut nan = false;
        for (s, d) in src.chunks(RUN).zip(dec.chunks(RUN)) {
            let diff = &mut diff[..s.len()];
            match curve {
                Some(c) => differences(diff, s, d, |v| c.apply(v) as f64, |v| c.apply(v) as f64),
                None => differences(
                    diff,
                    s,
                    d,
                    |v| self.display(v, false),
                    |v| self.display(v, true),
                ),
            }
            for run in diff.chunks(LANES) {
                for (l, &x) in run.iter().enumerate() {
                    sse[l] += x * x;
                    max_abs[l] = max_abs[l].max(x.abs());
                    nan |= x.is_nan();
                }
            }
            diff.iter().for_each(|&x| each(x));
            if bright.is_finite() {
                for (&s, &d) in s.iter().zip(d) {
                    if s > bright {
                        max_rel = nan_max(max_rel, ((d - s) / s).abs() as f64);
                    }
                }
            }
        }
        FrameError {
            count: src.len() as u64,
            // A NaN carries through the sums; `max` would drop it.
            sse: sse.iter().sum(),
            max_abs: match nan {
                true => f64::NAN,
                false => max_abs.iter().copied().fold(0.0, f64::max),
            },
            max_rel,
        }
    }
}

/// `diff[i]` = the display value of `s[i]` less that of `d[i]`; NaN where either is not
/// finite (a NaN or an infinity anywhere makes the frame's error NaN).
#[inline(always)]
fn differences(
    diff: &mut [f64],
    s: &[f32],
    d: &[f32],
    source: impl Fn(f32) -> f64,
    decoded: impl Fn(f32) -> f64,
) {
    for ((x, &s), &d) in diff.iter_mut().zip(s).zip(d) {
        *x = if d.is_finite() && s.is_finite() {
            source(s) - decoded(d)
        } else {
            f64::NAN
        };
    }
}

/// The larger of two errors, NaN if either is (`f64::max` drops a NaN).
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// How many values erred by how much, in bins of 1/16 of an 8-bit level (errors on the
/// 0–1 scale never exceed 255 levels): the pooled error's percentiles without keeping
/// every value. 32 KiB however long the sequence.
#[derive(Clone, Debug, Default)]
pub struct ErrorHistogram {
    bins: Vec<u64>,
}

impl ErrorHistogram {
    /// Bins per 8-bit level.
    pub const PER_LEVEL: usize = 16;

    /// Counts one error on the 0–1 scale (a NaN is not counted: the frame's PSNR already
    /// says it is not a number).
    pub fn record(&mut self, diff: f64) {
        if diff.is_nan() {
            return;
        }
        if self.bins.is_empty() {
            self.bins = vec![0; 256 * Self::PER_LEVEL];
        }
        let b = (diff.abs() * 255.0 * Self::PER_LEVEL as f64) as usize;
        let last = self.bins.len() - 1;
        self.bins[b.min(last)] += 1;
    }

    /// Adds another histogram's counts.
    pub fn merge(&mut self, other: &ErrorHistogram) {
        if self.bins.is_empty() {
            self.bins = other.bins.clone();
        } else {
            for (a, b) in self.bins.iter_mut().zip(&other.bins) {
                *a += b;
            }
        }
    }

    /// The error, in 8-bit levels, that a share `q` (0 to 1) of the values do not exceed,
    /// to the bin's upper edge (at most 1/16 of a level above the true quantile); 0 when
    /// nothing was counted.
    pub fn quantile_levels(&self, q: f64) -> f64 {
        let total: u64 = self.bins.iter().sum();
        if total == 0 {
            return 0.0;
        }
        let need = (q.clamp(0.0, 1.0) * total as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (i, n) in self.bins.iter().enumerate() {
            seen += n;
            if seen >= need {
                return (i + 1) as f64 / Self::PER_LEVEL as f64;
            }
        }
        256.0
    }
}

/// Pooled statistics over a sequence.
#[derive(Clone, Debug, Default)]
pub struct SequenceError {
    /// Each frame, in order.
    pub frames: Vec<FrameError>,
    /// Every value's error, when frames were added with [`SequenceError::add`].
    pub levels: ErrorHistogram,
}

impl SequenceError {
    /// Adds a frame.
    pub fn push(&mut self, f: FrameError) {
        self.frames.push(f);
    }
    /// Compares a frame with `metric`, adds it and counts its values' errors.
    pub fn add(&mut self, metric: Metric, src: &[f32], dec: &[f32]) {
        let f = metric.compare_counted(src, dec, &mut self.levels);
        self.frames.push(f);
    }
    /// The 99.9th percentile of every value's error, in 8-bit levels (frames added with
    /// [`SequenceError::add`]): the histogram's bin edge, never above the largest error
    /// (identical sequences read 0, not the first bin's edge of 1/16).
    pub fn p999_levels(&self) -> f64 {
        let q = self.levels.quantile_levels(0.999);
        let max = self.max_abs() * 255.0;
        if max.is_nan() {
            q
        } else {
            q.min(max)
        }
    }
    /// PSNR of the error pooled over all frames and values (the mean PSNR).
    pub fn mean_psnr(&self) -> f64 {
        let sse: f64 = self.frames.iter().map(|f| f.sse).sum();
        let n: u64 = self.frames.iter().map(|f| f.count).sum();
        psnr(sse / n.max(1) as f64)
    }
    /// Lowest per-frame PSNR and its frame; a frame whose PSNR is NaN (values that are not
    /// numbers) is the worst.
    pub fn worst(&self) -> (usize, f64) {
        self.frames
            .iter()
            .enumerate()
            .map(|(i, f)| (i, f.psnr()))
            .fold((0, IDENTICAL_DB), |a, b| {
                if a.1.is_nan() || !(b.1.is_nan() || b.1 < a.1) {
                    a
                } else {
                    b
                }
            })
    }
    /// The first frame whose values are not all numbers, if any.
    pub fn first_not_a_number(&self) -> Option<usize> {
        self.frames.iter().position(|f| f.sse.is_nan())
    }
    /// Largest absolute error of any frame, 0–1 scale (NaN if any frame's is).
    pub fn max_abs(&self) -> f64 {
        self.frames.iter().map(|f| f.max_abs).fold(0.0, nan_max)
    }
    /// Largest relative error of any frame (HDR; over texels brighter than 1% of white;
    /// NaN if any frame's is).
    pub fn max_rel(&self) -> f64 {
        self.frames.iter().map(|f| f.max_rel).fold(0.0, nan_max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_that_are_not_numbers_are_never_a_perfect_match() {
        assert!(psnr(f64::NAN).is_nan());
        let src = [0.5f32; 6];
        let mut seq = SequenceError::default();
        for (k, bad) in [0.5f32, f32::INFINITY, f32::NAN, 0.25]
            .into_iter()
            .enumerate()
        {
            let mut dec = [0.5f32; 6];
            dec[k] = bad;
            for m in [Metric::Srgb8, Metric::Hdr { exposure: 1.5 }] {
                let e = m.compare(&src, &dec);
                assert_eq!(e.psnr().is_nan(), !bad.is_finite(), "{bad} through {m:?}");
            }
            seq.push(Metric::Hdr { exposure: 1.5 }.compare(&src, &dec));
        }
        assert!(seq.mean_psnr().is_nan() && seq.max_abs().is_nan());
        assert_eq!(seq.first_not_a_number(), Some(1));
        let (frame, worst) = seq.worst();
        assert!(frame == 1 && worst.is_nan());
    }

    #[test]
    fn the_percentile_counts_every_value_to_a_sixteenth_of_a_level() {
        // 1000 values: 997 exact, one off by 1 level, one by 3, one by 40.
        let src = vec![128.0f32 / 255.0; 1000];
        let mut dec = src.clone();
        dec[5] += 1.0 / 255.0;
        dec[10] += 3.0 / 255.0;
        dec[20] -= 40.0 / 255.0;
        let mut seq = SequenceError::default();
        seq.add(Metric::Srgb8, &src, &dec);
        let near = |q: f64, levels: f64| {
            let p = seq.levels.quantile_levels(q);
            assert!(
                (p - levels).abs() <= 1.0 / 16.0 + 1e-9,
                "q {q}: {p}, not {levels}"
            );
        };
        near(0.997, 0.0);
        near(0.998, 1.0);
        near(0.999, 3.0);
        near(1.0, 40.0);
        assert_eq!(seq.p999_levels(), seq.levels.quantile_levels(0.999));
        // Nothing differs: the largest error (next to nothing), not the first bin's upper
        // edge.
        let mut same = SequenceError::default();
        same.add(Metric::Srgb8, &src, &src);
        assert_eq!(same.p999_levels(), same.max_abs() * 255.0);
        assert!(same.p999_levels() < 1e-3);
        assert_eq!(ErrorHistogram::default().quantile_levels(0.999), 0.0);
    }

    #[test]
    fn identical_is_99_db_and_one_code_value_is_48() {
        let a = vec![128.0f32 / 255.0; 300];
        let m = Metric::Srgb8;
        assert_eq!(m.compare(&a, &a).psnr(), IDENTICAL_DB);
        let b: Vec<f32> = a.iter().map(|v| v + 1.0 / 255.0).collect();
        assert!((m.compare(&a, &b).psnr() - 48.13).abs() < 0.01);
    }
}
