//! Numerical stability at the extremes, and reproducible output (issue: the encoder).

use std::io::Cursor;

use vbim_encoder::{encode, EncoderConfig, InputKind, MemorySource, Preset, SegmentMode};
use vbim_format::decode::{Decoder, Output};
use vbim_format::Reader;

fn source(
    w: usize,
    h: usize,
    channels: usize,
    kind: InputKind,
    frames: Vec<Vec<f32>>,
) -> MemorySource {
    MemorySource::new("memory", w, h, channels, kind, frames)
}

fn run(src: &MemorySource, cfg: &EncoderConfig) -> (Vec<u8>, Vec<Vec<f32>>) {
    let mut bytes = Vec::new();
    encode(src, cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    let reader = Reader::open(Cursor::new(bytes.clone())).unwrap();
    let h = reader.header().clone();
    let mut d = Decoder::new(reader).unwrap();
    let mut frames = Vec::new();
    for i in 0..h.frame_count {
        let mut o = vec![0f32; h.texel_count() * h.channels as usize];
        d.frame(i as f64, Output::Stored, &mut o).unwrap();
        frames.push(o);
    }
    (bytes, frames)
}

fn cfg(max_degree: usize, segment: SegmentMode) -> EncoderConfig {
    EncoderConfig {
        max_degree,
        segment,
        tolerance_db: 50.0,
        // The coding at this budget as it is: the aim would move it to deliver 50 dB
        // pooled, and these signals' per-value bounds assume the budget itself.
        aim: false,
        ..EncoderConfig::preset(Preset::Default)
    }
}

/// Per-texel signals over 40 frames: constant, linear, a step, a one-frame spike.
fn signal(kind: usize, t: usize, x: usize) -> f32 {
    let base = 0.05 + 0.01 * x as f32;
    match kind {
        0 => base,
        1 => base * (1.0 + t as f32 * 0.05),
        2 => {
            if t < 20 {
                base
            } else {
                base * 8.0
            }
        }
        _ => {
            if t == 17 {
                base * 20.0
            } else {
                base
            }
        }
    }
}

#[test]
fn every_degree_on_constant_linear_step_and_spike_signals() {
    let (w, h, n) = (16, 16, 40);
    for kind in 0..4 {
        let frames: Vec<Vec<f32>> = (0..n)
            .map(|t| {
                (0..w * h)
                    .flat_map(|i| {
                        let v = signal(kind, t, i % w);
                        [v, v * 0.9, v * 0.7]
                    })
                    .collect()
            })
            .collect();
        let src = source(w, h, 3, InputKind::Hdr, frames.clone());
        for d in 1..=8 {
            for seg in [
                SegmentMode::Fixed(2),
                SegmentMode::Fixed(13),
                SegmentMode::Auto { max: 40 },
            ] {
                // Not looping: these ramps would jump back at a loop seam.
                let mut c = cfg(d, seg);
                c.looping = false;
                let (_, dec) = run(&src, &c);
                for (t, (a, b)) in frames.iter().zip(&dec).enumerate() {
                    for (i, (x, y)) in a.iter().zip(b).enumerate() {
                        assert!(
                            y.is_finite() && *y >= 0.0,
                            "signal {kind} degree {d} {seg:?}: frame {t} value {i} = {y}"
                        );
                        // A constant is reproduced to quantisation at every degree; a ramp in
                        // linear light is curved in the log domain: within a few percent once
                        // there is a bubble term or the segments adapt.
                        let tol = if kind == 0 { 0.02 } else { 0.04 };
                        let adapts = d >= 2 || matches!(seg, SegmentMode::Auto { .. });
                        if kind == 0 || (kind == 1 && adapts) {
                            assert!(
                                (x - y).abs() <= tol * x + 1e-4,
                                "signal {kind} degree {d} {seg:?}: frame {t}: {y} vs {x}"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn a_segment_of_100000_frames() {
    let n = 100_001;
    let frames: Vec<Vec<f32>> = (0..n)
        .map(|t| {
            let u = t as f32 / (n - 1) as f32;
            (0..64)
                .map(|i| 0.2 + 0.5 * u * u * (1.0 - u) + 0.001 * i as f32)
                .collect()
        })
        .collect();
    let src = source(8, 8, 1, InputKind::Hdr, frames.clone());
    let mut c = cfg(4, SegmentMode::Fixed(100_000));
    c.tile_size = 8;
    c.looping = false;
    let (bytes, dec) = run(&src, &c);
    let r = Reader::open(Cursor::new(bytes)).unwrap();
    assert_eq!(r.layout().boundaries, vec![0, 100_000]);
    // Judged in the protocol's metric (the budget is spent there): every sampled frame
    // within the 50 dB tolerance, and no texel off by more than 3% (at this exposure 3% of
    // the value is about 0.005 on the export scale).
    let greens: Vec<f32> = frames
        .iter()
        .map(|f| vbim_format::curve::max_green(f, 1))
        .collect();
    let e = vbim_format::curve::exposure_from_max_greens(&greens);
    let mut sq = 0.0f64;
    let mut count = 0usize;
    for t in (0..n).step_by(997) {
        for i in 0..64 {
            let (x, y) = (frames[t][i], dec[t][i]);
            assert!((x - y).abs() <= 0.03 * x, "frame {t}: {y} vs {x}");
            let d = vbim_format::curve::export_curve(x, e) - vbim_format::curve::export_curve(y, e);
            sq += (d as f64).powi(2);
            count += 1;
        }
    }
    let psnr = -10.0 * (sq / count as f64).log10();
    assert!(psnr >= 50.0, "mean PSNR {psnr:.2} dB over sampled frames");
}

#[test]
fn hdr_from_1e_minus_4_to_6e4_and_exact_zeros_survive() {
    let (w, h) = (32, 8);
    let value = |i: usize| {
        if i.is_multiple_of(7) {
            0.0
        } else {
            1e-4 * (6e8f32).powf((i % w) as f32 / (w - 1) as f32)
        }
    };
    let frames: Vec<Vec<f32>> = (0..6)
        .map(|_| (0..w * h).flat_map(|i| [value(i); 3]).collect())
        .collect();
    let src = source(w, h, 3, InputKind::Hdr, frames.clone());
    let (_, dec) = run(&src, &cfg(3, SegmentMode::Auto { max: 6 }));
    // The metric's white is the value the exposure maps to 1: 1.5 / 6e4 here. What the
    // protocol weighs — texels brighter than 1% of white — keeps its relative precision,
    // zeros stay below 1% of white, and nothing overflows half-float's 65504.
    let white = 6e4 / 1.5;
    for (a, b) in frames.iter().zip(&dec) {
        for (x, y) in a.iter().zip(b) {
            assert!(
                y.is_finite() && *y >= 0.0 && *y <= 65504.0,
                "{x} decoded as {y}"
            );
            if *x == 0.0 {
                assert!(*y < 0.01 * white, "zero decoded as {y}");
            } else if *x > 0.01 * white {
                assert!((y - x).abs() <= 0.1 * x, "{x} decoded as {y}");
            }
        }
    }
    // And a night-only sequence, whose white is 1e-3: its 1e-4 texels keep their precision.
    let night: Vec<Vec<f32>> = (0..6)
        .map(|t| {
            (0..w * h)
                .flat_map(|i| [1e-4 + 9e-4 * ((i + t) % w) as f32 / w as f32; 3])
                .collect()
        })
        .collect();
    let src = source(w, h, 3, InputKind::Hdr, night.clone());
    let (_, dec) = run(&src, &cfg(3, SegmentMode::Auto { max: 6 }));
    for (a, b) in night.iter().zip(&dec) {
        for (x, y) in a.iter().zip(b) {
            assert!((y - x).abs() <= 0.05 * x, "{x} decoded as {y}");
        }
    }
}

#[test]
fn single_frame_and_non_looping_sequences() {
    for looping in [true, false] {
        let one = source(16, 16, 3, InputKind::Srgb8, vec![vec![0.5; 16 * 16 * 3]]);
        let mut c = cfg(4, SegmentMode::Auto { max: 48 });
        c.looping = looping;
        let (bytes, dec) = run(&one, &c);
        assert_eq!(dec.len(), 1);
        assert!(
            dec[0].iter().all(|v| (v - 0.5).abs() < 1.0 / 255.0),
            "looping {looping}"
        );
        let r = Reader::open(Cursor::new(bytes)).unwrap();
        assert_eq!(r.header().segment_count, if looping { 1 } else { 0 });
    }
    let frames: Vec<Vec<f32>> = (0..9).map(|t| vec![t as f32 / 10.0; 16 * 16]).collect();
    let src = source(16, 16, 1, InputKind::Srgb8, frames.clone());
    let mut c = cfg(2, SegmentMode::Fixed(4));
    c.looping = false;
    let (bytes, dec) = run(&src, &c);
    let r = Reader::open(Cursor::new(bytes)).unwrap();
    assert_eq!(r.layout().boundaries, vec![0, 4, 8]);
    assert!(!r.header().looping);
    for (a, b) in frames.iter().zip(&dec) {
        assert!((a[0] - b[0]).abs() < 1.0 / 255.0);
    }
}

#[test]
fn output_is_identical_across_runs_and_thread_counts() {
    let (w, h, n) = (48, 40, 30);
    let frames: Vec<Vec<f32>> = (0..n)
        .map(|t| {
            (0..w * h)
                .flat_map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let v = 0.3 + 0.25 * ((x * 0.2 + t as f32 * 0.3).sin() * (y * 0.15).cos());
                    [v, v * 0.8, v * 0.6 + 0.01 * t as f32]
                })
                .collect()
        })
        .collect();
    let src = source(w, h, 3, InputKind::Hdr, frames);
    let mut outputs = Vec::new();
    for threads in [1, 2, 1, 3] {
        let mut c = EncoderConfig::preset(Preset::Default);
        c.threads = threads;
        outputs.push(run(&src, &c).0);
    }
    assert!(
        outputs.windows(2).all(|p| p[0] == p[1]),
        "outputs differ between runs or thread counts"
    );
}

#[test]
fn the_aim_settles_on_exact_constant_and_single_frame_sequences() {
    // Constant light is coded exactly at any budget (99 dB): the aim must stop, within the
    // settings' range, and the result be exact. A single frame, an 8-bit grey sequence and
    // the extremes of the tolerance take the same path.
    let flat = source(
        24,
        16,
        3,
        InputKind::Hdr,
        vec![vec![0.25f32; 24 * 16 * 3]; 12],
    );
    let one = source(
        24,
        16,
        1,
        InputKind::Srgb8,
        vec![(0..24 * 16).map(|i| (i % 7) as f32 / 7.0).collect()],
    );
    // (Values k/7 are not on the 8-bit grid: 59 dB is the most an 8-bit decode delivers.)
    for (src, t) in [(&flat, 45.0), (&flat, 99.0), (&one, 10.0), (&one, 55.0)] {
        let cfg = EncoderConfig {
            tolerance_db: t,
            ..EncoderConfig::preset(Preset::Default)
        };
        let mut bytes = Vec::new();
        let mut rep = encode(src, &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
        rep.verify_bytes(src, &bytes, "memory", &|_, _, _| {})
            .unwrap();
        let a = rep.aim.as_ref().expect("the aim ran");
        let p = rep.mean_psnr().unwrap();
        assert!(p >= t - 0.5, "T {t}: {p:.2} dB; {a:?}");
        assert!(
            (10.0..=99.0).contains(&a.internal_db) && a.passes.len() <= 8,
            "T {t}: {a:?}"
        );
        eprintln!("T {t}: {p:.2} dB after {} passes", a.passes.len());
    }
}
