//! Version 2's sections decoded on the GPU as coded (`lanes.wgsl`), on a real adapter:
//! the dense plane they leave is the one the pairs of the same blocks leave (every mask,
//! set and coefficient a mask names), for keyframe and bubble planes, any lanes and maps;
//! damaged words raise the fault flag, never a hang.

use vbim_format::dct::N;
use vbim_format::plane2::{
    self, ContextMap, Geometry, LaneShape, Layout, Plane, Section, CONTEXTS,
};

use super::plan::groups_offset;
use super::tests::{coded_plane, decode_bubble_plane, decode_key_step, shape};
use super::*;
use crate::coded::Coded;
use crate::decoder::{KeyStep, SegmentData};
use crate::readback::read_buffer;

fn lcg(seed: &mut u64) -> u32 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*seed >> 33) as u32
}

/// Smooth DCs with noise, sparse detail, empty stretches and a few extreme values.
fn blocks(order: &[(usize, usize)], seed: u64) -> Vec<[i32; N * N]> {
    let mut s = seed;
    order
        .iter()
        .map(|&(x, y)| {
            let mut q = [0i32; N * N];
            if (x / 8 + y / 8) % 3 != 0 {
                q[0] = (3 * x + 2 * y) as i32 + (lcg(&mut s) % 5) as i32 - 2;
            }
            if lcg(&mut s).is_multiple_of(3) {
                for _ in 0..lcg(&mut s) % 20 {
                    let i = 1 + (lcg(&mut s) % 63) as usize;
                    q[i] = (lcg(&mut s) % 81) as i32 - 40;
                }
            }
            if lcg(&mut s).is_multiple_of(89) {
                q[0] = i32::MIN + (lcg(&mut s) % 3) as i32;
                q[5] = 1 << 30;
            }
            q
        })
        .collect()
}

/// The dense plane's masks, sets and the coefficients the masks name, for `n` blocks.
fn dense_plane(gpu: &Gpu, n: usize) -> (Vec<u32>, Vec<u32>, Vec<i32>) {
    let raw = read_buffer(&gpu.device, &gpu.queue, &gpu.masks);
    let words: &[u32] = bytemuck::cast_slice(&raw);
    let masks = words[..2 * n].to_vec();
    let sets_at = groups_offset(gpu.part) as usize / 4;
    let sets = words[sets_at..sets_at + 2 * n.div_ceil(64)].to_vec();
    let raw = read_buffer(&gpu.device, &gpu.queue, &gpu.coefs);
    let coefs: &[i32] = bytemuck::cast_slice(&raw);
    let named = (0..n * N * N)
        .map(|i| {
            let (b, f) = (i / 64, i % 64);
            match masks[2 * b + f / 32] >> (f % 32) & 1 {
                1 => coefs[i],
                _ => 0,
            }
        })
        .collect();
    (masks, sets, named)
}

/// A segment of one plane coded as section `bytes` (planes `shapes`, maps `maps`): plane
/// `p` as a keyframe step, or with `tile` blocks across a tile as a bubble plane whose
/// member tiles `member` says.
fn lane_segment(
    (bytes, shapes, maps, layout): (&[u8], &[Plane], &[ContextMap], Layout),
    p: usize,
    bubble: Option<(usize, &dyn Fn(usize) -> bool)>,
) -> SegmentData {
    let section = Section::parse_layout(bytes, shapes, maps, layout).unwrap();
    let file_count = plane2::file_histograms(maps).count() as u32;
    let mut data = Coded::default();
    let span = data.push_section(bytes, &section, file_count);
    let plane = (&section.planes[p], 0, shapes[p].family);
    let n = shapes[p].geometry.order.len();
    let lane = data.push_lane_plane(0.01, plane, n, bubble);
    let mut seg = SegmentData::new();
    seg.sections = vec![span];
    seg.data = data;
    match bubble {
        None => {
            seg.steps = vec![KeyStep {
                number: 0,
                intra: true,
                plane: 0,
            }];
            seg.planes = vec![lane];
            seg.bubbles = 1;
            seg.layers = 2;
        }
        Some(_) => {
            seg.planes = vec![lane, lane];
            seg.bubbles = 1;
            seg.layers = 3;
        }
    }
    seg
}

/// Decodes `seg` (as [`lane_segment`] made it) on `gpu`.
fn decode(gpu: &mut Gpu, seg: &SegmentData, bubbles: bool) {
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    gpu.decode(&mut enc, seg, bubbles);
    gpu.queue.submit([enc.finish()]);
}

/// A plane and its blocks.
type PlaneBlocks<'a> = (Plane<'a>, &'a [[i32; N * N]]);

/// Codes `planes` (a keyframe plane, then a bubble plane of `ts`-block tiles) with
/// Version 2's lanes, cut at `bytes`.
fn version_2(bytes: usize) -> LaneShape {
    LaneShape {
        bytes,
        symbols_per_state: None,
    }
}

/// `maps` in lanes `lanes` shapes, decodes each on the GPU as coded and as pairs, and
/// checks the dense planes are the same; then damages the words.
fn lanes_match_pairs(
    gpu: &mut Gpu,
    (planes, maps): (&[PlaneBlocks], &[ContextMap]),
    lanes: LaneShape,
    members: &dyn Fn(usize) -> bool,
) {
    let bytes = plane2::encode(planes, maps, lanes).unwrap();
    let layout = lanes.layout();
    let shapes: Vec<Plane> = planes.iter().map(|(p, _)| *p).collect();
    let tiles = |p: &Plane| {
        let ts = p.geometry.tile.unwrap_or(1);
        (p.geometry.grid.0 / ts) * (p.geometry.grid.1 / ts)
    };
    for (p, (shape, q)) in planes.iter().enumerate() {
        let n = q.len();
        let bubble = shape.geometry.tile.map(|_| (tiles(shape), members));
        let what = format!("plane {p}, lanes {lanes:?}");
        // As pairs.
        let mut c = Coded::default();
        let (span, _) = coded_plane(&mut c, 0.01, q, bubble);
        match bubble {
            None => drop(decode_key_step(gpu, 0, span, c)),
            Some(_) => decode_bubble_plane(gpu, c, span),
        }
        let want = dense_plane(gpu, n);
        // As coded.
        let seg = lane_segment((&bytes, &shapes, maps, layout), p, bubble);
        decode(gpu, &seg, bubble.is_some());
        assert!(!gpu.lanes_faulted(), "{what}: a lane faulted");
        let got = dense_plane(gpu, n);
        assert!(got.0 == want.0, "{what}: masks differ");
        assert!(got.1 == want.1, "{what}: sets differ");
        for (i, (g, w)) in got.2.iter().zip(&want.2).enumerate() {
            assert_eq!(g, w, "{what}: block {}, coefficient {}", i / 64, i % 64);
        }
        // Damaged words: the fault flag, never a hang.
        let mut bad = bytes.clone();
        let words_at = Section::parse_layout(&bytes, &shapes, maps, layout)
            .unwrap()
            .words_at;
        for b in bad.iter_mut().skip(words_at + 7).step_by(13) {
            *b ^= 0x5A;
        }
        decode(
            gpu,
            &lane_segment((&bad, &shapes, maps, layout), p, bubble),
            bubble.is_some(),
        );
        assert!(
            gpu.lanes_faulted(),
            "{what}: damaged words, and no lane faulted"
        );
    }
}

#[test]
fn keyframe_and_bubble_planes_decode_as_coded_to_the_dense_plane_their_pairs_give() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    // A keyframe plane of 48 × 36 blocks and a bubble plane of its tiles of 2 blocks (the
    // player's 16² texels) or 4, some not members; maps of 9 clusters at random, and of
    // one with a file-wide histogram.
    let (bw, bh) = (48, 36);
    let key_order: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
    let key = blocks(&key_order, 1);
    let mut seed = 7;
    let spread = ContextMap {
        clusters: 9,
        of: (0..CONTEXTS).map(|_| (lcg(&mut seed) % 9) as u8).collect(),
        tables: vec![None; 9],
    };
    for (ts, wide) in [(2usize, false), (4, true)] {
        let (tw, th) = (bw / ts, bh / ts);
        let member = move |t: usize| !(t % tw * 5 + t / tw * 3).is_multiple_of(4);
        let mut bubble_order = Vec::new();
        for t in (0..tw * th).filter(|&t| member(t)) {
            let (tx, ty) = (t % tw, t / tw);
            for y in ty * ts..ty * ts + ts {
                for x in tx * ts..tx * ts + ts {
                    bubble_order.push((x, y));
                }
            }
        }
        let bubble = blocks(&bubble_order, 2);
        let geometry = |order, tile| Geometry {
            grid: (bw, bh),
            order,
            tile,
        };
        let planes = [
            (
                Plane {
                    family: 0,
                    geometry: geometry(&key_order, None),
                },
                &key[..],
            ),
            (
                Plane {
                    family: 1,
                    geometry: geometry(&bubble_order, Some(ts)),
                },
                &bubble[..],
            ),
        ];
        // File-wide histograms for family 1, from its own symbols.
        let counts = plane2::context_counts(&planes[1..], 2, Layout::OneState).unwrap();
        let totals: Vec<u64> = (0..vbim_format::ans::TOKENS)
            .map(|t| {
                (0..CONTEXTS)
                    .map(|c| counts[1][c * vbim_format::ans::TOKENS + t])
                    .sum()
            })
            .collect();
        let file = ContextMap {
            clusters: 1,
            of: vec![0; CONTEXTS],
            tables: vec![vbim_format::ans::Histogram::from_counts(&totals)],
        };
        let maps = [spread.clone(), file];
        let (pw, ph) = (8 * bw as u32, 8 * bh as u32);
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, 8 * ts as u32);
        gpu.set_decode_shape(shape(wide));
        gpu.decode_lanes(&maps);
        // Version 2's lanes, and version 3's of several states (a state per 16 or 200
        // symbols: 2 to 64 a lane).
        for lane_bytes in [usize::MAX, 200, 16] {
            lanes_match_pairs(&mut gpu, (&planes, &maps), version_2(lane_bytes), &member);
        }
        for (bytes, per) in [(usize::MAX, 16), (200, 16), (usize::MAX, 200)] {
            let v3 = LaneShape {
                bytes,
                symbols_per_state: Some(per),
            };
            lanes_match_pairs(&mut gpu, (&planes, &maps), v3, &member);
        }
    }
}

/// A keyframe plane of `grid` blocks whose blocks lie at `order`.
fn keyframe_plane<'a>(grid: (usize, usize), order: &'a [(usize, usize)]) -> Plane<'a> {
    Plane {
        family: 0,
        geometry: Geometry {
            grid,
            order,
            tile: None,
        },
    }
}

/// GPU state for planes of `grid` blocks, decoding lanes coded with `maps`.
fn lanes_gpu(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    (bw, bh): (usize, usize),
    maps: &[ContextMap],
) -> Gpu {
    let (pw, ph) = (8 * bw as u32, 8 * bh as u32);
    let mut gpu = Gpu::new(device, queue, (pw, ph), [pw, ph], 2, 1, 16);
    gpu.decode_lanes(maps);
    gpu
}

/// 96 × 96 dense blocks: about 90,000 symbols, beyond the 65,535 loop iterations
/// llvmpipe allows one invocation; however large a lane the caller asks for, the
/// encoder's caps cut it. And a 256 × 256-block night keyframe (smooth DCs, a few jumps):
/// more cells than one invocation may visit, so the DC's prefix sum must be shared out
/// (rows, then columns) to be right.
#[test]
fn planes_beyond_one_invocations_loop_budget_decode_as_coded() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let mut s = 9;
    for (bw, bh) in [(96usize, 96usize), (256, 256)] {
        let order: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
        let q: Vec<[i32; N * N]> = order
            .iter()
            .map(|&(x, y)| {
                let mut q = [0i32; N * N];
                if bw == 96 {
                    for v in q.iter_mut().take(12) {
                        *v = (lcg(&mut s) % 9) as i32 - 4;
                    }
                } else {
                    let jump = if lcg(&mut s).is_multiple_of(97) {
                        400
                    } else {
                        0
                    };
                    q[0] = (x * 3 + y * 5) as i32 + jump;
                }
                q
            })
            .collect();
        let plane = keyframe_plane((bw, bh), &order);
        let maps = [ContextMap::single()];
        let mut gpu = lanes_gpu(&device, &queue, (bw, bh), &maps);
        let bytes = plane2::encode(&[(plane, &q[..])], &maps, version_2(usize::MAX)).unwrap();
        let lanes = Section::parse_layout(&bytes, &[plane], &maps, Layout::OneState)
            .unwrap()
            .planes[0]
            .lanes
            .len();
        assert!(bw == 256 || lanes >= 6, "{lanes} lanes");
        let whole = version_2(usize::MAX);
        lanes_match_pairs(&mut gpu, (&[(plane, &q[..])], &maps), whole, &|_| true);
    }
    // Version 3: a sparse plane of 512 regions (a few DC jumps) in one lane of one state,
    // which visits every group place of its regions in each of the four passes.
    let (bw, bh) = (512usize, 256usize);
    let order: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
    let q: Vec<[i32; N * N]> = order
        .iter()
        .map(|_| {
            let mut q = [0i32; N * N];
            if lcg(&mut s).is_multiple_of(4001) {
                q[0] = 300;
            }
            q
        })
        .collect();
    let plane = keyframe_plane((bw, bh), &order);
    let maps = [ContextMap::single()];
    let mut gpu = lanes_gpu(&device, &queue, (bw, bh), &maps);
    // (A state per 100,000 symbols: one for the lane's 8,192 group flags and few blocks.)
    let v3 = LaneShape {
        bytes: usize::MAX,
        symbols_per_state: Some(100_000),
    };
    let bytes = plane2::encode(&[(plane, &q[..])], &maps, v3).unwrap();
    let section = Section::parse_layout(&bytes, &[plane], &maps, Layout::States).unwrap();
    let lane = section.planes[0].lanes[0];
    assert_eq!(
        (lane.1 - lane.0, lane.3 - lane.2),
        (512, 1),
        "one lane of one state"
    );
    lanes_match_pairs(&mut gpu, (&[(plane, &q[..])], &maps), v3, &|_| true);
}

/// A segment's bubble planes decoded as coded go in batches: one dispatch of each lane
/// pass covers the planes of a section that fit the dense plane together
/// (`workgroup_id.z`), each at its own place in the dense plane, with its own groups and
/// states. Every plane's layer sums to its reference, with version 2's lanes and version
/// 3's states, a state a workgroup (a GPU's shape) and eight (a CPU adapter's): four
/// planes of 256, 64, 52 and 36 blocks in a dense plane of 256 go in two batches, the
/// second of three planes, or in three where their states outgrow the scratch's.
#[test]
fn bubble_planes_decoded_as_coded_in_batches_match_the_reference() {
    use super::tests::summed_bubble_layer;
    use super::tests::{assert_members_match, bubble_reference, random_blocks};
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (pw, ph, ts) = (256u32, 64u32, 16usize);
    let (bw, bh, per) = (pw as usize / 8, ph as usize / 8, ts / 8);
    let tiles_x = bw / per;
    let tiles = tiles_x * (bh / per);
    let members: [&dyn Fn(usize) -> bool; 4] =
        [&|_| true, &|t| t % 4 == 0, &|t| t % 5 == 0, &|t| t % 7 == 1];
    let mut orders = Vec::new();
    let mut blocks = Vec::new();
    for (n, member) in members.iter().enumerate() {
        let mut order = Vec::new();
        for t in (0..tiles).filter(|&t| member(t)) {
            let (tx, ty) = (t % tiles_x, t / tiles_x);
            for y in ty * per..ty * per + per {
                for x in tx * per..tx * per + per {
                    order.push((x, y));
                }
            }
        }
        blocks.push(random_blocks(order.len(), &mut (40 + n as u32)));
        orders.push(order);
    }
    let planes: Vec<PlaneBlocks> = orders
        .iter()
        .zip(&blocks)
        .map(|(order, q)| {
            let geometry = Geometry {
                grid: (bw, bh),
                order,
                tile: Some(per),
            };
            let plane = Plane {
                family: 0,
                geometry,
            };
            (plane, &q[..])
        })
        .collect();
    let shapes: Vec<Plane> = planes.iter().map(|(p, _)| *p).collect();
    let maps = [ContextMap::single()];
    let file_count = plane2::file_histograms(&maps).count() as u32;
    let steps: Vec<f32> = (0..members.len()).map(|n| 0.004 * (n + 1) as f32).collect();
    for wide in [true, false] {
        // (With a state per 40 symbols the planes' states outgrow the scratch's, a
        // plane's most: the second batch is cut in two.)
        let v3 = |per| LaneShape {
            bytes: usize::MAX,
            symbols_per_state: Some(per),
        };
        for (lanes, batches) in [
            (version_2(64), &[1, 3][..]),
            (v3(200), &[1, 3]),
            (v3(40), &[1, 2, 1]),
        ] {
            let what = format!("GPU shape {wide}, lanes {lanes:?}");
            let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 5, 1, ts as u32);
            gpu.set_decode_shape(shape(wide));
            gpu.decode_lanes(&maps);
            let bytes = plane2::encode(&planes, &maps, lanes).unwrap();
            let section = Section::parse_layout(&bytes, &shapes, &maps, lanes.layout()).unwrap();
            let mut data = Coded::default();
            let span = data.push_section(&bytes, &section, file_count);
            let mut seg = SegmentData::new();
            seg.steps = Vec::new();
            seg.bubbles = 1;
            seg.layers = 2 + members.len();
            for (n, member) in members.iter().enumerate() {
                let sp = (&section.planes[n], 0, 0);
                let bubble = Some((tiles, *member));
                let plane = data.push_lane_plane(steps[n], sp, blocks[n].len(), bubble);
                if n == 0 {
                    // (The keyframe plane the segment has no step for.)
                    seg.planes.push(plane);
                }
                seg.planes.push(plane);
            }
            seg.sections = vec![span];
            seg.data = data;
            let target = super::decode::Target {
                pack_first: None,
                pack_before_last: None,
                set: Some(0),
            };
            let mut ops = Vec::new();
            gpu.plan_decode(&seg, target, &mut ops);
            let blocks_passes = ops
                .iter()
                .filter(|o| o.kind == super::ops::Kind::Lane(super::lanes::LanePass::Blocks));
            let planes: Vec<u32> = blocks_passes.map(|o| o.groups[2]).collect();
            assert_eq!(planes, batches, "{what}: planes of each batch");
            decode(&mut gpu, &seg, true);
            assert!(!gpu.lanes_faulted(), "{what}: a lane faulted");
            for (n, member) in members.iter().enumerate() {
                let mut c = Coded::default();
                let (_, parsed) = coded_plane(&mut c, steps[n], &blocks[n], Some((tiles, member)));
                let want = bubble_reference(&parsed, member, (pw, ph, ts), steps[n]);
                let got = summed_bubble_layer(&gpu, n as u32, (pw, ph), steps[n]);
                assert_members_match(
                    &got,
                    &want,
                    *member,
                    (pw, ts),
                    &format!("{what}, plane {n}"),
                );
            }
        }
    }
}
