//! How a segment's GPU decode is cut into dispatches and spread over frames, chosen for
//! the adapter: a CPU adapter (lavapipe), whose time follows work, and a GPU, whose time
//! per dispatch is mostly latency (BENCHMARKS.md, "On a hardware GPU").

/// The shape of the GPU decode ([`PlayerConfig::decode_shape`]): settings that trade
/// GPU time between adapters, all of which decode the same coefficients. Start from
/// [`DecodeShape::CPU`], [`DecodeShape::GPU`] or [`DecodeShape::for_adapter`].
///
/// [`PlayerConfig::decode_shape`]: crate::PlayerConfig::decode_shape
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DecodeShape {
    /// How many workgroups one dispatch of a decode pass covers: the grain at which a
    /// segment's decode is recorded over frames. Rounded up to a multiple of 32, at most
    /// 16 384 (a parse dispatch then stays within WebGPU's 65 535 workgroups). A pass whose
    /// workgroups cost less than 64 blocks of the budget's unit (by
    /// [`DecodeShape::weights`]: the keyframe's pack, the bubble gather, a split
    /// group) covers as many more, up to 16 384, so that its dispatches record the same work in
    /// fewer steps. A slice is
    /// the smallest piece of work a frame records: with a
    /// [`decode_budget`](crate::PlayerConfig::decode_budget) smaller than one slice's cost,
    /// each frame records one slice and [`Totals::over_budget`](crate::Totals::over_budget)
    /// counts it.
    pub slice_groups: u32,
    /// Parse a coefficient stream with a workgroup per piece (its 64 lanes read the
    /// piece's bytes, varints and pairs side by side, joined by scans) rather than an
    /// invocation per piece reading its pairs in sequence.
    pub wide_parse: bool,
    /// Workgroups that share a group of 64 blocks in the keyframe block pass (`key_add`),
    /// each visiting its share in sequence: 1, 2, 4 … 64.
    pub group_split: u32,
    /// What each step of a decode (a dispatch, a clear, the upload) costs beside its work,
    /// in the blocks of [`decode_budget`](crate::PlayerConfig::decode_budget): the work
    /// its latency is worth, so that a frame of many small steps counts as the time it
    /// takes.
    pub step_cost: u64,
    /// What a unit of each decode pass costs, in the same blocks.
    pub weights: PassWeights,
    /// Decode a version 2 file's coefficient sections on the GPU as the file codes them
    /// (`lanes.wgsl`: an invocation per rANS lane); `false`: the decoder thread decodes
    /// them to version 1's pairs, which the GPU parses. Off for both adapters: a lane is
    /// a serial chain of symbols (40 000–72 000 per segment along the longest lanes of
    /// the benchmark streams), and an H100 took 22, 32 and 61 ms per 512², 2048² and
    /// 4096² segment that way, against 1.7, 1.8 and 6.2 ms for the same sections as
    /// pairs (BENCHMARKS.md, "Format 2 on the GPU"); lavapipe 49–60 ms against 22 ms at
    /// 512² (with the lane fields below). Since, a keyframe's planes and a segment's
    /// bubble planes go in batches that share each dispatch: 2.3–2.9 times shorter chains
    /// and a third of the dispatches, for 8 B/texel more GPU memory with the lanes on
    /// (a dense plane of a keyframe's planes); not yet measured on hardware
    /// (BENCHMARKS.md, "A chunk's planes side by side"). Planes larger than the dense
    /// plane (about 5800² texels) always go as pairs.
    pub lanes: bool,
    /// Keep the DCT tables that the keyframe passes and the reconstruction index per
    /// invocation (each at its own texel and term) in a storage buffer rather than a
    /// uniform one. On an H200 a storage buffer took 6–8% off a smooth day's displayed
    /// frame and 29% off a detailed day's, whose blocks hold several terms each (a GPU's
    /// constant cache serves one address at a time, and a warp's invocations ask for
    /// several); on lavapipe a uniform buffer is 14% faster (BENCHMARKS.md, "On a
    /// hardware GPU").
    pub storage_tables: bool,
    /// An invocation of the reconstruction evaluates two quads of 2 × 2 texels side by
    /// side rather than one, so that a block's terms, a region's range and a tile's
    /// degree are found once for eight texels. On an H200 it took 14–21% off a detailed
    /// day's reconstruction (blocks of several terms) and changed nothing measurable on
    /// smooth days; on lavapipe the frame was 15–25% slower with it (BENCHMARKS.md, "On a
    /// hardware GPU").
    pub wide_reconstruct: bool,
    /// States of a lane decoded side by side in one workgroup of the lane passes
    /// ([`DecodeShape::lanes`]), 1 to 64. On a GPU one: a state is a serial chain whose
    /// branches follow its own symbols, so states that share a warp wait for each other
    /// (an H100 took twice as long with eight). On a CPU adapter eight, whose SIMD runs a
    /// workgroup's invocations in lockstep: a 512² segment of the demo in version 3 took
    /// 49 ms on lavapipe against 74 ms with one (BENCHMARKS.md, "Format 2 on the GPU").
    pub lane_group: u32,
    /// The lane passes read their job from a storage buffer rather than a uniform one. On
    /// a CPU adapter a storage buffer: lavapipe (Mesa 22.3) optimises a shader whose loops
    /// test a uniform again, with the uniform's value put in, every time the bound value
    /// changes — every plane's dispatches —, and a 512² segment's lanes took 210–281 ms
    /// that way against 49 ms. On a GPU the uniform buffer the lanes were measured with.
    pub lane_job_storage: bool,
}

impl DecodeShape {
    /// For a CPU adapter: slices of 32 workgroups (a dispatch's time there is in
    /// proportion to its work, and small slices spread a decode evenly), the serial parse
    /// and whole groups (the wide parse's scans and more workgroups are work there: a
    /// 512² segment took 105 ms with the wide parse against 91 ms), no cost per step,
    /// version 2's sections decoded to pairs by the decoder thread, the DCT tables in a
    /// uniform buffer, a quad per invocation of the reconstruction; should the lanes be
    /// turned on, eight states a workgroup and their job in a storage buffer.
    pub const CPU: DecodeShape = DecodeShape {
        slice_groups: 32,
        wide_parse: false,
        group_split: 1,
        step_cost: 0,
        weights: PassWeights::LAVAPIPE,
        lanes: false,
        storage_tables: false,
        wide_reconstruct: false,
        lane_group: 8,
        lane_job_storage: true,
    };

    /// For a GPU, as measured on an H100: slices of 2048 workgroups (a 4096² segment
    /// took 82 ms in slices of 32, 7.7 ms in 2048), the wide parse (a 4096² segment's
    /// parse 3.2 → 0.34 ms), groups split in up to 8 where a pass has too few to fill the
    /// chip (a 512² segment's `key_add` 0.33 → 0.09 ms), and 35 000 blocks per step: a
    /// segment's decode took as long at 512² as at 2048² (about 20 µs per step whatever
    /// its work), and a block of the budget's unit about 0.58 ns ([`PassWeights::H100`]);
    /// version 2's sections decoded to pairs by the decoder thread (`lanes`); the DCT
    /// tables in a storage buffer and two quads per invocation of the reconstruction
    /// (measured on an H200); should the lanes be turned on, a state a workgroup and
    /// their job in a uniform buffer.
    pub const GPU: DecodeShape = DecodeShape {
        slice_groups: 2048,
        wide_parse: true,
        group_split: 8,
        step_cost: 35_000,
        weights: PassWeights::H100,
        lanes: false,
        storage_tables: true,
        wide_reconstruct: true,
        lane_group: 1,
        lane_job_storage: false,
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

/// The shape `cfg` asks for, or the adapter's ([`DecodeShape::for_adapter`]).
pub(crate) fn resolved(cfg: &crate::PlayerConfig, device: &wgpu::Device) -> DecodeShape {
    cfg.decode_shape
        .unwrap_or_else(|| DecodeShape::for_adapter(&device.adapter_info()))
}

/// What one unit of each decode pass costs, in quarters of a block (the unit of
/// [`PlayerConfig::decode_budget`]: the time of a block's 64 texel sums of one sparse term,
/// what writing a bubble block as texels cost when bubble planes were decoded to texels;
/// the weights below were fitted in it): how the player shares a segment's decode out over
/// frames. Each pass's unit is named with its field.
///
/// [`PlayerConfig::decode_budget`]: crate::PlayerConfig::decode_budget
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PassWeights {
    /// An entry point of a coefficient stream: a piece of up to 128 pairs.
    pub parse: u32,
    /// A block of a keyframe plane added onto the head.
    pub key_add: u32,
    /// 1/16 of a 32² region of the head measured and packed into 16 bits.
    pub key_pack: u32,
    /// A block of a bubble plane gathered into its set: its mask, first term and the
    /// rest's place written.
    pub bubble_gather: u32,
    /// A 16-bit word of a version 2 plane's longest rANS lane decoded (`lane_blocks`,
    /// both parities): the serial chain its decode waits for.
    pub lane_word: u32,
    /// A block of a version 2 plane through each of its other passes (`lane_prepare`, the
    /// two DC scans; the groups' flags per group pair; a section's tables per 16
    /// invocations).
    pub lane_block: u32,
}

impl PassWeights {
    /// Measured on lavapipe from the frames of `vbim bench render --csv` (the extra time
    /// of each frame against the work of each kind it recorded): an entry point reads 128
    /// pairs in sequence, a keyframe block's inverse transform reads every coefficient of
    /// a dense keyframe, packing touches a texel once. A bubble block's gather, 0.13 µs
    /// against `key_add`'s 0.58 µs a block on the 2048² benchmark day (`vbim bench decode
    /// --gpu`), is 3.
    pub const LAVAPIPE: PassWeights = PassWeights {
        parse: 55,
        key_add: 12,
        key_pack: 2,
        bubble_gather: 3,
        // 4.1 µs a word of the longest lane (`bench decode --gpu --lanes true --fit` on
        // the demo in 2.0, eight states a workgroup, the job in a storage buffer): llvmpipe
        // runs a workgroup's states side by side, so the other states' symbols add to the
        // longest's.
        lane_word: 55,
        lane_block: 1,
    };

    /// Fitted on an H100 from each pass's GPU time per 4096² segment (`vbim bench decode
    /// --gpu`, timestamps between passes), less 20 µs per dispatch (the step cost): a
    /// block of the budget's unit about 0.58 ns there. Arithmetic is cheap on a GPU
    /// (a keyframe block's transform 3 quarter-blocks, against lavapipe's 12); a parse's
    /// entry point, 3.5–10 ns of work beside its dispatch's latency, 40. A bubble block's
    /// gather (a mask, a 16-byte store and its few terms) is not measured there yet: 1,
    /// what zeroing a block's texels weighed.
    pub const H100: PassWeights = PassWeights {
        parse: 40,
        key_add: 3,
        key_pack: 2,
        bubble_gather: 1,
        // 5–14 µs a word of the longest lane (`bench decode --gpu --lanes true` on the
        // benchmark streams in 2.0, a lane to a workgroup: 12–22 symbols a word,
        // 0.45–0.63 µs a symbol), the larger streams' 12 µs here.
        lane_word: 80_000,
        lane_block: 1,
    };
}
