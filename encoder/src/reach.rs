//! How far a quantisation error reaches in time, and the sensitivity it is seen at there.
//!
//! A quantiser step turns an error budget in metric units into coded units through the
//! sensitivity ([`crate::domain::Domain`]): how far a unit of coded error moves the
//! metric. The error is seen in more frames than the one it is coded for, each weighing it
//! by its own sensitivity:
//! - a keyframe's error is interpolated into the segments on both sides of it, at weight
//!   1 at the keyframe falling to 0 at the keyframes beyond;
//! - a bubble coefficient's error reaches every inner frame of its segment.
//!
//! Where the sensitivity changes within that reach, a step set from the keyframe's own
//! frame, or from a segment's mean, puts the error where it is seen most: a midday whose
//! highlights saturate the display (no sensitivity there) hides a keyframe's error that
//! the dusk after it shows, and a sunrise segment's mean is lowered by the frames still
//! dark. On the unseen winter day of BENCHMARKS.md such frames sat 8–10 dB below the mean.
//! So each step is set from the most sensitive frame it reaches (docs/MODEL.md,
//! "Quantiser steps").

use rayon::prelude::*;

/// The RMS sensitivity at which a keyframe's error is seen: at every texel the largest
/// of its sensitivity in each frame the keyframe reaches, weighted by the keyframe's
/// interpolation weight there (its own frame, `key`: 1), measured on the search's
/// subsample and scaled to the whole frame's `own_rms` (the keyframe's own RMS
/// sensitivity). `reached`: (weight, subsampled sensitivity) of each frame it reaches.
/// Never below `own_rms`.
pub(crate) fn keyframe(key: &[f32], own_rms: f64, reached: &[(f32, &[f32])]) -> f64 {
    const RUN: usize = 4096;
    let (own, seen) = key
        .par_chunks(RUN)
        .enumerate()
        .map(|(r, run)| {
            let mut acc = (0.0f64, 0.0f64);
            for (k, &s) in run.iter().enumerate() {
                let i = r * RUN + k;
                let most = reached.iter().fold(s, |m, (w, f)| m.max(w * f[i]));
                acc.0 += (s as f64).powi(2);
                acc.1 += (most as f64).powi(2);
            }
            acc
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    if own > 0.0 {
        own_rms * (seen / own).sqrt()
    } else {
        // Nothing in the keyframe's own frame sees its error: the frames it reaches alone
        // set the step.
        own_rms.max((seen / key.len().max(1) as f64).sqrt())
    }
}

/// The frames of a segment of `len` frames that a keyframe at its start (`at_start`) or
/// at its end reaches, by their offset from the segment's start: (offset, weight).
pub(crate) fn weights(len: u32, at_start: bool) -> impl Iterator<Item = (u32, f32)> {
    (1..len).map(move |j| {
        let u = j as f32 / len as f32;
        (j, if at_start { 1.0 - u } else { u })
    })
}

/// The RMS sensitivity at which a segment's bubble coefficients' error is seen: that of
/// its most sensitive inner frame, from each inner frame's sum of squared sensitivities
/// over `texels` texels.
pub(crate) fn segment(frame_sens_sq: &[f64], texels: usize) -> f64 {
    let most = frame_sens_sq.iter().copied().fold(0.0, f64::max);
    (most / texels.max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_keyframe_whose_neighbours_are_no_more_sensitive_keeps_its_own_sensitivity() {
        let key = [2.0, 1.0, 0.5];
        let reached: Vec<(f32, &[f32])> = weights(4, true).map(|(_, w)| (w, &key[..])).collect();
        assert_eq!(keyframe(&key, 3.0, &reached), 3.0);
        assert_eq!(keyframe(&key, 3.0, &[]), 3.0);
    }

    #[test]
    fn a_keyframe_saturated_where_the_next_frames_see_is_coded_for_them() {
        // Texel 1 is saturated (insensitive) in the keyframe and sensitive after it: the
        // frame after the keyframe, at weight 3/4, sees it at 4 · 3/4 = 3.
        let (key, next) = ([1.0, 0.0], [1.0, 4.0]);
        let reached: Vec<(f32, &[f32])> = weights(4, true).map(|(_, w)| (w, &next[..])).collect();
        let s = keyframe(&key, 1.0 / 2f64.sqrt(), &reached);
        // Own mean square 1/2 over the two texels; reached (1 + 9) / 2.
        assert!((s - (10.0f64 / 2.0).sqrt()).abs() < 1e-6, "{s}");
    }

    #[test]
    fn a_keyframe_that_sees_nothing_takes_the_sensitivity_of_the_frames_it_reaches() {
        let (key, next) = ([0.0, 0.0], [2.0, 2.0]);
        let s = keyframe(&key, 0.0, &[(0.5, &next[..])]);
        assert!((s - 1.0).abs() < 1e-9, "{s}"); // weight 1/2 × 2
    }

    #[test]
    fn weights_fall_from_the_keyframe_to_the_far_end() {
        let start: Vec<_> = weights(4, true).collect();
        assert_eq!(start, vec![(1, 0.75), (2, 0.5), (3, 0.25)]);
        let end: Vec<_> = weights(4, false).collect();
        assert_eq!(end, vec![(1, 0.25), (2, 0.5), (3, 0.75)]);
        assert_eq!(weights(1, true).count(), 0);
    }

    #[test]
    fn a_segment_is_quantised_for_its_most_sensitive_frame() {
        assert_eq!(segment(&[4.0, 16.0, 9.0], 4), 2.0);
        assert_eq!(segment(&[], 4), 0.0);
    }
}
