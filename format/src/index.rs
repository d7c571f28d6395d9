//! The chunk index (`docs/FORMAT.md`, section "Index"): one 40-byte entry per chunk, in
//! playback order, so that a reader knows every byte range before reading any chunk.

use crate::header::Header;
pub use crate::header::ENTRY_SIZE;
use crate::{FormatError, Result};

/// Flag bit: a reader that does not know this chunk's kind may skip it.
pub const FLAG_OPTIONAL: u16 = 1;
/// Flag bit: a keyframe that decodes without any earlier keyframe.
pub const FLAG_INTRA: u16 = 2;
/// What a chunk holds.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChunkKind {
    /// JSON metadata (e.g. the bake's manifest). Optional.
    Metadata,
    /// A keyframe: the decoded state at a segment boundary.
    Keyframe,
    /// Per-tile metadata of one segment: the polynomial degree of each tile.
    TileMap,
    /// The bubble-coefficient planes of one segment.
    Coefficients,
    /// A kind this reader does not know (only legal with [`FLAG_OPTIONAL`]).
    Unknown(u16),
}

impl ChunkKind {
    /// The kind as stored in an index entry.
    pub fn code(self) -> u16 {
        match self {
            ChunkKind::Metadata => 1,
            ChunkKind::Keyframe => 2,
            ChunkKind::TileMap => 3,
            ChunkKind::Coefficients => 4,
            ChunkKind::Unknown(c) => c,
        }
    }
    /// The kind stored as `c` (unknown codes are kept, so a reader can skip them).
    pub fn from_code(c: u16) -> ChunkKind {
        match c {
            1 => ChunkKind::Metadata,
            2 => ChunkKind::Keyframe,
            3 => ChunkKind::TileMap,
            4 => ChunkKind::Coefficients,
            c => ChunkKind::Unknown(c),
        }
    }
    /// The kind's name in reports.
    pub fn name(self) -> String {
        match self {
            ChunkKind::Metadata => "metadata".into(),
            ChunkKind::Keyframe => "keyframe".into(),
            ChunkKind::TileMap => "tilemap".into(),
            ChunkKind::Coefficients => "coeffs".into(),
            ChunkKind::Unknown(c) => format!("unknown({c})"),
        }
    }
}
/// One chunk of the index: what it is, which frames it covers, where it is and its checksum.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IndexEntry {
    /// What the chunk holds.
    pub kind: ChunkKind,
    /// Flag bits ([`FLAG_OPTIONAL`], and for keyframes the intra bit).
    pub flags: u16,
    /// Keyframe number for keyframes; segment number for tile maps and coefficients; 0 else.
    pub number: u32,
    /// The media frames the chunk covers, inclusive: a keyframe's single frame, a segment's
    /// two boundary frames (the last may equal the frame count in a looping file).
    pub first_frame: u32,
    /// (the last of them)
    pub last_frame: u32,
    /// Byte offset in the file.
    pub offset: u64,
    /// Length in bytes as stored.
    pub length: u64,
    /// XXH3-64 of the chunk's bytes as stored.
    pub checksum: u64,
}

impl IndexEntry {
    /// Whether a keyframe is coded on its own (decodable without the one before).
    pub fn is_intra(&self) -> bool {
        self.flags & FLAG_INTRA != 0
    }
    /// Whether a reader that does not know the kind may skip the chunk.
    pub fn is_optional(&self) -> bool {
        self.flags & FLAG_OPTIONAL != 0
    }

    /// Appends the entry as stored (40 bytes).
    pub fn write(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.kind.code().to_le_bytes());
        out.extend_from_slice(&self.flags.to_le_bytes());
        out.extend_from_slice(&self.number.to_le_bytes());
        out.extend_from_slice(&self.first_frame.to_le_bytes());
        out.extend_from_slice(&self.last_frame.to_le_bytes());
        out.extend_from_slice(&self.offset.to_le_bytes());
        out.extend_from_slice(&self.length.to_le_bytes());
        out.extend_from_slice(&self.checksum.to_le_bytes());
    }

    /// Reads an entry from its 40 stored bytes.
    pub fn read(b: &[u8]) -> IndexEntry {
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap());
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap());
        IndexEntry {
            kind: ChunkKind::from_code(u16_at(0)),
            flags: u16_at(2),
            number: u32_at(4),
            first_frame: u32_at(8),
            last_frame: u32_at(12),
            offset: u64_at(16),
            length: u64_at(24),
            checksum: u64_at(32),
        }
    }
}

/// The segment structure recovered from a validated index.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Segment boundaries b_0 = 0 < b_1 < … < b_S (S + 1 values; one value when S = 0).
    pub boundaries: Vec<u32>,
    /// Index position of each stored keyframe.
    pub keyframes: Vec<usize>,
    /// Index positions of each segment's tile map and coefficient chunks.
    pub segments: Vec<(usize, usize)>,
    /// Index position of the metadata chunk, if there is one.
    pub metadata: Option<usize>,
}

impl Layout {
    /// The stored keyframe at boundary `b` (the last boundary of a looping file is keyframe 0).
    pub fn keyframe_of_boundary(&self, b: usize) -> usize {
        if b == self.keyframes.len() {
            0
        } else {
            b
        }
    }
}

/// Checks an index against its header and recovers the segment layout. Every rule here is
/// one of `docs/FORMAT.md`'s "a reader must refuse" rules.
pub fn validate(h: &Header, entries: &[IndexEntry], index_end: u64) -> Result<Layout> {
    let bad = |i: usize, m: String| Err(FormatError::InvalidIndex(format!("entry {i}: {m}")));
    let mut prev_end = index_end;
    let mut keyframes = Vec::new();
    let mut tilemaps = Vec::new();
    let mut coeffs = Vec::new();
    let mut key_frames_at = Vec::new();
    let mut seg_ranges = Vec::new();
    let mut metadata = None;
    for (i, e) in entries.iter().enumerate() {
        // Chunks are stored in index order without overlap: an index cannot loop or alias.
        if e.offset < prev_end {
            return bad(
                i,
                format!(
                    "offset {} overlaps what precedes it (ends at {prev_end})",
                    e.offset
                ),
            );
        }
        let end = match e.offset.checked_add(e.length) {
            Some(end) if end <= h.file_size => end,
            _ => {
                return bad(
                    i,
                    format!(
                        "bytes {}+{} run past the end of the file",
                        e.offset, e.length
                    ),
                )
            }
        };
        prev_end = end;
        if e.first_frame > e.last_frame || e.last_frame > h.frame_count {
            return bad(
                i,
                format!(
                    "frames {}–{} outside 0–{}",
                    e.first_frame, e.last_frame, h.frame_count
                ),
            );
        }
        match e.kind {
            ChunkKind::Metadata => {
                if metadata.is_some() {
                    return bad(i, "a second metadata chunk".into());
                }
                if e.length > crate::limits::MAX_METADATA {
                    return bad(i, format!("metadata of {} bytes", e.length));
                }
                metadata = Some(i);
            }
            ChunkKind::Keyframe => {
                if e.number as usize != keyframes.len() || e.first_frame != e.last_frame {
                    return bad(i, format!("keyframe {} out of order", e.number));
                }
                if keyframes.is_empty() && !e.is_intra() {
                    return bad(i, "the first keyframe is not intra".into());
                }
                keyframes.push(i);
                key_frames_at.push(e.first_frame);
            }
            ChunkKind::TileMap | ChunkKind::Coefficients => {
                let list = if e.kind == ChunkKind::TileMap {
                    &mut tilemaps
                } else {
                    &mut coeffs
                };
                if e.number as usize != list.len() {
                    return bad(
                        i,
                        format!("{} of segment {} out of order", e.kind.name(), e.number),
                    );
                }
                list.push(i);
                if e.kind == ChunkKind::TileMap {
                    seg_ranges.push((e.first_frame, e.last_frame));
                } else if seg_ranges.get(e.number as usize) != Some(&(e.first_frame, e.last_frame))
                {
                    return bad(
                        i,
                        format!("segment {} frames differ from its tile map's", e.number),
                    );
                }
            }
            ChunkKind::Unknown(c) => {
                if !e.is_optional() {
                    return bad(i, format!("unknown chunk kind {c} not marked optional"));
                }
            }
        }
    }
    if keyframes.len() != h.keyframe_count as usize {
        return Err(FormatError::InvalidIndex(format!(
            "{} keyframes, header says {}",
            keyframes.len(),
            h.keyframe_count
        )));
    }
    if tilemaps.len() != h.segment_count as usize || coeffs.len() != h.segment_count as usize {
        return Err(FormatError::InvalidIndex(format!(
            "{} tile maps and {} coefficient chunks, header says {} segments",
            tilemaps.len(),
            coeffs.len(),
            h.segment_count
        )));
    }
    // Keyframe frames are the segment boundaries; segment s spans keyframes s and s + 1.
    let mut boundaries = key_frames_at.clone();
    if h.looping && h.segment_count > 0 {
        boundaries.push(h.frame_count);
    }
    if boundaries[0] != 0 || boundaries.windows(2).any(|w| w[0] >= w[1]) {
        return Err(FormatError::InvalidIndex(
            "keyframes are not at increasing frames from 0".into(),
        ));
    }
    let last = *boundaries.last().unwrap();
    let expect_last = if h.looping {
        h.frame_count
    } else {
        h.frame_count - 1
    };
    if h.segment_count > 0 && last != expect_last {
        return Err(FormatError::InvalidIndex(format!(
            "the last segment ends at frame {last}, not {expect_last}"
        )));
    }
    for (s, r) in seg_ranges.iter().enumerate() {
        if *r != (boundaries[s], boundaries[s + 1]) {
            return Err(FormatError::InvalidIndex(format!(
                "segment {s} covers frames {}–{}, its keyframes are at {} and {}",
                r.0,
                r.1,
                boundaries[s],
                boundaries[s + 1]
            )));
        }
    }
    // Independently decodable keyframes come at least every `intra_interval` frames.
    let mut last_intra = 0u32;
    for &k in &keyframes {
        let e = &entries[k];
        if e.is_intra() {
            last_intra = e.first_frame;
        } else if e.first_frame - last_intra > h.intra_interval {
            return Err(FormatError::InvalidIndex(format!(
                "keyframe {} at frame {} is {} frames past the last intra keyframe (limit {})",
                e.number,
                e.first_frame,
                e.first_frame - last_intra,
                h.intra_interval
            )));
        }
    }
    let segments = tilemaps.into_iter().zip(coeffs).collect();
    Ok(Layout {
        boundaries,
        keyframes,
        segments,
        metadata,
    })
}
