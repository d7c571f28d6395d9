//! The format's hard maxima, checked before anything is allocated, and the bound on a
//! payload's decompressed size. (The memory a decoder may spend on a stream is
//! the `memory` module's.)

/// Largest width or height (the largest 2D texture wgpu guarantees on desktop is 16384).
pub const MAX_DIMENSION: u32 = 16_384;
/// Largest number of frames in one sequence.
pub const MAX_FRAMES: u32 = 10_000_000;
/// Largest number of chunks (the index is read whole, 40 bytes an entry: 160 MB at most).
pub const MAX_CHUNKS: u32 = 4_000_000;
/// Largest decompressed payload of one chunk: four f32 planes of the largest texture.
pub const MAX_CHUNK_DECODED: u64 = 4 * 4 * (MAX_DIMENSION as u64) * (MAX_DIMENSION as u64);
/// Largest polynomial degree in time.
pub const MAX_DEGREE: u8 = 8;
/// Fastest media frame rate, frames per second (a lightmap day plays at a few to a few
/// dozen: a file claiming 4294967295/1 played no frame at all).
pub const MAX_FPS: f64 = 1000.0;
/// Slowest media frame rate: a frame a day.
pub const MIN_FPS: f64 = 1.0 / 86_400.0;
/// Largest toe `v0` of the HDR log curve: decoding is `v0 · (2^c − 1)` with `c` clamped
/// to 120, which stays a finite f32 for any toe up to about 255. (The encoder picks
/// 2⁻¹⁰ / exposure: at most 43 for half-float input, whose values end at 65504.)
pub const MAX_LOG_TOE: f32 = 200.0;
/// Largest size of the metadata chunk.
pub const MAX_METADATA: u64 = 64 << 20;
/// A coefficient payload may decompress to at most this many times its stored size (or
/// [`FLOOR_PER_BLOCK`] bytes per block, whichever is more). The encoder's payloads expand
/// 2.4–4.2× (every stream of BENCHMARKS.md); a zstd bomb expands thousands of times.
pub const MAX_EXPANSION: u64 = 32;
/// Bytes per coded 8×8 block a payload may always decompress to, whatever its stored size:
/// a smooth plane of few terms per block compresses far beyond [`MAX_EXPANSION`].
pub const FLOOR_PER_BLOCK: u64 = 16;

/// The most a decompressed payload of `blocks` coded blocks and `steps` quantiser steps may
/// take, given its stored size: the format's bound for dense blocks, capped by
/// [`MAX_EXPANSION`] times the stored bytes (but never below [`FLOOR_PER_BLOCK`] per block).
pub fn payload_bound(blocks: usize, steps: usize, stored: usize) -> usize {
    let dense = 16 + 4 * steps as u64 + blocks as u64 * 64 * 5;
    let by_file = (stored as u64 * MAX_EXPANSION).max(FLOOR_PER_BLOCK * blocks as u64 + 4096);
    dense.min(by_file).min(usize::MAX as u64 / 2) as usize
}

/// `1.61 GB`, `512.0 MB`, `900 kB`: SI, as the command line takes sizes.
pub fn human_bytes(n: u64) -> String {
    let n = n as f64;
    if n >= 1e9 {
        format!("{:.2} GB", n / 1e9)
    } else if n >= 1e6 {
        format!("{:.1} MB", n / 1e6)
    } else if n >= 1e3 {
        format!("{:.0} kB", n / 1e3)
    } else {
        format!("{n} B")
    }
}
