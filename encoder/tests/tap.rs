//! The encoder's tap (`vbim_encoder::bench::tap`, the `bench` feature) records every
//! keyframe plane and every bubble plane the quantiser is handed, and nothing when off.
#![cfg(feature = "bench")]

mod common;

use std::io::Cursor;

use vbim_encoder::bench::tap::{self, PlaneKind};
use vbim_encoder::{encode, EncoderConfig, MemorySource, Preset, SegmentMode};

const W: usize = 64;
const H: usize = 48;
const FRAMES: usize = 24;

fn source() -> MemorySource {
    common::moving_edge_day("tap", W, H, FRAMES)
}

#[test]
fn the_tap_records_each_plane_the_quantiser_is_handed() {
    let cfg = EncoderConfig {
        segment: SegmentMode::Auto { max: 8 },
        aim: false,
        ..EncoderConfig::preset(Preset::Default)
    };
    // Off: nothing recorded.
    encode(&source(), &cfg, Cursor::new(Vec::new()), &|_, _, _| {}).unwrap();
    assert!(tap::take().is_empty());

    tap::start();
    let report = encode(&source(), &cfg, Cursor::new(Vec::new()), &|_, _, _| {}).unwrap();
    let planes = tap::take();
    let keys: Vec<_> = planes
        .iter()
        .filter(|p| !matches!(p.kind, PlaneKind::Bubble { .. }))
        .collect();
    assert_eq!(keys.len(), report.keyframes as usize * 3);
    let intra = keys
        .iter()
        .filter(|p| p.kind == PlaneKind::IntraKeyframe)
        .count();
    assert_eq!(intra, report.intra_keyframes * 3);
    assert_eq!(
        keys[0].kind,
        PlaneKind::IntraKeyframe,
        "keyframe 0 is coded on its own"
    );
    for (i, p) in keys.iter().enumerate() {
        assert_eq!(p.plane, i % 3);
        assert_eq!(p.data.len(), p.w * p.h);
        assert!(
            p.w >= W && p.h >= H,
            "a whole (padded) plane: {}×{}",
            p.w,
            p.h
        );
        assert!(p.step > 0.0 && p.deadzone >= 0.0 && p.data.iter().all(|v| v.is_finite()));
    }
    // The first keyframe's luma holds the light, not a difference: it varies.
    let luma = &keys[0].data;
    assert!(luma.iter().any(|&v| v != luma[0]));
    // Bubble planes: whole member tiles in a row, a tile high, of terms 2 and up.
    let bubbles: Vec<_> = planes
        .iter()
        .filter(|p| matches!(p.kind, PlaneKind::Bubble { .. }))
        .collect();
    assert!(!bubbles.is_empty(), "a moving edge needs bubble terms");
    for p in bubbles {
        let PlaneKind::Bubble { term } = p.kind else {
            unreachable!()
        };
        assert!(term >= 2);
        assert_eq!(p.w % p.h, 0);
        assert_eq!(p.data.len(), p.w * p.h);
    }
}
