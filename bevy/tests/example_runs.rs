//! The terrain example, in a real window under Xvfb: it bakes its small day, plays it
//! through Bevy's lightmap slot, saves a screenshot at noon and exits cleanly.

use std::path::PathBuf;
use std::process::Command;

/// The example's binary, which `cargo test` builds beside the tests
/// (`target/<profile>/examples/terrain`).
fn example() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let dir = exe.parent().and_then(|d| d.parent()).unwrap();
    let bin = dir.join("examples").join("terrain");
    assert!(
        bin.exists(),
        "{} is missing: `cargo test --workspace` builds it (or `cargo build -p bevy_vbim --examples`)",
        bin.display()
    );
    bin
}

#[test]
fn the_terrain_example_runs_under_xvfb_and_shows_a_lit_terrain() {
    let xvfb = Command::new("xvfb-run").arg("--help").output();
    assert!(
        xvfb.is_ok(),
        "xvfb-run is missing: `apt-get install -y xvfb xauth` (.ci/run installs them)"
    );
    let dir = tempfile::tempdir().unwrap();
    let shot = dir.path().join("noon.png");
    // 90 frames: Bevy compiles its pipelines in the background and draws nothing but the
    // sky until they are ready (a few seconds on lavapipe).
    let o = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 640x360x24"])
        .arg(example())
        .args([
            "--frames", "90", "--hour", "12", "--paused", "--window", "640x360",
        ])
        .arg("--screenshot")
        .arg(&shot)
        .output()
        .expect("xvfb-run runs");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "the example failed:\n{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("90 frames shown"), "{out}");
    // The screenshot: the terrain at noon is lit, not black (the lightmap reached Bevy's
    // material) and not one colour (it is a terrain, not a cleared window).
    let img = image::open(&shot).unwrap().to_rgb8();
    let (w, h) = img.dimensions();
    // The centre of the view is terrain.
    let centre: Vec<[u8; 3]> = (h / 2..h * 3 / 4)
        .flat_map(|y| (w / 3..w * 2 / 3).map(move |x| (x, y)))
        .map(|(x, y)| img.get_pixel(x, y).0)
        .collect();
    let mean = centre.iter().map(|p| p[1] as f64).sum::<f64>() / centre.len() as f64;
    let spread =
        centre.iter().map(|p| p[1]).max().unwrap() - centre.iter().map(|p| p[1]).min().unwrap();
    assert!(
        mean > 20.0 && spread > 20,
        "the noon terrain looks unlit: mean green {mean:.1}, spread {spread}"
    );
}
