//! What the CPU's share of a GPU parse of today's streams would cost: every coefficient
//! stream of a `.vbim` file (1) decompressed, (2) parsed into blocks as the player's
//! decoder parses it now (`plane::read_blocks`), and (3) only scanned for entry points —
//! every `E` pairs, the byte offset, the coefficient position and the running DC — from
//! which GPU invocations could each parse a piece on their own. Times are wall-clock on
//! one thread, best of three passes over the file (run it on a quiet machine).
//!
//! `cargo run --release -p vbim-format --example scan_cost -- FILE [E]`

use std::fs::File;
use std::io::BufReader;
use std::time::Instant;

use vbim_format::chunk::{self, CoeffReader};
use vbim_format::dct::N;
use vbim_format::plane::{read_blocks, Blocks};
use vbim_format::{varint, ChunkKind, Reader};

/// An entry point of one stream: what a GPU invocation would be given to parse from.
#[derive(Clone, Copy, Default, Debug)]
struct Entry {
    byte: u32,
    position: u32,
    dc: i32,
}

/// Parses one (zero run, value) pair of a stream of `n` blocks at `*at`, from
/// coefficient position `*p`: advances both, and adds the value to the running DC while
/// still in the DC terms (the first `n` positions). `Some(true)` when the run was the
/// final one, reaching the end; `None` where a varint is truncated or malformed.
#[inline(always)]
fn pair(buf: &[u8], n: usize, at: &mut usize, p: &mut u64, dc: &mut i32) -> Option<bool> {
    *p += varint::get_u32(buf, at).ok()? as u64;
    if *p >= (n * N * N) as u64 {
        return Some(true);
    }
    let v = varint::get_i32(buf, at).ok()?;
    if *p < n as u64 {
        *dc = dc.wrapping_add(v);
    }
    *p += 1;
    Some(false)
}

/// Scans one stream of `n` blocks from `*pos`, pushing an entry every `every` pairs.
fn scan(buf: &[u8], pos: &mut usize, n: usize, every: usize, out: &mut Vec<Entry>) -> Option<()> {
    let (mut at, mut p, mut dc) = (*pos, 0u64, 0i32);
    for pairs in 0usize.. {
        if pairs.is_multiple_of(every) {
            out.push(Entry {
                byte: at as u32,
                position: p as u32,
                dc,
            });
        }
        if pair(buf, n, &mut at, &mut p, &mut dc)? {
            break;
        }
    }
    (p == (n * N * N) as u64).then_some(())?;
    *pos = at;
    Some(())
}

/// Checks that each entry point is where parsing `every` pairs from the one before
/// arrives: each piece can be parsed on its own.
fn check(buf: &[u8], n: usize, every: usize, entries: &[Entry]) -> Option<()> {
    for w in entries.windows(2) {
        let (mut at, mut p, mut dc) = (w[0].byte as usize, w[0].position as u64, w[0].dc);
        for _ in 0..every {
            pair(buf, n, &mut at, &mut p, &mut dc)?;
        }
        (at == w[1].byte as usize && p == w[1].position as u64 && dc == w[1].dc).then_some(())?;
    }
    Some(())
}

/// A raw stream and the blocks of each of its planes.
struct Raw {
    bytes: Vec<u8>,
    planes: Vec<(usize, usize)>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().ok_or("usage: scan_cost FILE [E]")?;
    let every: usize = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(256);
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
    for r in &raws {
        for &(at, n) in &r.planes {
            out.clear();
            scan(&r.bytes, &mut at.clone(), n, every, &mut out).ok_or("scan failed")?;
            check(&r.bytes, n, every, &out).ok_or("an entry point is not where parsing arrives")?;
        }
    }
    let mut points = 0;
    let t_scan = best(&mut || {
        points = 0;
        for r in &raws {
            for &(at, n) in &r.planes {
                let mut at = at;
                out.clear();
                scan(&r.bytes, &mut at, n, every, &mut out).unwrap();
                points += out.len();
                std::hint::black_box(&out);
            }
        }
    });
    let raw_bytes: usize = raws.iter().map(|r| r.bytes.len()).sum();
    let stored_bytes: usize = stored.iter().map(|s| s.len()).sum();
    println!(
        "{path}: {stored_bytes} bytes stored, {raw_bytes} raw, {points} entry points every {every} pairs ({} bytes at 12 each)",
        points * 12
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
