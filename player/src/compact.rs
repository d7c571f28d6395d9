//! The compact form in which the decoder hands a plane's quantised coefficients to the GPU
//! (`decode.wgsl` reads it). Blocks go in runs: a record of two words for up to
//! [`RUN`] consecutive blocks of one block row — where the run starts, how many blocks it
//! covers, where its terms start — and the blocks' terms as a stream of 16-bit entries,
//! each block's last entry flagged. A run may carry a few empty blocks between blocks with
//! terms (one entry each), which costs less than a record of its own.
//!
//! A term entry is `zig-zag index << 10 | last << 9 | value`, the value in 9-bit two's
//! complement (−255…255; quantised values are small, most are ±1 or ±2). A value outside
//! that range is written as `index << 10 | last << 9 | 0x100` followed by its 32 bits in
//! two entries. An empty block is one entry with value 0 and `last` set. Blocks outside
//! every run have no entry: a keyframe pass starts from the reference keyframe or zeros, a
//! bubble pass from zeroed planes.
//!
//! Smooth content is why it is made this way: most blocks of a smooth plane hold a DC term
//! alone, which a record per block (8 bytes) and its term (2 bytes) made 5× the term
//! itself; in runs it costs 2.5 bytes.

use vbim_format::dct;
use vbim_format::plane::Blocks;

/// Most blocks in one run (a record says how many in 10 bits; a GPU workgroup decodes a
/// run's blocks one after another, so a bound keeps enough runs to spread the work).
pub(crate) const RUN: usize = 64;
/// Most empty blocks a run goes on through (each costs one entry; a new record costs
/// four).
const GAP: usize = 3;
/// The flag of a block's last entry.
pub(crate) const LAST: u16 = 1 << 9;
/// The escape: a 9-bit value field of −256 says the value follows in two entries.
pub(crate) const ESCAPE: u16 = 0x100;

/// Where one plane's runs lie in a [`Compact`] buffer.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct PlaneSpan {
    /// Quantiser step.
    pub step: f32,
    /// First record (its index in words, two words a record) and the number of records.
    pub records: u32,
    pub count: u32,
    /// The plane's terms: `[terms, terms_end)` in entries of the term stream.
    pub terms: u32,
    pub terms_end: u32,
    /// The largest magnitude any texel of the plane can take (from its terms), which
    /// sets a bubble plane's 16-bit scale.
    pub bound: f32,
    /// A bubble plane's scale: its texels are stored as round(value / scale).
    pub scale: f32,
}

/// Records and terms of several planes, appended one after another.
#[derive(Clone, Debug, Default)]
pub(crate) struct Compact {
    /// Two words per run: `first column | row << 11 | (blocks − 1) << 22` (in blocks),
    /// and its first entry relative to the plane's first.
    pub records: Vec<u32>,
    /// Term entries.
    pub terms: Vec<u16>,
    /// Scratch: what each block of a row is (absent, empty, with terms).
    row: Vec<u8>,
    /// Records and terms the last released segment held.
    hint: (usize, usize),
}

const ABSENT: u8 = 0;
const EMPTY: u8 = 1;
const FULL: u8 = 2;

impl Compact {
    /// Empties it for the next segment, with room for as many records and terms as the
    /// last one released held (the next segment is usually of a similar size).
    pub fn clear(&mut self) {
        self.records.clear();
        self.terms.clear();
        let (r, t) = std::mem::take(&mut self.hint);
        self.records.reserve(r);
        self.terms.reserve(t);
    }

    /// Gives back the storage once the coefficients are in a GPU staging buffer, so that
    /// a box in flight holds them once, remembering their size for [`Compact::clear`].
    pub fn release(&mut self) {
        self.hint = (self.records.len(), self.terms.len());
        self.records = Vec::new();
        self.terms = Vec::new();
    }

    /// Bytes this holds as uploaded (the term stream padded to whole words).
    pub fn bytes(&self) -> u64 {
        self.records.len() as u64 * 4 + self.terms.len().next_multiple_of(2) as u64 * 2
    }

    /// Appends a plane of `bw × bh` blocks whose block at column `bx`, row `by` is
    /// `blocks`' block `index(bx, by)`, or absent (`None`: not part of this plane, as a
    /// bubble plane's tiles below its degree are not); returns where it went. With
    /// `bound`, also a bound on the plane's texels (what a bubble plane's 16-bit scale
    /// needs; keyframes, which stay f32, do not).
    pub fn push_plane(
        &mut self,
        step: f32,
        blocks: &Blocks,
        (bw, bh): (usize, usize),
        index: impl Fn(usize, usize) -> Option<usize>,
        bound: bool,
    ) -> PlaneSpan {
        let (records, terms) = (self.records.len() as u32, self.terms.len() as u32);
        let mut peak = 0f32;
        let mut row = std::mem::take(&mut self.row);
        for by in 0..bh {
            row.clear();
            row.extend((0..bw).map(|bx| match index(bx, by) {
                None => ABSENT,
                Some(b) if blocks.nonzero(b) == 0 => EMPTY,
                Some(_) => FULL,
            }));
            let mut x = 0;
            while x < bw {
                if row[x] != FULL {
                    x += 1;
                    continue;
                }
                let end = run_end(&row, x);
                self.records
                    .push(x as u32 | (by as u32) << 11 | ((end - x - 1) as u32) << 22);
                self.records.push(self.terms.len() as u32 - terms);
                for (bx, &kind) in row.iter().enumerate().take(end).skip(x) {
                    match index(bx, by) {
                        Some(b) if kind == FULL => {
                            peak = peak.max(self.push_block(blocks, b, bound));
                        }
                        _ => self.terms.push(LAST),
                    }
                }
                x = end;
            }
        }
        self.row = row;
        PlaneSpan {
            step,
            records,
            count: (self.records.len() as u32 - records) / 2,
            terms,
            terms_end: self.terms.len() as u32,
            bound: peak * step,
            scale: 0.0,
        }
    }

    /// Appends block `b`'s terms; returns a bound on its texels' magnitude in units of
    /// the step: the block's columns of the inverse transform (exact), then each row's
    /// largest possible value, |Σ_kx col[kx][y] · T[kx][x]| ≤ Σ_kx |col[kx][y]| ·
    /// max |T[kx]| — exact down the columns, so within a small factor of the true peak
    /// rather than the sum of every term's.
    fn push_block(&mut self, blocks: &Blocks, b: usize, bound: bool) -> f32 {
        let t = dct::basis();
        let z = dct::zigzag();
        let amax = row_max();
        let mut col = [[0f32; dct::N]; dct::N];
        // The columns with a term: the rows' sums below skip the others (a DC-only block,
        // the commonest, has one), adding in the same order, so the bound is the same.
        let mut touched = 0u32;
        let mut head = self.terms.len();
        for (i, v) in blocks.terms(b) {
            if bound {
                let (ky, kx) = (z[i] / dct::N, z[i] % dct::N);
                touched |= 1 << kx;
                for (c, &ty) in col[kx].iter_mut().zip(&t[ky]) {
                    *c += v as f32 * ty;
                }
            }
            head = self.terms.len();
            let e = (i as u16) << 10;
            if (-255..=255).contains(&v) {
                self.terms.push(e | (v as u16 & 0x1FF));
            } else {
                let u = v as u32;
                self.terms
                    .extend_from_slice(&[e | ESCAPE, u as u16, (u >> 16) as u16]);
            }
        }
        self.terms[head] |= LAST;
        if !bound {
            return 0.0;
        }
        // Column after column, eight rows at a time (vectorised).
        let mut rows = [0f32; dct::N];
        while touched != 0 {
            let kx = touched.trailing_zeros() as usize;
            touched &= touched - 1;
            for (r, c) in rows.iter_mut().zip(&col[kx]) {
                *r += c.abs() * amax[kx];
            }
        }
        rows.iter().fold(0f32, |m, &r| m.max(r))
    }

    /// Appends a copy of `src`'s planes (as [`Compact::push_plane`] left them there),
    /// returning their spans here.
    pub fn push_copy(&mut self, src: &Compact, spans: &[PlaneSpan], out: &mut Vec<PlaneSpan>) {
        let (dr, dt) = (self.records.len() as u32, self.terms.len() as u32);
        self.records.extend_from_slice(&src.records);
        self.terms.extend_from_slice(&src.terms);
        out.extend(spans.iter().map(|s| PlaneSpan {
            records: s.records + dr,
            terms: s.terms + dt,
            terms_end: s.terms_end + dt,
            ..*s
        }));
    }
}

/// The end (exclusive) of the run starting at block `x` (which has terms): on through
/// blocks with terms, and through up to [`GAP`] empty ones when a block with terms
/// follows, at most [`RUN`] blocks; never past an absent block.
fn run_end(row: &[u8], x: usize) -> usize {
    let mut end = x + 1;
    let mut y = x + 1;
    while y < row.len() && y - x < RUN {
        match row[y] {
            FULL => {
                y += 1;
                end = y;
            }
            EMPTY => {
                let mut z = y;
                while z < row.len() && row[z] == EMPTY && z - y < GAP {
                    z += 1;
                }
                if z < row.len() && row[z] == FULL && z - x < RUN {
                    y = z;
                } else {
                    break;
                }
            }
            _ => break,
        }
    }
    end
}

/// For each basis row k, the largest |T[k][n]|: a term's largest contribution to any texel
/// is |value| · step · rowmax[ky] · rowmax[kx].
/// (Computed once: it was a third of the decoder's time when computed per block.)
fn row_max() -> &'static [f32; dct::N] {
    static ROW_MAX: std::sync::OnceLock<[f32; dct::N]> = std::sync::OnceLock::new();
    ROW_MAX.get_or_init(|| {
        let t = dct::basis();
        std::array::from_fn(|k| t[k].iter().fold(0f32, |m, &v| m.max(v.abs())))
    })
}

/// The scale of a bubble plane whose texels are at most `bound` in magnitude: 16-bit
/// signed steps that reach just past it (the GPU sums in f32, so allow a little).
pub(crate) fn bubble_scale(bound: f32) -> f32 {
    if bound > 0.0 && bound.is_finite() {
        bound * (1.0 + 1e-3) / 32767.0
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vbim_format::plane::{self, Onto, Plane};

    /// Reads the compact form back on the CPU the way `decode.wgsl` does, adding onto
    /// `out`.
    fn interpret(c: &Compact, s: &PlaneSpan, out: &mut Plane) {
        let t = dct::basis();
        let z = dct::zigzag();
        for r in 0..s.count as usize {
            let w = c.records[s.records as usize + 2 * r];
            let (bx0, by, n) = (
                (w & 0x7FF) as usize,
                (w >> 11 & 0x7FF) as usize,
                (w >> 22) as usize + 1,
            );
            let mut i = (s.terms + c.records[s.records as usize + 2 * r + 1]) as usize;
            for bx in bx0..bx0 + n {
                let mut terms = Vec::new();
                loop {
                    let e = c.terms[i];
                    i += 1;
                    let mut q = (e & 0x1FF) as i32;
                    if q == ESCAPE as i32 {
                        q = (c.terms[i] as u32 | (c.terms[i + 1] as u32) << 16) as i32;
                        i += 2;
                    } else if q > 0x100 {
                        q -= 0x200;
                    }
                    if q != 0 {
                        terms.push(((e >> 10) as usize, q));
                    }
                    if e & LAST != 0 {
                        break;
                    }
                }
                for y in 0..8 {
                    for x in 0..8 {
                        let v = &mut out.data[(by * 8 + y) * out.w + bx * 8 + x];
                        for &(i, q) in &terms {
                            let c = q as f32 * s.step;
                            *v += (c * t[z[i] / 8][y]) * t[z[i] % 8][x];
                        }
                    }
                }
            }
            assert!(i <= s.terms_end as usize);
        }
    }

    #[test]
    fn the_compact_form_decodes_to_the_reference_planes_and_its_bound_holds() {
        // Blocks of every density (many empty), with values that need the escape.
        let (bw, bh) = (40, 5);
        let mut seed = 7u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        let blocks: Vec<[i32; 64]> = (0..bw * bh)
            .map(|_| {
                let mut q = [0i32; 64];
                let density = [0, 0, 0, 1, 1, 2, 9, 40][(next() % 8) as usize];
                for _ in 0..density {
                    let v = (next() % 2001) as i32 - 1000;
                    q[(next() % 64) as usize] = if next() % 5 == 0 { v * 4001 } else { v / 100 };
                }
                q
            })
            .collect();
        let mut raw = Vec::new();
        plane::write_coefficients(&blocks, &mut raw);
        let mut parsed = Blocks::default();
        plane::read_blocks(&raw, &mut 0, blocks.len(), &mut parsed).unwrap();
        let step = 0.013;
        // A keyframe's plane (every block present), and a bubble plane's (the blocks of
        // columns 8–15 and from 30 on absent).
        let all = |bx: usize, by: usize| Some(by * bw + bx);
        let some =
            |bx: usize, by: usize| (!(8..16).contains(&bx) && bx < 30).then_some(by * bw + bx);
        for (name, order) in [
            ("all", &all as &dyn Fn(usize, usize) -> Option<usize>),
            ("some", &some),
        ] {
            let mut want = Plane::zeros(bw * 8, bh * 8);
            for (x, y) in (0..bh).flat_map(|y| (0..bw).map(move |x| (x, y))) {
                if let Some(b) = order(x, y) {
                    let at = std::iter::once((x, y));
                    plane::add_blocks_of(&mut want, at, Onto::Zeros, &parsed, b, step);
                }
            }
            let mut c = Compact::default();
            c.push_plane(1.0, &parsed, (bw, bh), all, false); // before it: the offsets
            let span = c.push_plane(step, &parsed, (bw, bh), order, true);
            assert!(c.terms.iter().any(|&e| e & 0x1FF == ESCAPE), "{name}");
            assert!(
                span.count * 2 < (bw * bh) as u32,
                "{name}: runs, not blocks"
            );
            let mut got = Plane::zeros(bw * 8, bh * 8);
            interpret(&c, &span, &mut got);
            let peak = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
            for (i, (g, w)) in got.data.iter().zip(&want.data).enumerate() {
                assert!(
                    (g - w).abs() <= 1e-5 * peak,
                    "{name}, texel {i}: {g} against {w}"
                );
            }
            assert!(
                span.bound >= peak && span.bound < 3.0 * peak,
                "{name}: {} {peak}",
                span.bound
            );
            // A copy keeps the spans' contents.
            let mut d = Compact::default();
            d.push_plane(1.0, &parsed, (bw, bh), all, false);
            let mut spans = Vec::new();
            d.push_copy(&c, &[span], &mut spans);
            let mut again = Plane::zeros(bw * 8, bh * 8);
            interpret(&d, &spans[0], &mut again);
            assert_eq!(again, got, "{name}");
        }
    }

    #[test]
    fn runs_go_through_short_gaps_and_stop_at_absent_blocks_and_the_limit() {
        let row = |s: &str| -> Vec<u8> {
            s.bytes()
                .map(|c| match c {
                    b'#' => FULL,
                    b'.' => EMPTY,
                    _ => ABSENT,
                })
                .collect()
        };
        assert_eq!(run_end(&row("##..#....#"), 0), 5);
        assert_eq!(run_end(&row("##_#"), 0), 2);
        assert_eq!(run_end(&row("###."), 0), 3);
        assert_eq!(run_end(&row(&"#".repeat(100)), 0), RUN);
        assert_eq!(run_end(&row("#...#"), 0), 5);
    }
}
