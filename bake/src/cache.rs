//! The precomputed maps (normals, horizons, sky visibility, obscurance) cached beside the
//! output, keyed by a hash of everything they depend on: the height field's bytes and
//! sidecar, the resolution, the number of azimuths and the obscurance settings.

use std::io::{Read, Write};
use std::path::Path;

use crate::horizon::HorizonMap;
use crate::light::Precomputed;
use crate::scene::Scene;
use crate::sky::{SkyVisibility, SECTORS};
use crate::BakeError;

/// Bump when the precomputation changes, so that stale caches are recomputed.
const MAGIC: &[u8; 8] = b"VBIMPRE4";

fn fnv(h: &mut u64, bytes: &[u8]) {
    for &b in bytes {
        *h ^= b as u64;
        *h = h.wrapping_mul(0x100_0000_01b3);
    }
}

pub fn key(scene: &Scene) -> Result<u64, BakeError> {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    fnv(&mut h, MAGIC);
    let hf =
        std::fs::read(&scene.heightfield).map_err(|e| BakeError::input(&scene.heightfield, e))?;
    fnv(&mut h, &hf);
    if let Ok(side) = std::fs::read(scene.heightfield.with_extension("json")) {
        fnv(&mut h, &side);
    }
    let o = &scene.obscurance;
    let params = format!(
        "{} {} {} {} {:?} {:?}",
        scene.size, scene.azimuths, o.enabled, o.l_max_cells, o.tau_cells, scene.detail
    );
    fnv(&mut h, params.as_bytes());
    Ok(h)
}

fn path(dir: &Path, key: u64) -> std::path::PathBuf {
    dir.join(format!("pre-{key:016x}.bin"))
}

fn put(out: &mut impl Write, v: &[f32]) -> std::io::Result<()> {
    for x in v {
        out.write_all(&x.to_le_bytes())?;
    }
    Ok(())
}

/// Writes the maps for `key`, streamed (the maps are 200 bytes a texel at 32 azimuths: a
/// copy of them in memory was a third of a 4096² bake's peak).
pub fn store(dir: &Path, key: u64, pre: &Precomputed) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let hf = &pre.hf;
    let final_path = path(dir, key);
    let tmp = final_path.with_extension("tmp");
    let mut out = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
    out.write_all(MAGIC)?;
    out.write_all(&key.to_le_bytes())?;
    for v in [hf.w as u64, hf.h as u64, pre.horizons.azimuths as u64] {
        out.write_all(&v.to_le_bytes())?;
    }
    out.write_all(&hf.cell_x.to_le_bytes())?;
    out.write_all(&hf.cell_y.to_le_bytes())?;
    put(&mut out, &hf.z)?;
    for n in &pre.normals {
        put(&mut out, n)?;
    }
    put(&mut out, &pre.horizons.angles)?;
    put(&mut out, &pre.sky.coef)?;
    put(&mut out, &pre.sky.total)?;
    put(&mut out, &pre.obscurance)?;
    out.write_all(&pre.sky.elevation)?;
    out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    std::fs::rename(tmp, final_path)
}

/// Loads the cached maps for `key`, or `None` when absent or unreadable (then the caller
/// recomputes them).
pub fn load(dir: &Path, key: u64, scene: &Scene) -> Option<Precomputed> {
    let file = std::fs::File::open(path(dir, key)).ok()?;
    let len = file.metadata().ok()?.len();
    // Read array by array (a copy of the whole file in memory was as large as the maps).
    let mut r = std::io::BufReader::new(file);
    let mut head = [0u8; 56];
    r.read_exact(&mut head).ok()?;
    if &head[..8] != MAGIC || head[8..16] != key.to_le_bytes() {
        return None;
    }
    let u = |i: usize| u64::from_le_bytes(head[i..i + 8].try_into().unwrap()) as usize;
    let (w, h, az) = (u(16), u(24), u(32));
    if w != scene.size || h != scene.size || az != scene.azimuths {
        return None;
    }
    let cell_x = f64::from_le_bytes(head[40..48].try_into().unwrap());
    let cell_y = f64::from_le_bytes(head[48..56].try_into().unwrap());
    let t = w * h;
    let need = 56 + 4 * (t + 3 * t + az * t + SECTORS * t + t + t) as u64 + (SECTORS * t) as u64;
    if len != need {
        return None;
    }
    let mut buf = vec![0u8; 1 << 16];
    let mut take = |n: usize| -> Option<Vec<f32>> {
        let mut v = Vec::with_capacity(n);
        while v.len() < n {
            let bytes = &mut buf[..4 * (n - v.len()).min(1 << 14)];
            r.read_exact(bytes).ok()?;
            v.extend(
                bytes
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes(c.try_into().unwrap())),
            );
        }
        Some(v)
    };
    let z = take(t)?;
    let normals = take(3 * t)?
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let angles = take(az * t)?;
    let coef = take(SECTORS * t)?;
    let total = take(t)?;
    let obscurance = take(t)?;
    let mut elevation = vec![0u8; SECTORS * t];
    r.read_exact(&mut elevation).ok()?;
    let hf = crate::HeightField {
        w,
        h,
        cell_x,
        cell_y,
        z,
    };
    let clouds = Precomputed::clouds_for(&hf, scene);
    Some(Precomputed {
        hf,
        normals,
        horizons: HorizonMap {
            azimuths: az,
            texels: t,
            angles,
        },
        sky: SkyVisibility {
            coef,
            total,
            elevation,
        },
        obscurance,
        clouds,
    })
}
