//! The encoder's settings as data: every knob, the presets, and the check of their ranges.

use vbim_format::limits::MAX_DEGREE;

pub use crate::payloads::FormatVersion;

/// How segment boundaries are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentMode {
    /// Adaptive: as long as the fit meets the budget, up to this many frames.
    Auto {
        /// The longest segment, frames.
        max: u32,
    },
    /// Every segment this many frames (the last may be shorter).
    Fixed(u32),
}

/// A starting point for [`EncoderConfig`]: how much encode time to spend on bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// About 2× quicker than `Default`, degree ≤ 3, for iteration.
    Fast,
    /// The balance measured in BENCHMARKS.md.
    Default,
    /// The fewest bytes: zstd 19 and a denser segment search.
    Best,
}

/// Every knob of the encoder; `docs/MODEL.md` gives each one's measured effect.
#[derive(Clone, Debug)]
pub struct EncoderConfig {
    /// Error budget: the target mean PSNR in dB of the protocol's metric.
    pub tolerance_db: f64,
    /// Find, on a sample of the sequence, the internal budget that delivers
    /// `tolerance_db` (within about ±0.5 dB; BENCHMARKS.md) before coding. Off, the budget
    /// is the tolerance itself and a day with dark nights pools 3 to 6.5 dB above it.
    pub aim: bool,
    /// With `aim`: no frame's PSNR more than this below `tolerance_db` (the protocol pairs
    /// a 45 dB mean with a 38 dB worst frame). The frames below it are raised
    /// (`frame_raise_db`) and the rest of the day pays for them, so that the mean stays
    /// at the tolerance; where that cannot reach the floor, the whole budget is raised, up
    /// to a mean 0.2 dB above the tolerance on the aim's sample. Infinite: no floor.
    pub worst_margin_db: f64,
    /// Highest polynomial degree in time (1 = keyframe interpolation only).
    pub max_degree: usize,
    /// How segment boundaries are chosen.
    pub segment: SegmentMode,
    /// The format version written: version 1 (the default, every player reads it),
    /// version 2 (0.69–0.90× the bytes; the player's decoder thread decodes its sections
    /// to version 1's pairs at 9–12× version 1's CPU time) or version 3 (version 2 with
    /// several rANS states a lane, for a GPU decoder; about 2% more bytes than 2).
    pub format: FormatVersion,
    /// zstd level of the tile maps and, in version 1, of the keyframe and coefficient
    /// payloads (1 to 22).
    pub zstd_level: i32,
    /// Versions 2 and 3: where rANS lanes are cut and, in version 3, how many states
    /// they have ([`Lanes`]: any values are valid). In version 2 every lane is a serial
    /// chain of symbols that a GPU decodes in one invocation: shorter lanes shorten the
    /// longest chain of a plane, for a few bytes each (BENCHMARKS.md, "Lanes"); in
    /// version 3 a lane's states share its symbols.
    ///
    /// [`Lanes`]: crate::Lanes
    pub lanes: crate::Lanes,
    /// Worker threads (0 = one per core). The output does not depend on it.
    pub threads: usize,
    /// Largest distance between independently decodable keyframes, in media seconds.
    pub intra_interval_s: f64,
    /// Side of the square tiles that each choose their own degree, texels.
    pub tile_size: usize,
    /// Media frame rate (num, den).
    pub rate: (u32, u32),
    /// Whether frame N−1 is followed by frame 0 (the model then spans the seam).
    pub looping: bool,
    /// JSON stored in the metadata chunk.
    pub metadata: Option<String>,
    /// Sub-sampling stride of the segment-length search (1 = every texel).
    pub search_stride: usize,
    /// What the encode may hold, in bytes (an estimate counted before it starts; the
    /// output does not depend on it). A sequence whose frames do not fit whole is coded
    /// in bands of tile rows, read from the input a band at a time (docs/MODEL.md).
    pub memory_limit: u64,
    /// Tile rows per band, overriding what `memory_limit` would choose (the output does
    /// not depend on it either; tests and benchmarks compare the two).
    pub band_tiles: Option<usize>,
    /// Dead zone of the quantiser, in steps beyond the half step; `None`: the default
    /// ([`EncoderConfig::deadzone`]).
    pub deadzone: Option<f32>,
    /// Versions 2 and 3: squared quantiser steps a bit is worth to the rate-aware
    /// quantiser, which drops a block's ±1 coefficients whose bits (as version 2's coder
    /// counts them) cost more than the error they save; 0: off. `None`: the version's
    /// default ([`EncoderConfig::rate_lambda`]). Version 1's pairs through zstd are not
    /// what it counts, and it bought nothing there (measured): version 1 ignores it.
    pub rate_lambda: Option<f32>,
    /// Chroma steps relative to luma.
    pub chroma_step_factor: f32,
    /// Extra accuracy asked of single frames, dB above `tolerance_db`'s budget, one value
    /// per frame (empty: none). The keyframe at a frame, and the bubble planes of the
    /// segment around it, are quantised finer by its raise (a segment by the largest
    /// among its frames); segment lengths do not change. With `aim`, this is the starting point: the
    /// aim adds the raises that bring the worst frames up to the floor of
    /// `worst_margin_db` (docs/MODEL.md, "Evening the error out in time").
    pub frame_raise_db: Vec<f64>,
}

/// The tolerances (and internal budgets) the encoder takes, dB: 10 is coarser than any
/// light is worth coding, 99 finer than a half float holds.
pub(crate) const MIN_TOLERANCE_DB: f64 = 10.0;
/// See [`MIN_TOLERANCE_DB`].
pub(crate) const MAX_TOLERANCE_DB: f64 = 99.0;
/// What `--tolerance` promises with the aim: the delivered mean within this of T, dB.
pub(crate) const PROMISE_DB: f64 = 0.5;
/// How far the full encode's PSNR (mean or a frame's) lands from the aim's sample's,
/// about (BENCHMARKS.md, "The worst-frame floor"), dB: a report warns of a miss only
/// beyond it.
pub(crate) const SAMPLE_ERROR_DB: f64 = 0.3;

impl EncoderConfig {
    /// The settings of preset `p`.
    pub fn preset(p: Preset) -> EncoderConfig {
        let base = EncoderConfig {
            tolerance_db: 45.0,
            aim: true,
            worst_margin_db: 7.0,
            max_degree: 4,
            // Longer segments fit the budget but cost more than they save (measured).
            segment: SegmentMode::Auto { max: 32 },
            // Version 1: version 2's sections cost the player's decoder thread 9–12×
            // version 1's CPU time (to pairs), and decoded on an H100 as coded they took
            // 10–18× the pairs' GPU time (BENCHMARKS.md, "Format 2 on the GPU").
            format: FormatVersion::V1,
            zstd_level: 9,
            lanes: crate::Lanes::default(),
            threads: 0,
            intra_interval_s: 4.0,
            tile_size: 16,
            rate: (24, 1),
            looping: true,
            metadata: None,
            search_stride: 4,
            memory_limit: DEFAULT_MEMORY_LIMIT,
            band_tiles: None,
            deadzone: None,
            rate_lambda: None,
            chroma_step_factor: 1.5,
            frame_raise_db: Vec::new(),
        };
        match p {
            Preset::Fast => EncoderConfig {
                max_degree: 3,
                segment: SegmentMode::Auto { max: 24 },
                zstd_level: 3,
                search_stride: 8,
                ..base
            },
            Preset::Default => base,
            // Degree 6 or 64-frame segments were measured to cost bytes: best spends its
            // time on the entropy coder and a denser segment search instead.
            Preset::Best => EncoderConfig {
                zstd_level: 19,
                search_stride: 2,
                ..base
            },
        }
    }

    /// Checks every knob's range; the error names the knob and its range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(MIN_TOLERANCE_DB..=MAX_TOLERANCE_DB).contains(&self.tolerance_db) {
            return Err(ConfigError::Tolerance(self.tolerance_db));
        }
        if self.worst_margin_db.is_nan() || self.worst_margin_db < 0.0 {
            return Err(ConfigError::WorstMargin(self.worst_margin_db));
        }
        if !(1..=MAX_DEGREE as usize).contains(&self.max_degree) {
            return Err(ConfigError::MaxDegree(self.max_degree));
        }
        if matches!(
            self.segment,
            SegmentMode::Auto { max: 0 } | SegmentMode::Fixed(0)
        ) {
            return Err(ConfigError::EmptySegments);
        }
        if !(1..=22).contains(&self.zstd_level) {
            return Err(ConfigError::ZstdLevel(self.zstd_level));
        }
        if self.intra_interval_s.is_nan() || self.intra_interval_s <= 0.0 {
            return Err(ConfigError::IntraInterval(self.intra_interval_s));
        }
        if !(8..=256).contains(&self.tile_size) || !self.tile_size.is_multiple_of(8) {
            return Err(ConfigError::TileSize(self.tile_size));
        }
        let fps = self.rate.0 as f64 / self.rate.1.max(1) as f64;
        let fps_range = vbim_format::limits::MIN_FPS..=vbim_format::limits::MAX_FPS;
        if self.rate.0 == 0 || self.rate.1 == 0 || !fps_range.contains(&fps) {
            return Err(ConfigError::Rate(self.rate.0, self.rate.1));
        }
        if self.search_stride == 0 {
            return Err(ConfigError::SearchStride);
        }
        if self.band_tiles == Some(0) {
            return Err(ConfigError::EmptyBands);
        }
        if let Some((frame, &raise)) = self
            .frame_raise_db
            .iter()
            .enumerate()
            .find(|(_, r)| !(0.0..=MAX_FRAME_RAISE_DB).contains(*r))
        {
            return Err(ConfigError::FrameRaise { frame, raise });
        }
        if let Some(d) = self.deadzone.filter(|d| !(0.0..0.5).contains(d)) {
            return Err(ConfigError::Deadzone(d));
        }
        if let Some(l) = self
            .rate_lambda
            .filter(|l| !(0.0..=MAX_RATE_LAMBDA).contains(l))
        {
            return Err(ConfigError::RateLambda(l));
        }
        if self.threads > max_threads() {
            return Err(ConfigError::Threads {
                threads: self.threads,
                reason: format!(
                    "more than {} (4 per core, at least 16) only adds switching",
                    max_threads()
                ),
            });
        }
        Ok(())
    }

    /// The dead zone used: as set, else 0.2, or 0.15 with the rate-aware quantiser on,
    /// which drops what a wider dead zone would (BENCHMARKS.md, "Rate-aware
    /// quantisation"). So with it off, versions 2 and 3 code the integers of version 1.
    pub fn deadzone(&self) -> f32 {
        self.deadzone
            .unwrap_or(if self.rate_lambda() > 0.0 { 0.15 } else { 0.2 })
    }

    /// The rate-aware quantiser's price of a bit in squared steps: as set (0 in version
    /// 1, which ignores it), else 0.1 in versions 2 and 3.
    pub fn rate_lambda(&self) -> f32 {
        match self.format {
            FormatVersion::V1 => 0.0,
            _ => self.rate_lambda.unwrap_or(0.1),
        }
    }

    /// The intra interval in frames (at least 1).
    pub fn intra_interval_frames(&self) -> u32 {
        ((self.intra_interval_s * self.rate.0 as f64 / self.rate.1 as f64).floor() as u32).max(1)
    }
}

/// The highest price of a bit the rate-aware quantiser takes ([`EncoderConfig::rate_lambda`]),
/// squared steps: at 1 it already drops nearly every ±1 (a ±1 costs a few bits).
pub const MAX_RATE_LAMBDA: f32 = 10.0;

/// The most extra accuracy a frame may be asked for ([`EncoderConfig::frame_raise_db`]), dB.
pub const MAX_FRAME_RAISE_DB: f64 = 40.0;

/// The encoder's memory limit unless told otherwise: 4 GB, which holds a 2048² day's
/// frames whole and codes 4096² and 8192² in bands.
pub const DEFAULT_MEMORY_LIMIT: u64 = 4_000_000_000;

/// The most worker threads an encode may ask for: 4 per core, at least 16. (3,000
/// threads took 10 s just to start; the work is CPU-bound, so more than the cores buys
/// nothing.)
pub fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    (4 * cores).max(16)
}

/// A setting out of its range. Messages name the setting and the range, not a flag: the
/// command line, a build script and a test all see the same error.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// `tolerance_db` outside 10 to 99.
    #[error("tolerance {0} dB is outside 10 to 99")]
    Tolerance(f64),
    /// `worst_margin_db` negative or not a number.
    #[error("worst-frame margin {0} dB is not 0 or more")]
    WorstMargin(f64),
    /// `max_degree` outside 1 to the format's largest.
    #[error("max degree {0} is outside 1 to {MAX_DEGREE}")]
    MaxDegree(usize),
    /// A segment length of 0.
    #[error("segments must be at least 1 frame long")]
    EmptySegments,
    /// `zstd_level` outside 1 to 22.
    #[error("zstd level {0} is outside 1 to 22")]
    ZstdLevel(i32),
    /// `intra_interval_s` not positive.
    #[error("intra interval {0} s is not positive")]
    IntraInterval(f64),
    /// `tile_size` not a multiple of 8 from 8 to 256.
    #[error("tile size {0} is not a multiple of 8 from 8 to 256")]
    TileSize(usize),
    /// A frame rate of nothing, or outside 1/86400 to 1000 frames per second.
    #[error("frame rate {0}/{1} (must be 1/86400 to 1000 frames per second)")]
    Rate(u32, u32),
    /// `search_stride` of 0.
    #[error("search stride 0 (1 searches every texel)")]
    SearchStride,
    /// `band_tiles` of 0.
    #[error("bands must be at least 1 tile row high")]
    EmptyBands,
    /// A value of `frame_raise_db` outside 0 to `MAX_FRAME_RAISE_DB`.
    #[error("frame {frame}'s raise {raise} dB is outside 0 to {MAX_FRAME_RAISE_DB}")]
    FrameRaise {
        /// The frame.
        frame: usize,
        /// Its raise, dB.
        raise: f64,
    },
    /// `frame_raise_db` neither empty nor one value per frame.
    #[error("{given} frame raises for a sequence of {frames} frames")]
    FrameRaiseLength {
        /// Values given.
        given: usize,
        /// Frames in the sequence.
        frames: usize,
    },
    /// `deadzone` outside 0 to 0.5 (not included).
    #[error("dead zone {0} is outside 0 to 0.5 steps")]
    Deadzone(f32),
    /// `rate_lambda` outside 0 to `MAX_RATE_LAMBDA`.
    #[error(
        "rate-aware quantiser's price {0} is outside 0 to {MAX_RATE_LAMBDA} squared steps a bit"
    )]
    RateLambda(f32),
    /// The worker pool could not be started.
    #[error("cannot start {threads} worker threads: {reason}")]
    Threads {
        /// Threads asked for (0: one per core).
        threads: usize,
        /// Why not.
        reason: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_setting_out_of_range_is_named() {
        let ok = EncoderConfig::preset(Preset::Default);
        assert_eq!(ok.validate(), Ok(()));
        let bad = |f: &dyn Fn(&mut EncoderConfig)| {
            let mut c = ok.clone();
            f(&mut c);
            c.validate().unwrap_err()
        };
        assert!(matches!(
            bad(&|c| c.tolerance_db = f64::NAN),
            ConfigError::Tolerance(t) if t.is_nan()
        ));
        assert_eq!(bad(&|c| c.max_degree = 9), ConfigError::MaxDegree(9));
        assert_eq!(
            bad(&|c| c.segment = SegmentMode::Fixed(0)),
            ConfigError::EmptySegments
        );
        assert_eq!(bad(&|c| c.tile_size = 12), ConfigError::TileSize(12));
        assert_eq!(bad(&|c| c.rate = (24, 0)), ConfigError::Rate(24, 0));
        assert_eq!(
            bad(&|c| c.rate = (u32::MAX, 1)),
            ConfigError::Rate(u32::MAX, 1)
        );
        assert!(matches!(
            bad(&|c| c.threads = 100_000),
            ConfigError::Threads {
                threads: 100_000,
                ..
            }
        ));
        assert_eq!(bad(&|c| c.deadzone = Some(0.5)), ConfigError::Deadzone(0.5));
        assert!(matches!(
            bad(&|c| c.rate_lambda = Some(f32::NAN)),
            ConfigError::RateLambda(l) if l.is_nan()
        ));
        let mut c = ok.clone();
        c.threads = max_threads();
        assert_eq!(c.validate(), Ok(()));
    }
}
