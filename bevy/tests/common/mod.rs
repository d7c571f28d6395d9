//! What the Bevy tests share: a headless app on a real adapter, and reading an image back.

use std::ops::{Deref, DerefMut};
use std::path::Path;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use bevy::app::PluginsState;
use bevy::log::LogPlugin;
use bevy::prelude::*;
use bevy::render::pipelined_rendering::PipelinedRenderingPlugin;
use bevy::render::render_asset::RenderAssets;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy::render::RenderApp;
use bevy::time::TimeUpdateStrategy;
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use bevy_vbim::{VbimEvent, VbimPlugin};

/// Every `VbimEvent` the app raised.
#[derive(Resource, Default)]
pub struct Seen(pub Vec<VbimEvent>);

fn collect(mut events: MessageReader<VbimEvent>, mut seen: ResMut<Seen>) {
    seen.0.extend(events.read().cloned());
}

/// The app a game would have, without a window: Bevy's default plugins, rendering
/// synchronously in `update` (no pipelined rendering) so that a frame's image can be read
/// right after it, and a fixed 60 Hz virtual clock.
pub fn app(assets: &Path) -> TestApp {
    // Taken before anything touches the GPU, and held until the app is gone.
    let turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    // Fail with what to install, rather than Bevy's panic, when there is no adapter.
    if let Err(e) = vbim_player::headless_device() {
        panic!("{e}");
    }
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
            })
            .set(AssetPlugin {
                file_path: assets.to_string_lossy().into_owned(),
                ..default()
            }),
    )
    .add_plugins(VbimPlugin)
    .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_nanos(
        16_666_667,
    )))
    .init_resource::<Seen>()
    .add_systems(Update, collect);
    while app.plugins_state() == PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();
    TestApp { app, _turn: turn }
}

/// One Bevy app at a time in this test process. A game has one; the test harness runs
/// tests on parallel threads, and NVIDIA's Vulkan driver (580, on an H200) hangs when
/// several apps create and drive their devices at once in one process: the four playback
/// tests in parallel never ended, the same four one after another passed in 5 s.
/// Lavapipe does not mind, so CI would not have shown it.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// A test's app, holding its turn on the GPU (fields drop in order: the app first).
pub struct TestApp {
    app: App,
    _turn: MutexGuard<'static, ()>,
}

impl Deref for TestApp {
    type Target = App;
    fn deref(&self) -> &App {
        &self.app
    }
}

impl DerefMut for TestApp {
    fn deref_mut(&mut self) -> &mut App {
        &mut self.app
    }
}

/// Bevy's texture behind `image`, read back: RGBA f32, row by row.
pub fn read_image(app: &App, image: &Handle<Image>) -> Vec<f32> {
    let world = app.sub_app(RenderApp).world();
    let gpu = world
        .resource::<RenderAssets<GpuImage>>()
        .get(image.id())
        .expect("the image is on the GPU");
    let device = world.resource::<RenderDevice>();
    let queue = world.resource::<RenderQueue>();
    let bytes = vbim_player::read_texture(device.wgpu_device(), &queue.0, &gpu.texture, 8);
    bytes
        .chunks_exact(2)
        .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
        .collect()
}
