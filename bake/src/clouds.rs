//! Moving cloud shadows: a smooth, periodic fBm layer projected from above along the sun
//! and carried by the wind. The layer tiles the map, and the wind moves it by whole periods
//! over one day, so the sequence still loops seamlessly. Because translation preserves the
//! layer's value distribution, the covered share of the map is the same in every frame.

/// Share of direct sun a fully covered texel keeps.
pub const SHADOW_TRANSMISSION: f32 = 0.2;

#[derive(Clone, Debug)]
pub struct CloudLayer {
    pub size: usize,
    /// Cloud density in [0, 1], `size × size`, periodic.
    pub density: Vec<f32>,
    /// Wind: the layer moves by (wx, wy) whole map periods per day.
    pub wind: (i32, i32),
}

fn hash(x: u32, y: u32, seed: u32) -> f32 {
    let mut h =
        x.wrapping_mul(0x8da6_b343) ^ y.wrapping_mul(0xd816_3841) ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0xffff) as f32 / 65535.0
}

/// Periodic value noise with `cells` lattice cells across the period, at (u, v) in [0, 1).
fn value_noise(u: f32, v: f32, cells: u32, seed: u32) -> f32 {
    let (x, y) = (u * cells as f32, v * cells as f32);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let q = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (sx, sy) = (q(fx), q(fy));
    let (ix, iy) = (x0 as u32 % cells, y0 as u32 % cells);
    let (jx, jy) = ((ix + 1) % cells, (iy + 1) % cells);
    let a = hash(ix, iy, seed) * (1.0 - sx) + hash(jx, iy, seed) * sx;
    let b = hash(ix, jy, seed) * (1.0 - sx) + hash(jx, jy, seed) * sx;
    a * (1.0 - sy) + b * sy
}

impl CloudLayer {
    /// A layer whose density is ≥ 0.5 on `coverage` of the map.
    pub fn new(size: usize, coverage: f64, seed: u32) -> CloudLayer {
        let mut v = Vec::with_capacity(size * size);
        for y in 0..size {
            for x in 0..size {
                let (u, w) = (x as f32 / size as f32, y as f32 / size as f32);
                let mut s = 0.0;
                let mut amp = 0.5;
                for o in 0..5 {
                    s += amp * value_noise(u, w, 3 << o, seed + o);
                    amp *= 0.5;
                }
                v.push(s);
            }
        }
        let mut sorted = v.clone();
        sorted.sort_by(f32::total_cmp);
        let q = sorted[((1.0 - coverage.clamp(0.0, 1.0)) * (sorted.len() - 1) as f64) as usize];
        let edge = 0.03;
        let density = v
            .iter()
            .map(|&s| {
                let t = ((s - q + edge) / (2.0 * edge)).clamp(0.0, 1.0);
                t * t * (3.0 - 2.0 * t)
            })
            .collect();
        CloudLayer {
            size,
            density,
            wind: (2, 1),
        }
    }

    /// Texels the layer moves per frame for a day of `frames` frames.
    pub fn speed(&self, frames: usize) -> f64 {
        let (wx, wy) = self.wind;
        ((wx * wx + wy * wy) as f64).sqrt() * self.size as f64 / frames as f64
    }

    /// Direct-sun transmission at map texel (x, y) in frame `i` of `frames`, for a shadow
    /// cast along the sun direction `dir` by a layer `lift` texels above the ground.
    pub fn transmission(
        &self,
        x: f32,
        y: f32,
        i: usize,
        frames: usize,
        dir: [f64; 3],
        lift: f32,
    ) -> f32 {
        let n = self.size as f32;
        let t = i as f32 / frames as f32;
        let slope = (dir[2].max(0.05)) as f32;
        let px = x - self.wind.0 as f32 * n * t + lift * dir[0] as f32 / slope;
        let py = y - self.wind.1 as f32 * n * t + lift * dir[1] as f32 / slope;
        let d = self.sample(px, py);
        1.0 - (1.0 - SHADOW_TRANSMISSION) * d
    }

    fn sample(&self, x: f32, y: f32) -> f32 {
        let n = self.size as f32;
        let (x, y) = (x.rem_euclid(n), y.rem_euclid(n));
        let (x0, y0) = (
            x.floor() as usize % self.size,
            y.floor() as usize % self.size,
        );
        let (x1, y1) = ((x0 + 1) % self.size, (y0 + 1) % self.size);
        let (fx, fy) = (x - x.floor(), y - y.floor());
        let d = |xx: usize, yy: usize| self.density[yy * self.size + xx];
        let a = d(x0, y0) * (1.0 - fx) + d(x1, y0) * fx;
        let b = d(x0, y1) * (1.0 - fx) + d(x1, y1) * fx;
        a * (1.0 - fy) + b * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meets_the_protocols_cloudy_definition_in_every_frame() {
        let layer = CloudLayer::new(128, 0.45, 7);
        let frames = 240;
        assert!(
            layer.speed(frames) * 4.0 >= 2.0,
            "at 512² the wind moves ≥ 2 texels per frame"
        );
        let up = [0.0, 0.0, 1.0];
        for i in (0..frames).step_by(17) {
            let covered = (0..128 * 128)
                .filter(|&k| {
                    layer.transmission((k % 128) as f32, (k / 128) as f32, i, frames, up, 0.0)
                        <= 0.4
                })
                .count();
            assert!(
                covered as f64 / (128.0 * 128.0) >= 0.30,
                "frame {i}: {covered} covered"
            );
        }
        // Periodic in time: frame `frames` equals frame 0.
        for k in (0..128 * 128).step_by(97) {
            let (x, y) = ((k % 128) as f32, (k / 128) as f32);
            let a = layer.transmission(x, y, 0, frames, up, 0.0);
            let b = layer.transmission(x, y, frames, frames, up, 0.0);
            assert!((a - b).abs() < 1e-4);
        }
    }
}
