//! Quantised blocks held sparse until their stream is written. A coefficient stream is
//! written frequency-major across all its blocks (`vbim_format::plane::write_coefficients`),
//! so a segment coded in bands must hold every band's blocks before writing any; as 64
//! integers a block that is 4 bytes a texel and plane, most of them zeros. Held as a DC
//! and the non-zero AC terms, a stream takes about what its entropy-coded form does.

use vbim_format::dct::N;

/// One coefficient stream's quantised blocks (zig-zag order), in stream order.
#[derive(Default, Clone)]
pub struct SparseBlocks {
    dc: Vec<i32>,
    /// Non-zero AC terms as (block, zig-zag index, value), in block order.
    ac: Vec<(u32, u8, i32)>,
    /// The ±1 AC terms the rate-aware quantiser may drop, with their coefficients'
    /// magnitudes in steps, as (block, zig-zag index, |c|), in block order
    /// ([`SparseBlocks::push_rated`]; empty once [`SparseBlocks::refine`] ran).
    ones: Vec<(u32, u8, f32)>,
}

impl SparseBlocks {
    /// Appends a block.
    pub fn push(&mut self, q: &[i32; N * N]) {
        let b = self.dc.len() as u32;
        self.dc.push(q[0]);
        self.ac.extend(ac_terms(b, q));
    }

    /// Appends a block `q` quantised from the coefficients `c` (zig-zag) with `step`,
    /// keeping what [`SparseBlocks::refine`] needs.
    pub fn push_rated(&mut self, q: &[i32; N * N], c: &[f32; N * N], step: f32) {
        let b = self.dc.len() as u32;
        self.ones.extend(
            crate::rdoq::ones(q, c, step)
                .into_iter()
                .map(|(i, a)| (b, i, a)),
        );
        self.push(q);
    }

    /// Runs the rate-aware quantiser over every block pushed with
    /// [`SparseBlocks::push_rated`], at the token costs of all the stream's blocks: a
    /// segment coded in bands learns them from the whole segment, as one coded whole.
    pub fn refine(&mut self, lambda: f32) {
        use rayon::prelude::*;
        let costs = crate::rdoq::Costs::learn(self.blocks());
        let ones = std::mem::take(&mut self.ones);
        // The blocks with candidates, each refined alone.
        let each: Vec<&[(u32, u8, f32)]> = ones.chunk_by(|a, b| a.0 == b.0).collect();
        let mut want = each.iter().map(|o| o[0].0).peekable();
        let picked: Vec<[i32; N * N]> = self
            .blocks()
            .enumerate()
            .filter_map(|(b, q)| want.next_if(|&w| w == b as u32).map(|_| q))
            .collect();
        let changed: Vec<(u32, [i32; N * N])> = each
            .par_iter()
            .zip(picked)
            .filter_map(|(o, before)| {
                let mut q = before;
                let cand: Vec<(u8, f32)> = o.iter().map(|t| (t.1, t.2)).collect();
                crate::rdoq::refine(&mut q, &cand, &costs, lambda);
                (q != before).then_some((o[0].0, q))
            })
            .collect();
        // The AC terms again, the changed blocks' their own.
        let mut next = changed.iter().peekable();
        let mut ac = Vec::with_capacity(self.ac.len());
        for run in self.ac.chunk_by(|a, b| a.0 == b.0) {
            match next.next_if(|c| c.0 == run[0].0) {
                Some((b, q)) => ac.extend(ac_terms(*b, q)),
                None => ac.extend_from_slice(run),
            }
        }
        self.ac = ac;
    }

    /// The blocks, dense, in stream order.
    pub fn blocks(&self) -> impl Iterator<Item = [i32; N * N]> + '_ {
        let mut ac = self.ac.iter().peekable();
        self.dc.iter().enumerate().map(move |(b, &dc)| {
            let mut q = [0; N * N];
            q[0] = dc;
            while let Some(&(_, f, v)) = ac.next_if(|t| t.0 == b as u32) {
                q[f as usize] = v;
            }
            q
        })
    }

    /// Writes the stream exactly as `write_coefficients` writes the same blocks dense.
    pub fn write(&self, out: &mut Vec<u8>) {
        vbim_format::plane::write_sparse(&self.dc, self.ac.iter().copied(), out);
    }
}

/// Block `b`'s non-zero AC terms as (block, zig-zag index, value).
fn ac_terms(b: u32, q: &[i32; N * N]) -> impl Iterator<Item = (u32, u8, i32)> + '_ {
    (1..N * N)
        .filter(|&f| q[f] != 0)
        .map(move |f| (b, f as u8, q[f]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use vbim_format::plane::write_coefficients;

    /// Blocks with runs of zeros, zero and repeated DCs, values of every size.
    fn blocks(n: usize, seed: u64) -> Vec<[i32; N * N]> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) as u32
        };
        (0..n)
            .map(|_| {
                let mut q = [0i32; N * N];
                q[0] = (next() % 5) as i32 - 2;
                for v in q.iter_mut().skip(1) {
                    let r = next();
                    if r % 7 == 0 {
                        *v = (r as i32 >> 8) % 100_000 - 50_000;
                    } else if r % 5 == 0 {
                        *v = (r % 3) as i32 - 1;
                    }
                }
                q
            })
            .collect()
    }

    #[test]
    fn sparse_streams_are_written_as_the_dense_ones() {
        for (n, seed) in [(0, 1), (1, 2), (3, 3), (500, 4)] {
            let b = blocks(n, seed);
            let mut dense = Vec::new();
            write_coefficients(&b, &mut dense);
            let mut s = SparseBlocks::default();
            b.iter().for_each(|q| s.push(q));
            let mut sparse = Vec::new();
            s.write(&mut sparse);
            assert_eq!(sparse, dense, "{n} blocks");
            assert_eq!(s.blocks().collect::<Vec<_>>(), b, "{n} blocks back");
        }
        // All zeros: one run.
        let z = vec![[0i32; N * N]; 10];
        let (mut dense, mut sparse) = (Vec::new(), Vec::new());
        write_coefficients(&z, &mut dense);
        let mut s = SparseBlocks::default();
        z.iter().for_each(|q| s.push(q));
        s.write(&mut sparse);
        assert_eq!(sparse, dense);
    }

    #[test]
    fn a_stream_refined_sparse_is_the_blocks_refined_dense() {
        // Blocks of a few low terms, some with ±1s further out; coefficients a little
        // off their integers.
        let b: Vec<[i32; N * N]> = blocks(400, 7)
            .into_iter()
            .map(|mut q| {
                for (i, v) in q.iter_mut().enumerate().skip(1) {
                    *v = if i < 4 {
                        (*v).clamp(-3, 3)
                    } else {
                        (*v).clamp(-1, 1) * (i % 3 == 0) as i32
                    };
                }
                q
            })
            .collect();
        let c: Vec<[f32; N * N]> = b.iter().map(|q| q.map(|v| v as f32 * 0.8 + 0.05)).collect();
        let mut s = SparseBlocks::default();
        b.iter().zip(&c).for_each(|(q, c)| s.push_rated(q, c, 1.0));
        s.refine(0.2);
        let costs = crate::rdoq::Costs::learn(b.iter().copied());
        let dense: Vec<[i32; N * N]> = b
            .iter()
            .zip(&c)
            .map(|(q, c)| {
                let (mut q, ones) = (*q, crate::rdoq::ones(q, c, 1.0));
                crate::rdoq::refine(&mut q, &ones, &costs, 0.2);
                q
            })
            .collect();
        assert!(
            dense != b,
            "nothing dropped: the test would not see a difference"
        );
        assert_eq!(s.blocks().collect::<Vec<_>>(), dense);
    }
}
