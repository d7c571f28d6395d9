//! How a segment's GPU decode is cut into dispatches and spread over frames, chosen for
//! the adapter: a CPU adapter (lavapipe), whose time follows work, and a GPU, whose time
//! per dispatch is mostly latency (BENCHMARKS.md, "On a hardware GPU").

/// The shape of the GPU decode ([`PlayerConfig::decode_shape`]): four settings that trade
/// GPU time between adapters, all of which decode the same coefficients. Start from
/// [`DecodeShape::CPU`], [`DecodeShape::GPU`] or [`DecodeShape::for_adapter`].
///
/// [`PlayerConfig::decode_shape`]: crate::PlayerConfig::decode_shape
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DecodeShape {
    /// How many workgroups one dispatch of a decode pass covers: the grain at which a
    /// segment's decode is recorded over frames. Rounded up to a multiple of 32, at most
    /// 16 384 (a parse dispatch then stays within WebGPU's 65 535 workgroups). A slice is
    /// the smallest piece of work a frame records: with a
    /// [`decode_budget`](crate::PlayerConfig::decode_budget) smaller than one slice's cost,
    /// each frame records one slice and [`Totals::over_budget`](crate::Totals::over_budget)
    /// counts it.
    pub slice_groups: u32,
    /// Parse a coefficient stream with a workgroup per piece (its 64 lanes read the
    /// piece's bytes, varints and pairs side by side, joined by scans) rather than an
    /// invocation per piece reading its pairs in sequence.
    pub wide_parse: bool,
    /// Workgroups that share a group of 64 blocks in the block passes (`key_add`,
    /// `bubble_write`), each visiting its share in sequence: 1, 2, 4 … 64.
    pub group_split: u32,
    /// What each step of a decode (a dispatch, a clear, the upload) costs beside its work,
    /// in the blocks of [`decode_budget`](crate::PlayerConfig::decode_budget): the work
    /// its latency is worth, so that a frame of many small steps counts as the time it
    /// takes.
    pub step_cost: u64,
}

impl DecodeShape {
    /// For a CPU adapter: slices of 32 workgroups (a dispatch's time there is in
    /// proportion to its work, and small slices spread a decode evenly), the serial parse
    /// and whole groups (the wide parse's scans and more workgroups are work there: a
    /// 512² segment took 105 ms with the wide parse against 91 ms), no cost per step.
    pub const CPU: DecodeShape = DecodeShape {
        slice_groups: 32,
        wide_parse: false,
        group_split: 1,
        step_cost: 0,
    };

    /// For a GPU, as measured on an H100: slices of 2048 workgroups (a 4096² segment
    /// took 82 ms in slices of 32, 7.7 ms in 2048), the wide parse (a 4096² segment's
    /// parse 3.2 → 0.34 ms), groups split in 8 (no workgroup walks more than 8 blocks in
    /// sequence), and 40 000 blocks per step: a segment's decode took as long at 512² as
    /// at 2048² (about 20 µs per step whatever its work), and a block's work about
    /// 0.45 ns.
    pub const GPU: DecodeShape = DecodeShape {
        slice_groups: 2048,
        wide_parse: true,
        group_split: 8,
        step_cost: 40_000,
    };

    /// [`DecodeShape::CPU`] on a CPU adapter, [`DecodeShape::GPU`] on any other.
    pub fn for_adapter(info: &wgpu::AdapterInfo) -> DecodeShape {
        if info.device_type == wgpu::DeviceType::Cpu {
            DecodeShape::CPU
        } else {
            DecodeShape::GPU
        }
    }
}
