//! The main world's side: the component that asks for a stream to play into an image, the
//! statistics the player reports back, and the events those reports raise.

use std::sync::mpsc::Receiver;
use std::sync::Mutex;
use std::time::Duration;

use bevy::asset::Handle;
use bevy::ecs::prelude::*;
use bevy::image::Image;
use bevy::time::{Time, Virtual};
use vbim_player::{FrameRecord, FrameState, Irradiance, Policy, SwitchMode, Throttle, Totals};

use crate::asset::VbimStream;

/// Plays a [`VbimStream`] into an [`Image`], written on the GPU every frame.
///
/// The image must be the stream's size, `Rgba16Float`, with `STORAGE_BINDING` and
/// `TEXTURE_BINDING` usage: make it with [`VbimStream::lightmap_image`] or
/// [`lightmap_image`](crate::lightmap_image). Give the same handle to the material or
/// `Lightmap` that shows it: the player writes into that texture and never replaces it.
///
/// Playback follows `Time<Virtual>` (its pause and relative speed) times [`speed`], and
/// starts when the stream is loaded and the image exists. [`VbimStats`] (added with this
/// component) says what is shown; [`VbimEvent`]s say when it loaded, looped, stalled,
/// caught up, met damaged data or failed.
///
/// [`speed`]: VbimPlayback::speed
#[derive(Component, Clone, Debug)]
#[require(VbimStats)]
pub struct VbimPlayback {
    /// The stream to play.
    pub stream: Handle<VbimStream>,
    /// The image it plays into.
    pub target: Handle<Image>,
    /// Holds the day where it is (the lightmap stays on the GPU; nothing is re-evaluated).
    pub paused: bool,
    /// Media time per unit of virtual time (1.0: the stream's own rate; 0 or less stops).
    pub speed: f64,
    /// What is shown when data is late (applied while playing).
    pub policy: Policy,
    /// The reader's bandwidth cap (and, for tests, a stall pattern), applied while playing.
    pub throttle: Throttle,
    /// The catch-up window of [`Policy::Interpolate`], used when the player opens.
    pub catch_up: Duration,
    /// The image a package's sky track plays into ([`VbimStream::sky_image`]); `None`:
    /// the sky is not written.
    pub sky: Option<Handle<Image>>,
    /// A cube map the sky is resampled into every frame ([`sky_cube_image`]), for Bevy's
    /// `Skybox` (its `brightness`: [`lux_per_unit`]`(SUN_LUX)`, the sky being in the
    /// lightmap's units) or a generated environment map; `None`: no cube is written.
    ///
    /// [`sky_cube_image`]: crate::sky_cube_image
    /// [`lux_per_unit`]: crate::lux_per_unit
    pub sky_cube: Option<Handle<Image>>,
    /// An image the package's light for objects is written into every frame
    /// ([`irradiance_volume_image`]), for Bevy's `IrradianceVolume`: sky and bounce per
    /// cell of its irradiance grid, so that ordinary meshes on the terrain are lit as the
    /// ground around them; `None`: nothing is written.
    ///
    /// [`irradiance_volume_image`]: crate::irradiance_volume_image
    pub irradiance_volume: Option<Handle<Image>>,
    /// The weather to show (a package's weather name; `None`: its first). Changing it
    /// switches weather: the new weather's tracks start reading at once and, when they show
    /// the shown time, lightmap and sky cross-fade over [`fade`](VbimPlayback::fade).
    pub weather: Option<String>,
    /// The cross-fade of a weather switch.
    pub fade: Duration,
    /// Whether a switch keeps the shown weather playing until the fade ends (`Live`: twice
    /// the GPU memory meanwhile) or holds its last image (`Held`: one weather's memory, the
    /// light standing still while the new weather's data comes).
    pub switch_mode: SwitchMode,
    /// The playback clock: integer nanoseconds of media time driven so far.
    pub(crate) clock_ns: u64,
    /// The last seek asked for: (generation, media time in ns).
    pub(crate) seek: (u32, u64),
}

impl VbimPlayback {
    /// Plays `stream` into `target` at the stream's own rate, with the `interpolate` policy
    /// and no bandwidth cap.
    pub fn new(stream: Handle<VbimStream>, target: Handle<Image>) -> Self {
        VbimPlayback {
            stream,
            target,
            paused: false,
            speed: 1.0,
            policy: Policy::Interpolate,
            throttle: Throttle::UNLIMITED,
            catch_up: Duration::from_millis(500),
            sky: None,
            sky_cube: None,
            irradiance_volume: None,
            weather: None,
            fade: Duration::from_secs(2),
            switch_mode: SwitchMode::Live,
            clock_ns: 0,
            seek: (0, 0),
        }
    }

    /// Switches to weather `name` with a cross-fade of `fade` (see [`VbimPlayback::weather`];
    /// [`VbimEventKind::WeatherChanged`] says when it is shown).
    pub fn switch_weather(&mut self, name: &str, fade: Duration) {
        self.weather = Some(name.to_string());
        self.fade = fade;
    }

    /// Jumps to `time` into the day (wrapped at the day's end for a looping stream), from
    /// the next rendered frame on.
    pub fn set_time(&mut self, time: Duration) {
        self.seek = (
            self.seek.0.wrapping_add(1),
            time.as_nanos().min(u64::MAX as u128) as u64,
        );
    }
}

/// What a playback showed in the last frame the render world reported (one frame behind
/// the main world's, as everything the render world says), and its running totals.
#[derive(Component, Clone, Debug, Default)]
pub struct VbimStats {
    /// The player is open and has shown at least one frame.
    pub playing: bool,
    /// The media time shown, from the start of the day (wrapped at loops).
    pub time: Duration,
    /// The media time shown, in frames from the start of the day (wrapped at loops).
    pub frame: f64,
    /// How far the display is behind the clock, media frames.
    pub drift: f64,
    /// What the last frame showed (`None` before the first).
    pub state: Option<FrameState>,
    /// Times the day wrapped at its end.
    pub loops: u64,
    /// Bytes the player holds on the GPU (every track; both weathers during a switch).
    pub gpu_bytes: u64,
    /// The weather shown (until a switch's fade ends, the one it started from).
    pub weather: String,
    /// The weather a switch in progress goes to, and its fade's weight (0 until the new
    /// weather's tracks show the shown time, then rising to 1).
    pub switching: Option<(String, f32)>,
    /// The player's running totals: frames, stalls, bytes read and uploaded, CPU time,
    /// damage.
    pub totals: Totals,
    /// What an object standing on the terrain receives at the time shown, for a package
    /// with irradiance tracks: `irradiance.at(u, v, normal)` (lightmap coordinates and a
    /// map-frame normal: x east, y south, z up; Bevy's x, z, y), in the lightmap's units.
    pub irradiance: Option<Irradiance>,
    /// A stall began and the true state has not been shown since.
    in_stall: bool,
}

/// Something that happened to a playback.
#[derive(Message, Clone, Debug, PartialEq)]
pub struct VbimEvent {
    /// The entity with the [`VbimPlayback`].
    pub entity: Entity,
    /// What happened.
    pub kind: VbimEventKind,
}

/// What happened to a playback.
#[derive(Clone, Debug, PartialEq)]
pub enum VbimEventKind {
    /// The player opened and its frames began (it may still be buffering: `VbimStats::state`
    /// says `Waiting` until the first data is shown).
    Loaded,
    /// The day wrapped at its end (a looping stream).
    Looped,
    /// Data came late: the display holds (or, with `wait`, the clock waits). The buffering
    /// before the first frame is not a stall.
    Stalled,
    /// The display shows the true state again after a stall.
    CaughtUp,
    /// A chunk was damaged or could not be read; playback goes on (the message names the
    /// chunk).
    Damaged(String),
    /// The stream could not be played (the image does not fit it, the file vanished, the
    /// device cannot hold it); the playback stays stopped.
    Failed(String),
    /// A weather switch's fade ended: the weather named is shown.
    WeatherChanged(String),
    /// A weather switch was refused (no such weather, or its tracks cannot be opened); the
    /// weather shown stays.
    WeatherRefused(String),
}

/// What the render world tells the main world about one playback.
pub(crate) enum Report {
    /// The player opened: the bytes it holds on the GPU.
    Opened { gpu_bytes: u64 },
    /// One rendered frame.
    Frame {
        record: FrameRecord,
        totals: Box<Totals>,
        frame_count: u32,
        rate: (u32, u32),
        looped: bool,
        weather: String,
        switching: Option<(String, f32)>,
        gpu_bytes: u64,
        irradiance: Option<Box<Irradiance>>,
    },
    /// The player could not open or write the image.
    Failed(String),
    /// A weather switch was refused.
    WeatherRefused(String),
}

/// The render world's reports, received by the main world.
#[derive(Resource)]
pub(crate) struct Reports(pub(crate) Mutex<Receiver<(Entity, Report)>>);

/// Advances every playback's clock by the frame's virtual time (which Bevy has already
/// scaled and paused) times the playback's own speed. The clock counts integer
/// nanoseconds; a frame's product is rounded once, so no float error accumulates.
pub(crate) fn advance_clocks(time: Res<Time<Virtual>>, mut playbacks: Query<&mut VbimPlayback>) {
    let delta = time.delta().as_nanos() as f64;
    for mut p in &mut playbacks {
        if p.paused || p.speed.is_nan() || p.speed <= 0.0 || delta == 0.0 {
            continue;
        }
        let step = (delta * p.speed).round().min(u64::MAX as f64) as u64;
        p.clock_ns = p.clock_ns.saturating_add(step);
    }
}

/// Turns the render world's reports into [`VbimStats`] and [`VbimEvent`]s.
pub(crate) fn receive_reports(
    reports: Res<Reports>,
    mut stats: Query<&mut VbimStats>,
    mut events: MessageWriter<VbimEvent>,
) {
    let Ok(rx) = reports.0.lock() else { return };
    for (entity, report) in rx.try_iter() {
        let Ok(mut s) = stats.get_mut(entity) else {
            continue;
        };
        let mut send = |kind| {
            events.write(VbimEvent { entity, kind });
        };
        match report {
            Report::Opened { gpu_bytes } => s.gpu_bytes = gpu_bytes,
            Report::Failed(e) => {
                s.playing = false;
                send(VbimEventKind::Failed(e));
            }
            Report::WeatherRefused(e) => send(VbimEventKind::WeatherRefused(e)),
            Report::Frame {
                record,
                totals,
                frame_count,
                rate,
                looped,
                weather,
                switching,
                gpu_bytes,
                irradiance,
            } => {
                if !s.playing {
                    send(VbimEventKind::Loaded);
                } else if s.weather != weather {
                    send(VbimEventKind::WeatherChanged(weather.clone()));
                }
                s.weather = weather;
                s.switching = switching;
                s.gpu_bytes = gpu_bytes;
                s.irradiance = irradiance.map(|b| *b);
                // A stall is the player's own count (a run of late frames counts once; the
                // buffering before the first frame is not one).
                if totals.stalls > s.totals.stalls {
                    s.in_stall = true;
                    send(VbimEventKind::Stalled);
                }
                if record.state == FrameState::Exact && s.in_stall {
                    s.in_stall = false;
                    send(VbimEventKind::CaughtUp);
                }
                if looped {
                    s.loops += 1;
                    send(VbimEventKind::Looped);
                }
                if totals.damaged > s.totals.damaged {
                    send(VbimEventKind::Damaged(
                        totals.last_error.clone().unwrap_or_default(),
                    ));
                }
                let frames = frame_count.max(1) as f64;
                let frame = record.shown.rem_euclid(frames);
                s.playing = true;
                s.frame = frame;
                s.time = Duration::from_secs_f64(
                    (frame * rate.1 as f64 / rate.0.max(1) as f64).max(0.0),
                );
                s.drift = record.drift;
                s.state = Some(record.state);
                s.totals = *totals;
            }
        }
    }
}
