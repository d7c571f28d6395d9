//! GPU timestamps around each displayed frame's work, and the reference it is measured
//! against: a pass that blends two `Rgba16Float` frames into a lightmap of the same size
//! (what a video texture costs the GPU), timed in the same submission.

/// Timestamps around the player's passes and around the reference blend, each frame.
pub(super) struct FrameTimer {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readback: wgpu::Buffer,
    blend: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    size: (u32, u32),
    period: f64,
}

const BLEND_WGSL: &str = r#"
@group(0) @binding(0) var a: texture_2d<f32>;
@group(0) @binding(1) var b: texture_2d<f32>;
@group(0) @binding(2) var out_tex: texture_storage_2d<rgba16float, write>;
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(out_tex);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let xy = vec2<i32>(id.xy);
    textureStore(out_tex, xy, mix(textureLoad(a, xy, 0), textureLoad(b, xy, 0), 0.4));
}
"#;

/// The compute pipeline of `source`'s `main`, its layout taken from the shader (the
/// benchmarks' own passes: the reference blend, a game's load).
pub(super) fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &str,
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// A bind group of `pipeline`'s group 0 with `resources` at bindings 0, 1, 2 …
pub(super) fn bind_group(
    device: &wgpu::Device,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    resources: &[wgpu::BindingResource],
) -> wgpu::BindGroup {
    let entries: Vec<_> = (0u32..)
        .zip(resources)
        .map(|(binding, r)| wgpu::BindGroupEntry {
            binding,
            resource: r.clone(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}

impl FrameTimer {
    /// A timer for `width × height` lightmaps, if `device` has timestamp queries.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, (w, h): (u32, u32)) -> Option<Self> {
        if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            return None;
        }
        let set = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("frame timer"),
            ty: wgpu::QueryType::Timestamp,
            count: 4,
        });
        let buffer = |usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frame timer"),
                size: 32,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as B;
        let resolved = buffer(B::QUERY_RESOLVE | B::COPY_SRC);
        let readback = buffer(B::MAP_READ | B::COPY_DST);
        use wgpu::TextureUsages as U;
        let texture = |usage| device.create_texture(&vbim_player::lightmap_descriptor(w, h, usage));
        let (a, b) = (texture(U::TEXTURE_BINDING), texture(U::TEXTURE_BINDING));
        let out = texture(U::STORAGE_BINDING);
        let blend = compute_pipeline(device, "reference blend", BLEND_WGSL);
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let (va, vb, vo) = (view(&a), view(&b), view(&out));
        let group = bind_group(
            device,
            "reference blend",
            &blend,
            &[
                wgpu::BindingResource::TextureView(&va),
                wgpu::BindingResource::TextureView(&vb),
                wgpu::BindingResource::TextureView(&vo),
            ],
        );
        Some(FrameTimer {
            set,
            resolved,
            readback,
            blend,
            group,
            size: (w, h),
            period: queue.get_timestamp_period() as f64,
        })
    }

    /// An empty pass that writes timestamp `i`, at its start or at its end.
    fn stamp(&self, enc: &mut wgpu::CommandEncoder, i: u32, at_start: bool) {
        let (b, e) = if at_start {
            (Some(i), None)
        } else {
            (None, Some(i))
        };
        enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                query_set: &self.set,
                beginning_of_pass_write_index: b,
                end_of_pass_write_index: e,
            }),
        });
    }

    /// Before the player records its frame.
    pub fn begin(&self, enc: &mut wgpu::CommandEncoder) {
        self.stamp(enc, 0, true);
    }

    /// After the player's frame.
    pub fn end(&self, enc: &mut wgpu::CommandEncoder) {
        self.stamp(enc, 1, false);
    }

    /// The reference blend, timed, and the timestamps resolved for [`FrameTimer::read`]:
    /// recorded into a submission of its own, after the player's, so that each can also be
    /// timed by the wall clock from submission to completion.
    pub fn blend(&self, enc: &mut wgpu::CommandEncoder) {
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("reference blend"),
                timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                    query_set: &self.set,
                    beginning_of_pass_write_index: Some(2),
                    end_of_pass_write_index: Some(3),
                }),
            });
            pass.set_pipeline(&self.blend);
            pass.set_bind_group(0, &self.group, &[]);
            pass.dispatch_workgroups(self.size.0.div_ceil(8), self.size.1.div_ceil(8), 1);
        }
        enc.resolve_query_set(&self.set, 0..4, &self.resolved, 0);
        enc.copy_buffer_to_buffer(&self.resolved, 0, &self.readback, 0, 32);
    }

    /// The player's frame and the reference blend, ms, once the submission is done.
    pub fn read(&self, device: &wgpu::Device) -> (f64, f64) {
        let slice = self.readback.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        let t: [u64; 4] = {
            let data = slice.get_mapped_range();
            let mut t = [0u64; 4];
            for (i, v) in t.iter_mut().enumerate() {
                *v = u64::from_le_bytes(data[i * 8..i * 8 + 8].try_into().unwrap_or([0; 8]));
            }
            t
        };
        self.readback.unmap();
        let ms = |a: u64, b: u64| b.saturating_sub(a) as f64 * self.period * 1e-6;
        (ms(t[0], t[1]), ms(t[2], t[3]))
    }
}

/// Bytes per texel a displayed frame's reconstruction reads and writes at the stream's
/// highest degree, with K_{s+1} in the f32 head (before the next decode packs it) and in
/// 16 bits (after), and the reference blend's: two Rgba16Float reads and one write. A
/// bubble layer reads its block's 16 bytes per 64 texels here; the terms beyond a block's
/// first (2 bytes each where they fit in 16 bits) depend on the content ([`mean_bytes_per_texel`] counts them), so
/// these are in quarter bytes: (head, packed, blend) × 4.
pub(super) fn quarter_bytes_per_texel(h: &vbim_format::Header) -> (u64, u64, u64) {
    let ch = h.channels as u64;
    let bubbles = ch * (h.max_degree as u64).saturating_sub(1);
    let write = 8 * 4;
    let packed = 4 * (2 * ch + 2 * ch) + bubbles + write;
    let head = 4 * (2 * ch + 4 * ch) + bubbles + write;
    (head, packed, 4 * (16 + 8))
}

/// What a file's frames touch, over its segments ([`mean_bytes_per_texel`]).
pub(super) struct Touched {
    /// Bytes per texel a frame reads and writes, K_{s+1} packed.
    pub bytes: f64,
    /// Of the bubble planes' coded blocks: the share with no term, with one, and the
    /// mean number of terms.
    pub empty: f64,
    pub one: f64,
    pub terms: f64,
}

/// The bytes per texel a frame touches (K_{s+1} packed) over the file at `path`: each tile
/// reads its keyframes (2 bytes a plane each) and its bubble layers up to its own degree
/// (a block's 16 bytes per 64 texels), and the frame the terms beyond each block's first
/// (two to a 4-byte word where they fit in 16 bits, a word each otherwise), counted from
/// the file's coefficient streams; each segment weighted by
/// its frames. `None` for a file without tile map chunks (format 2 keeps them in its
/// sections).
pub(super) fn mean_bytes_per_texel(path: &std::path::Path) -> Result<Option<Touched>, String> {
    use vbim_format::chunk::{self, CoeffReader};
    use vbim_format::plane::{read_blocks, Blocks};
    use vbim_format::{ChunkKind, Reader};
    let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut r = Reader::open(std::io::BufReader::new(file)).map_err(|e| e.to_string())?;
    let h = r.header().clone();
    let entries = r.entries().to_vec();
    let (pw, ph) = chunk::padded_size(&h);
    let texels = (pw * ph) as f64;
    let np = h.channels as usize;
    let (mut bytes, mut frames_in_all) = (0.0, 0.0);
    // Coded bubble blocks: with no term, with one, all, and their terms.
    let mut blocks = [0usize; 4];
    let mut tiles = None;
    let mut q = Blocks::default();
    let fail = |i: usize, e: &dyn std::fmt::Display| format!("{}: chunk {i}: {e}", path.display());
    for (i, e) in entries.iter().enumerate() {
        let frames = (e.last_frame - e.first_frame) as f64;
        match e.kind {
            ChunkKind::TileMap => {
                let raw = r.read_chunk(i).map_err(|e| e.to_string())?;
                tiles = Some(
                    chunk::read_tilemap(&h, &raw, e.last_frame - e.first_frame)
                        .map_err(|e| fail(i, &e))?,
                );
            }
            ChunkKind::Coefficients => {
                let Some(t) = tiles.take() else { continue };
                let stored = r.read_chunk(i).map_err(|e| e.to_string())?;
                let mut c = CoeffReader::open(&h, &stored, &t).map_err(|e| fail(i, &e))?;
                // K_s and K_{s+1}, 16 bits each, and the frame's write; then each bubble
                // plane's blocks (those of the tiles whose degree reaches its term), 16
                // bytes each, and their words of terms.
                let mut seg = texels * (8.0 + 4.0 * np as f64);
                for k in 2..=c.max_degree() {
                    for p in 0..np {
                        let mut read = Ok(());
                        c.scan_plane(k, p, |_, s| {
                            read = read_blocks(s.stream, &mut 0, s.blocks, &mut q);
                        })
                        .map_err(|e| fail(i, &e))?;
                        read.map_err(|e| fail(i, &e))?;
                        let mut words = 0;
                        for b in 0..q.len() {
                            let terms = q.nonzero(b);
                            blocks[terms.min(2)] += 1;
                            blocks[3] += terms;
                            // After the first, two 16-bit terms to a word where they all
                            // fit, one word each otherwise (`bubble_gather`).
                            let rest = terms.saturating_sub(1);
                            let wide = q.terms(b).skip(1).any(|(_, v)| i16::try_from(v).is_err());
                            words += if wide { rest } else { rest.div_ceil(2) };
                        }
                        seg += 16.0 * q.len() as f64 + 4.0 * words as f64;
                    }
                }
                bytes += frames * seg;
                frames_in_all += frames;
            }
            _ => {}
        }
    }
    let coded = (blocks[0] + blocks[1] + blocks[2]).max(1) as f64;
    Ok((frames_in_all > 0.0).then(|| Touched {
        bytes: bytes / (frames_in_all * texels),
        empty: blocks[0] as f64 / coded,
        one: blocks[1] as f64 / coded,
        terms: blocks[3] as f64 / coded,
    }))
}
