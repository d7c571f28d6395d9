//! vbim-scene — the terrain scene: the sample's height field as a mesh, lit by the streamed
//! lightmap, under the streamed sky where the package has a sky track (else a gradient whose
//! colours follow the time of day, from the bake's manifest in the file's metadata chunk),
//! with the sun's disc where the manifest puts it, seen from a camera orbiting the map
//! (`vbim play --scene`); where the package has irradiance tracks, a few objects stand on
//! the terrain lit by them (`objects`).

pub mod mesh;
mod objects;

use glam::{Mat4, Vec3};
use vbim_bake::Manifest;
use wgpu::util::DeviceExt;

pub use mesh::Mesh;
pub use objects::{showcase, Object};

/// Offscreen colour format: 8-bit sRGB, so the GPU applies the sRGB curve after the
/// shader's tone mapping.
pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniforms {
    view_proj: [[f32; 4]; 4],
    inv_view_proj: [[f32; 4]; 4],
    params: [f32; 4],
    sky_zenith: [f32; 4],
    sky_horizon: [f32; 4],
    eye: [f32; 4],
    sun_dir: [f32; 4],
    sun_color: [f32; 4],
}

/// What to draw a frame with.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub eye: Vec3,
    pub target: Vec3,
    pub fovy: f32,
    pub exposure: f32,
    /// The sky and sun of the moment shown ([`SkyTrack::at`]).
    pub sky: SkyAt,
    /// Strength of the detail texture (0 = none).
    pub detail: f32,
}

/// The sky and sun of one moment, from the bake's manifest: the gradient's colours (used
/// where no sky map is bound) and the sun's direction (map frame: x east, y south, z up)
/// and colour (the direct sun's texel value at normal incidence).
#[derive(Clone, Copy, Debug, Default)]
pub struct SkyAt {
    pub zenith: [f32; 3],
    pub horizon: [f32; 3],
    pub sun_dir: [f32; 3],
    pub sun_color: [f32; 3],
}

/// The angular radius of the sun's disc as drawn: the bake's soft 1.5° disc.
const SUN_RADIUS_DEG: f32 = 0.75;

/// A camera orbiting the map: phase 0–1 is one turn, looking at the centre from above.
pub fn orbit(phase: f32, mesh: &Mesh) -> (Vec3, Vec3) {
    let a = phase * std::f32::consts::TAU + 0.6;
    let r = 1.7 * mesh.extent.0.max(mesh.extent.1);
    (
        Vec3::new(r * a.cos(), 0.9 * r, r * a.sin()),
        Vec3::new(0.0, 0.05, 0.0),
    )
}

pub struct SceneRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    terrain: wgpu::RenderPipeline,
    sky: wgpu::RenderPipeline,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    uniforms: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    has_sky_map: bool,
    layout: wgpu::BindGroupLayout,
    format: wgpu::TextureFormat,
    objects: Option<objects::ObjectsPass>,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    pub width: u32,
    pub height: u32,
}

/// A repeating detail texture: smooth value noise around 0.5 (`2·d` averages 1).
fn detail_texels(n: usize) -> Vec<u8> {
    let hash = |x: usize, y: usize| {
        let mut h = (x as u32).wrapping_mul(0x9e37_79b1) ^ (y as u32).wrapping_mul(0x85eb_ca77);
        h ^= h >> 15;
        h = h.wrapping_mul(0x2c1b_3c6d);
        h ^= h >> 12;
        (h & 0xff) as f32 / 255.0
    };
    let mut out = Vec::with_capacity(n * n * 4);
    for y in 0..n {
        for x in 0..n {
            let mut v = 0.0;
            let mut amp = 0.5;
            let mut total = 0.0;
            for o in 0..4 {
                let cells = 4usize << o;
                let (fx, fy) = (
                    x as f32 * cells as f32 / n as f32,
                    y as f32 * cells as f32 / n as f32,
                );
                let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
                let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
                let s = |t: f32| t * t * (3.0 - 2.0 * t);
                let g = |a: usize, b: usize| hash(a % cells, b % cells);
                let top = g(x0, y0) * (1.0 - s(tx)) + g(x0 + 1, y0) * s(tx);
                let bot = g(x0, y0 + 1) * (1.0 - s(tx)) + g(x0 + 1, y0 + 1) * s(tx);
                v += amp * (top * (1.0 - s(ty)) + bot * s(ty));
                total += amp;
                amp *= 0.5;
            }
            let d = (0.5 + 0.35 * (v / total - 0.5)).clamp(0.0, 1.0);
            let b = (d * 255.0).round() as u8;
            out.extend_from_slice(&[b, b, b, 255]);
        }
    }
    out
}

impl SceneRenderer {
    /// A renderer of `mesh` lit by `lightmap`, under `sky_map` (a sky track's map,
    /// `Rgba16Float`) or, without one, the gradient of each [`View`]'s [`SkyAt`].
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        mesh: &Mesh,
        lightmap: &wgpu::TextureView,
        sky_map: Option<&wgpu::TextureView>,
        width: u32,
        height: u32,
        format: wgpu::TextureFormat,
    ) -> SceneRenderer {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("terrain"),
            source: wgpu::ShaderSource::Wgsl(
                [include_str!("uniforms.wgsl"), include_str!("terrain.wgsl")]
                    .concat()
                    .into(),
            ),
        });
        let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("terrain vertices"),
            contents: bytemuck::cast_slice(&mesh.vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("terrain indices"),
            contents: bytemuck::cast_slice(&mesh.indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("scene uniforms"),
            size: std::mem::size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let dn = 128u32;
        let detail = device.create_texture_with_data(
            queue,
            &wgpu::TextureDescriptor {
                label: Some("detail"),
                size: wgpu::Extent3d {
                    width: dn,
                    height: dn,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            &detail_texels(dn as usize),
        );
        let linear = |mode| {
            device.create_sampler(&wgpu::SamplerDescriptor {
                address_mode_u: mode,
                address_mode_v: mode,
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                ..Default::default()
            })
        };
        let tex_entry = |b| wgpu::BindGroupLayoutEntry {
            binding: b,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: true },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let samp_entry = |b| wgpu::BindGroupLayoutEntry {
            binding: b,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
            count: None,
        };
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("scene"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                tex_entry(1),
                samp_entry(2),
                tex_entry(3),
                samp_entry(4),
                tex_entry(5),
                samp_entry(6),
            ],
        });
        // Without a sky map, a 1×1 stand-in the shader does not read.
        let blank = device
            .create_texture(&vbim_player::lightmap_descriptor(
                1,
                1,
                wgpu::TextureUsages::TEXTURE_BINDING,
            ))
            .create_view(&Default::default());
        let sky_view = sky_map.unwrap_or(&blank);
        let sky_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let detail_view = detail.create_view(&Default::default());
        let (ls, ds) = (
            linear(wgpu::AddressMode::ClampToEdge),
            linear(wgpu::AddressMode::Repeat),
        );
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("scene"),
            layout: &bgl,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniforms.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(lightmap),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&ls),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(&detail_view),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::Sampler(&ds),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::TextureView(sky_view),
                },
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: wgpu::BindingResource::Sampler(&sky_sampler),
                },
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("scene"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });
        let pipeline =
            |vs: &str, fs: &str, buffers: &[wgpu::VertexBufferLayout], depth_write: bool| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some(vs),
                    layout: Some(&layout),
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some(vs),
                        buffers,
                        compilation_options: Default::default(),
                    },
                    fragment: Some(wgpu::FragmentState {
                        module: &module,
                        entry_point: Some(fs),
                        targets: &[Some(format.into())],
                        compilation_options: Default::default(),
                    }),
                    primitive: wgpu::PrimitiveState {
                        cull_mode: None,
                        ..Default::default()
                    },
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: DEPTH,
                        depth_write_enabled: Some(depth_write),
                        depth_compare: Some(if depth_write {
                            wgpu::CompareFunction::Less
                        } else {
                            wgpu::CompareFunction::Always
                        }),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                    multisample: Default::default(),
                    multiview_mask: None,
                    cache: None,
                })
            };
        let vlayout = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<mesh::Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x2, 2 => Float32x3],
        };
        let terrain = pipeline("vs_terrain", "fs_terrain", &[vlayout], true);
        let sky = pipeline("vs_sky", "fs_sky", &[], false);
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let color = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("scene colour"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let depth = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("scene depth"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        });
        SceneRenderer {
            device: device.clone(),
            queue: queue.clone(),
            terrain,
            sky,
            vertices,
            indices,
            index_count: mesh.indices.len() as u32,
            uniforms,
            bind_group,
            has_sky_map: sky_map.is_some(),
            layout: bgl,
            format,
            objects: None,
            color_view: color.create_view(&Default::default()),
            color,
            depth_view: depth.create_view(&Default::default()),
            width,
            height,
        }
    }

    /// Stands `objects` on the terrain from the next frame on, lit by the light for
    /// objects in `irradiance` (`PackagePlayer::irradiance_buffer`); none for an empty
    /// list.
    pub fn set_objects(&mut self, irradiance: &wgpu::Buffer, objects: &[Object]) {
        self.objects = (!objects.is_empty()).then(|| {
            objects::ObjectsPass::new(
                &self.device,
                &self.layout,
                self.format,
                DEPTH,
                irradiance,
                objects,
            )
        });
    }

    /// Draws the sky, the terrain and its objects into `target` (or the offscreen target).
    pub fn render(&self, v: &View, target: Option<&wgpu::TextureView>) {
        let aspect = self.width as f32 / self.height as f32;
        let proj = Mat4::perspective_rh(v.fovy, aspect, 0.01, 20.0);
        let view = Mat4::look_at_rh(v.eye, v.target, Vec3::Y);
        let vp = proj * view;
        let rgb1 = |c: [f32; 3]| [c[0], c[1], c[2], 1.0];
        // Map frame (x east, y south, z up) to the world (x east, y up, z south).
        let s = v.sky.sun_dir;
        let sun_world = Vec3::new(s[0], s[2], s[1]).normalize_or_zero();
        let u = Uniforms {
            view_proj: vp.to_cols_array_2d(),
            inv_view_proj: vp.inverse().to_cols_array_2d(),
            params: [v.exposure, 24.0, v.detail, self.has_sky_map as u32 as f32],
            sky_zenith: rgb1(v.sky.zenith),
            sky_horizon: rgb1(v.sky.horizon),
            eye: [v.eye.x, v.eye.y, v.eye.z, 1.0],
            sun_dir: [
                sun_world.x,
                sun_world.y,
                sun_world.z,
                SUN_RADIUS_DEG.to_radians().cos(),
            ],
            sun_color: rgb1(v.sky.sun_color),
        };
        self.queue
            .write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("scene"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: target.unwrap_or(&self.color_view),
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.set_pipeline(&self.sky);
            pass.draw(0..3, 0..1);
            pass.set_pipeline(&self.terrain);
            pass.set_vertex_buffer(0, self.vertices.slice(..));
            pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..self.index_count, 0, 0..1);
            if let Some(o) = &self.objects {
                o.draw(&mut pass);
            }
        }
        self.queue.submit(Some(enc.finish()));
    }

    /// Reads the offscreen target back as RGBA8 (sRGB-encoded).
    pub fn read(&self) -> Vec<u8> {
        vbim_player::read_texture(&self.device, &self.queue, &self.color, 4)
    }
}

/// The sky and sun over the day from the bake's manifest (each frame's `sky_color`,
/// `sky_horizon_sun_side`, `sun_dir` and `sun_color`), interpolated at a fractional frame;
/// a plain sky and no sun without one.
pub struct SkyTrack {
    frames: Vec<SkyAt>,
}

impl SkyTrack {
    pub fn from_manifest(manifest: Option<&Manifest>) -> SkyTrack {
        let f = |c: [f64; 3]| c.map(|v| v as f32);
        let frames: Vec<SkyAt> = manifest
            .map(|m| {
                m.per_frame
                    .iter()
                    .map(|i| SkyAt {
                        zenith: f(i.sky_color),
                        horizon: f(i.sky_horizon_sun_side),
                        sun_dir: f(i.sun_dir),
                        sun_color: f(i.sun_color),
                    })
                    .collect()
            })
            .unwrap_or_default();
        if frames.is_empty() {
            return SkyTrack {
                frames: vec![SkyAt {
                    zenith: [0.046, 0.068, 0.11],
                    horizon: [0.08, 0.09, 0.11],
                    ..Default::default()
                }],
            };
        }
        SkyTrack { frames }
    }

    /// The sky and sun at fractional frame `t` (wrapping).
    pub fn at(&self, t: f64) -> SkyAt {
        let n = self.frames.len();
        let t = t.rem_euclid(n as f64);
        let (i, f) = (t.floor() as usize % n, (t - t.floor()) as f32);
        let (a, b) = (self.frames[i], self.frames[(i + 1) % n]);
        let lerp = |a: [f32; 3], b: [f32; 3]| [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * f);
        SkyAt {
            zenith: lerp(a.zenith, b.zenith),
            horizon: lerp(a.horizon, b.horizon),
            sun_dir: lerp(a.sun_dir, b.sun_dir),
            sun_color: lerp(a.sun_color, b.sun_color),
        }
    }
}
