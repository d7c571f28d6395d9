//! `vbim bench entropy FILE`: what a context-adaptive entropy coder would make of the file's
//! coefficient streams, against what they take now.
//!
//! Today every stream is (zero run, value) varint pairs through zstd (docs/FORMAT.md,
//! "Coefficient streams"): zstd finds repeated byte strings, but it has no idea that a
//! coefficient at a high frequency is almost always 0, or that a block beside a busy block
//! is busy too. A codec's coder (H.264's CABAC, AV1's symbol coder) codes each coefficient
//! with probabilities learnt from its context. This measures the *ideal code length* of
//! such a model, Σ −log₂ p over every binary decision, with the probabilities adapting as
//! they go: an arithmetic coder reaches it within about 1%. The number tells what a format
//! change to the entropy coding would buy before anyone makes one.
//!
//! The model, per 8×8 block in zig-zag order (contexts kept apart per stream kind and for
//! luma and chroma):
//! - DC: predicted from the left, upper and upper-left blocks' DC (the median predictor of
//!   LOCO-I); the residual as zero / sign / Exp-Golomb magnitude, its prefix adaptive in a
//!   context of the neighbours' residual sizes.
//! - AC: a "coded" flag per block (context: how many of the left and upper blocks have AC
//!   terms), then per position up to the last non-zero one a significance flag (context:
//!   the position's band, whether the left and upper blocks have a term there, whether the
//!   previous position had one) and, where significant, a last flag (context: band); levels
//!   as greater-than-1, greater-than-2 flags and an Exp-Golomb remainder, signs as raw bits.

use std::io::BufReader;

use vbim_format::chunk::{self, TileMap};
use vbim_format::dct::N;
use vbim_format::plane2::{band, size_class};
use vbim_format::{plane, plane2, ChunkKind, Header, Reader};

use super::static_coding::{PlaneStream, Study};
use super::BenchEntropyArgs;
use crate::progress::Stages;

/// The largest payload decompressed: the format's own bound for one chunk.
const LIMIT: usize = vbim_format::limits::MAX_CHUNK_DECODED as usize;

/// An adaptive binary probability: counts, halved when they reach [`HALVE_AT`] so that the
/// estimate follows the content as it changes over the day.
#[derive(Clone, Copy)]
struct Bit {
    n: [f32; 2],
}

const HALVE_AT: f32 = 1024.0;

impl Default for Bit {
    fn default() -> Bit {
        Bit { n: [0.4, 0.4] }
    }
}

impl Bit {
    /// Bits to code `b`, and learn it.
    fn code(&mut self, b: bool) -> f64 {
        let p = self.n[b as usize] / (self.n[0] + self.n[1]);
        self.n[b as usize] += 1.0;
        if self.n[0] + self.n[1] > HALVE_AT {
            // (Never below the prior: a symbol not seen for a long while stays possible.)
            self.n[0] = (self.n[0] * 0.5).max(0.4);
            self.n[1] = (self.n[1] * 0.5).max(0.4);
        }
        -(p as f64).log2()
    }
}

/// The bands of `plane2::band`.
const BANDS: usize = 12;
/// Unary prefix bins of an Exp-Golomb code that get their own adaptive probability.
const PREFIX: usize = 12;

/// The contexts of one kind of stream for one plane class.
struct Model {
    dc_zero: [Bit; 4],
    dc_sign: [Bit; 4],
    dc_prefix: [[Bit; PREFIX]; 4],
    coded: [Bit; 3],
    sig: [[[Bit; 2]; 3]; BANDS],
    last: [Bit; BANDS],
    gt1: [[Bit; 3]; BANDS],
    gt2: [Bit; BANDS],
    rem_prefix: [Bit; PREFIX],
}

impl Default for Model {
    fn default() -> Model {
        Model {
            dc_zero: Default::default(),
            dc_sign: Default::default(),
            dc_prefix: [[Bit::default(); PREFIX]; 4],
            coded: Default::default(),
            sig: [[[Bit::default(); 2]; 3]; BANDS],
            last: [Bit::default(); BANDS],
            gt1: [[Bit::default(); 3]; BANDS],
            gt2: [Bit::default(); BANDS],
            rem_prefix: [Bit::default(); PREFIX],
        }
    }
}

/// Exp-Golomb (order 0) code of `v ≥ 0`: the unary prefix through adaptive bins (the last
/// bin shared by the rest), the suffix as raw bits.
fn exp_golomb(v: u32, prefix: &mut [Bit; PREFIX]) -> f64 {
    let len = 31 - (v + 1).leading_zeros() as usize;
    let mut bits = 0.0;
    for i in 0..=len {
        bits += prefix[i.min(PREFIX - 1)].code(i < len);
    }
    bits + len as f64
}

impl Model {
    /// Bits for `blocks`, the model learning as it goes and starting afresh every
    /// `substream` blocks (0: never). `left`, `up` and `up_left` give the block beside
    /// block b that was coded before it in its substream, if any.
    fn code(
        &mut self,
        blocks: &[[i32; N * N]],
        substream: usize,
        left: impl Fn(usize) -> Option<usize>,
        up: impl Fn(usize) -> Option<usize>,
        up_left: impl Fn(usize) -> Option<usize>,
    ) -> f64 {
        let mut bits = 0.0;
        let mut residual = vec![0i32; blocks.len()];
        for (b, q) in blocks.iter().enumerate() {
            if substream > 0 && b > 0 && b % substream == 0 {
                // A substream a parser starts on its own: it learns from scratch.
                *self = Model::default();
            }
            let (l, u, ul) = (left(b), up(b), up_left(b));
            // DC, predicted.
            let dc = |o: Option<usize>| o.map(|i| blocks[i][0]);
            let pred = match (dc(l), dc(u), dc(ul)) {
                (Some(a), Some(c), Some(d)) => {
                    if d >= a.max(c) {
                        a.min(c)
                    } else if d <= a.min(c) {
                        a.max(c)
                    } else {
                        a + c - d
                    }
                }
                (Some(a), Some(c), None) => (a + c) / 2,
                (Some(a), None, _) => a,
                (None, Some(c), _) => c,
                _ => 0,
            };
            let r = q[0] - pred;
            residual[b] = r;
            let nb = |o: Option<usize>| o.map_or(0, |i| size_class(residual[i]));
            let ctx = (nb(l) + nb(u)).min(3);
            bits += self.dc_zero[ctx].code(r == 0);
            if r != 0 {
                bits += self.dc_sign[ctx].code(r < 0);
                bits += exp_golomb(r.unsigned_abs() - 1, &mut self.dc_prefix[ctx]);
            }
            // AC.
            let has_ac =
                |o: Option<usize>| o.is_some_and(|i| blocks[i][1..].iter().any(|&v| v != 0));
            let last = (1..N * N).rev().find(|&i| q[i] != 0);
            let ctx = has_ac(l) as usize + has_ac(u) as usize;
            bits += self.coded[ctx].code(last.is_some());
            let Some(last) = last else { continue };
            let mut prev_sig = q[0] != 0;
            let mut big = 0usize;
            for (i, &v) in q.iter().enumerate().take(last + 1).skip(1) {
                let at = |o: Option<usize>| o.is_some_and(|j| blocks[j][i] != 0);
                let n = at(l) as usize + at(u) as usize;
                let bd = band(i);
                bits += self.sig[bd][n][prev_sig as usize].code(v != 0);
                prev_sig = v != 0;
                if v == 0 {
                    continue;
                }
                bits += self.last[bd].code(i == last);
                let m = v.unsigned_abs();
                bits += self.gt1[bd][big.min(2)].code(m > 1);
                if m > 1 {
                    big += 1;
                    bits += self.gt2[bd].code(m > 2);
                    if m > 2 {
                        bits += exp_golomb(m - 3, &mut self.rem_prefix);
                    }
                }
                bits += 1.0; // sign
            }
        }
        bits
    }
}

/// What one kind of stream costs now and under the model.
#[derive(Default, Clone, Copy)]
struct Tally {
    chunks: usize,
    stored: u64,
    model_bits: f64,
    /// Bytes outside the coefficient streams (mode, steps, degree): kept as they are.
    other: u64,
}

const KINDS: [&str; 4] = [
    "intra keyframes",
    "predicted keyframes",
    "bubble terms (coefficient chunks)",
    "tile maps and metadata",
];

/// One coefficient plane of a chunk, as read from today's stream.
struct PlaneData {
    chroma: bool,
    blocks: Vec<[i32; N * N]>,
    /// Each block's place on the block grid, in stream order.
    order: Vec<(usize, usize)>,
    /// Blocks across a tile, for a bubble plane.
    tile: Option<usize>,
}

/// A keyframe or coefficient chunk's planes: (kind of stream, bytes outside the
/// coefficient streams, planes); `None` for other chunks (a tile map is kept in `tiles`).
fn chunk_planes(
    h: &Header,
    e: &vbim_format::IndexEntry,
    bytes: &[u8],
    tiles: &mut Option<TileMap>,
) -> Result<Option<(usize, u64, Vec<PlaneData>)>, String> {
    let planes = h.channels as usize;
    let (w, ht) = chunk::padded_size(h);
    let (bw, bh) = (w / N, ht / N);
    match e.kind {
        ChunkKind::Keyframe => {
            let raw = chunk::decompress(bytes, LIMIT).map_err(|e| e.to_string())?;
            let kind = if raw[0] == chunk::MODE_INTRA { 0 } else { 1 };
            let mut pos = 4 + 4 * planes;
            let raster: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
            let mut out = Vec::new();
            for p in 0..planes {
                let blocks = plane::read_coefficients(&raw, &mut pos, bw * bh)
                    .map_err(|e| format!("plane {p}: {e}"))?;
                out.push(PlaneData {
                    chroma: p > 0,
                    blocks,
                    order: raster.clone(),
                    tile: None,
                });
            }
            Ok(Some((kind, 4 + 4 * planes as u64, out)))
        }
        ChunkKind::TileMap => {
            let len = e.last_frame - e.first_frame;
            *tiles = Some(chunk::read_tilemap(h, bytes, len).map_err(|e| e.to_string())?);
            Ok(None)
        }
        ChunkKind::Coefficients => {
            let t = tiles.as_ref().ok_or("coefficients before a tile map")?;
            let raw = chunk::decompress(bytes, LIMIT).map_err(|e| e.to_string())?;
            let dmax = raw[0];
            let mut pos = 4 + 4 * (dmax.max(1) as usize - 1) * planes;
            let ts = h.tile_size as usize / N;
            let (tx, ty) = (h.tiles_x() as usize, h.tiles_y() as usize);
            let mut out = Vec::new();
            for k in 2..=dmax {
                for p in 0..planes {
                    // The member tiles' blocks: tiles in raster order, each tile's blocks
                    // in raster order; their places on the block grid.
                    let mut order = Vec::new();
                    for tyi in 0..ty {
                        for txi in 0..tx {
                            if t.degree(p, tyi * tx + txi) < k {
                                continue;
                            }
                            for y in tyi * ts..((tyi + 1) * ts).min(bh) {
                                for x in txi * ts..(txi + 1) * ts {
                                    order.push((x, y));
                                }
                            }
                        }
                    }
                    let blocks = plane::read_coefficients(&raw, &mut pos, order.len())
                        .map_err(|e| format!("term {k}, plane {p}: {e}"))?;
                    out.push(PlaneData {
                        chroma: p > 0,
                        blocks,
                        order,
                        tile: Some(ts),
                    });
                }
            }
            Ok(Some((
                2,
                4 + 4 * (dmax.max(1) as u64 - 1) * planes as u64,
                out,
            )))
        }
        _ => Ok(None),
    }
}

pub fn run(a: BenchEntropyArgs) -> Result<(), String> {
    let name = a.file.display().to_string();
    let f = crate::sequence::open_input(&a.file)?;
    let mut r = Reader::open(BufReader::new(f)).map_err(|e| format!("{name}: {e}"))?;
    let h = r.header().clone();
    let entries = r.entries().to_vec();
    let (w, _) = chunk::padded_size(&h);
    let bw = w / N;
    let mut tally = [Tally::default(); 4];
    let mut tiles: Option<TileMap> = None;
    let mut study = Study::default();
    let stages = Stages::new();
    for (i, e) in entries.iter().enumerate() {
        stages.report("modelling chunks", i as u64, entries.len() as u64);
        let bytes = r
            .read_chunk(i)
            .map_err(|e| format!("{name}: chunk {i}: {e}"))?;
        let Some((kind, other, planes)) = chunk_planes(&h, e, &bytes, &mut tiles)
            .map_err(|e| format!("{name}: chunk {i}: {e}"))?
        else {
            tally[3].chunks += 1;
            tally[3].stored += bytes.len() as u64;
            continue;
        };
        // Each chunk's models (luma, chroma) start from scratch, so that a player can seek
        // to the chunk.
        let mut models: [Model; 2] = Default::default();
        study.start_chunk(kind, bytes.len() as u64, other);
        for p in &planes {
            let grid = Grid {
                bw,
                sub: a.substream,
            };
            let m = &mut models[p.chroma as usize];
            tally[kind].model_bits += grid.code_at(m, &p.blocks, &p.order);
            study.plane(&PlaneStream {
                kind,
                chroma: p.chroma,
                blocks: &p.blocks,
                order: &p.order,
                grid: (bw, chunk::padded_size(&h).1 / N),
                tile: p.tile,
            });
        }
        let t = &mut tally[kind];
        t.chunks += 1;
        t.stored += bytes.len() as u64;
        t.other += other;
    }
    stages.finish();
    report(&name, &h, &tally);
    study.report(std::array::from_fn(|k| {
        tally[k].model_bits / 8.0 + tally[k].other as f64
    }));
    // Format 2's plane coding (`vbim_format::plane2`) with the maps the study learnt:
    // every chunk coded, decoded back and checked.
    let maps = study.maps(16);
    let mut map_bits = vbim_format::ans::BitWriter::default();
    maps.iter()
        .for_each(|m| m.write(&mut map_bits, plane2::Layout::OneState));
    let map_bytes = map_bits.finish().len() as u64;
    let (mut coded, mut stored) = (map_bytes, 0u64);
    let bh = chunk::padded_size(&h).1 / N;
    for (i, e) in entries.iter().enumerate() {
        stages.report("coding chunks with plane2", i as u64, entries.len() as u64);
        let bytes = r
            .read_chunk(i)
            .map_err(|e| format!("{name}: chunk {i}: {e}"))?;
        let Some((kind, other, planes)) = chunk_planes(&h, e, &bytes, &mut tiles)
            .map_err(|e| format!("{name}: chunk {i}: {e}"))?
        else {
            continue;
        };
        let shapes: Vec<plane2::Plane> = planes
            .iter()
            .map(|p| plane2::Plane {
                family: kind * 2 + p.chroma as usize,
                geometry: plane2::Geometry {
                    grid: (bw, bh),
                    order: &p.order,
                    tile: p.tile,
                },
            })
            .collect();
        let input: Vec<(plane2::Plane, &[[i32; N * N]])> = shapes
            .iter()
            .zip(&planes)
            .map(|(s, p)| (*s, &p.blocks[..]))
            .collect();
        let shape = plane2::LaneShape {
            bytes: LANE_BYTES,
            symbols_per_state: None,
        };
        let section = plane2::encode(&input, &maps, shape)
            .map_err(|e| format!("{name}: chunk {i}: plane2: {e}"))?;
        let back = plane2::decode(&section, &shapes, &maps, shape.layout())
            .map_err(|e| format!("{name}: chunk {i}: plane2 decode: {e}"))?;
        for (p, got) in planes.iter().zip(&back) {
            if p.blocks != *got {
                return Err(format!("{name}: chunk {i}: plane2 did not round-trip"));
            }
        }
        coded += section.len() as u64 + other;
        stored += bytes.len() as u64;
    }
    stages.finish();
    println!(
        "Format 2's plane coding (vbim_format::plane2, design E, 16 histograms per family, lanes of {LANE_BYTES} B or more; every chunk decoded back and checked): {coded} B against {stored} B stored, {:.3} (the file's context maps {map_bytes} B)",
        coded as f64 / stored.max(1) as f64
    );
    Ok(())
}

/// The coded size at which `plane2` cuts a lane.
const LANE_BYTES: usize = 4096;

/// The block grid of a plane.
struct Grid {
    bw: usize,
    /// Blocks per independently parsed substream (0: the whole stream is one).
    sub: usize,
}

impl Grid {
    /// Every block of the plane in raster order (a keyframe's stream).
    #[cfg(test)]
    fn code(&self, m: &mut Model, blocks: &[[i32; N * N]], n: usize) -> f64 {
        let order: Vec<(usize, usize)> = (0..n).map(|b| (b % self.bw, b / self.bw)).collect();
        self.code_at(m, blocks, &order)
    }

    /// `blocks[b]` sits at `order[b]`; its neighbours are whichever of the blocks to its
    /// left, above and above-left came earlier in the stream.
    fn code_at(&self, m: &mut Model, blocks: &[[i32; N * N]], order: &[(usize, usize)]) -> f64 {
        let bh = order.iter().map(|p| p.1 + 1).max().unwrap_or(0);
        let mut index = vec![u32::MAX; self.bw * bh];
        for (b, &(x, y)) in order.iter().enumerate() {
            index[y * self.bw + x] = b as u32;
        }
        let find = |b: usize, dx: isize, dy: isize| {
            let (x, y) = order[b];
            let (x, y) = (x as isize + dx, y as isize + dy);
            if x < 0 || y < 0 {
                return None;
            }
            let j = index[y as usize * self.bw + x as usize] as usize;
            let same_substream = self.sub == 0 || j / self.sub == b / self.sub;
            (j < b && same_substream).then_some(j)
        };
        m.code(
            blocks,
            self.sub,
            |b| find(b, -1, 0),
            |b| find(b, 0, -1),
            |b| find(b, -1, -1),
        )
    }
}

fn report(name: &str, h: &Header, tally: &[Tally; 4]) {
    println!(
        "{name}: {}×{}, {} channel(s), {} frames",
        h.width, h.height, h.channels, h.frame_count
    );
    println!(
        "| streams | chunks | now (zstd of run/value pairs) | context-adaptive (ideal) | ratio |"
    );
    println!("|---|---:|---:|---:|---:|");
    let (mut now, mut model) = (0u64, 0.0f64);
    for (k, t) in tally.iter().enumerate() {
        let est = if k == 3 {
            t.stored as f64
        } else {
            t.model_bits / 8.0 + t.other as f64
        };
        now += t.stored;
        model += est;
        if t.chunks == 0 {
            continue;
        }
        println!(
            "| {} | {} | {} B | {:.0} B | {:.3} |",
            KINDS[k],
            t.chunks,
            t.stored,
            est,
            est / t.stored.max(1) as f64
        );
    }
    println!(
        "| all chunks | | {now} B | {model:.0} B | {:.3} |",
        model / now.max(1) as f64
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed pseudo-random sequence (no dependency, the same on every machine).
    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn an_adaptive_bit_costs_its_entropy_and_follows_a_change() {
        let h = |p: f64| -(p * p.log2() + (1.0 - p) * (1.0 - p).log2());
        let (mut seed, mut b) = (1u64, Bit::default());
        let n = 200_000;
        let first: f64 = (0..n).map(|_| b.code(lcg(&mut seed) < 0.1)).sum::<f64>() / n as f64;
        // Within 2% of the entropy: the halving keeps it adaptive at a small price.
        assert!(
            (first / h(0.1) - 1.0).abs() < 0.02,
            "{first} against {}",
            h(0.1)
        );
        // The source changes: the estimate follows within a few thousand symbols.
        let second: f64 = (0..n).map(|_| b.code(lcg(&mut seed) < 0.7)).sum::<f64>() / n as f64;
        assert!(
            (second / h(0.7) - 1.0).abs() < 0.02,
            "{second} against {}",
            h(0.7)
        );
    }

    #[test]
    fn exp_golomb_lengths() {
        // With the prefix bins certain (learnt), a value costs about its suffix: 0 → 0
        // bits, 1–2 → 1, 3–6 → 2, 7–14 → 3.
        let mut prefix = [Bit::default(); PREFIX];
        for _ in 0..5000 {
            exp_golomb(4, &mut prefix);
        }
        let c = exp_golomb(4, &mut prefix);
        assert!((2.0..2.05).contains(&c), "{c}");
    }

    #[test]
    fn zero_blocks_cost_nearly_nothing_and_neighbours_help() {
        let n = 4096;
        let zeros = vec![[0i32; N * N]; n];
        let grid = Grid { bw: 64, sub: 0 };
        let bits = grid.code(&mut Model::default(), &zeros, n);
        assert!(bits / (n as f64) < 0.02, "{bits} bits for {n} empty blocks");
        // DC values that step up row by row: each is its left neighbour's, so the
        // residual is 0 and costs next to nothing. (The format's DC differences from the
        // previous block jump at every row's start.)
        let ramp: Vec<[i32; N * N]> = (0..n)
            .map(|b| {
                let mut q = [0; N * N];
                q[0] = 7 * (b / 64) as i32;
                q
            })
            .collect();
        let bits = grid.code(&mut Model::default(), &ramp, n);
        assert!(bits / (n as f64) < 0.1, "{bits} bits for {n} ramp blocks");
    }

    #[test]
    fn substreams_cut_the_context_and_cost_more() {
        let mut seed = 7u64;
        let n = 4096;
        let blocks: Vec<[i32; N * N]> = (0..n)
            .map(|_| {
                let mut q = [0; N * N];
                for (i, v) in q.iter_mut().enumerate().take(12) {
                    if lcg(&mut seed) < 0.6 / (1 + i) as f64 {
                        *v = if lcg(&mut seed) < 0.5 { 1 } else { -2 };
                    }
                }
                q
            })
            .collect();
        let cost = |sub| {
            let grid = Grid { bw: 64, sub };
            grid.code(&mut Model::default(), &blocks, n)
        };
        let (whole, cut) = (cost(0), cost(64));
        assert!(cut > whole * 1.01, "{cut} against {whole}");
    }
}
