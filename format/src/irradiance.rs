//! Irradiance tracks: what an object standing on the terrain receives, on a coarse grid,
//! frame by frame (`docs/FORMAT.md`, "Irradiance tracks"). This module is the definition
//! of what such a track's frames mean; the bake writes them through it and the player
//! answers queries through it.
//!
//! A frame is an image of [`LAYERS`] layers of `nx × ny` cells, five layers across and two
//! down (`5·nx × 2·ny` texels, RGB). Cell (i, j) covers the lightmap's texels from
//! u = i / nx to (i + 1) / nx and v = j / ny to (j + 1) / ny and stands for a point a stated
//! height above the ground at its centre. Every value is in the lightmap's units
//! (irradiance / π), so the codec's error budget means the same as on the ground:
//! - layer 0, **the sun's transmission**: the share of the direct sun the clouds (and the
//!   weather's haze) let through at the cell, 0 to 1, the same in the three channels. The
//!   terrain's part is not coded: each cell's horizon is in the metadata ([`GridInfo`]), and
//!   a reader computes the sun disc's share above it for the frame's sun direction
//!   ([`GridInfo::visibility`]), exact in time however suddenly a ridge hides the sun. A
//!   normal N receives the frame's sun colour × that share × the transmission ×
//!   max(0, N·s): order-2 spherical harmonics cannot carry a near-point source;
//! - layers 1–9, **sky and bounce**: the order-2 spherical-harmonic irradiance
//!   (Ramamoorthi & Hanrahan 2001) of everything else (the sky the terrain leaves visible,
//!   the light reflected by the ground around, the ambient floor), stored as the irradiance
//!   it gives at the nine normals [`DIRECTIONS`]: an invertible change of basis that keeps
//!   every stored value a non-negative irradiance. [`Cell`] holds the coefficients.
//!
//! Directions are in the map frame: x east (along u), y south (along v), z up.

/// Layers in a frame: the sun's transmission, then the nine directions' irradiance.
pub const LAYERS: usize = 10;
/// Layers across a frame's image (two rows of layers).
pub const LAYERS_ACROSS: usize = 5;

/// The nine normals at which the sky-and-bounce irradiance is stored (unit vectors, map
/// frame). Chosen to make the change of basis well conditioned: a coding error e on every
/// stored value moves the irradiance at any other normal by at most 3.2 e (1.2 e for
/// independent errors, RMS).
pub const DIRECTIONS: [[f64; 3]; 9] = [
    [0.4811, -0.6603, 0.5767],
    [0.6819, 0.0280, -0.7309],
    [-0.8972, 0.4393, 0.0461],
    [-0.7103, -0.6121, 0.3474],
    [0.9360, 0.2597, 0.2378],
    [-0.0127, 0.3660, 0.9305],
    [-0.4746, -0.0907, -0.8755],
    [0.0798, 0.9615, -0.2628],
    [0.1815, -0.9007, -0.3946],
];

/// The frame image's size for `nx × ny` cells.
pub fn image_size(nx: usize, ny: usize) -> (usize, usize) {
    (LAYERS_ACROSS * nx, (LAYERS / LAYERS_ACROSS) * ny)
}

/// The cells of a frame image `w × h` texels, if it is one.
pub fn cells_of(w: usize, h: usize) -> Option<(usize, usize)> {
    let (nx, ny) = (w / LAYERS_ACROSS, h / (LAYERS / LAYERS_ACROSS));
    (nx > 0 && ny > 0 && image_size(nx, ny) == (w, h)).then_some((nx, ny))
}

/// The texel of cell (i, j) in `layer`, in a frame image of `nx × ny` cells.
pub fn texel(layer: usize, i: usize, j: usize, nx: usize, ny: usize) -> (usize, usize) {
    (
        (layer % LAYERS_ACROSS) * nx + i,
        (layer / LAYERS_ACROSS) * ny + j,
    )
}

/// The nine real spherical harmonics of order ≤ 2 at unit vector `n` (Ramamoorthi &
/// Hanrahan's normalisation and order: Y00, Y1−1 (y), Y10 (z), Y11 (x), Y2−2 (xy),
/// Y2−1 (yz), Y20, Y21 (xz), Y22 (x² − y²)).
pub fn sh_basis(n: [f64; 3]) -> [f64; 9] {
    let [x, y, z] = n;
    [
        0.282_094_8,
        0.488_602_5 * y,
        0.488_602_5 * z,
        0.488_602_5 * x,
        1.092_548_4 * x * y,
        1.092_548_4 * y * z,
        0.315_391_6 * (3.0 * z * z - 1.0),
        1.092_548_4 * x * z,
        0.546_274_2 * (x * x - y * y),
    ]
}

/// Â_l / π for each of the nine coefficients: projecting radiance L on the harmonics and
/// multiplying by these gives the coefficients of irradiance / π (π, 2π/3, π/4 over π).
pub const COSINE_LOBE: [f64; 9] = [
    1.0,
    2.0 / 3.0,
    2.0 / 3.0,
    2.0 / 3.0,
    0.25,
    0.25,
    0.25,
    0.25,
    0.25,
];

/// The matrix taking the irradiance at [`DIRECTIONS`] to the nine coefficients.
fn to_coefficients() -> &'static [[f64; 9]; 9] {
    static M: std::sync::OnceLock<[[f64; 9]; 9]> = std::sync::OnceLock::new();
    M.get_or_init(|| {
        // Invert B[k][j] = Y_j(d_k) by Gauss–Jordan with partial pivoting (well
        // conditioned: cond ≈ 1.6).
        let mut a = [[0f64; 18]; 9];
        for (k, row) in a.iter_mut().enumerate() {
            row[..9].copy_from_slice(&sh_basis(unit(DIRECTIONS[k])));
            row[9 + k] = 1.0;
        }
        for c in 0..9 {
            let p = (c..9)
                .max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))
                .expect("rows left");
            a.swap(c, p);
            let d = a[c][c];
            for v in a[c].iter_mut() {
                *v /= d;
            }
            for r in 0..9 {
                if r != c {
                    let f = a[r][c];
                    let pivot = a[c];
                    for (v, pv) in a[r].iter_mut().zip(pivot) {
                        *v -= f * pv;
                    }
                }
            }
        }
        let mut m = [[0f64; 9]; 9];
        for (mr, ar) in m.iter_mut().zip(&a) {
            mr.copy_from_slice(&ar[9..]);
        }
        m
    })
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / l)
}

/// One cell of a frame as a reader uses it: the sun a surface facing it receives (colour ×
/// the terrain's share × the transmission) and the sky-and-bounce irradiance's nine
/// coefficients per channel (irradiance / π = Σ_j `sh[j]` · Y_j(N)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cell {
    /// The direct sun a surface facing it receives, RGB.
    pub sun: [f32; 3],
    /// The coefficients, RGB each.
    pub sh: [[f32; 3]; 9],
}

impl Cell {
    /// The cell from the irradiance at [`DIRECTIONS`] and its sun.
    pub fn from_stored(sun: [f32; 3], at: &[[f32; 3]; 9]) -> Cell {
        let m = to_coefficients();
        let mut sh = [[0f32; 3]; 9];
        for (j, out) in sh.iter_mut().enumerate() {
            for c in 0..3 {
                out[c] = (0..9).map(|k| m[j][k] * at[k][c] as f64).sum::<f64>() as f32;
            }
        }
        Cell { sun, sh }
    }

    /// The irradiance / π the coefficients give at `n` (sky and bounce only).
    pub fn sky(&self, n: [f64; 3]) -> [f32; 3] {
        let y = sh_basis(n);
        let mut e = [0f64; 3];
        for (j, c) in self.sh.iter().enumerate() {
            for k in 0..3 {
                e[k] += y[j] * c[k] as f64;
            }
        }
        e.map(|v| v as f32)
    }

    /// The irradiance the coefficients give at [`DIRECTIONS`], each at least 0 (order-2
    /// ringing can dip below it where the light is very uneven): layers 1 to 9.
    pub fn stored(&self) -> [[f32; 3]; 9] {
        DIRECTIONS.map(|d| self.sky(unit(d)).map(|v| v.max(0.0)))
    }

    /// `a · (1 − w) + b · w`, value by value.
    pub fn lerp(a: &Cell, b: &Cell, w: f32) -> Cell {
        let mix = |x: f32, y: f32| x + (y - x) * w;
        let mut c = *a;
        for k in 0..3 {
            c.sun[k] = mix(a.sun[k], b.sun[k]);
            for j in 0..9 {
                c.sh[j][k] = mix(a.sh[j][k], b.sh[j][k]);
            }
        }
        c
    }
}

/// One frame's grid of cells, row by row (v), cell by cell (u).
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Cells along u.
    pub nx: usize,
    /// Cells along v.
    pub ny: usize,
    /// `nx × ny` cells.
    pub cells: Vec<Cell>,
    /// The frame's sun direction (unit, map frame; below the horizon when it is night).
    pub sun_dir: [f32; 3],
}

impl Grid {
    /// The grid a frame image holds (`5·nx × 2·ny` texels, RGB interleaved) for a frame
    /// whose sun has direction `sun_dir` and colour `sun_color`, over the cells and horizons
    /// of `info`.
    pub fn from_image(
        rgb: &[f32],
        info: &GridInfo,
        sun_dir: [f32; 3],
        sun_color: [f32; 3],
    ) -> Grid {
        let [nx, ny] = info.cells;
        let (w, _) = image_size(nx, ny);
        let at = |layer: usize, i: usize, j: usize| {
            let (x, y) = texel(layer, i, j, nx, ny);
            let o = (y * w + x) * 3;
            [rgb[o], rgb[o + 1], rgb[o + 2]]
        };
        let mut cells = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let t = at(0, i, j);
                let share = info.visibility(j * nx + i, sun_dir)
                    * ((t[0] + t[1] + t[2]) / 3.0).clamp(0.0, 1.0);
                let dirs = std::array::from_fn(|k| at(k + 1, i, j));
                cells.push(Cell::from_stored(sun_color.map(|c| c * share), &dirs));
            }
        }
        Grid {
            nx,
            ny,
            cells,
            sun_dir,
        }
    }

    /// The frame image of the grid, with each cell's sun transmission (`nx × ny`, 0 to 1) in
    /// layer 0.
    pub fn to_image(&self, transmission: &[f32]) -> Vec<f32> {
        let (w, h) = image_size(self.nx, self.ny);
        let mut out = vec![0f32; w * h * 3];
        for j in 0..self.ny {
            for i in 0..self.nx {
                let k = j * self.nx + i;
                let t = transmission[k].clamp(0.0, 1.0);
                let layers = std::iter::once([t; 3]).chain(self.cells[k].stored());
                for (layer, v) in layers.enumerate() {
                    let (x, y) = texel(layer, i, j, self.nx, self.ny);
                    out[(y * w + x) * 3..][..3].copy_from_slice(&v);
                }
            }
        }
        out
    }

    /// The cell between the four around lightmap coordinates (u, v) (0 to 1 across the
    /// lightmap), bilinear between cell centres and clamped at the edges: what an object
    /// at (u, v) receives.
    pub fn cell_at(&self, u: f32, v: f32) -> Cell {
        let ([a, b, c, d], [wx, wy]) = corners(u, v, self.nx, self.ny);
        let [a, b, c, d] = [a, b, c, d].map(|k| &self.cells[k]);
        let top = Cell::lerp(a, b, wx);
        let bottom = Cell::lerp(c, d, wx);
        Cell::lerp(&top, &bottom, wy)
    }

    /// What a surface at lightmap coordinates (u, v) with unit normal `n` (map frame)
    /// receives, irradiance / π, RGB: the sun times max(0, N·s) plus sky and bounce.
    pub fn irradiance(&self, u: f32, v: f32, n: [f32; 3]) -> [f32; 3] {
        let c = self.cell_at(u, v);
        let s = self.sun_dir;
        let cos = (n[0] * s[0] + n[1] * s[1] + n[2] * s[2]).max(0.0);
        let sky = c.sky(n.map(|x| x as f64));
        std::array::from_fn(|k| c.sun[k] * cos + sky[k])
    }
}

/// The four cells around lightmap coordinates (u, v) on a grid of `nx × ny` cells (row by
/// row: (x0, y0), (x1, y0), (x0, y1), (x1, y1)) and the weights of x1 and y1: bilinear
/// between cell centres, clamped at the edges. The grid's readers (the CPU query, the
/// player's lightmap sample) all sample so; `irradiance.wgsl` says the same.
pub fn corners(u: f32, v: f32, nx: usize, ny: usize) -> ([usize; 4], [f32; 2]) {
    let fx = (u * nx as f32 - 0.5).clamp(0.0, (nx - 1) as f32);
    let fy = (v * ny as f32 - 0.5).clamp(0.0, (ny - 1) as f32);
    let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(nx - 1), (y0 + 1).min(ny - 1));
    (
        [y0 * nx + x0, y0 * nx + x1, y1 * nx + x0, y1 * nx + x1],
        [fx - x0 as f32, fy - y0 as f32],
    )
}

/// What an irradiance track's metadata says about its grid (the bake's manifest's
/// `irradiance_grid`), with each cell's horizon, from which a reader computes the sun's
/// share above the terrain.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct GridInfo {
    /// Cells along u and v.
    pub cells: [usize; 2],
    /// The height above the ground the cells' points stand at, metres.
    pub height_m: f32,
    /// The ground's albedo in the bounce.
    pub albedo: f32,
    /// The sun disc's angular diameter, degrees (the bake's soft sun).
    pub sun_diameter_deg: f32,
    /// Azimuths of the horizons: azimuth a looks from +x (east) towards +y (south) by
    /// 360° · a / azimuths.
    pub azimuths: usize,
    /// Each cell's horizon elevation in steps of 90° / 255 (0: the horizontal or below),
    /// azimuth by azimuth: `horizons[a · cells + c]`. Empty for a track without direct sun
    /// (layer 0 is 0 everywhere; [`GridInfo::visibility`] is then 1).
    pub horizons: Vec<u8>,
}

/// The angle of one step of [`GridInfo::horizons`], radians.
pub const HORIZON_STEP: f64 = std::f64::consts::FRAC_PI_2 / 255.0;

impl GridInfo {
    /// Whether the description holds together: cells, azimuths and horizons.
    pub fn check(&self) -> Result<(), String> {
        let [nx, ny] = self.cells;
        if !(1..=4096).contains(&nx) || !(1..=4096).contains(&ny) {
            return Err(format!("irradiance grid of {nx}×{ny} cells"));
        }
        let whole = self.horizons.is_empty() || self.horizons.len() == self.azimuths * nx * ny;
        if !(1..=1024).contains(&self.azimuths) || !whole {
            return Err(format!(
                "irradiance grid: {} horizons for {} azimuths of {nx}×{ny} cells",
                self.horizons.len(),
                self.azimuths
            ));
        }
        if !(self.sun_diameter_deg > 0.0 && self.sun_diameter_deg < 20.0) {
            return Err(format!(
                "irradiance grid: sun diameter {}°",
                self.sun_diameter_deg
            ));
        }
        Ok(())
    }

    /// The share of the sun disc above cell `c`'s horizon for sun direction `d` (unit, map
    /// frame): the disc's elevation against the horizon towards its azimuth, linear
    /// between the two nearest azimuths, over the disc's diameter (paper 001's soft sun).
    pub fn visibility(&self, c: usize, d: [f32; 3]) -> f32 {
        if self.horizons.is_empty() {
            return 1.0;
        }
        let cells = self.cells[0] * self.cells[1];
        let n = self.azimuths;
        let e = (d[2] as f64).clamp(-1.0, 1.0).asin();
        let t = (d[1] as f64)
            .atan2(d[0] as f64)
            .rem_euclid(std::f64::consts::TAU)
            / std::f64::consts::TAU
            * n as f64;
        let a0 = (t.floor() as usize) % n;
        let a1 = (a0 + 1) % n;
        let f = t - t.floor();
        let h = |a: usize| self.horizons[a * cells + c] as f64 * HORIZON_STEP;
        let phi = h(a0) * (1.0 - f) + h(a1) * f;
        let alpha = (self.sun_diameter_deg as f64).to_radians();
        ((e + 0.5 * alpha - phi) / alpha).clamp(0.0, 1.0) as f32
    }
}

/// One frame's sun: its direction (unit, map frame) and colour (the direct sun's texel
/// value at normal incidence, RGB).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSun {
    /// Direction.
    pub dir: [f32; 3],
    /// Colour.
    pub color: [f32; 3],
}

/// Each frame's sun from a track's metadata (the bake's manifest: `per_frame` entries with
/// `sun_dir` and `sun_color`); `None` if the metadata lacks them for some frame of `frames`.
pub fn frame_suns(metadata: &str, frames: usize) -> Option<Vec<FrameSun>> {
    let v: serde_json::Value = serde_json::from_str(metadata).ok()?;
    let per = v.get("per_frame")?.as_array()?;
    if per.len() < frames {
        return None;
    }
    let three = |f: &serde_json::Value, key: &str| -> Option<[f32; 3]> {
        let d = f.get(key)?.as_array()?;
        let c = |k: usize| d.get(k).and_then(|x| x.as_f64()).map(|x| x as f32);
        let d = [c(0)?, c(1)?, c(2)?];
        d.iter().all(|x| x.is_finite()).then_some(d)
    };
    per.iter()
        .take(frames)
        .map(|f| {
            Some(FrameSun {
                dir: three(f, "sun_dir")?,
                color: three(f, "sun_color")?,
            })
        })
        .collect()
}

/// The cells of an irradiance track as its header states them, or why it cannot be one:
/// its frames must be RGB grids of 5·nx × 2·ny texels, and there must be frames.
pub fn frame_cells(h: &crate::Header) -> Result<(usize, usize), String> {
    let cells = cells_of(h.width as usize, h.height as usize).filter(|_| h.channels == 3);
    match cells {
        Some(c) if h.frame_count > 0 => Ok(c),
        Some(_) => Err("an irradiance track without frames".into()),
        None => Err(format!(
            "an irradiance track of {}×{}, {} channel(s): its frames are RGB grids of \
             5·nx × 2·ny texels",
            h.width, h.height, h.channels
        )),
    }
}

/// An irradiance track's grid and each frame's sun, from its header and metadata, or why
/// it cannot be played: [`frame_cells`], then a metadata chunk with every frame's sun and
/// a grid that holds together ([`GridInfo::check`]) and matches the frames.
pub fn read_track<R: std::io::Read + std::io::Seek>(
    reader: &mut crate::Reader<R>,
) -> Result<(GridInfo, Vec<FrameSun>), String> {
    let h = reader.header().clone();
    let (nx, ny) = frame_cells(&h)?;
    let frames = h.frame_count as usize;
    let meta = reader
        .metadata()
        .map_err(|e| e.to_string())?
        .ok_or("an irradiance track without metadata (each frame's sun)")?;
    let suns = frame_suns(&meta, frames)
        .ok_or_else(|| format!("its metadata lacks the sun of some of its {frames} frames"))?;
    let info = grid_info(&meta)
        .ok_or("its metadata lacks a valid irradiance_grid (cells, horizons, sun diameter)")?;
    if info.cells != [nx, ny] {
        return Err(format!(
            "its metadata's grid is {:?} cells, its frames hold {nx}×{ny}",
            info.cells
        ));
    }
    Ok((info, suns))
}

/// The grid description in a track's metadata, if it has a valid one.
pub fn grid_info(metadata: &str) -> Option<GridInfo> {
    let v: serde_json::Value = serde_json::from_str(metadata).ok()?;
    let info: GridInfo = serde_json::from_value(v.get("irradiance_grid")?.clone()).ok()?;
    info.check().ok().map(|()| info)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rand_dirs(n: usize) -> Vec<[f64; 3]> {
        // A deterministic spread of directions (a Fibonacci sphere).
        let g = (1.0 + 5f64.sqrt()) / 2.0;
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let a = std::f64::consts::TAU * i as f64 / g;
                [r * a.cos(), r * a.sin(), z]
            })
            .collect()
    }

    #[test]
    fn the_stored_directions_give_back_the_coefficients() {
        // Y00's term (5 · 0.28) outweighs every other (8 · 0.1 · 1.09 at most): positive.
        let sh: [[f32; 3]; 9] = std::array::from_fn(|j| match j {
            0 => [5.0, 4.0, 3.0],
            _ => [0.1 - 0.01 * j as f32, 0.01 * j as f32, -0.05],
        });
        let cell = Cell { sun: [2.0; 3], sh };
        let stored = cell.stored();
        // Positive everywhere here, so nothing was clamped.
        let back = Cell::from_stored(cell.sun, &stored);
        for (j, (got, want)) in back.sh.iter().zip(&sh).enumerate() {
            for (c, (g, w)) in got.iter().zip(want).enumerate() {
                assert!((g - w).abs() < 1e-4, "{j} {c}");
            }
        }
    }

    #[test]
    fn uniform_light_gives_the_same_irradiance_at_every_normal() {
        // A uniform sphere of radiance L: irradiance / π = L at every normal.
        let mut sh = [[0f32; 3]; 9];
        sh[0] = [(2.0 * std::f64::consts::PI.sqrt()) as f32 * 0.7; 3];
        let cell = Cell { sun: [0.0; 3], sh };
        for d in rand_dirs(50) {
            assert!((cell.sky(d)[0] - 0.7).abs() < 1e-5);
        }
    }

    #[test]
    fn a_coding_error_moves_the_irradiance_by_at_most_a_few_times_itself() {
        // The change of basis's Lebesgue constant: every stored value off by up to e.
        let m = to_coefficients();
        let worst = rand_dirs(4000)
            .into_iter()
            .map(|n| {
                let y = sh_basis(n);
                (0..9)
                    .map(|k| (0..9).map(|j| y[j] * m[j][k]).sum::<f64>().abs())
                    .sum::<f64>()
            })
            .fold(0.0, f64::max);
        assert!(worst < 3.2, "{worst}");
    }

    #[test]
    fn a_grid_is_bilinear_between_cell_centres_and_flat_beyond() {
        let mk = |v: f32| Cell {
            sun: [v; 3],
            sh: [[0.0; 3]; 9],
        };
        let g = Grid {
            nx: 2,
            ny: 1,
            cells: vec![mk(1.0), mk(3.0)],
            sun_dir: [0.0, 0.0, 1.0],
        };
        let up = [0.0, 0.0, 1.0];
        assert_eq!(g.irradiance(0.0, 0.5, up)[0], 1.0);
        assert_eq!(g.irradiance(0.25, 0.5, up)[0], 1.0);
        assert_eq!(g.irradiance(0.5, 0.5, up)[0], 2.0);
        assert_eq!(g.irradiance(1.0, 0.5, up)[0], 3.0);
        assert_eq!(g.irradiance(0.5, 0.5, [0.0, 0.0, -1.0])[0], 0.0);
        let img = g.to_image(&[0.5, 1.0]);
        assert_eq!(img.len(), 5 * 2 * 2 * 3);
        // No horizon anywhere: the sun at the zenith is wholly visible.
        let info = GridInfo {
            cells: [2, 1],
            sun_diameter_deg: 1.5,
            azimuths: 8,
            horizons: vec![0; 16],
            ..GridInfo::default()
        };
        let back = Grid::from_image(&img, &info, g.sun_dir, [2.0; 3]);
        assert_eq!(back.cells[0].sun, [1.0; 3]);
        assert_eq!(back.cells[1].sun, [2.0; 3]);
    }

    #[test]
    fn the_sun_sets_behind_a_cells_horizon_over_the_discs_diameter() {
        // Cell 0 has a horizon of 10° towards the west (azimuth 180°), none elsewhere.
        let mut horizons = vec![0u8; 8];
        let ten = (10f64.to_radians() / HORIZON_STEP).round() as u8;
        horizons[4] = ten;
        let info = GridInfo {
            cells: [1, 1],
            sun_diameter_deg: 2.0,
            azimuths: 8,
            horizons,
            ..GridInfo::default()
        };
        info.check().unwrap();
        let west = |deg: f64| {
            let e = deg.to_radians();
            [-(e.cos()) as f32, 0.0, e.sin() as f32]
        };
        let phi = ten as f64 * HORIZON_STEP;
        let at = |e: f64| info.visibility(0, west(phi.to_degrees() + e));
        assert!(at(1.0) > 0.999);
        assert!((at(0.0) - 0.5).abs() < 1e-3);
        assert!(at(-1.0) < 1e-3);
        // To the east the sun is seen down to the horizontal.
        assert!((info.visibility(0, [1.0, 0.0, 0.0]) - 0.5).abs() < 1e-3);
        let mut bad = info.clone();
        bad.horizons.pop();
        assert!(bad.check().is_err());
    }

    #[test]
    fn metadata_gives_each_frames_sun_and_the_grid() {
        let m = r#"{"per_frame":[{"sun_dir":[0,0,1],"sun_color":[1,1,1]},
                                 {"sun_dir":[1,0,0],"sun_color":[0.5,0.4,0.3]}],
                    "irradiance_grid":{"cells":[2,1],"height_m":2.0,"albedo":0.3,
                        "sun_diameter_deg":1.5,"azimuths":2,"horizons":[0,1,2,3]}}"#;
        assert_eq!(frame_suns(m, 2).unwrap()[1].dir, [1.0, 0.0, 0.0]);
        assert_eq!(frame_suns(m, 2).unwrap()[1].color, [0.5, 0.4, 0.3]);
        assert_eq!(frame_suns(m, 3), None);
        assert_eq!(grid_info(m).unwrap().cells, [2, 1]);
        assert_eq!(grid_info(&m.replace("[0,1,2,3]", "[0,1,2]")), None);
        assert_eq!(frame_suns("{", 1), None);
    }
}
