//! Light for objects on a real adapter: a small bake of two weathers with irradiance
//! tracks, coded, played as a package. The CPU answer is the time interpolation of the
//! reference decoder's frames, the shader function gives the CPU answer, and a damaged
//! irradiance chunk is held, then caught up, never a panic.

use std::io::Cursor;
use std::path::Path;
use std::time::Duration;

use vbim_encoder::{encode, EncoderConfig, FrameSet, Preset, SegmentMode};
use vbim_format::decode::{Decoder, Output};
use vbim_format::irradiance::{read_track, Grid};
use vbim_format::package::Package;
use vbim_format::{ChunkKind, Reader};
use vbim_player::{
    headless_device, irradiance_wgsl, LightmapSampling, PackagePlayer, PlayerConfig,
};

/// 1/60 s: a display frame.
const DISPLAY: u64 = 16_666_667;
const CELLS: usize = 8;

fn device() -> (wgpu::Device, wgpu::Queue) {
    match headless_device() {
        Ok((d, q, _)) => (d, q),
        Err(e) => panic!("{e}"),
    }
}

/// Bakes 24 frames of a 64² terrain under a clear and an overcast sky, codes every track
/// and writes `day.vbimpkg`; returns the folder.
fn package() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let hf = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../samples/dem/jacksboro_fault_mpl.png"
    );
    let mut scene = vbim_bake::Scene::with_heightfield(hf);
    scene.size = 64;
    scene.frames = 24;
    scene.fps = "24/1".into();
    scene.objects.cells = CELLS;
    scene.weathers = ["clear", "overcast"]
        .iter()
        .zip([0.0, 1.0])
        .map(|(n, cover)| vbim_bake::WeatherParams {
            name: n.to_string(),
            cover,
            turbidity: 2.5,
        })
        .collect();
    let bake_dir = dir.path().join("bake");
    let opts = vbim_bake::BakeOptions {
        out: bake_dir.clone(),
        format: vbim_bake::FrameFormat::Exr,
        use_cache: false,
    };
    let summary = vbim_bake::bake(&scene, &opts, &|_, _, _| {}).unwrap();
    let baked =
        Package::parse(&std::fs::read_to_string(summary.package.as_ref().unwrap()).unwrap())
            .unwrap();
    assert!(baked.weathers.iter().all(|w| w.irradiance.is_some()));
    let coded = baked.coded_as("day");
    for (w, c) in baked.weathers.iter().zip(&coded.weathers) {
        for ((_, input), (_, file)) in w.tracks().zip(c.tracks()) {
            encode_dir(&bake_dir.join(input), &dir.path().join(file));
        }
    }
    std::fs::write(dir.path().join("day.vbimpkg"), coded.to_json()).unwrap();
    dir
}

fn encode_dir(input: &Path, out: &Path) {
    let frames = FrameSet::open(input.to_str().unwrap()).unwrap();
    let cfg = EncoderConfig {
        segment: SegmentMode::Fixed(6),
        rate: (24, 1),
        aim: false,
        metadata: Some(std::fs::read_to_string(input.join("manifest.json")).unwrap()),
        ..EncoderConfig::preset(Preset::Default)
    };
    let mut bytes = Vec::new();
    encode(&frames, &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    std::fs::write(out, bytes).unwrap();
}

/// Frame `k` of the irradiance track at `path`, through the reference decoder.
fn reference(path: &Path, k: usize) -> Grid {
    let mut reader = Reader::open(std::fs::File::open(path).unwrap()).unwrap();
    let h = reader.header().clone();
    let (info, suns) = read_track(&mut reader).unwrap();
    assert_eq!(info.cells, [CELLS, CELLS]);
    let mut d = Decoder::new(reader).unwrap();
    let mut rgb = vec![0f32; (h.width * h.height * 3) as usize];
    d.frame(k as f64, Output::Linear, &mut rgb).unwrap();
    Grid::from_image(&rgb, &info, suns[k].dir, suns[k].color)
}

fn normals() -> Vec<[f32; 3]> {
    let mut out = vec![
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
    ];
    for i in 0..28 {
        let z = 1.0 - 2.0 * (i as f32 + 0.5) / 28.0;
        let r = (1.0 - z * z).sqrt();
        let a = 2.399_963 * i as f32;
        out.push([r * a.cos(), r * a.sin(), z]);
    }
    out
}

fn points() -> Vec<[f32; 2]> {
    (0..7)
        .flat_map(|j| (0..7).map(move |i| [i as f32 / 6.0, (j as f32 + 0.3) / 6.3]))
        .collect()
}

#[test]
fn between_two_frames_an_object_gets_the_time_interpolation_of_the_two() {
    let dir = package();
    let (device, queue) = device();
    let path = dir.path().join("day.vbimpkg");
    let mut p = PackagePlayer::open(&device, &queue, &path, None, PlayerConfig::default()).unwrap();
    assert_eq!(p.irradiance_grid().unwrap().cells, [CELLS, CELLS]);
    let track = dir.path().join("day-clear-irradiance.vbim");
    let mut seen = 0;
    for _ in 0..240 {
        let r = p.advance(DISPLAY);
        let rec = p.wait_irradiance(Duration::from_secs(10)).unwrap();
        assert!(rec.exact && rec.error.is_none(), "{rec:?}");
        let t = r.lightmap.shown.rem_euclid(24.0);
        let (k0, w) = (t.floor() as usize, (t - t.floor()) as f32);
        if !(0.2..0.8).contains(&w) || seen > 3 {
            continue;
        }
        seen += 1;
        let (a, b) = (reference(&track, k0), reference(&track, (k0 + 1) % 24));
        for [u, v] in points() {
            for n in normals() {
                let got = p.irradiance(u, v, n).unwrap();
                let (ea, eb) = (a.irradiance(u, v, n), b.irradiance(u, v, n));
                for c in 0..3 {
                    let want = ea[c] * (1.0 - w) + eb[c] * w;
                    assert!(
                        (got[c] - want).abs() <= 1e-5 * (1.0 + want.abs()),
                        "t {t:.3}, ({u}, {v}), {n:?}: {} against {want}",
                        got[c]
                    );
                }
            }
        }
    }
    assert!(seen > 0, "no frame between two media frames");
}

#[test]
fn the_shader_function_gives_the_cpu_answer() {
    let dir = package();
    let (device, queue) = device();
    let path = dir.path().join("day.vbimpkg");
    let mut p = PackagePlayer::open(&device, &queue, &path, None, PlayerConfig::default()).unwrap();
    // Mid-morning, between two frames, halfway through a fade to overcast: four frames mixed.
    for _ in 0..150 {
        p.advance(DISPLAY);
    }
    p.switch_weather("overcast", 2_000_000_000).unwrap();
    let mut mixed = false;
    for _ in 0..600 {
        let r = p.advance(DISPLAY);
        if r.switch
            .as_ref()
            .is_some_and(|s| (0.3..0.7).contains(&s.weight))
        {
            mixed = r.objects.as_ref().unwrap().exact;
            break;
        }
    }
    assert!(
        mixed,
        "the fade reached its middle with both weathers' grids"
    );
    assert_eq!(p.irradiance_frames().unwrap().slots().count(), 4);
    let queries: Vec<[f32; 8]> = points()
        .iter()
        .flat_map(|&[u, v]| {
            normals()
                .into_iter()
                .map(move |n| [u, v, 0.0, 0.0, n[0], n[1], n[2], 0.0])
        })
        .collect();
    let cpu: Vec<[f32; 3]> = queries
        .iter()
        .map(|q| p.irradiance(q[0], q[1], [q[4], q[5], q[6]]).unwrap())
        .collect();
    let gpu = evaluate_on_gpu(&device, &queue, p.irradiance_buffer().unwrap(), &queries);
    let scale = cpu.iter().flatten().fold(0f32, |m, v| m.max(v.abs()));
    for (i, (c, g)) in cpu.iter().zip(&gpu).enumerate() {
        for k in 0..3 {
            assert!(
                (c[k] - g[k]).abs() <= 1e-4 * scale,
                "query {i}: CPU {c:?}, GPU {g:?}"
            );
        }
    }
}

/// Runs `vbim_irradiance` over `queries` (uv, _, _, normal, _) in a compute shader.
fn evaluate_on_gpu(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    grid: &wgpu::Buffer,
    queries: &[[f32; 8]],
) -> Vec<[f32; 3]> {
    use wgpu::util::DeviceExt;
    let src = irradiance_wgsl(0, 0)
        + r#"
@group(0) @binding(1) var<storage, read> queries: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> answers: array<vec4<f32>>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&answers) { return; }
    let q = queries[2u * i];
    let n = queries[2u * i + 1u];
    answers[i] = vec4<f32>(vbim_irradiance(q.xy, n.xyz), 0.0);
}
"#;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("irradiance test"),
        source: wgpu::ShaderSource::Wgsl(src.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: None,
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let q = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(queries),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = (queries.len() * 16) as u64;
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let read = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: grid.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: q.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: out.as_entire_binding(),
            },
        ],
    });
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups((queries.len() as u32).div_ceil(64), 1, 1);
    }
    enc.copy_buffer_to_buffer(&out, 0, &read, 0, size);
    queue.submit(Some(enc.finish()));
    read.slice(..)
        .map_async(wgpu::MapMode::Read, |r| r.unwrap());
    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    let data = read.slice(..).get_mapped_range();
    bytemuck::cast_slice::<u8, [f32; 4]>(&data)
        .iter()
        .map(|v| [v[0], v[1], v[2]])
        .collect()
}

#[test]
fn a_damaged_irradiance_chunk_is_held_then_caught_up() {
    let dir = package();
    let track = dir.path().join("day-clear-irradiance.vbim");
    // Damage the coefficients of the segment of frames 6 to 12.
    let entry = Reader::open(std::fs::File::open(&track).unwrap())
        .unwrap()
        .entries()
        .iter()
        .find(|e| e.kind == ChunkKind::Coefficients && e.first_frame == 6)
        .cloned()
        .expect("a segment from frame 6");
    let mut bytes = std::fs::read(&track).unwrap();
    bytes[(entry.offset + entry.length / 2) as usize] ^= 0x5a;
    std::fs::write(&track, bytes).unwrap();
    let (device, queue) = device();
    let path = dir.path().join("day.vbimpkg");
    let mut p = PackagePlayer::open(&device, &queue, &path, None, PlayerConfig::default()).unwrap();
    let (mut held, mut caught_up) = (0, false);
    let mut error = None;
    for _ in 0..60 {
        let r = p.advance(DISPLAY);
        let rec = p.wait_irradiance(Duration::from_secs(10)).unwrap();
        let t = r.lightmap.shown;
        if (6.0..11.0).contains(&t) {
            assert!(
                !rec.exact,
                "t {t:.2}: the damaged segment's grid is not shown"
            );
            held += 1;
            error = error.or(rec.error);
            assert!(
                p.irradiance(0.5, 0.5, [0.0, 0.0, 1.0]).is_some(),
                "the last answer stays"
            );
        }
        if t >= 12.0 {
            caught_up |= rec.exact;
        }
    }
    let error = error.expect("the failure is reported");
    assert!(
        error.contains("day-clear-irradiance.vbim") && error.contains("frame"),
        "{error}"
    );
    assert!(
        held > 0 && caught_up,
        "held {held} frames, caught up: {caught_up}"
    );
}

#[test]
fn the_lightmap_beneath_an_object_comes_back_a_frame_or_two_later_without_waiting() {
    let dir = package();
    let (device, queue) = device();
    let path = dir.path().join("day.vbimpkg");
    let mut p = PackagePlayer::open(&device, &queue, &path, None, PlayerConfig::default()).unwrap();
    let before = p.gpu_bytes();
    p.set_lightmap_sampling(Some(LightmapSampling {
        max_side: 16,
        every_ns: 0,
    }));
    // 64² averaged over blocks of 4: 16², and its three buffers counted.
    assert_eq!(p.lightmap_sampling_grid(), Some([16, 16, 4]));
    assert_eq!(p.gpu_bytes() - before, 3 * 16 * 16 * 16 + 16);
    // Every frame's lightmap by the media time it showed. Frames that show the same time
    // need not hold the same texels: when data is late (a loaded machine: it failed CI
    // once) the player shows its held copy of the last frame at that frame's time, kept
    // as RGB9E5, which rounds a texel differently from the Rgba16Float it copies.
    let mut shown: std::collections::HashMap<u64, Vec<(i32, Vec<f32>)>> = Default::default();
    let (mut checked, mut latest_lag) = (0, 0);
    for frame in 0..40 {
        let r = p.advance(DISPLAY);
        let lm = p.read_lightmap();
        shown
            .entry(r.lightmap.shown.to_bits())
            .or_default()
            .push((frame, lm));
        let (bx, by) = (5usize, 9usize);
        let (u, v) = ((bx as f32 + 0.5) / 16.0, (by as f32 + 0.5) / 16.0);
        let Some(s) = p.sample_lightmap(u, v) else {
            continue;
        };
        // The mean of the block's 4 × 4 texels of a frame (RGBA, 64 texels a row).
        let mean = |lm: &[f32], c: usize| {
            let mut sum = 0.0;
            for y in by * 4..by * 4 + 4 {
                for x in bx * 4..bx * 4 + 4 {
                    sum += lm[(y * 64 + x) * 4 + c];
                }
            }
            sum / 16.0
        };
        let candidates = &shown[&s.shown.to_bits()];
        let matching = candidates.iter().rev().find(|(_, lm)| {
            (0..3).all(|c| {
                let want = mean(lm, c);
                (s.rgb[c] - want).abs() <= 1e-5 + 1e-4 * want.abs()
            })
        });
        let Some((at, _)) = matching else {
            let (at, lm) = candidates.last().unwrap();
            panic!(
                "frame {frame}: the sample {:?} matches none of the {} frames that showed its \
                 time (the last, frame {at}: {:?})",
                s.rgb,
                candidates.len(),
                [0, 1, 2].map(|c| mean(lm, c))
            );
        };
        latest_lag = frame - at;
        checked += 1;
    }
    assert!(checked > 30, "{checked} frames had a sample");
    assert!(latest_lag <= 2, "the sample lags {latest_lag} frames");
}
