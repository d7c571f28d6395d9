//! The CPU's share of the GPU parse against a CPU parse: every coefficient stream of a
//! `.vbim` file (1) decompressed, (2) parsed into blocks (`plane::read_blocks`, the
//! reference decoder's parse), and (3) only scanned for entry points (`scan::scan`, what
//! the player's decoder thread does), from which GPU invocations each parse a piece. Times are wall-clock on
//! one thread, best of three passes over the file (run it on a quiet machine).
//!
//! `cargo run --release -p vbim-format --example scan_cost -- FILE`

use std::fs::File;
use std::io::BufReader;
use std::time::Instant;

use vbim_format::chunk::{self, CoeffReader};
use vbim_format::chunk::{scan, ENTRY_PAIRS};
use vbim_format::dct::N;
use vbim_format::plane::{read_blocks, Blocks};
use vbim_format::{ChunkKind, Reader};

/// A raw stream and the blocks of each of its planes.
struct Raw {
    bytes: Vec<u8>,
    planes: Vec<(usize, usize)>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().ok_or("usage: scan_cost FILE")?;
    let every = ENTRY_PAIRS;
    let mut r = Reader::open(BufReader::new(File::open(path)?))?;
    let h = r.header().clone();
    let entries = r.entries().to_vec();
    let (w, ht) = chunk::padded_size(&h);
    let key_blocks = (w / N) * (ht / N);
    let per_tile = (h.tile_size as usize / N).pow(2);
    // The stored chunks, and for each its planes' (start byte in the raw stream, blocks).
    let mut stored = Vec::new();
    let mut raws = Vec::new();
    let mut tiles = None;
    for (i, e) in entries.iter().enumerate() {
        let bytes = r.read_chunk(i)?;
        match e.kind {
            ChunkKind::Keyframe => {
                let raw = zstd::bulk::decompress(&bytes, 1 << 30)?;
                let np = h.channels as usize;
                let mut at = 4 + 4 * np;
                let mut planes = Vec::new();
                let mut q = Blocks::default();
                for _ in 0..np {
                    planes.push((at, key_blocks));
                    read_blocks(&raw, &mut at, key_blocks, &mut q)?;
                }
                raws.push(Raw { bytes: raw, planes });
                stored.push(bytes);
            }
            ChunkKind::TileMap => {
                tiles = Some(chunk::read_tilemap(
                    &h,
                    &bytes,
                    e.last_frame - e.first_frame,
                )?);
            }
            ChunkKind::Coefficients => {
                let t = tiles.take().ok_or("coefficients without a tile map")?;
                let raw = zstd::bulk::decompress(&bytes, 1 << 30)?;
                let c = CoeffReader::open(&h, &bytes, &t)?;
                let np = h.channels as usize;
                let d = c.max_degree() as usize;
                let mut at = 4 + 4 * (d - 1) * np;
                let mut planes = Vec::new();
                let mut q = Blocks::default();
                for k in 2..=d {
                    for p in 0..np {
                        let members = t.degrees(p).iter().filter(|&&x| x as usize >= k).count();
                        let n = members * per_tile;
                        planes.push((at, n));
                        read_blocks(&raw, &mut at, n, &mut q)?;
                    }
                }
                raws.push(Raw { bytes: raw, planes });
                stored.push(bytes);
            }
            _ => {}
        }
    }
    let best = |f: &mut dyn FnMut()| {
        (0..3)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_nanos() as u64
            })
            .min()
            .unwrap()
    };
    let t_zstd = best(&mut || {
        for s in &stored {
            std::hint::black_box(zstd::bulk::decompress(s, 1 << 30).unwrap());
        }
    });
    let mut q = Blocks::default();
    let t_parse = best(&mut || {
        for r in &raws {
            for &(at, n) in &r.planes {
                let mut at = at;
                read_blocks(&r.bytes, &mut at, n, &mut q).unwrap();
                std::hint::black_box(q.len());
            }
        }
    });
    let mut out = Vec::new();
    let mut points = 0;
    let t_scan = best(&mut || {
        points = 0;
        for r in &raws {
            for &(at, n) in &r.planes {
                let mut at = at;
                out.clear();
                scan(&r.bytes, &mut at, n, &mut out).unwrap();
                points += out.len();
                std::hint::black_box(&out);
            }
        }
    });
    let raw_bytes: usize = raws.iter().map(|r| r.bytes.len()).sum();
    let stored_bytes: usize = stored.iter().map(|s| s.len()).sum();
    println!(
        "{path}: {stored_bytes} bytes stored, {raw_bytes} raw, {points} entry points every {every} pairs ({} bytes at 16 each, {:.1}% of the raw streams)",
        points * 16,
        100.0 * (points * 16) as f64 / raw_bytes as f64
    );
    println!("| step | ms | per raw MB |");
    println!("|---|---:|---:|");
    for (name, t) in [
        ("zstd", t_zstd),
        ("parse (read_blocks)", t_parse),
        ("scan for entry points", t_scan),
    ] {
        println!(
            "| {name} | {:.1} | {:.2} ms |",
            t as f64 / 1e6,
            t as f64 / 1e6 / (raw_bytes as f64 / 1e6)
        );
    }
    Ok(())
}
