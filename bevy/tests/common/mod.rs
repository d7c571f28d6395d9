//! What the Bevy tests share: a headless app on a real adapter, and reading an image back.

use std::path::Path;
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
pub fn app(assets: &Path) -> App {
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
    app
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
