//! `vbim`: bake, encode, inspect, decode and compare video-based illumination maps.
//! A thin command line over the crates; each subcommand lives in its own module.

#[cfg(feature = "bench")]
mod bench;
mod cli;
mod cmd_bake;
mod cmd_compare;
mod cmd_convert;
mod cmd_decode;
mod cmd_demo;
mod cmd_encode;
mod cmd_inspect;
mod cmd_play;
mod plot;
mod progress;
mod sequence;
mod session;
mod units;
mod window;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// `vbim`: the commands.
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

/// One subcommand with its arguments.
#[derive(Subcommand)]
pub enum Command {
    /// Bake a day of terrain lightmaps from a scene file (samples/*.toml).
    Bake(cli::BakeArgs),
    /// Encode a sequence of EXR/PNG frames into a .vbim file.
    Encode(cli::EncodeArgs),
    /// Print a .vbim file's header, chunk index and model summary.
    Inspect(cli::InspectArgs),
    /// Rewrite a .vbim file in another format version without coding it again (it decodes to the same frames, bit for bit).
    Convert(cli::ConvertArgs),
    /// Decode every frame of a .vbim file with the CPU reference decoder.
    Decode(cli::DecodeArgs),
    /// Compare two sequences (directories, patterns or .vbim files) with the protocol's metrics.
    Compare(cli::CompareArgs),
    /// Play a .vbim file through the GPU player: headless (simulated or real time) with a
    /// summary of drift against bandwidth, or in a terrain scene (`--scene`).
    Play(cli::PlayArgs),
    /// The whole job on the shipped sample: bake a day, encode it, play it in the terrain
    /// scene under a bandwidth cap with stalls, and write frames, a preview, plots and a report.
    Demo(cli::DemoArgs),
    /// Benchmarks (results go in BENCHMARKS.md). Built with `--features bench`.
    #[cfg(feature = "bench")]
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// (A build without the `bench` feature: `vbim bench …` says how to get it.)
    #[cfg(not(feature = "bench"))]
    #[command(hide = true)]
    Bench {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        args: Vec<String>,
    },
}

/// Set by the Ctrl-C / SIGTERM handler before it removes the files being written.
static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

fn main() -> ExitCode {
    // Die quietly when the reader of our output goes away (`vbim inspect F | head`), as
    // Unix tools do, instead of panicking on a failed print.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    #[cfg(unix)]
    quiet_mesa();
    // glibc maps a block at or above its mmap threshold with fresh pages, which the kernel
    // zeroes, and unmaps it when freed; the threshold moves with the blocks freed, and
    // the heap is trimmed beyond twice it. Fixed at its largest (32 MB, and trimming
    // beyond 64 MB as the moving rule would), a 2048² encode's frame-sized blocks are
    // reused from the heap: 0.93× the time, the same peak (BENCHMARKS.md, "Bake and
    // encode at size"). (The threshold fixed alone trims the heap at 128 KiB: 512²'s
    // encode then took 3–4× the page faults.)
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 64 << 20);
    }
    // Ctrl-C or SIGTERM: remove the files being written (a frame's or a stream's temporary,
    // the passes of `--exact`), then exit as a shell expects of an interrupted command.
    let _ = ctrlc::set_handler(|| {
        INTERRUPTED.store(true, std::sync::atomic::Ordering::SeqCst);
        vbim_files::remove_temporaries();
        std::process::exit(130);
    });
    let args = Cli::parse();
    let res = match args.command {
        Command::Bake(a) => cmd_bake::run(a),
        Command::Encode(a) => cmd_encode::run(a),
        Command::Inspect(a) => cmd_inspect::run(a),
        Command::Convert(a) => cmd_convert::run(a),
        Command::Decode(a) => cmd_decode::run(a),
        Command::Compare(a) => cmd_compare::run(a),
        Command::Play(a) => cmd_play::run(a),
        Command::Demo(a) => cmd_demo::run(a),
        #[cfg(feature = "bench")]
        Command::Bench(b) => bench::run(b),
        #[cfg(not(feature = "bench"))]
        Command::Bench { .. } => Err("this vbim was built without the benchmarks: build it with \
             `cargo build --release --features bench` (BENCHMARKS.md)"
            .into()),
    };
    // A command that failed because the handler removed its files under it (an --exact
    // pass being verified) must not exit 1 first: the handler exits 130 in a moment.
    if res.is_err() && INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst) {
        loop {
            std::thread::park();
        }
    }
    match res {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line naming the culprit; exit status 1 for a user error (docs/CONVENTIONS.md).
            eprintln!("vbim: error: {e}");
            ExitCode::from(1)
        }
    }
}

/// Mesa's Vulkan drivers print `error: XDG_RUNTIME_DIR is invalid or not set` at every
/// device creation when the variable is unset, though nothing is wrong (a shell without a
/// login session, a container, CI). Give it a private directory of its own, as a login
/// session would; an existing valid setting is kept.
#[cfg(unix)]
fn quiet_mesa() {
    use std::os::unix::fs::PermissionsExt;
    let valid = std::env::var_os("XDG_RUNTIME_DIR")
        .map(std::path::PathBuf::from)
        .is_some_and(|d| d.is_absolute() && d.is_dir());
    if valid {
        return;
    }
    let dir = std::env::temp_dir().join(format!("vbim-runtime-{}", unsafe { libc::getuid() }));
    let ok = std::fs::create_dir_all(&dir).is_ok()
        && std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).is_ok();
    if ok {
        // Before any thread starts: nothing else reads the environment concurrently.
        std::env::set_var("XDG_RUNTIME_DIR", dir);
    }
}
