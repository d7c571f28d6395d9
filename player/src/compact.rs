//! The compact form in which the decoder hands a plane's quantised coefficients to the GPU
//! (`decode.wgsl` reads it): one record of two words per block that has a term — its
//! position, and where its terms start — and the terms as a stream of 16-bit entries.
//!
//! A term is `zig-zag index << 10 | value` with the value in 10-bit two's complement;
//! quantised values are small (most are ±1 or ±2), so one entry holds nearly all of them.
//! A value outside −511…511 is written as `index << 10 | 0x200` followed by its 32 bits
//! in two entries. Blocks without a term have no record: a keyframe pass starts from the
//! reference keyframe or zeros, a bubble pass from zeroed planes.

use vbim_format::dct;
use vbim_format::plane::Blocks;

/// The escape: a 10-bit value field of −512 says the value follows in two entries.
pub(crate) const ESCAPE: u16 = 0x200;

/// Where one plane's blocks lie in a [`Compact`] buffer.
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
    /// Two words per record: `column | row << 16` (in blocks), first term relative to
    /// the plane's first term.
    pub records: Vec<u32>,
    /// Term entries.
    pub terms: Vec<u16>,
}

impl Compact {
    pub fn clear(&mut self) {
        self.records.clear();
        self.terms.clear();
    }

    /// Bytes this holds as uploaded (the term stream padded to whole words).
    pub fn bytes(&self) -> u64 {
        self.records.len() as u64 * 4 + self.terms.len().next_multiple_of(2) as u64 * 2
    }

    /// Appends the blocks of `blocks` that have a term, block `i` lying at block position
    /// `at(i)`; returns where they went.
    pub fn push_plane(
        &mut self,
        step: f32,
        blocks: &Blocks,
        at: impl Iterator<Item = (usize, usize)>,
    ) -> PlaneSpan {
        let amax = row_max();
        let t = dct::basis();
        let z = dct::zigzag();
        let (records, terms) = (self.records.len() as u32, self.terms.len() as u32);
        let mut bound = 0f32;
        for (b, (bx, by)) in at.enumerate().take(blocks.len()) {
            if blocks.nonzero(b) == 0 {
                continue;
            }
            self.records.push(bx as u32 | (by as u32) << 16);
            self.records.push(self.terms.len() as u32 - terms);
            // The block's columns of the inverse transform (exact), then each row's
            // largest possible value: |Σ_kx col[kx][y] · T[kx][x]| ≤ Σ_kx |col[kx][y]| ·
            // max |T[kx]|. Exact down the columns, so within a small factor of the
            // block's true peak rather than the sum of every term's.
            let mut col = [[0f32; dct::N]; dct::N];
            for (i, v) in blocks.terms(b) {
                let (ky, kx) = (z[i] / dct::N, z[i] % dct::N);
                for (c, &ty) in col[kx].iter_mut().zip(&t[ky]) {
                    *c += v as f32 * ty;
                }
                let head = (i as u16) << 10;
                if (-511..=511).contains(&v) {
                    self.terms.push(head | (v as u16 & 0x3FF));
                } else {
                    let u = v as u32;
                    self.terms
                        .extend_from_slice(&[head | ESCAPE, u as u16, (u >> 16) as u16]);
                }
            }
            for y in 0..dct::N {
                let row: f32 = col.iter().zip(&amax).map(|(c, a)| c[y].abs() * a).sum();
                bound = bound.max(row);
            }
        }
        PlaneSpan {
            step,
            records,
            count: (self.records.len() as u32 - records) / 2,
            terms,
            terms_end: self.terms.len() as u32,
            bound: bound * step,
            scale: 0.0,
        }
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

/// For each basis row k, the largest |T[k][n]|: a term's largest contribution to any texel
/// is |value| · step · rowmax[ky] · rowmax[kx].
fn row_max() -> [f32; dct::N] {
    let t = dct::basis();
    std::array::from_fn(|k| t[k].iter().fold(0f32, |m, &v| m.max(v.abs())))
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

    /// Reads the compact form back on the CPU the way `decode.wgsl` does.
    fn interpret(c: &Compact, s: &PlaneSpan, out: &mut Plane) {
        let t = dct::basis();
        let z = dct::zigzag();
        for r in 0..s.count as usize {
            let w = c.records[s.records as usize + 2 * r];
            let (bx, by) = ((w & 0xFFFF) as usize, (w >> 16) as usize);
            let start = (s.terms + c.records[s.records as usize + 2 * r + 1]) as usize;
            let end = if r + 1 < s.count as usize {
                (s.terms + c.records[s.records as usize + 2 * r + 3]) as usize
            } else {
                s.terms_end as usize
            };
            let mut terms = Vec::new();
            let mut i = start;
            while i < end {
                let e = c.terms[i];
                let mut q = (e & 0x3FF) as i32;
                i += 1;
                if q == ESCAPE as i32 {
                    q = (c.terms[i] as u32 | (c.terms[i + 1] as u32) << 16) as i32;
                    i += 2;
                } else if q >= 0x200 {
                    q -= 0x400;
                }
                terms.push(((e >> 10) as usize, q));
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
    }

    #[test]
    fn the_compact_form_decodes_to_the_reference_planes_and_its_bound_holds() {
        // Blocks of every density, with values that need the escape.
        let (bw, bh) = (6, 4);
        let mut seed = 7u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        let blocks: Vec<[i32; 64]> = (0..bw * bh)
            .map(|b| {
                let mut q = [0i32; 64];
                for _ in 0..(b % 7) * 9 {
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
        let mut want = Plane::zeros(bw * 8, bh * 8);
        let at = || (0..bh).flat_map(|y| (0..bw).map(move |x| (x, y)));
        plane::add_blocks_of(&mut want, at(), Onto::Zeros, &parsed, 0, step);
        let mut c = Compact::default();
        c.push_plane(1.0, &parsed, at()); // something before, to test the offsets
        let span = c.push_plane(step, &parsed, at());
        assert!(c.terms.iter().any(|&e| e & 0x3FF == ESCAPE));
        let mut got = Plane::zeros(bw * 8, bh * 8);
        interpret(&c, &span, &mut got);
        let peak = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
        for (i, (g, w)) in got.data.iter().zip(&want.data).enumerate() {
            assert!((g - w).abs() <= 1e-5 * peak, "texel {i}: {g} against {w}");
        }
        assert!(
            span.bound >= peak && span.bound < 3.0 * peak,
            "{} {peak}",
            span.bound
        );
        // A copy keeps the spans' contents.
        let mut d = Compact::default();
        d.push_plane(1.0, &parsed, at());
        let mut spans = Vec::new();
        d.push_copy(&c, &[span], &mut spans);
        let mut again = Plane::zeros(bw * 8, bh * 8);
        interpret(&d, &spans[0], &mut again);
        assert_eq!(again, got);
    }
}
