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
        let i = ((c / self.lut_max).clamp(0.0, 1.0) * (LUT - 1) as f32) as usize;
        self.lut[i]
    }

    /// A frame (interleaved, linear or code / 255) → coded planes (Y, Co, Cg or Y alone)
    /// padded by repeating edge texels, and the per-texel sensitivity plane.
    pub fn code(&self, data: &[f32]) -> (Vec<Plane>, Vec<f32>) {
        let ch = self.channels;
        let mut planes = vec![Plane::zeros(self.pw, self.ph); ch];
        let mut sens = vec![0f32; self.pw * self.ph];
        for y in 0..self.ph {
            let sy = y.min(self.height - 1);
            for x in 0..self.pw {
                let sx = x.min(self.width - 1);
                let s = (sy * self.width + sx) * ch;
                let i = y * self.pw + x;
                if ch == 3 {
                    let c = [0, 1, 2].map(|k| self.transfer.encode(data[s + k]));
                    let v = rgb_to_ycocg(c);
                    for k in 0..3 {
                        planes[k].data[i] = v[k];
                    }
                    sens[i] =
                        (self.sensitivity(c[0]) + self.sensitivity(c[1]) + self.sensitivity(c[2]))
                            / 3.0;
                } else {
                    let c = self.transfer.encode(data[s]);
                    planes[0].data[i] = c;
                    sens[i] = self.sensitivity(c);
                }
            }
        }
        (planes, sens)
    }
}
