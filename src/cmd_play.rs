//! `vbim play FILE --headless …`: plays a stream through the GPU player and reports how
//! bandwidth turned into drift, and how far what was shown is from the true state.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;
use std::time::{Duration, Instant};

use serde::Serialize;
use vbim_format::curve::linear_to_srgb;
use vbim_format::decode::Output;
use vbim_format::metrics::{Metric, SequenceError};
use vbim_player::{frames_csv, Summary};
use vbim_player::{headless_device, FrameRecord, Player};

use crate::cli::PlayArgs;
use crate::session::{mean_rate, scene_mesh, Session};

/// What a session measured.
#[derive(Serialize, Clone, Debug)]
pub struct Outcome {
    pub adapter: String,
    pub policy: String,
    pub read_rate: Option<u64>,
    pub mean_rate: f64,
    pub ring_bytes: usize,
    /// GPU memory the player holds, bytes (`Player::gpu_bytes`).
    pub gpu_bytes: u64,
    /// Buffering before the first frame (the header's pre-roll and the margin), ms.
    pub preroll_ms: f64,
    pub frames: usize,
    pub mean_drift: f64,
    pub p99_drift: f64,
    pub max_drift: f64,
    pub late_frames: usize,
    pub stalls: usize,
    pub bytes_read_per_s: f64,
    pub bytes_uploaded_per_s: f64,
    pub mean_render_ms: f64,
    pub p99_render_ms: f64,
    pub decode_core_share: f64,
    /// Reader CPU time per second of playback (share of one core).
    #[serde(default)]
    pub read_core_share: f64,
    /// PSNR of what was shown against the true state at the target time (protocol metric).
    pub shown_mean_psnr: Option<f64>,
    pub shown_worst_psnr: Option<f64>,
    pub damaged_chunks: u64,
    /// The most segment-decode work one frame recorded, blocks.
    pub decode_work_max: u64,
    /// Frames that found a segment due before the decode budget let it finish.
    pub budget_late: u64,
    /// Frames over the budget because one step of a decode costs more than it.
    pub over_budget: u64,
    pub last_error: Option<String>,
    #[serde(skip)]
    pub records: Vec<FrameRecord>,
}

pub fn play(
    s: &Session,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    adapter: &str,
) -> Result<Outcome, String> {
    let name = s.file.display().to_string();
    let mut player = s.open_player(device, queue, s.realtime)?;
    let h = player.header().clone();
    if s.start > 0 {
        player.set_time(s.start_ns(&h)?);
    }
    let mut reference = s.reference()?;
    let metric = if s.check_every > 0 {
        Some(s.metric()?)
    } else {
        None
    };
    let frames = s.display_frames();
    let mut records = Vec::with_capacity(frames.min(RESERVED_RECORDS) as usize);
    let mut err = SequenceError::default();
    let mut truth = vec![0f32; h.texel_count() * h.channels as usize];
    let (n, ch) = (h.frame_count as f64, h.channels as usize);
    let start = Instant::now();
    let mut prev_t = 0u64;
    for k in 1..=frames {
        // Exact integer ticks per display frame: t_k = ⌊k · 10⁹ / hz⌋, no accumulated error.
        let t = k * 1_000_000_000 / s.display_hz as u64;
        if s.realtime {
            let wall = start.elapsed().as_nanos() as u64;
            if t > wall {
                std::thread::sleep(Duration::from_nanos(t - wall));
            }
        }
        let r = player.advance((t - prev_t) / s.slow);
        prev_t = t;
        if let Some(m) = metric {
            if r.index % s.check_every == 0 && r.state != vbim_player::FrameState::Waiting {
                let target = if h.looping {
                    r.target % n
                } else {
                    r.target.min(n - 1.0)
                };
                reference
                    .frame(target, Output::Linear, &mut truth)
                    .map_err(|e| format!("{name}: {e}"))?;
                let shown = player.read_display();
                let mut a = Vec::with_capacity(truth.len());
                let mut b = Vec::with_capacity(truth.len());
                for i in 0..h.texel_count() {
                    for c in 0..ch {
                        let (x, y) = (truth[i * ch + c], shown[i * 4 + c]);
                        if m == Metric::Srgb8 {
                            a.push(linear_to_srgb(x));
                            b.push(linear_to_srgb(y));
                        } else {
                            a.push(x);
                            b.push(y);
                        }
                    }
                }
                err.push(m.compare(&a, &b));
            }
        }
        records.push(r);
    }
    finish(player, s, adapter, records, &err)
}

/// Frame records reserved up front: a long session grows its record buffer as it plays,
/// never by a size an argument alone asks for.
const RESERVED_RECORDS: u64 = 1 << 20;

/// What the summary needs from the player at the end of a session.
struct Ended {
    totals: vbim_player::Totals,
    ring: usize,
    gpu_bytes: u64,
    preroll_ns: u64,
    header: vbim_format::Header,
}

impl Ended {
    fn of<R: std::io::Read + std::io::Seek + Send + 'static>(p: &Player<R>) -> Ended {
        Ended {
            totals: p.totals().clone(),
            ring: p.ring_bytes(),
            gpu_bytes: p.gpu_bytes(),
            preroll_ns: p.preroll_ns(),
            header: p.header().clone(),
        }
    }
}

/// Stops the player and summarises the session.
fn finish(
    mut player: Player<BufReader<File>>,
    s: &Session,
    adapter: &str,
    records: Vec<FrameRecord>,
    err: &SequenceError,
) -> Result<Outcome, String> {
    let ended = Ended::of(&player);
    player
        .stop(Duration::from_secs(10))
        .map_err(|e| e.to_string())?;
    summarise(ended, s, adapter, records, err)
}

/// The session's summary from what the player said at its end.
fn summarise(
    ended: Ended,
    s: &Session,
    adapter: &str,
    records: Vec<FrameRecord>,
    err: &SequenceError,
) -> Result<Outcome, String> {
    let Ended {
        totals,
        ring,
        gpu_bytes,
        preroll_ns: player_preroll_ns,
        header: h,
    } = ended;
    let preroll_ms = player_preroll_ns as f64 / 1e6;
    let sum = Summary::of(&records);
    // A stream that shows nothing while nothing holds its data back is broken in a way the
    // checks before did not see (it used to end "played N frames", exit 0, having shown
    // none). Under a bandwidth cap, showing nothing is a result.
    let shown = records.iter().any(|r| {
        matches!(
            r.state,
            vbim_player::FrameState::Exact | vbim_player::FrameState::CatchingUp
        )
    });
    if !shown && s.throttle.rate.is_none() && s.duration_ns > player_preroll_ns {
        let why = totals
            .last_error
            .clone()
            .unwrap_or_else(|| "no segment of it could be decoded".into());
        return Err(format!(
            "{}: no frame was shown in {:.1} s of playback: {why}",
            s.file.display(),
            s.duration_ns as f64 * 1e-9
        ));
    }
    Ok(Outcome {
        adapter: adapter.to_string(),
        policy: s.policy.name().into(),
        read_rate: s.throttle.rate,
        mean_rate: mean_rate(&h),
        ring_bytes: ring,
        gpu_bytes,
        preroll_ms,
        frames: sum.frames,
        mean_drift: sum.mean_drift,
        p99_drift: sum.p99_drift,
        max_drift: sum.max_drift,
        late_frames: sum.late_frames,
        stalls: sum.stalls,
        bytes_read_per_s: sum.bytes_read_per_s,
        bytes_uploaded_per_s: sum.bytes_uploaded_per_s,
        mean_render_ms: sum.mean_render_ms,
        p99_render_ms: sum.p99_render_ms,
        decode_core_share: sum.decode_core_share,
        read_core_share: sum.read_core_share,
        shown_mean_psnr: (!err.frames.is_empty()).then(|| err.mean_psnr()),
        shown_worst_psnr: (!err.frames.is_empty()).then(|| err.worst().1),
        damaged_chunks: totals.damaged,
        decode_work_max: totals.decode_work_max,
        budget_late: totals.budget_late,
        over_budget: totals.over_budget,
        last_error: totals.last_error,
        records,
    })
}

/// Builds the session from the command line.
pub fn print(o: &Outcome, s: &Session) {
    let fmt_rate = |r: f64| format!("{:.1} kB/s", r / 1e3);
    println!(
        "played {} frames ({:.1} s at {} Hz, {} time) on {}, policy {}",
        o.frames,
        s.duration_ns as f64 * 1e-9,
        s.display_hz,
        if s.realtime { "real" } else { "simulated" },
        o.adapter,
        o.policy
    );
    println!(
        "read        {} (cap {}, stream mean {}), ring {} bytes, pre-roll {:.0} ms",
        fmt_rate(o.bytes_read_per_s),
        o.read_rate
            .map_or("none".to_string(), |r| fmt_rate(r as f64)),
        fmt_rate(o.mean_rate),
        o.ring_bytes,
        o.preroll_ms
    );
    println!(
        "uploaded    {:.2} MB/s; GPU memory {:.1} MB",
        o.bytes_uploaded_per_s / 1e6,
        o.gpu_bytes as f64 / 1e6
    );
    println!(
        "decode      at most {} blocks in one frame (budget {}); {} frames late for the budget, {} over it (one step larger than the budget)",
        o.decode_work_max,
        s.decode_budget
            .map_or("spread".to_string(), |b| b.to_string()),
        o.budget_late,
        o.over_budget
    );
    println!(
        "drift       mean {:.3}, p99 {:.3}, max {:.3} media frames; {} frames late by > 1; {} stalls",
        o.mean_drift, o.p99_drift, o.max_drift, o.late_frames, o.stalls
    );
    // Wall clock of `advance`: in real time that is the render thread's work; in simulated
    // time the reader and decoder run inside `advance` and the GPU is waited for, so it is
    // not the render thread's cost (`vbim bench render` measures that).
    println!(
        "advance     {:.3} ms mean, {:.3} ms p99 per frame, wall clock ({}); reader {:.2}% + decoder {:.2}% of a core",
        o.mean_render_ms,
        o.p99_render_ms,
        if s.realtime {
            "render thread"
        } else {
            "simulated time: includes reading, decoding and GPU waits"
        },
        o.read_core_share * 100.0,
        o.decode_core_share * 100.0,
    );
    if let (Some(m), Some(w)) = (o.shown_mean_psnr, o.shown_worst_psnr) {
        println!(
            "shown       {m:.2} dB mean PSNR against the true state, worst checked frame {w:.2} dB"
        );
    }
    if o.damaged_chunks > 0 {
        println!(
            "damaged     {} chunk(s); last: {}",
            o.damaged_chunks,
            o.last_error.as_deref().unwrap_or("")
        );
    }
}

pub fn run(a: PlayArgs) -> Result<(), String> {
    let s = Session::from_args(&a)?;
    if let Some(scene) = &a.scene {
        if !a.headless {
            return crate::window::run(&s, scene, (a.width, a.height), a.exit_after);
        }
        let out = a
            .out
            .clone()
            .ok_or("--scene --headless needs --out DIR for the frames")?;
        let stages = crate::progress::Stages::new();
        let c = capture_scene(
            &s,
            scene,
            &out,
            a.frames as usize,
            (a.width, a.height),
            &|d, t| stages.report("render", d, t),
        )?;
        stages.finish();
        print(&c.outcome, &s);
        if !c.switches.is_empty() {
            println!(
                "tracks      GPU memory {:.1} MB, {:.1} MB at most during a switch",
                c.gpu_bytes.0 as f64 / 1e6,
                c.gpu_bytes.1 as f64 / 1e6
            );
        }
        for sw in &c.switches {
            println!(
                "weather     to {} at {:.2} s: its tracks showed the shown time {:.0} ms later, then a {:.2} s fade",
                sw.to,
                sw.asked_s,
                sw.fade_started_after_ms,
                s.fade_ns as f64 * 1e-9
            );
        }
        println!(
            "frames      {} PNG in {}, preview {}",
            c.frames.len(),
            out.display(),
            c.preview.display()
        );
        if let Some(p) = &a.stats {
            std::fs::write(p, frames_csv(&c.outcome.records))
                .map_err(|e| format!("{}: {e}", p.display()))?;
        }
        return Ok(());
    }
    if !a.headless {
        return Err("playback without --scene is headless only: add --headless".into());
    }
    let (device, queue, info) = headless_device().map_err(|e| e.to_string())?;
    let adapter = format!("{} ({:?})", info.name, info.backend);
    let o = play(&s, &device, &queue, &adapter)?;
    print(&o, &s);
    if let Some(p) = &a.stats {
        std::fs::write(p, frames_csv(&o.records)).map_err(|e| format!("{}: {e}", p.display()))?;
    }
    if let Some(p) = &a.json {
        std::fs::write(p, serde_json::to_string_pretty(&o).unwrap())
            .map_err(|e| format!("{}: {e}", p.display()))?;
    }
    Ok(())
}

/// What a scene capture produced.
pub struct Capture {
    pub frames: Vec<std::path::PathBuf>,
    pub preview: std::path::PathBuf,
    pub outcome: Outcome,
    /// Each weather switch: where to, when it was asked for (s of playback), and how long
    /// the new weather took to show the shown time (its fade's start), ms.
    pub switches: Vec<SwitchTiming>,
    /// GPU memory of every open track and the outputs: at the first frame, and at most
    /// (both weathers open during a switch), bytes.
    pub gpu_bytes: (u64, u64),
}

/// How a weather switch went.
#[derive(Serialize, Clone, Debug)]
pub struct SwitchTiming {
    pub to: String,
    pub asked_s: f64,
    pub fade_started_after_ms: f64,
}

/// Plays `s` while rendering the terrain scene, capturing `n` frames evenly over the
/// duration into `out` (PNG) plus an animated preview (GIF). A package plays with its sky
/// track, and the session's weather switches happen at their times.
pub fn capture_scene(
    s: &Session,
    scene_file: &Path,
    out: &Path,
    n: usize,
    size: (u32, u32),
    progress: &dyn Fn(u64, u64),
) -> Result<Capture, String> {
    use vbim_scene::{orbit, SceneRenderer, View, FORMAT};
    let (mesh, hf) = scene_mesh(scene_file)?;
    let (device, queue, info) = headless_device().map_err(|e| e.to_string())?;
    let mut player = s.open_package(&device, &queue, s.realtime)?;
    let h = player.lightmap_player().header().clone();
    if (h.width, h.height) != (hf.w as u32, hf.h as u32) {
        eprintln!(
            "note: the lightmap is {}×{}, the terrain {}×{}: the lightmap is stretched over it",
            h.width, h.height, hf.w, hf.h
        );
    }
    let (exposure, sky) = s.scene_look()?;
    let mut renderer = SceneRenderer::new(
        &device,
        &queue,
        &mesh,
        player.lightmap_view(),
        player.sky_view(),
        size.0,
        size.1,
        FORMAT,
    );
    if let Some(b) = player.irradiance_buffer() {
        renderer.set_objects(b, &vbim_scene::showcase(&mesh, &hf));
    }
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let total = s.display_frames();
    let n = n.max(1) as u64;
    if s.start > 0 {
        player.set_time(s.start_ns(player.lightmap_player().header())?);
    }
    let mut records = Vec::with_capacity(total.min(RESERVED_RECORDS) as usize);
    let mut frames = Vec::new();
    let mut gif_frames = Vec::new();
    let (gw, gh) = (size.0 / 3, size.1 / 3);
    let mut prev_t = 0;
    let mut next_capture = 0u64;
    let mut captured = 0u64;
    let mut switches = s.switches.iter().peekable();
    let mut switches_done: Vec<SwitchTiming> = Vec::new();
    let mut gpu_bytes = (player.gpu_bytes(), player.gpu_bytes());
    for k in 1..=total {
        let t = k * 1_000_000_000 / s.display_hz as u64;
        while let Some((name, _)) = switches.next_if(|(_, at)| t >= *at) {
            player
                .switch_weather(name, s.fade_ns)
                .map_err(|e| e.to_string())?;
        }
        let rec = player.advance(t - prev_t);
        prev_t = t;
        gpu_bytes.1 = gpu_bytes.1.max(player.gpu_bytes());
        if let Some(sw) = &rec.switch {
            let asked = (t - sw.since_ns) as f64 * 1e-9;
            let new = switches_done
                .last()
                .is_none_or(|d: &SwitchTiming| (d.asked_s - asked).abs() > 1e-9);
            if sw.weight > 0.0 && new {
                switches_done.push(SwitchTiming {
                    to: sw.to.clone(),
                    asked_s: asked,
                    fade_started_after_ms: sw.since_ns as f64 * 1e-6,
                });
            }
        }
        let r = rec.lightmap;
        records.push(r);
        if k >= next_capture && captured < n {
            // A capture is for looking at: the objects' light of this very frame, even if
            // its grid's decoder thread is a frame behind.
            player.wait_irradiance(std::time::Duration::from_secs(2));
            let (eye, target) = orbit(captured as f32 / n as f32 * 0.5, &mesh);
            let v = View {
                eye,
                target,
                fovy: 0.75,
                exposure,
                sky: sky.at(r.shown),
                detail: 0.5,
            };
            renderer.render(&v, None);
            let px = renderer.read();
            let img = image::RgbaImage::from_raw(size.0, size.1, px).expect("size");
            let path = out.join(format!("frame_{captured:04}.png"));
            vbim_bake::write_file(&path, |tmp| img.save(tmp).map_err(|e| e.to_string()))
                .map_err(|e| e.to_string())?;
            gif_frames.push(image::imageops::resize(
                &img,
                gw,
                gh,
                image::imageops::FilterType::Triangle,
            ));
            frames.push(path);
            captured += 1;
            next_capture = captured * total / n;
            progress(captured, n);
        }
    }
    let preview = out.join("preview.gif");
    let delay = image::Delay::from_numer_denom_ms(1000, 15);
    vbim_bake::write_file(&preview, |tmp| {
        let file = File::create(tmp).map_err(|e| e.to_string())?;
        let mut enc =
            image::codecs::gif::GifEncoder::new_with_speed(std::io::BufWriter::new(file), 10);
        enc.set_repeat(image::codecs::gif::Repeat::Infinite)
            .map_err(|e| e.to_string())?;
        for f in gif_frames {
            enc.encode_frame(image::Frame::from_parts(f, 0, 0, delay))
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    })
    .map_err(|e| e.to_string())?;
    let adapter = format!("{} ({:?})", info.name, info.backend);
    // The lightmap track shown at the end (after a switch: the new weather's, since it
    // opened).
    let ended = Ended::of(player.lightmap_player());
    drop(player);
    let outcome = summarise(ended, s, &adapter, records, &SequenceError::default())?;
    Ok(Capture {
        frames,
        preview,
        outcome,
        switches: switches_done,
        gpu_bytes,
    })
}
