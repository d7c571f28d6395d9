//! The command line's arguments, command by command: every option with its unit and
//! default (`main.rs` holds the list of commands).

use std::path::PathBuf;

use clap::{Args, Parser};
use vbim_player::Policy;

use crate::units::{Bandwidth, Span, StallSpec};

/// `vbim play` parsed on its own (see [`PlayArgs::headless`]).
#[derive(Parser)]
#[command(name = "play")]
struct PlayCommand {
    #[command(flatten)]
    args: PlayArgs,
}

/// `--memory-limit`, for every command that decodes or plays a stream.
#[derive(Args, Clone)]
pub struct MemoryArgs {
    /// Memory one stream may take while it is decoded or played (SI: `4GB`); a stream that could need more is refused before anything is allocated for it.
    #[arg(long = "memory-limit", default_value = "2GB", value_parser = crate::units::parse_memory_limit)]
    pub limits: vbim_format::Limits,
}

impl PlayArgs {
    /// `vbim play FILE --headless` with the command line's defaults: commands that play a
    /// file (`bench drift`, `demo`) start from this and set what they change, so that a
    /// default is written once, in its `#[arg]`.
    pub fn headless(file: &std::path::Path) -> PlayArgs {
        let argv = [
            std::ffi::OsStr::new("play"),
            "--headless".as_ref(),
            "--".as_ref(),
            file.as_os_str(),
        ];
        PlayCommand::try_parse_from(argv)
            .expect("play's defaults parse")
            .args
    }
}

#[derive(Args, Clone)]
pub struct PlayArgs {
    /// The .vbim file, or a package of weathers (.vbimpkg: `vbim encode` of a bake with weathers).
    pub file: PathBuf,
    /// A package's weather to play, and the one whose lightmap track is measured [default: the package's first].
    #[arg(long)]
    pub weather: Option<String>,
    /// With --scene: switch to another weather at a time of the display's clock, cross-fading lightmap and sky over --fade (`overcast@20s`; may be given again for later switches). In a window, W cycles the weathers.
    #[arg(long, value_parser = crate::units::parse_weather_switch)]
    pub switch_weather: Vec<crate::units::WeatherSwitch>,
    /// The cross-fade of a weather switch, at most an hour.
    #[arg(long, default_value = "2s", value_parser = crate::units::parse_short_span)]
    pub fade: Span,
    /// A weather switch closes the shown weather at once and fades in from its last image (one weather's GPU memory; the light stands still while the new weather's data comes), instead of keeping both weathers playing until the fade ends.
    #[arg(long)]
    pub hold_on_switch: bool,
    /// Run without a window and print the summary.
    #[arg(long)]
    pub headless: bool,
    /// Playback duration (`60s`, `2min`, `500ms`; at most 3 hours).
    #[arg(long, default_value = "60s", value_parser = crate::units::parse_play_duration)]
    pub duration: Span,
    /// Display refresh rate in Hz (1 to 1000).
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub display_hz: u32,
    /// Play the file this many times slower than its own rate (a 240-frame day at 1/6 fps, a 24-minute day, is `--slow 144` on a 24 fps file); the duration is the display's.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=100000))]
    pub slow: u64,
    /// Media frame to start at.
    #[arg(long, default_value_t = 0)]
    pub start: u64,
    /// Cap the reader: SI bytes per second (`2MB/s`, `500kB/s`) or a multiple of the stream's mean bit rate (`1.2x`) [default: unlimited].
    #[arg(long)]
    pub bandwidth: Option<Bandwidth>,
    /// Stall the reader periodically: `300ms@5s` = 300 ms every 5 s of playback; `300ms@5s+2s` = the same, the first at 2 s [default: none].
    #[arg(long)]
    pub stall: Option<StallSpec>,
    /// What to show when data is late: interpolate (hold, then blend), wait (pause the clock) or skip (hold, then jump).
    #[arg(long, default_value = "interpolate")]
    pub policy: Policy,
    /// Catch-up window of the interpolate policy.
    #[arg(long, default_value = "500ms", value_parser = crate::units::parse_short_span)]
    pub catch_up: Span,
    /// Ring capacity in bytes, 1 kB to 100 GB (a ring larger than the file holds the file) [default: the header's read-ahead at the read rate].
    #[arg(long, value_parser = crate::units::parse_ring)]
    pub ring: Option<u64>,
    /// Added to the header's pre-roll, at most an hour: a reader stall this long while the ring first fills is survived (`500ms`).
    #[arg(long, default_value = "0s", value_parser = crate::units::parse_short_span)]
    pub preroll_margin: Span,
    /// The most segment-decode work one displayed frame records, in blocks (the time of 64 texel sums of one 8×8 block of one plane; each pass weighted by its measured cost); a segment due before its decode is done is held or waited for and reported [default: each decode spread evenly over the frames before it is due but the last].
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub decode_budget: Option<u64>,
    /// How far a tile of the lightmap may lag the exact image before it is evaluated again, as a share of the protocol's GPU bound (2^-10 relative for HDR, 0.5/255 for 8-bit): 0 evaluates every texel every frame, larger shares trade accuracy for GPU time, `inf` evaluates a tile only when the keyframes change. The default, 0.25, keeps every frame within the bound with the evaluation's own rounding.
    #[arg(long, default_value_t = 0.25, value_parser = parse_share)]
    pub reuse_share: f32,
    /// Run in real time with the reader and decoder on their own threads (default: simulated time, stepped deterministically, as fast as the machine goes).
    #[arg(long)]
    pub realtime: bool,
    /// Per-frame records as CSV.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Measure the shown frame against the reference decoder every N displayed frames (0 = never).
    #[arg(long, default_value_t = 30)]
    pub check_every: u64,
    /// Summary as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Render the lightmap on the sample's terrain (scene file, e.g. samples/jacksboro.toml).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// With --scene --headless: directory for the rendered PNG frames and the animated preview (preview.gif).
    #[arg(short, long)]
    pub out: Option<PathBuf>,
    /// With --scene --headless: frames to capture, evenly spread over the duration (1 to 100000).
    #[arg(long, default_value_t = 120, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub frames: u32,
    /// Rendered width in pixels (16 to 8192).
    #[arg(long, default_value_t = 960, value_parser = clap::value_parser!(u32).range(16..=8192))]
    pub width: u32,
    /// Rendered height in pixels (16 to 8192).
    #[arg(long, default_value_t = 540, value_parser = clap::value_parser!(u32).range(16..=8192))]
    pub height: u32,
    /// With a window: close it after this many frames (for scripted runs) [default: never].
    #[arg(long)]
    pub exit_after: Option<u64>,
    #[command(flatten)]
    pub memory: MemoryArgs,
}

#[derive(Args)]
pub struct DemoArgs {
    /// Scene file (with `[[weather]]` tables: a package of weathers, and a switch mid-day in the preview).
    #[arg(default_value = "samples/jacksboro-weather.toml")]
    pub scene: PathBuf,
    /// Output directory.
    #[arg(short, long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Bake resolution, texels per side (8 to 8192).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(8..=8192))]
    pub size: u32,
    /// Frames per day (2 to 100000).
    #[arg(long, default_value_t = 240, value_parser = clap::value_parser!(u32).range(2..=100_000))]
    pub frames: u32,
    /// Media frame rate of the demo stream: the day plays in frames / fps seconds.
    #[arg(long, default_value = "24/1")]
    pub fps: String,
    /// Reader cap during playback, SI rate or multiple of the stream's mean.
    #[arg(long, default_value = "1.2x")]
    pub bandwidth: Bandwidth,
    /// Reader stalls during playback.
    #[arg(long, default_value = "500ms@4s")]
    pub stall: StallSpec,
    /// Added to the header's pre-roll, as long as a stall: the header's pre-roll assumes a
    /// reader that never stalls, and a stall while the ring first fills would make the
    /// day's first transition late.
    #[arg(long, default_value = "500ms")]
    pub preroll_margin: Span,
    /// Frames rendered in the terrain scene (1 to 100000).
    #[arg(long, default_value_t = 120, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub render_frames: u32,
    /// Moving cloud shadows in the bake [default: the scene's].
    #[arg(long)]
    pub clouds: Option<bool>,
}

#[derive(Args)]
pub struct EncodeArgs {
    /// Input frames: a directory, a glob (`frames/*.exr`) or a printf pattern (`frames/%04d.exr`).
    pub input: String,
    /// Output .vbim file (written under a temporary name, renamed when complete).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Target mean PSNR in dB of the protocol's metric, delivered within about ±0.5 dB in one pass [default: 45].
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Use the tolerance as the internal budget as it is, without first finding on a sample the budget that delivers it (quicker; over-delivers by 3–6.5 dB on a day with dark nights).
    #[arg(long)]
    pub no_aim: bool,
    /// Keep every frame's PSNR within this of the tolerance: the frames below get tighter budgets and the rest of the day pays for them (`inf`: no floor) [default: 7, the protocol's 45 dB mean with a 38 dB worst frame].
    #[arg(long, conflicts_with = "no_aim")]
    pub worst_margin: Option<f64>,
    /// Highest polynomial degree in time, 1–8 (1 = keyframe interpolation) [default: preset's, 4].
    #[arg(long)]
    pub max_degree: Option<usize>,
    /// Segment length: `auto` (adaptive, up to the preset's maximum), `auto:N` (adaptive up to N frames) or N frames.
    #[arg(long, value_parser = crate::units::parse_segment)]
    pub segment: Option<crate::units::SegmentSpec>,
    /// zstd level of the tile maps, and in format 1 of the keyframes and coefficients, 1–22 [default: preset's, 9].
    #[arg(long)]
    pub zstd_level: Option<i32>,
    /// Format version to write: 1 (zero-run pairs through zstd), 2 (rANS lanes: 0.69–0.90× the bytes; the player's decoder thread spends 9–12× version 1's CPU time on them, decoding them to version 1's pairs for the GPU) or 3 (2 with several rANS states a lane, which a GPU decodes side by side: about 2% more bytes than 2).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=3))]
    pub format_version: u16,
    /// Formats 2 and 3: the coded size at which a rANS lane is cut, bytes (0: a lane per region of 16 × 16 blocks). In format 2 shorter lanes shorten the serial chains a GPU decodes, for a few bytes each [default: 512 in format 2, 16384 in format 3].
    #[arg(long)]
    pub lane_bytes: Option<usize>,
    /// Format 3: a lane of n symbols gets ⌈n / this⌉ rANS states (1 to 64), which a GPU decodes side by side; fewer symbols a state shorten its serial chains for 4–6 bytes a state.
    #[arg(long, default_value_t = vbim_encoder::SYMBOLS_PER_STATE, value_parser = clap::value_parser!(u64).range(1..))]
    pub symbols_per_state: u64,
    /// Formats 2 and 3: the rate-aware quantiser's price of a bit, in squared quantiser steps (0: off, 0–10). A block's ±1 coefficients whose bits cost more than the error they save are dropped: 0.95–1.00× the bytes at the same PSNR (0.987× on average over six days) for about 5% more encode time [default: 0.1; format 1 ignores it].
    #[arg(long)]
    pub rate_lambda: Option<f32>,
    /// Worker threads; 0 = one per core. The output is identical for any value.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Largest distance between independently decodable keyframes, media time (`4s`, `500ms`, `2min`) [default: 4s].
    #[arg(long, value_parser = crate::units::parse_duration)]
    pub intra_interval: Option<f64>,
    /// Media frame rate, frames per second as a rational (`24/1`, `1/6`) [default: the manifest's fps, else 24/1].
    #[arg(long, value_parser = crate::units::parse_rate)]
    pub fps: Option<(u32, u32)>,
    /// The sequence loops: frame N−1 is followed by frame 0 (the default).
    #[arg(long = "loop", overrides_with = "no_loop")]
    pub looping: bool,
    /// The sequence plays once and holds its last frame.
    #[arg(long = "no-loop", overrides_with = "looping")]
    pub no_loop: bool,
    /// JSON file stored in the metadata chunk [default: manifest.json beside the frames, if any].
    #[arg(long)]
    pub meta: Option<PathBuf>,
    /// Tile size in texels (multiple of 8) [default: 16].
    #[arg(long)]
    pub tile: Option<usize>,
    /// What the encode may hold (SI units: `4GB`, `800MB`). Frames too large to hold a segment's worth whole are coded in bands of tile rows read a band at a time; the output is the same.
    #[arg(long = "memory-limit", default_value = "4GB", value_parser = crate::units::parse_memory_limit)]
    pub memory_limit: vbim_format::Limits,
    /// Tile rows per band, instead of what the memory limit allows (the output is the same; for measuring).
    #[arg(long)]
    pub band: Option<usize>,
    /// Preset: smaller search, degree ≤ 3, zstd 3.
    #[arg(long, conflicts_with = "best")]
    pub fast: bool,
    /// Preset: denser segment search, zstd 19 (slower, ~5% smaller).
    #[arg(long)]
    pub best: bool,
    /// Skip decoding the result to measure its error.
    #[arg(long, conflicts_with = "exact")]
    pub no_verify: bool,
    /// Hold the tolerance exactly: re-encode with a corrected internal budget until the
    /// measured mean PSNR is within [T, T + 0.5] dB (2–5 encode-and-measure passes).
    #[arg(long)]
    pub exact: bool,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write a PNG map of the polynomial degree of every tile in every segment.
    #[arg(long)]
    pub degree_map: Option<PathBuf>,
}

#[derive(Args)]
pub struct ConvertArgs {
    /// The .vbim file to read.
    pub file: PathBuf,
    /// The .vbim file to write (written under a temporary name, then renamed).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Format version to write: 2 (rANS lanes), 3 (rANS lanes of several states, for a GPU decoder) or 1 (zero-run pairs through zstd, for players built before format 2).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..=3))]
    pub format_version: u16,
    /// zstd level of format 1's keyframes and coefficients, 1–22.
    #[arg(long, default_value_t = 9, value_parser = clap::value_parser!(i32).range(1..=22))]
    pub zstd_level: i32,
    /// Formats 2 and 3: the coded size at which a rANS lane is cut, bytes (0: a lane per region of 16 × 16 blocks). In format 2 shorter lanes shorten the serial chains a GPU decodes, for a few bytes each [default: 512 in format 2, 16384 in format 3].
    #[arg(long)]
    pub lane_bytes: Option<usize>,
    /// Format 3: a lane of n symbols gets ⌈n / this⌉ rANS states (1 to 64), which a GPU decodes side by side; fewer symbols a state shorten its serial chains for 4–6 bytes a state.
    #[arg(long, default_value_t = vbim_encoder::SYMBOLS_PER_STATE, value_parser = clap::value_parser!(u64).range(1..))]
    pub symbols_per_state: u64,
}

/// The format version `--format-version` names (clap keeps it within 1–3).
pub fn format_version(v: u16) -> vbim_encoder::FormatVersion {
    match v {
        1 => vbim_encoder::FormatVersion::V1,
        2 => vbim_encoder::FormatVersion::V2,
        _ => vbim_encoder::FormatVersion::V3,
    }
}

#[derive(Args)]
pub struct DecodeArgs {
    /// The .vbim file.
    pub file: PathBuf,
    /// Output directory (created if missing).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Frame format: exr (linear half RGB), png8 (8-bit: sRGB files as stored, HDR through the protocol's export curve) or png16 (linear × scale).
    #[arg(long, default_value = "exr")]
    pub format: String,
    /// Refuse a stream of more frames than this: each frame is a file (a bake makes at most 100000).
    #[arg(long, default_value_t = 100_000, value_parser = clap::value_parser!(u32).range(1..))]
    pub max_frames: u32,
    #[command(flatten)]
    pub memory: MemoryArgs,
}

#[derive(Args)]
pub struct CompareArgs {
    /// Reference sequence: directory, pattern, or .vbim file.
    pub a: String,
    /// Sequence to measure: directory, pattern, or .vbim file.
    pub b: String,
    /// Write per-frame figures as CSV to this file (`-` for standard output).
    #[arg(long)]
    pub csv: Option<String>,
    /// Exposure of the HDR metric [default: from the reference, 1.5 / median of per-frame max green].
    #[arg(long, value_parser = crate::units::parse_exposure)]
    pub exposure: Option<f32>,
    #[command(flatten)]
    pub memory: MemoryArgs,
}

#[derive(Args)]
pub struct BakeArgs {
    /// Scene file (TOML), e.g. samples/jacksboro.toml.
    pub scene: PathBuf,
    /// Output directory (created if missing): frames, manifest.json, contact_sheet.png.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Frame file format: exr (half-float linear RGB), png8 (protocol export curve) or png16
    /// (linear × the manifest's png16_scale).
    #[arg(long, default_value = "exr")]
    pub format: String,
    /// Frames per day, 1 to 100000 [default: the scene's `frames`].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub frames: Option<u32>,
    /// Bake resolution in texels per side, 8 to 8192 [default: the scene's `size`].
    #[arg(long, value_parser = clap::value_parser!(u32).range(8..=8192))]
    pub size: Option<u32>,
    /// Moving cloud shadows on or off [default: the scene's `clouds.enabled`].
    #[arg(long)]
    pub clouds: Option<bool>,
    /// Fractal detail below the height field's resolution, following its measured roughness, on or off [default: the scene's `detail.enabled`].
    #[arg(long)]
    pub detail: Option<bool>,
    /// Recompute the horizon, sky and obscurance maps even if cached in OUT/.vbim-cache.
    #[arg(long)]
    pub no_cache: bool,
}

#[derive(Args)]
pub struct InspectArgs {
    /// The .vbim file, or a package (.vbimpkg): then each track's weather, kind, size and bytes, and with --verify every track's chunks.
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Verify every chunk's checksum (reads the whole file).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub verify: bool,
}

/// A share of a bound: a number ≥ 0 (`inf` allowed).
pub fn parse_share(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v >= 0.0 => Ok(v),
        _ => Err(format!("{s:?}: expected a number ≥ 0 (or inf)")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headless_play_args_are_the_commands_defaults() {
        let a = PlayArgs::headless(std::path::Path::new("-odd name.vbim"));
        assert_eq!(a.file, PathBuf::from("-odd name.vbim"));
        assert!(a.headless && !a.realtime);
        assert_eq!((a.duration.ns(), a.display_hz), (60_000_000_000, 60));
        assert_eq!(
            (a.policy, a.catch_up.ns()),
            (vbim_player::Policy::Interpolate, 500_000_000)
        );
        assert_eq!((a.bandwidth, a.stall, a.ring), (None, None, None));
        assert_eq!((a.check_every, a.preroll_margin.ns()), (30, 0));
    }
}
