//! A held weather switch ([`SwitchMode::Held`](super::SwitchMode::Held)): the shown
//! weather's tracks close at once and the outputs keep its last image; when the new
//! weather shows the shown time, that image is copied aside and faded into the new weather.
//! One weather's memory, plus 8 bytes a texel for the copy during the fade.

use super::fade::FadeJob;
use super::PackagePlayer;
use crate::{lightmap_descriptor, FrameRecord, FrameState, PlayerError, SwitchRecord};

/// A held switch in progress.
pub(super) struct Held {
    /// The weather whose last image the outputs hold, and the media time it showed.
    pub(super) from: String,
    at: f64,
    fade_ns: u64,
    /// The package clock of the frame the switch began in.
    asked: Option<u64>,
    /// Once the new weather shows the shown time: the fade's start, its passes, and the
    /// copies of the held images they read.
    fading: Option<(u64, FadeJob, Option<FadeJob>, Vec<wgpu::Texture>)>,
}

impl Held {
    pub(super) fn fading(&self) -> bool {
        self.fading.is_some()
    }

    /// The media time of the image on screen while only the held image is (before the
    /// fade), frames.
    pub(super) fn still(&self) -> Option<f64> {
        self.fading.is_none().then_some(self.at)
    }

    /// Bytes of the held images' copies.
    pub(super) fn bytes(&self) -> u64 {
        self.fading.as_ref().map_or(0, |f| {
            f.3.iter()
                .map(|t| t.width() as u64 * t.height() as u64 * 8)
                .sum()
        })
    }
}

impl PackagePlayer {
    /// Starts (or redirects) a held switch to `name`.
    pub(super) fn switch_held(&mut self, name: &str, fade_ns: u64) -> Result<(), PlayerError> {
        // A held switch that has not begun to fade is redirected: the image held stays.
        let (from, held_at) = match self.held.take() {
            Some(h) => (h.from, h.at),
            None if name == self.shown.name => return Ok(()),
            None => (self.shown.name.clone(), self.last_shown),
        };
        let to = self.open_joined(name)?;
        // The outputs keep the shown weather's last image; its tracks close now.
        self.shown = to;
        self.held = Some(Held {
            from,
            at: held_at,
            fade_ns,
            asked: None,
            fading: None,
        });
        Ok(())
    }

    /// The held switch's frame: once the new weather (now `shown`, in its own textures)
    /// shows its time exactly, copy the held images aside and fade them into it. Returns
    /// the frame's switch record and whether the fade is over.
    pub(super) fn advance_held(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        lightmap: &FrameRecord,
        sky: Option<&FrameRecord>,
    ) -> (SwitchRecord, bool) {
        let h = self.held.as_mut().expect("a held switch");
        let mut weight = 0.0;
        let mut done = false;
        match &h.fading {
            None => {
                let exact = |r: &FrameRecord| r.state == FrameState::Exact;
                if exact(lightmap) && sky.is_none_or(exact) {
                    let copy = |out: &wgpu::Texture, enc: &mut wgpu::CommandEncoder| {
                        let t = self.device.create_texture(&lightmap_descriptor(
                            out.width(),
                            out.height(),
                            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                        ));
                        enc.copy_texture_to_texture(
                            out.as_image_copy(),
                            t.as_image_copy(),
                            out.size(),
                        );
                        t
                    };
                    let size = |t: &wgpu::Texture| (t.width(), t.height());
                    let held_lm = copy(&self.lightmap.0, enc);
                    let lm = self.fade.job(
                        &self.device,
                        &held_lm.create_view(&Default::default()),
                        self.shown.lightmap.view(),
                        &self.lightmap.1,
                        size(&self.lightmap.0),
                    );
                    let mut textures = vec![held_lm];
                    let sk = match (&self.sky, &self.shown.sky) {
                        (Some((t, v)), Some(p)) => {
                            let held_sky = copy(t, enc);
                            let job = self.fade.job(
                                &self.device,
                                &held_sky.create_view(&Default::default()),
                                p.view(),
                                v,
                                size(t),
                            );
                            textures.push(held_sky);
                            Some(job)
                        }
                        _ => None,
                    };
                    h.fading = Some((self.ticks, lm, sk, textures));
                }
            }
            Some((start, lm, sk, _)) => {
                weight = ((self.ticks - start) as f64 / h.fade_ns.max(1) as f64).min(1.0) as f32;
                self.fade.record(&self.queue, enc, lm, weight);
                if let Some(sk) = sk {
                    self.fade.record(&self.queue, enc, sk, weight);
                }
                done = weight >= 1.0;
            }
        }
        let record = SwitchRecord {
            to: self.shown.name.clone(),
            lightmap: *lightmap,
            sky: sky.copied(),
            weight,
            since_ns: self.ticks - *h.asked.get_or_insert(self.ticks),
        };
        (record, done)
    }

    /// The held fade is over: the new weather writes the outputs.
    pub(super) fn finish_held(&mut self) {
        if self.held.take().is_some() {
            self.shown_takes_over();
        }
    }
}
