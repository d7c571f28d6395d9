//! Entry points for hostile bytes: the fuzz targets (`fuzz/`) call them, and the regression
//! test (`format/tests/fuzz_corpus.rs`) replays every input the fuzzer kept or found a
//! crash with. Each takes arbitrary bytes and must return — an error is fine — without
//! panicking, hanging or allocating beyond [`FUZZ_LIMITS`].

use std::io::Cursor;

use crate::checksum::xxh3;
use crate::chunk::{self, CoeffReader, TileMap};
use crate::decode::{Decoder, Output};
use crate::header::{Header, HEADER_SIZE};
use crate::index::ENTRY_SIZE;
use crate::plane::Plane;
use crate::plane2;
use crate::{ColorEncoding, Limits, Reader, Transfer};

/// What the targets let a file make the decoder hold: small, so that the fuzzer runs many
/// inputs a second and a limit that is not checked shows as an out-of-memory crash.
pub const FUZZ_LIMITS: Limits = Limits { memory: 64 << 20 };

/// Frames [`decode`] decodes at most (a file may claim ten million).
const MAX_FRAMES: u32 = 64;

/// `data` with every checksum it holds made right — each chunk's in the index, the
/// index's in the header, the header's own — so that a mutated file reaches the semantic
/// checks behind them, as a file crafted by someone who read FORMAT.md would. Fields at
/// the offsets FORMAT.md gives; what lies outside the data is left alone.
pub fn with_checksums(data: &[u8]) -> Vec<u8> {
    let mut v = data.to_vec();
    if v.len() < HEADER_SIZE {
        return v;
    }
    let u32_at = |v: &[u8], i: usize| u32::from_le_bytes(v[i..i + 4].try_into().unwrap());
    let u64_at = |v: &[u8], i: usize| u64::from_le_bytes(v[i..i + 8].try_into().unwrap());
    let (chunks, index) = (u32_at(&v, 60) as usize, u64_at(&v, 64));
    let index_len = chunks.saturating_mul(ENTRY_SIZE);
    if let Some(end) = usize::try_from(index)
        .ok()
        .and_then(|at| at.checked_add(index_len))
        .filter(|&end| end <= v.len())
    {
        let at = end - index_len;
        for e in 0..chunks {
            let entry = at + e * ENTRY_SIZE;
            let (offset, length) = (u64_at(&v, entry + 16), u64_at(&v, entry + 24));
            let range = usize::try_from(offset).ok().and_then(|o| {
                let len = usize::try_from(length).ok()?;
                Some(o..o.checked_add(len)?)
            });
            if let Some(sum) = range.and_then(|r| v.get(r)).map(xxh3) {
                v[entry + 32..entry + 40].copy_from_slice(&sum.to_le_bytes());
            }
        }
        let sum = xxh3(&v[at..end]);
        v[176..184].copy_from_slice(&sum.to_le_bytes());
    }
    let size = (u32_at(&v, 12) as usize).clamp(HEADER_SIZE, v.len());
    let sum = xxh3(&v[..size - 8]);
    v[size - 8..size].copy_from_slice(&sum.to_le_bytes());
    v
}

/// Arbitrary bytes as a whole file (checksums made right: [`with_checksums`]): header,
/// index, metadata, and every chunk read and checked against its checksum.
pub fn container(data: &[u8]) {
    let data = with_checksums(data);
    let Ok(mut r) = Reader::open(Cursor::new(&data)) else {
        return;
    };
    let _ = r.metadata();
    for i in 0..r.entries().len() {
        let _ = r.read_chunk(i);
    }
}

/// Arbitrary bytes as a whole file (checksums made right: [`with_checksums`]), decoded
/// frame by frame (the first `MAX_FRAMES` (64), then the last) by the reference decoder
/// within [`FUZZ_LIMITS`].
pub fn decode(data: &[u8]) {
    let data = with_checksums(data);
    let Ok(r) = Reader::open(Cursor::new(&data)) else {
        return;
    };
    let Ok(mut d) = Decoder::with_limits(r, FUZZ_LIMITS) else {
        return;
    };
    let h = d.header().clone();
    let mut out = vec![0f32; h.texel_count() * h.channels as usize];
    let last = h.frame_count - 1;
    for i in (0..h.frame_count.min(MAX_FRAMES)).chain([last]) {
        if d.frame(i as f64, Output::Stored, &mut out).is_err() {
            return;
        }
    }
}

/// Arbitrary bytes as chunk payloads. The first four bytes pick a small header (size,
/// channels, degree, colour); the rest is read as a keyframe (intra and predicted, parsed
/// to planes and to blocks), as a tile map, and as the coefficients of a tile map the
/// header bytes pick: in version 1, compressed here so that the fuzzer mutates the payload
/// itself rather than a zstd frame, and as it is in version 2 (with context maps the
/// header bytes pick).
pub fn chunks(data: &[u8]) {
    let Some((&[a, b, c, d], payload)) = data.split_first_chunk::<4>() else {
        return;
    };
    let h = small_header(a, b, c, d);
    if let Ok(z) = zstd::bulk::compress(payload, 1) {
        payloads(&h, &z, d);
    }
    for layout in [plane2::Layout::OneState, plane2::Layout::States] {
        payloads(&small_header_2(a, b, c, d, layout), payload, d);
    }
}

/// [`chunks`]' version 2 or 3 header (as `layout` says): `small_header`'s, with context
/// maps of 1 to 3 clusters a family that `d` picks, the even clusters with a file-wide
/// table of small tokens.
pub fn small_header_2(a: u8, b: u8, c: u8, d: u8, layout: plane2::Layout) -> Header {
    let table = crate::ans::Histogram::from_counts(&[30, 20, 10, 5, 2, 1]);
    let maps = (0..plane2::FAMILIES)
        .map(|f| {
            let clusters = 1 + ((d as usize >> f) % 3) as u8;
            plane2::ContextMap {
                clusters,
                of: (0..plane2::CONTEXTS)
                    .map(|i| ((i + f) % clusters as usize) as u8)
                    .collect(),
                tables: (0..clusters)
                    .map(|k| table.clone().filter(|_| k % 2 == 0))
                    .collect(),
            }
        })
        .collect();
    Header {
        coding: crate::Coding::Lanes(maps, layout),
        ..small_header(a, b, c, d)
    }
}

/// [`chunks`]' reads of `z` under header `h`.
fn payloads(h: &Header, z: &[u8], d: u8) {
    let _ = chunk::read_keyframe(h, z, None);
    let (w, ht) = chunk::padded_size(h);
    let zeros: Vec<Plane> = (0..h.channels).map(|_| Plane::zeros(w, ht)).collect();
    let _ = chunk::read_keyframe(h, z, Some(&zeros));
    let _ = chunk::keyframe_streams(h, z, |_, _, s| agrees(s));
    let _ = chunk::read_tilemap(h, z, 4);
    // A tile map of the header's degree, with a pattern of lower degrees.
    let n = h.tile_count();
    let degree = |t: usize| 1 + ((t + d as usize) % h.max_degree as usize) as u8;
    let tiles = TileMap {
        luma: (0..n).map(degree).collect(),
        chroma: if h.channels == 3 {
            (0..n).map(|t| degree(t + 1)).collect()
        } else {
            Vec::new()
        },
    };
    let _ = chunk::read_coeffs(h, z, &tiles);
    if let Ok(mut r) = CoeffReader::open(h, z, &tiles) {
        for k in 2..=r.max_degree() {
            for p in 0..h.channels as usize {
                if r.scan_plane(k, p, |_, s| agrees(s)).is_err() {
                    return;
                }
            }
        }
        let _ = r.finish();
    }
}

/// A stream the scan accepted must parse whole (the GPU parser relies on the scan alone),
/// and its entry points must lie inside it, in order.
fn agrees(s: chunk::Scanned<'_>) {
    let mut pos = 0;
    let parsed = crate::plane::read_blocks(s.stream, &mut pos, s.blocks, &mut Default::default());
    assert!(
        parsed.is_ok() && pos == s.stream.len(),
        "the scan accepted a stream the parser refuses: {parsed:?}"
    );
    assert!(s
        .entries
        .windows(2)
        .all(|w| w[0].byte < w[1].byte && w[0].position <= w[1].position));
    assert!(s.entries.iter().all(|e| (e.byte as usize) < s.stream.len()));
}

/// A valid header of at most 72×72 texels picked by four bytes.
fn small_header(a: u8, b: u8, c: u8, d: u8) -> Header {
    let srgb = c & 2 != 0;
    Header {
        version_minor: 0,
        coding: crate::Coding::Pairs,
        width: 1 + (a % 72) as u32,
        height: 1 + (b % 72) as u32,
        channels: if c & 1 != 0 { 3 } else { 1 },
        color: if srgb {
            ColorEncoding::Srgb8
        } else {
            ColorEncoding::LinearHdr
        },
        looping: false,
        frame_count: 5,
        rate_num: 24,
        rate_den: 1,
        tile_size: if c & 4 != 0 { 16 } else { 8 },
        max_degree: 1 + d % crate::limits::MAX_DEGREE,
        transfer: if srgb {
            Transfer::Srgb
        } else {
            Transfer::LogToe { v0: 1e-3 }
        },
        segment_count: 1,
        keyframe_count: 2,
        intra_interval: 4,
        chunk_count: 5,
        index_offset: 0,
        file_size: 0,
        read_ahead: Default::default(),
        index_checksum: 0,
        largest_payload: None,
    }
}

/// Arbitrary bytes as a format 2 or 3 coefficient section ([`crate::plane2`]). The first
/// four bytes pick a plane of at most 40 × 40 blocks (a keyframe's, or a bubble plane's
/// member tiles of 4 × 4 blocks), a context map of 1 to 8 histograms and the lanes'
/// layout (the top bit of the third: version 3's states); the rest is the section. What
/// decodes must code again to the same blocks.
pub fn plane2(data: &[u8]) {
    let Some((&[a, b, c, d], section)) = data.split_first_chunk::<4>() else {
        return;
    };
    let (order, geometry, map) = plane2_shape(a, b, c, d);
    let plane = plane2::Plane {
        family: 0,
        geometry: plane2::Geometry {
            order: &order,
            ..geometry
        },
    };
    let maps = [map];
    let shape = plane2::LaneShape {
        bytes: 64,
        symbols_per_state: (c & 0x80 != 0).then_some(16),
    };
    let layout = shape.layout();
    if let Ok(blocks) = plane2::decode(section, &[plane], &maps, layout) {
        let again = plane2::encode(&[(plane, &blocks[0][..])], &maps, shape)
            .expect("decoded blocks code again");
        let back = plane2::decode(&again, &[plane], &maps, layout).expect("and decode");
        assert!(
            back == blocks,
            "a section's blocks did not survive coding again"
        );
    }
}

/// The plane and map [`plane2()`] decodes with, from its first four bytes: its blocks'
/// places, its geometry (places left empty) and the map.
pub fn plane2_shape(
    a: u8,
    b: u8,
    c: u8,
    d: u8,
) -> (
    Vec<(usize, usize)>,
    plane2::Geometry<'static>,
    plane2::ContextMap,
) {
    let (w, h) = (1 + a as usize % 40, 1 + b as usize % 40);
    let bubble = c & 1 == 1;
    let clusters = 1 + (c >> 1) % 8;
    let mut order = Vec::new();
    if bubble {
        for ty in 0..h.div_ceil(4) {
            for tx in 0..w.div_ceil(4) {
                if (tx + 7 * ty + d as usize).is_multiple_of(3) {
                    continue;
                }
                for y in ty * 4..(ty * 4 + 4).min(h) {
                    for x in tx * 4..(tx * 4 + 4).min(w) {
                        order.push((x, y));
                    }
                }
            }
        }
    } else {
        order = (0..w * h).map(|i| (i % w, i / w)).collect();
    }
    // Every other cluster with a file-wide table of the small tokens (a chunk that needs
    // another token sends its own).
    let table = crate::ans::Histogram::from_counts(&[40, 20, 10, 5, 3, 2, 1, 1]);
    let map = plane2::ContextMap {
        clusters,
        of: (0..plane2::CONTEXTS)
            .map(|i| ((i * 7 + d as usize) % clusters as usize) as u8)
            .collect(),
        tables: (0..clusters)
            .map(|k| table.clone().filter(|_| k % 2 == 1))
            .collect(),
    };
    let geometry = plane2::Geometry {
        grid: (w, h),
        order: &[],
        tile: bubble.then_some(4),
    };
    (order, geometry, map)
}

/// `cargo fuzz run package`: any bytes as a package file's text. What parses must name only
/// valid weathers and paths inside the package's folder, and write itself out as text that
/// parses to the same package.
pub fn package(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(p) = crate::package::Package::parse(text) else {
        return;
    };
    for w in &p.weathers {
        assert!(crate::package::valid_name(&w.name), "{:?}", w.name);
        for path in std::iter::once(&w.lightmap).chain(&w.sky) {
            assert!(crate::package::valid_track_path(path), "{path:?}");
            assert!(!path.starts_with('/') && !path.split('/').any(|c| c == ".."));
        }
    }
    let again = crate::package::Package::parse(&p.to_json()).expect("its own JSON parses");
    assert_eq!(again, p);
}

#[cfg(test)]
mod tests {
    /// A valid file is left as it is; a damaged one is made to pass its checksums.
    #[test]
    fn with_checksums_fixes_exactly_the_checksums() {
        let file = include_bytes!("../../fuzz/seeds/container/hdr.vbim").to_vec();
        assert_eq!(super::with_checksums(&file), file);
        let last = |bytes: &[u8]| {
            let mut r = crate::Reader::open(std::io::Cursor::new(bytes.to_vec()))?;
            r.read_chunk(r.entries().len() - 1).map(|_| ())
        };
        let mut bad = file.clone();
        let n = bad.len();
        bad[n - 1] ^= 1;
        assert!(last(&bad).is_err());
        last(&super::with_checksums(&bad)).unwrap();
        // The header and index too.
        bad[30] ^= 1;
        assert!(crate::Reader::open(std::io::Cursor::new(&bad)).is_err());
        let fixed = super::with_checksums(&bad);
        assert!(!matches!(
            crate::Reader::open(std::io::Cursor::new(&fixed)),
            Err(crate::FormatError::HeaderChecksum | crate::FormatError::IndexChecksum)
        ));
    }

    /// Every header the chunk target can pick is one a reader would accept.
    #[test]
    fn every_small_header_is_valid() {
        for a in [0, 7, 71, 255] {
            for c in 0..8 {
                for d in 0..=255u8 {
                    let mut h = super::small_header(a, 255 - a, c, d);
                    h.file_size = 1 << 20;
                    h.index_offset = 1 << 16;
                    h.validate(crate::header::HEADER_SIZE as u64)
                        .unwrap_or_else(|e| panic!("{a} {c} {d}: {e}"));
                }
            }
        }
    }
}
