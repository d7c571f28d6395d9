//! The runtime's benchmarks: the player's decoder (and the GPU decode alone), drift and
//! shown error under bandwidth caps, and the render thread's CPU and GPU time.

use std::time::Instant;

use vbim_player::thread_cpu_ns;

use super::stats;
use super::{BenchDecodeArgs, BenchDriftArgs, BenchRenderArgs};

pub(super) fn bench_decode(a: BenchDecodeArgs) -> Result<(), String> {
    use vbim_format::chunk;
    use vbim_format::Reader;
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
    let (mut zstd_t, mut full_t, mut pairs_t) = (Vec::new(), Vec::new(), Vec::new());
    // Version 2 as coded: the boxes, the sum of each plane's longest lane, all lanes'
    // words.
    let mut chains = (0u64, 0u64, 0u64);
    // Bytes the boxes of a play-through upload.
    let mut upload = 0u64;
    for _ in 0..a.runs.max(1) {
        // The entropy decoding alone: every keyframe, tile map and coefficient chunk
        // decompressed (zstd), or decoded to pairs (format 2's rANS lanes).
        let t = Instant::now();
        let mut total = 0usize;
        let limit = vbim_format::limits::MAX_CHUNK_DECODED as usize;
        let tile_maps = each_payload(&h, &entries, &chunks, |what, c| {
            total += chunk::payload(&h, what, c, limit)
                .map_err(|e| e.to_string())?
                .len();
            Ok(())
        })?;
        total += tile_maps;
        zstd_t.push(t.elapsed().as_secs_f64());
        std::hint::black_box(total);
        // The player's decoder: every chunk in playback order, every segment filled for
        // the GPU (scanned streams; the GPU does the rest).
        // Format 2: with its sections as coded (for a GPU), and decoded to pairs (for a
        // CPU adapter, `DecodeShape::lanes`).
        let lanes = matches!(h.coding, vbim_format::Coding::Lanes(..));
        for (as_coded, times) in [(true, &mut full_t), (false, &mut pairs_t)] {
            if !as_coded && !lanes {
                continue;
            }
            let t = Instant::now();
            let mut dec = DecoderCore::new(h.clone(), layout.clone(), entries.clone());
            dec.set_lanes(as_coded);
            let mut packed = SegmentData::new();
            let mut seen = (0, 0, 0);
            let mut uploaded = 0;
            for (i, c) in chunks.iter().enumerate() {
                if let Event::Ready(s) = dec.take(i, Some(c)) {
                    dec.fill(s, 0, 0, &mut packed)?;
                    let (longest, words) = packed.lane_words();
                    seen = (seen.0 + 1, seen.1 + longest, seen.2 + words);
                    uploaded += packed.bytes();
                }
            }
            if as_coded {
                chains = seen;
                upload = uploaded;
            }
            times.push(t.elapsed().as_secs_f64());
        }
    }
    let gpu = a
        .gpu
        .then(|| gpu_decode(&h, &layout, &entries, &chunks, a.runs, &a.shape))
        .transpose()?;
    let (zm, z0, z1) = stats(&mut zstd_t);
    let (fm, f0, f1) = stats(&mut full_t);
    println!(
        "decode benchmark: {name}, {}×{}, {} frames at {}/{} fps ({duration:.1} s), {} segments, {} runs, block kernel {}",
        h.width, h.height, h.frame_count, h.rate_num, h.rate_den, h.segment_count, a.runs,
        vbim_format::plane::kernel_build()
    );
    let entropy = match h.coding {
        vbim_format::Coding::Pairs => "zstd alone     ",
        vbim_format::Coding::Lanes(..) => "rANS to pairs  ",
    };
    println!(
        "{entropy} median {:.3} s (min {z0:.3}, max {z1:.3}) = {:.2}% of one core in real time",
        zm,
        100.0 * zm / duration
    );
    println!(
        "uploads         {upload} bytes over a play-through: {:.2}× the file's {} bytes",
        upload as f64 / bytes.len().max(1) as f64,
        bytes.len()
    );
    let what = match pairs_t.is_empty() {
        true => "full decode    ",
        false => "full, as coded ",
    };
    println!(
        "{what} median {:.3} s (min {f0:.3}, max {f1:.3}) = {:.2}% of one core in real time",
        fm,
        100.0 * fm / duration
    );
    if chains.2 > 0 {
        let n = chains.0.max(1) as f64;
        println!(
            "lanes           per segment {:.0} words in all; the longest lane of each plane, summed: {:.0} words",
            chains.2 as f64 / n,
            chains.1 as f64 / n
        );
    }
    if h.context_maps().is_some() {
        let n = h.segment_count.max(1) as f64;
        let c = lane_symbols(&h, &entries, &chunks)?;
        println!(
            "lanes           per segment {:.0} rANS states; the longest lane of each plane, summed: {:.0} steps (the serial chains a GPU decodes plane after plane: with one state a lane, its symbols; with several, per pass its busiest state's); a chunk's planes side by side: {:.0} steps; as the player dispatches them (a chunk's planes in batches that fit its dense plane, side by side): {:.0} steps",
            c.states as f64 / n,
            c.longest as f64 / n,
            c.shared as f64 / n,
            c.player as f64 / n,
        );
    }
    if !pairs_t.is_empty() {
        let (pm, p0, p1) = stats(&mut pairs_t);
        println!("full, to pairs  median {pm:.3} s (min {p0:.3}, max {p1:.3}) = {:.2}% of one core in real time (the decoder thread's work where the GPU parses pairs: a CPU adapter)", 100.0 * pm / duration);
    }
    if let Some((adapter, mut times, boxes, passes, (names, samples, key_add), bytes)) = gpu {
        let (gm, g0, g1) = stats(&mut times);
        println!(
            "GPU decode      median {gm:.3} s (min {g0:.3}, max {g1:.3}) for {boxes} segments, {:.1} ms each, on {adapter}",
            1e3 * gm / boxes.max(1) as f64,
        );
        println!(
            "GPU memory      {bytes} bytes (the player's GPU state, textures included): {:.2} B/texel",
            bytes as f64 / (h.width as f64 * h.height as f64).max(1.0)
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
            if a.fit {
                super::fit::print(&names, &samples, key_add);
            }
        }
    }
    Ok(())
}

/// A version 2 or 3 file's lanes, counted ([`lane_symbols`]).
struct Chains {
    /// rANS states (one a lane in version 2).
    states: u64,
    /// The sum over planes of each plane's longest lane in steps: the serial chains of a
    /// decoder that runs a plane's lanes side by side, plane after plane (a likely zero
    /// lengthens them as much as a rare value).
    longest: u64,
    /// The sum over chunks of each one's longest lane (a chunk's planes side by side).
    shared: u64,
    /// As the player dispatches them: a chunk's planes in the player's batches
    /// ([`vbim_player::bench::lane_batches`]), each batch's side by side.
    player: u64,
}

/// A version 2 or 3 file's lanes' serial chains
/// ([`vbim_format::plane2::lane_symbols`]).
fn lane_symbols(
    h: &vbim_format::Header,
    entries: &[vbim_format::IndexEntry],
    chunks: &[&[u8]],
) -> Result<Chains, String> {
    let mut c = Chains {
        states: 0,
        longest: 0,
        shared: 0,
        player: 0,
    };
    // The player's room for a batch (where the planes go as pairs, none: each plane
    // alone, as plane after plane).
    let room = vbim_player::bench::lane_room(h).unwrap_or((0, 0));
    each_payload(h, entries, chunks, |what, bytes| {
        let mut planes =
            vbim_format::payload2::lane_symbols(h, what, bytes).map_err(|e| e.to_string())?;
        let longest = |p: &vbim_format::payload2::PlaneLanes| p.1.iter().map(|l| l.0).max();
        c.shared += planes.iter().filter_map(longest).max().unwrap_or(0);
        planes.sort_by_key(|p| std::cmp::Reverse(p.0));
        let states = |p: &vbim_format::payload2::PlaneLanes| p.1.iter().map(|l| l.1 as u64).sum();
        let size = |k: usize| (planes[k].0 as u32, states(&planes[k]), 0);
        vbim_player::bench::lane_batches(planes.len(), size, room, |batch| {
            let most = batch.iter().filter_map(|&k| longest(&planes[k])).max();
            c.player += most.unwrap_or(0);
        });
        for (_, lanes) in planes {
            c.longest += lanes.iter().map(|l| l.0).max().unwrap_or(0);
            c.states += lanes.iter().map(|l| l.1 as u64).sum::<u64>();
        }
        Ok(())
    })?;
    Ok(c)
}

/// Calls `each` with every keyframe and coefficient chunk in file order (what its payload
/// holds, its bytes), a coefficient chunk with the tile map read before it; errors name
/// the chunk. Returns the bytes of the tile maps it read.
fn each_payload(
    h: &vbim_format::Header,
    entries: &[vbim_format::IndexEntry],
    chunks: &[&[u8]],
    mut each: impl FnMut(vbim_format::chunk::Payload, &[u8]) -> Result<(), String>,
) -> Result<usize, String> {
    use vbim_format::{chunk, ChunkKind};
    let (mut tiles, mut read) = (None, 0);
    for (i, (e, c)) in entries.iter().zip(chunks).enumerate() {
        let what = match e.kind {
            ChunkKind::Keyframe => chunk::Payload::Keyframe,
            ChunkKind::Coefficients => {
                chunk::Payload::Coefficients(tiles.as_ref().ok_or("no tile map")?)
            }
            ChunkKind::TileMap => {
                let t = chunk::read_tilemap(h, c, e.last_frame - e.first_frame)
                    .map_err(|e| format!("chunk {i}: {e}"))?;
                read += t.luma.len();
                tiles = Some(t);
                continue;
            }
            _ => continue,
        };
        each(what, c).map_err(|e| format!("chunk {i}: {e}"))?;
    }
    Ok(read)
}

/// A decode shape in words, for the benchmarks' first line.
fn describe(s: &vbim_player::DecodeShape) -> String {
    format!(
        "dispatches of {} workgroups, {} parse, groups of blocks split in up to {}, {} blocks per step, {} weights, version 2 sections {}, DCT tables in a {} buffer, {} an invocation of the reconstruction, {}",
        s.slice_groups,
        if s.wide_parse { "wide" } else { "serial" },
        s.group_split,
        s.step_cost,
        if s.weights == vbim_player::PassWeights::H100 { "H100" } else if s.weights == vbim_player::PassWeights::LAVAPIPE { "lavapipe" } else { "own" },
        if s.lanes { "as coded" } else { "as pairs" },
        if s.storage_tables { "storage" } else { "uniform" },
        if s.wide_reconstruct { "two quads" } else { "a quad" },
        match s.lanes {
            true => format!(
                ", {} lane states a workgroup, their job in a {} buffer",
                s.lane_group,
                if s.lane_job_storage { "storage" } else { "uniform" }
            ),
            false => String::new(),
        }
    )
}

/// The adapter in words, each run's time, the segments decoded, the time by pass per
/// segment (ns; empty where the adapter has no timestamps inside passes), each dispatch
/// timed (the pass names, then (pass, work, ns) for the fit), and the GPU memory the
/// decode state holds after the last segment.
type GpuTimes = (
    String,
    Vec<f64>,
    usize,
    Vec<(&'static str, f64)>,
    (Vec<&'static str>, Vec<super::fit::Sample>, u32),
    u64,
);

/// The GPU decode of every segment of a stream, `runs` times.
fn gpu_decode(
    h: &vbim_format::Header,
    layout: &vbim_format::index::Layout,
    entries: &[vbim_format::IndexEntry],
    chunks: &[&[u8]],
    runs: usize,
    shape: &super::args::ShapeArgs,
) -> Result<GpuTimes, String> {
    use vbim_player::bench::{timing_device, DecoderCore, Event, GpuDecoder, SegmentData};
    let (device, queue, info) = timing_device().map_err(|e| e.to_string())?;
    let shape = shape.shape(&info);
    let adapter = format!(
        "{} ({:?}), decode shape: {}",
        info.name,
        info.backend,
        describe(&shape)
    );
    let mut gpu = GpuDecoder::new(&device, &queue, h, Some(shape));
    let (mut times, mut boxes) = (Vec::new(), 0);
    let mut passes: Vec<(&'static str, f64)> = Vec::new();
    let (mut names, mut samples) = (Vec::new(), Vec::new());
    for _ in 0..runs.max(1) {
        let mut dec = DecoderCore::new(h.clone(), layout.clone(), entries.to_vec());
        dec.set_lanes(shape.lanes);
        let mut seg = SegmentData::new();
        let (mut t, mut n) = (0.0, 0);
        for (i, c) in chunks.iter().enumerate() {
            if let Event::Ready(s) = dec.take(i, Some(c)) {
                dec.fill(s, 0, 0, &mut seg)?;
                let (dt, steps) = gpu
                    .decode(&seg)
                    .map_err(|e| format!("the GPU decode of chunk {i}: {e}"))?;
                t += dt.as_secs_f64();
                n += 1;
                let marks = gpu.pass_times();
                // Each dispatch's own mark, in order (a compute pass's first mark times the
                // clears before it): the samples of the fit, where they pair up.
                let timed: Vec<_> = marks
                    .iter()
                    .filter(|(l, _)| *l != vbim_player::bench::PASS_CHANGES)
                    .collect();
                if timed.len() == steps.len() && timed.iter().zip(&steps).all(|(m, s)| m.0 == s.0) {
                    for (&&(_, ns), &(label, units)) in timed.iter().zip(&steps) {
                        let p = names.iter().position(|&n| n == label).unwrap_or_else(|| {
                            names.push(label);
                            names.len() - 1
                        });
                        samples.push((p, units as f64, ns));
                    }
                }
                // Summed per kind of pass, in the order they first came.
                for (label, ns) in marks {
                    merge_by_label(&mut passes, label, ns, std::ops::Add::add);
                }
            }
        }
        times.push(t);
        boxes = n;
    }
    // Per segment, the mean over runs.
    let per = (runs.max(1) * boxes.max(1)) as f64;
    let passes = passes.into_iter().map(|(l, ns)| (l, ns / per)).collect();
    let key_add = shape.weights.key_add;
    let bytes = gpu.gpu_bytes();
    Ok((
        adapter,
        times,
        boxes,
        passes,
        (names, samples, key_add),
        bytes,
    ))
}

/// Adds `ns` to `label`'s entry of `into` with `merge` (a sum, a maximum), or appends the
/// label: GPU times by kind of pass, in the order the kinds first came.
fn merge_by_label(
    into: &mut Vec<(&'static str, f64)>,
    label: &'static str,
    ns: f64,
    merge: fn(f64, f64) -> f64,
) {
    match into.iter_mut().find(|(l, _)| *l == label) {
        Some((_, t)) => *t = merge(*t, ns),
        None => into.push((label, ns)),
    }
}

pub(super) fn bench_drift(a: BenchDriftArgs) -> Result<(), String> {
    use crate::cmd_play::play;
    use crate::session::Session;
    use crate::units::Bandwidth;
    use vbim_player::Policy;
    if a.phases == 0 {
        return Err("--phases must be at least 1".into());
    }
    std::fs::create_dir_all(&a.out).map_err(|e| format!("{}: {e}", a.out.display()))?;
    let (device, queue, info) = vbim_player::headless_device().map_err(|e| e.to_string())?;
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

pub(super) fn bench_render(a: BenchRenderArgs) -> Result<(), String> {
    use super::frame_gpu::{mean_bytes_per_texel, quarter_bytes_per_texel, FrameTimer};
    use vbim_player::{Player, PlayerConfig};
    let name = a.file.display().to_string();
    // Timestamps where the adapter has them (lavapipe does); the player asks for none.
    let (device, queue, info) = vbim_player::bench::timing_device().map_err(|e| e.to_string())?;
    let summary = |v: &mut Vec<f64>| {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        v.sort_by(f64::total_cmp);
        [
            mean,
            v[((v.len() - 1) as f64 * 0.99) as usize],
            v[v.len() - 1],
        ]
    };
    // Per run: cpu, wall, plan, GPU and blend by timestamps, GPU and blend by the wall clock
    // from submission to completion, each frame's GPU time over its blend's: [mean, p99,
    // max] each.
    let mut runs: Vec<[[f64; 3]; 8]> = Vec::new();
    let (mut h, mut timed, mut work) = (None, false, (0u64, 0u64));
    // Each pass's GPU time over the last run, by label: its sum, and its largest in one
    // frame (ns).
    let mut passes_timed = false;
    let (mut sums, mut largest) = (Vec::new(), Vec::new());
    // Each frame against the blend after it, over every run: the frames that recorded no
    // decode work (the reconstruction alone), then those that did.
    let mut by_decode: [Vec<f64>; 2] = Default::default();
    // What each run's game load took once calibrated (ms).
    let mut load_took = Vec::new();
    // Frames whose data was late (held, catching up, waiting), over every run: their GPU
    // time is not the stream's.
    let mut late: std::collections::BTreeMap<&'static str, usize> = Default::default();
    for _ in 0..a.runs.max(1) {
        let f = crate::sequence::open_input(&a.file)?;
        let cfg = PlayerConfig {
            decode_budget: a.budget,
            decode_shape: Some(a.shape.shape(&info)),
            reuse_share: a.reuse_share,
            reuse_probe: a.reuse_probe,
            ..PlayerConfig::default()
        };
        let mut player = Player::open(&device, &queue, std::io::BufReader::new(f), cfg)
            .map_err(|e| e.to_string())?;
        let header = player.header().clone();
        passes_timed = a.passes && player.time_passes();
        sums.clear();
        largest.clear();
        if a.start > 0 {
            player.set_time(crate::session::start_ns(a.start, &header)?);
        }
        let timer = FrameTimer::new(&device, &queue, (header.width, header.height));
        timed = timer.is_some();
        let load = super::game_load::GameLoad::new(&device, &queue, a.game_load);
        load_took.extend(load.as_ref().map(|l| l.took_ms));
        h = Some(header);
        let mut series: [Vec<f64>; 8] = Default::default();
        let mut rows = String::from(
            "frame,gpu_ms,blend_ms,gpu_wall_ms,blend_wall_ms,decode_work,segment,u,state,decode_ms,reconstruct_ms\n",
        );
        let start = Instant::now();
        let mut prev = 0u64;
        let warm = 60;
        for k in 1..=a.frames + warm {
            let t = k * 1_000_000_000 / 60;
            let wall = start.elapsed().as_nanos() as u64;
            if t > wall {
                std::thread::sleep(std::time::Duration::from_nanos(t - wall));
            }
            if let Some(load) = &load {
                let mut enc = device.create_command_encoder(&Default::default());
                load.record(&mut enc);
                queue.submit([enc.finish()]);
            }
            let (c0, t0) = (thread_cpu_ns(), Instant::now());
            // The display's pace; the media advances `slow` times slower.
            let frame = player.plan((t - prev) / a.slow);
            let t1 = Instant::now();
            let mut enc = device.create_command_encoder(&Default::default());
            if let Some(timer) = &timer {
                timer.begin(&mut enc);
            }
            player.render_into(&frame, &mut enc);
            if let Some(timer) = &timer {
                timer.end(&mut enc);
            }
            queue.submit([enc.finish()]);
            player.submitted();
            let (c2, t2) = (thread_cpu_ns(), Instant::now());
            player.wait_for_gpu();
            let t3 = Instant::now();
            let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
            // This frame's passes, by label (the decode's kinds, then the reconstruction).
            let mut split = (0.0, 0.0);
            if passes_timed {
                let mut frame_passes = Vec::new();
                for (label, ns) in player.pass_times() {
                    merge_by_label(&mut frame_passes, label, ns, std::ops::Add::add);
                }
                for &(label, ns) in &frame_passes {
                    if label == "reconstruct" {
                        split.1 += ns * 1e-6;
                    } else {
                        split.0 += ns * 1e-6;
                    }
                    if k > warm {
                        merge_by_label(&mut sums, label, ns, std::ops::Add::add);
                        merge_by_label(&mut largest, label, ns, f64::max);
                    }
                }
            }
            // The reference blend in a submission of its own, timed the same two ways.
            let (mut gpu, mut blend, mut blend_wall) = (0.0, 0.0, 0.0);
            if let Some(timer) = &timer {
                let mut enc = device.create_command_encoder(&Default::default());
                timer.blend(&mut enc);
                let t4 = Instant::now();
                queue.submit([enc.finish()]);
                player.wait_for_gpu();
                blend_wall = ms(t4, Instant::now());
                (gpu, blend) = timer.read(&device);
            }
            let gpu_wall = ms(t2, t3);
            prev = t;
            if k > warm {
                series[0].push((c2 - c0) as f64 * 1e-6);
                series[1].push((t2 - t0).as_secs_f64() * 1e3);
                series[2].push((t1 - t0).as_secs_f64() * 1e3);
                series[3].push(gpu);
                series[4].push(blend);
                series[5].push(gpu_wall);
                series[6].push(blend_wall);
                // Each frame against the blend timed right after it, at the same clock (a
                // hardware GPU's changes within a run: the H100's halved halfway through).
                series[7].push(gpu / blend.max(1e-9));
                let r = &frame.record;
                by_decode[(r.decode_work > 0) as usize].push(gpu / blend.max(1e-9));
                if r.state != vbim_player::FrameState::Exact {
                    *late.entry(r.state.name()).or_default() += 1;
                }
                rows += &format!(
                    "{k},{gpu:.4},{blend:.4},{gpu_wall:.4},{blend_wall:.4},{},{},{:.4},{:?},{:.4},{:.4}\n",
                    r.decode_work, r.segment, r.u, r.state, split.0, split.1
                );
            }
        }
        let t = player.totals();
        work = (t.decode_work_max, t.budget_late);
        player
            .stop(std::time::Duration::from_secs(10))
            .map_err(|e| e.to_string())?;
        runs.push(series.map(|mut v| summary(&mut v)));
        if let Some(path) = &a.csv {
            std::fs::write(path, rows).map_err(|e| format!("{}: {e}", path.display()))?;
        }
    }
    let h = h.expect("at least one run");
    // Median over runs of each figure, with the smallest and largest.
    let stat = |i: usize, j: usize| stats(&mut runs.iter().map(|r| r[i][j]).collect::<Vec<_>>());
    let line = |label: &str, i: usize, digits: usize| {
        let ((m, m0, m1), (p, p0, p1), (x, ..)) = (stat(i, 0), stat(i, 1), stat(i, 2));
        println!(
            "{label:<50} mean {m:.digits$} ms ({m0:.digits$}–{m1:.digits$}), p99 {p:.digits$} ms ({p0:.digits$}–{p1:.digits$}), max {x:.digits$} ms"
        );
    };
    println!(
        "render benchmark: {name}, {}×{} at {}/{} fps{}, 60 Hz, {} frames × {} runs on {} ({:?}), decode budget {}, decode shape: {}, reuse share {} (deciding every {} frames where few tiles are kept){}; median over runs (min–max)",
        h.width, h.height, h.rate_num, h.rate_den,
        if a.slow > 1 { format!(" played {}× slower", a.slow) } else { String::new() },
        a.frames, runs.len(), info.name, info.backend,
        a.budget.map_or("spread (default)".to_string(), |b| format!("{b} blocks per frame")),
        describe(&a.shape.shape(&info)),
        a.reuse_share,
        a.reuse_probe,
        if a.game_load > 0.0 {
            format!(
                ", a game's load of about {} ms before each frame ({} ms once calibrated; its time is in the wall clock's \"submission to completion\" of the frame, not in the timestamps)",
                a.game_load,
                load_took
                    .iter()
                    .map(|t| format!("{t:.2}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        } else {
            String::new()
        }
    );
    line(
        "render thread CPU time, advance = plan + record + submit",
        0,
        3,
    );
    line(
        "  the same, wall clock (preemption and waits included)",
        1,
        3,
    );
    line("  of which plan (the player's own logic, wall clock)", 2, 4);
    let ratios = |label: &str, g: usize, b: usize| {
        let (m, p, x, r) = (
            stat(g, 0).0,
            stat(g, 1).0,
            stat(g, 2).0,
            stat(b, 0).0.max(1e-9),
        );
        println!(
            "{label}: mean {:.2}×, p99 {:.2}×, max {:.2}× the blend; p99 / mean {:.2}",
            m / r,
            p / r,
            x / r,
            p / m.max(1e-9)
        );
    };
    if timed {
        line("GPU time per displayed frame (timestamps)", 3, 3);
        line("reference: blend two Rgba16Float frames (timestamps)", 4, 3);
        ratios("  timestamps", 3, 4);
        let ((m, ..), (p, ..), (x, ..)) = (stat(7, 0), stat(7, 1), stat(7, 2));
        println!(
            "  each frame against the blend timed after it (the same clock): mean {m:.2}×, p99 {p:.2}×, max {x:.2}×"
        );
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        println!(
            "    of which {} frames recorded no decode work, mean {:.2}× (the reconstruction alone), and {} a share of a decode, mean {:.2}×",
            by_decode[0].len(),
            mean(&by_decode[0]),
            by_decode[1].len(),
            mean(&by_decode[1])
        );
    }
    // A CPU adapter's timestamps need not bracket its work (lavapipe defers some of it
    // to the next flush): the wall clock from submission to completion is the figure
    // there. On a hardware GPU it adds the submission's latency to both.
    line("submission to completion, the player's frame (wall)", 5, 3);
    if timed {
        // (The blend is the timer's: an adapter without timestamps has no reference.)
        line("submission to completion, the reference blend (wall)", 6, 3);
        ratios("  wall clock", 5, 6);
    }
    if !late.is_empty() {
        let what: Vec<String> = late.iter().map(|(s, n)| format!("{n} {s}")).collect();
        println!(
            "frames whose data was late (not the stream's cost: the decoder thread or the reader fell behind): {}",
            what.join(", ")
        );
    }
    let (head, packed, blend) = quarter_bytes_per_texel(&h);
    println!(
        "bytes per texel a frame touches at degree {}, besides the bubble terms after each block's first (2 bytes each where they fit in 16 bits, 4 otherwise): {:.2} (K_(s+1) packed), {:.2} (in the f32 head, until the next decode packs it), 0.47 in a tile it keeps (its state: 80 bytes read, 40 written per 16² texels); the blend {} ({:.2}×)",
        h.max_degree,
        packed as f64 / 4.0,
        head as f64 / 4.0,
        blend / 4,
        packed as f64 / blend as f64
    );
    if let Some(t) = mean_bytes_per_texel(&a.file)? {
        println!(
            "  over this file's tiles, each read up to its own degree, and its bubble terms: {:.2} on average (K_(s+1) packed; {:.2}× the blend); of its bubble planes' coded blocks {:.0}% hold no term, {:.0}% one, {:.2} on average",
            t.bytes,
            t.bytes / (blend / 4) as f64,
            100.0 * t.empty,
            100.0 * t.one,
            t.terms
        );
    }
    println!(
        "decode work: at most {} blocks in one frame; frames late for the budget: {}",
        work.0, work.1
    );
    if a.passes && !passes_timed {
        println!("GPU time by pass: not measured (the adapter has no timestamps inside passes)");
    } else if passes_timed {
        let total: f64 = sums.iter().map(|p| p.1).sum();
        println!(
            "GPU time by pass per displayed frame (timestamps between passes, last run): {:.3} ms in all",
            total / a.frames as f64 / 1e6
        );
        for (&(label, sum), &(_, max)) in sums.iter().zip(&largest) {
            println!(
                "  {label:<24} mean {:>7.3} ms  {:>5.1}%  largest in one frame {:>7.3} ms",
                sum / a.frames as f64 / 1e6,
                100.0 * sum / total.max(1.0),
                max / 1e6
            );
        }
    }
    Ok(())
}
