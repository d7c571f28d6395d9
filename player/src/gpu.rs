//! The GPU side: what stays resident — the chain's head keyframe (R32Float, one layer
//! per plane), the keyframe before it (16-bit steps of a range per 32² region, two to an
//! R32Uint texel), one set of bubble planes (16-bit signed integers with a scale per
//! plane, two to an R32Uint texel), the display texture the renderer samples and a held
//! copy for catch-up blending (RGB9E5 in an R32Uint texel) — and the passes that fill
//! them: the segment decode of `decode.wgsl` (parsing the coefficient streams,
//! dequantisation, inverse DCT, predicted keyframes) and the per-frame reconstruction of
//! `reconstruct.wgsl`. The decode parses each plane into a dense plane of i32
//! coefficients with a 64-bit mask per block (4 bytes per texel of one plane, reused
//! plane after plane), which the passes after it read and put back to zero.
//!
//! The head stays f32: the next predicted keyframe is built on it, and a 16-bit head
//! would add its rounding at every step of the chain (docs/FORMAT.md, "What the GPU
//! decoder guarantees"). The previous keyframe is only displayed, and is packed afresh
//! from the f32 head at every step, so it carries one rounding, like the bubble planes,
//! which are rebuilt for every segment from their coefficients.

use wgpu::util::DeviceExt;

use crate::coded::Coded;
use crate::decoder::SegmentData;
use crate::slots::MAX_BUBBLE_PLANES;

/// Finds an adapter and opens a device without a window, on the backends `WGPU_BACKEND`
/// names (all of them by default). With no adapter, the error says what to install.
pub fn headless_device() -> Result<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo), String> {
    open_headless(wgpu::InstanceDescriptor::new_without_display_handle_from_env())
}

/// [`headless_device`] on `backends` alone (for example `wgpu::Backends::GL`, the backend
/// WebGL and older machines give), whatever `WGPU_BACKEND` says.
pub fn headless_device_on(
    backends: wgpu::Backends,
) -> Result<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo), String> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    desc.backends = backends;
    open_headless(desc)
}

/// [`headless_device`] with GPU timestamps between dispatches where the adapter has them,
/// for `vbim bench decode --gpu`'s time per pass.
#[cfg(feature = "bench")]
pub fn timing_device() -> Result<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo), String> {
    open_headless_with(
        wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
        crate::marks::NEEDS,
    )
}

fn open_headless(
    desc: wgpu::InstanceDescriptor,
) -> Result<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo), String> {
    open_headless_with(desc, wgpu::Features::empty())
}

/// A device with `wanted`'s features that the adapter has (the others are left out).
fn open_headless_with(
    desc: wgpu::InstanceDescriptor,
    wanted: wgpu::Features,
) -> Result<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo), String> {
    let backends = desc.backends;
    let instance = wgpu::Instance::new(desc);
    let adapter =
        pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
            .map_err(|e| {
                format!(
            "no GPU adapter found on {backends:?} ({e}). On a machine without a GPU install \
             a software one: `apt-get install -y libvulkan1 mesa-vulkan-drivers` (Vulkan, \
             lavapipe) or `libegl1 libegl-mesa0 libgl1-mesa-dri` (OpenGL, llvmpipe)"
        )
            })?;
    let info = adapter.get_info();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("vbim"),
        required_features: wanted & adapter.features(),
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
    /// Quantiser step of each bubble plane (its scale comes from its bound, which the
    /// decode computed on the GPU).
    pub steps: [f32; MAX_BUBBLE_PLANES],
}

/// One decode pass's parameters (`Job` in decode.wgsl), at a 256-byte stride in a uniform
/// buffer bound with a dynamic offset.
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Job {
    step: f32,
    layer: u32,
    stream: u32,
    entries: u32,
    count: u32,
    blocks: u32,
    lo: u32,
    hi: u32,
    members: u32,
    member_count: u32,
    groups_x: u32,
    blocks_x: u32,
    per: u32,
    tiles_x: u32,
    size: [u32; 2],
    _pad: [u32; 2],
}

const JOB_STRIDE: u64 = 256;
/// Bytes [`Gpu::decode`] uploads for `seg` on a GPU whose dense plane holds `part`
/// blocks: its streams, entry points and member spans, and one job's parameters per part
/// of each plane decoded (and the bubbles' zero pass).
pub(crate) fn upload_bytes(seg: &SegmentData, bubbles: bool, part: u32) -> u64 {
    seg.bytes() + job_bytes(seg, bubbles, part)
}

/// The planes [`Gpu::decode`] decodes: the keyframe steps', and the bubbles' when wanted.
fn decoded_planes(seg: &SegmentData, bubbles: bool) -> usize {
    if bubbles {
        seg.planes.len()
    } else {
        seg.bubbles
    }
}

/// Bytes of the decode passes' parameters: one job per part of each plane, and one for
/// the bubbles' zero pass.
fn job_bytes(seg: &SegmentData, bubbles: bool, part: u32) -> u64 {
    let jobs: u64 = seg.planes[..decoded_planes(seg, bubbles)]
        .iter()
        .map(|p| parts(p.blocks, part) as u64)
        .sum();
    (jobs + 1) * JOB_STRIDE
}

/// Parts a plane of `blocks` blocks is decoded in, `part` blocks at most each (at least
/// one, so that an empty plane still has its job).
fn parts(blocks: u32, part: u32) -> u32 {
    blocks.div_ceil(part).max(1)
}

/// Blocks per workgroup of the block passes (`GROUP_BLOCKS` in decode.wgsl).
const GROUP_BLOCKS: u32 = 64;
/// Bytes of the sets of blocks with a coefficient for `blocks` blocks: 64 bits per group
/// of [`GROUP_BLOCKS`].
fn group_bytes(blocks: u32) -> u64 {
    blocks.div_ceil(GROUP_BLOCKS) as u64 * 8
}

/// Where the sets start in the mask buffer of a dense plane of `part` blocks: after the
/// masks, at a storage binding's offset alignment (WebGPU's default, 256), so that one
/// clear covers both.
fn groups_offset(part: u32) -> u64 {
    (part as u64 * 8).next_multiple_of(256)
}

/// Bytes of the mask buffer of a dense plane of `part` blocks: masks, then sets.
fn mask_bytes(part: u32) -> u64 {
    groups_offset(part) + group_bytes(part)
}

/// Blocks the dense plane holds for planes of `plane` texels: a whole plane, or as many
/// blocks as one storage binding of WebGPU's default limits holds.
pub(crate) fn part_blocks(plane: [u32; 2]) -> u32 {
    let whole = (plane[0] / 8) * (plane[1] / 8);
    let binding = wgpu::Limits::default().max_storage_buffer_binding_size / 256;
    whole.min(binding as u32).max(1)
}

/// Workgroups per dispatch row: WebGPU's default limit per dimension.
const GROUPS_X: u32 = 65_535;

/// The DCT basis and zig-zag order (`Tables` in decode.wgsl).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Tables {
    basis: [f32; 64],
    zigzag: [u32; 64],
    row_max: [f32; 8],
}

pub(crate) struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    /// Packs what is on screen into `held` (from the display, or the caller's output).
    hold: wgpu::ComputePipeline,
    hold_layout: wgpu::BindGroupLayout,
    hold_group: wgpu::BindGroup,
    parse: wgpu::ComputePipeline,
    key_add: wgpu::ComputePipeline,
    key_zero: wgpu::ComputePipeline,
    key_pack: wgpu::ComputePipeline,
    bubble_bound: wgpu::ComputePipeline,
    bubble_write: wgpu::ComputePipeline,
    bubble_zero: wgpu::ComputePipeline,
    key_layout: wgpu::BindGroupLayout,
    bubble_layout: wgpu::BindGroupLayout,
    parse_layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    tables: wgpu::Buffer,
    /// Decode pass parameters, `JOB_STRIDE` apart; grows with the longest keyframe chain.
    jobs: wgpu::Buffer,
    /// A segment's streams, entry points and member spans; grows with the largest segment.
    words: wgpu::Buffer,
    /// The dense plane: `part` blocks of 64 i32 coefficients; their masks, then per group
    /// of [`GROUP_BLOCKS`] blocks which have a coefficient ([`groups_offset`]). The masks
    /// and sets are cleared before each parse.
    coefs: wgpu::Buffer,
    masks: wgpu::Buffer,
    part: u32,
    /// Each bubble layer's bound (f32 bits), for the decode and the reconstruction.
    bounds: wgpu::Buffer,
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
    parse_group: Option<wgpu::BindGroup>,
    /// Scratch for the jobs of one segment, and each plane's first job (kept: no
    /// allocation per segment).
    job_bytes: Vec<u8>,
    first_job: Vec<u64>,
    /// Timestamps between the decode's dispatches (`vbim bench decode --gpu`).
    #[cfg(feature = "bench")]
    marks: Option<crate::marks::Marks>,
    pub width: u32,
    pub height: u32,
    /// The padded planes' size (whole tiles).
    plane: [u32; 2],
    pub channels: u32,
    /// Blocks across a tile, and tiles across a plane.
    per: u32,
    tiles_x: u32,
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

/// The fewest layers an array texture may have on `device`'s backend. wgpu's GL backend
/// decides whether a texture is an array from its layer count alone (one layer: a plain
/// 2D texture), and a one-layer texture bound as `texture_2d_array` there reads back
/// garbage; a second, unused layer keeps it an array. Other backends need no padding.
pub(crate) fn min_array_layers(device: &wgpu::Device) -> u32 {
    if device.adapter_info().backend == wgpu::Backend::Gl {
        2
    } else {
        1
    }
}

/// The textures [`Gpu::new`] creates for a stream of `width × height` texels coded on
/// planes of `plane` texels with bubble terms up to `max_degree`: the head keyframe
/// (f32), the previous keyframe and the bubble planes (16-bit pairs), the lightmap
/// (Rgba16Float) and its held copy (RGB9E5 packed into R32Uint). Array textures have at
/// least `min_layers` layers ([`min_array_layers`]).
fn texture_plans(
    (width, height): (u32, u32),
    plane: [u32; 2],
    max_degree: u32,
    channels: u32,
    min_layers: u32,
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
    let bubble_layers = (max_degree.saturating_sub(1) * channels).max(min_layers);
    let channels = channels.max(min_layers);
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

/// Bytes of the textures, the range buffer and the dense plane [`Gpu::new`] creates for a
/// stream ([`texture_plans`]'s), known before creating them, so that a stream is refused
/// before anything that size exists.
pub(crate) fn planned_texture_bytes(
    size: (u32, u32),
    plane: [u32; 2],
    max_degree: u32,
    channels: u32,
    min_layers: u32,
) -> u64 {
    texture_plans(size, plane, max_degree, channels, min_layers)
        .iter()
        .map(|d| extent_bytes(d.size, d.format))
        .sum::<u64>()
        + range_bytes(plane, channels)
        + part_blocks(plane) as u64 * 256
        + mask_bytes(part_blocks(plane))
        + BOUND_BYTES
}

/// Bytes of the bubble bounds: one u32 per bubble plane.
const BOUND_BYTES: u64 = MAX_BUBBLE_PLANES as u64 * 4;

impl Gpu {
    /// GPU state for the stream `h` describes (its size, padded planes, degree, channels
    /// and tiles).
    pub fn for_stream(device: &wgpu::Device, queue: &wgpu::Queue, h: &vbim_format::Header) -> Gpu {
        let (pw, ph) = vbim_format::chunk::padded_size(h);
        Gpu::new(
            device,
            queue,
            (h.width, h.height),
            [pw as u32, ph as u32],
            h.max_degree as u32,
            h.channels as u32,
            h.tile_size as u32,
        )
    }

    /// GPU state for a stream of `width × height` texels of `channels` planes, coded on
    /// planes of `plane` texels (whole tiles of `tile_size`), with bubble terms up to
    /// `max_degree`.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        (width, height): (u32, u32),
        plane: [u32; 2],
        max_degree: u32,
        channels: u32,
        tile_size: u32,
    ) -> Gpu {
        let [keys, previous, bubbles, display, held] = texture_plans(
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
            row_max: [0.0; 8],
        };
        for (k, row) in vbim_format::dct::basis().iter().enumerate() {
            t.basis[k * 8..k * 8 + 8].copy_from_slice(row);
        }
        for (i, &z) in vbim_format::dct::zigzag().iter().enumerate() {
            t.zigzag[i] = z as u32;
        }
        for (m, row) in t.row_max.iter_mut().zip(vbim_format::dct::basis()) {
            *m = row.iter().fold(0f32, |m, &v| m.max(v.abs()));
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
                entry(9, storage(true)),
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
                entry(6, storage(true)),
                entry(7, storage(true)),
                entry(10, storage(true)),
            ],
        });
        let bubble_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim bubble decode"),
            entries: &[
                entry(0, uniform(true)),
                entry(1, uniform(false)),
                words_entry,
                planes16,
                entry(6, storage(true)),
                entry(7, storage(true)),
                entry(8, storage(false)),
                entry(10, storage(true)),
            ],
        });
        let parse_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim parse"),
            entries: &[
                entry(0, uniform(true)),
                words_entry,
                entry(6, storage(false)),
                entry(7, storage(false)),
                entry(10, storage(false)),
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
        let decode = concat!(include_str!("job.wgsl"), include_str!("decode.wgsl"));
        let parse_source = concat!(include_str!("job.wgsl"), include_str!("parse.wgsl"));
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
        let parse = pipeline_for("vbim parse", parse_source, &parse_layout, "parse");
        let key_add = pipeline_for("vbim key_add", decode, &key_layout, "key_add");
        let key_zero = pipeline_for("vbim key_zero", decode, &key_layout, "key_zero");
        let key_pack = pipeline_for("vbim key_pack", decode, &key_layout, "key_pack");
        let bubble_bound =
            pipeline_for("vbim bubble_bound", decode, &bubble_layout, "bubble_bound");
        let bubble_write =
            pipeline_for("vbim bubble_write", decode, &bubble_layout, "bubble_write");
        let bubble_zero = pipeline_for("vbim bubble_zero", decode, &bubble_layout, "bubble_zero");
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
        let coefs = buffer("vbim dense coefficients", part as u64 * 256, B::STORAGE);
        let masks = buffer(
            "vbim coefficient masks and sets",
            mask_bytes(part),
            B::STORAGE | B::COPY_DST,
        );
        // (COPY_SRC: tests read it back.)
        let bounds = buffer(
            "vbim bubble bounds",
            BOUND_BYTES,
            B::STORAGE | B::COPY_DST | B::COPY_SRC,
        );
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
            [&ranges, &bounds],
            &params,
        );
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
            parse,
            key_add,
            key_zero,
            key_pack,
            bubble_bound,
            bubble_write,
            bubble_zero,
            key_layout,
            bubble_layout,
            parse_layout,
            params,
            tables,
            jobs,
            words,
            coefs,
            masks,
            part,
            bounds,
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
            parse_group: None,
            job_bytes: Vec::with_capacity(64 * JOB_STRIDE as usize),
            first_job: Vec::with_capacity(64),
            #[cfg(feature = "bench")]
            marks: None,
            width,
            height,
            plane,
            channels,
            per: tile_size / 8,
            tiles_x: plane[0] / tile_size,
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
            entries.extend_from_slice(more);
            entries.push(wgpu::BindGroupEntry {
                binding: 6,
                resource: self.coefs.as_entire_binding(),
            });
            let sets = groups_offset(self.part);
            entries.push(wgpu::BindGroupEntry {
                binding: 7,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &self.masks,
                    offset: 0,
                    size: wgpu::BufferSize::new(self.part as u64 * 8),
                }),
            });
            entries.push(wgpu::BindGroupEntry {
                binding: 10,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &self.masks,
                    offset: sets,
                    size: wgpu::BufferSize::new(group_bytes(self.part)),
                }),
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
            .map(|v| {
                let ranges = wgpu::BindGroupEntry {
                    binding: 5,
                    resource: self.ranges.as_entire_binding(),
                };
                group(
                    &self.key_layout,
                    &[
                        tables.clone(),
                        view(3, v),
                        view(4, &self.previous_view),
                        ranges,
                    ],
                )
            })
            .collect();
        let bounds = wgpu::BindGroupEntry {
            binding: 8,
            resource: self.bounds.as_entire_binding(),
        };
        self.bubble_group = Some(group(
            &self.bubble_layout,
            &[tables.clone(), view(4, &self.bubble_view), bounds],
        ));
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
            + self.coefs.size()
            + self.masks.size()
            + self.bounds.size()
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

    /// Blocks the dense plane holds (a plane of more goes in parts).
    pub fn part(&self) -> u32 {
        self.part
    }

    /// Records the decode of `seg` into `enc`: its keyframe steps, built in turn on the
    /// head (the head packed into the previous keyframe before the last step), then
    /// (with `bubbles`) its bubble planes. Each plane is parsed into the dense plane, part
    /// by part, and read from there. The streams go through `Queue::write_buffer`, which
    /// takes effect at the queue's next submission: the one that carries `enc`. It
    /// uploads [`upload_bytes`].
    pub fn decode(&mut self, enc: &mut wgpu::CommandEncoder, seg: &SegmentData, bubbles: bool) {
        let ch = self.channels as usize;
        let words = seg.bytes();
        let planes = decoded_planes(seg, bubbles);
        let jobs = job_bytes(seg, bubbles, self.part);
        if words > self.words.size() || jobs > self.jobs.size() {
            use wgpu::BufferUsages as B;
            if words > self.words.size() {
                self.words = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("vbim coefficient streams"),
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
            // Written into a staging buffer by the decoder thread: a copy on the GPU, no
            // bytes through this thread.
            Some(staged) => {
                enc.copy_buffer_to_buffer(&staged.buffer, 0, &self.words, 0, staged.bytes)
            }
            None => self.write_words(&seg.data),
        }
        let (pw, ph) = (self.plane[0], self.plane[1]);
        // Each plane's first job; its parts follow.
        let mut first_job = std::mem::take(&mut self.first_job);
        first_job.clear();
        self.job_bytes.clear();
        for (i, span) in seg.planes[..planes].iter().enumerate() {
            first_job.push(self.job_bytes.len() as u64);
            let n = parts(span.blocks, self.part);
            for k in 0..n {
                let lo = k * self.part;
                self.push_job(Job {
                    step: span.step,
                    // A bubble plane's layer; a keyframe plane's channel, the layer of the
                    // previous keyframe `key_pack` writes (the head's passes write the
                    // layer their binding views).
                    layer: if i < seg.bubbles {
                        i % ch
                    } else {
                        i - seg.bubbles
                    } as u32,
                    stream: span.stream,
                    entries: span.entries,
                    count: span.count,
                    blocks: span.blocks,
                    lo,
                    hi: (lo + self.part).min(span.blocks),
                    members: span.members,
                    member_count: span.member_count,
                    groups_x: GROUPS_X,
                    blocks_x: pw / 8,
                    per: self.per,
                    tiles_x: self.tiles_x,
                    size: [pw, ph],
                    _pad: [0; 2],
                });
            }
        }
        let zero_job = self.job_bytes.len() as u64;
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
        // The parts of plane `plane`: (job offset, blocks in the part, entry points).
        let jobs_of = &first_job;
        let part_jobs = |plane: usize| {
            let span = &seg.planes[plane];
            let part = self.part;
            (0..parts(span.blocks, part)).map(move |k| {
                let lo = k * part;
                let blocks = (lo + part).min(span.blocks) - lo.min(span.blocks);
                let job = jobs_of[plane] + k as u64 * JOB_STRIDE;
                (job as u32, blocks, span.count)
            })
        };
        let bubble_group = self.bubble_group.as_ref().expect("made at creation");
        let last = seg.steps.len().saturating_sub(1);
        for (n, st) in seg.steps.iter().enumerate() {
            for p in 0..ch {
                let plane = st.plane + p;
                for (k, (job, blocks, entries)) in part_jobs(plane).enumerate() {
                    let mut pass = self.parse_part(enc, job, blocks, entries);
                    pass.set_bind_group(0, &self.key_groups[p], &[job]);
                    if k == 0 && n == last {
                        // The head becomes the previous keyframe (the earlier steps' heads
                        // are never shown).
                        // (One invocation per region, 64 to a workgroup.)
                        pass.set_pipeline(&self.key_pack);
                        let [rx, ry] = self.regions;
                        pass.dispatch_workgroups((rx * ry).div_ceil(64), 1, 1);
                        self.mark(&mut pass, "key_pack");
                    }
                    if k == 0 && st.intra {
                        pass.set_pipeline(&self.key_zero);
                        pass.dispatch_workgroups(pw.div_ceil(8), ph.div_ceil(8), 1);
                        self.mark(&mut pass, "key_zero");
                    }
                    // A predicted keyframe is added onto the head: the keyframe it follows.
                    pass.set_pipeline(&self.key_add);
                    dispatch(&mut pass, blocks.div_ceil(GROUP_BLOCKS));
                    self.mark(&mut pass, "key_add");
                }
            }
        }
        if bubbles {
            enc.clear_buffer(&self.bounds, 0, None);
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                self.mark(&mut pass, "clears and pass changes");
                pass.set_bind_group(0, bubble_group, &[zero_job as u32]);
                pass.set_pipeline(&self.bubble_zero);
                if bubble_layers > 0 {
                    pass.dispatch_workgroups((pw / 2).div_ceil(8), ph.div_ceil(8), bubble_layers);
                }
                self.mark(&mut pass, "bubble_zero");
            }
            for plane in seg.bubbles..planes {
                // The bound first (over every part), then the blocks, parsed again if the
                // plane went in parts.
                let whole = parts(seg.planes[plane].blocks, self.part) == 1;
                for (job, blocks, entries) in part_jobs(plane) {
                    if blocks == 0 {
                        continue;
                    }
                    let mut pass = self.parse_part(enc, job, blocks, entries);
                    pass.set_bind_group(0, bubble_group, &[job]);
                    pass.set_pipeline(&self.bubble_bound);
                    dispatch(&mut pass, blocks.div_ceil(64));
                    self.mark(&mut pass, "bubble_bound");
                    if whole {
                        pass.set_pipeline(&self.bubble_write);
                        dispatch(&mut pass, blocks.div_ceil(GROUP_BLOCKS));
                        self.mark(&mut pass, "bubble_write");
                    }
                }
                if whole {
                    continue;
                }
                for (job, blocks, entries) in part_jobs(plane) {
                    let mut pass = self.parse_part(enc, job, blocks, entries);
                    pass.set_bind_group(0, bubble_group, &[job]);
                    pass.set_pipeline(&self.bubble_write);
                    dispatch(&mut pass, blocks.div_ceil(GROUP_BLOCKS));
                    self.mark(&mut pass, "bubble_write");
                }
            }
        }
        self.first_job = first_job;
    }

    /// A timestamp after what `pass` recorded so far (`vbim bench decode --gpu`), where
    /// the device has them; nothing otherwise.
    #[inline]
    fn mark(&self, pass: &mut wgpu::ComputePass, label: &'static str) {
        #[cfg(feature = "bench")]
        if let Some(m) = &self.marks {
            m.mark(pass, label);
        }
        #[cfg(not(feature = "bench"))]
        let _ = (pass, label);
    }

    /// Clears the masks and sets of the dense plane's first `blocks` blocks, then parses a
    /// part (job at `job`) into it from its `entries` entry points: a pass that goes on
    /// with the passes that read it. (The coefficients themselves need no clearing: only
    /// those whose mask bit the parse sets are ever read.)
    fn parse_part<'e>(
        &self,
        enc: &'e mut wgpu::CommandEncoder,
        job: u32,
        blocks: u32,
        entries: u32,
    ) -> wgpu::ComputePass<'e> {
        let sets = groups_offset(self.part) + group_bytes(blocks);
        enc.clear_buffer(&self.masks, 0, Some(sets));
        let mut pass = enc.begin_compute_pass(&Default::default());
        self.mark(&mut pass, "clears and pass changes");
        pass.set_pipeline(&self.parse);
        let group = self.parse_group.as_ref().expect("made at creation");
        pass.set_bind_group(0, group, &[job]);
        let groups = entries.div_ceil(64);
        pass.dispatch_workgroups(groups.min(GROUPS_X), groups.div_ceil(GROUPS_X), 1);
        self.mark(&mut pass, "parse");
        pass
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
            [&self.ranges, &self.bounds],
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

    /// Uploads `data` into the stream buffer from the CPU (a box filled by a decoder
    /// without a device).
    fn write_words(&self, data: &Coded) {
        if !data.words.is_empty() {
            self.queue
                .write_buffer(&self.words, 0, bytemuck::cast_slice(&data.words));
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
/// planes, held image, output and previous keyframe views, the previous keyframe's
/// ranges and the bubble planes' bounds.
fn reconstruct_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    views: [&wgpu::TextureView; 5],
    [ranges, bounds]: [&wgpu::Buffer; 2],
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
    entries.push(wgpu::BindGroupEntry {
        binding: 9,
        resource: bounds.as_entire_binding(),
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

/// The GPU decode alone, for `vbim bench decode --gpu`: boxes filled by a decoder without
/// a device, decoded one after another on a GPU of the stream's size.
#[cfg(feature = "bench")]
pub struct GpuDecoder(Gpu);

#[cfg(feature = "bench")]
impl GpuDecoder {
    /// GPU state for the stream `h` describes.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, h: &vbim_format::Header) -> Self {
        let mut gpu = Gpu::for_stream(device, queue, h);
        gpu.marks = crate::marks::Marks::new(device);
        GpuDecoder(gpu)
    }

    /// The GPU time between the marks of the last decode, each to the pass it ends (ns;
    /// empty unless the device has timestamps inside passes: [`timing_device`]). Call it
    /// after each [`GpuDecoder::decode`]: the query set holds one decode's marks.
    pub fn pass_times(&mut self) -> Vec<(&'static str, f64)> {
        let g = &self.0;
        g.marks
            .as_ref()
            .map_or_else(Vec::new, |m| m.read(&g.device, &g.queue))
    }

    /// Decodes `seg` (its keyframes and bubble planes), waits for the GPU and returns the
    /// wall-clock time from recording to completion.
    pub fn decode(&mut self, seg: &SegmentData) -> std::time::Duration {
        let t = std::time::Instant::now();
        let mut enc = self.0.device.create_command_encoder(&Default::default());
        if self.0.marks.is_some() {
            // A first mark, so that the time before the decode is not counted.
            let mut pass = enc.begin_compute_pass(&Default::default());
            self.0.mark(&mut pass, crate::marks::START);
        }
        self.0.decode(&mut enc, seg, true);
        self.0.queue.submit([enc.finish()]);
        self.0.wait();
        t.elapsed()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::readback::read_buffer;

    use crate::coded::PlaneSpan;
    use crate::decoder::KeyStep;
    use vbim_format::chunk::Scanned;
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

    /// A stream of `blocks` scanned and appended to `c` (with `members`, as a bubble
    /// plane's).
    fn coded_plane(
        c: &mut Coded,
        step: f32,
        blocks: &[[i32; 64]],
        members: Option<(usize, &dyn Fn(usize) -> bool)>,
    ) -> (PlaneSpan, Blocks) {
        let mut raw = Vec::new();
        plane::write_coefficients(blocks, &mut raw);
        let mut entries = Vec::new();
        vbim_format::scan::scan(&raw, &mut 0, blocks.len(), &mut entries).unwrap();
        let s = Scanned {
            stream: &raw,
            entries: &entries,
            blocks: blocks.len(),
        };
        let mut parsed = Blocks::default();
        plane::read_blocks(&raw, &mut 0, blocks.len(), &mut parsed).unwrap();
        (c.push_plane(step, s, members), parsed)
    }

    /// Decodes one keyframe step (plane 0 of a one-channel stream) onto the head.
    fn decode_key_step(gpu: &mut Gpu, number: usize, span: PlaneSpan, data: Coded) {
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
        gpu.decode(&mut enc, &seg, false);
        gpu.queue.submit([enc.finish()]);
    }

    /// The head keyframe's plane 0 matches `want` within 1e-5 of its peak.
    fn assert_head_matches(gpu: &Gpu, want: &Plane, part: Option<u32>) {
        let raw = read_texture_layer(&gpu.device, &gpu.queue, &gpu.keys, 4, 0);
        let got: &[f32] = bytemuck::cast_slice(&raw);
        let peak = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
        for (i, (g, w)) in got.iter().zip(&want.data).enumerate() {
            assert!(
                (g - w).abs() <= 1e-5 * peak,
                "parts {part:?}, texel {i}: GPU {g} against {w}"
            );
        }
    }

    /// A smooth plane whose DC repeats for hundreds of blocks: the scan cuts the runs into
    /// pieces of `FILL_BLOCKS`, each parsed by an invocation of its own, and the GPU's
    /// keyframe is the reference decoder's, in one part and in parts.
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
        for part in [None, Some(100)] {
            let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, 16);
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
            assert_head_matches(&gpu, &want, part);
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
        for part in [None, Some(7)] {
            let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, 16);
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
            assert_head_matches(&gpu, &want, part);
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
                    let vals: Vec<f32> =
                        inside.clone().map(|(y, x)| first.data[y * w + x]).collect();
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

    /// The bubble passes: a plane whose tiles of columns 2–3 are not members, written as
    /// 16-bit integers times the scale its bound gives, zeros outside its tiles; the
    /// bound within 3× of the plane's peak. Whole and in parts of 7 blocks.
    #[test]
    fn bubble_passes_match_the_reference_kernel_within_half_a_step() {
        let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
        let (pw, ph, ts) = (96u32, 32u32, 16usize);
        let tiles_x = pw as usize / ts;
        let tiles = tiles_x * (ph as usize / ts);
        let member = |t: usize| !(2..4).contains(&(t % tiles_x));
        let members = (0..tiles).filter(|&t| member(t)).count();
        let per2 = (ts / 8) * (ts / 8);
        let blocks = random_blocks(members * per2, &mut 11);
        let step = 0.004;
        for part in [None, Some(7)] {
            let mut gpu = Gpu::new(&device, &queue, (pw, ph), [pw, ph], 2, 1, ts as u32);
            if let Some(p) = part {
                gpu.part = p;
                gpu.bind_decode();
            }
            let mut c = Coded::default();
            // A keyframe plane before it, so that the bubble plane's offsets are not 0.
            coded_plane(&mut c, 1.0, &random_blocks(4, &mut 5), None);
            let (span, parsed) = coded_plane(&mut c, step, &blocks, Some((tiles, &member)));
            let mut want = Plane::zeros(pw as usize, ph as usize);
            for (rank, t) in (0..tiles).filter(|&t| member(t)).enumerate() {
                let at = plane::tile_blocks(t, tiles_x, ts);
                plane::add_blocks_of(&mut want, at, Onto::Zeros, &parsed, rank * per2, step);
            }
            let mut seg = SegmentData::new();
            seg.steps = Vec::new();
            seg.planes = vec![span, span];
            seg.bubbles = 1;
            seg.data = c;
            seg.layers = 3;
            let mut enc = device.create_command_encoder(&Default::default());
            gpu.decode(&mut enc, &seg, true);
            queue.submit([enc.finish()]);

            let bound = bytemuck::cast_slice::<u8, f32>(&read_buffer(&device, &queue, &gpu.bounds))
                [0]
                * step;
            let scale = bound * (1.0 + 1e-3) / 32767.0;
            let peak = want.data.iter().fold(0f32, |m, v| m.max(v.abs()));
            assert!(
                bound >= peak && bound < 3.0 * peak,
                "parts {part:?}: bound {bound} for a peak of {peak}"
            );
            let raw = read_texture_layer(&device, &queue, &gpu.bubbles, 4, 0);
            let got: Vec<f32> = bytemuck::cast_slice::<u8, i16>(&raw)
                .iter()
                .map(|&q| q as f32 * scale)
                .collect();
            for (i, (g, w)) in got.iter().zip(&want.data).enumerate() {
                assert!(
                    (g - w).abs() <= 0.5001 * scale,
                    "parts {part:?}, texel {i}: GPU {g} against {w} (scale {scale})"
                );
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
