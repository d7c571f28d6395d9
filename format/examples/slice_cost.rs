//! What GPU-parallel parsing would cost in bytes: every coefficient stream of a `.vbim`
//! file re-written in independent slices of S blocks (each frequency-major on its own, DC
//! prediction restarting per slice, and a LEB128 table of slice lengths in front), each
//! chunk recompressed with zstd at the encoder's default level, against the same chunks
//! re-written whole. The slices are what a GPU parse pass would hand one invocation each.
//!
//! `cargo run --release -p vbim-format --example slice_cost -- FILE [S ...]`

use std::fs::File;
use std::io::BufReader;

use vbim_format::chunk::{self, CoeffReader};
use vbim_format::dct::N;
use vbim_format::plane::{read_blocks, write_coefficients, Blocks};
use vbim_format::{ChunkKind, Reader};

/// zstd level of the default preset.
const LEVEL: i32 = 9;

fn blocks_of(s: chunk::Scanned<'_>) -> Vec<[i32; N * N]> {
    let mut q = Blocks::default();
    read_blocks(s.stream, &mut 0, s.blocks, &mut q).expect("scanned streams parse");
    (0..q.len()).map(|b| q.block(b)).collect()
}

/// One plane's stream, whole (`slice` = 0), in slices of `slice` blocks each coded
/// frequency-major on its own (`slice` > 0), or frequency-major across the plane with
/// each frequency's stream cut every `−slice` blocks (`slice` < 0: the order stays the
/// whole stream's, with a run ended at every cut).
fn write_plane(blocks: &[[i32; N * N]], slice: isize, out: &mut Vec<u8>) {
    if slice == 0 {
        write_coefficients(blocks, out);
        return;
    }
    if slice < 0 {
        let s = (-slice) as usize;
        let mut parts: Vec<Vec<u8>> = Vec::new();
        for f in 0..N * N {
            for c in blocks.chunks(s) {
                let mut v = Vec::new();
                let mut w = vbim_format::plane::RunWriter::new(&mut v);
                let mut prev = 0i32;
                for b in c {
                    if f == 0 {
                        w.value(b[0].wrapping_sub(prev));
                        prev = b[0];
                    } else {
                        w.value(b[f]);
                    }
                }
                w.finish();
                parts.push(v);
            }
        }
        write_parts(parts, out);
        return;
    }
    let slice = slice as usize;
    let parts: Vec<Vec<u8>> = blocks
        .chunks(slice)
        .map(|c| {
            let mut v = Vec::new();
            write_coefficients(c, &mut v);
            v
        })
        .collect();
    write_parts(parts, out);
}

/// Independently parseable pieces, after a LEB128 table of their lengths.
fn write_parts(parts: Vec<Vec<u8>>, out: &mut Vec<u8>) {
    for p in &parts {
        put_leb128(out, p.len() as u32);
    }
    for p in parts {
        out.extend(p);
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().ok_or("usage: slice_cost FILE [S ...]")?;
    let mut sizes: Vec<isize> = args[1..]
        .iter()
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    if sizes.is_empty() {
        sizes = vec![64, 256, 1024, -64, -256, -1024];
    }
    let mut all = vec![0];
    all.extend(sizes);
    let mut r = Reader::open(BufReader::new(File::open(path)?))?;
    let h = r.header().clone();
    let entries = r.entries().to_vec();
    // Per slice size: compressed bytes, raw bytes; and the file's own chunk bytes.
    let (mut zipped, mut raw) = (vec![0u64; all.len()], vec![0u64; all.len()]);
    let (mut stored, mut terms) = (0u64, 0u64);
    let mut tiles = None;
    for (i, e) in entries.iter().enumerate() {
        let bytes = r.read_chunk(i)?;
        let mut planes: Vec<Vec<[i32; N * N]>> = Vec::new();
        let mut head = Vec::new();
        match e.kind {
            ChunkKind::Keyframe => {
                chunk::keyframe_streams(&h, &bytes, |_, step, s| {
                    head.extend(step.to_le_bytes());
                    planes.push(blocks_of(s));
                })?;
            }
            ChunkKind::TileMap => {
                let seg_len = e.last_frame - e.first_frame;
                tiles = Some(chunk::read_tilemap(&h, &bytes, seg_len)?);
                continue;
            }
            ChunkKind::Coefficients => {
                let t = tiles.take().ok_or("coefficients without a tile map")?;
                let mut c = CoeffReader::open(&h, &bytes, &t)?;
                for k in 2..=c.max_degree() {
                    for p in 0..h.channels as usize {
                        c.scan_plane(k, p, |step, s| {
                            head.extend(step.to_le_bytes());
                            planes.push(blocks_of(s));
                        })?;
                    }
                }
                c.finish()?;
            }
            _ => continue,
        }
        stored += bytes.len() as u64;
        terms += planes
            .iter()
            .flatten()
            .map(|b| b.iter().filter(|&&v| v != 0).count() as u64)
            .sum::<u64>();
        for (j, &s) in all.iter().enumerate() {
            let mut out = head.clone();
            for p in &planes {
                write_plane(p, s, &mut out);
            }
            raw[j] += out.len() as u64;
            zipped[j] += zstd::bulk::compress(&out, LEVEL)?.len() as u64;
        }
    }
    println!("{path}: keyframe and coefficient chunks {stored} bytes, {terms} non-zero terms");
    println!("| slice (blocks) | zstd bytes | vs whole | raw bytes | raw / zstd |");
    println!("|---:|---:|---:|---:|---:|");
    for (j, &s) in all.iter().enumerate() {
        println!(
            "| {} | {} | {:+.2}% | {} | {:.2} |",
            if s == 0 {
                "whole".to_string()
            } else {
                s.to_string()
            },
            zipped[j],
            100.0 * (zipped[j] as f64 / zipped[0] as f64 - 1.0),
            raw[j],
            raw[j] as f64 / zipped[j] as f64
        );
    }
    Ok(())
}

/// An unsigned LEB128 varint (the slice-length table's coding).
fn put_leb128(out: &mut Vec<u8>, mut u: u32) {
    while u >= 0x80 {
        out.push(u as u8 | 0x80);
        u >>= 7;
    }
    out.push(u as u8);
}
