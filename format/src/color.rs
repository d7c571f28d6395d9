//! The colour transform: YCoCg, so that luma and chroma can be quantised (and modelled in
//! time) separately. Applied to coded values; exactly invertible in real arithmetic.

#[inline]
/// RGB to YCoCg (Y = (R + 2G + B) / 4).
pub fn rgb_to_ycocg([r, g, b]: [f32; 3]) -> [f32; 3] {
    [
        0.25 * r + 0.5 * g + 0.25 * b,
        0.5 * r - 0.5 * b,
        -0.25 * r + 0.5 * g - 0.25 * b,
    ]
}

#[inline]
/// YCoCg back to RGB: the exact inverse of [`rgb_to_ycocg`] in real arithmetic.
pub fn ycocg_to_rgb([y, co, cg]: [f32; 3]) -> [f32; 3] {
    let t = y - cg;
    [t + co, y + cg, t - co]
}
