//! The design study for format 2's coefficient coding, printed by `vbim bench entropy`
//! after the adaptive model: what a *static*, GPU-decodable coder would make of the same
//! quantised integers.
//!
//! The adaptive model of `entropy.rs` learns every probability as it goes and takes its
//! contexts from the blocks coded before: one long serial chain, which a GPU cannot
//! share out. A coder a GPU decodes (rANS, as JPEG XL, GST and Recoil use it) wants
//! instead:
//! - **static probabilities**: one histogram per cluster of contexts, counted by the
//!   encoder over the chunk and sent with it (12-bit probabilities);
//! - **hybrid-uint tokens** (JPEG XL's 4-2-0): values below 16 are their own token, larger
//!   ones a token for the exponent and the two bits below the leading one, then raw bits;
//!   signed values folded (0, −1, 1, −2, … → 0, 1, 2, 3, …);
//! - per block, in this order: the DC's residual against the planar prediction
//!   (left + up − up-left, 0 outside the plane, or outside the tile for a bubble plane: a
//!   linear predictor, so the GPU undoes it with a 2-D prefix sum), the number of non-zero
//!   AC coefficients, then the coefficients in zig-zag order until that many were coded,
//!   each in a context of how many are left and of its frequency band (JPEG XL's
//!   zero-density contexts);
//! - contexts that a lane decoding its own blocks knows when it needs them.
//!
//! The designs differ in what the DC, the count and the coefficients see:
//! - **A, within the block**: the count in a context of the block's own DC residual size;
//! - **B, checkerboard**: blocks with x + y even are coded as in A; the others then take
//!   the mean count and residual size of their four neighbours (all even, so decoded in a
//!   first pass): two passes, each fully parallel;
//! - **D**: B after a flag per group of 4 × 4 blocks saying whether any of them holds
//!   anything (the groups in a checkerboard of their own);
//! - **E**: D with an odd block's coefficients also in a context of how many of its
//!   neighbours have a coefficient at the same frequency;
//! - **F**: E with a keyframe's DC plane as an integer 5/3 wavelet pyramid instead of
//!   planar residuals (a bubble plane's DC as in E);
//! - **G**: E with one symbol for a block's DC residual and whether it has a coefficient
//!   (2 × the folded residual + 1 if it has; in D's DC context × whether an odd block's
//!   neighbours have any), then its count less one only where it has one: a block with
//!   nothing but its DC is one symbol, not two, and a GPU lane's time is its symbols;
//! - **R**: G with each non-zero coefficient and the zeros before it as one symbol (the
//!   run, whether the value is beyond ±1 and its sign: a token of its own for each run up
//!   to 30, four more for longer runs with the run less 31 in 5 raw bits), in E's context
//!   of the run's first position, then |v| − 2 by band where it is beyond ±1: JPEG's
//!   run–level coding in E's contexts, for half the symbols;
//! - **C, serial neighbours**: the left and upper blocks' counts and residual sizes, as a
//!   CPU coder would use them (the reference: what parallelism costs).
//!
//! The contexts of each stream family (intra keyframe, predicted keyframe, bubble term; ×
//! luma, chroma) are clustered once per file (greedy merges of the pair whose merge costs
//! least on the file's totals, JPEG XL's approach) into K histograms; each chunk then pays
//! for its K histograms' symbols at the chunk's own quantised probabilities, plus the
//! histograms themselves (estimated at 8 bits per symbol used, 8 per histogram). rANS
//! codes within about 0.1% of that length. Parallel lanes each end on a 32-bit state:
//! the report counts 4 bytes per lane at one lane per 256 and per 64 blocks of a plane.

use vbim_format::ans::{self, TOKENS};
use vbim_format::dct::N;
use vbim_format::plane2::{self, band, count_bucket, left_bucket, pack as pack_signed, size_class};

/// The hybrid-uint token of `v` and its raw bits' count.
fn hybrid_uint(v: u32) -> (usize, u32) {
    let (t, n, _) = ans::hybrid_uint(v);
    (t, n)
}

// Context numbers within a family: each design's DC and count contexts, then the AC
// contexts all three share.
const DC_A: usize = 0;
const DC_B: usize = DC_A + 1; // even blocks, then 4 buckets of the neighbours' sizes
const DC_C: usize = DC_B + 5; // 4: the left and upper residual sizes
const NZ_A: usize = DC_C + 4; // 3: the block's own DC size
const NZ_B: usize = NZ_A + 3; // even: 3 by DC size; odd: 8 by the neighbours' mean count
const NZ_C: usize = NZ_B + 11; // 8 by the left and upper mean count, 3 without either
const GROUP_D: usize = NZ_C + 11; // 6: even groups; odd by their empty neighbour groups
const DC_D: usize = GROUP_D + 6; // as DC_B, blocks of groups with something only
const NZ_D: usize = DC_D + 5; // as NZ_B, the same
const AC: usize = NZ_D + 11; // 10 × 12: coefficients left × band
const AC_EVEN: usize = AC + 120; // E: even blocks as AC
const AC_ODD: usize = AC_EVEN + 120; // E: odd blocks, × 3 by the neighbours with a term there
const DC_F: usize = AC_ODD + 360; // F: keyframe DC pyramid, 1 + 6 levels × 2 × 4 activity
const DC_FB: usize = DC_F + 49; // F: bubble planes' DC as DC_D
const JOINT_G: usize = DC_FB + 5; // G: 10, DC_D's × whether a neighbour has a coefficient
const NZ_G: usize = JOINT_G + 10; // G: as NZ_D, the count less one where there is any
const RUN_R: usize = NZ_G + 11; // R: E's coefficient contexts (120 even, 360 odd) at a run's start
const BIG_R: usize = RUN_R + 480; // R: 12, |v| − 2 of a coefficient beyond ±1, by band
const CONTEXTS: usize = BIG_R + 12;

/// The contexts each design reads, besides the shared AC ones.
const DESIGNS: [(&str, &[std::ops::Range<usize>]); 8] = [
    (
        "A, within the block",
        &[DC_A..DC_A + 1, NZ_A..NZ_A + 3, AC..AC + 120],
    ),
    (
        "B, checkerboard (2 passes)",
        &[DC_B..DC_B + 5, NZ_B..NZ_B + 11, AC..AC + 120],
    ),
    (
        "D, B after a flag per empty 4 × 4 blocks (4 passes)",
        &[
            GROUP_D..GROUP_D + 6,
            DC_D..DC_D + 5,
            NZ_D..NZ_D + 11,
            AC..AC + 120,
        ],
    ),
    (
        "E, D with odd blocks' coefficients in a context of their neighbours'",
        &[
            GROUP_D..GROUP_D + 6,
            DC_D..DC_D + 5,
            NZ_D..NZ_D + 11,
            AC_EVEN..AC_ODD + 360,
        ],
    ),
    (
        "F, E with a keyframe's DC plane as a 5/3 wavelet pyramid (parallel per level)",
        &[
            GROUP_D..GROUP_D + 6,
            DC_F..DC_FB + 5,
            NZ_D..NZ_D + 11,
            AC_EVEN..AC_ODD + 360,
        ],
    ),
    (
        "G, E with one symbol for a block's DC residual and whether it has a coefficient",
        &[
            GROUP_D..GROUP_D + 6,
            JOINT_G..NZ_G + 11,
            AC_EVEN..AC_ODD + 360,
        ],
    ),
    (
        "R, G with each non-zero coefficient and the zeros before it in one symbol",
        &[GROUP_D..GROUP_D + 6, JOINT_G..NZ_G + 11, RUN_R..BIG_R + 12],
    ),
    (
        "C, serial neighbours",
        &[DC_C..DC_C + 4, NZ_C..NZ_C + 11, AC..AC + 120],
    ),
];

/// Stream families: (intra keyframe, predicted keyframe, bubble term) × (luma, chroma).
const FAMILIES: usize = 6;

/// One plane's stream as the study reads it.
pub(super) struct PlaneStream<'a> {
    /// Kind of chunk (0 intra keyframe, 1 predicted keyframe, 2 bubble term).
    pub kind: usize,
    pub chroma: bool,
    /// The blocks in stream order and where each lies on the block grid.
    pub blocks: &'a [[i32; N * N]],
    pub order: &'a [(usize, usize)],
    /// Blocks across and down the plane.
    pub grid: (usize, usize),
    /// Blocks across a tile, for a bubble plane: its DC prediction stays in the tile.
    pub tile: Option<usize>,
}

/// The symbols of one chunk: a count per (family, context, token), and the raw bits.
struct ChunkCounts {
    kind: usize,
    counts: Vec<u32>,
    raw_bits: u64,
    /// Design F's raw bits less the others' (its keyframe DC symbols differ).
    raw_f: i64,
    /// Design G's raw bits less the others' (its joint DC symbols and counts less one).
    raw_g: i64,
    /// Design R's raw bits less G's (its long runs' and its |v| − 2's against the
    /// coefficients').
    raw_r: i64,
    /// Blocks of each plane stream (for the lanes' states).
    planes: Vec<usize>,
    /// Bytes outside the coefficient streams, kept as they are.
    other: u64,
    stored: u64,
}

#[derive(Default)]
pub(super) struct Study {
    chunks: Vec<ChunkCounts>,
}

impl Study {
    /// Starts a chunk of `kind` (0–2), `stored` bytes as the file has it, of which `other`
    /// lie outside the coefficient streams.
    pub fn start_chunk(&mut self, kind: usize, stored: u64, other: u64) {
        self.chunks.push(ChunkCounts {
            kind,
            counts: vec![0; FAMILIES * CONTEXTS * TOKENS],
            raw_bits: 0,
            raw_f: 0,
            raw_g: 0,
            raw_r: 0,
            planes: Vec::new(),
            other,
            stored,
        });
    }

    /// Counts one plane's symbols into the chunk started last.
    pub fn plane(&mut self, p: &PlaneStream) {
        let c = self.chunks.last_mut().expect("a chunk started");
        c.planes.push(p.blocks.len());
        let family = p.kind * 2 + p.chroma as usize;
        let base = family * CONTEXTS;
        let (bw, bh) = p.grid;
        let mut index = vec![u32::MAX; bw * bh];
        for (b, &(x, y)) in p.order.iter().enumerate() {
            index[y * bw + x] = b as u32;
        }
        let at = |x: isize, y: isize| -> Option<usize> {
            if x < 0 || y < 0 || x >= bw as isize || y >= bh as isize {
                return None;
            }
            let i = index[y as usize * bw + x as usize];
            (i != u32::MAX).then_some(i as usize)
        };
        let nz: Vec<usize> = p
            .blocks
            .iter()
            .map(|q| q[1..].iter().filter(|&&v| v != 0).count())
            .collect();
        // DC residuals against the planar prediction, in the prediction's domain.
        let same_tile = |(x, y): (usize, usize), (u, v): (usize, usize)| {
            p.tile.is_none_or(|t| x / t == u / t && y / t == v / t)
        };
        let residual: Vec<i32> = p
            .order
            .iter()
            .enumerate()
            .map(|(b, &(x, y))| {
                let dc = |dx: isize, dy: isize| {
                    at(x as isize + dx, y as isize + dy)
                        .filter(|&j| same_tile((x, y), p.order[j]))
                        .map_or(0, |j| p.blocks[j][0])
                };
                p.blocks[b][0]
                    .wrapping_sub(dc(-1, 0))
                    .wrapping_sub(dc(0, -1))
                    .wrapping_add(dc(-1, -1))
            })
            .collect();
        // F: a keyframe's DC plane through an integer 5/3 wavelet pyramid (JPEG 2000's
        // reversible transform, rows then columns, level by level): the coarsest values, then each level's details
        // in a context of their level, direction and the activity of the level's coarse
        // values around them (decoded before them).
        if p.tile.is_none() && p.blocks.len() == bw * bh {
            let dc: Vec<i32> = p.blocks.iter().map(|q| q[0]).collect();
            let mut raw_planar = 0i64;
            for &r in &residual {
                raw_planar += hybrid_uint(pack_signed(r)).1 as i64;
            }
            let mut raw_f = 0i64;
            pyramid(dc, bw, bh, |ctx, v| {
                let (t, raw) = hybrid_uint(v);
                c.counts[(base + DC_F + ctx) * TOKENS + t] += 1;
                raw_f += raw as i64;
            });
            c.raw_f += raw_f - raw_planar;
        }
        // (Each design codes the DC and the count once: their raw bits are counted with
        // design A's symbol only; G's difference is kept apart.)
        let mut raw_g = 0i64;
        let mut raw_r = 0i64;
        let mut put = |ctx: usize, v: u32, raw_too: bool| {
            // (R's run symbols are their own tokens.)
            let (t, raw) = match (RUN_R..BIG_R).contains(&ctx) {
                true => (v as usize, 0),
                false => hybrid_uint(v),
            };
            c.counts[(base + ctx) * TOKENS + t] += 1;
            if raw_too {
                c.raw_bits += raw as u64;
            }
        };
        // D: groups of 4 × 4 blocks, empty where no block has a DC residual or a
        // coefficient; a flag per group (checkerboard of groups), then B's symbols for the
        // blocks of the groups with something.
        let (gw, gh) = (bw.div_ceil(4), bh.div_ceil(4));
        let mut group_full = vec![None::<bool>; gw * gh];
        for (b, &(x, y)) in p.order.iter().enumerate() {
            let g = &mut group_full[(y / 4) * gw + x / 4];
            *g = Some(g.unwrap_or(false) || residual[b] != 0 || nz[b] != 0);
        }
        for gy in 0..gh {
            for gx in 0..gw {
                let Some(full) = group_full[gy * gw + gx] else {
                    continue;
                };
                let around: Vec<bool> = [(-1, 0), (1, 0), (0, -1), (0, 1)]
                    .iter()
                    .filter_map(|&(dx, dy)| {
                        let (u, v) = (gx as isize + dx, gy as isize + dy);
                        if u < 0 || v < 0 || u >= gw as isize || v >= gh as isize {
                            return None;
                        }
                        group_full[v as usize * gw + u as usize]
                    })
                    .collect();
                let ctx = if (gx + gy) % 2 == 1 && !around.is_empty() {
                    1 + around.iter().filter(|&&f| !f).count()
                } else {
                    0
                };
                put(GROUP_D + ctx, full as u32, true);
            }
        }
        for (b, &(x, y)) in p.order.iter().enumerate() {
            let (xi, yi) = (x as isize, y as isize);
            let own = size_class(residual[b]);
            // B: the four neighbours (even blocks, decoded in the first pass).
            let odd = (x + y) % 2 == 1;
            let four: Vec<usize> = [(-1, 0), (1, 0), (0, -1), (0, 1)]
                .iter()
                .filter_map(|&(dx, dy)| at(xi + dx, yi + dy))
                .collect();
            let (dc_b, nz_b) = if odd && !four.is_empty() {
                let sizes: usize = four.iter().map(|&j| size_class(residual[j])).sum();
                let mean =
                    (four.iter().map(|&j| nz[j]).sum::<usize>() + four.len() / 2) / four.len();
                (1 + (2 * sizes / four.len()).min(3), 3 + count_bucket(mean))
            } else {
                (0, own)
            };
            // C: the left and upper blocks, coded before this one.
            let lu: Vec<usize> = [(-1, 0), (0, -1)]
                .iter()
                .filter_map(|&(dx, dy)| at(xi + dx, yi + dy))
                .collect();
            let dc_c = lu
                .iter()
                .map(|&j| size_class(residual[j]))
                .sum::<usize>()
                .min(3);
            let nz_c = if lu.is_empty() {
                8 + own
            } else {
                count_bucket((lu.iter().map(|&j| nz[j]).sum::<usize>() + lu.len() / 2) / lu.len())
            };
            let r = pack_signed(residual[b]);
            put(DC_A, r, true);
            put(DC_B + dc_b, r, false);
            put(DC_C + dc_c, r, false);
            let n = nz[b] as u32;
            put(NZ_A + own, n, true);
            put(NZ_B + nz_b, n, false);
            put(NZ_C + nz_c, n, false);
            if group_full[(y / 4) * gw + x / 4] == Some(true) {
                put(DC_D + dc_b, r, false);
                put(NZ_D + nz_b, n, false);
                // G: a block with nothing but its DC in one symbol, not two (the serial
                // chain a GPU lane decodes is its symbols). A residual too large to
                // double goes as in D.
                match r.checked_mul(2) {
                    Some(j) => {
                        let j = j + (n > 0) as u32;
                        // (An odd block's neighbours' counts were the context of its own: the
                        // bit that joins the residual keeps a part of it.)
                        let busy = odd && four.iter().any(|&k| nz[k] > 0);
                        put(JOINT_G + dc_b + 5 * busy as usize, j, false);
                        raw_g +=
                            hybrid_uint(j).1 as i64 - (hybrid_uint(r).1 + hybrid_uint(n).1) as i64;
                        if n > 0 {
                            put(NZ_G + nz_b, n - 1, false);
                            raw_g += hybrid_uint(n - 1).1 as i64;
                        }
                    }
                    None => {
                        put(JOINT_G + dc_b, r, false);
                        put(NZ_G + nz_b, n, false);
                    }
                }
                if p.tile.is_some() {
                    put(DC_FB + dc_b, r, false);
                }
            }
            let mut left = nz[b];
            // E's context of position i (an odd block knows its four neighbours'
            // coefficients, all even), with `left` coefficients to come.
            let e_ctx = |i: usize, left: usize| {
                let ctx = left_bucket(left) * 12 + band(i);
                if odd && !four.is_empty() {
                    let hits = four.iter().filter(|&&j| p.blocks[j][i] != 0).count();
                    let class = (2 * hits).div_ceil(four.len()).min(2);
                    120 + class * 120 + ctx
                } else {
                    ctx
                }
            };
            let mut start = 1;
            for (i, &v) in p.blocks[b].iter().enumerate().skip(1) {
                if left == 0 {
                    break;
                }
                let ctx = left_bucket(left) * 12 + band(i);
                put(AC + ctx, pack_signed(v), true);
                put(AC_EVEN + e_ctx(i, left), pack_signed(v), false);
                raw_r -= hybrid_uint(pack_signed(v)).1 as i64;
                if v != 0 {
                    // R: the zeros since the last non-zero one, whether this one is beyond
                    // ±1 and its sign, in E's context of the run's first position (a token
                    // of its own for each run up to 30; longer runs four tokens and the
                    // run less 31 in 5 raw bits); beyond ±1, |v| − 2 by band.
                    let big = v.unsigned_abs() > 1;
                    let run = i - start;
                    let low = (big as usize) << 1 | (v < 0) as usize;
                    let (t, raw) = match run < 31 {
                        true => (run * 4 + low, 0),
                        false => (124 + low, 5),
                    };
                    put(RUN_R + e_ctx(start, left), t as u32, false);
                    raw_r += raw;
                    if big {
                        let m = v.unsigned_abs() - 2;
                        put(BIG_R + band(i), m, false);
                        raw_r += hybrid_uint(m).1 as i64;
                    }
                    start = i + 1;
                }
                left -= (v != 0) as usize;
            }
        }
        c.raw_g += raw_g;
        c.raw_r += raw_r;
    }

    /// The report's rows: for each design and number of histograms per family, the bytes
    /// of every coefficient chunk (symbols, raw bits, histograms, other bytes) and the
    /// lanes' states, by kind of chunk.
    pub fn report(&self, adaptive: [f64; 3]) {
        let stored: [u64; 3] = std::array::from_fn(|k| {
            self.chunks
                .iter()
                .filter(|c| c.kind == k)
                .map(|c| c.stored)
                .sum()
        });
        let total: u64 = stored.iter().sum();
        if total == 0 {
            return;
        }
        let lanes = |per: usize| -> u64 {
            self.chunks
                .iter()
                .flat_map(|c| &c.planes)
                .map(|&b| 4 * b.div_ceil(per) as u64)
                .sum()
        };
        let (lanes256, lanes64) = (lanes(256), lanes(64));
        println!();
        println!(
            "Static, GPU-decodable designs (src/bench/static_coding.rs): bytes of the keyframe and coefficient chunks ({total} B stored; the adaptive model's ideal {:.0} B, {:.3})",
            adaptive.iter().sum::<f64>(),
            adaptive.iter().sum::<f64>() / total as f64
        );
        println!("| design | histograms per family | intra keyframes | predicted keyframes | bubble terms | all | of which histograms | with lanes' states, a lane per 256 blocks | per 64 |");
        println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
        for (name, own) in &DESIGNS {
            let contexts: Vec<usize> = own.iter().cloned().flatten().collect();
            let ks = [32, 16, 8, 4, 1];
            // Per family, its clusters at each k.
            let sets: Vec<Option<Vec<Vec<Vec<usize>>>>> = (0..FAMILIES)
                .map(|family| {
                    let chunks: Vec<&ChunkCounts> = self
                        .chunks
                        .iter()
                        .filter(|c| c.kind == family / 2)
                        .collect();
                    (!chunks.is_empty()).then(|| cluster(&chunks, family, &contexts, &ks))
                })
                .collect();
            for (ki, k) in ks.iter().enumerate().rev() {
                let mut bytes = [0.0f64; 3];
                let mut tables = 0.0;
                for (family, set) in sets.iter().enumerate() {
                    let Some(set) = set else { continue };
                    let kind = family / 2;
                    for c in self.chunks.iter().filter(|c| c.kind == kind) {
                        let (bits, table) = chunk_bits(c, family, &set[ki]);
                        bytes[kind] += (bits + table) / 8.0;
                        tables += table / 8.0;
                    }
                }
                for (kind, b) in bytes.iter_mut().enumerate() {
                    for c in self.chunks.iter().filter(|c| c.kind == kind) {
                        // Raw bits and other bytes once per chunk (not per family).
                        let f = match name.as_bytes()[0] {
                            b'F' => c.raw_f,
                            b'G' => c.raw_g,
                            b'R' => c.raw_g + c.raw_r,
                            _ => 0,
                        };
                        *b += (c.raw_bits as i64 + f) as f64 / 8.0 + c.other as f64;
                    }
                }
                let all: f64 = bytes.iter().sum();
                let ratio = |b: f64, s: u64| {
                    if s == 0 {
                        "—".to_string()
                    } else {
                        format!("{:.3}", b / s as f64)
                    }
                };
                println!(
                    "| {name} | {k} | {} | {} | {} | {} ({all:.0} B) | {:.1}% | {} | {} |",
                    ratio(bytes[0], stored[0]),
                    ratio(bytes[1], stored[1]),
                    ratio(bytes[2], stored[2]),
                    ratio(all, total),
                    100.0 * tables / all,
                    ratio(all + lanes256 as f64, total),
                    ratio(all + lanes64 as f64, total),
                );
            }
        }
        println!(
            "(ratios against the stored bytes; a lane's state is 4 bytes: {lanes256} B in all at a lane per 256 blocks of a plane, {lanes64} B at one per 64)"
        );
        // Symbols: the serial chains a lane decodes (a token with its raw bits is one).
        let symbols: Vec<String> = DESIGNS
            .iter()
            .map(|(name, own)| {
                let mut n = 0u64;
                for family in 0..FAMILIES {
                    for c in self.chunks.iter().filter(|c| c.kind == family / 2) {
                        for ctx in own.iter().cloned().flatten() {
                            let at = (family * CONTEXTS + ctx) * TOKENS;
                            n += c.counts[at..at + TOKENS]
                                .iter()
                                .map(|&k| k as u64)
                                .sum::<u64>();
                        }
                    }
                }
                format!("{} {n}", &name[..1])
            })
            .collect();
        println!("Symbols coded, by design: {}", symbols.join(", "));
        self.report_fixed_map(total);
        // Where design D's bytes go, each context with a histogram of its own.
        let kinds = [
            ("empty-group flags", GROUP_D..GROUP_D + 6),
            ("DC residuals", DC_D..DC_D + 5),
            ("counts of coefficients", NZ_D..NZ_D + 11),
            ("coefficients", AC..AC + 120),
        ];
        let parts: Vec<String> = kinds
            .iter()
            .map(|(what, range)| {
                let (mut bits, mut symbols) = (0.0, 0u64);
                for family in 0..FAMILIES {
                    for c in self.chunks.iter().filter(|c| c.kind == family / 2) {
                        for ctx in range.clone() {
                            bits += chunk_bits(c, family, &[vec![ctx]]).0;
                            let at = (family * CONTEXTS + ctx) * TOKENS;
                            symbols += c.counts[at..at + TOKENS]
                                .iter()
                                .map(|&n| n as u64)
                                .sum::<u64>();
                        }
                    }
                }
                format!(
                    "{what} {:.0} B ({:.2} bits × {symbols})",
                    bits / 8.0,
                    bits / symbols.max(1) as f64
                )
            })
            .collect();
        let raw: u64 = self.chunks.iter().map(|c| c.raw_bits).sum();
        println!(
            "Design D's symbols, each context its own histogram: {}; raw bits {} B",
            parts.join(", "),
            raw / 8
        );
    }
}

/// The integer 5/3 wavelet pyramid of a `w` × `h` plane: rows then columns at each level
/// (an odd last value goes down as a low value), until one value is left. Calls `emit(context, token value)` for the
/// coarsest value (context 0) and for every difference, coarsest level first: context
/// 1 + (level · 2 + direction) · 4 + the activity class of the two coarse values around it.
fn pyramid(mut v: Vec<i32>, mut w: usize, mut h: usize, mut emit: impl FnMut(usize, u32)) {
    let mut details: Vec<(usize, usize, u32)> = Vec::new();
    let mut level = 0;
    while w > 1 || h > 1 {
        for dir in 0..2 {
            let (n, m) = if dir == 0 { (w, h) } else { (h, w) };
            if n < 2 {
                continue;
            }
            let half = n.div_ceil(2);
            let mut next = vec![0i32; half * m];
            let idx =
                |i: usize, j: usize, len: usize| if dir == 0 { j * len + i } else { i * len + j };
            for j in 0..m {
                // LeGall 5/3 lifting, as JPEG 2000's reversible path: each odd value less
                // the mean of its even neighbours, then each even value plus a quarter of
                // the two differences beside it. A linear ramp leaves no difference.
                let x = |i: usize| v[idx(i.min(n - 1), j, w)];
                let even = |i: usize| {
                    x(if i < n {
                        i
                    } else {
                        n - 1 - (n % 2 == 0) as usize
                    })
                };
                let diffs: Vec<i32> = (0..n / 2)
                    .map(|k| {
                        x(2 * k + 1)
                            .wrapping_sub(even(2 * k).wrapping_add(even(2 * k + 2)).div_euclid(2))
                    })
                    .collect();
                let d = |k: isize| -> i32 {
                    if diffs.is_empty() {
                        0
                    } else {
                        diffs[k.clamp(0, diffs.len() as isize - 1) as usize]
                    }
                };
                let lows: Vec<i32> = (0..half)
                    .map(|k| {
                        let k = k as isize;
                        x(2 * k as usize).wrapping_add((d(k - 1) + d(k) + 2).div_euclid(4))
                    })
                    .collect();
                for (k, &diff) in diffs.iter().enumerate() {
                    let around = |i: usize| lows[i.min(half - 1)];
                    let act = (around(k + 1) - around(k.saturating_sub(1))).unsigned_abs();
                    let class = match act {
                        0 => 0,
                        1..=2 => 1,
                        3..=8 => 2,
                        _ => 3,
                    };
                    let ctx = 1 + ((level.min(5) * 2 + dir) * 4 + class);
                    details.push((level, ctx, pack_signed(diff)));
                }
                for (k, &l) in lows.iter().enumerate() {
                    next[if dir == 0 { j * half + k } else { k * w + j }] = l;
                }
            }
            v = next;
            if dir == 0 {
                w = half;
            } else {
                h = half;
            }
        }
        level += 1;
    }
    emit(0, pack_signed(v[0]));
    details.sort_by_key(|d| std::cmp::Reverse(d.0));
    for (_, ctx, value) in details {
        emit(ctx, value);
    }
}

impl Study {
    /// Design E's contexts clustered into at most `k` histograms per family, as
    /// `vbim_format::plane2` numbers them (families without chunks: one histogram).
    pub fn maps(&self, k: usize) -> Vec<plane2::ContextMap> {
        let (_, own) = DESIGNS[3];
        let contexts: Vec<usize> = own.iter().cloned().flatten().collect();
        debug_assert_eq!(contexts.len(), plane2::contexts(plane2::Layout::OneState));
        (0..FAMILIES)
            .map(|family| {
                let chunks: Vec<&ChunkCounts> = self
                    .chunks
                    .iter()
                    .filter(|c| c.kind == family / 2)
                    .collect();
                if chunks.is_empty() {
                    return plane2::ContextMap::single();
                }
                let clusters = cluster(&chunks, family, &contexts, &[k]).remove(0);
                let mut of = vec![0u8; plane2::CONTEXTS];
                for (ci, members) in clusters.iter().enumerate() {
                    for &ctx in members {
                        // The study's context → its place in E's list = plane2's number.
                        let at = contexts.iter().position(|&c| c == ctx).expect("E's own");
                        of[at] = ci as u8;
                    }
                }
                plane2::ContextMap {
                    clusters: clusters.len() as u8,
                    of,
                    tables: vec![None; clusters.len()],
                }
            })
            .collect()
    }
}

/// Design E's contexts in 16 histograms by a fixed rule, which a format could state once
/// instead of sending a map: the empty-group flags, the DC residuals, the counts of even
/// and of odd blocks, and the coefficients by 3 classes of how many are left × 4 of band
/// (the odd blocks' neighbour classes folded in).
fn fixed_map() -> Vec<Vec<usize>> {
    let mut map = vec![
        (GROUP_D..GROUP_D + 6).collect(),
        (DC_D..DC_D + 5).collect(),
        (NZ_D..NZ_D + 3).collect(),
        (NZ_D + 3..NZ_D + 11).collect(),
    ];
    let mut ac = vec![Vec::new(); 12];
    for left in 0..10 {
        for b in 0..12 {
            let l = match left {
                0..=1 => 0,
                2..=4 => 1,
                _ => 2,
            };
            let band = match b {
                0..=2 => 0,
                3..=5 => 1,
                6..=8 => 2,
                _ => 3,
            };
            let ctx = left * 12 + b;
            ac[l * 4 + band].push(AC_EVEN + ctx);
            for class in 0..3 {
                ac[l * 4 + band].push(AC_ODD + class * 120 + ctx);
            }
        }
    }
    map.extend(ac);
    map
}

impl Study {
    fn report_fixed_map(&self, total: u64) {
        let map = fixed_map();
        let mut bytes = 0.0;
        for family in 0..FAMILIES {
            for c in self.chunks.iter().filter(|c| c.kind == family / 2) {
                let (bits, table) = chunk_bits(c, family, &map);
                bytes += (bits + table) / 8.0;
            }
        }
        for c in &self.chunks {
            bytes += c.raw_bits as f64 / 8.0 + c.other as f64;
        }
        println!(
            "E with its contexts in 16 histograms by a fixed rule (no map sent): {bytes:.0} B, {:.3}",
            bytes / total as f64
        );
    }
}

/// The file's totals of `family` per context.
fn totals(chunks: &[&ChunkCounts], family: usize, ctx: usize) -> Vec<u64> {
    let mut h = vec![0u64; TOKENS];
    for c in chunks {
        let at = (family * CONTEXTS + ctx) * TOKENS;
        for (t, n) in h.iter_mut().zip(&c.counts[at..at + TOKENS]) {
            *t += *n as u64;
        }
    }
    h
}

/// `contexts` of `family` merged greedily on the file's totals, as the encoder merges
/// them (`vbim_encoder::bench::cluster`). Returns the clusters (each its contexts) when
/// `ks` of them are left, in the order of `ks` (largest first).
fn cluster(
    chunks: &[&ChunkCounts],
    family: usize,
    contexts: &[usize],
    ks: &[usize],
) -> Vec<Vec<Vec<usize>>> {
    let totals: Vec<Vec<u64>> = contexts
        .iter()
        .map(|&c| totals(chunks, family, c))
        .collect();
    let refs: Vec<&[u64]> = totals.iter().map(|t| &t[..]).collect();
    vbim_encoder::bench::cluster(&refs, ks)
        .into_iter()
        .map(|set| {
            set.into_iter()
                .map(|members| members.into_iter().map(|i| contexts[i]).collect())
                .collect()
        })
        .collect()
}

/// A chunk's bits for `family` with `clusters`: its symbols at each cluster's quantised
/// (12-bit) probabilities, and the estimated cost of sending those histograms.
fn chunk_bits(c: &ChunkCounts, family: usize, clusters: &[Vec<usize>]) -> (f64, f64) {
    let (mut bits, mut table) = (0.0, 0.0);
    for members in clusters {
        let mut h = vec![0u64; TOKENS];
        for &ctx in members {
            let at = (family * CONTEXTS + ctx) * TOKENS;
            for (t, n) in h.iter_mut().zip(&c.counts[at..at + TOKENS]) {
                *t += *n as u64;
            }
        }
        let n: u64 = h.iter().sum();
        if n == 0 {
            continue;
        }
        let q = quantise(&h);
        bits += h
            .iter()
            .zip(&q)
            .filter(|(&c, _)| c > 0)
            .map(|(&c, &p)| c as f64 * (4096.0 / p as f64).log2())
            .sum::<f64>();
        table += 8.0 + 8.0 * h.iter().filter(|&&c| c > 0).count() as f64;
    }
    (bits, table)
}

/// Counts as 12-bit probabilities summing to 4096, every used symbol at least 1.
fn quantise(h: &[u64]) -> Vec<u32> {
    let n: u64 = h.iter().sum();
    let mut q: Vec<u32> = h
        .iter()
        .map(|&c| {
            if c == 0 {
                0
            } else {
                ((c as f64 * 4096.0 / n as f64).round() as u32).max(1)
            }
        })
        .collect();
    let sum: i64 = q.iter().map(|&x| x as i64).sum();
    // The largest absorbs the rounding (it stays far above 1 for any histogram of a few
    // symbols' worth of difference).
    let big = (0..q.len()).max_by_key(|&i| q[i]).unwrap_or(0);
    q[big] = (q[big] as i64 + 4096 - sum).max(1) as u32;
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn g_codes_a_block_with_nothing_but_its_dc_in_one_symbol() {
        // 8 × 8 blocks of a keyframe: DCs that never repeat a prediction exactly, a few
        // blocks with coefficients (every group has something).
        let (bw, bh) = (8, 8);
        let order: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
        let blocks: Vec<[i32; N * N]> = (0..bw * bh)
            .map(|b| {
                let mut q = [0; N * N];
                q[0] = (b * b % 11) as i32 * 3 + 1;
                if b % 7 == 0 {
                    (q[3], q[10]) = (2, -1);
                }
                q
            })
            .collect();
        let mut study = Study::default();
        study.start_chunk(0, 1000, 0);
        study.plane(&PlaneStream {
            kind: 0,
            chroma: false,
            blocks: &blocks,
            order: &order,
            grid: (bw, bh),
            tile: None,
        });
        let c = &study.chunks[0];
        let symbols = |ranges: &[std::ops::Range<usize>]| -> u64 {
            let ctxs = ranges.iter().cloned().flatten();
            ctxs.map(|ctx| c.counts[ctx * TOKENS..(ctx + 1) * TOKENS].iter())
                .map(|n| n.map(|&n| n as u64).sum::<u64>())
                .sum()
        };
        let with_coefficients = blocks.iter().filter(|q| q[1..].iter().any(|&v| v != 0));
        assert_eq!(symbols(&[DC_D..DC_D + 5, NZ_D..NZ_D + 11]), 2 * 64);
        assert_eq!(
            symbols(&[JOINT_G..JOINT_G + 10, NZ_G..NZ_G + 11]),
            64 + with_coefficients.count() as u64
        );
    }

    #[test]
    fn r_codes_each_non_zero_coefficient_with_the_zeros_before_it() {
        // One 8 × 8 keyframe plane of one block: terms at zig-zag 1 (1), 5 (−3) and 40 (2),
        // so runs of 0, 3 and 34 zeros.
        let mut q = [0; N * N];
        (q[0], q[1], q[5], q[40]) = (7, 1, -3, 2);
        let mut study = Study::default();
        study.start_chunk(0, 1000, 0);
        study.plane(&PlaneStream {
            kind: 0,
            chroma: false,
            blocks: &[q],
            order: &[(0, 0)],
            grid: (1, 1),
            tile: None,
        });
        let c = &study.chunks[0];
        let tokens = |ctxs: std::ops::Range<usize>| -> Vec<(usize, u32)> {
            let mut t: Vec<(usize, u32)> = ctxs
                .flat_map(|ctx| (0..TOKENS).map(move |t| (ctx, t)))
                .filter(|&(ctx, t)| c.counts[ctx * TOKENS + t] > 0)
                .map(|(ctx, t)| (t, c.counts[ctx * TOKENS + t]))
                .collect();
            t.sort();
            t
        };
        // Run 0 of +1; run 3 beyond ±1, negative; run 34, beyond ±1, positive: a long run.
        assert_eq!(tokens(RUN_R..BIG_R), [(0, 1), (3 * 4 + 3, 1), (124 + 2, 1)]);
        // |v| − 2 of the two beyond ±1: 1 and 0.
        assert_eq!(tokens(BIG_R..BIG_R + 12), [(0, 1), (1, 1)]);
        // E coded every position up to the last term: 40 symbols; R three and two.
        assert_eq!(
            tokens(AC_EVEN..AC_ODD + 360)
                .iter()
                .map(|t| t.1)
                .sum::<u32>(),
            40
        );
        // Its raw bits against the coefficients' (none for values this small): the long
        // run's 5.
        assert_eq!(c.raw_r, 5);
    }

    #[test]
    fn signed_values_fold_onto_the_naturals() {
        assert_eq!(
            (-3..=3).map(pack_signed).collect::<Vec<_>>(),
            [5, 3, 1, 0, 2, 4, 6]
        );
    }

    #[test]
    fn the_pyramid_codes_each_value_once_and_a_ramp_in_few_differences() {
        let (w, h) = (37, 21);
        let ramp: Vec<i32> = (0..w * h)
            .map(|i| 3 * (i % w) as i32 - 5 * (i / w) as i32)
            .collect();
        let (mut count, mut nonzero) = (0, 0);
        pyramid(ramp, w, h, |_, v| {
            count += 1;
            nonzero += (v != 0) as usize;
        });
        assert_eq!(count, w * h);
        // Only the differences at the plane's right and lower edges (where the symmetric
        // extension breaks the ramp) and the coarse levels' rounding are left.
        assert!(nonzero < (w + h) * 2, "{nonzero} of {count}");
    }

    #[test]
    fn quantised_probabilities_sum_to_4096_and_keep_rare_symbols() {
        let q = quantise(&[1_000_000, 1, 0, 3]);
        assert_eq!(q.iter().sum::<u32>(), 4096);
        assert_eq!((q[1], q[2]), (1, 0));
    }

    #[test]
    fn clustering_merges_alike_contexts_first() {
        // Contexts 0 and 1 hold the same distribution, 2 another: two clusters keep 2 apart.
        let mut c = ChunkCounts {
            kind: 0,
            counts: vec![0; FAMILIES * CONTEXTS * TOKENS],
            raw_bits: 0,
            raw_f: 0,
            raw_g: 0,
            raw_r: 0,
            planes: vec![],
            other: 0,
            stored: 0,
        };
        for (ctx, h) in [(0, [90, 10]), (1, [45, 5]), (2, [5, 95])] {
            c.counts[ctx * TOKENS] = h[0];
            c.counts[ctx * TOKENS + 1] = h[1];
        }
        let mut got = cluster(&[&c], 0, &[0, 1, 2], &[2]).remove(0);
        got.iter_mut().for_each(|g| g.sort());
        got.sort();
        assert_eq!(got, vec![vec![0, 1], vec![2]]);
        // One cluster of all three costs more than the two.
        let (two, _) = chunk_bits(&c, 0, &got);
        let (one, _) = chunk_bits(&c, 0, &[vec![0, 1, 2]]);
        assert!(one > two * 1.2, "{one} against {two}");
    }
}
