//! Creating the GPU state: textures, buffers, bind group layouts, pipelines, and the bind
//! groups over them.

use wgpu::util::DeviceExt;

use super::decode::SLICE_GROUPS;
use super::job::{decode_source, JOB_BINDING, JOB_STRIDE};
use super::layouts::{compute_pipeline, layouts, Layouts, TablesIn};
use super::plan::*;
use super::reconstruct::Params;
use super::Gpu;

/// What decode.wgsl and reconstruct.wgsl share: the DCT tables and a block's set of
/// coefficients visited in order.
const BLOCKS_WGSL: &str = include_str!("blocks.wgsl");

/// The DCT basis and zig-zag order (`Tables` in blocks.wgsl).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Tables {
    basis: [f32; 64],
    zigzag: [u32; 64],
    /// A term's basis values at a quad (`Tables::quad` in blocks.wgsl).
    quad: [[f32; 4]; 1024],
}

impl Gpu {
    /// GPU state for the stream `h` describes (its size, padded planes, degree, channels
    /// and tiles), decoding in `shape` (a version 2 file's sections as coded where
    /// [`DecodeShape::lanes`](crate::DecodeShape::lanes) says so).
    pub fn for_stream(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        h: &vbim_format::Header,
        shape: crate::DecodeShape,
    ) -> Gpu {
        let (pw, ph) = vbim_format::chunk::padded_size(h);
        let mut gpu = Gpu::with_shape(
            device,
            queue,
            ((h.width, h.height), [pw as u32, ph as u32]),
            (h.max_degree as u32, h.channels as u32, h.tile_size as u32),
            shape,
        );
        gpu.set_decode_shape(shape);
        if let Some(maps) = h.context_maps().filter(|_| shape.lanes) {
            gpu.decode_lanes(maps);
        }
        gpu
    }

    /// Decodes version 2 planes coded with `maps` as coded from now on (where they fit
    /// the dense plane whole, [`super::lanes::Scratch::new`]).
    pub(super) fn decode_lanes(&mut self, maps: &[vbim_format::plane2::ContextMap]) {
        let geometry = (self.plane, self.per * 8, self.channels);
        self.lanes =
            super::lanes::LanesGpu::new(&self.device, &self.queue, (geometry, maps), &self.shape);
        // The lanes' dense plane holds a keyframe's planes side by side
        // (`lanes::lane_blocks`): the coefficients, masks and sets grown to hold them.
        if let Some(dense) = self.lanes.as_ref().map(|l| l.plan.dense) {
            let grow = |buffer: &mut wgpu::Buffer, bytes: u64, label| {
                if bytes > buffer.size() {
                    *buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some(label),
                        size: bytes,
                        usage: buffer.usage(),
                        mapped_at_creation: false,
                    });
                }
            };
            grow(
                &mut self.coefs,
                dense as u64 * 256,
                "vbim dense coefficients",
            );
            let masks = mask_bytes(dense);
            grow(
                &mut self.masks,
                masks,
                "vbim ring of coefficient masks and sets",
            );
        }
        self.bind_decode();
    }

    /// GPU state for a stream of `width × height` texels of `channels` planes, coded on
    /// planes of `plane` texels (whole tiles of `tile_size`), with bubble terms up to
    /// `max_degree`; the DCT tables where the adapter's decode shape keeps them (the
    /// tests' constructor: the player's is [`Gpu::for_stream`]).
    #[cfg(test)]
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        size: (u32, u32),
        plane: [u32; 2],
        max_degree: u32,
        channels: u32,
        tile_size: u32,
    ) -> Gpu {
        let shape = crate::DecodeShape::for_adapter(&device.adapter_info());
        let stream = (max_degree, channels, tile_size);
        Gpu::with_shape(device, queue, (size, plane), stream, shape)
    }

    /// [`Gpu::new`], built as `shape` says: the DCT tables where its `storage_tables` keeps
    /// them, the reconstruction's quads per invocation from its `wide_reconstruct`.
    fn with_shape(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        ((width, height), plane): ((u32, u32), [u32; 2]),
        (max_degree, channels, tile_size): (u32, u32, u32),
        shape: crate::DecodeShape,
    ) -> Gpu {
        let tables_in = TablesIn::of(shape);
        let [keys, packed, bubble_blocks, display, held] = texture_plans(
            (width, height),
            plane,
            max_degree,
            channels,
            min_array_layers(device),
        )
        .map(|d| device.create_texture(&d));
        let display_view = display.create_view(&Default::default());
        let held_view = held.create_view(&Default::default());
        let array_view = |t: &wgpu::Texture| {
            t.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        };
        let keys_view = array_view(&keys);
        let bubble_view = array_view(&bubble_blocks);
        let packed_view = array_view(&packed);
        let ranges = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vbim 16-bit keyframe ranges"),
            size: range_bytes(plane, channels).max(8),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let key_views = (0..channels)
            .map(|l| {
                keys.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: l,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("vbim params"),
            contents: bytemuck::bytes_of(&Params::zeroed_params()),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let tables = dct_tables(device, tables_in);
        let Layouts {
            reconstruct: bgl,
            hold: hold_layout,
            key: key_layout,
            pack: pack_layout,
            bubble: bubble_layout,
            parse: parse_layout,
        } = layouts(device, tables_in);
        let pipeline_for =
            |label, source, layout, entry| compute_pipeline(device, label, source, layout, entry);
        let decode = &decode_source(
            &tables_in.wgsl(&format!("{BLOCKS_WGSL}{}", include_str!("decode.wgsl"))),
        );
        let reconstruct = &tables_in.wgsl(&format!(
            "const QUADS: u32 = {}u;\n{BLOCKS_WGSL}{}",
            if shape.wide_reconstruct { 2 } else { 1 },
            include_str!("reconstruct.wgsl")
        ));
        let parse_source = &decode_source(&format!(
            "const PIECE_PAIRS: u32 = {}u;\nconst FILL_BLOCKS: u32 = {}u;\n{}",
            vbim_format::chunk::ENTRY_PAIRS,
            vbim_format::chunk::FILL_BLOCKS,
            include_str!("parse.wgsl")
        ));
        let pipeline = pipeline_for("vbim reconstruct", reconstruct, &bgl, "main");
        let pipeline_fresh = pipeline_for(
            "vbim reconstruct, first of a generation",
            reconstruct,
            &bgl,
            "main_fresh",
        );
        let hold = pipeline_for("vbim hold", reconstruct, &hold_layout, "hold");
        let hold_group = hold_group(device, &hold_layout, &display_view, &held_view);
        let parse = pipeline_for("vbim parse", parse_source, &parse_layout, "parse");
        let parse_wide = pipeline_for("vbim parse_wide", parse_source, &parse_layout, "parse_wide");
        let key_add = pipeline_for("vbim key_add", decode, &key_layout, "key_add");
        let key_pack = pipeline_for("vbim key_pack", decode, &pack_layout, "key_pack");
        let bubble_gather = pipeline_for(
            "vbim bubble_gather",
            decode,
            &bubble_layout,
            "bubble_gather",
        );
        let buffer = |label: &str, size: u64, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as B;
        let part = part_blocks(plane);
        // (Copied from in the parse's tests only: the usage costs nothing.)
        let coefs = buffer(
            "vbim dense coefficients",
            part as u64 * 256,
            B::STORAGE | B::COPY_SRC,
        );
        let mask_slots = mask_slots(max_degree, channels);
        let masks = buffer(
            "vbim ring of coefficient masks and sets",
            mask_slots as u64 * slot_bytes(part),
            B::STORAGE | B::COPY_DST | B::COPY_SRC,
        );
        // Zeroed at creation: generation 0, which no frame has.
        let tiles = buffer(
            "vbim reconstruction tiles",
            tile_bytes((width, height)).0,
            B::STORAGE,
        );
        let peaks = buffer(
            "vbim reconstruction tile bounds",
            tile_bytes((width, height)).1,
            B::STORAGE | B::COPY_DST,
        );
        // (COPY_SRC: tests read it back.)
        let degrees = buffer(
            "vbim tile degrees",
            degree_bytes(plane, tile_size, channels),
            B::STORAGE | B::COPY_DST | B::COPY_SRC,
        );
        // (COPY_SRC: tests read them back.)
        let terms = [0; BUBBLE_SETS as usize].map(|_| {
            buffer(
                "vbim bubble terms",
                FIRST_TERM_BYTES,
                B::STORAGE | B::COPY_SRC,
            )
        });
        let jobs = buffer(
            "vbim decode jobs",
            64 * JOB_STRIDE,
            // (STORAGE: the lane passes' job, `DecodeShape::lane_job_storage`.)
            B::UNIFORM | B::STORAGE | B::COPY_DST,
        );
        let words = buffer("vbim coefficients", grown(0), B::STORAGE | B::COPY_DST);
        // Enough slices for a block pass over a whole part; grown if a pass needs more.
        let slices = slice_buffer(device, (part / 64).div_ceil(SLICE_GROUPS).max(16) as u64);
        let mut gpu = Gpu {
            device: device.clone(),
            queue: queue.clone(),
            pipeline,
            pipeline_fresh,
            hold,
            hold_layout,
            hold_group,
            parse,
            parse_wide,
            key_add,
            key_pack,
            bubble_gather,
            key_layout,
            pack_layout,
            bubble_layout,
            parse_layout,
            params,
            tables,
            jobs,
            words,
            slices,
            coefs,
            masks,
            mask_slots,
            part,
            tiles,
            peaks,
            gen: 0,
            last_params: None,
            parity: 0,
            frame3: 0,
            reuse_probe: 0,
            since_probe: 0,
            after_first: false,
            keys,
            key_views,
            packed,
            packed_view,
            ranges,
            regions: regions(plane),
            bubble_blocks,
            bubble_view,
            terms,
            display,
            display_view,
            held,
            bind_groups: Vec::new(),
            reconstruct_layout: bgl,
            keys_view,
            held_view,
            output: None,
            key_groups: Vec::new(),
            pack_group: None,
            bubble_groups: Vec::new(),
            parse_group: None,
            job_bytes: Vec::with_capacity(64 * JOB_STRIDE as usize),
            batch: Vec::with_capacity(64),
            batch_out: Vec::with_capacity(super::job::BATCH_PLANES as usize),
            lane_planes: Vec::with_capacity(64),
            lane_members: Vec::with_capacity(super::job::BATCH_PLANES as usize),
            // (Set from the adapter below.)
            shape: crate::DecodeShape::CPU,
            slice_span: 1,
            set_layers: set_layers(max_degree, channels),
            #[cfg(feature = "bench")]
            marks: None,
            width,
            height,
            plane,
            channels,
            per: tile_size / 8,
            tiles_x: plane[0] / tile_size,
            tile_count: (plane[0] / tile_size) * (plane[1] / tile_size),
            degrees,
            lanes: None,
            planned_section: None,
        };
        gpu.bind_decode();
        gpu.bind_reconstruct();
        gpu.set_decode_shape(crate::DecodeShape::for_adapter(&device.adapter_info()));
        gpu
    }

    /// (Re)makes the reconstruction's bind groups, one per bubble set, over the player's
    /// lightmap and, where one is set, the caller's output.
    pub(super) fn bind_reconstruct(&mut self) {
        self.bind_groups = self.reconstruct_groups(&self.display_view);
        if let Some((texture, ..)) = self.output.take() {
            self.output = Some(self.output_groups(texture));
        }
    }

    /// The caller's `texture` as the reconstruction's output: with the reconstruction's
    /// bind groups (one per bubble set) and the hold pass's over it.
    pub(super) fn output_groups(
        &self,
        texture: wgpu::Texture,
    ) -> (wgpu::Texture, Vec<wgpu::BindGroup>, wgpu::BindGroup) {
        let view = texture.create_view(&Default::default());
        let groups = self.reconstruct_groups(&view);
        let hold = hold_group(&self.device, &self.hold_layout, &view, &self.held_view);
        (texture, groups, hold)
    }

    /// The reconstruction's bind group for each bubble set, writing `output`.
    pub(super) fn reconstruct_groups(&self, output: &wgpu::TextureView) -> Vec<wgpu::BindGroup> {
        self.terms
            .iter()
            .map(|terms| {
                reconstruct_group(
                    &self.device,
                    &self.reconstruct_layout,
                    [
                        &self.keys_view,
                        &self.bubble_view,
                        &self.held_view,
                        output,
                        &self.packed_view,
                    ],
                    [&self.ranges, terms, &self.tiles, &self.peaks, &self.degrees],
                    [&self.params, &self.tables],
                )
            })
            .collect()
    }

    /// (Re)makes the decode passes' bind groups over the current `jobs` and `words`.
    pub(super) fn bind_decode(&mut self) {
        // A job and those after it: a dispatch over a batch of planes reads one each.
        let job = wgpu::BufferBinding {
            buffer: &self.jobs,
            offset: 0,
            size: wgpu::BufferSize::new(JOB_BINDING),
        };
        // The job, the streams and the dense plane, then the layout's own bindings.
        let group = |layout: &wgpu::BindGroupLayout, more: &[wgpu::BindGroupEntry]| {
            let mut entries = vec![
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(job.clone()),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: self.words.as_entire_binding(),
                },
            ];
            entries.push(wgpu::BindGroupEntry {
                binding: 11,
                resource: slice_binding(&self.slices),
            });
            entries.extend_from_slice(more);
            entries.push(wgpu::BindGroupEntry {
                binding: 6,
                resource: self.coefs.as_entire_binding(),
            });
            // The ring of masks, whole, twice: its masks and its sets (each job says
            // where its slot's are).
            entries.push(wgpu::BindGroupEntry {
                binding: 7,
                resource: self.masks.as_entire_binding(),
            });
            entries.push(wgpu::BindGroupEntry {
                binding: 10,
                resource: self.masks.as_entire_binding(),
            });
            self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("vbim decode"),
                layout,
                entries: &entries,
            })
        };
        let view = |binding, v| wgpu::BindGroupEntry {
            binding,
            resource: wgpu::BindingResource::TextureView(v),
        };
        let tables = wgpu::BindGroupEntry {
            binding: 1,
            resource: self.tables.as_entire_binding(),
        };
        self.parse_group = Some(group(&self.parse_layout, &[]));
        self.key_groups = self
            .key_views
            .iter()
            .map(|v| group(&self.key_layout, &[tables.clone(), view(3, v)]))
            .collect();
        let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
        self.pack_group = Some(self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vbim keyframe pack"),
            layout: &self.pack_layout,
            entries: &[
                entry(0, wgpu::BindingResource::Buffer(job.clone())),
                entry(11, slice_binding(&self.slices)),
                entry(14, wgpu::BindingResource::TextureView(&self.keys_view)),
                entry(4, wgpu::BindingResource::TextureView(&self.packed_view)),
                entry(5, self.ranges.as_entire_binding()),
            ],
        }));
        let degrees = wgpu::BindGroupEntry {
            binding: 9,
            resource: self.degrees.as_entire_binding(),
        };
        self.bubble_groups = self
            .terms
            .iter()
            .map(|terms| {
                let terms = wgpu::BindGroupEntry {
                    binding: 13,
                    resource: terms.as_entire_binding(),
                };
                group(
                    &self.bubble_layout,
                    &[view(12, &self.bubble_view), degrees.clone(), terms],
                )
            })
            .collect();
        if let Some(mut lanes) = self.lanes.take() {
            let dense = (&self.coefs, &self.masks);
            lanes.bind(&self.device, &self.jobs, &self.words, dense);
            self.lanes = Some(lanes);
        }
    }
}

/// The slices buffer as a dispatch binds it (its slice's entry, at a dynamic offset).
fn slice_binding(slices: &wgpu::Buffer) -> wgpu::BindingResource<'_> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer: slices,
        offset: 0,
        size: wgpu::BufferSize::new(16),
    })
}

/// The reconstruction's bind group: its parameters and the DCT tables, then the head
/// keyframe, bubble blocks, held image, output and 16-bit keyframe views, the 16-bit
/// keyframes' ranges, a bubble set's terms, the tiles' state and the tiles' degrees.
pub(super) fn reconstruct_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    views: [&wgpu::TextureView; 5],
    [ranges, terms, tiles, peaks, degrees]: [&wgpu::Buffer; 5],
    [params, tables]: [&wgpu::Buffer; 2],
) -> wgpu::BindGroup {
    let mut entries = vec![
        wgpu::BindGroupEntry {
            binding: 0,
            resource: params.as_entire_binding(),
        },
        wgpu::BindGroupEntry {
            binding: 13,
            resource: tables.as_entire_binding(),
        },
    ];
    for (i, v) in views.into_iter().enumerate() {
        entries.push(wgpu::BindGroupEntry {
            binding: i as u32 + 1,
            resource: wgpu::BindingResource::TextureView(v),
        });
    }
    for (binding, buffer) in [
        (6, ranges),
        (9, terms),
        (10, tiles),
        (12, peaks),
        (11, degrees),
    ] {
        entries.push(wgpu::BindGroupEntry {
            binding,
            resource: buffer.as_entire_binding(),
        });
    }
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("vbim reconstruct"),
        layout,
        entries: &entries,
    })
}

/// The hold pass's bind group: what is on screen, and the held texture it packs it into.
pub(super) fn hold_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    shown: &wgpu::TextureView,
    held: &wgpu::TextureView,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("vbim hold"),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 7,
                resource: wgpu::BindingResource::TextureView(shown),
            },
            wgpu::BindGroupEntry {
                binding: 8,
                resource: wgpu::BindingResource::TextureView(held),
            },
        ],
    })
}

/// The first workgroup of each of `count` slices of a pass (slice k's, k ·
/// [`SLICE_GROUPS`], at k · [`JOB_STRIDE`]), bound with a dynamic offset beside the job:
/// written once, so that a pass in slices uploads one job, not one per slice.
pub(super) fn slice_buffer(device: &wgpu::Device, count: u64) -> wgpu::Buffer {
    let stride = JOB_STRIDE as usize / 4;
    let mut words = vec![0u32; count as usize * stride];
    for (k, slot) in words.chunks_exact_mut(stride).enumerate() {
        slot[0] = k as u32 * SLICE_GROUPS;
    }
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("vbim decode slices"),
        contents: bytemuck::cast_slice(&words),
        usage: wgpu::BufferUsages::UNIFORM,
    })
}

/// The DCT basis and the zig-zag order, from the reference decoder's own tables
/// (`Tables` in blocks.wgsl), in a uniform or a storage buffer (`tables_in`).
fn dct_tables(device: &wgpu::Device, tables_in: TablesIn) -> wgpu::Buffer {
    let mut t = Tables {
        basis: [0.0; 64],
        zigzag: [0; 64],
        quad: [[0.0; 4]; 1024],
    };
    let basis = vbim_format::dct::basis();
    for (k, row) in basis.iter().enumerate() {
        t.basis[k * 8..k * 8 + 8].copy_from_slice(row);
    }
    for (i, &z) in vbim_format::dct::zigzag().iter().enumerate() {
        t.zigzag[i] = z as u32;
        let (ky, kx) = (z / 8, z % 8);
        for (q, slot) in t.quad[i * 16..i * 16 + 16].iter_mut().enumerate() {
            let (qx, qy) = (q % 4, q / 4);
            *slot = [
                basis[ky][2 * qy],
                basis[ky][2 * qy + 1],
                basis[kx][2 * qx],
                basis[kx][2 * qx + 1],
            ];
        }
    }
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("vbim dct tables"),
        contents: bytemuck::bytes_of(&t),
        usage: tables_in.usage(),
    })
}
