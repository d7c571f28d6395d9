//! `--exact`: the delivered mean PSNR is held at or above T, and brought down towards
//! [T, T + 0.5 dB] where a plain encode over-delivers (a day with a static night pools far
//! below the per-segment budget).

use std::io::Cursor;

use vbim_encoder::BAND_DB;
use vbim_encoder::{encode, encode_to_tolerance, EncoderConfig, InputKind, MemorySource, Preset};

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
    let mut plain = encode(&src, &cfg, &mut stream, &|_, _, _| {}).unwrap();
    stream.set_position(0);
    plain.verify(&src, stream, "plain", &|_, _, _| {}).unwrap();
    let out = dir.path().join("exact.vbim");
    let exact = encode_to_tolerance(&src, &cfg, &out, &|_, _, _| {}).unwrap();
    let (p0, p1) = (plain.mean_psnr.unwrap(), exact.mean_psnr.unwrap());
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
