//! A whole bake: the scene's terrain, its precomputed maps (cached between bakes), every
//! frame of the day lit and written, then the manifest and the contact sheet.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use vbim_format::curve::exposure_from_max_greens;
use vbim_format::package::{Package, WeatherTracks, PACKAGE_VERSION};

use crate::error::out_err;
use crate::light::WeatherLight;
use crate::objects::{self, ObjectGrid};
use crate::scene::WeatherParams;
use crate::{cache, detail, light, manifest, output, sky_track, BakeError};
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
    /// Of which the irradiance tracks (light for objects): the grid's horizons and every
    /// frame's grid, wall-clock equivalent.
    pub objects_s: f64,
    /// The day's manifest (the first weather's, for a scene with weathers).
    pub manifest: PathBuf,
    pub contact_sheet: PathBuf,
    /// Each weather's day and sky track, in the scene's order (empty without weathers).
    pub weathers: Vec<WeatherSummary>,
    /// For a scene with weathers, `OUT/package.json`: the weathers as a package whose
    /// tracks are folders of frames (`vbim_format::package`).
    pub package: Option<PathBuf>,
}

/// Where one weather's bake went.
#[derive(Debug, Clone)]
pub struct WeatherSummary {
    pub name: String,
    /// The weather's lightmap manifest (`OUT/NAME/manifest.json`).
    pub manifest: PathBuf,
    /// Its sky track's manifest (`OUT/NAME/sky/manifest.json`).
    pub sky_manifest: PathBuf,
    /// Its irradiance track's manifest (`OUT/NAME/irradiance/manifest.json`), unless the
    /// scene's `[objects]` is off.
    pub irradiance_manifest: Option<PathBuf>,
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

/// Bakes the scene's day into `opts.out`: frames, `manifest.json` and a contact sheet —
/// or, for a scene with weathers, one folder per weather holding those and the weather's
/// sky track in `sky/` (`docs/BAKE.md`, "Weathers and the analytic sky").
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

    let mut summary = BakeSummary {
        frames: scene.frames,
        size: scene.size,
        precompute_s,
        cache_hit,
        lighting_s: 0.0,
        writing_s: 0.0,
        objects_s: 0.0,
        manifest: PathBuf::new(),
        contact_sheet: PathBuf::new(),
        weathers: Vec::new(),
        package: None,
    };
    if scene.weathers.is_empty() {
        let day = bake_day(
            &pre,
            scene,
            None,
            &opts.out,
            opts.format,
            "frames",
            progress,
        )?;
        summary.add(day);
        return Ok(summary);
    }
    // The horizon, sky and obscurance maps are shared, and so is the objects' grid with its
    // horizons; each weather lights its own day.
    let t_grid = Instant::now();
    let grid = scene.objects.enabled.then(|| ObjectGrid::new(&pre, scene));
    summary.objects_s += t_grid.elapsed().as_secs_f64();
    for w in &scene.weathers {
        let dir = opts.out.join(&w.name);
        std::fs::create_dir_all(&dir).map_err(|e| out_err(&dir, e))?;
        let light = WeatherLight::new(&pre.hf, scene, w);
        let stage = format!("{} frames", w.name);
        let day = bake_day(
            &pre,
            scene,
            Some((w, &light, grid.as_ref())),
            &dir,
            opts.format,
            &stage,
            progress,
        )?;
        let manifest = Manifest::read(&day.manifest).map_err(BakeError::Setting)?;
        let sky = sky_track::write(
            scene,
            w,
            &light,
            &manifest,
            &dir.join(sky_track::DIR),
            progress,
        )?;
        summary.weathers.push(WeatherSummary {
            name: w.name.clone(),
            manifest: day.manifest.clone(),
            sky_manifest: sky,
            irradiance_manifest: day.irradiance.clone(),
        });
        summary.add(day);
    }
    // The bake as a package whose tracks are folders of frames: `vbim encode OUT` codes
    // each and writes the package of files. Written last: it names only complete days.
    let package = Package {
        vbim_package: PACKAGE_VERSION,
        weathers: scene
            .weathers
            .iter()
            .map(|w| WeatherTracks {
                name: w.name.clone(),
                lightmap: w.name.clone(),
                sky: Some(format!("{}/{}", w.name, sky_track::DIR)),
                irradiance: grid
                    .as_ref()
                    .map(|_| format!("{}/{}", w.name, objects::DIR)),
            })
            .collect(),
    };
    let path = opts.out.join(PACKAGE_FILE);
    output::write_text(&path, &package.to_json())?;
    summary.package = Some(path);
    Ok(summary)
}

/// The bake's package of weathers, beside their folders.
pub const PACKAGE_FILE: &str = "package.json";

/// One lit day: where its manifest and contact sheet went, and its timings.
struct Day {
    manifest: PathBuf,
    contact_sheet: PathBuf,
    lighting_s: f64,
    writing_s: f64,
    objects_s: f64,
    /// The irradiance track's manifest, if the day has one.
    irradiance: Option<PathBuf>,
}

impl BakeSummary {
    fn add(&mut self, day: Day) {
        if self.manifest.as_os_str().is_empty() {
            self.manifest = day.manifest;
            self.contact_sheet = day.contact_sheet;
        }
        self.lighting_s += day.lighting_s;
        self.writing_s += day.writing_s;
        self.objects_s += day.objects_s;
    }
}

/// Lights every frame of the day under `weather` (or the scene's sector sky) into `dir`,
/// with its manifest and contact sheet, and its irradiance track when the weather comes
/// with the objects' grid.
fn bake_day(
    pre: &Precomputed,
    scene: &Scene,
    weather: Option<(&WeatherParams, &WeatherLight, Option<&ObjectGrid>)>,
    dir: &Path,
    format: FrameFormat,
    stage: &str,
    progress: Progress,
) -> Result<Day, BakeError> {
    let light = weather.map(|w| w.1);
    let grid = weather.and_then(|w| w.2);
    let grid_dir = dir.join(objects::DIR);
    if grid.is_some() {
        std::fs::create_dir_all(&grid_dir).map_err(|e| out_err(&grid_dir, e))?;
    }
    let objects_ns = std::sync::atomic::AtomicU64::new(0);
    let n = scene.frames;
    let texels = scene.size * scene.size;
    // The 8-bit export needs the exposure of the whole day before the first file: a first
    // pass lights every frame and keeps only its largest values.
    let (exposure, max_value) = if format == FrameFormat::Exr {
        (None, None)
    } else {
        let stats: Vec<(f32, f32)> = (0..n)
            .into_par_iter()
            .map_init(
                || vec![0f32; texels * 3],
                |buf, i| {
                    light::light_frame_in(pre, scene, light, i, buf);
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
                let info = light::light_frame_in(pre, scene, light, i, buf);
                add_elapsed(&lighting_ns, tl);
                if let Some(g) = grid {
                    // What objects receive, from the lightmap just lit (its bounce).
                    let to = Instant::now();
                    let sun = light::sun_in(scene, light, i);
                    let (frame, transmission) = g.frame(pre, scene, light, &sun, i, buf);
                    let (w, h) = vbim_format::irradiance::image_size(frame.nx, frame.ny);
                    output::write_frame(
                        &grid_dir.join(vbim_files::frame_name(i, FrameFormat::Exr)),
                        w,
                        h,
                        &frame.to_image(&transmission),
                        FrameFormat::Exr,
                        None,
                        None,
                    )?;
                    add_elapsed(&objects_ns, to);
                }
                let tw = Instant::now();
                let path = dir.join(vbim_files::frame_name(i, format));
                output::write_frame(
                    &path,
                    scene.size,
                    scene.size,
                    buf,
                    format,
                    exposure,
                    png16_scale,
                )?;
                add_elapsed(&writing_ns, tw);
                let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                progress(stage, k, n as u64);
                Ok(info)
            },
        )
        .collect();
    let infos: Vec<FrameInfo> = infos.into_iter().collect::<Result<_, _>>()?;
    let greens: Vec<f32> = infos.iter().map(|f| f.max_green).collect();
    let exposure = exposure.unwrap_or_else(|| exposure_from_max_greens(&greens));
    let threads = rayon::current_num_threads() as f64;
    let mut m = manifest::of_bake(scene, format, exposure, png16_scale, &infos);
    if let Some((w, _, _)) = weather {
        m.weather = Some(w.name.clone());
        m.sky = Some(sky_track::DIR.into());
    }
    let manifest = m
        .write(dir)
        .map_err(|e| out_err(&dir.join(Manifest::FILE_NAME), e))?;
    let irradiance = match grid {
        Some(g) => Some(write_grid_manifest(g, light, scene, &m, &grid_dir)?),
        None => None,
    };
    let contact_sheet = dir.join("contact_sheet.png");
    // The sheet is for people: expose so that the brightest frame's peak maps to x = 1
    // (mid-tone highlights), rather than the protocol's export exposure, which is set by the
    // median frame and whitens the whole day.
    let peak = greens.iter().copied().fold(0.0, f32::max);
    let sheet_exposure = if peak > 0.0 { 1.0 / peak } else { exposure };
    output::contact_sheet(pre, scene, light, sheet_exposure, &contact_sheet)?;
    Ok(Day {
        manifest,
        contact_sheet,
        // Per-frame work summed over threads, divided by the threads: wall-clock equivalent.
        lighting_s: lighting_ns.into_inner() as f64 * 1e-9 / threads,
        writing_s: writing_ns.into_inner() as f64 * 1e-9 / threads,
        objects_s: objects_ns.into_inner() as f64 * 1e-9 / threads,
        irradiance,
    })
}

/// Adds the time since `since` to `counter`, ns (per-frame work summed over threads).
fn add_elapsed(counter: &std::sync::atomic::AtomicU64, since: Instant) {
    counter.fetch_add(
        since.elapsed().as_nanos() as u64,
        std::sync::atomic::Ordering::Relaxed,
    );
}

/// The irradiance track's manifest: the lightmap's timing, exposure and per-frame sun
/// (the track plays in step with it and its errors are measured on the ground's display
/// scale), the grid's frames and what they hold.
fn write_grid_manifest(
    grid: &ObjectGrid,
    light: Option<&WeatherLight>,
    scene: &Scene,
    day: &Manifest,
    dir: &Path,
) -> Result<PathBuf, BakeError> {
    let info = grid.info(light);
    let (w, h) = vbim_format::irradiance::image_size(info.cells[0], info.cells[1]);
    let manifest = Manifest {
        width: w,
        height: h,
        format: Some(FrameFormat::Exr),
        png16_scale: None,
        units: "irradiance / π, linear RGB, in the lightmap's units, for objects on the \
                terrain: 10 layers of cells (the sun's transmission, then sky and bounce at \
                nine normals), vbim_format::irradiance"
            .into(),
        files: (0..scene.frames)
            .map(|i| vbim_files::frame_name(i, FrameFormat::Exr))
            .collect(),
        track: Some("irradiance".into()),
        sky: None,
        irradiance_grid: Some(serde_json::to_value(&info).expect("a grid serialises")),
        ..day.clone()
    };
    manifest
        .write(dir)
        .map_err(|e| out_err(&dir.join(Manifest::FILE_NAME), e))
}
