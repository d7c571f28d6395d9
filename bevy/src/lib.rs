//! bevy_vbim: play a vbim lighting day inside a Bevy app.
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_vbim::{VbimPlayback, VbimPlugin, VbimStream};
//!
//! fn main() {
//!     App::new()
//!         .add_plugins((DefaultPlugins, VbimPlugin))
//!         .add_systems(Startup, setup)
//!         .run();
//! }
//!
//! fn setup(mut commands: Commands, assets: Res<AssetServer>, mut images: ResMut<Assets<Image>>) {
//!     // The lightmap the terrain's material (or `Lightmap`) samples: written on the GPU.
//!     let lightmap = images.add(bevy_vbim::lightmap_image(512, 512));
//!     let day: Handle<VbimStream> = assets.load("jacksboro.vbim");
//!     commands.spawn(VbimPlayback::new(day, lightmap.clone()));
//! }
//! ```
//!
//! A `.vbim` file is an asset ([`VbimStream`]) that holds the stream's header and the
//! file's path, never its chunks: the player streams them from the file through its ring
//! while it plays. A [`VbimPlayback`] component plays a stream into an `Image` the app owns
//! (`Rgba16Float`, linear, in the project's texel units): the player runs in the render
//! world on Bevy's device, decodes on the GPU and writes that image's texture in Bevy's own
//! command encoder before the cameras draw, so a material or `Lightmap` built with the
//! handle sees every frame. Playback follows `Time<Virtual>`; [`VbimStats`] and
//! [`VbimEvent`] report back.
//!
//! A package of weathers (`.vbimpkg`) is an asset too: [`VbimPlayback::sky`] names an image
//! its sky track is written into ([`VbimStream::sky_image`]), and setting
//! [`VbimPlayback::weather`] cross-fades lightmap and sky to another weather
//! ([`VbimEventKind::WeatherChanged`] when it is shown). Its irradiance tracks light the
//! objects on the terrain: [`VbimStats::irradiance`] answers on the CPU, and
//! [`VbimPlayback::irradiance_volume`] names an image ([`irradiance_volume_image`]) written
//! every frame for Bevy's `IrradianceVolume`, which lights ordinary meshes.
//!
//! # Units
//! A texel is the irradiance reaching the surface divided by π, on a scale where the noon
//! sun on flat open ground is about 1.0. Bevy adds a lightmap to a surface's diffuse light
//! as `texel × lightmap_exposure × base_color`, then applies the camera's exposure. To
//! light terrain as Bevy's lights would, pick how many lux the bake's noon sun stands for
//! and set `StandardMaterial::lightmap_exposure` to [`lux_per_unit`] of it; [`sun_light`]
//! and [`sky_light`] give the directional and ambient lights that light other objects to
//! match (docs/BEVY.md has the derivation).
//!
//! The plugin's library depends on `vbim-player` and `vbim-format` only.
#![deny(missing_docs)]

mod asset;
mod objects;
mod playback;
mod render;
mod units;

use std::sync::mpsc;
use std::sync::Mutex;

use bevy::app::{App, First, Plugin, PostUpdate};
use bevy::asset::{AssetApp, AssetPlugin};
use bevy::core_pipeline::schedule::camera_driver;
use bevy::ecs::prelude::*;
use bevy::render::renderer::{RenderGraph, RenderGraphSystems};
use bevy::render::{ExtractSchedule, Render, RenderApp, RenderSystems};

pub use asset::{lightmap_image, sky_cube_image, StreamError, VbimStream};
pub use objects::irradiance_volume_image;
pub use playback::{VbimEvent, VbimEventKind, VbimPlayback, VbimStats};
pub use units::{bake_sky, lux_per_unit, sky_light, sun_light, BEVY_AMBIENT_DIFFUSE};
pub use vbim_player::{FrameState, Irradiance, Policy, Stall, SwitchMode, Throttle, Totals};

/// Adds `.vbim` assets, [`VbimPlayback`], [`VbimStats`] and [`VbimEvent`]. Add it after
/// Bevy's `DefaultPlugins` (it needs the asset and render plugins).
pub struct VbimPlugin;

impl Plugin for VbimPlugin {
    fn build(&self, app: &mut App) {
        let folder = app
            .get_added_plugins::<AssetPlugin>()
            .first()
            .map(|p| p.file_path.clone())
            .unwrap_or_else(|| AssetPlugin::default().file_path);
        let (tx, rx) = mpsc::channel();
        app.init_asset::<VbimStream>()
            .register_asset_loader(asset::VbimLoader::new(&folder))
            .add_message::<VbimEvent>()
            .insert_resource(playback::Reports(Mutex::new(rx)))
            .add_systems(
                First,
                (
                    playback::receive_reports,
                    objects::write_irradiance_volumes.after(playback::receive_reports),
                ),
            )
            .add_systems(PostUpdate, playback::advance_clocks);
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            bevy::log::warn!(
                "VbimPlugin: no render app (add it after DefaultPlugins); nothing will play"
            );
            return;
        };
        render_app
            .insert_resource(render::Players::new(tx))
            .init_resource::<render::ExtractedPlaybacks>()
            .add_systems(ExtractSchedule, render::extract_playbacks)
            .add_systems(
                Render,
                render::prepare_players.in_set(RenderSystems::Prepare),
            )
            .add_systems(
                RenderGraph,
                render::advance_players
                    .in_set(RenderGraphSystems::Render)
                    .before(camera_driver),
            );
    }
}
