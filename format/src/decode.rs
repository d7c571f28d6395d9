//! The CPU reference decoder: the definition of what a `.vbim` file decodes to. The GPU
//! player is tested against it, and the encoder uses its keyframe path to stay closed-loop.

use std::io::{Read, Seek};
use std::sync::Arc;

use crate::basis;
use crate::chunk::{self, TileMap};
use crate::color::ycocg_to_rgb;
use crate::header::Header;
use crate::memory::Limits;
use crate::plane::Plane;
use crate::reader::Reader;
use crate::{FormatError, Result};

/// Everything needed to evaluate any time inside one segment.
#[derive(Clone, Debug)]
pub struct Segment {
    /// The segment's number.
    pub index: usize,
    /// First boundary frame.
    pub start: u32,
    /// Last boundary frame.
    pub end: u32,
    /// The keyframe that opens the segment (K_s), one plane per channel.
    pub k0: Arc<Vec<Plane>>,
    /// The keyframe that closes it (K_{s+1}).
    pub k1: Arc<Vec<Plane>>,
    /// Each tile's degree.
    pub tiles: TileMap,
    /// `bubbles[k − 2][plane]`.
    pub bubbles: Vec<Vec<Plane>>,
}

/// What [`Segment::eval`] writes per texel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Output {
    /// Linear light (what the player's texture holds).
    Linear,
    /// What a decoded file stores: sRGB code value / 255 for 8-bit files, linear for HDR.
    Stored,
}

impl Segment {
    /// Evaluates the segment at frame time `t` (fractional frames, b_s ≤ t ≤ b_{s+1}) into
    /// `out` (`width × height × channels`, interleaved).
    pub fn eval(&self, h: &Header, t: f64, mode: Output, out: &mut [f32]) {
        let len = (self.end - self.start).max(1) as f64;
        let u = ((t - self.start as f64) / len).clamp(0.0, 1.0);
        let dmax = self.tiles.max_degree() as usize;
        let w = basis::weights(dmax, u);
        eval_planes(h, &self.k0, &self.k1, &self.bubbles, &w, mode, out);
    }
}

/// v = w0·K0 + w1·K1 + Σ w_k·C_k in the coded YCoCg domain, then RGB, clamp, transfer.
/// Tiles of lower degree hold zero bubble coefficients, so one loop serves them all.
pub fn eval_planes(
    h: &Header,
    k0: &[Plane],
    k1: &[Plane],
    bubbles: &[Vec<Plane>],
    w: &[f32; basis::MAX_TERMS],
    mode: Output,
    out: &mut [f32],
) {
    let (width, height) = (h.width as usize, h.height as usize);
    let ch = h.channels as usize;
    let pw = k0[0].w;
    let decode = |c: f32| match mode {
        Output::Linear => h.transfer.decode_linear(c),
        Output::Stored => h.transfer.decode_stored(c),
    };
    for y in 0..height {
        for x in 0..width {
            let i = y * pw + x;
            let mut v = [0f32; 3];
            for (p, vp) in v.iter_mut().enumerate().take(ch) {
                let mut s = w[0] * k0[p].data[i] + w[1] * k1[p].data[i];
                for (k, b) in bubbles.iter().enumerate() {
                    s += w[k + 2] * b[p].data[i];
                }
                *vp = s;
            }
            let o = (y * width + x) * ch;
            if ch == 3 {
                let rgb = ycocg_to_rgb(v);
                for c in 0..3 {
                    out[o + c] = decode(rgb[c]);
                }
            } else {
                out[o] = decode(v[0]);
            }
        }
    }
}

/// Decodes frames of a `.vbim` stream in any order, caching what sequential playback reuses.
pub struct Decoder<R> {
    reader: Reader<R>,
    last_key: Option<(usize, Arc<Vec<Plane>>)>,
    key0: Option<Arc<Vec<Plane>>>,
    segment: Option<Segment>,
}

impl<R: Read + Seek> Decoder<R> {
    /// A decoder reading from `reader`, within the default [`Limits`].
    pub fn new(reader: Reader<R>) -> Result<Self> {
        Self::with_limits(reader, Limits::default())
    }

    /// A decoder reading from `reader`, refused if the stream could need more memory than
    /// `limits` allow ([`crate::memory::decoder_memory`]).
    pub fn with_limits(reader: Reader<R>, limits: Limits) -> Result<Self> {
        let h = reader.header();
        limits.check(
            &format!(
                "decoding a {}×{} stream of {} channel(s), degree ≤ {}",
                h.width, h.height, h.channels, h.max_degree
            ),
            crate::memory::decoder_memory(h, reader.entries()),
        )?;
        Ok(Decoder {
            reader,
            last_key: None,
            key0: None,
            segment: None,
        })
    }
    /// The stream's header.
    pub fn header(&self) -> &Header {
        self.reader.header()
    }
    /// The reader underneath (for metadata and raw chunks).
    pub fn reader(&mut self) -> &mut Reader<R> {
        &mut self.reader
    }

    fn chunk_error(&self, i: usize, e: FormatError) -> FormatError {
        let entry = self.reader.entries()[i];
        match e {
            FormatError::Invalid(what) => FormatError::BadChunk {
                chunk: i,
                first: entry.first_frame,
                last: entry.last_frame,
                what,
            },
            other => other,
        }
    }

    /// The decoded keyframe `k` (stored numbering), decoding the predicted chain from the
    /// last intra keyframe at or before it when it is not cached.
    pub fn keyframe(&mut self, k: usize) -> Result<Arc<Vec<Plane>>> {
        if k == 0 {
            if let Some(k0) = &self.key0 {
                return Ok(k0.clone());
            }
        }
        if let Some((i, p)) = &self.last_key {
            if *i == k {
                return Ok(p.clone());
            }
        }
        let layout = self.reader.layout().clone();
        let entries = self.reader.entries().to_vec();
        let start = match &self.last_key {
            Some((i, _))
                if *i < k && (*i + 1..=k).all(|j| !entries[layout.keyframes[j]].is_intra()) =>
            {
                *i + 1
            }
            _ => (0..=k)
                .rev()
                .find(|&j| entries[layout.keyframes[j]].is_intra())
                .unwrap_or(0),
        };
        let mut prev = if start > 0 {
            self.last_key.as_ref().map(|(_, p)| p.clone())
        } else {
            None
        };
        for j in start..=k {
            let ci = layout.keyframes[j];
            let bytes = self.reader.read_chunk(ci)?;
            // An intra keyframe (by its index entry) has no reference, whatever its payload
            // says: a payload that disagrees is refused (the player does the same).
            let reference = match entries[ci].is_intra() {
                true => None,
                false => prev.as_deref().map(|v| &v[..]),
            };
            let planes = chunk::read_keyframe(self.reader.header(), &bytes, reference)
                .map_err(|e| self.chunk_error(ci, e))?;
            let planes = Arc::new(planes);
            if j == 0 {
                self.key0 = Some(planes.clone());
            }
            prev = Some(planes);
        }
        let p = prev.expect("at least one keyframe decoded");
        self.last_key = Some((k, p.clone()));
        Ok(p)
    }

    /// Loads segment `s` (keyframes, tile map, coefficients).
    pub fn segment(&mut self, s: usize) -> Result<&Segment> {
        if self.segment.as_ref().is_none_or(|seg| seg.index != s) {
            // The old segment's planes go first: the memory bound counts one segment's.
            self.segment = None;
            let layout = self.reader.layout().clone();
            let (ti, ci) = layout.segments[s];
            let (start, end) = (layout.boundaries[s], layout.boundaries[s + 1]);
            let k0 = self.keyframe(s)?;
            let k1 = self.keyframe(layout.keyframe_of_boundary(s + 1))?;
            let tbytes = self.reader.read_chunk(ti)?;
            let h = self.reader.header().clone();
            let tiles = chunk::read_tilemap(&h, &tbytes, end - start)
                .map_err(|e| self.chunk_error(ti, e))?;
            let cbytes = self.reader.read_chunk(ci)?;
            let bubbles =
                chunk::read_coeffs(&h, &cbytes, &tiles).map_err(|e| self.chunk_error(ci, e))?;
            self.segment = Some(Segment {
                index: s,
                start,
                end,
                k0,
                k1,
                tiles,
                bubbles,
            });
        }
        Ok(self.segment.as_ref().unwrap())
    }

    /// The segment containing frame time `t`, and `t` clamped into the sequence.
    pub fn locate(&self, t: f64) -> (usize, f64) {
        let b = &self.reader.layout().boundaries;
        let last = *b.last().unwrap() as f64;
        let t = t.clamp(0.0, last);
        let s = b.partition_point(|&x| x as f64 <= t).saturating_sub(1);
        (s.min(b.len().saturating_sub(2)), t)
    }

    /// Decodes frame time `t` into `out` (`width × height × channels`).
    pub fn frame(&mut self, t: f64, mode: Output, out: &mut [f32]) -> Result<()> {
        let h = self.reader.header().clone();
        let need = h.texel_count() * h.channels as usize;
        if out.len() != need {
            return Err(FormatError::Invalid(format!(
                "output holds {} values, need {need}",
                out.len()
            )));
        }
        if h.segment_count == 0 {
            // A single frame that does not loop: the keyframe is the whole sequence.
            let k = self.keyframe(0)?;
            let mut w = [0f32; basis::MAX_TERMS];
            w[0] = 1.0;
            eval_planes(&h, &k, &k, &[], &w, mode, out);
            return Ok(());
        }
        let (s, t) = self.locate(t);
        self.segment(s)?.eval(&h, t, mode, out);
        Ok(())
    }
}
