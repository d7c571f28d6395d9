//! Format 2's keyframe and coefficient payloads (`docs/FORMAT.md`, "Version 2"): the same
//! head as version 1's payload before zstd (mode or degree, plane count, quantiser steps),
//! then every plane's blocks in one coefficient section ([`plane2`]) instead of zero-run
//! pairs through zstd.
//!
//! Readers turn a version 2 payload into version 1's form before zstd ([`to_pairs`]) and
//! decode that as before, so that both versions of a stream decode to the same planes bit
//! for bit; the encoder goes the other way ([`encode`]). The GPU player will read sections
//! itself (`plane2.wgsl`) and skip the pairs.

use crate::dct::N;
use crate::head::{padded_size, TileMap, MODE_INTRA, MODE_PREDICTED};
use crate::header::Header;
use crate::plane2::{self, ContextMap, Geometry, BUBBLE, INTRA_KEY, PREDICTED_KEY};
use crate::{plane, FormatError, Result};

/// What a payload holds.
#[derive(Clone, Copy, Debug)]
pub enum Payload<'a> {
    /// A keyframe: every plane whole.
    Keyframe,
    /// A segment's bubble terms: the tiles `TileMap` gives a degree of k or more, for
    /// each term k ≥ 2 and plane.
    Coefficients(&'a TileMap),
}

/// Where one plane of a payload lies and which maps code it.
#[derive(Clone, Debug)]
pub struct Shape {
    /// Its family ([`plane2::family`]).
    pub family: usize,
    /// Its blocks' places on the padded block grid, in the order the payload lists them:
    /// raster order for a keyframe; member tiles in raster order, each tile's blocks in
    /// raster order, for a bubble plane.
    pub order: Vec<(usize, usize)>,
    /// Blocks across a tile, for a bubble plane.
    pub tile: Option<usize>,
}

/// A payload's head and the shapes of its planes: the head is format 1's (its length in
/// bytes comes first). [`section_planes`] with each plane's blocks listed.
pub fn shapes(h: &Header, what: Payload, bytes: &[u8]) -> Result<(usize, Vec<Shape>)> {
    let (head, planes) = section_planes(h, what, bytes)?;
    let channels = h.channels as usize;
    let (w, ht) = padded_size(h);
    let (bw, bh) = (w / N, ht / N);
    let (ts, tx) = (h.tile_size as usize, h.tiles_x() as usize);
    let shapes = planes
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let order = match what {
                Payload::Keyframe => (0..bw * bh).map(|b| (b % bw, b / bw)).collect(),
                // Term k = i / channels + 2 of plane i % channels: the tiles whose degree
                // reaches k, each tile's blocks in raster order. (Extended tile by tile:
                // collected from a flattened iterator of tiles, the list grew block by
                // block.)
                Payload::Coefficients(tiles) => {
                    let (k, c) = ((i / channels + 2) as u8, i % channels);
                    let mut order = Vec::new();
                    for t in (0..h.tile_count()).filter(|&t| tiles.degree(c, t) >= k) {
                        order.extend(plane::tile_blocks(t, tx, ts));
                    }
                    order
                }
            };
            Shape {
                family: p.family,
                order,
                tile: p.geometry.tile,
            }
        })
        .collect();
    Ok((head, shapes))
}

/// A payload's head and its planes as a coefficient section codes them, without their
/// blocks' places (what [`Section::parse_layout`](plane2::Section::parse_layout) reads:
/// families and grids): checks the head as [`shapes`] does, without listing every block.
pub fn section_planes(
    h: &Header,
    what: Payload,
    bytes: &[u8],
) -> Result<(usize, Vec<plane2::Plane<'static>>)> {
    let planes = h.channels as usize;
    let (w, ht) = padded_size(h);
    let head = bytes
        .get(..4)
        .ok_or_else(|| FormatError::Invalid(format!("a payload of {} bytes", bytes.len())))?;
    let plane = |family, tile| plane2::Plane {
        family,
        geometry: Geometry {
            grid: (w / N, ht / N),
            order: &[],
            tile,
        },
    };
    let (head_len, out) = match what {
        Payload::Keyframe => {
            let kind = match head[0] {
                MODE_INTRA => INTRA_KEY,
                MODE_PREDICTED => PREDICTED_KEY,
                m => return Err(FormatError::Invalid(format!("unknown keyframe mode {m}"))),
            };
            if head[1] as usize != planes {
                return Err(FormatError::Invalid(format!(
                    "{} planes, expected {planes}",
                    head[1]
                )));
            }
            let out = (0..planes)
                .map(|p| plane(plane2::family(kind, p > 0), None))
                .collect();
            (4 + 4 * planes, out)
        }
        Payload::Coefficients(tiles) => {
            let dmax = tiles.max_degree();
            if head[0] != dmax || (dmax > 1 && head[1] as usize != planes) {
                return Err(FormatError::Invalid(format!(
                    "coefficients for degree {} × {} planes, tile map needs {dmax} × {planes}",
                    head[0], head[1]
                )));
            }
            let tile = Some(h.tile_size as usize / N);
            let out = (2..=dmax)
                .flat_map(|_| (0..planes).map(|p| plane(plane2::family(BUBBLE, p > 0), tile)))
                .collect();
            (4 + 4 * (dmax.max(1) as usize - 1) * planes, out)
        }
    };
    if bytes.len() < head_len {
        return Err(FormatError::Invalid(format!(
            "a payload of {} bytes, its head {head_len}",
            bytes.len()
        )));
    }
    Ok((head_len, out))
}

/// A plane's shape and its blocks (64 integers each, zig-zag order).
pub type PlaneBlocks = (Shape, Vec<[i32; N * N]>);

/// The planes of a version 1 payload before zstd (what `chunk::write_keyframe` and
/// `chunk::write_coeffs` return): its head's length, and each plane's shape and blocks.
pub fn planes(h: &Header, what: Payload, raw: &[u8]) -> Result<(usize, Vec<PlaneBlocks>)> {
    let (head, shapes) = shapes(h, what, raw)?;
    let mut pos = head;
    let planes = shapes
        .into_iter()
        .map(|s| {
            let blocks = plane::read_coefficients(raw, &mut pos, s.order.len())?;
            Ok((s, blocks))
        })
        .collect::<Result<Vec<_>>>()?;
    if pos != raw.len() {
        return Err(FormatError::Invalid(format!(
            "{} stray bytes after the planes",
            raw.len() - pos
        )));
    }
    Ok((head, planes))
}

fn geometry<'a>(h: &Header, s: &'a Shape) -> plane2::Plane<'a> {
    let (w, ht) = padded_size(h);
    plane2::Plane {
        family: s.family,
        geometry: Geometry {
            grid: (w / N, ht / N),
            order: &s.order,
            tile: s.tile,
        },
    }
}

/// The counts of each family's contexts' tokens in a version 1 payload before zstd, coded
/// as `layout`'s version codes them: what an encoder learns a file's context maps from
/// (`plane2::context_counts`).
pub fn context_counts(
    h: &Header,
    what: Payload,
    raw: &[u8],
    layout: plane2::Layout,
) -> Result<Vec<Vec<u64>>> {
    let (_, planes) = planes(h, what, raw)?;
    let input: Vec<(plane2::Plane, &[[i32; N * N]])> = planes
        .iter()
        .map(|(s, b)| (geometry(h, s), &b[..]))
        .collect();
    plane2::context_counts(&input, plane2::FAMILIES, layout)
}

/// Codes a version 1 payload before zstd as a version 2 or 3 payload with `maps`, its
/// lanes cut and given states as `shape` says (its layout: the version's).
pub fn encode(
    h: &Header,
    what: Payload,
    raw: &[u8],
    maps: &[ContextMap],
    shape: plane2::LaneShape,
) -> Result<Vec<u8>> {
    let (head, planes) = planes(h, what, raw)?;
    let input: Vec<(plane2::Plane, &[[i32; N * N]])> = planes
        .iter()
        .map(|(s, b)| (geometry(h, s), &b[..]))
        .collect();
    let section = plane2::encode(&input, maps, shape)?;
    let mut out = Vec::with_capacity(head + section.len());
    out.extend_from_slice(&raw[..head]);
    out.extend_from_slice(&section);
    Ok(out)
}

/// A version 2 or 3 payload's planes: each one's blocks, and its lanes' steps and states
/// ([`plane2::lane_symbols`]).
pub fn lane_symbols(h: &Header, what: Payload, bytes: &[u8]) -> Result<Vec<PlaneLanes>> {
    let (maps, layout, head, shapes) = coded(h, what, bytes)?;
    let geometries: Vec<plane2::Plane> = shapes.iter().map(|s| geometry(h, s)).collect();
    let lanes = plane2::lane_symbols(&bytes[head..], &geometries, maps, layout)?;
    Ok(shapes.iter().map(|s| s.order.len()).zip(lanes).collect())
}

/// A plane's blocks, and each of its lanes' steps and states ([`lane_symbols`]).
pub type PlaneLanes = (usize, Vec<(u64, usize)>);

/// What decoding a version 2 or 3 payload's section needs: the file's context maps, its
/// lanes' layout, the head's length (within `bytes`: [`section_planes`] refuses a payload
/// shorter than its head) and the planes' shapes.
fn coded<'h>(
    h: &'h Header,
    what: Payload,
    bytes: &[u8],
) -> Result<(&'h [ContextMap], plane2::Layout, usize, Vec<Shape>)> {
    let (Some(maps), Some(layout)) = (h.context_maps(), h.lane_layout()) else {
        return Err(FormatError::Invalid(
            "a version 1 file has no coefficient sections".into(),
        ));
    };
    let (head, shapes) = shapes(h, what, bytes)?;
    Ok((maps, layout, head, shapes))
}

/// A version 2 payload (`h` holds its file's context maps) as version 1's payload before
/// zstd: the same head, then each plane's blocks as zero-run pairs. Refuses a payload
/// whose pairs would pass `limit` bytes.
pub fn to_pairs(h: &Header, what: Payload, bytes: &[u8], limit: usize) -> Result<Vec<u8>> {
    let (maps, layout, head, shapes) = coded(h, what, bytes)?;
    let geometries: Vec<plane2::Plane> = shapes.iter().map(|s| geometry(h, s)).collect();
    let mut out = bytes[..head].to_vec();
    plane2::decode_each(&bytes[head..], &geometries, maps, layout, |_, blocks| {
        write_pairs(blocks, &mut out);
        if out.len() > limit {
            return Err(FormatError::Invalid(format!(
                "payload decodes to more than {limit} bytes (the format's bound or the header's largest payload)"
            )));
        }
        Ok(())
    })?;
    Ok(out)
}

/// Writes decoded sparse blocks as `plane::write_coefficients` writes dense ones.
fn write_pairs(d: &plane2::Decoded, out: &mut Vec<u8>) {
    plane::write_block_terms(&d.dc, &d.first, &d.count, &d.terms, out);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn section_planes_are_the_shapes_without_their_blocks() {
        let h = Header {
            version_minor: 0,
            coding: crate::Coding::Lanes(
                vec![ContextMap::single(); plane2::FAMILIES],
                plane2::Layout::States,
            ),
            width: 41,
            height: 23,
            channels: 3,
            color: crate::ColorEncoding::LinearHdr,
            looping: false,
            frame_count: 5,
            rate_num: 24,
            rate_den: 1,
            tile_size: 16,
            max_degree: 3,
            transfer: crate::Transfer::LogToe { v0: 1e-3 },
            segment_count: 1,
            keyframe_count: 2,
            intra_interval: 4,
            chunk_count: 5,
            index_offset: 0,
            file_size: 0,
            read_ahead: Default::default(),
            index_checksum: 0,
            largest_payload: None,
        };
        let n = h.tile_count();
        let tiles = TileMap {
            luma: vec![3; n],
            chroma: if h.channels == 3 {
                vec![3; n]
            } else {
                Vec::new()
            },
        };
        let mut head = vec![3u8, h.channels, 0, 0];
        head.extend((0..2 * h.channels as usize).flat_map(|_| 0.5f32.to_le_bytes()));
        for what in [Payload::Keyframe, Payload::Coefficients(&tiles)] {
            let mut bytes = head.clone();
            if matches!(what, Payload::Keyframe) {
                bytes[0] = MODE_INTRA;
                bytes.truncate(4 + 4 * h.channels as usize);
            }
            let (n, full) = shapes(&h, what, &bytes).unwrap();
            let (m, light) = section_planes(&h, what, &bytes).unwrap();
            assert_eq!(n, m);
            assert_eq!(full.len(), light.len());
            for (a, b) in full.iter().zip(&light) {
                assert_eq!(a.family, b.family);
                assert_eq!(a.tile, b.geometry.tile);
                assert!(b.geometry.order.is_empty());
            }
            assert!(section_planes(&h, what, &bytes[..n - 1]).is_err());
        }
    }

    #[test]
    fn sparse_blocks_are_written_as_the_dense_ones_are() {
        let mut s = 1u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) as u32
        };
        let blocks: Vec<[i32; N * N]> = (0..300)
            .map(|b| {
                let mut q = [0i32; N * N];
                q[0] = (next() % 9) as i32 - 4 + b / 50;
                if b % 3 != 0 {
                    for _ in 0..next() % 6 {
                        q[1 + (next() % 63) as usize] = (next() % 7) as i32 - 3;
                    }
                }
                q
            })
            .collect();
        let mut sparse = plane2::Decoded::default();
        for q in &blocks {
            sparse.dc.push(q[0]);
            sparse.first.push(sparse.terms.len() as u32);
            let t: Vec<(u8, i32)> = (1..N * N)
                .filter(|&i| q[i] != 0)
                .map(|i| (i as u8, q[i]))
                .collect();
            sparse.count.push(t.len() as u8);
            sparse.terms.extend(t);
        }
        assert_eq!(sparse.dense(), blocks);
        let (mut a, mut b) = (vec![7u8], vec![7u8]);
        plane::write_coefficients(&blocks, &mut a);
        write_pairs(&sparse, &mut b);
        assert_eq!(a, b);
    }
}
