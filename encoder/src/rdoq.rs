//! Rate-aware quantisation: after the dead-zone quantiser, a block's coefficients of ±1
//! are set to 0 where the bits they cost are worth more than the error they save.
//!
//! The bits are counted as format 2's coder would spend them on a block with no
//! neighbours (`vbim_format::plane2`: the count of non-zero AC coefficients, then each
//! coefficient up to the last non-zero one in a context of how many are still to come and
//! its zig-zag band), each token at the cost its share of the plane's own tokens gives it.
//! A coefficient dropped shortens what follows it and changes the count, so a block is
//! costed whole for every change tried. The error is counted in squared steps (the DCT is
//! orthonormal, so a coefficient's squared error is the block's), and a bit is worth
//! `lambda` squared steps.

use vbim_format::ans::{hybrid_uint, TOKENS};
use vbim_format::dct::N;
use vbim_format::plane2::{band, left_bucket, pack};

const LEFTS: usize = 10;
const BANDS: usize = 12;
/// Changes tried on a block at most: a block gives up a few coefficients, and a dense one
/// would otherwise cost its count squared.
const MOST_DROPS: usize = 8;

/// Bits a token costs, per context, learned from a plane's blocks.
pub(crate) struct Costs {
    count: Vec<f32>,
    ac: Vec<f32>,
}

impl Costs {
    /// The costs of the tokens of `blocks` as the plane's own statistics give them (an
    /// adaptive coder's view; a token never seen costs as if seen half a time).
    pub fn learn(blocks: impl IntoIterator<Item = [i32; N * N]>) -> Costs {
        let mut count = vec![0u32; TOKENS];
        let mut ac = vec![0u32; LEFTS * BANDS * TOKENS];
        for q in blocks {
            symbols(&q, |ctx, v| match ctx {
                None => count[hybrid_uint(v).0] += 1,
                Some(c) => ac[c * TOKENS + hybrid_uint(v).0] += 1,
            });
        }
        Costs {
            count: bits(&count),
            ac: bits(&ac),
        }
    }

    /// A block's bits (its AC coefficients and their count; the DC is left alone).
    fn block(&self, q: &[i32; N * N]) -> f32 {
        let mut sum = 0.0;
        symbols(q, |ctx, v| {
            let (t, raw, _) = hybrid_uint(v);
            sum += raw as f32
                + match ctx {
                    None => self.count[t],
                    Some(c) => self.ac[c * TOKENS + t],
                };
        });
        sum
    }
}

/// Each context's tokens' costs in bits from their counts.
fn bits(counts: &[u32]) -> Vec<f32> {
    counts
        .chunks(TOKENS)
        .flat_map(|row| {
            let total = row.iter().sum::<u32>() as f64 + 0.5 * TOKENS as f64;
            row.iter()
                .map(move |&c| (-((c as f64 + 0.5) / total).log2()) as f32)
        })
        .collect()
}

/// A block's symbols as format 2 codes an even block: the count of its non-zero AC
/// coefficients (context `None`), then each coefficient from zig-zag position 1 until
/// that many non-zero ones have come (context `Some(left × BANDS + band)`), zig-zag packed.
fn symbols(q: &[i32; N * N], mut f: impl FnMut(Option<usize>, u32)) {
    let n = q[1..].iter().filter(|&&v| v != 0).count();
    f(None, n as u32);
    let mut left = n;
    for (i, &v) in q.iter().enumerate().skip(1) {
        if left == 0 {
            break;
        }
        f(Some(left_bucket(left) * BANDS + band(i)), pack(v));
        left -= (v != 0) as usize;
    }
}

/// The ±1 AC coefficients of `q` (`c` quantised with `step`) as (zig-zag position,
/// |c| in steps): what [`refine`] may drop.
pub(crate) fn ones(q: &[i32; N * N], c: &[f32; N * N], step: f32) -> Vec<(u8, f32)> {
    (1..N * N)
        .filter(|&i| q[i].abs() == 1)
        .map(|i| (i as u8, c[i].abs() / step))
        .collect()
}

/// Drops those of the ±1 AC coefficients `ones` of `q` ([`ones`]) whose bits cost more
/// than `lambda` squared steps each buy back, one at a time, the best first.
pub(crate) fn refine(q: &mut [i32; N * N], ones: &[(u8, f32)], costs: &Costs, lambda: f32) {
    let mut bits = costs.block(q);
    for _ in 0..MOST_DROPS {
        let mut best: Option<(f32, usize, f32)> = None;
        for &(i, a) in ones {
            let i = i as usize;
            if q[i] == 0 {
                continue;
            }
            // Its error from |c| − 1 to |c|. (Lowering larger values by one was tried:
            // no gain, BENCHMARKS.md.)
            let more_error = a * a - (a - 1.0) * (a - 1.0);
            let v = std::mem::replace(&mut q[i], 0);
            let b = costs.block(q);
            q[i] = v;
            let gain = more_error - lambda * (bits - b);
            if gain < best.map_or(0.0, |b| b.0) {
                best = Some((gain, i, b));
            }
        }
        let Some((_, i, b)) = best else { break };
        q[i] = 0;
        bits = b;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(values: &[(usize, i32)]) -> [i32; N * N] {
        let mut q = [0; N * N];
        for &(i, v) in values {
            q[i] = v;
        }
        q
    }

    #[test]
    fn a_lone_one_far_out_goes_and_a_costly_one_stays_at_no_lambda() {
        // A plane of blocks with a few low coefficients; one block also has a lone ±1
        // at position 40, which costs the zeros before it.
        let mut blocks = vec![block(&[(1, 3), (2, -1)]); 50];
        blocks.push(block(&[(1, 3), (2, -1), (40, 1)]));
        let costs = Costs::learn(blocks.iter().copied());
        let lone = block(&[(1, 3), (2, -1), (40, 1)]);
        let mut c = [0f32; N * N];
        (c[1], c[2], c[40]) = (3.1, -0.9, 0.8);
        let mut q = lone;
        refine(&mut q, &ones(&lone, &c, 1.0), &costs, 0.15);
        assert_eq!(q, block(&[(1, 3), (2, -1)]), "the lone one is dropped");
        // Without a price on bits nothing is worth an error.
        let mut q = lone;
        refine(&mut q, &ones(&lone, &c, 1.0), &costs, 0.0);
        assert_eq!(q, lone);
    }

    #[test]
    fn a_common_block_costs_fewer_bits_than_a_rare_one() {
        let common = block(&[(1, 2), (5, 1), (9, -1)]);
        let rare = block(&[(1, 2), (5, 1), (9, -1), (20, 1)]);
        let mut blocks = vec![common; 30];
        blocks.push(rare);
        let costs = Costs::learn(blocks.iter().copied());
        let (c, r) = (costs.block(&common), costs.block(&rare));
        assert!(c < r, "{c} {r}");
        // The same blocks seen as often cost the same whatever their order.
        let again = Costs::learn(blocks.iter().rev().copied());
        assert_eq!(again.block(&rare), r);
    }
}
