//! The arguments of `vbim bench …`, every option with its unit and default.

use std::path::PathBuf;

use clap::{Args, Subcommand};

use crate::cli::MemoryArgs;
use crate::units::{Span, StallSpec};

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Time the baker: precomputation, per-frame lighting and file writing, apart.
    Bake(BenchBakeArgs),
    /// Time the player's decoder on a file: the entropy decoding alone (zstd, or format 2's rANS to pairs), and the decoder's whole work (checks,
    /// zstd, the scan for the GPU's entry points), as a share of one core at the file's frame rate.
    Decode(BenchDecodeArgs),
    /// Bytes of the protocol's lossless baseline: every frame's half-float RGB through zstd.
    Lossless(BenchLosslessArgs),
    /// Draw a rate–distortion CSV (method,setting,bytes,bpp,mean_psnr,…) as a PNG plot.
    PlotRd(BenchPlotArgs),
    /// Draw a tolerance CSV (sequence,mode,asked,delivered,…; scripts/tolerance_bench.sh):
    /// the mean PSNR delivered minus the tolerance asked, against it, with the ±0.5 dB band.
    PlotTolerance(BenchPlotArgs),
    /// Draw a size CSV (size,detail,frames,bake_s,bake_peak_mb,encode_s,encode_peak_mb,…;
    /// scripts/size_bench.sh): the bake's and the encoder's peak memory against the size.
    PlotSize(BenchPlotArgs),
    /// Draw a reuse CSV (pace,share,gpu_ms,…,mean_ratio,…,psnr_db,worst_db;
    /// scripts/reuse_bench.sh): shown error against GPU time per displayed frame, one line
    /// per pace, a point per `--reuse-share`.
    PlotReuse(BenchPlotArgs),
    /// Sweep bandwidth caps from 0.25× to 2× the stream's mean rate under a stall pattern,
    /// for each policy; drift and shown error against bandwidth (CSV + PNG).
    Drift(BenchDriftArgs),
    /// The render thread's CPU time per displayed frame (`advance`: plan + record + submit,
    /// waiting for the GPU between frames so that its execution is not counted), and the
    /// GPU time apart; real time, 60 Hz, reader and decoder on their own threads.
    Render(BenchRenderArgs),
    /// What the runtime costs as the lightmap grows: for each size, a day baked and encoded
    /// (default preset, 24/1 fps), then played in a process of its own: file bytes, the
    /// player's GPU memory and the process's peak per texel, bytes uploaded against bytes
    /// read over a loop, the decoder's share of a core, render-thread CPU and GPU time per
    /// frame. A table, `scale.csv` and three plots.
    Scale(BenchScaleArgs),
    /// One stream of `bench scale`, measured in this process (JSON on stdout).
    #[command(hide = true)]
    ScaleOne(BenchScaleOneArgs),
    /// How much of the lightmap each displayed frame changes, at several media rates: the
    /// share of tiles a player would have to re-evaluate, found with the reference decoder
    /// (what re-evaluating only the tiles that change could save).
    Changes(BenchChangesArgs),
    /// What a context-adaptive entropy coder would make of the file's coefficient streams:
    /// the ideal code length of an adaptive binary model (which an arithmetic coder
    /// reaches within about 1%) against their bytes now (zstd of run/value pairs), by kind
    /// of stream; then the same for static designs a GPU decodes in parallel (per-chunk
    /// histograms, rANS lanes), by design and number of histograms. Measures what a change
    /// of the format's entropy coding would buy.
    Entropy(BenchEntropyArgs),
    /// Light for objects in a package with irradiance tracks: each track's bytes per frame
    /// and share of its weather's bytes, the buffer and what a frame uploads, and the cost
    /// of `PackagePlayer::irradiance` per call on one core (10 000 queries at scattered
    /// positions and normals, two frames mixed and, mid-fade, four).
    Objects(BenchObjectsArgs),
    /// What larger transforms would make of the planes the encoder quantises: the frames
    /// encoded once with the encoder's tap on, then every keyframe and bubble plane coded
    /// in 8 × 8 blocks (the format's), 16 × 16, 32 × 32 or a choice per 16 × 16 region, by
    /// one adaptive model: bytes at equal error, and the terms a texel's reconstruction
    /// sums. A research harness for the format's next coding tool.
    Transforms(BenchTransformsArgs),
    /// What predicting a keyframe's blocks from what is decoded around them would make of
    /// the planes the encoder quantises: a zero-mean surface through the neighbouring
    /// blocks' DCs (a GPU still decodes every block at once), or AV1's texel modes from the
    /// reconstructed texels above and to the left, each chosen per block against today's
    /// coding, closed loop, by one adaptive model: bytes at equal error. A research harness.
    Intra(BenchIntraArgs),
}

#[derive(Args)]
pub struct BenchIntraArgs {
    #[command(flatten)]
    pub study: StudyArgs,
}

/// What the coding studies (`bench transforms`, `bench intra`) take.
#[derive(Args)]
pub struct StudyArgs {
    /// The frames (a directory of numbered EXR or PNG frames, as `vbim encode` takes).
    pub frames: String,
    /// The budget, in dB, encoded at as it is (`--tolerance T --no-aim`).
    #[arg(long, default_value_t = 41.0)]
    pub tolerance: f64,
    /// The frame rate the frames are encoded at.
    #[arg(long, default_value = "24/1", value_parser = crate::units::parse_rate)]
    pub fps: (u32, u32),
    /// Multiples of each plane's step to code at: each way's bytes are read off the line
    /// through them at today's coding's error at 1 (keep 1 among them).
    #[arg(long, default_value = "0.9,1,1.12,1.25,1.4", value_delimiter = ',')]
    pub steps: Vec<f32>,
}

#[derive(Args)]
pub struct BenchTransformsArgs {
    #[command(flatten)]
    pub study: StudyArgs,
    /// What the choices charge for the reconstruction's work: bits per term a texel's
    /// reconstruction sums, in units of an 8 × 8 block's term (a 16 × 16 block's term counts
    /// four). 0: bytes and error alone.
    #[arg(long, default_value_t = 0.0)]
    pub term_bits: f64,
    /// Code every keyframe block, of every size, less the zero-mean quadratic surface
    /// through its 3 × 3 blocks' decoded means (`bench intra`'s surface), to see what it
    /// adds to larger blocks.
    #[arg(long, conflicts_with = "intra")]
    pub surface: bool,
    /// Also code the quadtree with its keyframes' 8 × 8 blocks free to take `bench intra`'s
    /// texel modes (closed loop, once the quadtree is chosen): what texel intra adds beside
    /// larger blocks.
    #[arg(long)]
    pub intra: bool,
}

#[derive(Args)]
pub struct BenchObjectsArgs {
    /// The package (.vbimpkg) with irradiance tracks.
    pub package: PathBuf,
    /// Queries per timed run.
    #[arg(long, default_value_t = 10_000)]
    pub queries: usize,
    /// Timed runs (the median and the spread are reported).
    #[arg(long, default_value_t = 7)]
    pub runs: usize,
    /// Also plot, from noon to midnight, what an up-facing object receives in the cell the
    /// evening sun leaves last (a ridge) and in the one it leaves first (a valley), and
    /// the sun's share of each (PNG).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

#[derive(Args)]
pub struct BenchEntropyArgs {
    /// The .vbim file.
    pub file: PathBuf,
    /// Cut every stream into substreams of this many blocks, each parsed on its own (its
    /// probabilities learnt from scratch, no context from another): what parsing on the
    /// GPU in parallel would cost (0: one substream per stream). Every chunk starts from
    /// scratch in any case, so that a player can seek to it.
    #[arg(long, default_value_t = 0)]
    pub substream: usize,
}

#[derive(Args)]
pub struct BenchChangesArgs {
    /// The .vbim file.
    pub file: PathBuf,
    /// Media rates to play at, in frames per second (`1/6`: a frame every 6 seconds).
    #[arg(long, default_value = "24,6,1,1/6", value_delimiter = ',', value_parser = crate::units::parse_rate)]
    pub rates: Vec<(u32, u32)>,
    /// The display's refresh rate.
    #[arg(long, default_value_t = 60.0)]
    pub display_hz: f64,
    /// Displayed frames per phase.
    #[arg(long, default_value_t = 120)]
    pub shown: usize,
    /// Starting points spread evenly over the day (night, sunrise, noon, sunset, …).
    #[arg(long, default_value_t = 8)]
    pub phases: usize,
    /// A tile is re-evaluated when a texel of it would be further than this share of the
    /// protocol's bound from the true value.
    #[arg(long, default_value_t = 0.25)]
    pub share: f64,
}

#[derive(Args)]
pub struct BenchRenderArgs {
    /// The .vbim file.
    pub file: PathBuf,
    /// Displayed frames measured per run.
    #[arg(long, default_value_t = 600)]
    pub frames: u64,
    /// Runs (each a fresh player); the figures are the median over runs and their spread.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// The player's per-frame decode budget, blocks (`PlayerConfig::decode_budget`);
    /// unset: the default, each segment spread over the frames before it is due.
    #[arg(long)]
    pub budget: Option<u64>,
    #[command(flatten)]
    pub shape: ShapeArgs,
    /// `PlayerConfig::reuse_share`: how far a tile may lag before it is evaluated again,
    /// as a share of the protocol's GPU bound (0: every texel every frame).
    #[arg(long, default_value_t = 0.25, value_parser = crate::cli::parse_share)]
    pub reuse_share: f32,
    /// Play the file this many times slower than its own rate (a 240-frame day at 1/6 fps,
    /// a 24-minute day, is `--slow 144` on a 24 fps file): media time per displayed frame
    /// is what lets tiles be reused.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=100000))]
    pub slow: u64,
    /// Media frame to start at (the figures change over a day: a sunrise changes every
    /// texel, a noon little).
    #[arg(long, default_value_t = 0)]
    pub start: u64,
    /// Write the last run's frames (GPU time, blend, decode work, segment; with
    /// `--passes`, the decode's and the reconstruction's GPU time) to this CSV.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Also time each pass of every frame (GPU timestamps between the passes, where the
    /// adapter has them inside passes; the frame's own figures then include their cost),
    /// and print where the frames' GPU time goes: each decode kind and the reconstruction.
    #[arg(long)]
    pub passes: bool,
    /// A game's own GPU work: a compute pass of about this many milliseconds submitted
    /// before each displayed frame, untimed (0: none), so that a hardware GPU keeps the
    /// clock a game keeps it at rather than idling between frames.
    #[arg(long, default_value_t = 0.0)]
    pub game_load: f64,
    /// `PlayerConfig::reuse_probe`: where the last deciding frame kept under one tile in
    /// 16, decide again only every this many frames (0: every frame decides).
    #[arg(long, default_value_t = 8)]
    pub reuse_probe: u32,
}

#[derive(Args)]
pub struct BenchScaleArgs {
    /// Scene file.
    #[arg(default_value = "samples/jacksboro.toml")]
    pub scene: PathBuf,
    /// Lightmap sizes, texels per side (a 64² stream is always measured as the baseline).
    #[arg(long, default_value = "512,1024,2048", value_delimiter = ',')]
    pub sizes: Vec<usize>,
    /// Frames per day.
    #[arg(long, default_value_t = 240)]
    pub frames: usize,
    /// Moving cloud shadows (the cloudy day is the harder one to stream).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub clouds: bool,
    /// Fractal detail below the height field's resolution (`[detail]` in the scene): real
    /// terrain at 2048² and up has it, and it costs 10–20× the bytes of a smooth blow-up,
    /// so the runtime's figures should be taken on it too.
    #[arg(long, default_value_t = false, action = clap::ArgAction::Set)]
    pub detail: bool,
    /// Display rate while measuring, Hz (uploads do not depend on it; GPU time per
    /// displayed frame does not either, but the run's length does).
    #[arg(long, default_value_t = 24)]
    pub display_hz: u32,
    /// Directory for the streams (kept for the next run), the measurements
    /// (`costs.json`), the CSV and the plots.
    #[arg(short, long, default_value = "out/scale")]
    pub out: PathBuf,
    /// Only draw the table and plots again from `costs.json`.
    #[arg(long)]
    pub replot: bool,
    /// The encoder's memory limit (SI: `10GB`; an 8192² day needs about 10GB).
    #[arg(long = "encoder-memory-limit", default_value = "4GB", value_parser = crate::units::parse_memory_limit)]
    pub encoder_limits: vbim_format::Limits,
    // The player's, `--memory-limit` (an 8192² day needs about 4–5GB).
    #[command(flatten)]
    pub memory: MemoryArgs,
}

#[derive(Args)]
pub struct BenchScaleOneArgs {
    /// The .vbim file.
    pub file: PathBuf,
    /// Display rate, Hz.
    #[arg(long, default_value_t = 24)]
    pub display_hz: u32,
    #[command(flatten)]
    pub memory: MemoryArgs,
}

#[derive(Args)]
pub struct BenchLosslessArgs {
    /// Frames (directory, glob or pattern).
    pub input: String,
    /// zstd level.
    #[arg(long, default_value_t = 3)]
    pub level: i32,
}

#[derive(Args)]
pub struct BenchPlotArgs {
    /// The CSV written by scripts/rd_bench.sh (plot-rd), scripts/tolerance_bench.sh, scripts/size_bench.sh or scripts/reuse_bench.sh.
    pub csv: PathBuf,
    /// Output PNG.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Plot title [default: what the plot shows].
    #[arg(long)]
    pub title: Option<String>,
}

impl BenchPlotArgs {
    /// The title given, else `default`.
    pub fn title_or(&self, default: &str) -> String {
        self.title.clone().unwrap_or_else(|| default.to_string())
    }
}

#[derive(Args)]
pub struct BenchDriftArgs {
    /// The .vbim file.
    pub file: PathBuf,
    /// Output directory for drift.csv and drift.png.
    #[arg(short, long, default_value = "out/bench-drift")]
    pub out: PathBuf,
    /// Stall pattern.
    #[arg(long, default_value = "500ms@10s")]
    pub stall: StallSpec,
    /// Playback per point.
    #[arg(long, default_value = "60s")]
    pub duration: Span,
    /// Multiples of the mean bit rate to sweep.
    #[arg(
        long,
        default_value = "0.25,0.5,0.75,1,1.2,1.5,2",
        value_delimiter = ','
    )]
    pub factors: Vec<f64>,
    /// Measure shown error every N frames.
    #[arg(long, default_value_t = 30)]
    pub check_every: u64,
    /// Run each point with the stall at N phases spread evenly over its period (a stall
    /// whose period is the loop's length always lands at the same moment of the day); the
    /// plots show the worst phase, the CSV every run.
    #[arg(long, default_value_t = 1)]
    pub phases: u32,
    /// Added to the header's pre-roll, as `vbim play --preroll-margin`.
    #[arg(long, default_value = "0s")]
    pub preroll_margin: Span,
}

#[derive(Args)]
pub struct BenchDecodeArgs {
    /// The .vbim file.
    pub file: PathBuf,
    /// Repetitions; the median and the spread are reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Also decode every segment on the GPU (the default adapter), one after another,
    /// each submitted and waited for: the GPU decode's time alone, which `bench scale`'s
    /// GPU time per frame only includes.
    #[arg(long)]
    pub gpu: bool,
    /// With `--gpu`: fit each dispatch's GPU time to a latency per dispatch and a cost
    /// per unit of each pass's work, and print them as a decode shape's `step_cost` and
    /// weights for this adapter (needs timestamps inside passes).
    #[arg(long, requires = "gpu")]
    pub fit: bool,
    #[command(flatten)]
    pub shape: ShapeArgs,
}

#[derive(Args)]
pub struct BenchBakeArgs {
    /// Scene file.
    #[arg(default_value = "samples/jacksboro.toml")]
    pub scene: PathBuf,
    /// Bake resolution, texels per side (8 to 8192).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(8..=8192))]
    pub size: u32,
    /// Frames per day (2 to 100000).
    #[arg(long, default_value_t = 240, value_parser = clap::value_parser!(u32).range(2..=100_000))]
    pub frames: u32,
    /// Repetitions; the median and the spread are reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Moving clouds on or off.
    #[arg(long, default_value_t = false)]
    pub clouds: bool,
}

/// The GPU decode's shape (`vbim_player::DecodeShape`), each field the adapter's default
/// unless named.
#[derive(Args, Clone, Copy, Debug)]
pub struct ShapeArgs {
    /// Workgroups per dispatch of a decode pass (`DecodeShape::slice_groups`; 32 on a CPU
    /// adapter, 2048 on a GPU).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub slice: Option<u32>,
    /// Parse with a workgroup per piece (true) or an invocation per piece (false)
    /// (`DecodeShape::wide_parse`; true on a GPU).
    #[arg(long)]
    pub wide_parse: Option<bool>,
    /// Workgroups per group of 64 blocks in the block passes (`DecodeShape::group_split`;
    /// 8 on a GPU, 1 on a CPU adapter).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub split: Option<u32>,
    /// What each step of a segment's decode costs beside its work, in blocks of the
    /// decode budget (`DecodeShape::step_cost`; 35 000 on a GPU, 0 on a CPU adapter).
    #[arg(long)]
    pub step_cost: Option<u64>,
    /// Whose cost of each pass's work the decode is planned by (`DecodeShape::weights`;
    /// `h100` on a GPU, `lavapipe` on a CPU adapter): with the other shape fields, plans
    /// a GPU's decode on lavapipe, to count its steps.
    #[arg(long, value_enum)]
    pub weights: Option<Weights>,
    /// Decode a version 2 file's sections on the GPU as coded (true) or decoded to pairs by
    /// the decoder thread (false) (`DecodeShape::lanes`; false on both: an H100 took
    /// 10–18 times as long as for the pairs).
    #[arg(long)]
    pub lanes: Option<bool>,
    /// Keep the DCT tables in a storage buffer (true) or a uniform one (false)
    /// (`DecodeShape::storage_tables`; true on a GPU, false on a CPU adapter)
    #[arg(long)]
    pub storage_tables: Option<bool>,
    /// Reconstruct two quads of 2 × 2 texels per invocation (true) or one (false)
    /// (`DecodeShape::wide_reconstruct`; true on a GPU, false on a CPU adapter)
    #[arg(long)]
    pub wide_reconstruct: Option<bool>,
    /// With `--lanes true`: states decoded side by side in one workgroup of the lane passes
    /// (`DecodeShape::lane_group`; 1 on a GPU, 8 on a CPU adapter)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub lane_group: Option<u32>,
    /// With `--lanes true`: the lane passes read their job from a storage buffer (true) or
    /// a uniform one (false) (`DecodeShape::lane_job_storage`; false on a GPU, true on a
    /// CPU adapter)
    #[arg(long)]
    pub lane_job_storage: Option<bool>,
}

/// The measured pass weights (`vbim_player::PassWeights`).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum Weights {
    Lavapipe,
    H100,
}

impl ShapeArgs {
    /// The adapter's shape with what was named.
    pub fn shape(&self, info: &wgpu::AdapterInfo) -> vbim_player::DecodeShape {
        let base = vbim_player::DecodeShape::for_adapter(info);
        vbim_player::DecodeShape {
            slice_groups: self.slice.unwrap_or(base.slice_groups),
            wide_parse: self.wide_parse.unwrap_or(base.wide_parse),
            group_split: self.split.unwrap_or(base.group_split),
            step_cost: self.step_cost.unwrap_or(base.step_cost),
            weights: match self.weights {
                Some(Weights::Lavapipe) => vbim_player::PassWeights::LAVAPIPE,
                Some(Weights::H100) => vbim_player::PassWeights::H100,
                None => base.weights,
            },
            lanes: self.lanes.unwrap_or(base.lanes),
            storage_tables: self.storage_tables.unwrap_or(base.storage_tables),
            wide_reconstruct: self.wide_reconstruct.unwrap_or(base.wide_reconstruct),
            lane_group: self.lane_group.unwrap_or(base.lane_group),
            lane_job_storage: self.lane_job_storage.unwrap_or(base.lane_job_storage),
        }
    }
}
