//! The fixed-size file header (`docs/FORMAT.md`, section "Header").

use crate::ans::{BitReader, BitWriter};
use crate::checksum::xxh3;
use crate::limits::{
    MAX_CHUNKS, MAX_DEGREE, MAX_DIMENSION, MAX_FPS, MAX_FRAMES, MAX_LOG_TOE, MIN_FPS,
};
use crate::plane2::{ContextMap, Layout, FAMILIES};
use crate::{FormatError, Result};

/// Bytes of one index entry (the index, which follows the header, is `chunk_count` of them).
pub const ENTRY_SIZE: usize = 40;

/// `«VBIM»\r\n`: a non-ASCII first byte catches 7-bit transfers, CR LF catches newline
/// conversion (the same trick as PNG and KTX2).
pub const MAGIC: [u8; 8] = [0xAB, b'V', b'B', b'I', b'M', 0xBB, 0x0D, 0x0A];
/// The newest major version this crate reads and writes. It reads versions 1, 2 and 3
/// and refuses any other; they differ in how keyframe and coefficient chunks are coded
/// ([`Coding`]).
pub const VERSION_MAJOR: u16 = 3;
/// The minor version this crate writes with major versions 2 and 3: a reader accepts any
/// (they only append header fields and add optional chunks). Version 1 files are written
/// as 1.1, which appended [`Header::largest_payload`] to 1.0.
pub const VERSION_MINOR: u16 = 0;
/// Bytes of a version 1.0 header: the shortest a reader accepts. Later minor versions
/// append fields before the header's checksum; readers skip what they do not know.
pub const HEADER_SIZE: usize = 192;
/// Bytes of a version 1.1 header; a version 2.0 or 3.0 header appends its context maps.
pub const HEADER_SIZE_1_1: usize = 200;
/// The most bytes of context maps a header may hold: six families of 502 contexts take at
/// most 2.3 kB, and each cluster's file-wide histogram at most 200 bytes (the encoder's 16
/// clusters a family: 19 kB at most, about 1.5 kB in practice).
const MAX_MAPS_BYTES: usize = 60 << 10;
/// Number of (read rate, read-ahead) points of the buffer model.
pub const READ_AHEAD_POINTS: usize = 4;

/// How texel values are represented in the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorEncoding {
    /// Linear light, HDR (the bake's EXR output). Coded through [`Transfer::LogToe`].
    LinearHdr = 0,
    /// 8-bit sRGB input (PNG). Coded as sRGB code values in [0, 1].
    Srgb8 = 1,
}

/// The curve between linear light and the domain the model is fitted and quantised in
/// (see [`crate::curve`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transfer {
    /// Coded value = sRGB code value / 255.
    Srgb,
    /// Coded value = log2(1 + v / v0): relative precision above `v0`, absolute below.
    LogToe {
        /// The toe: below it the curve is nearly linear.
        v0: f32,
    },
}

/// One point of the buffer model: reading at `rate` bytes per second from the start of the
/// file, a player needs `bytes` of read-ahead (ring capacity) and must buffer for
/// `preroll_ns` nanoseconds before starting, so that no chunk arrives after the moment
/// it is needed. Computed by the encoder like a video codec's leaky-bucket model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct ReadAhead {
    /// Read rate, bytes per second.
    pub rate: u64,
    /// Ring capacity needed at that rate, bytes.
    pub bytes: u64,
    /// Buffering needed before the first frame at that rate, ns.
    pub preroll_ns: u64,
}
/// How a file codes its keyframe and coefficient chunks: what its major version means.
#[derive(Clone, Debug, PartialEq)]
pub enum Coding {
    /// Version 1: each plane's blocks as (zero run, value) pairs, the payload compressed
    /// by zstd ([`crate::plane`]).
    Pairs,
    /// Versions 2 and 3: each payload's planes in rANS lanes ([`crate::plane2`]), coded
    /// with the file's context maps (one per family, [`FAMILIES`]), which the header
    /// carries; one state a lane in version 2, several in version 3 (the layout).
    Lanes(Vec<ContextMap>, Layout),
}

/// The file header: what the stream is (size, channels, frame rate, model) and where its parts are. `docs/FORMAT.md` gives the byte layout.

#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// Minor version of the writer.
    pub version_minor: u16,
    /// How keyframes and coefficients are coded: the major version (1, 2 or 3).
    pub coding: Coding,
    /// Lightmap width, texels.
    pub width: u32,
    /// Lightmap height, texels.
    pub height: u32,
    /// 3 (RGB) or 1 (Y).
    pub channels: u8,
    /// What the values mean: linear HDR or sRGB 8-bit.
    pub color: ColorEncoding,
    /// Whether playback wraps from the last frame to the first (the model then spans the seam).
    pub looping: bool,
    /// Media frames in the sequence.
    pub frame_count: u32,
    /// Media frame rate, frames per second, as `rate_num / rate_den`: the numerator.
    pub rate_num: u32,
    /// The denominator.
    pub rate_den: u32,
    /// Tile size of the per-tile degree model, texels.
    pub tile_size: u16,
    /// Largest polynomial degree in time of any tile.
    pub max_degree: u8,
    /// The curve between linear light and the coded domain.
    pub transfer: Transfer,
    /// Segments (keyframe to keyframe).
    pub segment_count: u32,
    /// Keyframes stored (segments + 1, or segments for a looping file, whose last keyframe is the first).
    pub keyframe_count: u32,
    /// Largest distance in frames between two independently decodable keyframes.
    pub intra_interval: u32,
    /// Chunks in the index.
    pub chunk_count: u32,
    /// Byte offset of the index.
    pub index_offset: u64,
    /// Size of the whole file, bytes.
    pub file_size: u64,
    /// The buffer model: read-ahead and pre-roll at several read rates.
    pub read_ahead: [ReadAhead; READ_AHEAD_POINTS],
    /// XXH3-64 of the index's bytes.
    pub index_checksum: u64,
    /// The largest decompressed payload of any keyframe or coefficient chunk, bytes
    /// (version 1.1; `None` in a 1.0 file). A decoder plans its memory by it at open and
    /// refuses a chunk that decompresses to more; without it, the bound is the format's
    /// (up to 32× a chunk's stored size), which is 10–15× what real payloads take.
    pub largest_payload: Option<u64>,
}

impl Header {
    /// Tiles across.
    pub fn tiles_x(&self) -> u32 {
        self.width.div_ceil(self.tile_size as u32)
    }
    /// Tiles down.
    pub fn tiles_y(&self) -> u32 {
        self.height.div_ceil(self.tile_size as u32)
    }
    /// Tiles in all.
    pub fn tile_count(&self) -> usize {
        self.tiles_x() as usize * self.tiles_y() as usize
    }
    /// Texels in one frame.
    pub fn texel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }
    /// Frames per second as a float, for display only (time itself is kept in integers).
    pub fn fps(&self) -> f64 {
        self.rate_num as f64 / self.rate_den as f64
    }

    /// The smallest read-ahead that suffices at `rate` bytes per second: the buffer model's
    /// point at the highest tabulated rate not above `rate`. `None` below the slowest point
    /// (the model makes no promise there).
    pub fn read_ahead_at(&self, rate: u64) -> Option<ReadAhead> {
        self.read_ahead
            .iter()
            .filter(|p| p.rate > 0 && p.rate <= rate)
            .max_by_key(|p| p.rate)
            .copied()
    }

    /// The major version: 1 for zero-run pairs through zstd, 2 for rANS lanes of one
    /// state, 3 for lanes of several.
    pub fn version_major(&self) -> u16 {
        match self.coding {
            Coding::Pairs => 1,
            Coding::Lanes(_, Layout::OneState) => 2,
            Coding::Lanes(_, Layout::States) => 3,
        }
    }

    /// The file's context maps (versions 2 and 3), one per family.
    pub fn context_maps(&self) -> Option<&[ContextMap]> {
        match &self.coding {
            Coding::Pairs => None,
            Coding::Lanes(maps, _) => Some(maps),
        }
    }

    /// How the file's sections lay out their lanes (versions 2 and 3).
    pub fn lane_layout(&self) -> Option<Layout> {
        match &self.coding {
            Coding::Pairs => None,
            Coding::Lanes(_, layout) => Some(*layout),
        }
    }

    /// Bytes of this header as stored: 2.0 and 3.0 with their context maps; for version 1, 1.1's
    /// when it states the largest payload, else 1.0's.
    pub fn header_size(&self) -> usize {
        match &self.coding {
            Coding::Lanes(..) => HEADER_SIZE_1_1 + 4 + self.context_maps_size(),
            Coding::Pairs if self.largest_payload.is_some() => HEADER_SIZE_1_1,
            Coding::Pairs => HEADER_SIZE,
        }
    }

    /// Bytes of a 2.0 or 3.0 header's context maps as stored, after their length (0 for
    /// version 1).
    pub fn context_maps_size(&self) -> usize {
        match &self.coding {
            Coding::Lanes(maps, layout) => maps_bytes(maps, *layout).len(),
            Coding::Pairs => 0,
        }
    }

    /// The header as stored ([`Header::header_size`] bytes), checksum included.
    pub fn to_bytes(&self) -> Vec<u8> {
        let size = self.header_size();
        let mut b = vec![0u8; size];
        let mut w = Cursor {
            buf: &mut b,
            pos: 0,
        };
        w.put(&MAGIC);
        w.put(&self.version_major().to_le_bytes());
        w.put(&self.version_minor.to_le_bytes());
        w.put(&(size as u32).to_le_bytes());
        w.put(&self.width.to_le_bytes());
        w.put(&self.height.to_le_bytes());
        w.put(&[self.channels, self.color as u8]);
        w.put(&(self.looping as u16).to_le_bytes());
        w.put(&self.frame_count.to_le_bytes());
        w.put(&self.rate_num.to_le_bytes());
        w.put(&self.rate_den.to_le_bytes());
        w.put(&self.tile_size.to_le_bytes());
        w.put(&[self.max_degree]);
        let (tid, tparam) = match self.transfer {
            Transfer::Srgb => (0u8, 0f32),
            Transfer::LogToe { v0 } => (1u8, v0),
        };
        w.put(&[tid]);
        w.put(&tparam.to_le_bytes());
        w.put(&self.segment_count.to_le_bytes());
        w.put(&self.keyframe_count.to_le_bytes());
        w.put(&self.intra_interval.to_le_bytes());
        w.put(&self.chunk_count.to_le_bytes());
        w.put(&self.index_offset.to_le_bytes());
        w.put(&self.file_size.to_le_bytes());
        for p in &self.read_ahead {
            w.put(&p.rate.to_le_bytes());
            w.put(&p.bytes.to_le_bytes());
            w.put(&p.preroll_ns.to_le_bytes());
        }
        w.put(&self.index_checksum.to_le_bytes());
        if let Some(p) = self.largest_payload {
            w.put(&p.to_le_bytes());
        } else if self.version_major() > 1 {
            // Version 2 states it always (a header without it is refused on reading).
            w.put(&0u64.to_le_bytes());
        }
        if let Coding::Lanes(maps, layout) = &self.coding {
            let m = maps_bytes(maps, *layout);
            w.put(&(m.len() as u32).to_le_bytes());
            w.put(&m);
        }
        debug_assert_eq!(w.pos, size - 8);
        let sum = xxh3(&b[..size - 8]);
        b[size - 8..].copy_from_slice(&sum.to_le_bytes());
        b
    }

    /// Parses and validates a header. `bytes` must hold at least [`HEADER_SIZE`] bytes; the
    /// caller reads `header_size` from offset 12 first when it wants to skip extensions.
    pub fn from_bytes(bytes: &[u8]) -> Result<Header> {
        if bytes.len() < 16 {
            return Err(FormatError::Truncated(format!(
                "{} bytes, shorter than the 16-byte file signature",
                bytes.len()
            )));
        }
        if bytes[..8] != MAGIC {
            return Err(FormatError::BadMagic);
        }
        let major = u16::from_le_bytes([bytes[8], bytes[9]]);
        if !(1..=VERSION_MAJOR).contains(&major) {
            return Err(FormatError::UnsupportedVersion {
                found: major,
                known: VERSION_MAJOR,
            });
        }
        let header_size = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        if !(HEADER_SIZE..=1 << 16).contains(&header_size) {
            return Err(FormatError::InvalidHeader(format!(
                "header size {header_size} (expected {HEADER_SIZE} to 65536)"
            )));
        }
        if bytes.len() < header_size {
            return Err(FormatError::Truncated(format!(
                "{} bytes, shorter than the {header_size}-byte header",
                bytes.len()
            )));
        }
        let stored = u64::from_le_bytes(bytes[header_size - 8..header_size].try_into().unwrap());
        if xxh3(&bytes[..header_size - 8]) != stored {
            return Err(FormatError::HeaderChecksum);
        }
        let mut r = Reader {
            buf: bytes,
            pos: 10,
        };
        let version_minor = r.u16();
        let _size = r.u32();
        let width = r.u32();
        let height = r.u32();
        let channels = r.u8();
        let color = match r.u8() {
            0 => ColorEncoding::LinearHdr,
            1 => ColorEncoding::Srgb8,
            c => {
                return Err(FormatError::InvalidHeader(format!(
                    "unknown colour encoding {c}"
                )))
            }
        };
        let flags = r.u16();
        let frame_count = r.u32();
        let rate_num = r.u32();
        let rate_den = r.u32();
        let tile_size = r.u16();
        let max_degree = r.u8();
        let tid = r.u8();
        let tparam = f32::from_le_bytes(r.take(4).try_into().unwrap());
        let transfer = match tid {
            0 => Transfer::Srgb,
            1 => Transfer::LogToe { v0: tparam },
            t => {
                return Err(FormatError::InvalidHeader(format!(
                    "unknown transfer curve {t}"
                )))
            }
        };
        let segment_count = r.u32();
        let keyframe_count = r.u32();
        let intra_interval = r.u32();
        let chunk_count = r.u32();
        let index_offset = r.u64();
        let file_size = r.u64();
        let mut read_ahead = [ReadAhead::default(); READ_AHEAD_POINTS];
        for p in &mut read_ahead {
            p.rate = r.u64();
            p.bytes = r.u64();
            p.preroll_ns = r.u64();
        }
        let index_checksum = r.u64();
        // 1.1 appends the largest payload, 2.0 and 3.0 always have it. A header too short to hold it
        // is damaged.
        let largest_payload = match (major, version_minor, header_size) {
            (1, 0, _) => None,
            (_, _, n) if n >= HEADER_SIZE_1_1 => Some(r.u64()),
            (v, m, n) => {
                return Err(FormatError::InvalidHeader(format!(
                    "a version {v}.{m} header of {n} bytes (1.1 and later hold at least {HEADER_SIZE_1_1})"
                )))
            }
        };
        let coding = match major {
            1 => Coding::Pairs,
            _ => {
                // 2.0 and 3.0 append the context maps: their length, then the maps.
                let room = header_size - 8 - r.pos;
                let len = if room >= 4 {
                    r.u32() as usize
                } else {
                    usize::MAX
                };
                if len > room.saturating_sub(4) || len > MAX_MAPS_BYTES {
                    return Err(FormatError::InvalidHeader(format!(
                        "context maps of {len} bytes in a {header_size}-byte header"
                    )));
                }
                let layout = match major {
                    2 => Layout::OneState,
                    _ => Layout::States,
                };
                Coding::Lanes(read_maps(r.take(len), layout)?, layout)
            }
        };
        let h = Header {
            version_minor,
            coding,
            width,
            height,
            channels,
            color,
            looping: flags & 1 != 0,
            frame_count,
            rate_num,
            rate_den,
            tile_size,
            max_degree,
            transfer,
            segment_count,
            keyframe_count,
            intra_interval,
            chunk_count,
            index_offset,
            file_size,
            read_ahead,
            index_checksum,
            largest_payload,
        };
        h.validate(header_size as u64)?;
        Ok(h)
    }

    /// Checks every size, count and offset against the format's limits, so that nothing a
    /// header says can cause a huge allocation or an endless loop later.
    pub fn validate(&self, header_size: u64) -> Result<()> {
        let bad = |m: String| Err(FormatError::InvalidHeader(m));
        if self.width == 0
            || self.height == 0
            || self.width > MAX_DIMENSION
            || self.height > MAX_DIMENSION
        {
            return bad(format!(
                "size {}×{} (each side must be 1 to {MAX_DIMENSION})",
                self.width, self.height
            ));
        }
        if self.channels != 1 && self.channels != 3 {
            return bad(format!("{} channels (must be 1 or 3)", self.channels));
        }
        if self.frame_count == 0 || self.frame_count > MAX_FRAMES {
            return bad(format!(
                "frame count {} (must be 1 to {MAX_FRAMES})",
                self.frame_count
            ));
        }
        if self.rate_num == 0 || self.rate_den == 0 || !(MIN_FPS..=MAX_FPS).contains(&self.fps()) {
            return bad(format!(
                "frame rate {}/{} (must be 1/86400 to 1000 frames per second)",
                self.rate_num, self.rate_den
            ));
        }
        if !(8..=256).contains(&self.tile_size) || !self.tile_size.is_multiple_of(8) {
            return bad(format!(
                "tile size {} (must be a multiple of 8 from 8 to 256)",
                self.tile_size
            ));
        }
        if self.max_degree == 0 || self.max_degree > MAX_DEGREE {
            return bad(format!(
                "maximum degree {} (must be 1 to {MAX_DEGREE})",
                self.max_degree
            ));
        }
        if let Transfer::LogToe { v0 } = self.transfer {
            // Decoding is v0 · (2^c − 1) with c clamped to 120 (curve.rs, reconstruct.wgsl):
            // a toe above 200 could come near overflowing f32 (every texel +inf); no real one is
            // near it (texels are irradiance / π, about 1 at noon; toes are ~1e-4).
            if !(v0.is_finite() && v0 > 0.0 && v0 <= MAX_LOG_TOE) {
                return bad(format!(
                    "log curve parameter {v0} (must be positive, at most {MAX_LOG_TOE})"
                ));
            }
        }
        if self.color == ColorEncoding::Srgb8 && self.transfer != Transfer::Srgb {
            return bad("8-bit sRGB data must use the sRGB transfer".into());
        }
        // Boundaries are 0 = b_0 < … < b_S = F (looping) or F − 1 (not looping).
        let steps = if self.looping {
            self.frame_count
        } else {
            self.frame_count - 1
        };
        if self.segment_count > steps || (self.segment_count == 0 && steps > 0) {
            return bad(format!(
                "{} segments for {} frames ({})",
                self.segment_count,
                self.frame_count,
                if self.looping {
                    "looping"
                } else {
                    "not looping"
                }
            ));
        }
        let expect_keys = if self.looping {
            self.segment_count
        } else {
            self.segment_count + 1
        };
        if self.keyframe_count != expect_keys {
            return bad(format!(
                "{} keyframes for {} segments (expected {expect_keys})",
                self.keyframe_count, self.segment_count
            ));
        }
        if self.chunk_count == 0 || self.chunk_count > crate::limits::MAX_CHUNKS {
            return bad(format!(
                "chunk count {} (must be 1 to {MAX_CHUNKS})",
                self.chunk_count
            ));
        }
        if self.intra_interval == 0 {
            return bad("intra interval 0".into());
        }
        if let Some(p) = self.largest_payload {
            if p == 0 || p > crate::limits::MAX_CHUNK_DECODED {
                return bad(format!(
                    "largest payload {p} bytes (must be 1 to {})",
                    crate::limits::MAX_CHUNK_DECODED
                ));
            }
        }
        let index_len = self.chunk_count as u64 * ENTRY_SIZE as u64;
        if self.index_offset < header_size
            || self
                .index_offset
                .checked_add(index_len)
                .is_none_or(|end| end > self.file_size)
        {
            return bad(format!(
                "index at byte {} ({} entries) does not fit in a {}-byte file",
                self.index_offset, self.chunk_count, self.file_size
            ));
        }
        Ok(())
    }
}

/// The context maps as a header stores them: the number of families (8 bits), then each
/// map ([`ContextMap::write`]), zero bits to the byte.
fn maps_bytes(maps: &[ContextMap], layout: Layout) -> Vec<u8> {
    let mut w = BitWriter::default();
    w.put(maps.len() as u32, 8);
    maps.iter().for_each(|m| m.write(&mut w, layout));
    w.finish()
}

/// Reads what [`maps_bytes`] wrote: exactly [`FAMILIES`] maps, and nothing after them.
fn read_maps(bytes: &[u8], layout: Layout) -> Result<Vec<ContextMap>> {
    let bad = |m: String| FormatError::InvalidHeader(format!("context maps: {m}"));
    let mut r = BitReader::new(bytes);
    let n = r.get(8).map_err(|e| bad(e.to_string()))? as usize;
    if n != FAMILIES {
        return Err(bad(format!("{n} families (the format has {FAMILIES})")));
    }
    let maps = (0..n)
        .map(|_| ContextMap::read(&mut r, layout).map_err(|e| bad(e.to_string())))
        .collect::<Result<Vec<_>>>()?;
    if r.position().div_ceil(8) != bytes.len() {
        return Err(bad(format!(
            "{} bytes after the maps",
            bytes.len() - r.position().div_ceil(8)
        )));
    }
    Ok(maps)
}

struct Cursor<'a> {
    buf: &'a mut [u8],
    pos: usize,
}
impl Cursor<'_> {
    fn put(&mut self, b: &[u8]) {
        self.buf[self.pos..self.pos + b.len()].copy_from_slice(b);
        self.pos += b.len();
    }
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}
impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> &'a [u8] {
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        s
    }
    fn u8(&mut self) -> u8 {
        self.take(1)[0]
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take(2).try_into().unwrap())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take(8).try_into().unwrap())
    }
}
