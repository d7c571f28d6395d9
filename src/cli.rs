//! The command line: every option with its unit and default.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "vbim",
    version,
    about = "Video-based illumination maps: bake, encode and stream day/night terrain lightmap sequences"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Bake a day of terrain lightmaps from a scene file (samples/*.toml).
    Bake(BakeArgs),
    /// Print a .vbim file's header, chunk index and model summary.
    Inspect(InspectArgs),
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
    /// Frames per day [default: the scene's `frames`].
    #[arg(long)]
    pub frames: Option<usize>,
    /// Bake resolution in texels per side [default: the scene's `size`].
    #[arg(long)]
    pub size: Option<usize>,
    /// Moving cloud shadows on or off [default: the scene's `clouds.enabled`].
    #[arg(long)]
    pub clouds: Option<bool>,
    /// Recompute the horizon, sky and obscurance maps even if cached in OUT/.vbim-cache.
    #[arg(long)]
    pub no_cache: bool,
}

#[derive(Args)]
pub struct InspectArgs {
    /// The .vbim file.
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Verify every chunk's checksum (reads the whole file).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub verify: bool,
}
