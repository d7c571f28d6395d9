//! The cross-fade of a weather switch: one compute pass per track kind that writes
//! `from + (to − from) · w` into the package's output texture. It reads 16 bytes and
//! writes 8 a texel: a fade costs what a video texture's blend does.

/// The fade pipeline of one device, and the bind groups of the fade in progress.
pub(crate) struct FadePass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

/// One fade: from one track's texture to another's, into the output.
pub(crate) struct FadeJob {
    group: wgpu::BindGroup,
    uniform: wgpu::Buffer,
    size: (u32, u32),
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniform {
    w: f32,
    width: u32,
    height: u32,
    pad: u32,
}

impl FadePass {
    pub fn new(device: &wgpu::Device) -> FadePass {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim fade"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                super::read_entry(1),
                super::read_entry(2),
                super::write_entry(3, wgpu::TextureViewDimension::D2),
            ],
        });
        let pipeline = crate::gpu::compute_pipeline(
            device,
            "vbim fade",
            include_str!("fade.wgsl"),
            &layout,
            "main",
        );
        FadePass { pipeline, layout }
    }

    /// A fade from `from` to `to` into `out` (all `size`, Rgba16Float).
    pub fn job(
        &self,
        device: &wgpu::Device,
        from: &wgpu::TextureView,
        to: &wgpu::TextureView,
        out: &wgpu::TextureView,
        size: (u32, u32),
    ) -> FadeJob {
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vbim fade"),
            size: std::mem::size_of::<Uniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vbim fade"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(from),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(to),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(out),
                },
            ],
        });
        FadeJob {
            group,
            uniform,
            size,
        }
    }

    /// Records the fade at weight `w` (0: all `from`, 1: all `to`).
    pub fn record(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        job: &FadeJob,
        w: f32,
    ) {
        let u = Uniform {
            w,
            width: job.size.0,
            height: job.size.1,
            pad: 0,
        };
        queue.write_buffer(&job.uniform, 0, bytemuck::bytes_of(&u));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("vbim fade"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &job.group, &[]);
        pass.dispatch_workgroups(job.size.0.div_ceil(8), job.size.1.div_ceil(8), 1);
    }
}
