//! `vbim bench scale`: what the runtime costs as the lightmap grows — the budget every
//! runtime feature must stay within. For each size, a day of the sample is baked and
//! encoded (default preset, 24/1 fps; kept for the next run), then played in a process of
//! its own, so that its peak memory is its own: two loops in simulated time, the second
//! measured. A 64² stream gives the process's baseline.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use vbim_bake::{bake, BakeOptions, FrameFormat, Scene};
use vbim_encoder::{encode_file, EncoderConfig, FrameSet, Preset};
use vbim_player::{thread_cpu_ns, Player, PlayerConfig};

use super::{BenchScaleArgs, BenchScaleOneArgs};
use crate::plot::{lines, Series};
use crate::progress::Stages;

/// The lightmap size whose process gives the baseline memory.
const BASELINE: usize = 64;

/// What one stream cost (one process, `vbim bench scale-one`).
#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct Cost {
    pub size: u32,
    pub texels: u64,
    pub file_bytes: u64,
    /// GPU memory the player holds ([`Player::gpu_bytes`]).
    pub gpu_bytes: u64,
    /// The process's peak resident memory (VmHWM), bytes.
    pub peak_rss: u64,
    /// Over the second loop: bytes read, and bytes uploaded to the GPU.
    pub loop_read: u64,
    pub loop_uploaded: u64,
    /// Over the second loop: decoder CPU time, reader CPU time, and the loop's media
    /// duration, ns.
    pub loop_decode_ns: u64,
    #[serde(default)]
    pub loop_read_ns: u64,
    pub loop_media_ns: u64,
    /// Means per displayed frame over the second loop: the render thread's CPU time in
    /// recording and submitting (`render`), and the GPU's execution (waited for apart), ns.
    pub render_cpu_ns: f64,
    pub gpu_ns: f64,
    pub display_hz: u32,
    /// The adapter it played on (name and backend): wgpu falls back to OpenGL where
    /// Vulkan is missing, and the GPU figures are not comparable across backends.
    #[serde(default)]
    pub adapter: String,
}

/// `vbim bench scale`: every size, each in a child process; a table, a CSV and plots.
pub fn run(a: BenchScaleArgs) -> Result<(), String> {
    std::fs::create_dir_all(&a.out).map_err(|e| format!("{}: {e}", a.out.display()))?;
    let saved = a.out.join("costs.json");
    if a.replot {
        let text =
            std::fs::read_to_string(&saved).map_err(|e| format!("{}: {e}", saved.display()))?;
        let costs: Vec<Cost> =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", saved.display()))?;
        return report(&a, &costs);
    }
    let mut sizes = vec![BASELINE];
    sizes.extend(a.sizes.iter().copied().filter(|&s| s != BASELINE));
    let mut costs = Vec::new();
    for &size in &sizes {
        let file = stream_for(&a, size)?;
        eprintln!("playing {}", file.display());
        let exe = this_binary()?;
        let out = std::process::Command::new(exe)
            .args(["bench", "scale-one"])
            .arg(&file)
            .args(["--display-hz", &a.display_hz.to_string()])
            .args(["--memory-limit", &a.memory.limits.memory.to_string()])
            .output()
            .map_err(|e| e.to_string())?;
        if !out.status.success() {
            return Err(format!(
                "{}: {}",
                file.display(),
                String::from_utf8_lossy(&out.stderr).trim()
            ));
        }
        let cost: Cost = serde_json::from_slice(&out.stdout)
            .map_err(|e| format!("{}: the measuring process said: {e}", file.display()))?;
        costs.push(cost);
    }
    write(
        &saved,
        &serde_json::to_string_pretty(&costs).expect("costs serialise"),
    )?;
    report(&a, &costs)
}

/// This very binary, for the measuring child processes. On Linux `/proc/self/exe`: it
/// still runs this build when the file has been rebuilt or removed during a long run,
/// where the path `current_exe` gives then names another build, or nothing.
fn this_binary() -> Result<PathBuf, String> {
    let own = Path::new("/proc/self/exe");
    if cfg!(target_os = "linux") && own.exists() {
        return Ok(own.to_path_buf());
    }
    std::env::current_exe().map_err(|e| e.to_string())
}

/// The stream of `size`², baked and encoded unless `out` already holds it.
fn stream_for(a: &BenchScaleArgs, size: usize) -> Result<PathBuf, String> {
    let file = a.out.join(format!("{size}.vbim"));
    if file.is_file() {
        return Ok(file);
    }
    let mut scene = Scene::load(&a.scene).map_err(|e| e.to_string())?;
    scene.size = size;
    scene.frames = a.frames;
    scene.clouds.enabled = a.clouds;
    scene.detail.enabled = a.detail;
    let frames = a.out.join(format!("frames-{size}"));
    let stages = Stages::new();
    let progress = |s: &str, d: u64, t: u64| stages.report(s, d, t);
    eprintln!("baking and encoding {size}² × {} frames", a.frames);
    let opts = BakeOptions {
        out: frames.clone(),
        format: FrameFormat::Exr,
        use_cache: true,
    };
    bake(&scene, &opts, &progress).map_err(|e| e.to_string())?;
    let fs = FrameSet::open(&frames.to_string_lossy()).map_err(|e| e.to_string())?;
    let cfg = EncoderConfig {
        rate: (24, 1),
        memory_limit: a.encoder_limits.memory,
        ..EncoderConfig::preset(Preset::Default)
    };
    encode_file(&fs, &cfg, &file, &progress).map_err(|e| e.to_string())?;
    stages.finish();
    // The frames are large at the sizes that matter; the stream is what is measured.
    std::fs::remove_dir_all(&frames).map_err(|e| format!("{}: {e}", frames.display()))?;
    Ok(file)
}

/// `vbim bench scale-one FILE`: plays two loops in simulated time and prints its [`Cost`]
/// as JSON.
pub fn run_one(a: BenchScaleOneArgs) -> Result<(), String> {
    let name = a.file.display().to_string();
    let (device, queue, info) = vbim_player::headless_device().map_err(|e| e.to_string())?;
    let f = crate::sequence::open_input(&a.file)?;
    let file_bytes = f.metadata().map_err(|e| format!("{name}: {e}"))?.len();
    let cfg = PlayerConfig {
        threaded: false,
        limits: a.memory.limits,
        ..PlayerConfig::default()
    };
    let mut player = Player::open(&device, &queue, std::io::BufReader::new(f), cfg)
        .map_err(|e| format!("{name}: {e}"))?;
    let h = player.header().clone();
    // One display frame every 1/hz s, in integer ns (never accumulated in floats).
    let hz = a.display_hz.max(1) as u64;
    let frame_at = |k: u64| k * 1_000_000_000 / hz;
    let loop_ns = crate::session::frame_ns(h.frame_count as u64, &h)
        .ok_or_else(|| format!("{name}: a loop longer than the player's clock"))?;
    let per_loop = loop_ns * hz / 1_000_000_000;
    let (mut k, mut prev) = (0u64, 0u64);
    let mut step = |player: &mut Player<_>, cpu: &mut Vec<u64>, gpu: &mut Vec<u64>| {
        k += 1;
        let t = frame_at(k);
        let frame = player.plan(t - prev);
        prev = t;
        let c0 = thread_cpu_ns();
        player.render(&frame);
        cpu.push(thread_cpu_ns() - c0);
        let g0 = Instant::now();
        player.wait_for_gpu();
        gpu.push(g0.elapsed().as_nanos() as u64);
    };
    let (mut cpu, mut gpu) = (Vec::new(), Vec::new());
    for _ in 0..per_loop {
        step(&mut player, &mut cpu, &mut gpu);
    }
    let before = player.totals().clone();
    let (mut cpu, mut gpu) = (Vec::new(), Vec::new());
    for _ in 0..per_loop {
        step(&mut player, &mut cpu, &mut gpu);
    }
    let after = player.totals().clone();
    let mean = |v: &[u64]| v.iter().sum::<u64>() as f64 / v.len().max(1) as f64;
    let cost = Cost {
        size: h.width,
        texels: h.width as u64 * h.height as u64,
        file_bytes,
        gpu_bytes: player.gpu_bytes(),
        peak_rss: peak_rss()?,
        loop_read: after.bytes_read - before.bytes_read,
        loop_uploaded: after.bytes_uploaded - before.bytes_uploaded,
        loop_decode_ns: after.decode_ns - before.decode_ns,
        loop_read_ns: after.read_ns - before.read_ns,
        loop_media_ns: loop_ns,
        render_cpu_ns: mean(&cpu),
        gpu_ns: mean(&gpu),
        display_hz: a.display_hz,
        adapter: format!("{} ({:?})", info.name, info.backend),
    };
    player
        .stop(std::time::Duration::from_secs(10))
        .map_err(|e| e.to_string())?;
    println!(
        "{}",
        serde_json::to_string(&cost).expect("a cost serialises")
    );
    Ok(())
}

/// The process's peak resident set (VmHWM), bytes.
fn peak_rss() -> Result<u64, String> {
    let status = std::fs::read_to_string("/proc/self/status").map_err(|e| e.to_string())?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map(|kb| kb * 1024)
        .ok_or_else(|| "no VmHWM in /proc/self/status".into())
}

/// The table (stdout), `scale.csv` and the plots.
fn report(a: &BenchScaleArgs, costs: &[Cost]) -> Result<(), String> {
    let base = costs
        .iter()
        .find(|c| c.size as usize == BASELINE)
        .map_or(0, |c| c.peak_rss);
    let rows: Vec<_> = costs
        .iter()
        .filter(|c| c.size as usize != BASELINE)
        .collect();
    let mut csv = String::from(
        "size,texels,file_bytes,gpu_bytes,gpu_bytes_per_texel,peak_rss,peak_above_64_per_texel,loop_read,loop_uploaded,upload_over_read,decoder_core_share,reader_core_share,render_cpu_ms,gpu_ms\n",
    );
    println!(
        "| size | file | GPU resident, B/texel | peak above 64², B/texel | upload / read over a loop | reader + decoder, share of a core | render thread CPU per frame | GPU per frame |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|");
    let per_texel = |b: u64, c: &Cost| b as f64 / c.texels as f64;
    for c in &rows {
        let above = c.peak_rss.saturating_sub(base);
        let ratio = c.loop_uploaded as f64 / c.loop_read.max(1) as f64;
        let share = c.loop_decode_ns as f64 / c.loop_media_ns as f64;
        let read_share = c.loop_read_ns as f64 / c.loop_media_ns as f64;
        println!(
            "| {}² | {:.2} MB | {:.1} | {:.1} | {:.1}× | {:.2}% + {:.2}% | {:.3} ms | {:.1} ms |",
            c.size,
            c.file_bytes as f64 / 1e6,
            per_texel(c.gpu_bytes, c),
            per_texel(above, c),
            ratio,
            read_share * 100.0,
            share * 100.0,
            c.render_cpu_ns * 1e-6,
            c.gpu_ns * 1e-6
        );
        csv += &format!(
            "{},{},{},{},{:.3},{},{:.3},{},{},{:.4},{:.6},{:.6},{:.4},{:.3}\n",
            c.size,
            c.texels,
            c.file_bytes,
            c.gpu_bytes,
            per_texel(c.gpu_bytes, c),
            c.peak_rss,
            per_texel(above, c),
            c.loop_read,
            c.loop_uploaded,
            ratio,
            share,
            read_share,
            c.render_cpu_ns * 1e-6,
            c.gpu_ns * 1e-6
        );
    }
    let mut adapters: Vec<&str> = costs.iter().map(|c| c.adapter.as_str()).collect();
    adapters.dedup();
    println!("\nplayed on: {}", adapters.join(", "));
    write(&a.out.join("scale.csv"), &csv)?;
    let mtexels = |c: &Cost| c.texels as f64 / 1e6;
    let series = |name: &str, f: &dyn Fn(&Cost) -> f64| Series {
        name: name.into(),
        points: rows.iter().map(|c| (mtexels(c), f(c))).collect(),
    };
    // The runtime issue's targets, drawn across the measured range.
    let target = |name: &str, v: f64| Series {
        name: name.into(),
        points: rows.iter().map(|c| (mtexels(c), v)).collect(),
    };
    let plots: [(&str, &str, &str, Vec<Series>); 4] = [
        (
            "scale_memory.png",
            "Memory per texel of the lightmap",
            "bytes per texel",
            vec![
                series("GPU resident (the player's textures and buffers)", &|c| {
                    per_texel(c.gpu_bytes, c)
                }),
                series("process peak above a 64² stream's", &|c| {
                    per_texel(c.peak_rss.saturating_sub(base), c)
                }),
                target("target for the peak at 2048²: 64", 64.0),
                target("the display texture alone: 8", 8.0),
            ],
        ),
        (
            "scale_upload.png",
            "Bytes uploaded to the GPU over a loop, per byte read",
            "upload / read",
            vec![
                series("upload / read", &|c| {
                    c.loop_uploaded as f64 / c.loop_read.max(1) as f64
                }),
                target("target at 2048²: 3", 3.0),
            ],
        ),
        (
            "scale_render.png",
            "Render thread CPU time per displayed frame (record + submit)",
            "milliseconds",
            vec![
                series("render thread CPU", &|c| c.render_cpu_ns * 1e-6),
                target("target at 4096²: 0.25", 0.25),
            ],
        ),
        (
            "scale_gpu.png",
            "GPU execution per displayed frame",
            "milliseconds",
            vec![series("GPU execution", &|c| c.gpu_ns * 1e-6)],
        ),
    ];
    for (file, title, y, s) in plots {
        let x = "texels of the lightmap, millions (log)";
        lines(&a.out.join(file), title, x, y, &s, true)?;
    }
    println!(
        "\n{}: costs.json, scale.csv, scale_memory.png, scale_upload.png, scale_render.png, scale_gpu.png",
        a.out.display()
    );
    Ok(())
}

fn write(path: &Path, text: &str) -> Result<(), String> {
    vbim_bake::write_text(path, text).map_err(|e| e.to_string())
}
