//! The offline tools' benchmarks: the baker's stages, the lossless baseline, and the plots
//! of the benchmark scripts' CSVs.

use std::time::Instant;

use rayon::prelude::*;
use vbim_bake::{light_frame, load_terrain, write_frame, FrameFormat, Precomputed, Scene};

use super::stats;
use super::{BenchBakeArgs, BenchLosslessArgs, BenchPlotArgs};

pub(super) fn bench_bake(a: BenchBakeArgs) -> Result<(), String> {
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
                light_frame(&pre, &scene, i, buf);
            },
        );
        light_t.push(t.elapsed().as_secs_f64());
    }
    // Writing: 24 frames of the day as EXR, timed alone.
    let mut buf = vec![0f32; texels * 3];
    light_frame(&pre, &scene, scene.frames / 2, &mut buf);
    for _ in 0..a.runs.max(1) {
        let t = Instant::now();
        for i in 0..24 {
            write_frame(
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

pub(super) fn bench_lossless(a: BenchLosslessArgs) -> Result<(), String> {
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

pub(super) fn plot_rd(a: BenchPlotArgs) -> Result<(), String> {
    let mut series = csv_series(&a.csv, 5, |f, line| {
        let bpp = f[3].parse().map_err(|_| format!("bad bpp in {line}"))?;
        let psnr = f[4].parse().map_err(|_| format!("bad PSNR in {line}"))?;
        Ok((f[0].to_string(), (bpp, psnr)))
    })?;
    // Lossless points (99 dB) would squash the axis: named in the title instead.
    let mut title = a.title_or("Rate against distortion");
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

pub(super) fn plot_tolerance(a: BenchPlotArgs) -> Result<(), String> {
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
        &a.title_or("Mean PSNR delivered against the tolerance asked"),
        "tolerance asked, dB",
        "mean PSNR delivered − asked, dB (protocol metric)",
        &series,
        false,
    )?;
    println!("wrote {}", a.out.display());
    Ok(())
}

pub(super) fn plot_reuse(a: BenchPlotArgs) -> Result<(), String> {
    // Points in the order of the CSV (share by share), not sorted by time: the line then
    // follows the knob.
    let text = std::fs::read_to_string(&a.csv).map_err(|e| format!("{}: {e}", a.csv.display()))?;
    let mut series: Vec<crate::plot::Series> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() < 9 {
            continue;
        }
        let num = |i: usize| -> Result<f64, String> {
            f[i].parse()
                .map_err(|_| format!("bad number in column {} of {line}", i + 1))
        };
        let name = match f[0] {
            "1" => "the file's rate".to_string(),
            n => format!("{n}× slower"),
        };
        let p = (num(5)?, num(7)?);
        match series.iter_mut().find(|s| s.name == name) {
            Some(s) => s.points.push(p),
            None => series.push(crate::plot::Series {
                name,
                points: vec![p],
            }),
        }
    }
    if series.is_empty() {
        return Err(format!("{}: no rows", a.csv.display()));
    }
    crate::plot::lines(
        &a.out,
        &a.title_or("The runtime's GPU time against the error shown"),
        "GPU time per displayed frame ÷ the reference blend's (same run)",
        "mean PSNR of the shown frames against the true state, dB",
        &series,
        false,
    )?;
    println!("wrote {}", a.out.display());
    Ok(())
}

pub(super) fn plot_size(a: BenchPlotArgs) -> Result<(), String> {
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
        &a.title_or("Peak resident memory against size"),
        "texels per frame (log)",
        "peak resident memory, GB",
        &series,
        true,
    )?;
    println!("wrote {}", a.out.display());
    Ok(())
}
