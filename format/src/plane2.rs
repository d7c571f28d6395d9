//! Format 2's coding of a chunk's coefficient planes, designed for a GPU decoder
//! ("design E" of BENCHMARKS.md, "A static coder a GPU can decode"): the sections of
//! version 2's keyframe and coefficient chunks ([`payload2`](crate::payload2)).
//!
//! A plane is a grid of 8×8 blocks (each 64 quantised coefficients in zig-zag order),
//! whole for a keyframe, the member tiles' blocks for a bubble plane. Its symbols are
//! hybrid-uint tokens ([`ans`]) coded by rANS lanes, in four passes, each of
//! which a GPU runs with one invocation per lane, every lane independent of the others
//! within a pass:
//! 1. **even groups**: per group of 4 × 4 blocks with a member (x + y even on the group
//!    grid), whether any of its blocks holds anything (a DC residual or a coefficient);
//! 2. **odd groups**: the same, in a context of how many of the four neighbouring groups
//!    (decoded in pass 1) are empty;
//! 3. **even blocks** of the groups that hold something: the DC's residual against the
//!    planar prediction, the count of non-zero coefficients (in a context of the residual's
//!    size), then the coefficients in zig-zag order until that many were coded (in a
//!    context of how many are left and of the frequency band);
//! 4. **odd blocks**: the same, in contexts of their four neighbours (all even, so decoded
//!    in pass 3): the mean size of their residuals, the mean of their counts, and for each
//!    coefficient how many of them have one at that frequency.
//!
//! The DC is then the 2-D prefix sum of the residuals (planar prediction: left + up −
//! up-left, 0 outside the plane, or outside the tile for a bubble plane), a pass of scans.
//!
//! **Lanes** are runs of regions of 16 × 16 blocks in raster order, cut by the encoder
//! where a lane's coded size reaches a target (or it holds [`MAX_LANE_SYMBOLS`] symbols or
//! [`MAX_LANE_REGIONS`] regions); a lane holds its regions' symbols pass by pass.
//! **Histograms**: which cluster of histograms codes each context is the file's
//! [`ContextMap`], per family (a kind of chunk × luma or chroma), which also holds each
//! cluster's histogram over the whole file. A chunk codes each cluster it uses with its
//! own histogram or with the file's, whichever costs fewer bits: a small chunk's own
//! tables can cost more than its symbols.
//!
//! A chunk's coefficient section: for each family it uses, in increasing order, for each
//! of its map's clusters a bit saying whether the chunk uses it, and if it does a bit
//! saying whether its own histogram follows ([`Histogram::write`]; 0: the file's); zero
//! bits to the byte. Then per plane: its lane count, and per lane the regions it covers
//! and its words (LEB128 varints). Then every lane's words (16-bit, little-endian), plane
//! after plane.

use std::ops::Range;

use crate::ans::{self, BitReader, BitWriter, Histogram, Symbol, TOKENS};
use crate::dct::N;
use crate::{varint, FormatError, Result};

/// Blocks across a region, the unit lanes are made of.
pub const REGION: usize = 16;
/// Blocks across a group, the unit of the empty flags.
pub const GROUP: usize = 4;
/// The encoder ends a lane once it holds this many symbols, or [`MAX_LANE_REGIONS`]
/// regions, whatever its size: llvmpipe (lavapipe) ends every loop of a GPU invocation
/// once its loops have run 65,535 iterations in all, and a GPU decoder spends about one
/// per symbol and one per group of a region. (A region holds at most 16,656 symbols.)
pub const MAX_LANE_SYMBOLS: usize = 16_384;
/// See [`MAX_LANE_SYMBOLS`].
pub const MAX_LANE_REGIONS: usize = 1024;
/// Version 3's lanes cover at most this many regions: a state walks its share of the
/// lane's 16 group places a region in each of four passes, and a lane of one state (few
/// symbols) over 1,024 regions would pass llvmpipe's 65,535 loop iterations.
pub const MAX_LANE_REGIONS_3: usize = 512;

/// The most regions a lane of `layout` covers.
pub fn max_lane_regions(layout: Layout) -> usize {
    match layout {
        Layout::OneState => MAX_LANE_REGIONS,
        Layout::States => MAX_LANE_REGIONS_3,
    }
}
/// Groups in a region.
pub const GROUPS: usize = (REGION / GROUP) * (REGION / GROUP);

/// A region's cells (x, y from its corner) in raster order: version 2's block order.
const RASTER: [(u8, u8); REGION * REGION] = cell_order(false);
/// A region's cells group by group (groups in raster order, each one's cells in raster
/// order): version 3's block order.
const BY_GROUP: [(u8, u8); REGION * REGION] = cell_order(true);

const fn cell_order(by_group: bool) -> [(u8, u8); REGION * REGION] {
    let mut out = [(0u8, 0u8); REGION * REGION];
    let mut i = 0;
    while i < REGION * REGION {
        out[i] = if by_group {
            let (g, c) = (i / (GROUP * GROUP), i % (GROUP * GROUP));
            let per = REGION / GROUP;
            (
                (g % per * GROUP + c % GROUP) as u8,
                (g / per * GROUP + c / GROUP) as u8,
            )
        } else {
            ((i % REGION) as u8, (i / REGION) as u8)
        };
        i += 1;
    }
    out
}
/// A version 3 lane's rANS states, at most (a GPU decoder runs them side by side, one
/// invocation each, in one workgroup).
pub const MAX_STATES: usize = 64;

/// How a section lays out a plane's lanes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// Version 2: one rANS state a lane; per lane its regions and its words.
    OneState,
    /// Version 3: per lane its regions, its states s (1 to [`MAX_STATES`]) and each
    /// state's words; group k of the lane (16 a region, in raster order within each of its
    /// regions in turn) is coded by state k mod s, its flag and its blocks alike, so a lane
    /// decodes s symbols at a time.
    States,
}

/// Where an encoder cuts a plane's lanes and how many states it gives them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LaneShape {
    /// A lane ends once its coded size reaches this (or it holds [`MAX_LANE_SYMBOLS`]
    /// symbols or [`max_lane_regions`] regions).
    pub bytes: usize,
    /// `None`: version 2's layout, one state a lane. Otherwise version 3's: a lane of n
    /// symbols has ⌈n / this⌉ states (1 to [`MAX_STATES`]).
    pub symbols_per_state: Option<u64>,
}

impl LaneShape {
    /// The layout a section coded in this shape has.
    pub fn layout(&self) -> Layout {
        match self.symbols_per_state {
            None => Layout::OneState,
            Some(_) => Layout::States,
        }
    }

    /// The states of a lane of `symbols`.
    pub fn states(&self, symbols: usize) -> usize {
        match self.symbols_per_state {
            None => 1,
            Some(per) => (symbols as u64)
                .div_ceil(per.max(1))
                .clamp(1, MAX_STATES as u64) as usize,
        }
    }
}

// Contexts, per family.
const FLAG: usize = 0; // 6: even groups; odd groups by their empty neighbours (1 + 0–4)
const DC: usize = FLAG + 6; // 5: even blocks; odd blocks by the neighbours' residual sizes
const COUNT: usize = DC + 5; // 11: even by the residual's size (3); odd by the mean count (8)
const AC_EVEN: usize = COUNT + 11; // 10 × 12: coefficients left × band
const AC_ODD: usize = AC_EVEN + 120; // 3 × 10 × 12: × how many neighbours have one there
                                     // Version 3 codes a block's residual and whether it has a coefficient as one symbol, in DC's
                                     // contexts where no neighbour has a coefficient, and these where one has.
const JOINT_BUSY: usize = AC_ODD + 360; // 5
/// Version 3's joint symbol holds folded residuals below this; a larger one is this, then
/// the rest.
const ESCAPE: u32 = u32::MAX >> 1;
/// Contexts of one family (version 3's; version 2 has the first 502, [`contexts`]).
pub const CONTEXTS: usize = JOINT_BUSY + 5;

/// Contexts of one family in a file of `layout`: version 2's 502, version 3's 507 (its
/// joint symbols' contexts after them). A [`ContextMap`] holds [`CONTEXTS`] whatever the
/// version; a version 2 header stores the first 502.
pub fn contexts(layout: Layout) -> usize {
    match layout {
        Layout::OneState => JOINT_BUSY,
        Layout::States => CONTEXTS,
    }
}

/// Families of planes, each coded with its own [`ContextMap`]: intra keyframes, predicted
/// keyframes and bubble terms, each luma then chroma ([`family`]).
pub const FAMILIES: usize = 6;
/// Kinds of plane, in the order of [`family`]'s `kind`.
pub const INTRA_KEY: usize = 0;
/// See [`INTRA_KEY`].
pub const PREDICTED_KEY: usize = 1;
/// See [`INTRA_KEY`].
pub const BUBBLE: usize = 2;

/// The family of a plane of `kind` ([`INTRA_KEY`], [`PREDICTED_KEY`] or [`BUBBLE`]), luma
/// or chroma.
pub fn family(kind: usize, chroma: bool) -> usize {
    kind * 2 + chroma as usize
}

/// Where a plane's blocks lie.
#[derive(Clone, Copy, Debug)]
pub struct Geometry<'a> {
    /// Blocks across and down the plane.
    pub grid: (usize, usize),
    /// Each block's place on the grid, in the order the planes list them.
    pub order: &'a [(usize, usize)],
    /// Blocks across a tile, for a bubble plane (its DC prediction stays in the tile).
    pub tile: Option<usize>,
}

/// One plane of a chunk: its family (kind of chunk × luma or chroma: an index into the
/// maps) and where its blocks lie.
#[derive(Clone, Copy, Debug)]
pub struct Plane<'a> {
    /// Which [`ContextMap`] codes it.
    pub family: usize,
    /// Its blocks' places.
    pub geometry: Geometry<'a>,
}

/// Which histogram (cluster) of a chunk codes each context of a family, and each
/// cluster's histogram over the whole file, which a chunk may use instead of sending its
/// own (a small chunk's own tables can cost more than its symbols).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ContextMap {
    /// Histograms, 1 to 255.
    pub clusters: u8,
    /// The cluster of each of the [`CONTEXTS`] contexts.
    pub of: Vec<u8>,
    /// Each cluster's file-wide histogram (`None`: chunks send their own).
    pub tables: Vec<Option<Histogram>>,
}

impl ContextMap {
    /// Every context in one histogram, with no file-wide table.
    pub fn single() -> ContextMap {
        ContextMap {
            clusters: 1,
            of: vec![0; CONTEXTS],
            tables: vec![None],
        }
    }

    /// Appends the map: the cluster count (8 bits), the cluster of each of the
    /// [`contexts`] of `layout` in as few bits as the count needs, then per cluster a bit
    /// saying whether a file-wide histogram follows, and the histogram.
    pub fn write(&self, out: &mut BitWriter, layout: Layout) {
        out.put(self.clusters as u32, 8);
        let bits = bits_for(self.clusters);
        for &k in &self.of[..contexts(layout)] {
            out.put(k as u32, bits);
        }
        for t in &self.tables {
            out.put(t.is_some() as u32, 1);
            if let Some(h) = t {
                h.write(out);
            }
        }
    }

    /// Reads a map [`ContextMap::write`] wrote for `layout` (contexts it does not have in
    /// cluster 0).
    pub fn read(r: &mut BitReader, layout: Layout) -> Result<ContextMap> {
        let clusters = r.get(8)? as u8;
        if clusters == 0 {
            return Err(FormatError::Invalid("context map of no cluster".into()));
        }
        let bits = bits_for(clusters);
        let mut of: Vec<u8> = (0..contexts(layout))
            .map(|_| {
                let k = r.get(bits)?;
                if k >= clusters as u32 {
                    return Err(FormatError::Invalid(format!(
                        "context map: cluster {k} of {clusters}"
                    )));
                }
                Ok(k as u8)
            })
            .collect::<Result<_>>()?;
        of.resize(CONTEXTS, 0);
        let tables = (0..clusters)
            .map(|_| match r.get(1)? {
                1 => Histogram::read(r).map(Some),
                _ => Ok(None),
            })
            .collect::<Result<_>>()?;
        Ok(ContextMap {
            clusters,
            of,
            tables,
        })
    }
}

fn bits_for(clusters: u8) -> u32 {
    32 - (clusters.max(1) as u32 - 1).leading_zeros()
}

/// What a walk over a plane's symbols does with each: the encoder records the value it is
/// given, the decoder ignores it and returns the one it decodes.
trait Coder {
    fn code(&mut self, stream: usize, ctx: usize, value: u32) -> Result<u32>;
    /// Pass `pass` (0–3) begins.
    #[inline(always)]
    fn pass(&mut self, _pass: usize) {}
}

/// 0, −1, 1, −2, … → 0, 1, 2, 3, … (zig-zag, without overflow at `i32::MIN`).
pub fn pack(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

fn unpack(u: u32) -> i32 {
    ((u >> 1) as i32) ^ -((u & 1) as i32)
}

/// The size class of a DC residual: 0, 1–2, 3+.
pub fn size_class(v: i32) -> usize {
    match v.unsigned_abs() {
        0 => 0,
        1..=2 => 1,
        _ => 2,
    }
}

/// Buckets of a count of non-zero coefficients (or of a mean of them): 0–7.
pub fn count_bucket(n: usize) -> usize {
    match n {
        0..=2 => n,
        3..=4 => 3,
        5..=8 => 4,
        9..=16 => 5,
        17..=32 => 6,
        _ => 7,
    }
}

/// Buckets of the coefficients still to code in a block (at least 1): 0–9.
pub fn left_bucket(n: usize) -> usize {
    match n {
        1..=4 => n - 1,
        5..=6 => 4,
        7..=8 => 5,
        9..=12 => 6,
        13..=16 => 7,
        17..=24 => 8,
        _ => 9,
    }
}

/// Zig-zag positions in bands of growing width (the lowest frequencies one each): 0–11.
pub fn band(i: usize) -> usize {
    match i {
        0..=5 => i,
        6..=7 => 6,
        8..=10 => 7,
        11..=15 => 8,
        16..=23 => 9,
        24..=35 => 10,
        _ => 11,
    }
}

/// The planar residuals of `dc` (one per block, in the planes' order) in `geo`'s domains.
fn residuals(geo: &Geometry, index: &[u32], dc: &[i32]) -> Vec<i32> {
    let at = |x: isize, y: isize, home: (usize, usize)| -> i32 {
        if x < 0 || y < 0 {
            return 0;
        }
        let (x, y) = (x as usize, y as usize);
        if let Some(t) = geo.tile {
            if x / t != home.0 / t || y / t != home.1 / t {
                return 0;
            }
        }
        match index[y * geo.grid.0 + x] {
            u32::MAX => 0,
            j => dc[j as usize],
        }
    };
    geo.order
        .iter()
        .enumerate()
        .map(|(b, &(x, y))| {
            let (xi, yi) = (x as isize, y as isize);
            dc[b]
                .wrapping_sub(at(xi - 1, yi, (x, y)))
                .wrapping_sub(at(xi, yi - 1, (x, y)))
                .wrapping_add(at(xi - 1, yi - 1, (x, y)))
        })
        .collect()
}

/// Each grid cell's block (`u32::MAX` where none), checking the places.
fn grid_index(geo: &Geometry) -> Result<Vec<u32>> {
    let (bw, bh) = geo.grid;
    let cells = bw
        .checked_mul(bh)
        .filter(|&c| c <= u32::MAX as usize)
        .ok_or_else(|| FormatError::Invalid("plane grid too large".into()))?;
    let mut index = vec![u32::MAX; cells];
    for (b, &(x, y)) in geo.order.iter().enumerate() {
        if x >= bw || y >= bh || index[y * bw + x] != u32::MAX {
            return Err(FormatError::Invalid(format!(
                "block {b} at ({x}, {y}) outside the {bw}×{bh} grid or twice"
            )));
        }
        index[y * bw + x] = b as u32;
    }
    Ok(index)
}

/// Walks a plane's four passes, coding every symbol through `coder`; `source` gives the
/// blocks to code (the encoder), or nothing (the decoder). `stream_of(region, group)`
/// gives the rANS stream of a group (0–15, in raster order within its region); `layout`
/// picks version 2's symbols or version 3's (a block's residual and whether it has a
/// coefficient in one). Returns the blocks, their DC restored, sparse.
fn walk(
    geo: &Geometry,
    source: Option<&[[i32; N * N]]>,
    stream_of: &impl Fn(usize, usize) -> usize,
    coder: &mut impl Coder,
    layout: Layout,
) -> Result<Decoded> {
    let joint = layout == Layout::States;
    let (bw, bh) = geo.grid;
    let index = grid_index(geo)?;
    let n = geo.order.len();
    let src_residual = source.map(|s| {
        let dc: Vec<i32> = s.iter().map(|q| q[0]).collect();
        residuals(geo, &index, &dc)
    });
    // Sparse: a plane of a day's light is mostly empty blocks, and touching 256 bytes of
    // every block was most of a decode. Each block's non-zero positions as a mask (what
    // the odd blocks' contexts read), its terms where `first` says.
    let mut out = Decoded {
        dc: vec![0i32; n],
        first: vec![0u32; n],
        count: vec![0u8; n],
        terms: Vec::new(),
    };
    let mut mask = vec![0u64; n];
    let mut residual = vec![0i32; n];
    let rw = bw.div_ceil(REGION);
    let region_of = |x: usize, y: usize| (y / REGION) * rw + x / REGION;
    let at = |x: isize, y: isize| -> Option<usize> {
        if x < 0 || y < 0 || x >= bw as isize || y >= bh as isize {
            return None;
        }
        match index[y as usize * bw + x as usize] {
            u32::MAX => None,
            j => Some(j as usize),
        }
    };
    const FOUR: [(isize, isize); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];
    // Passes 1 and 2: the groups' flags.
    let (gw, gh) = (bw.div_ceil(GROUP), bh.div_ceil(GROUP));
    let mut exists = vec![false; gw * gh];
    let mut full = vec![false; gw * gh];
    for (b, &(x, y)) in geo.order.iter().enumerate() {
        let g = (y / GROUP) * gw + x / GROUP;
        exists[g] = true;
        if let Some(s) = source {
            let r = src_residual.as_ref().map_or(0, |r| r[b]);
            full[g] |= r != 0 || s[b][1..].iter().any(|&v| v != 0);
        }
    }
    // Regions in raster order, and within each its cells in raster order: `cells(k, side)`
    // lists the cells of side `side` (in blocks) that region k covers.
    let regions = rw * bh.div_ceil(REGION);
    let per = REGION / GROUP;
    for parity in 0..2 {
        coder.pass(parity);
        for region in 0..regions {
            let (rx, ry) = ((region % rw) * per, (region / rw) * per);
            for gy in ry..(ry + per).min(gh) {
                for gx in rx..(rx + per).min(gw) {
                    let g = gy * gw + gx;
                    if !exists[g] || (gx + gy) % 2 != parity {
                        continue;
                    }
                    // The neighbouring groups that exist, and how many of them are empty.
                    let (mut around, mut empty) = (0, 0);
                    for &(dx, dy) in &FOUR {
                        let (u, v) = (gx as isize + dx, gy as isize + dy);
                        if u >= 0 && v >= 0 && u < gw as isize && v < gh as isize {
                            let n = v as usize * gw + u as usize;
                            if exists[n] {
                                around += 1;
                                empty += !full[n] as usize;
                            }
                        }
                    }
                    let ctx = if parity == 1 && around > 0 {
                        1 + empty
                    } else {
                        0
                    };
                    let stream = stream_of(region, (gy - ry) * per + gx - rx);
                    let v = coder.code(stream, FLAG + ctx, full[g] as u32)?;
                    if v > 1 {
                        return Err(FormatError::Invalid(format!("group flag {v}")));
                    }
                    full[g] = v == 1;
                }
            }
        }
    }
    // Passes 3 and 4: the blocks of the groups with something, each region's in raster
    // order (version 2) or group by group (version 3, so that a state visits only its own
    // groups).
    let order = match layout {
        Layout::OneState => &RASTER,
        Layout::States => &BY_GROUP,
    };
    for parity in 0..2 {
        coder.pass(2 + parity);
        // A region's cells of this parity, in the order's turn (regions start on even
        // cells), each with its group's place in the region.
        let cells: Vec<(usize, usize, usize)> = (order.iter())
            .map(|&(dx, dy)| (dx as usize, dy as usize))
            .filter(|&(dx, dy)| (dx + dy) % 2 == parity)
            .map(|(dx, dy)| (dx, dy, dy / GROUP * per + dx / GROUP))
            .collect();
        for region in 0..regions {
            let (rx, ry) = ((region % rw) * REGION, (region / rw) * REGION);
            // The region's groups that hold something, a bit each: most regions of a
            // day's planes hold none, and their cells are then not visited.
            let (gx0, gy0) = (rx / GROUP, ry / GROUP);
            let mut busy = 0u32;
            for k in 0..GROUPS {
                let (gx, gy) = (gx0 + k % per, gy0 + k / per);
                if gx < gw && gy < gh && full[gy * gw + gx] {
                    busy |= 1 << k;
                }
            }
            if busy == 0 {
                continue;
            }
            for &(dx, dy, group) in &cells {
                let (x, y) = (rx + dx, ry + dy);
                if busy >> group & 1 == 0 || x >= bw || y >= bh {
                    continue;
                }
                let Some(b) = at(x as isize, y as isize) else {
                    continue;
                };
                debug_assert_eq!(region_of(x, y), region);
                let stream = stream_of(region, group);
                // The neighbours, which only an odd block's contexts read.
                let mut four_at = [0usize; 4];
                let mut len = 0;
                if parity == 1 {
                    for &(dx, dy) in &FOUR {
                        if let Some(j) = at(x as isize + dx, y as isize + dy) {
                            four_at[len] = j;
                            len += 1;
                        }
                    }
                }
                let four = &four_at[..len];
                let odd = parity == 1 && !four.is_empty();
                // An odd block's contexts: its neighbours' residual sizes and counts (and in
                // version 3 whether any of them has a coefficient).
                let (dc_ctx, count_ctx, busy) = if odd {
                    let sizes: usize = four.iter().map(|&j| size_class(residual[j])).sum();
                    let counts: usize = four.iter().map(|&j| out.count[j] as usize).sum();
                    let mean = (counts + four.len() / 2) / four.len();
                    let dc_ctx = 1 + (2 * sizes / four.len()).min(3);
                    (dc_ctx, 3 + count_bucket(mean), counts > 0)
                } else {
                    (0, usize::MAX, false)
                };
                let want = source.map(|s| &s[b]);
                let packed = src_residual.as_ref().map_or(0, |r| pack(r[b]));
                let nz = want.map_or(0, |q| q[1..].iter().filter(|&&v| v != 0).count());
                let (r, nz) = if joint {
                    // One symbol for the residual and whether any coefficient follows
                    // (2 × the folded residual + 1 if one does), in a context of whether
                    // a neighbour has one; then the count less one where there is any.
                    // A folded residual of ESCAPE or more (beyond ±2^30) is ESCAPE in
                    // the symbol, the rest in a second one of the same context.
                    let ctx = if busy { JOINT_BUSY } else { DC } + dc_ctx;
                    let head = packed.min(ESCAPE) << 1 | (nz > 0) as u32;
                    let j = coder.code(stream, ctx, head)?;
                    let mut folded = j >> 1;
                    if folded == ESCAPE {
                        let rest = coder.code(stream, ctx, packed.wrapping_sub(ESCAPE))?;
                        folded = ESCAPE.checked_add(rest).ok_or_else(|| {
                            FormatError::Invalid(format!(
                                "block ({x}, {y}): a DC residual beyond 32 bits"
                            ))
                        })?;
                    }
                    let r = unpack(folded);
                    let count_ctx = if odd { count_ctx } else { size_class(r) };
                    let nz = match j & 1 {
                        0 => 0,
                        _ => {
                            let less = nz.saturating_sub(1) as u32;
                            let n = coder.code(stream, COUNT + count_ctx, less)?;
                            (n as usize).saturating_add(1)
                        }
                    };
                    (r, nz)
                } else {
                    let r = unpack(coder.code(stream, DC + dc_ctx, packed)?);
                    let count_ctx = if odd { count_ctx } else { size_class(r) };
                    (
                        r,
                        coder.code(stream, COUNT + count_ctx, nz as u32)? as usize,
                    )
                };
                residual[b] = r;
                if nz >= N * N {
                    return Err(FormatError::Invalid(format!(
                        "block ({x}, {y}): {nz} coefficients"
                    )));
                }
                out.count[b] = nz as u8;
                out.first[b] = out.terms.len() as u32;
                // An odd block's coefficient at position i is coded in a context of how
                // many of its neighbours have one there, h of n: none, up to half, or more
                // (⌈2h / n⌉ capped at 2). Per position, as two masks: any, and more than
                // half.
                let (any, most) = if odd {
                    let m: [u64; 4] = std::array::from_fn(|k| four.get(k).map_or(0, |&j| mask[j]));
                    let most = match four.len() {
                        1 => m[0],
                        2 => m[0] & m[1],
                        3 => (m[0] & m[1]) | (m[0] & m[2]) | (m[1] & m[2]),
                        _ => (m[0] & m[1] & (m[2] | m[3])) | (m[2] & m[3] & (m[0] | m[1])),
                    };
                    (m[0] | m[1] | m[2] | m[3], most)
                } else {
                    (0, 0)
                };
                let mut left = nz;
                let mut i = 1;
                while left > 0 {
                    if i == N * N {
                        return Err(FormatError::Invalid(format!(
                            "block ({x}, {y}): {left} coefficients past the last position"
                        )));
                    }
                    let ctx = left_bucket(left) * 12 + band(i);
                    let ctx = if odd {
                        let level = (any >> i & 1) + (most >> i & 1);
                        AC_ODD + level as usize * 120 + ctx
                    } else {
                        AC_EVEN + ctx
                    };
                    let v = unpack(coder.code(stream, ctx, want.map_or(0, |q| pack(q[i])))?);
                    if v != 0 {
                        mask[b] |= 1 << i;
                        out.terms.push((i as u8, v));
                        left -= 1;
                    }
                    i += 1;
                }
            }
        }
    }
    // The DC: the planar residuals' 2-D prefix sum, in raster order of the grid, on a grid
    // of every cell (0 where the plane has no block; predictions stay in a bubble
    // plane's tile).
    let mut grid = vec![0i32; bw * bh];
    for (b, &(x, y)) in geo.order.iter().enumerate() {
        grid[y * bw + x] = residual[b];
    }
    // (x and y within their tile counted, not divided: a division per cell was 7% of a
    // large plane's decode.)
    let t = geo.tile.unwrap_or(usize::MAX);
    let mut ty = 0;
    for y in 0..bh {
        let up = ty != 0;
        let mut tx = 0;
        for x in 0..bw {
            let i = y * bw + x;
            let left = tx != 0;
            tx = if tx + 1 == t { 0 } else { tx + 1 };
            if index[i] == u32::MAX {
                continue;
            }
            let pred = if left { grid[i - 1] } else { 0 }
                .wrapping_add(if up { grid[i - bw] } else { 0 })
                .wrapping_sub(if left && up { grid[i - bw - 1] } else { 0 });
            grid[i] = grid[i].wrapping_add(pred);
        }
        ty = if ty + 1 == t { 0 } else { ty + 1 };
    }
    for (b, &(x, y)) in geo.order.iter().enumerate() {
        out.dc[b] = grid[y * bw + x];
    }
    Ok(out)
}

/// A plane's blocks as decoded, sparse: each block's DC, and its non-zero AC terms.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Decoded {
    /// Each block's DC.
    pub dc: Vec<i32>,
    /// Block b's terms are `terms[first[b]..first[b] + count[b]]`.
    pub first: Vec<u32>,
    /// Each block's number of non-zero AC terms.
    pub count: Vec<u8>,
    /// (zig-zag index, value) of the non-zero AC terms, block by block, each block's in
    /// increasing index.
    pub terms: Vec<(u8, i32)>,
}

impl Decoded {
    /// Block b's non-zero AC terms.
    pub fn terms_of(&self, b: usize) -> &[(u8, i32)] {
        let f = self.first[b] as usize;
        &self.terms[f..f + self.count[b] as usize]
    }

    /// Every block dense, 64 integers in zig-zag order.
    pub fn dense(&self) -> Vec<[i32; N * N]> {
        (0..self.dc.len())
            .map(|b| {
                let mut q = [0i32; N * N];
                q[0] = self.dc[b];
                for &(i, v) in self.terms_of(b) {
                    q[i as usize] = v;
                }
                q
            })
            .collect()
    }
}

/// The encoder's record: each symbol's lane, context and value, in walking order.
struct Record(Vec<(usize, usize, u32)>);

impl Coder for Record {
    fn code(&mut self, stream: usize, ctx: usize, value: u32) -> Result<u32> {
        self.0.push((stream, ctx, value));
        Ok(value)
    }
}

/// Counts of each context's tokens over `planes` of `blocks`, per family: what an encoder
/// learns a [`ContextMap`] from (`counts[family][ctx · TOKENS + token]`).
pub fn context_counts(
    planes: &[(Plane, &[[i32; N * N]])],
    families: usize,
    layout: Layout,
) -> Result<Vec<Vec<u64>>> {
    let mut counts = vec![vec![0u64; CONTEXTS * TOKENS]; families];
    for (p, blocks) in planes {
        if p.family >= families || blocks.len() != p.geometry.order.len() {
            return Err(FormatError::Invalid(
                "a plane of no family or of other blocks".into(),
            ));
        }
        let mut rec = Record(Vec::new());
        walk(&p.geometry, Some(blocks), &|_, _| 0, &mut rec, layout)?;
        for (_, ctx, v) in rec.0 {
            counts[p.family][ctx * TOKENS + ans::hybrid_uint(v).0] += 1;
        }
    }
    Ok(counts)
}

/// Codes a chunk's `planes` of `blocks` with `maps` (one per family), in lanes cut and
/// given states as `shape` says. Returns the coefficient section.
pub fn encode(
    planes: &[(Plane, &[[i32; N * N]])],
    maps: &[ContextMap],
    shape: LaneShape,
) -> Result<Vec<u8>> {
    // Every symbol, by plane, each with its group's place for now: its region × 16 + its
    // place in the region.
    let mut records = Vec::with_capacity(planes.len());
    for (p, blocks) in planes {
        if blocks.len() != p.geometry.order.len() {
            return Err(FormatError::Invalid(
                "blocks and places differ in number".into(),
            ));
        }
        let mut rec = Record(Vec::new());
        let place = |region: usize, group: usize| region * GROUPS + group;
        walk(&p.geometry, Some(blocks), &place, &mut rec, shape.layout())?;
        records.push(rec.0);
    }
    // The chunk's histograms: per family used, per cluster.
    let used = used_families(planes.iter().map(|(p, _)| p), maps.len())?;
    let mut counts: Vec<Vec<Vec<u64>>> = maps
        .iter()
        .map(|m| vec![vec![0u64; TOKENS]; m.clusters as usize])
        .collect();
    for ((p, _), rec) in planes.iter().zip(&records) {
        let map = &maps[p.family];
        for &(_, ctx, v) in rec {
            counts[p.family][map.of[ctx] as usize][ans::hybrid_uint(v).0] += 1;
        }
    }
    let mut bits = BitWriter::default();
    // Each histogram's place in the list the lanes are coded with.
    let mut place = vec![Vec::new(); maps.len()];
    let mut list = Vec::new();
    for &f in &used {
        for (k, c) in counts[f].iter().enumerate() {
            place[f].push(list.len() as u16);
            let Some(own) = Histogram::from_counts(c) else {
                bits.put(0, 1);
                continue;
            };
            bits.put(1, 1);
            // The file's table where it costs fewer bits than this chunk's own table
            // and symbols at its own probabilities.
            let symbols = |h: &Histogram| -> f64 {
                (c.iter().enumerate())
                    .filter(|&(_, &n)| n > 0)
                    .map(|(t, &n)| n as f64 * h.cost(t))
                    .sum()
            };
            let mut table = BitWriter::default();
            own.write(&mut table);
            let own_bits = table.len_bits() as f64 + symbols(&own);
            let file = maps[f]
                .tables
                .get(k)
                .and_then(Option::as_ref)
                .filter(|h| (c.iter().enumerate()).all(|(t, &n)| n == 0 || h.frequency(t) > 0));
            match file {
                Some(h) if symbols(h) <= own_bits => {
                    bits.put(0, 1);
                    list.push(h.clone());
                }
                _ => {
                    bits.put(1, 1);
                    own.write(&mut bits);
                    list.push(own);
                }
            }
        }
    }
    let mut out = bits.finish();
    // Lanes: runs of regions cut by size; then, in version 3, states by symbols.
    let mut words = Vec::new();
    for ((p, _), rec) in planes.iter().zip(&records) {
        let map = &maps[p.family];
        let symbols = |ctx: usize, v: u32| {
            let (t, n, raw) = ans::hybrid_uint(v);
            let histogram = place[p.family][map.of[ctx] as usize];
            [
                Some(Symbol::Token {
                    histogram,
                    token: t as u16,
                }),
                (n > 0).then_some(Symbol::Raw {
                    value: raw,
                    bits: n as u8,
                }),
            ]
        };
        let (bw, bh) = p.geometry.grid;
        let regions = bw.div_ceil(REGION) * bh.div_ceil(REGION);
        let mut cost = vec![0.0f64; regions];
        let mut count = vec![0usize; regions];
        for &(at, ctx, v) in rec {
            let region = at / GROUPS;
            count[region] += 1;
            for s in symbols(ctx, v).into_iter().flatten() {
                cost[region] += match s {
                    Symbol::Token { histogram, token } => {
                        list[histogram as usize].cost(token as usize)
                    }
                    Symbol::Raw { bits, .. } => bits as f64,
                };
            }
        }
        let mut lanes: Vec<(usize, usize)> = Vec::new(); // (regions, symbols) per lane
        let (mut run, mut bits, mut symbols_in) = (0usize, 0.0f64, 0usize);
        for (c, n) in cost.iter().zip(&count) {
            run += 1;
            bits += c;
            symbols_in += n;
            if bits >= 8.0 * shape.bytes as f64
                || symbols_in >= MAX_LANE_SYMBOLS
                || run == max_lane_regions(shape.layout())
            {
                lanes.push((run, symbols_in));
                (run, bits, symbols_in) = (0, 0.0, 0);
            }
        }
        if run > 0 || lanes.is_empty() {
            lanes.push((run, symbols_in));
        }
        // Each region's lane, first region and first stream; each lane's states.
        let mut of_region = vec![(0usize, 0usize, 0usize); regions];
        let mut states = Vec::with_capacity(lanes.len());
        let (mut r, mut streams) = (0, 0);
        for &(n, symbols_in) in &lanes {
            let k = shape.states(symbols_in);
            of_region[r..r + n].fill((r, streams, k));
            states.push(k);
            (r, streams) = (r + n, streams + k);
        }
        let mut coded: Vec<Vec<Symbol>> = vec![Vec::new(); streams];
        for &(at, ctx, v) in rec {
            let (r0, s0, k) = of_region[at / GROUPS];
            let stream = s0 + (at - r0 * GROUPS) % k;
            coded[stream].extend(symbols(ctx, v).into_iter().flatten());
        }
        varint::put_u32(&mut out, lanes.len() as u32);
        let mut next = 0;
        for (&(n, _), &k) in lanes.iter().zip(&states) {
            varint::put_u32(&mut out, n as u32);
            if shape.symbols_per_state.is_some() {
                varint::put_u32(&mut out, k as u32);
            }
            for stream in &coded[next..next + k] {
                let w = ans::encode(stream, &list);
                varint::put_u32(&mut out, w.len() as u32);
                words.push(w);
            }
            next += k;
        }
    }
    for w in words.iter().flatten() {
        out.extend_from_slice(&w.to_le_bytes());
    }
    Ok(out)
}

/// The families `planes` use, in increasing order, checked against the maps.
fn used_families<'a>(
    planes: impl Iterator<Item = &'a Plane<'a>>,
    maps: usize,
) -> Result<Vec<usize>> {
    let mut used: Vec<usize> = planes.map(|p| p.family).collect();
    used.sort_unstable();
    used.dedup();
    if used.last().is_some_and(|&f| f >= maps) {
        return Err(FormatError::Invalid(
            "a plane of a family without a map".into(),
        ));
    }
    Ok(used)
}

/// The decoder's streams, those of every lane of the plane being decoded; `COUNT`: count
/// each lane's steps ([`lane_symbols`]).
struct Streams<'a, 'h, const COUNT: bool> {
    decoders: Vec<ans::Decoder<'a>>,
    /// The histogram of each context (`None`: the chunk sent none).
    of: Vec<Option<&'h Histogram>>,
    /// Each stream's symbols in the pass under way.
    symbols: Vec<u64>,
    /// Each lane's streams, and its steps so far ([`lane_symbols`]): per pass, its
    /// busiest stream's symbols.
    lanes: Vec<(Range<usize>, u64)>,
}

impl<const COUNT: bool> Streams<'_, '_, COUNT> {
    /// Ends a pass: each lane's steps grow by its busiest stream's symbols in it.
    fn end_pass(&mut self) {
        if !COUNT {
            return;
        }
        for (streams, steps) in &mut self.lanes {
            *steps += self.symbols[streams.clone()]
                .iter()
                .max()
                .copied()
                .unwrap_or(0);
            self.symbols[streams.clone()].fill(0);
        }
    }
}

impl<const COUNT: bool> Coder for Streams<'_, '_, COUNT> {
    #[inline(always)]
    fn code(&mut self, stream: usize, ctx: usize, _: u32) -> Result<u32> {
        let Some(h) = self.of[ctx] else {
            return Err(FormatError::Invalid(format!(
                "context {ctx} coded without a histogram"
            )));
        };
        let d = &mut self.decoders[stream];
        if COUNT {
            self.symbols[stream] += 1;
        }
        let t = d.token(h)?;
        let raw = d.raw(ans::raw_bits_of(t))?;
        Ok(ans::hybrid_value(t, raw))
    }

    fn pass(&mut self, _: usize) {
        self.end_pass();
    }
}

/// A coefficient section's parts, parsed and checked: what a GPU decoder uploads.
#[derive(Clone, Debug)]
pub struct Section {
    /// How its lanes are laid out and its blocks coded (the file's version).
    pub layout: Layout,
    /// The chunk's histograms.
    pub histograms: Vec<Histogram>,
    /// For each of `histograms`, its place among the file's ([`file_histograms`]) where
    /// it is the file's, `None` where the chunk sent its own.
    pub file: Vec<Option<u16>>,
    /// Per family, the histogram (an index into `histograms`, `u16::MAX`: none) of each
    /// of its map's clusters; empty for a family the section does not use.
    pub places: Vec<Vec<u16>>,
    /// Per plane: each lane's regions (a run from the plane's first, in raster order of
    /// regions) and streams, each stream's words ([first, end) in `words`), and the
    /// histogram of each context (an index into `histograms`, `u16::MAX` where the chunk
    /// sent none).
    pub planes: Vec<SectionPlane>,
    /// Where the lanes' words start in the section's bytes (two bytes each, little-endian).
    pub words_at: usize,
    /// Every lane's words, plane after plane; a lane's first two are its state. (Empty
    /// from [`Section::parse_layout`].)
    pub words: Vec<u16>,
}

/// The file's histograms, numbered as [`Section::file`] numbers them: family by family,
/// cluster by cluster, those the maps carry.
pub fn file_histograms(maps: &[ContextMap]) -> impl Iterator<Item = (usize, usize, &Histogram)> {
    maps.iter().enumerate().flat_map(|(f, m)| {
        (m.tables.iter().enumerate()).filter_map(move |(k, t)| t.as_ref().map(|h| (f, k, h)))
    })
}

/// One plane of a [`Section`].
#[derive(Clone, Debug)]
pub struct SectionPlane {
    /// Each lane's (first region, end region, first stream, end stream): its regions and
    /// its states' word runs in `streams` (one in version 2).
    pub lanes: Vec<(usize, usize, usize, usize)>,
    /// Each stream's (first word, end word) in the section's words.
    pub streams: Vec<(usize, usize)>,
    /// The histogram of each of the [`CONTEXTS`] contexts.
    pub histogram_of: Vec<u16>,
}

impl Section {
    /// Parses a coefficient section [`encode`] wrote for `planes` with the file's `maps`,
    /// its lanes laid out as `layout`.
    pub fn parse(
        bytes: &[u8],
        planes: &[Plane],
        maps: &[ContextMap],
        layout: Layout,
    ) -> Result<Section> {
        let mut s = Section::parse_layout(bytes, planes, maps, layout)?;
        s.words = bytes[s.words_at..]
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        Ok(s)
    }

    /// [`Section::parse`] without copying the lanes' words out (`words` stays empty): a
    /// GPU decoder uploads them from `bytes[words_at..]` as they are. Only the planes'
    /// families and grids are read, not their blocks' places.
    pub fn parse_layout(
        bytes: &[u8],
        planes: &[Plane],
        maps: &[ContextMap],
        layout: Layout,
    ) -> Result<Section> {
        let used = used_families(planes.iter(), maps.len())?;
        let mut r = BitReader::new(bytes);
        let mut place = vec![Vec::new(); maps.len()];
        let mut histograms = Vec::new();
        let mut file = Vec::new();
        // Each family's first place among the file's histograms.
        let firsts: Vec<usize> = maps
            .iter()
            .scan(0, |n, m| {
                let first = *n;
                *n += m.tables.iter().flatten().count();
                Some(first)
            })
            .collect();
        for &f in &used {
            for k in 0..maps[f].clusters as usize {
                if r.get(1)? == 0 {
                    place[f].push(u16::MAX);
                    continue;
                }
                place[f].push(histograms.len() as u16);
                if r.get(1)? == 1 {
                    histograms.push(Histogram::read(&mut r)?);
                    file.push(None);
                } else {
                    let tables = &maps[f].tables;
                    let table = tables.get(k).and_then(Option::as_ref);
                    histograms.push(table.cloned().ok_or_else(|| {
                        FormatError::Invalid(format!(
                            "family {f}, cluster {k}: the file's histogram, which it has not"
                        ))
                    })?);
                    let rank = tables[..k].iter().flatten().count();
                    file.push(Some((firsts[f] + rank) as u16));
                }
            }
        }
        let mut at = r.position().div_ceil(8);
        let mut out = Vec::with_capacity(planes.len());
        let mut total_words = 0usize;
        for p in planes {
            let (bw, bh) = p.geometry.grid;
            let regions = bw.div_ceil(REGION) * bh.div_ceil(REGION);
            let count = varint::get_u32(bytes, &mut at)? as usize;
            if count == 0 || count > regions.max(1) {
                return Err(FormatError::Invalid(format!(
                    "{count} lanes for {regions} regions"
                )));
            }
            let mut lanes = Vec::with_capacity(count);
            let mut streams = Vec::with_capacity(count);
            let mut covered = 0usize;
            for _ in 0..count {
                let n = varint::get_u32(bytes, &mut at)? as usize;
                let k = match layout {
                    Layout::OneState => 1,
                    Layout::States => varint::get_u32(bytes, &mut at)? as usize,
                };
                // What a GPU decoder's lane may loop over (the encoder's caps).
                let most = max_lane_regions(layout);
                if n > most || k == 0 || k > MAX_STATES {
                    return Err(FormatError::Invalid(format!(
                        "a lane of {n} regions and {k} states (at most {most} regions, 1 to {MAX_STATES} states)"
                    )));
                }
                let first = streams.len();
                for _ in 0..k {
                    let w = varint::get_u32(bytes, &mut at)? as usize;
                    // A state to start from.
                    if w < 2 {
                        return Err(FormatError::Invalid(format!(
                            "a lane's stream of {w} words (at least 2, its state)"
                        )));
                    }
                    let words_end = total_words.saturating_add(w);
                    streams.push((total_words, words_end));
                    total_words = words_end;
                }
                let end = covered.saturating_add(n);
                lanes.push((covered, end, first, streams.len()));
                covered = end;
            }
            if covered != regions {
                return Err(FormatError::Invalid(format!(
                    "lanes cover {covered} regions of {regions}"
                )));
            }
            let map = &maps[p.family];
            out.push(SectionPlane {
                lanes,
                streams,
                histogram_of: map
                    .of
                    .iter()
                    .map(|&k| place[p.family][k as usize])
                    .collect(),
            });
        }
        if bytes.len() - at != 2 * total_words {
            return Err(FormatError::Invalid(format!(
                "{} bytes of lanes for {total_words} words",
                bytes.len() - at
            )));
        }
        Ok(Section {
            layout,
            histograms,
            file,
            places: place,
            planes: out,
            words_at: at,
            words: Vec::new(),
        })
    }
}

/// Decodes a coefficient section [`encode`] wrote for `planes`, with the file's `maps`,
/// its lanes laid out as `layout`. Returns each plane's blocks in its places' order.
pub fn decode(
    bytes: &[u8],
    planes: &[Plane],
    maps: &[ContextMap],
    layout: Layout,
) -> Result<Vec<Vec<[i32; N * N]>>> {
    let mut out = Vec::with_capacity(planes.len());
    decode_each(bytes, planes, maps, layout, |_, blocks| {
        out.push(blocks.dense());
        Ok(())
    })?;
    Ok(out)
}

/// [`decode`], handing each plane's blocks, sparse, to `each(plane, blocks)` as soon as
/// they are decoded, so that one plane's blocks are held at a time.
pub fn decode_each(
    bytes: &[u8],
    planes: &[Plane],
    maps: &[ContextMap],
    layout: Layout,
    mut each: impl FnMut(usize, &Decoded) -> Result<()>,
) -> Result<()> {
    decode_counted::<false>(bytes, planes, maps, layout, |i, blocks, _| each(i, blocks))
}

/// Each plane's lanes' serial steps, plane by plane: with one state a lane, its symbols
/// (a token and its raw bits are one), whatever the words they take (a likely zero costs
/// a fraction of a bit, and a step all the same); with several, per pass, its busiest
/// state's symbols, since its states decode side by side. Each lane's steps and states.
/// Decodes the section.
pub fn lane_symbols(
    bytes: &[u8],
    planes: &[Plane],
    maps: &[ContextMap],
    layout: Layout,
) -> Result<Vec<Vec<(u64, usize)>>> {
    let mut out = Vec::with_capacity(planes.len());
    decode_counted::<true>(bytes, planes, maps, layout, |_, _, lanes| {
        out.push(lanes.to_vec());
        Ok(())
    })?;
    Ok(out)
}

/// [`decode_each`], handing on each lane's steps (counted with `COUNT`, else 0) and
/// states too.
fn decode_counted<const COUNT: bool>(
    bytes: &[u8],
    planes: &[Plane],
    maps: &[ContextMap],
    layout: Layout,
    mut each: impl FnMut(usize, &Decoded, &[(u64, usize)]) -> Result<()>,
) -> Result<()> {
    let section = Section::parse(bytes, planes, maps, layout)?;
    for (i, (p, sp)) in planes.iter().zip(&section.planes).enumerate() {
        let mut decoders = Vec::with_capacity(sp.streams.len());
        for &(w0, w1) in &sp.streams {
            decoders.push(ans::Decoder::new(&section.words[w0..w1])?);
        }
        // Each region's groups' streams: group k of a lane (16 a region) is its state
        // k mod s. (Made once: a division per block was 2.5% of a decode.)
        let mut of_region: Vec<[u32; GROUPS]> = Vec::new();
        for &(r0, r1, s0, s1) in &sp.lanes {
            of_region.extend(
                (0..r1 - r0)
                    .map(|r| std::array::from_fn(|g| (s0 + (r * GROUPS + g) % (s1 - s0)) as u32)),
            );
        }
        let stream_of = |region: usize, group: usize| of_region[region][group] as usize;
        let mut streams = Streams::<COUNT> {
            symbols: vec![0; decoders.len()],
            lanes: (sp.lanes.iter())
                .map(|&(_, _, s0, s1)| (s0..s1, 0))
                .collect(),
            decoders,
            of: (sp.histogram_of.iter())
                .map(|&h| section.histograms.get(h as usize))
                .collect(),
        };
        let blocks = walk(&p.geometry, None, &stream_of, &mut streams, layout)?;
        streams.end_pass();
        for d in &streams.decoders {
            d.finish()?;
        }
        let counted: Vec<(u64, usize)> = (streams.lanes.iter())
            .map(|(r, steps)| (*steps, r.len()))
            .collect();
        each(i, &blocks, &counted)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed pseudo-random sequence (no dependency, the same on every machine).
    fn lcg(seed: &mut u64) -> u32 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 33) as u32
    }

    /// Blocks of a smooth plane with sparse detail: DCs on a ramp with noise, a few
    /// coefficients in some blocks, empty regions.
    fn blocks(n: usize, seed: u64, order: &[(usize, usize)]) -> Vec<[i32; N * N]> {
        let mut s = seed;
        (0..n)
            .map(|b| {
                let (x, y) = order[b];
                let mut q = [0i32; N * N];
                q[0] = if (x / 8 + y / 8) % 3 == 0 {
                    0
                } else {
                    (3 * x + 2 * y) as i32 + (lcg(&mut s) % 5) as i32 - 2
                };
                if lcg(&mut s).is_multiple_of(4) {
                    for _ in 0..lcg(&mut s) % 12 {
                        let i = 1 + (lcg(&mut s) % 40) as usize;
                        q[i] = (lcg(&mut s) % 41) as i32 - 20;
                    }
                }
                if lcg(&mut s).is_multiple_of(97) {
                    q[63] = -70_000;
                    q[0] = i32::MAX - (lcg(&mut s) % 3) as i32;
                }
                q
            })
            .collect()
    }

    /// Lanes cut at `bytes`: version 2's layout, or with `states`, version 3's.
    fn shape(bytes: usize, states: Option<u64>) -> LaneShape {
        LaneShape {
            bytes,
            symbols_per_state: states,
        }
    }

    fn round_trip(
        planes: &[(Plane, &[[i32; N * N]])],
        maps: &[ContextMap],
        shape: LaneShape,
    ) -> usize {
        let bytes = encode(planes, maps, shape).unwrap();
        let shapes: Vec<Plane> = planes.iter().map(|(p, _)| *p).collect();
        let got = decode(&bytes, &shapes, maps, shape.layout()).unwrap();
        for ((_, want), got) in planes.iter().zip(&got) {
            assert_eq!(*want, &got[..]);
        }
        bytes.len()
    }

    #[test]
    fn keyframe_and_bubble_planes_round_trip_with_any_lanes_and_maps() {
        // A keyframe plane of 37 × 29 blocks (regions and groups cut at its edges).
        let (bw, bh) = (37, 29);
        let key_order: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
        let key = blocks(key_order.len(), 1, &key_order);
        // A bubble plane: the member tiles (4 × 4 blocks) of a checker of tiles, each
        // tile's blocks in raster order.
        let mut bubble_order = Vec::new();
        for ty in 0..bh.div_ceil(4) {
            for tx in 0..bw.div_ceil(4) {
                if (tx * 7 + ty * 3) % 5 < 2 {
                    continue;
                }
                for y in ty * 4..(ty * 4 + 4).min(bh) {
                    for x in tx * 4..(tx * 4 + 4).min(bw) {
                        bubble_order.push((x, y));
                    }
                }
            }
        }
        let bubble = blocks(bubble_order.len(), 2, &bubble_order);
        let planes = [
            (
                Plane {
                    family: 0,
                    geometry: Geometry {
                        grid: (bw, bh),
                        order: &key_order,
                        tile: None,
                    },
                },
                &key[..],
            ),
            (
                Plane {
                    family: 1,
                    geometry: Geometry {
                        grid: (bw, bh),
                        order: &bubble_order,
                        tile: Some(4),
                    },
                },
                &bubble[..],
            ),
        ];
        let mut seed = 3;
        // Clusters 1, 3 and 5 with file-wide tables: one that covers the small tokens only
        // (chunks that need others send their own), one of everything.
        let small = Histogram::from_counts(&[50, 30, 10, 5, 3, 1]);
        let all = Histogram::from_counts(&[1; crate::ans::TOKENS]);
        let spread = ContextMap {
            clusters: 7,
            of: (0..CONTEXTS).map(|_| (lcg(&mut seed) % 7) as u8).collect(),
            tables: (0..7)
                .map(|k| match k {
                    1 | 5 => small.clone(),
                    3 => all.clone(),
                    _ => None,
                })
                .collect(),
        };
        let maps_tried = [
            vec![ContextMap::single(), ContextMap::single()],
            vec![spread.clone(), ContextMap::single()],
        ];
        for (maps, states) in maps_tried.iter().flat_map(|m| [(m, None), (m, Some(16))]) {
            // A GPU decoder's view: the file's histograms by their place among the
            // file's, the words where they lie.
            let shape = shape(64, states);
            let bytes = encode(&planes, maps, shape).unwrap();
            let shapes: Vec<Plane> = planes.iter().map(|(p, _)| *p).collect();
            let layout = Section::parse_layout(&bytes, &shapes, maps, shape.layout()).unwrap();
            let full = Section::parse(&bytes, &shapes, maps, shape.layout()).unwrap();
            assert!(layout.words.is_empty());
            assert_eq!(bytes.len() - layout.words_at, 2 * full.words.len());
            let file: Vec<&Histogram> = file_histograms(maps).map(|(_, _, h)| h).collect();
            for (h, g) in full.histograms.iter().zip(&full.file) {
                if let Some(g) = g {
                    assert_eq!(file[*g as usize], h);
                }
            }
            // With one state a lane, every symbol the encoder coded is one step of one
            // lane's chain; with several, a lane's states share its symbols (a state per
            // 16 of them here), and its chain is its busiest state's in each pass.
            let steps = lane_symbols(&bytes, &shapes, maps, shape.layout()).unwrap();
            for ((p, source), (lanes, sp)) in planes.iter().zip(steps.iter().zip(&full.planes)) {
                let mut record = Record(Vec::new());
                walk(
                    &p.geometry,
                    Some(source),
                    &|_, _| 0,
                    &mut record,
                    shape.layout(),
                )
                .unwrap();
                let symbols = record.0.len() as u64;
                let (chains, streams) = lanes.iter().fold((0, 0), |a, l| (a.0 + l.0, a.1 + l.1));
                assert_eq!(lanes.len(), sp.lanes.len());
                assert_eq!(streams, sp.streams.len());
                assert!(lanes.len() > 1 && lanes.iter().all(|&(n, _)| n > 0));
                match states {
                    None => assert_eq!((chains, streams), (symbols, lanes.len())),
                    Some(_) => assert!(
                        streams > 2 * lanes.len() && chains < symbols / 2,
                        "{chains} steps of {symbols} symbols in {streams} states"
                    ),
                }
            }
            let one = round_trip(
                &planes,
                maps,
                LaneShape {
                    bytes: usize::MAX,
                    ..shape
                },
            );
            let many = round_trip(&planes, maps, shape);
            // Lanes and states cost their final states and lengths, a few bytes each.
            let streams: usize = full.planes.iter().map(|p| p.streams.len()).sum();
            assert!(
                many > one && many < one + 7 * streams,
                "{many} against {one}"
            );
        }
        // An empty plane, and a plane whose blocks are all zero.
        let zeros = vec![[0i32; N * N]; key.len()];
        let none: Vec<(usize, usize)> = Vec::new();
        let planes = [
            (
                Plane {
                    family: 0,
                    geometry: Geometry {
                        grid: (bw, bh),
                        order: &key_order,
                        tile: None,
                    },
                },
                &zeros[..],
            ),
            (
                Plane {
                    family: 0,
                    geometry: Geometry {
                        grid: (bw, bh),
                        order: &none,
                        tile: Some(4),
                    },
                },
                &[][..],
            ),
        ];
        for states in [None, Some(1024)] {
            let bytes = round_trip(&planes, &[ContextMap::single()], shape(4096, states));
            // All zero: a flag per group at a near-certain probability.
            assert!(bytes < 40, "{bytes} bytes for nothing");
        }
    }

    #[test]
    fn context_maps_round_trip_and_damage_is_refused() {
        let mut seed = 11;
        let map = ContextMap {
            clusters: 13,
            of: (0..CONTEXTS).map(|_| (lcg(&mut seed) % 13) as u8).collect(),
            tables: (0..13)
                .map(|k| Histogram::from_counts(&[k + 1, 5, 0, 2]).filter(|_| k % 3 == 0))
                .collect(),
        };
        let mut w = BitWriter::default();
        map.write(&mut w, Layout::States);
        let bytes = w.finish();
        let read = |b: &[u8], layout| ContextMap::read(&mut BitReader::new(b), layout);
        assert_eq!(read(&bytes, Layout::States).unwrap(), map);
        assert!(read(&bytes[..bytes.len() - 1], Layout::States).is_err());
        // Version 2's maps stop at its contexts; the others read as cluster 0.
        let mut w = BitWriter::default();
        map.write(&mut w, Layout::OneState);
        let mut two = map.clone();
        two.of[contexts(Layout::OneState)..].fill(0);
        assert_eq!(read(&w.finish(), Layout::OneState).unwrap(), two);

        let order: Vec<(usize, usize)> = (0..400).map(|b| (b % 20, b / 20)).collect();
        let q = blocks(order.len(), 5, &order);
        let plane = Plane {
            family: 0,
            geometry: Geometry {
                grid: (20, 20),
                order: &order,
                tile: None,
            },
        };
        let maps = [ContextMap::single()];
        for shape in [shape(256, None), shape(256, Some(64))] {
            let layout = shape.layout();
            let good = encode(&[(plane, &q[..])], &maps, shape).unwrap();
            // Any single byte changed or cut: an error or other blocks, never a panic.
            for i in 0..good.len() {
                for flip in [1u8, 0x80] {
                    let mut bad = good.clone();
                    bad[i] ^= flip;
                    if let Ok(got) = decode(&bad, &[plane], &maps, layout) {
                        assert_eq!(got[0].len(), q.len());
                    }
                }
                assert!(decode(&good[..i], &[plane], &maps, layout).is_err());
            }
            // A plane of a family without a map.
            let other = Plane { family: 1, ..plane };
            assert!(encode(&[(other, &q[..])], &maps, shape).is_err());
        }
        // A version 2 section read as version 3, or the other way: refused or other
        // blocks, never a panic.
        for shape in [shape(256, None), shape(256, Some(64))] {
            let good = encode(&[(plane, &q[..])], &maps, shape).unwrap();
            let other = match shape.layout() {
                Layout::OneState => Layout::States,
                Layout::States => Layout::OneState,
            };
            if let Ok(got) = decode(&good, &[plane], &maps, other) {
                assert_eq!(got[0].len(), q.len());
            }
        }
    }
}
