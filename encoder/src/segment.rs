//! Segment search: how long the segment starting at a boundary may be. The longest one
//! whose fit with all bubbles meets the fit budget — over the frame, on every tile within
//! `WORST_TILE_FACTOR`, and on every frame within `WORST_FRAME_FACTOR` — found by growing
//! the length geometrically until one fails, then bisecting.

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::domain::Domain;
use crate::model::{self, CodedFrame, Projectors, SegmentParams};
use crate::EncoderConfig;

/// How far above the fit budget a single tile may be when choosing a segment's length
/// (the metric pools all texels; a worst frame of 38 dB allows local peaks).
const WORST_TILE_FACTOR: f64 = 3.0;
/// How far above the fit budget a single frame of a segment may be: keeps the error even
/// in time, so that fast transitions (sunrise, sunset, a loop seam there) are not where
/// the worst frames gather.
const WORST_FRAME_FACTOR: f64 = 1.25;

/// The frames the search sees: coded frames by number, subsampled as the search reads
/// them ([`Domain::subsampled`]), and how to fit them.
pub(crate) struct Search<'a> {
    /// The subsampled frames' domain.
    pub dom: &'a Domain,
    /// Texels a side of a subsampled tile.
    pub tile: usize,
    pub window: &'a BTreeMap<u32, Arc<CodedFrame>>,
    pub cfg: &'a EncoderConfig,
    pub params: &'a SegmentParams,
}

impl Search<'_> {
    /// The longest segment from boundary `b`, at most `max_len` frames.
    pub fn length(&self, b: u32, max_len: u32, projectors: &mut Projectors) -> u32 {
        let (cfg, sp) = (self.cfg, self.params);
        let mut ok = |len: u32| -> bool {
            if len as usize <= cfg.max_degree {
                return true; // as many bubbles as interior frames: an exact fit
            }
            let frames: Vec<&CodedFrame> =
                (b..=b + len).map(|i| self.window[&i].as_ref()).collect();
            let p = projectors.get(len, cfg.max_degree);
            let (rms, worst_tile, worst_frame) =
                model::fit_error(self.dom, self.tile, 1, &frames, &p);
            rms <= sp.fit_budget
                && worst_tile <= WORST_TILE_FACTOR * sp.fit_budget
                && worst_frame <= WORST_FRAME_FACTOR * sp.fit_budget
        };
        let (mut good, mut bad) = (1u32, None);
        let mut l = 2u32;
        while l <= max_len {
            if ok(l) {
                good = l;
                l = if l < 4 { l + 1 } else { l + l / 2 };
            } else {
                bad = Some(l);
                break;
            }
        }
        match bad {
            None if good < max_len && ok(max_len) => max_len,
            None => good,
            Some(mut hi) => {
                while hi - good > 1 {
                    let mid = good + (hi - good) / 2;
                    if ok(mid) {
                        good = mid;
                    } else {
                        hi = mid;
                    }
                }
                good
            }
        }
    }
}
