//! Chunk payloads (`docs/FORMAT.md`, section "Chunk payloads"): keyframes, tile maps and
//! coefficient planes. Keyframe, tile-map and coefficient chunks are zstd frames; their
//! decompressed size is bounded by what the header allows before anything is allocated.

use crate::dct::N;
pub use crate::head::{padded_size, TileMap, MODE_INTRA, MODE_PREDICTED};
use crate::header::{Coding, Header};
use crate::limits::payload_bound;
use crate::payload2;
pub use crate::payload2::Payload;
use crate::plane::{self, Onto, Plane};
use crate::scan;
pub use crate::scan::{scan, AcTerms, EntryPoint, ENTRY_PAIRS, FILL_BLOCKS};
use crate::{FormatError, Result};

thread_local! {
    /// Block storage reused by every coefficient stream this thread decodes.
    static BLOCKS: std::cell::RefCell<plane::Blocks> = Default::default();
    /// Entry points of the stream this thread scanned last.
    static ENTRIES: std::cell::RefCell<Vec<scan::EntryPoint>> = Default::default();
}

/// One keyframe plane: `base` (the predecessor's plane; zeros for an intra keyframe) plus
/// the stream's blocks. Built one row of blocks at a time: each row is copied from the
/// base and gets its blocks added while it is in cache, rather than the whole base being
/// copied first and walked again (the additions are the same, in the same order).
fn keyframe_plane(
    raw: &[u8],
    pos: &mut usize,
    (w, ht): (usize, usize),
    base: Reference<&Plane, Plane>,
    step: f32,
) -> Result<Plane> {
    let dims = match &base {
        Reference::None => None,
        Reference::Borrowed(b) => Some((b.w, b.h)),
        Reference::Owned(b) => Some((b.w, b.h)),
    };
    if let Some((bw, bh)) = dims.filter(|&d| d != (w, ht)) {
        return Err(FormatError::Invalid(format!(
            "reference keyframe is {bw}×{bh}, expected {w}×{ht}"
        )));
    }
    let bw = w / N;
    BLOCKS.with_borrow_mut(|q| {
        plane::read_blocks(raw, pos, bw * (ht / N), q)?;
        let base = match base {
            // Nothing to copy: the blocks are added where the reference is.
            Reference::Owned(mut out) => {
                let at = plane::all_blocks(&out);
                plane::add_blocks_of(&mut out, at, Onto::Plane, q, 0, step);
                return Ok(out);
            }
            Reference::Borrowed(b) => Some(b),
            Reference::None => None,
        };
        let mut out = Plane {
            w,
            h: ht,
            data: plane::try_storage(w, ht)?,
        };
        for by in 0..ht / N {
            let rows = by * N * w..(by + 1) * N * w;
            match base {
                Some(b) => out.data.extend_from_slice(&b.data[rows]),
                None => out.data.resize(rows.end, 0.0),
            }
            let at = (0..bw).map(|bx| (bx, by));
            plane::add_blocks_of(&mut out, at, Onto::Plane, q, by * bw, step);
        }
        Ok(out)
    })
}

/// The most a keyframe or coefficient payload of `blocks` coded blocks and `steps`
/// quantiser steps may decompress to: the format's bound ([`payload_bound`]), and no more
/// than the header's largest payload where it states one (1.1).
pub fn payload_limit(h: &Header, blocks: usize, steps: usize, stored: usize) -> usize {
    let bound = payload_bound(blocks, steps, stored);
    h.largest_payload.map_or(bound, |p| {
        bound.min(usize::try_from(p).unwrap_or(usize::MAX))
    })
}

/// A keyframe or coefficient chunk's payload as version 1 has it before zstd, refusing
/// one larger than `limit` bytes: decompressed (version 1), or its coefficient section
/// decoded and written as pairs (version 2, [`payload2::to_pairs`]).
pub fn payload(h: &Header, what: Payload, bytes: &[u8], limit: usize) -> Result<Vec<u8>> {
    match h.coding {
        Coding::Pairs => decompress(bytes, limit),
        Coding::Lanes(..) => payload2::to_pairs(h, what, bytes, limit),
    }
}

/// Decompresses a zstd frame, refusing output larger than `limit` bytes.
pub fn decompress(bytes: &[u8], limit: usize) -> Result<Vec<u8>> {
    let zstd_error = |e: std::io::Error| FormatError::Invalid(format!("zstd: {e}"));
    let capacity = match zstd::zstd_safe::get_frame_content_size(bytes) {
        Ok(Some(n)) if n > limit as u64 => {
            return Err(FormatError::Invalid(format!(
                "payload claims {n} bytes decompressed (limit {limit}: the format's bound, the header's largest payload, or {}× its stored size)",
                crate::limits::MAX_EXPANSION
            )));
        }
        // The encoder's frames state their size: allocate that, not the limit.
        Ok(Some(n)) => n as usize,
        _ => {
            // A frame that does not state its size (not one this encoder writes) grows its
            // output as it decompresses, up to the limit: allocating the limit up front let
            // a 431-byte file ask for 28 GB.
            use std::io::Read;
            let mut out = Vec::new();
            zstd::stream::read::Decoder::new(bytes)
                .map_err(zstd_error)?
                .take(limit as u64 + 1)
                .read_to_end(&mut out)
                .map_err(zstd_error)?;
            if out.len() > limit {
                return Err(FormatError::Invalid(format!(
                    "payload decompresses to more than {limit} bytes (the format's bound, the header's largest payload, or {}× its stored size)",
                    crate::limits::MAX_EXPANSION
                )));
            }
            return Ok(out);
        }
    };
    // One decompression context per thread, kept: creating one per chunk cost ~1% of the
    // player's decode.
    thread_local! {
        static DCTX: std::cell::RefCell<Option<zstd::bulk::Decompressor<'static>>> =
            const { std::cell::RefCell::new(None) };
    }
    DCTX.with_borrow_mut(|d| {
        let d = match d {
            Some(d) => d,
            None => d.insert(zstd::bulk::Decompressor::new().map_err(zstd_error)?),
        };
        d.decompress(bytes, capacity).map_err(zstd_error)
    })
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
    let prev = prev.map_or(Reference::None, Reference::Borrowed);
    read_keyframe_from(h, bytes, prev)
}

/// The keyframe a predicted keyframe is coded against.
pub enum Reference<B, O> {
    /// An intra keyframe: no reference.
    None,
    /// Still needed by its owner: copied.
    Borrowed(B),
    /// No longer needed: the new keyframe is built in its planes, with no copy.
    Owned(O),
}

/// [`read_keyframe`] with the reference given as a [`Reference`].
pub fn read_keyframe_from(
    h: &Header,
    bytes: &[u8],
    prev: Reference<&[Plane], Vec<Plane>>,
) -> Result<Vec<Plane>> {
    let (w, ht) = padded_size(h);
    let planes = h.channels as usize;
    let nblocks = (w / N) * (ht / N);
    let raw = payload(
        h,
        Payload::Keyframe,
        bytes,
        payload_limit(h, nblocks * planes, planes, bytes.len()),
    )?;
    keyframe_from_raw(h, &raw, prev)
}

/// Decodes an uncompressed keyframe payload (what [`write_keyframe`] returns). The encoder
/// uses it to measure candidate quantisers exactly as a player will decode them.
pub fn read_keyframe_raw(h: &Header, raw: &[u8], prev: Option<&[Plane]>) -> Result<Vec<Plane>> {
    keyframe_from_raw(h, raw, prev.map_or(Reference::None, Reference::Borrowed))
}

fn keyframe_from_raw(
    h: &Header,
    raw: &[u8],
    prev: Reference<&[Plane], Vec<Plane>>,
) -> Result<Vec<Plane>> {
    let (w, ht) = padded_size(h);
    let planes = h.channels as usize;
    let mut r = Bytes { b: raw, pos: 0 };
    let head = r.take(4)?;
    let (mode, np) = (head[0], head[1] as usize);
    if np != planes {
        return Err(FormatError::Invalid(format!(
            "{np} planes, expected {planes}"
        )));
    }
    let mut base: Vec<Reference<&Plane, Plane>> = match (mode, prev) {
        (MODE_INTRA, _) => (0..planes).map(|_| Reference::None).collect(),
        (MODE_PREDICTED, Reference::Borrowed(p)) if p.len() == planes => {
            p.iter().map(Reference::Borrowed).collect()
        }
        (MODE_PREDICTED, Reference::Owned(p)) if p.len() == planes => {
            p.into_iter().map(Reference::Owned).collect()
        }
        (MODE_PREDICTED, _) => {
            return Err(FormatError::Invalid(
                "predicted keyframe without its reference".into(),
            ))
        }
        (m, _) => return Err(FormatError::Invalid(format!("unknown keyframe mode {m}"))),
    };
    let steps: Vec<f32> = (0..planes).map(|_| r.f32()).collect::<Result<_>>()?;
    let mut pos = r.pos;
    let mut out = Vec::with_capacity(planes);
    for (b, &step) in base.drain(..).zip(&steps) {
        out.push(keyframe_plane(raw, &mut pos, (w, ht), b, step)?);
    }
    if pos != raw.len() {
        return Err(FormatError::Invalid(format!(
            "{} stray bytes after the planes",
            raw.len() - pos
        )));
    }
    Ok(out)
}

/// A keyframe chunk (checksum-verified) decompressed and its coefficient streams scanned
/// ([`scan::scan`]), for a decoder that parses, dequantises and transforms them elsewhere
/// (the GPU player): calls `each(plane, step, stream)` for every plane in order, the
/// stream's blocks being in raster order over the padded plane. Returns the mode byte
/// ([`MODE_INTRA`] or [`MODE_PREDICTED`]). Refuses everything [`read_keyframe`] refuses
/// except a missing reference, which only the caller can know about.
pub fn keyframe_streams(
    h: &Header,
    bytes: &[u8],
    mut each: impl FnMut(usize, f32, Scanned<'_>),
) -> Result<u8> {
    let (w, ht) = padded_size(h);
    let planes = h.channels as usize;
    let nblocks = (w / N) * (ht / N);
    let raw = payload(
        h,
        Payload::Keyframe,
        bytes,
        payload_limit(h, nblocks * planes, planes, bytes.len()),
    )?;
    let mut r = Bytes { b: &raw, pos: 0 };
    let head = r.take(4)?;
    let (mode, np) = (head[0], head[1] as usize);
    if np != planes {
        return Err(FormatError::Invalid(format!(
            "{np} planes, expected {planes}"
        )));
    }
    if mode != MODE_INTRA && mode != MODE_PREDICTED {
        return Err(FormatError::Invalid(format!(
            "unknown keyframe mode {mode}"
        )));
    }
    let steps: Vec<f32> = (0..planes).map(|_| r.f32()).collect::<Result<_>>()?;
    let mut pos = r.pos;
    for (p, &step) in steps.iter().enumerate() {
        scanned(&raw, &mut pos, nblocks, |s| each(p, step, s))?;
    }
    if pos != raw.len() {
        return Err(FormatError::Invalid(format!(
            "{} stray bytes after the planes",
            raw.len() - pos
        )));
    }
    Ok(mode)
}

/// One coefficient stream and its entry points, as [`keyframe_streams`] and
/// [`CoeffReader::scan_plane`] hand them over (valid for the call only).
#[derive(Clone, Copy, Debug)]
pub struct Scanned<'a> {
    /// The stream's bytes, from its first pair to the end of its final run.
    pub stream: &'a [u8],
    /// Where pieces of it can be parsed from: at most [`scan::ENTRY_PAIRS`] pairs apart,
    /// and inside long runs of equal DC every [`scan::FILL_BLOCKS`] blocks.
    pub entries: &'a [scan::EntryPoint],
    /// Its number of blocks.
    pub blocks: usize,
    /// What the scan saw of its AC coefficients.
    pub ac: scan::AcTerms,
}

/// Scans the stream of `n` blocks at `raw[*pos..]`, moves past it and hands it to `each`.
fn scanned(raw: &[u8], pos: &mut usize, n: usize, each: impl FnOnce(Scanned<'_>)) -> Result<()> {
    ENTRIES.with_borrow_mut(|entries| {
        entries.clear();
        let start = *pos;
        let ac = scan::scan(raw, pos, n, entries)?;
        each(Scanned {
            stream: &raw[start..*pos],
            entries,
            blocks: n,
            ac,
        });
        Ok(())
    })
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
    let mut reader = CoeffReader::open(h, bytes, tiles)?;
    let mut band = Plane::zeros(0, 0);
    let mut out = Vec::new();
    for k in 2..=reader.max_degree() {
        let mut planes_k = Vec::with_capacity(h.channels as usize);
        for p in 0..h.channels as usize {
            let mut plane = Plane::try_zeros(w, ht)?;
            reader.read_plane(k, p, &mut band, |r| {
                for (y, x0, values) in r.member_rows() {
                    plane.data[y * w + x0..][..values.len()].copy_from_slice(values);
                }
            })?;
            planes_k.push(plane);
        }
        out.push(planes_k);
    }
    reader.finish()?;
    Ok(out)
}

/// One row of tiles of a decoded bubble plane, as [`CoeffReader::read_plane`] hands it out.
pub struct TileRows<'a> {
    /// The padded plane's row at the band's first row.
    pub y0: usize,
    /// `tile_size` rows of the padded plane's width. Only the member tiles' columns hold
    /// this plane's values; the others hold whatever an earlier row left there.
    pub band: &'a Plane,
    /// Degree of each tile of the row (for this plane's channel).
    pub degrees: &'a [u8],
    /// The term being read: tiles of degree ≥ k are members.
    pub k: u8,
    /// Tile size in texels.
    pub tile_size: usize,
}

impl TileRows<'_> {
    /// Whether `tile` (in this row) holds term `k`.
    pub fn is_member(&self, tile: usize) -> bool {
        self.degrees[tile] >= self.k
    }

    /// Column ranges `[x0, x1)` of the padded plane covered by runs of member tiles.
    pub fn member_spans(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        spans(self.degrees.len(), move |t| self.is_member(t))
            .map(move |(a, b)| (a * self.tile_size, b * self.tile_size))
    }

    /// The member tiles' values, run by run and row by row: (row of the padded plane,
    /// first column, values).
    pub fn member_rows(&self) -> impl Iterator<Item = (usize, usize, &[f32])> + '_ {
        let w = self.band.w;
        self.member_spans().flat_map(move |(x0, x1)| {
            (0..self.band.h)
                .map(move |y| (self.y0 + y, x0, &self.band.data[y * w + x0..y * w + x1]))
        })
    }
}

/// Maximal runs `[a, b)` of `0..n` where `keep` holds.
pub fn spans(n: usize, keep: impl Fn(usize) -> bool) -> impl Iterator<Item = (usize, usize)> {
    let mut t = 0;
    std::iter::from_fn(move || {
        while t < n && !keep(t) {
            t += 1;
        }
        if t == n {
            return None;
        }
        let a = t;
        while t < n && keep(t) {
            t += 1;
        }
        Some((a, t))
    })
}

/// A coefficient chunk read plane by plane: decoded one band of tiles at a time, handing out
/// finished rows (a band of 16 rows stays in cache, so a segment's bubble planes are never
/// zeroed, accumulated and copied as whole planes in memory: the reference decoder's path),
/// or only scanned for a parser elsewhere ([`CoeffReader::scan_plane`]: the GPU
/// player's).
pub struct CoeffReader<'t> {
    raw: Vec<u8>,
    pos: usize,
    steps: Vec<f32>,
    tiles: &'t TileMap,
    dmax: u8,
    planes: usize,
    tiles_x: usize,
    tiles_y: usize,
    tile_size: usize,
    /// The plane read next, as (k, plane): planes come in stream order.
    next: (u8, usize),
}

impl<'t> CoeffReader<'t> {
    /// Decompresses the chunk and reads its header (degree, planes, steps).
    pub fn open(h: &Header, bytes: &[u8], tiles: &'t TileMap) -> Result<CoeffReader<'t>> {
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
        let raw = payload(
            h,
            Payload::Coefficients(tiles),
            bytes,
            payload_limit(h, total_blocks, planes * h.max_degree as usize, bytes.len()),
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
        let pos = r.pos;
        Ok(CoeffReader {
            raw,
            pos,
            steps,
            tiles,
            dmax,
            planes,
            tiles_x: h.tiles_x() as usize,
            tiles_y: h.tiles_y() as usize,
            tile_size: ts,
            next: (2, 0),
        })
    }

    /// The highest degree present: planes k = 2..=this follow.
    pub fn max_degree(&self) -> u8 {
        self.dmax
    }

    /// Decodes bubble plane (`k`, `p`) — planes must be read in stream order, k = 2..=D,
    /// then p — and calls `rows` for each row of tiles, top to bottom. Only the tiles whose
    /// degree reaches `k` carry terms ([`TileRows`]); the rest of the plane is zero, and
    /// their columns of the band are left as they were, so that a caller keeping a
    /// plane's zeros from one segment to the next writes only what changed.
    /// `band` is scratch space, kept by the caller so that nothing is allocated per plane.
    pub fn read_plane(
        &mut self,
        k: u8,
        p: usize,
        band: &mut Plane,
        mut rows: impl FnMut(TileRows<'_>),
    ) -> Result<()> {
        self.take_plane(k, p)?;
        let ts = self.tile_size;
        let per = ts / N;
        let w = self.tiles_x * ts;
        let step = self.steps[(k as usize - 2) * self.planes + p];
        let tiles = self.tiles;
        let members = (0..self.tiles_x * self.tiles_y)
            .filter(|&t| tiles.degree(p, t) >= k)
            .count();
        if band.w != w || band.h != ts {
            *band = Plane::zeros(w, ts);
        }
        let (raw, pos) = (&self.raw, &mut self.pos);
        BLOCKS.with_borrow_mut(|q| {
            plane::read_blocks(raw, pos, members * per * per, q)?;
            let mut b = 0;
            let degrees = tiles.degrees(p);
            for ty in 0..self.tiles_y {
                let row_degrees = &degrees[ty * self.tiles_x..(ty + 1) * self.tiles_x];
                for (tx, &d) in row_degrees.iter().enumerate() {
                    if d < k {
                        continue;
                    }
                    // The blocks in the order the encoder wrote them, moved into the band.
                    // Every block of a member tile is written whole (onto zeros), so the
                    // band needs no clearing first.
                    let t = ty * self.tiles_x + tx;
                    let at =
                        plane::tile_blocks(t, self.tiles_x, ts).map(|(bx, by)| (bx, by - ty * per));
                    plane::add_blocks_of(band, at, Onto::Zeros, q, b, step);
                    b += per * per;
                }
                rows(TileRows {
                    y0: ty * ts,
                    band,
                    degrees: row_degrees,
                    k,
                    tile_size: ts,
                });
            }
            Ok(())
        })
    }

    /// Scans bubble plane (`k`, `p`) — in stream order, as [`CoeffReader::read_plane`] —
    /// for a decoder that parses, dequantises and transforms it elsewhere (the GPU
    /// player): calls `each(step, stream)` once, the stream's blocks being those of the
    /// tiles whose degree reaches `k`, tile by tile in raster order, each tile's blocks as
    /// [`plane::tile_blocks`] orders them.
    pub fn scan_plane(
        &mut self,
        k: u8,
        p: usize,
        each: impl FnOnce(f32, Scanned<'_>),
    ) -> Result<()> {
        self.take_plane(k, p)?;
        let per = self.tile_size / N;
        let step = self.steps[(k as usize - 2) * self.planes + p];
        let members = self.tiles.degrees(p).iter().filter(|&&d| d >= k).count();
        scanned(&self.raw, &mut self.pos, members * per * per, |s| {
            each(step, s)
        })
    }

    /// Moves past bubble plane (`k`, `p`), which must be the next in stream order.
    fn take_plane(&mut self, k: u8, p: usize) -> Result<()> {
        if (k, p) != self.next || k > self.dmax {
            return Err(FormatError::Invalid(format!(
                "bubble plane {k}/{p} read out of order (next is {}/{})",
                self.next.0, self.next.1
            )));
        }
        self.next = if p + 1 < self.planes {
            (k, p + 1)
        } else {
            (k + 1, 0)
        };
        Ok(())
    }

    /// Checks that every plane was read and nothing follows them.
    pub fn finish(&self) -> Result<()> {
        if self.next.0 <= self.dmax {
            return Err(FormatError::Invalid(format!(
                "bubble planes from {}/{} not read",
                self.next.0, self.next.1
            )));
        }
        if self.pos != self.raw.len() {
            return Err(FormatError::Invalid(format!(
                "{} stray bytes after the planes",
                self.raw.len() - self.pos
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::{decompress, spans};

    #[test]
    fn a_frame_that_does_not_state_its_size_is_bounded_by_what_it_holds() {
        // zstd's streaming encoder does not know the size, so its frame does not state it.
        let data = vec![7u8; 100_000];
        let frame = zstd::stream::encode_all(&data[..], 3).unwrap();
        assert!(matches!(
            zstd::zstd_safe::get_frame_content_size(&frame),
            Ok(None)
        ));
        // A limit far beyond any memory: allocating it up front aborted the process.
        assert_eq!(decompress(&frame, usize::MAX / 4).unwrap(), data);
        let e = decompress(&frame, 99_999).unwrap_err().to_string();
        assert!(e.contains("more than 99999"), "{e}");
        // A frame that states more than the limit is refused before decompressing.
        let stated = zstd::bulk::compress(&data, 3).unwrap();
        assert!(decompress(&stated, 1000)
            .unwrap_err()
            .to_string()
            .contains("claims"));
    }

    #[test]
    fn spans_are_the_maximal_runs() {
        let keep = [false, true, true, false, true, false, false, true];
        let got: Vec<_> = spans(keep.len(), |t| keep[t]).collect();
        assert_eq!(got, vec![(1, 3), (4, 5), (7, 8)]);
        assert_eq!(spans(3, |_| false).count(), 0);
        assert_eq!(spans(3, |_| true).collect::<Vec<_>>(), vec![(0, 3)]);
        assert_eq!(spans(0, |_| true).count(), 0);
    }
}
