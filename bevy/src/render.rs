//! The render world's side: one `vbim_player::PackagePlayer` per playing entity (a plain
//! file is a package of one weather), opened on Bevy's own device, writing into the
//! textures of the entity's images, its GPU work recorded into Bevy's command encoder
//! before the cameras draw.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};

use bevy::asset::{AssetId, Assets};
use bevy::ecs::prelude::*;
use bevy::image::Image;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::TextureId;
use bevy::render::renderer::{RenderContext, RenderDevice, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy::render::Extract;
use vbim_format::Header;
use vbim_player::{PackagePlayer, PlayerConfig, Policy, SwitchMode, Throttle};

use crate::asset::VbimStream;
use crate::playback::{Report, VbimPlayback};

/// A playback as the render world sees it this frame.
#[derive(Clone)]
pub(crate) struct Extracted {
    /// The stream's file and header, once the asset is loaded.
    stream: Option<(Arc<PathBuf>, Header)>,
    target: AssetId<Image>,
    sky: Option<AssetId<Image>>,
    sky_cube: Option<AssetId<Image>>,
    weather: Option<String>,
    fade_ns: u64,
    switch_mode: SwitchMode,
    clock_ns: u64,
    seek: (u32, u64),
    policy: Policy,
    throttle: Throttle,
    catch_up_ns: u64,
}

/// This frame's playbacks, by main-world entity.
#[derive(Resource, Default)]
pub(crate) struct ExtractedPlaybacks(Vec<(Entity, Extracted)>);

/// One entity's player and what it was last told.
struct Slot {
    /// `None` once it failed: it stays stopped until the entity's playback is replaced.
    player: Option<Mutex<PackagePlayer>>,
    texture: Option<TextureId>,
    sky_texture: Option<TextureId>,
    cube_texture: Option<TextureId>,
    /// The weather last asked for.
    weather: Option<String>,
    clock_ns: u64,
    seek: u32,
    policy: Policy,
    throttle: Throttle,
    frame_count: u32,
    rate: (u32, u32),
    looping: bool,
    /// The lap of the day last shown (`shown / frame_count`), to notice loops.
    lap: Option<i64>,
    /// A seek was applied since the last frame: a lap change is not a loop.
    sought: bool,
    /// The asset and target it was opened for (a different one reopens it).
    opened_for: (Arc<PathBuf>, AssetId<Image>),
}

/// Every playing entity's player, and the channel to the main world.
#[derive(Resource)]
pub(crate) struct Players {
    slots: HashMap<Entity, Slot>,
    reports: Sender<(Entity, Report)>,
}

impl Players {
    pub(crate) fn new(reports: Sender<(Entity, Report)>) -> Self {
        Players {
            slots: HashMap::new(),
            reports,
        }
    }
}

pub(crate) fn extract_playbacks(
    mut out: ResMut<ExtractedPlaybacks>,
    playbacks: Extract<Query<(Entity, &VbimPlayback)>>,
    streams: Extract<Res<Assets<VbimStream>>>,
) {
    out.0.clear();
    for (entity, p) in &playbacks {
        let stream = streams
            .get(&p.stream)
            .map(|s| (s.shared_path(), s.header().clone()));
        out.0.push((
            entity,
            Extracted {
                stream,
                target: p.target.id(),
                sky: p.sky.as_ref().map(|s| s.id()),
                sky_cube: p.sky_cube.as_ref().map(|s| s.id()),
                weather: p.weather.clone(),
                fade_ns: p.fade.as_nanos().min(u64::MAX as u128) as u64,
                switch_mode: p.switch_mode,
                clock_ns: p.clock_ns,
                seek: p.seek,
                policy: p.policy,
                throttle: p.throttle,
                catch_up_ns: p.catch_up.as_nanos().min(u64::MAX as u128) as u64,
            },
        ));
    }
}

/// Opens players for new playbacks (once their stream and image exist), drops those of
/// entities that no longer play, and applies seeks, policies, throttles and new textures.
pub(crate) fn prepare_players(
    mut players: ResMut<Players>,
    extracted: Res<ExtractedPlaybacks>,
    images: Res<RenderAssets<GpuImage>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let players = &mut *players;
    // Dropping a player stops its threads.
    players
        .slots
        .retain(|e, _| extracted.0.iter().any(|(x, _)| x == e));
    for (entity, want) in &extracted.0 {
        let Some((path, header)) = &want.stream else {
            continue;
        };
        let Some(image) = images.get(want.target) else {
            continue;
        };
        let key = (path.clone(), want.target);
        if players
            .slots
            .get(entity)
            .is_some_and(|s| s.opened_for.0 != key.0 || s.opened_for.1 != key.1)
        {
            players.slots.remove(entity);
        }
        let slot = match players.slots.get_mut(entity) {
            Some(slot) => slot,
            None => {
                let slot = open(entity, want, key, header, &device, &queue, &players.reports);
                players.slots.entry(*entity).or_insert(slot)
            }
        };
        let Some(player) = slot
            .player
            .as_mut()
            .map(|p| p.get_mut().expect("not poisoned"))
        else {
            continue;
        };
        let sky = want.sky.and_then(|s| images.get(s));
        let sky_id = sky.map(|s| s.texture.id());
        if slot.texture != Some(image.texture.id()) || slot.sky_texture != sky_id {
            let sky = sky.map(|s| &*s.texture);
            if let Err(e) = player.set_outputs(Some(&image.texture), sky) {
                let _ = players
                    .reports
                    .send((*entity, Report::Failed(e.to_string())));
                slot.player = None;
                continue;
            }
            slot.texture = Some(image.texture.id());
            slot.sky_texture = sky_id;
        }
        let cube = want.sky_cube.and_then(|c| images.get(c));
        let cube_id = cube.map(|c| c.texture.id());
        if slot.cube_texture != cube_id {
            if let Err(e) = player.set_sky_cube(cube.map(|c| &*c.texture)) {
                let _ = players
                    .reports
                    .send((*entity, Report::Failed(e.to_string())));
                slot.player = None;
                continue;
            }
            slot.cube_texture = cube_id;
        }
        // Applies from the next switch on.
        player.set_switch_mode(want.switch_mode);
        if slot.weather != want.weather {
            if let Some(name) = &want.weather {
                if let Err(e) = player.switch_weather(name, want.fade_ns) {
                    let _ = players
                        .reports
                        .send((*entity, Report::WeatherRefused(e.to_string())));
                }
            }
            slot.weather = want.weather.clone();
        }
        if slot.policy != want.policy {
            player.set_policy(want.policy);
            slot.policy = want.policy;
        }
        if slot.throttle != want.throttle {
            player.set_throttle(want.throttle);
            slot.throttle = want.throttle;
        }
        if slot.seek != want.seek.0 {
            let day = media_ns(slot.frame_count, slot.rate);
            let t = if slot.looping && day > 0 {
                want.seek.1 % day
            } else {
                want.seek.1.min(day)
            };
            player.set_time(t);
            slot.seek = want.seek.0;
            slot.sought = true;
            // The clock runs on from here: the seek's frame advances by nothing more.
            slot.clock_ns = want.clock_ns;
        }
    }
}

/// The length of a day of `frames` at `rate` (frames per second as num/den), ns.
fn media_ns(frames: u32, rate: (u32, u32)) -> u64 {
    (frames as u128 * 1_000_000_000 * rate.1 as u128 / rate.0.max(1) as u128).min(u64::MAX as u128)
        as u64
}

fn open(
    entity: &Entity,
    want: &Extracted,
    key: (Arc<PathBuf>, AssetId<Image>),
    header: &Header,
    device: &RenderDevice,
    queue: &RenderQueue,
    reports: &Sender<(Entity, Report)>,
) -> Slot {
    let cfg = PlayerConfig {
        policy: want.policy,
        throttle: want.throttle,
        catch_up_ns: want.catch_up_ns,
        ..PlayerConfig::default()
    };
    let opened = PackagePlayer::open(
        device.wgpu_device(),
        queue,
        &key.0,
        want.weather.as_deref(),
        cfg,
    )
    .map_err(|e| e.to_string());
    let player = match opened {
        Ok(p) => {
            let _ = reports.send((
                *entity,
                Report::Opened {
                    gpu_bytes: p.gpu_bytes(),
                },
            ));
            Some(Mutex::new(p))
        }
        Err(e) => {
            let _ = reports.send((*entity, Report::Failed(e)));
            None
        }
    };
    Slot {
        player,
        texture: None,
        sky_texture: None,
        cube_texture: None,
        weather: want.weather.clone(),
        // The day starts when it can first be shown.
        clock_ns: want.clock_ns,
        seek: 0,
        policy: want.policy,
        throttle: want.throttle,
        frame_count: header.frame_count,
        rate: (header.rate_num, header.rate_den),
        looping: header.looping,
        lap: None,
        sought: false,
        opened_for: key,
    }
}

/// Records each player's frame into Bevy's command encoder, before the cameras draw.
pub(crate) fn advance_players(
    mut ctx: RenderContext,
    mut players: ResMut<Players>,
    extracted: Res<ExtractedPlaybacks>,
) {
    let players = &mut *players;
    for (entity, want) in &extracted.0 {
        let Some(slot) = players.slots.get_mut(entity) else {
            continue;
        };
        let Some(player) = slot
            .player
            .as_mut()
            .map(|p| p.get_mut().expect("not poisoned"))
        else {
            continue;
        };
        if slot.texture.is_none() {
            continue;
        }
        let dt = want.clock_ns.saturating_sub(slot.clock_ns);
        slot.clock_ns = want.clock_ns;
        let package = player.advance_into(dt, ctx.command_encoder());
        let record = package.lightmap;
        let lap = (record.shown / slot.frame_count.max(1) as f64).floor() as i64;
        let looped = slot.looping && !slot.sought && slot.lap.is_some_and(|l| lap > l);
        slot.lap = Some(lap);
        slot.sought = false;
        let _ = players.reports.send((
            *entity,
            Report::Frame {
                record,
                totals: Box::new(player.lightmap_player().totals().clone()),
                frame_count: slot.frame_count,
                rate: slot.rate,
                looped,
                weather: player.weather().to_string(),
                switching: player
                    .switching_to()
                    .map(|to| (to.to_string(), package.switch.map_or(0.0, |s| s.weight))),
                gpu_bytes: player.gpu_bytes(),
                irradiance: player.irradiance_frames().cloned().map(Box::new),
            },
        ));
    }
}
