//! `vbim bench …`: timings reported as the median of several runs with their spread
//! (docs/CONVENTIONS.md, "Units, flags and exit codes").

use std::time::Instant;

use vbim_player::thread_cpu_ns;

use rayon::prelude::*;
use vbim_bake::{light, load_terrain, output, FrameFormat, Precomputed, Scene};

use crate::cli::{BenchBakeArgs, BenchCommand};

pub fn run(c: BenchCommand) -> Result<(), String> {
    match c {
        BenchCommand::Bake(a) => bench_bake(a),
        BenchCommand::Decode(a) => bench_decode(a),
        BenchCommand::Lossless(a) => bench_lossless(a),
        BenchCommand::PlotRd(a) => plot_rd(a),
        BenchCommand::PlotTolerance(a) => plot_tolerance(a),
        BenchCommand::PlotSize(a) => plot_size(a),
        BenchCommand::Drift(a) => bench_drift(a),
        BenchCommand::Render(a) => bench_render(a),
        BenchCommand::Scale(a) => crate::bench_scale::run(a),
        BenchCommand::ScaleOne(a) => crate::bench_scale::run_one(a),
        BenchCommand::Changes(a) => crate::bench_changes::run(a),
        BenchCommand::Entropy(a) => crate::bench_entropy::run(a),
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
    scene.size = a.size as usize;
    scene.frames = a.frames as usize;
    scene.clouds.enabled = a.clouds;
    scene.validate()?;
    let hf = load_terrain(&scene).map_err(|e| e.to_string())?;
    let texels = scene.size * scene.size;
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
                scene.size,
                scene.size,
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
    use vbim_player::bench::{DecoderCore, Event, SegmentData};
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
        // The player's decoder: every chunk in playback order, every segment filled for
        // the GPU (scanned streams; the GPU does the rest).
        let t = Instant::now();
        let mut dec = DecoderCore::new(h.clone(), layout.clone(), entries.clone());
        let mut packed = SegmentData::new();
        for (i, c) in chunks.iter().enumerate() {
            if let Event::Ready(s) = dec.take(i, Some(c)) {
                dec.fill(s, 0, 0, &mut packed)?;
            }
        }
        full_t.push(t.elapsed().as_secs_f64());
    }
    let gpu = a
        .gpu
        .then(|| gpu_decode(&h, &layout, &entries, &chunks, a.runs))
        .transpose()?;
    let (zm, z0, z1) = stats(&mut zstd_t);
    let (fm, f0, f1) = stats(&mut full_t);
    println!(
        "decode benchmark: {name}, {}×{}, {} frames at {}/{} fps ({duration:.1} s), {} segments, {} runs, block kernel {}",
        h.width, h.height, h.frame_count, h.rate_num, h.rate_den, h.segment_count, a.runs,
        vbim_format::plane::kernel_build()
    );
    println!("zstd alone      median {:.3} s (min {z0:.3}, max {z1:.3}) = {:.2}% of one core in real time", zm, 100.0 * zm / duration);
    println!("full decode     median {:.3} s (min {f0:.3}, max {f1:.3}) = {:.2}% of one core in real time", fm, 100.0 * fm / duration);
    if let Some((adapter, mut times, boxes, passes)) = gpu {
        let (gm, g0, g1) = stats(&mut times);
        println!(
            "GPU decode      median {gm:.3} s (min {g0:.3}, max {g1:.3}) for {boxes} segments, {:.1} ms each, on {adapter}",
            1e3 * gm / boxes.max(1) as f64
        );
        if passes.is_empty() {
            println!(
                "GPU time by pass: not measured (the adapter has no timestamps inside passes)"
            );
        } else {
            let total: f64 = passes.iter().map(|p| p.1).sum();
            println!(
                "GPU time by pass, per segment (timestamps, mean over runs): {:.2} ms in all",
                total / 1e6
            );
            for (label, ns) in passes {
                println!(
                    "  {label:<24} {:>9.3} ms  {:>5.1}%",
                    ns / 1e6,
                    100.0 * ns / total.max(1.0)
                );
            }
        }
    }
    Ok(())
}

/// The adapter, each run's seconds, the number of segments, and the GPU time per segment
/// of each kind of pass (ns; empty where the adapter has no timestamps inside passes).
type GpuTimes = (String, Vec<f64>, usize, Vec<(&'static str, f64)>);

/// The GPU decode of every segment of a stream, `runs` times.
fn gpu_decode(
    h: &vbim_format::Header,
    layout: &vbim_format::index::Layout,
    entries: &[vbim_format::IndexEntry],
    chunks: &[&[u8]],
    runs: usize,
) -> Result<GpuTimes, String> {
    use vbim_player::bench::{timing_device, DecoderCore, Event, GpuDecoder, SegmentData};
    let (device, queue, info) = timing_device()?;
    let adapter = format!("{} ({:?})", info.name, info.backend);
    let mut gpu = GpuDecoder::new(&device, &queue, h);
    let (mut times, mut boxes) = (Vec::new(), 0);
    let mut passes: Vec<(&'static str, f64)> = Vec::new();
    for _ in 0..runs.max(1) {
        let mut dec = DecoderCore::new(h.clone(), layout.clone(), entries.to_vec());
        let mut seg = SegmentData::new();
        let (mut t, mut n) = (0.0, 0);
        for (i, c) in chunks.iter().enumerate() {
            if let Event::Ready(s) = dec.take(i, Some(c)) {
                dec.fill(s, 0, 0, &mut seg)?;
                t += gpu.decode(&seg).as_secs_f64();
                n += 1;
                // Summed per kind of pass, in the order they first came.
                for (label, ns) in gpu.pass_times() {
                    match passes.iter_mut().find(|(l, _)| *l == label) {
                        Some((_, t)) => *t += ns,
                        None => passes.push((label, ns)),
                    }
                }
            }
        }
        times.push(t);
        boxes = n;
    }
    // Per segment, the mean over runs.
    let per = (runs.max(1) * boxes.max(1)) as f64;
    let passes = passes.into_iter().map(|(l, ns)| (l, ns / per)).collect();
    Ok((adapter, times, boxes, passes))
}

fn bench_lossless(a: crate::cli::BenchLosslessArgs) -> Result<(), String> {
    use vbim_encoder::{FrameSet, FrameSource};
    let fs = FrameSet::open(&a.input).map_err(|e| e.to_string())?;
    let info = fs.info();
    let total =
        vbim_encoder::lossless_baseline(&fs, a.level, &|_, _, _| {}).map_err(|e| e.to_string())?;
    let bpp = total as f64 * 8.0 / (info.width * info.height * info.frames) as f64;
    println!(
        "{total} bytes, {bpp:.4} bpp (zstd level {} per frame)",
        a.level
    );
    Ok(())
}

/// The rows of a benchmark CSV (header skipped, rows with fewer than `fields` values
/// ignored) as series: `point` names each row's series and gives its point. Points are
/// sorted by x.
fn csv_series(
    path: &std::path::Path,
    fields: usize,
    point: impl Fn(&[&str], &str) -> Result<(String, (f64, f64)), String>,
) -> Result<Vec<crate::plot::Series>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut series: Vec<crate::plot::Series> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() < fields {
            continue;
        }
        let (name, p) = point(&f, line)?;
        match series.iter_mut().find(|s| s.name == name) {
            Some(s) => s.points.push(p),
            None => series.push(crate::plot::Series {
                name,
                points: vec![p],
            }),
        }
    }
    for s in &mut series {
        s.points.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    Ok(series)
}

/// Adds a horizontal line at `y` across the x range of the series so far (a band or a
/// limit to read the points against).
fn push_level(series: &mut Vec<crate::plot::Series>, name: String, y: f64) {
    let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
    let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
        (l.min(x), h.max(x))
    });
    series.push(crate::plot::Series {
        name,
        points: vec![(lo, y), (hi, y)],
    });
}

fn plot_rd(a: crate::cli::BenchPlotArgs) -> Result<(), String> {
    let mut series = csv_series(&a.csv, 5, |f, line| {
        let bpp = f[3].parse().map_err(|_| format!("bad bpp in {line}"))?;
        let psnr = f[4].parse().map_err(|_| format!("bad PSNR in {line}"))?;
        Ok((f[0].to_string(), (bpp, psnr)))
    })?;
    // Lossless points (99 dB) would squash the axis: named in the title instead.
    let mut title = a.title.clone();
    for s in series
        .iter()
        .filter(|s| s.points.iter().all(|p| p.1 >= 99.0))
    {
        title += &format!(" — {}: {:.2} bpp", s.name, s.points[0].0);
    }
    series.retain(|s| s.points.iter().any(|p| p.1 < 99.0));
    crate::plot::lines(
        &a.out,
        &title,
        "bits per texel per frame (log)",
        "mean PSNR, dB (protocol metric)",
        &series,
        true,
    )?;
    println!("wrote {}", a.out.display());
    Ok(())
}

fn plot_tolerance(a: crate::cli::BenchPlotArgs) -> Result<(), String> {
    let mut series = csv_series(&a.csv, 4, |f, line| {
        let asked: f64 = f[2]
            .parse()
            .map_err(|_| format!("bad tolerance in {line}"))?;
        let got: f64 = f[3].parse().map_err(|_| format!("bad PSNR in {line}"))?;
        Ok((format!("{} ({})", f[0], f[1]), (asked, got - asked)))
    })?;
    if series.is_empty() {
        return Err(format!("{}: no rows", a.csv.display()));
    }
    for (name, d) in [("−0.5 dB", -0.5), ("+0.5 dB", 0.5)] {
        push_level(&mut series, name.into(), d);
    }
    crate::plot::lines(
        &a.out,
        &a.title,
        "tolerance asked, dB",
        "mean PSNR delivered − asked, dB (protocol metric)",
        &series,
        false,
    )?;
    println!("wrote {}", a.out.display());
    Ok(())
}

fn plot_size(a: crate::cli::BenchPlotArgs) -> Result<(), String> {
    let mut series = Vec::new();
    for (column, what) in [(4, "bake"), (6, "encode")] {
        let s = csv_series(&a.csv, 7, |f, line| {
            let size: f64 = f[0].parse().map_err(|_| format!("bad size in {line}"))?;
            let mb: f64 = f[column]
                .parse()
                .map_err(|_| format!("bad peak in {line}"))?;
            let detail = if f[1] == "true" { ", with detail" } else { "" };
            Ok((format!("{what} peak{detail}"), (size * size, mb / 1000.0)))
        })?;
        series.extend(s);
    }
    if series.is_empty() {
        return Err(format!("{}: no rows", a.csv.display()));
    }
    let limit = vbim_encoder::DEFAULT_MEMORY_LIMIT as f64 / 1e9;
    push_level(
        &mut series,
        format!("the encoder's default --memory-limit, {limit} GB"),
        limit,
    );
    crate::plot::lines(
        &a.out,
        &a.title,
        "texels per frame (log)",
        "peak resident memory, GB",
        &series,
        true,
    )?;
    println!("wrote {}", a.out.display());
    Ok(())
}

fn bench_drift(a: crate::cli::BenchDriftArgs) -> Result<(), String> {
    use crate::cmd_play::play;
    use crate::session::Session;
    use crate::units::Bandwidth;
    use vbim_player::Policy;
    if a.phases == 0 {
        return Err("--phases must be at least 1".into());
    }
    std::fs::create_dir_all(&a.out).map_err(|e| format!("{}: {e}", a.out.display()))?;
    let (device, queue, info) = vbim_player::headless_device()?;
    let adapter = format!("{} ({:?})", info.name, info.backend);
    let mut csv = String::from("policy,factor,first_stall_s,read_rate,ring_bytes,mean_drift,p99_drift,max_drift,late_frames,stalls,shown_mean_psnr,shown_worst_psnr\n");
    let mut drift_series = Vec::new();
    let mut psnr_series = Vec::new();
    for policy in Policy::ALL {
        let name = policy.name();
        let (mut dp, mut pp) = (Vec::new(), Vec::new());
        for &f in &a.factors {
            let args = crate::cli::PlayArgs {
                duration: a.duration.clone(),
                bandwidth: Some(Bandwidth::TimesMean(f)),
                stall: Some(a.stall.clone()),
                policy,
                preroll_margin: a.preroll_margin.clone(),
                check_every: a.check_every,
                ..crate::cli::PlayArgs::headless(&a.file)
            };
            let base = Session::from_args(&args)?;
            // The worst phase: the largest mean drift, the lowest shown PSNR.
            let (mut worst_drift, mut worst_psnr) = (f64::MIN, f64::MAX);
            for k in 0..a.phases as u64 {
                let mut s = base.clone();
                if let Some(st) = s.throttle.stall.as_mut() {
                    st.first_ns += k * st.every_ns / a.phases as u64;
                    if st.first_ns > st.every_ns {
                        st.first_ns -= st.every_ns;
                    }
                }
                let first = s.throttle.stall.map_or(0.0, |st| st.first_ns as f64 * 1e-9);
                let o = play(&s, &device, &queue, &adapter)?;
                eprintln!(
                    "{name:>11} {f:>5}×, first stall at {first:.2} s: mean drift {:.3}, max {:.3}, late {}, shown {:.2} dB",
                    o.mean_drift,
                    o.max_drift,
                    o.late_frames,
                    o.shown_mean_psnr.unwrap_or(99.0)
                );
                csv += &format!(
                    "{name},{f},{first:.3},{},{},{:.4},{:.4},{:.4},{},{},{:.3},{:.3}\n",
                    o.read_rate.unwrap_or(0),
                    o.ring_bytes,
                    o.mean_drift,
                    o.p99_drift,
                    o.max_drift,
                    o.late_frames,
                    o.stalls,
                    o.shown_mean_psnr.unwrap_or(99.0),
                    o.shown_worst_psnr.unwrap_or(99.0)
                );
                worst_drift = worst_drift.max(o.mean_drift);
                worst_psnr = worst_psnr.min(o.shown_mean_psnr.unwrap_or(99.0));
            }
            dp.push((f, worst_drift));
            pp.push((f, worst_psnr));
        }
        drift_series.push(crate::plot::Series {
            name: name.into(),
            points: dp,
        });
        psnr_series.push(crate::plot::Series {
            name: name.into(),
            points: pp,
        });
    }
    let phases = if a.phases > 1 {
        format!(", worst of {} phases", a.phases)
    } else {
        String::new()
    };
    std::fs::write(a.out.join("drift.csv"), &csv).map_err(|e| e.to_string())?;
    // The file's name, not its path: a long path pushed the title off the image.
    let name = a.file.file_name().map_or_else(
        || a.file.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    crate::plot::lines(
        &a.out.join("drift.png"),
        &format!(
            "Mean drift against bandwidth, stalls {}{phases} ({name})",
            a.stall
        ),
        "read rate / stream mean rate",
        "mean drift, media frames",
        &drift_series,
        false,
    )?;
    crate::plot::lines(
        &a.out.join("shown_error.png"),
        &format!(
            "What was shown against the true state, stalls {}{phases}",
            a.stall
        ),
        "read rate / stream mean rate",
        "mean PSNR of shown frames, dB",
        &psnr_series,
        false,
    )?;
    print!("{csv}");
    println!(
        "wrote {}/drift.csv, drift.png, shown_error.png",
        a.out.display()
    );
    Ok(())
}

fn bench_render(a: crate::cli::BenchRenderArgs) -> Result<(), String> {
    use vbim_player::{Player, PlayerConfig};
    let name = a.file.display().to_string();
    let (device, queue, info) = vbim_player::headless_device()?;
    let summary = |v: &mut Vec<f64>| {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        v.sort_by(f64::total_cmp);
        [mean, v[((v.len() - 1) as f64 * 0.99) as usize]]
    };
    // Per run: [cpu mean, cpu p99, wall mean, wall p99, plan mean, plan p99, gpu mean, gpu p99].
    let mut runs: Vec<[f64; 8]> = Vec::new();
    let mut h = None;
    for _ in 0..a.runs.max(1) {
        let f = crate::sequence::open_input(&a.file)?;
        let mut player = Player::open(
            &device,
            &queue,
            std::io::BufReader::new(f),
            PlayerConfig::default(),
        )
        .map_err(|e| e.to_string())?;
        h = Some(player.header().clone());
        let (mut cpu, mut wall_t, mut plan_t, mut gpu) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let start = Instant::now();
        let mut prev = 0u64;
        let warm = 60;
        for k in 1..=a.frames + warm {
            let t = k * 1_000_000_000 / 60;
            let wall = start.elapsed().as_nanos() as u64;
            if t > wall {
                std::thread::sleep(std::time::Duration::from_nanos(t - wall));
            }
            let (c0, t0) = (thread_cpu_ns(), Instant::now());
            let frame = player.plan(t - prev);
            let t1 = Instant::now();
            player.render(&frame);
            let (c2, t2) = (thread_cpu_ns(), Instant::now());
            player.wait_for_gpu();
            let t3 = Instant::now();
            prev = t;
            if k > warm {
                plan_t.push((t1 - t0).as_secs_f64() * 1e3);
                cpu.push((c2 - c0) as f64 * 1e-6);
                wall_t.push((t2 - t0).as_secs_f64() * 1e3);
                gpu.push((t3 - t2).as_secs_f64() * 1e3);
            }
        }
        player
            .stop(std::time::Duration::from_secs(10))
            .map_err(|e| e.to_string())?;
        let [cm, cp] = summary(&mut cpu);
        let [wm, wp] = summary(&mut wall_t);
        let [pm, pp] = summary(&mut plan_t);
        let [gm, gp] = summary(&mut gpu);
        runs.push([cm, cp, wm, wp, pm, pp, gm, gp]);
    }
    let h = h.expect("at least one run");
    // Median over runs of each figure, with the smallest and largest.
    let stat = |i: usize| stats(&mut runs.iter().map(|r| r[i]).collect::<Vec<_>>());
    let line = |label: &str, i: usize, digits: usize| {
        let ((m, m0, m1), (p, p0, p1)) = (stat(i), stat(i + 1));
        println!(
            "{label:<50} mean {m:.digits$} ms ({m0:.digits$}–{m1:.digits$}), p99 {p:.digits$} ms ({p0:.digits$}–{p1:.digits$})"
        );
    };
    println!(
        "render benchmark: {name}, {}×{} at {}/{} fps, 60 Hz, {} frames × {} runs on {} ({:?}); median over runs (min–max)",
        h.width, h.height, h.rate_num, h.rate_den, a.frames, runs.len(), info.name, info.backend
    );
    line(
        "render thread CPU time, advance = plan + record + submit",
        0,
        3,
    );
    line(
        "  the same, wall clock (preemption and waits included)",
        2,
        3,
    );
    line("  of which plan (the player's own logic, wall clock)", 4, 4);
    line("GPU execution (waited for apart, not targeted)", 6, 3);
    Ok(())
}
