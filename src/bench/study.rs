//! What the coding studies (`bench transforms`, `bench intra`) share: the planes the
//! encoder's tap records, an adaptive model that prices every way alike, format 2's
//! tokens and context buckets, an orthonormal DCT, and the reading of bytes at equal error.

use std::collections::HashMap;

use vbim_encoder::bench::tap::{self, PlaneKind, TappedPlane};
use vbim_encoder::{encode, EncoderConfig, FrameSet, Preset};
use vbim_format::ans::{self, TOKENS};
use vbim_format::plane2;

/// Encodes the frames with the tap on; returns what the quantiser was handed.
pub(super) fn tapped_planes(
    frames: &str,
    tolerance: f64,
    fps: (u32, u32),
) -> Result<Vec<TappedPlane>, String> {
    let fs = FrameSet::open(frames).map_err(|e| e.to_string())?;
    let cfg = EncoderConfig {
        rate: fps,
        tolerance_db: tolerance,
        aim: false,
        format: vbim_encoder::FormatVersion::V2,
        ..EncoderConfig::preset(Preset::Default)
    };
    let stages = crate::progress::Stages::new();
    let progress = |s: &str, d: u64, t: u64| stages.report(s, d, t);
    tap::start();
    let coded = encode(&fs, &cfg, std::io::Cursor::new(Vec::new()), &progress);
    let planes = tap::take();
    stages.finish();
    coded.map_err(|e| e.to_string())?;
    Ok(planes)
}

/// A set of planes coded one way at one step.
#[derive(Clone, Default)]
pub(super) struct Coded {
    pub(super) bytes: f64,
    pub(super) dist: f64,
    pub(super) terms: f64,
    pub(super) texels: f64,
}

/// The bytes at distortion `d`: a line through the points in log–log (least squares).
pub(super) fn at_distortion(points: &[Coded], d: f64) -> f64 {
    let xs: Vec<f64> = points.iter().map(|p| p.dist.ln()).collect();
    let ys: Vec<f64> = points.iter().map(|p| p.bytes.ln()).collect();
    let n = xs.len() as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my + slope * (d.ln() - mx)).exp()
}

/// A symbol: its context (a model of its own) and value.
pub(super) type Symbol = (u32, u32);

/// One block quantised: its squared error, its non-zero terms (DC included) and its
/// symbols in coding order.
pub(super) struct Block {
    pub(super) dist: f64,
    pub(super) terms: u32,
    /// Texels it covers.
    pub(super) area: usize,
    pub(super) symbols: Vec<Symbol>,
    /// Its size n and place (bx, by) on the grid of n × n blocks.
    pub(super) place: (usize, usize, usize),
    /// Its quantised coefficients (zig-zag), for a decoder's reconstruction.
    pub(super) coefs: Vec<i32>,
}

/// The model family of a plane: luma or chroma, times its kind.
pub(super) fn family(p: &TappedPlane) -> u32 {
    let kind = match p.kind {
        PlaneKind::IntraKeyframe => 0,
        PlaneKind::PredictedKeyframe => 1,
        PlaneKind::Bubble { term } => 2 + (term.min(4) - 2) as u32,
    };
    kind * 2 + (p.plane > 0) as u32
}

/// An adaptive model: per context, each token's count so far and their sum. A context is
/// (size or kind: 2 bits) << 28 | (family: 8 bits) << 20 | the block-local context (8
/// bits). Sparse, so that a study may keep one per plane for its choices.
#[derive(Default)]
pub(super) struct Model {
    counts: HashMap<u32, ([f32; TOKENS], f32)>,
}

impl Model {
    fn index(ctx: u32) -> u32 {
        ((ctx >> 28) << 16) | (((ctx >> 20) & 0xFF) << 8) | (ctx & 0xFF)
    }

    /// The bits `v` would cost in context `ctx` (Krichevsky–Trofimov), not counted.
    pub(super) fn cost(&self, ctx: u32, v: u32) -> f64 {
        let (tok, raw) = token(v);
        let (n, total) = self
            .counts
            .get(&Model::index(ctx))
            .map_or((0.0, 0.0), |(c, t)| (c[tok as usize], *t));
        let p = (n as f64 + 0.5) / (total as f64 + 0.5 * TOKENS as f64);
        -p.log2() + raw as f64
    }

    /// The bits `v` costs in context `ctx`, then counted.
    pub(super) fn code(&mut self, ctx: u32, v: u32) -> f64 {
        let bits = self.cost(ctx, v);
        let (counts, total) = self
            .counts
            .entry(Model::index(ctx))
            .or_insert(([0.0; TOKENS], 0.0));
        counts[token(v).0 as usize] += 1.0;
        *total += 1.0;
        bits
    }
}

/// Format 2's hybrid-uint token of `v` and its raw bits' count.
pub(super) fn token(v: u32) -> (u32, u32) {
    let (t, raw, _) = ans::hybrid_uint(v);
    (t as u32, raw)
}

pub(super) fn size_class(r: i32) -> u32 {
    plane2::size_class(r) as u32
}

/// Buckets of how many non-zero terms are left: format 2's up to 32, then more for larger
/// blocks.
pub(super) fn left_bucket(n: u32) -> u32 {
    match n {
        0 => 0,
        1..=32 => plane2::left_bucket(n as usize) as u32,
        33..=64 => 10,
        65..=128 => 11,
        _ => 12,
    }
}

/// A zero-mean surface over an n × n block through the decoded means `m` of the 3 × 3
/// blocks around it (`m[1][1]` its own, rows first), bilinear or quadratic (Lagrange
/// through the blocks' centres): what a block less it leaves is its detail, a slope or a
/// bend across blocks taken out; zero-mean, so that its DC stays the block's own.
pub(super) fn dc_surface(n: usize, m: &[[f64; 3]; 3], quadratic: bool) -> Vec<f64> {
    // Texel x's offset from the block's centre, in blocks.
    let at = |x: usize| (x as f64 + 0.5) / n as f64 - 0.5;
    let weights = |u: f64| -> [f64; 3] {
        if quadratic {
            [u * (u - 1.0) / 2.0, 1.0 - u * u, u * (u + 1.0) / 2.0]
        } else {
            [(-u).max(0.0), 1.0 - u.abs(), u.max(0.0)]
        }
    };
    let mut p: Vec<f64> = (0..n * n)
        .map(|i| {
            let (wx, wy) = (weights(at(i % n)), weights(at(i / n)));
            (0..3)
                .map(|j| (0..3).map(|k| wx[k] * wy[j] * m[j][k]).sum::<f64>())
                .sum()
        })
        .collect();
    let avg = p.iter().sum::<f64>() / (n * n) as f64;
    p.iter_mut().for_each(|v| *v -= avg);
    p
}

/// Which recorded planes a row of a study's table is about.
pub(super) type Pick = fn(PlaneKind) -> bool;

/// Where step × 1 is among a study's steps (the first if it is not among them).
pub(super) fn step_index(steps: &[f32]) -> usize {
    steps.iter().position(|&m| m == 1.0).unwrap_or(0)
}

/// Each n × n block's mean as a decoder has it (the orthonormal DC is the sum over n,
/// quantised at `step` without a dead zone), in raster order: what the surfaces read.
pub(super) fn decoded_means(p: &TappedPlane, n: usize, step: f64) -> Vec<f64> {
    let bw = p.w / n;
    (0..bw * (p.h / n))
        .map(|b| {
            let (bx, by) = (b % bw, b / bw);
            let sum: f64 = (0..n * n)
                .map(|i| p.data[(by * n + i / n) * p.w + bx * n + i % n] as f64)
                .sum();
            (sum / n as f64 / step).round() * step / n as f64
        })
        .collect()
}

/// The means of the 3 × 3 blocks around block (bx, by) of a grid `bw` × `bh` (rows
/// first), the grid's edge repeated: a surface's input.
pub(super) fn around(
    means: &[f64],
    (bw, bh): (usize, usize),
    (bx, by): (usize, usize),
) -> [[f64; 3]; 3] {
    std::array::from_fn(|j| {
        std::array::from_fn(|i| {
            let x = (bx + i).saturating_sub(1).min(bw - 1);
            let y = (by + j).saturating_sub(1).min(bh - 1);
            means[y * bw + x]
        })
    })
}

/// The zig-zag order of an n × n block: (x, y) of each index.
pub(super) fn zigzag(n: usize) -> Vec<(usize, usize)> {
    let mut v: Vec<(usize, usize)> = (0..n * n).map(|i| (i % n, i / n)).collect();
    v.sort_by_key(|&(x, y)| {
        let d = x + y;
        (d, if d % 2 == 1 { x } else { y })
    });
    v
}

/// An orthonormal n × n DCT with its zig-zag order and each index's band.
pub(super) struct Transform {
    pub(super) n: usize,
    pub(super) basis: Vec<f64>,
    pub(super) order: Vec<(usize, usize)>,
    pub(super) band: Vec<u32>,
}

impl Transform {
    pub(super) fn new(n: usize) -> Transform {
        let mut basis = vec![0.0; n * n];
        for k in 0..n {
            let scale = if k == 0 {
                (1.0 / n as f64).sqrt()
            } else {
                (2.0 / n as f64).sqrt()
            };
            for i in 0..n {
                basis[k * n + i] = scale
                    * (std::f64::consts::PI * (2 * i + 1) as f64 * k as f64 / (2 * n) as f64).cos();
            }
        }
        let order = zigzag(n);
        let of8: HashMap<(usize, usize), usize> = zigzag(8)
            .into_iter()
            .enumerate()
            .map(|(i, p)| (p, i))
            .collect();
        let band = order
            .iter()
            .map(|&(x, y)| plane2::band(of8[&(x * 8 / n, y * 8 / n)]) as u32)
            .collect();
        Transform {
            n,
            basis,
            order,
            band,
        }
    }

    /// The block's coefficients (zig-zag), quantised with format 2's dead zone (the DC
    /// without), and the squared error of the quantised ones.
    pub(super) fn quantise(&self, block: &[f64], step: f64, deadzone: f64) -> (Vec<i32>, f64) {
        let n = self.n;
        // Rows, then columns.
        let mut rows = vec![0.0; n * n];
        for y in 0..n {
            for k in 0..n {
                rows[y * n + k] = (0..n)
                    .map(|x| self.basis[k * n + x] * block[y * n + x])
                    .sum();
            }
        }
        let mut out = Vec::with_capacity(n * n);
        let mut dist = 0.0;
        for (i, &(kx, ky)) in self.order.iter().enumerate() {
            let c: f64 = (0..n)
                .map(|y| self.basis[ky * n + y] * rows[y * n + kx])
                .sum();
            let a = c.abs() / step;
            let dz = if i == 0 { 0.0 } else { deadzone };
            let m = if a < 0.5 + dz { 0.0 } else { (a - dz).round() };
            let q = (m.min(1e9) as i32) * if c < 0.0 { -1 } else { 1 };
            dist += (c - q as f64 * step).powi(2);
            out.push(q);
        }
        (out, dist)
    }

    /// The block the quantised coefficients (zig-zag) stand for, at `step`.
    pub(super) fn inverse(&self, q: &[i32], step: f64) -> Vec<f64> {
        let n = self.n;
        // Columns, then rows: cols[y * n + kx] = Σ_ky basis[ky][y] · c[ky][kx].
        let mut c = vec![0.0; n * n];
        for (i, &(kx, ky)) in self.order.iter().enumerate() {
            c[ky * n + kx] = q[i] as f64 * step;
        }
        let mut cols = vec![0.0; n * n];
        for y in 0..n {
            for kx in 0..n {
                cols[y * n + kx] = (0..n)
                    .map(|ky| self.basis[ky * n + y] * c[ky * n + kx])
                    .sum();
            }
        }
        let mut out = vec![0.0; n * n];
        for y in 0..n {
            for x in 0..n {
                out[y * n + x] = (0..n)
                    .map(|kx| self.basis[kx * n + x] * cols[y * n + kx])
                    .sum();
            }
        }
        out
    }
}

/// A keyframe plane of `f(x, y)` for the studies' tests.
#[cfg(test)]
pub(super) fn test_plane(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> TappedPlane {
    TappedPlane {
        kind: PlaneKind::IntraKeyframe,
        plane: 0,
        w,
        h,
        data: (0..w * h).map(|i| f(i % w, i / w)).collect(),
        step: 0.05,
        deadzone: 0.15,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hybrid_tokens_cover_their_values() {
        for v in [0u32, 1, 15, 16, 17, 31, 32, 1000, 65_535, 1 << 30] {
            let (t, raw) = token(v);
            assert!((t as usize) < TOKENS, "{v}");
            if v >= 16 {
                let n = 31 - v.leading_zeros();
                assert_eq!(raw, n - 2);
            }
        }
        assert_eq!(plane2::pack(0), 0);
        assert_eq!(plane2::pack(-1), 1);
        assert_eq!(plane2::pack(1), 2);
    }

    #[test]
    fn the_inverse_undoes_a_fine_quantisation() {
        for n in [8, 16] {
            let t = Transform::new(n);
            let block: Vec<f64> = (0..n * n).map(|i| ((i * 31) % 23) as f64 / 7.0).collect();
            let (q, _) = t.quantise(&block, 1e-5, 0.0);
            let back = t.inverse(&q, 1e-5);
            for (a, b) in block.iter().zip(&back) {
                assert!((a - b).abs() < 1e-4, "{n}: {a} against {b}");
            }
        }
    }
}
