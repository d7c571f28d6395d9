//! A playback session: `vbim play`'s settings turned once into typed values, and what
//! both the headless player (`cmd_play.rs`) and the window (`window.rs`) need around a
//! player — the reference decoder, the metric, the terrain and the sky.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use vbim_format::decode::Decoder;
use vbim_format::metrics::Metric;
use vbim_format::{Header, Limits, Reader};
use vbim_player::{PackageFile, PackagePlayer, Player, PlayerConfig, Policy, Throttle};
use vbim_scene::SkyTrack;

use crate::cli::PlayArgs;
use crate::progress::Stages;
use crate::sequence::{open_input, Sequence};

/// Everything one playback session needs.
#[derive(Clone)]
pub struct Session {
    /// The lightmap track the session measures: the file itself, or a package's weather's.
    pub file: PathBuf,
    /// What was asked to play: `file`, or the package it belongs to.
    pub package: PathBuf,
    /// The weather played (a plain file's is the package module's `SINGLE_WEATHER`).
    pub weather: String,
    /// Switches to other weathers at clock times (ns), in time order; and their fade (ns).
    pub switches: Vec<(String, u64)>,
    pub fade_ns: u64,
    /// `PackagePlayer::set_switch_mode(Held)`.
    pub hold_on_switch: bool,
    pub policy: Policy,
    pub throttle: Throttle,
    pub catch_up_ns: u64,
    pub ring: Option<usize>,
    pub preroll_margin_ns: u64,
    /// `PlayerConfig::decode_budget`.
    pub decode_budget: Option<u64>,
    /// `PlayerConfig::reuse_share`.
    pub reuse_share: f32,
    pub realtime: bool,
    pub duration_ns: u64,
    pub display_hz: u32,
    /// The media advances this many times slower than the display's clock.
    pub slow: u64,
    /// Media frame to start at.
    pub start: u64,
    pub check_every: u64,
    /// The memory the stream may take, in the player and in the reference decoder each.
    pub limits: Limits,
}

impl Session {
    /// The display clock's time of `--start`, ns, checked against the stream's frames
    /// (`header` is the played track's): a frame past the last is a bad argument, not a
    /// time that overflows.
    pub fn start_ns(&self, header: &vbim_format::Header) -> Result<u64, String> {
        start_ns(self.start, header).map_err(|e| format!("--start: {e} ({})", self.file.display()))
    }

    /// Displayed frames in the session (duration × display rate, saturating).
    pub fn display_frames(&self) -> u64 {
        (self.duration_ns as u128 * self.display_hz as u128 / 1_000_000_000).min(u64::MAX as u128)
            as u64
    }

    /// The session `vbim play`'s flags ask for: the one place they become settings. A
    /// bandwidth relative to the stream's mean rate needs the file's header.
    pub fn from_args(a: &PlayArgs) -> Result<Session, String> {
        let limits = a.memory.limits;
        let package = PackageFile::open(&a.file).map_err(|e| e.to_string())?;
        let weather = match &a.weather {
            Some(w) => w.clone(),
            None => package.package.weathers[0].name.clone(),
        };
        let file = package.weather(&weather).map_err(|e| e.to_string())?;
        let file = a
            .file
            .parent()
            .unwrap_or(Path::new(""))
            .join(&file.lightmap);
        let mut switches = Vec::new();
        for sw in &a.switch_weather {
            package.weather(&sw.weather).map_err(|e| e.to_string())?;
            switches.push((sw.weather.clone(), sw.at.ns()));
        }
        switches.sort_by_key(|s| s.1);
        let h = open_reference(&file, limits)?.header().clone();
        let rate = a
            .bandwidth
            .map(|b| b.bytes_per_second(h.file_size, h.frame_count as f64 / h.fps()));
        Ok(Session {
            file,
            package: a.file.clone(),
            weather,
            switches,
            fade_ns: a.fade.ns(),
            hold_on_switch: a.hold_on_switch,
            policy: a.policy,
            throttle: Throttle {
                rate,
                stall: a.stall.as_ref().map(|s| s.stall),
            },
            catch_up_ns: a.catch_up.ns(),
            ring: a.ring.map(|r| r as usize),
            preroll_margin_ns: a.preroll_margin.ns(),
            decode_budget: a.decode_budget,
            reuse_share: a.reuse_share,
            realtime: a.realtime,
            duration_ns: a.duration.ns(),
            display_hz: a.display_hz,
            slow: a.slow,
            start: a.start,
            check_every: a.check_every,
            limits,
        })
    }

    /// Opens the session's file in a player on `device` (reader and decoder on their own
    /// threads when `threaded`, else stepped inside `advance`).
    pub fn open_player(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        threaded: bool,
    ) -> Result<Player<BufReader<File>>, String> {
        let name = self.file.display().to_string();
        let f = open_input(&self.file)?;
        Player::open(device, queue, BufReader::new(f), self.config(threaded))
            .map_err(|e| format!("{name}: {e}"))
    }

    /// Opens the session's package (or file) at its weather, with its sky.
    pub fn open_package(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        threaded: bool,
    ) -> Result<PackagePlayer, String> {
        let mut p = PackagePlayer::open(
            device,
            queue,
            &self.package,
            Some(&self.weather),
            self.config(threaded),
        )
        .map_err(|e| e.to_string())?;
        if self.hold_on_switch {
            p.set_switch_mode(vbim_player::SwitchMode::Held);
        }
        Ok(p)
    }

    /// The player settings of the session.
    fn config(&self, threaded: bool) -> PlayerConfig {
        PlayerConfig {
            policy: self.policy,
            catch_up_ns: self.catch_up_ns,
            throttle: self.throttle,
            ring_bytes: self.ring,
            preroll_margin_ns: self.preroll_margin_ns,
            decode_budget: self.decode_budget,
            reuse_share: self.reuse_share,
            threaded,
            limits: self.limits,
            ..Default::default()
        }
    }

    /// What the scene needs from the bake of the session's file: the export curve's
    /// exposure (1 for an 8-bit stream) and the sky over the day.
    pub fn scene_look(&self) -> Result<(f32, SkyTrack), String> {
        let mut seq = Sequence::open(&self.file.to_string_lossy(), self.limits)?;
        let exposure = match seq.metric(&Stages::new())? {
            Metric::Hdr { exposure } => exposure,
            Metric::Srgb8 => 1.0,
        };
        Ok((exposure, SkyTrack::from_manifest(seq.manifest().as_ref())))
    }

    /// The metric for comparing shown frames of the session's file with true ones.
    pub fn metric(&self) -> Result<Metric, String> {
        Sequence::open(&self.file.to_string_lossy(), self.limits)?.metric(&Stages::new())
    }

    /// The reference decoder of the session's file.
    pub fn reference(&self) -> Result<Decoder<BufReader<File>>, String> {
        open_reference(&self.file, self.limits)
    }
}

/// The terrain mesh of a scene file, and its height field.
pub fn scene_mesh(scene_file: &Path) -> Result<(vbim_scene::Mesh, vbim_bake::HeightField), String> {
    let scene = vbim_bake::Scene::load(scene_file).map_err(|e| e.to_string())?;
    let hf = vbim_bake::load_terrain(&scene).map_err(|e| e.to_string())?;
    let mesh = vbim_scene::Mesh::new(
        &hf,
        256,
        scene.view.vertical_exaggeration as f32,
        scene.view.snow_line as f32,
    );
    Ok((mesh, hf))
}

pub fn mean_rate(h: &Header) -> f64 {
    h.file_size as f64 / (h.frame_count as f64 / h.fps())
}

fn open_reference(file: &Path, limits: Limits) -> Result<Decoder<BufReader<File>>, String> {
    let name = file.display();
    let f = open_input(file)?;
    let r = Reader::open(BufReader::new(f)).map_err(|e| format!("{name}: {e}"))?;
    Decoder::with_limits(r, limits).map_err(|e| format!("{name}: {e}"))
}

/// Media frame `start`'s time on a player's clock, ns; an error if the stream has no such
/// frame.
pub fn start_ns(start: u64, header: &vbim_format::Header) -> Result<u64, String> {
    let frames = header.frame_count as u64;
    if start >= frames {
        return Err(format!(
            "frame {start} is past the stream's last, {} ({frames} frames)",
            frames.saturating_sub(1)
        ));
    }
    frame_ns(start, header).ok_or_else(|| format!("frame {start} is beyond the player's clock"))
}

/// Media frame `frame`'s time on a player's clock, ns (`None` past 2^64 − 1: the product
/// is taken in u128, where 2^32 frames at a rate of 1/2^32 fps still fit; within u64 for
/// any stream a player opens, whose duration is checked in ns).
pub fn frame_ns(frame: u64, header: &vbim_format::Header) -> Option<u64> {
    let ns =
        frame as u128 * 1_000_000_000 * header.rate_den as u128 / header.rate_num.max(1) as u128;
    u64::try_from(ns).ok()
}
