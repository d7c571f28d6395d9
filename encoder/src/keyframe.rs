//! Keyframe coding: every keyframe, the first one included, is coded intra and — while
//! the intra interval allows it — also as the difference from the previous *decoded*
//! keyframe; the smaller is kept, and decoded again at once with the reference decoder so
//! that the next prediction starts from what a player will have (closed loop).

use std::sync::Arc;

use vbim_format::chunk;
use vbim_format::plane::Plane;
use vbim_format::Header;

use crate::model::{self, CodedFrame};
use crate::EncodeError;

/// A keyframe as stored, and as every decoder will see it.
pub(crate) struct CodedKeyframe {
    /// The chunk's payload, before its coding for the file's version (`payloads`).
    pub bytes: Vec<u8>,
    /// The planes a decoder reconstructs from it.
    pub decoded: Arc<Vec<Plane>>,
    /// Coded on its own (else predicted from the keyframe before).
    pub intra: bool,
}

/// How keyframes are quantised: the error budget and the quantiser's shape.
#[derive(Clone, Copy)]
pub(crate) struct KeyParams {
    pub budget: f64,
    pub chroma_step_factor: f32,
    pub deadzone: f32,
    /// Squared steps a bit is worth to the rate-aware quantiser (0: off).
    pub rate_lambda: f32,
}

/// Codes `frame` as a keyframe of the stream described by `header`. `prev`: the decoded
/// keyframe before it, when the intra interval allows predicting from it; `None` codes it
/// intra (keyframe 0, or an interval reached). `sens_rms`: the RMS sensitivity its error
/// is weighed by in the frames it reaches ([`crate::reach::keyframe`]).
pub(crate) fn code(
    frame: &CodedFrame,
    prev: Option<&[Plane]>,
    header: &Header,
    p: KeyParams,
    sens_rms: f64,
) -> Result<CodedKeyframe, EncodeError> {
    let payload = |prev: Option<&[Plane]>| {
        model::code_keyframe(
            frame,
            prev,
            p.budget,
            sens_rms,
            p.chroma_step_factor,
            p.deadzone,
            p.rate_lambda,
        )
    };
    // Both quantise with the same step, but a residual carries the reference's
    // quantisation noise as well as the change, and a change that falls in the dead zone
    // is dropped: where the light moves fast (sunrise, sunset) the intra frame is often the
    // smaller, and the more accurate (BENCHMARKS.md, "Keyframe modes"). The two are
    // compared before zstd, which ranks them as zstd does at a fraction of the time.
    let (predicted, raw) = match prev {
        Some(prev) => {
            let (p, i) = rayon::join(|| payload(Some(prev)), || payload(None));
            if p.len() <= i.len() {
                (true, p)
            } else {
                (false, i)
            }
        }
        None => (false, payload(None)),
    };
    let reference = if predicted { prev } else { None };
    #[cfg(feature = "bench")]
    tap_keyframe(frame, reference, &p, sens_rms);
    let decoded = Arc::new(chunk::read_keyframe_raw(header, &raw, reference)?);
    Ok(CodedKeyframe {
        bytes: raw,
        decoded,
        intra: !predicted,
    })
}

/// Records the planes the quantiser was handed for the mode kept (`crate::tap`).
#[cfg(feature = "bench")]
fn tap_keyframe(frame: &CodedFrame, reference: Option<&[Plane]>, p: &KeyParams, sens_rms: f64) {
    use crate::tap::{PlaneKind, TappedPlane};
    if !crate::tap::active() {
        return;
    }
    for (pl, src) in frame.planes.iter().enumerate() {
        crate::tap::record(TappedPlane {
            kind: match reference {
                Some(_) => PlaneKind::PredictedKeyframe,
                None => PlaneKind::IntraKeyframe,
            },
            plane: pl,
            w: src.w,
            h: src.h,
            data: model::keyframe_target(frame, reference, pl).data,
            step: model::keyframe_step(p.budget, sens_rms, p.chroma_step_factor, pl),
            deadzone: p.deadzone,
        });
    }
}
