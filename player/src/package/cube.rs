//! The sky map as a cube map, for renderers whose skyboxes and environment maps take cubes
//! (Bevy's `Skybox`, `GeneratedEnvironmentMapLight`): one compute pass a frame that
//! resamples the package's equirectangular sky output into the caller's cube texture
//! (cube.wgsl). A 64² cube writes 197 kB (6 × 64² texels of 8 bytes) and reads the 33 kB
//! sky: nothing beside the lightmap.

use crate::PlayerError;

/// The cube pass of one device, and its bind group over the sky output and a cube.
pub(crate) struct SkyCube {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    cube: wgpu::Texture,
    group: wgpu::BindGroup,
}

impl SkyCube {
    /// The pass from `sky` (the package's sky output) into `cube`: a square `Rgba16Float`
    /// 2D texture of 6 layers (a cube map's storage) with storage and sampling usages.
    pub fn new(
        device: &wgpu::Device,
        sky: &wgpu::TextureView,
        cube: &wgpu::Texture,
    ) -> Result<SkyCube, PlayerError> {
        use wgpu::TextureUsages as U;
        let size = cube.size();
        if cube.format() != wgpu::TextureFormat::Rgba16Float
            || cube.dimension() != wgpu::TextureDimension::D2
            || size.depth_or_array_layers != 6
            || size.width != size.height
            || size.width == 0
            || !cube
                .usage()
                .contains(U::STORAGE_BINDING | U::TEXTURE_BINDING)
        {
            return Err(PlayerError::SkyCube(format!(
                "a sky cube is a square Rgba16Float 2D texture of 6 layers with STORAGE_BINDING \
                 and TEXTURE_BINDING; got {}×{}×{} {:?} {:?} with {:?}",
                size.width,
                size.height,
                size.depth_or_array_layers,
                cube.dimension(),
                cube.format(),
                cube.usage()
            )));
        }
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vbim sky cube"),
            entries: &[
                super::read_entry(0),
                super::write_entry(1, wgpu::TextureViewDimension::D2Array),
            ],
        });
        let pipeline = crate::gpu::compute_pipeline(
            device,
            "vbim sky cube",
            include_str!("cube.wgsl"),
            &layout,
            "main",
        );
        let group = group(device, &layout, sky, cube);
        Ok(SkyCube {
            pipeline,
            layout,
            cube: cube.clone(),
            group,
        })
    }

    /// Reads the sky from `sky` (a new sky output) from now on.
    pub fn bind(&mut self, device: &wgpu::Device, sky: &wgpu::TextureView) {
        self.group = group(device, &self.layout, sky, &self.cube);
    }

    /// Records the pass (after everything that writes the sky output this frame).
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let n = self.cube.width();
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("vbim sky cube"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.group, &[]);
        pass.dispatch_workgroups(n.div_ceil(8), n.div_ceil(8), 6);
    }
}

/// The pass's bind group: `sky` read, `cube`'s six layers written.
fn group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    sky: &wgpu::TextureView,
    cube: &wgpu::Texture,
) -> wgpu::BindGroup {
    let faces = cube.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    });
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("vbim sky cube"),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(sky),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(&faces),
            },
        ],
    })
}

/// What texel (`x`, `y`) of face `face` of an `n`² sky cube holds, from `sky` (the sky
/// output read back: RGBA f32 rows of `width × height`): the CPU's statement of the cube
/// pass (cube.wgsl), for tests and tools. The texel's direction is read from WebGPU's
/// table of each face's major axis and the axes its s and t run along, as (east, up,
/// north); the azimuth runs clockwise from north; the sky is sampled bilinearly between
/// texel centres, wrapping in azimuth, and below the horizon at the horizon's row.
pub fn sky_cube_texel(
    sky: &[f32],
    (width, height): (usize, usize),
    face: u32,
    (x, y): (u32, u32),
    n: u32,
) -> [f32; 3] {
    let s = 2.0 * (x as f64 + 0.5) / n as f64 - 1.0;
    let t = 2.0 * (y as f64 + 0.5) / n as f64 - 1.0;
    let (major, sc, tc): ([f64; 3], [f64; 3], [f64; 3]) = match face {
        0 => ([1., 0., 0.], [0., 0., -1.], [0., -1., 0.]),
        1 => ([-1., 0., 0.], [0., 0., 1.], [0., -1., 0.]),
        2 => ([0., 1., 0.], [1., 0., 0.], [0., 0., 1.]),
        3 => ([0., -1., 0.], [1., 0., 0.], [0., 0., -1.]),
        4 => ([0., 0., 1.], [1., 0., 0.], [0., -1., 0.]),
        _ => ([0., 0., -1.], [-1., 0., 0.], [0., -1., 0.]),
    };
    let [east, up, north]: [f64; 3] = std::array::from_fn(|i| major[i] + s * sc[i] + t * tc[i]);
    let len = (east * east + up * up + north * north).sqrt();
    let azimuth = (90.0 - north.atan2(east).to_degrees()).rem_euclid(360.0);
    let elevation = (up / len).asin().to_degrees().max(0.0);
    let (w, h) = (width as i64, height as i64);
    let u = azimuth / 360.0 * w as f64 - 0.5;
    let v = (1.0 - elevation / 90.0) * h as f64 - 0.5;
    let (c, r) = (u.floor() as i64, v.floor() as i64);
    let (fu, fv) = (u - u.floor(), v - v.floor());
    let at = |c: i64, r: i64, ch: usize| {
        sky[((r.clamp(0, h - 1) * w + c.rem_euclid(w)) * 4) as usize + ch] as f64
    };
    std::array::from_fn(|ch| {
        let top = at(c, r, ch) * (1.0 - fu) + at(c + 1, r, ch) * fu;
        let bottom = at(c, r + 1, ch) * (1.0 - fu) + at(c + 1, r + 1, ch) * fu;
        (top * (1.0 - fv) + bottom * fv) as f32
    })
}
