//! Planes of coded values and how their quantised DCT coefficients are packed.
//!
//! A plane is padded to whole tiles (edge texels repeated by the encoder). Its 8×8 blocks are
//! transformed ([`crate::dct`]) and quantised with one step per plane; the integers are then
//! written frequency-major — all blocks' DC terms (each as the difference from the previous
//! block's), then every block's first AC term in zig-zag order, and so on — as zig-zag
//! varints, which groups similar magnitudes together for zstd.

use crate::dct::{self, N};
use crate::varint;
use crate::Result;

/// One plane of f32 values, row-major, `w × h` with both multiples of 8.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    pub w: usize,
    pub h: usize,
    pub data: Vec<f32>,
}

impl Plane {
    pub fn zeros(w: usize, h: usize) -> Plane {
        Plane {
            w,
            h,
            data: vec![0.0; w * h],
        }
    }

    pub fn read_block(&self, bx: usize, by: usize) -> [f32; N * N] {
        let mut b = [0f32; N * N];
        for y in 0..N {
            let row = (by * N + y) * self.w + bx * N;
            b[y * N..y * N + N].copy_from_slice(&self.data[row..row + N]);
        }
        b
    }

    pub fn write_block(&mut self, bx: usize, by: usize, b: &[f32; N * N]) {
        for y in 0..N {
            let row = (by * N + y) * self.w + bx * N;
            self.data[row..row + N].copy_from_slice(&b[y * N..y * N + N]);
        }
    }

    /// Adds a block into the plane (used by predicted keyframes).
    pub fn add_block(&mut self, bx: usize, by: usize, b: &[f32; N * N]) {
        for y in 0..N {
            let row = (by * N + y) * self.w + bx * N;
            for x in 0..N {
                self.data[row + x] += b[y * N + x];
            }
        }
    }
}

/// Block origins (in block units) of the blocks covering tile `t` of a plane, row by row.
pub fn tile_blocks(
    t: usize,
    tiles_x: usize,
    tile_size: usize,
) -> impl Iterator<Item = (usize, usize)> {
    let per = tile_size / N;
    let (tx, ty) = (t % tiles_x, t / tiles_x);
    (0..per).flat_map(move |y| (0..per).map(move |x| (tx * per + x, ty * per + y)))
}

/// Block origins of a whole plane, row by row.
pub fn all_blocks(p: &Plane) -> impl Iterator<Item = (usize, usize)> {
    let (bw, bh) = (p.w / N, p.h / N);
    (0..bh).flat_map(move |y| (0..bw).map(move |x| (x, y)))
}

/// Writes quantised blocks (each 64 integers in zig-zag order) frequency-major — the DC
/// terms as differences from the previous block's, then each AC position across all
/// blocks — as (zero run, value) pairs: a LEB128 count of zeros, then a zig-zag varint
/// of the non-zero value; a final run reaches the end. Coefficient planes are mostly
/// zeros, so this is both smaller before zstd and far faster to decode than one varint
/// per coefficient.
pub fn write_coefficients(blocks: &[[i32; N * N]], out: &mut Vec<u8>) {
    let mut run = 0u32;
    let mut emit = |v: i32, out: &mut Vec<u8>| {
        if v == 0 {
            run += 1;
        } else {
            varint::put_u32(out, run);
            varint::put_i32(out, v);
            run = 0;
        }
    };
    let mut prev_dc = 0i32;
    for b in blocks {
        emit(b[0].wrapping_sub(prev_dc), out);
        prev_dc = b[0];
    }
    for f in 1..N * N {
        for b in blocks {
            emit(b[f], out);
        }
    }
    varint::put_u32(out, run);
}

/// Decoded blocks of one coefficient stream with each block's number of non-zero terms,
/// kept from stream to stream so that steady-state decoding neither allocates nor faults
/// in fresh pages, and so that empty blocks are skipped without being scanned.
#[derive(Default)]
pub struct Blocks {
    pub q: Vec<[i32; N * N]>,
    pub nonzero: Vec<u8>,
}

/// Reads `n` blocks written by [`write_coefficients`].
pub fn read_coefficients(buf: &[u8], pos: &mut usize, n: usize) -> Result<Vec<[i32; N * N]>> {
    let mut b = Blocks::default();
    read_blocks(buf, pos, n, &mut b)?;
    Ok(b.q)
}

/// Reads `n` blocks written by [`write_coefficients`] into `out`, reusing its storage.
pub fn read_blocks(buf: &[u8], pos: &mut usize, n: usize, out: &mut Blocks) -> Result<()> {
    let total = n * N * N;
    // Every pair takes at least two bytes: refuse a count the stream cannot hold before
    // allocating for it (zero runs make the blocks themselves cheap to describe).
    if n > 0 && buf.len() <= *pos {
        return Err(crate::FormatError::Invalid(format!(
            "coefficient stream empty for {n} blocks"
        )));
    }
    if n > crate::limits::MAX_CHUNK_DECODED as usize / (N * N) {
        return Err(crate::FormatError::Invalid(format!(
            "{n} blocks in one stream"
        )));
    }
    out.q.clear();
    out.q.resize(n, [0i32; N * N]);
    out.nonzero.clear();
    out.nonzero.resize(n, 0);
    let (blocks, nonzero) = (&mut out.q, &mut out.nonzero);
    let mut idx = 0usize;
    loop {
        let run = varint::get_u32(buf, pos)? as usize;
        idx = idx
            .checked_add(run)
            .filter(|&i| i <= total)
            .ok_or_else(|| {
                crate::FormatError::Invalid(format!("zero run past the end of {n} blocks"))
            })?;
        if idx == total {
            break;
        }
        let v = varint::get_i32(buf, pos)?;
        // Frequency-major: position idx is frequency idx / n of block idx % n.
        blocks[idx % n][idx / n] = v;
        if idx >= n && v != 0 {
            nonzero[idx % n] += 1; // AC terms; the DC term is counted after its prediction
        }
        idx += 1;
        if idx == total {
            // The writer always ends with a run, possibly empty.
            let tail = varint::get_u32(buf, pos)?;
            if tail != 0 {
                return Err(crate::FormatError::Invalid("zero run past the end".into()));
            }
            break;
        }
    }
    // Undo the DC prediction.
    let mut prev = 0i32;
    for (b, nz) in blocks.iter_mut().zip(nonzero.iter_mut()) {
        prev = prev.wrapping_add(b[0]);
        b[0] = prev;
        *nz += (prev != 0) as u8;
    }
    Ok(())
}

/// Quantised zig-zag integers → spatial block: dequantise with `step`, inverse DCT.
pub fn dequantize_block(q: &[i32; N * N], step: f32) -> [f32; N * N] {
    let z = dct::zigzag();
    let mut b = [0f32; N * N];
    for (i, &pos) in z.iter().enumerate() {
        b[pos] = q[i] as f32 * step;
    }
    dct::inverse(&mut b);
    b
}

/// Adds a dequantised block into the plane at block (bx, by). This is the decoder's
/// definition of a block's contribution (the encoder reconstructs through it too, so both
/// sides agree bit for bit): an all-zero block adds nothing; a block with at most
/// [`SPARSE_MAX`] non-zero coefficients adds each one's basis image directly (64
/// multiply-adds apiece); denser blocks go through the separable inverse DCT.
pub fn add_dequantized(p: &mut Plane, bx: usize, by: usize, q: &[i32; N * N], step: f32) {
    let nonzero = q.iter().filter(|&&v| v != 0).count();
    add_dequantized_counted(p, bx, by, q, step, nonzero);
}

/// [`add_dequantized`] for a block whose number of non-zero terms is known
/// ([`Blocks::nonzero`]).
pub fn add_dequantized_counted(
    p: &mut Plane,
    bx: usize,
    by: usize,
    q: &[i32; N * N],
    step: f32,
    nonzero: usize,
) {
    if nonzero == 0 {
        return;
    }
    if nonzero > SPARSE_MAX {
        p.add_block(bx, by, &dequantize_block(q, step));
        return;
    }
    let t = dct::basis();
    let z = dct::zigzag();
    let w = p.w;
    let mut left = nonzero;
    for (i, &v) in q.iter().enumerate() {
        if v == 0 {
            continue;
        }
        let (ky, kx) = (z[i] / N, z[i] % N);
        let c = v as f32 * step;
        let tx = &t[kx];
        for y in 0..N {
            let a = c * t[ky][y];
            let at = (by * N + y) * w + bx * N;
            // A fixed-size row: no bounds checks inside, so the eight lanes vectorise.
            let row: &mut [f32; N] = (&mut p.data[at..at + N]).try_into().unwrap();
            for x in 0..N {
                row[x] += a * tx[x];
            }
        }
        // The count says when the last one is done: the high frequencies are not scanned.
        left -= 1;
        if left == 0 {
            break;
        }
    }
}

/// Blocks with at most this many non-zero coefficients are added coefficient by
/// coefficient instead of through the full inverse transform.
pub const SPARSE_MAX: usize = 6;

/// Spatial block → quantised zig-zag integers, with a dead zone: a coefficient rounds away
/// from zero only past `(0.5 + deadzone) · step`. Used by the encoder; here so that its
/// rounding rule sits beside the decoder's inverse.
pub fn quantize_block(block: &[f32; N * N], step: f32, deadzone: f32) -> [i32; N * N] {
    let mut b = *block;
    dct::forward(&mut b);
    let z = dct::zigzag();
    let mut q = [0i32; N * N];
    for (i, &pos) in z.iter().enumerate() {
        let a = b[pos].abs() / step;
        let dz = if i == 0 { 0.0 } else { deadzone };
        let m = if a < 0.5 + dz { 0.0 } else { (a - dz).round() };
        q[i] = (m.min(1e9) as i32) * if b[pos] < 0.0 { -1 } else { 1 };
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coefficients_round_trip() {
        let blocks: Vec<[i32; 64]> = (0..5)
            .map(|i| {
                let mut b = [0i32; 64];
                for (j, v) in b.iter_mut().enumerate() {
                    *v = ((i * 64 + j) as i32 * 7919) % 201 - 100;
                }
                b
            })
            .collect();
        let mut buf = Vec::new();
        write_coefficients(&blocks, &mut buf);
        let mut pos = 0;
        assert_eq!(read_coefficients(&buf, &mut pos, 5).unwrap(), blocks);
        assert_eq!(pos, buf.len());
        assert!(read_coefficients(&buf[..buf.len() - 1], &mut 0, 5).is_err());
        // Sparse blocks, and all-zero ones.
        let mut sparse = vec![[0i32; 64]; 7];
        sparse[3][10] = -4;
        sparse[6][63] = 9;
        sparse[0][0] = 2;
        for bl in [sparse, vec![[0i32; 64]; 4]] {
            let mut buf = Vec::new();
            write_coefficients(&bl, &mut buf);
            let mut pos = 0;
            assert_eq!(read_coefficients(&buf, &mut pos, bl.len()).unwrap(), bl);
            assert_eq!(pos, buf.len());
        }
    }

    #[test]
    fn quantisation_error_is_bounded_by_the_step() {
        let mut b = [0f32; 64];
        for (i, v) in b.iter_mut().enumerate() {
            *v = (i as f32 * 0.37).sin() * 3.0;
        }
        let step = 0.01;
        let r = dequantize_block(&quantize_block(&b, step, 0.0), step);
        for (a, o) in r.iter().zip(b) {
            assert!((a - o).abs() < step * 8.0 * 0.5 + 1e-4);
        }
    }
}
