//! What the plugin adds to Bevy's frame: the CPU time of the thread that runs Bevy's main
//! and render schedules, per frame, for a lightmapped quad drawn by a camera, with the
//! lightmap a static image (without the plugin) and streamed by `VbimPlayback` (with it).
//!
//! ```sh
//! cargo run --release -p bevy_vbim --example bench -- out/scale/512.vbim out/scale/2048.vbim
//! ```
//!
//! Headless (no window; rendering into a 1280×720 image), pipelined rendering off so that
//! one thread runs both schedules and its CPU clock measures them; virtual time steps
//! 1/60 s per frame. The reader and decoder threads are not on that thread: `vbim bench
//! decode` and `scripts/runtime_cpu.sh` measure them.

use std::path::Path;
use std::time::{Duration, Instant};

use bevy::app::PluginsState;
use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::log::LogPlugin;
use bevy::pbr::Lightmap;
use bevy::prelude::*;
use bevy::render::pipelined_rendering::PipelinedRenderingPlugin;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat, TextureUsages};
use bevy::time::TimeUpdateStrategy;
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use bevy_vbim::{lightmap_image, VbimPlayback, VbimPlugin, VbimStats, VbimStream};

const WARM_UP: usize = 60;
const FRAMES: usize = 300;

fn app(with_plugin: bool) -> App {
    let mut app = App::new();
    app.add_plugins(
        DefaultPlugins
            .build()
            .disable::<WinitPlugin>()
            .disable::<PipelinedRenderingPlugin>()
            .disable::<LogPlugin>()
            .set(WindowPlugin {
                primary_window: None,
                exit_condition: ExitCondition::DontExit,
                ..default()
            }),
    )
    .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_nanos(
        16_666_667,
    )));
    if with_plugin {
        app.add_plugins(VbimPlugin);
    }
    while app.plugins_state() == PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();
    app
}

/// Median and mean of per-frame CPU time of this thread, and mean wall time, ms.
fn measure(app: &mut App) -> (f64, f64, f64) {
    for _ in 0..WARM_UP {
        app.update();
    }
    let mut cpu = Vec::with_capacity(FRAMES);
    let t0 = Instant::now();
    for _ in 0..FRAMES {
        let c0 = vbim_player::thread_cpu_ns();
        app.update();
        cpu.push((vbim_player::thread_cpu_ns() - c0) as f64 / 1e6);
    }
    let wall = t0.elapsed().as_secs_f64() * 1e3 / FRAMES as f64;
    let mean = cpu.iter().sum::<f64>() / FRAMES as f64;
    cpu.sort_by(f64::total_cmp);
    (cpu[FRAMES / 2], mean, wall)
}

fn run(stream: &Path, with_plugin: bool) -> (f64, f64, f64, Option<VbimStats>) {
    let header = VbimStream::open(stream).unwrap_or_else(|e| panic!("{e}"));
    let (w, h) = (header.header().width, header.header().height);
    let mut app = app(with_plugin);
    let world = app.world_mut();
    let lightmap = world
        .resource_mut::<Assets<Image>>()
        .add(lightmap_image(w, h));
    let mut view = Image::new_uninit(
        Extent3d {
            width: 1280,
            height: 720,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        TextureFormat::Rgba16Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    view.texture_descriptor.usage =
        TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING;
    let view = world.resource_mut::<Assets<Image>>().add(view);
    let mut mesh = Plane3d::default().mesh().size(2.0, 2.0).build();
    let uv = mesh.attribute(Mesh::ATTRIBUTE_UV_0).unwrap().clone();
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_1, uv);
    let mesh = world.resource_mut::<Assets<Mesh>>().add(mesh);
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial::default());
    world.spawn((
        Mesh3d(mesh),
        MeshMaterial3d(material),
        Lightmap {
            image: lightmap.clone(),
            ..default()
        },
    ));
    world.spawn((
        Camera3d::default(),
        RenderTarget::Image(view.into()),
        Tonemapping::None,
        Transform::from_xyz(0.0, 2.5, 0.01).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let playback = with_plugin.then(|| {
        let s = world
            .resource_mut::<Assets<VbimStream>>()
            .add(header.clone());
        world.spawn(VbimPlayback::new(s, lightmap)).id()
    });
    let (median, mean, wall) = measure(&mut app);
    let stats = playback.and_then(|e| app.world().get::<VbimStats>(e).cloned());
    (median, mean, wall, stats)
}

fn main() {
    let streams: Vec<String> = std::env::args().skip(1).collect();
    if streams.is_empty() {
        eprintln!("usage: bench STREAM.vbim [STREAM.vbim …]");
        std::process::exit(2);
    }
    println!(
        "| stream | size | without the plugin: CPU ms/frame (median, mean) | with it | added (median) | wall ms/frame without / with |"
    );
    println!("|---|---|---|---|---|---|");
    for s in &streams {
        let path = Path::new(s);
        let h = VbimStream::open(path).unwrap_or_else(|e| panic!("{e}"));
        let (m0, a0, w0, _) = run(path, false);
        let (m1, a1, w1, stats) = run(path, true);
        let st = stats.expect("the playback's statistics");
        assert!(st.playing, "{s} never played: {st:?}");
        println!(
            "| {} | {}² | {m0:.3}, {a0:.3} | {m1:.3}, {a1:.3} | {:+.3} | {w0:.1} / {w1:.1} |",
            path.file_name().unwrap().to_string_lossy(),
            h.header().width,
            m1 - m0
        );
        eprintln!(
            "  {}: {} frames shown, {} stalls, {:.1} MB on the GPU",
            s,
            st.totals.frames,
            st.totals.stalls,
            st.gpu_bytes as f64 / 1e6
        );
    }
}
