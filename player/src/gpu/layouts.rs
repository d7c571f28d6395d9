//! The bind group layouts of the GPU state's passes (which binding of which shader is
//! what) and the compute pipelines over them.

/// The bind group layouts of the reconstruction, the hold pass and the decode passes
/// (keyframe, bubble, parse): which binding of which shader is what.
pub(super) struct Layouts {
    pub reconstruct: wgpu::BindGroupLayout,
    pub hold: wgpu::BindGroupLayout,
    pub key: wgpu::BindGroupLayout,
    /// `key_pack`'s: the head read whole (every channel in one dispatch).
    pub pack: wgpu::BindGroupLayout,
    pub bubble: wgpu::BindGroupLayout,
    pub parse: wgpu::BindGroupLayout,
}

/// Where the DCT tables live for the shaders that index them per invocation (each at its
/// own texel and term: `basis` and `zigzag` in blocks.wgsl):
/// [`DecodeShape::storage_tables`](crate::DecodeShape::storage_tables) says which, and why.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum TablesIn {
    Uniform,
    Storage,
}

impl TablesIn {
    /// Where `shape` keeps them.
    pub fn of(shape: crate::DecodeShape) -> TablesIn {
        match shape.storage_tables {
            true => TablesIn::Storage,
            false => TablesIn::Uniform,
        }
    }

    /// `source` with the tables' address space put in (`var<TABLES>` in the WGSL).
    pub fn wgsl(self, source: &str) -> String {
        let space = match self {
            TablesIn::Uniform => "uniform",
            TablesIn::Storage => "storage, read",
        };
        source.replace("var<TABLES>", &format!("var<{space}>"))
    }

    /// The tables buffer's usage.
    pub fn usage(self) -> wgpu::BufferUsages {
        match self {
            TablesIn::Uniform => wgpu::BufferUsages::UNIFORM,
            TablesIn::Storage => wgpu::BufferUsages::STORAGE,
        }
    }

    fn binding(self) -> wgpu::BindingType {
        wgpu::BindingType::Buffer {
            ty: match self {
                TablesIn::Uniform => wgpu::BufferBindingType::Uniform,
                TablesIn::Storage => wgpu::BufferBindingType::Storage { read_only: true },
            },
            has_dynamic_offset: false,
            min_binding_size: None,
        }
    }
}

pub(super) fn layouts(device: &wgpu::Device, tables: TablesIn) -> Layouts {
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
    use wgpu::StorageTextureAccess as Access;
    use wgpu::TextureFormat as Format;
    use wgpu::TextureViewDimension::{D2Array, D2};
    let sampled = |sample_type, view_dimension| wgpu::BindingType::Texture {
        sample_type,
        view_dimension,
        multisampled: false,
    };
    let storage_texture = |access, format, view_dimension| wgpu::BindingType::StorageTexture {
        access,
        format,
        view_dimension,
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
                storage_texture(Access::WriteOnly, Format::Rgba16Float, D2),
            ),
            entry(5, sampled(wgpu::TextureSampleType::Uint, D2Array)),
            entry(6, storage(true)),
            entry(9, storage(true)),
            entry(10, storage(false)),
            entry(12, storage(false)),
            entry(11, storage(true)),
            entry(13, tables.binding()),
        ],
    });
    let hold_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("vbim hold"),
        entries: &[
            entry(
                7,
                sampled(wgpu::TextureSampleType::Float { filterable: false }, D2),
            ),
            entry(8, storage_texture(Access::WriteOnly, Format::R32Uint, D2)),
        ],
    });
    let words_entry = entry(2, storage(true));
    let key_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("vbim keyframe decode"),
        entries: &[
            entry(0, uniform(true)),
            entry(11, uniform(true)),
            entry(1, tables.binding()),
            words_entry,
            entry(3, storage_texture(Access::ReadWrite, Format::R32Float, D2)),
            entry(6, storage(true)),
            entry(7, storage(true)),
            entry(10, storage(true)),
        ],
    });
    let pack_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("vbim keyframe pack"),
        entries: &[
            entry(0, uniform(true)),
            entry(11, uniform(true)),
            entry(
                14,
                sampled(
                    wgpu::TextureSampleType::Float { filterable: false },
                    D2Array,
                ),
            ),
            entry(
                4,
                storage_texture(Access::WriteOnly, Format::R32Uint, D2Array),
            ),
            entry(5, storage(false)),
        ],
    });
    let bubble_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("vbim bubble decode"),
        entries: &[
            entry(0, uniform(true)),
            entry(11, uniform(true)),
            words_entry,
            entry(6, storage(true)),
            entry(7, storage(true)),
            entry(9, storage(false)),
            entry(10, storage(true)),
            entry(
                12,
                storage_texture(Access::WriteOnly, Format::Rgba32Uint, D2Array),
            ),
            entry(13, storage(false)),
        ],
    });
    let parse_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("vbim parse"),
        entries: &[
            entry(0, uniform(true)),
            entry(11, uniform(true)),
            words_entry,
            entry(6, storage(false)),
            entry(7, storage(false)),
            entry(10, storage(false)),
        ],
    });
    Layouts {
        reconstruct: bgl,
        hold: hold_layout,
        key: key_layout,
        pack: pack_layout,
        bubble: bubble_layout,
        parse: parse_layout,
    }
}

/// A compute pipeline running `entry` of the WGSL `source` over bind group 0 of `layout`.
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    layout: &wgpu::BindGroupLayout,
    entry: &str,
) -> wgpu::ComputePipeline {
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
}
