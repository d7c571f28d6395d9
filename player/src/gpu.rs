//! The GPU side: what stays resident — the chain's head keyframe (R32Float, one layer
//! per plane), the keyframe before it (16-bit steps of a range per 32² region, two to an
//! R32Uint texel), one set of bubble planes (16-bit signed integers with a scale per
//! plane, two to an R32Uint texel), the display texture the renderer samples and a held
//! copy for catch-up blending (RGB9E5 in an R32Uint texel) — and the passes that fill
//! them: the segment decode of `decode.wgsl` (dequantisation, inverse DCT, predicted
//! keyframes) and the per-frame reconstruction of `reconstruct.wgsl`.
//!
//! The head stays f32: the next predicted keyframe is built on it, and a 16-bit head
//! would add its rounding at every step of the chain (docs/FORMAT.md, "What the GPU
//! decoder guarantees"). The previous keyframe is only displayed, and is packed afresh
//! from the f32 head at every step, so it carries one rounding, like the bubble planes,
//! which are rebuilt for every segment from their coefficients.

use wgpu::util::DeviceExt;

use crate::compact::Compact;
use crate::decoder::SegmentData;
use crate::slots::MAX_BUBBLE_PLANES;

/// Finds an adapter and opens a device without a window. With no adapter, the error says
/// what to install.
pub fn headless_device() -> Result<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo), String> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter =
        pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
            .map_err(|e| {
                format!(
            "no GPU adapter found ({e}). On a machine without a GPU install a software one: \
             `apt-get install -y libvulkan1 mesa-vulkan-drivers` (Vulkan, lavapipe) or \
             `libegl1 libegl-mesa0 libgl1-mesa-dri` (OpenGL, llvmpipe)"
        )
            })?;
    let info = adapter.get_info();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("vbim"),
        required_features: wgpu::Features::empty(),
        // WebGPU's defaults, not the adapter's maxima: what Bevy and browsers give.
        required_limits: wgpu::Limits::default(),
        ..Default::default()
    }))
    .map_err(|e| {
        format!(
            "{} ({:?}): cannot open a device: {e}",
            info.name, info.backend
        )
    })?;
    Ok((device, queue, info))
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Params {
    pub w: [f32; 12],
    pub size: [u32; 2],
    pub layers: u32,
    pub transfer: u32,
    pub v0: f32,
    pub alpha: f32,
    pub channels: u32,
    pub blend: u32,
    /// Regions of the previous keyframe's ranges, across and down.
    pub regions: [u32; 2],
    pub _pad: [u32; 2],
    /// Scale of each bubble plane.
    pub scales: [f32; MAX_BUBBLE_PLANES],
}

/// One decode pass's parameters (`Job` in decode.wgsl), at a 256-byte stride in a uniform
/// buffer bound with a dynamic offset.
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Job {
    step: f32,
    inv_scale: f32,
    records: u32,
    count: u32,
    terms: u32,
    terms_end: u32,
    layer: u32,
    groups_x: u32,
    size: [u32; 2],
    _pad: [u32; 2],
}

const JOB_STRIDE: u64 = 256;
/// Bytes [`Gpu::decode`] uploads for `seg`: its records and terms, and one job's
/// parameters per plane decoded (and the bubbles' zero pass).
pub(crate) fn upload_bytes(seg: &SegmentData, bubbles: bool) -> u64 {
    seg.bytes() + job_bytes(seg, bubbles)
}

/// The planes [`Gpu::decode`] decodes: the keyframe steps', and the bubbles' when wanted.
fn decoded_planes(seg: &SegmentData, bubbles: bool) -> usize {
    if bubbles {
        seg.planes.len()
    } else {
        seg.bubbles
    }
}

/// Bytes of the decode passes' parameters: one job per plane, and one for the bubbles'
/// zero pass.
fn job_bytes(seg: &SegmentData, bubbles: bool) -> u64 {
    (decoded_planes(seg, bubbles) as u64 + 1) * JOB_STRIDE
}

/// Workgroups per dispatch row: WebGPU's default limit per dimension.
const GROUPS_X: u32 = 65_535;

/// The DCT basis and zig-zag order (`Tables` in decode.wgsl).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Tables {
    basis: [f32; 64],
    zigzag: [u32; 64],
}

pub(crate) struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    /// Packs what is on screen into `held` (from the display, or the caller's output).
    hold: wgpu::ComputePipeline,
    hold_layout: wgpu::BindGroupLayout,
    hold_group: wgpu::BindGroup,
    key_add: wgpu::ComputePipeline,
    key_zero: wgpu::ComputePipeline,
    key_pack: wgpu::ComputePipeline,
    bubble_write: wgpu::ComputePipeline,
    bubble_zero: wgpu::ComputePipeline,
    key_layout: wgpu::BindGroupLayout,
    bubble_layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    tables: wgpu::Buffer,
    /// Decode pass parameters, `JOB_STRIDE` apart; grows with the longest keyframe chain.
    jobs: wgpu::Buffer,
    /// A segment's records and terms; grows with the largest segment.
    words: wgpu::Buffer,
    /// The chain's head keyframe K_{s+1}, f32.
    keys: wgpu::Texture,
    /// One view per plane of the head, for the decode passes.
    key_views: Vec<wgpu::TextureView>,
    /// The previous keyframe K_s, 16-bit, and the range of each of its regions.
    previous: wgpu::Texture,
    previous_view: wgpu::TextureView,
    ranges: wgpu::Buffer,
    regions: [u32; 2],
    bubbles: wgpu::Texture,
    bubble_view: wgpu::TextureView,
    display: wgpu::Texture,
    pub display_view: wgpu::TextureView,
    held: wgpu::Texture,
    bind_group: wgpu::BindGroup,
    /// The reconstruction's layout and inputs, for a bind group over a caller's texture.
    reconstruct_layout: wgpu::BindGroupLayout,
    keys_view: wgpu::TextureView,
    held_view: wgpu::TextureView,
    /// A texture of the caller's that the reconstruction writes instead of `display`, with
    /// the reconstruction's and the hold pass's bind groups over it.
    output: Option<(wgpu::Texture, wgpu::BindGroup, wgpu::BindGroup)>,
    /// Decode bind groups (per keyframe layer, and the bubbles'): remade when `words` or
    /// `jobs` grow.
    key_groups: Vec<wgpu::BindGroup>,
    bubble_group: Option<wgpu::BindGroup>,
    /// Scratch for the jobs of one segment (kept: no allocation per segment).
    job_bytes: Vec<u8>,
    pub width: u32,
    pub height: u32,
    /// The padded planes' size (whole tiles).
    plane: [u32; 2],
    pub channels: u32,
}

/// Bytes a buffer of at least `need` bytes is given: an eighth more (at least 64 KiB), so
/// that it grows a few times at the start of a stream and then never, without the up to
/// 2× of rounding to a power of two (2 bytes per texel of a 2048² stream's coefficients).
fn grown(need: u64) -> u64 {
    (need + need / 8)
        .max(1 << 16)
        .next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT)
}

/// The side of a region of the previous keyframe with its own range (`REGION` in
/// decode.wgsl; `REGION_GROUPS` workgroups of 8 × 8 in reconstruct.wgsl).
const REGION: u32 = 32;

/// Regions of [`REGION`]² texels across and down a plane of `plane` texels.
fn regions(plane: [u32; 2]) -> [u32; 2] {
    plane.map(|n| n.div_ceil(REGION))
}

/// Bytes of the previous keyframe's ranges: a (lowest value, step) pair of f32 per region
/// and plane.
fn range_bytes(plane: [u32; 2], channels: u32) -> u64 {
    let [rx, ry] = regions(plane);
    rx as u64 * ry as u64 * channels as u64 * 8
}

/// The textures [`Gpu::new`] creates for a stream of `width × height` texels coded on
/// planes of `plane` texels with bubble terms up to `max_degree`: the head keyframe
/// (f32), the previous keyframe and the bubble planes (16-bit pairs), the lightmap
/// (Rgba16Float) and its held copy (RGB9E5 packed into R32Uint).
fn texture_plans(
    (width, height): (u32, u32),
    plane: [u32; 2],
    max_degree: u32,
    channels: u32,
) -> [wgpu::TextureDescriptor<'static>; 5] {
    use wgpu::TextureUsages as U;
    let texture =
        |label, (width, height, depth_or_array_layers), format, usage| wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        };
    let bubble_layers = (max_degree.saturating_sub(1) * channels).max(1);
    [
        texture(
            "vbim head keyframe",
            (plane[0], plane[1], channels),
            wgpu::TextureFormat::R32Float,
            // (COPY_SRC: tests read it back.)
            U::TEXTURE_BINDING | U::STORAGE_BINDING | U::COPY_SRC,
        ),
        texture(
            "vbim previous keyframe",
            (plane[0] / 2, plane[1], channels),
            wgpu::TextureFormat::R32Uint,
            U::TEXTURE_BINDING | U::STORAGE_BINDING | U::COPY_SRC,
        ),
        texture(
            "vbim bubbles",
            (plane[0] / 2, plane[1], bubble_layers),
            wgpu::TextureFormat::R32Uint,
            // (COPY_SRC: tests read it back.)
            U::TEXTURE_BINDING | U::STORAGE_BINDING | U::COPY_SRC,
        ),
        texture(
            "vbim lightmap",
            (width, height, 1),
            wgpu::TextureFormat::Rgba16Float,
            U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC,
        ),
        texture(
            "vbim held",
            (width, height, 1),
            wgpu::TextureFormat::R32Uint,
            U::TEXTURE_BINDING | U::STORAGE_BINDING,
        ),
    ]
}

/// Bytes of the textures and range buffer [`Gpu::new`] creates for a stream
/// ([`texture_plans`]'s), known before creating them, so that a stream is refused before
/// anything that size exists.
pub(crate) fn planned_texture_bytes(
    size: (u32, u32),
    plane: [u32; 2],
    max_degree: u32,
    channels: u32,
) -> u64 {
    texture_plans(size, plane, max_degree, channels)
        .iter()
        .map(|d| extent_bytes(d.size, d.format))
        .sum::<u64>()
        + range_bytes(plane, channels)
}

impl Gpu {
    /// GPU state for a stream of `width × height` texels of `channels` planes, coded on
    /// planes of `plane` texels (whole tiles), with bubble terms up to `max_degree`.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        (width, height): (u32, u32),
        plane: [u32; 2],
        max_degree: u32,
        channels: u32,
    ) -> Gpu {
        let [keys, previous, bubbles, display, held] =
            texture_plans((width, height), plane, max_degree, channels)
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
        let bubble_view = array_view(&bubbles);
        let previous_view = array_view(&previous);
        let ranges = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vbim previous keyframe ranges"),
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
        let mut t = Tables {
            basis: [0.0; 64],
            zigzag: [0; 64],
        };
        for (k, row) in vbim_format::dct::basis().iter().enumerate() {
            t.basis[k * 8..k * 8 + 8].copy_from_slice(row);
        }
        for (i, &z) in vbim_format::dct::zigzag().iter().enumerate() {
            t.zigzag[i] = z as u32;
        }
        let tables = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("vbim dct tables"),
            contents: bytemuck::bytes_of(&t),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let entry = |binding: u32, ty: wgpu::BindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let uniform = |dynamic| wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        };
        let storage = |read_only| wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        use wgpu::TextureViewDimension::{D2Array, D2};
        let sampled = |sample_type, view_dimension| wgpu::BindingType::Texture {
            sample_type,
            view_dimension,
            multisampled: false,
        };
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim reconstruct"),
            entries: &[
                entry(0, uniform(false)),
                entry(
                    1,
                    sampled(
                        wgpu::TextureSampleType::Float { filterable: false },
                        D2Array,
                    ),
                ),
                entry(2, sampled(wgpu::TextureSampleType::Uint, D2Array)),
                entry(3, sampled(wgpu::TextureSampleType::Uint, D2)),
                entry(
                    4,
                    wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: wgpu::TextureFormat::Rgba16Float,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                ),
                entry(5, sampled(wgpu::TextureSampleType::Uint, D2Array)),
                entry(6, storage(true)),
            ],
        });
        let hold_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim hold"),
            entries: &[
                entry(
                    7,
                    sampled(wgpu::TextureSampleType::Float { filterable: false }, D2),
                ),
                entry(
                    8,
                    wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: wgpu::TextureFormat::R32Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                ),
            ],
        });
        let words_entry = entry(2, storage(true));
        let planes16 = entry(
            4,
            wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: wgpu::TextureFormat::R32Uint,
                view_dimension: wgpu::TextureViewDimension::D2Array,
            },
        );
        let key_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim keyframe decode"),
            entries: &[
                entry(0, uniform(true)),
                entry(1, uniform(false)),
                words_entry,
                entry(
                    3,
                    wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::ReadWrite,
                        format: wgpu::TextureFormat::R32Float,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                ),
                planes16,
                entry(5, storage(false)),
            ],
        });
        let bubble_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim bubble decode"),
            entries: &[
                entry(0, uniform(true)),
                entry(1, uniform(false)),
                words_entry,
                planes16,
            ],
        });
        let pipeline_for =
            |label: &str, source: &str, layout: &wgpu::BindGroupLayout, entry: &str| {
                let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some(label),
                    source: wgpu::ShaderSource::Wgsl(source.into()),
                });
                let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some(label),
                    bind_group_layouts: &[Some(layout)],
                    immediate_size: 0,
                });
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(label),
                    layout: Some(&layout),
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
            };
        let decode = include_str!("decode.wgsl");
        let pipeline = pipeline_for(
            "vbim reconstruct",
            include_str!("reconstruct.wgsl"),
            &bgl,
            "main",
        );
        let hold = pipeline_for(
            "vbim hold",
            include_str!("reconstruct.wgsl"),
            &hold_layout,
            "hold",
        );
        let hold_group = hold_group(device, &hold_layout, &display_view, &held_view);
        let key_add = pipeline_for("vbim key_add", decode, &key_layout, "key_add");
        let key_zero = pipeline_for("vbim key_zero", decode, &key_layout, "key_zero");
        let key_pack = pipeline_for("vbim key_pack", decode, &key_layout, "key_pack");
        let bubble_write =
            pipeline_for("vbim bubble_write", decode, &bubble_layout, "bubble_write");
        let bubble_zero = pipeline_for("vbim bubble_zero", decode, &bubble_layout, "bubble_zero");
        let bind_group = reconstruct_group(
            device,
            &bgl,
            [
                &keys_view,
                &bubble_view,
                &held_view,
                &display_view,
                &previous_view,
            ],
            &ranges,
            &params,
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
        let jobs = buffer(
            "vbim decode jobs",
            64 * JOB_STRIDE,
            B::UNIFORM | B::COPY_DST,
        );
        let words = buffer("vbim coefficients", grown(0), B::STORAGE | B::COPY_DST);
        let mut gpu = Gpu {
            device: device.clone(),
            queue: queue.clone(),
            pipeline,
            hold,
            hold_layout,
            hold_group,
            key_add,
            key_zero,
            key_pack,
            bubble_write,
            bubble_zero,
            key_layout,
            bubble_layout,
            params,
            tables,
            jobs,
            words,
            keys,
            key_views,
            previous,
            previous_view,
            ranges,
            regions: regions(plane),
            bubbles,
            bubble_view,
            display,
            display_view,
            held,
            bind_group,
            reconstruct_layout: bgl,
            keys_view,
            held_view,
            output: None,
            key_groups: Vec::new(),
            bubble_group: None,
            job_bytes: Vec::with_capacity(64 * JOB_STRIDE as usize),
            width,
            height,
            plane,
            channels,
        };
        gpu.bind_decode();
        gpu
    }

    /// (Re)makes the decode passes' bind groups over the current `jobs` and `words`.
    fn bind_decode(&mut self) {
        let job = wgpu::BufferBinding {
            buffer: &self.jobs,
            offset: 0,
            size: wgpu::BufferSize::new(std::mem::size_of::<Job>() as u64),
        };
        let group = |layout: &wgpu::BindGroupLayout, more: &[wgpu::BindGroupEntry]| {
            let mut entries = vec![
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(job.clone()),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: self.tables.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: self.words.as_entire_binding(),
                },
            ];
            entries.extend_from_slice(more);
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
        self.key_groups = self
            .key_views
            .iter()
            .map(|v| {
                let ranges = wgpu::BindGroupEntry {
                    binding: 5,
                    resource: self.ranges.as_entire_binding(),
                };
                group(
                    &self.key_layout,
                    &[view(3, v), view(4, &self.previous_view), ranges],
                )
            })
            .collect();
        self.bubble_group = Some(group(&self.bubble_layout, &[view(4, &self.bubble_view)]));
    }

    /// Bytes of the textures and buffers the player holds on the GPU (the budget's figure).
    pub fn bytes(&self) -> u64 {
        [
            &self.keys,
            &self.previous,
            &self.bubbles,
            &self.display,
            &self.held,
        ]
        .iter()
        .map(|t| texture_bytes(t))
        .sum::<u64>()
            + self.ranges.size()
            + self.params.size()
            + self.tables.size()
            + self.jobs.size()
            + self.words.size()
    }

    /// Whether a segment's coefficients fit one storage binding of this device.
    pub fn fits(&self, seg: &SegmentData) -> Result<(), String> {
        let limit = self.device.limits().max_storage_buffer_binding_size;
        let need = seg.bytes();
        if need > limit {
            return Err(format!(
                "segment {}: {need} bytes of coefficients, more than one storage binding holds ({limit})",
                seg.index
            ));
        }
        Ok(())
    }

    /// Records the decode of `seg` into `enc`: its keyframe steps, built in turn on the
    /// head (the head packed into the previous keyframe before the last step), then
    /// (with `bubbles`) its bubble planes. The records and terms go through
    /// `Queue::write_buffer`, which takes effect at the queue's next submission: the one
    /// that carries `enc`. It uploads [`upload_bytes`].
    pub fn decode(&mut self, enc: &mut wgpu::CommandEncoder, seg: &SegmentData, bubbles: bool) {
        let ch = self.channels as usize;
        let rec_bytes = seg.record_bytes();
        let words = seg.bytes();
        let planes = decoded_planes(seg, bubbles);
        let jobs = job_bytes(seg, bubbles);
        if words > self.words.size() || jobs > self.jobs.size() {
            use wgpu::BufferUsages as B;
            if words > self.words.size() {
                self.words = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("vbim coefficients"),
                    size: grown(words),
                    usage: B::STORAGE | B::COPY_DST,
                    mapped_at_creation: false,
                });
            }
            if jobs > self.jobs.size() {
                self.jobs = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("vbim decode jobs"),
                    size: grown(jobs),
                    usage: B::UNIFORM | B::COPY_DST,
                    mapped_at_creation: false,
                });
            }
            self.bind_decode();
        }
        match &seg.staged {
            // Packed into a staging buffer by the decoder thread: a copy on the GPU, no
            // bytes through this thread.
            Some(staged) => {
                enc.copy_buffer_to_buffer(&staged.buffer, 0, &self.words, 0, staged.bytes)
            }
            None => self.write_words(&seg.data),
        }
        // Terms are addressed in u16 entries from the start of `words`.
        let term0 = (rec_bytes / 2) as u32;
        let (pw, ph) = (self.plane[0], self.plane[1]);
        self.job_bytes.clear();
        for (i, span) in seg.planes[..planes].iter().enumerate() {
            let job = Job {
                step: span.step,
                inv_scale: if span.scale > 0.0 {
                    1.0 / span.scale
                } else {
                    0.0
                },
                records: span.records,
                count: span.count,
                terms: term0 + span.terms,
                terms_end: term0 + span.terms_end,
                // A bubble plane's layer; a keyframe plane's channel, the layer of the
                // previous keyframe `key_pack` writes (the head's passes write the layer
                // their binding views).
                layer: if i < seg.bubbles {
                    i % ch
                } else {
                    i - seg.bubbles
                } as u32,
                groups_x: GROUPS_X,
                size: [pw, ph],
                _pad: [0; 2],
            };
            self.push_job(job);
        }
        let bubble_layers = ((seg.layers.saturating_sub(2)) * ch) as u32;
        self.push_job(Job {
            layer: bubble_layers,
            size: [pw / 2, ph],
            ..Job::default()
        });
        self.queue.write_buffer(&self.jobs, 0, &self.job_bytes);
        let dispatch = |pass: &mut wgpu::ComputePass, count: u32| {
            if count > 0 {
                pass.dispatch_workgroups(count.min(GROUPS_X), count.div_ceil(GROUPS_X), 1);
            }
        };
        let last = seg.steps.len().saturating_sub(1);
        for (n, st) in seg.steps.iter().enumerate() {
            for p in 0..ch {
                let plane = st.plane + p;
                let offset = (plane as u64 * JOB_STRIDE) as u32;
                let mut pass = enc.begin_compute_pass(&Default::default());
                pass.set_bind_group(0, &self.key_groups[p], &[offset]);
                if n == last {
                    // The head becomes the previous keyframe (the earlier steps' heads are
                    // never shown).
                    // (One invocation per region, 64 to a workgroup.)
                    pass.set_pipeline(&self.key_pack);
                    let [rx, ry] = self.regions;
                    pass.dispatch_workgroups((rx * ry).div_ceil(64), 1, 1);
                }
                if st.intra {
                    pass.set_pipeline(&self.key_zero);
                    pass.dispatch_workgroups(pw.div_ceil(8), ph.div_ceil(8), 1);
                }
                // A predicted keyframe is added onto the head: the keyframe it follows.
                pass.set_pipeline(&self.key_add);
                dispatch(&mut pass, seg.planes[plane].count);
            }
        }
        if bubbles {
            let mut pass = enc.begin_compute_pass(&Default::default());
            let zero = (planes as u64 * JOB_STRIDE) as u32;
            let bubble_group = self.bubble_group.as_ref().expect("made at creation");
            pass.set_bind_group(0, bubble_group, &[zero]);
            pass.set_pipeline(&self.bubble_zero);
            if bubble_layers > 0 {
                pass.dispatch_workgroups((pw / 2).div_ceil(8), ph.div_ceil(8), bubble_layers);
            }
            pass.set_pipeline(&self.bubble_write);
            for (i, span) in seg.planes[seg.bubbles..planes].iter().enumerate() {
                let plane = seg.bubbles + i;
                pass.set_bind_group(0, bubble_group, &[(plane as u64 * JOB_STRIDE) as u32]);
                dispatch(&mut pass, span.count);
            }
        }
    }

    fn push_job(&mut self, job: Job) {
        let at = self.job_bytes.len();
        self.job_bytes.extend_from_slice(bytemuck::bytes_of(&job));
        self.job_bytes.resize(at + JOB_STRIDE as usize, 0);
    }

    /// Makes the reconstruction write into `texture` (the caller's) instead of the
    /// player's own lightmap, or into its own again with `None`.
    pub fn set_output(&mut self, texture: Option<&wgpu::Texture>) -> Result<(), String> {
        let Some(t) = texture else {
            self.output = None;
            return Ok(());
        };
        use wgpu::TextureUsages as U;
        let need = U::STORAGE_BINDING | U::TEXTURE_BINDING;
        if t.format() != wgpu::TextureFormat::Rgba16Float
            || (t.width(), t.height()) != (self.width, self.height)
            || t.depth_or_array_layers() != 1
            || t.dimension() != wgpu::TextureDimension::D2
            || !t.usage().contains(need)
        {
            return Err(format!(
                "the output must be a {}×{} 2D Rgba16Float texture with STORAGE_BINDING | \
                 TEXTURE_BINDING usage (the player reads it to keep the image on screen for \
                 catch-up blending); got {}×{}×{} {:?} with {:?}",
                self.width,
                self.height,
                t.width(),
                t.height(),
                t.depth_or_array_layers(),
                t.format(),
                t.usage()
            ));
        }
        let view = t.create_view(&Default::default());
        let group = reconstruct_group(
            &self.device,
            &self.reconstruct_layout,
            [
                &self.keys_view,
                &self.bubble_view,
                &self.held_view,
                &view,
                &self.previous_view,
            ],
            &self.ranges,
            &self.params,
        );
        let hold = hold_group(&self.device, &self.hold_layout, &view, &self.held_view);
        self.output = Some((t.clone(), group, hold));
        Ok(())
    }

    /// The texture the reconstruction writes: the caller's, or the player's own.
    fn target(&self) -> &wgpu::Texture {
        self.output.as_ref().map_or(&self.display, |(t, ..)| t)
    }

    /// Keeps what is on screen for blending (at the start of a catch-up).
    pub fn hold(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&self.hold);
        let group = self.output.as_ref().map_or(&self.hold_group, |(.., g)| g);
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(self.width.div_ceil(8), self.height.div_ceil(8), 1);
    }

    /// Uploads `data` into the coefficient buffer from the CPU (a box packed by a decoder
    /// without a device): records, then terms padded to a whole word.
    fn write_words(&self, data: &Compact) {
        let rec_bytes = data.records.len() as u64 * 4;
        if rec_bytes > 0 {
            self.queue
                .write_buffer(&self.words, 0, bytemuck::cast_slice(&data.records));
        }
        if data.terms.is_empty() {
            return;
        }
        let t: &[u8] = bytemuck::cast_slice(&data.terms);
        if t.len().is_multiple_of(4) {
            self.queue.write_buffer(&self.words, rec_bytes, t);
        } else {
            // Whole words only: the last entry goes with a zero beside it.
            let (body, last) = t.split_at(t.len() - 2);
            if !body.is_empty() {
                self.queue.write_buffer(&self.words, rec_bytes, body);
            }
            let tail = [last[0], last[1], 0, 0];
            self.queue
                .write_buffer(&self.words, rec_bytes + body.len() as u64, &tail);
        }
    }

    /// Records the reconstruction of one frame into `enc`. The parameters go through
    /// `Queue::write_buffer`, which takes effect at the queue's next submission: the one
    /// that carries `enc`.
    pub fn reconstruct(&self, enc: &mut wgpu::CommandEncoder, params: &Params, hold_first: bool) {
        let params = Params {
            regions: self.regions,
            ..*params
        };
        self.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        if hold_first {
            self.hold(enc);
        }
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        let group = self.output.as_ref().map_or(&self.bind_group, |(_, g, _)| g);
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(self.width.div_ceil(8), self.height.div_ceil(8), 1);
    }

    /// Reads the texture the reconstruction writes back (RGBA, f32). For tests and error
    /// measurement.
    pub fn read_display(&self) -> Vec<f32> {
        let raw = read_texture(&self.device, &self.queue, self.target(), 8);
        bytemuck::cast_slice::<u8, half::f16>(&raw)
            .iter()
            .map(|v| v.to_f32())
            .collect()
    }

    /// Waits for the GPU to finish what was submitted.
    pub fn wait(&self) {
        let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
    }
}

impl Params {
    pub fn zeroed_params() -> Params {
        bytemuck::Zeroable::zeroed()
    }
}

/// The reconstruction's bind group: its parameters, then the head keyframe, bubble
/// planes, held image, output and previous keyframe views, and the previous keyframe's
/// ranges.
fn reconstruct_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    views: [&wgpu::TextureView; 5],
    ranges: &wgpu::Buffer,
    params: &wgpu::Buffer,
) -> wgpu::BindGroup {
    let mut entries = vec![wgpu::BindGroupEntry {
        binding: 0,
        resource: params.as_entire_binding(),
    }];
    for (i, v) in views.into_iter().enumerate() {
        entries.push(wgpu::BindGroupEntry {
            binding: i as u32 + 1,
            resource: wgpu::BindingResource::TextureView(v),
        });
    }
    entries.push(wgpu::BindGroupEntry {
        binding: 6,
        resource: ranges.as_entire_binding(),
    });
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("vbim reconstruct"),
        layout,
        entries: &entries,
    })
}

/// The hold pass's bind group: what is on screen, and the held texture it packs it into.
fn hold_group(
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

/// Bytes a texture holds (one mip level, every layer).
fn texture_bytes(t: &wgpu::Texture) -> u64 {
    extent_bytes(t.size(), t.format())
}

/// Bytes of a texture of `size` texels of `format`.
fn extent_bytes(size: wgpu::Extent3d, format: wgpu::TextureFormat) -> u64 {
    let texel = format.block_copy_size(None).unwrap_or(0) as u64;
    size.width as u64 * size.height as u64 * size.depth_or_array_layers as u64 * texel
}

/// Copies a 2D texture to the CPU, rows tightly packed (`bytes_per_texel` per texel):
/// blocks until the GPU is done. For tests, measurements and headless capture.
pub fn read_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    bytes_per_texel: u32,
) -> Vec<u8> {
    read_texture_layer(device, queue, texture, bytes_per_texel, 0)
}

/// [`read_texture`] for one layer of an array texture.
fn read_texture_layer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    bytes_per_texel: u32,
    layer: u32,
) -> Vec<u8> {
    let (w, h) = (texture.width(), texture.height());
    let row = (w * bytes_per_texel).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
        * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("vbim readback"),
        size: (row * h) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d {
                x: 0,
                y: 0,
                z: layer,
            },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    queue.submit(Some(enc.finish()));
    let slice = buf.slice(..);
    slice.map_async(wgpu::MapMode::Read, |_| {});
    let _ = device.poll(wgpu::PollType::wait_indefinitely());
    let data = slice.get_mapped_range();
    let mut out = Vec::with_capacity((w * h * bytes_per_texel) as usize);
    for y in 0..h as usize {
        let start = y * row as usize;
        out.extend_from_slice(&data[start..start + (w * bytes_per_texel) as usize]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::decoder::KeyStep;
    use vbim_format::plane::{self, Blocks, Onto, Plane};

    fn random_blocks(n: usize, seed: &mut u32) -> Vec<[i32; 64]> {
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

    /// The keyframe passes on a real adapter: an intra keyframe, then a predicted one
    /// built on it, against the reference decoder's block kernel; the first, packed into
    /// the previous keyframe, within half a 16-bit step of its region's range.
    #[test]
    fn keyframe_passes_match_the_reference_kernel() {
        let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
        let (pw, ph) = (96u32, 24u32);
        let (bw, bh) = (pw as usize / 8, ph as usize / 8);
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1);
        let mut seed = 3;
        let mut want = Plane::zeros(pw as usize, ph as usize);
        let mut first = None;
        let mut seg = SegmentData::new();
        for (n, step) in [(0usize, 0.01f32), (1, 0.002)] {
            if n == 1 {
                first = Some(want.clone());
            }
            let blocks = random_blocks(bw * bh, &mut seed);
            let mut raw = Vec::new();
            plane::write_coefficients(&blocks, &mut raw);
            let mut parsed = Blocks::default();
            plane::read_blocks(&raw, &mut 0, blocks.len(), &mut parsed).unwrap();
            let at = (0..bh).flat_map(|y| (0..bw).map(move |x| (x, y)));
            plane::add_blocks_of(&mut want, at, Onto::Plane, &parsed, 0, step);
            let mut c = Compact::default();
            let span = c.push_plane(step, &parsed, (bw, bh), |x, y| Some(y * bw + x), false);
            seg.steps = vec![KeyStep {
                number: n,
                intra: n == 0,
                plane: 0,
            }];
            seg.planes = vec![span];
            seg.bubbles = 1;
            seg.data = c;
            seg.layers = 2;
            let mut enc = device.create_command_encoder(&Default::default());
            gpu.decode(&mut enc, &seg, false);
            queue.submit([enc.finish()]);
        }
        let raw = read_texture_layer(&device, &queue, &gpu.keys, 4, 0);
        let got: &[f32] = bytemuck::cast_slice(&raw);
        let peak = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
        for (i, (g, w)) in got.iter().zip(&want.data).enumerate() {
            assert!(
                (g - w).abs() <= 1e-5 * peak,
                "texel {i}: GPU {g} against {w}"
            );
        }
        // The previous keyframe: 16-bit steps of each 32² region's range.
        let first = first.expect("two steps");
        let raw = read_texture_layer(&device, &queue, &gpu.previous, 4, 0);
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

    /// The bubble pass: a plane whose tiles of columns 4–7 are absent, written as
    /// 16-bit integers times its scale, zeros outside its blocks.
    #[test]
    fn bubble_passes_match_the_reference_kernel_within_half_a_step() {
        let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
        let (pw, ph) = (96u32, 24u32);
        let (bw, bh) = (pw as usize / 8, ph as usize / 8);
        let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1);
        let blocks = random_blocks(bw * bh, &mut 11);
        let mut raw = Vec::new();
        plane::write_coefficients(&blocks, &mut raw);
        let mut parsed = Blocks::default();
        plane::read_blocks(&raw, &mut 0, blocks.len(), &mut parsed).unwrap();
        let step = 0.004;
        let order = |x: usize, y: usize| (!(4..8).contains(&x)).then_some(y * bw + x);
        let mut want = Plane::zeros(pw as usize, ph as usize);
        for (x, y) in (0..bh).flat_map(|y| (0..bw).map(move |x| (x, y))) {
            if let Some(b) = order(x, y) {
                let at = std::iter::once((x, y));
                plane::add_blocks_of(&mut want, at, Onto::Zeros, &parsed, b, step);
            }
        }
        let mut c = Compact::default();
        let mut span = c.push_plane(step, &parsed, (bw, bh), order, true);
        span.scale = crate::compact::bubble_scale(span.bound);
        let mut seg = SegmentData::new();
        seg.steps = Vec::new();
        seg.planes = vec![span];
        seg.bubbles = 0;
        seg.data = c;
        seg.layers = 3;
        let mut enc = device.create_command_encoder(&Default::default());
        gpu.decode(&mut enc, &seg, true);
        queue.submit([enc.finish()]);
        let raw = read_texture_layer(&device, &queue, &gpu.bubbles, 4, 0);
        let got: Vec<f32> = bytemuck::cast_slice::<u8, i16>(&raw)
            .iter()
            .map(|&q| q as f32 * span.scale)
            .collect();
        for (i, (g, w)) in got.iter().zip(&want.data).enumerate() {
            assert!(
                (g - w).abs() <= 0.5001 * span.scale,
                "texel {i}: GPU {g} against {w} (scale {})",
                span.scale
            );
        }
    }

    /// The held image: what is on screen, packed by the hold pass and read back through
    /// a blend at its start (alpha 0), is within a 9-bit step of the texel's largest
    /// channel (and the output's half-float rounding), from zero to beyond RGB9E5's range.
    #[test]
    fn the_held_image_keeps_nine_bits_of_each_texels_largest_channel() {
        let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
        let (w, h) = (16u32, 8u32);
        let mut gpu = Gpu::new(&device, &queue, (w, h), [w, h], 2, 3);
        use wgpu::TextureUsages as U;
        let screen = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("on screen"),
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba16Float,
            usage: U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC | U::COPY_DST,
            view_formats: &[],
        });
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
        gpu.reconstruct(&mut enc, &params, true);
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
}
