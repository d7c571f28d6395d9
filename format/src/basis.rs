//! The temporal basis of a segment (`docs/MODEL.md`).
//!
//! Inside a segment of length L frames, normalised time u = (t − b_s) / L runs from 0 to 1.
//! A texel is v(u) = K_s·(1 − u) + K_{s+1}·u + Σ_{k=2..d} c_k·B_k(u), where the first two
//! terms are the linear "hat" functions (degree 1 is exactly keyframe interpolation) and
//! B_k are the Lobatto bubble functions
//!     B_k(u) = (P_k(x) − P_{k−2}(x)) / sqrt(2(2k − 1)),   x = 2u − 1,
//! built from Legendre polynomials P_k. They vanish at both ends, so extra degrees add
//! curvature without moving the keyframes, and the curve is continuous across boundaries.
//! Their derivatives are orthonormal, which keeps the least-squares fit well conditioned at
//! every degree and segment length (no monomials in the raw frame index anywhere).

use crate::limits::MAX_DEGREE;

/// Number of basis weights for the largest degree: two hats plus the bubbles.
pub const MAX_TERMS: usize = MAX_DEGREE as usize + 1;

/// Legendre polynomials P_0..=P_n at x by the three-term recurrence (stable on [−1, 1]).
fn legendre(n: usize, x: f64, out: &mut [f64; MAX_TERMS]) {
    out[0] = 1.0;
    if n >= 1 {
        out[1] = x;
    }
    for k in 2..=n {
        out[k] = ((2 * k - 1) as f64 * x * out[k - 1] - (k - 1) as f64 * out[k - 2]) / k as f64;
    }
}

/// Bubble function B_k(u) for k ≥ 2.
pub fn bubble(k: usize, u: f64) -> f64 {
    debug_assert!((2..=MAX_DEGREE as usize).contains(&k));
    weights_f64(k, u)[k]
}

/// All basis weights at normalised time `u` for polynomials up to `degree`:
/// `w[0] = 1 − u`, `w[1] = u`, `w[k] = B_k(u)` for 2 ≤ k ≤ degree, zero beyond.
/// These f32 weights are what both the CPU reference decoder and the GPU shader use.
pub fn weights(degree: usize, u: f64) -> [f32; MAX_TERMS] {
    weights_f64(degree, u).map(|w| w as f32)
}

/// Least-squares projection of a segment's interior samples onto its bubble functions.
///
/// For a segment of `len` frames the interior frames are u_j = j / len, j = 1..len−1 (the
/// end frames are the keyframes). `coefficients` maps the residual after keyframe
/// interpolation at those frames to bubble coefficients c_2..c_{1+n}, computed once per
/// segment length by a QR factorisation (modified Gram–Schmidt) in f64.
#[derive(Clone, Debug)]
pub struct Projector {
    /// Frames in the segment.
    pub len: u32,
    /// Number of bubbles fitted: min(max_degree − 1, len − 1).
    pub bubbles: usize,
    /// Row-major `bubbles × (len − 1)` pseudo-inverse.
    pinv: Vec<f64>,
    /// Bubble values at the interior frames, `(len − 1) × bubbles`, for evaluating fits.
    pub design: Vec<f64>,
    /// The QR factors of `design`: Q (`(len − 1) × bubbles`, orthonormal columns) and R
    /// (`bubbles × bubbles`, upper triangular). Gram–Schmidt keeps spans nested, so the
    /// fit with the first d bubbles is the projection on Q's first d columns.
    pub q: Vec<f64>,
    /// R of the QR factorisation (see `q`).
    pub r: Vec<f64>,
}

impl Projector {
    /// The projector for segments of `len` frames fitting at most `max_degree − 1` bubbles.
    pub fn new(len: u32, max_degree: usize) -> Projector {
        assert!(len >= 1 && max_degree >= 1);
        let m = len as usize - 1;
        let n = (max_degree - 1).min(m);
        let mut design = vec![0.0; m * n];
        for j in 0..m {
            let u = (j + 1) as f64 / len as f64;
            let w = weights_f64(n + 1, u);
            design[j * n..j * n + n].copy_from_slice(&w[2..2 + n]);
        }
        // Modified Gram–Schmidt: A = Q R, then pinv = R⁻¹ Qᵀ.
        let mut q = design.clone();
        let mut r = vec![0.0; n * n];
        for k in 0..n {
            for i in 0..k {
                let dot: f64 = (0..m).map(|j| q[j * n + i] * q[j * n + k]).sum();
                r[i * n + k] = dot;
                for j in 0..m {
                    q[j * n + k] -= dot * q[j * n + i];
                }
            }
            let norm = (0..m)
                .map(|j| q[j * n + k] * q[j * n + k])
                .sum::<f64>()
                .sqrt();
            r[k * n + k] = norm;
            for j in 0..m {
                q[j * n + k] /= norm;
            }
        }
        // Solve R X = Qᵀ by back substitution, column by column of Qᵀ.
        let mut pinv = vec![0.0; n * m];
        for j in 0..m {
            for k in (0..n).rev() {
                let mut v = q[j * n + k];
                for i in k + 1..n {
                    v -= r[k * n + i] * pinv[i * m + j];
                }
                pinv[k * m + j] = v / r[k * n + k];
            }
        }
        Projector {
            len,
            bubbles: n,
            pinv,
            design,
            q,
            r,
        }
    }

    /// Bubble coefficients c_2..c_{1+bubbles} for one texel's interior residual `r`
    /// (length len − 1).
    pub fn project(&self, r: &[f64], out: &mut [f64]) {
        let m = self.len as usize - 1;
        for (k, o) in out.iter_mut().enumerate().take(self.bubbles) {
            let row = &self.pinv[k * m..k * m + m];
            *o = row.iter().zip(r).map(|(a, b)| a * b).sum();
        }
    }
}

impl Projector {
    /// Bubble coefficients of the least-squares fit with the first `d` bubbles, from
    /// `z = Qᵀ r` (back substitution on R's leading d × d block).
    pub fn coeffs_from_qt(&self, z: &[f64], d: usize, out: &mut [f64]) {
        let n = self.bubbles;
        for k in (0..d).rev() {
            let tail: f64 = (k + 1..d).map(|i| self.r[k * n + i] * out[i]).sum();
            out[k] = (z[k] - tail) / self.r[k * n + k];
        }
    }
}

/// The weights of [`weights`] in f64: the one place the bubble formula
/// B_k(u) = (P_k(2u − 1) − P_{k−2}(2u − 1)) / √(2(2k − 1)) is written.
fn weights_f64(degree: usize, u: f64) -> [f64; MAX_TERMS] {
    let mut w = [0f64; MAX_TERMS];
    w[0] = 1.0 - u;
    w[1] = u;
    let mut p = [0.0; MAX_TERMS];
    legendre(degree, 2.0 * u - 1.0, &mut p);
    for k in 2..=degree {
        w[k] = (p[k] - p[k - 2]) / ((2 * (2 * k - 1)) as f64).sqrt();
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bubbles_vanish_at_both_ends() {
        for k in 2..=MAX_DEGREE as usize {
            assert!(bubble(k, 0.0).abs() < 1e-12, "B_{k}(0)");
            assert!(bubble(k, 1.0).abs() < 1e-12, "B_{k}(1)");
        }
    }

    #[test]
    fn projection_reproduces_polynomials_exactly() {
        // A cubic residual that vanishes at the ends is in the span of B_2, B_3.
        for len in [4u32, 7, 24, 1000, 100_000] {
            let p = Projector::new(len, 4);
            let m = len as usize - 1;
            let r: Vec<f64> = (1..=m)
                .map(|j| {
                    let u = j as f64 / len as f64;
                    u * (1.0 - u) * (0.3 + 2.0 * u)
                })
                .collect();
            let mut c = [0.0; 3];
            p.project(&r, &mut c);
            for (j, rv) in r.iter().enumerate() {
                let fit: f64 = (0..p.bubbles)
                    .map(|k| c[k] * p.design[j * p.bubbles + k])
                    .sum();
                assert!(
                    (fit - rv).abs() < 1e-9,
                    "len {len} frame {j}: {fit} vs {rv}"
                );
            }
            assert!(
                c[2].abs() < 1e-9,
                "len {len}: no quartic term expected, got {}",
                c[2]
            );
        }
    }

    #[test]
    fn short_segments_cap_the_number_of_bubbles() {
        assert_eq!(Projector::new(1, 8).bubbles, 0);
        assert_eq!(Projector::new(2, 8).bubbles, 1);
        assert_eq!(Projector::new(3, 8).bubbles, 2);
        assert_eq!(Projector::new(50, 8).bubbles, 7);
    }
}
