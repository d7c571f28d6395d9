//! Format versions: an encode in version 2 (the rate-aware quantiser off) decodes to the
//! same frames as in version 1,
//! in fewer bytes, and `convert` turns either into the other byte for byte.

mod common;

use std::io::Cursor;

use vbim_encoder::{convert, encode, EncoderConfig, FormatVersion, MemorySource};
use vbim_encoder::{Preset, SegmentMode};
use vbim_format::decode::{Decoder, Output};
use vbim_format::{ChunkKind, Reader};

const W: usize = 128;
const H: usize = 96;
const FRAMES: usize = 30;

/// A smooth day with a moving shadow edge and some fine, periodic texture.
fn source() -> MemorySource {
    common::moving_edge_day("versions", W, H, FRAMES)
}

/// The sequence coded in `format`, with the rate-aware quantiser off (versions 2 and 3
/// then code version 1's integers).
fn encoded(format: FormatVersion) -> Vec<u8> {
    encoded_with(format, Some(0.0))
}

fn encoded_with(format: FormatVersion, rate_lambda: Option<f32>) -> Vec<u8> {
    let cfg = EncoderConfig {
        format,
        rate_lambda,
        segment: SegmentMode::Auto { max: 8 },
        aim: false,
        ..EncoderConfig::preset(Preset::Default)
    };
    let mut bytes = Vec::new();
    encode(&source(), &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    bytes
}

fn frames(bytes: &[u8]) -> Vec<Vec<f32>> {
    let mut d = Decoder::new(Reader::open(Cursor::new(bytes.to_vec())).unwrap()).unwrap();
    (0..FRAMES)
        .map(|f| {
            let mut out = vec![0f32; W * H * 3];
            d.frame(f as f64, Output::Linear, &mut out).unwrap();
            out
        })
        .collect()
}

/// Bytes of the keyframe and coefficient chunks.
fn payload_bytes(bytes: &[u8]) -> u64 {
    let r = Reader::open(Cursor::new(bytes)).unwrap();
    r.entries()
        .iter()
        .filter(|e| matches!(e.kind, ChunkKind::Keyframe | ChunkKind::Coefficients))
        .map(|e| e.length)
        .sum()
}

fn converted(bytes: &[u8], to: FormatVersion) -> Vec<u8> {
    let mut out = Vec::new();
    convert(
        "test",
        Cursor::new(bytes),
        Cursor::new(&mut out),
        to,
        (
            EncoderConfig::preset(Preset::Default).zstd_level,
            vbim_encoder::Lanes::default(),
        ),
        &|_, _, _| {},
    )
    .unwrap();
    out
}

#[test]
fn versions_2_and_3_decode_as_version_1_in_fewer_bytes_and_convert_every_way() {
    let v1 = encoded(FormatVersion::V1);
    let v2 = encoded(FormatVersion::V2);
    let v3 = encoded(FormatVersion::V3);
    let major = |b: &[u8]| {
        Reader::open(Cursor::new(b))
            .unwrap()
            .header()
            .version_major()
    };
    assert_eq!((major(&v1), major(&v2), major(&v3)), (1, 2, 3));
    assert_eq!(frames(&v1), frames(&v2), "the same planes, bit for bit");
    assert_eq!(frames(&v1), frames(&v3), "the same planes, bit for bit");
    let (p1, p2, p3) = (payload_bytes(&v1), payload_bytes(&v2), payload_bytes(&v3));
    assert!(p2 < p1, "version 2's payloads {p2} B, version 1's {p1} B");
    // Version 3's states cost their final values and lengths.
    assert!(
        p3 < p1 && p3 >= p2,
        "version 3's payloads {p3} B, 2's {p2} B, 1's {p1} B"
    );
    // The same payloads learn the same maps: converting is encoding in the other version.
    assert_eq!(converted(&v1, FormatVersion::V2), v2);
    assert_eq!(converted(&v2, FormatVersion::V1), v1);
    assert_eq!(converted(&v2, FormatVersion::V3), v3);
    assert_eq!(converted(&v3, FormatVersion::V2), v2);
}

#[test]
fn the_rate_aware_quantiser_trades_a_little_error_for_bytes() {
    let plain = encoded(FormatVersion::V2);
    let rated = encoded_with(FormatVersion::V2, None);
    let (p, r) = (payload_bytes(&plain), payload_bytes(&rated));
    assert!(r < p, "with the rate-aware quantiser {r} B, without {p} B");
    // The error it adds is a share of the quantiser's: the RMS error against the source
    // grows by a little.
    let src = source();
    let rms = |bytes: &[u8]| {
        let (mut sum, mut n) = (0f64, 0usize);
        for (f, out) in frames(bytes).iter().enumerate() {
            for (a, b) in out.iter().zip(&src.frames[f]) {
                sum += ((a - b) as f64).powi(2);
                n += 1;
            }
        }
        (sum / n as f64).sqrt()
    };
    let (ep, er) = (rms(&plain), rms(&rated));
    assert!(
        er > ep && er < 1.2 * ep,
        "RMS error {ep} without, {er} with"
    );
}
