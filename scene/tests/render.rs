//! Rendering tests of the terrain scene on a real adapter (lavapipe/llvmpipe without a GPU).

use glam::Vec3;
use vbim_bake::light_frame;
use vbim_bake::{load_terrain, HeightField, Precomputed, Scene};
use vbim_scene::{mesh::base_colour, Mesh, Object, SceneRenderer, SkyAt, View, FORMAT};

fn device() -> (wgpu::Device, wgpu::Queue) {
    let (d, q, info) = vbim_player::headless_device().unwrap_or_else(|e| panic!("{e}"));
    eprintln!("adapter: {} ({:?})", info.name, info.backend);
    (d, q)
}

/// A lightmap texture (Rgba16Float, as the player's) from linear RGB.
fn lightmap(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    w: u32,
    h: u32,
    rgb: &[f32],
) -> wgpu::TextureView {
    use wgpu::util::DeviceExt;
    let data: Vec<u8> = rgb
        .chunks(3)
        .flat_map(|p| [p[0], p[1], p[2], 1.0])
        .flat_map(|v| half::f16::from_f32(v).to_le_bytes())
        .collect();
    device
        .create_texture_with_data(
            queue,
            &vbim_player::lightmap_descriptor(w, h, wgpu::TextureUsages::TEXTURE_BINDING),
            wgpu::util::TextureDataOrder::LayerMajor,
            &data,
        )
        .create_view(&Default::default())
}

/// A flat `n` × `n` height field of 30 m cells at height `z`.
fn flat(n: usize, z: f32) -> HeightField {
    HeightField {
        w: n,
        h: n,
        cell_x: 30.0,
        cell_y: 30.0,
        z: vec![z; n * n],
    }
}

fn view(eye: Vec3, exposure: f32) -> View {
    View {
        eye,
        target: Vec3::ZERO,
        fovy: 0.8,
        exposure,
        sky: SkyAt {
            zenith: [0.1, 0.15, 0.3],
            horizon: [0.2, 0.2, 0.25],
            ..Default::default()
        },
        detail: 0.0,
    }
}

fn srgb8(x: f32) -> f32 {
    (vbim_format::curve::linear_to_srgb(x) * 255.0).round()
}

#[test]
fn a_flat_terrain_under_a_constant_lightmap_renders_the_expected_colour() {
    let (device, queue) = device();
    let hf = flat(32, 100.0);
    let mesh = Mesh::new(&hf, 32, 1.0, 1.1);
    let light = [0.8f32, 0.7, 0.5];
    let lm = lightmap(&device, &queue, 32, 32, &light.repeat(32 * 32));
    let r = SceneRenderer::new(&device, &queue, &mesh, &lm, None, 64, 64, FORMAT);
    let exposure = 2.0;
    // Straight down at the centre of the map.
    r.render(&view(Vec3::new(0.0, 1.5, 0.001), exposure), None);
    let px = r.read();
    let base = base_colour(0.0, 0.0, 1.1);
    let centre = (32 * 64 + 32) * 4;
    for c in 0..3 {
        let x = base[c] * light[c] * exposure;
        let want = srgb8(x / (1.0 + x));
        let got = px[centre + c] as f32;
        assert!((got - want).abs() <= 1.0, "channel {c}: {got} vs {want}");
    }
}

fn real(size: usize) -> (Scene, Precomputed) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/jacksboro.toml");
    let mut s = Scene::load(&root).unwrap();
    s.size = size;
    s.frames = 24;
    let pre = Precomputed::compute(load_terrain(&s).unwrap(), &s);
    (s, pre)
}

fn luminance(px: &[u8]) -> f64 {
    let lin = |v: u8| vbim_format::curve::srgb_to_linear(v as f32 / 255.0) as f64;
    px.chunks(4)
        .map(|p| 0.2126 * lin(p[0]) + 0.7152 * lin(p[1]) + 0.0722 * lin(p[2]))
        .sum::<f64>()
        / (px.len() / 4) as f64
}

fn render_frame(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    s: &Scene,
    pre: &Precomputed,
    frame: usize,
    size: (u32, u32),
) -> Vec<u8> {
    let n = s.size;
    let mut buf = vec![0f32; n * n * 3];
    light_frame(pre, s, frame, &mut buf);
    let lm = lightmap(device, queue, n as u32, n as u32, &buf);
    let mesh = Mesh::new(
        &pre.hf,
        64,
        s.view.vertical_exaggeration as f32,
        s.view.snow_line as f32,
    );
    let r = SceneRenderer::new(device, queue, &mesh, &lm, None, size.0, size.1, FORMAT);
    let (eye, target) = vbim_scene::orbit(0.1, &mesh);
    let mut v = view(eye, 3.0);
    v.target = target;
    v.detail = 0.5;
    // The sky of that moment, from the bake's sky model.
    let sun = vbim_bake::sun_for_frame(s, frame);
    let model = vbim_bake::sky_model(s);
    let (base, glow) = (model.base(sun.elevation), model.glow(sun.elevation));
    v.sky.zenith = base.map(|c| c as f32);
    v.sky.horizon = [0, 1, 2].map(|c| (base[c] + glow[c]) as f32);
    r.render(&v, None);
    r.read()
}

#[test]
fn noon_and_night_differ_as_the_lightmaps_say() {
    let (device, queue) = device();
    let (s, pre) = real(48);
    let noon = luminance(&render_frame(&device, &queue, &s, &pre, 12, (96, 54)));
    let night = luminance(&render_frame(&device, &queue, &s, &pre, 0, (96, 54)));
    assert!(night < noon / 10.0, "night {night} vs noon {noon}");
}

#[test]
fn a_rendered_frame_of_the_sample_matches_its_reference_image() {
    let (device, queue) = device();
    let (s, pre) = real(64);
    let (w, h) = (160u32, 90u32);
    // Frame 9 of 24: 9 h, a low morning sun with long shadows.
    let px = render_frame(&device, &queue, &s, &pre, 9, (w, h));
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/reference/jacksboro_morning.png");
    if std::env::var("VBIM_UPDATE_REFERENCE").is_ok() {
        image::RgbaImage::from_raw(w, h, px.clone())
            .unwrap()
            .save(&path)
            .unwrap();
    }
    let reference = image::open(&path)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (VBIM_UPDATE_REFERENCE=1 writes it)",
                path.display()
            )
        })
        .to_rgba8();
    assert_eq!(reference.dimensions(), (w, h));
    let mse: f64 = px
        .chunks(4)
        .zip(reference.as_raw().chunks(4))
        .map(|(a, b)| {
            (0..3)
                .map(|c| (a[c] as f64 - b[c] as f64).powi(2))
                .sum::<f64>()
                / 3.0
        })
        .sum::<f64>()
        / (w * h) as f64;
    let psnr = 10.0 * (255.0f64 * 255.0 / mse.max(1e-12)).log10();
    assert!(psnr >= 40.0, "rendered frame vs reference: {psnr:.2} dB");
}

/// The sky map is drawn where it says: column 0 towards north, the zenith's row first. A
/// map whose north half is red and south half blue, seen looking north and south just above
/// the horizon; and the sun's disc where the manifest puts it.
#[test]
fn the_sky_map_is_seen_in_the_direction_it_maps_and_the_sun_where_it_is() {
    let (device, queue) = device();
    let hf = flat(8, 0.0);
    let mesh = Mesh::new(&hf, 8, 1.0, 1.1);
    let lm = lightmap(&device, &queue, 8, 8, &[0.1f32; 3].repeat(64));
    let (w, h) = (32usize, 8usize);
    let sky: Vec<f32> = (0..w * h)
        .flat_map(|i| {
            let c = i % w;
            // Azimuth from north: columns 0–7 and 24–31 face north, 8–23 south.
            if !(8..24).contains(&c) {
                [0.8, 0.0, 0.0]
            } else {
                [0.0, 0.0, 0.8]
            }
        })
        .collect();
    let sky = lightmap(&device, &queue, w as u32, h as u32, &sky);
    let r = SceneRenderer::new(&device, &queue, &mesh, &lm, Some(&sky), 32, 32, FORMAT);
    let centre = |v: &View| {
        r.render(v, None);
        let px = r.read();
        let i = (16 * 32 + 16) * 4;
        [px[i], px[i + 1], px[i + 2]]
    };
    // The eye far above the terrain, looking level: north is −z in the world.
    let mut v = view(Vec3::new(0.0, 5.0, 0.0), 1.0);
    v.target = Vec3::new(0.0, 5.2, -10.0);
    let north = centre(&v);
    v.target = Vec3::new(0.0, 5.2, 10.0);
    let south = centre(&v);
    assert!(north[0] > 100 && north[2] < 10, "north {north:?}");
    assert!(south[2] > 100 && south[0] < 10, "south {south:?}");
    // A sun in the east, 20° up (map frame: x east, z up), seen straight on.
    let e = 20f32.to_radians();
    v.sky.sun_dir = [e.cos(), 0.0, e.sin()];
    v.sky.sun_color = [1.0, 0.9, 0.8];
    v.target = Vec3::new(10.0 * e.cos(), 5.0 + 10.0 * e.sin(), 0.0);
    // A narrow view: the 1.5° disc covers the middle pixels.
    v.fovy = 0.05;
    let sun = centre(&v);
    assert!(sun.iter().all(|&c| c > 240), "the sun's disc: {sun:?}");
}

/// An irradiance buffer (the layout of `vbim_player::irradiance_wgsl`) of one frame of
/// 1×1 cell: a sun of `sun` towards `sun_dir` (map frame) and a uniform sky and ground of
/// irradiance / π `ambient` at every normal.
fn irradiance_buffer(
    device: &wgpu::Device,
    sun: [f32; 3],
    sun_dir: [f32; 3],
    ambient: [f32; 3],
) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    let mut words: Vec<u32> = vec![1, 1, 1, 0];
    words.extend([1.0f32, 0.0, 0.0, 0.0].map(f32::to_bits));
    words.extend([sun_dir[0], sun_dir[1], sun_dir[2], 0.0].map(f32::to_bits));
    words.extend([0u32; 12]);
    words.extend([sun[0], sun[1], sun[2], 0.0].map(f32::to_bits));
    // Y00 = 1 / (2√π): the coefficient 2√π · a gives a at every normal.
    let c0 = 2.0 * std::f32::consts::PI.sqrt();
    words.extend(ambient.map(|a| (a * c0).to_bits()).into_iter().chain([0]));
    words.extend([0u32; 32]);
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(&words),
        usage: wgpu::BufferUsages::STORAGE,
    })
}

#[test]
fn an_object_is_lit_by_the_light_for_objects_where_it_stands() {
    let (device, queue) = device();
    let hf = flat(32, 100.0);
    let mesh = Mesh::new(&hf, 32, 1.0, 1.1);
    let lm = lightmap(&device, &queue, 32, 32, &[0.1f32; 3].repeat(32 * 32));
    let mut r = SceneRenderer::new(&device, &queue, &mesh, &lm, None, 64, 64, FORMAT);
    let albedo = [0.6, 0.5, 0.4];
    let object = Object::on_ground(&mesh, &hf, [0.5, 0.5], 0.3, albedo);
    assert!(
        (object.centre[1] - 0.3).abs() < 1e-5,
        "resting on the ground: {object:?}"
    );
    let exposure = 1.5;
    // Straight down at the sphere's top, whose normal is up: the sun from the zenith gives
    // it the sun's full value, plus the ambient; a sun from below gives it none.
    for (sun_dir, lit) in [([0.0, 0.0, 1.0], true), ([0.0, 0.0, -1.0], false)] {
        let (sun, ambient) = ([0.9, 0.8, 0.7], [0.05, 0.06, 0.08]);
        let buf = irradiance_buffer(&device, sun, sun_dir, ambient);
        r.set_objects(&buf, &[object]);
        r.render(&view(Vec3::new(0.0, 1.5, 0.001), exposure), None);
        let px = r.read();
        let centre = (32 * 64 + 32) * 4;
        for c in 0..3 {
            let e = ambient[c] + if lit { sun[c] } else { 0.0 };
            let x = albedo[c] * e * exposure;
            let want = srgb8(x / (1.0 + x));
            let got = px[centre + c] as f32;
            assert!(
                (got - want).abs() <= 1.5,
                "sun {sun_dir:?}, channel {c}: {got} vs {want}"
            );
        }
    }
}
