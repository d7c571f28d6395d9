//! `--exact`: the delivered mean PSNR is held at or above T, and brought down towards
//! [T, T + 0.5 dB] where a plain encode over-delivers (a day with a static night pools far
//! below the per-segment budget).

use std::io::Cursor;

use vbim_encoder::BAND_DB;
use vbim_encoder::{
    encode, encode_to_tolerance, EncodeReport, EncoderConfig, InputKind, MemorySource, Preset,
};

/// `src` encoded with `cfg` and measured with the reference decoder.
fn measured(src: &MemorySource, cfg: &EncoderConfig) -> EncodeReport {
    let mut stream = Cursor::new(Vec::new());
    let mut rep = encode(src, cfg, &mut stream, &|_, _, _| {}).unwrap();
    rep.verify_bytes(src, stream.get_ref(), "the sequence", &|_, _, _| {})
        .unwrap();
    rep
}

/// Half a day of light with a shadow edge sweeping across, then a static night.
fn day_and_night(w: usize, h: usize, n: usize) -> MemorySource {
    let frames = (0..n)
        .map(|t| {
            let day = (2.0 * std::f32::consts::PI * t as f32 / n as f32)
                .sin()
                .max(0.0);
            (0..w * h)
                .flat_map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let edge =
                        1.0 / (1.0 + (-(x - w as f32 * 2.0 * t as f32 / n as f32) * 0.4).exp());
                    let v = 5e-4 + day * (0.2 + 0.7 * edge) * (0.8 + 0.2 * (y * 0.3).sin());
                    [v, v * 0.9, v * 0.7]
                })
                .collect()
        })
        .collect();
    MemorySource::new("day and night", w, h, 3, InputKind::Hdr, frames)
}

#[test]
fn exact_tolerance_holds_the_budget_with_fewer_bytes() {
    let src = day_and_night(128, 96, 96);
    let cfg = EncoderConfig {
        tolerance_db: 40.0,
        ..EncoderConfig::preset(Preset::Default)
    };
    let dir = tempfile::tempdir().unwrap();
    let mut stream = Cursor::new(Vec::new());
    // The budget as it is (no aim): what `--exact` improves on.
    let as_is = EncoderConfig {
        aim: false,
        ..cfg.clone()
    };
    let mut plain = encode(&src, &as_is, &mut stream, &|_, _, _| {}).unwrap();
    stream.set_position(0);
    plain.verify(&src, stream, "plain", &|_, _, _| {}).unwrap();
    let out = dir.path().join("exact.vbim");
    let exact = encode_to_tolerance(&src, &cfg, &out, &|_, _, _| {}).unwrap();
    let (p0, p1) = (plain.mean_psnr().unwrap(), exact.mean_psnr().unwrap());
    assert!(
        p0 > 40.0 + BAND_DB,
        "the plain encode over-delivers here ({p0:.2} dB)"
    );
    // At least the tolerance, and closer to it than the plain encode. (On content this
    // small the delivered PSNR moves in steps of several dB as segment lengths change, so
    // landing inside the 0.5 dB band is not promised; the benchmark day lands in it.)
    assert!(
        p1 >= 40.0 && p1 < p0,
        "exact delivered {p1:.2} dB, plain {p0:.2} dB; passes {:?}",
        exact.calibration
    );
    assert!(
        exact.bytes < plain.bytes,
        "{} vs {}",
        exact.bytes,
        plain.bytes
    );
    assert_eq!(exact.tolerance_db, 40.0);
    assert!(!exact.calibration.is_empty());
    // The kept file is the one reported; no pass is left behind.
    assert_eq!(std::fs::metadata(&out).unwrap().len(), exact.bytes);
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["exact.vbim"], "only the kept file is left");
}

/// A real day: Aletsch baked at 256² with 72 frames (one per 20 minutes) by the bake's
/// own lighting, in memory. With tiles of 8² it has 1024 of them, so the aim draws a
/// sample rather than using the whole frame.
fn aletsch_day() -> MemorySource {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/aletsch.toml");
    let mut scene = vbim_bake::Scene::load(&path).unwrap();
    let (size, n) = (256, 72);
    scene.frames = n;
    scene.size = size;
    let pre = vbim_bake::Precomputed::compute(vbim_bake::load_terrain(&scene).unwrap(), &scene);
    let frames = (0..n)
        .map(|i| {
            let mut frame = vec![0f32; size * size * 3];
            vbim_bake::light_frame(&pre, &scene, i, &mut frame);
            frame
        })
        .collect();
    MemorySource::new("aletsch", size, size, 3, InputKind::Hdr, frames)
}

#[test]
fn one_pass_delivers_the_tolerance_asked() {
    let src = aletsch_day();
    let measured = |cfg: &EncoderConfig| measured(&src, cfg);
    for t in [40.0, 46.0] {
        let cfg = EncoderConfig {
            tolerance_db: t,
            tile_size: 8,
            worst_margin_db: f64::INFINITY,
            ..EncoderConfig::preset(Preset::Default)
        };
        let plain = measured(&EncoderConfig {
            aim: false,
            ..cfg.clone()
        });
        let aimed = measured(&cfg);
        let (p0, p1) = (plain.mean_psnr().unwrap(), aimed.mean_psnr().unwrap());
        let a = aimed.aim.as_ref().expect("the aim ran");
        eprintln!(
            "T {t}: budget as it is {p0:.2} dB, one pass {p1:.2} dB ({} sample passes)",
            a.passes.len()
        );
        assert!(
            (p1 - t).abs() <= 0.5,
            "T {t}: delivered {p1:.2} dB (the budget as it is: {p0:.2} dB); aim {a:?}"
        );
        assert!(a.sample_texels < 256 * 256, "a sample, not the whole frame");
        assert_eq!(aimed.tolerance_db, t);
        assert_eq!(aimed.internal_tolerance_db, a.internal_db);
    }
    // With the worst-frame floor (the default), no frame more than 7 dB below T (to the
    // sample's accuracy), and the mean at least T.
    let cfg = EncoderConfig {
        tolerance_db: 44.0,
        tile_size: 8,
        ..EncoderConfig::preset(Preset::Default)
    };
    let r = measured(&cfg);
    let (mean, worst) = (r.mean_psnr().unwrap(), r.worst_psnr().unwrap());
    eprintln!("T 44 with the floor: mean {mean:.2} dB, worst frame {worst:.2} dB");
    assert!(
        worst >= 44.0 - 7.0 - 0.5 && mean >= 44.0 - 0.5,
        "mean {mean:.2} dB, worst frame {worst:.2} dB; aim {:?}",
        r.aim
    );
}

/// `frame_raise_db`: the frames raised come out more accurate, the others no worse; a
/// raise per frame that does not match the sequence is refused.
#[test]
fn raised_frames_come_out_more_accurate() {
    let n = 96;
    let src = day_and_night(128, 96, n);
    let measured = |cfg: &EncoderConfig| measured(&src, cfg);
    let cfg = EncoderConfig {
        tolerance_db: 30.0,
        aim: false,
        ..EncoderConfig::preset(Preset::Default)
    };
    let plain = measured(&cfg);
    // The first light, where the error is largest.
    let raised = 0..12;
    let mut raise = vec![0.0; n];
    raise[raised.clone()].fill(8.0);
    let shaped = measured(&EncoderConfig {
        frame_raise_db: raise,
        ..cfg.clone()
    });
    let mean = |r: &vbim_encoder::EncodeReport, f: std::ops::Range<usize>| {
        let k = f.len() as f64;
        r.measured.as_ref().unwrap().frame_psnr[f]
            .iter()
            .sum::<f64>()
            / k
    };
    let (before, after) = (mean(&plain, raised.clone()), mean(&shaped, raised.clone()));
    eprintln!("raised frames: {before:.2} → {after:.2} dB");
    assert!(after >= before + 3.0, "{before:.2} → {after:.2} dB");
    // A raise only tightens: the other frames come out no worse (the day after the raised
    // frames better, its predicted keyframes starting from a more accurate one).
    let rest = |r: &EncodeReport| mean(r, raised.end..n);
    assert!(
        rest(&shaped) >= rest(&plain) - 0.1,
        "{:.2} vs {:.2} dB",
        rest(&plain),
        rest(&shaped)
    );
    assert!(shaped.bytes > plain.bytes);
    let wrong = EncoderConfig {
        frame_raise_db: vec![1.0; n - 1],
        ..cfg.clone()
    };
    let e = encode(&src, &wrong, Cursor::new(Vec::new()), &|_, _, _| {}).unwrap_err();
    assert!(
        e.to_string()
            .contains("95 frame raises for a sequence of 96 frames"),
        "{e}"
    );
    let mut bad = vec![0.0; n];
    bad[7] = f64::NAN;
    let e = EncoderConfig {
        frame_raise_db: bad,
        ..cfg
    }
    .validate()
    .unwrap_err();
    assert!(e.to_string().contains("frame 7's raise NaN dB"), "{e}");
}

#[test]
fn what_the_aim_cannot_deliver_is_named_with_its_reason() {
    // (A delivered promise, which says nothing, is the CLI test's real day.)
    let src = day_and_night(64, 48, 48);
    // 10 dB, the coarsest budget there is, still codes this smooth light far finer: the
    // mean is above the promise, and the report says the budget can go no coarser.
    let coarse = measured(
        &src,
        &EncoderConfig {
            tolerance_db: 10.0,
            ..EncoderConfig::preset(Preset::Default)
        },
    );
    assert!(coarse.mean_psnr().unwrap() > 10.5);
    let said = coarse.shortfalls();
    assert_eq!(said.len(), 1, "{said:?}");
    assert!(said[0].contains("coarsest budget"), "{said:?}");
    // Without the aim the budget is used as it is and nothing is promised.
    let as_is = measured(
        &src,
        &EncoderConfig {
            tolerance_db: 10.0,
            aim: false,
            ..EncoderConfig::preset(Preset::Default)
        },
    );
    assert_eq!(as_is.shortfalls(), Vec::<String>::new());
}
