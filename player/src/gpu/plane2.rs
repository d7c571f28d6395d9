//! Format 2's coefficient coding decoded on the GPU (`plane2.wgsl`): a prototype that
//! decodes one plane of a coded section into the dense plane the player's decode passes
//! read (coefficients valid where a block's mask has the bit, and the set of blocks that
//! have any), tested against the specification (`vbim_format::plane2`) on a real adapter.
//! Not yet part of the player's decode, which reads format 2 through the decoder thread's
//! conversion to format 1's pairs; it is what that decode will build on. It takes what
//! the player would upload for a plane (its words, lanes and histograms, a bubble plane's
//! member spans as `coded.rs` lays them out) and builds the rest on the GPU: the slot
//! tables, each tile's rank, each group's flags. Buffers are made per call.

use vbim_format::dct::N;
use vbim_format::plane2::{Geometry, Section, GROUP, REGION};
use wgpu::util::DeviceExt;

use crate::coded::member_spans;
use crate::readback::read_buffer;

/// The prototype's pipelines.
pub(crate) struct Plane2Gpu {
    layout: wgpu::BindGroupLayout,
    slots: wgpu::ComputePipeline,
    prepare: wgpu::ComputePipeline,
    flags: wgpu::ComputePipeline,
    blocks: wgpu::ComputePipeline,
    dc_rows: wgpu::ComputePipeline,
    dc_cols: wgpu::ComputePipeline,
}

const BINDINGS: u32 = 9;

impl Plane2Gpu {
    pub fn new(device: &wgpu::Device) -> Plane2Gpu {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = (0..BINDINGS)
            .map(|binding| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: match binding {
                        0 => wgpu::BufferBindingType::Uniform,
                        1 | 4 => wgpu::BufferBindingType::Storage { read_only: true },
                        _ => wgpu::BufferBindingType::Storage { read_only: false },
                    },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect();
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim plane2"),
            entries: &entries,
        });
        let source = include_str!("plane2.wgsl");
        let pipeline = |entry| {
            super::resources::compute_pipeline(device, "vbim plane2", source, &layout, entry)
        };
        Plane2Gpu {
            slots: pipeline("slots"),
            prepare: pipeline("prepare"),
            flags: pipeline("flags"),
            blocks: pipeline("blocks"),
            dc_rows: pipeline("dc_rows"),
            dc_cols: pipeline("dc_cols"),
            layout,
        }
    }

    /// Decodes plane `plane` of `section` (whose blocks lie as `geo` says) and returns its
    /// blocks, or what was wrong: a lane that read past its words or did not end on the
    /// state it started from, or a symbol that made no sense.
    pub fn decode(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        section: &Section,
        plane: usize,
        geo: &Geometry,
    ) -> Result<Vec<[i32; N * N]>, String> {
        let sp = section.planes.get(plane).ok_or("no such plane")?;
        let (bw, bh) = geo.grid;
        let (gw, gh) = (bw.div_ceil(GROUP), bh.div_ceil(GROUP));
        let n = geo.order.len();
        // A bubble plane's member spans, as the player uploads them: its blocks come a
        // whole tile after another, member tiles in raster order.
        let ts = geo.tile.unwrap_or(0);
        let (tiles_x, tiles_y) = match ts {
            0 => (0, 0),
            _ if !bw.is_multiple_of(ts) || !bh.is_multiple_of(ts) || !n.is_multiple_of(ts * ts) => {
                return Err("a bubble plane of partial tiles".into());
            }
            _ => (bw / ts, bh / ts),
        };
        let mut member = vec![false; tiles_x * tiles_y];
        if ts > 0 {
            for c in geo.order.chunks(ts * ts) {
                member[(c[0].1 / ts) * tiles_x + c[0].0 / ts] = true;
            }
        }
        let spans: Vec<[u32; 2]> = member_spans(member.len(), &|t| member[t]).collect();
        let w = &section.words;
        let mut lanes = Vec::with_capacity(2 * sp.lanes.len());
        for &(r0, r1, w0, w1) in &sp.lanes {
            if w1 < w0 + 2 {
                return Err("a lane shorter than its state".into());
            }
            let x = (w[w0] as u32) << 16 | w[w0 + 1] as u32;
            lanes.push([x, (w0 + 2) as u32, w1 as u32, 0]);
            lanes.push([r0 as u32, r1 as u32, 0, 0]);
        }
        let lane_count = sp.lanes.len();
        let words: Vec<u32> = w
            .chunks(2)
            .map(|p| p[0] as u32 | (*p.get(1).unwrap_or(&0) as u32) << 16)
            .chain([0])
            .collect();
        // Contexts' histograms, each histogram's frequencies, then room for its slot
        // table (`slots` fills it).
        let hs = &section.histograms;
        let mut tables: Vec<u32> = sp.histogram_of.iter().map(|&h| h as u32).collect();
        tables.extend(
            hs.iter()
                .flat_map(|h| (0..128).map(move |t| h.frequency(t) | h.cumulative(t) << 16)),
        );
        let slots = tables.len() as u32;
        tables.resize(tables.len() + hs.len() * 1024, 0);
        let storage = |data: &[u8], label| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: data,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            })
        };
        let zeros = |bytes: usize, label| storage(&vec![0u8; bytes.max(8)], label);
        let buffers = [
            storage(bytemuck::cast_slice(&words), "plane2 words"),
            storage(bytemuck::cast_slice(&lanes), "plane2 lanes"),
            storage(bytemuck::cast_slice(&tables), "plane2 tables"),
            storage(
                bytemuck::cast_slice(&spans.iter().copied().chain([[0; 2]]).collect::<Vec<_>>()),
                "plane2 spans",
            ),
            // Filled with garbage: `prepare` must write every group's flags and every
            // tile's rank.
            storage(
                &vec![0xA5u8; (gw * gh + tiles_x * tiles_y) * 4],
                "plane2 groups",
            ),
            zeros(n * 8, "plane2 info"),
            // Not cleared, as the player's dense plane is not: filled with garbage, so
            // that a coefficient read without its mask bit shows.
            storage(&vec![0x5Au8; (n * N * N * 4).max(8)], "plane2 coefs"),
            zeros((2 * n + n.div_ceil(32)) * 4, "plane2 masks and sets"),
        ];
        let params = |parity: u32| {
            let p: [u32; 16] = [
                bw as u32,
                bh as u32,
                gw as u32,
                gh as u32,
                bw.div_ceil(REGION) as u32,
                ts as u32,
                lane_count as u32,
                parity,
                slots,
                2 * n as u32,
                tiles_x as u32,
                tiles_y as u32,
                spans.len() as u32,
                (n / (ts * ts).max(1)) as u32,
                hs.len() as u32,
                0,
            ];
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("plane2 params"),
                contents: bytemuck::cast_slice(&p),
                usage: wgpu::BufferUsages::UNIFORM,
            })
        };
        let params = [params(0), params(1)];
        let groups_of = |parity: usize| {
            let entries: Vec<wgpu::BindGroupEntry> = std::iter::once(&params[parity])
                .chain(&buffers)
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: b.as_entire_binding(),
                })
                .collect();
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("vbim plane2"),
                layout: &self.layout,
                entries: &entries,
            })
        };
        let bind = [groups_of(0), groups_of(1)];
        let mut enc = device.create_command_encoder(&Default::default());
        let lane_groups = (lane_count as u32).div_ceil(64);
        let cells = (tiles_x * tiles_y).max(gw * gh) as u32;
        for (pipeline, parity, groups) in [
            (&self.slots, 0, (hs.len() as u32 * 1024).div_ceil(64)),
            (&self.prepare, 0, cells.div_ceil(64)),
            (&self.flags, 0, lane_groups),
            (&self.flags, 1, lane_groups),
            (&self.blocks, 0, lane_groups),
            (&self.blocks, 1, lane_groups),
            (&self.dc_rows, 0, (bh as u32).div_ceil(64)),
            (&self.dc_cols, 0, (bw as u32).div_ceil(64)),
        ] {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind[parity], &[]);
            pass.dispatch_workgroups(groups, 1, 1);
        }
        queue.submit([enc.finish()]);
        let ends: Vec<[u32; 4]> =
            bytemuck::cast_slice(&read_buffer(device, queue, &buffers[1])).to_vec();
        for (l, e) in ends.iter().step_by(2).enumerate() {
            if e[3] != 0 {
                return Err(format!(
                    "lane {l} read past its words or decoded a symbol out of range"
                ));
            }
            if e[0] != 1 << 16 || e[1] != e[2] {
                return Err(format!(
                    "lane {l} ended on state {} at word {} of {}",
                    e[0], e[1], e[2]
                ));
            }
        }
        // The dense plane as the player's passes would read it: a coefficient where its
        // mask has the bit, and a block in the sets where it has any.
        let raw = read_buffer(device, queue, &buffers[6]);
        let coefs: &[i32] = bytemuck::cast_slice(&raw);
        let raw = read_buffer(device, queue, &buffers[7]);
        let marks: &[u32] = bytemuck::cast_slice(&raw);
        let (masks, sets) = marks.split_at(2 * n);
        (0..n)
            .map(|b| {
                let mask = masks[2 * b] as u64 | (masks[2 * b + 1] as u64) << 32;
                if (sets[b / 32] >> (b % 32) & 1 != 0) != (mask != 0) {
                    return Err(format!("block {b}: its set bit disagrees with its mask"));
                }
                let mut q = [0i32; N * N];
                for (i, v) in q.iter_mut().enumerate() {
                    if mask >> i & 1 != 0 {
                        *v = coefs[b * N * N + i];
                        if *v == 0 {
                            return Err(format!("block {b}: mask bit {i} on a zero"));
                        }
                    }
                }
                Ok(q)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::headless_device;
    use vbim_format::plane2::{self, ContextMap, Plane, CONTEXTS};

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

    #[test]
    fn a_plane_too_large_for_one_lavapipe_invocation_is_cut_into_lanes_it_can_run() {
        // 96 × 96 dense blocks: about 90,000 symbols, beyond the 65,535 loop iterations
        // llvmpipe allows one invocation; however large a lane the caller asks for, the
        // encoder's caps cut it.
        let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
        let gpu = Plane2Gpu::new(&device);
        let (bw, bh) = (96, 96);
        let order: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
        let mut s = 9;
        let q: Vec<[i32; N * N]> = order
            .iter()
            .map(|_| {
                let mut q = [0i32; N * N];
                for v in q.iter_mut().take(12) {
                    *v = (lcg(&mut s) % 9) as i32 - 4;
                }
                q
            })
            .collect();
        let lanes = keyframe_on_the_gpu((&gpu, &device, &queue), (bw, bh), &order, &q, usize::MAX);
        assert!(lanes >= 6, "{lanes} lanes");
    }

    /// Codes `q`, a keyframe plane of `grid` blocks in `order`, in lanes of `lane_bytes`,
    /// decodes it on the GPU, checks that it gave `q` back, and returns how many lanes the
    /// plane was cut into.
    fn keyframe_on_the_gpu(
        (gpu, device, queue): (&Plane2Gpu, &wgpu::Device, &wgpu::Queue),
        grid: (usize, usize),
        order: &[(usize, usize)],
        q: &[[i32; N * N]],
        lane_bytes: usize,
    ) -> usize {
        let shape = Plane {
            family: 0,
            geometry: Geometry {
                grid,
                order,
                tile: None,
            },
        };
        let maps = [ContextMap::single()];
        let bytes = plane2::encode(&[(shape, q)], &maps, lane_bytes).unwrap();
        let section = Section::parse(&bytes, &[shape], &maps).unwrap();
        let got = gpu
            .decode(device, queue, &section, 0, &shape.geometry)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(got == q, "the GPU's blocks differ");
        section.planes[0].lanes.len()
    }

    #[test]
    fn the_gpu_decodes_what_the_specification_decodes() {
        let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
        let gpu = Plane2Gpu::new(&device);
        // An odd-sized keyframe plane; a bubble plane of whole tiles (the player pads its
        // planes to them), some not members, in tiles of 2 blocks (the player's 16²
        // texels) or 4.
        let (bw, bh) = (45, 35);
        let key_order: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
        let key = blocks(&key_order, 1);
        for ts in [2, 4] {
            let (tw, th) = (48 / ts, 36 / ts);
            let mut bubble_order = Vec::new();
            for ty in 0..th {
                for tx in 0..tw {
                    if (tx * 5 + ty * 3) % 4 == 0 {
                        continue;
                    }
                    for y in ty * ts..ty * ts + ts {
                        for x in tx * ts..tx * ts + ts {
                            bubble_order.push((x, y));
                        }
                    }
                }
            }
            let bubble = blocks(&bubble_order, 2);
            let shapes = [
                Plane {
                    family: 0,
                    geometry: Geometry {
                        grid: (bw, bh),
                        order: &key_order,
                        tile: None,
                    },
                },
                Plane {
                    family: 1,
                    geometry: Geometry {
                        grid: (48, 36),
                        order: &bubble_order,
                        tile: Some(ts),
                    },
                },
            ];
            sections_decode_on_the_gpu(&gpu, (&device, &queue), &shapes, [&key, &bubble]);
        }
    }

    /// Codes two planes (`shapes`, blocks `q`) as one section in lanes of several sizes
    /// and checks the GPU's blocks against the specification's, then damages the words:
    /// an error or other blocks, never a hang.
    fn sections_decode_on_the_gpu(
        gpu: &Plane2Gpu,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        shapes: &[Plane; 2],
        q: [&[[i32; N * N]]; 2],
    ) {
        let mut seed = 7;
        let maps = [
            ContextMap {
                clusters: 9,
                of: (0..CONTEXTS).map(|_| (lcg(&mut seed) % 9) as u8).collect(),
                tables: vec![None; 9],
            },
            ContextMap::single(),
        ];
        for lane_bytes in [usize::MAX, 200, 16] {
            let input = [(shapes[0], q[0]), (shapes[1], q[1])];
            let bytes = plane2::encode(&input, &maps, lane_bytes).unwrap();
            let section = Section::parse(&bytes, shapes, &maps).unwrap();
            let want = plane2::decode(&bytes, shapes, &maps).unwrap();
            for (p, want) in want.iter().enumerate() {
                let got = gpu
                    .decode(device, queue, &section, p, &shapes[p].geometry)
                    .unwrap_or_else(|e| panic!("plane {p}, lanes of {lane_bytes} B: {e}"));
                assert_eq!(got.len(), want.len());
                for (b, (g, w)) in got.iter().zip(want).enumerate() {
                    assert_eq!(g, w, "plane {p}, lanes of {lane_bytes} B, block {b}");
                }
            }
            // Damaged words: an error or other blocks, never a hang.
            let mut bad = section.clone();
            for w in bad.words.iter_mut().skip(7).step_by(13) {
                *w ^= 0x5A5A;
            }
            let _ = gpu.decode(device, queue, &bad, 0, &shapes[0].geometry);
            let _ = gpu.decode(device, queue, &bad, 1, &shapes[1].geometry);
        }
    }

    /// A 2048² keyframe plane: 65,536 cells, more than llvmpipe lets one invocation loop
    /// over, so the DC's prefix sum must be shared out (rows, then columns) to be right.
    #[test]
    fn the_dc_of_a_plane_of_more_cells_than_one_invocation_may_visit_is_exact() {
        let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
        let gpu = Plane2Gpu::new(&device);
        let (bw, bh) = (256, 256);
        let order: Vec<(usize, usize)> = (0..bw * bh).map(|b| (b % bw, b / bw)).collect();
        // Smooth DCs (small residuals) with a few jumps, nothing else: a night keyframe.
        let mut s = 11;
        let q: Vec<[i32; N * N]> = order
            .iter()
            .map(|&(x, y)| {
                let mut b = [0i32; N * N];
                b[0] = (x * 3 + y * 5) as i32
                    + if lcg(&mut s).is_multiple_of(97) {
                        400
                    } else {
                        0
                    };
                b
            })
            .collect();
        keyframe_on_the_gpu((&gpu, &device, &queue), (bw, bh), &order, &q, 4096);
    }
}
