//! Packages on a real adapter: a plain file plays as a package of one weather, a weather
//! switch cross-fades lightmap and sky from one weather to the other in step with the
//! timeline (never a pop, never a late frame of the shown weather), and bad packages are
//! refused naming the file.

use std::io::Cursor;
use std::path::Path;

use vbim_encoder::{encode, EncoderConfig, InputKind, MemorySource, Preset, SegmentMode};
use vbim_format::decode::{Decoder, Output};
use vbim_format::package::{Package, WeatherTracks};
use vbim_player::{headless_device, FrameState, PackagePlayer, PlayerConfig, Policy};

const DISPLAY: u64 = 16_666_667;

fn device() -> (wgpu::Device, wgpu::Queue) {
    match headless_device() {
        Ok((d, q, _)) => (d, q),
        Err(e) => panic!("{e}"),
    }
}

/// A day-like sequence: a shadow edge sweeping over a gradient, scaled by `gain` and
/// tinted by `tint` (a weather), `n` frames of `w × h`.
fn sequence(w: usize, h: usize, n: usize, gain: f32, tint: [f32; 3]) -> MemorySource {
    let frames = (0..n)
        .map(|t| {
            let day = 0.2 + (std::f32::consts::PI * t as f32 / n as f32).sin().max(0.0);
            (0..w * h)
                .flat_map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let edge = 1.0 / (1.0 + (-(x - w as f32 * t as f32 / n as f32) * 0.5).exp());
                    let v = gain * day * (0.3 + 0.6 * edge) * (0.8 + 0.2 * (y * 0.3).sin());
                    tint.map(|c| v * c)
                })
                .collect()
        })
        .collect();
    MemorySource::new("test", w, h, 3, InputKind::Hdr, frames)
}

fn write_stream(path: &Path, src: &MemorySource) -> Vec<u8> {
    let cfg = EncoderConfig {
        segment: SegmentMode::Fixed(6),
        rate: (24, 1),
        aim: false,
        ..EncoderConfig::preset(Preset::Default)
    };
    let mut bytes = Vec::new();
    encode(src, &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    std::fs::write(path, &bytes).unwrap();
    bytes
}

/// Two weathers of 40×24 lightmaps and 16×4 skies, 36 frames at 24 fps, looping.
struct Fixture {
    dir: tempfile::TempDir,
    /// (lightmap, sky) bytes of "clear" then "overcast".
    bytes: Vec<(Vec<u8>, Vec<u8>)>,
}

const FRAMES: usize = 36;

fn fixture() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = Vec::new();
    let mut weathers = Vec::new();
    for (name, gain, tint) in [
        ("clear", 1.0, [1.0, 0.95, 0.8]),
        ("overcast", 0.35, [0.8, 0.85, 0.9]),
    ] {
        let lm = write_stream(
            &dir.path().join(format!("{name}.vbim")),
            &sequence(40, 24, FRAMES, gain, tint),
        );
        let sky = write_stream(
            &dir.path().join(format!("{name}-sky.vbim")),
            &sequence(16, 4, FRAMES, 0.5 * gain, [0.5, 0.7, 1.0]),
        );
        bytes.push((lm, sky));
        weathers.push(WeatherTracks {
            name: name.into(),
            lightmap: format!("{name}.vbim"),
            sky: Some(format!("{name}-sky.vbim")),
            irradiance: None,
        });
    }
    let p = Package {
        vbim_package: 1,
        weathers,
    };
    std::fs::write(dir.path().join("day.vbimpkg"), p.to_json()).unwrap();
    Fixture { dir, bytes }
}

fn inline() -> PlayerConfig {
    PlayerConfig {
        policy: Policy::Interpolate,
        threaded: false,
        ..Default::default()
    }
}

fn reference(bytes: &[u8], t: f64, texels: usize) -> Vec<f32> {
    let mut d =
        Decoder::new(vbim_format::Reader::open(Cursor::new(bytes.to_vec())).unwrap()).unwrap();
    let mut out = vec![0f32; texels * 3];
    d.frame(t, Output::Linear, &mut out).unwrap();
    out
}

/// `gpu` (RGBA) against `a + (b − a) w` (RGB): the protocol's HDR bound (2^-10 relative,
/// the half float's own rounding) on each weather's reference, plus the fade's rounding.
fn assert_mix(gpu: &[f32], a: &[f32], b: &[f32], w: f32, what: &str) {
    for i in 0..a.len() / 3 {
        for c in 0..3 {
            let want = a[i * 3 + c] + (b[i * 3 + c] - a[i * 3 + c]) * w;
            let g = gpu[i * 4 + c];
            let tol = 2.5 * 2f32.powi(-10) * a[i * 3 + c].max(b[i * 3 + c]) + 1e-6;
            assert!(
                (g - want).abs() <= tol,
                "{what}: texel {i} channel {c}: {g} against {want} (weight {w})"
            );
        }
    }
}

#[test]
fn a_weather_switch_cross_fades_lightmap_and_sky_in_step_without_a_pop() {
    let (device, queue) = device();
    let fx = fixture();
    let mut p = PackagePlayer::open(
        &device,
        &queue,
        &fx.dir.path().join("day.vbimpkg"),
        None,
        inline(),
    )
    .unwrap();
    assert_eq!(p.weather(), "clear");
    let one_weather = p.gpu_bytes();
    for _ in 0..20 {
        let r = p.advance(DISPLAY);
        assert!(r.switch.is_none());
    }
    let fade_ns = 250_000_000;
    p.switch_weather("overcast", fade_ns).unwrap();
    assert!(p.switching());
    let (mut last_w, mut fade_started, mut peak) = (0f32, None, 0u64);
    let mut frames = 0;
    while p.switching() {
        frames += 1;
        assert!(frames < 200, "the switch never ended");
        let r = p.advance(DISPLAY);
        peak = peak.max(p.gpu_bytes());
        // The shown weather never waits for the new one.
        assert_eq!(r.lightmap.state, FrameState::Exact, "frame {frames}");
        assert_eq!(r.sky.unwrap().state, FrameState::Exact, "frame {frames}");
        let Some(s) = r.switch else { break };
        let t = r.lightmap.shown;
        if s.weight > 0.0 {
            fade_started.get_or_insert(s.since_ns);
            // Both weathers show the same time, and the weight moves by one display frame
            // of the fade at a time: no jump.
            assert!((s.lightmap.shown - t).abs() < 1e-6 && s.lightmap.state == FrameState::Exact);
            let step = DISPLAY as f32 / fade_ns as f32;
            assert!(
                s.weight - last_w <= step * 1.001 + 1e-6,
                "{last_w} → {}",
                s.weight
            );
        } else {
            assert!(fade_started.is_none(), "the weight never goes back to 0");
        }
        last_w = s.weight;
        let w = if s.weight > 0.0 { s.weight } else { 0.0 };
        let lm = p.read_lightmap();
        let a = reference(&fx.bytes[0].0, t, 40 * 24);
        let b = reference(&fx.bytes[1].0, t, 40 * 24);
        assert_mix(&lm, &a, &b, w, &format!("lightmap, switch frame {frames}"));
        let sky = p.read_sky().unwrap();
        let a = reference(&fx.bytes[0].1, t, 16 * 4);
        let b = reference(&fx.bytes[1].1, t, 16 * 4);
        assert_mix(&sky, &a, &b, w, &format!("sky, switch frame {frames}"));
    }
    assert_eq!(last_w, 1.0);
    assert_eq!(p.weather(), "overcast");
    let started = fade_started.expect("the fade started");
    eprintln!(
        "switch: fade started {:.0} ms after the switch; GPU memory {one_weather} → {peak} B during it",
        started as f64 * 1e-6
    );
    assert!(peak > one_weather && p.gpu_bytes() <= one_weather + 1024);
    // After the switch the new weather writes the outputs, exactly.
    for _ in 0..30 {
        let r = p.advance(DISPLAY);
        assert!(r.switch.is_none());
        assert_eq!(r.lightmap.state, FrameState::Exact);
    }
    let r = p.advance(DISPLAY);
    let want = reference(&fx.bytes[1].0, r.lightmap.shown, 40 * 24);
    assert_mix(&p.read_lightmap(), &want, &want, 0.0, "after the switch");
    // Through the loop seam and a seek, still the new weather.
    p.set_time(0);
    for _ in 0..3 {
        p.advance(DISPLAY);
    }
    let r = p.advance(DISPLAY);
    let want = reference(&fx.bytes[1].1, r.sky.unwrap().shown, 16 * 4);
    assert_mix(
        &p.read_sky().unwrap(),
        &want,
        &want,
        0.0,
        "sky after a seek",
    );
}

#[test]
fn a_plain_file_plays_as_a_package_of_one_weather() {
    let (device, queue) = device();
    let fx = fixture();
    let path = fx.dir.path().join("clear.vbim");
    let mut p = PackagePlayer::open(&device, &queue, &path, None, inline()).unwrap();
    assert_eq!(p.weather(), vbim_format::package::SINGLE_WEATHER);
    assert!(p.sky_view().is_none());
    assert_eq!(p.file().tracks.len(), 1);
    let mut r = p.advance(DISPLAY);
    for _ in 0..10 {
        r = p.advance(DISPLAY);
    }
    let want = reference(&fx.bytes[0].0, r.lightmap.shown, 40 * 24);
    assert_mix(&p.read_lightmap(), &want, &want, 0.0, "a plain file");
    let e = p.switch_weather("overcast", 1).unwrap_err().to_string();
    assert!(
        e.contains("no weather \"overcast\"") && e.contains("default"),
        "{e}"
    );
}

#[test]
fn packages_that_cannot_play_are_refused_naming_the_file() {
    let (device, queue) = device();
    let fx = fixture();
    let dir = fx.dir.path();
    let open = |name: &str, json: &str| {
        let path = dir.join(name);
        std::fs::write(&path, json).unwrap();
        match PackagePlayer::open(&device, &queue, &path, None, inline()) {
            Ok(_) => panic!("{name} opened"),
            Err(e) => e.to_string(),
        }
    };
    // A track of another length.
    write_stream(
        &dir.join("short.vbim"),
        &sequence(40, 24, 12, 1.0, [1.0; 3]),
    );
    let e = open(
        "short.vbimpkg",
        r#"{"vbim_package": 1, "weathers": [{"name": "a", "lightmap": "clear.vbim"},
            {"name": "b", "lightmap": "short.vbim"}]}"#,
    );
    assert!(
        e.contains("short.vbim") && e.contains("one timeline"),
        "{e}"
    );
    // A missing track.
    let e = open(
        "missing.vbimpkg",
        r#"{"vbim_package": 1, "weathers": [{"name": "a", "lightmap": "gone.vbim"}]}"#,
    );
    assert!(e.contains("gone.vbim"), "{e}");
    // A sky in one weather only.
    let e = open(
        "halfsky.vbimpkg",
        r#"{"vbim_package": 1, "weathers": [{"name": "a", "lightmap": "clear.vbim", "sky": "clear-sky.vbim"},
            {"name": "b", "lightmap": "overcast.vbim"}]}"#,
    );
    assert!(e.contains("halfsky.vbimpkg") && e.contains("sky"), "{e}");
    // A path out of the package's folder, and a file that is neither.
    let e = open(
        "escape.vbimpkg",
        r#"{"vbim_package": 1, "weathers": [{"name": "a", "lightmap": "../clear.vbim"}]}"#,
    );
    assert!(
        e.contains("escape.vbimpkg") && e.contains("track path"),
        "{e}"
    );
    let e = open("junk.vbimpkg", "\u{0}\u{1}binary");
    assert!(e.contains("junk.vbimpkg"), "{e}");
    // An unknown weather.
    let e = match PackagePlayer::open(
        &device,
        &queue,
        &dir.join("day.vbimpkg"),
        Some("rain"),
        inline(),
    ) {
        Ok(_) => panic!("opened"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("rain") && e.contains("clear, overcast"), "{e}");
}

/// Under a bandwidth cap with stalls, a switch leaves the shown weather exactly as late as
/// it is without one (the new tracks read beside it, starting at the first time their
/// data can be there), and once the fade begins the new weather is never late either.
#[test]
fn a_capped_switch_never_makes_a_frame_late() {
    let (device, queue) = device();
    let fx = fixture();
    let path = fx.dir.path().join("day.vbimpkg");
    let mean = fx.bytes[0].0.len() as f64 / (FRAMES as f64 / 24.0);
    let cfg = PlayerConfig {
        throttle: vbim_player::Throttle {
            rate: Some((1.2 * mean) as u64),
            stall: Some(vbim_player::Stall::every(200_000_000, 1_000_000_000)),
        },
        preroll_margin_ns: 200_000_000,
        ..inline()
    };
    let late = |r: &vbim_player::FrameRecord| r.state != FrameState::Exact;
    let run = |switch: bool| {
        let mut p = PackagePlayer::open(&device, &queue, &path, None, cfg.clone()).unwrap();
        let (mut shown_late, mut new_late_in_fade, mut started) = (0, 0, None);
        for k in 0..400 {
            if switch && k == 100 {
                p.switch_weather("overcast", 200_000_000).unwrap();
            }
            let r = p.advance(DISPLAY);
            // Frames before the first shown one are the pre-roll, the same in both runs.
            shown_late += (k > 60 && late(&r.lightmap)) as u32;
            // Lightmap and sky in step, from the first frame (their pre-rolls differ).
            let sky = r.sky.unwrap();
            if !late(&r.lightmap) && !late(&sky) {
                assert_eq!(r.lightmap.shown, sky.shown, "frame {k}");
            }
            if let Some(s) = &r.switch {
                if s.weight > 0.0 {
                    started.get_or_insert(s.since_ns);
                    new_late_in_fade += late(&s.lightmap) as u32;
                }
            }
        }
        (
            shown_late,
            new_late_in_fade,
            started,
            p.weather().to_string(),
        )
    };
    let (alone, _, _, _) = run(false);
    let (with, new_late, started, weather) = run(true);
    assert_eq!(with, alone, "the switch made the shown weather late");
    assert_eq!(new_late, 0, "the new weather was late during its fade");
    assert_eq!(weather, "overcast");
    eprintln!(
        "capped switch: fade began {:.0} ms after it was asked for; {alone} late frames alone",
        started.unwrap() as f64 * 1e-6
    );
}

/// A held switch closes the shown weather at once: the outputs keep its last image while
/// the new weather's data comes, then fade from that image into the new weather; the
/// memory stays one weather's and the copy of the held image.
#[test]
fn a_held_switch_fades_from_the_last_image_within_one_weathers_memory() {
    let (device, queue) = device();
    let fx = fixture();
    let path = fx.dir.path().join("day.vbimpkg");
    let mut p = PackagePlayer::open(&device, &queue, &path, None, inline()).unwrap();
    p.set_switch_mode(vbim_player::SwitchMode::Held);
    let mut last = p.advance(DISPLAY);
    for _ in 0..20 {
        last = p.advance(DISPLAY);
    }
    let one_weather = p.gpu_bytes();
    let held_lm = reference(&fx.bytes[0].0, last.lightmap.shown, 40 * 24);
    let held_sky = reference(&fx.bytes[0].1, last.lightmap.shown, 16 * 4);
    let fade_ns = 200_000_000;
    p.switch_weather("overcast", fade_ns).unwrap();
    assert_eq!(
        p.weather(),
        "clear",
        "the held weather is on screen until the fade ends"
    );
    let (mut peak, mut frames, mut last_w) = (0, 0, 0f32);
    while p.switching() {
        frames += 1;
        assert!(frames < 200, "the switch never ended");
        let r = p.advance(DISPLAY);
        peak = peak.max(p.gpu_bytes());
        let Some(s) = r.switch else { break };
        // Before the fade: the held image; during it, the held image into the new weather.
        let t = r.lightmap.shown;
        let w = s.weight;
        assert!(w >= last_w && w - last_w <= DISPLAY as f32 / fade_ns as f32 * 1.001 + 1e-6);
        last_w = w;
        let b = reference(&fx.bytes[1].0, t, 40 * 24);
        let b_sky = reference(&fx.bytes[1].1, t, 16 * 4);
        if w == 0.0 {
            assert_mix(&p.read_lightmap(), &held_lm, &held_lm, 0.0, "held lightmap");
            assert_mix(
                &p.read_sky().unwrap(),
                &held_sky,
                &held_sky,
                0.0,
                "held sky",
            );
        } else {
            assert_eq!(s.lightmap.state, FrameState::Exact);
            assert_mix(
                &p.read_lightmap(),
                &held_lm,
                &b,
                w,
                &format!("held fade, frame {frames}"),
            );
            assert_mix(
                &p.read_sky().unwrap(),
                &held_sky,
                &b_sky,
                w,
                "held sky fade",
            );
        }
    }
    assert_eq!(p.weather(), "overcast");
    // One weather at a time (the larger of the two) and the copies of the held images.
    let one_weather = one_weather.max(p.gpu_bytes());
    let copies = (40 * 24 + 16 * 4) * 8;
    assert!(
        peak <= one_weather + copies,
        "{peak} B during the switch against {one_weather} B + {copies} B of copies"
    );
    let r = p.advance(DISPLAY);
    let want = reference(&fx.bytes[1].0, r.lightmap.shown, 40 * 24);
    assert_mix(
        &p.read_lightmap(),
        &want,
        &want,
        0.0,
        "after the held switch",
    );
}

/// The tracks stay in step at every frame through reader stalls, a `set_time` and a jump
/// to 100 simulated hours; a switch asked for during a stall fades only once the new
/// weather's data is there; a damaged chunk in the sky track is reported while the
/// lightmap plays on.
#[test]
fn tracks_stay_in_step_through_stalls_seeks_and_100_hours_and_damage_stops_no_other_track() {
    let (device, queue) = device();
    let fx = fixture();
    let path = fx.dir.path().join("day.vbimpkg");
    let mean = fx.bytes[0].0.len() as f64 / (FRAMES as f64 / 24.0);
    let cfg = PlayerConfig {
        throttle: vbim_player::Throttle {
            rate: Some((1.5 * mean) as u64),
            stall: Some(vbim_player::Stall::every(400_000_000, 1_500_000_000)),
        },
        ..inline()
    };
    let mut p = PackagePlayer::open(&device, &queue, &path, None, cfg).unwrap();
    let in_step = |r: &vbim_player::PackageRecord, what: &str| {
        let sky = r.sky.unwrap();
        if r.lightmap.state == FrameState::Exact && sky.state == FrameState::Exact {
            assert_eq!(r.lightmap.shown, sky.shown, "{what}");
        }
    };
    for k in 0..300 {
        in_step(&p.advance(DISPLAY), &format!("frame {k}"));
    }
    // A switch asked for inside a stall (the reader stalls 0.4 s every 1.5 s: at 300 frames
    // = 5 s, the next stall is at 6 s).
    for _ in 0..65 {
        p.advance(DISPLAY);
    }
    p.switch_weather("overcast", 100_000_000).unwrap();
    let mut saw_fade = false;
    for k in 0..400 {
        let r = p.advance(DISPLAY);
        in_step(&r, &format!("switch frame {k}"));
        if let Some(s) = &r.switch {
            if s.weight > 0.0 {
                saw_fade = true;
                assert_eq!(
                    s.lightmap.state,
                    FrameState::Exact,
                    "a fade before the data"
                );
                assert_eq!(s.sky.unwrap().state, FrameState::Exact);
            }
        }
        if !p.switching() {
            break;
        }
    }
    assert!(saw_fade && p.weather() == "overcast");
    // A seek, then 100 hours on: in step, and on the exact frame (the day loops every 1.5 s).
    p.set_time(700_000_000);
    for k in 0..200 {
        in_step(&p.advance(DISPLAY), &format!("after set_time, frame {k}"));
    }
    let hours = 100 * 3_600_000_000_000u64;
    p.set_time(hours);
    let mut last = None;
    for k in 0..400 {
        let r = p.advance(DISPLAY);
        in_step(&r, &format!("at 100 h, frame {k}"));
        last = Some(r);
    }
    let r = last.unwrap();
    let clock_frames = (hours + 400 * DISPLAY) as f64 * 24.0 / 1e9;
    assert!(
        (r.lightmap.target - clock_frames).abs() < 1e-3,
        "{} {clock_frames}",
        r.lightmap.target
    );

    // A damaged chunk in the clear weather's sky: reported by the sky, the lightmap plays on.
    let sky_path = fx.dir.path().join("clear-sky.vbim");
    let mut bytes = fx.bytes[0].1.clone();
    let reader = vbim_format::Reader::open(Cursor::new(bytes.clone())).unwrap();
    let last_chunk = *reader.entries().last().unwrap();
    bytes[(last_chunk.offset + last_chunk.length / 2) as usize] ^= 0x5a;
    std::fs::write(&sky_path, &bytes).unwrap();
    let mut p = PackagePlayer::open(&device, &queue, &path, None, inline()).unwrap();
    let mut exact = 0;
    for _ in 0..200 {
        let r = p.advance(DISPLAY);
        exact += (r.lightmap.state == FrameState::Exact) as u32;
    }
    assert!(
        p.sky_player().unwrap().totals().damaged > 0,
        "the damage is reported"
    );
    assert_eq!(p.lightmap_player().totals().damaged, 0);
    assert!(
        exact >= 195,
        "the lightmap played on: {exact} exact frames of 200"
    );
}

/// The sky as a cube map (`set_sky_cube`): every texel of every face is the sky output
/// sampled along the texel's direction, read as (east, up, north) with the azimuth
/// clockwise from north, bilinear between texel centres and the horizon's row below the
/// horizon; through a weather switch too. What cannot hold a cube, or a package without a
/// sky, is refused.
#[test]
fn the_sky_resampled_into_a_cube_follows_each_texels_direction() {
    let (device, queue) = device();
    let fx = fixture();
    let pkg = fx.dir.path().join("day.vbimpkg");
    let mut p = PackagePlayer::open(&device, &queue, &pkg, None, inline()).unwrap();
    let n = 12;
    let cube_texture = |layers: u32| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some("test cube"),
            size: wgpu::Extent3d {
                width: n,
                height: n,
                depth_or_array_layers: layers,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba16Float,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        })
    };
    let e = p.set_sky_cube(Some(&cube_texture(4))).unwrap_err();
    assert!(e.to_string().contains("6 layers"), "{e}");
    let cube = cube_texture(6);
    p.set_sky_cube(Some(&cube)).unwrap();
    let check = |p: &PackagePlayer, what: &str| {
        let sky = p.read_sky().unwrap();
        for face in 0..6 {
            let raw = vbim_player::read_texture_layer(&device, &queue, &cube, 8, face);
            let texels: &[half::f16] = bytemuck::cast_slice(&raw);
            for y in 0..n {
                for x in 0..n {
                    let want = vbim_player::sky_cube_texel(&sky, (16, 4), face, (x, y), n);
                    for (ch, want) in want.iter().enumerate() {
                        let got = texels[((y * n + x) * 4) as usize + ch].to_f32();
                        assert!(
                            (got - want).abs() <= 1.1 * 2f32.powi(-10) * want.abs() + 1e-6,
                            "{what}: face {face} texel ({x}, {y}) channel {ch}: {got} against {want}"
                        );
                    }
                }
            }
        }
    };
    for _ in 0..12 {
        p.advance(DISPLAY);
    }
    check(&p, "clear");
    p.switch_weather("overcast", 2 * DISPLAY).unwrap();
    for _ in 0..40 {
        p.advance(DISPLAY);
    }
    assert_eq!(p.weather(), "overcast");
    check(&p, "overcast, after a switch");
    // A plain file has no sky to put in a cube.
    let mut plain = PackagePlayer::open(
        &device,
        &queue,
        &fx.dir.path().join("clear.vbim"),
        None,
        inline(),
    )
    .unwrap();
    let e = plain.set_sky_cube(Some(&cube)).unwrap_err();
    assert!(e.to_string().contains("no sky"), "{e}");
}
