//! `vbim bench transforms FRAMES`: what larger transforms would make of the planes the
//! encoder quantises — a research harness for the format's next coding tool, as `bench
//! entropy` was for format 2's coding.
//!
//! The frames are encoded once (format 2, `--no-aim` at the tolerance given) with the
//! encoder's tap on (`vbim_encoder::bench::tap`), which records every keyframe plane
//! (the target of the mode kept) and every bubble plane's member tiles with their steps
//! and dead zone. Each recorded plane is then transformed by an orthonormal DCT of 8 × 8
//! (what the format does), 16 × 16 or 32 × 32 blocks, or chosen per region: per 16 × 16
//! region one 16 × 16 block or four 8 × 8 ones, or a quadtree from 32 × 32 down to 8 × 8
//! (the smaller `D + λ·(R + term_bits · T)`, λ = `LAMBDA`·step², bits from the plane's
//! statistics of each size, T the terms its texels sum: `--term-bits` prices the
//! reconstruction's work), quantised with the plane's step scaled by
//! each of `--steps` and its dead zone, and coded by one adaptive model for all of them:
//! per block the DC's residual against the planar prediction (left + up − up-left) in a
//! context of its neighbours' residual sizes, the count of non-zero AC terms in a context
//! of that residual's size and whether the left and upper blocks have any, then the AC
//! terms in zig-zag order until the count is reached, each in a context of how many are
//! left and of its frequency band (for a larger block, the band of the 8 × 8 frequency it
//! scales down to); tokens are JPEG XL's hybrid-uint (16 direct, then exponent and two
//! bits, the rest raw), each context's tokens counted as they come (a Krichevsky–Trofimov
//! estimate: the ideal length of an adaptive arithmetic coder). A choice codes a flag per
//! node that could split, in a context of its size.
//!
//! Rates are compared at equal distortion: each way's bytes are fitted against its summed
//! squared error (each plane weighted as the metric weighs it) in log–log over the steps,
//! and read at the 8 × 8 blocks' error at the step as coded. The distortion is the coded
//! domain's squared error, not the metric's PSNR (the steps are uniform over a plane, so
//! the two move together). Also printed: how many terms a texel's reconstruction sums (a
//! block's non-zero terms, DC included, over the texels it covers), what the player's
//! keyframe pass (per segment) and bubble reconstruction (per displayed frame) would pay.
//!
//! With `--surface`, every keyframe block of every size is coded less the zero-mean
//! quadratic surface through its own grid's 3 × 3 decoded means (`bench intra`'s), and the
//! ratios are against today's 8 × 8 blocks without it: what the surface adds beside
//! larger blocks. With `--intra`, one more way: the quadtree as chosen, coded again closed
//! loop with its keyframes' 8 × 8 blocks free to take `bench intra`'s texel modes
//! (`intra::within_quadtree`): what texel intra adds beside larger blocks.

use std::collections::HashMap;

use rayon::prelude::*;
use vbim_encoder::bench::tap::{PlaneKind, TappedPlane};
use vbim_encoder::bench::PLANE_WEIGHT;
use vbim_format::plane2;

use super::study::{
    around, at_distortion, dc_surface, decoded_means, family, left_bucket, size_class, step_index,
    tapped_planes, token, Block, Coded, Model, Pick, Symbol, Transform,
};

use super::args::BenchTransformsArgs;

/// λ of the per-region choice, in squared steps per bit.
const LAMBDA: f64 = 0.12;

/// How a plane's blocks are chosen.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Way {
    /// Every block n × n.
    Size(usize),
    /// Per 16 × 16 region, one 16 × 16 block or four 8 × 8.
    Choice,
    /// Per 32 × 32 region, one 32 × 32 block or four regions chosen as `Choice` does.
    Quadtree,
    /// The quadtree's blocks, the 8 × 8 ones of keyframes free to take a texel mode of
    /// `bench intra` (closed loop, once the quadtree is chosen).
    QuadtreeIntra,
}

/// What every way is run with.
#[derive(Clone, Copy)]
struct Options {
    /// Bits a term a texel sums costs in the choices.
    term_bits: f64,
    /// Keyframe blocks less the quadratic surface through their neighbours' DCs.
    surface: bool,
}

impl Options {
    fn surface_on(self, p: &TappedPlane) -> bool {
        // A bubble plane's tiles lie side by side in one row: their neighbours there are
        // not the ones in the lightmap.
        self.surface && !matches!(p.kind, PlaneKind::Bubble { .. })
    }
}

/// Every way, 8 × 8 (today's) first.
const WAYS: [Way; 6] = [
    Way::Size(8),
    Way::Size(16),
    Way::Size(32),
    Way::Choice,
    Way::Quadtree,
    Way::QuadtreeIntra,
];

impl Way {
    /// The way whose bytes stand for this one's on planes it cannot code.
    fn fallback(self) -> Way {
        match self {
            Way::Quadtree | Way::QuadtreeIntra => Way::Choice,
            _ => Way::Size(8),
        }
    }

    fn label(self) -> String {
        match self {
            Way::Size(n) => format!("{n} × {n}"),
            Way::Choice => "8 or 16, per region".into(),
            Way::Quadtree => "8, 16 or 32, a quadtree".into(),
            Way::QuadtreeIntra => "the quadtree, its 8 × 8 blocks with texel intra".into(),
        }
    }
}

pub fn run(a: BenchTransformsArgs) -> Result<(), String> {
    let planes = tapped_planes(&a.study.frames, a.study.tolerance, a.study.fps)?;
    let opts = Options {
        term_bits: a.term_bits,
        surface: a.surface,
    };
    let groups: [(&str, Pick); 3] = [
        ("intra keyframes", |k| k == PlaneKind::IntraKeyframe),
        ("predicted keyframes", |k| k == PlaneKind::PredictedKeyframe),
        ("bubble planes", |k| matches!(k, PlaneKind::Bubble { .. })),
    ];
    println!(
        "transforms: {}, encoded at --tolerance {} --no-aim in format 2; bytes at the 8 × 8 \
         blocks' error (steps × {:?}), one adaptive model for every way; a term a texel sums \
         priced at {} bits in the choices{}",
        a.study.frames,
        a.study.tolerance,
        a.study.steps,
        a.term_bits,
        if a.surface {
            "; keyframe blocks less the quadratic surface through their neighbours' DCs"
        } else {
            ""
        }
    );
    println!("| planes | way | bytes at step × 1 | error | at the 8 × 8 error: bytes | ratio | terms a texel sums |");
    println!("|---|---|---:|---:|---:|---:|---:|");
    // Per way (in `WAYS`' order), the bytes of every group at each group's 8 × 8 error.
    let mut totals = [0.0; WAYS.len()];
    // Today's coding of every group (8 × 8 blocks, no surface), at its own error.
    let mut today = 0.0;
    for (name, pick) in groups {
        let set: Vec<&TappedPlane> = planes.iter().filter(|p| pick(p.kind)).collect();
        if set.is_empty() {
            continue;
        }
        // The 8 × 8 blocks' bytes on their own line and their error, at step × 1: today's
        // coding, without the surface.
        let mut base: Option<(f64, f64)> = None;
        if a.surface {
            let plain = Options {
                surface: false,
                ..opts
            };
            let points: Vec<Coded> = a
                .study
                .steps
                .iter()
                .map(|&m| code_all(&set, Way::Size(8), m, plain))
                .collect();
            let d = step_one(&a.study.steps, &points).dist;
            base = Some((at_distortion(&points, d), d));
            println!(
                "| {name} ({} planes) | 8 × 8, no surface | {:.0} | {d:.4e} | {:.0} | 1.000 | |",
                set.len(),
                step_one(&a.study.steps, &points).bytes,
                at_distortion(&points, d)
            );
        }
        let mut bytes_of = [None; WAYS.len()];
        for (w, way) in WAYS.into_iter().enumerate() {
            if set
                .iter()
                .any(|p| p.w % block_of(way) != 0 || p.h % block_of(way) != 0)
                || (way == Way::QuadtreeIntra && !a.intra)
            {
                continue;
            }
            let points: Vec<Coded> = a
                .study
                .steps
                .iter()
                .map(|&m| code_all(&set, way, m, opts))
                .collect();
            let at1 = step_one(&a.study.steps, &points);
            let (b8, d8) =
                *base.get_or_insert_with(|| (at_distortion(&points, at1.dist), at1.dist));
            let bytes = at_distortion(&points, d8);
            bytes_of[w] = Some(bytes);
            println!(
                "| {name} ({} planes) | {} | {:.0} | {:.4e} | {:.0} | {:.3} | {:.2} |",
                set.len(),
                way.label(),
                at1.bytes,
                at1.dist,
                bytes,
                bytes / b8,
                at1.terms / at1.texels
            );
        }
        // A way that cannot code these planes counts them as its fallback codes them (a
        // quadtree's bubble planes of 16-texel tiles: as the choice).
        for (w, way) in WAYS.into_iter().enumerate() {
            let fallback = WAYS.iter().position(|&f| f == way.fallback());
            if w == 0 {
                today += base.map_or(0.0, |(b8, _)| b8);
            }
            totals[w] += bytes_of[w]
                .or(fallback.and_then(|f| bytes_of[f]))
                .unwrap_or(0.0);
        }
    }
    for (w, way) in WAYS.into_iter().enumerate() {
        let shown = match way {
            Way::QuadtreeIntra => a.intra,
            Way::Size(8) | Way::Size(32) => a.surface,
            _ => true,
        };
        if shown {
            println!(
                "every plane, {}{}: {:.0} bytes against {today:.0} in 8 × 8 blocks, {:.3}",
                way.label(),
                if a.surface { " with the surface" } else { "" },
                totals[w],
                totals[w] / today
            );
        }
    }
    Ok(())
}

/// The point coded at step × 1 (the first if 1 is not among the steps).
fn step_one<'a>(steps: &[f32], points: &'a [Coded]) -> &'a Coded {
    &points[step_index(steps)]
}

fn block_of(way: Way) -> usize {
    match way {
        Way::Size(n) => n,
        Way::Choice => 16,
        Way::Quadtree | Way::QuadtreeIntra => 32,
    }
}

/// Every plane of `set` coded `way` with its step × `mult`.
fn code_all(set: &[&TappedPlane], way: Way, mult: f32, opts: Options) -> Coded {
    // Per plane, the blocks in coding order (their contexts already family-tagged).
    let coded: Vec<(f64, Vec<Block>)> = set
        .par_iter()
        .map(|p| {
            let family = family(p);
            let step = p.step * mult;
            let blocks = match way {
                Way::Size(n) => tag(quantise_plane(p, n, step, opts.surface_on(p)), family, n),
                Way::Choice => choose(p, step, family, &[8, 16], opts),
                Way::Quadtree | Way::QuadtreeIntra => choose(p, step, family, &[8, 16, 32], opts),
            };
            (PLANE_WEIGHT[p.plane.min(2)], blocks)
        })
        .collect();
    let mut model = Model::default();
    let mut out = Coded::default();
    for ((weight, blocks), p) in coded.iter().zip(set) {
        if way == Way::QuadtreeIntra && !matches!(p.kind, PlaneKind::Bubble { .. }) {
            let (dist, bits, _, _) =
                super::intra::within_quadtree(p, p.step * mult, family(p), blocks, &mut model);
            out.dist += weight * dist;
            out.bytes += bits / 8.0;
        } else {
            for b in blocks {
                out.dist += weight * b.dist;
                for &(ctx, v) in &b.symbols {
                    out.bytes += model.code(ctx, v) / 8.0;
                }
            }
        }
        // (A texel mode's block counts the terms the quadtree gave it.)
        out.terms += blocks
            .iter()
            .map(|b| b.terms as f64 * b.area as f64)
            .sum::<f64>();
        out.texels += (p.w * p.h) as f64;
    }
    out
}

/// Tags the block-local contexts with the family and the block size (top bits), so that
/// each (family, size) learns its own statistics.
fn tag(blocks: Vec<Block>, family: u32, n: usize) -> Vec<Block> {
    let size = match n {
        16 => 1,
        32 => 2,
        _ => 0,
    };
    blocks
        .into_iter()
        .map(|mut b| {
            for s in &mut b.symbols {
                s.0 |= (size << 28) | (family << 20);
            }
            b
        })
        .collect()
}

/// A plane's n × n blocks quantised and turned into symbols, in raster order; with
/// `surface`, each block less the zero-mean quadratic surface through its 3 × 3 blocks'
/// decoded means (`study::dc_surface`), which leaves its DC as it was.
fn quantise_plane(p: &TappedPlane, n: usize, step: f32, surface: bool) -> Vec<Block> {
    let (bw, bh) = (p.w / n, p.h / n);
    let t = Transform::new(n);
    let source = |b: usize| -> Vec<f64> {
        let (bx, by) = (b % bw, b / bw);
        (0..n * n)
            .map(|i| p.data[(by * n + i / n) * p.w + bx * n + i % n] as f64)
            .collect()
    };
    let step = step as f64;
    let means = if surface {
        decoded_means(p, n, step)
    } else {
        Vec::new()
    };
    let q: Vec<(Vec<i32>, f64)> = (0..bw * bh)
        .map(|b| {
            let mut block = source(b);
            if surface {
                let m = around(&means, (bw, bh), (b % bw, b / bw));
                for (v, s) in block.iter_mut().zip(dc_surface(n, &m, true)) {
                    *v -= s;
                }
            }
            t.quantise(&block, step, p.deadzone as f64)
        })
        .collect();
    let dc: Vec<i32> = q.iter().map(|(c, _)| c[0]).collect();
    let count: Vec<u32> = q
        .iter()
        .map(|(c, _)| c[1..].iter().filter(|&&v| v != 0).count() as u32)
        .collect();
    let at = |x: isize, y: isize, v: &[i32]| -> i32 {
        if x < 0 || y < 0 {
            0
        } else {
            v[y as usize * bw + x as usize]
        }
    };
    let residual: Vec<i32> = (0..bw * bh)
        .map(|b| {
            let (x, y) = ((b % bw) as isize, (b / bw) as isize);
            dc[b] - (at(x - 1, y, &dc) + at(x, y - 1, &dc) - at(x - 1, y - 1, &dc))
        })
        .collect();
    (0..bw * bh)
        .map(|b| {
            let (x, y) = ((b % bw) as isize, (b / bw) as isize);
            let (coefs, dist) = &q[b];
            let r = residual[b];
            let near = |f: &dyn Fn(isize, isize) -> u32| f(x - 1, y) + f(x, y - 1);
            let size_at = |x: isize, y: isize| -> u32 {
                if x < 0 || y < 0 {
                    0
                } else {
                    size_class(residual[y as usize * bw + x as usize])
                }
            };
            let busy_at = |x: isize, y: isize| -> u32 {
                (x >= 0 && y >= 0 && count[y as usize * bw + x as usize] > 0) as u32
            };
            let mut symbols = vec![
                (near(&size_at).min(3), plane2::pack(r)),
                (10 + size_class(r) * 3 + near(&busy_at), count[b]),
            ];
            let mut left = count[b];
            for (i, &v) in coefs.iter().enumerate().skip(1) {
                if left == 0 {
                    break;
                }
                symbols.push((100 + left_bucket(left) * 12 + t.band[i], plane2::pack(v)));
                left -= (v != 0) as u32;
            }
            Block {
                dist: *dist,
                terms: count[b] + (coefs[0] != 0) as u32,
                area: n * n,
                symbols,
                place: (n, b % bw, b / bw),
                coefs: coefs.clone(),
            }
        })
        .collect()
}

/// One size of a quadtree: its blocks (taken as they are chosen), each one's cost, and the
/// width of its grid.
type Level = (Vec<Option<Block>>, Vec<f64>, usize);

/// A quadtree over the sizes `sizes` (smallest first, each twice the one before): per
/// region of the largest size, the block of that size or its four quarters, each chosen
/// the same way down to the smallest, by the smaller `D + λ·(R + term_bits · T)`: each
/// symbol's bits from the plane's own statistics of its size, T the terms the block's
/// texels sum in units of an 8 × 8 block's (its non-zero terms times its area over 64),
/// so that `term_bits` prices the reconstruction's work. Every node that could split codes
/// whether it did, in a context of its size, before the first block under it. (The DC
/// residuals and neighbour contexts of each size are those of its own grid, as if the
/// whole plane had that size: the study's approximation of a mixed grid.)
fn choose(p: &TappedPlane, step: f32, family: u32, sizes: &[usize], opts: Options) -> Vec<Block> {
    let term_bits = opts.term_bits;
    let lambda = LAMBDA * (step as f64).powi(2);
    // Per size: its blocks (taken as chosen), their costs J, and its grid's width.
    let mut levels: Vec<Level> = sizes
        .iter()
        .map(|&n| {
            let blocks = tag(quantise_plane(p, n, step, opts.surface_on(p)), family, n);
            let costs = static_costs(&blocks);
            let j = blocks
                .iter()
                .map(|b| {
                    let bits: f64 = b.symbols.iter().map(|s| costs[s]).sum();
                    let terms = b.terms as f64 * b.area as f64 / 64.0;
                    b.dist + lambda * (bits + term_bits * terms)
                })
                .collect();
            (blocks.into_iter().map(Some).collect(), j, p.w / n)
        })
        .collect();
    // The best cost of cell (x, y) of level l, and how it is coded: the blocks (level,
    // index) in order, each after the split flags (level, split) of the nodes opened
    // since the block before.
    fn best(levels: &[Level], l: usize, x: usize, y: usize) -> (f64, Vec<Coding>) {
        let (_, j, w) = &levels[l];
        if l == 0 {
            return (j[y * w + x], vec![Coding::Block(l, y * w + x)]);
        }
        let own = (
            j[y * w + x],
            vec![Coding::Flag(l, 0), Coding::Block(l, y * w + x)],
        );
        let mut split = (0.0, vec![Coding::Flag(l, 1)]);
        for i in 0..4 {
            let (c, picks) = best(levels, l - 1, 2 * x + i % 2, 2 * y + i / 2);
            split.0 += c;
            split.1.extend(picks);
        }
        if own.0 <= split.0 {
            own
        } else {
            split
        }
    }
    let top = sizes.len() - 1;
    let (tw, th) = (levels[top].2, p.h / sizes[top]);
    let mut out = Vec::new();
    for r in 0..tw * th {
        let (_, picks) = best(&levels, top, r % tw, r / tw);
        let mut flags = Vec::new();
        for pick in picks {
            match pick {
                Coding::Flag(l, split) => {
                    flags.push(((3 << 28) | (family << 20) | l as u32, split));
                }
                Coding::Block(l, i) => {
                    let mut b = levels[l].0[i].take().expect("each block picked once");
                    b.symbols.splice(0..0, flags.drain(..));
                    out.push(b);
                }
            }
        }
    }
    out
}

/// One step of a quadtree's coding: a node's split flag (its level, 1 if split), or a
/// block (its level and index in that level's grid).
enum Coding {
    Flag(usize, u32),
    Block(usize, usize),
}

/// Each symbol's ideal length in bits under its context's own statistics over `blocks`.
fn static_costs(blocks: &[Block]) -> HashMap<Symbol, f64> {
    let mut count: HashMap<(u32, u32), f64> = HashMap::new();
    let mut total: HashMap<u32, f64> = HashMap::new();
    for s in blocks.iter().flat_map(|b| &b.symbols) {
        let (tok, _) = token(s.1);
        *count.entry((s.0, tok)).or_default() += 1.0;
        *total.entry(s.0).or_default() += 1.0;
    }
    let mut out = HashMap::new();
    for s in blocks.iter().flat_map(|b| &b.symbols) {
        let (tok, raw) = token(s.1);
        out.entry(*s)
            .or_insert_with(|| -(count[&(s.0, tok)] / total[&s.0]).log2() + raw as f64);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const FREE: Options = Options {
        term_bits: 0.0,
        surface: false,
    };

    use crate::bench::study::test_plane as plane;

    #[test]
    fn the_transforms_keep_energy_and_a_fine_step_keeps_the_block() {
        for n in [8, 16, 32] {
            let t = Transform::new(n);
            let block: Vec<f64> = (0..n * n)
                .map(|i| ((i * 7919) % 101) as f64 / 10.0)
                .collect();
            let energy: f64 = block.iter().map(|v| v * v).sum();
            let (q, dist) = t.quantise(&block, 1e-4, 0.0);
            let coded: f64 = q.iter().map(|&v| (v as f64 * 1e-4).powi(2)).sum();
            assert!(
                (coded - energy).abs() < 1e-3 * energy,
                "{n}: {coded} against {energy}"
            );
            assert!(dist < 1e-6 * n as f64 * n as f64);
            assert_eq!(t.band.len(), n * n);
            assert_eq!(t.band[0], 0);
        }
    }

    #[test]
    fn a_smooth_plane_costs_fewer_bytes_in_larger_blocks_at_equal_error() {
        // A gentle curved ramp with a little texture: what a keyframe's sky-lit slopes are.
        let p = plane(128, 128, |x, y| {
            let (u, v) = (x as f32 / 128.0, y as f32 / 128.0);
            3.0 * u + 2.0 * v * v + 0.02 * ((x * 13 + y * 7) % 5) as f32
        });
        let set = [&p];
        let steps = [0.8, 1.0, 1.25, 1.6];
        let curve = |way| {
            steps
                .iter()
                .map(|&m| code_all(&set, way, m, FREE))
                .collect::<Vec<_>>()
        };
        let small = curve(Way::Size(8));
        let large = curve(Way::Size(16));
        let chosen = curve(Way::Choice);
        let d8 = small[1].dist;
        assert!(at_distortion(&large, d8) < 0.9 * small[1].bytes);
        assert!(at_distortion(&chosen, d8) < 0.95 * small[1].bytes);
        // Larger blocks sum more terms a texel.
        assert!(large[1].terms / large[1].texels > small[1].terms / small[1].texels);
        let quad = curve(Way::Quadtree);
        assert!(at_distortion(&quad, d8) < 0.95 * small[1].bytes);
    }

    #[test]
    fn the_surface_takes_a_bend_out_of_small_blocks_and_leaves_bubble_planes_alone() {
        let mut p = plane(128, 128, |x, y| {
            let (u, v) = (x as f32 / 128.0, y as f32 / 128.0);
            4.0 * u * u + 2.0 * v * v + 0.01 * ((x * 13 + y * 7) % 5) as f32
        });
        let with = Options {
            term_bits: 0.0,
            surface: true,
        };
        let plain = code_all(&[&p], Way::Size(8), 1.0, FREE);
        let surfaced = code_all(&[&p], Way::Size(8), 1.0, with);
        assert!(
            surfaced.bytes < 0.95 * plain.bytes,
            "{} against {}",
            surfaced.bytes,
            plain.bytes
        );
        p.kind = PlaneKind::Bubble { term: 2 };
        let plain = code_all(&[&p], Way::Size(8), 1.0, FREE);
        let surfaced = code_all(&[&p], Way::Size(8), 1.0, with);
        assert_eq!(surfaced.bytes, plain.bytes);
    }

    #[test]
    fn texel_intra_beside_the_quadtree_codes_stripes_in_fewer_bytes() {
        // Vertical stripes a texel wide, of random heights, with the terms priced so that
        // the quadtree keeps 8 × 8 blocks: the vertical mode continues them.
        let col = |x: usize| ((x * 2_654_435_761) % 97) as f32 / 20.0;
        let p = plane(64, 64, |x, _| col(x));
        let small = Options {
            term_bits: 64.0,
            surface: false,
        };
        let quad = code_all(&[&p], Way::Quadtree, 1.0, small);
        let intra = code_all(&[&p], Way::QuadtreeIntra, 1.0, small);
        assert!(
            intra.bytes < 0.8 * quad.bytes,
            "{} against {}",
            intra.bytes,
            quad.bytes
        );
        assert!(
            intra.dist <= 1.5 * quad.dist,
            "{} against {}",
            intra.dist,
            quad.dist
        );
    }

    #[test]
    fn texel_intra_beside_the_quadtree_counts_the_error_it_reconstructs() {
        // Ramps, edges and texture, so that every size and several modes are taken.
        let p = plane(128, 96, |x, y| {
            let edge = if 2 * x + y > 150 { 1.0 } else { 0.1 };
            edge + 0.02 * x as f32 + 0.3 * ((x * 7 + y * 13) % 11) as f32 / 11.0
        });
        for step in [0.02, 0.1] {
            let blocks = choose(&p, step, 0, &[8, 16, 32], FREE);
            let sizes: Vec<usize> = blocks.iter().map(|b| b.place.0).collect();
            let (dist, _, taken, recon) =
                super::super::intra::within_quadtree(&p, step, 0, &blocks, &mut Model::default());
            let seen: f64 = recon
                .iter()
                .zip(&p.data)
                .map(|(r, &s)| (r - s as f64).powi(2))
                .sum();
            assert!(
                (seen - dist).abs() <= 1e-6 * seen,
                "at {step}: {seen} against {dist}"
            );
            assert!(
                taken > 0 && sizes.contains(&16),
                "at {step}: {taken} {sizes:?}"
            );
        }
    }

    #[test]
    fn pricing_the_terms_picks_smaller_blocks() {
        // A ramp with a sharp shadow edge: large blocks win the ramp, lose at the edge.
        let p = plane(128, 128, |x, y| {
            let edge = if x + y / 2 > 70 { 1.0 } else { 0.2 };
            edge + 0.01 * x as f32 + 0.005 * y as f32
        });
        let terms = |bits| {
            let c = code_all(
                &[&p],
                Way::Quadtree,
                1.0,
                Options {
                    term_bits: bits,
                    surface: false,
                },
            );
            c.terms / c.texels
        };
        let free = terms(0.0);
        let priced = terms(64.0);
        let small = code_all(&[&p], Way::Size(8), 1.0, FREE);
        assert!(priced < free, "{priced} against {free}");
        assert!(priced <= free.min(small.terms / small.texels * 1.5));
    }
}
