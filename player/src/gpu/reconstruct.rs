//! The per-frame reconstruction (`reconstruct.wgsl`): the time basis evaluated over the
//! resident keyframes and bubble planes into the lightmap, the hold pass that keeps what is
//! on screen for catch-up blending, and the caller's output texture.

use super::plan::degree_stride;
use super::Gpu;
use crate::slots::MAX_BUBBLE_PLANES;

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
    /// Regions of the 16-bit keyframes' ranges, across and down.
    pub regions: [u32; 2],
    /// The first layer of K_s and of K_{s+1} among the 16-bit keyframes.
    pub keys: [u32; 2],
    /// Quantiser step of each bubble plane (a block's terms after its first are stored as
    /// 16-bit integers where they fit).
    pub steps: [f32; MAX_BUBBLE_PLANES],
    /// The first layer of the segment's bubble set among the bubble blocks.
    pub set_base: u32,
    /// 1 while K_{s+1} is read from the f32 head (not packed yet).
    pub head_f32: u32,
    /// The generation of everything but the weights (set by [`Gpu::reconstruct`]): a tile
    /// evaluated under another is evaluated again.
    pub gen: u32,
    /// The largest change of Σ over planes of |c| (code domain) a tile of 16² texels may
    /// lag by before it is evaluated again; 0: every tile every frame.
    pub reuse: f32,
    /// Which copy of the tiles' state the frame reads (set by [`Gpu::reconstruct`]).
    pub parity: u32,
    /// The stream's tiles: their side in texels, how many across a plane and in it
    /// (set by [`Gpu::reconstruct`]).
    pub tile: u32,
    pub tiles_x: u32,
    pub tiles: u32,
    /// The first word of the bubble set's tile degrees (set by [`Gpu::reconstruct`]).
    pub degrees: u32,
    /// The frame's place in a cycle of three, whether it decides which tiles to keep
    /// (1), and whether the feedback from the kept count is on (set by
    /// [`Gpu::reconstruct`]).
    pub frame3: u32,
    pub probe: u32,
    pub feedback: u32,
}

/// A texture given to [`Player::set_output`](crate::Player::set_output) that the player
/// cannot write: it must be a `width × height` 2D `Rgba16Float` texture with
/// `STORAGE_BINDING | TEXTURE_BINDING` usage ([`lightmap_descriptor`](crate::lightmap_descriptor)).
#[derive(Debug, Clone, thiserror::Error)]
#[error(
    "the output must be a {width}×{height} 2D Rgba16Float texture with STORAGE_BINDING | \
     TEXTURE_BINDING usage (the player reads it to keep the image on screen for catch-up \
     blending); got {}×{}×{} {dimension:?} {format:?} with {usage:?}",
    got.width,
    got.height,
    got.depth_or_array_layers
)]
pub struct OutputError {
    /// The stream's width.
    pub width: u32,
    /// The stream's height.
    pub height: u32,
    /// The texture's size.
    pub got: wgpu::Extent3d,
    /// Its dimension.
    pub dimension: wgpu::TextureDimension,
    /// Its format.
    pub format: wgpu::TextureFormat,
    /// Its usages.
    pub usage: wgpu::TextureUsages,
}

impl Gpu {
    /// Makes the reconstruction write into `texture` (the caller's) instead of the
    /// player's own lightmap, or into its own again with `None`.
    pub fn set_output(&mut self, texture: Option<&wgpu::Texture>) -> Result<(), OutputError> {
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
            return Err(OutputError {
                width: self.width,
                height: self.height,
                got: t.size(),
                dimension: t.dimension(),
                format: t.format(),
                usage: t.usage(),
            });
        }
        self.output = Some(self.output_groups(t.clone()));
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

    /// Records the reconstruction of one frame into `enc`. The parameters go through
    /// `Queue::write_buffer`, which takes effect at the queue's next submission: the one
    /// that carries `enc`. `fresh`: what the lightmap holds cannot be reused (a new output,
    /// a seek), so every tile is evaluated.
    pub fn reconstruct(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        params: &Params,
        hold_first: bool,
        fresh: bool,
    ) {
        let set = params.set_base / self.set_layers.max(1);
        let mut params = Params {
            regions: self.regions,
            gen: self.gen,
            tile: self.per * 8,
            tiles_x: self.tiles_x,
            tiles: self.tile_count,
            degrees: set * degree_stride(self.plane, self.per * 8, self.channels),
            ..*params
        };
        // Anything but the weights changed: the tiles' bounds and images are another
        // generation's. (The generation wraps after 2^32 changes; a tile last evaluated
        // exactly 2^32 changes ago is not a worry.)
        let same = self.last_params.as_ref().is_some_and(|last| {
            let strip = |p: &Params| Params { w: [0.0; 12], ..*p };
            bytemuck::bytes_of(&strip(last)) == bytemuck::bytes_of(&strip(&params))
        });
        let first = fresh || hold_first || !same;
        if first {
            self.gen = self.gen.wrapping_add(1).max(1);
            params.gen = self.gen;
        }
        // (Stored before the fields that change every frame are set.)
        self.last_params = Some(params);
        self.parity ^= 1;
        params.parity = self.parity;
        params.frame3 = self.frame3;
        self.frame3 = (self.frame3 + 1) % 3;
        params.feedback = (self.reuse_probe > 0) as u32;
        // A frame decides every `reuse_probe` frames, and right after the first of a
        // generation (which keeps no tile, so its count says nothing).
        let probe = self.reuse_probe == 0
            || self.since_probe + 1 >= self.reuse_probe as u64
            || self.after_first;
        params.probe = probe as u32;
        self.since_probe = if probe { 0 } else { self.since_probe + 1 };
        self.after_first = first;
        // The first frame of a generation evaluates every tile and finds the tiles'
        // bounds (atomic maxima, cleared first); the others may keep tiles.
        let pipeline = if first && params.reuse > 0.0 {
            enc.clear_buffer(&self.peaks, 0, None);
            &self.pipeline_fresh
        } else {
            &self.pipeline
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
        pass.set_pipeline(pipeline);
        let groups = self
            .output
            .as_ref()
            .map_or(&self.bind_groups, |(_, g, _)| g);
        pass.set_bind_group(0, &groups[set as usize], &[]);
        // A workgroup is 8 × 8 invocations of a 2 × 2 quad each, a tile of 16² texels
        // (reconstruct.wgsl; `tile_bytes` counts its state).
        pass.dispatch_workgroups(self.width.div_ceil(16), self.height.div_ceil(16), 1);
        self.mark(&mut pass, "reconstruct");
    }

    /// Reads the texture the reconstruction writes back (RGBA, f32). For tests and error
    /// measurement.
    pub fn read_display(&self) -> Vec<f32> {
        let raw = crate::readback::read_texture(&self.device, &self.queue, self.target(), 8);
        bytemuck::cast_slice::<u8, half::f16>(&raw)
            .iter()
            .map(|v| v.to_f32())
            .collect()
    }
}

impl Params {
    pub fn zeroed_params() -> Params {
        bytemuck::Zeroable::zeroed()
    }
}
