//! What the quantiser is handed, recorded for `vbim bench transforms` and `bench intra` (the `bench`
//! feature): each keyframe plane the encoder codes (the target of its chosen mode — the
//! frame, or its difference from the keyframe before) and each bubble plane's member tiles,
//! with the step and dead zone they are quantised with. A research harness for the next
//! coding tool: it measures what other transforms would make of the very planes the
//! encoder quantises. Nothing is recorded unless [`start`] was called.

use std::sync::Mutex;

/// What a recorded plane is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlaneKind {
    /// A keyframe coded on its own.
    IntraKeyframe,
    /// A keyframe coded as its difference from the keyframe before.
    PredictedKeyframe,
    /// A segment's bubble term `term` (2 up to the segment's degree).
    Bubble {
        /// The term's degree.
        term: usize,
    },
}

/// One plane as the quantiser saw it.
pub struct TappedPlane {
    /// What it is.
    pub kind: PlaneKind,
    /// 0 for luma, 1 and 2 for chroma (each plane's weight in the metric differs).
    pub plane: usize,
    /// Width and height in texels: a keyframe's whole plane; a bubble plane's member
    /// tiles side by side in one row, a tile high.
    pub w: usize,
    /// Height in texels.
    pub h: usize,
    /// Row-major values in the coded domain.
    pub data: Vec<f32>,
    /// The quantiser's step.
    pub step: f32,
    /// The quantiser's dead zone, in steps.
    pub deadzone: f32,
}

static TAPPED: Mutex<Option<Vec<TappedPlane>>> = Mutex::new(None);

/// Starts recording (dropping anything recorded before).
pub fn start() {
    *TAPPED.lock().unwrap() = Some(Vec::new());
}

/// Stops recording and returns what was recorded, in the order it was coded.
pub fn take() -> Vec<TappedPlane> {
    TAPPED.lock().unwrap().take().unwrap_or_default()
}

pub(crate) fn active() -> bool {
    TAPPED.lock().unwrap().is_some()
}

pub(crate) fn record(p: TappedPlane) {
    if let Some(v) = TAPPED.lock().unwrap().as_mut() {
        v.push(p);
    }
}
