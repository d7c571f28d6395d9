//! The terrain mesh: a grid over the height field, with lightmap coordinates and a base
//! colour from elevation and slope (meadow, forest, rock, snow).

use bytemuck::{Pod, Zeroable};
use vbim_bake::HeightField;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct Vertex {
    pub pos: [f32; 3],
    pub uv: [f32; 2],
    pub base: [f32; 3],
}

pub struct Mesh {
    pub vertices: Vec<Vertex>,
    pub indices: Vec<u32>,
    /// Half the map's width and depth in scene units (its longer side spans [−1, 1]).
    pub extent: (f32, f32),
    /// Map metres to scene units.
    place: Place,
}

/// How the height field's metres become the scene's units (x east, y up, z south).
#[derive(Clone, Copy, Debug)]
struct Place {
    half: f32,
    width_m: f32,
    depth_m: f32,
    lo: f32,
    vx: f32,
}

/// Base colour (linear albedo) from normalised elevation `e` (0–1) and slope (1 − n_z).
pub fn base_colour(e: f32, slope: f32, snow_line: f32) -> [f32; 3] {
    let meadow = [0.16, 0.22, 0.09];
    let forest = [0.08, 0.13, 0.06];
    let rock = [0.24, 0.22, 0.20];
    let snow = [0.80, 0.82, 0.86];
    let mix = |a: [f32; 3], b: [f32; 3], t: f32| {
        [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * t.clamp(0.0, 1.0))
    };
    let mut c = mix(meadow, forest, (e * 2.0 - 0.2).clamp(0.0, 1.0));
    c = mix(
        c,
        rock,
        ((slope - 0.12) * 6.0).max(((e - 0.7) * 5.0).clamp(0.0, 1.0)),
    );
    if e > snow_line {
        c = mix(
            c,
            snow,
            ((e - snow_line) * 12.0).min(1.0) * (1.0 - (slope * 3.0).min(1.0)),
        );
    }
    c
}

impl Mesh {
    /// A grid of at most `max_cells`² quads over `hf`, with vertical exaggeration `vx`.
    pub fn new(hf: &HeightField, max_cells: usize, vx: f32, snow_line: f32) -> Mesh {
        let step = (hf.w.max(hf.h) as f32 / max_cells as f32).max(1.0);
        let (gw, gh) = (
            ((hf.w - 1) as f32 / step).ceil() as usize + 1,
            ((hf.h - 1) as f32 / step).ceil() as usize + 1,
        );
        let width_m = (hf.w - 1) as f32 * hf.cell_x as f32;
        let depth_m = (hf.h - 1) as f32 * hf.cell_y as f32;
        let half = 0.5 * width_m.max(depth_m);
        let (lo, hi) =
            hf.z.iter()
                .fold((f32::MAX, f32::MIN), |(a, b), &z| (a.min(z), b.max(z)));
        let normals = hf.normals();
        let mut vertices = Vec::with_capacity(gw * gh);
        for j in 0..gh {
            for i in 0..gw {
                let (x, y) = (
                    ((i as f32) * step).min((hf.w - 1) as f32),
                    ((j as f32) * step).min((hf.h - 1) as f32),
                );
                let z = hf.sample(x, y);
                let n = normals[(y.round() as usize) * hf.w + x.round() as usize];
                let e = if hi > lo { (z - lo) / (hi - lo) } else { 0.0 };
                vertices.push(Vertex {
                    pos: [
                        (x * hf.cell_x as f32 - 0.5 * width_m) / half,
                        (z - lo) * vx / half,
                        (y * hf.cell_y as f32 - 0.5 * depth_m) / half,
                    ],
                    // Lightmap texel centres: texel k covers [k, k + 1) / size.
                    uv: [(x + 0.5) / hf.w as f32, (y + 0.5) / hf.h as f32],
                    base: base_colour(e, 1.0 - n[2], snow_line),
                });
            }
        }
        let mut indices = Vec::with_capacity((gw - 1) * (gh - 1) * 6);
        for j in 0..gh - 1 {
            for i in 0..gw - 1 {
                let a = (j * gw + i) as u32;
                let (b, c, d) = (a + 1, a + gw as u32, a + gw as u32 + 1);
                indices.extend_from_slice(&[a, c, b, b, c, d]);
            }
        }
        Mesh {
            vertices,
            indices,
            extent: (width_m / half * 0.5, depth_m / half * 0.5),
            place: Place {
                half,
                width_m,
                depth_m,
                lo,
                vx,
            },
        }
    }

    /// The ground of `hf` (the field the mesh was made from) at lightmap coordinates
    /// (u, v), in scene units.
    pub fn ground(&self, hf: &HeightField, u: f32, v: f32) -> [f32; 3] {
        let p = self.place;
        let (x, y) = (u * hf.w as f32 - 0.5, v * hf.h as f32 - 0.5);
        let z = hf.sample(x, y);
        [
            (x * hf.cell_x as f32 - 0.5 * p.width_m) / p.half,
            (z - p.lo) * p.vx / p.half,
            (y * hf.cell_y as f32 - 0.5 * p.depth_m) / p.half,
        ]
    }
}
