//! `vbim bench …`: timings reported as the median of several runs with their spread
//! (PROTOCOL.md, "Timings").

use std::time::Instant;

use rayon::prelude::*;
use vbim_bake::{light, load_terrain, output, FrameFormat, Precomputed, Scene};

use crate::cli::{BenchBakeArgs, BenchCommand};

pub fn run(c: BenchCommand) -> Result<(), String> {
    match c {
        BenchCommand::Bake(a) => bench_bake(a),
        BenchCommand::Decode(a) => bench_decode(a),
    }
}

/// Median, min and max of a set of timings.
fn stats(v: &mut [f64]) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let med = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    (med, v[0], v[n - 1])
}

fn bench_bake(a: BenchBakeArgs) -> Result<(), String> {
    let mut scene = Scene::load(&a.scene).map_err(|e| e.to_string())?;
    scene.size = a.size;
    scene.frames = a.frames;
    scene.clouds.enabled = a.clouds;
    scene.validate()?;
    let hf = load_terrain(&scene).map_err(|e| e.to_string())?;
    let texels = a.size * a.size;
    let (mut pre_t, mut light_t, mut write_t) = (Vec::new(), Vec::new(), Vec::new());
    let tmp = std::env::temp_dir().join(format!("vbim-bench-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).map_err(|e| e.to_string())?;
    let mut pre = None;
    for _ in 0..a.runs.max(1) {
        let t = Instant::now();
        pre = Some(Precomputed::compute(hf.clone(), &scene));
        pre_t.push(t.elapsed().as_secs_f64());
    }
    let pre = pre.unwrap();
    for _ in 0..a.runs.max(1) {
        let t = Instant::now();
        (0..scene.frames).into_par_iter().for_each_init(
            || vec![0f32; texels * 3],
            |buf, i| {
                light::light_frame(&pre, &scene, i, buf);
            },
        );
        light_t.push(t.elapsed().as_secs_f64());
    }
    // Writing: 24 frames of the day as EXR, timed alone.
    let mut buf = vec![0f32; texels * 3];
    light::light_frame(&pre, &scene, scene.frames / 2, &mut buf);
    for _ in 0..a.runs.max(1) {
        let t = Instant::now();
        for i in 0..24 {
            output::write_frame(
                &tmp.join(format!("f{i}.exr")),
                a.size,
                a.size,
                &buf,
                FrameFormat::Exr,
                None,
                None,
            )
            .map_err(|e| e.to_string())?;
        }
        write_t.push(t.elapsed().as_secs_f64() / 24.0);
    }
    let _ = std::fs::remove_dir_all(&tmp);
    let (pm, p0, p1) = stats(&mut pre_t);
    let (lm, l0, l1) = stats(&mut light_t);
    let (wm, w0, w1) = stats(&mut write_t);
    let per_frame = lm / scene.frames as f64;
    println!(
        "bake benchmark: {} at {}², {} frames, {} azimuths, clouds {}, {} threads, {} runs",
        scene.name,
        a.size,
        scene.frames,
        scene.azimuths,
        if a.clouds { "on" } else { "off" },
        rayon::current_num_threads(),
        a.runs
    );
    println!(
        "precompute (horizons, sky, obscurance)  median {pm:.3} s  (min {p0:.3}, max {p1:.3})"
    );
    println!(
        "lighting, all frames                     median {lm:.3} s  (min {l0:.3}, max {l1:.3}) = {:.2} ms/frame",
        per_frame * 1e3
    );
    println!("precompute + lighting                    {:.3} s", pm + lm);
    println!(
        "EXR writing, per frame (apart)           median {:.2} ms  (min {:.2}, max {:.2})",
        wm * 1e3,
        w0 * 1e3,
        w1 * 1e3
    );
    Ok(())
}

fn bench_decode(a: crate::cli::BenchDecodeArgs) -> Result<(), String> {
    use vbim_format::chunk;
    use vbim_format::{ChunkKind, Reader};
    use vbim_player::assemble::{DecoderCore, Event, SegmentData};
    let name = a.file.display().to_string();
    let bytes = std::fs::read(&a.file).map_err(|e| format!("{name}: {e}"))?;
    let r = Reader::open(std::io::Cursor::new(&bytes)).map_err(|e| format!("{name}: {e}"))?;
    let h = r.header().clone();
    let entries = r.entries().to_vec();
    let layout = r.layout().clone();
    let chunks: Vec<&[u8]> = entries
        .iter()
        .map(|e| &bytes[e.offset as usize..(e.offset + e.length) as usize])
        .collect();
    let duration = h.frame_count as f64 / h.fps();
    let (mut zstd_t, mut full_t) = (Vec::new(), Vec::new());
    for _ in 0..a.runs.max(1) {
        // zstd alone: every keyframe, tile map and coefficient chunk decompressed.
        let t = Instant::now();
        let mut total = 0usize;
        for (e, c) in entries.iter().zip(&chunks) {
            if matches!(
                e.kind,
                ChunkKind::Keyframe | ChunkKind::TileMap | ChunkKind::Coefficients
            ) {
                total += chunk::decompress(c, vbim_format::limits::MAX_CHUNK_DECODED as usize)
                    .map_err(|e| e.to_string())?
                    .len();
            }
        }
        zstd_t.push(t.elapsed().as_secs_f64());
        std::hint::black_box(total);
        // The player's decoder: every chunk in playback order, every segment into staging.
        let t = Instant::now();
        let mut dec = DecoderCore::new(h.clone(), layout.clone(), entries.clone());
        let mut staging = SegmentData::with_capacity(&h);
        for (i, c) in chunks.iter().enumerate() {
            if let Event::Ready(s) = dec.take(i, Some(c)) {
                dec.fill(s, 0, 0, &mut staging)?;
            }
        }
        full_t.push(t.elapsed().as_secs_f64());
    }
    let (zm, z0, z1) = stats(&mut zstd_t);
    let (fm, f0, f1) = stats(&mut full_t);
    println!(
        "decode benchmark: {name}, {}×{}, {} frames at {}/{} fps ({duration:.1} s), {} segments, {} runs",
        h.width, h.height, h.frame_count, h.rate_num, h.rate_den, h.segment_count, a.runs
    );
    println!("zstd alone      median {:.3} s (min {z0:.3}, max {z1:.3}) = {:.2}% of one core in real time", zm, 100.0 * zm / duration);
    println!("full decode     median {:.3} s (min {f0:.3}, max {f1:.3}) = {:.2}% of one core in real time", fm, 100.0 * fm / duration);
    Ok(())
}
