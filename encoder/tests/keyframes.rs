//! Keyframe modes: every keyframe the intra interval does not force is coded intra and
//! predicted, and the smaller is kept.

use std::io::Cursor;

use vbim_encoder::{encode, EncoderConfig, InputKind, MemorySource, Preset, SegmentMode};
use vbim_format::{ChunkKind, Reader};

const W: usize = 32;
const FRAMES: usize = 24;

/// A fine texture, different for every seed: what an intra keyframe pays for in full.
fn texture(seed: u32) -> Vec<f32> {
    (0..W * W)
        .flat_map(|i| {
            let mut h = (i as u32 ^ seed.wrapping_mul(0x9e37_79b9)).wrapping_mul(0x85eb_ca6b);
            h ^= h >> 13;
            h = h.wrapping_mul(0xc2b2_ae35);
            let v = 0.2 + 0.5 * (h >> 8) as f32 / (1u32 << 24) as f32;
            [v, v * 0.9, v * 0.8]
        })
        .collect()
}

/// Whether each keyframe after the first came out intra.
fn intra_keyframes(frames: Vec<Vec<f32>>) -> Vec<bool> {
    let src = MemorySource::new("keyframes", W, W, 3, InputKind::Hdr, frames);
    let cfg = EncoderConfig {
        segment: SegmentMode::Fixed(4),
        rate: (24, 1),
        // The modes at the default budget as it is (the aim would move it).
        aim: false,
        ..EncoderConfig::preset(Preset::Default)
    };
    // The default intra interval (4 s) forces no keyframe of this 1-second sequence.
    assert!(cfg.intra_interval_frames() as usize > FRAMES);
    let mut bytes = Vec::new();
    encode(&src, &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    let reader = Reader::open(Cursor::new(bytes)).unwrap();
    let modes: Vec<bool> = reader
        .entries()
        .iter()
        .filter(|e| e.kind == ChunkKind::Keyframe && e.number > 0)
        .map(|e| e.is_intra())
        .collect();
    assert!(modes.len() >= 4, "{} keyframes", modes.len());
    modes
}

#[test]
fn a_slowly_brightening_picture_is_predicted() {
    // The residual between two keyframes is 2% of the picture: far cheaper than the
    // texture itself.
    let base = texture(1);
    let frames = (0..FRAMES)
        .map(|t| base.iter().map(|v| v * (1.0 + 0.005 * t as f32)).collect())
        .collect();
    let modes = intra_keyframes(frames);
    assert!(modes.iter().all(|&intra| !intra), "{modes:?}");
}

#[test]
fn unrelated_pictures_are_intra() {
    // Each frame its own texture: the residual between two keyframes has twice the
    // variance of either, so intra is the smaller.
    let frames = (0..FRAMES).map(|t| texture(100 + t as u32)).collect();
    let modes = intra_keyframes(frames);
    assert!(modes.iter().all(|&intra| intra), "{modes:?}");
}
