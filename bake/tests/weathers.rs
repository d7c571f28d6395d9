//! Weathers: the ground is lit by the very sky the bake writes into the sky track, and a
//! bake with weathers writes a day and a sky track per weather.

use vbim_bake::{
    bake, light_with_sun_in, sky_map, texel_direction, BakeOptions, FrameFormat, HeightField,
    Manifest, Precomputed, Scene, SunState, WeatherLight, WeatherParams, SKY_MAP_WIDTH,
};

fn field(n: usize, f: impl Fn(usize, usize) -> f32) -> HeightField {
    HeightField {
        w: n,
        h: n,
        cell_x: 30.0,
        cell_y: 30.0,
        z: (0..n * n).map(|i| f(i % n, i / n)).collect(),
    }
}

fn weather(name: &str, cover: f64) -> WeatherParams {
    WeatherParams {
        name: name.into(),
        cover,
        turbidity: 2.5,
    }
}

fn sun(elev_deg: f64, az: f64) -> SunState {
    let e = elev_deg.to_radians();
    SunState {
        elevation: e,
        azimuth_north: 0.0,
        dir: [e.cos() * az.cos(), e.cos() * az.sin(), e.sin()],
        color: [0.9, 0.85, 0.8],
    }
}

/// On an open flat plane the sky term is the dome's cosine-weighted mean (no
/// interreflection: the plane sees no ground), plus the ambient floor: the ground and the
/// sky track agree. With the sun up, the sun adds its colour times sin e, except under an
/// overcast sky, which lets no sun through.
#[test]
fn an_open_plane_gets_the_sky_it_sees_and_the_sun_the_weather_lets_through() {
    let mut scene = Scene::with_heightfield("synthetic");
    scene.frames = 24;
    let pre = Precomputed::compute(field(32, |_, _| 100.0), &scene);
    let mut out = vec![0f32; 32 * 32 * 3];
    for (cover, elev) in [(0.0, 40.0), (0.0, -3.0), (0.5, 25.0), (1.0, 60.0)] {
        let w = weather("w", cover);
        let light = WeatherLight::new(&pre.hf, &scene, &w);
        let s = sun(elev, 0.7);
        let dome = light.dome(&scene, &s);
        light_with_sun_in(&pre, &scene, Some(&light), &s, 0, &mut out);
        let sky = dome.horizontal();
        let direct = vbim_bake::direct_share(cover) * elev.to_radians().sin().max(0.0);
        // Without clouds every texel is the same; with them, the least shadowed one.
        for c in 0..3 {
            let want = s.color[c] * direct + sky[c] + scene.sky.ambient;
            let got = (0..32 * 32)
                .map(|p| out[p * 3 + c] as f64)
                .fold(0.0, f64::max);
            assert!(
                (got - want).abs() <= 0.01 * want + 1e-6,
                "cover {cover}, sun {elev}°, channel {c}: {got} against {want}"
            );
        }
        if cover == 1.0 {
            let (lo, hi) = out
                .chunks_exact(3)
                .fold((f32::MAX, 0f32), |(a, b), p| (a.min(p[1]), b.max(p[1])));
            assert!(hi - lo < 1e-6, "overcast: no shadows ({lo}–{hi})");
        }
    }
}

/// A texel at the bottom of a trench sees only the high sky. Under a clear sky away from
/// the sun (darker overhead than at the horizon) its direct sky per unit of visibility is
/// less than an open texel's: the sector sky weighs the sky the texel sees.
#[test]
fn a_trench_sees_the_darker_high_sky() {
    let mut scene = Scene::with_heightfield("synthetic");
    scene.frames = 24;
    scene.albedo = 0.0;
    scene.sky.ambient = 0.0;
    // A trench along y, 3 cells wide, 1.5 km deep.
    let pre = Precomputed::compute(
        field(48, |x, _| if (22..25).contains(&x) { 0.0 } else { 1500.0 }),
        &scene,
    );
    let light = WeatherLight::new(&pre.hf, &scene, &weather("clear", 0.0));
    let s = sun(-2.0, 0.0);
    let mut out = vec![0f32; 48 * 48 * 3];
    light_with_sun_in(&pre, &scene, Some(&light), &s, 0, &mut out);
    let (open, trench) = (24 * 48 + 5, 24 * 48 + 23);
    let per_visibility = |p: usize| out[p * 3 + 1] as f64 / pre.sky.total[p] as f64;
    assert!(pre.sky.total[trench] < 0.5 * pre.sky.total[open]);
    assert!(
        per_visibility(trench) < 0.95 * per_visibility(open),
        "trench {} against open {}",
        per_visibility(trench),
        per_visibility(open)
    );
}

/// A bake with weathers: a folder per weather with its day, and its sky track whose
/// manifest says what it is, whose timing is the day's and whose maps are the dome.
#[test]
fn a_bake_with_weathers_writes_a_day_and_a_sky_per_weather() {
    let dir = tempfile::tempdir().unwrap();
    let hf = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../samples/dem/jacksboro_fault_mpl.png"
    );
    let mut scene = Scene::with_heightfield(hf);
    scene.size = 24;
    scene.frames = 8;
    scene.weathers = vec![weather("clear", 0.0), weather("overcast", 1.0)];
    scene.validate().unwrap();
    let out = dir.path().join("out");
    let opts = BakeOptions {
        out: out.clone(),
        format: FrameFormat::Exr,
        use_cache: false,
    };
    let s = bake(&scene, &opts, &|_, _, _| {}).unwrap();
    assert_eq!(s.weathers.len(), 2);
    let package = std::fs::read_to_string(s.package.as_ref().unwrap()).unwrap();
    let package = vbim_format::package::Package::parse(&package).unwrap();
    assert_eq!(package.weathers[1].name, "overcast");
    assert_eq!(package.weathers[1].sky.as_deref(), Some("overcast/sky"));
    for w in &s.weathers {
        let day = Manifest::read(&w.manifest).unwrap();
        let sky = Manifest::read(&w.sky_manifest).unwrap();
        assert_eq!(day.weather.as_deref(), Some(w.name.as_str()));
        assert_eq!(day.sky.as_deref(), Some("sky"));
        assert_eq!(sky.track.as_deref(), Some("sky"));
        assert_eq!((sky.width, sky.height), (SKY_MAP_WIDTH, SKY_MAP_WIDTH / 4));
        assert_eq!(
            (sky.frames, &sky.fps, sky.looping),
            (8, &day.fps, day.looping)
        );
        assert_eq!(sky.files.len(), 8);
        assert!(w
            .sky_manifest
            .parent()
            .unwrap()
            .join("sky_sheet.png")
            .exists());
        for f in sky.files.iter().chain(&day.files) {
            assert!(
                w.manifest.parent().unwrap().join(f).exists()
                    || w.sky_manifest.parent().unwrap().join(f).exists()
            );
        }
        // The light for objects: a grid of as many cells as texels here (24 < 32), in 10
        // layers, on the day's timeline.
        let grid_manifest = w.irradiance_manifest.as_ref().expect("an irradiance track");
        let grid = Manifest::read(grid_manifest).unwrap();
        assert_eq!(grid.track.as_deref(), Some("irradiance"));
        assert_eq!((grid.width, grid.height), (5 * 24, 2 * 24));
        assert_eq!((grid.frames, grid.per_frame.len()), (8, 8));
        let info: vbim_format::irradiance::GridInfo =
            serde_json::from_value(grid.irradiance_grid.clone().unwrap()).unwrap();
        assert_eq!((info.cells, info.height_m), ([24, 24], 2.0));
        // The terrain's share of the sun is computed from the horizons, which an overcast
        // weather (no direct sun) does not carry.
        let horizons = if w.name == "clear" { 24 * 24 * 32 } else { 0 };
        assert_eq!(info.horizons.len(), horizons, "{}", w.name);
        info.check().unwrap();
        for f in &grid.files {
            assert!(grid_manifest.parent().unwrap().join(f).exists());
        }
    }
    assert_eq!(
        package.weathers[1].irradiance.as_deref(),
        Some("overcast/irradiance")
    );
    // The zenith row of the clear sky's noon map against the dome.
    let light = WeatherLight::new(
        &vbim_bake::load_terrain(&scene).unwrap(),
        &scene,
        &scene.weathers[0],
    );
    let sun = vbim_bake::sun_for_frame(&scene, 4);
    let map = sky_map(&light.dome(&scene, &sun), SKY_MAP_WIDTH);
    let want = light
        .dome(&scene, &sun)
        .radiance(texel_direction(5, 0, SKY_MAP_WIDTH));
    for c in 0..3 {
        assert!((map[5 * 3 + c] as f64 - want[c]).abs() < 1e-6);
    }
    // A weather named twice, or with a name that is not a folder name, is refused.
    let mut bad = scene.clone();
    bad.weathers.push(weather("clear", 0.3));
    assert!(bad.validate().unwrap_err().contains("twice"));
    bad.weathers = vec![weather("../up", 0.3)];
    assert!(bad.validate().unwrap_err().contains("name"));
}

/// The sky track seen from an open flat plane is the lightmap's sky term: at every frame of
/// a day, the cosine-weighted integral of the written map (128 × 32 texels over the
/// hemisphere) equals the plane's texel less its sun and ambient, within 1%.
#[test]
fn the_sky_track_integrated_over_the_dome_is_the_grounds_sky_term_at_every_frame() {
    let mut scene = Scene::with_heightfield("synthetic");
    scene.frames = 48;
    scene.albedo = 0.0;
    let pre = Precomputed::compute(field(16, |_, _| 100.0), &scene);
    let alpha = scene.sun.angular_diameter_deg.to_radians();
    let (w, h) = (SKY_MAP_WIDTH, SKY_MAP_WIDTH / 4);
    for cover in [0.0, 1.0] {
        let light = WeatherLight::new(&pre.hf, &scene, &weather("w", cover));
        let mut out = vec![0f32; 16 * 16 * 3];
        for i in 0..scene.frames {
            let sun = vbim_bake::sun_for_frame(&scene, i);
            vbim_bake::light_frame_in(&pre, &scene, Some(&light), i, &mut out);
            let map = sky_map(&light.dome(&scene, &sun), w);
            let direct = vbim_bake::direct_share(cover)
                * vbim_bake::sun_visibility(sun.elevation, alpha, 0.0)
                * sun.dir[2].max(0.0);
            for c in 0..3 {
                // Row r spans [e_lo, e_hi]: each of its texels weighs Δ(sin² e) / w of E/π.
                let mut e_sum = 0.0;
                for r in 0..h {
                    let e_hi = std::f64::consts::FRAC_PI_2 * (1.0 - r as f64 / h as f64);
                    let e_lo = std::f64::consts::FRAC_PI_2 * (1.0 - (r + 1) as f64 / h as f64);
                    let weight = (e_hi.sin().powi(2) - e_lo.sin().powi(2)) / w as f64;
                    for col in 0..w {
                        e_sum += map[(r * w + col) * 3 + c] as f64 * weight;
                    }
                }
                let ground = out[(8 * 16 + 8) * 3 + c] as f64;
                let sky = ground - sun.color[c] * direct - scene.sky.ambient;
                assert!(
                    (e_sum - sky).abs() <= 0.01 * sky.abs() + 1e-6,
                    "cover {cover}, frame {i}, channel {c}: the map gives {e_sum}, the ground {sky}"
                );
            }
        }
    }
}

/// Preetham's model at its published values: the zenith luminance for turbidity 2 and the
/// sun 30° from the zenith is Y_z = (4.0453 T − 4.9710) tan χ − 0.2155 T + 2.4192 with
/// χ = (4/9 − T/120)(π − 2θs) = 5.884 kcd/m² (Preetham, Shirley & Smits 1999, appendix); in
/// texel units that is × π · 1.15 / 127.5. The CIE overcast horizon is a third of its zenith.
#[test]
fn the_clear_zenith_is_preethams_and_the_overcast_horizon_a_third_of_its_zenith() {
    let e = 60f64.to_radians();
    let sun = SunState {
        elevation: e,
        azimuth_north: 0.0,
        dir: [0.0, -e.cos(), e.sin()],
        color: [1.0; 3],
    };
    let clear = vbim_bake::SkyDome::new(
        &sun,
        1.15,
        vbim_bake::SkyWeather {
            cover: 0.0,
            turbidity: 2.0,
        },
        0.0,
    );
    let z = clear.radiance([0.0, 0.0, 1.0]);
    let lum = 0.2126 * z[0] + 0.7152 * z[1] + 0.0722 * z[2];
    let want = 5.8837 * std::f64::consts::PI * 1.15 / 127.5;
    assert!(
        (lum / want - 1.0).abs() < 0.002,
        "zenith {lum} against {want}"
    );
    // Brighter towards the horizon away from the sun than at the zenith (Perez's A < 0).
    let h = clear.radiance([0.0, 0.999, 0.045]);
    assert!(0.2126 * h[0] + 0.7152 * h[1] + 0.0722 * h[2] > lum);
}

/// On a real terrain at noon the overcast day is darker than the clear one, and the ridges'
/// shading has less contrast (no sun: only the sky's gradient and the horizon's cut).
#[test]
fn overcast_is_darker_and_flatter_than_clear_at_noon() {
    let hf = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../samples/dem/jacksboro_fault_mpl.png"
    );
    let mut scene = Scene::with_heightfield(hf);
    scene.size = 48;
    scene.frames = 24;
    let pre = Precomputed::compute(vbim_bake::load_terrain(&scene).unwrap(), &scene);
    let stats = |cover: f64| {
        let light = WeatherLight::new(&pre.hf, &scene, &weather("w", cover));
        let mut out = vec![0f32; 48 * 48 * 3];
        vbim_bake::light_frame_in(&pre, &scene, Some(&light), 12, &mut out);
        let g: Vec<f64> = out.chunks(3).map(|p| p[1] as f64).collect();
        let mean = g.iter().sum::<f64>() / g.len() as f64;
        let sd = (g.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / g.len() as f64).sqrt();
        (mean, sd / mean)
    };
    let (clear, clear_cv) = stats(0.0);
    let (overcast, overcast_cv) = stats(1.0);
    assert!(
        overcast < 0.5 * clear,
        "overcast {overcast} against clear {clear}"
    );
    assert!(
        overcast_cv < 0.5 * clear_cv,
        "relative contrast: overcast {overcast_cv}, clear {clear_cv}"
    );
}
