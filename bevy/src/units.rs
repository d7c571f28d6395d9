//! From the project's texel units (irradiance / π; the noon sun on open ground ≈ 1.0) to
//! Bevy's lux, for the lightmap and for the lights that stand for the bake's sun and sky.

use bevy::color::Color;

/// Bevy 0.19's diffuse ambient factor: its ambient light reaches a surface's diffuse colour
/// through `EnvBRDFApprox(diffuse, F_AB(1.0, N·V))`, whose first term is 0.452 for every
/// view angle (the polynomial `F_AB` at perceptual roughness 1; no DFG LUT). A white
/// surface under `GlobalAmbientLight { brightness: b, .. }` shows 0.452 · b.
pub const BEVY_AMBIENT_DIFFUSE: f32 = 0.452;

/// Lux of perpendicular light per unit of texel, when the bake's noon sun (a texel of about
/// 1.0) stands for `sun_lux` (Bevy's `light_consts::lux::DIRECT_SUNLIGHT` is 100,000):
/// `sun_lux / π`. Use it as `StandardMaterial::lightmap_exposure` of lightmapped meshes: a
/// white surface with a texel `v` then shows radiance `v · sun_lux / π`, as it would under
/// `v · sun_lux` lux of perpendicular light (Lambert: radiance = E · albedo / π).
pub fn lux_per_unit(sun_lux: f32) -> f32 {
    sun_lux / std::f32::consts::PI
}

/// The colour and illuminance of a `DirectionalLight` standing for a sun whose texel value
/// at normal incidence is `sun` (RGB; the bake's manifest has it per frame as
/// `sun_color`): `sun_lux` times its luminance, so that an unshadowed white surface facing
/// it shows what its lightmap texel would.
pub fn sun_light(sun_lux: f32, sun: [f32; 3]) -> (Color, f32) {
    let l = luminance(sun);
    (chromaticity(sun), sun_lux * l)
}

/// The colour and brightness of a `GlobalAmbientLight` standing for a sky whose radiance,
/// cosine-weighted over the upper hemisphere, is `sky` in texel units (what an open flat
/// texel receives from it): `lux_per_unit(sun_lux) · luminance(sky)`, divided by Bevy's
/// [`BEVY_AMBIENT_DIFFUSE`] so that a white surface shows what its lightmap texel would.
/// For the bake's sky (see docs/BAKE.md), that radiance is the zenith colour plus a quarter
/// of the sun-side glow: [`bake_sky`].
pub fn sky_light(sun_lux: f32, sky: [f32; 3]) -> (Color, f32) {
    (
        chromaticity(sky),
        lux_per_unit(sun_lux) * luminance(sky) / BEVY_AMBIENT_DIFFUSE,
    )
}

/// The bake's sky radiance cosine-weighted over the upper hemisphere, from the manifest's
/// `sky_color` (the zenith-coloured dome) and `sky_horizon_sun_side` (the dome plus the
/// sun-side glow): the glow is weighted by `max(0, cos Δazimuth)²` over eight equal sky
/// patches, whose mean is ¼.
pub fn bake_sky(zenith: [f32; 3], horizon_sun_side: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|c| zenith[c] + 0.25 * (horizon_sun_side[c] - zenith[c]).max(0.0))
}

/// Rec. 709 luminance of linear RGB.
fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// `c` scaled to unit luminance (white for black), as Bevy's light colours are.
fn chromaticity(c: [f32; 3]) -> Color {
    let l = luminance(c);
    if l <= 0.0 {
        return Color::WHITE;
    }
    Color::linear_rgb(c[0] / l, c[1] / l, c[2] / l)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy::color::LinearRgba;

    #[test]
    fn light_colours_have_unit_luminance_and_carry_the_level_in_the_intensity() {
        let (c, e) = sun_light(100_000.0, [0.9, 0.8, 0.6]);
        let c = LinearRgba::from(c);
        let l = 0.2126 * c.red + 0.7152 * c.green + 0.0722 * c.blue;
        assert!((l - 1.0).abs() < 1e-6);
        assert!((e - 100_000.0 * luminance([0.9, 0.8, 0.6])).abs() < 1e-2);
        // Night: no light, a harmless colour.
        assert_eq!(sun_light(100_000.0, [0.0; 3]), (Color::WHITE, 0.0));
    }

    #[test]
    fn the_sky_light_undoes_bevys_ambient_factor() {
        let (_, b) = sky_light(100_000.0, [0.1, 0.1, 0.1]);
        // What a white surface shows (before exposure), against the texel's radiance.
        let shown = BEVY_AMBIENT_DIFFUSE * b;
        let texel = lux_per_unit(100_000.0) * 0.1;
        assert!((shown / texel - 1.0).abs() < 1e-5);
    }
}
