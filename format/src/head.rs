//! What the keyframe and coefficient payloads of both versions start from: a keyframe's
//! mode byte, the padded size of the planes they code, and a segment's tile map (which
//! tiles a bubble plane holds). `chunk` (version 1) and `payload2` (version 2) both read
//! their heads with these; `chunk` re-exports them.

use crate::header::Header;

/// Keyframe mode byte: coded on its own.
pub const MODE_INTRA: u8 = 0;
/// Keyframe mode byte: coded as the difference from the previous keyframe.
pub const MODE_PREDICTED: u8 = 1;

/// Padded plane size: whole tiles.
pub fn padded_size(h: &Header) -> (usize, usize) {
    let t = h.tile_size as usize;
    (h.tiles_x() as usize * t, h.tiles_y() as usize * t)
}

/// The per-tile polynomial degrees of one segment: luma (plane 0) and chroma (planes 1–2).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileMap {
    /// Degree of each luma tile, row-major.
    pub luma: Vec<u8>,
    /// Degree of each chroma tile, row-major (empty for one channel).
    pub chroma: Vec<u8>,
}

impl TileMap {
    /// The degrees of every tile for `plane`: luma for plane 0, chroma for the others.
    pub fn degrees(&self, plane: usize) -> &[u8] {
        if plane == 0 {
            &self.luma
        } else {
            &self.chroma
        }
    }
    /// Degree of `tile` in `plane` (0 luma, 1–2 chroma).
    pub fn degree(&self, plane: usize, tile: usize) -> u8 {
        self.degrees(plane)[tile]
    }
    /// The largest degree of any tile in any plane.
    pub fn max_degree(&self) -> u8 {
        self.luma
            .iter()
            .chain(&self.chroma)
            .copied()
            .max()
            .unwrap_or(1)
    }
}
