//! A whole bake: the scene's terrain, its precomputed maps (cached between bakes), every
//! frame of the day lit and written, then the manifest and the contact sheet.

use std::path::PathBuf;
use std::time::Instant;

use rayon::prelude::*;
use vbim_format::curve::exposure_from_max_greens;

use crate::error::out_err;
use crate::{cache, detail, light, manifest, output, BakeError};
use crate::{FrameFormat, FrameInfo, HeightField, Manifest, Precomputed, Progress, Scene};

pub struct BakeOptions {
    pub out: PathBuf,
    pub format: FrameFormat,
    /// Reuse precomputed maps from `OUT/.vbim-cache` when the inputs match.
    pub use_cache: bool,
}

/// What a bake did, with its timings (file writing apart from lighting).
#[derive(Debug, Clone)]
pub struct BakeSummary {
    pub frames: usize,
    pub size: usize,
    pub precompute_s: f64,
    pub cache_hit: bool,
    pub lighting_s: f64,
    pub writing_s: f64,
    pub manifest: PathBuf,
    pub contact_sheet: PathBuf,
}

/// Loads the scene's height field and resamples it to the bake's resolution.
/// The scene's height field at the bake's resolution: resampled, with fractal detail
/// below the source's resolution where the scene asks for it (module `detail`).
pub fn load_terrain(scene: &Scene) -> Result<HeightField, BakeError> {
    let source = HeightField::load(&scene.heightfield)?;
    let mut hf = source.resample(scene.size, scene.size);
    if scene.detail.enabled {
        detail::add_detail(&mut hf, &source, &scene.detail);
    }
    Ok(hf)
}

/// Bakes the scene's day into `opts.out`: frames, `manifest.json`, `contact_sheet.png`.
pub fn bake(
    scene: &Scene,
    opts: &BakeOptions,
    progress: Progress,
) -> Result<BakeSummary, BakeError> {
    scene.validate().map_err(BakeError::Setting)?;
    std::fs::create_dir_all(&opts.out).map_err(|e| out_err(&opts.out, e))?;
    let t0 = Instant::now();
    progress("precompute", 0, 1);
    let key = cache::key(scene)?;
    let cache_dir = opts.out.join(".vbim-cache");
    let mut cache_hit = false;
    let pre = match opts
        .use_cache
        .then(|| cache::load(&cache_dir, key, scene))
        .flatten()
    {
        Some(p) => {
            cache_hit = true;
            p
        }
        None => {
            let pre = Precomputed::compute(load_terrain(scene)?, scene);
            if opts.use_cache {
                // A cache that cannot be written only costs time next run.
                let _ = cache::store(&cache_dir, key, &pre);
            }
            pre
        }
    };
    progress("precompute", 1, 1);
    let precompute_s = t0.elapsed().as_secs_f64();

    let n = scene.frames;
    let texels = scene.size * scene.size;
    // The 8-bit export needs the exposure of the whole day before the first file: a first
    // pass lights every frame and keeps only its largest values.
    let (exposure, max_value) = if opts.format == FrameFormat::Exr {
        (None, None)
    } else {
        let stats: Vec<(f32, f32)> = (0..n)
            .into_par_iter()
            .map_init(
                || vec![0f32; texels * 3],
                |buf, i| {
                    light::light_frame(&pre, scene, i, buf);
                    (
                        buf.chunks_exact(3).map(|p| p[1]).fold(0.0, f32::max),
                        buf.iter().copied().fold(0.0, f32::max),
                    )
                },
            )
            .collect();
        let greens: Vec<f32> = stats.iter().map(|s| s.0).collect();
        (
            Some(exposure_from_max_greens(&greens)),
            Some(stats.iter().map(|s| s.1).fold(0.0, f32::max)),
        )
    };
    let png16_scale = max_value.map(|m| if m > 0.0 { 65535.0 / m } else { 1.0 });

    let done = std::sync::atomic::AtomicU64::new(0);
    let lighting_ns = std::sync::atomic::AtomicU64::new(0);
    let writing_ns = std::sync::atomic::AtomicU64::new(0);
    let infos: Vec<Result<FrameInfo, BakeError>> = (0..n)
        .into_par_iter()
        .map_init(
            || vec![0f32; texels * 3],
            |buf, i| {
                let tl = Instant::now();
                let info = light::light_frame(&pre, scene, i, buf);
                lighting_ns.fetch_add(
                    tl.elapsed().as_nanos() as u64,
                    std::sync::atomic::Ordering::Relaxed,
                );
                let tw = Instant::now();
                let path = opts.out.join(vbim_files::frame_name(i, opts.format));
                output::write_frame(
                    &path,
                    scene.size,
                    scene.size,
                    buf,
                    opts.format,
                    exposure,
                    png16_scale,
                )?;
                writing_ns.fetch_add(
                    tw.elapsed().as_nanos() as u64,
                    std::sync::atomic::Ordering::Relaxed,
                );
                let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                progress("frames", k, n as u64);
                Ok(info)
            },
        )
        .collect();
    let infos: Vec<FrameInfo> = infos.into_iter().collect::<Result<_, _>>()?;
    let greens: Vec<f32> = infos.iter().map(|f| f.max_green).collect();
    let exposure = exposure.unwrap_or_else(|| exposure_from_max_greens(&greens));
    let threads = rayon::current_num_threads() as f64;
    let manifest = manifest::of_bake(scene, opts.format, exposure, png16_scale, &infos)
        .write(&opts.out)
        .map_err(|e| out_err(&opts.out.join(Manifest::FILE_NAME), e))?;
    let contact_sheet = opts.out.join("contact_sheet.png");
    // The sheet is for people: expose so that the brightest frame's peak maps to x = 1
    // (mid-tone highlights), rather than the protocol's export exposure, which is set by the
    // median frame and whitens the whole day.
    let peak = greens.iter().copied().fold(0.0, f32::max);
    let sheet_exposure = if peak > 0.0 { 1.0 / peak } else { exposure };
    output::contact_sheet(&pre, scene, sheet_exposure, &contact_sheet)?;
    Ok(BakeSummary {
        frames: n,
        size: scene.size,
        precompute_s,
        cache_hit,
        // Per-frame work summed over threads, divided by the threads: wall-clock equivalent.
        lighting_s: lighting_ns.into_inner() as f64 * 1e-9 / threads,
        writing_s: writing_ns.into_inner() as f64 * 1e-9 / threads,
        manifest,
        contact_sheet,
    })
}
