//! The coded domain: linear light → transfer curve → YCoCg planes padded to whole tiles,
//! plus each texel's sensitivity — how much one unit of coded error moves the protocol's
//! metric there — so that error budgets are spent where the metric sees them.

use vbim_format::color::rgb_to_ycocg;
use vbim_format::metrics::Metric;
use vbim_format::plane::Plane;
use vbim_format::Transfer;

pub struct Domain {
    pub transfer: Transfer,
    pub channels: usize,
    pub width: usize,
    pub height: usize,
    pub pw: usize,
    pub ph: usize,
    /// d(metric value)/d(coded value) tabulated over the coded range.
    lut: Vec<f32>,
    lut_max: f32,
}

const LUT: usize = 4096;

/// The table's entry for code value `c` in a table over `0..=max`.
#[inline]
fn lut_index(c: f32, max: f32) -> i32 {
    ((c / max).clamp(0.0, 1.0) * (LUT - 1) as f32) as i32
}

impl Domain {
    pub fn new(
        transfer: Transfer,
        metric: Metric,
        channels: usize,
        width: usize,
        height: usize,
        tile: usize,
    ) -> Domain {
        let (pw, ph) = (width.div_ceil(tile) * tile, height.div_ceil(tile) * tile);
        let lut_max = match transfer {
            Transfer::Srgb => 1.0,
            Transfer::LogToe { .. } => transfer.encode(65504.0),
        };
        let lut = (0..LUT)
            .map(|i| {
                let c = lut_max * i as f32 / (LUT - 1) as f32;
                let d = lut_max / (LUT - 1) as f32;
                let f = |c: f32| {
                    metric.display(transfer.decode_stored(c.clamp(0.0, lut_max)), false) as f32
                };
                ((f(c + d) - f(c - d)) / (2.0 * d)).abs()
            })
            .collect();
        Domain {
            transfer,
            channels,
            width,
            height,
            pw,
            ph,
            lut,
            lut_max,
        }
    }

    /// Metric units per coded unit at coded value `c`.
    #[inline]
    pub fn sensitivity(&self, c: f32) -> f32 {
        self.sensitivity_at(self.sensitivity_index(c))
    }

    /// Where [`Domain::sensitivity`] looks up code value `c`.
    #[inline]
    fn sensitivity_index(&self, c: f32) -> usize {
        lut_index(c, self.lut_max) as usize
    }

    /// [`Domain::sensitivity_at`]'s indices for code values `v − e`, a run at a time (the
    /// arithmetic side by side, the lookups apart).
    pub fn sensitivity_indices(&self, v: &[f32], e: &[f64], out: &mut [i32]) {
        let max = self.lut_max;
        for ((o, &v), &e) in out.iter_mut().zip(v).zip(e) {
            *o = lut_index(v - e as f32, max);
        }
    }

    /// The sensitivity at a [`Domain::sensitivity_index`].
    #[inline]
    pub fn sensitivity_at(&self, i: usize) -> f32 {
        self.lut[i]
    }

    /// A frame (interleaved, linear or code / 255) → coded planes (Y, Co, Cg or Y alone)
    /// padded by repeating edge texels, and the per-texel sensitivity plane.
    pub fn code(&self, data: &[f32]) -> (Vec<Plane>, Vec<f32>) {
        self.code_rows(data, 0, 0..self.ph)
    }

    /// Padded rows `rows` of a frame, from the source rows starting at `first_row`
    /// (`data` holds source rows `first_row..`, and every source row `rows` needs:
    /// [`Domain::source_rows`]). Each texel is coded as [`Domain::code`] codes it; runs of
    /// rows in parallel (a large frame read alone is coded by every core).
    pub fn code_rows(
        &self,
        data: &[f32],
        first_row: usize,
        rows: std::ops::Range<usize>,
    ) -> (Vec<Plane>, Vec<f32>) {
        use rayon::prelude::*;
        const RUN: usize = 16;
        let h = rows.len();
        let mut planes = vec![Plane::zeros(self.pw, h); self.channels];
        let mut sens = vec![0f32; self.pw * h];
        // Each run of rows: its part of every plane and of the sensitivity.
        let mut parts: Vec<_> = planes
            .iter_mut()
            .map(|p| p.data.chunks_mut(self.pw * RUN))
            .collect();
        let runs: Vec<(Vec<&mut [f32]>, &mut [f32])> = sens
            .chunks_mut(self.pw * RUN)
            .map(|s| (parts.iter_mut().map(|p| p.next().unwrap()).collect(), s))
            .collect();
        runs.into_par_iter()
            .enumerate()
            .for_each(|(r, (mut planes, sens))| {
                let start = rows.start + r * RUN;
                self.fill_rows(data, first_row, start, &mut planes, sens);
            });
        (planes, sens)
    }

    /// Codes padded rows from `start` into `planes` and `sens` (as many rows as they hold).
    fn fill_rows(
        &self,
        data: &[f32],
        first_row: usize,
        start: usize,
        planes: &mut [&mut [f32]],
        sens: &mut [f32],
    ) {
        let ch = self.channels;
        for (r, srow) in sens.chunks_mut(self.pw).enumerate() {
            let y = start + r;
            let sy = y.min(self.height - 1) - first_row;
            for (x, sv) in srow.iter_mut().enumerate() {
                let sx = x.min(self.width - 1);
                let s = (sy * self.width + sx) * ch;
                let i = r * self.pw + x;
                if ch == 3 {
                    let c = [0, 1, 2].map(|k| self.transfer.encode(data[s + k]));
                    let v = rgb_to_ycocg(c);
                    for k in 0..3 {
                        planes[k][i] = v[k];
                    }
                    *sv =
                        (self.sensitivity(c[0]) + self.sensitivity(c[1]) + self.sensitivity(c[2]))
                            / 3.0;
                } else {
                    let c = self.transfer.encode(data[s]);
                    planes[0][i] = c;
                    *sv = self.sensitivity(c);
                }
            }
        }
    }

    /// The source rows that padded rows `rows` are coded from (the padding repeats the
    /// last row).
    pub fn source_rows(&self, rows: &std::ops::Range<usize>) -> std::ops::Range<usize> {
        let last = self.height - 1;
        rows.start.min(last)..rows.end.min(self.height).max(rows.start.min(last) + 1)
    }

    /// The domain of a frame subsampled as the segment search reads it: every
    /// `stride`-th texel of each tile, in both directions, packed into tiles of
    /// [`Domain::sub_tile`] texels.
    pub fn subsampled(&self, tile: usize, stride: usize) -> Domain {
        let st = Self::sub_tile(tile, stride);
        Domain {
            transfer: self.transfer,
            channels: self.channels,
            width: self.pw / tile * st,
            height: self.ph / tile * st,
            pw: self.pw / tile * st,
            ph: self.ph / tile * st,
            lut: self.lut.clone(),
            lut_max: self.lut_max,
        }
    }

    /// Texels a side of a subsampled tile.
    pub fn sub_tile(tile: usize, stride: usize) -> usize {
        tile.div_ceil(stride)
    }

    /// Keeps the texels of a coded frame (`planes`, `sens` over the padded frame) that
    /// the search reads, laid out in the domain of [`Domain::subsampled`].
    pub fn subsample(
        &self,
        planes: &[Plane],
        sens: &[f32],
        tile: usize,
        stride: usize,
    ) -> (Vec<Plane>, Vec<f32>) {
        let st = Self::sub_tile(tile, stride);
        let (tx, ty) = (self.pw / tile, self.ph / tile);
        let sw = tx * st;
        let mut out = vec![Plane::zeros(sw, ty * st); planes.len()];
        let mut out_sens = vec![0f32; sw * ty * st];
        for y in 0..ty * st {
            let sy = (y / st) * tile + (y % st) * stride;
            for x in 0..sw {
                let sx = (x / st) * tile + (x % st) * stride;
                let (i, o) = (sy * self.pw + sx, y * sw + x);
                for (p, q) in planes.iter().zip(out.iter_mut()) {
                    q.data[o] = p.data[i];
                }
                out_sens[o] = sens[i];
            }
        }
        (out, out_sens)
    }
}
