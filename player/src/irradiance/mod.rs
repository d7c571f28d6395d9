//! Light for objects: the irradiance tracks of a package (`vbim_format::irradiance`),
//! decoded on the CPU (`track.rs`), answered on the CPU ([`Irradiance::at`]) and uploaded
//! to a storage buffer that `irradiance.wgsl` evaluates the same way on the GPU.
//!
//! What is shown is a weighted sum of up to four frames ("slots"): the two frames around
//! the shown time, weighted by its fraction; during a weather's fade, those of both
//! weathers, weighted again by the fade. Each slot keeps its own sun direction, so the
//! answer between two frames is exactly the time interpolation of the two frames' answers.

mod track;

use std::sync::{Arc, OnceLock};

pub(crate) use track::IrradianceTrack;
use vbim_format::irradiance::Grid;

/// At most this many frames are mixed.
pub const MAX_SLOTS: usize = 4;
/// Bytes of the buffer's header: size, weights, four sun directions.
const HEADER_BYTES: u64 = 96;
/// Bytes of one cell in the buffer: the sun and nine coefficients, each a `vec4<f32>`.
const CELL_BYTES: u64 = 160;

/// What an object receives at the shown time: up to `MAX_SLOTS` (4) decoded frames and
/// their weights.
#[derive(Clone, Debug, Default)]
pub struct Irradiance {
    slots: Vec<(Arc<Grid>, f32)>,
    /// The slots' coefficients summed with their weights, made at the first query (the
    /// sun stays per slot: each has its own direction).
    mixed: OnceLock<Mixed>,
}

#[derive(Clone, Debug)]
struct Mixed {
    nx: usize,
    ny: usize,
    sh: Vec<[[f32; 3]; 9]>,
    /// Per cell, each slot's sun times its weight.
    sun: Vec<[[f32; 3]; MAX_SLOTS]>,
    dirs: [[f32; 3]; MAX_SLOTS],
}

/// The same decoded frames with the same weights: the same answer everywhere (a paused
/// or held display gives an equal value every frame, which a caller can skip).
impl PartialEq for Irradiance {
    fn eq(&self, other: &Self) -> bool {
        self.slots.len() == other.slots.len()
            && self
                .slots
                .iter()
                .zip(&other.slots)
                .all(|((a, wa), (b, wb))| Arc::ptr_eq(a, b) && wa == wb)
    }
}

impl Irradiance {
    /// What a surface at lightmap coordinates (u, v) (0 to 1; u east, v south) with unit
    /// normal `n` (map frame: x east, y south, z up) receives: irradiance / π, linear RGB,
    /// in the lightmap's units (a flat open texel's value, for an up-facing normal). The
    /// weighted sum over the slots of [`Grid::irradiance`], bilinear between cell centres.
    pub fn at(&self, u: f32, v: f32, n: [f32; 3]) -> [f32; 3] {
        self.eval(u, v, n, true)
    }

    /// [`Irradiance::at`] without the sun: the sky and the bounce alone (for a renderer
    /// whose own directional light, with its own shadows, brings the sun).
    pub fn sky_at(&self, u: f32, v: f32, n: [f32; 3]) -> [f32; 3] {
        self.eval(u, v, n, false)
    }

    fn eval(&self, u: f32, v: f32, n: [f32; 3], sun: bool) -> [f32; 3] {
        if self.slots.is_empty() {
            return [0.0; 3];
        }
        let m = self.mixed.get_or_init(|| self.mix_slots());
        let ([k00, k10, k01, k11], [wx, wy]) = vbim_format::irradiance::corners(u, v, m.nx, m.ny);
        let y = vbim_format::irradiance::sh_basis(n.map(|c| c as f64)).map(|c| c as f32);
        let cos: [f32; MAX_SLOTS] = std::array::from_fn(|s| {
            let d = m.dirs[s];
            (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]).max(0.0) * sun as u32 as f32
        });
        let mut e = [0f32; 3];
        for (k, w) in [
            (k00, (1.0 - wx) * (1.0 - wy)),
            (k10, wx * (1.0 - wy)),
            (k01, (1.0 - wx) * wy),
            (k11, wx * wy),
        ] {
            let (sh, sun) = (&m.sh[k], &m.sun[k]);
            for c in 0..3 {
                let mut x = 0.0;
                for j in 0..9 {
                    x += y[j] * sh[j][c];
                }
                for s in 0..MAX_SLOTS {
                    x += cos[s] * sun[s][c];
                }
                e[c] += w * x;
            }
        }
        e
    }

    fn mix_slots(&self) -> Mixed {
        let first = &self.slots[0].0;
        let cells = first.cells.len();
        let mut m = Mixed {
            nx: first.nx,
            ny: first.ny,
            sh: vec![[[0.0; 3]; 9]; cells],
            sun: vec![[[0.0; 3]; MAX_SLOTS]; cells],
            dirs: [[0.0; 3]; MAX_SLOTS],
        };
        for (s, (g, w)) in self.slots.iter().enumerate() {
            m.dirs[s] = g.sun_dir;
            for (k, cell) in g.cells.iter().enumerate().take(cells) {
                for c in 0..3 {
                    m.sun[k][s][c] = w * cell.sun[c];
                    for j in 0..9 {
                        m.sh[k][j][c] += w * cell.sh[j][c];
                    }
                }
            }
        }
        m
    }

    /// The frames mixed and their weights.
    pub fn slots(&self) -> impl Iterator<Item = (&Grid, f32)> {
        self.slots.iter().map(|(g, w)| (&**g, *w))
    }

    pub(crate) fn new(slots: Vec<(Arc<Grid>, f32)>) -> Irradiance {
        debug_assert!(slots.len() <= MAX_SLOTS);
        Irradiance {
            slots,
            mixed: OnceLock::new(),
        }
    }

    /// `self` weighted by 1 − `w`, `other` by `w`.
    pub(crate) fn mix(self, other: Irradiance, w: f32) -> Irradiance {
        let slots = self
            .slots
            .into_iter()
            .map(|(g, x)| (g, x * (1.0 - w)))
            .chain(other.slots.into_iter().map(|(g, x)| (g, x * w)))
            .collect();
        Irradiance::new(slots)
    }
}

/// The WGSL text that declares the shown grid's buffer at `@group(group) @binding(binding)`
/// and the function `vbim_irradiance(uv: vec2<f32>, n: vec3<f32>) -> vec3<f32>` that
/// evaluates it as [`Irradiance::at`] does. Bind [`crate::PackagePlayer::irradiance_buffer`]
/// there, as a read-only storage buffer.
pub fn irradiance_wgsl(group: u32, binding: u32) -> String {
    include_str!("irradiance.wgsl")
        .replace("@group(GROUP)", &format!("@group({group})"))
        .replace("@binding(BINDING)", &format!("@binding({binding})"))
}

/// The shown grid in a storage buffer; each frame uploads the header and only the slots
/// whose frame changed.
pub(crate) struct IrradianceBuffer {
    buffer: wgpu::Buffer,
    cells: usize,
    held: [Option<Arc<Grid>>; MAX_SLOTS],
}

impl IrradianceBuffer {
    /// A buffer for grids of `nx × ny` cells.
    pub(crate) fn new(device: &wgpu::Device, nx: usize, ny: usize) -> IrradianceBuffer {
        let cells = nx * ny;
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vbim irradiance"),
            size: HEADER_BYTES + CELL_BYTES * (MAX_SLOTS * cells) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        IrradianceBuffer {
            buffer,
            cells,
            held: Default::default(),
        }
    }

    pub(crate) fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Its size, bytes.
    pub(crate) fn bytes(&self) -> u64 {
        self.buffer.size()
    }

    /// Writes `shown` into the buffer (through `queue`, before the frame's submission);
    /// returns the bytes written.
    pub(crate) fn upload(&mut self, queue: &wgpu::Queue, shown: &Irradiance) -> u64 {
        let Some((first, _)) = shown.slots.first() else {
            return 0;
        };
        let mut head = [0u32; (HEADER_BYTES / 4) as usize];
        head[0] = first.nx as u32;
        head[1] = first.ny as u32;
        head[2] = shown.slots.len() as u32;
        for (s, (g, w)) in shown.slots.iter().enumerate() {
            head[4 + s] = w.to_bits();
            for c in 0..3 {
                head[8 + 4 * s + c] = g.sun_dir[c].to_bits();
            }
        }
        queue.write_buffer(&self.buffer, 0, bytemuck::cast_slice(&head));
        let mut written = HEADER_BYTES;
        for (s, (g, _)) in shown.slots.iter().enumerate() {
            if self.held[s].as_ref().is_some_and(|h| Arc::ptr_eq(h, g))
                || g.cells.len() != self.cells
            {
                continue;
            }
            let mut data = Vec::with_capacity(self.cells * (CELL_BYTES / 4) as usize);
            for cell in &g.cells {
                data.extend_from_slice(&[cell.sun[0], cell.sun[1], cell.sun[2], 0.0]);
                for sh in &cell.sh {
                    data.extend_from_slice(&[sh[0], sh[1], sh[2], 0.0]);
                }
            }
            let at = HEADER_BYTES + CELL_BYTES * (s * self.cells) as u64;
            queue.write_buffer(&self.buffer, at, bytemuck::cast_slice(&data));
            written += (data.len() * 4) as u64;
            self.held[s] = Some(g.clone());
        }
        written
    }
}
