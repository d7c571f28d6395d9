//! A package's light for objects while it plays: each frame, the shown weather's
//! irradiance track at the lightmap's shown time (and, during a weather's fade, the new
//! weather's too, mixed by the fade's weight), answered on the CPU and uploaded for shaders.
//! A frame whose grid is not decoded yet, or could not be, is held: the last answer stays
//! until the track has the shown time again.

use vbim_format::irradiance::GridInfo;

use super::{PackagePlayer, Tracks};
use crate::irradiance::{Irradiance, IrradianceBuffer};

/// The shown light for objects and its buffer.
pub(super) struct Objects {
    buffer: IrradianceBuffer,
    shown: Irradiance,
    /// During a held switch: what was shown when the old weather closed.
    from: Option<Irradiance>,
    info: GridInfo,
    /// The last step's times and weights, which [`PackagePlayer::wait_irradiance`] repeats.
    last: Step,
}

/// The shown weather's time, the new weather's time and the fade's weight during a live
/// switch, and a held switch's weight.
type Step = (f64, Option<(f64, f32)>, Option<f32>);

/// What the light for objects did this frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectsRecord {
    /// Whether the answer is the shown time's: false while the grid is held (its frames
    /// not decoded yet, or damaged).
    pub exact: bool,
    /// Why a frame could not be decoded, naming the file and the frame.
    pub error: Option<String>,
    /// Bytes written to the irradiance buffer this frame.
    pub bytes_uploaded: u64,
}

impl Objects {
    pub(super) fn new(device: &wgpu::Device, tracks: &Tracks) -> Option<Objects> {
        let t = tracks.irradiance.as_ref()?;
        let info = t.info().clone();
        Some(Objects {
            buffer: IrradianceBuffer::new(device, info.cells[0], info.cells[1]),
            shown: Irradiance::default(),
            from: None,
            info,
            last: (0.0, None, None),
        })
    }

    pub(super) fn gpu_bytes(&self) -> u64 {
        self.buffer.bytes()
    }
}

/// The frames of `tracks`' irradiance around media time `t`: `Ok(None)` while they are
/// being decoded.
fn frames(tracks: &mut Tracks, t: f64) -> Result<Option<Irradiance>, String> {
    match tracks.irradiance.as_mut() {
        Some(tr) => Ok(tr.update(t)?.map(|s| Irradiance::new(s.to_vec()))),
        None => Ok(None),
    }
}

impl PackagePlayer {
    /// Steps the light for objects to the lightmap's shown time `shown` (and the new
    /// weather's `to_shown` with the fade's `weight` during a switch).
    pub(super) fn step_objects(
        &mut self,
        shown: f64,
        to: Option<(f64, f32)>,
        held_weight: Option<f32>,
    ) -> Option<ObjectsRecord> {
        let objects = self.objects.as_mut()?;
        objects.last = (shown, to, held_weight);
        let mut error = None;
        let mut take = |r: Result<Option<Irradiance>, String>| {
            r.unwrap_or_else(|e| {
                error = Some(e);
                None
            })
        };
        let now = take(frames(&mut self.shown, shown));
        let next = match (to, self.switch.as_mut()) {
            (Some((t, w)), Some(sw)) => Some((take(frames(&mut sw.to, t)), w)),
            _ => None,
        };
        let mixed = match (held_weight, next) {
            (Some(w), _) => {
                // A held switch: `shown` is the new weather; the old answer fades out.
                let from = objects
                    .from
                    .get_or_insert_with(|| objects.shown.clone())
                    .clone();
                now.map(|n| from.mix(n, w))
            }
            (None, Some((n, w))) if w > 0.0 => now.zip(n).map(|(a, b)| a.mix(b, w)),
            _ => {
                objects.from = None;
                now
            }
        };
        let exact = mixed.is_some();
        if let Some(m) = mixed {
            objects.shown = m;
        }
        let bytes_uploaded = objects.buffer.upload(&self.queue, &objects.shown);
        Some(ObjectsRecord {
            exact,
            error,
            bytes_uploaded,
        })
    }

    /// What a surface at lightmap coordinates (u, v) (0 to 1; u east, v south) with unit
    /// normal `n` (map frame: x east, y south, z up) receives at the shown time:
    /// irradiance / π, linear RGB, in the lightmap's units — the sun kept apart and sky
    /// and bounce in spherical harmonics, from the grid of the weather's irradiance
    /// track (`docs/PLAYER.md`, "Light for objects"). `None` for a package without
    /// irradiance tracks, or before its first frame is decoded. The same answer as the
    /// shader function of [`crate::irradiance_wgsl`] over [`Self::irradiance_buffer`].
    pub fn irradiance(&self, u: f32, v: f32, n: [f32; 3]) -> Option<[f32; 3]> {
        let o = self.objects.as_ref()?;
        o.shown.slots().next()?;
        Some(o.shown.at(u, v, n))
    }

    /// The frames the shown answer mixes ([`Self::irradiance`] is their weighted sum).
    pub fn irradiance_frames(&self) -> Option<&Irradiance> {
        self.objects.as_ref().map(|o| &o.shown)
    }

    /// The storage buffer that holds the shown grid for shaders ([`crate::irradiance_wgsl`]
    /// says how to bind it); rewritten in the frame's submission.
    pub fn irradiance_buffer(&self) -> Option<&wgpu::Buffer> {
        self.objects.as_ref().map(|o| o.buffer.buffer())
    }

    /// The grid's cells, height above the ground and albedo, if the package has one.
    pub fn irradiance_grid(&self) -> Option<&GridInfo> {
        self.objects.as_ref().map(|o| &o.info)
    }

    /// Waits up to `timeout` for the grids of the last frame's time (the shown weather's,
    /// and during a switch the new one's), then steps to them again (for tools and tests
    /// that need the answer now, not a frame later).
    pub fn wait_irradiance(&mut self, timeout: std::time::Duration) -> Option<ObjectsRecord> {
        let (shown, to, held) = self.objects.as_ref()?.last;
        let end = std::time::Instant::now() + timeout;
        if let Some(tr) = self.shown.irradiance.as_mut() {
            let _ = tr.wait(shown, timeout);
        }
        if let (Some((t, _)), Some(sw)) = (to, self.switch.as_mut()) {
            if let Some(tr) = sw.to.irradiance.as_mut() {
                let _ = tr.wait(t, end.saturating_duration_since(std::time::Instant::now()));
            }
        }
        self.step_objects(shown, to, held)
    }
}
