//! The GPU side: a pool of keyframe slots and two slots of bubble terms (double
//! buffering: what is being displayed is never written), the display texture the renderer
//! samples, a held copy for catch-up blending, and the compute pass that evaluates the
//! basis per texel.
//!
//! Keyframes live apart from the bubbles because consecutive segments share one: K_{s+1}
//! closes segment s and opens s + 1, so it is uploaded once. Four keyframe slots are
//! enough for any upload: the segment on screen holds at most two, the one being uploaded
//! needs at most two more.

use wgpu::util::DeviceExt;

use std::sync::atomic::Ordering;

use crate::decoder::{row_pitch, SegmentData, Staging};

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
        required_limits: adapter.limits(),
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
    /// Keyframe slots of K_s and K_{s+1}.
    pub key0: u32,
    pub key1: u32,
    pub _pad: [u32; 2],
}

/// Keyframe slots on the GPU.
pub(crate) const KEY_SLOTS: usize = 4;

impl UploadPlan {
    /// Bytes the upload copies from staging.
    pub fn bytes(&self, seg: &SegmentData, h: &vbim_format::Header) -> u64 {
        let bubbles = self.bubbles.map_or(0, |_| seg.layers.saturating_sub(2));
        let terms = self.key0.is_some() as usize + self.key1.is_some() as usize + bubbles;
        terms as u64 * crate::decoder::term_bytes(h)
    }
}

/// What one upload copies from a segment's staging buffer: its K_s and K_{s+1} into
/// keyframe slots (`None`: already there, or not wanted), its bubbles into a bubble slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct UploadPlan {
    pub key0: Option<usize>,
    pub key1: Option<usize>,
    pub bubbles: Option<usize>,
}

pub(crate) struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    keys: wgpu::Texture,
    slots: [wgpu::Texture; 2],
    display: wgpu::Texture,
    pub display_view: wgpu::TextureView,
    held: wgpu::Texture,
    bind_groups: [wgpu::BindGroup; 2],
    pub width: u32,
    pub height: u32,
    pub max_layers: u32,
    pub channels: u32,
    /// Bytes of the textures and buffers above (the budget's figure).
    pub bytes: u64,
}

impl Gpu {
    /// `max_layers` terms of `channels` planes each.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        width: u32,
        height: u32,
        max_layers: u32,
        channels: u32,
    ) -> Gpu {
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        // One R32Float layer per plane of each term: term k, plane p is layer
        // k·channels + p of its texture (the staging layout, copied as it is).
        let array = |label: &'static str, terms: u32| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: terms.max(1) * channels,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::R32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        };
        let keys = array("vbim keyframes", KEY_SLOTS as u32);
        let bubbles = max_layers.saturating_sub(2);
        let slots = [
            array("vbim bubbles A", bubbles),
            array("vbim bubbles B", bubbles),
        ];
        let image = |label: &str, usage: wgpu::TextureUsages| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba16Float,
                usage,
                view_formats: &[],
            })
        };
        use wgpu::TextureUsages as U;
        let display = image(
            "vbim lightmap",
            U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC,
        );
        let held = image("vbim held", U::TEXTURE_BINDING | U::COPY_DST);
        let display_view = display.create_view(&Default::default());
        let held_view = held.create_view(&Default::default());
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("vbim params"),
            contents: bytemuck::bytes_of(&Params::zeroed_params()),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("vbim reconstruct"),
            source: wgpu::ShaderSource::Wgsl(include_str!("reconstruct.wgsl").into()),
        });
        let entry = |binding: u32, ty: wgpu::BindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim"),
            entries: &[
                entry(
                    0,
                    wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                ),
                entry(
                    1,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                ),
                entry(
                    2,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                ),
                entry(
                    3,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                ),
                entry(
                    4,
                    wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: wgpu::TextureFormat::Rgba16Float,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                ),
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("vbim"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("vbim reconstruct"),
            layout: Some(&layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let array_view = |t: &wgpu::Texture| {
            t.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        };
        let keys_view = array_view(&keys);
        let bind = |t: &wgpu::Texture| {
            let v = array_view(t);
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("vbim"),
                layout: &bgl,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: params.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(&keys_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::TextureView(&v),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::TextureView(&held_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: wgpu::BindingResource::TextureView(&display_view),
                    },
                ],
            })
        };
        let bind_groups = [bind(&slots[0]), bind(&slots[1])];
        let bytes = [&keys, &slots[0], &slots[1], &display, &held]
            .iter()
            .map(|t| texture_bytes(t))
            .sum::<u64>()
            + params.size();
        Gpu {
            device: device.clone(),
            queue: queue.clone(),
            pipeline,
            params,
            keys,
            slots,
            display,
            display_view,
            held,
            bind_groups,
            width,
            height,
            max_layers,
            channels,
            bytes,
        }
    }

    /// Records the copies of a decoded segment that `plan` asks for: its keyframes into
    /// keyframe slots, its bubble terms into a bubble slot. A mapped staging buffer is
    /// unmapped and copied by the GPU (nothing but the commands is recorded here); host
    /// staging goes through `write_texture`. ([`UploadPlan::bytes`] is what it moves.)
    pub fn upload(&self, enc: &mut wgpu::CommandEncoder, plan: UploadPlan, seg: &SegmentData) {
        let (w, h) = (self.width, self.height);
        let ch = self.channels;
        let pitch = row_pitch(w) as u32;
        let term = pitch as u64 * h as u64 * ch as u64;
        // (staging term, texture, first layer, terms)
        let mut copies: [Option<(u32, &wgpu::Texture, u32, u32)>; 3] = [None; 3];
        if let Some(k) = plan.key0 {
            copies[0] = Some((0, &self.keys, k as u32 * ch, 1));
        }
        if let Some(k) = plan.key1 {
            copies[1] = Some((1, &self.keys, k as u32 * ch, 1));
        }
        if let Some(b) = plan.bubbles {
            let n = (seg.layers.min(self.max_layers as usize) as u32).saturating_sub(2);
            if n > 0 {
                copies[2] = Some((2, &self.slots[b], 0, n));
            }
        }
        if let Staging::Mapped(buffer) = &seg.staging {
            buffer.unmap();
        }
        for (t, texture, layer, terms) in copies.into_iter().flatten() {
            let layout = wgpu::TexelCopyBufferLayout {
                offset: t as u64 * term,
                bytes_per_row: Some(pitch),
                rows_per_image: Some(h),
            };
            let dst = wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: 0,
                    y: 0,
                    z: layer,
                },
                aspect: wgpu::TextureAspect::All,
            };
            let size = wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: terms * ch,
            };
            match &seg.staging {
                Staging::Mapped(buffer) => {
                    enc.copy_buffer_to_texture(
                        wgpu::TexelCopyBufferInfo { buffer, layout },
                        dst,
                        size,
                    );
                }
                Staging::Host(data) => {
                    let b: &[u8] = bytemuck::cast_slice(data);
                    let at = layout.offset as usize;
                    let data = &b[at..at + (terms as u64 * term) as usize];
                    let layout = wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        ..layout
                    };
                    self.queue.write_texture(dst, data, layout, size);
                }
            }
        }
    }

    /// After the submission that copied `seg`, asks for its staging buffer to be mapped
    /// again; `seg.mapped` turns true when it is (wgpu calls back from a later submit or
    /// poll), and only then may the decoder write into it.
    pub fn remap(&self, seg: &SegmentData) {
        if let Staging::Mapped(buffer) = &seg.staging {
            seg.mapped.store(false, Ordering::Release);
            let flag = seg.mapped.clone();
            buffer.map_async(wgpu::MapMode::Write, .., move |_| {
                // On failure too: the decoder then reports that the buffer is not mapped.
                flag.store(true, Ordering::Release);
            });
        }
    }

    /// Keeps what is on screen for blending (at the start of a catch-up).
    pub fn hold(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.copy_texture_to_texture(
            self.display.as_image_copy(),
            self.held.as_image_copy(),
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
    }

    /// Records one frame into `enc`: an optional segment upload, then the reconstruction
    /// from bubble slot `eval.0` and the keyframe slots in its parameters. The parameters
    /// go through `Queue::write_buffer`, which takes effect at the queue's next submission:
    /// the one that carries `enc`. An uploaded staging buffer may be mapped again
    /// ([`Gpu::remap`]) only after that submission.
    pub fn record(
        &self,
        enc: &mut wgpu::CommandEncoder,
        upload: Option<(UploadPlan, &SegmentData)>,
        eval: Option<(usize, &Params, bool)>,
    ) {
        if let Some((plan, seg)) = upload {
            self.upload(enc, plan, seg);
        }
        if let Some((slot, params, hold_first)) = eval {
            self.queue
                .write_buffer(&self.params, 0, bytemuck::bytes_of(params));
            if hold_first {
                self.hold(enc);
            }
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_groups[slot], &[]);
            pass.dispatch_workgroups(self.width.div_ceil(8), self.height.div_ceil(8), 1);
        }
    }

    /// Reads the display texture back (RGBA, f32). For tests and error measurement.
    pub fn read_display(&self) -> Vec<f32> {
        let raw = read_texture(&self.device, &self.queue, &self.display, 8);
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

/// Bytes a texture holds (one mip level, every layer).
fn texture_bytes(t: &wgpu::Texture) -> u64 {
    let texel = t.format().block_copy_size(None).unwrap_or(0) as u64;
    t.width() as u64 * t.height() as u64 * t.depth_or_array_layers() as u64 * texel
}

/// Copies a 2D texture to the CPU, rows tightly packed (`bytes_per_texel` per texel):
/// blocks until the GPU is done. For tests, measurements and headless capture.
pub fn read_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    bytes_per_texel: u32,
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
        texture.as_image_copy(),
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
