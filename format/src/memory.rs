//! The memory a decoder may spend on one stream ([`Limits`]), and what a stream can make
//! each decoder hold, computed from its header and index alone — so that a stream is
//! refused before the decoder allocates what it claims (a 300-byte file may declare an
//! 8192² stream of degree 8).

use crate::chunk;
use crate::header::Header;
use crate::index::{ChunkKind, IndexEntry};
use crate::{FormatError, Result};

/// The memory a decoder may spend on one stream.
///
/// The CPU decoder ([`crate::decode::Decoder`]) and the GPU player check what a stream
/// needs ([`decoder_memory`], and the player's own count) against it when they open it, and
/// refuse a stream that needs more before allocating any of it. The counts are upper
/// bounds: what the texel count makes a decoder hold, exactly, plus what the largest
/// payload may (the header's largest payload in a 1.1 file; for a 1.0 file a bound set
/// by its chunks' stored sizes, 10–15× what they really take). The default lets every size
/// the project targets through — the 4096² benchmark day (degree ≤ 4) counts 1.84 GB to
/// decode on the CPU and about 1.58 GB to play on the GPU (1.06 GB measured) — and refuses
/// a few-hundred-byte file that claims an 8192² stream (3.2 GB or more for its planes)
/// until the limit is raised; an 8192² day needs about 4–5 GB to play.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Bytes of memory (CPU and GPU together) one stream may take.
    pub memory: u64,
}

impl Limits {
    /// The default memory limit: 2 GB.
    pub const DEFAULT_MEMORY: u64 = 2_000_000_000;

    /// Refuses `need` bytes for `what` when they exceed the limit.
    pub fn check(&self, what: &str, need: u64) -> Result<()> {
        if need > self.memory {
            return Err(FormatError::OverLimit {
                what: what.to_string(),
                need,
                limit: self.memory,
            });
        }
        Ok(())
    }
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            memory: Self::DEFAULT_MEMORY,
        }
    }
}

/// The largest decompressed payload any chunk of the stream may have
/// ([`crate::chunk::payload_limit`] of each keyframe and coefficient chunk: the header's
/// largest payload where it states one, else the format's bound).
pub fn largest_payload(h: &Header, entries: &[IndexEntry]) -> u64 {
    let (w, ht) = chunk::padded_size(h);
    let blocks = w * ht / 64;
    let ch = h.channels as usize;
    let bubble_planes = ch * h.max_degree.saturating_sub(1) as usize;
    entries
        .iter()
        .map(|e| {
            let (n, steps) = match e.kind {
                ChunkKind::Keyframe => (blocks * ch, ch),
                ChunkKind::Coefficients => (
                    blocks * bubble_planes,
                    bubble_planes * h.max_degree as usize,
                ),
                _ => return 0,
            };
            crate::chunk::payload_limit(h, n, steps, e.length as usize) as u64
        })
        .max()
        .unwrap_or(0)
}

/// Bytes the CPU reference decoder may hold for a stream, at most: its f32 planes (four
/// keyframes — keyframe 0, the opening and closing ones, one being built — and one
/// segment's bubble planes) plus the largest payload, decompressed, and its parse (20 bytes
/// a term, at most one term per texel of a plane or per two bytes of payload), and in
/// version 2 what decoding a section holds ([`section_memory`]).
pub fn decoder_memory(h: &Header, entries: &[IndexEntry]) -> u64 {
    let (w, ht) = chunk::padded_size(h);
    let texels = w as u64 * ht as u64;
    let ch = h.channels as u64;
    let planes = texels * ch * 4 * (4 + h.max_degree.saturating_sub(1) as u64);
    let payload = largest_payload(h, entries);
    let terms = (payload / 2).min(texels);
    planes + payload + 20 * terms + section_memory(h, entries)
}

/// Bytes a version 2 payload's decode to pairs holds besides the pairs themselves
/// (`payload2::to_pairs`): one plane's sparse blocks at a time (its DCs, residuals, term
/// places and counts, non-zero masks and grid index: 25 bytes a block, and 8 a term: at
/// most one a texel, and one per two bytes of the pairs it decodes to, which the largest
/// payload bounds), the section's words (its stored size), and the decode tables of the
/// file's histograms and of a chunk's own (4.7 kB each, at most one of each per cluster).
/// 0 for version 1.
pub fn section_memory(h: &Header, entries: &[IndexEntry]) -> u64 {
    let Some(maps) = h.context_maps() else {
        return 0;
    };
    let clusters: u64 = maps.iter().map(|m| m.clusters as u64).sum();
    let (w, ht) = chunk::padded_size(h);
    let texels = w as u64 * ht as u64;
    let stored = entries
        .iter()
        .filter(|e| matches!(e.kind, ChunkKind::Keyframe | ChunkKind::Coefficients))
        .map(|e| e.length)
        .max()
        .unwrap_or(0);
    let terms = (largest_payload(h, entries) / 2).min(texels);
    25 * (texels / 64) + 8 * terms + stored + clusters * 2 * 4700
}
