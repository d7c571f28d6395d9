//! The decode and hold passes on a real adapter, against the reference decoder.

use vbim_format::chunk::Scanned;
use vbim_format::plane::{self, Blocks, Onto, Plane};

use super::plan::{groups_offset, lightmap_descriptor, REGION};
use super::*;
use crate::coded::{Coded, PlaneSpan};
use crate::decoder::{KeyStep, SegmentData};
use crate::readback::{read_buffer, read_texture_layer};

/// A GPU's decode shape (the wide parse, groups split among workgroups) or a CPU
/// adapter's, on the tests' adapter.
pub(super) fn shape(gpu: bool) -> crate::DecodeShape {
    if gpu {
        crate::DecodeShape::GPU
    } else {
        crate::DecodeShape::CPU
    }
}

pub(super) fn random_blocks(n: usize, seed: &mut u32) -> Vec<[i32; 64]> {
    let mut next = || {
        *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        *seed >> 8
    };
    (0..n)
        .map(|_| {
            let mut q = [0i32; 64];
            let density = [0, 0, 1, 1, 2, 9, 40][(next() % 7) as usize];
            for _ in 0..density {
                let v = (next() % 2001) as i32 - 1000;
                q[(next() % 64) as usize] = if next() % 5 == 0 { v * 4001 } else { v / 100 };
            }
            q
        })
        .collect()
}

/// A stream of `blocks` scanned and appended to `c` (with `members`, as a bubble
/// plane's).
pub(super) fn coded_plane(
    c: &mut Coded,
    step: f32,
    blocks: &[[i32; 64]],
    members: Option<(usize, &dyn Fn(usize) -> bool)>,
) -> (PlaneSpan, Blocks) {
    let mut raw = Vec::new();
    plane::write_coefficients(blocks, &mut raw);
    let mut entries = Vec::new();
    let ac = vbim_format::chunk::scan(&raw, &mut 0, blocks.len(), &mut entries).unwrap();
    let s = Scanned {
        stream: &raw,
        entries: &entries,
        blocks: blocks.len(),
        ac,
    };
    let mut parsed = Blocks::default();
    plane::read_blocks(&raw, &mut 0, blocks.len(), &mut parsed).unwrap();
    (c.push_plane(step, s, members), parsed)
}

/// The reference decoder's bubble plane of `pw × ph` texels from `parsed`, the blocks of
/// the tiles of `ts`² texels that `member` keeps, in rank order (zeros elsewhere).
pub(super) fn bubble_reference(
    parsed: &Blocks,
    member: &dyn Fn(usize) -> bool,
    (pw, ph, ts): (u32, u32, usize),
    step: f32,
) -> Plane {
    let tiles_x = pw as usize / ts;
    let tiles = tiles_x * (ph as usize / ts);
    let per2 = (ts / 8) * (ts / 8);
    let mut want = Plane::zeros(pw as usize, ph as usize);
    for (rank, t) in (0..tiles).filter(|&t| member(t)).enumerate() {
        let at = plane::tile_blocks(t, tiles_x, ts);
        plane::add_blocks_of(&mut want, at, Onto::Zeros, parsed, rank * per2, step);
    }
    want
}

/// Decodes the plane at `span` of `data` as a segment's one bubble plane (term 2 of a
/// one-channel stream, no keyframe step) into bubble set 0.
pub(super) fn decode_bubble_plane(gpu: &mut Gpu, data: Coded, span: PlaneSpan) {
    let mut seg = SegmentData::new();
    seg.steps = Vec::new();
    seg.planes = vec![span, span];
    seg.bubbles = 1;
    seg.data = data;
    seg.layers = 3;
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    gpu.decode(&mut enc, &seg, true);
    gpu.queue.submit([enc.finish()]);
}

/// Decodes one keyframe step (plane 0 of a one-channel stream) onto the head; returns
/// each dispatch's pass and work ([`Gpu::decode`]).
pub(super) fn decode_key_step(
    gpu: &mut Gpu,
    number: usize,
    span: PlaneSpan,
    data: Coded,
) -> Vec<(&'static str, u64)> {
    let mut seg = SegmentData::new();
    seg.steps = vec![KeyStep {
        number,
        intra: number == 0,
        plane: 0,
    }];
    seg.planes = vec![span];
    seg.bubbles = 1;
    seg.data = data;
    seg.layers = 2;
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let dispatches = gpu.decode(&mut enc, &seg, false);
    gpu.queue.submit([enc.finish()]);
    dispatches
}

/// The head keyframe's plane 0 matches `want` within 1e-5 of its peak.
fn assert_head_matches(gpu: &Gpu, want: &Plane, what: &str) {
    let raw = read_texture_layer(&gpu.device, &gpu.queue, &gpu.keys, 4, 0);
    let got: &[f32] = bytemuck::cast_slice(&raw);
    let peak = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
    for (i, (g, w)) in got.iter().zip(&want.data).enumerate() {
        assert!(
            (g - w).abs() <= 1e-5 * peak,
            "{what}, texel {i}: GPU {g} against {w}"
        );
    }
}

/// A smooth plane whose DC repeats for hundreds of blocks: the scan cuts the runs into
/// pieces of `FILL_BLOCKS`, each parsed on its own, and the GPU's keyframe is the
/// reference decoder's, in one part and in parts, by either parse.
#[test]
fn long_runs_of_equal_dc_parsed_in_pieces_match_the_reference() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (pw, ph) = (512u32, 128u32);
    let n = (pw as usize / 8) * (ph as usize / 8);
    let blocks: Vec<[i32; 64]> = (0..n)
        .map(|b| {
            let mut q = [0i32; 64];
            q[0] = if b < 600 { 40 } else { -9 };
            if b % 97 == 0 {
                q[3] = 5;
            }
            q
        })
        .collect();
    for (part, wide) in [
        (None, false),
        (Some(100), false),
        (None, true),
        (Some(100), true),
    ] {
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, 16);
        gpu.set_decode_shape(shape(wide));
        if let Some(p) = part {
            gpu.part = p;
            gpu.bind_decode();
        }
        let mut c = Coded::default();
        let (span, parsed) = coded_plane(&mut c, 0.01, &blocks, None);
        // One piece by the pairs, three more inside the two runs of 599 and 423
        // blocks (every 256 blocks written).
        assert_eq!(span.count, 4, "entry points");
        let mut want = Plane::zeros(pw as usize, ph as usize);
        let bw = pw as usize / 8;
        let at = (0..n).map(|b| (b % bw, b / bw));
        plane::add_blocks_of(&mut want, at, Onto::Plane, &parsed, 0, 0.01);
        decode_key_step(&mut gpu, 0, span, c);
        assert_head_matches(&gpu, &want, &format!("parts {part:?}, GPU shape {wide}"));
    }
}

/// Both parses write exactly the stream's coefficients into the dense plane (values,
/// masks and sets) on a plane of hundreds of pieces: dense and empty blocks, values of
/// every varint length up to five bytes, long runs of equal DC that the scan cuts (of a
/// zero DC and not), and a last piece that ends in a run to the plane's end.
#[test]
fn both_parses_write_every_coefficient_of_a_large_random_plane() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (pw, ph) = (4096u32, 256u32);
    let n = (pw as usize / 8) * (ph as usize / 8);
    let mut seed = 5u32;
    let mut blocks = random_blocks(n, &mut seed);
    for (b, q) in blocks.iter_mut().enumerate() {
        match b {
            // Long runs of one DC: not zero, then zero, then not zero again.
            1000..1900 => *q = [0; 64],
            1900..2400 => {
                *q = [0; 64];
                q[0] = -(1 << 29);
            }
            2400..3000 => *q = [0; 64],
            // Five-byte varints, and the largest runs' neighbours.
            _ if b % 211 == 0 => {
                q[0] = i32::MAX / 3;
                q[63] = -(1 << 30);
            }
            _ => {}
        }
        if (1000..1900).contains(&b) {
            q[0] = 77;
        }
    }
    // The last blocks empty: the stream ends in a zero run to the plane's end.
    for q in &mut blocks[n - 300..] {
        *q = [0; 64];
    }
    for wide in [false, true] {
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, 16);
        gpu.set_decode_shape(shape(wide));
        let mut c = Coded::default();
        let (span, _) = coded_plane(&mut c, 0.01, &blocks, None);
        assert!(span.count > 400, "{} pieces", span.count);
        decode_key_step(&mut gpu, 0, span, c);
        let coefs = read_buffer(&gpu.device, &gpu.queue, &gpu.coefs);
        let coefs: &[i32] = bytemuck::cast_slice(&coefs);
        let masks = read_buffer(&gpu.device, &gpu.queue, &gpu.masks);
        let masks: &[u32] = bytemuck::cast_slice(&masks);
        let sets = &masks[groups_offset(gpu.part) as usize / 4..];
        for (d, q) in blocks.iter().enumerate() {
            let mask = masks[2 * d] as u64 | (masks[2 * d + 1] as u64) << 32;
            for (f, &v) in q.iter().enumerate() {
                let set = mask >> f & 1 == 1;
                assert_eq!(
                    set,
                    v != 0,
                    "GPU shape {wide}, block {d}, coefficient {f}: mask"
                );
                if set {
                    let got = coefs[d * 64 + f];
                    assert_eq!(got, v, "GPU shape {wide}, block {d}, coefficient {f}");
                }
            }
            let marked = sets[d / 32] >> (d % 32) & 1 == 1;
            assert_eq!(marked, mask != 0, "GPU shape {wide}, block {d}: set");
        }
    }
}

/// The keyframe passes on a real adapter: an intra keyframe, then a predicted one
/// built on it, against the reference decoder's block kernel; the first, packed into
/// the previous keyframe, within half a 16-bit step of its region's range. With the
/// plane whole in the dense plane, and in parts of 7 blocks (as an 8192² plane goes
/// in two).
#[test]
fn keyframe_passes_match_the_reference_kernel() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (pw, ph) = (96u32, 32u32);
    let (bw, bh) = (pw as usize / 8, ph as usize / 8);
    for (part, wide) in [
        (None, false),
        (Some(7), false),
        (None, true),
        (Some(7), true),
    ] {
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, 16);
        gpu.set_decode_shape(shape(wide));
        if let Some(p) = part {
            gpu.part = p;
            gpu.bind_decode();
        }
        let mut seed = 3;
        let mut want = Plane::zeros(pw as usize, ph as usize);
        let mut first = None;
        for (n, step) in [(0usize, 0.01f32), (1, 0.002)] {
            if n == 1 {
                first = Some(want.clone());
            }
            let blocks = random_blocks(bw * bh, &mut seed);
            let mut c = Coded::default();
            let (span, parsed) = coded_plane(&mut c, step, &blocks, None);
            let at = (0..bh).flat_map(|y| (0..bw).map(move |x| (x, y)));
            plane::add_blocks_of(&mut want, at, Onto::Plane, &parsed, 0, step);
            decode_key_step(&mut gpu, n, span, c);
        }
        assert_head_matches(&gpu, &want, &format!("parts {part:?}, GPU shape {wide}"));
        // The previous keyframe: 16-bit steps of each 32² region's range.
        let first = first.expect("two steps");
        let raw = read_texture_layer(&device, &queue, &gpu.packed, 4, 0);
        let q: &[u16] = bytemuck::cast_slice(&raw);
        let (w, rs) = (pw as usize, REGION as usize);
        for ry in 0..(ph as usize).div_ceil(rs) {
            for rx in 0..w.div_ceil(rs) {
                let at = |i: usize| (ry * rs + i / rs, rx * rs + i % rs);
                let inside = (0..rs * rs)
                    .map(at)
                    .filter(|&(y, x)| y < ph as usize && x < w);
                let vals: Vec<f32> = inside.clone().map(|(y, x)| first.data[y * w + x]).collect();
                let lo = vals.iter().fold(f32::INFINITY, |m, &v| m.min(v));
                let hi = vals.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
                let step = (hi - lo) / 65535.0;
                for ((y, x), v) in inside.zip(vals) {
                    let g = lo + q[y * w + x] as f32 * step;
                    assert!(
                        (g - v).abs() <= 0.5001 * step + 1e-6 * hi.abs().max(lo.abs()),
                        "previous keyframe at ({x}, {y}): {g} against {v} (step {step})"
                    );
                }
            }
        }
    }
}

/// Layer `layer` of bubble set 0, of quantiser step `step`, as the reconstruction sums it
/// (reconstruct.wgsl, `bubble_plane`): each block's mask, first term and the rest from
/// the set's terms (16-bit integers two to a word times the step, or f32 where the start's
/// top bit says so), (c · T[ky][y]) · T[kx][x] in increasing zig-zag order, over a plane
/// of `pw × ph`.
pub(super) fn summed_bubble_layer(
    gpu: &Gpu,
    layer: u32,
    (pw, ph): (u32, u32),
    step: f32,
) -> Vec<f32> {
    let raw = read_texture_layer(&gpu.device, &gpu.queue, &gpu.bubble_blocks, 16, layer);
    let blocks: &[[u32; 4]] = bytemuck::cast_slice(&raw);
    let terms = read_buffer(&gpu.device, &gpu.queue, &gpu.terms[0]);
    let terms: &[u32] = bytemuck::cast_slice(&terms);
    let (t, zz) = (vbim_format::dct::basis(), vbim_format::dct::zigzag());
    let mut out = vec![0f32; (pw * ph) as usize];
    for (i, out) in out.iter_mut().enumerate() {
        let (x, y) = (i % pw as usize, i / pw as usize);
        let [lo, hi, rest, first] = blocks[(y / 8) * (pw as usize / 8) + x / 8];
        let (wide, start) = (rest >> 31 == 1, (rest & 0x7FFF_FFFF) as usize);
        let bits = (0..64).filter(|&b| (lo as u64 | (hi as u64) << 32) >> b & 1 == 1);
        let mut sum = 0f32;
        for (j, b) in bits.enumerate() {
            let c = match (j, wide) {
                (0, _) => f32::from_bits(first),
                (j, true) => f32::from_bits(terms[start + j - 1]),
                (j, false) => {
                    let w = terms[start + (j - 1) / 2] >> (16 * ((j - 1) % 2));
                    (w as u16 as i16) as f32 * step
                }
            };
            let pos = zz[b];
            sum += (c * t[pos / 8][y % 8]) * t[pos % 8][x % 8];
        }
        *out = sum;
    }
    out
}

/// The texels of `got` in member tiles (of `ts`² texels, `pw` texels across) match
/// `want` within 1e-5 of its peak; `what` names the case.
pub(super) fn assert_members_match(
    got: &[f32],
    want: &Plane,
    member: &dyn Fn(usize) -> bool,
    (pw, ts): (u32, usize),
    what: &str,
) {
    let tiles_x = pw as usize / ts;
    let peak = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
    for (i, (g, w)) in got.iter().zip(&want.data).enumerate() {
        let (x, y) = (i % pw as usize, i / pw as usize);
        if !member((y / ts) * tiles_x + x / ts) {
            continue;
        }
        assert!(
            (g - w).abs() <= 1e-5 * peak,
            "{what}, texel ({x}, {y}): GPU {g} against {w}"
        );
    }
}

/// A bubble plane as the reconstruction sums it matches the reference decoder's within
/// f32 rounding: tiles of columns 2–3 are not members, the plane is whole or in parts of
/// 7 blocks, and the terms of blocks with many (up to 40) go to the set's term buffer.
#[test]
fn bubble_blocks_sum_to_the_reference_plane() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (pw, ph, ts) = (96u32, 32u32, 16usize);
    let tiles_x = pw as usize / ts;
    let tiles = tiles_x * (ph as usize / ts);
    let member = |t: usize| !(2..4).contains(&(t % tiles_x));
    let members = (0..tiles).filter(|&t| member(t)).count();
    let per2 = (ts / 8) * (ts / 8);
    let blocks = random_blocks(members * per2, &mut 11);
    let step = 0.004;
    for (part, wide) in [
        (None, false),
        (Some(8), false),
        (None, true),
        (Some(8), true),
    ] {
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, ts as u32);
        gpu.set_decode_shape(shape(wide));
        if let Some(p) = part {
            gpu.part = p;
            gpu.bind_decode();
        }
        let mut c = Coded::default();
        // A keyframe plane before it, so that the bubble plane's offsets are not 0.
        coded_plane(&mut c, 1.0, &random_blocks(4, &mut 5), None);
        let (span, parsed) = coded_plane(&mut c, step, &blocks, Some((tiles, &member)));
        let want = bubble_reference(&parsed, &member, (pw, ph, ts), step);
        decode_bubble_plane(&mut gpu, c, span);
        let got = summed_bubble_layer(&gpu, 0, (pw, ph), step);
        let what = format!("parts {part:?}, GPU shape {wide}");
        assert_members_match(&got, &want, &member, (pw, ts), &what);
    }
}

/// A segment's bubble planes whose blocks fit the dense plane together are parsed and
/// gathered in batches, a dispatch covering each batch's planes (`workgroup_id.z`), each
/// at its own place in the dense plane and the ring of masks: every plane's layer sums
/// to its reference, with the dense plane whole (one plane alone, then three together)
/// and smaller (the first plane in parts, the others in two batches), by either parse.
#[test]
fn bubble_planes_decoded_in_batches_match_the_reference() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (pw, ph, ts) = (256u32, 64u32, 16usize);
    let tiles_x = pw as usize / ts;
    let tiles = tiles_x * (ph as usize / ts);
    let per2 = (ts / 8) * (ts / 8);
    // 256, 64, 52 and 36 blocks.
    let members: [&dyn Fn(usize) -> bool; 4] =
        [&|_| true, &|t| t % 4 == 0, &|t| t % 5 == 0, &|t| t % 7 == 1];
    for (part, wide, batched) in [
        (None, false, 3),
        (None, true, 3),
        (Some(128), false, 2),
        (Some(128), true, 2),
    ] {
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 5, 1, ts as u32);
        gpu.set_decode_shape(shape(wide));
        if let Some(p) = part {
            gpu.part = p;
            gpu.bind_decode();
        }
        let mut c = Coded::default();
        let mut seg = SegmentData::new();
        seg.steps = Vec::new();
        seg.bubbles = 1;
        seg.layers = 2 + members.len();
        let mut wants = Vec::new();
        for (n, member) in members.iter().enumerate() {
            let count = (0..tiles).filter(|&t| member(t)).count();
            let step = 0.004 * (n + 1) as f32;
            let blocks = random_blocks(count * per2, &mut (20 + n as u32));
            let (span, parsed) = coded_plane(&mut c, step, &blocks, Some((tiles, member)));
            if n == 0 {
                // (The keyframe plane the segment has no step for.)
                seg.planes.push(span);
            }
            seg.planes.push(span);
            wants.push((bubble_reference(&parsed, member, (pw, ph, ts), step), step));
        }
        seg.data = c;
        let target = decode::Target {
            pack_first: None,
            pack_before_last: None,
            set: Some(0),
        };
        let mut ops = Vec::new();
        gpu.plan_decode(&seg, target, &mut ops);
        let most = ops.iter().map(|o| o.groups[2]).max();
        assert_eq!(most, Some(batched), "parts {part:?}, GPU shape {wide}");
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        gpu.decode(&mut enc, &seg, true);
        gpu.queue.submit([enc.finish()]);
        for (n, (want, step)) in wants.iter().enumerate() {
            let got = summed_bubble_layer(&gpu, n as u32, (pw, ph), *step);
            let what = format!("parts {part:?}, GPU shape {wide}, plane {n}");
            assert_members_match(&got, want, members[n], (pw, ts), &what);
        }
    }
}

/// The set's tile degrees mark the tiles with a coefficient, found again for each
/// segment: after a segment whose plane had every tile, the next one's degrees are its
/// own, and where a tile's degree reaches the layer its blocks are this segment's (a
/// plane taller than one slice, 336 rows, so that the gather goes in several).
#[test]
fn tile_degrees_and_bubble_blocks_follow_each_segment() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (pw, ph, ts) = (32u32, 336u32, 16usize);
    let tiles_x = pw as usize / ts;
    let tiles = tiles_x * (ph as usize / ts);
    let per2 = (ts / 8) * (ts / 8);
    let step = 0.004;
    let every: &dyn Fn(usize) -> bool = &|_| true;
    let some: &dyn Fn(usize) -> bool = &|t| t % 3 == 0;
    for wide in [false, true] {
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, ts as u32);
        gpu.set_decode_shape(crate::DecodeShape {
            slice_groups: 1,
            ..shape(wide)
        });
        for (seed, member) in [(3, every), (4, some)] {
            let members = (0..tiles).filter(|&t| member(t)).count();
            let blocks = random_blocks(members * per2, &mut { seed });
            let mut c = Coded::default();
            let (span, parsed) = coded_plane(&mut c, step, &blocks, Some((tiles, member)));
            let want = bubble_reference(&parsed, member, (pw, ph, ts), step);
            decode_bubble_plane(&mut gpu, c, span);
            // Set 0, plane 0: term 2 in the plane's tiles with a coefficient, 0 elsewhere.
            let degrees = read_buffer(&device, &queue, &gpu.degrees);
            let degrees: &[u32] = bytemuck::cast_slice(&degrees);
            let mut ranks = 0..;
            for (t, &d) in degrees[..tiles].iter().enumerate() {
                let coded = member(t).then(|| ranks.next().unwrap_or(0));
                let any = coded.is_some_and(|r| {
                    blocks[r * per2..(r + 1) * per2]
                        .iter()
                        .any(|b| b.iter().any(|&v| v != 0))
                });
                assert_eq!(d, 2 * any as u32, "GPU shape {wide}, seed {seed}, tile {t}");
            }
            let got = summed_bubble_layer(&gpu, 0, (pw, ph), step);
            let peak = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
            for (i, (g, w)) in got.iter().zip(&want.data).enumerate() {
                let (x, y) = (i % pw as usize, i / pw as usize);
                let read = degrees[(y / ts) * tiles_x + x / ts] >= 2;
                let g = if read { *g } else { 0.0 };
                assert!(
                    (g - w).abs() <= 1e-5 * peak,
                    "GPU shape {wide}, seed {seed}, texel ({x}, {y}): GPU {g} against {w}"
                );
            }
        }
    }
}

/// The held image: what is on screen, packed by the hold pass and read back through
/// a blend at its start (alpha 0), is within a 9-bit step of the texel's largest
/// channel (and the output's half-float rounding), from zero to beyond RGB9E5's range.
#[test]
fn the_held_image_keeps_nine_bits_of_each_texels_largest_channel() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (w, h) = (16u32, 8u32);
    let mut gpu = Gpu::new(&device, &queue, (w, h), [w, h], 2, 3, 8);
    use wgpu::TextureUsages as U;
    let screen = device.create_texture(&lightmap_descriptor(
        w,
        h,
        U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC | U::COPY_DST,
    ));
    let texels = (w * h) as usize;
    let want: Vec<[f32; 3]> = (0..texels)
        .map(|i| {
            let big = 2f32.powf(i as f32 * 0.37 - 20.0);
            [
                big,
                big * ((i % 5) as f32 / 7.0),
                big * 1e-3 * (i % 3) as f32,
            ]
        })
        .collect();
    let raw: Vec<half::f16> = want
        .iter()
        .flat_map(|c| [c[0], c[1], c[2], 1.0].map(half::f16::from_f32))
        .collect();
    queue.write_texture(
        screen.as_image_copy(),
        bytemuck::cast_slice(&raw),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(w * 8),
            rows_per_image: Some(h),
        },
        screen.size(),
    );
    let on_screen: Vec<f32> = raw.iter().map(|v| v.to_f32()).collect();
    gpu.set_output(Some(&screen)).unwrap();
    let mut params = Params::zeroed_params();
    params.size = [w, h];
    params.channels = 3;
    params.blend = 1;
    params.alpha = 0.0;
    let mut enc = device.create_command_encoder(&Default::default());
    gpu.reconstruct(&mut enc, &params, true, true);
    queue.submit([enc.finish()]);
    let got = gpu.read_display();
    for i in 0..texels {
        let (g, s) = (&got[i * 4..i * 4 + 3], &on_screen[i * 4..i * 4 + 3]);
        let peak = s.iter().fold(0f32, |m, v| m.max(*v)).min(65408.0);
        for c in 0..3 {
            let tol = peak / 512.0 + s[c].min(65408.0) / 1024.0 + 1e-7;
            assert!(
                (g[c] - s[c].min(65408.0)).abs() <= tol,
                "texel {i} channel {c}: held {} against {} on screen",
                g[c],
                s[c]
            );
        }
    }
}

/// A pass whose workgroups cost less than a full group of 64 blocks goes in longer slices
/// of about a slice of full groups' work, not in more steps: a 512² keyframe's pack (128
/// workgroups, an eighth of a full group's work each) takes one dispatch at slices of 32
/// workgroups, and no slice of it records more than a slice of full groups.
#[test]
fn cheap_passes_take_slices_of_a_full_slices_work() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (pw, ph) = (512u32, 512u32);
    let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, 16);
    gpu.set_decode_shape(shape(false));
    let w = crate::PassWeights::LAVAPIPE;
    let full = super::decode::SLICE_GROUPS as u64 * super::decode::FULL_GROUP;
    let blocks = random_blocks((pw * ph / 64) as usize, &mut 5);
    let mut c = Coded::default();
    let (span, _) = coded_plane(&mut c, 0.01, &blocks, None);
    let dispatches = decode_key_step(&mut gpu, 0, span, c);
    let weight = w.key_pack as u64;
    let of: Vec<u64> = dispatches
        .iter()
        .filter(|d| d.0 == "key_pack")
        .map(|d| d.1 * weight)
        .collect();
    // 256 regions, 8 units each.
    assert_eq!(of.iter().sum::<u64>(), 256 * 8 * weight);
    assert_eq!(of.len(), 1, "{of:?}");
    assert!(of.iter().all(|&u| u <= full), "{of:?} against {full}");
}

/// A version 2 or 3 stream's bubble terms are bounded, not counted, on the CPU (its
/// symbols are decoded on the GPU): at 4096² the bound passed one storage binding (an
/// H200 refused the bind group: 178 MB against 128 MiB) while the terms took a few
/// percent of it. The bound is cut to one binding and no buffer bound whole passes one;
/// terms counted from pairs beyond one binding refuse the segment, naming it.
#[test]
fn bubble_terms_and_streams_never_pass_one_binding() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let gpu = Gpu::new(&device, &queue, (64, 64), [64, 64], 2, 1, 16);
    let limit = device.limits().max_storage_buffer_binding_size;
    let lanes = PlaneSpan {
        terms: u32::MAX,
        lanes: Some(crate::coded::LanePlane::default()),
        ..PlaneSpan::default()
    };
    let pairs = |words: u64| PlaneSpan {
        terms: words as u32,
        ..PlaneSpan::default()
    };
    let mut seg = SegmentData::new();
    seg.index = 7;
    seg.bubbles = 1;
    // A keyframe plane (not counted), a bubble plane from pairs, two from lanes.
    seg.planes = vec![pairs(limit), pairs(1000), lanes, lanes];
    assert_eq!(
        super::decode::term_bytes(&seg),
        (4000, 2 * 4 * u32::MAX as u64)
    );
    assert!(gpu.fits(&seg).is_ok(), "a lane bound beyond one binding");
    assert_eq!(gpu.term_need(&seg), limit);
    // Room to grow, but never past one binding.
    assert!(gpu.bound_size(gpu.term_need(&seg)) <= limit);
    assert_eq!(gpu.bound_size(1 << 20), super::plan::grown(1 << 20));
    assert_eq!(gpu.bound_size(limit - 4), limit);
    // Pairs counted beyond one binding: refused, naming the segment.
    seg.planes = vec![pairs(0), pairs(limit / 4 + 1)];
    let e = gpu.fits(&seg).unwrap_err();
    assert!(
        e.starts_with("segment 7: ") && e.contains("of bubble terms"),
        "{e}"
    );
}
