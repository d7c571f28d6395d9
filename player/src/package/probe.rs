//! The lightmap beneath an object, on the CPU without waiting for the GPU (paper 001's
//! "sampling the terrain illumination map directly beneath the object"): every so often a
//! pass averages the lightmap output into a small grid (`probe.wgsl`), which is copied into
//! one of two mappable buffers; the buffer is mapped once the frame that recorded the copy
//! has been submitted, and read when the GPU is done. Answers are a frame or more old, and
//! say which media time they show.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use super::PackagePlayer;

/// How the lightmap is sampled for [`PackagePlayer::sample_lightmap`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LightmapSampling {
    /// The small grid's longer side, texels (1 to 1024): the lightmap is averaged over
    /// square blocks to fit it.
    pub max_side: u32,
    /// Playback time between two readbacks, ns.
    pub every_ns: u64,
}

impl Default for LightmapSampling {
    /// 128 texels on the longer side, four readbacks a second.
    fn default() -> Self {
        LightmapSampling {
            max_side: 128,
            every_ns: 250_000_000,
        }
    }
}

/// What [`PackagePlayer::sample_lightmap`] answers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightmapSample {
    /// The lightmap there, averaged over the small grid's block and bilinear between
    /// block centres: linear RGB, the lightmap's units.
    pub rgb: [f32; 3],
    /// The media time (frames, not wrapped) of the frame it was read from.
    pub shown: f64,
}

enum Slot {
    Idle,
    /// Its copy is in a frame's commands, not yet known to be submitted.
    Recorded(f64),
    /// Mapping: the flag is set when the data can be read.
    Mapping(f64, Arc<AtomicBool>),
}

/// The sampling pass, its buffers and the newest grid read back.
pub(super) struct Probe {
    cfg: LightmapSampling,
    size: [u32; 3],
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    small: wgpu::Buffer,
    staging: [wgpu::Buffer; 2],
    slots: [Slot; 2],
    last_ns: Option<u64>,
    latest: Option<(Vec<[f32; 3]>, f64)>,
}

impl Probe {
    pub(super) fn new(
        device: &wgpu::Device,
        width: u32,
        height: u32,
        cfg: LightmapSampling,
    ) -> Probe {
        use wgpu::BindingType as B;
        let cfg = LightmapSampling {
            max_side: cfg.max_side.clamp(1, 1024),
            ..cfg
        };
        let f = width.max(height).div_ceil(cfg.max_side).max(1);
        let size = [width.div_ceil(f), height.div_ceil(f), f];
        let bytes = size[0] as u64 * size[1] as u64 * 16;
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim lightmap probe"),
            entries: &[
                super::read_entry(0),
                entry(
                    1,
                    B::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: false },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                ),
                entry(
                    2,
                    B::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                ),
            ],
        });
        let pipeline = crate::gpu::compute_pipeline(
            device,
            "vbim lightmap probe",
            include_str!("probe.wgsl"),
            &layout,
            "main",
        );
        use wgpu::BufferUsages as U;
        let buffer = |label, size, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let params = buffer("vbim lightmap probe params", 16, U::UNIFORM | U::COPY_DST);
        let staging = || {
            buffer(
                "vbim lightmap probe readback",
                bytes,
                U::MAP_READ | U::COPY_DST,
            )
        };
        Probe {
            cfg,
            size,
            pipeline,
            layout,
            params,
            small: buffer("vbim lightmap probe", bytes, U::STORAGE | U::COPY_SRC),
            staging: [staging(), staging()],
            slots: [Slot::Idle, Slot::Idle],
            last_ns: None,
            latest: None,
        }
    }

    /// GPU memory: the small grid and its two readback buffers, bytes.
    pub(super) fn bytes(&self) -> u64 {
        self.small.size() * 3 + 16
    }

    /// Once a frame, after everything that writes `lightmap` this frame: maps the copies
    /// recorded in earlier frames (their commands were submitted since), keeps the newest
    /// grid that is ready, and records a new copy when it is time and a buffer is free.
    pub(super) fn step(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        enc: &mut wgpu::CommandEncoder,
        lightmap: &wgpu::Texture,
        clock_ns: u64,
        shown: f64,
    ) {
        for (slot, staging) in self.slots.iter_mut().zip(&self.staging) {
            if let Slot::Recorded(t) = *slot {
                let ready = Arc::new(AtomicBool::new(false));
                let flag = ready.clone();
                staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                    flag.store(r.is_ok(), Ordering::Release);
                });
                *slot = Slot::Mapping(t, ready);
            }
        }
        let _ = device.poll(wgpu::PollType::Poll);
        for (slot, staging) in self.slots.iter_mut().zip(&self.staging) {
            if let Slot::Mapping(t, ready) = slot {
                if ready.load(Ordering::Acquire) {
                    let t = *t;
                    if self.latest.as_ref().is_none_or(|(_, old)| t >= *old) {
                        let data = staging.slice(..).get_mapped_range();
                        let grid = bytemuck::cast_slice::<u8, [f32; 4]>(&data)
                            .iter()
                            .map(|v| [v[0], v[1], v[2]])
                            .collect();
                        self.latest = Some((grid, t));
                    }
                    staging.unmap();
                    *slot = Slot::Idle;
                }
            }
        }
        let due = self
            .last_ns
            .is_none_or(|last| clock_ns.saturating_sub(last) >= self.cfg.every_ns);
        let readable = lightmap
            .usage()
            .contains(wgpu::TextureUsages::TEXTURE_BINDING);
        let Some(i) = self.slots.iter().position(|s| matches!(s, Slot::Idle)) else {
            return;
        };
        if !due || !readable {
            return;
        }
        let [w, h, f] = self.size;
        queue.write_buffer(&self.params, 0, bytemuck::cast_slice(&[w, h, f, 0u32]));
        let view = lightmap.create_view(&Default::default());
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vbim lightmap probe"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: self.small.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: self.params.as_entire_binding(),
                },
            ],
        });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("vbim lightmap probe"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        }
        enc.copy_buffer_to_buffer(&self.small, 0, &self.staging[i], 0, self.small.size());
        self.slots[i] = Slot::Recorded(shown);
        self.last_ns = Some(clock_ns);
    }

    /// The newest grid read back at (u, v), bilinear between block centres.
    fn sample(&self, u: f32, v: f32) -> Option<LightmapSample> {
        let (grid, shown) = self.latest.as_ref()?;
        let [w, h, _] = self.size.map(|x| x as usize);
        // Block centres as the irradiance grid's cell centres: the same sampling.
        let ([a, b, c, d], [wx, wy]) = vbim_format::irradiance::corners(u, v, w, h);
        let rgb = std::array::from_fn(|ch| {
            let top = grid[a][ch] * (1.0 - wx) + grid[b][ch] * wx;
            let bottom = grid[c][ch] * (1.0 - wx) + grid[d][ch] * wx;
            top * (1.0 - wy) + bottom * wy
        });
        Some(LightmapSample { rgb, shown: *shown })
    }

    /// The small grid's size: (width, height, the block's side).
    pub(super) fn grid(&self) -> [u32; 3] {
        self.size
    }
}

impl PackagePlayer {
    /// Samples the lightmap for [`Self::sample_lightmap`] from the next frame on (or stops
    /// with `None`): every `every_ns` of playback the lightmap output is averaged into a
    /// grid of at most `max_side` texels a side and read back without waiting for the GPU.
    /// Its GPU memory (the grid and two readback buffers, 48 bytes a grid texel: 786 kB at
    /// 128²) counts in [`Self::gpu_bytes`].
    pub fn set_lightmap_sampling(&mut self, sampling: Option<LightmapSampling>) {
        self.probe = sampling.map(|cfg| {
            let t = &self.lightmap.0;
            Probe::new(&self.device, t.width(), t.height(), cfg)
        });
    }

    /// The lightmap beneath an object at lightmap coordinates (u, v) (0 to 1, u east, v
    /// south), from the newest readback: a frame or more behind the display, and only the
    /// light on the ground's own normal, averaged over the sampling grid's block (the
    /// lightmap's size over [`LightmapSampling::max_side`]). `None` until sampling is on
    /// and its first readback has arrived. For an object's own normals and shadows,
    /// [`Self::irradiance`].
    pub fn sample_lightmap(&self, u: f32, v: f32) -> Option<LightmapSample> {
        self.probe.as_ref()?.sample(u, v)
    }

    /// The sampling grid's width, height and block side, if sampling is on.
    pub fn lightmap_sampling_grid(&self) -> Option<[u32; 3]> {
        self.probe.as_ref().map(Probe::grid)
    }
}
