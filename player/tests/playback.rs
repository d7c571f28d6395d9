//! The player on a real wgpu adapter (lavapipe or llvmpipe on machines without a GPU):
//! GPU reconstruction against the CPU reference decoder, stalls, loops, damage, threads.

use std::collections::BTreeMap;
use std::io::Cursor;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use vbim_encoder::{
    encode, EncoderConfig, FormatVersion, InputKind, MemorySource, Preset, SegmentMode,
};
use vbim_format::curve::linear_to_srgb;
use vbim_format::decode::{Decoder, Output};
use vbim_format::Reader;
use vbim_player::{
    headless_device, headless_device_on, DecodeShape, FrameState, Player, PlayerConfig, Policy,
    Stall, Throttle,
};

fn device() -> (wgpu::Device, wgpu::Queue) {
    opened(headless_device())
}

/// A device on wgpu's GL backend (llvmpipe on machines without a GPU): the backend whose
/// limits and texture rules differ most from Vulkan's, and the one WebGL gives.
fn gl_device() -> (wgpu::Device, wgpu::Queue) {
    opened(headless_device_on(wgpu::Backends::GL))
}

fn opened(
    device: Result<vbim_player::Headless, vbim_player::DeviceError>,
) -> (wgpu::Device, wgpu::Queue) {
    match device {
        Ok((d, q, info)) => {
            eprintln!("adapter: {} ({:?})", info.name, info.backend);
            (d, q)
        }
        Err(e) => panic!("{e}"),
    }
}

/// A small day-like sequence: a moving soft shadow edge over a gradient, bright by day.
fn sequence(w: usize, h: usize, n: usize, kind: InputKind) -> MemorySource {
    let frames = (0..n)
        .map(|t| {
            let day = (std::f32::consts::PI * t as f32 / n as f32).sin().max(0.0);
            (0..w * h)
                .flat_map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let edge = 1.0 / (1.0 + (-(x - w as f32 * t as f32 / n as f32) * 0.5).exp());
                    let v = 0.02 + day * (0.3 + 0.6 * edge) * (0.8 + 0.2 * (y * 0.2).sin());
                    let v = if kind == InputKind::Srgb8 {
                        (linear_to_srgb(v.min(1.0)) * 255.0).round() / 255.0
                    } else {
                        v
                    };
                    [v, v * 0.9, v * 0.75]
                })
                .collect()
        })
        .collect();
    MemorySource::new("test", w, h, 3, kind, frames)
}

/// Noisy content: every frame costs bits, so the ring holds little of the file.
fn noisy(w: usize, h: usize, n: usize) -> MemorySource {
    let mut src = sequence(w, h, n, InputKind::Hdr);
    let mut seed = 12345u32;
    for f in &mut src.frames {
        for v in f.iter_mut() {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            *v *= 0.7 + 0.6 * (seed >> 8) as f32 / (1 << 24) as f32;
        }
    }
    src
}

fn encode_bytes(src: &MemorySource, cfg: &EncoderConfig) -> Vec<u8> {
    let mut bytes = Vec::new();
    encode(src, cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    bytes
}

/// A stream encoded once for every test of this file that plays it (the same stream in
/// several decode shapes and adapters): the tests run side by side, and encoding is a good
/// part of their time on two cores.
fn encoded_once(key: &str, encode: impl FnOnce() -> Vec<u8>) -> Arc<Vec<u8>> {
    type Slot = Arc<OnceLock<Arc<Vec<u8>>>>;
    static STREAMS: Mutex<BTreeMap<String, Slot>> = Mutex::new(BTreeMap::new());
    let slot = STREAMS
        .lock()
        .unwrap()
        .entry(key.to_string())
        .or_default()
        .clone();
    // Encoded outside the map's lock: other streams encode meanwhile; a test that needs
    // this one waits for it.
    slot.get_or_init(|| Arc::new(encode())).clone()
}

fn header_of(bytes: &[u8]) -> vbim_format::Header {
    Reader::open(Cursor::new(bytes)).unwrap().header().clone()
}

fn config(segment: SegmentMode) -> EncoderConfig {
    EncoderConfig {
        segment,
        rate: (24, 1),
        tolerance_db: 45.0,
        // A fixed budget, not the one the aim finds: these tests' bounds (the seam against
        // the loop's mean, the bit rate under a cap) were set on the streams it gives.
        aim: false,
        ..EncoderConfig::preset(Preset::Default)
    }
}

fn inline(policy: Policy, throttle: Throttle) -> PlayerConfig {
    PlayerConfig {
        policy,
        throttle,
        threaded: false,
        ..Default::default()
    }
}

/// A player of `bytes`, stepped inline, interpolating, read under `throttle`.
fn interpolating(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    bytes: Vec<u8>,
    throttle: Throttle,
) -> Player<Cursor<Vec<u8>>> {
    Player::open(
        device,
        queue,
        Cursor::new(bytes),
        inline(Policy::Interpolate, throttle),
    )
    .unwrap()
}

/// A player of `bytes`, stepped inline, unthrottled, interpolating.
fn unthrottled(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    bytes: Vec<u8>,
) -> Player<Cursor<Vec<u8>>> {
    interpolating(device, queue, bytes, Throttle::UNLIMITED)
}

/// 1/60 s in ns; 60 Hz display over 24 fps media.
const DISPLAY: u64 = 16_666_667;

#[test]
fn gpu_reconstruction_matches_the_reference_decoder() {
    let (device, queue) = device();
    reconstruction_matches_the_reference(&device, &queue);
}

#[test]
fn gpu_reconstruction_matches_the_reference_decoder_on_gl() {
    let (device, queue) = gl_device();
    reconstruction_matches_the_reference(&device, &queue);
}

fn reconstruction_matches_the_reference(device: &wgpu::Device, queue: &wgpu::Queue) {
    // GL's one-layer arrays take a second layer (see `min_array_layers`).
    let layers = |n: u64| match device.adapter_info().backend {
        wgpu::Backend::Gl => n.max(2),
        _ => n,
    };
    // RGB (YCoCg planes) in both domains, and a one-channel HDR sequence (Y alone), in
    // format 1; RGB HDR in formats 2 and 3 too. Odd sizes: the reconstruction's last 2 × 2 quads
    // and workgroups are partly outside.
    let (w, h) = (41, 23);
    for (kind, ch, format) in [
        (InputKind::Hdr, 3, FormatVersion::V1),
        (InputKind::Srgb8, 3, FormatVersion::V1),
        (InputKind::Hdr, 1, FormatVersion::V1),
        (InputKind::Hdr, 3, FormatVersion::V2),
        (InputKind::Hdr, 3, FormatVersion::V3),
    ] {
        let mut src = sequence(w, h, 30, kind);
        if ch == 1 {
            for f in &mut src.frames {
                *f = f.iter().step_by(3).copied().collect();
            }
            src.info.channels = 1;
        }
        let cfg = EncoderConfig {
            format,
            ..config(SegmentMode::Auto { max: 12 })
        };
        let bytes = encode_bytes(&src, &cfg);
        let major = match format {
            FormatVersion::V1 => 1,
            FormatVersion::V2 => 2,
            FormatVersion::V3 => 3,
        };
        assert_eq!(header_of(&bytes).version_major(), major);
        let mut reference =
            Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
        let mut player = unthrottled(device, queue, bytes);
        // The budget's figure, counted by hand: the head keyframe's ch R32Float layers,
        // two slots of ch 16-bit keyframe layers and two sets of (degree − 1) × ch layers
        // of bubble blocks (16 bytes per 8 × 8 texels), over the padded planes (48 × 32,
        // whole 16-texel tiles), the lightmap (Rgba16Float) and its held copy (RGB9E5, 4
        // bytes); then the buffers: the 16-bit keyframes' ranges (2 × 1 regions of 32² per
        // plane and slot, 8 bytes each), the 240-byte uniform of the reconstruction, the
        // 512-byte DCT tables, and the decode jobs and coefficients and each set's bubble
        // terms, at least 16, 64 and 2 × 64 KiB.
        let (planes, d) = (48 * 32u64, player.header().max_degree as u64);
        let set = (d - 1).max(1) * ch as u64;
        let textures = planes * (layers(ch as u64) * 4 + 2 * ch as u64 * 2)
            + planes / 64 * 16 * 2 * set
            + (w * h) as u64 * (8 + 4);
        let ranges = 2 * 2 * ch as u64 * 8;
        let buffers = player.gpu_bytes() - textures - ranges - 240 - 512;
        assert!(
            ((16 << 10) + (64 << 10) + (128 << 10)..1 << 20).contains(&buffers),
            "degree {d}, {ch} channel(s): {} bytes, {buffers} in decode buffers",
            player.gpu_bytes()
        );
        let mut cpu = vec![0f32; w * h * ch];
        let mut checked = 0;
        for _ in 0..90 {
            let r = player.advance(DISPLAY);
            assert_eq!(
                r.state,
                FrameState::Exact,
                "unthrottled playback is exact: {kind:?} {ch} frame {} {:?}",
                r.index,
                player.totals()
            );
            if !r.index.is_multiple_of(7) {
                continue;
            }
            let gpu = player.read_display();
            let t = r.shown % 30.0;
            let mode = if kind == InputKind::Srgb8 {
                Output::Stored
            } else {
                Output::Linear
            };
            reference.frame(t, mode, &mut cpu).unwrap();
            for i in 0..w * h {
                for c in 0..3 {
                    // One channel is shown as grey: every display channel is Y.
                    let (g, want) = (gpu[i * 4 + c], cpu[i * ch + c.min(ch - 1)]);
                    match kind {
                        // Within 0.5/255 on the 8-bit scale.
                        InputKind::Srgb8 => {
                            let d = (linear_to_srgb(g) - want).abs() * 255.0;
                            assert!(d <= 0.5, "frame {t:.3} texel {i} channel {c}: {g} vs code {want} ({d} codes)");
                        }
                        // The protocol's HDR bound.
                        InputKind::Hdr => {
                            assert!(
                                within_hdr_bound(g, want),
                                "frame {t:.3} texel {i} channel {c}: GPU {g} vs CPU {want}"
                            );
                        }
                    }
                }
            }
            checked += 1;
        }
        assert!(checked >= 10);
    }
}

#[test]
fn a_stall_longer_than_the_read_ahead_holds_then_catches_up_without_black_frames() {
    let (device, queue) = device();
    let bytes = encode_bytes(&noisy(64, 32, 96), &config(SegmentMode::Fixed(6)));
    let header = header_of(&bytes);
    let mean_rate = header.file_size as f64 / (96.0 / 24.0);
    // 3× the mean rate, with a 1.5 s stall every 6 s of playback: far longer than what the
    // ring (the header's read-ahead at that rate) holds.
    let rate = (mean_rate * 3.0) as u64;
    let ahead = header.read_ahead_at(rate).unwrap().bytes as f64;
    assert!(1.5 > ahead / mean_rate, "the stall outlasts the read-ahead");
    let throttle = Throttle {
        rate: Some(rate),
        stall: Some(Stall::every(1_500_000_000, 6_000_000_000)),
    };
    let mut player = interpolating(&device, &queue, bytes, throttle);
    let mut states = Vec::new();
    let mut drift_after = Vec::new();
    for k in 0..1500 {
        let r = player.advance(DISPLAY);
        states.push(r.state);
        if r.state == FrameState::Waiting {
            assert!(
                !states.contains(&FrameState::Exact),
                "waiting only before the first frame (pre-roll)"
            );
            continue;
        }
        let img = player.read_display();
        let mean: f32 = img.chunks(4).map(|p| p[1]).sum::<f32>() / (img.len() / 4) as f32;
        assert!(
            mean > 1e-3,
            "frame {k}: black ({mean}) in state {:?}",
            r.state
        );
        assert!(r.drift >= -1e-6, "frame {k}: negative drift {}", r.drift);
        if k > 0 && states[k - 1] == FrameState::CatchingUp && r.state == FrameState::Exact {
            drift_after.push(r.drift);
        }
    }
    assert!(states.contains(&FrameState::Held), "the stall was felt");
    assert!(
        states.contains(&FrameState::CatchingUp),
        "and caught up smoothly"
    );
    assert!(
        !drift_after.is_empty() && drift_after.iter().all(|d| d.abs() < 1e-6),
        "drift returns to zero: {drift_after:?}"
    );
}

#[test]
fn loops_are_seamless_and_100_hours_land_on_the_exact_frame() {
    let (device, queue) = device();
    let bytes = encode_bytes(
        &sequence(16, 8, 24, InputKind::Hdr),
        &config(SegmentMode::Auto { max: 8 }),
    );
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
    let mut player = unthrottled(&device, &queue, bytes);
    // Across three loop seams at 60 Hz, every frame is exact.
    for _ in 0..(3 * 60 + 10) {
        let r = player.advance(DISPLAY);
        assert_eq!(r.state, FrameState::Exact, "frame at {:.3}", r.target);
    }
    // 100 hours later, in steps of a little over an hour (integer ticks, no float drift).
    let step = 3_600_000_000_000u64 + 7;
    let target_ticks = 100 * 3_600_000_000_000u64 + 1_234_567_891;
    let mut t = player.ticks();
    while t + step < target_ticks {
        player.advance(step);
        t += step;
    }
    let mut r = player.advance(target_ticks - t);
    assert_eq!(player.ticks(), target_ticks);
    // The reader re-synchronised; within the catch-up window the display is exact again.
    for _ in 0..120 {
        if r.state == FrameState::Exact {
            break;
        }
        r = player.advance(DISPLAY);
    }
    assert_eq!(r.state, FrameState::Exact);
    // 24 frames per second, 24-frame loop: the position is the ticks' fraction of a second.
    let expect = (player.ticks() % 1_000_000_000) as f64 * 24.0 / 1e9;
    assert!(
        (r.shown % 24.0 - expect).abs() < 1e-6,
        "shown {} expected {expect}",
        r.shown % 24.0
    );
    let gpu = player.read_display();
    let mut cpu = vec![0f32; 16 * 8 * 3];
    reference.frame(expect, Output::Linear, &mut cpu).unwrap();
    for i in 0..16 * 8 {
        assert!((gpu[i * 4 + 1] - cpu[i * 3 + 1]).abs() <= cpu[i * 3 + 1] * 2f32.powi(-10) + 1e-6);
    }
}

#[test]
fn a_damaged_chunk_mid_stream_is_reported_and_playback_recovers() {
    let (device, queue) = device();
    let mut cfg = config(SegmentMode::Fixed(4));
    cfg.intra_interval_s = 0.5;
    let mut bytes = encode_bytes(&sequence(32, 16, 48, InputKind::Hdr), &cfg);
    let r = Reader::open(Cursor::new(bytes.clone())).unwrap();
    // Damage the coefficients of a segment in the middle.
    let (_, ci) = r.layout().segments[5];
    let e = r.entries()[ci];
    bytes[(e.offset + e.length / 2) as usize] ^= 0xff;
    let mut player = unthrottled(&device, &queue, bytes);
    let mut saw_hold = false;
    for _ in 0..200 {
        let rec = player.advance(DISPLAY);
        saw_hold |= rec.state != FrameState::Exact;
        let img = player.read_display();
        assert!(img.iter().all(|v| v.is_finite()));
    }
    let t = player.totals();
    assert!(t.damaged >= 1, "damage reported");
    let msg = t.last_error.clone().unwrap();
    assert!(
        msg.contains(&format!("chunk {ci}")) && msg.contains("checksum mismatch"),
        "{msg}"
    );
    assert!(saw_hold, "the damaged segment was held over");
}

#[test]
fn threads_stop_and_join_mid_stream() {
    let (device, queue) = device();
    let bytes = encode_bytes(
        &sequence(32, 16, 48, InputKind::Hdr),
        &config(SegmentMode::Fixed(6)),
    );
    let cfg = PlayerConfig {
        throttle: Throttle {
            rate: Some(20_000),
            stall: None,
        },
        clock: Arc::new(vbim_player::SystemClock::new()),
        ..Default::default()
    };
    let mut player = Player::open(&device, &queue, Cursor::new(bytes), cfg).unwrap();
    for _ in 0..5 {
        player.advance(DISPLAY);
        std::thread::sleep(Duration::from_millis(2));
    }
    // A generous deadline that fails with a message, not a timing assertion.
    player
        .stop(Duration::from_secs(10))
        .expect("threads joined");
}

#[test]
fn wait_and_skip_policies() {
    let (device, queue) = device();
    let bytes = encode_bytes(
        &sequence(32, 16, 48, InputKind::Hdr),
        &config(SegmentMode::Fixed(6)),
    );
    let header = header_of(&bytes);
    let rate = (header.file_size as f64 / 2.0 * 0.5) as u64; // half the mean rate: always late
    for policy in [Policy::Wait, Policy::Skip] {
        // No pre-roll: start as soon as the first segment is in, and fall behind.
        let cfg = PlayerConfig {
            preroll_ns: Some(0),
            ..inline(
                policy,
                Throttle {
                    rate: Some(rate),
                    stall: None,
                },
            )
        };
        let mut player = Player::open(&device, &queue, Cursor::new(bytes.clone()), cfg).unwrap();
        let mut last = None;
        let mut max_drift = 0f64;
        for _ in 0..300 {
            let r = player.advance(DISPLAY);
            if r.state == FrameState::Waiting && last.is_none() {
                continue; // pre-roll
            }
            max_drift = max_drift.max(r.drift);
            if policy == Policy::Wait {
                assert!(r.state != FrameState::CatchingUp && r.state != FrameState::Held);
                if let Some(prev) = last {
                    assert!(r.shown >= prev, "wait never goes back");
                }
            } else {
                assert!(r.state != FrameState::CatchingUp && r.state != FrameState::Waiting);
            }
            last = Some(r.shown);
        }
        assert!(
            max_drift > 1.0,
            "{policy:?}: at half the bit rate the display falls behind"
        );
    }
}

/// A real day: Jacksboro baked at 64² with 96 frames (one per 15 minutes) by the bake's
/// own lighting, in memory.
fn jacksboro_day(size: usize, n: usize) -> Vec<Vec<f32>> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/jacksboro.toml");
    let mut scene = vbim_bake::Scene::load(&path).unwrap();
    scene.frames = n;
    scene.size = size;
    let pre = vbim_bake::Precomputed::compute(vbim_bake::load_terrain(&scene).unwrap(), &scene);
    (0..n)
        .map(|i| {
            let mut frame = vec![0f32; size * size * 3];
            vbim_bake::light_frame(&pre, &scene, i, &mut frame);
            frame
        })
        .collect()
}

#[test]
fn the_loop_seam_in_a_sunrise_adds_no_error() {
    let (device, queue) = device();
    let (size, n) = (64, 96);
    let day = jacksboro_day(size, n);
    let greens: Vec<f32> = day
        .iter()
        .map(|f| vbim_format::curve::max_green(f, 3))
        .collect();
    let exposure = vbim_format::curve::exposure_from_max_greens(&greens);
    // The seam goes where the morning changes the picture fastest: the largest mean step of
    // the export curve (what the error metric sees) between two frames of the first half.
    let visible_step = |i: usize| -> f64 {
        let curve = |v: f32| vbim_format::curve::export_curve(v, exposure) as f64;
        let (a, b) = (&day[i], &day[(i + 1) % n]);
        a.iter()
            .zip(b)
            .map(|(x, y)| (curve(*y) - curve(*x)).abs())
            .sum::<f64>()
            / a.len() as f64
    };
    let steepest = (0..n / 2)
        .max_by(|a, b| visible_step(*a).total_cmp(&visible_step(*b)))
        .unwrap();
    // Rotated so that the steepest step falls across the seam: frame n−1 → frame 0.
    let frames: Vec<Vec<f32>> = (0..n)
        .map(|i| day[(i + steepest + 1) % n].clone())
        .collect();
    let src = MemorySource::new(
        "sunrise-seam",
        size,
        size,
        3,
        InputKind::Hdr,
        frames.clone(),
    );
    let bytes = encode_bytes(&src, &config(SegmentMode::Auto { max: 32 }));
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
    let mut player = unthrottled(&device, &queue, bytes);
    let metric = vbim_format::metrics::Metric::Hdr { exposure };
    // Per media frame: MSE of the displayed frame against the source; per display frame,
    // the largest difference against the reference decoder (what the player itself adds).
    let mut mse = vec![Vec::new(); n];
    let mut mid = vec![Vec::new(); n];
    let mut cpu = vec![0f32; size * size * 3];
    // Two loops at 48 Hz: every media frame and every midpoint is shown, the seam twice.
    let step = 1_000_000_000 / 48;
    for _ in 0..4 * n + 1 {
        let r = player.advance(step);
        assert_eq!(
            r.state,
            FrameState::Exact,
            "no stall at the seam ({:.2})",
            r.target
        );
        let f = r.shown % n as f64;
        let gpu = player.read_display();
        let rgb: Vec<f32> = gpu.chunks(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        reference.frame(f, Output::Linear, &mut cpu).unwrap();
        let added = rgb
            .iter()
            .zip(&cpu)
            .map(|(a, b)| (a - b).abs() / b.max(1e-3))
            .fold(0.0, f32::max);
        assert!(
            added <= 2f32.powi(-10),
            "at frame {f:.3}: the GPU differs from the reference by {added}"
        );
        if (f - f.round()).abs() < 1e-4 {
            let k = f.round() as usize % n;
            let e = metric.compare(&frames[k], &rgb);
            mse[k].push(e.sse / e.count as f64);
        } else if (f - f.floor() - 0.5).abs() < 1e-4 {
            // Between two media frames the source has no frame: the midpoint of the two
            // is the reference, for the seam's midpoint and the loop's alike.
            let k = f.floor() as usize % n;
            let blend: Vec<f32> = frames[k]
                .iter()
                .zip(&frames[(k + 1) % n])
                .map(|(a, b)| 0.5 * (a + b))
                .collect();
            let e = metric.compare(&blend, &rgb);
            mid[k].push(e.sse / e.count as f64);
        }
    }
    assert!(
        mse.iter().chain(&mid).all(|m| m.len() >= 2),
        "every media frame and midpoint shown, twice"
    );
    let worst = |m: &Vec<Vec<f64>>| -> Vec<f64> {
        m.iter()
            .map(|m| m.iter().copied().fold(0.0, f64::max))
            .collect()
    };
    let (per_frame, per_mid) = (worst(&mse), worst(&mid));
    let mean = per_frame.iter().sum::<f64>() / n as f64;
    let mid_mean = per_mid.iter().sum::<f64>() / n as f64;
    // The two frames that meet at the seam have no more error than the loop's mean. (The
    // sunrise's own frames a little further on have up to 4× the mean, as they do with no
    // seam there: that is the content, not the seam.)
    for k in [n - 1, 0] {
        assert!(
            per_frame[k] <= mean,
            "frame {k}, at the seam: MSE {:e} over the loop's mean {mean:e}",
            per_frame[k]
        );
    }
    // Halfway across the seam the source itself is a blend of the sunrise's steepest step,
    // which no curve through the frames follows exactly: no more error there than halfway
    // between the sunrise's other frames (±8 frames), nor than 1.25 × the loop's mean at
    // midpoints (mostly the flat night and day; it was 0.79× it when the keyframes'
    // quantisers took their own frame's sensitivity, and 1.05× since they take the most
    // sensitive frame they reach, which lowers the day's error and not the seam's).
    let sunrise: Vec<usize> = (n - 8..n).chain(0..9).collect();
    let sunrise_mid = sunrise.iter().map(|k| per_mid[*k]).sum::<f64>() / sunrise.len() as f64;
    assert!(
        per_mid[n - 1] <= sunrise_mid && per_mid[n - 1] <= 1.25 * mid_mean,
        "halfway across the seam: MSE {:e} over the sunrise's mean at midpoints {sunrise_mid:e} \
         or 1.25 × the loop's {mid_mean:e}",
        per_mid[n - 1]
    );
    // And the frames around it have no more than the sunrise's mean (±8 frames).
    let sunrise_mean = sunrise.iter().map(|k| per_frame[*k]).sum::<f64>() / sunrise.len() as f64;
    for k in [n - 2, n - 1, 0, 1] {
        assert!(
            per_frame[k] <= sunrise_mean,
            "frame {k}, by the seam: MSE {:e} over the sunrise's mean {sunrise_mean:e}",
            per_frame[k]
        );
    }
}

/// The protocol's GPU bound for HDR: within 2^-10 relative, or 1e-6 absolute below 1e-3.
fn within_hdr_bound(g: f32, want: f32) -> bool {
    if want < 1e-3 {
        (g - want).abs() <= 1e-6 + want * 2f32.powi(-10)
    } else {
        (g - want).abs() <= want * 2f32.powi(-10)
    }
}

/// Compares the display with the reference decoder at media time `t` (3-channel HDR):
/// the protocol's GPU bound.
fn assert_display_matches(
    player: &Player<Cursor<Vec<u8>>>,
    reference: &mut Decoder<Cursor<Vec<u8>>>,
    t: f64,
    texels: usize,
    what: &str,
) {
    let gpu = player.read_display();
    let mut cpu = vec![0f32; texels * 3];
    reference.frame(t, Output::Linear, &mut cpu).unwrap();
    for i in 0..texels {
        for c in 0..3 {
            let (g, want) = (gpu[i * 4 + c], cpu[i * 3 + c]);
            assert!(
                within_hdr_bound(g, want),
                "{what}, media time {t:.3}, texel {i} channel {c}: GPU {g} vs CPU {want}"
            );
        }
    }
}

/// An HDR test sequence encoded with fixed segments: its bytes, header, index and layout.
fn stream(
    w: usize,
    h: usize,
    n: usize,
    segment: u32,
) -> (
    Vec<u8>,
    vbim_format::Header,
    Vec<vbim_format::IndexEntry>,
    vbim_format::index::Layout,
) {
    let bytes = encode_bytes(
        &sequence(w, h, n, InputKind::Hdr),
        &config(SegmentMode::Fixed(segment)),
    );
    let r = Reader::open(Cursor::new(bytes.clone())).unwrap();
    let (hd, entries, layout) = (r.header().clone(), r.entries().to_vec(), r.layout().clone());
    (bytes, hd, entries, layout)
}

#[test]
fn keyframes_shared_by_consecutive_segments_are_sent_once() {
    use vbim_player::bench::{DecoderCore, Event, SegmentData};
    let (bytes, h, entries, layout) = stream(32, 16, 48, 6);
    let intra: Vec<usize> = (0..layout.keyframes.len())
        .filter(|&k| entries[layout.keyframes[k]].is_intra())
        .collect();
    assert!(
        intra.len() < layout.keyframes.len(),
        "no predicted keyframe: {intra:?}"
    );
    let mut dec = DecoderCore::new(h.clone(), layout.clone(), entries.clone());
    let mut b = SegmentData::new();
    let mut sent = Vec::new();
    let mut generation = 0;
    // The whole stream, then a seek back to its start: what was sent before no longer
    // counts.
    let order = (0..entries.len()).chain(0..entries.len());
    for (k, i) in order.enumerate() {
        let e = &entries[i];
        if k == entries.len() {
            dec.reset();
            generation += 1;
        }
        let chunk = &bytes[e.offset as usize..(e.offset + e.length) as usize];
        if let Event::Ready(s) = dec.take(i, Some(chunk)) {
            dec.fill(s, generation, 0, &mut b).unwrap();
            assert_eq!(b.keys, [s, layout.keyframe_of_boundary(s + 1)]);
            assert!(b.bytes() > 0 && b.plane_count() == b.steps.len() * 3 + (b.layers - 2) * 3);
            let steps: Vec<usize> = b.steps.iter().map(|st| st.number).collect();
            sent.push((s, steps));
        }
    }
    assert!(sent.len() >= 4, "{sent:?}");
    // The first segment, and the first after the reset, carry K_0 and K_1; the others
    // only their closing keyframe.
    for (n, (s, steps)) in sent.iter().enumerate() {
        let restart = n == 0 || sent[n - 1].0 > *s;
        let closing = layout.keyframe_of_boundary(s + 1);
        if restart {
            assert_eq!(steps, &[0, 1], "{sent:?}");
        } else {
            assert_eq!(steps, &[closing], "{sent:?}");
        }
    }
}

#[test]
fn dropped_segments_leave_the_display_exact_where_it_says_so() {
    // Skip policy at half the mean rate with no pre-roll: the display is always behind, so
    // segments arrive already in the past and are dropped, and the next one (whose K_s the
    // decoder did not stage again) must find that keyframe on the GPU.
    let (device, queue) = device();
    let (w, h, n) = (48, 32, 96);
    let bytes = encode_bytes(&noisy(w, h, n), &config(SegmentMode::Fixed(4)));
    let header = header_of(&bytes);
    let mean_rate = header.file_size as f64 / (n as f64 / 24.0);
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
    // (Each keeps up on average: 2 × 2.5/4 and 1.5 × 3/4 of the mean rate.)
    for (policy, factor, stall) in [
        (Policy::Skip, 2.0, 1_500_000_000),
        (Policy::Interpolate, 1.5, 1_000_000_000),
    ] {
        let cfg = PlayerConfig {
            preroll_ns: Some(0),
            ..inline(
                policy,
                Throttle {
                    rate: Some((mean_rate * factor) as u64),
                    stall: Some(Stall::every(stall, 4_000_000_000)),
                },
            )
        };
        let mut player = Player::open(&device, &queue, Cursor::new(bytes.clone()), cfg).unwrap();
        let mut exact = 0;
        for _ in 0..900 {
            let r = player.advance(DISPLAY);
            if r.state == FrameState::Exact {
                exact += 1;
                if exact % 3 == 0 {
                    let what = format!("{policy:?} at {factor}×, frame {}", r.index);
                    assert_display_matches(
                        &player,
                        &mut reference,
                        r.shown % n as f64,
                        w * h,
                        &what,
                    );
                }
            }
        }
        let t = player.totals();
        eprintln!("{policy:?}: {exact} exact, {t:?}");
        // (Interpolate, decoding ahead, may keep up without a drop.)
        assert!(
            policy != Policy::Skip || t.segments_dropped >= 5,
            "{policy:?}: segments were dropped: {t:?}"
        );
        // A dropped segment still has its keyframes built on the GPU, so the next one
        // plays: drops do not cascade. A 1 or 1.5 s stall misses 6 or 9 segments of 4
        // frames; the reader catches up at twice the display's pace, so up to 6 arrive late
        // (a broken chain would drop every one until the next intra keyframe).
        assert!(
            t.segments_dropped <= 6 * t.stalls,
            "{policy:?}: drops cascade: {t:?}"
        );
        assert!(exact >= 60, "{policy:?}: {exact} exact frames");
        // Coefficient streams go up, not decoded planes: a few times the bytes read (the
        // stream after zstd plus entry points every 128 pairs, about 6% of it; decoded
        // planes would be tens of times).
        let ratio = t.bytes_uploaded as f64 / t.bytes_read as f64;
        eprintln!("{policy:?}: uploaded {:.2}× the bytes read", ratio);
        assert!(
            ratio < 4.5,
            "{policy:?}: uploaded {ratio:.2}× the bytes read: {t:?}"
        );
    }
}

#[test]
fn a_preroll_margin_absorbs_a_stall_while_the_ring_first_fills() {
    let (device, queue) = device();
    let bytes = encode_bytes(&noisy(64, 32, 96), &config(SegmentMode::Fixed(6)));
    let header = header_of(&bytes);
    let rate = (header.file_size as f64 / 4.0 * 1.2) as u64;
    // A 500 ms stall at 300 ms, before the ring has filled, then every 10 s.
    let stall = Stall {
        length_ns: 500_000_000,
        every_ns: 10_000_000_000,
        first_ns: 300_000_000,
    };
    let late = |margin: u64| {
        let cfg = PlayerConfig {
            preroll_margin_ns: margin,
            ..inline(
                Policy::Interpolate,
                Throttle {
                    rate: Some(rate),
                    stall: Some(stall),
                },
            )
        };
        let mut player = Player::open(&device, &queue, Cursor::new(bytes.clone()), cfg).unwrap();
        let base = player.preroll_ns() - margin;
        let late = (0..600)
            .filter(|_| {
                let r = player.advance(DISPLAY);
                if r.state == FrameState::Waiting && r.index < 60 {
                    assert_eq!(r.drift, 0.0, "pre-roll is not drift: {r:?}");
                }
                r.drift > 1.0
            })
            .count();
        (late, base)
    };
    let (without, base) = late(0);
    let (with, _) = late(500_000_000);
    eprintln!("header pre-roll {base} ns: {without} frames late without a margin, {with} with");
    assert!(without > 0, "the start-up stall is felt without a margin");
    assert_eq!(with, 0, "a margin as long as the stall absorbs it");
}

#[test]
fn threaded_playback_shows_the_reference_whenever_it_says_exact() {
    // The reader and decoder on their own threads, the display stepped faster than real
    // time: which frames are exact depends on scheduling, but every one that says so must
    // match the reference (keyframe slots shared across segments, loops included).
    let (device, queue) = device();
    let (w, h, n) = (48, 32, 48);
    let bytes = encode_bytes(&noisy(w, h, n), &config(SegmentMode::Fixed(4)));
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
    let cfg = PlayerConfig {
        clock: Arc::new(vbim_player::SystemClock::new()),
        ..Default::default()
    };
    let mut player = Player::open(&device, &queue, Cursor::new(bytes), cfg).unwrap();
    let mut checked = 0;
    for k in 0..600 {
        let r = player.advance(DISPLAY);
        if r.state == FrameState::Exact && k % 4 == 0 {
            let what = format!("threaded, frame {}", r.index);
            assert_display_matches(&player, &mut reference, r.shown % n as f64, w * h, &what);
            checked += 1;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let t = player.totals().clone();
    player
        .stop(Duration::from_secs(10))
        .expect("threads joined");
    eprintln!("{checked} frames checked, {t:?}");
    assert!(checked >= 20, "{checked} exact frames checked: {t:?}");
    assert!(t.segments_uploaded >= 24, "two loops and more: {t:?}");
}

/// A seek while the ring holds a whole file read before it: nothing decoded or read for
/// the old position may delay the new one. The reader and decoder run on their own
/// threads, the clock is paused (as in an app that seeks, then waits), and most of the
/// day was read before the seek, so that a player which still decoded or showed the
/// stale segments one a frame would need about a hundred frames to show the seek's.
#[test]
fn a_seek_shows_its_frame_without_working_through_what_was_read_before_it() {
    let (device, queue) = device();
    let n = 480;
    let bytes = encode_bytes(
        &sequence(16, 8, n, InputKind::Hdr),
        &config(SegmentMode::Fixed(4)),
    );
    let segments = n / 4;
    let cfg = PlayerConfig {
        ring_bytes: Some(2 * bytes.len()),
        clock: Arc::new(vbim_player::SystemClock::new()),
        ..Default::default()
    };
    // The chunks' bytes (the file less its header and index).
    let chunks: u64 = Reader::open(Cursor::new(&bytes))
        .unwrap()
        .entries()
        .iter()
        .map(|e| e.length)
        .sum();
    let mut player = Player::open(&device, &queue, Cursor::new(bytes), cfg).unwrap();
    // Until the ring (as large as the file) is full, the boxes full behind it; the clock
    // still.
    let (mut last, mut still) = (0, 0);
    for _ in 0..1000 {
        player.advance(0);
        let read = player.totals().bytes_read;
        still = if read == last { still + 1 } else { 0 };
        last = read;
        if still == 20 {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    // The ring and the boxes hold most of the day: a hundred segments or so.
    assert!(
        3 * last >= 2 * chunks,
        "{last} of {chunks} bytes read before the seek"
    );
    // Near the end of the day: every segment before it was read for the old position.
    let frame = (n - 10) as u64;
    player.set_time(frame * 1_000_000_000 / 24);
    let mut shown_after = None;
    for k in 0..segments {
        let r = player.advance(0);
        if r.state == FrameState::Exact {
            assert!((r.shown - frame as f64).abs() < 1e-6, "{r:?}");
            shown_after = Some(k);
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let t = player.totals().clone();
    player
        .stop(Duration::from_secs(10))
        .expect("threads joined");
    // Generous: the seek's chain is a few chunks, read and parsed in milliseconds; 1 s of
    // frames covers a loaded machine, and is still far from the stale segments' count.
    assert!(
        shown_after.is_some_and(|k| k <= 50),
        "the seek's frame was shown after {shown_after:?} frames (None: not in {segments}), \
         {segments} segments having been read before it: {t:?}"
    );
}

/// A moving edge takes tiles in and out of each bubble term from segment to segment: the
/// GPU's bubble planes (one set, rebuilt for every segment) must never keep a tile's
/// terms from the segment before, at any frame — checked against the reference decoder.
#[test]
fn tiles_that_leave_a_term_are_zero_in_the_next_segment() {
    use vbim_format::chunk::read_tilemap;
    let (device, queue) = device();
    let (bytes, h, entries, layout) = stream(96, 32, 96, 8);
    let chunk = |i: usize| {
        let e = &entries[i];
        &bytes[e.offset as usize..(e.offset + e.length) as usize]
    };
    // Otherwise the test could not tell a stale tile from a zero one.
    let members = |s: usize| {
        let (ti, _) = layout.segments[s];
        let len = layout.boundaries[s + 1] - layout.boundaries[s];
        let tiles = read_tilemap(&h, chunk(ti), len).unwrap();
        (0..h.tile_count())
            .flat_map(|t| (0..3).map(move |p| (p, t)))
            .map(|(p, t)| tiles.degree(p, t))
            .collect::<Vec<u8>>()
    };
    let left: usize = (1..layout.segments.len())
        .map(|s| {
            let (a, b) = (members(s - 1), members(s));
            a.iter().zip(&b).filter(|(x, y)| x > y).count()
        })
        .sum();
    assert!(left > 0, "no tile left a term between segments");
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
    let mut player = unthrottled(&device, &queue, bytes.clone());
    // Media frames at 24 fps, one display frame each: every media frame of the loop.
    let mut checked = 0;
    for _ in 0..96 {
        let r = player.advance(41_666_667);
        assert_eq!(r.state, FrameState::Exact);
        assert_display_matches(
            &player,
            &mut reference,
            r.shown % 96.0,
            96 * 32,
            "moving edge",
        );
        checked += 1;
    }
    assert_eq!(checked, 96);
}

#[test]
fn recording_into_the_callers_encoder_shows_what_advance_shows() {
    // A renderer that submits once per frame: `advance_into` its encoder, submit, then
    // `submitted`. Under stalls (uploads, holds, catch-ups), every frame must match a
    // player that submits on its own, bit for bit.
    let (device, queue) = device();
    let bytes = encode_bytes(&noisy(64, 32, 96), &config(SegmentMode::Fixed(6)));
    let header = header_of(&bytes);
    let rate = (header.file_size as f64 / 4.0 * 3.0) as u64;
    let throttle = Throttle {
        rate: Some(rate),
        stall: Some(Stall::every(1_500_000_000, 6_000_000_000)),
    };
    let open = || interpolating(&device, &queue, bytes.clone(), throttle);
    let (mut own, mut embedded) = (open(), open());
    let mut states = Vec::new();
    for k in 0..900 {
        let a = own.advance(DISPLAY);
        let mut encoder = device.create_command_encoder(&Default::default());
        let b = embedded.advance_into(DISPLAY, &mut encoder);
        queue.submit([encoder.finish()]);
        embedded.submitted();
        assert_eq!(
            (a.state, a.shown.to_bits()),
            (b.state, b.shown.to_bits()),
            "frame {k}"
        );
        assert_eq!(
            own.read_display(),
            embedded.read_display(),
            "frame {k}: the displays differ"
        );
        states.push(a.state);
    }
    for s in [FrameState::Exact, FrameState::Held, FrameState::CatchingUp] {
        assert!(states.contains(&s), "{s:?} was shown");
    }
}

/// A header whose checksum is valid but whose buffer model claims 2^62 bytes of read-ahead
/// and a pre-roll of 584 years: the ring is sized from the file instead (it used to abort
/// the allocation), and playback starts within the time it takes to read the whole file.
#[test]
fn a_hostile_buffer_model_is_bounded_by_the_file() {
    let (device, queue) = device();
    let src = sequence(32, 16, 48, InputKind::Hdr);
    let mut bytes = encode_bytes(&src, &config(SegmentMode::Fixed(8)));
    let h = vbim_format::rewrite(&mut bytes, |h, _| {
        for p in &mut h.read_ahead {
            p.bytes = 1 << 62;
            p.preroll_ns = u64::MAX;
        }
    })
    .unwrap();
    let file_size = bytes.len();
    let rate = h.read_ahead[0].rate.max(1);
    let throttle = Throttle {
        rate: Some(rate),
        stall: None,
    };
    let mut player = interpolating(&device, &queue, bytes, throttle);
    // The whole file and a 16-byte header per chunk, at most.
    assert!(
        player.ring_bytes() <= file_size + 16 * (h.chunk_count as usize + 4),
        "ring {} for a {file_size}-byte file",
        player.ring_bytes()
    );
    let whole_file_ns = file_size as u64 * 1_000_000_000 / rate;
    assert!(
        player.preroll_ns() <= whole_file_ns,
        "{}",
        player.preroll_ns()
    );
    let shown = (0..(whole_file_ns / DISPLAY + 120))
        .filter(|_| player.advance(DISPLAY).state != FrameState::Waiting)
        .count();
    assert!(shown > 60, "only {shown} frames shown");
}

/// An index that calls a predicted keyframe intra (checksums recomputed): the CPU decoder
/// and the player both refuse the keyframe instead of the player decoding it against its
/// predecessor and showing a different picture from the reference (27 dB against 92 dB).
#[test]
fn an_intra_flag_that_disagrees_with_the_payload_is_refused_by_both_decoders() {
    use vbim_format::index::FLAG_INTRA;
    let (device, queue) = device();
    let src = sequence(32, 16, 48, InputKind::Hdr);
    let mut bytes = encode_bytes(&src, &config(SegmentMode::Fixed(8)));
    let mut frame = None;
    vbim_format::rewrite(&mut bytes, |_, entries| {
        let k = entries
            .iter()
            .position(|e| e.kind == vbim_format::ChunkKind::Keyframe && !e.is_intra())
            .expect("a smooth day has predicted keyframes");
        entries[k].flags |= FLAG_INTRA;
        frame = Some(entries[k].first_frame);
    })
    .unwrap();
    let frame = frame.unwrap();
    // The CPU reference decoder refuses the frame the keyframe stands at.
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
    let mut out = vec![0f32; 32 * 16 * 3];
    let e = reference
        .frame(frame as f64, Output::Linear, &mut out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("reference"), "{e}");
    // The player reports the chunk damaged.
    let mut player = unthrottled(&device, &queue, bytes);
    for _ in 0..240 {
        player.advance(DISPLAY);
    }
    assert!(player.totals().damaged > 0, "{:?}", player.totals());
}

/// The GPU decode against the reference decoder at every media frame of a looping day and
/// past its loop seam, then after a `set_time` into the middle of its keyframe chain: 8-bit
/// and HDR, 1 and 3 channels, at an odd size and a long thin one. Segments of 2 frames
/// and an intra interval longer than the day make the chain nearly as long as the day
/// (22–23 predicted keyframes), longer than the default 4 s interval allows at 24 fps
/// with segments of 8 frames or more.
#[test]
fn every_frame_matches_the_reference_through_the_longest_chain_a_seek_and_the_loop() {
    let (device, queue) = device();
    // (Format 2 here: its sections decoded to pairs by the decoder thread, the CPU
    // adapter's shape.)
    every_frame_matches_the_reference(&device, &queue, None, &[V1, V2]);
}

#[test]
fn every_frame_matches_the_reference_through_the_longest_chain_a_seek_and_the_loop_on_gl() {
    let (device, queue) = gl_device();
    every_frame_matches_the_reference(&device, &queue, None, &[V1]);
}

/// A hardware GPU decodes in the shape `DecodeShape::GPU` (dispatches of 2048
/// workgroups, a workgroup per piece of a stream, groups of blocks split among 8
/// workgroups; lavapipe, the tests' adapter, in `DecodeShape::CPU`): the same frames as a
/// GPU decodes them, and in slices of 96 (several spans of 32, passes that end inside a
/// slice); format 2's sections both as pairs (the shape's default) and decoded on the GPU
/// as coded (`lanes`, `lanes.wgsl`), and format 3's as coded. (Four tests, not one loop:
/// the test harness runs them side by side, and they are most of this file's time.)
#[test]
fn every_frame_matches_the_reference_as_a_gpu_decodes() {
    as_a_gpu_decodes(2048, false, &[V1, V2]);
}

#[test]
fn every_frame_matches_the_reference_as_a_gpu_decodes_format_2_as_coded() {
    as_a_gpu_decodes(2048, true, &[V2]);
}

#[test]
fn every_frame_matches_the_reference_as_a_gpu_decodes_format_3_as_coded() {
    as_a_gpu_decodes(2048, true, &[V3]);
}

#[test]
fn every_frame_matches_the_reference_as_a_gpu_decodes_in_slices() {
    as_a_gpu_decodes(96, false, &[V1]);
}

fn as_a_gpu_decodes(slice_groups: u32, lanes: bool, formats: &[FormatVersion]) {
    let (device, queue) = device();
    let shape = DecodeShape {
        slice_groups,
        lanes,
        ..DecodeShape::GPU
    };
    every_frame_matches_the_reference(&device, &queue, Some(shape), formats);
}

const V1: FormatVersion = FormatVersion::V1;
const V2: FormatVersion = FormatVersion::V2;
const V3: FormatVersion = FormatVersion::V3;

fn every_frame_matches_the_reference(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    decode_shape: Option<DecodeShape>,
    formats: &[FormatVersion],
) {
    let n = 48;
    // Each in the formats asked for.
    let cases = [
        (InputKind::Hdr, 3, (1000, 600)),
        (InputKind::Srgb8, 3, (4096, 64)),
        (InputKind::Hdr, 1, (4096, 64)),
        (InputKind::Srgb8, 1, (1000, 600)),
    ];
    for (format, (kind, ch, (w, h))) in formats.iter().flat_map(|&f| cases.map(|c| (f, c))) {
        let bytes = encoded_once(&format!("{format:?} {kind:?} {ch} {w}x{h} {n}"), || {
            let mut src = sequence(w, h, n, kind);
            if ch == 1 {
                for f in &mut src.frames {
                    *f = f.iter().step_by(3).copied().collect();
                }
                src.info.channels = 1;
            }
            let mut cfg = config(SegmentMode::Fixed(2));
            cfg.intra_interval_s = 1000.0;
            cfg.format = format;
            encode_bytes(&src, &cfg)
        });
        let r = Reader::open(Cursor::new(bytes.to_vec())).unwrap();
        // The longest run of predicted keyframes (the encoder may still code one intra
        // where that is cheaper).
        let (mut run, mut longest) = (0, 0);
        for &k in &r.layout().keyframes {
            run = if r.entries()[k].is_intra() {
                0
            } else {
                run + 1
            };
            longest = longest.max(run);
        }
        assert!(longest >= 12, "a chain of {longest} predicted keyframes");
        let mut reference = Decoder::new(r).unwrap();
        let cfg = PlayerConfig {
            decode_shape,
            ..inline(Policy::Interpolate, Throttle::UNLIMITED)
        };
        let mut player = Player::open(device, queue, Cursor::new(bytes.to_vec()), cfg).unwrap();
        let what = format!(
            "{format:?}, {kind:?}, {ch} channel(s), {w}×{h}, decode shape {decode_shape:?}"
        );
        let mode = if kind == InputKind::Srgb8 {
            Output::Stored
        } else {
            Output::Linear
        };
        let mut cpu = vec![0f32; w * h * ch];
        let mut worst = 0f32;
        let mut check = |player: &Player<Cursor<Vec<u8>>>, t: f64| {
            let gpu = player.read_display();
            reference.frame(t, mode, &mut cpu).unwrap();
            for i in 0..w * h {
                for c in 0..3 {
                    let (g, want) = (gpu[i * 4 + c], cpu[i * ch + c.min(ch - 1)]);
                    let err = match kind {
                        // In 8-bit codes; at most 0.5.
                        InputKind::Srgb8 => (linear_to_srgb(g) - want).abs() * 255.0 / 0.5,
                        // As a fraction of the HDR bound.
                        _ => {
                            (g - want).abs()
                                / (want * 2f32.powi(-10) + if want < 1e-3 { 1e-6 } else { 0.0 })
                        }
                    };
                    worst = worst.max(err);
                    assert!(
                        err <= 1.0,
                        "{what}, media time {t:.3}, texel {i} channel {c}: GPU {g} vs CPU {want}"
                    );
                }
            }
        };
        // Every media frame of a loop and a quarter (one display frame per media frame).
        let step = 1_000_000_000 / 24 + 1;
        for _ in 0..n + n / 4 {
            let r = player.advance(step);
            assert_eq!(r.state, FrameState::Exact, "{what}, frame {}", r.index);
            check(&player, r.shown % n as f64);
        }
        // Into the middle of the chain, halfway between two frames; the display jumps to
        // the data as soon as it is there (the policy that blends would not be exact).
        player.set_policy(Policy::Skip);
        player.set_time(37_500_000_000 / 24);
        let mut exact = 0;
        for _ in 0..8 {
            let r = player.advance(step);
            if r.state == FrameState::Exact {
                check(&player, r.shown % n as f64);
                exact += 1;
            }
        }
        assert!(exact >= 6, "{what}: {exact} exact frames after the seek");
        assert!(player.totals().seeks >= 1);
        eprintln!(
            "{what}: chain of {longest}, largest GPU difference {:.2} of the protocol's bound",
            worst
        );
    }
}

/// An engine keeps the texture its materials were built with: the player reconstructs
/// into the caller's texture, bit for bit what its own would show, through a stall and
/// the catch-up blend (whose held image then comes from the caller's texture).
#[test]
fn a_callers_texture_gets_what_the_players_own_would_show() {
    let (device, queue) = device();
    // Noisy content and no pre-roll: the ring holds little, so stalls show.
    let (w, h, n) = (48u32, 32u32, 96);
    let bytes = encode_bytes(
        &noisy(w as usize, h as usize, n),
        &config(SegmentMode::Fixed(4)),
    );
    let rate = header_of(&bytes).file_size as f64 / (n as f64 / 24.0) * 1.5;
    let cfg = || PlayerConfig {
        preroll_ns: Some(0),
        ..inline(
            Policy::Interpolate,
            Throttle {
                rate: Some(rate as u64),
                stall: Some(Stall::every(1_000_000_000, 4_000_000_000)),
            },
        )
    };
    let open = || Player::open(&device, &queue, Cursor::new(bytes.clone()), cfg()).unwrap();
    let texture =
        |w, h, usage| device.create_texture(&vbim_player::lightmap_descriptor(w, h, usage));
    use wgpu::TextureUsages as U;
    let (mut own, mut theirs) = (open(), open());
    let e = theirs
        .set_output(Some(&texture(
            w,
            h - 1,
            U::STORAGE_BINDING | U::TEXTURE_BINDING,
        )))
        .unwrap_err();
    assert!(e.to_string().contains("48×32"), "{e}");
    let e = theirs
        .set_output(Some(&texture(w, h, U::STORAGE_BINDING)))
        .unwrap_err();
    assert!(e.to_string().contains("TEXTURE_BINDING"), "{e}");
    let engine = texture(w, h, U::STORAGE_BINDING | U::COPY_SRC | U::TEXTURE_BINDING);
    theirs.set_output(Some(&engine)).unwrap();
    let mut states = std::collections::HashSet::new();
    for i in 0..900 {
        let (a, b) = (own.advance(DISPLAY), theirs.advance(DISPLAY));
        assert_eq!((a.state, a.shown), (b.state, b.shown), "frame {i}");
        states.insert(format!("{:?}", a.state));
        if i % 7 == 0 || a.state == FrameState::CatchingUp {
            let raw = vbim_player::read_texture(&device, &queue, &engine, 8);
            let got: Vec<f32> = bytemuck::cast_slice::<u8, half::f16>(&raw)
                .iter()
                .map(|v| v.to_f32())
                .collect();
            assert!(got == own.read_display(), "frame {i} ({:?})", a.state);
        }
    }
    assert!(states.contains("CatchingUp"), "{states:?}");
}

/// A per-frame decode budget in simulated time: across a loop, a 500 ms stall and a seek
/// into a long predicted chain, no frame records more decode work than the budget, every
/// exact frame matches the reference within the protocol's bound, and nothing is late
/// for the budget; a budget too small for the stream is reported. With lavapipe's cost of
/// a step (its work alone) and with a GPU's (a fixed cost per step beside it).
#[test]
fn a_decode_budget_bounds_every_frame_and_a_budget_too_small_is_reported() {
    let (device, queue) = device();
    let gpu_like = DecodeShape {
        step_cost: 2000,
        ..DecodeShape::CPU
    };
    for shape in [None, Some(gpu_like)] {
        a_decode_budget_bounds_every_frame(&device, &queue, shape);
    }
}

fn a_decode_budget_bounds_every_frame(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    decode_shape: Option<DecodeShape>,
) {
    let (w, h, n) = (64, 48, 96);
    let mut cfg = config(SegmentMode::Fixed(8));
    cfg.intra_interval_s = 1000.0;
    let bytes = encode_bytes(&noisy(w, h, n), &cfg);
    let header = header_of(&bytes);
    let mean_rate = header.file_size as f64 / (n as f64 / 24.0);
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
    let throttle = Throttle {
        rate: Some((mean_rate * 4.0) as u64),
        stall: Some(Stall::every(500_000_000, 6_000_000_000)),
    };
    // The largest decode of the run below, with no limit: all of it in the frame it
    // starts (a segment's, or the seek's rebuild of the chain, which may be larger).
    let seek_to = 88 * 1_000_000_000 / 24 + 5_000_000;
    let whole = {
        let cfg = PlayerConfig {
            decode_budget: Some(u64::MAX),
            decode_shape,
            ..inline(Policy::Interpolate, throttle)
        };
        let mut player = Player::open(device, queue, Cursor::new(bytes.clone()), cfg).unwrap();
        let mut most = (0..600)
            .map(|_| player.advance(DISPLAY).decode_work)
            .max()
            .unwrap();
        player.set_time(seek_to);
        for _ in 0..120 {
            most = most.max(player.advance(DISPLAY).decode_work);
        }
        most
    };
    // Eight frames' share of it, where a segment lasts 20 displayed frames.
    let budget = whole.div_ceil(8);
    let cfg = PlayerConfig {
        decode_budget: Some(budget),
        decode_shape,
        ..inline(Policy::Interpolate, throttle)
    };
    let mut player = Player::open(device, queue, Cursor::new(bytes.clone()), cfg).unwrap();
    let mut check = |player: &mut Player<Cursor<Vec<u8>>>, frames: usize, what: &str| {
        let mut exact = 0;
        for _ in 0..frames {
            let r = player.advance(DISPLAY);
            assert!(
                r.decode_work <= budget,
                "{what}, decode shape {decode_shape:?}, frame {}: {} blocks of decode over a budget of {budget}",
                r.index,
                r.decode_work
            );
            if r.state == FrameState::Exact {
                exact += 1;
                let what = format!("{what}, frame {}", r.index);
                assert_display_matches(player, &mut reference, r.shown % n as f64, w * h, &what);
            }
        }
        exact
    };
    // A loop and a half, through the stall at 6 s.
    let exact = check(&mut player, 600, "playing");
    assert!(exact > 400, "{exact} exact frames of 600");
    // Into the chain's far end: 11 predicted keyframes to rebuild.
    player.set_time(seek_to);
    let exact = check(&mut player, 120, "after the seek");
    assert!(exact > 60, "{exact} exact frames of 120 after the seek");
    let t = player.totals();
    eprintln!("budget {budget} of {whole}: {t:?}");
    assert!(t.stalls >= 1, "{t:?}");
    assert!(t.seeks >= 1, "{t:?}");
    assert_eq!(t.budget_late, 0, "{t:?}");
    assert_eq!(t.over_budget, 0, "{t:?}");
    assert!(
        t.decode_work_max <= budget && t.decode_work_max > budget / 2,
        "{t:?}"
    );

    // A 200th of the largest decode per frame, where a segment lasts 20 displayed frames
    // and its decode takes about 40 steps: most steps run alone, over the budget, and
    // segments come due before they are decoded.
    let small = whole.div_ceil(200);
    let cfg = PlayerConfig {
        decode_budget: Some(small),
        decode_shape,
        ..inline(Policy::Interpolate, Throttle::UNLIMITED)
    };
    let mut player = Player::open(device, queue, Cursor::new(bytes), cfg).unwrap();
    for _ in 0..300 {
        let over = player.totals().over_budget;
        let r = player.advance(DISPLAY);
        // More only where one step costs more than the budget: it runs alone, reported.
        assert!(
            r.decode_work <= small || player.totals().over_budget == over + 1,
            "frame {}: {}",
            r.index,
            r.decode_work
        );
    }
    let t = player.totals();
    assert!(t.budget_late > 0, "{t:?}");
    let said = t.last_error.clone().unwrap_or_default();
    assert!(said.contains("too small"), "{said}");
}

/// Reusing tiles that have not changed enough: at 1000 displayed frames a second (a slow
/// day's pace against the display), every frame stays within (1 + share) times the
/// protocol's bound of the reference at the time it shows, and an unbounded share leaves
/// the lightmap lagging far outside it, so tiles really are kept between frames; with
/// every frame deciding, and with the default probe (frames that skip deciding where few
/// tiles were kept).
#[test]
fn reused_tiles_stay_within_their_share_of_the_bound_and_an_unbounded_share_lags() {
    let (device, queue) = device();
    let (w, h, n) = (64, 48, 48);
    let bytes = encode_bytes(
        &sequence(w, h, n, InputKind::Hdr),
        &config(SegmentMode::Fixed(8)),
    );
    let mut reference = Decoder::new(Reader::open(Cursor::new(bytes.clone())).unwrap()).unwrap();
    let mut cpu = vec![0f32; w * h * 3];
    for probe in [0, 8] {
        let mut worst = Vec::new();
        for share in [0.25f32, 4.0, f32::INFINITY] {
            let cfg = PlayerConfig {
                reuse_share: share,
                reuse_probe: probe,
                ..inline(Policy::Interpolate, Throttle::UNLIMITED)
            };
            let mut player =
                Player::open(&device, &queue, Cursor::new(bytes.clone()), cfg).unwrap();
            let mut most = 0f32;
            for k in 0..600 {
                let r = player.advance(2_000_000);
                if k % 4 != 0 || r.state != FrameState::Exact {
                    continue;
                }
                let gpu = player.read_display();
                reference
                    .frame(r.shown % n as f64, Output::Linear, &mut cpu)
                    .unwrap();
                for i in 0..w * h {
                    for c in 0..3 {
                        let (g, want) = (gpu[i * 4 + c], cpu[i * 3 + c]);
                        let bound = if want < 1e-3 {
                            1e-6 + want * 2f32.powi(-10)
                        } else {
                            want * 2f32.powi(-10)
                        };
                        most = most.max((g - want).abs() / bound);
                    }
                }
            }
            eprintln!("probe {probe}, share {share}: worst error {most:.3} of the bound");
            worst.push(most);
        }
        assert!(worst[0] <= 1.0, "share 0.25: {} of the bound", worst[0]);
        assert!(worst[1] <= 5.0, "share 4: {} of the bound", worst[1]);
        assert!(
            worst[2] > 5.0,
            "an unbounded share: {} of the bound",
            worst[2]
        );
    }
}

/// With no budget (the default), each segment's decode starts in the frame the segment
/// before it goes on screen, which frees what it writes, and is spread evenly over the
/// frames until it is due but the last: a segment of 20 displayed frames leaves at most
/// its margin frame and one more without decode work, and no frame records more than
/// twice the even share or, where one step is larger than the share (a keyframe plane's
/// inverse transform, one slice of 768 blocks here), twice that step.
#[test]
fn without_a_budget_a_decode_starts_at_once_and_spreads_over_the_frames_before_it_is_due() {
    let (device, queue) = device();
    let (w, h, n) = (256, 192, 96);
    let bytes = encode_bytes(&noisy(w, h, n), &config(SegmentMode::Fixed(8)));
    let cfg = inline(Policy::Interpolate, Throttle::UNLIMITED);
    let mut player = Player::open(&device, &queue, Cursor::new(bytes), cfg).unwrap();
    let frames: Vec<_> = (0..330).map(|_| player.advance(DISPLAY)).collect();
    let step = ((w / 8) * (h / 8)) as u64 * vbim_player::PassWeights::LAVAPIPE.key_add as u64 / 4;
    // Runs of frames showing one segment, the first two (the start) and the last
    // (unfinished) left out.
    let mut runs: Vec<Vec<u64>> = Vec::new();
    let mut last = usize::MAX;
    for r in &frames {
        if r.segment != last {
            runs.push(Vec::new());
            last = r.segment;
        }
        runs.last_mut().unwrap().push(r.decode_work);
    }
    let steady = &runs[2..runs.len() - 1];
    assert!(steady.len() >= 10, "{} segments", steady.len());
    for (i, work) in steady.iter().enumerate() {
        assert_eq!(work.len(), 20, "segment {i}: {work:?}");
        assert!(
            work[0] > 0,
            "segment {i}: the next decode waited a frame: {work:?}"
        );
        let idle = work.iter().filter(|&&x| x == 0).count();
        assert!(
            idle <= 2,
            "segment {i}: {idle} frames without decode: {work:?}"
        );
        let share = work.iter().sum::<u64>().div_ceil(work.len() as u64 - 1);
        let most = *work.iter().max().unwrap();
        assert!(
            most <= 2 * share.max(step),
            "segment {i}: {most} against a share of {share} (a step {step}): {work:?}"
        );
    }
}
