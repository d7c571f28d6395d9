//! The model of one segment (`docs/MODEL.md`): given the decoded keyframes at its ends and
//! the source frames inside, choose each tile's degree (luma and chroma apart) as the
//! fewest terms that meet the error budget, and quantise the bubble-coefficient planes.

use std::collections::HashMap;
use std::sync::Arc;

use rayon::prelude::*;
use vbim_format::basis::Projector;
use vbim_format::chunk::{self, TileMap};
use vbim_format::dct::N;
use vbim_format::plane::{self, Plane};

use crate::domain::Domain;
use crate::rdoq::Costs;
use crate::sparse::SparseBlocks;
use crate::EncodeError;

/// A source frame in the coded domain with its per-texel sensitivity.
pub struct CodedFrame {
    pub planes: Vec<Plane>,
    pub sens: Vec<f32>,
}

/// Per-plane weight of squared coded error in the mean RGB squared error: a luma error
/// moves all three channels, a Co error two of them by the same amount, a Cg error all.
pub const PLANE_WEIGHT: [f64; 3] = [1.0, 2.0 / 3.0, 1.0];

/// Projectors by (segment length, max degree), built once.
#[derive(Default)]
pub struct Projectors {
    map: HashMap<(u32, usize), Arc<Projector>>,
}

impl Projectors {
    pub fn get(&mut self, len: u32, max_degree: usize) -> Arc<Projector> {
        self.map
            .entry((len, max_degree))
            .or_insert_with(|| Arc::new(Projector::new(len, max_degree)))
            .clone()
    }
}

/// Weighted squared fit error of one tile for each number of bubbles 0..=nb and each
/// interior frame (`[slot · frames + frame]`), summed over its texels, per plane group
/// (luma, chroma); with `every_slot` false only slot nb (all bubbles) is summed, the others
/// stay 0 (the segment search needs no more, and summing every slot was half its time).
/// Optionally keeps z = Qᵀr per texel and plane (for the coefficients).
/// The keyframes cover the frame; the inner frames may be a band of it, starting at
/// texel `inner_at` of the frame.
///
/// The tile's values in every frame are read first, as runs of its rows (reading a
/// texel's values frame by frame missed the cache at every frame: a sixth of the
/// encode); then a row at a time, the arithmetic runs across the row's texels, each
/// texel's in the order of the sums (so the results are those of one texel at a time,
/// bit for bit).
/// Sums of a tile's errors added side by side (independent chains of additions).
const LANES: usize = 8;

#[allow(clippy::too_many_arguments)]
fn tile_errors(
    dom: &Domain,
    tile: (usize, usize),
    ts: usize,
    stride: usize,
    k0: &[Plane],
    k1: &[Plane],
    inner: &[&CodedFrame],
    inner_at: usize,
    p: &Projector,
    every_slot: bool,
    mut keep_z: Option<&mut Vec<f64>>,
) -> ([Vec<f64>; 2], usize) {
    let m = inner.len();
    let nb = p.bubbles;
    let planes = dom.channels;
    let slots = nb + 1;
    let first_slot = if every_slot { 0 } else { nb };
    let len = (m + 1) as f64;
    let mut err = [vec![0.0; slots * m], vec![0.0; slots * m]];
    // The bubbles' columns of Q, each contiguous, and the keyframes' weights.
    let q: Vec<Vec<f64>> = (0..nb)
        .map(|k| (0..m).map(|j| p.q[j * nb + k]).collect())
        .collect();
    let hat: Vec<f64> = (0..m).map(|j| (j + 1) as f64 / len).collect();
    // The texels read along a row, and the rows read: the same steps.
    let xs: Vec<usize> = (0..ts).step_by(stride).collect();
    let n = xs.len();
    // The tile's values first, frame by frame and plane by plane, row after row: a
    // constant stride the cache's prefetch follows (read a row at a time between the
    // arithmetic, the frames' values missed the cache one after another). Per row:
    // [plane][frame][texel] and the sensitivity [frame][texel].
    let (per_row, sens_row) = (planes * m * n, m * n);
    let mut src_tile = vec![0.0f32; xs.len() * per_row];
    let mut sens_tile = vec![0.0f32; xs.len() * sens_row];
    let gather = |to: &mut [f32], from: &[f32], at: usize| match stride {
        1 => to.copy_from_slice(&from[at..at + n]),
        _ => to.iter_mut().zip(&xs).for_each(|(d, &x)| *d = from[at + x]),
    };
    let row_at = |ty: usize| (tile.1 * ts + ty) * dom.pw + tile.0 * ts;
    for (j, f) in inner.iter().enumerate() {
        for (ri, &ty) in xs.iter().enumerate() {
            let to = &mut sens_tile[ri * sens_row + j * n..][..n];
            gather(to, &f.sens, row_at(ty) - inner_at);
        }
        for pl in 0..planes {
            for (ri, &ty) in xs.iter().enumerate() {
                let to = &mut src_tile[ri * per_row + (pl * m + j) * n..][..n];
                gather(to, &f.planes[pl].data, row_at(ty) - inner_at);
            }
        }
    }
    // Per plane of a row, the residual and what remains of it ([frame][texel]), z
    // ([plane][bubble][texel]) and each slot's weighted squared error
    // ([plane][slot][frame][texel]).
    let mut r = vec![0.0f64; m * n];
    let mut e = vec![0.0f64; m * n];
    let mut z = vec![0.0f64; planes * nb * n];
    let mut c = vec![0.0f64; planes * slots * m * n];
    let (mut a, mut b) = (vec![0.0f64; n], vec![0.0f64; n]);
    let (mut lut_at, mut lut_s) = (vec![0i32; n], vec![0f32; n]);
    let mut count = 0;
    for (ri, &ty) in xs.iter().enumerate() {
        let row = row_at(ty);
        let src = &src_tile[ri * per_row..(ri + 1) * per_row];
        let sens = &sens_tile[ri * sens_row..(ri + 1) * sens_row];
        for pl in 0..planes {
            for (i, &x) in xs.iter().enumerate() {
                a[i] = k0[pl].data[row + x] as f64;
                b[i] = k1[pl].data[row + x] as f64;
            }
            let src = &src[pl * m * n..(pl + 1) * m * n];
            for j in 0..m {
                let u = hat[j];
                let (rj, vj) = (&mut r[j * n..(j + 1) * n], &src[j * n..(j + 1) * n]);
                for i in 0..n {
                    rj[i] = vj[i] as f64 - (a[i] * (1.0 - u) + b[i] * u);
                }
            }
            let zp = &mut z[pl * nb * n..(pl + 1) * nb * n];
            for (k, qk) in q.iter().enumerate() {
                // As `Sum` folds: from −0, frame by frame.
                let zk = &mut zp[k * n..(k + 1) * n];
                zk.fill(-0.0);
                for (j, &qj) in qk.iter().enumerate() {
                    for (zi, &ri) in zk.iter_mut().zip(&r[j * n..(j + 1) * n]) {
                        *zi += qj * ri;
                    }
                }
            }
            let w = PLANE_WEIGHT[pl];
            let cp = &mut c[pl * slots * m * n..(pl + 1) * slots * m * n];
            // A slot's errors, [frame][texel].
            let mut slot = |cs: &mut [f64], e: &[f64]| {
                for j in 0..m {
                    let cj = &mut cs[j * n..(j + 1) * n];
                    let (ej, sj) = (&e[j * n..(j + 1) * n], &sens[j * n..(j + 1) * n]);
                    if pl == 0 {
                        // The sensitivity at the source value alone understates a large
                        // luma error: a curve that misses a jump out of the metric's
                        // saturated range (dawn under a night-set exposure) lands where
                        // the metric is steep. Take the larger of the two ends. (The
                        // lookups apart: the arithmetic around them then runs side by side.)
                        dom.sensitivity_indices(&src[j * n..(j + 1) * n], ej, &mut lut_at);
                        for ((s, &l), &own) in lut_s.iter_mut().zip(&lut_at).zip(sj) {
                            *s = own.max(dom.sensitivity_at(l as usize));
                        }
                        for ((c, &ei), &s) in cj.iter_mut().zip(ej).zip(&lut_s) {
                            *c = w * (ei * s as f64).powi(2);
                        }
                    } else {
                        for ((c, &ei), &s) in cj.iter_mut().zip(ej).zip(sj) {
                            *c = w * (ei * s as f64).powi(2);
                        }
                    }
                }
            };
            e.copy_from_slice(&r);
            if first_slot == 0 {
                slot(&mut cp[..m * n], &e);
            }
            for (k, qk) in q.iter().enumerate() {
                let zk = &zp[k * n..(k + 1) * n];
                for (j, &qj) in qk.iter().enumerate() {
                    for (ei, &zi) in e[j * n..(j + 1) * n].iter_mut().zip(zk) {
                        *ei -= zi * qj;
                    }
                }
                if k + 1 >= first_slot {
                    slot(&mut cp[(k + 1) * m * n..(k + 2) * m * n], &e);
                }
            }
        }
        // Summed texel by texel, plane by plane, as one texel at a time would: each sum
        // a chain of additions in that order, eight sums side by side.
        for (g, group) in [(0, 0..1), (1, 1..planes)] {
            for s in first_slot..slots {
                let sums = &mut err[g][s * m..(s + 1) * m];
                for (block, j0) in sums.chunks_mut(LANES).zip((0..m).step_by(LANES)) {
                    let mut acc = [0.0f64; LANES];
                    acc[..block.len()].copy_from_slice(block);
                    for i in 0..n {
                        for pl in group.clone() {
                            let cs = &c[((pl * slots + s) * m + j0) * n + i..];
                            for (l, a) in acc[..block.len()].iter_mut().enumerate() {
                                *a += cs[l * n];
                            }
                        }
                    }
                    block.copy_from_slice(&acc[..block.len()]);
                }
            }
        }
        if let Some(zs) = keep_z.as_deref_mut() {
            for i in 0..n {
                for pl in 0..planes {
                    zs.extend((0..nb).map(|k| z[(pl * nb + k) * n + i]));
                }
            }
        }
        count += n;
    }
    (err, count)
}

/// The fit error (metric units) of a candidate segment fitted with `p` (all its bubbles),
/// on every `stride`-th texel: RMS over everything, the largest per-tile RMS and the
/// largest per-frame RMS. Used to choose segment lengths.
pub fn fit_error(
    dom: &Domain,
    ts: usize,
    stride: usize,
    frames: &[&CodedFrame],
    p: &Projector,
) -> (f64, f64, f64) {
    let (tx, ty) = (dom.pw / ts, dom.ph / ts);
    let (k0, k1) = (&frames[0].planes, &frames[frames.len() - 1].planes);
    let inner = &frames[1..frames.len() - 1];
    let m = inner.len();
    let (sum, max, frames_sq, count) = (0..tx * ty)
        .into_par_iter()
        .map(|t| {
            let (err, count) = tile_errors(
                dom,
                (t % tx, t / tx),
                ts,
                stride,
                k0,
                k1,
                inner,
                0,
                p,
                false,
                None,
            );
            let all = p.bubbles * m..(p.bubbles + 1) * m;
            let pf: Vec<f64> = err[0][all.clone()]
                .iter()
                .zip(&err[1][all])
                .map(|(a, b)| a + b)
                .collect();
            let n = (count * m.max(1)) as f64;
            let ms = pf.iter().sum::<f64>() / n;
            (ms, ms, pf, count)
        })
        .reduce(
            || (0.0, 0.0, vec![0.0; m], 0),
            |a, b| {
                (
                    a.0 + b.0,
                    a.1.max(b.1),
                    a.2.iter().zip(&b.2).map(|(x, y)| x + y).collect(),
                    a.3 + b.3,
                )
            },
        );
    let worst_frame = frames_sq.iter().copied().fold(0.0, f64::max) / count.max(1) as f64;
    (
        (sum / (tx * ty) as f64).sqrt(),
        max.sqrt(),
        worst_frame.sqrt(),
    )
}

/// How far one frame's fit error in a tile may exceed the fit budget (as mean squares;
/// 1.25² is the RMS bound the segment length keeps to, `choose_length`).
const WORST_FRAME_SHARE: f64 = 1.25 * 1.25;

/// One coded segment: its tile map, the tile map's chunk payload (zstd) and the
/// coefficients' payload before its coding for the file's version (`payloads`).
pub struct SegmentCode {
    pub tiles: TileMap,
    pub tilemap_bytes: Vec<u8>,
    pub coeff_bytes: Vec<u8>,
}

#[derive(Clone, Copy)]
pub struct SegmentParams {
    pub max_degree: usize,
    /// Budget of the fit, RMS in metric units per tile.
    pub fit_budget: f64,
    /// Budget of coefficient quantisation, RMS in metric units.
    pub quant_budget: f64,
    pub chroma_step_factor: f32,
    pub deadzone: f32,
    /// Squared steps a bit is worth to the rate-aware quantiser (`rdoq`; 0: off).
    pub rate_lambda: f32,
    pub zstd_level: i32,
}

/// The inner frames of a segment over a band of padded rows (all of them, or a band).
pub struct Rows {
    /// The band's first padded row.
    pub first: usize,
    /// The inner frames, cut to the band.
    pub frames: Vec<Arc<CodedFrame>>,
}

/// What a segment is coded from: its decoded keyframes (whole), its inner frames (read a
/// band at a time through `rows`), and each inner frame's sum of squared sensitivities
/// over the whole frame (which set the quantiser steps, so they must be known before any
/// band).
pub struct SegmentInput<'a, R> {
    pub k0: &'a [Plane],
    pub k1: &'a [Plane],
    pub inner: usize,
    pub frame_sens_sq: Vec<f64>,
    /// Tile rows per band (all of them: the whole frame at once).
    pub band_tiles: usize,
    pub rows: R,
}

/// Chooses degrees and codes the bubble planes of the segment between decoded keyframes
/// `k0` and `k1`, one band of tile rows at a time. A tile's degree and coefficients are
/// its own; the quantiser steps depend on the segment's highest degree, which only the
/// last band settles, so until then each band is quantised at every highest degree still
/// possible and the streams kept sparse ([`SparseBlocks`]). With one band, there is one.
pub fn code_segment<R>(
    dom: &Domain,
    ts: usize,
    input: SegmentInput<'_, R>,
    projectors: &mut Projectors,
    sp: &SegmentParams,
) -> Result<SegmentCode, EncodeError>
where
    R: FnMut(std::ops::Range<usize>) -> Result<Rows, EncodeError>,
{
    let SegmentInput {
        k0,
        k1,
        inner: m,
        frame_sens_sq,
        band_tiles,
        mut rows,
    } = input;
    let (tx, ty) = (dom.pw / ts, dom.ph / ts);
    let planes = dom.channels;
    let len = m as u32 + 1;
    let p = projectors.get(len, sp.max_degree);
    let nb = p.bubbles;
    // Quantiser steps: a coefficient error δ costs about rms(B_k)·δ in value, and the
    // RMS sensitivity of the segment's most sensitive frame turns that into metric units
    // (`reach::segment`); the budget is shared by the dmax − 1 bubble terms of the
    // segment's highest degree.
    let sens_rms = crate::reach::segment(&frame_sens_sq, dom.pw * dom.ph).max(1e-9);
    let steps_for = |dmax: usize| -> Vec<f32> {
        let mut steps = Vec::new();
        for k in 2..=dmax {
            let brms = (1..len)
                .map(|j| vbim_format::basis::bubble(k, j as f64 / len as f64).powi(2))
                .sum::<f64>()
                .max(1e-12)
                / (len as f64 - 1.0).max(1.0);
            let base = ((12.0f64).sqrt() * sp.quant_budget
                / (sens_rms * brms.sqrt() * (dmax as f64 - 1.0).sqrt()))
                as f32;
            for pl in 0..planes {
                steps.push(if pl == 0 {
                    base
                } else {
                    base * sp.chroma_step_factor
                });
            }
        }
        steps
    };
    let top = nb + 1;
    let mut tiles = TileMap {
        luma: Vec::with_capacity(tx * ty),
        chroma: Vec::with_capacity(tx * ty),
    };
    // Streams (k, plane) for each highest degree still possible: `variants[dmax]`.
    let mut variants: Vec<Option<Vec<SparseBlocks>>> = (0..=top)
        .map(|d| (d >= 2).then(|| vec![SparseBlocks::default(); (d - 1) * planes]))
        .collect();
    let mut dmax = 1usize;
    // Bubble planes as the quantiser saw them, for `crate::tap`: (highest degree, plane).
    #[cfg(feature = "bench")]
    let mut tapped: Vec<(usize, crate::tap::TappedPlane)> = Vec::new();
    for band in (0..ty).step_by(band_tiles.max(1)) {
        let band_end = (band + band_tiles.max(1)).min(ty);
        let r = rows(band * ts..band_end * ts)?;
        debug_assert_eq!(r.first, band * ts);
        let inner: Vec<&CodedFrame> = r.frames.iter().map(|f| f.as_ref()).collect();
        let at = band * ts * dom.pw;
        // Per tile: degrees and z = Qᵀr for every texel and plane.
        let per_tile: Vec<(u8, u8, Vec<f64>)> = (band * tx..band_end * tx)
            .into_par_iter()
            .map(|t| {
                let mut zs = Vec::with_capacity(ts * ts * planes * nb);
                let (err, count) = tile_errors(
                    dom,
                    (t % tx, t / tx),
                    ts,
                    1,
                    k0,
                    k1,
                    &inner,
                    at,
                    &p,
                    true,
                    Some(&mut zs),
                );
                let (dl, dc) = choose_degrees(&err, count, m, nb, planes, sp.fit_budget);
                (dl, dc, zs)
            })
            .collect();
        tiles.luma.extend(per_tile.iter().map(|t| t.0));
        tiles.chroma.extend(per_tile.iter().map(|t| t.1));
        let band_dmax = per_tile
            .iter()
            .map(|t| t.0.max(t.1) as usize)
            .max()
            .unwrap_or(1);
        dmax = dmax.max(band_dmax);
        // Bubble planes of the band: coefficients of the chosen fit for each texel.
        let bh = (band_end - band) * ts;
        let mut bubbles: Vec<Vec<Plane>> = (2..=band_dmax)
            .map(|_| vec![Plane::zeros(dom.pw, bh); planes])
            .collect();
        for (t, (dl, dc, zs)) in per_tile.iter().enumerate() {
            let (ox, oy) = ((t % tx) * ts, (t / tx) * ts);
            let mut c = vec![0.0f64; nb];
            let mut idx = 0;
            for ty_ in 0..ts {
                for tx_ in 0..ts {
                    let i = (oy + ty_) * dom.pw + ox + tx_;
                    for pl in 0..planes {
                        let d = if pl == 0 { *dl } else { *dc } as usize - 1;
                        let z = &zs[idx * nb..idx * nb + nb];
                        idx += 1;
                        p.coeffs_from_qt(z, d, &mut c);
                        for (b, ck) in bubbles.iter_mut().zip(&c).take(d) {
                            b[pl].data[i] = *ck as f32;
                        }
                    }
                }
            }
        }
        drop(per_tile);
        // The highest degrees still possible: from here up, or (last band) the one.
        let last = band_end == ty;
        for (d, streams) in variants.iter_mut().enumerate() {
            if d < dmax || (last && d > dmax) {
                *streams = None;
            }
            let Some(streams) = streams else { continue };
            let steps = steps_for(d);
            for k in 2..=band_dmax.min(d) {
                for (pl, src) in bubbles[k - 2].iter().enumerate() {
                    let step = steps[(k - 2) * planes + pl];
                    let members: Vec<usize> = (band * tx..band_end * tx)
                        .filter(|&t| tiles.degree(pl, t) as usize >= k)
                        .collect();
                    let c: Vec<[f32; N * N]> = members
                        .par_iter()
                        .flat_map_iter(|&t| plane::tile_blocks(t, tx, ts).collect::<Vec<_>>())
                        .map(|(bx, by)| {
                            plane::coefficients(&src.read_block(bx, by - band * ts / N))
                        })
                        .collect();
                    let q = quantize(&c, step, sp.deadzone, 0.0);
                    #[cfg(feature = "bench")]
                    if crate::tap::active() {
                        tapped.push((
                            d,
                            tap_bubble(src, &members, (tx, ts, band), (k, pl), step, sp.deadzone),
                        ));
                    }
                    let s = &mut streams[(k - 2) * planes + pl];
                    match sp.rate_lambda > 0.0 {
                        // Refined once the segment's every band is in (below).
                        true => q.iter().zip(&c).for_each(|(q, c)| s.push_rated(q, c, step)),
                        false => q.iter().for_each(|b| s.push(b)),
                    }
                }
            }
        }
    }
    debug_assert_eq!(dmax, tiles.max_degree() as usize);
    #[cfg(feature = "bench")]
    for (_, p) in tapped.into_iter().filter(|(d, _)| *d == dmax) {
        crate::tap::record(p);
    }
    let steps = steps_for(dmax);
    let mut raw = vec![dmax as u8, if dmax > 1 { planes as u8 } else { 0 }, 0, 0];
    for s in &steps {
        raw.extend_from_slice(&s.to_le_bytes());
    }
    // The rate-aware quantiser prices a stream's tokens by the whole stream, so it runs
    // once every band is in: the file does not depend on where the bands fall.
    for s in variants[dmax].iter_mut().flatten() {
        if sp.rate_lambda > 0.0 {
            s.refine(sp.rate_lambda);
        }
        s.write(&mut raw);
    }
    Ok(SegmentCode {
        tilemap_bytes: zstd::bulk::compress(
            &chunk::write_tilemap(&tiles, planes as u8),
            sp.zstd_level,
        )
        .expect("zstd"),
        coeff_bytes: raw,
        tiles,
    })
}

/// A band's bubble plane `src` (term k, plane pl) as `crate::tap` records it: its member
/// tiles side by side in one row.
#[cfg(feature = "bench")]
fn tap_bubble(
    src: &Plane,
    members: &[usize],
    (tx, ts, band): (usize, usize, usize),
    (k, pl): (usize, usize),
    step: f32,
    deadzone: f32,
) -> crate::tap::TappedPlane {
    let w = members.len() * ts;
    let mut data = vec![0f32; w * ts];
    for (i, &t) in members.iter().enumerate() {
        let (ox, oy) = ((t % tx) * ts, (t / tx - band) * ts);
        for y in 0..ts {
            let row = &src.data[(oy + y) * src.w + ox..][..ts];
            data[y * w + i * ts..][..ts].copy_from_slice(row);
        }
    }
    crate::tap::TappedPlane {
        kind: crate::tap::PlaneKind::Bubble { term: k },
        plane: pl,
        w,
        h: ts,
        data,
        step,
        deadzone,
    }
}

/// The cheapest (luma, chroma) degrees within budget — on average over the segment's
/// frames, and in every frame within WORST_FRAME_SHARE of it, so that a tile's error
/// cannot gather in the one frame where the light turns — each bubble costing one plane
/// for luma and two for chroma.
fn choose_degrees(
    err: &[Vec<f64>; 2],
    count: usize,
    m: usize,
    nb: usize,
    planes: usize,
    fit_budget: f64,
) -> (u8, u8) {
    let budget = fit_budget * fit_budget * count as f64;
    let frame_err = |dl: usize, dc: usize, j: usize| {
        err[0][dl * m + j] + if planes == 3 { err[1][dc * m + j] } else { 0.0 }
    };
    let mut best = (nb + 1, nb + 1, usize::MAX);
    for dl in 0..=nb {
        for dc in 0..=dl {
            let cost = dl + 2 * dc;
            if cost >= best.2 {
                continue;
            }
            let (mut sum, mut worst) = (0.0, 0.0f64);
            for j in 0..m {
                let e = frame_err(dl, dc, j);
                sum += e;
                worst = worst.max(e);
            }
            if sum <= budget * m.max(1) as f64 && worst <= WORST_FRAME_SHARE * budget {
                best = (dl, dc, cost);
            }
        }
    }
    if best.2 == usize::MAX {
        best = (nb, if planes == 3 { nb } else { 0 }, 0);
    }
    let dc = if planes == 3 { best.1 } else { 0 };
    ((best.0 + 1) as u8, (dc + 1) as u8)
}

/// A plane's blocks (zig-zag DCT coefficients) quantised with a dead zone, then — with
/// `rate_lambda` > 0 — refined by what their bits cost at the plane's own token costs
/// (`rdoq`).
fn quantize(c: &[[f32; N * N]], step: f32, deadzone: f32, rate_lambda: f32) -> Vec<[i32; N * N]> {
    let mut q: Vec<[i32; N * N]> = c
        .par_iter()
        .map(|c| plane::quantize_coefficients(c, step, deadzone))
        .collect();
    if rate_lambda > 0.0 {
        let costs = Costs::learn(q.iter().copied());
        q.par_iter_mut().zip(c).for_each(|(q, c)| {
            let ones = crate::rdoq::ones(q, c, step);
            crate::rdoq::refine(q, &ones, &costs, rate_lambda);
        });
    }
    q
}

/// Codes a keyframe: intra, or as the difference from the previous decoded keyframe, with
/// its error `budget` (metric units) weighed at RMS sensitivity `sens_rms` (that of the
/// frames it reaches, `reach::keyframe`). Returns the payload before its coding for the
/// file's version; the caller decodes it with the reference decoder (closed loop).
/// The quantiser's step of a keyframe's plane `pl`: the budget's error at the RMS
/// sensitivity the keyframe is weighed by, chroma's scaled.
pub(crate) fn keyframe_step(budget: f64, sens_rms: f64, chroma_step_factor: f32, pl: usize) -> f32 {
    let base = ((12.0f64).sqrt() * budget / sens_rms.max(1e-9)) as f32;
    if pl == 0 {
        base
    } else {
        base * chroma_step_factor
    }
}

/// What a keyframe's plane `pl` codes: the frame's plane, or its difference from `prev`'s.
pub(crate) fn keyframe_target(src: &CodedFrame, prev: Option<&[Plane]>, pl: usize) -> Plane {
    let plane_src = &src.planes[pl];
    match prev {
        Some(p) => Plane {
            w: plane_src.w,
            h: plane_src.h,
            data: plane_src
                .data
                .iter()
                .zip(&p[pl].data)
                .map(|(a, b)| a - b)
                .collect(),
        },
        None => plane_src.clone(),
    }
}

pub fn code_keyframe(
    src: &CodedFrame,
    prev: Option<&[Plane]>,
    budget: f64,
    sens_rms: f64,
    chroma_step_factor: f32,
    deadzone: f32,
    rate_lambda: f32,
) -> Vec<u8> {
    let mut steps = Vec::new();
    let mut blocks = Vec::new();
    for pl in 0..src.planes.len() {
        let step = keyframe_step(budget, sens_rms, chroma_step_factor, pl);
        steps.push(step);
        let target = keyframe_target(src, prev, pl);
        let origins: Vec<(usize, usize)> = plane::all_blocks(&target).collect();
        let c: Vec<[f32; N * N]> = origins
            .par_iter()
            .map(|&(bx, by)| plane::coefficients(&target.read_block(bx, by)))
            .collect();
        let q = quantize(&c, step, deadzone, rate_lambda);
        blocks.push(q);
    }
    let mode = if prev.is_some() {
        chunk::MODE_PREDICTED
    } else {
        chunk::MODE_INTRA
    };
    chunk::write_keyframe(mode, &steps, &blocks)
}

#[cfg(test)]
mod tests {
    use super::*;
    use vbim_format::metrics::Metric;
    use vbim_format::Transfer;

    /// `tile_errors` as it was written first: one texel at a time, each texel's values
    /// read frame by frame. The row-wise version must give the same sums, bit for bit.
    #[allow(clippy::too_many_arguments)]
    fn one_texel_at_a_time(
        dom: &Domain,
        tile: (usize, usize),
        ts: usize,
        stride: usize,
        k0: &[Plane],
        k1: &[Plane],
        inner: &[&CodedFrame],
        inner_at: usize,
        p: &Projector,
        keep_z: &mut Vec<f64>,
    ) -> ([Vec<f64>; 2], usize) {
        let m = inner.len();
        let nb = p.bubbles;
        let len = (m + 1) as f64;
        let mut err = [vec![0.0; (nb + 1) * m], vec![0.0; (nb + 1) * m]];
        let q: Vec<Vec<f64>> = (0..nb)
            .map(|k| (0..m).map(|j| p.q[j * nb + k]).collect())
            .collect();
        let hat: Vec<f64> = (0..m).map(|j| (j + 1) as f64 / len).collect();
        let mut count = 0;
        for ty in (0..ts).step_by(stride) {
            for tx in (0..ts).step_by(stride) {
                let i = (tile.1 * ts + ty) * dom.pw + tile.0 * ts + tx;
                let bi = i - inner_at;
                count += 1;
                let sens: Vec<f32> = inner.iter().map(|f| f.sens[bi]).collect();
                for pl in 0..dom.channels {
                    let (a, b) = (k0[pl].data[i] as f64, k1[pl].data[i] as f64);
                    let src: Vec<f32> = inner.iter().map(|f| f.planes[pl].data[bi]).collect();
                    let r: Vec<f64> = (0..m)
                        .map(|j| src[j] as f64 - (a * (1.0 - hat[j]) + b * hat[j]))
                        .collect();
                    let z: Vec<f64> = q
                        .iter()
                        .map(|qk| qk.iter().zip(&r).map(|(q, r)| q * r).sum())
                        .collect();
                    let (g, w) = (pl.min(1), PLANE_WEIGHT[pl]);
                    let acc = |err: &mut [f64], e: &[f64]| {
                        for j in 0..m {
                            let s = match pl {
                                0 => sens[j].max(dom.sensitivity(src[j] - e[j] as f32)),
                                _ => sens[j],
                            };
                            err[j] += w * (e[j] * s as f64).powi(2);
                        }
                    };
                    let mut e = r.clone();
                    acc(&mut err[g][..m], &e);
                    for (k, (zk, qk)) in z.iter().zip(&q).enumerate() {
                        for (ej, qj) in e.iter_mut().zip(qk) {
                            *ej -= zk * qj;
                        }
                        acc(&mut err[g][(k + 1) * m..(k + 2) * m], &e);
                    }
                    keep_z.extend_from_slice(&z);
                }
            }
        }
        (err, count)
    }

    #[test]
    fn tile_errors_row_by_row_are_those_of_one_texel_at_a_time() {
        // HDR, so that luma's sensitivity is looked up at both ends of the error.
        let (w, h, ts) = (48, 32, 16);
        let e = 0.5;
        let transfer = Transfer::LogToe {
            v0: (2.0f32).powi(-10) / e,
        };
        let dom = Domain::new(transfer, Metric::Hdr { exposure: e }, 3, w, h, ts);
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        // Frames of smooth light with noise on top; the inner frames a band of 16 rows
        // starting at row 16.
        let mut frame = |t: f32, rows: std::ops::Range<usize>| {
            let data: Vec<f32> = rows
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .flat_map(|(x, y)| {
                    let v = 40.0 * (1.0 + (t + 0.1 * (x + y) as f32).sin());
                    [v, 0.8 * v, 0.6 * v]
                })
                .map(|v| v * (0.9 + 0.2 * next()))
                .collect();
            data
        };
        let whole = |t: f32, frame: &mut dyn FnMut(f32, std::ops::Range<usize>) -> Vec<f32>| {
            let (planes, sens) = dom.code(&frame(t, 0..h));
            CodedFrame { planes, sens }
        };
        let k0 = whole(0.0, &mut frame);
        let k1 = whole(1.0, &mut frame);
        for m in [1usize, 3, 7] {
            let inner: Vec<CodedFrame> = (1..=m)
                .map(|j| {
                    let f = whole(j as f32 / (m + 1) as f32, &mut frame);
                    let band = 16 * w..32 * w;
                    CodedFrame {
                        planes: f
                            .planes
                            .iter()
                            .map(|p| Plane {
                                w: p.w,
                                h: 16,
                                data: p.data[band.clone()].to_vec(),
                            })
                            .collect(),
                        sens: f.sens[band.clone()].to_vec(),
                    }
                })
                .collect();
            let inner: Vec<&CodedFrame> = inner.iter().collect();
            let p = Projector::new(m as u32 + 1, 4);
            for (tile, stride) in [((0, 1), 1), ((2, 1), 1), ((1, 1), 3)] {
                let mut z_rows = Vec::new();
                let mut z_one = Vec::new();
                let args = (&dom, tile, ts, stride, &k0.planes, &k1.planes);
                let rows = tile_errors(
                    args.0,
                    args.1,
                    args.2,
                    args.3,
                    args.4,
                    args.5,
                    &inner,
                    16 * w,
                    &p,
                    true,
                    Some(&mut z_rows),
                );
                let one = one_texel_at_a_time(
                    args.0,
                    args.1,
                    args.2,
                    args.3,
                    args.4,
                    args.5,
                    &inner,
                    16 * w,
                    &p,
                    &mut z_one,
                );
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(rows.1, one.1);
                for g in 0..2 {
                    assert_eq!(
                        bits(&rows.0[g]),
                        bits(&one.0[g]),
                        "m {m}, {tile:?}, group {g}"
                    );
                }
                assert_eq!(bits(&z_rows), bits(&z_one), "m {m}, {tile:?}");
                // The search's sums: slot nb alone, the same bits.
                let last = tile_errors(
                    args.0,
                    args.1,
                    args.2,
                    args.3,
                    args.4,
                    args.5,
                    &inner,
                    16 * w,
                    &p,
                    false,
                    None,
                );
                let all = p.bubbles * m..(p.bubbles + 1) * m;
                for g in 0..2 {
                    assert_eq!(bits(&last.0[g][all.clone()]), bits(&one.0[g][all.clone()]));
                }
            }
        }
    }
}
