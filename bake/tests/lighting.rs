//! Known answers for the terrain lighting (issue: sample scenes).

use std::f64::consts::PI;

use vbim_bake::SunState;
use vbim_bake::{light_frame, light_with_sun, sun_visibility};
use vbim_bake::{HeightField, Precomputed, Scene};

fn field(w: usize, h: usize, cell: f64, f: impl Fn(usize, usize) -> f32) -> HeightField {
    HeightField {
        w,
        h,
        cell_x: cell,
        cell_y: cell,
        z: (0..w * h).map(|i| f(i % w, i / w)).collect(),
    }
}

fn scene() -> Scene {
    let mut s = Scene::with_heightfield("synthetic");
    s.frames = 24;
    s
}

/// A sun at `elev_deg` towards map azimuth `az` (0 = +x, π/2 = +y), white, strength 1.
fn sun(elev_deg: f64, az: f64) -> SunState {
    let e = elev_deg.to_radians();
    SunState {
        elevation: e,
        azimuth_north: 0.0,
        dir: [e.cos() * az.cos(), e.cos() * az.sin(), e.sin()],
        color: [1.0; 3],
    }
}

#[test]
fn flat_open_plane_sees_the_whole_sky_and_is_fully_open() {
    let hf = field(32, 32, 30.0, |_, _| 100.0);
    let pre = Precomputed::compute(hf, &scene());
    for i in 0..32 * 32 {
        assert!(
            (pre.sky.total[i] as f64 - PI).abs() < 1e-4,
            "I = {}",
            pre.sky.total[i]
        );
        assert!(
            (pre.obscurance[i] - 1.0).abs() < 1e-5,
            "W = {}",
            pre.obscurance[i]
        );
    }
}

#[test]
fn without_albedo_the_sky_term_is_radiance_times_visibility() {
    let hf = field(48, 48, 30.0, |x, y| {
        ((x as f32 * 0.4).sin() * (y as f32 * 0.3).cos()) * 150.0 + 300.0
    });
    let mut s = scene();
    s.albedo = 0.0;
    s.sky.glow = 0.0;
    s.sky.ambient = 0.0;
    s.obscurance.modulate_interreflection = false;
    let pre = Precomputed::compute(hf, &s);
    let night = sun(-20.0, 0.0);
    let mut out = vec![0f32; 48 * 48 * 3];
    light_with_sun(&pre, &s, &night, 0, &mut out);
    let l = vbim_bake::sky_model(&s).base(night.elevation);
    for i in 0..48 * 48 {
        for c in 0..3 {
            let want = l[c] * pre.sky.total[i] as f64 / PI;
            let got = out[i * 3 + c] as f64;
            assert!(
                (got - want).abs() <= 1e-6 * want.max(1e-9) + 1e-12,
                "texel {i}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn step_shadow_half_contour_sits_at_h_over_tan_elevation() {
    // Low ground for x < 200, a plateau 60 m higher from x = 200; cells of 10 m.
    let (w, step_x, h, cell) = (256usize, 200usize, 60.0f32, 10.0);
    let hf = field(w, 8, cell, |x, _| if x >= step_x { h } else { 0.0 });
    let mut s = scene();
    s.sun.angular_diameter_deg = 0.5;
    for elev in [3.0f64, 5.0] {
        let pre = Precomputed::compute(hf.clone(), &s);
        // The sun stands over the plateau (towards +x): the step's shadow falls towards −x.
        let y = 4;
        let o: Vec<f64> = (0..step_x)
            .map(|x| {
                let phi = pre.horizons.at(y * w + x, 0.0) as f64;
                sun_visibility(elev.to_radians(), 0.5f64.to_radians(), phi)
            })
            .collect();
        // The O = 0.5 crossing, interpolated between texels.
        let mut crossing = None;
        for x in 0..step_x - 1 {
            if (o[x] - 0.5) * (o[x + 1] - 0.5) <= 0.0 && o[x] != o[x + 1] {
                crossing = Some(x as f64 + (0.5 - o[x]) / (o[x + 1] - o[x]));
                break;
            }
        }
        let crossing = crossing.expect("a shadow edge on the low ground");
        // The step's top edge is at x = step_x; the shadow edge is h / tan(e) before it.
        let want = step_x as f64 - (h as f64 / elev.to_radians().tan()) / cell;
        assert!(
            (crossing - want).abs() <= 1.0,
            "elevation {elev}°: edge at {crossing}, expected {want}"
        );
    }
}

#[test]
fn a_sun_below_the_horizon_gives_no_direct_light() {
    let hf = field(32, 32, 30.0, |x, y| (x * 13 % 7 + y * 3 % 5) as f32 * 20.0);
    let mut s = scene();
    s.sky.strength = 0.0;
    s.sky.glow = 0.0;
    s.sky.night = 0.0;
    s.sky.ambient = 0.0;
    let pre = Precomputed::compute(hf, &s);
    let mut out = vec![0f32; 32 * 32 * 3];
    light_with_sun(&pre, &s, &sun(-1.0, 1.0), 0, &mut out);
    assert!(
        out.iter().all(|&v| v == 0.0),
        "light with the sun below the horizon"
    );
    light_with_sun(&pre, &s, &sun(20.0, 1.0), 0, &mut out);
    assert!(out.iter().any(|&v| v > 0.1), "and light with it above");
}

#[test]
fn horizons_are_clamped_to_the_normals_hemisphere_on_steep_slopes() {
    // A plane rising 60° towards +x: downhill there is no terrain, yet the horizon may not
    // drop below the tangent plane; uphill it is the plane itself.
    let slope = 60f64.to_radians().tan() as f32;
    let hf = field(48, 48, 10.0, |x, _| x as f32 * 10.0 * slope);
    let pre = Precomputed::compute(hf, &scene());
    let n = pre.horizons.azimuths;
    for y in 8..40 {
        for x in 8..40 {
            let i = y * 48 + x;
            let down = pre.horizons.plane(n / 2)[i] as f64; // towards −x
            let up = pre.horizons.plane(0)[i] as f64; // towards +x
            assert!(
                (down + 60f64.to_radians()).abs() < 1e-3,
                "downhill horizon {}",
                down.to_degrees()
            );
            assert!(
                (up - 60f64.to_radians()).abs() < 1e-2,
                "uphill horizon {}",
                up.to_degrees()
            );
            assert!(
                (pre.sky.total[i] as f64 - PI).abs() < 0.03 * PI,
                "I = {}",
                pre.sky.total[i]
            );
        }
    }
    // A sun behind the slope (20° high, towards +x, the slope faces −x) lights none of it.
    let mut out = vec![0f32; 48 * 48 * 3];
    let mut s = scene();
    s.sky.strength = 0.0;
    s.sky.glow = 0.0;
    s.sky.night = 0.0;
    s.sky.ambient = 0.0;
    light_with_sun(&pre, &s, &sun(20.0, 0.0), 0, &mut out);
    assert!(out[(24 * 48 + 24) * 3] == 0.0);
}

fn real_scene(size: usize) -> Scene {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples");
    let mut s = Scene::load(&root.join("jacksboro.toml")).unwrap();
    s.size = size;
    s.frames = 48;
    s
}

#[test]
fn a_real_day_is_never_negative_or_nan_and_night_is_dark() {
    for clouds in [false, true] {
        let mut s = real_scene(64);
        s.clouds.enabled = clouds;
        let pre = Precomputed::compute(vbim_bake::load_terrain(&s).unwrap(), &s);
        let mut out = vec![0f32; 64 * 64 * 3];
        let mut means = Vec::new();
        for i in 0..s.frames {
            light_frame(&pre, &s, i, &mut out);
            assert!(
                out.iter().all(|v| v.is_finite() && *v >= 0.0),
                "frame {i} (clouds {clouds})"
            );
            means.push(out.iter().map(|&v| v as f64).sum::<f64>() / out.len() as f64);
        }
        let (midnight, noon) = (means[0], means[s.frames / 2]);
        assert!(midnight < noon / 10.0, "night {midnight} vs noon {noon}");
        assert!(
            noon > 0.5 && noon < 1.6,
            "noon on open terrain is about 1: {noon}"
        );
    }
}
