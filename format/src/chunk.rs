//! Chunk payloads (`docs/FORMAT.md`, section "Chunk payloads"): keyframes, tile maps and
//! coefficient planes. Keyframe, tile-map and coefficient chunks are zstd frames; their
//! decompressed size is bounded by what the header allows before anything is allocated.

use crate::dct::N;
use crate::header::Header;
use crate::plane::{self, Plane};
use crate::{FormatError, Result};

pub const MODE_INTRA: u8 = 0;
pub const MODE_PREDICTED: u8 = 1;

thread_local! {
    /// Block storage reused by every coefficient stream this thread decodes.
    static BLOCKS: std::cell::RefCell<plane::Blocks> = Default::default();
}

/// Reads one coefficient stream of `n` blocks at `pos` and adds each dequantised block into
/// `plane` at the next of `origins` (block units).
fn add_stream(
    raw: &[u8],
    pos: &mut usize,
    n: usize,
    origins: impl Iterator<Item = (usize, usize)>,
    plane: &mut Plane,
    step: f32,
) -> Result<()> {
    BLOCKS.with_borrow_mut(|q| {
        plane::read_blocks(raw, pos, n, q)?;
        for ((bx, by), (qb, &nz)) in origins.zip(q.q.iter().zip(&q.nonzero)) {
            plane::add_dequantized_counted(plane, bx, by, qb, step, nz as usize);
        }
        Ok(())
    })
}

/// Padded plane size: whole tiles.
pub fn padded_size(h: &Header) -> (usize, usize) {
    let t = h.tile_size as usize;
    (h.tiles_x() as usize * t, h.tiles_y() as usize * t)
}

/// Decompresses a zstd frame, refusing output larger than `limit` bytes.
pub fn decompress(bytes: &[u8], limit: usize) -> Result<Vec<u8>> {
    if let Ok(Some(n)) = zstd::zstd_safe::get_frame_content_size(bytes) {
        if n > limit as u64 {
            return Err(FormatError::Invalid(format!(
                "payload claims {n} bytes decompressed (limit {limit})"
            )));
        }
    }
    zstd::bulk::decompress(bytes, limit).map_err(|e| FormatError::Invalid(format!("zstd: {e}")))
}

/// Upper bound of a decompressed payload holding `blocks` coefficient blocks.
fn stream_limit(blocks: usize, steps: usize) -> usize {
    16 + 4 * steps + blocks * N * N * 5
}

struct Bytes<'a> {
    b: &'a [u8],
    pos: usize,
}
impl<'a> Bytes<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let s = self
            .b
            .get(self.pos..self.pos + n)
            .ok_or_else(|| FormatError::Invalid("payload ends early".into()))?;
        self.pos += n;
        Ok(s)
    }
    fn f32(&mut self) -> Result<f32> {
        let v = f32::from_le_bytes(self.take(4)?.try_into().unwrap());
        if !v.is_finite() || v <= 0.0 {
            return Err(FormatError::Invalid(format!("quantiser step {v}")));
        }
        Ok(v)
    }
}

/// Raw (uncompressed) keyframe payload: mode, plane count, one step per plane, then each
/// plane's coefficients. `blocks[p]` are plane p's blocks in raster order.
pub fn write_keyframe(mode: u8, steps: &[f32], blocks: &[Vec<[i32; N * N]>]) -> Vec<u8> {
    let mut out = vec![mode, steps.len() as u8, 0, 0];
    for s in steps {
        out.extend_from_slice(&s.to_le_bytes());
    }
    for b in blocks {
        plane::write_coefficients(b, &mut out);
    }
    out
}

/// Decodes a keyframe chunk (already checksum-verified) into coded-domain planes.
/// `prev` is the previous decoded keyframe, required when the keyframe is predicted.
pub fn read_keyframe(h: &Header, bytes: &[u8], prev: Option<&[Plane]>) -> Result<Vec<Plane>> {
    let (w, ht) = padded_size(h);
    let planes = h.channels as usize;
    let nblocks = (w / N) * (ht / N);
    let raw = decompress(bytes, stream_limit(nblocks * planes, planes))?;
    read_keyframe_raw(h, &raw, prev)
}

/// Decodes an uncompressed keyframe payload (what [`write_keyframe`] returns). The encoder
/// uses it to measure candidate quantisers exactly as a player will decode them.
pub fn read_keyframe_raw(h: &Header, raw: &[u8], prev: Option<&[Plane]>) -> Result<Vec<Plane>> {
    let (w, ht) = padded_size(h);
    let planes = h.channels as usize;
    let nblocks = (w / N) * (ht / N);
    let mut r = Bytes { b: raw, pos: 0 };
    let head = r.take(4)?;
    let (mode, np) = (head[0], head[1] as usize);
    if np != planes {
        return Err(FormatError::Invalid(format!(
            "{np} planes, expected {planes}"
        )));
    }
    let base: Vec<Plane> = match mode {
        MODE_INTRA => vec![Plane::zeros(w, ht); planes],
        MODE_PREDICTED => match prev {
            Some(p) if p.len() == planes => p.to_vec(),
            _ => {
                return Err(FormatError::Invalid(
                    "predicted keyframe without its reference".into(),
                ))
            }
        },
        m => return Err(FormatError::Invalid(format!("unknown keyframe mode {m}"))),
    };
    let steps: Vec<f32> = (0..planes).map(|_| r.f32()).collect::<Result<_>>()?;
    let mut out = base;
    let mut pos = r.pos;
    for (p, step) in steps.iter().enumerate() {
        let (bw, bh) = (w / N, ht / N);
        let origins = (0..bh).flat_map(|y| (0..bw).map(move |x| (x, y)));
        add_stream(raw, &mut pos, nblocks, origins, &mut out[p], *step)?;
    }
    if pos != raw.len() {
        return Err(FormatError::Invalid(format!(
            "{} stray bytes after the planes",
            raw.len() - pos
        )));
    }
    Ok(out)
}

/// The per-tile polynomial degrees of one segment: luma (plane 0) and chroma (planes 1–2).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileMap {
    pub luma: Vec<u8>,
    pub chroma: Vec<u8>,
}

impl TileMap {
    pub fn degree(&self, plane: usize, tile: usize) -> u8 {
        if plane == 0 {
            self.luma[tile]
        } else {
            self.chroma[tile]
        }
    }
    pub fn max_degree(&self) -> u8 {
        self.luma
            .iter()
            .chain(&self.chroma)
            .copied()
            .max()
            .unwrap_or(1)
    }
}

/// Raw tile-map payload: luma degrees, then chroma degrees when there are 3 channels.
pub fn write_tilemap(t: &TileMap, channels: u8) -> Vec<u8> {
    let mut out = t.luma.clone();
    if channels == 3 {
        out.extend_from_slice(&t.chroma);
    }
    out
}

/// Decodes a tile map. A tile's degree is 1 to min(max degree, segment length), chroma's at
/// most luma's.
pub fn read_tilemap(h: &Header, bytes: &[u8], seg_len: u32) -> Result<TileMap> {
    let n = h.tile_count();
    let chroma_n = if h.channels == 3 { n } else { 0 };
    let raw = decompress(bytes, n + chroma_n)?;
    if raw.len() != n + chroma_n {
        return Err(FormatError::Invalid(format!(
            "tile map of {} bytes, expected {}",
            raw.len(),
            n + chroma_n
        )));
    }
    let cap = (h.max_degree as u32).min(seg_len.max(1)) as u8;
    let luma = raw[..n].to_vec();
    let chroma = if chroma_n > 0 {
        raw[n..].to_vec()
    } else {
        vec![1; n]
    };
    for t in 0..n {
        if !(1..=cap).contains(&luma[t]) || !(1..=luma[t]).contains(&chroma[t]) {
            return Err(FormatError::Invalid(format!(
                "tile {t}: degrees {}/{} outside 1–{cap}",
                luma[t], chroma[t]
            )));
        }
    }
    Ok(TileMap { luma, chroma })
}

/// Raw coefficient payload: the highest degree D present, plane count, a step per (degree,
/// plane), then for k = 2..=D and each plane the blocks of the tiles whose degree is ≥ k.
pub fn write_coeffs(max_degree: u8, steps: &[f32], blocks: &[Vec<[i32; N * N]>]) -> Vec<u8> {
    let planes = if max_degree > 1 {
        steps.len() / (max_degree as usize - 1)
    } else {
        0
    };
    let mut out = vec![max_degree, planes as u8, 0, 0];
    for s in steps {
        out.extend_from_slice(&s.to_le_bytes());
    }
    for b in blocks {
        plane::write_coefficients(b, &mut out);
    }
    out
}

/// Decodes a coefficient chunk into bubble planes: `result[k − 2][plane]`.
pub fn read_coeffs(h: &Header, bytes: &[u8], tiles: &TileMap) -> Result<Vec<Vec<Plane>>> {
    let (w, ht) = padded_size(h);
    let planes = h.channels as usize;
    let ts = h.tile_size as usize;
    let per_tile = (ts / N) * (ts / N);
    let n = h.tile_count();
    let total_blocks: usize = (0..n)
        .map(|t| {
            (0..planes)
                .map(|p| tiles.degree(p, t) as usize - 1)
                .sum::<usize>()
                * per_tile
        })
        .sum();
    let dmax = tiles.max_degree();
    let raw = decompress(
        bytes,
        stream_limit(total_blocks, planes * h.max_degree as usize),
    )?;
    let mut r = Bytes { b: &raw, pos: 0 };
    let head = r.take(4)?;
    if head[0] != dmax || (dmax > 1 && head[1] as usize != planes) {
        return Err(FormatError::Invalid(format!(
            "coefficients for degree {} × {} planes, tile map needs {dmax} × {planes}",
            head[0], head[1]
        )));
    }
    let nsteps = (dmax as usize - 1) * planes;
    let steps: Vec<f32> = (0..nsteps).map(|_| r.f32()).collect::<Result<_>>()?;
    let mut pos = r.pos;
    let tiles_x = h.tiles_x() as usize;
    let mut out = Vec::with_capacity(dmax as usize - 1);
    for k in 2..=dmax {
        let mut planes_k = Vec::with_capacity(planes);
        for p in 0..planes {
            let mut plane = Plane::zeros(w, ht);
            let members: Vec<usize> = (0..n).filter(|&t| tiles.degree(p, t) >= k).collect();
            let step = steps[(k as usize - 2) * planes + p];
            let origins = members
                .iter()
                .flat_map(|&t| plane::tile_blocks(t, tiles_x, ts));
            add_stream(
                &raw,
                &mut pos,
                members.len() * per_tile,
                origins,
                &mut plane,
                step,
            )?;
            planes_k.push(plane);
        }
        out.push(planes_k);
    }
    if pos != raw.len() {
        return Err(FormatError::Invalid(format!(
            "{} stray bytes after the planes",
            raw.len() - pos
        )));
    }
    Ok(out)
}
