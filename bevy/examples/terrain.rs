//! A day of lighting on the shipped sample's terrain, streamed into Bevy's own lightmap slot.
//!
//! ```sh
//! cargo run --release -p bevy_vbim --example terrain            # bakes a small day first
//! cargo run --release -p bevy_vbim --example terrain -- --stream out/demo/jacksboro-weather.vbimpkg
//! ```
//!
//! The terrain is a Bevy mesh with the bake's lightmap coordinates in `UV_1`, a
//! `StandardMaterial` with vertex colours as its albedo, and Bevy's `Lightmap` component
//! pointing at the image the player writes. A directional light and the ambient light
//! follow the sun and sky of the bake's manifest (carried in the stream's metadata) and
//! light a few spheres standing on the terrain; they do not light the terrain's diffuse,
//! which the lightmap already holds. A package's light for objects (its irradiance
//! tracks) goes into Bevy's `IrradianceVolume` over the terrain and replaces the ambient
//! light for the spheres: each is lit by the sky it sees and the ground around it, and
//! Bevy's directional light, with its shadows, brings the sun. A package's sky track is
//! resampled into a cube map every frame, which is both the camera's `Skybox` and, on an
//! adapter with binding arrays, its `GeneratedEnvironmentMapLight` (Bevy filters it again
//! each frame): every surface's specular light is the streamed sky, which the sixth
//! sphere, polished metal, mirrors. (Without binding arrays Bevy 0.19.1 cannot draw a
//! lightmapped mesh under an environment map, so lavapipe shows no reflections.) (Without
//! a sky track the background is the manifest's zenith colour;
//! `--atmosphere`: Bevy's own atmosphere, scattering that sun — on a hardware GPU; it
//! crashes lavapipe). W cycles the package's weathers (a 2 s cross-fade; `--weather NAME` starts in that one). `--hour H` starts at that hour (`--paused`: and stays there); `--screenshot F.png` saves
//! the window before `--frames N` quits. The window's title shows the time of day and the player's
//! statistics. Keys: Space pause, ↑/↓ speed ×2 / ÷2, ←/→ one hour back /
//! on, W next weather, Esc quit. `--frames N` quits after N frames (CI runs it under Xvfb).
//! `--window WxH` sizes the window (default 1280x720). On a software adapter (lavapipe) the
//! camera draws without multisampling: there a 4× MSAA frame costs about twice as much,
//! nearly all of it Bevy's PBR fragment shader.

use std::path::{Path, PathBuf};
use std::time::Duration;

use bevy::asset::RenderAssetUsages;
use bevy::camera::Exposure;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::light::atmosphere::ScatteringMedium;
use bevy::light::{
    Atmosphere, GeneratedEnvironmentMapLight, GlobalAmbientLight, IrradianceVolume, LightProbe,
    Skybox,
};
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::pbr::AtmosphereSettings;
use bevy::pbr::Lightmap;
use bevy::prelude::*;
use bevy::render::renderer::{RenderAdapterInfo, RenderDevice};
use bevy::render::settings::WgpuFeatures;
use bevy::render::view::screenshot::{save_to_disk, Screenshot};
use bevy::window::{PrimaryWindow, WindowResolution};
use bevy_vbim::{
    bake_sky, lux_per_unit, sky_light, sun_light, VbimEvent, VbimEventKind, VbimPlayback,
    VbimPlugin, VbimStats, VbimStream,
};
use vbim_bake::{FrameInfo, Manifest};

/// The lux the bake's noon sun (a texel of 1.0) stands for.
const SUN_LUX: f32 = 100_000.0;
/// The camera's exposure: Bevy's "sunlight" value, for a day lit at `SUN_LUX`.
const EV100: f32 = 14.0;

struct Args {
    stream: Option<PathBuf>,
    scene: PathBuf,
    frames: Option<u64>,
    /// Start at this hour of the day.
    hour: f64,
    /// Start paused.
    paused: bool,
    /// Bevy's atmosphere as the sky (off: a plain sky colour from the manifest). Off by
    /// default: it crashes lavapipe (Mesa 22.3, a segmentation fault in its first frames),
    /// the adapter of machines without a GPU.
    atmosphere: bool,
    /// Save the window to this PNG before quitting (with `--frames`).
    screenshot: Option<PathBuf>,
    /// The package's weather to start in (`None`: its first).
    weather: Option<String>,
    /// The window's size in pixels.
    window: (u32, u32),
}

fn args() -> Result<Args, String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut a = Args {
        stream: None,
        scene: root.join("samples/jacksboro-weather.toml"),
        frames: None,
        hour: 0.0,
        paused: false,
        atmosphere: false,
        screenshot: None,
        weather: None,
        window: (1280, 720),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--stream" => a.stream = Some(value()?.into()),
            "--scene" => a.scene = value()?.into(),
            "--frames" => a.frames = Some(value()?.parse().map_err(|e| format!("--frames: {e}"))?),
            "--hour" => a.hour = value()?.parse().map_err(|e| format!("--hour: {e}"))?,
            "--paused" => a.paused = true,
            "--atmosphere" => a.atmosphere = true,
            "--screenshot" => a.screenshot = Some(value()?.into()),
            "--weather" => a.weather = Some(value()?),
            "--window" => {
                let v = value()?;
                a.window = v
                    .split_once('x')
                    .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                    .filter(|&(w, h)| w > 0 && h > 0)
                    .ok_or(format!("--window: {v} is not WIDTHxHEIGHT in pixels"))?;
            }
            _ => {
                return Err(format!(
                    "unknown argument {flag} (--stream F.vbim|F.vbimpkg, --scene S.toml, --frames N, --hour H, --paused, --atmosphere, --screenshot F.png, --weather NAME, --window WxH)"
                ))
            }
        }
    }
    Ok(a)
}

/// A small day of the scene (128², 48 frames, 24 fps), baked and encoded once into
/// `target/bevy_vbim_example/`, for when no stream is given: a package of its weathers
/// (lightmap and sky tracks) when the scene has some, else one file.
fn small_day(scene_file: &Path) -> Result<PathBuf, String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bevy_vbim_example");
    let mut scene = vbim_bake::Scene::load(scene_file).map_err(|e| e.to_string())?;
    scene.size = 128;
    scene.frames = 48;
    let stem = format!("{}_{}x{}", scene.name, scene.size, scene.frames);
    let file = dir.join(if scene.weathers.is_empty() {
        format!("{stem}.vbim")
    } else {
        format!("{stem}.vbimpkg")
    });
    if file.exists() {
        return Ok(file);
    }
    eprintln!(
        "baking and encoding a small day into {} (once)",
        dir.display()
    );
    let frames = dir.join(format!("frames_{}", scene.name));
    let quiet = |_: &str, _: u64, _: u64| {};
    let baked = vbim_bake::bake(
        &scene,
        &vbim_bake::BakeOptions {
            out: frames.clone(),
            format: vbim_bake::FrameFormat::Exr,
            use_cache: true,
        },
        &quiet,
    )
    .map_err(|e| e.to_string())?;
    let encode = |input: &Path, out: &Path| -> Result<(), String> {
        let fs = vbim_encoder::FrameSet::open(input.to_str().ok_or("path is not UTF-8")?)
            .map_err(|e| e.to_string())?;
        let mut cfg = vbim_encoder::EncoderConfig::preset(vbim_encoder::Preset::Fast);
        cfg.rate = (24, 1);
        cfg.metadata = std::fs::read_to_string(input.join(vbim_bake::Manifest::FILE_NAME)).ok();
        // Written under another name first: an interrupted run leaves no half file behind.
        let part = out.with_extension("part");
        vbim_encoder::encode_file(&fs, &cfg, &part, &quiet).map_err(|e| e.to_string())?;
        std::fs::rename(&part, out).map_err(|e| e.to_string())
    };
    if baked.weathers.is_empty() {
        encode(&frames, &file)?;
        return Ok(file);
    }
    let baked = std::fs::read_to_string(frames.join(vbim_bake::PACKAGE_FILE))
        .map_err(|e| e.to_string())
        .and_then(|t| vbim_format::package::Package::parse(&t).map_err(|e| e.to_string()))?;
    let package = baked.coded_as(&stem);
    for (w, coded) in baked.weathers.iter().zip(&package.weathers) {
        for ((_, input), (_, file)) in w.tracks().zip(coded.tracks()) {
            encode(&frames.join(input), &dir.join(file))?;
        }
    }
    // The package last: it names only complete tracks.
    vbim_bake::write_text(&file, &package.to_json()).map_err(|e| e.to_string())?;
    Ok(file)
}

#[derive(Resource)]
struct Day {
    playback: Entity,
    /// The stream's weathers (W cycles them).
    weathers: Vec<String>,
    manifest: Option<Manifest>,
    /// The stream's frame rate, frames per second.
    fps: f64,
    exit_after: Option<u64>,
    screenshot: Option<PathBuf>,
    frames: u64,
}

#[derive(Component)]
struct Sun;

fn main() {
    let a = match args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("terrain: {e}");
            std::process::exit(2);
        }
    };
    let stream = match a.stream.clone().map_or_else(|| small_day(&a.scene), Ok) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("terrain: {e}");
            std::process::exit(1);
        }
    };
    let stream = std::fs::canonicalize(&stream).unwrap_or(stream);
    let folder = stream.parent().unwrap_or(Path::new(".")).to_path_buf();
    let name = stream.file_name().unwrap().to_string_lossy().into_owned();
    let (w, h) = a.window;
    App::new()
        .add_plugins(
            DefaultPlugins
                .set(AssetPlugin {
                    file_path: folder.to_string_lossy().into_owned(),
                    ..default()
                })
                .set(WindowPlugin {
                    primary_window: Some(Window {
                        resolution: WindowResolution::new(w, h),
                        ..default()
                    }),
                    ..default()
                }),
        )
        .add_plugins(VbimPlugin)
        .insert_resource(ClearColor(Color::BLACK))
        .insert_resource(GlobalAmbientLight::NONE)
        .add_systems(
            Startup,
            move |commands: Commands,
                  assets: Res<AssetServer>,
                  images: ResMut<Assets<Image>>,
                  meshes: ResMut<Assets<Mesh>>,
                  materials: ResMut<Assets<StandardMaterial>>,
                  media: ResMut<Assets<ScatteringMedium>>,
                  device: Res<RenderDevice>,
                  info: Res<RenderAdapterInfo>| {
                let adapter = AdapterChoices {
                    reflections: light_probes_in_arrays(&device),
                    msaa: if info.device_type == wgpu::DeviceType::Cpu {
                        Msaa::Off
                    } else {
                        Msaa::default()
                    },
                };
                setup(
                    commands,
                    assets,
                    images,
                    meshes,
                    materials,
                    media,
                    &a,
                    (&name, &stream),
                    adapter,
                )
            },
        )
        .add_systems(
            Update,
            (keys, follow_sun, readout, report_events, exit_after),
        )
        .run();
}

/// What the example draws differently by adapter.
struct AdapterChoices {
    /// Specular light from the streamed sky (`light_probes_in_arrays`).
    reflections: bool,
    /// Bevy's 4× multisampling, except on a software adapter (lavapipe), where it doubles
    /// the frame's cost.
    msaa: Msaa,
}

#[allow(clippy::too_many_arguments)]
fn setup(
    mut commands: Commands,
    assets: Res<AssetServer>,
    mut images: ResMut<Assets<Image>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut media: ResMut<Assets<ScatteringMedium>>,
    a: &Args,
    (name, path): (&str, &Path),
    adapter: AdapterChoices,
) {
    // The header and manifest now, for the mesh's size and the sun; the asset server
    // loads the same file for the player.
    let opened = VbimStream::open(path).unwrap_or_else(|e| panic!("{e}"));
    let (w, h) = (opened.header().width, opened.header().height);
    let manifest = opened.metadata().and_then(|m| Manifest::parse(m).ok());
    let lightmap = images.add(bevy_vbim::lightmap_image(w, h));
    // A package's sky, as a cube map for the camera's skybox.
    let sky_cube = opened
        .sky_image()
        .map(|_| images.add(bevy_vbim::sky_cube_image(64)));
    // A package's light for objects, for Bevy's irradiance volume over the terrain (one
    // voxel a cell of the package's grid).
    let volume = opened
        .irradiance_volume_image()
        .map(|image| images.add(image));
    let stream: Handle<VbimStream> = assets.load(name.to_string());
    let mut p = VbimPlayback::new(stream, lightmap.clone());
    p.sky_cube = sky_cube.clone();
    p.irradiance_volume = volume.clone();
    p.paused = a.paused;
    if let Some(w) = &a.weather {
        if !opened.weathers().contains(w) {
            panic!(
                "{}: no weather {w} (it has {:?})",
                path.display(),
                opened.weathers()
            );
        }
        p.weather = Some(w.clone());
    }
    if a.hour > 0.0 {
        p.set_time(opened.duration().mul_f64((a.hour / 24.0).clamp(0.0, 1.0)));
    }
    let playback = commands.spawn(p).id();

    let scene = vbim_bake::Scene::load(&a.scene).unwrap_or_else(|e| panic!("{e}"));
    let hf = vbim_bake::load_terrain(&scene).unwrap_or_else(|e| panic!("{e}"));
    let grid = vbim_scene::Mesh::new(
        &hf,
        256,
        scene.view.vertical_exaggeration as f32,
        scene.view.snow_line as f32,
    );
    let terrain = terrain_mesh(&grid);
    let material = materials.add(StandardMaterial {
        base_color: Color::WHITE,
        perceptual_roughness: 0.95,
        reflectance: 0.2,
        lightmap_exposure: lux_per_unit(SUN_LUX),
        ..default()
    });
    commands.spawn((
        Mesh3d(meshes.add(terrain)),
        MeshMaterial3d(material),
        Lightmap {
            image: lightmap,
            ..default()
        },
    ));
    // Reflections of the streamed sky: only with a sky track, under its Skybox (not Bevy's
    // atmosphere), and where Bevy can draw the lightmapped terrain with them.
    let reflections = adapter.reflections && sky_cube.is_some() && !a.atmosphere;
    // Spheres standing on the terrain (the terrain scene's: on the highest and the lowest
    // ground and around the centre): ordinary meshes, lit by the irradiance volume and
    // the sun.
    for (k, o) in vbim_scene::showcase(&grid, &hf).into_iter().enumerate() {
        let [r, g, b] = o.albedo;
        // Diffuse, as the terrain scene draws them; the last one polished metal, whose
        // only light is specular: the environment map's sky, and the sun's highlight.
        let polished = k == 5 && reflections;
        commands.spawn((
            Mesh3d(meshes.add(Sphere::new(o.radius).mesh().uv(48, 24))),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::linear_rgb(r, g, b),
                perceptual_roughness: if polished { 0.2 } else { 1.0 },
                metallic: if polished { 1.0 } else { 0.0 },
                reflectance: 0.0,
                ..default()
            })),
            Transform::from_xyz(o.centre[0], o.centre[1], o.centre[2]),
        ));
    }
    if let Some(voxels) = volume {
        // The volume spans the map (x east, z south) and every height above it.
        let (ex, ez) = grid.extent;
        commands.spawn((
            LightProbe::default(),
            IrradianceVolume {
                voxels,
                intensity: lux_per_unit(SUN_LUX),
                affects_lightmapped_meshes: false,
            },
            Transform::from_xyz(0.0, 0.5, 0.0).with_scale(Vec3::new(2.0 * ex, 2.0, 2.0 * ez)),
        ));
    }
    commands.spawn((
        Sun,
        DirectionalLight {
            shadow_maps_enabled: true,
            affects_lightmapped_mesh_diffuse: false,
            ..default()
        },
        Transform::default(),
    ));
    if a.atmosphere {
        // Bevy's own sky: its atmosphere scatters the directional light, which follows the
        // bake's sun (one scene unit as one metre above the ground, as Bevy assumes).
        commands.spawn(Atmosphere::earth(
            media.add(ScatteringMedium::earth(256, 256)),
        ));
    }
    let mut camera = commands.spawn((
        Camera3d::default(),
        adapter.msaa,
        Exposure { ev100: EV100 },
        // ACES needs no lookup table (the example builds Bevy without them).
        Tonemapping::AcesFitted,
        // A little above the terrain's centre: the sky's lower third in view.
        Transform::from_xyz(1.3, 0.9, 1.3).looking_at(Vec3::new(0.0, 0.4, 0.0), Vec3::Y),
    ));
    if a.atmosphere {
        camera.insert(AtmosphereSettings::default());
    } else if let Some(cube) = sky_cube {
        // The sky in the lightmap's units: a texel of 1 is `lux_per_unit` nits, so the sky
        // and the ground it lights share the camera's exposure.
        camera.insert(Skybox {
            image: Some(cube.clone()),
            brightness: lux_per_unit(SUN_LUX),
            ..default()
        });
        if reflections {
            // The same cube as the light of reflections. Diffuse light is the lightmap's
            // (the terrain) and the irradiance volume's (the spheres): Bevy takes the
            // environment map's only where neither is.
            camera.insert(GeneratedEnvironmentMapLight {
                environment_map: cube,
                intensity: lux_per_unit(SUN_LUX),
                affects_lightmapped_mesh_diffuse: false,
                ..default()
            });
        }
    }
    commands.insert_resource(Day {
        playback,
        weathers: opened.weathers().to_vec(),
        manifest,
        fps: opened.header().rate_num as f64 / opened.header().rate_den.max(1) as f64,
        exit_after: a.frames,
        screenshot: a.screenshot.clone(),
        frames: 0,
    });
}

/// The grid as a Bevy mesh: positions, normals, vertex colours (the albedo) and the
/// lightmap's coordinates in `UV_1`, where Bevy's `Lightmap` reads them.
fn terrain_mesh(grid: &vbim_scene::Mesh) -> Mesh {
    let pos: Vec<[f32; 3]> = grid.vertices.iter().map(|v| v.pos).collect();
    let uv: Vec<[f32; 2]> = grid.vertices.iter().map(|v| v.uv).collect();
    let colour: Vec<[f32; 4]> = grid
        .vertices
        .iter()
        .map(|v| [v.base[0], v.base[1], v.base[2], 1.0])
        .collect();
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, pos)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uv.clone())
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_1, uv)
    .with_inserted_attribute(Mesh::ATTRIBUTE_COLOR, colour)
    .with_inserted_indices(Indices::U32(grid.indices.clone()));
    mesh.compute_smooth_normals();
    mesh
}

/// The manifest's frame at a fractional frame, linearly between its two neighbours.
fn frame_at(m: &Manifest, t: f64) -> Option<FrameInfo> {
    let n = m.per_frame.len();
    if n == 0 {
        return None;
    }
    let t = t.rem_euclid(n as f64);
    let (i, f) = (t.floor() as usize % n, t - t.floor());
    let (a, b) = (&m.per_frame[i], &m.per_frame[(i + 1) % n]);
    let mix3 = |x: [f64; 3], y: [f64; 3]| [0, 1, 2].map(|c| x[c] + (y[c] - x[c]) * f);
    let mut out = a.clone();
    out.sun_dir = mix3(a.sun_dir, b.sun_dir);
    out.sun_color = mix3(a.sun_color, b.sun_color);
    out.sky_color = mix3(a.sky_color, b.sky_color);
    out.sky_horizon_sun_side = mix3(a.sky_horizon_sun_side, b.sky_horizon_sun_side);
    Some(out)
}

/// Whether Bevy keeps this adapter's light probes in binding arrays (its own test, in
/// `bevy_pbr`'s `light_probe` module). Without them Bevy 0.19.1's shader for a lightmapped
/// mesh under an environment map does not compile (it ands a `bool` with the `u32` of
/// `affects_lightmapped_mesh_diffuse`), and the terrain is not drawn: lavapipe, WebGPU in
/// browsers and many phones lack them, so there the example shows no reflections.
fn light_probes_in_arrays(device: &RenderDevice) -> bool {
    // Bevy's own bound: a standard material's 16 textures and 8 light probes.
    let needed = 16 + 8;
    let limits = device.limits();
    device.features().contains(
        WgpuFeatures::TEXTURE_BINDING_ARRAY
            | WgpuFeatures::SAMPLED_TEXTURE_AND_STORAGE_BUFFER_ARRAY_NON_UNIFORM_INDEXING,
    ) && limits.max_binding_array_elements_per_shader_stage >= needed
        && limits.max_binding_array_sampler_elements_per_shader_stage >= needed
}

/// The sun, sky light and background follow the time the lightmap shows.
fn follow_sun(
    day: Res<Day>,
    stats: Query<&VbimStats>,
    mut sun: Single<(&mut DirectionalLight, &mut Transform), With<Sun>>,
    mut ambient: ResMut<GlobalAmbientLight>,
    mut clear: ResMut<ClearColor>,
) {
    let (Some(m), Ok(s)) = (&day.manifest, stats.get(day.playback)) else {
        return;
    };
    let Some(f) = frame_at(m, s.frame) else {
        return;
    };
    let f32s = |c: [f64; 3]| c.map(|x| x as f32);
    // Map frame: x east, y south, z up; Bevy's: x east, y up, z south.
    let towards = Vec3::new(
        f.sun_dir[0] as f32,
        f.sun_dir[2] as f32,
        f.sun_dir[1] as f32,
    );
    let (light, transform) = &mut *sun;
    (light.color, light.illuminance) = sun_light(SUN_LUX, f32s(f.sun_color));
    if towards.y > 0.0 {
        **transform = Transform::from_translation(towards).looking_at(Vec3::ZERO, Vec3::Y);
    } else {
        light.illuminance = 0.0;
    }
    let sky = bake_sky(f32s(f.sky_color), f32s(f.sky_horizon_sun_side));
    (ambient.color, ambient.brightness) = sky_light(SUN_LUX, sky);
    if s.irradiance.is_some() {
        // The irradiance volume lights the objects with the sky they see.
        ambient.brightness = 0.0;
    }
    ambient.affects_lightmapped_meshes = false;
    let exposure = 1.0 / (1.2 * 2f32.powf(EV100));
    let k = lux_per_unit(SUN_LUX) * exposure;
    let bg = f32s(f.sky_color).map(|c| (c * k).min(1.0));
    clear.0 = Color::linear_rgb(bg[0], bg[1], bg[2]);
}

fn keys(
    input: Res<ButtonInput<KeyCode>>,
    day: Res<Day>,
    mut playbacks: Query<(&mut VbimPlayback, &VbimStats)>,
    mut exit: MessageWriter<AppExit>,
) {
    let Ok((mut p, s)) = playbacks.get_mut(day.playback) else {
        return;
    };
    if input.just_pressed(KeyCode::Space) {
        p.paused = !p.paused;
    }
    if input.just_pressed(KeyCode::ArrowUp) {
        p.speed = (p.speed * 2.0).min(64.0);
    }
    if input.just_pressed(KeyCode::ArrowDown) {
        p.speed = (p.speed / 2.0).max(1.0 / 64.0);
    }
    let hour = day
        .manifest
        .as_ref()
        .map_or(0.0, |m| m.per_frame.len() as f64 / 24.0);
    let fps = day.fps;
    let step = |d: f64| Duration::from_secs_f64(((s.frame + d * hour).max(0.0)) / fps);
    if input.just_pressed(KeyCode::ArrowRight) {
        p.set_time(step(1.0));
    }
    if input.just_pressed(KeyCode::ArrowLeft) {
        p.set_time(step(-1.0));
    }
    if input.just_pressed(KeyCode::KeyW) && day.weathers.len() > 1 {
        let current = s.switching.as_ref().map_or(&s.weather, |w| &w.0);
        let i = day.weathers.iter().position(|w| w == current).unwrap_or(0);
        p.switch_weather(
            &day.weathers[(i + 1) % day.weathers.len()],
            Duration::from_secs(2),
        );
    }
    if input.just_pressed(KeyCode::Escape) {
        exit.write(AppExit::Success);
    }
}

/// The statistics, in the window's title.
fn readout(
    day: Res<Day>,
    stats: Query<(&VbimStats, &VbimPlayback)>,
    mut window: Single<&mut Window, With<PrimaryWindow>>,
) {
    let Ok((s, p)) = stats.get(day.playback) else {
        return;
    };
    let frames = day
        .manifest
        .as_ref()
        .map_or(1, |m| m.per_frame.len().max(1)) as f64;
    let hours = 24.0 * s.frame / frames;
    window.title = format!(
        "vbim {:02}:{:02} {}{}{} ×{} · drift {:.2} · loops {} · read {:.2} MB · GPU {:.1} MB · Space ↑↓ ←→ W Esc",
        hours.floor() as u32,
        (hours.fract() * 60.0).floor() as u32,
        match &s.switching {
            Some((to, w)) => format!("{} → {to} {:.0}% ", s.weather, w * 100.0),
            None => format!("{} ", s.weather),
        },
        if p.paused { "paused " } else { "" },
        s.state.map_or("loading", |st| st.name()),
        p.speed,
        s.drift,
        s.loops,
        s.totals.bytes_read as f64 / 1e6,
        s.gpu_bytes as f64 / 1e6,
    );
}

fn report_events(mut events: MessageReader<VbimEvent>) {
    for e in events.read() {
        match &e.kind {
            VbimEventKind::Failed(m) | VbimEventKind::Damaged(m) => eprintln!("vbim: {m}"),
            k => info!("vbim: {k:?}"),
        }
    }
}

fn exit_after(
    mut commands: Commands,
    mut day: ResMut<Day>,
    stats: Query<&VbimStats>,
    mut exit: MessageWriter<AppExit>,
) {
    let Some(n) = day.exit_after else { return };
    if stats.get(day.playback).is_ok_and(|s| s.playing) {
        day.frames += 1;
    }
    if day.frames == n {
        if let Some(path) = day.screenshot.clone() {
            commands
                .spawn(Screenshot::primary_window())
                .observe(save_to_disk(path));
        }
        if let Ok(s) = stats.get(day.playback) {
            println!(
                "terrain: {} frames shown, frame {:.2} of the day, {} stalls, {:.1} MB on the GPU",
                s.totals.frames,
                s.frame,
                s.totals.stalls,
                s.gpu_bytes as f64 / 1e6
            );
        }
    }
    // A few frames more for the screenshot to be captured and written.
    if day.frames >= n + 5 {
        exit.write(AppExit::Success);
    }
}
