//! `vbim bake SCENE --out DIR`

use vbim_bake::{bake, BakeOptions, FrameFormat, Scene};

use crate::cli::BakeArgs;
use crate::progress::Stages;

pub fn run(a: BakeArgs) -> Result<(), String> {
    let mut scene = Scene::load(&a.scene).map_err(|e| e.to_string())?;
    if let Some(f) = a.frames {
        scene.frames = f as usize;
    }
    if let Some(s) = a.size {
        scene.size = s as usize;
    }
    if let Some(c) = a.clouds {
        scene.clouds.enabled = c;
    }
    if let Some(d) = a.detail {
        scene.detail.enabled = d;
    }
    scene
        .validate()
        .map_err(|e| format!("{}: {e}", a.scene.display()))?;
    let format: FrameFormat = a.format.parse()?;
    let stages = Stages::new();
    let opts = BakeOptions {
        out: a.out.clone(),
        format,
        use_cache: !a.no_cache,
    };
    let s = bake(&scene, &opts, &|stage, done, total| {
        stages.report(stage, done, total)
    })
    .map_err(|e| e.to_string())?;
    stages.finish();
    println!(
        "baked {} frames of {}² in {}: precompute {:.2} s{}, lighting {:.2} s, writing {:.2} s",
        s.frames,
        s.size,
        a.out.display(),
        s.precompute_s,
        if s.cache_hit { " (cached)" } else { "" },
        s.lighting_s,
        s.writing_s
    );
    if s.weathers.iter().any(|w| w.irradiance_manifest.is_some()) {
        println!(
            "light for objects ({0}² cells, {1} m above the ground): {2:.2} s more \
             (its horizons, then every frame's grid, written)",
            scene.objects.cells, scene.objects.height_m, s.objects_s
        );
    }
    println!(
        "manifest: {}\ncontact sheet: {}",
        s.manifest.display(),
        s.contact_sheet.display()
    );
    if let Some(p) = &s.package {
        println!("package of folders: {}", p.display());
    }
    Ok(())
}
