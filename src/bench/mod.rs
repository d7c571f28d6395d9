//! `vbim bench …`, built only with the `bench` feature (`cargo build --release --features
//! bench`; CI and the benchmark scripts turn it on): the measurements of BENCHMARKS.md,
//! timings reported as the median of several runs with their spread (docs/CONVENTIONS.md,
//! "Units, flags and exit codes").
//!
//! `args` (the flags), `offline` (the baker, the lossless baseline, the plots of the
//! scripts' CSVs), `runtime` (the decoder, drift under bandwidth caps, the render thread; `frame_gpu`
//! times each displayed frame's GPU work and the reference blend, `game_load` stands in for a game's own GPU work),
//! `scale` (the runtime as the lightmap grows), `changes` (what a displayed frame changes)
//! and `entropy` (what a context-adaptive coder would save: a research harness for the
//! format's next coding); `transforms` (what larger transforms would make of the planes the
//! encoder quantises) and `intra` (what predicting a keyframe's blocks from their decoded
//! neighbours would), the harnesses for its next coding tools, sharing `study`; `fit` fits a GPU's decode costs from its timestamps; `objects`
//! measures the light for objects (irradiance tracks and the CPU query).

mod args;
mod changes;
mod entropy;
mod fit;
mod frame_gpu;
mod game_load;
mod intra;
mod objects;
mod offline;
mod runtime;
mod scale;
mod static_coding;
mod study;
mod transforms;

pub use args::*;

pub fn run(c: BenchCommand) -> Result<(), String> {
    match c {
        BenchCommand::Bake(a) => offline::bench_bake(a),
        BenchCommand::Decode(a) => runtime::bench_decode(a),
        BenchCommand::Lossless(a) => offline::bench_lossless(a),
        BenchCommand::PlotRd(a) => offline::plot_rd(a),
        BenchCommand::PlotTolerance(a) => offline::plot_tolerance(a),
        BenchCommand::PlotSize(a) => offline::plot_size(a),
        BenchCommand::PlotReuse(a) => offline::plot_reuse(a),
        BenchCommand::Drift(a) => runtime::bench_drift(a),
        BenchCommand::Render(a) => runtime::bench_render(a),
        BenchCommand::Scale(a) => scale::run(a),
        BenchCommand::ScaleOne(a) => scale::run_one(a),
        BenchCommand::Changes(a) => changes::run(a),
        BenchCommand::Entropy(a) => entropy::run(a),
        BenchCommand::Objects(a) => objects::run(a),
        BenchCommand::Transforms(a) => transforms::run(a),
        BenchCommand::Intra(a) => intra::run(a),
    }
}

/// Median, min and max of a set of timings.
pub(super) fn stats(v: &mut [f64]) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let med = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    (med, v[0], v[n - 1])
}
