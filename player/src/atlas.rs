//! Where the bubble planes' tiles live on the GPU: an atlas of tile-sized slots. A
//! segment's bubble plane (term k, plane p) holds only the tiles whose degree reaches k,
//! so only those take slots: plane after plane, each plane's tiles in raster order. The
//! atlas is as wide as the lightmap's row of tiles, one slot row after another, in array
//! layers of at most 8192 texel rows (WebGPU's default largest 2D texture); it grows when
//! a segment needs more slots than any before it (its contents are rebuilt for every
//! segment, so nothing is copied). `decode.wgsl` builds the map from a tile to its slot on
//! the GPU, from the segment's tile map.
//!
//! The decoder lays each plane's blocks out in atlas coordinates (`compact.rs` runs), so
//! the decode pass writes them where they go without a lookup; the reconstruction looks
//! each texel's tile up in the map.

use vbim_format::dct::N;
use vbim_format::Header;

/// The atlas's shape, fixed at open from the header; its size grows with the slots.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Atlas {
    /// Slots per slot row (the lightmap's tiles per row).
    pub cols: usize,
    /// Slot rows per array layer.
    pub rows_per_layer: usize,
    /// Tile size, texels.
    pub tile: usize,
}

/// Largest 2D texture side WebGPU guarantees.
const MAX_SIDE: usize = 8192;
/// Array layers a record can name (6 bits).
pub(crate) const MAX_LAYERS: usize = 64;

impl Atlas {
    pub fn new(h: &Header) -> Atlas {
        let tile = h.tile_size as usize;
        Atlas {
            cols: h.tiles_x() as usize,
            rows_per_layer: (MAX_SIDE / tile).max(1),
            tile,
        }
    }

    /// Blocks per tile side.
    fn per(&self) -> usize {
        self.tile / N
    }

    /// Slot `s`'s array layer, slot row in that layer and column.
    #[cfg(test)]
    pub fn place(&self, s: usize) -> (u32, usize, usize) {
        let row = s / self.cols;
        (
            (row / self.rows_per_layer) as u32,
            row % self.rows_per_layer,
            s % self.cols,
        )
    }

    /// Block rows (layer, row of blocks in it) that slots `[base, base + n)` cover.
    pub fn rows(&self, base: usize, n: usize) -> impl Iterator<Item = (u32, usize)> + use<> {
        let (per, cols, rpl) = (self.per(), self.cols, self.rows_per_layer);
        let last = if n == 0 { 0 } else { (base + n - 1) / cols + 1 };
        let first = (base / cols).min(last);
        (first..last).flat_map(move |row| {
            let (layer, r) = ((row / rpl) as u32, row % rpl);
            (0..per).map(move |j| (layer, r * per + j))
        })
    }

    /// Row width in blocks.
    pub fn width(&self) -> usize {
        self.cols * self.per()
    }

    /// The stream block at block (`bx`, `by`) of atlas layer `layer`, when that block
    /// belongs to one of slots `[base, base + n)`: the slot's rank from `base` is the
    /// member tile's rank, whose blocks come in raster order.
    pub fn block(
        &self,
        (base, n): (usize, usize),
        layer: u32,
        bx: usize,
        by: usize,
    ) -> Option<usize> {
        let per = self.per();
        let s = (layer as usize * self.rows_per_layer + by / per) * self.cols + bx / per;
        let rank = s.checked_sub(base).filter(|&r| r < n)?;
        Some((rank * per + by % per) * per + bx % per)
    }

    /// The atlas texture for `slots` slots: R32Uint texels (two 16-bit texels each)
    /// across, texel rows, array layers.
    pub fn extent(&self, slots: usize) -> (u32, u32, u32) {
        let rows = slots.div_ceil(self.cols).max(1);
        let layers = rows.div_ceil(self.rows_per_layer);
        (
            (self.cols * self.tile / 2) as u32,
            (rows.min(self.rows_per_layer) * self.tile) as u32,
            layers as u32,
        )
    }

    /// Most slots the atlas can address (records name at most [`MAX_LAYERS`] layers).
    pub fn max_slots(&self) -> usize {
        MAX_LAYERS * self.rows_per_layer * self.cols
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn atlas(cols: usize, rows_per_layer: usize, tile: usize) -> Atlas {
        Atlas {
            cols,
            rows_per_layer,
            tile,
        }
    }

    #[test]
    fn slots_fill_rows_then_layers_and_blocks_find_their_tiles() {
        let a = atlas(3, 2, 16);
        assert_eq!(a.place(0), (0, 0, 0));
        assert_eq!(a.place(4), (0, 1, 1));
        assert_eq!(a.place(6), (1, 0, 0));
        // Slots 4..8 cover slot rows 1 (layer 0) and 0, 1 of layer 1... rows of 2 blocks.
        let rows: Vec<_> = a.rows(4, 4).collect();
        assert_eq!(rows, [(0, 2), (0, 3), (1, 0), (1, 1)]);
        // Slot 4 is rank 0: its block (1, 1) is the fourth of the plane's first tile.
        assert_eq!(a.block((4, 4), 0, 3, 3), Some(3));
        // Slot 6 (layer 1, row 0, column 0) is rank 2.
        assert_eq!(a.block((4, 4), 1, 0, 0), Some(8));
        // Slot 3 is before the plane, slot 8 past it.
        assert_eq!(a.block((4, 4), 0, 0, 2), None);
        assert_eq!(a.block((4, 4), 1, 4, 2), None);
        assert_eq!(a.extent(7), (24, 32, 2));
        assert_eq!(a.rows(5, 0).count(), 0);
    }
}
