//! A package playing: the shown weather's lightmap and sky tracks in step, and weather
//! switches that cross-fade without a pop (`docs/PLAYER.md`, "Packages and weather").
//!
//! Each track is a [`Player`] of its own (its reader, ring, decoder and stall policy),
//! advanced with the same time step; the package owns the output textures a renderer
//! binds once. Outside a switch only the shown weather's tracks are read and decoded, and
//! they reconstruct straight into the outputs. A switch opens the new weather's tracks and
//! joins them to the timeline at the shown position ([`Player::join`]); their data
//! restarts for the first segment boundary a capped reader can deliver in time
//! ([`Player::earliest_join`]) while the shown weather goes on playing. When every new
//! track shows that very time exactly, the fade starts: for its length both weathers
//! reconstruct into their own textures and one pass a track mixes them into the outputs;
//! then the new weather writes the outputs and the old one is closed. A held switch
//! ([`SwitchMode::Held`], `held.rs`) closes the shown weather at once instead and fades
//! from its last image.

mod bindings;
mod cube;
pub(crate) use bindings::{read_entry, write_entry};
pub use cube::sky_cube_texel;
mod fade;
mod file;
mod held;
mod objects;
pub use objects::ObjectsRecord;
mod probe;
pub use probe::{LightmapSample, LightmapSampling};

use std::fs::File;
use std::path::Path;

use vbim_format::Header;

use crate::{lightmap_descriptor, FrameRecord, FrameState, Player, PlayerConfig, PlayerError};
use fade::{FadeJob, FadePass};
use file::package_error;
pub use file::{PackageFile, TrackInfo, TrackKind};
use held::Held;

/// How a weather switch holds the weather it starts from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SwitchMode {
    /// The shown weather plays on until the new one shows the same time, then both fade
    /// live: the light never stops, and both weathers are open (twice the memory) from the
    /// switch to the fade's end.
    #[default]
    Live,
    /// The shown weather's tracks close at once and its last image is held (the outputs
    /// keep it; a copy of 8 bytes a texel during the fade); the new weather fades in from
    /// that still image: the memory of one weather, but the light stands still while the
    /// new weather's data comes (the display holds, and the records say so). Needs output
    /// textures with `COPY_SRC` (the package's own have it; without it a switch is live).
    Held,
}

/// One weather's players.
pub(super) struct Tracks {
    name: String,
    lightmap: Player<File>,
    sky: Option<Player<File>>,
    /// Light for objects, decoded on the CPU.
    irradiance: Option<crate::irradiance::IrradianceTrack>,
}

impl Tracks {
    pub(super) fn players(&mut self) -> impl Iterator<Item = &mut Player<File>> {
        std::iter::once(&mut self.lightmap).chain(self.sky.as_mut())
    }
}

/// A switch in progress.
struct Switch {
    to: Tracks,
    fade_ns: u64,
    /// The package clock of the first frame after it was asked for (the frame that
    /// begins it).
    asked: Option<u64>,
    /// Once every new track shows the shown time exactly: the clock the fade started at
    /// and its passes.
    fading: Option<(u64, FadeJob, Option<FadeJob>)>,
}

/// What a switch did this frame.
#[derive(Clone, Debug)]
pub struct SwitchRecord {
    /// The weather switched to.
    pub to: String,
    /// The new weather's lightmap this frame (`Held` while its data is coming).
    pub lightmap: FrameRecord,
    /// Its sky.
    pub sky: Option<FrameRecord>,
    /// The fade's weight of the new weather (0 before the fade starts, 1 at its end).
    pub weight: f32,
    /// Playback time since the frame the switch began in (the first after it was asked
    /// for), ns.
    pub since_ns: u64,
}

/// One displayed frame of a package.
#[derive(Clone, Debug)]
pub struct PackageRecord {
    /// The shown weather's lightmap.
    pub lightmap: FrameRecord,
    /// The shown weather's sky.
    pub sky: Option<FrameRecord>,
    /// The light for objects, for a package with irradiance tracks.
    pub objects: Option<ObjectsRecord>,
    /// The switch in progress, if any.
    pub switch: Option<SwitchRecord>,
}

/// A package playing into two textures the renderer binds once: the lightmap and the sky
/// (see the module's documentation).
pub struct PackagePlayer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    file: PackageFile,
    cfg: PlayerConfig,
    shown: Tracks,
    switch: Option<Switch>,
    /// A switch asked for during a fade: it starts when the fade ends.
    pending: Option<(String, u64)>,
    lightmap: (wgpu::Texture, wgpu::TextureView),
    sky: Option<(wgpu::Texture, wgpu::TextureView)>,
    fade: FadePass,
    ticks: u64,
    mode: SwitchMode,
    /// A held switch in progress (the new weather is `shown`).
    held: Option<Held>,
    /// The media time the last frame showed (frames), which a held switch holds.
    last_shown: f64,
    /// The sky resampled into the caller's cube map every frame.
    cube: Option<cube::SkyCube>,
    /// The light for objects, for a package with irradiance tracks.
    objects: Option<objects::Objects>,
    /// The lightmap read back for [`PackagePlayer::sample_lightmap`], when asked for.
    probe: Option<probe::Probe>,
}

fn output(device: &wgpu::Device, h: &Header) -> (wgpu::Texture, wgpu::TextureView) {
    use wgpu::TextureUsages as U;
    let t = device.create_texture(&lightmap_descriptor(
        h.width,
        h.height,
        U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC,
    ));
    let v = t.create_view(&Default::default());
    (t, v)
}

impl PackagePlayer {
    /// Opens the package (or plain `.vbim` file) at `path` and starts playing `weather`
    /// (the package's first when `None`) at time 0. Every track uses `cfg`.
    pub fn open(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        path: &Path,
        weather: Option<&str>,
        cfg: PlayerConfig,
    ) -> Result<PackagePlayer, PlayerError> {
        let file = PackageFile::open(path)?;
        let name = weather
            .unwrap_or(&file.package.weathers[0].name)
            .to_string();
        file.weather(&name)?;
        let lightmap = output(
            device,
            &file
                .track(&name, TrackKind::Lightmap)
                .expect("checked")
                .header,
        );
        let sky = file
            .track(&name, TrackKind::Sky)
            .map(|t| output(device, &t.header));
        let mut shown = open_tracks(device, queue, &file, &name, &cfg)?;
        // The tracks start together: each buffers for the longest of their pre-rolls (a
        // sky's is shorter than its lightmap's, and would otherwise start ahead of it).
        let preroll = shown.players().map(|p| p.preroll_ns()).max().unwrap_or(0);
        for p in shown.players() {
            p.set_preroll_ns(preroll);
        }
        shown.lightmap.set_output(Some(&lightmap.0))?;
        if let (Some(p), Some(s)) = (shown.sky.as_mut(), &sky) {
            p.set_output(Some(&s.0))?;
        }
        let objects = objects::Objects::new(device, &shown);
        Ok(PackagePlayer {
            objects,
            probe: None,
            device: device.clone(),
            queue: queue.clone(),
            fade: FadePass::new(device),
            file,
            cfg,
            shown,
            switch: None,
            pending: None,
            lightmap,
            sky,
            ticks: 0,
            mode: SwitchMode::Live,
            held: None,
            last_shown: 0.0,
            cube: None,
        })
    }

    /// The package and its tracks.
    pub fn file(&self) -> &PackageFile {
        &self.file
    }
    /// The weather on screen (until a switch's fade ends, the one it started from).
    pub fn weather(&self) -> &str {
        self.held.as_ref().map_or(&self.shown.name, |h| &h.from)
    }
    /// How switches hold the weather they start from, from the next switch on.
    pub fn set_switch_mode(&mut self, mode: SwitchMode) {
        self.mode = mode;
    }
    /// The lightmap (linear RGB, `Rgba16Float`), the same texture for the whole playback.
    pub fn lightmap_view(&self) -> &wgpu::TextureView {
        &self.lightmap.1
    }
    /// The sky map (linear RGB, `Rgba16Float`, equirectangular over the upper hemisphere,
    /// the zenith's row first), when the package has sky tracks.
    pub fn sky_view(&self) -> Option<&wgpu::TextureView> {
        self.sky.as_ref().map(|s| &s.1)
    }
    /// The lightmap texture (for readback).
    pub fn lightmap_texture(&self) -> &wgpu::Texture {
        &self.lightmap.0
    }
    /// The sky texture (for readback).
    pub fn sky_texture(&self) -> Option<&wgpu::Texture> {
        self.sky.as_ref().map(|s| &s.0)
    }
    /// Reads the lightmap back (RGBA, f32, row by row); blocks: for tests and captures.
    pub fn read_lightmap(&self) -> Vec<f32> {
        read_f16(&self.device, &self.queue, &self.lightmap.0)
    }
    /// Reads the sky map back, likewise.
    pub fn read_sky(&self) -> Option<Vec<f32>> {
        self.sky
            .as_ref()
            .map(|(t, _)| read_f16(&self.device, &self.queue, t))
    }
    /// The shown weather's lightmap player (its header, totals and policy).
    pub fn lightmap_player(&self) -> &Player<File> {
        &self.shown.lightmap
    }
    /// The shown weather's sky player.
    pub fn sky_player(&self) -> Option<&Player<File>> {
        self.shown.sky.as_ref()
    }
    /// Reconstructs into textures of the caller's from the next frame on (each `width ×
    /// height` of its track, 2D, `Rgba16Float`, `STORAGE_BINDING | TEXTURE_BINDING`), as
    /// [`Player::set_output`]; `None` keeps the package's own. A fade in progress ends at
    /// once (the new weather is shown).
    pub fn set_outputs(
        &mut self,
        lightmap: Option<&wgpu::Texture>,
        sky: Option<&wgpu::Texture>,
    ) -> Result<(), PlayerError> {
        if self.switch.as_ref().is_some_and(|s| s.fading.is_some()) {
            self.finish_switch();
        }
        // A held image lives in the old outputs: with new ones the switch cuts.
        self.held = None;
        if let Some(t) = lightmap {
            self.shown.lightmap.set_output(Some(t))?;
            self.lightmap = (t.clone(), t.create_view(&Default::default()));
        }
        if let (Some(t), Some(p)) = (sky, self.shown.sky.as_mut()) {
            p.set_output(Some(t))?;
            self.sky = Some((t.clone(), t.create_view(&Default::default())));
            if let (Some(c), Some((_, v))) = (self.cube.as_mut(), &self.sky) {
                c.bind(&self.device, v);
            }
        }
        Ok(())
    }

    /// Changes the stall policy of the shown weather's tracks (and of the weather a switch
    /// goes to, once shown) from the next frame on.
    pub fn set_policy(&mut self, policy: crate::Policy) {
        self.cfg.policy = policy;
        for p in self.shown.players() {
            p.set_policy(policy);
        }
    }

    /// The package's playback clock, ns.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }
    /// Changes every open track's bandwidth cap and stalls (each track has its reader).
    pub fn set_throttle(&mut self, t: crate::Throttle) {
        self.cfg.throttle = t;
        for p in self.shown.players() {
            p.set_throttle(t);
        }
        if let Some(s) = self.switch.as_mut() {
            for p in s.to.players() {
                p.set_throttle(t);
            }
        }
    }
    /// Stops every track's threads and waits for them (each at most `deadline`).
    pub fn stop(&mut self, deadline: std::time::Duration) -> Result<(), PlayerError> {
        if let Some(s) = self.switch.as_mut() {
            for p in s.to.players() {
                p.stop(deadline)?;
            }
        }
        for p in self.shown.players() {
            p.stop(deadline)?;
        }
        Ok(())
    }
    /// The package's weathers, in its order.
    pub fn weathers(&self) -> impl Iterator<Item = &str> {
        self.file.package.weathers.iter().map(|w| w.name.as_str())
    }
    /// The weather a switch in progress goes to.
    pub fn switching_to(&self) -> Option<&str> {
        self.pending
            .as_ref()
            .map(|p| p.0.as_str())
            .or(self.switch.as_ref().map(|s| s.to.name.as_str()))
            .or(self.held.as_ref().map(|_| self.shown.name.as_str()))
    }
    /// Whether a switch is in progress (or waiting for a fade to end).
    pub fn switching(&self) -> bool {
        self.switch.is_some() || self.pending.is_some() || self.held.is_some()
    }
    /// GPU memory of every open track and the outputs, bytes (both weathers during a
    /// switch).
    pub fn gpu_bytes(&self) -> u64 {
        let tracks =
            |t: &Tracks| t.lightmap.gpu_bytes() + t.sky.as_ref().map_or(0, |s| s.gpu_bytes());
        let out =
            |(t, _): &(wgpu::Texture, wgpu::TextureView)| t.width() as u64 * t.height() as u64 * 8;
        tracks(&self.shown)
            + self.switch.as_ref().map_or(0, |s| tracks(&s.to))
            + self.held.as_ref().map_or(0, Held::bytes)
            + out(&self.lightmap)
            + self.sky.as_ref().map_or(0, out)
            + self.objects.as_ref().map_or(0, objects::Objects::gpu_bytes)
            + self.probe.as_ref().map_or(0, probe::Probe::bytes)
    }

    /// Switches to weather `name`, cross-fading over `fade_ns` of playback once the new
    /// weather's tracks show the shown time (see the module's documentation). The shown
    /// weather keeps playing meanwhile, or, in [`SwitchMode::Held`], its last image stays.
    /// Switching to the weather shown cancels a live switch that has not begun to fade; a
    /// switch asked for during a fade starts when it ends.
    pub fn switch_weather(&mut self, name: &str, fade_ns: u64) -> Result<(), PlayerError> {
        self.file.weather(name)?;
        let fading = self.switch.as_ref().is_some_and(|s| s.fading.is_some())
            || self.held.as_ref().is_some_and(Held::fading);
        if fading {
            self.pending = Some((name.to_string(), fade_ns));
            return Ok(());
        }
        self.pending = None;
        let copyable = |t: &wgpu::Texture| t.usage().contains(wgpu::TextureUsages::COPY_SRC);
        let can_hold =
            copyable(&self.lightmap.0) && self.sky.as_ref().is_none_or(|s| copyable(&s.0));
        if self.held.is_some()
            || (self.mode == SwitchMode::Held && can_hold && self.switch.is_none())
        {
            return self.switch_held(name, fade_ns);
        }
        if self.switch.as_ref().is_some_and(|s| s.to.name == name) {
            return Ok(());
        }
        self.switch = None;
        if name == self.shown.name {
            return Ok(());
        }
        let to = self.open_joined(name)?;
        self.switch = Some(Switch {
            to,
            fade_ns,
            asked: None,
            fading: None,
        });
        Ok(())
    }

    /// Jumps every track to `ticks` ns of playback; a switch that has not begun to fade
    /// goes on from there, one fading ends at once.
    pub fn set_time(&mut self, ticks: u64) {
        if self.switch.as_ref().is_some_and(|s| s.fading.is_some()) {
            self.finish_switch();
        }
        if self.held.as_ref().is_some_and(Held::fading) {
            self.finish_held();
        }
        self.ticks = ticks;
        for p in self.shown.players() {
            p.set_time(ticks);
        }
        if let Some(s) = self.switch.as_mut() {
            let at = s.to.lightmap.earliest_join(ticks);
            for p in s.to.players() {
                p.join(ticks, ticks, at);
            }
        }
    }

    /// Advances playback by `dt` ns: every open track, then the fade, in one submission.
    pub fn advance(&mut self, dt: u64) -> PackageRecord {
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let r = self.advance_into(dt, &mut enc);
        self.queue.submit(Some(enc.finish()));
        r
    }

    /// Like [`PackagePlayer::advance`], but records every track's work and the fade into
    /// the caller's encoder, which must be the next submission on the queue (as for
    /// [`Player::advance_into`]).
    pub fn advance_into(&mut self, dt: u64, enc: &mut wgpu::CommandEncoder) -> PackageRecord {
        self.ticks += dt;
        let lightmap = self.shown.lightmap.advance_into(dt, enc);
        let sky = self.shown.sky.as_mut().map(|p| p.advance_into(dt, enc));
        let mut record = None;
        let mut done = false;
        if let Some(sw) = self.switch.as_mut() {
            let to_lightmap = sw.to.lightmap.advance_into(dt, enc);
            let to_sky = sw.to.sky.as_mut().map(|p| p.advance_into(dt, enc));
            let mut weight = 0.0;
            match &sw.fading {
                None => {
                    let exact = |r: &FrameRecord| r.state == FrameState::Exact;
                    let same_time = (to_lightmap.shown - lightmap.shown).abs() < 1e-3;
                    if exact(&to_lightmap) && to_sky.as_ref().is_none_or(exact) && same_time {
                        // From the next frame on both weathers reconstruct into their own
                        // textures (this frame's output already holds the shown one).
                        self.shown
                            .lightmap
                            .set_output(None)
                            .expect("none is always valid");
                        if let Some(p) = self.shown.sky.as_mut() {
                            p.set_output(None).expect("none is always valid");
                        }
                        let size = |t: &wgpu::Texture| (t.width(), t.height());
                        let lm = self.fade.job(
                            &self.device,
                            self.shown.lightmap.view(),
                            sw.to.lightmap.view(),
                            &self.lightmap.1,
                            size(&self.lightmap.0),
                        );
                        let sk = match (&self.shown.sky, &sw.to.sky, &self.sky) {
                            (Some(a), Some(b), Some((t, v))) => {
                                Some(self.fade.job(&self.device, a.view(), b.view(), v, size(t)))
                            }
                            _ => None,
                        };
                        sw.fading = Some((self.ticks, lm, sk));
                    }
                }
                Some((start, lm, sk)) => {
                    weight =
                        ((self.ticks - start) as f64 / sw.fade_ns.max(1) as f64).min(1.0) as f32;
                    self.fade.record(&self.queue, enc, lm, weight);
                    if let Some(sk) = sk {
                        self.fade.record(&self.queue, enc, sk, weight);
                    }
                    done = weight >= 1.0;
                }
            }
            record = Some(SwitchRecord {
                to: sw.to.name.clone(),
                lightmap: to_lightmap,
                sky: to_sky,
                weight,
                since_ns: self.ticks - *sw.asked.get_or_insert(self.ticks),
            });
        }
        let (mut lightmap, mut sky) = (lightmap, sky);
        if self.held.is_some() {
            let (r, held_done) = self.advance_held(enc, &lightmap, sky.as_ref());
            record = Some(r);
            if let Some(at) = self.held.as_ref().and_then(Held::still) {
                // On screen is the held image: the frame says so.
                for r in std::iter::once(&mut lightmap).chain(sky.as_mut()) {
                    r.state = FrameState::Held;
                    r.shown = at;
                    r.drift = r.target - at;
                }
            }
            if held_done {
                self.finish_held();
            }
        }
        let (to, held_weight) = match (&self.held, &record) {
            (Some(_), Some(r)) => (None, Some(r.weight)),
            (None, Some(r)) => (Some((r.lightmap.shown, r.weight)), None),
            _ => (None, None),
        };
        let objects = self.step_objects(lightmap.shown, to, held_weight);
        self.last_shown = lightmap.shown;
        if done {
            // The new weather writes the outputs from the next frame on; the old tracks'
            // textures stay alive while this frame's commands need them.
            self.finish_switch();
        }
        if let Some(c) = &self.cube {
            // The sky output is complete: the tracks, the fade and the held image wrote it.
            c.record(enc);
        }
        if let Some(p) = self.probe.as_mut() {
            // The lightmap output is complete too.
            p.step(
                &self.device,
                &self.queue,
                enc,
                &self.lightmap.0,
                self.ticks,
                lightmap.shown,
            );
        }
        PackageRecord {
            lightmap,
            sky,
            objects,
            switch: record,
        }
    }

    /// Resamples the sky into `cube` every frame from now on (or stops with `None`): a
    /// cube map's texture (a square `Rgba16Float` 2D texture of 6 layers, with
    /// `STORAGE_BINDING` and `TEXTURE_BINDING`; 64² is plenty for a 128 × 32 sky), for
    /// skyboxes and environment maps. Its faces are in WebGPU's order and its directions
    /// are (east, up, north): a renderer whose world has x east, y up and z south samples
    /// it at (x, y, −z), as Bevy's `Skybox` does. Below the horizon each direction has the
    /// horizon's radiance at its azimuth. A package without sky tracks refuses it.
    pub fn set_sky_cube(&mut self, cube: Option<&wgpu::Texture>) -> Result<(), PlayerError> {
        let Some(cube) = cube else {
            self.cube = None;
            return Ok(());
        };
        let Some((_, sky)) = &self.sky else {
            return Err(PlayerError::SkyCube(format!(
                "{}: no sky tracks to put in a cube",
                self.file.path.display()
            )));
        };
        self.cube = Some(cube::SkyCube::new(&self.device, sky, cube)?);
        Ok(())
    }

    /// Opens weather `name`'s tracks and joins them to the timeline at the shown
    /// position, from where the new lightmap's data can first be there (both switch modes).
    fn open_joined(&self, name: &str) -> Result<Tracks, PlayerError> {
        let mut join_cfg = self.cfg.clone();
        // The new tracks follow the timeline: they never pause it while they load.
        if join_cfg.policy == crate::Policy::Wait {
            join_cfg.policy = crate::Policy::Interpolate;
        }
        let mut to = open_tracks(&self.device, &self.queue, &self.file, name, &join_cfg)?;
        let position = self.shown.lightmap.position();
        let at = to.lightmap.earliest_join(position);
        for p in to.players() {
            p.join(self.ticks, position, at);
        }
        Ok(to)
    }

    /// A switch is over: `shown`, the new weather, writes the outputs under the package's
    /// policy, and a switch asked for meanwhile starts (both switch modes).
    fn shown_takes_over(&mut self) {
        self.shown
            .lightmap
            .set_output(Some(&self.lightmap.0))
            .expect("the output fits every lightmap track (checked at open)");
        if let (Some(p), Some((t, _))) = (self.shown.sky.as_mut(), &self.sky) {
            p.set_output(Some(t))
                .expect("the output fits every sky track");
        }
        for p in self.shown.players() {
            p.set_policy(self.cfg.policy);
        }
        if let Some((name, fade)) = self.pending.take() {
            // The weather was checked when it was asked for; a file that went away since
            // leaves the weather as it is.
            let _ = self.switch_weather(&name, fade);
        }
    }

    /// The fade is over: the new weather writes the outputs, the old one closes.
    fn finish_switch(&mut self) {
        let Some(sw) = self.switch.take() else { return };
        // Dropping the old tracks stops their threads.
        self.shown = sw.to;
        self.shown_takes_over();
    }
}

fn read_f16(device: &wgpu::Device, queue: &wgpu::Queue, t: &wgpu::Texture) -> Vec<f32> {
    let raw = crate::readback::read_texture(device, queue, t, 8);
    bytemuck::cast_slice::<u8, half::f16>(&raw)
        .iter()
        .map(|v| v.to_f32())
        .collect()
}

fn open_tracks(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    file: &PackageFile,
    name: &str,
    cfg: &PlayerConfig,
) -> Result<Tracks, PlayerError> {
    let open = |kind| -> Result<Option<Player<File>>, PlayerError> {
        let Some(t) = file.track(name, kind) else {
            return Ok(None);
        };
        let f = File::open(&t.path).map_err(|e| package_error(&t.path, e))?;
        Player::open(device, queue, f, cfg.clone())
            .map(Some)
            .map_err(|e| PlayerError::Track {
                path: t.path.clone(),
                source: Box::new(e),
            })
    };
    Ok(Tracks {
        name: name.to_string(),
        lightmap: open(TrackKind::Lightmap)?.expect("every weather has a lightmap"),
        sky: open(TrackKind::Sky)?,
        irradiance: file
            .track(name, TrackKind::Irradiance)
            .map(|t| crate::irradiance::IrradianceTrack::open(&t.path, cfg.limits))
            .transpose()?,
    })
}
