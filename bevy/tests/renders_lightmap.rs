//! What Bevy renders from a streamed lightmap, read back from a camera's HDR target with
//! tone mapping off and a fixed exposure: a flat white lightmapped quad shows its texel
//! times the documented conversion, and a white sphere lit by the sun and sky lights the
//! plugin's conversions give matches the bake's texel beneath it at noon; the sky's cube
//! map, as Bevy's generated environment map, lights a sphere with the sky's radiance.

mod common;

use std::io::Cursor;
use std::path::Path;
use std::time::Duration;

use bevy::asset::RenderAssetUsages;
use bevy::camera::{Exposure, RenderTarget, ScalingMode};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::light::{GeneratedEnvironmentMapLight, GlobalAmbientLight};
use bevy::pbr::Lightmap;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat, TextureUsages};
use bevy_vbim::{
    bake_sky, lightmap_image, lux_per_unit, sky_light, sun_light, FrameState, VbimPlayback,
    VbimStats, VbimStream,
};
use common::{app, read_image};
use vbim_encoder::{encode, EncoderConfig, InputKind, MemorySource, Preset, SegmentMode};
use vbim_format::decode::{Decoder, Output};
use vbim_format::Reader;

const SUN_LUX: f32 = 100_000.0;
const EV100: f32 = 14.0;
/// The render target's side, pixels.
const VIEW: u32 = 64;

fn exposure() -> f32 {
    1.0 / (1.2 * 2f32.powf(EV100))
}

/// An HDR camera target Bevy renders into and the test reads back.
fn target(images: &mut Assets<Image>) -> Handle<Image> {
    let mut image = Image::new_uninit(
        Extent3d {
            width: VIEW,
            height: VIEW,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        TextureFormat::Rgba16Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.usage = TextureUsages::RENDER_ATTACHMENT
        | TextureUsages::TEXTURE_BINDING
        | TextureUsages::COPY_SRC
        | TextureUsages::COPY_DST;
    images.add(image)
}

/// A camera looking straight down at the origin, seeing `side` scene units across, with
/// tone mapping and dithering off and a fixed exposure, rendering into `target`.
fn camera(world: &mut World, target: Handle<Image>, side: f32, height: f32) -> Entity {
    world
        .spawn((
            Camera3d::default(),
            RenderTarget::Image(target.into()),
            Projection::Orthographic(OrthographicProjection {
                scaling_mode: ScalingMode::Fixed {
                    width: side,
                    height: side,
                },
                ..OrthographicProjection::default_3d()
            }),
            Tonemapping::None,
            DebandDither::Disabled,
            Exposure { ev100: EV100 },
            Msaa::Off,
            Transform::from_xyz(0.0, height, 0.0).looking_at(Vec3::ZERO, Vec3::NEG_Z),
        ))
        .id()
}

/// A flat square of `side` on the ground, lightmapped over its whole surface.
fn lightmapped_ground(world: &mut World, side: f32, lightmap: Handle<Image>) {
    let mut mesh = Plane3d::default().mesh().size(side, side).build();
    let uv = mesh.attribute(Mesh::ATTRIBUTE_UV_0).unwrap().clone();
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_1, uv);
    let mesh = world.resource_mut::<Assets<Mesh>>().add(mesh);
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::WHITE,
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            lightmap_exposure: lux_per_unit(SUN_LUX),
            ..default()
        });
    world.spawn((
        Mesh3d(mesh),
        MeshMaterial3d(material),
        Lightmap {
            image: lightmap,
            ..default()
        },
    ));
}

/// A white diffuse sphere of radius 0.2 standing on the origin, not lightmapped.
fn white_sphere(world: &mut World) {
    let sphere = world
        .resource_mut::<Assets<Mesh>>()
        .add(Sphere::new(0.2).mesh().uv(64, 32));
    let white = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::WHITE,
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        });
    world.spawn((
        Mesh3d(sphere),
        MeshMaterial3d(white),
        Transform::from_xyz(0.0, 0.2, 0.0),
    ));
}

fn stats(app: &App, e: Entity) -> VbimStats {
    app.world().get::<VbimStats>(e).unwrap().clone()
}

/// Jumps (paused) to `t` and runs frames until the true state of `t` has been shown and
/// the camera has rendered it.
fn show(app: &mut App, e: Entity, t: Duration) -> VbimStats {
    {
        let mut p = app.world_mut().get_mut::<VbimPlayback>(e).unwrap();
        p.paused = true;
        p.set_time(t);
    }
    let want = t.as_secs_f64();
    for _ in 0..600 {
        app.update();
        let s = stats(app, e);
        if s.state == Some(FrameState::Exact) && (s.time.as_secs_f64() - want).abs() < 1e-6 {
            // One more frame: the camera draws after the lightmap is written, and the
            // statistics trail the render world by one frame.
            app.update();
            return stats(app, e);
        }
    }
    panic!("{t:?} was never shown: {:?}", stats(app, e));
}

fn encode_to(dir: &Path, name: &str, src: &MemorySource, metadata: Option<String>) -> Vec<u8> {
    let cfg = EncoderConfig {
        segment: SegmentMode::Auto { max: 8 },
        rate: (24, 1),
        tolerance_db: 50.0,
        metadata,
        ..EncoderConfig::preset(Preset::Default)
    };
    let mut bytes = Vec::new();
    encode(src, &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    std::fs::write(dir.join(name), &bytes).unwrap();
    bytes
}

/// The centre pixel of what the camera renders, once it has settled: Bevy compiles its
/// pipelines in the background and draws nothing until they are ready, so frames run
/// until two in a row give the same pixel other than the (black) clear colour.
fn centre(app: &mut App, view: &Handle<Image>) -> [f32; 3] {
    let at = |p: &[f32]| {
        let i = ((VIEW / 2) * VIEW + VIEW / 2) as usize * 4;
        [p[i], p[i + 1], p[i + 2]]
    };
    let mut last = [0.0; 3];
    for _ in 0..600 {
        let now = at(&read_image(app, view));
        if now == last && now.iter().any(|&c| c > 0.0) {
            return now;
        }
        last = now;
        app.update();
    }
    panic!("the camera never showed a settled image: last {last:?}");
}

#[test]
fn a_white_lightmapped_quad_shows_the_texel_times_the_conversion() {
    let dir = tempfile::tempdir().unwrap();
    // A uniform day: each frame one colour over the whole map, from night through dusk to
    // noon and back, so that filtering cannot blur what a pixel shows.
    let (w, h, n) = (16, 16, 24);
    let level = |t: usize| {
        let sun = (std::f32::consts::PI * t as f32 / n as f32).sin();
        if sun <= 0.05 {
            [4e-4, 5e-4, 7e-4]
        } else {
            [sun, 0.95 * sun, 0.8 * sun].map(|c| c * c.sqrt())
        }
    };
    let frames = (0..n)
        .map(|t| (0..w * h).flat_map(|_| level(t)).collect())
        .collect();
    let src = MemorySource::new("uniform", w, h, 3, InputKind::Hdr, frames);
    let bytes = encode_to(dir.path(), "uniform.vbim", &src, None);
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes)).unwrap()).unwrap();

    let mut app = app(dir.path());
    app.insert_resource(GlobalAmbientLight::NONE)
        .insert_resource(ClearColor(Color::BLACK));
    let world = app.world_mut();
    let lightmap = world
        .resource_mut::<Assets<Image>>()
        .add(lightmap_image(w as u32, h as u32));
    let view = target(&mut world.resource_mut::<Assets<Image>>());
    let stream: Handle<VbimStream> = world.resource::<AssetServer>().load("uniform.vbim");
    let e = world
        .spawn(VbimPlayback::new(stream, lightmap.clone()))
        .id();
    lightmapped_ground(world, 2.0, lightmap);
    camera(world, view.clone(), 1.0, 3.0);

    // Noon, dusk and night (frames 12, 2 and 0 of 24 at 24 fps).
    for (what, frame) in [("noon", 12), ("dusk", 2), ("night", 0)] {
        let s = show(&mut app, e, Duration::from_secs_f64(frame as f64 / 24.0));
        let mut texel = vec![0f32; w * h * 3];
        reference
            .frame(s.frame, Output::Linear, &mut texel)
            .unwrap();
        let pixel = centre(&mut app, &view);
        for c in 0..3 {
            let want = texel[c] * lux_per_unit(SUN_LUX) * exposure();
            let ratio = pixel[c] / want;
            eprintln!("{what}: channel {c}: pixel / (texel × conversion) = {ratio:.4}");
            assert!(
                (ratio - 1.0).abs() <= 0.02,
                "{what}: channel {c}: pixel {} against texel {} × {} × {} = {want} ({ratio:.4}×)",
                pixel[c],
                texel[c],
                lux_per_unit(SUN_LUX),
                exposure()
            );
        }
    }
}

/// A flat height field (1 km², 32² cells), baked: open ground everywhere, so a white
/// sphere's top sees what a terrain texel does — the sun and the whole sky.
fn flat_day(dir: &Path) -> (Vec<u8>, vbim_bake::Manifest) {
    let n = 32;
    let z: Vec<u8> = (0..n * n).flat_map(|_| 300f32.to_le_bytes()).collect();
    std::fs::write(dir.join("flat.f32"), z).unwrap();
    std::fs::write(
        dir.join("flat.json"),
        format!(
            r#"{{"width": {n}, "height": {n}, "min_elevation_m": 300, "max_elevation_m": 300,
                "meters_per_pixel_x": 32, "meters_per_pixel_y": 32}}"#
        ),
    )
    .unwrap();
    let sample = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/jacksboro.toml"),
    )
    .unwrap();
    let scene_text = sample
        .lines()
        .map(|l| match l.split('=').next().map(str::trim) {
            Some("name") => "name = \"flat\"".to_string(),
            Some("heightfield") => "heightfield = \"flat.f32\"".to_string(),
            Some("frames") => "frames = 24".to_string(),
            Some("size") => "size = 32".to_string(),
            _ => l.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(dir.join("flat.toml"), scene_text).unwrap();
    let scene = vbim_bake::Scene::load(&dir.join("flat.toml")).unwrap();
    let frames = dir.join("frames");
    let quiet = |_: &str, _: u64, _: u64| {};
    let baked = vbim_bake::bake(
        &scene,
        &vbim_bake::BakeOptions {
            out: frames.clone(),
            format: vbim_bake::FrameFormat::Exr,
            use_cache: false,
        },
        &quiet,
    )
    .unwrap();
    let manifest_text = std::fs::read_to_string(&baked.manifest).unwrap();
    let manifest = vbim_bake::Manifest::parse(&manifest_text).unwrap();
    let fs = vbim_encoder::FrameSet::open(frames.to_str().unwrap()).unwrap();
    // Coded at 55 dB: what the test measures is the light's conversion between the
    // lightmap and Bevy's lights, so a texel's coding error (several per cent at noon at
    // the default 45 dB, and moved by any change to the encoder's budget) stays out of it.
    let cfg = EncoderConfig {
        rate: (24, 1),
        tolerance_db: 55.0,
        metadata: Some(manifest_text),
        ..EncoderConfig::preset(Preset::Default)
    };
    let file = dir.join("flat.vbim");
    vbim_encoder::encode_file(&fs, &cfg, &file, &quiet).unwrap();
    (std::fs::read(file).unwrap(), manifest)
}

#[test]
fn a_white_sphere_at_noon_matches_the_terrain_texel_beneath_it() {
    let dir = tempfile::tempdir().unwrap();
    let (bytes, manifest) = flat_day(dir.path());
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes)).unwrap()).unwrap();
    let noon = 12;
    let f = &manifest.per_frame[noon];
    let f32s = |c: [f64; 3]| c.map(|x| x as f32);

    let mut app = app(dir.path());
    app.insert_resource(ClearColor(Color::BLACK));
    let world = app.world_mut();
    let (colour, brightness) = sky_light(
        SUN_LUX,
        bake_sky(f32s(f.sky_color), f32s(f.sky_horizon_sun_side)),
    );
    world.insert_resource(GlobalAmbientLight {
        color: colour,
        brightness,
        affects_lightmapped_meshes: false,
    });
    let (colour, illuminance) = sun_light(SUN_LUX, f32s(f.sun_color));
    // Map frame: x east, y south, z up; Bevy's: x east, y up, z south.
    let towards = Vec3::new(
        f.sun_dir[0] as f32,
        f.sun_dir[2] as f32,
        f.sun_dir[1] as f32,
    );
    world.spawn((
        DirectionalLight {
            color: colour,
            illuminance,
            shadow_maps_enabled: false,
            affects_lightmapped_mesh_diffuse: false,
            ..default()
        },
        Transform::from_translation(towards).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let lightmap = world
        .resource_mut::<Assets<Image>>()
        .add(lightmap_image(32, 32));
    let view = target(&mut world.resource_mut::<Assets<Image>>());
    let stream: Handle<VbimStream> = world.resource::<AssetServer>().load("flat.vbim");
    let e = world
        .spawn(VbimPlayback::new(stream, lightmap.clone()))
        .id();
    lightmapped_ground(world, 2.0, lightmap);
    white_sphere(world);
    // Looking straight down at the sphere's top.
    camera(world, view.clone(), 0.1, 3.0);

    let s = show(&mut app, e, Duration::from_secs_f64(noon as f64 / 24.0));
    let mut texel = vec![0f32; 32 * 32 * 3];
    reference
        .frame(s.frame, Output::Linear, &mut texel)
        .unwrap();
    let beneath = (16 * 32 + 16) * 3;
    let pixel = centre(&mut app, &view);
    for c in 0..3 {
        let want = texel[beneath + c] * lux_per_unit(SUN_LUX) * exposure();
        let ratio = pixel[c] / want;
        eprintln!("noon: channel {c}: sphere top / (texel beneath × conversion) = {ratio:.4}");
        assert!(
            (ratio - 1.0).abs() <= 0.10,
            "channel {c}: sphere top {} against the texel beneath, {} × conversion = {want} \
             ({ratio:.3}×)",
            pixel[c],
            texel[beneath + c]
        );
    }
}

/// The sky's cube map (`VbimPlayback::sky_cube`) is a source Bevy's
/// `GeneratedEnvironmentMapLight` filters: under a sky of one radiance L everywhere (the
/// cube's directions below the horizon take the horizon's), a white diffuse sphere with no
/// other light shows L times the sky's conversion on top, as the lightmap's units promise.
/// (The sphere is not lightmapped: Bevy 0.19.1 cannot compile a lightmapped mesh's shader
/// under an environment map without binding arrays, which lavapipe lacks.)
#[test]
fn the_sky_cube_lights_a_sphere_as_bevys_generated_environment_map() {
    let dir = tempfile::tempdir().unwrap();
    let sky = [0.30f32, 0.42, 0.65];
    let frames = 24;
    let constant = |w: usize, h: usize, rgb: [f32; 3]| {
        let frame: Vec<f32> = (0..w * h).flat_map(|_| rgb).collect();
        MemorySource::new("sky", w, h, 3, InputKind::Hdr, vec![frame; frames])
    };
    encode_to(dir.path(), "day.vbim", &constant(8, 8, [0.2; 3]), None);
    encode_to(dir.path(), "day-sky.vbim", &constant(16, 4, sky), None);
    let package = vbim_format::package::Package {
        vbim_package: 1,
        weathers: vec![vbim_format::package::WeatherTracks {
            name: "clear".into(),
            lightmap: "day.vbim".into(),
            sky: Some("day-sky.vbim".into()),
            irradiance: None,
        }],
    };
    std::fs::write(dir.path().join("day.vbimpkg"), package.to_json()).unwrap();

    let mut app = app(dir.path());
    app.insert_resource(ClearColor(Color::BLACK));
    let world = app.world_mut();
    world.insert_resource(GlobalAmbientLight::NONE);
    let mut images = world.resource_mut::<Assets<Image>>();
    let lightmap = images.add(lightmap_image(8, 8));
    let cube = images.add(bevy_vbim::sky_cube_image(64));
    let view = target(&mut images);
    let stream: Handle<VbimStream> = world.resource::<AssetServer>().load("day.vbimpkg");
    let mut p = VbimPlayback::new(stream, lightmap);
    p.sky_cube = Some(cube.clone());
    let e = world.spawn(p).id();
    white_sphere(world);
    let cam = camera(world, view.clone(), 0.1, 3.0);
    world.entity_mut(cam).insert(GeneratedEnvironmentMapLight {
        environment_map: cube,
        intensity: lux_per_unit(SUN_LUX),
        ..default()
    });

    show(&mut app, e, Duration::from_secs_f64(0.25));
    let pixel = centre(&mut app, &view);
    for c in 0..3 {
        let want = sky[c] * lux_per_unit(SUN_LUX) * exposure();
        let ratio = pixel[c] / want;
        eprintln!("sky {c}: sphere top / (sky radiance × conversion) = {ratio:.4}");
        assert!(
            (ratio - 1.0).abs() <= 0.03,
            "channel {c}: sphere top {} against the sky's {} × conversion = {want} ({ratio:.3}×)",
            pixel[c],
            sky[c]
        );
    }
}
