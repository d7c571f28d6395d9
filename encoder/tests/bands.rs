//! Coding in bands: frames too large to hold a segment's worth whole are read a band of
//! tile rows at a time, and the file is the same byte for byte as the whole-frame path's.
//! Real files (EXR as the bake writes them, 8-bit grey PNG), a size that is a multiple of
//! neither the tile nor the EXR block, and content whose degree differs from band to
//! band, so that a band must be quantised before the segment's highest degree is known.

use std::path::Path;

use vbim_bake::{write_frame, FrameFormat};
use vbim_encoder::{encode_file, EncodeReport, EncoderConfig, FormatVersion, FrameSet, Preset};

const W: usize = 200;
const H: usize = 136;
const FRAMES: usize = 30;

/// Light at texel (x, y), frame t: a fine texture under a sky that brightens through the
/// day everywhere, and — in the rows from `sweep_rows.0` to `sweep_rows.1` — a shadow
/// edge sweeping across, which only curves of high degree follow.
fn light(x: usize, y: usize, t: usize, sweep_rows: (usize, usize)) -> f32 {
    let u = t as f32 / FRAMES as f32;
    let mut h = (x as u32).wrapping_mul(0x9e37_79b9) ^ (y as u32).wrapping_mul(0x85eb_ca6b);
    h ^= h >> 15;
    h = h.wrapping_mul(0xc2b2_ae35);
    let albedo = 0.6 + 0.4 * (h >> 8) as f32 / (1u32 << 24) as f32;
    let sky = 0.2 + 0.6 * (std::f32::consts::PI * u).sin();
    let sun = if (sweep_rows.0..sweep_rows.1).contains(&y) {
        let edge = (x as f32 - W as f32 * (1.2 * u - 0.1) - 0.3 * y as f32) / 6.0;
        1.5 / (1.0 + (-edge).exp())
    } else {
        0.0
    };
    albedo * (sky + sun)
}

fn write_hdr(dir: &Path, sweep_rows: (usize, usize)) {
    for t in 0..FRAMES {
        let rgb: Vec<f32> = (0..W * H)
            .flat_map(|i| {
                let v = light(i % W, i / W, t, sweep_rows);
                [v, 0.9 * v, 0.75 * v]
            })
            .collect();
        let path = dir.join(format!("frame_{t:04}.exr"));
        write_frame(&path, W, H, &rgb, FrameFormat::Exr, None, None).unwrap();
    }
}

fn write_grey_png(dir: &Path, sweep_rows: (usize, usize)) {
    for t in 0..FRAMES {
        let px: Vec<u8> = (0..W * H)
            .map(|i| {
                (light(i % W, i / W, t, sweep_rows) * 120.0)
                    .round()
                    .min(255.0) as u8
            })
            .collect();
        image::GrayImage::from_raw(W as u32, H as u32, px)
            .unwrap()
            .save(dir.join(format!("frame_{t:04}.png")))
            .unwrap();
    }
}

/// Encodes `dir` with `cfg` and returns the file and the report.
fn encode(dir: &Path, cfg: &EncoderConfig, name: &str) -> (Vec<u8>, EncodeReport) {
    let frames = FrameSet::open(dir.to_str().unwrap()).unwrap();
    let out = dir.join(name);
    let rep = encode_file(&frames, cfg, &out, &|_, _, _| {}).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    std::fs::remove_file(&out).unwrap();
    (bytes, rep)
}

/// The whole-frame file, and the same sequence coded in bands of 1 and 2 tile rows and
/// in the bands a small memory limit chooses: all the same bytes.
fn bands_match_whole(dir: &Path, cfg: EncoderConfig) {
    let (whole, rep) = encode(dir, &cfg, "whole.vbim");
    assert_eq!(rep.band_tiles, None, "136 rows fit the default limit whole");
    // Content whose highest degree differs between bands, or the test would not reach
    // the case where a band is quantised before the segment's highest degree is known.
    let tx = rep.tiles.0;
    let differs = rep.tile_degrees.iter().any(|seg| {
        let row_max: Vec<u8> = seg.chunks(tx).map(|r| *r.iter().max().unwrap()).collect();
        row_max.windows(2).any(|w| w[0] < w[1])
    });
    assert!(
        differs,
        "no segment whose degree rises from one tile row to the next"
    );
    for band in [1, 2] {
        let c = EncoderConfig {
            band_tiles: Some(band),
            ..cfg.clone()
        };
        let (banded, rep) = encode(dir, &c, &format!("band{band}.vbim"));
        assert_eq!(rep.band_tiles, Some(band));
        assert!(
            banded == whole,
            "bands of {band} tile rows: a different file"
        );
    }
    // A limit too small for whole frames: the plan chooses the bands.
    let limit = rep.memory_estimate / 2;
    let c = EncoderConfig {
        memory_limit: limit,
        ..cfg.clone()
    };
    let (banded, rep) = encode(dir, &c, "limited.vbim");
    let b = rep
        .band_tiles
        .expect("half the whole-frame estimate holds bands");
    assert!(b < rep.tiles.1, "{b} tile rows a band");
    assert!(
        rep.memory_estimate <= limit,
        "{} > {limit}",
        rep.memory_estimate
    );
    assert!(
        banded == whole,
        "bands chosen by the limit: a different file"
    );
}

/// The HDR day (the sweep in the lower rows: the first bands are the simple ones) and
/// its settings without the aim.
fn hdr_day() -> (tempfile::TempDir, EncoderConfig) {
    let dir = tempfile::tempdir().unwrap();
    write_hdr(dir.path(), (70, H));
    let cfg = EncoderConfig {
        aim: false,
        ..EncoderConfig::preset(Preset::Default)
    };
    (dir, cfg)
}

#[test]
fn an_hdr_sequence_coded_in_bands_is_the_whole_frame_file() {
    let (dir, cfg) = hdr_day();
    bands_match_whole(dir.path(), cfg);
}

#[test]
fn a_format_2_sequence_coded_in_bands_is_the_whole_frame_file() {
    // Version 2's rate-aware quantiser prices a segment's tokens: by what its own bands
    // hold, the file would change with the bands.
    let (dir, cfg) = hdr_day();
    let cfg = EncoderConfig {
        format: FormatVersion::V2,
        ..cfg
    };
    let off = EncoderConfig {
        rate_lambda: Some(0.0),
        ..cfg.clone()
    };
    assert!(
        encode(dir.path(), &cfg, "on.vbim").0 != encode(dir.path(), &off, "off.vbim").0,
        "the rate-aware quantiser changes nothing here: the test would not see the bands"
    );
    bands_match_whole(dir.path(), cfg);
}

#[test]
fn a_grey_8_bit_sequence_coded_in_bands_is_the_whole_frame_file() {
    let dir = tempfile::tempdir().unwrap();
    write_grey_png(dir.path(), (20, 90));
    let cfg = EncoderConfig {
        tile_size: 8,
        ..EncoderConfig::preset(Preset::Default)
    };
    bands_match_whole(dir.path(), cfg);
}

#[test]
fn a_limit_that_cannot_hold_one_band_is_refused_before_coding() {
    let dir = tempfile::tempdir().unwrap();
    write_grey_png(dir.path(), (0, 10));
    let frames = FrameSet::open(dir.path().to_str().unwrap()).unwrap();
    let cfg = EncoderConfig {
        memory_limit: 100_000,
        ..EncoderConfig::preset(Preset::Default)
    };
    let out = dir.path().join("x.vbim");
    let e = encode_file(&frames, &cfg, &out, &|_, _, _| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("memory limit") && e.contains("200×136"), "{e}");
    assert!(!out.exists());
}
