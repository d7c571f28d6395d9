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
}

impl SparseBlocks {
    /// Appends a block.
    pub fn push(&mut self, q: &[i32; N * N]) {
        let b = self.dc.len() as u32;
        self.dc.push(q[0]);
        for (f, &v) in q.iter().enumerate().skip(1) {
            if v != 0 {
                self.ac.push((b, f as u8, v));
            }
        }
    }

    /// Writes the stream exactly as `write_coefficients` writes the same blocks dense.
    pub fn write(&self, out: &mut Vec<u8>) {
        vbim_format::plane::write_sparse(&self.dc, self.ac.iter().copied(), out);
    }
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
}
