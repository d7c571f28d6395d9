use super::*;
use crate::light::{light_with_sun_in, sun_for_frame};
use crate::scene::WeatherParams;
use crate::sun::sun_at;

fn flat(n: usize) -> HeightField {
    HeightField {
        w: n,
        h: n,
        cell_x: 30.0,
        cell_y: 30.0,
        z: vec![300.0; n * n],
    }
}

fn clear() -> WeatherParams {
    WeatherParams {
        name: "clear".into(),
        cover: 0.0,
        turbidity: 2.5,
    }
}

/// The grid and the lightmap of one frame at `sun`.
fn frame(
    pre: &Precomputed,
    scene: &Scene,
    light: &WeatherLight,
    sun: &SunState,
) -> (Grid, Vec<f32>) {
    let mut lit = vec![0f32; scene.size * scene.size * 3];
    light_with_sun_in(pre, scene, Some(light), sun, 0, &mut lit);
    let grid = ObjectGrid::new(pre, scene);
    (grid.frame(pre, scene, Some(light), sun, 0, &lit).0, lit)
}

#[test]
fn on_flat_ground_at_noon_up_gets_the_texel_beneath_and_down_the_ground_it_sees() {
    let mut scene = Scene::with_heightfield("-");
    scene.size = 64;
    scene.objects.cells = 16;
    scene.weathers = vec![clear()];
    let pre = Precomputed::compute(flat(64), &scene);
    let light = WeatherLight::new(&pre.hf, &scene, &scene.weathers[0]);
    let sun = sun_at(scene.latitude, scene.day_of_year, 12.0, scene.sun.strength);
    let (grid, lit) = frame(&pre, &scene, &light, &sun);
    let texel = |u: f32, v: f32| {
        let (x, y) = ((u * 64.0) as usize, (v * 64.0) as usize);
        let o = (y * 64 + x) * 3;
        [lit[o], lit[o + 1], lit[o + 2]]
    };
    for (u, v) in [(0.5, 0.5), (0.1, 0.3), (0.97, 0.03)] {
        let up = grid.irradiance(u, v, [0.0, 0.0, 1.0]);
        let down = grid.irradiance(u, v, [0.0, 0.0, -1.0]);
        let t = texel(u, v);
        for c in 0..3 {
            let rel = (up[c] - t[c]).abs() / t[c];
            assert!(
                rel < 0.02,
                "up, channel {c}: {} against the texel's {}",
                up[c],
                t[c]
            );
            let want = scene.albedo as f32 * t[c];
            let rel = (down[c] - want).abs() / want;
            assert!(
                rel < 0.05,
                "down, channel {c}: {} against albedo × texel {want}",
                down[c]
            );
        }
    }
}

#[test]
fn after_sunset_in_a_valley_the_ridge_top_still_has_the_sun() {
    let hf_path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../samples/dem/jacksboro_fault_mpl.png"
    );
    let mut scene = Scene::with_heightfield(hf_path);
    scene.size = 128;
    scene.objects.cells = 32;
    scene.weathers = vec![clear()];
    scene.latitude = 36.59;
    let pre = Precomputed::compute(crate::load_terrain(&scene).unwrap(), &scene);
    let light = WeatherLight::new(&pre.hf, &scene, &scene.weathers[0]);
    let objects = ObjectGrid::new(&pre, &scene);
    // The last frame of the evening with the sun's disc wholly above the astronomical
    // horizon: the valleys are in the ridges' shadow, the highest ground is not.
    let i = (scene.frames / 2..scene.frames)
        .rev()
        .find(|&i| sun_for_frame(&scene, i).elevation.to_degrees() > 1.0)
        .unwrap();
    let sun = sun_for_frame(&scene, i);
    let mut lit = vec![0f32; 128 * 128 * 3];
    light_with_sun_in(&pre, &scene, Some(&light), &sun, i, &mut lit);
    let (grid, transmission) = objects.frame(&pre, &scene, Some(&light), &sun, i, &lit);
    // A clear sky lets the whole sun through; the terrain's share is the horizons'.
    assert!(transmission.iter().all(|&t| t == 1.0));
    let top = (0..objects.points.len())
        .max_by(|&a, &b| objects.points[a].z.total_cmp(&objects.points[b].z))
        .unwrap();
    assert!(
        grid.cells[top].sun[0] > 0.5 * sun.color[0] as f32,
        "the highest cell at {:.1}° of sun: {:?}",
        sun.elevation.to_degrees(),
        grid.cells[top].sun
    );
    let dark: Vec<usize> = (0..grid.cells.len())
        .filter(|&k| grid.cells[k].sun[0] == 0.0)
        .collect();
    assert!(
        !dark.is_empty()
            && dark
                .iter()
                .all(|&k| objects.points[k].z < objects.points[top].z),
        "some cells lower than the ridge are in its shadow: {} of {}",
        dark.len(),
        grid.cells.len()
    );
    // Such a cell still gets the sky and the ground around it.
    let k = dark[0];
    let (u, v) = (
        (k % 32) as f32 / 32.0 + 0.015,
        (k / 32) as f32 / 32.0 + 0.015,
    );
    let e = grid.irradiance(u, v, [0.0, 0.0, 1.0]);
    assert!(e[2] > 0.0, "{e:?}");
}

#[test]
fn the_horizon_of_a_point_on_a_plain_is_flat_and_a_wall_rises_above_it() {
    let mut hf = flat(64);
    for y in 0..64 {
        for x in 40..64 {
            hf.z[y * 64 + x] = 300.0 + 300.0;
        }
    }
    // 20 texels of 30 m to the wall (from x = 20 to 40), 300 m high: atan(300 / 600).
    let e = march(&hf, 20.0, 32.0, 300.0, 0.0) as f64;
    assert!(
        (e - (300.0f64 / 585.0).atan()).abs() < 0.03,
        "{}",
        e.to_degrees()
    );
    assert_eq!(march(&hf, 20.0, 32.0, 302.0, std::f64::consts::PI), 0.0);
}
