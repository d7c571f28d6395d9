//! The memory plan: what the GPU state holds for a stream, in bytes, known before anything
//! of that size is created (so that a stream is refused first), and the layout of the
//! dense plane and its ring of masks.

use super::Gpu;

/// Parts a plane of `blocks` blocks is decoded in, `part` blocks at most each (at least
/// one, so that an empty plane still has its job).
pub(super) fn parts(blocks: u32, part: u32) -> u32 {
    blocks.div_ceil(part).max(1)
}

/// Blocks per workgroup of the block passes (`GROUP_BLOCKS` in decode.wgsl).
pub(super) const GROUP_BLOCKS: u32 = 64;
/// Bytes of the sets of blocks with a coefficient for `blocks` blocks: 64 bits per group
/// of [`GROUP_BLOCKS`].
pub(super) fn group_bytes(blocks: u32) -> u64 {
    blocks.div_ceil(GROUP_BLOCKS) as u64 * 8
}

/// Where the sets start in the mask buffer of a dense plane of `part` blocks: after the
/// masks, at a storage binding's offset alignment (WebGPU's default, 256), so that one
/// clear covers both.
pub(super) fn groups_offset(part: u32) -> u64 {
    (part as u64 * 8).next_multiple_of(256)
}

/// Bytes of the masks and sets of a dense plane of `part` blocks: masks, then sets.
pub(super) fn mask_bytes(part: u32) -> u64 {
    groups_offset(part) + group_bytes(part)
}

/// The ring of masks: one slot of [`mask_bytes`] (at a storage offset's alignment) for
/// each plane a segment's decode parses, so that a segment clears them all in one step
/// before its first parse rather than a plane's before each: on a GPU a step costs about
/// 17 µs whatever its work, and a segment's twelve clears were a third of its steps
/// (BENCHMARKS.md, "On a hardware GPU"). As many slots as a segment has planes without a
/// chain of keyframes (its keyframe's and its bubble terms': channels × degree); a
/// segment with more clears the ring again when it comes round.
pub(super) fn mask_slots(max_degree: u32, channels: u32) -> u32 {
    channels.max(1) * max_degree.max(1)
}

/// Bytes between two slots of the ring of masks.
pub(super) fn slot_bytes(part: u32) -> u64 {
    mask_bytes(part).next_multiple_of(256)
}

pub(super) use crate::coded::part_blocks;

/// Workgroups per dispatch row: WebGPU's default limit per dimension.
pub(super) const GROUPS_X: u32 = 65_535;

/// Bytes a buffer of at least `need` bytes is given: an eighth more (at least 64 KiB), so
/// that it grows a few times at the start of a stream and then never, without the up to
/// 2× of rounding to a power of two (2 bytes per texel of a 2048² stream's coefficients).
pub(super) fn grown(need: u64) -> u64 {
    (need + need / 8)
        .max(1 << 16)
        .next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT)
}

/// The side of a region of a 16-bit keyframe with its own range (`REGION` in
/// decode.wgsl; `REGION_GROUPS` workgroups of 16 × 16 texels in reconstruct.wgsl).
pub(super) const REGION: u32 = 32;

/// Regions of [`REGION`]² texels across and down a plane of `plane` texels.
pub(super) fn regions(plane: [u32; 2]) -> [u32; 2] {
    plane.map(|n| n.div_ceil(REGION))
}

/// Bytes of the 16-bit keyframes' ranges: a (lowest value, step) pair of f32 per region,
/// plane and slot.
pub(super) fn range_bytes(plane: [u32; 2], channels: u32) -> u64 {
    let [rx, ry] = regions(plane);
    rx as u64 * ry as u64 * (KEY_SLOTS * channels) as u64 * 8
}

/// The fewest layers an array texture may have on `device`'s backend. wgpu's GL backend
/// decides whether a texture is an array from its layer count alone (one layer: a plain
/// 2D texture), and a one-layer texture bound as `texture_2d_array` there reads back
/// garbage; a second, unused layer keeps it an array. Other backends need no padding.
pub(crate) fn min_array_layers(device: &wgpu::Device) -> u32 {
    if device.adapter_info().backend == wgpu::Backend::Gl {
        2
    } else {
        1
    }
}

/// A 2D texture of `width × height × layers` texels of `format`: one mip level, no
/// multisampling, no other view formats.
pub(super) fn texture_descriptor(
    label: &'static str,
    (width, height, depth_or_array_layers): (u32, u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::TextureDescriptor<'static> {
    wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    }
}

/// A lightmap texture of `width × height` texels as the player writes it: 2D,
/// `Rgba16Float` (linear RGB in the stream's units, alpha 1), one mip level. A texture
/// given to [`Player::set_output`](crate::Player::set_output) needs at least
/// `STORAGE_BINDING | TEXTURE_BINDING` in `usage`.
pub fn lightmap_descriptor(
    width: u32,
    height: u32,
    usage: wgpu::TextureUsages,
) -> wgpu::TextureDescriptor<'static> {
    texture_descriptor(
        "vbim lightmap",
        (width, height, 1),
        wgpu::TextureFormat::Rgba16Float,
        usage,
    )
}

/// Slots of 16-bit keyframes: K_s of the segment on screen, and the one the next
/// segment's decode packs the head into (K_{s+1}, which the display reads from the head
/// until then).
pub(crate) const KEY_SLOTS: u32 = 2;
/// Bubble sets: the segment on screen's, and the one the next segment decodes into.
pub(crate) const BUBBLE_SETS: u32 = 2;

/// Bubble layers of one set for terms up to `max_degree` (at least one).
pub(crate) fn set_layers(max_degree: u32, channels: u32) -> u32 {
    (max_degree.saturating_sub(1) * channels).max(1)
}

/// The textures [`Gpu::new`] creates for a stream of `width × height` texels coded on
/// planes of `plane` texels with bubble terms up to `max_degree`: the head keyframe
/// (f32), the 16-bit keyframes ([`KEY_SLOTS`] slots) in 16-bit pairs, the bubble blocks
/// ([`BUBBLE_SETS`] sets: per block of 8 × 8 texels and bubble layer, its coefficients'
/// mask, where its terms after the first start, and the first, in an `Rgba32Uint`
/// texel), the lightmap (Rgba16Float) and its held copy (RGB9E5 packed into R32Uint).
/// Array textures have at least `min_layers` layers ([`min_array_layers`]).
pub(super) fn texture_plans(
    (width, height): (u32, u32),
    plane: [u32; 2],
    max_degree: u32,
    channels: u32,
    min_layers: u32,
) -> [wgpu::TextureDescriptor<'static>; 5] {
    use wgpu::TextureUsages as U;
    let bubble_layers = BUBBLE_SETS * set_layers(max_degree, channels);
    let packed_layers = KEY_SLOTS * channels;
    let channels = channels.max(min_layers);
    [
        texture_descriptor(
            "vbim head keyframe",
            (plane[0], plane[1], channels),
            wgpu::TextureFormat::R32Float,
            // (COPY_SRC: tests read it back.)
            U::TEXTURE_BINDING | U::STORAGE_BINDING | U::COPY_SRC,
        ),
        texture_descriptor(
            "vbim 16-bit keyframes",
            (plane[0] / 2, plane[1], packed_layers),
            wgpu::TextureFormat::R32Uint,
            U::TEXTURE_BINDING | U::STORAGE_BINDING | U::COPY_SRC,
        ),
        texture_descriptor(
            "vbim bubble blocks",
            (plane[0] / 8, plane[1] / 8, bubble_layers),
            wgpu::TextureFormat::Rgba32Uint,
            // (COPY_SRC: tests read it back.)
            U::TEXTURE_BINDING | U::STORAGE_BINDING | U::COPY_SRC,
        ),
        lightmap_descriptor(
            width,
            height,
            U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC,
        ),
        texture_descriptor(
            "vbim held",
            (width, height, 1),
            wgpu::TextureFormat::R32Uint,
            U::TEXTURE_BINDING | U::STORAGE_BINDING,
        ),
    ]
}

/// Words of one bubble set in the degrees buffer: a u32 per tile of `tile`² texels and
/// plane (`degrees` in decode.wgsl), then the set's term counter (where the next block's
/// terms go in the set's term buffer).
pub(super) fn degree_stride(plane: [u32; 2], tile: u32, channels: u32) -> u32 {
    let [tx, ty] = plane.map(|n| n / tile.max(1));
    tx * ty * channels + 1
}

/// Bytes of the tiles' degrees and the sets' term counters ([`degree_stride`] words per
/// set).
pub(super) fn degree_bytes(plane: [u32; 2], tile: u32, channels: u32) -> u64 {
    degree_stride(plane, tile, channels) as u64 * BUBBLE_SETS as u64 * 4
}

/// Bytes each bubble set's term buffer starts with (it grows with the segments' terms).
pub(super) const FIRST_TERM_BYTES: u64 = 1 << 16;

/// Bytes of the textures, the range buffer and the dense plane [`Gpu::new`] creates for a
/// stream ([`texture_plans`]'s) of tiles of `tile`² texels, known before creating them, so
/// that a stream is refused before anything that size exists.
pub(crate) fn planned_texture_bytes(
    size: (u32, u32),
    plane: [u32; 2],
    (max_degree, tile): (u32, u32),
    channels: u32,
    min_layers: u32,
) -> u64 {
    texture_plans(size, plane, max_degree, channels, min_layers)
        .iter()
        .map(|d| extent_bytes(d.size, d.format))
        .sum::<u64>()
        + range_bytes(plane, channels)
        + part_blocks(plane) as u64 * 256
        + mask_slots(max_degree, channels) as u64 * slot_bytes(part_blocks(plane))
        + BUBBLE_SETS as u64 * FIRST_TERM_BYTES
        + tile_bytes(size).0
        + tile_bytes(size).1
        + degree_bytes(plane, tile, channels)
}

/// Tiles of 16² texels the reconstruction decides for (a workgroup each).
pub(super) fn tile_count((w, h): (u32, u32)) -> u64 {
    w.div_ceil(16).max(1) as u64 * h.div_ceil(16).max(1) as u64
}

/// Bytes of the reconstruction's tile state, and of its tiles' bounds: two copies of 10
/// words, and 9 words, per tile (reconstruct.wgsl, `STATE_WORDS`, `PEAK_WORDS`); after
/// the bounds, the three counters of kept tiles (and a word of padding).
pub(super) fn tile_bytes(size: (u32, u32)) -> (u64, u64) {
    (tile_count(size) * 2 * 10 * 4, tile_count(size) * 9 * 4 + 16)
}

/// Bytes a texture holds (one mip level, every layer).
pub(super) fn texture_bytes(t: &wgpu::Texture) -> u64 {
    extent_bytes(t.size(), t.format())
}

/// Bytes of a texture of `size` texels of `format`.
pub(super) fn extent_bytes(size: wgpu::Extent3d, format: wgpu::TextureFormat) -> u64 {
    let texel = format.block_copy_size(None).unwrap_or(0) as u64;
    size.width as u64 * size.height as u64 * size.depth_or_array_layers as u64 * texel
}

impl Gpu {
    /// Bytes of the textures and buffers the player holds on the GPU (the budget's figure).
    pub fn bytes(&self) -> u64 {
        [
            &self.keys,
            &self.packed,
            &self.bubble_blocks,
            &self.display,
            &self.held,
        ]
        .iter()
        .map(|t| texture_bytes(t))
        .sum::<u64>()
            + self.ranges.size()
            + self.params.size()
            + self.tables.size()
            + self.jobs.size()
            + self.words.size()
            + self.slices.size()
            + self.coefs.size()
            + self.masks.size()
            + self.tiles.size()
            + self.peaks.size()
            + self.degrees.size()
            + self.terms.iter().map(|t| t.size()).sum::<u64>()
            + self.lanes.as_ref().map_or(0, |l| l.bytes())
    }
}
