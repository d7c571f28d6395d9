//! A small synthetic day the encoder's tests share: a smooth light that rises and falls,
//! a shadow edge moving across it, and fine periodic texture.

use vbim_encoder::{InputKind, MemorySource};

/// `frames` frames of `w` × `h` RGB, named `name`.
pub fn moving_edge_day(name: &str, w: usize, h: usize, frames: usize) -> MemorySource {
    let data = (0..frames)
        .map(|t| {
            let s = t as f32 / frames as f32;
            (0..w * h)
                .flat_map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let sun = (3.0 * s).sin().max(0.05);
                    let edge = if x + 0.5 * y > 10.0 + 30.0 * s {
                        1.0
                    } else {
                        0.3
                    };
                    let grain = 0.02 * ((x * 7.3 + y * 3.1).sin());
                    let v = sun * edge * (0.6 + 0.004 * x) + grain + 0.05;
                    [v, v * 0.9, v * 0.7 + 0.01 * y / h as f32]
                })
                .collect()
        })
        .collect();
    MemorySource::new(name, w, h, 3, InputKind::Hdr, data)
}
