//! Objects standing on the terrain, lit by the package's light for objects (its irradiance
//! tracks): spheres whose every pixel takes albedo × the irradiance its normal receives at
//! the object's place (`objects.wgsl` over `vbim_player::irradiance_wgsl`), so that a
//! sphere in a valley goes dark when the ridge hides the sun and takes the colour of the
//! sky and the ground around it.

use vbim_bake::HeightField;
use wgpu::util::DeviceExt;

use crate::mesh::Mesh;

/// One object: where it stands and what it looks like.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Object {
    /// Lightmap coordinates of its place (u east, v south, 0 to 1).
    pub uv: [f32; 2],
    /// Its centre, scene units (x east, y up, z south): resting on the ground.
    pub centre: [f32; 3],
    /// Its radius, scene units (the map's longer side spans 2).
    pub radius: f32,
    /// Its albedo, linear RGB.
    pub albedo: [f32; 3],
}

impl Object {
    /// A sphere of `radius` resting on the ground of `mesh` at (u, v).
    pub fn on_ground(
        mesh: &Mesh,
        hf: &HeightField,
        uv: [f32; 2],
        radius: f32,
        albedo: [f32; 3],
    ) -> Object {
        let g = mesh.ground(hf, uv[0], uv[1]);
        Object {
            uv,
            centre: [g[0], g[1] + radius, g[2]],
            radius,
            albedo,
        }
    }
}

/// A few spheres to show the light for objects: on the highest and the lowest ground of
/// the map's inner part, and four around its centre.
pub fn showcase(mesh: &Mesh, hf: &HeightField) -> Vec<Object> {
    let n = 24;
    let spot = |k: usize| {
        let (i, j) = (k % n, k / n);
        [
            0.15 + 0.7 * (i as f32 + 0.5) / n as f32,
            0.15 + 0.7 * (j as f32 + 0.5) / n as f32,
        ]
    };
    let height = |uv: [f32; 2]| mesh.ground(hf, uv[0], uv[1])[1];
    let by_height = |a: &usize, b: &usize| height(spot(*a)).total_cmp(&height(spot(*b)));
    let top = (0..n * n).max_by(by_height).expect("spots");
    let bottom = (0..n * n).min_by(by_height).expect("spots");
    let r = 0.045;
    let mut out = vec![
        Object::on_ground(mesh, hf, spot(top), r, [0.75, 0.75, 0.75]),
        Object::on_ground(mesh, hf, spot(bottom), r, [0.75, 0.75, 0.75]),
    ];
    let colours = [
        [0.70, 0.28, 0.20],
        [0.25, 0.45, 0.70],
        [0.80, 0.70, 0.35],
        [0.60, 0.60, 0.60],
    ];
    for (k, albedo) in colours.into_iter().enumerate() {
        let a = std::f32::consts::FRAC_PI_2 * k as f32 + 0.4;
        let uv = [0.5 + 0.22 * a.cos(), 0.5 + 0.22 * a.sin()];
        out.push(Object::on_ground(mesh, hf, uv, r, albedo));
    }
    out
}

/// The objects' pipeline and buffers.
pub(crate) struct ObjectsPass {
    pipeline: wgpu::RenderPipeline,
    sphere: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    instances: wgpu::Buffer,
    count: u32,
    bind_group: wgpu::BindGroup,
}

/// A unit sphere: `rings` × `segments` quads, positions (which are also the normals).
fn sphere(rings: u32, segments: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut v = Vec::new();
    for r in 0..=rings {
        let t = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let p = std::f32::consts::TAU * s as f32 / segments as f32;
            v.push([t.sin() * p.cos(), t.cos(), t.sin() * p.sin()]);
        }
    }
    let mut i = Vec::new();
    let w = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let a = r * w + s;
            i.extend_from_slice(&[a, a + w, a + 1, a + 1, a + w, a + w + 1]);
        }
    }
    (v, i)
}

impl ObjectsPass {
    pub(crate) fn new(
        device: &wgpu::Device,
        scene_layout: &wgpu::BindGroupLayout,
        format: wgpu::TextureFormat,
        depth: wgpu::TextureFormat,
        irradiance: &wgpu::Buffer,
        objects: &[Object],
    ) -> ObjectsPass {
        let source = vbim_player::irradiance_wgsl(1, 0)
            + include_str!("uniforms.wgsl")
            + include_str!("objects.wgsl");
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("objects"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let irr_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("objects' light"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("objects' light"),
            layout: &irr_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: irradiance.as_entire_binding(),
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("objects"),
            bind_group_layouts: &[Some(scene_layout), Some(&irr_layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("objects"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_object"),
                buffers: &[
                    wgpu::VertexBufferLayout {
                        array_stride: 12,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &wgpu::vertex_attr_array![0 => Float32x3],
                    },
                    wgpu::VertexBufferLayout {
                        array_stride: 48,
                        step_mode: wgpu::VertexStepMode::Instance,
                        attributes: &wgpu::vertex_attr_array![1 => Float32x4, 2 => Float32x4, 3 => Float32x4],
                    },
                ],
                compilation_options: Default::default(),
            },
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_object"),
                targets: &[Some(format.into())],
                compilation_options: Default::default(),
            }),
            primitive: Default::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: depth,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            multiview_mask: None,
            cache: None,
        });
        let (v, i) = sphere(16, 32);
        let init = |contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("objects"),
                contents,
                usage,
            })
        };
        let data: Vec<[f32; 12]> = objects
            .iter()
            .map(|o| {
                let (c, a) = (o.centre, o.albedo);
                [
                    c[0], c[1], c[2], o.radius, o.uv[0], o.uv[1], 0.0, 0.0, a[0], a[1], a[2], 1.0,
                ]
            })
            .collect();
        ObjectsPass {
            pipeline,
            sphere: init(bytemuck::cast_slice(&v), wgpu::BufferUsages::VERTEX),
            indices: init(bytemuck::cast_slice(&i), wgpu::BufferUsages::INDEX),
            index_count: i.len() as u32,
            instances: init(bytemuck::cast_slice(&data), wgpu::BufferUsages::VERTEX),
            count: objects.len() as u32,
            bind_group,
        }
    }

    /// Draws the objects (the scene's bind group is already set at group 0).
    pub(crate) fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        if self.count == 0 {
            return;
        }
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(1, &self.bind_group, &[]);
        pass.set_vertex_buffer(0, self.sphere.slice(..));
        pass.set_vertex_buffer(1, self.instances.slice(..));
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..self.index_count, 0, 0..self.count);
    }
}
