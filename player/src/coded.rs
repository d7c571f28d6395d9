//! The form in which the decoder hands a segment's coefficients to the GPU: each plane's
//! coefficient stream as the file codes it (after zstd), its entry points
//! (`vbim_format::chunk::scan`), and for a bubble plane the spans of tiles its blocks belong to.
//! `decode.wgsl` parses the streams, one invocation per entry point.
//!
//! All of it goes in one buffer of words, plane after plane:
//! - the stream's bytes, little-endian four to a word, the last word padded with zeros;
//! - its entry points, four words each: byte offset, position, running DC, and the first
//!   position the piece writes (`vbim_format::chunk::EntryPoint`);
//! - a bubble plane's member spans, two words each: the span's first tile (raster order
//!   over the plane's tiles) and the rank of that tile among the plane's member tiles.
//!   Block b of the stream lies in the tile of rank b / (blocks per tile); the span with
//!   the largest rank at or below it says which tile that is.
//!
//! This is what makes the upload follow the file: a smooth plane whose zstd'd stream is a
//! fraction of a byte per block uploads about twice that, not a record per block.

use vbim_format::chunk::{spans, Scanned};

/// Where one plane's data lies in a [`Coded`] buffer (all offsets in words).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct PlaneSpan {
    /// Quantiser step.
    pub step: f32,
    /// The stream's first word.
    pub stream: u32,
    /// The first entry point's first word, and the number of entry points.
    pub entries: u32,
    pub count: u32,
    /// Blocks the stream codes.
    pub blocks: u32,
    /// A bubble plane's member spans: first word and number (0 for a keyframe plane).
    pub members: u32,
    pub member_count: u32,
}

/// Streams, entry points and member spans of several planes, appended one after another.
#[derive(Clone, Debug, Default)]
pub(crate) struct Coded {
    pub words: Vec<u32>,
    /// Words the last released segment held.
    hint: usize,
}

impl Coded {
    /// Empties it for the next segment, with room for as many words as the last one
    /// released held (the next segment is usually of a similar size).
    pub fn clear(&mut self) {
        self.words.clear();
        self.words.reserve(std::mem::take(&mut self.hint));
    }

    /// Gives back the storage once the words are in a GPU staging buffer, so that a box in
    /// flight holds them once, remembering their size for [`Coded::clear`].
    pub fn release(&mut self) {
        self.hint = self.words.len();
        self.words = Vec::new();
    }

    /// Bytes this holds as uploaded.
    pub fn bytes(&self) -> u64 {
        self.words.len() as u64 * 4
    }

    /// Appends a plane's stream and entry points; with `members` (a bubble plane's: which
    /// of the plane's tiles carry its blocks), the spans of member tiles too.
    pub fn push_plane(
        &mut self,
        step: f32,
        s: Scanned<'_>,
        members: Option<(usize, &dyn Fn(usize) -> bool)>,
    ) -> PlaneSpan {
        let stream = self.words.len() as u32;
        let chunks = s.stream.chunks_exact(4);
        let tail = chunks.remainder();
        self.words
            .extend(chunks.map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])));
        if !tail.is_empty() {
            let mut last = [0u8; 4];
            last[..tail.len()].copy_from_slice(tail);
            self.words.push(u32::from_le_bytes(last));
        }
        let entries = self.words.len() as u32;
        for e in s.entries {
            self.words.extend([e.byte, e.position, e.dc as u32, e.from]);
        }
        let at = self.words.len() as u32;
        if let Some((tiles, member)) = members {
            self.words.extend(member_spans(tiles, member).flatten());
        }
        PlaneSpan {
            step,
            stream,
            entries,
            count: s.entries.len() as u32,
            blocks: s.blocks as u32,
            members: if members.is_some() { at } else { 0 },
            member_count: (self.words.len() as u32 - at) / 2,
        }
    }

    /// Appends a copy of `src`'s planes (as [`Coded::push_plane`] left them there),
    /// returning their spans here.
    pub fn push_copy(&mut self, src: &Coded, spans: &[PlaneSpan], out: &mut Vec<PlaneSpan>) {
        let d = self.words.len() as u32;
        self.words.extend_from_slice(&src.words);
        out.extend(spans.iter().map(|s| PlaneSpan {
            stream: s.stream + d,
            entries: s.entries + d,
            members: if s.member_count > 0 { s.members + d } else { 0 },
            ..*s
        }));
    }
}

/// The member spans of a bubble plane over `tiles` tiles of which `member` keeps some, as
/// the GPU decode reads them: each span's first tile and that tile's rank among the
/// members.
pub(crate) fn member_spans(
    tiles: usize,
    member: &dyn Fn(usize) -> bool,
) -> impl Iterator<Item = [u32; 2]> + '_ {
    let mut rank = 0u32;
    spans(tiles, member).map(move |(a, b)| {
        let span = [a as u32, rank];
        rank += (b - a) as u32;
        span
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use vbim_format::chunk::EntryPoint;

    #[test]
    fn a_plane_goes_in_as_words_entry_points_and_member_spans() {
        let stream = [1u8, 2, 3, 4, 5, 6];
        let entries = [
            EntryPoint {
                byte: 0,
                position: 0,
                dc: 0,
                from: 0,
            },
            EntryPoint {
                byte: 4,
                position: 9,
                dc: -3,
                from: 11,
            },
        ];
        let s = Scanned {
            stream: &stream,
            entries: &entries,
            blocks: 12,
        };
        let mut c = Coded::default();
        c.words.push(77); // something before it
        let key = c.push_plane(0.5, s, None);
        // Tiles 0, 1, 4, 5, 6 and 9 of 10 are members: spans [0, 2), [4, 7), [9, 10).
        let member = |t: usize| [0, 1, 4, 5, 6, 9].contains(&t);
        let bubble = c.push_plane(0.25, s, Some((10, &member)));
        assert_eq!(
            &c.words[1..3],
            &[0x0403_0201, 0x0000_0605],
            "little-endian, the tail padded with zeros"
        );
        assert_eq!((key.stream, key.entries, key.count), (1, 3, 2));
        assert_eq!(&c.words[3..11], &[0, 0, 0, 0, 4, 9, (-3i32) as u32, 11]);
        assert_eq!((key.members, key.member_count, key.blocks), (0, 0, 12));
        assert_eq!(bubble.stream, 11);
        assert_eq!((bubble.members, bubble.member_count), (21, 3));
        // Each span: its first tile and the rank of that tile among the members.
        assert_eq!(&c.words[21..], &[0, 0, 4, 2, 9, 5]);
        // A copy moves the offsets with the words.
        let mut d = Coded::default();
        d.words.extend([1, 2, 3]);
        let mut spans = Vec::new();
        d.push_copy(&c, &[key, bubble], &mut spans);
        assert_eq!(spans[0].stream, 4);
        assert_eq!((spans[1].members, spans[1].member_count), (24, 3));
        assert_eq!(&d.words[3..], &c.words[..]);
        assert_eq!(d.bytes(), (3 + c.words.len() as u64) * 4);
    }
}
