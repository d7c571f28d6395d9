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

/// Octaves of x the power's table covers below 1: x ∈ [2⁻⁹, 1), which
/// holds the whole power segment (it starts at 0.0031308 > 2⁻⁹).
const TABLE_OCTAVES: usize = 9;
/// Mantissa bits that index the table: 1024 pieces per octave, so that the linear
/// interpolation's error (h²/8 · |f''|, relative about 3·10⁻⁸) stays below an f32 ulp.
const TABLE_BITS: u32 = 10;

/// x^(1/2.4) at the start of each piece of each octave, and one past the last.
static POW_TABLE: std::sync::LazyLock<Vec<f32>> = std::sync::LazyLock::new(|| {
    let per = 1usize << TABLE_BITS;
    let mut t = Vec::with_capacity(TABLE_OCTAVES * per + 1);
    for o in 0..TABLE_OCTAVES {
        let base = (2.0f64).powi(o as i32 - TABLE_OCTAVES as i32);
        for i in 0..per {
            t.push((base * (1.0 + i as f64 / per as f64)).powf(1.0 / 2.4) as f32);
        }
    }
    t.push(1.0);
    t
});

/// [`linear_to_srgb`] by a table of the power read by the float's exponent and top
/// mantissa bits and interpolated linearly: within 1.2·10⁻⁷ of it (two ulps near 1).
#[inline(always)]
fn srgb_by_table(table: &[f32], v: f32) -> f32 {
    if v <= 0.0031308 || v.is_nan() {
        return v * 12.92;
    }
    if v >= 1.0 {
        return linear_to_srgb(v);
    }
    let bits = v.to_bits();
    // Unbiased exponent −9…−1 → octave 0…8 (v > 0.0031308 > 2⁻⁹).
    let octave = ((bits >> 23) as usize) + TABLE_OCTAVES - 127;
    let shift = 23 - TABLE_BITS;
    let piece = ((bits & 0x7f_ffff) >> shift) as usize;
    let frac = (bits & ((1 << shift) - 1)) as f32 * (1.0 / (1u32 << shift) as f32);
    let i = (octave << TABLE_BITS) + piece;
    let (a, b) = (table[i], table[i + 1]);
    1.055 * (a + frac * (b - a)) - 0.055
}

/// The export curve ([`export_curve`]) at one exposure, its sRGB power read from a table
/// (within 1.2·10⁻⁷ of `powf`, about 10⁻⁶ dB of PSNR): what the error metric applies to
/// every value it compares, at a fraction of `powf`'s time.
#[derive(Clone, Copy)]
pub struct ExportCurve {
    exposure: f32,
    table: &'static [f32],
}

impl ExportCurve {
    /// The curve at `exposure`.
    pub fn new(exposure: f32) -> ExportCurve {
        ExportCurve {
            exposure,
            table: POW_TABLE.as_slice(),
        }
    }

    /// [`export_curve`] of `v`, within 1.2·10⁻⁷ of it.
    #[inline(always)]
    pub fn apply(&self, v: f32) -> f32 {
        let x = (v * self.exposure).max(0.0);
        srgb_by_table(self.table, x / (1.0 + x))
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

    #[test]
    fn the_table_follows_the_power_within_an_ulp_or_two() {
        // Every float from just below the linear segment's end to past 1, in steps of a
        // few ulps: the pieces' ends, their middles and the octave boundaries all come by.
        let linear_to_srgb_fast = |v| srgb_by_table(&POW_TABLE, v);
        let mut worst = 0f32;
        let mut v = 0.0030f32;
        while v < 1.2 {
            let (a, b) = (linear_to_srgb(v), linear_to_srgb_fast(v));
            worst = worst.max((a - b).abs());
            v = f32::from_bits(v.to_bits() + 97);
        }
        assert!(worst <= 2e-7, "largest difference {worst}");
        for v in [0.0f32, 1e-9, 0.0031308, 1.0, f32::INFINITY] {
            assert_eq!(linear_to_srgb_fast(v), linear_to_srgb(v), "{v}");
        }
        assert!(linear_to_srgb_fast(f32::NAN).is_nan());
        assert_eq!(ExportCurve::new(1.5).apply(-1.0), 0.0);
        assert_eq!(
            ExportCurve::new(2.0).apply(0.25),
            linear_to_srgb_fast(0.5 / 1.5)
        );
    }
}
