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
//!
//! A version 2 or 3 file's planes come as coded (`lanes.wgsl` decodes them): per section (a
//! chunk's planes) its lanes' words as stored (16-bit, two to a word, the first in the low
//! half), the frequencies of the histograms the chunk sent itself (16-bit, up to each
//! one's last used token), and per family it uses the histogram of each cluster of the family
//! ([`SectionSpan`]); per plane, its streams (a lane's states: one a lane in version 2),
//! two words each (the lane's first region | the stream's place among the lane's states
//! << 16 | their number less one << 22; the stream's first word from the section's
//! first) and the end of the words, then a bubble plane's member spans as above. The file's own histograms go to the GPU once, when the stream
//! opens.

use vbim_format::chunk::{spans, Scanned};
use vbim_format::plane2::{Section, SectionPlane, FAMILIES};

/// Blocks the GPU's dense plane holds for planes of `plane` texels: a whole plane, or as
/// many blocks as one storage binding of WebGPU's default limits holds.
pub(crate) fn part_blocks(plane: [u32; 2]) -> u32 {
    let whole = (plane[0] / 8) * (plane[1] / 8);
    let binding = wgpu::Limits::default().max_storage_buffer_binding_size / 256;
    whole.min(binding as u32).max(1)
}

/// For a version 2 or 3 stream whose planes fit the dense plane whole (what `lanes.wgsl`
/// needs: an odd block's contexts read its neighbours anywhere in the plane), how many
/// histograms its file carries (a section's own are numbered after them); `None` for any
/// other stream, whose planes go to the GPU as pairs.
pub(crate) fn decodes_lanes(h: &vbim_format::Header) -> Option<u32> {
    let maps = h.context_maps()?;
    let (pw, ph) = vbim_format::chunk::padded_size(h);
    fits_dense_plane([pw as u32, ph as u32])
        .then(|| vbim_format::plane2::file_histograms(maps).count() as u32)
}

/// Whether a plane of `plane` texels fits the dense plane whole.
pub(crate) fn fits_dense_plane(plane: [u32; 2]) -> bool {
    (plane[0] as u64 / 8) * (plane[1] as u64 / 8) <= part_blocks(plane) as u64
}

/// A place that holds nothing (a family a section does not use).
pub(crate) const NONE: u32 = u32::MAX;

/// Where one coefficient section of a version 2 chunk lies in a [`Coded`] buffer (offsets
/// in words).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SectionSpan {
    /// Its lanes' words: the first word.
    pub words: u32,
    /// The frequencies of the histograms it sent itself: first word, and how many.
    pub own: u32,
    pub own_count: u32,
    /// Per family, the first word of the histogram of each of its clusters (the file's
    /// histogram g as g, the section's own i as the file's count + i, [`NONE`]: none);
    /// [`NONE`] for a family it does not use.
    pub places: [u32; FAMILIES],
    /// Version 3's blocks: a residual and whether a coefficient follows in one symbol,
    /// group by group.
    pub v3: bool,
}

/// A plane coded by rANS lanes (version 2): which section and family, and its lanes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct LanePlane {
    /// The section's index among the box's.
    pub section: u32,
    /// Its family (the context map that codes it).
    pub family: u32,
    /// Its lanes: first word, and how many.
    pub table: u32,
    pub count: u32,
    /// Its lanes' 16-bit words in all (the work of its decode), and its longest lane's
    /// (the serial chain a GPU runs).
    pub words: u32,
    pub longest: u32,
    /// A bubble plane's: its blocks come tile by tile, and its DC predictions stay in
    /// their tile.
    pub tiled: bool,
}

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
    /// A version 2 plane's lanes (its stream and entry points are then unused).
    pub lanes: Option<LanePlane>,
    /// A bound on the words a bubble set holds for it apart from its blocks (its terms
    /// beyond each block's first, 16 bits each where they fit): each such term is an AC
    /// coefficient, so at most the stream's AC pairs, which the scan counts, or, for
    /// lanes, their symbols (at most [`MAX_LANE_SYMBOLS`] each, a word each); and at most
    /// 63 a block.
    ///
    /// [`MAX_LANE_SYMBOLS`]: vbim_format::plane2::MAX_LANE_SYMBOLS
    pub terms: u32,
}

/// [`PlaneSpan::terms`] for a stream of `blocks` blocks whose scan saw `ac`: a word per AC
/// pair where one of them needs more than 16 bits; otherwise two terms to a word, a block
/// of r terms after its first taking ⌈r / 2⌉ words, at most (pairs + blocks with any) / 2
/// in all.
fn pair_words(ac: vbim_format::chunk::AcTerms, blocks: usize) -> u32 {
    let words = match ac.wide {
        true => ac.pairs,
        false => (ac.pairs + ac.pairs.min(blocks as u64)).div_ceil(2),
    };
    at_most_63_a_block(words, blocks)
}

/// [`PlaneSpan::terms`] for a version 2 plane of `blocks` blocks in `lanes` lanes of at
/// most [`MAX_LANE_SYMBOLS`](vbim_format::plane2::MAX_LANE_SYMBOLS) symbols each.
fn lane_words(lanes: usize, blocks: usize) -> u32 {
    let symbols = (lanes as u64).saturating_mul(vbim_format::plane2::MAX_LANE_SYMBOLS as u64);
    at_most_63_a_block(symbols, blocks)
}

/// `words`, but no more than a word for each of 63 terms of every block (and a u32).
fn at_most_63_a_block(words: u64, blocks: usize) -> u32 {
    words.min(blocks as u64 * 63).min(u32::MAX as u64) as u32
}

/// Streams, entry points and member spans of several planes, appended one after another.
#[derive(Clone, Debug, Default)]
pub(crate) struct Coded {
    pub words: Vec<u32>,
    /// Words the last released segment held.
    hint: usize,
    /// The last member spans appended (first word, spans): the next plane reuses them if
    /// it has the same (two chroma planes share their tile map's degrees).
    last_members: Option<(u32, u32)>,
}

impl Coded {
    /// Empties it for the next segment, with room for as many words as the last one
    /// released held (the next segment is usually of a similar size).
    pub fn clear(&mut self) {
        self.words.clear();
        self.last_members = None;
        self.words.reserve(std::mem::take(&mut self.hint));
    }

    /// Gives back the storage once the words are in a GPU staging buffer, so that a box in
    /// flight holds them once, remembering their size for [`Coded::clear`].
    pub fn release(&mut self) {
        self.hint = self.words.len();
        self.words = Vec::new();
        self.last_members = None;
    }

    /// Appends a bubble plane's member spans (or points at the last plane's, if they are
    /// the same); returns their first word and number.
    fn push_members(&mut self, (tiles, member): (usize, &dyn Fn(usize) -> bool)) -> (u32, u32) {
        let at = self.words.len() as u32;
        self.words.extend(member_spans(tiles, member).flatten());
        let count = (self.words.len() as u32 - at) / 2;
        if let Some((last, n)) = self.last_members {
            let (a, b) = (last as usize, at as usize);
            if n == count && self.words[a..a + 2 * n as usize] == self.words[b..] {
                self.words.truncate(b);
                return (last, n);
            }
        }
        self.last_members = Some((at, count));
        (at, count)
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
        self.push_bytes(s.stream);
        let entries = self.words.len() as u32;
        for e in s.entries {
            self.words.extend([e.byte, e.position, e.dc as u32, e.from]);
        }
        let (at, member_count) = members.map_or((0, 0), |m| self.push_members(m));
        PlaneSpan {
            step,
            stream,
            entries,
            count: s.entries.len() as u32,
            blocks: s.blocks as u32,
            members: at,
            member_count,
            lanes: None,
            terms: pair_words(s.ac, s.blocks),
        }
    }

    /// Appends a coefficient section's words (from `bytes`, the section as stored, which
    /// `section` was parsed from) and its own histograms, and each family's places;
    /// `file_count` is how many histograms the file carries.
    pub fn push_section(
        &mut self,
        bytes: &[u8],
        section: &Section,
        file_count: u32,
    ) -> SectionSpan {
        let words = self.words.len() as u32;
        self.push_bytes(&bytes[section.words_at..]);
        // The own histograms: a word each (where its frequencies start, from `own`, << 8 |
        // how many tokens they cover), then each one's frequencies up to its last used
        // token, two to a word.
        let own = self.words.len() as u32;
        let mine = section.histograms.iter().zip(&section.file);
        let own_count = mine.clone().filter(|(_, f)| f.is_none()).count() as u32;
        self.words.resize((own + own_count) as usize, 0);
        let mut index = Vec::with_capacity(section.histograms.len());
        let mut i = 0;
        for (h, file) in mine {
            match file {
                Some(g) => index.push(*g as u32),
                None => {
                    index.push(file_count + i);
                    let used = (0..128)
                        .rev()
                        .find(|&t| h.frequency(t) > 0)
                        .map_or(0, |t| t + 1);
                    let at = self.words.len() as u32 - own;
                    self.words[(own + i) as usize] = at << 8 | used as u32;
                    let f = |t: usize| h.frequency(t);
                    let pairs = (0..used.div_ceil(2)).map(|k| f(2 * k) | f(2 * k + 1) << 16);
                    self.words.extend(pairs);
                    i += 1;
                }
            }
        }
        let mut places = [NONE; FAMILIES];
        for (f, clusters) in section.places.iter().enumerate() {
            if clusters.is_empty() {
                continue;
            }
            places[f] = self.words.len() as u32;
            self.words
                .extend((clusters.iter()).map(|&k| index.get(k as usize).copied().unwrap_or(NONE)));
        }
        SectionSpan {
            words,
            own,
            own_count,
            places,
            v3: section.layout == vbim_format::plane2::Layout::States,
        }
    }

    /// Appends a version 2 plane: plane `sp` of section `section` (the box's
    /// `section`-th, `span` where it lies), of `family`, with `blocks` blocks; with
    /// `members`, a bubble plane's member spans as for [`Coded::push_plane`].
    pub fn push_lane_plane(
        &mut self,
        step: f32,
        (sp, section, family): (&SectionPlane, u32, usize),
        blocks: usize,
        members: Option<(usize, &dyn Fn(usize) -> bool)>,
    ) -> PlaneSpan {
        // Per stream (a lane's state): its lane's first region | its place among the
        // lane's states << 16 | their number less one << 22, and its first word; then the
        // end of the words. (A lane ends where the next one starts.)
        let table = self.words.len() as u32;
        for &(r0, _, s0, s1) in &sp.lanes {
            // (Planes of at most 16384² texels: 16,384 regions. States: at most 64.)
            debug_assert!(r0 < 1 << 16 && s1 - s0 <= 64);
            for (k, &(w0, _)) in sp.streams[s0..s1].iter().enumerate() {
                let place = r0 as u32 | (k as u32) << 16 | ((s1 - s0 - 1) as u32) << 22;
                self.words.extend([place, w0 as u32]);
            }
        }
        let (w_first, w1) = (sp.streams[0].0, sp.streams[sp.streams.len() - 1].1);
        self.words.push(w1 as u32);
        let (at, member_count) = members.map_or((0, 0), |m| self.push_members(m));
        PlaneSpan {
            step,
            blocks: blocks as u32,
            members: at,
            member_count,
            lanes: Some(LanePlane {
                section,
                family: family as u32,
                table,
                count: sp.streams.len() as u32,
                words: (w1 - w_first) as u32,
                longest: sp.streams.iter().map(|l| l.1 - l.0).max().unwrap_or(0) as u32,
                tiled: members.is_some(),
            }),
            terms: lane_words(sp.streams.len(), blocks),
            ..PlaneSpan::default()
        }
    }

    /// Appends bytes four to a word, little-endian, the last word padded with zeros.
    fn push_bytes(&mut self, bytes: &[u8]) {
        let chunks = bytes.chunks_exact(4);
        let tail = chunks.remainder();
        self.words
            .extend(chunks.map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])));
        if !tail.is_empty() {
            let mut last = [0u8; 4];
            last[..tail.len()].copy_from_slice(tail);
            self.words.push(u32::from_le_bytes(last));
        }
    }

    /// Appends a copy of `src`'s planes and sections (as [`Coded::push_plane`] and
    /// [`Coded::push_section`] left them there), returning their spans here.
    pub fn push_copy(
        &mut self,
        src: &Coded,
        (spans, sections): (&[PlaneSpan], &[SectionSpan]),
        out: (&mut Vec<PlaneSpan>, &mut Vec<SectionSpan>),
    ) {
        let d = self.words.len() as u32;
        let first_section = out.1.len() as u32;
        self.words.extend_from_slice(&src.words);
        out.0.extend(spans.iter().map(|s| PlaneSpan {
            stream: s.stream + d,
            entries: s.entries + d,
            members: if s.member_count > 0 { s.members + d } else { 0 },
            lanes: s.lanes.map(|l| LanePlane {
                section: l.section + first_section,
                table: l.table + d,
                ..l
            }),
            ..*s
        }));
        out.1.extend(sections.iter().map(|s| SectionSpan {
            words: s.words + d,
            own: s.own + d,
            places: s.places.map(|p| if p == NONE { NONE } else { p + d }),
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
            ac: Default::default(),
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
        let (mut spans, mut sections) = (Vec::new(), Vec::new());
        d.push_copy(&c, (&[key, bubble], &[]), (&mut spans, &mut sections));
        assert_eq!(spans[0].stream, 4);
        assert_eq!((spans[1].members, spans[1].member_count), (24, 3));
        assert_eq!(&d.words[3..], &c.words[..]);
        assert_eq!(d.bytes(), (3 + c.words.len() as u64) * 4);
        // A plane of the same members right after (two chroma planes) shares the spans;
        // one of other members has its own.
        let len = c.words.len();
        let again = c.push_plane(0.25, s, Some((10, &member)));
        assert_eq!((again.members, again.member_count), (21, 3));
        assert_eq!(
            c.words.len(),
            len + 2 + 8,
            "its stream and entry points alone"
        );
        let fewer = |t: usize| t == 4;
        let other = c.push_plane(0.25, s, Some((10, &fewer)));
        assert_eq!(other.member_count, 1);
        assert_eq!(&c.words[other.members as usize..], &[4, 0]);
    }
}
