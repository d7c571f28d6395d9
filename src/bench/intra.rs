//! `vbim bench intra FRAMES`: what predicting a keyframe's 8 × 8 blocks from what is
//! decoded around them would save — #36's "intra prediction in keyframes", measured before
//! anything is built, as `bench transforms` measured larger transforms.
//!
//! The frames are encoded once with the encoder's tap on (`study::tapped_planes`), and every
//! keyframe plane (an intra keyframe's frame; a predicted keyframe's difference from the
//! keyframe before) is coded again in 8 × 8 blocks in raster order, closed loop (each block
//! predicted from the blocks already reconstructed, as a decoder would have them), in one of
//! these ways:
//!
//! - **today**: the format's coding, the DCT of the texels, the DC against the planar
//!   prediction of its neighbours' (left + up − up-left);
//! - **a surface through the DCs** (bilinear or quadratic), every block or chosen per block:
//!   the texels less a zero-mean surface interpolated through the 3 × 3 blocks' decoded
//!   means, so a slope or a bend across blocks costs no AC terms. The DCs are coded as today
//!   and every surface needs only DCs, so a GPU still decodes every block at once;
//! - **texel intra prediction** (AV1's tools for an 8 × 8 block): DC, vertical, horizontal,
//!   Paeth, smooth and the two diagonals, from the reconstructed texels above (with the
//!   above-right block's) and to the left, chosen per block beside today's coding. A block
//!   then waits for its upper and left neighbours: a decoder's work is serial along the
//!   plane's diagonals.
//!
//! Each block takes the candidate of smallest `D + λ·R` (λ = `LAMBDA`·step², R from an
//! adaptive model of the plane so far), whose choice is coded as a symbol in a context of
//! its neighbours' choices. A way's symbols are those of `bench transforms`' 8 × 8 blocks
//! (the DC residual in a context of its neighbours' residual sizes, the count in a context
//! of the residual's size and whether its neighbours have terms, the AC terms in zig-zag
//! order in contexts of how many are left and of their band), each kind of prediction with
//! statistics of its own, all coded by one adaptive model (`study::Model`); bytes are read
//! at today's error on a line through each way's points over the steps (log bytes against
//! log squared error, each plane weighted as the metric weighs it).

use rayon::prelude::*;
use vbim_encoder::bench::tap::{PlaneKind, TappedPlane};
use vbim_encoder::bench::PLANE_WEIGHT;
use vbim_format::plane2;

use super::args::BenchIntraArgs;
use super::study::{
    around, at_distortion, dc_surface, decoded_means, family, left_bucket, size_class, step_index,
    tapped_planes, Block, Coded, Model, Pick, Symbol, Transform,
};

/// λ of the choices, in squared steps per bit (`bench transforms`' own).
const LAMBDA: f64 = 0.12;
/// The block's side.
const N: usize = 8;

/// How a block is predicted.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Mode {
    /// Today's coding: nothing.
    None,
    /// A bilinear surface through the 3 × 3 blocks' means, less its own mean.
    Bilinear,
    /// The same, quadratic.
    Quadratic,
    /// From the reconstructed texels around the block (`Texel` modes, AV1's).
    Dc,
    Vertical,
    Horizontal,
    Paeth,
    Smooth,
    Diagonal45,
    Diagonal135,
}

/// Every mode, in the order `bench intra` counts them.
const MODES: [Mode; 10] = [
    Mode::None,
    Mode::Bilinear,
    Mode::Quadratic,
    Mode::Dc,
    Mode::Vertical,
    Mode::Horizontal,
    Mode::Paeth,
    Mode::Smooth,
    Mode::Diagonal45,
    Mode::Diagonal135,
];

impl Mode {
    pub(super) fn texel(self) -> bool {
        !matches!(self, Mode::None | Mode::Bilinear | Mode::Quadratic)
    }

    fn surface(self) -> bool {
        matches!(self, Mode::Bilinear | Mode::Quadratic)
    }
}

/// A block's best candidate so far: its cost J, mode, prediction, quantised coefficients,
/// squared error and symbols.
type Candidate = (f64, Mode, [f64; N * N], Vec<i32>, f64, Vec<Symbol>);

/// A way of coding a plane: the modes its blocks choose from, and the regions (of so
/// many blocks a side; 0: the plane) outside which a texel mode does not look.
struct Way {
    label: &'static str,
    modes: &'static [Mode],
    region: usize,
}

pub(super) const TEXEL_MODES: &[Mode] = &[
    Mode::None,
    Mode::Dc,
    Mode::Vertical,
    Mode::Horizontal,
    Mode::Paeth,
    Mode::Smooth,
    Mode::Diagonal45,
    Mode::Diagonal135,
];

/// Today's first.
const WAYS: [Way; 7] = [
    Way {
        label: "today (no prediction)",
        modes: &[Mode::None],
        region: 0,
    },
    Way {
        label: "bilinear surface through the DCs, every block",
        modes: &[Mode::Bilinear],
        region: 0,
    },
    Way {
        label: "quadratic surface through the DCs, every block",
        modes: &[Mode::Quadratic],
        region: 0,
    },
    Way {
        label: "none, bilinear or quadratic, per block",
        modes: &[Mode::None, Mode::Bilinear, Mode::Quadratic],
        region: 0,
    },
    Way {
        label: "texel intra (AV1's 7 modes or none), per block",
        modes: TEXEL_MODES,
        region: 0,
    },
    Way {
        label: "texel intra, AV1's smooth mode or none, per block",
        modes: &[Mode::None, Mode::Smooth],
        region: 0,
    },
    Way {
        label: "texel intra, 7 modes or none, inside regions of 8 × 8 blocks",
        modes: TEXEL_MODES,
        region: 8,
    },
];

pub fn run(a: BenchIntraArgs) -> Result<(), String> {
    let planes = tapped_planes(&a.study.frames, a.study.tolerance, a.study.fps)?;
    println!(
        "intra: {}, encoded at --tolerance {} --no-aim in format 2; 8 × 8 blocks, closed loop; \
         bytes at today's error (steps × {:?}), one adaptive model for every way",
        a.study.frames, a.study.tolerance, a.study.steps
    );
    println!("| planes | way | bytes at step × 1 | error | at today's error: bytes | ratio | blocks: none / surface / texel |");
    println!("|---|---|---:|---:|---:|---:|---|");
    let groups: [(&str, Pick); 2] = [
        ("intra keyframes", |k| k == PlaneKind::IntraKeyframe),
        ("predicted keyframes", |k| k == PlaneKind::PredictedKeyframe),
    ];
    let mut totals = [0.0; WAYS.len()];
    for (name, pick) in groups {
        let set: Vec<&TappedPlane> = planes.iter().filter(|p| pick(p.kind)).collect();
        if set.is_empty() {
            continue;
        }
        let mut today: Option<(f64, f64)> = None;
        for (w, way) in WAYS.iter().enumerate() {
            let points: Vec<(Coded, [f64; MODES.len()])> = a
                .study
                .steps
                .par_iter()
                .map(|&m| code_all(&set, way, m))
                .collect();
            let at1 = &points[step_index(&a.study.steps)];
            let coded: Vec<Coded> = points.iter().map(|(c, _)| c.clone()).collect();
            let (b0, d0) = *today.get_or_insert_with(|| {
                let d = at1.0.dist;
                (at_distortion(&coded, d), d)
            });
            let bytes = at_distortion(&coded, d0);
            totals[w] += bytes;
            let all: f64 = at1.1.iter().sum::<f64>().max(1.0);
            let share = |pick: fn(Mode) -> bool| -> f64 {
                MODES
                    .iter()
                    .zip(at1.1)
                    .filter(|(&m, _)| pick(m))
                    .map(|(_, n)| n)
                    .sum::<f64>()
                    / all
            };
            let texel: Vec<String> = MODES
                .iter()
                .zip(at1.1)
                .filter(|(m, n)| m.texel() && *n > 0.0)
                .map(|(m, n)| format!("{m:?} {:.2}", n / all))
                .collect();
            println!(
                "| {name} ({} planes) | {} | {:.0} | {:.4e} | {:.0} | {:.3} | {:.2} / {:.2} / {:.2}{} |",
                set.len(),
                way.label,
                at1.0.bytes,
                at1.0.dist,
                bytes,
                bytes / b0,
                share(|m| m == Mode::None),
                share(Mode::surface),
                share(Mode::texel),
                if texel.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", texel.join(", "))
                },
            );
        }
    }
    // The bubble planes, which no way here changes, coded as today at their own step.
    let bubbles: Vec<&TappedPlane> = planes
        .iter()
        .filter(|p| matches!(p.kind, PlaneKind::Bubble { .. }))
        .collect();
    let bubble_bytes = code_all(&bubbles, &WAYS[0], 1.0).0.bytes;
    println!(
        "bubble planes ({} planes, as today): {bubble_bytes:.0} bytes",
        bubbles.len()
    );
    for (w, way) in WAYS.iter().enumerate().skip(1) {
        println!(
            "keyframes, {}: {:.0} bytes against {:.0} today, {:.3}; with the bubble planes {:.3}",
            way.label,
            totals[w],
            totals[0],
            totals[w] / totals[0],
            (totals[w] + bubble_bytes) / (totals[0] + bubble_bytes)
        );
    }
    Ok(())
}

/// Every plane of `set` coded `way` at its step × `mult`, in order, by one adaptive model
/// that both prices the choices and codes them (as a coder whose statistics carry from
/// plane to plane would); also how many blocks took no prediction, a surface, a texel mode.
fn code_all(set: &[&TappedPlane], way: &Way, mult: f32) -> (Coded, [f64; MODES.len()]) {
    let t = Transform::new(N);
    let mut model = Model::default();
    let mut out = Coded::default();
    let mut share = [0.0; MODES.len()];
    for p in set {
        let plane = code_plane(p, way, p.step * mult, family(p), &t, &mut model);
        out.dist += PLANE_WEIGHT[p.plane.min(2)] * plane.dist;
        out.bytes += plane.bits / 8.0;
        for (s, n) in share.iter_mut().zip(plane.modes) {
            *s += n;
        }
        out.texels += (p.w * p.h) as f64;
    }
    (out, share)
}

/// A plane coded: its squared error, its bits, its blocks by kind of mode and its
/// reconstruction.
struct Plane {
    dist: f64,
    bits: f64,
    modes: [f64; MODES.len()],
    recon: Vec<f64>,
}

/// What a block's contexts read of its coded neighbours.
#[derive(Clone, Copy, Default)]
struct Coded8 {
    /// Its DC's level (in steps): for a texel mode, its reconstruction's.
    level: i32,
    /// Its coded DC residual's size class.
    size: u32,
    /// Whether it has AC terms.
    busy: bool,
    /// Whether it took a prediction.
    predicted: bool,
}

/// One plane coded in raster order, closed loop.
fn code_plane(
    p: &TappedPlane,
    way: &Way,
    step: f32,
    family: u32,
    t: &Transform,
    model: &mut Model,
) -> Plane {
    let step = step as f64;
    let (w, bw, bh) = (p.w, p.w / N, p.h / N);
    let lambda = LAMBDA * step * step;
    let source = |bx: usize, by: usize| -> [f64; N * N] {
        let mut b = [0.0; N * N];
        for y in 0..N {
            for x in 0..N {
                b[y * N + x] = p.data[(by * N + y) * w + bx * N + x] as f64;
            }
        }
        b
    };
    let means = decoded_means(p, N, step);
    let mut recon = vec![0.0f64; p.w * p.h];
    let mut done = vec![Coded8::default(); bw * bh];
    let mut out = Plane {
        dist: 0.0,
        bits: 0.0,
        modes: [0.0; MODES.len()],
        recon: Vec::new(),
    };
    let tag = |kind: u32, local: u32| (kind << 28) | (family << 20) | local;
    for b in 0..bw * bh {
        let (bx, by) = (b % bw, b / bw);
        let src = source(bx, by);
        let near = |dx: isize, dy: isize| -> Option<Coded8> {
            let (x, y) = (bx as isize + dx, by as isize + dy);
            (x >= 0 && y >= 0 && (x as usize) < bw).then(|| done[y as usize * bw + x as usize])
        };
        let (left, up, corner) = (near(-1, 0), near(0, -1), near(-1, -1));
        let level = |c: Option<Coded8>| c.map_or(0, |c| c.level);
        let planar = level(left) + level(up) - level(corner);
        let sizes = (left.map_or(0, |c| c.size) + up.map_or(0, |c| c.size)).min(3);
        let busy = left.is_some_and(|c| c.busy) as u32 + up.is_some_and(|c| c.busy) as u32;
        let mode_ctx =
            left.is_some_and(|c| c.predicted) as u32 + up.is_some_and(|c| c.predicted) as u32;
        // In raster order the above-right block is decoded wherever there is one.
        let edges = Edges::read(&recon, w, (bx, by), way.region, bx + 1 < bw);
        let mut best: Option<Candidate> = None;
        for (m, &mode) in way.modes.iter().enumerate() {
            let Some(pred) = predict(mode, &edges, &around(&means, (bw, bh), (bx, by))) else {
                continue;
            };
            let residual: Vec<f64> = src.iter().zip(&pred).map(|(s, q)| s - q).collect();
            let (q, dist) = t.quantise(&residual, step, p.deadzone as f64);
            let mut symbols = Vec::with_capacity(8);
            if way.modes.len() > 1 {
                symbols.push((tag(3, mode_ctx), m as u32));
            }
            // A texel mode codes its residual's DC as it is; the others the DC against the
            // planar prediction of the neighbours' levels.
            let r = if mode.texel() { q[0] } else { q[0] - planar };
            let count = q[1..].iter().filter(|&&v| v != 0).count() as u32;
            let dc_kind = mode.texel() as u32;
            // Every kind of prediction codes its count and AC terms in today's contexts:
            // apart, each kind's contexts start cold, a choice priced by them picks today's
            // coding ever more often, and the texel modes saved nothing (Jacksboro cloudy's
            // keyframes 1.003× today's, against 0.938× shared).
            let ac_kind = 0;
            symbols.push((tag(dc_kind, sizes), plane2::pack(r)));
            symbols.push((tag(ac_kind, 10 + size_class(r) * 3 + busy), count));
            let mut left_n = count;
            for (i, &v) in q.iter().enumerate().skip(1) {
                if left_n == 0 {
                    break;
                }
                symbols.push((
                    tag(ac_kind, 100 + left_bucket(left_n) * 12 + t.band[i]),
                    plane2::pack(v),
                ));
                left_n -= (v != 0) as u32;
            }
            let bits: f64 = symbols.iter().map(|&(c, v)| model.cost(c, v)).sum();
            let j = dist + lambda * bits;
            if best.as_ref().is_none_or(|b| j < b.0) {
                best = Some((j, mode, pred, q, dist, symbols));
            }
        }
        let (_, mode, pred, q, dist, symbols) =
            best.expect("every way has a mode any block can take");
        for &(c, v) in &symbols {
            out.bits += model.code(c, v);
        }
        out.dist += dist;
        out.modes[MODES.iter().position(|&m| m == mode).expect("a mode")] += 1.0;
        let rest = t.inverse(&q, step);
        let mut sum = 0.0;
        for y in 0..N {
            for x in 0..N {
                let v = pred[y * N + x] + rest[y * N + x];
                recon[(by * N + y) * w + bx * N + x] = v;
                sum += v;
            }
        }
        let r = if mode.texel() { q[0] } else { q[0] - planar };
        done[b] = Coded8 {
            level: if mode.texel() {
                (sum / 8.0 / step).round() as i32
            } else {
                q[0]
            },
            size: size_class(r),
            busy: q[1..].iter().any(|&v| v != 0),
            predicted: mode != Mode::None,
        };
    }
    out.recon = recon;
    out
}

/// A plane's blocks as a quadtree chose them (`bench transforms --intra`; in coding order,
/// each with its split flags first), coded again closed loop, the 8 × 8 ones free to take
/// a texel mode instead (by the smallest D + λR, R from `model`, which then codes them):
/// the plane's squared error, its bits, how many blocks took a texel mode and its
/// reconstruction. Every 8 × 8
/// block codes its mode first; a texel mode's block codes its residual's DC as it is (in
/// contexts of its own) and its count and AC terms in the 8 × 8 blocks' contexts; the
/// other blocks keep their symbols (their DC
/// residuals are against their grid's DCs as the quadtree had them: an approximation where
/// a neighbour took a texel mode).
pub(super) fn within_quadtree(
    p: &TappedPlane,
    step: f32,
    family: u32,
    blocks: &[Block],
    model: &mut Model,
) -> (f64, f64, usize, Vec<f64>) {
    let step = step as f64;
    let lambda = LAMBDA * step * step;
    let w = p.w;
    let cw = p.w / N;
    let transforms: Vec<Transform> = [8, 16, 32].into_iter().map(Transform::new).collect();
    let t8 = &transforms[0];
    let mut recon = vec![0.0f64; p.w * p.h];
    // Which 8 × 8 cells are decoded: a quadtree's order leaves the above-right one for
    // later where it lies in the next quarter.
    let mut ready = vec![false; cw * (p.h / N)];
    let (mut dist, mut bits, mut taken) = (0.0, 0.0, 0);
    let mode_ctx = (3 << 28) | (family << 20) | 20;
    for b in blocks {
        let (n, bx, by) = b.place;
        let flags = b.symbols.iter().take_while(|s| s.0 >> 28 == 3).count();
        let mut pick = (b.dist, Vec::new(), [0.0; N * N], b.coefs.clone(), false);
        if n == N {
            let right = bx + 1 < cw && by > 0 && ready[(by - 1) * cw + bx + 1];
            let edges = Edges::read(&recon, w, (bx, by), 0, right);
            let src: Vec<f64> = (0..N * N)
                .map(|i| p.data[(by * N + i / N) * w + bx * N + i % N] as f64)
                .collect();
            // Today's coding, with the mode's symbol before its own.
            let mut own = b.symbols[flags..].to_vec();
            own.insert(0, (mode_ctx, 0));
            let cost = |s: &[Symbol]| s.iter().map(|&(c, v)| model.cost(c, v)).sum::<f64>();
            let mut best = b.dist + lambda * cost(&own);
            pick.1 = own;
            // The block's contexts as the quadtree coded it: its DC's, and whether its
            // neighbours have terms (the count's context, less the residual's size).
            let dc_local = b.symbols[flags].0 & 0xFF;
            let busy = ((b.symbols[flags + 1].0 & 0xFF) - 10) % 3;
            for (m, &mode) in TEXEL_MODES.iter().enumerate().skip(1) {
                let Some(pred) = predict(mode, &edges, &[[0.0; 3]; 3]) else {
                    continue;
                };
                let residual: Vec<f64> = src.iter().zip(&pred).map(|(s, q)| s - q).collect();
                let (q, d) = t8.quantise(&residual, step, p.deadzone as f64);
                let count = q[1..].iter().filter(|&&v| v != 0).count() as u32;
                // The 8 × 8 blocks' own contexts, the DC's apart.
                let tag = |local: u32| (family << 20) | local;
                let mut s = vec![
                    (mode_ctx, m as u32),
                    (((family | 0x80) << 20) | dc_local, plane2::pack(q[0])),
                    (tag(10 + size_class(q[0]) * 3 + busy), count),
                ];
                let mut left = count;
                for (i, &v) in q.iter().enumerate().skip(1) {
                    if left == 0 {
                        break;
                    }
                    s.push((
                        tag(100 + left_bucket(left) * 12 + t8.band[i]),
                        plane2::pack(v),
                    ));
                    left -= (v != 0) as u32;
                }
                let j = d + lambda * cost(&s);
                if j < best {
                    best = j;
                    pick = (d, s, pred, q, true);
                }
            }
        }
        let (d, own, pred, q, texel) = pick;
        for &(c, v) in b.symbols[..flags].iter().chain(if own.is_empty() {
            &b.symbols[flags..]
        } else {
            &own[..]
        }) {
            bits += model.code(c, v);
        }
        dist += d;
        taken += texel as usize;
        let t = &transforms[n.trailing_zeros() as usize - 3];
        let rest = t.inverse(&q, step);
        for y in 0..n {
            for x in 0..n {
                let v = rest[y * n + x] + if texel { pred[y * N + x] } else { 0.0 };
                recon[(by * n + y) * w + bx * n + x] = v;
            }
        }
        for cy in by * n / N..(by + 1) * n / N {
            for cx in bx * n / N..(bx + 1) * n / N {
                ready[cy * cw + cx] = true;
            }
        }
    }
    (dist, bits, taken, recon)
}

/// The reconstructed texels around a block: 16 above (the block's and its above-right
/// neighbour's, the last repeated where that one is not decoded yet), 8 to the left and
/// the one above-left; `None` where the plane ends.
pub(super) struct Edges {
    above: Option<[f64; 2 * N]>,
    left: Option<[f64; N]>,
    corner: Option<f64>,
}

impl Edges {
    /// Block (bx, by)'s edges in a plane `w` texels wide, `right` if its above-right
    /// neighbour is decoded; with `region` > 0, only those inside its region of
    /// `region`² blocks.
    pub(super) fn read(
        recon: &[f64],
        w: usize,
        (bx, by): (usize, usize),
        region: usize,
        right: bool,
    ) -> Edges {
        let inside = |i: usize| {
            if region == 0 {
                i > 0
            } else {
                !i.is_multiple_of(region)
            }
        };
        let right = right && (region == 0 || !(bx + 1).is_multiple_of(region));
        let above = inside(by).then(|| {
            let row = (by * N - 1) * w;
            let mut a = [0.0; 2 * N];
            for (i, v) in a.iter_mut().enumerate() {
                *v = if i < N || right {
                    recon[row + bx * N + i]
                } else {
                    recon[row + bx * N + N - 1]
                };
            }
            a
        });
        let left =
            inside(bx).then(|| std::array::from_fn(|j| recon[(by * N + j) * w + bx * N - 1]));
        let corner = (inside(bx) && inside(by)).then(|| recon[(by * N - 1) * w + bx * N - 1]);
        Edges {
            above,
            left,
            corner,
        }
    }
}

/// AV1's smooth weights for 8 texels, out of 256.
const SMOOTH: [f64; N] = [255.0, 197.0, 146.0, 105.0, 73.0, 50.0, 37.0, 32.0];

/// Mode `mode`'s prediction of the block, `None` where what it reads is not there.
/// `means` are the decoded means of the 3 × 3 blocks around it (`study::around`), which
/// the surfaces read.
pub(super) fn predict(mode: Mode, e: &Edges, means: &[[f64; 3]; 3]) -> Option<[f64; N * N]> {
    let mut p = [0.0; N * N];
    let fill = |p: &mut [f64; N * N], f: &dyn Fn(usize, usize) -> f64| {
        for y in 0..N {
            for x in 0..N {
                p[y * N + x] = f(x, y);
            }
        }
    };
    match mode {
        Mode::None => {}
        Mode::Bilinear | Mode::Quadratic => {
            p.copy_from_slice(&dc_surface(N, means, mode == Mode::Quadratic));
        }
        Mode::Dc => {
            let (mut s, mut n) = (0.0, 0.0);
            if let Some(a) = e.above {
                s += a[..N].iter().sum::<f64>();
                n += N as f64;
            }
            if let Some(l) = e.left {
                s += l.iter().sum::<f64>();
                n += N as f64;
            }
            if n == 0.0 {
                return None;
            }
            p = [s / n; N * N];
        }
        Mode::Vertical => {
            let a = e.above?;
            fill(&mut p, &|x, _| a[x]);
        }
        Mode::Horizontal => {
            let l = e.left?;
            fill(&mut p, &|_, y| l[y]);
        }
        Mode::Paeth => {
            let (a, l, c) = (e.above?, e.left?, e.corner?);
            fill(&mut p, &|x, y| {
                let base = a[x] + l[y] - c;
                let (pa, pl, pc) = ((base - a[x]).abs(), (base - l[y]).abs(), (base - c).abs());
                if pl <= pa && pl <= pc {
                    l[y]
                } else if pa <= pc {
                    a[x]
                } else {
                    c
                }
            });
        }
        Mode::Smooth => {
            let (a, l) = (e.above?, e.left?);
            let (below, right) = (l[N - 1], a[N - 1]);
            fill(&mut p, &|x, y| {
                (SMOOTH[y] * a[x]
                    + (256.0 - SMOOTH[y]) * below
                    + SMOOTH[x] * l[y]
                    + (256.0 - SMOOTH[x]) * right)
                    / 512.0
            });
        }
        Mode::Diagonal45 => {
            let a = e.above?;
            let at = |i: usize| a[i.min(2 * N - 1)];
            fill(&mut p, &|x, y| {
                let i = x + y + 1;
                (at(i - 1) + 2.0 * at(i) + at(i + 1)) / 4.0
            });
        }
        Mode::Diagonal135 => {
            let (a, l, c) = (e.above?, e.left?, e.corner?);
            fill(&mut p, &|x, y| match x.cmp(&y) {
                std::cmp::Ordering::Greater => a[x - y - 1],
                std::cmp::Ordering::Equal => c,
                std::cmp::Ordering::Less => l[y - x - 1],
            });
        }
    }
    Some(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::bench::study::test_plane as plane;

    fn bytes_at_todays_error(p: &TappedPlane, way: &Way) -> (f64, f64) {
        let steps = [0.8, 1.0, 1.25, 1.6];
        let curve =
            |way: &Way| -> Vec<Coded> { steps.iter().map(|&m| code_all(&[p], way, m).0).collect() };
        let today = curve(&WAYS[0]);
        let d = today[1].dist;
        (at_distortion(&curve(way), d), at_distortion(&today, d))
    }

    #[test]
    fn the_error_counted_is_the_reconstructions_and_a_fine_step_keeps_the_plane() {
        let p = plane(64, 48, |x, y| {
            ((x * 7 + y * 13) % 17) as f32 * 0.1 + y as f32 * 0.02
        });
        let t = Transform::new(N);
        for way in &WAYS {
            for step in [1e-4, 0.05, 0.3] {
                let coded = code_plane(&p, way, step, 0, &t, &mut Model::default());
                let seen: f64 = coded
                    .recon
                    .iter()
                    .zip(&p.data)
                    .map(|(r, &s)| (r - s as f64).powi(2))
                    .sum();
                assert!(
                    (seen - coded.dist).abs() <= 1e-6 * seen.max(1e-9),
                    "{} at {step}: {seen} against {}",
                    way.label,
                    coded.dist
                );
                if step < 1e-3 {
                    assert!(seen < 64.0 * 48.0 * 1e-8, "{}", way.label);
                }
            }
        }
    }

    #[test]
    fn inside_regions_a_block_reads_no_texel_of_another_region() {
        let (w, bw) = (64, 8);
        // Each texel holds its block's region (regions of 4 × 4 blocks).
        let recon: Vec<f64> = (0..w * w)
            .map(|i| ((i % w / N / 4) + 10 * (i / w / N / 4)) as f64)
            .collect();
        for by in 0..bw {
            for bx in 0..bw {
                let own = ((bx / 4) + 10 * (by / 4)) as f64;
                let e = Edges::read(&recon, w, (bx, by), 4, bx + 1 < bw);
                let seen = e
                    .above
                    .iter()
                    .flatten()
                    .chain(e.left.iter().flatten())
                    .chain(&e.corner);
                for &v in seen {
                    assert_eq!(v, own, "block ({bx}, {by})");
                }
                assert_eq!(e.above.is_some(), by % 4 > 0);
                assert_eq!(e.left.is_some(), bx % 4 > 0);
            }
        }
        // Without regions, the plane's edge alone bounds them: block (4, 4) reads its
        // left neighbour in region (0, 1) and its upper one in region (1, 0).
        let e = Edges::read(&recon, w, (4, 4), 0, true);
        assert_eq!(e.left.unwrap()[0], 10.0);
        assert_eq!(e.above.unwrap()[0], 1.0);
    }

    #[test]
    fn a_surface_through_the_dcs_codes_a_curved_slope_in_fewer_bytes() {
        // A smooth bend over many blocks: what a keyframe's sky-lit slopes are.
        let p = plane(128, 128, |x, y| {
            let (u, v) = (x as f32 / 128.0, y as f32 / 128.0);
            3.0 * u * u + 2.0 * v + 0.01 * ((x * 13 + y * 7) % 5) as f32
        });
        let (surface, today) = bytes_at_todays_error(&p, &WAYS[2]);
        assert!(surface < 0.9 * today, "{surface} against {today}");
    }

    #[test]
    fn texel_intra_codes_straight_edges_in_fewer_bytes() {
        // Vertical stripes of random heights, each a texel wide: V continues them exactly.
        let col = |x: usize| ((x * 2_654_435_761) % 97) as f32 / 20.0;
        let p = plane(64, 64, |x, _| col(x));
        let (intra, today) = bytes_at_todays_error(&p, &WAYS[4]);
        assert!(intra < 0.7 * today, "{intra} against {today}");
    }
}
