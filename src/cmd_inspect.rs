//! `vbim inspect FILE [--json]`: the header, the chunk index with each chunk's checksum
//! status, and a summary of the model (segments, degrees, colour split).

use std::io::BufReader;

use serde_json::json;
use vbim_format::chunk::{self, TileMap};
use vbim_format::{ChunkKind, ColorEncoding, Reader, Transfer};

use crate::cli::InspectArgs;

pub fn run(a: InspectArgs) -> Result<(), String> {
    let mut magic = [0u8; 8];
    let f = crate::sequence::open_input(&a.file)?;
    let is_vbim =
        std::io::Read::read_exact(&mut &f, &mut magic).is_ok() && magic == vbim_format::MAGIC;
    if !is_vbim {
        return package(&a);
    }
    let name = a.file.display().to_string();
    let f = crate::sequence::open_input(&a.file)?;
    let mut r = Reader::open(BufReader::new(f)).map_err(|e| format!("{name}: {e}"))?;
    let h = r.header().clone();
    let entries = r.entries().to_vec();
    let layout = r.layout().clone();

    // Per chunk: checksum status; tile maps also feed the model summary.
    let mut status = Vec::with_capacity(entries.len());
    let mut hist = vec![0u64; h.max_degree as usize + 1];
    let mut chroma_hist = vec![0u64; h.max_degree as usize + 1];
    let (mut lrgb, mut curved) = (0u64, 0u64);
    let mut damaged = 0;
    let mut tiles: Option<TileMap> = None;
    for (i, e) in entries.iter().enumerate() {
        let st = if !a.verify {
            "unchecked".to_string()
        } else {
            match r.read_chunk(i) {
                Ok(bytes) => {
                    if e.kind == ChunkKind::TileMap {
                        match chunk::read_tilemap(&h, &bytes, e.last_frame - e.first_frame) {
                            Ok(t) => {
                                let TileMap { luma, chroma } = tiles.insert(t);
                                for (l, c) in luma.iter().zip(chroma.iter()) {
                                    hist[*l as usize] += 1;
                                    chroma_hist[*c as usize] += 1;
                                    if *l > 1 {
                                        curved += 1;
                                        if *c == 1 && h.channels == 3 {
                                            lrgb += 1;
                                        }
                                    }
                                }
                                "ok".into()
                            }
                            Err(err) => {
                                damaged += 1;
                                format!("bad: {err}")
                            }
                        }
                    } else {
                        match payload_status(&mut r, i, e.kind, &bytes, tiles.as_ref()) {
                            Ok(()) => "ok".into(),
                            Err(err) => {
                                damaged += 1;
                                format!("bad: {err}")
                            }
                        }
                    }
                }
                Err(err) => {
                    damaged += 1;
                    format!("BAD: {err}")
                }
            }
        };
        status.push(st);
    }
    let seg_lens: Vec<u32> = layout.boundaries.windows(2).map(|w| w[1] - w[0]).collect();
    let intra = layout
        .keyframes
        .iter()
        .filter(|&&k| entries[k].is_intra())
        .count();
    let duration = h.frame_count as f64 / h.fps();
    let bpp = h.file_size as f64 * 8.0 / (h.texel_count() as f64 * h.frame_count as f64);
    let raw_bytes = h.texel_count() as f64
        * h.frame_count as f64
        * h.channels as f64
        * if h.color == ColorEncoding::Srgb8 {
            1.0
        } else {
            2.0
        };
    let transfer = match h.transfer {
        Transfer::Srgb => "srgb".to_string(),
        Transfer::LogToe { v0 } => format!("log2(1 + v / {v0:e})"),
    };
    let color = match h.color {
        ColorEncoding::LinearHdr => "linear HDR",
        ColorEncoding::Srgb8 => "sRGB 8-bit",
    };
    let metadata = r.metadata().ok().flatten();
    let kinds = bytes_by_kind(&h, &entries);

    if a.json {
        let chunks: Vec<_> = entries
            .iter()
            .zip(&status)
            .enumerate()
            .map(|(i, (e, st))| {
                json!({"chunk": i, "kind": e.kind.name(), "number": e.number, "intra": e.is_intra(),
                       "optional": e.is_optional(), "first_frame": e.first_frame, "last_frame": e.last_frame,
                       "offset": e.offset, "bytes": e.length, "checksum": format!("{:016x}", e.checksum), "status": st})
            })
            .collect();
        let v = json!({
            "file": name,
            "header": {
                "version": format!("{}.{}", h.version_major(), h.version_minor),
                "coding": coding_name(&h),
                "histograms_per_family": h.context_maps().map(|m| m.iter().map(|m| m.clusters).collect::<Vec<_>>()),
                "width": h.width, "height": h.height, "channels": h.channels, "color": color,
                "frames": h.frame_count, "rate": format!("{}/{}", h.rate_num, h.rate_den),
                "duration_s": duration, "looping": h.looping, "tile_size": h.tile_size,
                "max_degree": h.max_degree, "transfer": transfer, "segments": h.segment_count,
                "keyframes": h.keyframe_count, "intra_interval_frames": h.intra_interval,
                "chunks": h.chunk_count, "file_size": h.file_size,
                "largest_payload": h.largest_payload,
                "read_ahead": read_ahead_json(&h.read_ahead),
            },
            "chunks": chunks,
            "model": {
                "bpp": bpp, "ratio_to_raw": raw_bytes / h.file_size as f64,
                "segment_lengths": seg_lens, "intra_keyframes": intra,
                "luma_degree_histogram": hist, "chroma_degree_histogram": chroma_hist,
                "lrgb_share": if curved > 0 { lrgb as f64 / curved as f64 } else { 0.0 },
                "damaged_chunks": damaged,
            },
            "metadata_bytes": metadata.as_ref().map(|m| m.len()),
            "bytes_by_kind": kinds.iter().map(|(k, b)| (k.to_string(), json!(b))).collect::<serde_json::Map<_, _>>(),
        });
        println!("{}", serde_json::to_string_pretty(&v).unwrap());
    } else {
        println!(
            "{name}: .vbim {}.{}, {} bytes",
            h.version_major(),
            h.version_minor,
            h.file_size
        );
        match h.context_maps() {
            Some(maps) => println!(
                "  coding      {}, histograms per family {}",
                coding_name(&h),
                maps.iter()
                    .map(|m| m.clusters.to_string())
                    .collect::<Vec<_>>()
                    .join("/")
            ),
            None => println!("  coding      {}", coding_name(&h)),
        }
        println!(
            "  size        {}×{}, {} channel(s), {color}",
            h.width, h.height, h.channels
        );
        println!(
            "  frames      {} at {}/{} fps ({:.1} s){}",
            h.frame_count,
            h.rate_num,
            h.rate_den,
            duration,
            if h.looping { ", looping" } else { "" }
        );
        println!(
            "  model       tiles {0}×{0}, degree ≤ {1}, coded as {transfer}",
            h.tile_size, h.max_degree
        );
        println!(
            "  segments    {} (lengths {}–{} frames), keyframes {} ({} intra, every ≤ {} frames)",
            h.segment_count,
            seg_lens.iter().min().unwrap_or(&0),
            seg_lens.iter().max().unwrap_or(&0),
            h.keyframe_count,
            intra,
            h.intra_interval
        );
        println!(
            "  rate        {bpp:.4} bpp, {:.1}× smaller than raw",
            raw_bytes / h.file_size as f64
        );
        for p in &h.read_ahead {
            println!(
                "  read-ahead  at {:>12}: ring {:>10} bytes, preroll {:.3} s",
                rate_text(p.rate),
                p.bytes,
                p.preroll_ns as f64 * 1e-9
            );
        }
        match h.largest_payload {
            Some(p) => println!("  payloads    at most {p} bytes decompressed"),
            None => println!("  payloads    largest not stated (a 1.0 file)"),
        }
        let total = h.file_size.max(1) as f64;
        let parts: Vec<String> = kinds
            .iter()
            .map(|(k, b)| format!("{k} {b} ({:.1}%)", 100.0 * *b as f64 / total))
            .collect();
        println!("  bytes       {}", parts.join(", "));
        println!("  chunks      {}:", h.chunk_count);
        println!(
            "    {:>5}  {:<9} {:>5}  {:>13}  {:>9}  status",
            "#", "kind", "no.", "frames", "bytes"
        );
        for (i, (e, st)) in entries.iter().zip(&status).enumerate() {
            let kind = match (e.kind, e.is_intra()) {
                (ChunkKind::Keyframe, true) => "key/intra".to_string(),
                (ChunkKind::Keyframe, false) => "key/pred".to_string(),
                (k, _) => k.name(),
            };
            println!(
                "    {i:>5}  {kind:<9} {:>5}  {:>6}–{:<6}  {:>9}  {st}",
                e.number, e.first_frame, e.last_frame, e.length
            );
        }
        let total: u64 = hist.iter().sum();
        if total > 0 {
            let show: Vec<String> = hist
                .iter()
                .enumerate()
                .skip(1)
                .map(|(d, n)| format!("{d}: {:.1}%", 100.0 * *n as f64 / total as f64))
                .collect();
            println!("  degrees     (tiles × segments) {}", show.join(", "));
            if h.channels == 3 {
                println!(
                    "  colour      {:.1}% of curved tiles code one luma curve + chroma from keyframes (LRGB)",
                    if curved > 0 { 100.0 * lrgb as f64 / curved as f64 } else { 0.0 }
                );
            }
        }
        if let Some(m) = &metadata {
            println!("  metadata    {} bytes of JSON", m.len());
        }
    }
    if damaged > 0 {
        return Err(format!("{name}: {damaged} damaged chunk(s)"));
    }
    Ok(())
}

/// A rate in SI units (docs/CONVENTIONS.md): B/s, kB/s, MB/s or GB/s.
fn rate_text(r: u64) -> String {
    let r = r as f64;
    if r >= 1e9 {
        format!("{:.2} GB/s", r / 1e9)
    } else if r >= 1e6 {
        format!("{:.2} MB/s", r / 1e6)
    } else if r >= 1e3 {
        format!("{:.2} kB/s", r / 1e3)
    } else {
        format!("{r:.0} B/s")
    }
}

/// Whether a chunk whose checksum is right holds what its kind says: the metadata
/// decompresses (within its limit) to UTF-8 text; a keyframe or coefficient chunk is a zstd
/// frame (its header is read, not the payload: decoding needs the chain). A checksum only
/// says the bytes are the ones written, not that they were ever a payload.
fn payload_status(
    r: &mut Reader<BufReader<std::fs::File>>,
    i: usize,
    kind: ChunkKind,
    bytes: &[u8],
    tiles: Option<&TileMap>,
) -> Result<(), String> {
    let h = r.header().clone();
    let limit = h
        .largest_payload
        .unwrap_or(vbim_format::limits::MAX_CHUNK_DECODED) as usize;
    match kind {
        ChunkKind::Metadata => r.metadata().map(|_| ()).map_err(|e| e.to_string()),
        // Version 2: decoded (a section's damage shows only there).
        ChunkKind::Keyframe if h.context_maps().is_some() => {
            chunk::payload(&h, chunk::Payload::Keyframe, bytes, limit)
                .map(|_| ())
                .map_err(|e| format!("chunk {i}: {e}"))
        }
        ChunkKind::Coefficients if h.context_maps().is_some() => {
            let t = tiles.ok_or(format!("chunk {i}: coefficients before a tile map"))?;
            chunk::payload(&h, chunk::Payload::Coefficients(t), bytes, limit)
                .map(|_| ())
                .map_err(|e| format!("chunk {i}: {e}"))
        }
        ChunkKind::Keyframe | ChunkKind::Coefficients => {
            match zstd::zstd_safe::get_frame_content_size(bytes) {
                Err(_) => Err(format!("chunk {i}: not a zstd frame")),
                Ok(Some(n)) if n > vbim_format::limits::MAX_CHUNK_DECODED => Err(format!(
                    "chunk {i}: claims {n} bytes decompressed (at most {})",
                    vbim_format::limits::MAX_CHUNK_DECODED
                )),
                Ok(_) => Ok(()),
            }
        }
        _ => Ok(()),
    }
}

/// The file's bytes by what they hold: the header (with a 2.0 file's context maps apart),
/// the index, and each kind of chunk (keyframes intra and predicted apart).
fn bytes_by_kind(
    h: &vbim_format::Header,
    entries: &[vbim_format::IndexEntry],
) -> Vec<(&'static str, u64)> {
    let sum = |f: &dyn Fn(&vbim_format::IndexEntry) -> bool| -> u64 {
        entries.iter().filter(|e| f(e)).map(|e| e.length).sum()
    };
    let header = h.header_size() as u64;
    let maps = h.context_maps_size() as u64;
    let chunks: u64 = entries.iter().map(|e| e.length).sum();
    let mut out = vec![("header", header - maps)];
    if maps > 0 {
        out.push(("context maps", maps));
    }
    out.extend([
        (
            "intra keyframes",
            sum(&|e| e.kind == ChunkKind::Keyframe && e.is_intra()),
        ),
        (
            "predicted keyframes",
            sum(&|e| e.kind == ChunkKind::Keyframe && !e.is_intra()),
        ),
        ("coefficients", sum(&|e| e.kind == ChunkKind::Coefficients)),
        ("tile maps", sum(&|e| e.kind == ChunkKind::TileMap)),
        ("metadata", sum(&|e| e.kind == ChunkKind::Metadata)),
        (
            "index and other",
            h.file_size.saturating_sub(header + chunks) + sum(&|e| !known(e.kind)),
        ),
    ]);
    out
}

/// Whether `bytes_by_kind` names the kind.
fn known(k: ChunkKind) -> bool {
    matches!(
        k,
        ChunkKind::Keyframe | ChunkKind::Coefficients | ChunkKind::TileMap | ChunkKind::Metadata
    )
}

/// How the file codes its keyframes and coefficients (its major version).
fn coding_name(h: &vbim_format::Header) -> &'static str {
    match h.coding {
        vbim_format::Coding::Pairs => "zero-run pairs through zstd",
        vbim_format::Coding::Lanes(_, vbim_format::plane2::Layout::OneState) => {
            "rANS lanes (context maps in the header)"
        }
        vbim_format::Coding::Lanes(_, vbim_format::plane2::Layout::States) => {
            "rANS lanes of several states (context maps in the header)"
        }
    }
}

/// A buffer model's points as `--json` gives them (a file's, or a set of tracks').
fn read_ahead_json(points: &[vbim_format::ReadAhead]) -> serde_json::Value {
    points
        .iter()
        .map(|p| json!({"rate_bytes_per_s": p.rate, "bytes": p.bytes, "preroll_s": p.preroll_ns as f64 * 1e-9}))
        .collect()
}

/// What a package's player reads at once, from its tracks' buffer models: each weather's
/// tracks alone (outside a switch), and the two weathers of the switch that reads the most
/// (from a switch to the end of its fade).
fn read_sets(
    p: &vbim_player::PackageFile,
) -> Vec<(
    Vec<String>,
    [vbim_format::ReadAhead; vbim_format::READ_AHEAD_POINTS],
)> {
    let names: Vec<&str> = p.package.weathers.iter().map(|w| w.name.as_str()).collect();
    let mut sets: Vec<_> = names
        .iter()
        .map(|&n| (vec![n.to_string()], p.read_ahead(&[n])))
        .collect();
    let heaviest = names
        .iter()
        .enumerate()
        .flat_map(|(i, a)| names[i + 1..].iter().map(move |b| [*a, *b]))
        .map(|pair| (pair, p.read_ahead(&pair)))
        .max_by_key(|(_, pts)| pts[0].rate);
    if let Some((pair, pts)) = heaviest {
        sets.push((pair.map(String::from).to_vec(), pts));
    }
    sets
}

/// A package: its weathers and every track's kind, size, timing and bytes; with
/// `--verify`, every track's chunks are checked as `inspect` checks a file.
fn package(a: &InspectArgs) -> Result<(), String> {
    let p = vbim_player::PackageFile::open(&a.file).map_err(|e| e.to_string())?;
    let mut damaged = Vec::new();
    if a.verify {
        for t in &p.tracks {
            let f = crate::sequence::open_input(&t.path)?;
            let mut r = Reader::open(BufReader::new(f))
                .map_err(|e| format!("{}: {e}", t.path.display()))?;
            for i in 0..r.entries().len() {
                if let Err(e) = r.read_chunk(i) {
                    damaged.push(format!("{}: chunk {i}: {e}", t.path.display()));
                }
            }
        }
    }
    let total: u64 = p.tracks.iter().map(|t| t.bytes).sum();
    let sets = read_sets(&p);
    if a.json {
        let tracks: Vec<_> = p
            .tracks
            .iter()
            .map(|t| {
                json!({
                    "weather": t.weather, "kind": t.kind.name(), "file": t.path,
                    "width": t.header.width, "height": t.header.height,
                    "channels": t.header.channels, "frames": t.header.frame_count,
                    "fps": format!("{}/{}", t.header.rate_num, t.header.rate_den),
                    "looping": t.header.looping, "bytes": t.bytes,
                    "version": format!("{}.{}", t.header.version_major(), t.header.version_minor),
                })
            })
            .collect();
        let j = json!({
            "file": a.file, "package_version": p.package.vbim_package,
            "weathers": p.package.weathers.iter().map(|w| &w.name).collect::<Vec<_>>(),
            "tracks": tracks, "bytes": total, "damaged": damaged,
            "read_sets": sets.iter().map(|(what, pts)| json!({
                "tracks_of": what,
                "read_ahead": read_ahead_json(pts),
            })).collect::<Vec<_>>(),
        });
        println!("{}", serde_json::to_string_pretty(&j).unwrap());
    } else {
        let h = &p.tracks[0].header;
        println!(
            "{}: vbim package {}, {} weather(s), {} track(s), {} bytes",
            a.file.display(),
            p.package.vbim_package,
            p.package.weathers.len(),
            p.tracks.len(),
            total
        );
        println!(
            "  timeline    {} frames at {}/{} fps ({:.1} s){}",
            h.frame_count,
            h.rate_num,
            h.rate_den,
            h.frame_count as f64 / h.fps(),
            if h.looping { ", looping" } else { "" }
        );
        println!("  weather     track       size        bytes  file");
        for t in &p.tracks {
            println!(
                "  {:<11} {:<10} {:>4}×{:<5} {:>10}  {}",
                t.weather,
                t.kind.name(),
                t.header.width,
                t.header.height,
                t.bytes,
                t.path.display()
            );
        }
        let factors = vbim_format::buffer_model::RATE_FACTORS.map(|f| format!("{f}×"));
        println!(
            "  reading     each set of tracks, each track at {} its mean rate: rate, ring, pre-roll",
            factors.join(" / ")
        );
        for (what, pts) in &sets {
            let cells: Vec<String> = pts
                .iter()
                .map(|p| {
                    format!(
                        "{:.1} kB/s, {:.0} kB, {:.1} s",
                        p.rate as f64 / 1e3,
                        p.bytes as f64 / 1e3,
                        p.preroll_ns as f64 * 1e-9
                    )
                })
                .collect();
            println!("  {:<22} {}", what.join(" + "), cells.join(" / "));
        }
        if a.verify {
            println!(
                "  chunks      {}",
                if damaged.is_empty() {
                    "every track's chunks ok".to_string()
                } else {
                    format!("{} damaged: {}", damaged.len(), damaged.join("; "))
                }
            );
        }
    }
    if damaged.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{}: {} damaged chunk(s)",
            a.file.display(),
            damaged.len()
        ))
    }
}
