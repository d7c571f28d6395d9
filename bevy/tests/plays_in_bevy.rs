//! A headless Bevy app on a real adapter (lavapipe on machines without a GPU) plays two
//! streams into Bevy-owned images; the images, read back from Bevy's own textures, match the
//! CPU reference decoder at several times of day, after a `set_time`, across the loop point
//! and while paused.

mod common;

use std::io::Cursor;
use std::path::Path;
use std::time::Duration;

use bevy::prelude::*;
use bevy_vbim::{
    lightmap_image, FrameState, Policy, Throttle, VbimEvent, VbimEventKind, VbimPlayback,
    VbimStats, VbimStream,
};
use common::{app, read_image, Seen};
use vbim_encoder::{encode, EncoderConfig, InputKind, MemorySource, Preset, SegmentMode};
use vbim_format::curve::linear_to_srgb;
use vbim_format::decode::{Decoder, Output};
use vbim_format::Reader;

/// A small day: a soft shadow edge sweeping over a gradient, bright by day, dim by night.
fn day(w: usize, h: usize, n: usize, kind: InputKind, channels: usize) -> MemorySource {
    let frames = (0..n)
        .map(|t| {
            let sun = (std::f32::consts::PI * t as f32 / n as f32).sin().max(0.0);
            (0..w * h)
                .flat_map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let edge = 1.0 / (1.0 + (-(x - w as f32 * t as f32 / n as f32) * 0.5).exp());
                    let v = 0.02 + sun * (0.3 + 0.6 * edge) * (0.8 + 0.2 * (y * 0.2).sin());
                    let v = if kind == InputKind::Srgb8 {
                        (linear_to_srgb(v.min(1.0)) * 255.0).round() / 255.0
                    } else {
                        v
                    };
                    [v, v * 0.9, v * 0.75].into_iter().take(channels)
                })
                .collect()
        })
        .collect();
    MemorySource::new("day", w, h, channels, kind, frames)
}

fn write_stream(dir: &Path, name: &str, src: &MemorySource) -> Vec<u8> {
    let cfg = EncoderConfig {
        segment: SegmentMode::Auto { max: 8 },
        rate: (24, 1),
        tolerance_db: 45.0,
        ..EncoderConfig::preset(Preset::Default)
    };
    let mut bytes = Vec::new();
    encode(src, &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    std::fs::write(dir.join(name), &bytes).unwrap();
    bytes
}

struct Stream {
    entity: Entity,
    image: Handle<Image>,
    reference: Decoder<Cursor<Vec<u8>>>,
    kind: InputKind,
    channels: usize,
    texels: usize,
}

/// The protocol's GPU bound for HDR: within 2^-10 relative, or 1e-6 absolute below 1e-3.
fn within_hdr_bound(g: f32, want: f32) -> bool {
    (g - want).abs() <= want * 2f32.powi(-10) + if want < 1e-3 { 1e-6 } else { 0.0 }
}

fn stats(app: &App, e: Entity) -> VbimStats {
    app.world().get::<VbimStats>(e).unwrap().clone()
}

/// Runs frames until every stream shows the true state of a paused time for two frames in
/// a row, then checks each image against the reference decoder at the time shown.
fn check_paused(app: &mut App, streams: &mut [Stream], what: &str) {
    let mut last: Vec<Option<f64>> = vec![None; streams.len()];
    for _ in 0..600 {
        app.update();
        let now: Vec<VbimStats> = streams.iter().map(|s| stats(app, s.entity)).collect();
        let settled = now
            .iter()
            .zip(&last)
            .all(|(s, l)| s.playing && s.state == Some(FrameState::Exact) && *l == Some(s.frame));
        if settled {
            break;
        }
        last = now.iter().map(|s| Some(s.frame)).collect();
    }
    for s in streams.iter_mut() {
        let st = stats(app, s.entity);
        assert_eq!(st.state, Some(FrameState::Exact), "{what}: {st:?}");
        let gpu = read_image(app, &s.image);
        let mut cpu = vec![0f32; s.texels * s.channels];
        let mode = match s.kind {
            InputKind::Srgb8 => Output::Stored,
            _ => Output::Linear,
        };
        s.reference.frame(st.frame, mode, &mut cpu).unwrap();
        for i in 0..s.texels {
            for c in 0..3 {
                // One channel is shown as grey.
                let (g, want) = (gpu[i * 4 + c], cpu[i * s.channels + c.min(s.channels - 1)]);
                match s.kind {
                    InputKind::Srgb8 => {
                        let d = (linear_to_srgb(g) - want).abs() * 255.0;
                        assert!(
                            d <= 0.5,
                            "{what}, frame {:.3}, texel {i} channel {c}: {g} vs code {want}",
                            st.frame
                        );
                    }
                    _ => assert!(
                        within_hdr_bound(g, want),
                        "{what}, frame {:.3}, texel {i} channel {c}: GPU {g} vs CPU {want}",
                        st.frame
                    ),
                }
            }
        }
    }
}

fn set_paused(app: &mut App, streams: &[Stream], paused: bool) {
    for s in streams {
        app.world_mut()
            .get_mut::<VbimPlayback>(s.entity)
            .unwrap()
            .paused = paused;
    }
}

#[test]
fn two_streams_play_into_bevy_images_and_match_the_reference_decoder() {
    let dir = tempfile::tempdir().unwrap();
    // An HDR RGB day at an odd size, and an 8-bit grey one of another size; 30 frames at
    // 24 fps (a 1.25 s day) and one intra keyframe, so the chain of predicted keyframes
    // runs the whole day.
    let (w0, h0, w1, h1) = (37, 21, 24, 40);
    let hdr = write_stream(dir.path(), "hdr.vbim", &day(w0, h0, 30, InputKind::Hdr, 3));
    let grey = write_stream(
        dir.path(),
        "grey.vbim",
        &day(w1, h1, 30, InputKind::Srgb8, 1),
    );
    let mut app = app(dir.path());

    let spawn = |app: &mut App, name: &str, w: u32, h: u32| {
        let world = app.world_mut();
        let stream: Handle<VbimStream> = world.resource::<AssetServer>().load(name.to_string());
        let image = world
            .resource_mut::<Assets<Image>>()
            .add(lightmap_image(w, h));
        let mut p = VbimPlayback::new(stream, image.clone());
        p.policy = Policy::Wait;
        (world.spawn(p).id(), image)
    };
    let (e0, i0) = spawn(&mut app, "hdr.vbim", w0 as u32, h0 as u32);
    let (e1, i1) = spawn(&mut app, "grey.vbim", w1 as u32, h1 as u32);
    let decoder =
        |b: &Vec<u8>| Decoder::new(Reader::open(Cursor::new(b.clone())).unwrap()).unwrap();
    let mut streams = vec![
        Stream {
            entity: e0,
            image: i0,
            reference: decoder(&hdr),
            kind: InputKind::Hdr,
            channels: 3,
            texels: w0 * h0,
        },
        Stream {
            entity: e1,
            image: i1,
            reference: decoder(&grey),
            kind: InputKind::Srgb8,
            channels: 1,
            texels: w1 * h1,
        },
    ];

    // Playing: a few frames in, then paused mid-morning.
    for _ in 0..600 {
        app.update();
        if streams.iter().all(|s| stats(&app, s.entity).frame > 8.0) {
            break;
        }
    }
    set_paused(&mut app, &streams, true);
    check_paused(&mut app, &mut streams, "paused while playing");
    let held = stats(&app, e0).frame;
    for _ in 0..10 {
        app.update();
    }
    assert_eq!(
        stats(&app, e0).frame,
        held,
        "a paused playback holds its time"
    );

    // `set_time` deep into the chain of predicted keyframes, while paused.
    for s in &streams {
        app.world_mut()
            .get_mut::<VbimPlayback>(s.entity)
            .unwrap()
            .set_time(Duration::from_millis(1150));
    }
    check_paused(&mut app, &mut streams, "after set_time(1.15 s)");
    assert!(
        (stats(&app, e0).frame - 27.6).abs() < 1e-6,
        "{:?}",
        stats(&app, e0)
    );

    // Across the loop point: play on until both have wrapped, then pause.
    set_paused(&mut app, &streams, false);
    for _ in 0..600 {
        app.update();
        if streams.iter().all(|s| stats(&app, s.entity).loops >= 1) {
            break;
        }
    }
    for _ in 0..6 {
        app.update();
    }
    set_paused(&mut app, &streams, true);
    check_paused(&mut app, &mut streams, "after the loop point");
    assert!(stats(&app, e0).frame < 15.0, "{:?}", stats(&app, e0));

    // Virtual time paused: the playback holds even though it is not paused itself.
    set_paused(&mut app, &streams, false);
    app.world_mut().resource_mut::<Time<Virtual>>().pause();
    let before = stats(&app, e1).frame;
    for _ in 0..10 {
        app.update();
    }
    assert_eq!(stats(&app, e1).frame, before, "virtual time paused");

    let seen = &app.world().resource::<Seen>().0;
    for e in [e0, e1] {
        let kinds: Vec<&VbimEventKind> = seen
            .iter()
            .filter(|v| v.entity == e)
            .map(|v| &v.kind)
            .collect();
        assert_eq!(
            kinds
                .iter()
                .filter(|k| ***k == VbimEventKind::Loaded)
                .count(),
            1
        );
        assert!(kinds.contains(&&VbimEventKind::Looped), "{kinds:?}");
        assert!(
            !kinds.iter().any(|k| matches!(k, VbimEventKind::Failed(_))),
            "{kinds:?}"
        );
    }
    let st = stats(&app, e0);
    assert!(st.gpu_bytes > 0 && st.totals.frames > 20, "{st:?}");
}

#[test]
fn an_image_of_the_wrong_size_is_reported_not_written() {
    let dir = tempfile::tempdir().unwrap();
    write_stream(dir.path(), "day.vbim", &day(20, 12, 6, InputKind::Hdr, 3));
    let mut app = app(dir.path());
    let world = app.world_mut();
    let stream: Handle<VbimStream> = world.resource::<AssetServer>().load("day.vbim");
    let image = world
        .resource_mut::<Assets<Image>>()
        .add(lightmap_image(21, 12));
    let e = world.spawn(VbimPlayback::new(stream, image)).id();
    let mut failed = None;
    for _ in 0..300 {
        app.update();
        failed = app
            .world()
            .resource::<Seen>()
            .0
            .iter()
            .find_map(|v| match &v.kind {
                VbimEventKind::Failed(m) if v.entity == e => Some(m.clone()),
                _ => None,
            });
        if failed.is_some() {
            break;
        }
    }
    let msg = failed.expect("a Failed event");
    assert!(msg.contains("21") && msg.contains("20"), "{msg}");
    assert!(!stats(&app, e).playing);
}

/// Runs frames until `pred` holds for the events seen so far (at most `frames`).
fn until(app: &mut App, frames: usize, pred: impl Fn(&[VbimEvent]) -> bool) -> Vec<VbimEvent> {
    for _ in 0..frames {
        app.update();
        if pred(&app.world().resource::<Seen>().0) {
            break;
        }
    }
    app.world().resource::<Seen>().0.clone()
}

#[test]
fn a_starved_reader_raises_stalled_then_caught_up() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = write_stream(dir.path(), "day.vbim", &day(32, 32, 30, InputKind::Hdr, 3));
    let mut app = app(dir.path());
    let world = app.world_mut();
    let stream: Handle<VbimStream> = world.resource::<AssetServer>().load("day.vbim");
    let image = world
        .resource_mut::<Assets<Image>>()
        .add(lightmap_image(32, 32));
    let mut p = VbimPlayback::new(stream, image);
    // Read at a fifth of the stream's own rate (its bytes over its 1.25 s day): the display
    // must wait for data, then show it.
    p.policy = Policy::Wait;
    p.throttle = Throttle {
        rate: Some((bytes.len() as f64 / 1.25 / 5.0) as u64),
        stall: None,
    };
    let e = world.spawn(p).id();
    let kinds = |v: &[VbimEvent]| -> Vec<VbimEventKind> {
        v.iter()
            .filter(|x| x.entity == e)
            .map(|x| x.kind.clone())
            .collect()
    };
    let seen = until(&mut app, 3000, |v| {
        let k = kinds(v);
        let stalled = k.iter().position(|x| *x == VbimEventKind::Stalled);
        stalled.is_some_and(|i| k[i..].contains(&VbimEventKind::CaughtUp))
    });
    let k = kinds(&seen);
    let stalled = k.iter().position(|x| *x == VbimEventKind::Stalled);
    assert!(
        stalled.is_some_and(|i| k[i..].contains(&VbimEventKind::CaughtUp)),
        "{k:?} {:?}",
        app.world().get::<VbimStats>(e)
    );
    assert!(app.world().get::<VbimStats>(e).unwrap().totals.stalls >= 1);
}

#[test]
fn a_damaged_chunk_raises_damaged_naming_it_and_playback_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = write_stream(dir.path(), "day.vbim", &day(32, 32, 30, InputKind::Hdr, 3));
    // Flip a byte in the last chunk's payload (the index and its checksum stay valid).
    let reader = Reader::open(Cursor::new(bytes.clone())).unwrap();
    let last = *reader.entries().last().unwrap();
    bytes[(last.offset + last.length / 2) as usize] ^= 0x5a;
    std::fs::write(dir.path().join("day.vbim"), &bytes).unwrap();
    let mut app = app(dir.path());
    let world = app.world_mut();
    let stream: Handle<VbimStream> = world.resource::<AssetServer>().load("day.vbim");
    let image = world
        .resource_mut::<Assets<Image>>()
        .add(lightmap_image(32, 32));
    let e = world.spawn(VbimPlayback::new(stream, image)).id();
    let seen = until(&mut app, 600, |v| {
        v.iter()
            .any(|x| matches!(x.kind, VbimEventKind::Damaged(_)))
    });
    let msg = seen
        .iter()
        .find_map(|x| match &x.kind {
            VbimEventKind::Damaged(m) if x.entity == e => Some(m.clone()),
            _ => None,
        })
        .expect("a Damaged event");
    assert!(msg.contains("chunk"), "{msg}");
    // Playback goes on.
    let before = app.world().get::<VbimStats>(e).unwrap().totals.frames;
    for _ in 0..10 {
        app.update();
    }
    assert!(app.world().get::<VbimStats>(e).unwrap().totals.frames >= before + 10);
}

/// The sky's cube map (`VbimPlayback::sky_cube`, for a `Skybox`): every texel of every
/// face is the sky image resampled along the texel's direction
/// (`vbim_player::sky_cube_texel`), within the half float's rounding.
fn check_cube(app: &App, (sky, cube): (&Handle<Image>, &Handle<Image>), what: &str) {
    use bevy::render::render_asset::RenderAssets;
    use bevy::render::renderer::{RenderDevice, RenderQueue};
    use bevy::render::texture::GpuImage;
    let sky = read_image(app, sky);
    let world = app.sub_app(bevy::render::RenderApp).world();
    let gpu = world
        .resource::<RenderAssets<GpuImage>>()
        .get(cube.id())
        .unwrap();
    let (device, queue) = (
        world.resource::<RenderDevice>(),
        world.resource::<RenderQueue>(),
    );
    let n = gpu.texture.width();
    for face in 0..6 {
        let raw =
            vbim_player::read_texture_layer(device.wgpu_device(), &queue.0, &gpu.texture, 8, face);
        for y in 0..n {
            for x in 0..n {
                let want = vbim_player::sky_cube_texel(&sky, (16, 4), face, (x, y), n);
                for (c, want) in want.iter().enumerate() {
                    let at = (((y * n + x) * 4) as usize + c) * 2;
                    let got = half::f16::from_le_bytes([raw[at], raw[at + 1]]).to_f32();
                    assert!(
                        (got - want).abs() <= 1.1 * 2f32.powi(-10) * want.abs() + 1e-6,
                        "{what}: cube face {face} texel ({x}, {y}) channel {c}: {got} against {want}"
                    );
                }
            }
        }
    }
}

/// A package of two weathers plays in Bevy: the lightmap and the sky go into the app's two
/// images and match their tracks' reference decoders; changing the component's weather
/// cross-fades to the other weather, raises `WeatherChanged`, and the images then match the
/// new weather's tracks.
#[test]
fn a_package_plays_its_sky_and_switches_weather_from_the_component() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = Vec::new();
    for (name, gain) in [("clear", 1.0f32), ("overcast", 0.3)] {
        let mut lm = day(24, 16, 30, InputKind::Hdr, 3);
        let mut sky = day(16, 4, 30, InputKind::Hdr, 3);
        for f in lm.frames.iter_mut().chain(sky.frames.iter_mut()) {
            f.iter_mut().for_each(|v| *v *= gain);
        }
        let lm = write_stream(dir.path(), &format!("{name}.vbim"), &lm);
        let sky = write_stream(dir.path(), &format!("{name}-sky.vbim"), &sky);
        bytes.push((lm, sky));
    }
    let package = vbim_format::package::Package {
        vbim_package: 1,
        weathers: ["clear", "overcast"]
            .map(|n| vbim_format::package::WeatherTracks {
                name: n.into(),
                lightmap: format!("{n}.vbim"),
                sky: Some(format!("{n}-sky.vbim")),
                irradiance: None,
            })
            .to_vec(),
    };
    std::fs::write(dir.path().join("day.vbimpkg"), package.to_json()).unwrap();
    let opened = VbimStream::open(dir.path().join("day.vbimpkg")).unwrap();
    assert_eq!(opened.weathers(), ["clear", "overcast"]);
    let mut app = app(dir.path());
    let world = app.world_mut();
    let stream: Handle<VbimStream> = world.resource::<AssetServer>().load("day.vbimpkg");
    let mut images = world.resource_mut::<Assets<Image>>();
    let lightmap = images.add(lightmap_image(24, 16));
    let sky = images.add(opened.sky_image().unwrap());
    let cube = images.add(bevy_vbim::sky_cube_image(8));
    let mut p = VbimPlayback::new(stream, lightmap.clone());
    p.sky = Some(sky.clone());
    p.sky_cube = Some(cube.clone());
    p.policy = Policy::Wait;
    let e = world.spawn(p).id();
    let decoder =
        |b: &Vec<u8>| Decoder::new(Reader::open(Cursor::new(b.clone())).unwrap()).unwrap();
    let streams = |w: usize| {
        vec![
            Stream {
                entity: e,
                image: lightmap.clone(),
                reference: decoder(&bytes[w].0),
                kind: InputKind::Hdr,
                channels: 3,
                texels: 24 * 16,
            },
            Stream {
                entity: e,
                image: sky.clone(),
                reference: decoder(&bytes[w].1),
                kind: InputKind::Hdr,
                channels: 3,
                texels: 16 * 4,
            },
        ]
    };
    for _ in 0..600 {
        app.update();
        if stats(&app, e).frame > 6.0 {
            break;
        }
    }
    set_paused(&mut app, &streams(0), true);
    check_paused(&mut app, &mut streams(0), "clear, paused");
    check_cube(&app, (&sky, &cube), "clear, paused");
    assert_eq!(stats(&app, e).weather, "clear");

    set_paused(&mut app, &streams(0), false);
    app.world_mut()
        .get_mut::<VbimPlayback>(e)
        .unwrap()
        .switch_weather("overcast", Duration::from_millis(100));
    let seen = until(&mut app, 600, |v| {
        v.iter()
            .any(|x| x.kind == VbimEventKind::WeatherChanged("overcast".into()))
    });
    assert!(
        seen.iter()
            .any(|x| x.kind == VbimEventKind::WeatherChanged("overcast".into())),
        "{:?}",
        stats(&app, e)
    );
    assert_eq!(stats(&app, e).weather, "overcast");
    for _ in 0..3 {
        app.update();
    }
    set_paused(&mut app, &streams(1), true);
    check_paused(&mut app, &mut streams(1), "overcast, after the switch");
    check_cube(&app, (&sky, &cube), "overcast, after the switch");

    // An unknown weather is refused and the weather shown stays.
    app.world_mut()
        .get_mut::<VbimPlayback>(e)
        .unwrap()
        .switch_weather("rain", Duration::from_millis(100));
    let seen = until(&mut app, 60, |v| {
        v.iter()
            .any(|x| matches!(x.kind, VbimEventKind::WeatherRefused(_)))
    });
    let refused = seen.iter().find_map(|x| match &x.kind {
        VbimEventKind::WeatherRefused(m) => Some(m.clone()),
        _ => None,
    });
    assert!(refused.is_some_and(|m| m.contains("rain")));
    assert_eq!(stats(&app, e).weather, "overcast");
}

/// A package's light for objects reaches Bevy: [`VbimStats::irradiance`] answers on the
/// CPU, and the irradiance volume image holds, for each cell and face, the sky and bounce
/// that answer gives towards that face (Bevy's +Y is the map's up).
#[test]
fn a_packages_light_for_objects_fills_an_irradiance_volume() {
    use vbim_format::irradiance::{Cell, Grid, LAYERS};
    let dir = tempfile::tempdir().unwrap();
    let frames = 30;
    write_stream(
        dir.path(),
        "clear.vbim",
        &day(24, 16, frames, InputKind::Hdr, 3),
    );
    // An 8 × 8 grid (its layers on the codec's 8 × 8 blocks): a uniform A(t) plus an
    // up–down term B(t), no direct sun.
    let c0 = 2.0 * std::f32::consts::PI.sqrt();
    let (a, b) = (
        |k: usize| 0.1 + 0.01 * k as f32,
        |k: usize| 0.05 + 0.002 * k as f32,
    );
    let grids: Vec<Vec<f32>> = (0..frames)
        .map(|k| {
            let mut sh = [[0f32; 3]; 9];
            sh[0] = [a(k) * c0; 3];
            sh[2] = [b(k); 3];
            let g = Grid {
                nx: 8,
                ny: 8,
                cells: vec![Cell { sun: [0.0; 3], sh }; 64],
                sun_dir: [0.0, 0.0, 1.0],
            };
            g.to_image(&[0.0; 64])
        })
        .collect();
    assert_eq!(grids[0].len(), 40 * 16 * 3);
    assert_eq!(LAYERS, 10);
    let per_frame: Vec<String> = (0..frames)
        .map(|_| r#"{"sun_dir":[0,0,1],"sun_color":[1,1,1]}"#.to_string())
        .collect();
    let meta = format!(
        r#"{{"per_frame":[{}],"irradiance_grid":{{"cells":[8,8],"height_m":2,"albedo":0.25,
            "sun_diameter_deg":1.5,"azimuths":8,"horizons":[]}}}}"#,
        per_frame.join(",")
    );
    let cfg = EncoderConfig {
        segment: SegmentMode::Auto { max: 8 },
        rate: (24, 1),
        metadata: Some(meta),
        ..EncoderConfig::preset(Preset::Default)
    };
    let mut irr = Vec::new();
    let src = MemorySource::new("irradiance", 40, 16, 3, InputKind::Hdr, grids);
    encode(&src, &cfg, Cursor::new(&mut irr), &|_, _, _| {}).unwrap();
    std::fs::write(dir.path().join("clear-irradiance.vbim"), &irr).unwrap();
    let package = vbim_format::package::Package {
        vbim_package: 1,
        weathers: vec![vbim_format::package::WeatherTracks {
            name: "clear".into(),
            lightmap: "clear.vbim".into(),
            sky: None,
            irradiance: Some("clear-irradiance.vbim".into()),
        }],
    };
    std::fs::write(dir.path().join("day.vbimpkg"), package.to_json()).unwrap();
    let opened = VbimStream::open(dir.path().join("day.vbimpkg")).unwrap();
    let mut app = app(dir.path());
    let world = app.world_mut();
    let stream: Handle<VbimStream> = world.resource::<AssetServer>().load("day.vbimpkg");
    let mut images = world.resource_mut::<Assets<Image>>();
    let lightmap = images.add(lightmap_image(24, 16));
    let volume = images.add(opened.irradiance_volume_image().expect("a grid"));
    let mut p = VbimPlayback::new(stream, lightmap);
    p.irradiance_volume = Some(volume.clone());
    p.speed = 0.25;
    let e = world.spawn(p).id();
    for _ in 0..600 {
        app.update();
        if stats(&app, e).frame > 6.0 && stats(&app, e).irradiance.is_some() {
            break;
        }
    }
    let s = stats(&app, e);
    let irr = s
        .irradiance
        .expect("the light for objects reached the main world");
    let image = app
        .world()
        .resource::<Assets<Image>>()
        .get(&volume)
        .unwrap();
    let size = image.texture_descriptor.size;
    assert_eq!(
        (size.width, size.height, size.depth_or_array_layers),
        (8, 2, 24)
    );
    let data = image.data.as_ref().unwrap();
    let texel = |x: u32, y: u32, z: u32| {
        let at = (((z * 2 + y) * 8 + x) * 8) as usize;
        half::f16::from_le_bytes([data[at], data[at + 1]]).to_f32()
    };
    // Each face against the CPU answer towards it, within half-float rounding.
    let faces = [
        (0, 0, [1.0, 0.0, 0.0]),
        (1, 0, [-1.0, 0.0, 0.0]),
        (0, 1, [0.0, 0.0, 1.0]),
        (1, 1, [0.0, 0.0, -1.0]),
        (0, 2, [0.0, 1.0, 0.0]),
        (1, 2, [0.0, -1.0, 0.0]),
    ];
    for z in 0..8u32 {
        for x in 0..8u32 {
            let (u, v) = ((x as f32 + 0.5) / 8.0, (z as f32 + 0.5) / 8.0);
            for (dy, slab, n) in faces {
                let want = irr.sky_at(u, v, n)[0];
                let got = texel(x, dy, slab * 8 + z);
                assert!(
                    (got - want).abs() <= 2f32.powi(-10) * want.abs() + 1e-6,
                    "cell ({x}, {z}) face {n:?}: {got} against {want}"
                );
            }
        }
    }
    // Up is brighter than down by 2 · 0.4886 · B(t), as coded (within the codec's error).
    let t = s.frame as usize;
    let (up, down) = (texel(3, 0, 8 + 3), texel(3, 1, 8 + 3));
    let want = 2.0 * 0.488_602_5 * b(t);
    assert!(
        ((up - down) - want).abs() < 0.1 * want,
        "up {up}, down {down}: {} against {want} (frame {t})",
        up - down
    );

    // Paused, the volume is written no more (each write is an upload); playing, it is.
    #[derive(Resource, Default)]
    struct Modified(usize);
    let id = volume.id();
    app.init_resource::<Modified>().add_systems(
        Last,
        move |mut events: MessageReader<AssetEvent<Image>>, mut n: ResMut<Modified>| {
            n.0 += events.read().filter(|e| e.is_modified(id)).count();
        },
    );
    app.world_mut().get_mut::<VbimPlayback>(e).unwrap().paused = true;
    for _ in 0..5 {
        app.update();
    }
    app.world_mut().resource_mut::<Modified>().0 = 0;
    for _ in 0..20 {
        app.update();
    }
    assert_eq!(
        app.world().resource::<Modified>().0,
        0,
        "writes while paused"
    );
    app.world_mut().get_mut::<VbimPlayback>(e).unwrap().paused = false;
    for _ in 0..20 {
        app.update();
    }
    assert!(
        app.world().resource::<Modified>().0 >= 10,
        "{} writes in 20 frames of playing",
        app.world().resource::<Modified>().0
    );
}
