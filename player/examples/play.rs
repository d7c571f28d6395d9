//! Plays a `.vbim` file for a few seconds of simulated 60 Hz frames and prints what the
//! player did. `cargo run -p vbim-player --example play -- FILE.vbim`
//!
//! In an engine, pass the renderer's device and queue instead of `headless_device`, call
//! `advance` once per frame with the frame's time step, and bind `player.view()` (linear
//! RGB lightmap, Rgba16Float) where the terrain shader samples its lightmap. A renderer
//! that submits once per frame calls `advance_into(dt, &mut encoder)` instead, submits,
//! then calls `submitted()`.

use std::fs::File;
use std::io::BufReader;

use vbim_player::Summary;
use vbim_player::{headless_device, Player, PlayerConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: play FILE.vbim")?;
    let (device, queue, info) = headless_device()?;
    println!("adapter: {} ({:?})", info.name, info.backend);
    let file = BufReader::new(File::open(&path)?);
    let mut player = Player::open(&device, &queue, file, PlayerConfig::default())?;
    let h = player.header().clone();
    println!(
        "{}×{}, {} frames at {}/{} fps",
        h.width, h.height, h.frame_count, h.rate_num, h.rate_den
    );
    let mut records = Vec::new();
    let mut prev = 0u64;
    for k in 1..=300u64 {
        // Exact integer ticks per 60 Hz frame, without accumulated rounding.
        let t = k * 1_000_000_000 / 60;
        records.push(player.advance(t - prev));
        prev = t;
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let s = Summary::of(&records);
    println!(
        "{} frames: mean drift {:.3} frames, {} stalls, render thread {:.3} ms mean",
        s.frames, s.mean_drift, s.stalls, s.mean_render_ms
    );
    player.stop(std::time::Duration::from_secs(5))?;
    Ok(())
}
