//! The last step before writing: the keyframe and coefficient payloads, held until now as
//! version 1's payloads before zstd, coded for the file's version. Version 1 compresses each
//! with zstd. Version 2 first learns the file's context maps from every payload's symbols
//! (each family's contexts merged into [`HISTOGRAMS`] clusters, the merges that cost the
//! fewest bits first), then codes each payload's planes in rANS lanes
//! (`vbim_format::payload2`).

use rayon::prelude::*;
use vbim_format::ans::{Histogram, TOKENS};
use vbim_format::chunk::{Payload, TileMap};
use vbim_format::plane2::{ContextMap, CONTEXTS, FAMILIES};
use vbim_format::{payload2, ChunkKind, Coding, Header};

use crate::output::PendingChunk;
use crate::{EncodeError, Progress};

/// Histograms per family: BENCHMARKS.md ("A static coder a GPU can decode") measured 16
/// within 1% of 32 and 64, and each costs a chunk that uses it its table.
pub const HISTOGRAMS: usize = 16;
/// The coded size at which a lane is cut by default (`EncoderConfig::lane_bytes`): a GPU
/// decodes a lane's symbols in sequence, and lanes of 512 bytes rather than 4 KiB cut the
/// longest lanes of a 2048² day's planes to a quarter for 0.7% more bytes (0.3% at 512²,
/// where a region of 16 × 16 blocks often holds more than that and lanes cannot be cut
/// finer).
pub const LANE_BYTES: usize = 512;
/// Version 3's default: a lane's states, not its length, shorten its chains, and each
/// lane costs its lengths; lanes also end at 16,384 symbols, which binds first on most
/// planes.
pub const LANE_BYTES_3: usize = 16_384;
/// Version 3: a lane of n symbols has ⌈n / this⌉ rANS states by default
/// (`Lanes::symbols_per_state`).
pub const SYMBOLS_PER_STATE: u64 = 1024;

/// How versions 2 and 3 cut their lanes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lanes {
    /// The coded size at which a lane is cut (0: a lane per region of 16 × 16 blocks);
    /// `None`: the version's default, [`LANE_BYTES`] or [`LANE_BYTES_3`].
    pub bytes: Option<usize>,
    /// Version 3: a lane of n symbols has ⌈n / this⌉ states (1 to 64), decoded side by
    /// side; fewer symbols a state shorten a GPU's serial chains for 4–6 bytes a state
    /// (BENCHMARKS.md, "Format 3: lanes of several states").
    pub symbols_per_state: u64,
}

impl Default for Lanes {
    fn default() -> Lanes {
        Lanes {
            bytes: None,
            symbols_per_state: SYMBOLS_PER_STATE,
        }
    }
}

/// Which version of the format to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FormatVersion {
    /// Version 1 (1.1): zero-run pairs through zstd. Every player reads it.
    V1,
    /// Version 2 (2.0): rANS lanes with the file's context maps, 0.69–0.90× version 1's
    /// bytes (BENCHMARKS.md, "Format 2"). Players before version 2 refuse it. The player's
    /// decoder thread decodes its sections to pairs, 9–12× the time of version 1's zstd
    /// (the GPU can decode them as coded, `DecodeShape::lanes`, off by default).
    V2,
    /// Version 3 (3.0): version 2's coding with several rANS states a lane, each taking
    /// the lane's groups by place, so that a GPU decodes a lane's symbols several at a
    /// time. Players before version 3 refuse it; this player decodes its sections to
    /// pairs on the decoder thread.
    V3,
}

impl FormatVersion {
    /// The lane shape of this version with `lanes` (`None`: version 1 has no lanes).
    pub fn lane_shape(self, lanes: Lanes) -> Option<vbim_format::plane2::LaneShape> {
        match self {
            FormatVersion::V1 => None,
            FormatVersion::V2 => Some(vbim_format::plane2::LaneShape {
                bytes: lanes.bytes.unwrap_or(LANE_BYTES),
                symbols_per_state: None,
            }),
            FormatVersion::V3 => Some(vbim_format::plane2::LaneShape {
                bytes: lanes.bytes.unwrap_or(LANE_BYTES_3),
                symbols_per_state: Some(lanes.symbols_per_state),
            }),
        }
    }
}

/// Codes every pending payload (`raw`) for `version`, and sets the header's coding.
/// `tiles[s]` is segment s's tile map.
pub(crate) fn code(
    header: &mut Header,
    chunks: &mut [PendingChunk],
    tiles: &[TileMap],
    version: FormatVersion,
    (zstd_level, lanes): (i32, Lanes),
    progress: Progress,
) -> Result<(), EncodeError> {
    let what = |c: &PendingChunk| -> Result<Payload, EncodeError> {
        match c.kind {
            ChunkKind::Keyframe => Ok(Payload::Keyframe),
            _ => tiles
                .get(c.number as usize)
                .map(Payload::Coefficients)
                .ok_or_else(|| EncodeError::Input(format!("segment {} has no tile map", c.number))),
        }
    };
    let n = chunks.iter().filter(|c| c.raw).count() as u64;
    let done = std::sync::atomic::AtomicU64::new(0);
    let tick = |stage: &str| {
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress(stage, d, n);
    };
    match version.lane_shape(lanes) {
        None => {
            header.coding = Coding::Pairs;
            chunks.par_iter_mut().filter(|c| c.raw).for_each(|c| {
                c.bytes = zstd::bulk::compress(&c.bytes, zstd_level).expect("zstd");
                c.raw = false;
                tick("compress");
            });
        }
        Some(shape) => {
            let counts = chunks
                .par_iter()
                .filter(|c| c.raw)
                .map(|c| {
                    let counts =
                        payload2::context_counts(header, what(c)?, &c.bytes, shape.layout())?;
                    tick("model contexts");
                    Ok::<_, EncodeError>(counts)
                })
                .try_reduce(
                    || vec![vec![0u64; CONTEXTS * TOKENS]; FAMILIES],
                    |mut a, b| {
                        for (x, y) in a.iter_mut().flatten().zip(b.iter().flatten()) {
                            *x += y;
                        }
                        Ok(a)
                    },
                )?;
            let maps: Vec<ContextMap> = counts.par_iter().map(|f| map_of(f)).collect();
            header.coding = Coding::Lanes(maps.clone(), shape.layout());
            done.store(0, std::sync::atomic::Ordering::Relaxed);
            let h = &*header;
            chunks.par_iter_mut().filter(|c| c.raw).try_for_each(|c| {
                c.bytes = payload2::encode(h, what(c)?, &c.bytes, &maps, shape)?;
                c.raw = false;
                tick("entropy code");
                Ok::<_, EncodeError>(())
            })?;
        }
    }
    Ok(())
}

/// A family's context map from its token counts (`counts[ctx · TOKENS + token]`).
fn map_of(counts: &[u64]) -> ContextMap {
    let totals: Vec<&[u64]> = counts.chunks_exact(TOKENS).collect();
    let clusters = cluster(&totals, &[HISTOGRAMS]).remove(0);
    let mut of = vec![0u8; CONTEXTS];
    for (k, members) in clusters.iter().enumerate() {
        for &ctx in members {
            of[ctx] = k as u8;
        }
    }
    // Each cluster's histogram over the whole file: a chunk whose own table would cost
    // more than it saves uses it.
    let tables = clusters
        .iter()
        .map(|members| {
            let mut sum = vec![0u64; TOKENS];
            for &ctx in members {
                for (s, n) in sum.iter_mut().zip(totals[ctx]) {
                    *s += n;
                }
            }
            Histogram::from_counts(&sum)
        })
        .collect();
    ContextMap {
        clusters: clusters.len() as u8,
        of,
        tables,
    }
}

/// Bits of a histogram at its own ideal probabilities.
fn entropy_bits(h: &[u64]) -> f64 {
    let n: u64 = h.iter().sum();
    if n == 0 {
        return 0.0;
    }
    h.iter()
        .filter(|&&c| c > 0)
        .map(|&c| c as f64 * (n as f64 / c as f64).log2())
        .sum()
}

/// Contexts (each its token totals) merged greedily into clusters: each step merges the
/// two clusters whose merge adds the fewest bits. Contexts that never occur join the
/// first cluster (they cost nothing anywhere). Returns the clusters, each its contexts,
/// when `ks` of them are left, in the order of `ks` (largest first); at least one.
pub fn cluster(totals: &[&[u64]], ks: &[usize]) -> Vec<Vec<Vec<usize>>> {
    let merged =
        |a: &[u64], b: &[u64]| -> Vec<u64> { a.iter().zip(b).map(|(x, y)| x + y).collect() };
    let used: Vec<usize> = (0..totals.len())
        .filter(|&c| totals[c].iter().any(|&x| x > 0))
        .collect();
    let unused: Vec<usize> = (0..totals.len()).filter(|c| !used.contains(c)).collect();
    // Each cluster: contexts, totals, their bits.
    let mut groups: Vec<(Vec<usize>, Vec<u64>, f64)> = used
        .iter()
        .map(|&c| (vec![c], totals[c].to_vec(), entropy_bits(totals[c])))
        .collect();
    let n = groups.len();
    let cost = |g: &[(Vec<usize>, Vec<u64>, f64)], i: usize, j: usize| {
        entropy_bits(&merged(&g[i].1, &g[j].1)) - g[i].2 - g[j].2
    };
    // costs[i][j] (i < j) of the alive pairs, and each row's cheapest partner: a merge
    // updates the two rows it touches and the rows whose partner it took, not all.
    let mut costs: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    if j > i {
                        cost(&groups, i, j)
                    } else {
                        f64::INFINITY
                    }
                })
                .collect()
        })
        .collect();
    let mut alive = vec![true; n];
    let best_of = |costs: &[Vec<f64>], alive: &[bool], i: usize| {
        (i + 1..n)
            .filter(|&j| alive[j])
            .map(|j| (costs[i][j], j))
            .fold(
                (f64::INFINITY, usize::MAX),
                |a, b| if b.0 < a.0 { b } else { a },
            )
    };
    let mut best: Vec<(f64, usize)> = (0..n).map(|i| best_of(&costs, &alive, i)).collect();
    let mut left = n;
    let mut out = Vec::new();
    for &k in ks {
        while left > k.max(1) {
            let i = (0..n)
                .filter(|&i| alive[i] && best[i].1 != usize::MAX)
                .min_by(|&a, &b| best[a].0.total_cmp(&best[b].0))
                .expect("two clusters are left");
            let j = best[i].1;
            let cj = std::mem::take(&mut groups[j].0);
            groups[i].0.extend(cj);
            groups[i].1 = merged(&groups[i].1, &groups[j].1);
            groups[i].2 = entropy_bits(&groups[i].1);
            alive[j] = false;
            left -= 1;
            for o in (0..n).filter(|&o| alive[o] && o != i) {
                let c = cost(&groups, i, o);
                costs[i.min(o)][i.max(o)] = c;
            }
            for o in (0..n).filter(|&o| alive[o]) {
                if o == i || best[o].1 == i || best[o].1 == j {
                    best[o] = best_of(&costs, &alive, o);
                } else if o < i && costs[o][i] < best[o].0 {
                    best[o] = (costs[o][i], i);
                }
            }
        }
        let mut clusters: Vec<Vec<usize>> = (0..n)
            .filter(|&i| alive[i])
            .map(|i| groups[i].0.clone())
            .collect();
        match clusters.first_mut() {
            Some(first) => first.extend(&unused),
            None => clusters.push(unused.clone()),
        }
        out.push(clusters);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clustering_merges_alike_contexts_first_and_keeps_every_context() {
        // Two pairs of alike contexts and one that never occurs.
        let t: Vec<Vec<u64>> = vec![
            vec![100, 1, 0],
            vec![0, 0, 0],
            vec![1, 100, 0],
            vec![98, 2, 0],
            vec![2, 99, 1],
        ];
        let totals: Vec<&[u64]> = t.iter().map(|v| &v[..]).collect();
        let out = cluster(&totals, &[4, 2, 1]);
        let sorted = |mut c: Vec<Vec<usize>>| {
            c.iter_mut().for_each(|m| m.sort());
            c.sort();
            c
        };
        assert_eq!(out[0].len(), 4);
        assert_eq!(sorted(out[1].clone()), vec![vec![0, 1, 3], vec![2, 4]]);
        assert_eq!(sorted(out[2].clone()), vec![vec![0, 1, 2, 3, 4]]);
        // All unused: one cluster of everything.
        let z = [0u64; 3];
        assert_eq!(cluster(&[&z, &z], &[16]), vec![vec![vec![0, 1]]]);
    }

    #[test]
    fn the_cheapest_partner_bookkeeping_finds_the_exhaustive_search_merges() {
        // Pseudo-random histograms: the greedy order with the per-row bookkeeping gives the
        // same clusters as searching every pair at every step.
        let mut s = 7u64;
        let mut next = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            (s >> 40) % 50
        };
        let t: Vec<Vec<u64>> = (0..40).map(|_| (0..6).map(|_| next()).collect()).collect();
        let totals: Vec<&[u64]> = t.iter().map(|v| &v[..]).collect();
        let fast = cluster(&totals, &[10]).remove(0);
        // Exhaustive.
        let mut g: Vec<(Vec<usize>, Vec<u64>)> = t
            .iter()
            .enumerate()
            .map(|(i, v)| (vec![i], v.clone()))
            .collect();
        while g.len() > 10 {
            let mut best = (f64::INFINITY, 0, 0);
            for i in 0..g.len() {
                for j in i + 1..g.len() {
                    let m: Vec<u64> = g[i].1.iter().zip(&g[j].1).map(|(a, b)| a + b).collect();
                    let c = entropy_bits(&m) - entropy_bits(&g[i].1) - entropy_bits(&g[j].1);
                    if c < best.0 {
                        best = (c, i, j);
                    }
                }
            }
            let (_, i, j) = best;
            let gj = g.remove(j);
            g[i].0.extend(gj.0);
            g[i].1 = g[i].1.iter().zip(&gj.1).map(|(a, b)| a + b).collect();
        }
        let norm = |mut c: Vec<Vec<usize>>| {
            c.iter_mut().for_each(|m| m.sort());
            c.sort();
            c
        };
        assert_eq!(norm(fast), norm(g.into_iter().map(|x| x.0).collect()));
    }
}
