//! Sun and sky over the day: solar geometry from latitude, day of year and solar time, and
//! colours from atmospheric extinction along the air mass (`docs/BAKE.md`, "Sun and sky").

/// The sun's position and colour at one moment.
#[derive(Clone, Copy, Debug)]
pub struct SunState {
    /// Elevation of the disc's centre above the horizon, radians (negative at night).
    pub elevation: f64,
    /// Azimuth from north, clockwise (east = π/2), radians.
    pub azimuth_north: f64,
    /// Unit vector towards the sun in the map frame (x east, y south, z up).
    pub dir: [f64; 3],
    /// Texel value of the direct sun on a surface facing it, unshadowed, RGB.
    pub color: [f64; 3],
}

/// Extinction per unit air mass (Rayleigh-like: blue scatters most), per RGB channel.
pub const EXTINCTION: [f64; 3] = [0.12, 0.21, 0.42];

/// The turbidity at which [`EXTINCTION`] holds: a weather's sun at this turbidity (the
/// default) is the sector sky's, and a hazier or clearer one differs by its aerosols alone.
pub const REFERENCE_TURBIDITY: f64 = 2.5;

/// Wavelengths standing for the R, G and B channels, µm.
const WAVELENGTHS: [f64; 3] = [0.65, 0.55, 0.45];

/// The aerosol extinction per unit air mass that turbidity `t` adds to [`EXTINCTION`]
/// (negative below [`REFERENCE_TURBIDITY`]): Preetham et al.'s Ångström coefficient
/// β = 0.04608 T − 0.04586, over λ^1.3 at each channel's wavelength. Haze dims the blue end
/// most, less steeply than the air's own (Rayleigh) scattering.
pub fn aerosol_extinction(t: f64) -> [f64; 3] {
    let db = 0.04608 * (t - REFERENCE_TURBIDITY);
    WAVELENGTHS.map(|l| db * l.powf(-1.3))
}

/// `sun` seen through the aerosols of turbidity `t`: its colour dimmed (or, below
/// [`REFERENCE_TURBIDITY`], brightened) by [`aerosol_extinction`] along its air mass.
pub fn hazed(sun: SunState, t: f64) -> SunState {
    let m = air_mass(sun.elevation);
    let dk = aerosol_extinction(t);
    SunState {
        color: std::array::from_fn(|c| sun.color[c] * (-dk[c] * m).exp()),
        ..sun
    }
}

/// Air mass along the line of sight at elevation `e` (Kasten & Young 1989), finite at and
/// below the horizon.
pub fn air_mass(e: f64) -> f64 {
    let deg = e.to_degrees().max(-0.5);
    1.0 / (deg.to_radians().sin().max(-0.0087) + 0.50572 * (deg + 6.07995).powf(-1.6364))
}

/// Solar position for `latitude_deg`, `day_of_year` (1–365) and local solar time in hours.
pub fn sun_at(latitude_deg: f64, day_of_year: f64, hours: f64, strength: f64) -> SunState {
    let lat = latitude_deg.to_radians();
    // Declination (Cooper's approximation), hour angle 15° per hour from solar noon.
    let decl =
        (-23.44f64).to_radians() * (std::f64::consts::TAU * (day_of_year + 10.0) / 365.0).cos();
    let h = (15.0 * (hours - 12.0)).to_radians();
    let sin_e = lat.sin() * decl.sin() + lat.cos() * decl.cos() * h.cos();
    let e = sin_e.clamp(-1.0, 1.0).asin();
    let az = (h.sin()).atan2(h.cos() * lat.sin() - decl.tan() * lat.cos()) + std::f64::consts::PI;
    let (ce, se) = (e.cos(), e.sin());
    let dir = [az.sin() * ce, -az.cos() * ce, se];
    let m = air_mass(e);
    let color = EXTINCTION.map(|k| strength * (-k * m).exp());
    SunState {
        elevation: e,
        azimuth_north: az,
        dir,
        color,
    }
}

/// Sky radiance model: a zenith-coloured dome that brightens with the sun, a warm glow on
/// the sun's side around sunrise and sunset, and a faint night floor (airglow, starlight).
#[derive(Clone, Copy, Debug)]
pub struct SkyModel {
    /// Zenith sky radiance at full day (texel units: the value it gives a flat open texel).
    pub strength: f64,
    /// Sun-side glow at sunrise and sunset.
    pub glow: f64,
    /// Night sky radiance.
    pub night: f64,
}

pub const SKY_BLUE: [f64; 3] = [0.42, 0.62, 1.0];
pub const GLOW: [f64; 3] = [1.0, 0.55, 0.28];
pub const NIGHT: [f64; 3] = [0.55, 0.7, 1.0];

fn smoothstep(a: f64, b: f64, x: f64) -> f64 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl SkyModel {
    /// Uniform part of the sky radiance (RGB) at sun elevation `e`.
    pub fn base(&self, e: f64) -> [f64; 3] {
        let deg = e.to_degrees();
        // Day: grows through twilight (sun 18° below to 10° above), then with √sin e.
        let day = smoothstep(-18.0, 10.0, deg).powi(3) * (0.55 + 0.45 * e.sin().max(0.0).sqrt());
        let mut c = [0.0; 3];
        for i in 0..3 {
            c[i] = self.strength * SKY_BLUE[i] * day + self.night * NIGHT[i];
        }
        c
    }

    /// Extra radiance of the sky on the sun's side, before the per-sector weight.
    pub fn glow(&self, e: f64) -> [f64; 3] {
        let deg = e.to_degrees();
        let g = self.glow * (-((deg - 2.0) / 7.0).powi(2)).exp();
        GLOW.map(|c| c * g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noon_is_south_and_highest_midnight_below() {
        let noon = sun_at(36.6, 172.0, 12.0, 1.0);
        // Haze: the reference turbidity leaves the sun as it is; more dims it, the blue
        // most, and the more so the lower the sun.
        assert_eq!(hazed(noon, REFERENCE_TURBIDITY).color, noon.color);
        let hazy = hazed(noon, 6.0);
        let ratio = |s: SunState, c: usize| s.color[c] / noon.color[c];
        assert!(ratio(hazy, 2) < ratio(hazy, 1) && ratio(hazy, 1) < ratio(hazy, 0));
        assert!(
            ratio(hazy, 0) < 0.9 && ratio(hazy, 2) > 0.6,
            "{:?}",
            hazy.color
        );
        let low = sun_at(36.6, 172.0, 18.5, 1.0);
        assert!(hazed(low, 6.0).color[1] / low.color[1] < ratio(hazy, 1));
        assert!(hazed(noon, 1.7).color[2] > noon.color[2]);
        assert!((noon.azimuth_north.to_degrees() - 180.0).abs() < 1e-6);
        assert!((noon.elevation.to_degrees() - (90.0 - 36.6 + 23.44)).abs() < 0.1);
        assert!(sun_at(36.6, 172.0, 0.0, 1.0).elevation < 0.0);
        let morning = sun_at(36.6, 172.0, 8.0, 1.0);
        assert!(morning.dir[0] > 0.0, "morning sun in the east");
        let evening = sun_at(36.6, 172.0, 19.5, 1.0);
        assert!(
            evening.color[0] > 2.0 * evening.color[2],
            "sunset is red: {:?}",
            evening.color
        );
    }
}
