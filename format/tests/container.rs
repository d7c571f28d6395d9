//! Container tests: round trips, truncation at every byte, a flipped bit in every chunk,
//! and hostile headers refused before allocation.

use std::io::Cursor;

use vbim_format::chunk::Payload;
use vbim_format::chunk::{self, TileMap, MODE_INTRA, MODE_PREDICTED};
use vbim_format::decode::{Decoder, Output};
use vbim_format::index::{FLAG_INTRA, FLAG_OPTIONAL};
use vbim_format::payload2;
use vbim_format::plane::{self, Plane};
use vbim_format::plane2::{self, ContextMap};
use vbim_format::{
    ChunkKind, Coding, ColorEncoding, FormatError, Header, Reader, Transfer, Writer,
};
use vbim_format::{ReadAhead, HEADER_SIZE, READ_AHEAD_POINTS};

fn header(frames: u32, segments: u32, looping: bool) -> Header {
    Header {
        version_minor: 0,
        coding: vbim_format::Coding::Pairs,
        width: 20,
        height: 12,
        channels: 3,
        color: ColorEncoding::LinearHdr,
        looping,
        frame_count: frames,
        rate_num: 24,
        rate_den: 1,
        tile_size: 16,
        max_degree: 3,
        transfer: Transfer::LogToe { v0: 1e-3 },
        segment_count: segments,
        keyframe_count: if looping { segments } else { segments + 1 },
        intra_interval: 4,
        chunk_count: 0,
        index_offset: 0,
        file_size: 0,
        read_ahead: [ReadAhead::default(); READ_AHEAD_POINTS],
        index_checksum: 0,
        largest_payload: None,
    }
}

fn planes_with(h: &Header, f: impl Fn(usize, usize, usize) -> f32) -> Vec<Plane> {
    let (w, ht) = chunk::padded_size(h);
    (0..3)
        .map(|p| {
            let mut pl = Plane::zeros(w, ht);
            for y in 0..ht {
                for x in 0..w {
                    pl.data[y * w + x] = f(p, x, y);
                }
            }
            pl
        })
        .collect()
}

fn quantize(planes: &[Plane], step: f32) -> Vec<Vec<[i32; 64]>> {
    planes
        .iter()
        .map(|p| {
            plane::all_blocks(p)
                .map(|(bx, by)| plane::quantize_block(&p.read_block(bx, by), step, 0.0))
                .collect()
        })
        .collect()
}

fn z(raw: &[u8]) -> Vec<u8> {
    zstd::bulk::compress(raw, 3).unwrap()
}

/// A small looping file: 9 frames, boundaries 0, 4, 9; keyframe 1 predicted; degree-3 tiles
/// in segment 0; a metadata chunk and an optional chunk of an unknown kind.
fn sample_file() -> Vec<u8> {
    let mut h = header(9, 2, true);
    h.chunk_count = 1 + 1 + 2 + 1 + 2 + 1;
    let step = 0.01;
    let k0 = planes_with(&h, |p, x, y| {
        2.0 + 0.05 * x as f32 - 0.03 * y as f32 + p as f32 * 0.1
    });
    let k1 = planes_with(&h, |p, x, y| 3.0 + 0.02 * (x + y) as f32 - p as f32 * 0.05);
    let diff: Vec<Plane> = k0
        .iter()
        .zip(&k1)
        .map(|(a, b)| Plane {
            w: a.w,
            h: a.h,
            data: a.data.iter().zip(&b.data).map(|(x, y)| y - x).collect(),
        })
        .collect();
    let mut w = Writer::new(Cursor::new(Vec::new()), h.clone()).unwrap();
    w.write_chunk(
        ChunkKind::Metadata,
        FLAG_OPTIONAL,
        0,
        (0, 0),
        &z(br#"{"sky":[0.2,0.3,0.5]}"#),
    )
    .unwrap();
    let kf0 = z(&chunk::write_keyframe(
        MODE_INTRA,
        &[step; 3],
        &quantize(&k0, step),
    ));
    w.write_chunk(ChunkKind::Keyframe, FLAG_INTRA, 0, (0, 0), &kf0)
        .unwrap();
    let kf1 = z(&chunk::write_keyframe(
        MODE_PREDICTED,
        &[step; 3],
        &quantize(&diff, step),
    ));
    w.write_chunk(ChunkKind::Keyframe, 0, 1, (4, 4), &kf1)
        .unwrap();
    let tiles_n = h.tile_count();
    let t0 = TileMap {
        luma: vec![3; tiles_n],
        chroma: vec![2; tiles_n],
    };
    w.write_chunk(
        ChunkKind::TileMap,
        0,
        0,
        (0, 4),
        &z(&chunk::write_tilemap(&t0, 3)),
    )
    .unwrap();
    let bub = planes_with(&h, |p, x, _| if p == 0 { 0.2 } else { 0.01 * x as f32 });
    let mut blocks = Vec::new();
    let mut steps = Vec::new();
    for k in 2..=3u8 {
        for p in 0..3 {
            let d = t0.degree(p, 0);
            steps.push(step);
            blocks.push(if d >= k {
                quantize(&bub[p..p + 1], step).remove(0)
            } else {
                Vec::new()
            });
        }
    }
    w.write_chunk(
        ChunkKind::Coefficients,
        0,
        0,
        (0, 4),
        &z(&chunk::write_coeffs(3, &steps, &blocks)),
    )
    .unwrap();
    w.write_chunk(ChunkKind::Unknown(77), FLAG_OPTIONAL, 0, (4, 4), b"future")
        .unwrap();
    let t1 = TileMap {
        luma: vec![1; tiles_n],
        chroma: vec![1; tiles_n],
    };
    w.write_chunk(
        ChunkKind::TileMap,
        0,
        1,
        (4, 9),
        &z(&chunk::write_tilemap(&t1, 3)),
    )
    .unwrap();
    w.write_chunk(
        ChunkKind::Coefficients,
        0,
        1,
        (4, 9),
        &z(&chunk::write_coeffs(1, &[], &[])),
    )
    .unwrap();
    let (_, cur) = w.finish().unwrap();
    cur.into_inner()
}

fn decode_all(bytes: &[u8]) -> Result<Vec<Vec<f32>>, FormatError> {
    let reader = Reader::open(Cursor::new(bytes))?;
    let h = reader.header().clone();
    let mut d = Decoder::new(reader).unwrap();
    let mut frames = Vec::new();
    for f in 0..h.frame_count {
        let mut out = vec![0f32; h.texel_count() * 3];
        d.frame(f as f64, Output::Linear, &mut out)?;
        frames.push(out);
    }
    d.reader().metadata()?;
    Ok(frames)
}

#[test]
fn round_trip_header_index_and_frames() {
    let bytes = sample_file();
    let r = Reader::open(Cursor::new(&bytes)).unwrap();
    let h = r.header();
    assert_eq!(
        (h.width, h.height, h.frame_count, h.segment_count),
        (20, 12, 9, 2)
    );
    assert!(h.looping);
    assert_eq!(h.file_size as usize, bytes.len());
    assert_eq!(r.layout().boundaries, vec![0, 4, 9]);
    assert!(h.read_ahead.iter().all(|p| p.rate > 0 && p.bytes > 0));
    // A player asked for f × the mean rate finds the table's point for f (not the one below
    // it through a rounding difference).
    let duration = h.frame_count as f64 / h.fps();
    for (p, f) in h
        .read_ahead
        .iter()
        .zip(vbim_format::buffer_model::RATE_FACTORS)
    {
        let rate = vbim_format::buffer_model::rate_at(h.file_size, duration, f);
        assert_eq!(h.read_ahead_at(rate), Some(*p), "{f}× the mean rate");
    }
    let frames = decode_all(&bytes).unwrap();
    // Frame 0 is keyframe 0: R = G = B ≈ decode(2 + …) in the coded domain, within quantisation.
    let t = Transfer::LogToe { v0: 1e-3 };
    let expect = |c: f32| t.decode_linear(c);
    let y0 = 2.0f32;
    let rgb = vbim_format::color::ycocg_to_rgb([y0, y0 + 0.1, y0 + 0.2]);
    for c in 0..3 {
        let got = frames[0][c];
        let want = expect(rgb[c]);
        assert!(
            (got - want).abs() <= 0.02 * want + 1e-6,
            "channel {c}: {got} vs {want}"
        );
    }
    // Mid-segment frames carry the bubble term: the luma bubble raises frame 2 above the
    // straight line between the keyframes.
    assert!(frames.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
    let mut reader = Reader::open(Cursor::new(&bytes)).unwrap();
    assert_eq!(
        reader.metadata().unwrap().unwrap(),
        r#"{"sky":[0.2,0.3,0.5]}"#
    );
}

#[test]
fn every_truncation_is_an_error() {
    let bytes = sample_file();
    for n in 0..bytes.len() {
        let res = decode_all(&bytes[..n]);
        assert!(res.is_err(), "truncated to {n} bytes decoded without error");
    }
}

#[test]
fn a_flipped_bit_in_any_chunk_is_detected() {
    let bytes = sample_file();
    let r = Reader::open(Cursor::new(&bytes)).unwrap();
    let entries = r.entries().to_vec();
    for (i, e) in entries.iter().enumerate() {
        for bit in [0, 3, 7] {
            for at in [e.offset, e.offset + e.length / 2, e.offset + e.length - 1] {
                let mut bad = bytes.clone();
                bad[at as usize] ^= 1 << bit;
                let mut reader = Reader::open(Cursor::new(&bad)).unwrap();
                match reader.read_chunk(i) {
                    Err(FormatError::ChunkChecksum { chunk, first, last }) => {
                        assert_eq!((chunk, first, last), (i, e.first_frame, e.last_frame));
                        let msg = FormatError::ChunkChecksum { chunk, first, last }.to_string();
                        assert!(
                            msg.contains(&format!("chunk {i}"))
                                && msg.contains("checksum mismatch")
                        );
                    }
                    other => panic!("chunk {i} byte {at} bit {bit}: {other:?}"),
                }
                assert!(decode_all(&bad).is_err() || e.kind == ChunkKind::Unknown(77));
            }
        }
    }
    // And a flipped bit in the header or the index.
    for at in [20usize, HEADER_SIZE - 1, HEADER_SIZE + 5] {
        let mut bad = bytes.clone();
        bad[at] ^= 0x10;
        assert!(Reader::open(Cursor::new(&bad)).is_err(), "byte {at}");
    }
}

/// Rewrites header fields and re-seals the header checksum, as an attacker would.
fn hostile(edit: impl Fn(&mut Header)) -> Result<(), FormatError> {
    let bytes = sample_file();
    let mut h = Reader::open(Cursor::new(&bytes)).unwrap().header().clone();
    edit(&mut h);
    let mut bad = bytes.clone();
    let head = h.to_bytes();
    bad[..head.len()].copy_from_slice(&head);
    decode_all(&bad).map(|_| ())
}

#[test]
fn hostile_headers_are_refused_before_allocation() {
    type Edit = Box<dyn Fn(&mut Header)>;
    let cases: Vec<(&str, Edit)> = vec![
        ("width 2^31", Box::new(|h| h.width = 1 << 31)),
        ("height 0", Box::new(|h| h.height = 0)),
        ("frames 2^32-1", Box::new(|h| h.frame_count = u32::MAX)),
        ("chunks 2^32-1", Box::new(|h| h.chunk_count = u32::MAX)),
        ("chunks +1", Box::new(|h| h.chunk_count += 1)),
        (
            "index past end",
            Box::new(|h| h.index_offset = h.file_size - 10),
        ),
        ("file size huge", Box::new(|h| h.file_size = u64::MAX)),
        ("rate 0", Box::new(|h| h.rate_den = 0)),
        ("tile 7", Box::new(|h| h.tile_size = 7)),
        ("degree 200", Box::new(|h| h.max_degree = 200)),
        ("segments > frames", Box::new(|h| h.segment_count = 1000)),
        ("keyframes off", Box::new(|h| h.keyframe_count = 5)),
        (
            "log v0 NaN",
            Box::new(|h| h.transfer = Transfer::LogToe { v0: f32::NAN }),
        ),
        ("channels 4", Box::new(|h| h.channels = 4)),
        (
            "largest payload 0",
            Box::new(|h| h.largest_payload = Some(0)),
        ),
        (
            "largest payload 2^60",
            Box::new(|h| h.largest_payload = Some(1 << 60)),
        ),
        // Smaller than the payloads are: the first chunk over it is refused, unread.
        (
            "largest payload 8",
            Box::new(|h| h.largest_payload = Some(8)),
        ),
    ];
    for (name, edit) in cases {
        let res = hostile(edit);
        assert!(res.is_err(), "{name}: accepted");
    }
}

#[test]
fn hostile_index_entries_are_refused() {
    let bytes = sample_file();
    let r = Reader::open(Cursor::new(&bytes)).unwrap();
    let h = r.header().clone();
    let n = h.chunk_count as usize;
    for i in 0..n {
        for field in 0..4 {
            let mut e = r.entries().to_vec();
            match field {
                0 => e[i].length = u64::MAX - 3,
                1 => e[i].offset = 0,
                2 => e[i].offset = e[(i + 1) % n].offset,
                _ => e[i].last_frame = u32::MAX,
            }
            let mut raw = Vec::new();
            for x in &e {
                x.write(&mut raw);
            }
            let mut hh = h.clone();
            hh.index_checksum = vbim_format::xxh3(&raw);
            let mut bad = bytes.clone();
            let head = hh.to_bytes();
            let at = hh.index_offset as usize;
            bad[..head.len()].copy_from_slice(&head);
            bad[at..at + raw.len()].copy_from_slice(&raw);
            let ok = Reader::open(Cursor::new(&bad)).is_ok();
            assert!(!ok, "entry {i} field {field} accepted");
        }
    }
}

/// `v1` (a version 1 stream) with its keyframes and coefficients coded as version 2's
/// sections, with `maps`; every other chunk as it was.
fn as_version_2(v1: &[u8], maps: Vec<ContextMap>, shape: plane2::LaneShape) -> Vec<u8> {
    let mut r = Reader::open(Cursor::new(v1)).unwrap();
    let mut h = r.header().clone();
    h.coding = Coding::Lanes(maps.clone(), shape.layout());
    let old = r.header().clone();
    let entries = r.entries().to_vec();
    let mut w = Writer::new(Cursor::new(Vec::new()), h.clone()).unwrap();
    let mut tiles = None;
    for (i, e) in entries.iter().enumerate() {
        let bytes = r.read_chunk(i).unwrap();
        let what = match e.kind {
            ChunkKind::Keyframe => Some(Payload::Keyframe),
            ChunkKind::Coefficients => Some(Payload::Coefficients(tiles.as_ref().unwrap())),
            ChunkKind::TileMap => {
                let len = e.last_frame - e.first_frame;
                tiles = Some(chunk::read_tilemap(&old, &bytes, len).unwrap());
                None
            }
            _ => None,
        };
        let bytes = match what {
            Some(what) => {
                let raw = chunk::payload(&old, what, &bytes, usize::MAX / 4).unwrap();
                payload2::encode(&h, what, &raw, &maps, shape).unwrap()
            }
            None => bytes,
        };
        let frames = (e.first_frame, e.last_frame);
        w.write_chunk(e.kind, e.flags, e.number, frames, &bytes)
            .unwrap();
    }
    w.finish().unwrap().1.into_inner()
}

/// Maps of two histograms each: the DC and count contexts in one, the rest in the other.
fn two_cluster_maps() -> Vec<ContextMap> {
    (0..plane2::FAMILIES)
        .map(|f| ContextMap {
            clusters: 2,
            of: (0..plane2::CONTEXTS)
                .map(|c| u8::from(c >= 22 + f % 2))
                .collect(),
            // The coefficients' cluster has a file-wide table of the small tokens.
            tables: vec![
                None,
                vbim_format::ans::Histogram::from_counts(&[200, 40, 10, 4, 2, 1]),
            ],
        })
        .collect()
}

#[test]
fn version_2_decodes_to_the_same_frames_as_version_1() {
    let v1 = sample_file();
    let shapes = [None, Some(32)].map(|states| plane2::LaneShape {
        bytes: 64,
        symbols_per_state: states,
    });
    let maps_tried = [
        vec![ContextMap::single(); plane2::FAMILIES],
        two_cluster_maps(),
    ];
    for (maps, shape) in maps_tried
        .iter()
        .flat_map(|m| shapes.map(|s| (m.clone(), s)))
    {
        let v2 = as_version_2(&v1, maps.clone(), shape);
        let r = Reader::open(Cursor::new(&v2)).unwrap();
        let h = r.header();
        let major = match shape.symbols_per_state {
            None => 2,
            Some(_) => 3,
        };
        assert_eq!((h.version_major(), h.version_minor), (major, 0));
        // A version 2 header stores version 2's contexts; the others read as cluster 0.
        let stored: Vec<ContextMap> = (maps.iter().cloned())
            .map(|mut m| {
                m.of[plane2::contexts(shape.layout())..].fill(0);
                m
            })
            .collect();
        assert_eq!(h.context_maps(), Some(&stored[..]));
        assert_eq!(h.header_size() as u64, h.index_offset);
        // The largest payload is what the pairs of version 1 took before zstd.
        let h1 = Reader::open(Cursor::new(&v1)).unwrap().header().clone();
        assert_eq!(h.largest_payload, h1.largest_payload);
        assert_eq!(decode_all(&v2).unwrap(), decode_all(&v1).unwrap());
    }
}

#[test]
fn version_2_damage_is_refused_with_the_chunk_named() {
    let v3 = plane2::LaneShape {
        bytes: 64,
        symbols_per_state: Some(32),
    };
    let v2 = as_version_2(&sample_file(), two_cluster_maps(), v3);
    let r = Reader::open(Cursor::new(&v2)).unwrap();
    let h = r.header().clone();
    // Each keyframe and coefficient payload, cut short or with a flipped bit (checksums
    // redone): an error, never a panic; a cut one always an error.
    for e in r.entries() {
        if !matches!(e.kind, ChunkKind::Keyframe) {
            continue;
        }
        let at = e.offset as usize;
        let len = e.length as usize;
        let payload = &v2[at..at + len];
        for cut in 0..len {
            assert!(
                chunk::payload(&h, Payload::Keyframe, &payload[..cut], 1 << 20).is_err(),
                "cut at {cut} of {len}"
            );
        }
        for bit in 0..len * 8 {
            let mut bad = payload.to_vec();
            bad[bit / 8] ^= 1 << (bit % 8);
            let _ = chunk::payload(&h, Payload::Keyframe, &bad, 1 << 20);
        }
    }
    // Damaged maps in the header: refused, the maps named.
    let mut bad = v2.clone();
    let at = 197; // the first map's cluster count (after the 1.1 fields, the length, the family count)
    bad[at] = 0;
    let bad = vbim_format::fuzz::with_checksums(&bad);
    let e = Reader::open(Cursor::new(&bad)).unwrap_err().to_string();
    assert!(e.contains("context map"), "{e}");
}

#[test]
fn unknown_major_version_and_bad_magic() {
    let mut bytes = sample_file();
    bytes[8] = 4;
    match Reader::open(Cursor::new(&bytes)) {
        Err(FormatError::UnsupportedVersion { found: 4, .. }) => {}
        other => panic!("{other:?}"),
    }
    bytes[0] = b'X';
    assert!(matches!(
        Reader::open(Cursor::new(&bytes)),
        Err(FormatError::BadMagic)
    ));
}

#[test]
fn a_compression_bomb_is_refused() {
    // A keyframe chunk whose zstd frame claims a gigabyte.
    let h = header(1, 0, false);
    let bomb = zstd::bulk::compress(&vec![0u8; 8 << 20], 19).unwrap();
    assert!(chunk::read_keyframe(&h, &bomb, None).is_err());
}

#[test]
fn single_frame_sequence() {
    let mut h = header(1, 0, false);
    h.chunk_count = 1;
    let k0 = planes_with(&h, |_, x, _| 1.0 + x as f32 * 0.01);
    let mut w = Writer::new(Cursor::new(Vec::new()), h).unwrap();
    w.write_chunk(
        ChunkKind::Keyframe,
        FLAG_INTRA,
        0,
        (0, 0),
        &z(&chunk::write_keyframe(
            MODE_INTRA,
            &[0.01; 3],
            &quantize(&k0, 0.01),
        )),
    )
    .unwrap();
    let (_, cur) = w.finish().unwrap();
    let frames = decode_all(&cur.into_inner()).unwrap();
    assert_eq!(frames.len(), 1);
}

#[test]
fn version_1_1_states_the_largest_payload_and_1_0_files_read_as_before() {
    let bytes = sample_file();
    let h = Reader::open(Cursor::new(&bytes)).unwrap().header().clone();
    assert_eq!(h.version_minor, 1);
    // The largest decompressed keyframe or coefficient payload, exactly.
    let r = Reader::open(Cursor::new(&bytes)).unwrap();
    let largest = r
        .entries()
        .iter()
        .filter(|e| matches!(e.kind, ChunkKind::Keyframe | ChunkKind::Coefficients))
        .map(|e| {
            let c = &bytes[e.offset as usize..(e.offset + e.length) as usize];
            zstd::bulk::decompress(c, 1 << 24).unwrap().len() as u64
        })
        .max()
        .unwrap();
    assert_eq!(h.largest_payload, Some(largest));
    // The same stream under a 1.0 header (192 bytes, no largest payload; the index stays
    // where it is): read and decoded the same, its payloads bounded by the format alone.
    let mut old = bytes.clone();
    let h10 = Header {
        version_minor: 0,
        coding: vbim_format::Coding::Pairs,
        largest_payload: None,
        ..h.clone()
    };
    let head = h10.to_bytes();
    assert_eq!(head.len(), HEADER_SIZE);
    old[..head.len()].copy_from_slice(&head);
    let r10 = Reader::open(Cursor::new(&old)).unwrap();
    assert_eq!(r10.header().largest_payload, None);
    assert_eq!(decode_all(&old).unwrap(), decode_all(&bytes).unwrap());
    // A 1.1 header too short to hold the field is damaged, not read as 1.0.
    let mut short = old.clone();
    short[10..12].copy_from_slice(&1u16.to_le_bytes());
    let short = vbim_format::fuzz::with_checksums(&short);
    let e = Reader::open(Cursor::new(&short)).unwrap_err().to_string();
    assert!(e.contains("1.1") && e.contains("192"), "{e}");
}
