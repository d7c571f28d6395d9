//! The analytic sky of a weather: the radiance of the whole dome for one sun, the sky a
//! viewer sees (the sky track) and the light the ground gets from it (`light`, through the
//! sector tables of `sky`). `docs/BAKE.md`, "Weathers and the analytic sky", gives every
//! equation.
//!
//! - **Clear** (cover 0): Preetham, Shirley & Smits (1999), "A practical analytic model for
//!   daylight": the Perez distribution F(θ, γ) of luminance Y and chromaticity x, y, with
//!   coefficients linear in the turbidity T and the zenith values from the sun's zenith
//!   angle θs. Its luminance is in kcd/m²; the bake converts it into texel units with the
//!   sun's own photometric scale (`sun.strength` outside the atmosphere is 127.5 klux), so
//!   sun and sky keep the ratio daylight has.
//! - **Overcast** (cover 1): the CIE standard overcast sky, L(θ) = Lz (1 + 2 cos θ) / 3 (the
//!   zenith three times the horizon), grey, with the horizontal irradiance a share
//!   [`OVERCAST_SHARE`] of what the clear sky and sun together give at that moment.
//! - **In between**: L = (1 − c) L_clear + c L_overcast for cover c; the direct sun is
//!   shadowed by the moving cloud layer of coverage c and fades out as c goes from 0.8 to 1.
//! - **Twilight and night**: Preetham's model holds for the sun above the horizon. Below it
//!   the dome keeps the shape and colour of a sun on the horizon and its level falls by a
//!   decade every 2.7° (10^(0.37 e), about what civil and nautical twilight measure), over
//!   the scene's night floor (`sky.night`, airglow and starlight).

use crate::sun::SunState;

/// The overcast sky's horizontal irradiance as a share of the clear day's (sun + sky) at
/// the same moment: thick cloud passes about a third of the light on.
pub const OVERCAST_SHARE: f64 = 0.3;

/// Night sky colour (bluish), as the sector sky uses.
const NIGHT: [f64; 3] = crate::sun::NIGHT;

/// Illuminance of the sun outside the atmosphere, klux: `sun.strength` stands for it.
const SOLAR_KLUX: f64 = 127.5;

/// Twilight: decades of sky luminance lost per degree of sun below the horizon.
const TWILIGHT_DECADES_PER_DEG: f64 = 0.37;

/// A weather's sky parameters: cloud cover (0 clear to 1 overcast) and turbidity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkyWeather {
    pub cover: f64,
    pub turbidity: f64,
}

/// The share of the direct sun that the weather's cloud deck lets through before the
/// moving shadows: 1 up to cover 0.8, fading to 0 at overcast.
pub fn direct_share(cover: f64) -> f64 {
    let t = ((cover - 0.8) / 0.2).clamp(0.0, 1.0);
    1.0 - t * t * (3.0 - 2.0 * t)
}

/// Perez et al.'s five coefficients.
#[derive(Clone, Copy, Debug)]
struct Perez([f64; 5]);

impl Perez {
    /// F(θ, γ) for the view's zenith angle cosine `cos_t` and its angle γ to the sun.
    fn f(&self, cos_t: f64, gamma: f64) -> f64 {
        let [a, b, c, d, e] = self.0;
        let cg = gamma.cos();
        (1.0 + a * (b / cos_t.max(0.01)).exp()) * (1.0 + c * (d * gamma).exp() + e * cg * cg)
    }
}

/// The clear sky of Preetham et al. for one sun: Y (kcd/m²), x and y over the dome.
#[derive(Clone, Copy, Debug)]
struct Preetham {
    coef: [Perez; 3],
    /// Zenith Y, x, y divided by F(0, θs): the factor each channel's F is scaled by.
    scale: [f64; 3],
    sun: [f64; 3],
}

impl Preetham {
    /// For a sun at zenith angle `theta_s` (clamped to the horizon) towards `sun`.
    fn new(theta_s: f64, sun: [f64; 3], t: f64) -> Preetham {
        let ts = theta_s.clamp(0.0, std::f64::consts::FRAC_PI_2);
        let lum = Perez([
            0.1787 * t - 1.4630,
            -0.3554 * t + 0.4275,
            -0.0227 * t + 5.3251,
            0.1206 * t - 2.5771,
            -0.0670 * t + 0.3703,
        ]);
        let x = Perez([
            -0.0193 * t - 0.2592,
            -0.0665 * t + 0.0008,
            -0.0004 * t + 0.2125,
            -0.0641 * t - 0.8989,
            -0.0033 * t + 0.0452,
        ]);
        let y = Perez([
            -0.0167 * t - 0.2608,
            -0.0950 * t + 0.0092,
            -0.0079 * t + 0.2102,
            -0.0441 * t - 1.6537,
            -0.0109 * t + 0.0529,
        ]);
        let chi = (4.0 / 9.0 - t / 120.0) * (std::f64::consts::PI - 2.0 * ts);
        let yz = ((4.0453 * t - 4.9710) * chi.tan() - 0.2155 * t + 2.4192).max(0.0);
        let (t2, s1, s2, s3) = (t * t, ts, ts * ts, ts * ts * ts);
        let xz = t2 * (0.00166 * s3 - 0.00375 * s2 + 0.00209 * s1)
            + t * (-0.02903 * s3 + 0.06377 * s2 - 0.03202 * s1 + 0.00394)
            + (0.11693 * s3 - 0.21196 * s2 + 0.06052 * s1 + 0.25886);
        let yzc = t2 * (0.00275 * s3 - 0.00610 * s2 + 0.00317 * s1)
            + t * (-0.04214 * s3 + 0.08970 * s2 - 0.04153 * s1 + 0.00516)
            + (0.15346 * s3 - 0.26756 * s2 + 0.06670 * s1 + 0.26688);
        let coef = [lum, x, y];
        let zen = [yz, xz, yzc];
        let scale = [0, 1, 2].map(|k| zen[k] / coef[k].f(1.0, ts));
        Preetham { coef, scale, sun }
    }

    /// Linear sRGB luminance-scaled radiance (kcd/m²) towards the unit vector `v` (z ≥ 0).
    fn rgb(&self, v: [f64; 3]) -> [f64; 3] {
        let cos_g = (v[0] * self.sun[0] + v[1] * self.sun[1] + v[2] * self.sun[2]).clamp(-1.0, 1.0);
        let gamma = cos_g.acos();
        let [yl, x, y] = [0, 1, 2].map(|k| self.scale[k] * self.coef[k].f(v[2], gamma));
        xyy_to_rgb(x, y, yl.max(0.0))
    }
}

/// CIE xyY to linear sRGB (D65).
fn xyy_to_rgb(x: f64, y: f64, lum: f64) -> [f64; 3] {
    if y <= 1e-6 {
        return [0.0; 3];
    }
    let cx = x / y * lum;
    let cz = (1.0 - x - y) / y * lum;
    [
        3.2406 * cx - 1.5372 * lum - 0.4986 * cz,
        -0.9689 * cx + 1.8758 * lum + 0.0415 * cz,
        0.0557 * cx - 0.2040 * lum + 1.0570 * cz,
    ]
    .map(|c| c.max(0.0))
}

/// The sky dome of one weather at one moment, in texel units (radiance such that a uniform
/// dome of value L gives an open flat texel the value L).
#[derive(Clone, Copy, Debug)]
pub struct SkyDome {
    clear: Preetham,
    /// kcd/m² → texel units, including the twilight fall-off.
    clear_scale: f64,
    cover: f64,
    /// The overcast sky's zenith radiance (grey), texel units.
    overcast_zenith: f64,
    night: [f64; 3],
}

/// Unit vector for map-frame azimuth `a` (from +x east towards +y south) and elevation `e`.
pub fn direction(a: f64, e: f64) -> [f64; 3] {
    let (se, ce) = e.sin_cos();
    [a.cos() * ce, a.sin() * ce, se]
}

impl SkyDome {
    /// The dome under `sun` (whose `color` is the direct sun after the atmosphere, the
    /// scene's `sun.strength` outside it) for `weather`, over a night floor `night`.
    pub fn new(sun: &SunState, sun_strength: f64, weather: SkyWeather, night: f64) -> SkyDome {
        let theta_s = std::f64::consts::FRAC_PI_2 - sun.elevation;
        // On the horizon and below, the sky keeps the shape of a sun on the horizon.
        let mut sdir = sun.dir;
        if sun.elevation < 0.0 {
            let h = (sdir[0] * sdir[0] + sdir[1] * sdir[1]).sqrt().max(1e-9);
            sdir = [sdir[0] / h, sdir[1] / h, 0.0];
        }
        let clear = Preetham::new(theta_s, sdir, weather.turbidity);
        let twilight = if sun.elevation < 0.0 {
            10f64.powf(TWILIGHT_DECADES_PER_DEG * sun.elevation.to_degrees())
        } else {
            1.0
        };
        let clear_scale = twilight * std::f64::consts::PI * sun_strength / SOLAR_KLUX;
        let mut dome = SkyDome {
            clear,
            clear_scale,
            cover: weather.cover.clamp(0.0, 1.0),
            overcast_zenith: 0.0,
            night: NIGHT.map(|c| c * night),
        };
        // The overcast level: a share of the clear day's horizontal light (sky + sun).
        let lum = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let clear_sky = lum(dome.clear_radiance_horizontal());
        let direct = lum(sun.color) * sun.elevation.sin().max(0.0);
        // CIE overcast: E/π = (7/9) Lz.
        dome.overcast_zenith = OVERCAST_SHARE * (clear_sky + direct) * 9.0 / 7.0;
        dome
    }

    fn clear_radiance(&self, v: [f64; 3]) -> [f64; 3] {
        self.clear.rgb(v).map(|c| c * self.clear_scale)
    }

    /// The radiance towards `v` (unit, map frame); below the horizon the horizon's.
    pub fn radiance(&self, v: [f64; 3]) -> [f64; 3] {
        let mut v = v;
        if v[2] < 0.0 {
            let h = (v[0] * v[0] + v[1] * v[1]).sqrt().max(1e-9);
            v = [v[0] / h, v[1] / h, 0.0];
        }
        let clear = self.clear_radiance(v);
        let oc = self.overcast_zenith * (1.0 + 2.0 * v[2]) / 3.0;
        let c = self.cover;
        [0, 1, 2].map(|k| (1.0 - c) * clear[k] + c * oc + self.night[k])
    }

    /// E/π of the clear part on an open flat texel (the cosine-weighted mean radiance).
    fn clear_radiance_horizontal(&self) -> [f64; 3] {
        cosine_mean(|v| self.clear_radiance(v))
    }

    /// E/π of the whole dome on an open flat texel.
    pub fn horizontal(&self) -> [f64; 3] {
        cosine_mean(|v| self.radiance(v))
    }
}

/// ∫ L(v) cos θ dΩ / π over the upper hemisphere, by the midpoint rule in (azimuth, sin²e)
/// (equal cosine-weighted cells).
fn cosine_mean(l: impl Fn([f64; 3]) -> [f64; 3]) -> [f64; 3] {
    let (na, ne) = (48, 24);
    let mut sum = [0.0; 3];
    for j in 0..ne {
        // Cells of equal cos-weighted solid angle: sin²e uniform.
        let s2 = (j as f64 + 0.5) / ne as f64;
        let e = s2.sqrt().asin();
        for i in 0..na {
            let a = std::f64::consts::TAU * (i as f64 + 0.5) / na as f64;
            let r = l(direction(a, e));
            for k in 0..3 {
                sum[k] += r[k];
            }
        }
    }
    sum.map(|s| s / (na * ne) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sun::sun_at;

    fn dome(hours: f64, cover: f64) -> (SunState, SkyDome) {
        let sun = sun_at(40.0, 172.0, hours, 1.15);
        let w = SkyWeather {
            cover,
            turbidity: 2.5,
        };
        (sun, SkyDome::new(&sun, 1.15, w, 0.0))
    }

    #[test]
    fn the_overcast_zenith_is_three_times_the_horizon_and_has_its_share() {
        let (sun, d) = dome(12.0, 1.0);
        let z = d.radiance([0.0, 0.0, 1.0]);
        let h = d.radiance(direction(1.0, 0.0));
        assert!((z[1] / h[1] - 3.0).abs() < 1e-9, "{z:?} {h:?}");
        let (_, clear) = dome(12.0, 0.0);
        let lum = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let day = lum(clear.horizontal()) + lum(sun.color) * sun.elevation.sin();
        let got = lum(d.horizontal());
        assert!((got / day - OVERCAST_SHARE).abs() < 0.01, "{got} of {day}");
    }

    #[test]
    fn the_clear_sky_is_brightest_near_the_sun_blue_overhead_and_symmetric_about_it() {
        let (sun, d) = dome(15.0, 0.0);
        let sun_az = sun.dir[1].atan2(sun.dir[0]);
        let near = d.radiance(direction(sun_az, sun.elevation + 0.15));
        let away = d.radiance(direction(sun_az + std::f64::consts::PI, 0.6));
        assert!(near[1] > 2.0 * away[1], "{near:?} {away:?}");
        let zen = d.radiance([0.0, 0.0, 1.0]);
        assert!(zen[2] > zen[0], "a blue zenith: {zen:?}");
        let a = d.radiance(direction(sun_az + 0.7, 0.3));
        let b = d.radiance(direction(sun_az - 0.7, 0.3));
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-12 * a[k].max(1e-30) + 1e-15);
        }
        // The clear day's sky against its sun: daylight's share, about a sixth of the
        // horizontal light at a high sun.
        let lum = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let (sun, d) = dome(12.0, 0.0);
        let share =
            lum(d.horizontal()) / (lum(d.horizontal()) + lum(sun.color) * sun.elevation.sin());
        assert!((0.08..0.3).contains(&share), "sky share {share}");
    }

    #[test]
    fn twilight_falls_by_decades_and_night_keeps_its_floor() {
        let lum = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let at = |e_deg: f64| {
            let mut sun = sun_at(40.0, 172.0, 19.0, 1.15);
            sun.elevation = e_deg.to_radians();
            sun.dir = direction(0.3, sun.elevation);
            let w = SkyWeather {
                cover: 0.0,
                turbidity: 2.5,
            };
            lum(SkyDome::new(&sun, 1.15, w, 3e-4).horizontal())
        };
        let (e0, e6, e18) = (at(-0.01), at(-6.0), at(-18.0));
        assert!(e0 > 50.0 * e6 && e6 > e18, "{e0} {e6} {e18}");
        let floor = 3e-4 * lum(NIGHT);
        assert!(
            e18 > floor && e18 < 1.2 * floor,
            "the night floor: {e18} over {floor}"
        );
        assert!(at(5.0) > e0, "brighter with the sun up");
    }
}
