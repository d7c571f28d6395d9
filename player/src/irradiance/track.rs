//! One weather's irradiance track, decoded on the CPU by a thread of its own: the grid is
//! small (a 32² grid is a 160 × 64 image), so the format's reference decoder serves, and
//! the render thread only takes decoded frames from a channel and never waits for one.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::path::Path;
use std::sync::Arc;
use std::thread::JoinHandle;

use crossbeam_channel::{Receiver, Sender};
use vbim_format::decode::{Decoder, Output};
use vbim_format::irradiance::{read_track, Grid, GridInfo};
use vbim_format::{Limits, Reader};

use crate::PlayerError;

/// Frames decoded ahead of the shown one.
const AHEAD: usize = 6;

/// The two frames around a time and their weights.
pub(crate) type Around = [(Arc<Grid>, f32); 2];

/// A decoded frame, or why it could not be.
type Decoded = (usize, Result<Arc<Grid>, String>);

/// One weather's irradiance track being played.
pub(crate) struct IrradianceTrack {
    frames: usize,
    looping: bool,
    info: GridInfo,
    ask: Option<Sender<usize>>,
    got: Receiver<Decoded>,
    worker: Option<JoinHandle<()>>,
    cache: BTreeMap<usize, Arc<Grid>>,
    asked: BTreeSet<usize>,
    /// Frames that could not be decoded, with why (retried when asked for again after
    /// the time has left them).
    failed: BTreeMap<usize, String>,
}

impl IrradianceTrack {
    /// Opens the track at `path` (a `.vbim` file whose frames are grids) and starts its
    /// decoder thread.
    pub(crate) fn open(path: &Path, limits: Limits) -> Result<IrradianceTrack, PlayerError> {
        let err = |reason: String| PlayerError::Package {
            path: path.to_path_buf(),
            reason,
        };
        let file = File::open(path).map_err(|e| err(e.to_string()))?;
        let mut reader = Reader::open(file).map_err(|e| err(e.to_string()))?;
        let h = reader.header().clone();
        let (info, suns) = read_track(&mut reader).map_err(err)?;
        let [nx, ny] = info.cells;
        let frames = h.frame_count as usize;
        let mut decoder = Decoder::with_limits(reader, limits).map_err(|e| err(e.to_string()))?;
        let (ask, asked_rx) = crossbeam_channel::unbounded::<usize>();
        let (got_tx, got) = crossbeam_channel::unbounded::<Decoded>();
        let name = path.display().to_string();
        let grid = info.clone();
        let worker = std::thread::Builder::new()
            .name("vbim-irradiance".into())
            .spawn(move || {
                let mut rgb = vec![0f32; nx * ny * vbim_format::irradiance::LAYERS * 3];
                for k in asked_rx {
                    let r = decoder
                        .frame(k as f64, Output::Linear, &mut rgb)
                        .map(|()| {
                            Arc::new(Grid::from_image(&rgb, &grid, suns[k].dir, suns[k].color))
                        })
                        .map_err(|e| format!("{name}: frame {k}: {e}"));
                    if got_tx.send((k, r)).is_err() {
                        break;
                    }
                }
            })
            .map_err(PlayerError::Thread)?;
        Ok(IrradianceTrack {
            frames,
            looping: h.looping,
            info,
            ask: Some(ask),
            got,
            worker: Some(worker),
            cache: BTreeMap::new(),
            asked: BTreeSet::new(),
            failed: BTreeMap::new(),
        })
    }

    /// The grid's description.
    pub(crate) fn info(&self) -> &GridInfo {
        &self.info
    }

    /// The two frames around media time `t` (frames, not wrapped) and the second's weight.
    fn around(&self, t: f64) -> (usize, usize, f32) {
        let n = self.frames;
        let t = if self.looping {
            t.rem_euclid(n as f64)
        } else {
            t.clamp(0.0, (n - 1) as f64)
        };
        let k0 = (t.floor() as usize).min(n - 1);
        let k1 = if self.looping {
            (k0 + 1) % n
        } else {
            (k0 + 1).min(n - 1)
        };
        (k0, k1, (t - k0 as f64) as f32)
    }

    /// Takes what the thread decoded, asks for the frames around `t` and a few ahead, and
    /// returns the two frames around `t` with the second's weight, if both are decoded;
    /// else the first frame that failed, if one did.
    pub(crate) fn update(&mut self, t: f64) -> Result<Option<Around>, String> {
        while let Ok(decoded) = self.got.try_recv() {
            self.take(decoded);
        }
        let (k0, k1, w) = self.around(t);
        let n = self.frames;
        let window: Vec<usize> = (0..AHEAD + 2)
            .map(|d| {
                if self.looping {
                    (k0 + d) % n
                } else {
                    (k0 + d).min(n - 1)
                }
            })
            .collect();
        self.cache.retain(|k, _| window.contains(k));
        // A failed frame is asked for again once the time has left it.
        self.failed.retain(|k, _| window.contains(k));
        for &k in &window {
            if !self.cache.contains_key(&k)
                && !self.asked.contains(&k)
                && !self.failed.contains_key(&k)
            {
                if let Some(ask) = &self.ask {
                    if ask.send(k).is_ok() {
                        self.asked.insert(k);
                    }
                }
            }
        }
        match (self.cache.get(&k0), self.cache.get(&k1)) {
            (Some(a), Some(b)) => Ok(Some([(a.clone(), 1.0 - w), (b.clone(), w)])),
            _ => match self.failed.get(&k0).or_else(|| self.failed.get(&k1)) {
                Some(e) => Err(e.clone()),
                None => Ok(None),
            },
        }
    }

    /// Waits up to `timeout` until the frames around `t` are decoded (or one failed).
    pub(crate) fn wait(
        &mut self,
        t: f64,
        timeout: std::time::Duration,
    ) -> Result<Option<Around>, String> {
        let end = std::time::Instant::now() + timeout;
        loop {
            let r = self.update(t);
            if !matches!(r, Ok(None)) {
                return r;
            }
            // Sleeps until the thread sends a frame (or the time is up).
            let left = end.saturating_duration_since(std::time::Instant::now());
            match self.got.recv_timeout(left) {
                Ok(decoded) => self.take(decoded),
                Err(_) => return r,
            }
        }
    }

    /// Keeps a frame the thread sent: its grid, or why it could not be decoded.
    fn take(&mut self, (k, r): Decoded) {
        self.asked.remove(&k);
        match r {
            Ok(g) => {
                self.cache.insert(k, g);
                self.failed.remove(&k);
            }
            Err(e) => {
                self.failed.insert(k, e);
            }
        }
    }
}

impl Drop for IrradianceTrack {
    fn drop(&mut self) {
        // Closing the request channel ends the thread after the frame it is decoding.
        self.ask = None;
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}
