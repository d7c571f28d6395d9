//! Transfer curves: between linear light and the coded domain the model lives in, and the
//! 8-bit export curve used to measure error (docs/CONVENTIONS.md).

use crate::header::Transfer;

/// sRGB code value (0–1) to linear light.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light (0–1) to sRGB code value (0–1).
pub fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

impl Transfer {
    /// Linear value → coded value. Srgb expects the 8-bit code value / 255 as `v`.
    pub fn encode(self, v: f32) -> f32 {
        match self {
            Transfer::Srgb => v,
            // log2(1 + x) rather than ln_1p(x)·log2(e): several times faster, and the
            // absolute error it adds near zero (~1e-7 coded units) is far below any step.
            Transfer::LogToe { v0 } => (1.0 + v.max(0.0) / v0).log2(),
        }
    }

    /// Coded value → linear light. Clamps to the curve's valid range first, so that a
    /// polynomial's overshoot never yields a negative, NaN or infinite texel.
    pub fn decode_linear(self, c: f32) -> f32 {
        match self {
            Transfer::Srgb => srgb_to_linear(c.clamp(0.0, 1.0)),
            Transfer::LogToe { v0 } => v0 * (c.clamp(0.0, 120.0).exp2() - 1.0),
        }
    }

    /// Coded value → the value a decoded file stores: the 8-bit code value / 255 for sRGB
    /// files, linear light for HDR files.
    pub fn decode_stored(self, c: f32) -> f32 {
        match self {
            Transfer::Srgb => c.clamp(0.0, 1.0),
            Transfer::LogToe { .. } => self.decode_linear(c),
        }
    }
}

/// The protocol's 8-bit export curve without the final rounding: x = v·e, y = x / (1 + x),
/// then the sRGB transfer function. Returns a value in [0, 1).
pub fn export_curve(v: f32, exposure: f32) -> f32 {
    let x = (v * exposure).max(0.0);
    linear_to_srgb(x / (1.0 + x))
}

/// A frame's largest green value (interleaved RGB, or Y alone for one channel): what the
/// protocol's exposure is computed from.
pub fn max_green(data: &[f32], channels: usize) -> f32 {
    let g = if channels == 3 { 1 } else { 0 };
    data.iter()
        .skip(g)
        .step_by(channels.max(1))
        .copied()
        .fold(0.0, f32::max)
}

/// The protocol's exposure: 1.5 / the median over frames of each frame's largest green.
pub fn exposure_from_max_greens(max_greens: &[f32]) -> f32 {
    let mut g: Vec<f32> = max_greens
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if g.is_empty() {
        return 1.0;
    }
    g.sort_by(f32::total_cmp);
    let n = g.len();
    let median = if n % 2 == 1 {
        g[n / 2]
    } else {
        0.5 * (g[n / 2 - 1] + g[n / 2])
    };
    if median > 0.0 {
        1.5 / median
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_toe_round_trips_the_hdr_range() {
        let t = Transfer::LogToe { v0: 1e-4 };
        for v in [0.0f32, 1e-6, 1e-4, 0.5, 1.0, 6e4, 65504.0] {
            let back = t.decode_linear(t.encode(v));
            assert!((back - v).abs() <= 1e-5 * v.max(1e-3), "{v} -> {back}");
        }
        assert_eq!(t.decode_linear(-3.0), 0.0);
        assert!(t.decode_linear(1e9).is_finite());
    }

    #[test]
    fn srgb_round_trips() {
        for i in 0..=255 {
            let c = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
    }
}
