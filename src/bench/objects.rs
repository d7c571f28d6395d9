//! `vbim bench objects PKG`: what the light for objects costs — the irradiance tracks'
//! bytes, the GPU buffer and its uploads, and the CPU query's time per call.

use std::time::{Duration, Instant};

use vbim_player::{PackagePlayer, PlayerConfig, TrackKind};

use super::args::BenchObjectsArgs;
use super::stats;

/// A display frame at 60 Hz, ns.
const DISPLAY: u64 = 16_666_667;

pub fn run(a: BenchObjectsArgs) -> Result<(), String> {
    let (device, queue, info) = vbim_player::headless_device().map_err(|e| e.to_string())?;
    let mut p = PackagePlayer::open(&device, &queue, &a.package, None, PlayerConfig::default())
        .map_err(|e| e.to_string())?;
    let file = p.file().clone();
    let grid = p
        .irradiance_grid()
        .cloned()
        .ok_or_else(|| format!("{}: no irradiance tracks", a.package.display()))?;
    println!(
        "{}: {}² cells at {} m above the ground; adapter {}",
        a.package.display(),
        grid.cells[0],
        grid.height_m,
        info.name
    );
    println!("  weather     irradiance bytes  per frame  share of the weather's bytes");
    for w in &file.package.weathers {
        let tracks: Vec<_> = file.tracks.iter().filter(|t| t.weather == w.name).collect();
        let all: u64 = tracks.iter().map(|t| t.bytes).sum();
        if let Some(t) = tracks.iter().find(|t| t.kind == TrackKind::Irradiance) {
            println!(
                "  {:<11} {:>16}  {:>9.0}  {:>5.1}%",
                w.name,
                t.bytes,
                t.bytes as f64 / t.header.frame_count as f64,
                100.0 * t.bytes as f64 / all as f64
            );
        }
    }
    // Half a day in, then measure what each frame uploads over two seconds.
    let frames_per_media = 60.0 / file.tracks[0].header.fps();
    let skip = (file.tracks[0].header.frame_count as f64 * 0.45 * frames_per_media) as usize;
    p.set_time(skip as u64 * DISPLAY);
    let mut uploaded = Vec::new();
    for _ in 0..120 {
        let r = p.advance(DISPLAY);
        p.wait_irradiance(Duration::from_secs(10));
        uploaded.push(r.objects.map_or(0, |o| o.bytes_uploaded));
    }
    let mean_up = uploaded.iter().sum::<u64>() as f64 / uploaded.len() as f64;
    println!(
        "  buffer      {} bytes on the GPU; {:.0} bytes uploaded per displayed frame (mean of \
         120 at 60 Hz; a frame's grids go up once, the weights every frame)",
        p.irradiance_buffer().map_or(0, |b| b.size()),
        mean_up
    );
    time_queries(&p, &a, "two frames mixed");
    time_first_query(&mut p);
    if let Some(path) = &a.plot {
        plot_evening(&file, path)?;
    }
    let weathers: Vec<String> = p.weathers().map(str::to_string).collect();
    if let Some(other) = weathers.iter().find(|w| *w != p.weather()) {
        p.switch_weather(other, 4_000_000_000)
            .map_err(|e| e.to_string())?;
        for _ in 0..1200 {
            let r = p.advance(DISPLAY);
            if r.switch.as_ref().is_some_and(|s| s.weight > 0.3) {
                break;
            }
        }
        if p.irradiance_frames()
            .is_some_and(|f| f.slots().count() == 4)
        {
            time_queries(&p, &a, "mid-fade, four frames mixed");
            time_first_query(&mut p);
        }
    }
    Ok(())
}

/// Times `a.queries` calls of `irradiance` at scattered positions and normals, `a.runs`
/// times, on this thread.
fn time_queries(p: &PackagePlayer, a: &BenchObjectsArgs, what: &str) {
    let n = a.queries.max(1);
    let q: Vec<([f32; 2], [f32; 3])> = (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - z * z).sqrt();
            let t = 2.399_963 * i as f32;
            let uv = [
                (i as f32 * 0.618_034).fract(),
                (i as f32 * 0.754_877).fract(),
            ];
            (uv, [r * t.cos(), r * t.sin(), z])
        })
        .collect();
    let mut times = Vec::new();
    let mut sink = 0f32;
    for _ in 0..a.runs.max(1) {
        let t0 = Instant::now();
        for (uv, nrm) in &q {
            let e = p.irradiance(uv[0], uv[1], *nrm).unwrap_or_default();
            sink += e[1];
        }
        times.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    let (med, lo, hi) = stats(&mut times);
    println!(
        "  query       {what}: {n} calls in {med:.3} ms ({lo:.3}–{hi:.3}, {} runs), {:.0} ns a \
         call (checksum {sink:.3e})",
        a.runs.max(1),
        med * 1e6 / n as f64
    );
}

/// The first query of a frame also sums the slots' coefficients: its time, median of 7
/// frames.
fn time_first_query(p: &mut PackagePlayer) {
    let mut times = Vec::new();
    for _ in 0..7 {
        p.advance(DISPLAY);
        p.wait_irradiance(Duration::from_secs(10));
        let t0 = Instant::now();
        let e = p.irradiance(0.5, 0.5, [0.0, 0.0, 1.0]);
        times.push(t0.elapsed().as_secs_f64() * 1e6);
        std::hint::black_box(e);
    }
    let (med, lo, hi) = stats(&mut times);
    println!(
        "  first       the first call of a frame (it sums the frames' coefficients): \
         {med:.0} µs ({lo:.0}–{hi:.0})"
    );
}

/// The evening at the ridge and in the valley, from the first weather's irradiance track
/// through the reference decoder: every media frame from noon on, the sun of every cell
/// and what an up-facing object at its centre receives; the ridge is the cell the sun
/// leaves last, the valley the one it leaves first.
fn plot_evening(file: &vbim_player::PackageFile, path: &std::path::Path) -> Result<(), String> {
    use vbim_format::irradiance::{read_track, Grid};
    let t = file
        .tracks
        .iter()
        .find(|t| t.kind == TrackKind::Irradiance)
        .ok_or("no irradiance track")?;
    let err = |e: vbim_format::FormatError| format!("{}: {e}", t.path.display());
    let f = std::fs::File::open(&t.path).map_err(|e| format!("{}: {e}", t.path.display()))?;
    let mut reader = vbim_format::Reader::open(f).map_err(err)?;
    let h = reader.header().clone();
    let n = h.frame_count as usize;
    let (info, suns_of) =
        read_track(&mut reader).map_err(|e| format!("{}: {e}", t.path.display()))?;
    let [nx, ny] = info.cells;
    let mut d = vbim_format::decode::Decoder::new(reader).map_err(err)?;
    let mut rgb = vec![0f32; (h.width * h.height * 3) as usize];
    let (mut suns, mut totals) = (Vec::new(), Vec::new());
    for (k, sun) in suns_of.iter().enumerate().skip(n / 2) {
        d.frame(k as f64, vbim_format::decode::Output::Linear, &mut rgb)
            .map_err(err)?;
        let g = Grid::from_image(&rgb, &info, sun.dir, sun.color);
        suns.push(g.cells.iter().map(|c| c.sun[1]).collect::<Vec<f32>>());
        totals.push(
            (0..nx * ny)
                .map(|c| {
                    let u = ((c % nx) as f32 + 0.5) / nx as f32;
                    let v = ((c / nx) as f32 + 0.5) / ny as f32;
                    g.irradiance(u, v, [0.0, 0.0, 1.0])[1]
                })
                .collect::<Vec<f32>>(),
        );
    }
    // The last frame after noon at which each cell still has the sun (above a thousandth
    // of the day's brightest sun: coding noise is not sunlight).
    let peak = suns.iter().flatten().fold(0f32, |m, &v| m.max(v));
    let cells = nx * ny;
    let last_sun = |c: usize| suns.iter().rposition(|s| s[c] > 1e-3 * peak).unwrap_or(0);
    let ridge = (0..cells).max_by_key(|&c| last_sun(c)).unwrap_or(0);
    let valley = (0..cells).min_by_key(|&c| last_sun(c)).unwrap_or(0);
    let hours = |i: usize| 24.0 * (n / 2 + i) as f64 / n as f64;
    let series = |c: usize, what: &str, v: &[Vec<f32>]| crate::plot::Series {
        name: format!("{what}, cell {c}"),
        points: v
            .iter()
            .enumerate()
            .map(|(i, s)| (hours(i), s[c] as f64))
            .collect(),
    };
    crate::plot::lines(
        path,
        "Light for objects after noon: where the sun stays longest, where it leaves first",
        "hour of the day",
        "irradiance / π (green), lightmap units",
        &[
            series(ridge, "ridge: up-facing object", &totals),
            series(ridge, "ridge: sun at normal incidence", &suns),
            series(valley, "valley: up-facing object", &totals),
            series(valley, "valley: sun at normal incidence", &suns),
        ],
        false,
    )?;
    println!(
        "  evening     {}: the sun leaves the valley's cell {valley} after {:.1} h and the \
         ridge's cell {ridge} after {:.1} h; plot {}",
        t.weather,
        hours(last_sun(valley)),
        hours(last_sun(ridge)),
        path.display()
    );
    Ok(())
}
