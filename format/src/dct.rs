//! The 8×8 orthonormal DCT-II that decorrelates every plane in space before quantisation.
//! Separable, f32, with a fixed summation order so that encoder and decoder agree bit for bit.

use std::sync::OnceLock;

/// Block size: 8×8.
pub const N: usize = 8;

/// The orthonormal DCT-II basis: `basis()[k][n]` is frequency k at sample n.
/// (This and [`zigzag`] are inlined: the block kernel asks for them once per block.)
#[inline]
pub fn basis() -> &'static [[f32; N]; N] {
    table()
}

#[inline]
fn table() -> &'static [[f32; N]; N] {
    static T: OnceLock<[[f32; N]; N]> = OnceLock::new();
    T.get_or_init(|| {
        let mut t = [[0f32; N]; N];
        for (k, row) in t.iter_mut().enumerate() {
            let a = if k == 0 {
                (1.0 / N as f64).sqrt()
            } else {
                (2.0 / N as f64).sqrt()
            };
            for (n, v) in row.iter_mut().enumerate() {
                *v = (a
                    * (std::f64::consts::PI * (2 * n + 1) as f64 * k as f64 / (2 * N) as f64).cos())
                    as f32;
            }
        }
        t
    })
}

/// Forward transform of one block (row-major 8×8), in place.
pub fn forward(block: &mut [f32; N * N]) {
    let t = table();
    let mut tmp = [0f32; N * N];
    for y in 0..N {
        for k in 0..N {
            let mut s = 0.0;
            for n in 0..N {
                s += t[k][n] * block[y * N + n];
            }
            tmp[y * N + k] = s;
        }
    }
    for x in 0..N {
        for k in 0..N {
            let mut s = 0.0;
            for n in 0..N {
                s += t[k][n] * tmp[n * N + x];
            }
            block[k * N + x] = s;
        }
    }
}

/// Inverse transform of one block of coefficients, in place. Rows of coefficients that are
/// all zero, and then columns that are, are skipped: adding an exact zero to a sum that
/// starts at +0.0 never changes its bits, so the result is the dense loops' (most blocks
/// of a coefficient plane are nearly empty).
pub fn inverse(block: &mut [f32; N * N]) {
    let t = table();
    // Columns, a whole row of coefficients at a time: for every output (n, x) the sum still
    // runs over k in ascending order, so the result is the element-wise loops' bit for bit,
    // but the inner loop is eight independent lanes the compiler vectorises.
    let mut tmp = [[0f32; N]; N];
    // Columns of coefficients that hold a non-zero term: the rows pass skips the others.
    let mut cols = [false; N];
    for (k, tk) in t.iter().enumerate() {
        let c: &[f32; N] = block[k * N..k * N + N].try_into().unwrap();
        if c.iter().all(|&v| v == 0.0) {
            continue;
        }
        for x in 0..N {
            cols[x] |= c[x] != 0.0;
        }
        for (n, out) in tmp.iter_mut().enumerate() {
            let a = tk[n];
            for x in 0..N {
                out[x] += a * c[x];
            }
        }
    }
    // Rows. Skipping by column instead of by value gives the same bits: a sum that starts
    // at +0.0 is never −0.0, so adding a zero product (of either sign) leaves it as it is.
    for (y, row) in tmp.iter().enumerate() {
        let mut out = [0f32; N];
        for (k, &c) in row.iter().enumerate() {
            if !cols[k] {
                continue;
            }
            for n in 0..N {
                out[n] += t[k][n] * c;
            }
        }
        block[y * N..y * N + N].copy_from_slice(&out);
    }
}

/// [`inverse`] of a block given as its non-zero coefficients, `(row-major position, value)`
/// in zig-zag order, with the same bits, as rows of samples. This is the decoder's dense
/// path: its work grows with the terms and the columns that hold them, where [`inverse`]
/// scans all 64 coefficients and loads whole coefficient rows that were just written one
/// scalar at a time.
///
/// The columns pass takes one term at a time into the intermediate held transposed: term
/// (ky, kx) adds `t[ky] · c` to intermediate column kx, one 8-lane row of `tmp_t`. Zig-zag
/// order visits each column's terms in ascending ky, the order of [`inverse`]'s sums, and
/// the absent (zero) terms it would add leave a sum that starts at +0.0 unchanged.
#[inline(always)]
pub fn inverse_terms(terms: impl Iterator<Item = (usize, f32)>) -> [[f32; N]; N] {
    let t = table();
    let mut tmp_t = [[0f32; N]; N];
    let mut cols = 0u8;
    for (pos, c) in terms {
        // (`% N` tells the compiler the row is in range.)
        let (ky, kx) = (pos / N % N, pos % N);
        cols |= 1 << kx;
        let (col, tk) = (&mut tmp_t[kx], &t[ky]);
        for n in 0..N {
            col[n] += tk[n] * c;
        }
    }
    // Rows: column k of the intermediate (a row of `tmp_t`) times basis row k, for the
    // columns that hold a term, in ascending k.
    let mut out = [[0f32; N]; N];
    let mut left = cols;
    while left != 0 {
        let k = left.trailing_zeros() as usize;
        left &= left - 1;
        let tk = &t[k];
        for (row, &c) in out.iter_mut().zip(&tmp_t[k]) {
            for n in 0..N {
                row[n] += tk[n] * c;
            }
        }
    }
    out
}

/// Zig-zag scan order: coefficient positions from low to high frequency.
#[inline]
pub fn zigzag() -> &'static [usize; N * N] {
    static Z: OnceLock<[usize; N * N]> = OnceLock::new();
    Z.get_or_init(|| {
        let mut z = [0usize; N * N];
        let mut i = 0;
        for s in 0..(2 * N - 1) {
            let range: Vec<usize> = (0..N).filter(|&y| s >= y && s - y < N).collect();
            let ys: Vec<usize> = if s % 2 == 0 {
                range.into_iter().rev().collect()
            } else {
                range
            };
            for y in ys {
                z[i] = y * N + (s - y);
                i += 1;
            }
        }
        z
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        let mut b = [0f32; 64];
        for (i, v) in b.iter_mut().enumerate() {
            *v = ((i * 37) % 11) as f32 - 3.0;
        }
        let orig = b;
        forward(&mut b);
        inverse(&mut b);
        for (a, o) in b.iter().zip(orig) {
            assert!((a - o).abs() < 1e-4);
        }
        let z = zigzag();
        let mut seen = [false; 64];
        for &p in z.iter() {
            seen[p] = true;
        }
        assert!(seen.iter().all(|&s| s));
        assert_eq!(&z[..4], &[0, 1, 8, 16]);
    }

    /// The inverse as first written, one coefficient at a time: the vectorised form must
    /// give the same bits, or files coded with predicted keyframes would drift.
    fn inverse_elementwise(block: &mut [f32; N * N]) {
        let t = table();
        let mut tmp = [0f32; N * N];
        for x in 0..N {
            for k in 0..N {
                let c = block[k * N + x];
                for n in 0..N {
                    tmp[n * N + x] += t[k][n] * c;
                }
            }
        }
        for y in 0..N {
            let mut out = [0f32; N];
            for k in 0..N {
                for n in 0..N {
                    out[n] += t[k][n] * tmp[y * N + k];
                }
            }
            block[y * N..y * N + N].copy_from_slice(&out);
        }
    }

    /// A block of coefficients, each non-zero with probability `density`/64.
    fn random_block(seed: &mut u32, density: u32) -> [f32; 64] {
        let mut b = [0f32; 64];
        for v in b.iter_mut() {
            *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            if (*seed >> 8) % 64 < density {
                *v = ((*seed >> 12) % 2001) as f32 * 0.37 - 370.0;
            }
        }
        b
    }

    #[test]
    fn inverse_terms_is_inverse_bit_for_bit() {
        let z = zigzag();
        let mut seed = 3u32;
        for density in [1, 2, 7, 20, 64] {
            for _ in 0..500 {
                let b = random_block(&mut seed, density);
                let terms = z.iter().map(|&p| (p, b[p])).filter(|&(_, v)| v != 0.0);
                let got = inverse_terms(terms);
                let mut want = b;
                inverse(&mut want);
                for (i, (x, y)) in got.as_flattened().iter().zip(&want).enumerate() {
                    assert_eq!(x.to_bits(), y.to_bits(), "sample {i} of {b:?}");
                }
            }
        }
    }

    #[test]
    fn inverse_is_the_elementwise_sum_bit_for_bit() {
        let mut seed = 7u32;
        for density in [1, 3, 8, 20, 64] {
            for _ in 0..500 {
                let b = random_block(&mut seed, density);
                let (mut a, mut e) = (b, b);
                inverse(&mut a);
                inverse_elementwise(&mut e);
                for (x, y) in a.iter().zip(&e) {
                    assert_eq!(x.to_bits(), y.to_bits(), "{b:?}");
                }
            }
        }
    }
}
