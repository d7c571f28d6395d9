//! `vbim demo`: the whole job on the shipped sample, with nothing to configure.

use std::path::Path;
use std::time::Instant;

use serde_json::json;
use vbim_bake::{bake, BakeOptions, BakeSummary, FrameFormat, Scene};
use vbim_encoder::{encode_file, lossless_baseline, EncoderConfig, FrameSet, FrameSource, Preset};
use vbim_format::package::Package;

use crate::cli::DemoArgs;
use crate::cmd_play::{capture_scene, play, Outcome};
use crate::plot::{lines, Series};
use crate::progress::Stages;
use crate::session::Session;
use crate::units::{parse_rate, Span};

fn write(path: &Path, text: &str) -> Result<(), String> {
    vbim_bake::write_text(path, text).map_err(|e| e.to_string())
}

pub fn run(a: DemoArgs) -> Result<(), String> {
    let t0 = Instant::now();
    let out = a.out.clone();
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let stages = Stages::new();
    let progress = |s: &str, d: u64, t: u64| stages.report(s, d, t);

    // 1. Bake a day.
    let mut scene = Scene::load(&a.scene).map_err(|e| e.to_string())?;
    scene.size = a.size as usize;
    scene.frames = a.frames as usize;
    if let Some(c) = a.clouds {
        scene.clouds.enabled = c;
    }
    let frames_dir = out.join("frames");
    eprintln!(
        "[1/5] baking {} frames of {}² from {}",
        scene.frames,
        scene.size,
        a.scene.display()
    );
    let baked = bake(
        &scene,
        &BakeOptions {
            out: frames_dir.clone(),
            format: FrameFormat::Exr,
            use_cache: true,
        },
        &progress,
    )
    .map_err(|e| e.to_string())?;
    stages.finish();

    // 2. Encode every track (the default preset): the day, or each weather's day and sky
    // (then a package ties them), and measure the lossless baseline of the first day.
    eprintln!("[2/5] encoding");
    let mut cfg = EncoderConfig::preset(Preset::Default);
    cfg.rate = parse_rate(&a.fps)?;
    let (jobs, coded) = tracks_of(&scene.name, &baked, &frames_dir, &out)?;
    let mut tracks = Vec::new();
    for job in &jobs {
        let fs = FrameSet::open(job.input.to_str().ok_or("output path is not UTF-8")?)
            .map_err(|e| e.to_string())?;
        let mut cfg = cfg.clone();
        cfg.metadata = std::fs::read_to_string(job.input.join(vbim_bake::Manifest::FILE_NAME)).ok();
        let mut rep = encode_file(&fs, &cfg, &job.out, &progress).map_err(|e| e.to_string())?;
        rep.verify_file(&fs, &job.out, &progress)
            .map_err(|e| e.to_string())?;
        stages.finish();
        for s in rep.shortfalls() {
            eprintln!("warning: {}: {s}", job.out.display());
        }
        tracks.push((job, fs, rep));
    }
    // The package last: it names only complete tracks.
    let package = match coded {
        Some(p) => {
            let path = out.join(format!("{}.vbimpkg", scene.name));
            write(&path, &p.to_json())?;
            Some(path)
        }
        None => None,
    };
    let (_, fs, rep) = &tracks[0];
    let file = package.clone().unwrap_or_else(|| jobs[0].out.clone());
    rep.write_degree_map(&out.join("degree_map.png"))?;
    let lossless = lossless_baseline(fs, 3, &progress).map_err(|e| e.to_string())?;
    stages.finish();
    let info = fs.info();
    let texel_frames = (info.width * info.height * info.frames) as f64;
    let lossless_bpp = lossless as f64 * 8.0 / texel_frames;

    // 3. Play it headless under a bandwidth cap with stalls, measuring what is shown (the
    // first weather's day).
    eprintln!(
        "[3/5] playing under {} with stalls {}",
        a.bandwidth, a.stall
    );
    let day_s = a.frames as f64 * cfg.rate.1 as f64 / cfg.rate.0 as f64;
    let duration = 2.0 * day_s;
    let play_args = crate::cli::PlayArgs {
        duration: Span::from_secs(duration),
        bandwidth: Some(a.bandwidth),
        stall: Some(a.stall.clone()),
        preroll_margin: a.preroll_margin.clone(),
        check_every: 15,
        frames: a.render_frames,
        ..crate::cli::PlayArgs::headless(&file)
    };
    let mut s = Session::from_args(&play_args)?;
    let (device, queue, adapter) = vbim_player::headless_device().map_err(|e| e.to_string())?;
    let adapter = format!("{} ({:?})", adapter.name, adapter.backend);
    let measured: Outcome = play(&s, &device, &queue, &adapter)?;
    drop((device, queue));

    // 4. The same playback in the terrain scene, captured; with weathers, the last one is
    // asked for at 07:12 of the first day and the first at 01:12 of the second (under the
    // demo's cap each takes 2–4 s of the 10 s day to start: it fades in late morning),
    // each over a fade of a twentieth of a day (at most 1 s).
    eprintln!("[4/5] rendering {} frames of the scene", a.render_frames);
    // The display's clock runs ahead of the day by the pre-roll (the headless run's).
    let preroll_s = measured.preroll_ms * 1e-3;
    if baked.weathers.len() > 1 {
        let (first, last) = (
            &baked.weathers[0].name,
            &baked.weathers[baked.weathers.len() - 1].name,
        );
        let at = |days: f64| ((days * day_s + preroll_s) * 1e9) as u64;
        s.switches = vec![(last.clone(), at(0.3)), (first.clone(), at(1.05))];
        s.fade_ns = (day_s / 20.0).min(1.0).mul_add(1e9, 0.0) as u64;
    }
    let render_dir = out.join("render");
    let cap = capture_scene(
        &s,
        &a.scene,
        &render_dir,
        a.render_frames as usize,
        (960, 540),
        &|d, t| stages.report("render", d, t),
    )?;
    stages.finish();
    std::fs::copy(&cap.preview, out.join("preview.gif")).map_err(|e| e.to_string())?;
    // The still: a quarter past seven in the morning of the first day (long shadows, the
    // first weather's sky).
    let still_s = preroll_s + 0.3 * day_s;
    let still = cap
        .frames
        .get((still_s / duration * cap.frames.len() as f64) as usize)
        .or(cap.frames.first())
        .ok_or("no frame rendered")?;
    std::fs::copy(still, out.join("frame.png")).map_err(|e| e.to_string())?;

    // 5. Plots and the report.
    eprintln!("[5/5] plots and report");
    lines(
        &out.join("rate_distortion.png"),
        "Rate against distortion: vbim and the lossless baseline",
        "bits per texel per frame (log)",
        "mean PSNR, dB (protocol metric; 99 = identical)",
        &[
            Series {
                name: "lossless zstd per frame (half float)".into(),
                points: vec![(lossless_bpp, 99.0)],
            },
            Series {
                name: format!("vbim, --tolerance {}", cfg.tolerance_db),
                points: vec![(rep.bpp, rep.mean_psnr().unwrap_or(0.0))],
            },
        ],
        true,
    )?;
    let drift: Vec<(f64, f64)> = measured
        .records
        .iter()
        .map(|r| (r.clock_ns as f64 * 1e-9, r.drift))
        .collect();
    lines(
        &out.join("drift.png"),
        &format!(
            "Drift while playing at {} with stalls {}",
            a.bandwidth, a.stall
        ),
        "playback time, s",
        "drift, media frames",
        &[Series {
            name: "target − shown".into(),
            points: drift,
        }],
        false,
    )?;
    let report = json!({
        "scene": a.scene, "size": a.size, "frames": a.frames, "fps": a.fps,
        "bake": { "precompute_s": baked.precompute_s, "lighting_s": baked.lighting_s, "writing_s": baked.writing_s },
        "encode": rep,
        "tracks": tracks.iter().map(|(j, _, r)| json!({
            "weather": j.weather, "kind": j.kind, "file": j.out, "width": r.width, "height": r.height,
            "bytes": r.bytes, "mean_psnr": r.mean_psnr(), "worst_psnr": r.worst_psnr(),
        })).collect::<Vec<_>>(),
        "package": package,
        "switches": cap.switches,
        "lossless": { "bytes": lossless, "bpp": lossless_bpp },
        "playback": measured,
        "render": { "frames": cap.frames.len(), "dir": render_dir, "preview": out.join("preview.gif") },
        "total_s": t0.elapsed().as_secs_f64(),
    });
    write(
        &out.join("report.json"),
        &serde_json::to_string_pretty(&report).unwrap(),
    )?;
    let verdict = drift_verdict(measured.late_frames, measured.max_drift, measured.stalls);
    let md = format!(
        "# vbim demo report\n\n\
         Scene `{}`, {}² lightmaps, {} frames per day, played at {} fps.\n\n\
         ![preview](preview.gif)\n\n\
         ## Encode\n\n\
         | | bytes | bpp | ratio to raw | mean PSNR | worst frame | encode time |\n|---|---:|---:|---:|---:|---:|---:|\n\
         | vbim (default preset, --tolerance {}) | {} | {:.4} | {:.1}× | {:.2} dB | {:.2} dB | {:.1} s |\n\
         | lossless zstd per frame (half float) | {} | {:.4} | {:.1}× | identical | identical | |\n\n\
         ![rate–distortion](rate_distortion.png)\n\n\
         Degree of every 16² tile in every segment (dark blue 1 … yellow {}): ![degrees](degree_map.png)\n\n\
         ## Playback\n\n\
         Reader capped at {} ({:.1} kB/s; the stream's mean is {:.1} kB/s) with stalls {}, policy interpolate, \
         ring {} bytes, pre-roll {:.0} ms (the header's and a {} margin), 60 Hz display, {:.0} s simulated on {}.\n\n\
         | mean drift | p99 drift | max drift | frames late by > 1 | stalls | shown vs true (mean PSNR) | worst checked |\n|---:|---:|---:|---:|---:|---:|---:|\n\
         | {:.3} | {:.3} | {:.3} | {} | {} | {} | {} |\n\n\
         {}\n\n\
         ![drift](drift.png)\n\n\
         Rendered frames: `render/` ({} PNG); a still: ![frame](frame.png)\n\n\
         {}\
         Total time {:.1} s.\n",
        a.scene.display(), a.size, a.frames, a.fps,
        cfg.tolerance_db, rep.bytes, rep.bpp, rep.ratio_to_raw, rep.mean_psnr().unwrap_or(0.0), rep.worst_psnr().unwrap_or(0.0), rep.encode_s,
        lossless, lossless_bpp, texel_frames * 6.0 / lossless as f64, cfg.max_degree,
        a.bandwidth, measured.read_rate.unwrap_or(0) as f64 / 1e3, measured.mean_rate / 1e3, a.stall, measured.ring_bytes, measured.preroll_ms, a.preroll_margin, duration, measured.adapter,
        measured.mean_drift, measured.p99_drift, measured.max_drift, measured.late_frames, measured.stalls,
        measured.shown_mean_psnr.map_or("–".into(), |v| format!("{v:.2} dB")),
        measured.shown_worst_psnr.map_or("–".into(), |v| format!("{v:.2} dB")),
        verdict,
        cap.frames.len(), weathers_md(&tracks, &cap.switches, s.fade_ns), t0.elapsed().as_secs_f64(),
    );
    write(&out.join("report.md"), &md)?;
    println!("demo finished in {:.1} s", t0.elapsed().as_secs_f64());
    if let Some(p) = &package {
        println!(
            "  {}: {} weathers, each a lightmap, a sky and an irradiance track",
            p.display(),
            baked.weathers.len()
        );
    }
    for (j, _, r) in &tracks {
        println!(
            "  {}: {} bytes, {:.4} bpp, mean PSNR {:.2} dB",
            j.out.display(),
            r.bytes,
            r.bpp,
            r.mean_psnr().unwrap_or(0.0)
        );
    }
    for sw in &cap.switches {
        println!(
            "  weather:  to {} at {:.2} s, its fade began {:.0} ms later",
            sw.to, sw.asked_s, sw.fade_started_after_ms
        );
    }
    println!(
        "  playback: mean drift {:.3}, max {:.3} frames, {} stalls",
        measured.mean_drift, measured.max_drift, measured.stalls
    );
    println!("            {verdict}");
    println!("  report:   {}", out.join("report.md").display());
    println!("  preview:  {}", out.join("preview.gif").display());
    println!(
        "  frames:   {} (baked), {} (rendered)",
        frames_dir.display(),
        render_dir.display()
    );
    println!(
        "  plots:    {}, {}",
        out.join("rate_distortion.png").display(),
        out.join("drift.png").display()
    );
    Ok(())
}

/// One track the demo encodes.
struct TrackJob {
    weather: Option<String>,
    kind: &'static str,
    input: std::path::PathBuf,
    out: std::path::PathBuf,
}

/// The tracks of a bake: its one day, or each weather's day and sky, named as
/// [`Package::coded_as`] names them (with the package that ties them).
fn tracks_of(
    name: &str,
    baked: &BakeSummary,
    frames: &Path,
    out: &Path,
) -> Result<(Vec<TrackJob>, Option<Package>), String> {
    let Some(path) = &baked.package else {
        let day = TrackJob {
            weather: None,
            kind: "lightmap",
            input: frames.to_path_buf(),
            out: out.join(format!("{name}.vbim")),
        };
        return Ok((vec![day], None));
    };
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let baked = Package::parse(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    let coded = baked.coded_as(name);
    let mut jobs = Vec::new();
    for (w, c) in baked.weathers.iter().zip(&coded.weathers) {
        for ((kind, input), (_, file)) in w.tracks().zip(c.tracks()) {
            jobs.push(TrackJob {
                weather: Some(w.name.clone()),
                kind,
                input: frames.join(input),
                out: out.join(file),
            });
        }
    }
    Ok((jobs, Some(coded)))
}

/// The report's section on weathers: every track's size and error, and each switch.
fn weathers_md(
    tracks: &[(&TrackJob, FrameSet, vbim_encoder::EncodeReport)],
    switches: &[crate::cmd_play::SwitchTiming],
    fade_ns: u64,
) -> String {
    if tracks.len() < 2 {
        return String::new();
    }
    let mut md = String::from(
        "## Weathers\n\nEach weather is a lightmap track, a sky track (a 128 × 32 map of the \
         upper hemisphere) and an irradiance track (light for objects: a grid of cells in 10 \
         layers) on one timeline, tied by the package file.\n\n\
         | weather | track | size | bytes | mean PSNR | worst frame |\n|---|---|---|---:|---:|---:|\n",
    );
    for (j, _, r) in tracks {
        md += &format!(
            "| {} | {} | {}×{} | {} | {:.2} dB | {:.2} dB |\n",
            j.weather.as_deref().unwrap_or(""),
            j.kind,
            r.width,
            r.height,
            r.bytes,
            r.mean_psnr().unwrap_or(0.0),
            r.worst_psnr().unwrap_or(0.0)
        );
    }
    md += "\n";
    for sw in switches {
        md += &format!(
            "- At {:.2} s the scene switched to **{}**: the new weather's tracks showed the \
             shown time {:.0} ms later, then lightmap and sky cross-faded over {:.2} s.\n",
            sw.asked_s,
            sw.to,
            sw.fade_started_after_ms,
            fade_ns as f64 * 1e-9
        );
    }
    md + "\n"
}

/// What the drift plot shows, in words: a plot that stays at zero is a result, not a
/// broken plot, and says where to see a stream that falls behind.
fn drift_verdict(late: usize, max_drift: f64, stalls: usize) -> String {
    if late == 0 && max_drift <= 1.0 {
        format!(
            "No frame was late: the ring absorbed every reader stall (largest drift {max_drift:.2} \
             media frames, {stalls} held stretches), so the drift plot (drift.png) stays at zero. \
             `vbim bench drift` plays the same stream under tighter caps and longer stalls, \
             where the display holds and catches up."
        )
    } else {
        format!(
            "{late} frames were late by more than one media frame (largest drift \
             {max_drift:.2}); the plot shows where the display held and caught up."
        )
    }
}
