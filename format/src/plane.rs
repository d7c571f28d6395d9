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
    /// Width, texels.
    pub w: usize,
    /// Height, texels.
    pub h: usize,
    /// Values, row-major.
    pub data: Vec<f32>,
}

/// Room for a `w × h` plane's values, or an error naming its size if it cannot be had.
pub(crate) fn try_storage(w: usize, h: usize) -> crate::Result<Vec<f32>> {
    let mut data = Vec::new();
    w.checked_mul(h)
        .and_then(|n| data.try_reserve_exact(n).ok())
        .ok_or_else(|| {
            crate::FormatError::Invalid(format!(
                "cannot allocate a {w}×{h} plane ({} bytes)",
                w as u128 * h as u128 * 4
            ))
        })?;
    Ok(data)
}

impl Plane {
    /// A `w × h` plane of zeros.
    pub fn zeros(w: usize, h: usize) -> Plane {
        Plane {
            w,
            h,
            data: vec![0.0; w * h],
        }
    }

    /// A `w × h` plane of zeros, or an error if the memory cannot be had: a decoder's
    /// planes are sized by a header, and a failed allocation must not abort the process.
    pub fn try_zeros(w: usize, h: usize) -> crate::Result<Plane> {
        let mut data = try_storage(w, h)?;
        data.resize(w * h, 0.0);
        Ok(Plane { w, h, data })
    }

    /// The 8×8 block at block column `bx`, block row `by`.
    pub fn read_block(&self, bx: usize, by: usize) -> [f32; N * N] {
        let mut b = [0f32; N * N];
        for y in 0..N {
            let row = (by * N + y) * self.w + bx * N;
            b[y * N..y * N + N].copy_from_slice(&self.data[row..row + N]);
        }
        b
    }

    /// Writes the 8×8 block at block column `bx`, block row `by`.
    pub fn write_block(&mut self, bx: usize, by: usize, b: &[f32; N * N]) {
        for y in 0..N {
            let row = (by * N + y) * self.w + bx * N;
            self.data[row..row + N].copy_from_slice(&b[y * N..y * N + N]);
        }
    }
}

/// Block origins (in block units) of the blocks covering tile `t` of a plane, row by row.
/// (One range, not rows of ranges: its exact length lets a `Vec` extend by it at once,
/// where a flattened iterator pushed block by block — 7% of a 2048² format 2 decode,
/// which lists every bubble plane's blocks.)
pub fn tile_blocks(
    t: usize,
    tiles_x: usize,
    tile_size: usize,
) -> impl ExactSizeIterator<Item = (usize, usize)> {
    let per = tile_size / N;
    let (x0, y0) = (t % tiles_x * per, t / tiles_x * per);
    (0..per * per).map(move |j| (x0 + j % per, y0 + j / per))
}

/// Block origins of a whole plane, row by row.
pub fn all_blocks(p: &Plane) -> impl Iterator<Item = (usize, usize)> + use<> {
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
    let dc: Vec<i32> = blocks.iter().map(|b| b[0]).collect();
    let terms = blocks.iter().enumerate().flat_map(|(i, b)| {
        (1..N * N)
            .filter(move |&f| b[f] != 0)
            .map(move |f| (i as u32, f as u8, b[f]))
    });
    write_sparse(&dc, terms, out);
}

/// Writes blocks held sparse as [`write_coefficients`] writes them dense: `dc` each block's
/// DC, `terms` the non-zero AC terms as (block, zig-zag index, value) in block order. The
/// terms are gathered per frequency in two passes over them (a stable counting sort):
/// reading frequency by frequency across dense blocks would stream a whole plane 63 times
/// (a 2048² plane is 16 MB).
pub fn write_sparse(
    dc: &[i32],
    terms: impl Iterator<Item = (u32, u8, i32)> + Clone,
    out: &mut Vec<u8>,
) {
    let mut start = [0usize; N * N + 1];
    for (_, f, _) in terms.clone() {
        start[f as usize + 1] += 1;
    }
    for f in 1..=N * N {
        start[f] += start[f - 1];
    }
    let mut at = start;
    let mut by_f = vec![(0u32, 0i32); start[N * N]];
    for (b, f, v) in terms {
        by_f[at[f as usize]] = (b, v);
        at[f as usize] += 1;
    }
    write_runs(dc, &start, &by_f, out);
}

/// [`write_sparse`] for blocks whose terms are held block by block: block b's (zig-zag
/// index, value) terms are `terms[first[b]..first[b] + count[b]]`, in increasing index
/// (the blocks themselves in any order in `terms`). Walks the slices directly: through
/// [`write_sparse`]'s iterator this was a fifth of a format 2 section's decode to pairs.
pub(crate) fn write_block_terms(
    dc: &[i32],
    first: &[u32],
    count: &[u8],
    terms: &[(u8, i32)],
    out: &mut Vec<u8>,
) {
    let mut start = [0usize; N * N + 1];
    for &(f, _) in terms {
        start[f as usize + 1] += 1;
    }
    for f in 1..=N * N {
        start[f] += start[f - 1];
    }
    let mut at = start;
    let mut by_f = vec![(0u32, 0i32); terms.len()];
    for (b, (&first, &count)) in first.iter().zip(count).enumerate() {
        let first = first as usize;
        for &(f, v) in &terms[first..first + count as usize] {
            by_f[at[f as usize]] = (b as u32, v);
            at[f as usize] += 1;
        }
    }
    write_runs(dc, &start, &by_f, out);
}

/// The pairs of blocks `dc` whose AC terms are `by_f`, (block, value) frequency by
/// frequency (frequency f's from `start[f]`), each frequency's in block order.
fn write_runs(dc: &[i32], start: &[usize; N * N + 1], by_f: &[(u32, i32)], out: &mut Vec<u8>) {
    // A byte per DC and per run and value, most often.
    out.reserve(2 * by_f.len() + dc.len() + N * N);
    let mut w = RunWriter::new(out);
    let mut prev_dc = 0i32;
    for &d in dc {
        w.value(d.wrapping_sub(prev_dc));
        prev_dc = d;
    }
    let n = dc.len() as u32;
    for f in 1..N * N {
        // Zeros before each term of this frequency, then after its last one.
        let mut next = 0u32;
        for &(b, v) in &by_f[start[f]..start[f + 1]] {
            w.zeros(b - next);
            w.value(v);
            next = b + 1;
        }
        w.zeros(n - next);
    }
    w.finish();
}

/// The (zero run, value) pairs of a coefficient stream as [`write_coefficients`] writes
/// them, for writers that hold their blocks in another form (the encoder's sparse ones).
pub struct RunWriter<'a> {
    out: &'a mut Vec<u8>,
    run: u32,
}

impl<'a> RunWriter<'a> {
    /// Writes onto the end of `out`.
    pub fn new(out: &'a mut Vec<u8>) -> RunWriter<'a> {
        RunWriter { out, run: 0 }
    }

    /// The next coefficient.
    pub fn value(&mut self, v: i32) {
        if v == 0 {
            self.run += 1;
        } else {
            varint::put_u32(self.out, self.run);
            varint::put_i32(self.out, v);
            self.run = 0;
        }
    }

    /// `n` zero coefficients.
    pub fn zeros(&mut self, n: u32) {
        self.run += n;
    }

    /// The final run, which reaches the end of the stream.
    pub fn finish(self) {
        varint::put_u32(self.out, self.run);
    }
}

/// Decoded blocks of one coefficient stream, kept sparse: each block's DC term, and its
/// non-zero AC terms as (zig-zag index, value) in increasing index. The stream is
/// frequency-major, so writing it into 64-integer blocks would scatter one store per term
/// across a megabyte; here the terms are gathered per block in a second, cache-resident
/// pass. Kept from stream to stream so that steady-state decoding does not allocate.
#[derive(Default)]
pub struct Blocks {
    dc: Vec<i32>,
    /// AC terms of block b: zig-zag indices `ac_index[start[b]..start[b + 1]]` and their
    /// values at the same places. (Two arrays, 5 bytes a term: a tuple would pad to 8, and
    /// a dense 2048² keyframe plane holds 4 million terms.)
    ac_index: Vec<u8>,
    ac_value: Vec<i32>,
    start: Vec<u32>,
    /// Scratch: (block | zig-zag index << [`BLOCK_BITS`], value) in stream order, and
    /// bucket cursors. (8 bytes a term, not 12: the scratch is the largest thing the
    /// player's decoder holds on the CPU.)
    parsed: Vec<(u32, i32)>,
    cursor: Vec<u32>,
}

impl Blocks {
    /// Number of blocks read.
    pub fn len(&self) -> usize {
        self.dc.len()
    }

    /// Whether no block has a coefficient.
    pub fn is_empty(&self) -> bool {
        self.dc.is_empty()
    }

    /// Non-zero terms of block `b`, DC included.
    #[inline(always)]
    pub fn nonzero(&self, b: usize) -> usize {
        (self.dc[b] != 0) as usize + (self.start[b + 1] - self.start[b]) as usize
    }

    /// The non-zero terms of block `b` as (zig-zag index, value), in increasing index.
    /// (Inlined: the block kernel runs it once or twice per block.)
    #[inline(always)]
    pub fn terms(&self, b: usize) -> impl Iterator<Item = (usize, i32)> + '_ {
        let dc = (self.dc[b] != 0).then_some((0, self.dc[b]));
        let at = self.start[b] as usize..self.start[b + 1] as usize;
        let (index, value) = (&self.ac_index[at.clone()], &self.ac_value[at]);
        dc.into_iter()
            .chain(index.iter().zip(value).map(|(&i, &v)| (i as usize, v)))
    }

    /// Block `b` as 64 integers in zig-zag order.
    pub fn block(&self, b: usize) -> [i32; N * N] {
        let mut q = [0i32; N * N];
        for (i, v) in self.terms(b) {
            q[i] = v;
        }
        q
    }
}

/// Reads `n` blocks written by [`write_coefficients`].
pub fn read_coefficients(buf: &[u8], pos: &mut usize, n: usize) -> Result<Vec<[i32; N * N]>> {
    let mut b = Blocks::default();
    read_blocks(buf, pos, n, &mut b)?;
    Ok((0..n).map(|i| b.block(i)).collect())
}

/// Reads `n` blocks written by [`write_coefficients`] into `out`, reusing its storage.
pub fn read_blocks(buf: &[u8], pos: &mut usize, n: usize, out: &mut Blocks) -> Result<()> {
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
    out.dc.clear();
    out.dc.resize(n, 0);
    out.parsed.clear();
    out.start.clear();
    out.start.resize(n + 1, 0);
    // The parse loop works on locals: behind `out` the vectors' lengths and pointers would
    // be reloaded after every store, as the compiler cannot tell them from the data.
    let mut parsed = std::mem::take(&mut out.parsed);
    let parse = parse_pairs(buf, pos, &mut out.dc, &mut parsed, &mut out.start[1..]);
    out.parsed = parsed;
    parse?;
    // Undo the DC prediction.
    let mut prev = 0i32;
    for d in out.dc.iter_mut() {
        prev = prev.wrapping_add(*d);
        *d = prev;
    }
    // Gather each block's AC terms: counts → offsets, then one pass in stream order, which
    // is increasing frequency within every block.
    for i in 0..n {
        out.start[i + 1] += out.start[i];
    }
    out.cursor.clear();
    out.cursor.extend_from_slice(&out.start[..n]);
    out.ac_index.clear();
    out.ac_index.resize(out.parsed.len(), 0);
    out.ac_value.clear();
    out.ac_value.resize(out.parsed.len(), 0);
    // (As slices, whose pointers stay in registers.)
    let (cursor, index, value) = (
        &mut out.cursor[..],
        &mut out.ac_index[..],
        &mut out.ac_value[..],
    );
    for &(bf, v) in &out.parsed {
        let c = &mut cursor[(bf & BLOCK_MASK) as usize];
        index[*c as usize] = (bf >> BLOCK_BITS) as u8;
        value[*c as usize] = v;
        *c += 1;
    }
    Ok(())
}

/// Bits of a block's index in [`Blocks`]' scratch; the zig-zag index (6 bits) goes above.
const BLOCK_BITS: u32 = 26;
const BLOCK_MASK: u32 = (1 << BLOCK_BITS) - 1;
// `read_blocks` refuses streams of more blocks than one chunk can decode to.
const _: () = assert!(crate::limits::MAX_CHUNK_DECODED / (N * N) as u64 <= 1 << BLOCK_BITS);

/// The (zero run, value) pairs of a stream of `dc.len()` blocks: DC differences into `dc`,
/// non-zero AC terms as (block | zig-zag index << [`BLOCK_BITS`], value) in stream order
/// into `parsed`, and each block's count of them into `counts`.
fn parse_pairs(
    buf: &[u8],
    pos: &mut usize,
    dc: &mut [i32],
    parsed: &mut Vec<(u32, i32)>,
    counts: &mut [u32],
) -> Result<()> {
    let n = dc.len();
    // Frequency-major: stream position f·n + b is frequency f of block b. The position is
    // kept as (f, b), so that a pair costs no division unless its run wraps a frequency.
    let past_end = || crate::FormatError::Invalid(format!("zero run past the end of {n} blocks"));
    let mut at = *pos;
    let (mut f, mut b) = (0usize, 0usize);
    loop {
        let run = varint::get_u32(buf, &mut at)? as usize;
        if n == 0 {
            if run > 0 {
                return Err(past_end());
            }
            break;
        }
        b += run;
        if b >= n {
            f += b / n;
            b %= n;
        }
        if f > N * N || (f == N * N && b > 0) {
            return Err(past_end());
        }
        if f == N * N {
            break;
        }
        let v = varint::get_i32(buf, &mut at)?;
        if f == 0 {
            dc[b] = v;
        } else if v != 0 {
            parsed.push((b as u32 | (f as u32) << BLOCK_BITS, v));
            counts[b] += 1;
        }
        b += 1;
        if b == n {
            b = 0;
            f += 1;
        }
        if f == N * N {
            // The writer always ends with a run, possibly empty.
            let tail = varint::get_u32(buf, &mut at)?;
            if tail != 0 {
                return Err(crate::FormatError::Invalid("zero run past the end".into()));
            }
            break;
        }
    }
    *pos = at;
    Ok(())
}

/// Quantised zig-zag integers → spatial block: dequantise with `step`, inverse DCT.
pub fn dequantize_block(q: &[i32; N * N], step: f32) -> [f32; N * N] {
    spatial(q.iter().enumerate().map(|(i, &v)| (i, v)), step)
}

/// Dequantised terms (zig-zag index, value) inverse-transformed into a spatial block.
fn spatial(terms: impl Iterator<Item = (usize, i32)>, step: f32) -> [f32; N * N] {
    let z = dct::zigzag();
    let mut d = [0f32; N * N];
    for (i, v) in terms {
        d[z[i]] = v as f32 * step;
    }
    dct::inverse(&mut d);
    d
}

/// Where decoded blocks go: `Plane` adds them to the plane's values (a predicted keyframe
/// onto its reference); `Zeros` writes each block whole over whatever the plane held (a
/// plane coded on its own), with the bits `Plane` would give on a zeroed plane but
/// without clearing the plane first or reading it back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Onto {
    /// Add onto the plane's values.
    Plane,
    /// Write whole blocks over them.
    Zeros,
}

/// Adds blocks `b0`, `b0 + 1`, … of a decoded stream, dequantised, into the plane at the
/// block origins `at` yields (in block units), one block per origin, `onto` its values or
/// zeros.
///
/// This is the decoder's definition of a block's contribution (the encoder reconstructs its
/// keyframes through the decoder, so both sides agree bit for bit): an all-zero block adds
/// nothing; a block with at most [`SPARSE_MAX`] non-zero coefficients adds each one's basis
/// image directly (64 multiply-adds apiece, in increasing zig-zag order); denser blocks go
/// through the separable inverse DCT.
///
/// On x86-64 CPUs with AVX the same code runs compiled for 8-wide registers (one block row
/// per operation instead of two). Only the width changes: every texel still sees the same
/// IEEE multiplies and adds in the same order (Rust never fuses them into FMAs), so both
/// builds give identical bits, which `add_blocks_is_the_same_with_and_without_avx` checks.
pub fn add_blocks_of(
    p: &mut Plane,
    at: impl Iterator<Item = (usize, usize)>,
    onto: Onto,
    blocks: &Blocks,
    b0: usize,
    step: f32,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has just been found to support AVX.
        unsafe { add_blocks_avx(p, at, onto, blocks, b0, step) };
        return;
    }
    add_blocks_portable(p, at, onto, blocks, b0, step);
}

/// Which build of the block kernel [`add_blocks_of`] runs on this CPU, for benchmark
/// reports (figures from the two builds are not comparable).
pub fn kernel_build() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        return "AVX, 8 lanes";
    }
    "portable"
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn add_blocks_avx(
    p: &mut Plane,
    at: impl Iterator<Item = (usize, usize)>,
    onto: Onto,
    blocks: &Blocks,
    b0: usize,
    step: f32,
) {
    add_blocks_portable(p, at, onto, blocks, b0, step);
}

/// The kernel both builds share; inlined so that it takes the instruction set of its caller.
#[inline(always)]
fn add_blocks_portable(
    p: &mut Plane,
    at: impl Iterator<Item = (usize, usize)>,
    onto: Onto,
    blocks: &Blocks,
    b0: usize,
    step: f32,
) {
    for (i, (bx, by)) in at.enumerate() {
        add_block_of(p, (bx, by), onto, blocks, b0 + i, step);
    }
}

#[inline(always)]
fn add_block_of(
    p: &mut Plane,
    (bx, by): (usize, usize),
    onto: Onto,
    blocks: &Blocks,
    b: usize,
    step: f32,
) {
    let nonzero = blocks.nonzero(b);
    if nonzero == 0 && onto == Onto::Plane {
        return;
    }
    let w = p.w;
    let at = by * N * w + bx * N;
    // The block's rows are loaded once, updated in registers and stored once: each texel
    // still gets its additions one after another, starting from the plane's value.
    let mut acc = [[0f32; N]; N];
    if onto == Onto::Plane {
        for (y, row) in acc.iter_mut().enumerate() {
            *row = p.data[at + y * w..at + y * w + N].try_into().unwrap();
        }
        prefetch_rows_ahead(&p.data, at, w);
    }
    let z = dct::zigzag();
    if nonzero > SPARSE_MAX {
        let s = dct::inverse_terms(blocks.terms(b).map(|(i, v)| (z[i], v as f32 * step)));
        for (row, s) in acc.iter_mut().zip(&s) {
            for x in 0..N {
                row[x] += s[x];
            }
        }
    } else {
        let t = dct::basis();
        for (i, v) in blocks.terms(b) {
            // (`% N` tells the compiler the row is in range.)
            let (ky, kx) = (z[i] / N % N, z[i] % N);
            let c = v as f32 * step;
            // The term's factor for every row at once (one 8-lane multiply), then each
            // row adds its factor times the column basis.
            let a: [f32; N] = std::array::from_fn(|y| c * t[ky][y]);
            let tx = &t[kx];
            for (row, &a) in acc.iter_mut().zip(&a) {
                for x in 0..N {
                    row[x] += a * tx[x];
                }
            }
        }
    }
    for (y, row) in acc.iter().enumerate() {
        p.data[at + y * w..at + y * w + N].copy_from_slice(row);
    }
}

/// Asks for the rows of the block eight blocks to the right of the one at `at`: a
/// keyframe's reference plane was last written a keyframe ago, and it is read one block
/// at a time: eight 32-byte pieces a plane row apart (2 KB at 512²), which the hardware
/// prefetchers did not run ahead of (the rows' loads were ~30% of the predicted
/// keyframes' kernel samples before this).
#[inline(always)]
fn prefetch_rows_ahead(data: &[f32], at: usize, w: usize) {
    #[cfg(target_arch = "x86_64")]
    for y in 0..N {
        // A prefetch never faults, so the address may lie past the plane.
        let ahead = data.as_ptr().wrapping_add(at + y * w + 8 * N);
        // SAFETY: SSE is part of x86-64; a prefetch reads nothing the program sees.
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                ahead as *const i8,
            )
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (data, at, w);
}

/// Blocks with at most this many non-zero coefficients are added coefficient by
/// coefficient instead of through the full inverse transform.
pub const SPARSE_MAX: usize = 6;

/// Spatial block → quantised zig-zag integers, with a dead zone: a coefficient rounds away
/// from zero only past `(0.5 + deadzone) · step`. Used by the encoder; here so that its
/// rounding rule sits beside the decoder's inverse.
pub fn quantize_block(block: &[f32; N * N], step: f32, deadzone: f32) -> [i32; N * N] {
    quantize_coefficients(&coefficients(block), step, deadzone)
}

/// Spatial block → its DCT coefficients in zig-zag order.
pub fn coefficients(block: &[f32; N * N]) -> [f32; N * N] {
    let mut b = *block;
    dct::forward(&mut b);
    let mut c = [0f32; N * N];
    for (c, &pos) in c.iter_mut().zip(dct::zigzag()) {
        *c = b[pos];
    }
    c
}

/// Zig-zag DCT coefficients → quantised integers, with [`quantize_block`]'s dead zone.
pub fn quantize_coefficients(c: &[f32; N * N], step: f32, deadzone: f32) -> [i32; N * N] {
    let mut q = [0i32; N * N];
    for (i, (q, &c)) in q.iter_mut().zip(c).enumerate() {
        let a = c.abs() / step;
        let dz = if i == 0 { 0.0 } else { deadzone };
        let m = if a < 0.5 + dz { 0.0 } else { (a - dz).round() };
        *q = (m.min(1e9) as i32) * if c < 0.0 { -1 } else { 1 };
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

    /// Terms held block by block, the blocks listed out of order in the terms (as a
    /// format 2 walk leaves them), write the same pairs as the dense blocks.
    #[test]
    fn block_terms_write_what_dense_blocks_do() {
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        let blocks: Vec<[i32; 64]> = (0..40)
            .map(|b| {
                let mut q = [0i32; 64];
                q[0] = next() as i32 % 300 - 150;
                // Every fifth block empty, the others from sparse to dense.
                for v in q[1..].iter_mut().filter(|_| b % 5 != 0) {
                    if next() % 64 < b as u32 {
                        *v = next() as i32 % 41 - 20;
                    }
                }
                q
            })
            .collect();
        let mut dense = Vec::new();
        write_coefficients(&blocks, &mut dense);
        let (mut first, mut count, mut terms) = (vec![0u32; 40], vec![0u8; 40], Vec::new());
        // Odd blocks' terms first, then the even ones'.
        for b in (1..40).step_by(2).chain((0..40).step_by(2)) {
            first[b] = terms.len() as u32;
            for (i, &v) in blocks[b].iter().enumerate().skip(1) {
                if v != 0 {
                    terms.push((i as u8, v));
                    count[b] += 1;
                }
            }
        }
        let dc: Vec<i32> = blocks.iter().map(|q| q[0]).collect();
        let mut sparse = Vec::new();
        write_block_terms(&dc, &first, &count, &terms, &mut sparse);
        assert_eq!(sparse, dense);
    }

    /// Blocks of every density (empty, sparse, dense) added onto a plane of arbitrary
    /// values, so that the order of the additions shows in the bits.
    /// Returns the plane, the blocks and the blocks as read back from their stream.
    fn mixed_blocks(seed: &mut u32) -> (Plane, Vec<[i32; 64]>, Blocks) {
        let mut next = || {
            *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            *seed >> 8
        };
        let p = Plane {
            w: 64,
            h: 32,
            data: (0..64 * 32).map(|_| next() as f32 * 1e-4 - 800.0).collect(),
        };
        let blocks: Vec<[i32; 64]> = (0..32)
            .map(|i| {
                let density = [0, 1, 2, 6, 7, 20, 64][i % 7];
                std::array::from_fn(|_| {
                    if next() % 64 < density {
                        (next() % 2001) as i32 - 1000
                    } else {
                        0
                    }
                })
            })
            .collect();
        let mut buf = Vec::new();
        write_coefficients(&blocks, &mut buf);
        let mut q = Blocks::default();
        read_blocks(&buf, &mut 0, 32, &mut q).unwrap();
        (p, blocks, q)
    }

    fn assert_same_bits(a: &Plane, b: &Plane, what: &str) {
        for (i, (x, y)) in a.data.iter().zip(&b.data).enumerate() {
            assert_eq!(x.to_bits(), y.to_bits(), "texel {i}, {what}");
        }
    }

    #[test]
    fn added_blocks_are_the_per_texel_sums_in_order() {
        let mut seed = 11;
        for _ in 0..20 {
            let (p, bl, q) = mixed_blocks(&mut seed);
            let step = 0.37;
            let mut got = p.clone();
            add_blocks_of(&mut got, all_blocks(&p), Onto::Plane, &q, 0, step);
            // The definition, texel by texel: dense blocks add their inverse transform,
            // sparse ones each term's basis image in zig-zag order.
            let mut want = p.clone();
            let (t, z) = (dct::basis(), dct::zigzag());
            for (b, (bx, by)) in all_blocks(&p).enumerate() {
                let n = bl[b].iter().filter(|&&v| v != 0).count();
                if n > SPARSE_MAX {
                    let s = dequantize_block(&bl[b], step);
                    for (i, v) in s.iter().enumerate() {
                        want.data[(by * N + i / N) * p.w + bx * N + i % N] += v;
                    }
                    continue;
                }
                for (i, &v) in bl[b].iter().enumerate().filter(|(_, v)| **v != 0) {
                    let c = v as f32 * step;
                    for y in 0..N {
                        for x in 0..N {
                            let at = (by * N + y) * p.w + bx * N + x;
                            want.data[at] += c * t[z[i] / N][y] * t[z[i] % N][x];
                        }
                    }
                }
            }
            assert_same_bits(&got, &want, "added");
            // Written over the plane's values, the blocks are their sums onto zeros.
            let mut over = p.clone();
            add_blocks_of(&mut over, all_blocks(&p), Onto::Zeros, &q, 0, step);
            let mut onto_zeros = Plane::zeros(p.w, p.h);
            add_blocks_of(&mut onto_zeros, all_blocks(&p), Onto::Plane, &q, 0, step);
            assert_same_bits(&over, &onto_zeros, "written over");
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn add_blocks_is_the_same_with_and_without_avx() {
        assert!(
            std::arch::is_x86_feature_detected!("avx"),
            "this test compares the AVX build of the block kernel with the portable one: \
             run it on an x86-64 CPU with AVX"
        );
        let mut seed = 5;
        for _ in 0..20 {
            let (p, _, q) = mixed_blocks(&mut seed);
            let (mut portable, mut avx) = (p.clone(), p.clone());
            add_blocks_portable(&mut portable, all_blocks(&p), Onto::Plane, &q, 0, 0.37);
            // SAFETY: AVX support was checked above.
            unsafe { add_blocks_avx(&mut avx, all_blocks(&p), Onto::Plane, &q, 0, 0.37) };
            assert_ne!(portable, p);
            assert_same_bits(&portable, &avx, "AVX");
        }
    }

    #[test]
    fn reused_block_storage_reads_like_fresh_storage() {
        // Dense, then sparse and shorter, then a damaged stream, then dense again: nothing
        // one stream leaves in the reused storage shows through the next.
        let dense: Vec<[i32; 64]> = (0..9)
            .map(|i| std::array::from_fn(|j| ((i * 64 + j) as i32 * 7919) % 41 - 20))
            .collect();
        let mut sparse = vec![[0i32; 64]; 6];
        sparse[2][0] = 5;
        sparse[4][17] = -3;
        sparse[4][63] = 1;
        let streams = [dense.clone(), sparse, vec![[0i32; 64]; 3], dense];
        let mut reused = Blocks::default();
        for (k, bl) in streams.iter().enumerate() {
            let mut buf = Vec::new();
            write_coefficients(bl, &mut buf);
            if k == 2 {
                let bad = &buf[..buf.len() / 2];
                assert!(read_blocks(bad, &mut 0, bl.len(), &mut reused).is_err());
            }
            read_blocks(&buf, &mut 0, bl.len(), &mut reused).unwrap();
            assert_eq!(reused.len(), bl.len());
            for (b, want) in bl.iter().enumerate() {
                assert_eq!(&reused.block(b), want, "stream {k}, block {b}");
                let n = want.iter().filter(|&&v| v != 0).count();
                assert_eq!(reused.nonzero(b), n, "stream {k}, block {b}");
            }
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
