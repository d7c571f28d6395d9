//! Writing a bake: frames (EXR half RGB, or PNG), the manifest and the contact sheet. Every
//! file is written under a temporary name and renamed, so an interrupted bake never leaves
//! a truncated file under a final name.

use std::path::{Path, PathBuf};

use half::f16;
use serde::{Deserialize, Serialize};
use vbim_format::curve::export_curve;

use crate::light::{self, Precomputed};
use crate::scene::Scene;
use crate::{out_err, BakeError};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameFormat {
    /// Half-float RGB OpenEXR, linear.
    Exr,
    /// 8-bit sRGB PNG through the protocol's export curve.
    Png8,
    /// 16-bit PNG of the linear value times the manifest's `png16_scale`.
    Png16,
}

impl std::str::FromStr for FrameFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "exr" => Ok(FrameFormat::Exr),
            "png8" => Ok(FrameFormat::Png8),
            "png16" => Ok(FrameFormat::Png16),
            _ => Err(format!("unknown format {s:?} (exr, png8 or png16)")),
        }
    }
}

pub fn frame_name(i: usize, f: FrameFormat) -> String {
    match f {
        FrameFormat::Exr => format!("frame_{i:04}.exr"),
        FrameFormat::Png8 | FrameFormat::Png16 => format!("frame_{i:04}.png"),
    }
}

/// Writes `path` through a temporary file beside it: `write` fills the temporary file,
/// whose name ends like `path`'s (image writers pick the format from the extension); it is
/// then synced and renamed over `path`. If anything fails the temporary file is removed
/// and `path` is untouched, so an interrupted run never leaves a truncated file under a
/// final name. Only a regular file (or nothing) is ever replaced ([`check_output`]).
/// `io_err` turns a refused path, a failed sync or a failed rename into the caller's error.
/// The one place every `vbim` output file is written.
pub fn write_atomic<T, E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<T, E>,
    io_err: impl FnOnce(std::io::Error) -> E,
) -> Result<T, E> {
    if let Err(e) = check_output(path) {
        return Err(io_err(e));
    }
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("out");
    let tmp = path.with_file_name(format!(".tmp-{}-{name}", std::process::id()));
    let _registered = Temporary::new(tmp.clone());
    let result = write(&tmp).and_then(|value| {
        std::fs::File::open(&tmp)
            .and_then(|f| f.sync_all())
            .and_then(|()| std::fs::rename(&tmp, path))
            .map_err(io_err)?;
        Ok(value)
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Temporary files being written, which [`remove_temporaries`] removes when the process
/// is interrupted (the `vbim` command's Ctrl-C and SIGTERM handler), so that an interrupted
/// run leaves nothing behind: no `.tmp-` file of [`write_atomic`], no pass file of
/// `--exact`.
static TEMPORARIES: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

fn temporaries() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner())
}

/// A temporary file registered for removal on interruption while this lives (dropping it
/// only forgets the registration: the owner removes or renames the file itself).
pub struct Temporary(PathBuf);

impl Temporary {
    /// Registers `path`.
    pub fn new(path: PathBuf) -> Temporary {
        temporaries().push(path.clone());
        Temporary(path)
    }

    /// The registered path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        let mut list = temporaries();
        if let Some(i) = list.iter().position(|p| *p == self.0) {
            list.swap_remove(i);
        }
    }
}

/// Removes every registered temporary file. For an interrupt handler, which then exits:
/// the registrations are forgotten, whatever still holds them.
pub fn remove_temporaries() {
    for p in temporaries().drain(..) {
        let _ = std::fs::remove_file(p);
    }
}

/// Refuses an output path that exists and is not a regular file. Renaming over a device,
/// a FIFO, a socket, a directory or a symbolic link would replace what is not ours: as
/// root, `-o /dev/null` would have turned the machine's null device into a file.
pub fn check_output(path: &Path) -> std::io::Result<()> {
    let kind = match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
        Ok(m) => m.file_type(),
    };
    let what = if kind.is_file() {
        return Ok(());
    } else if kind.is_dir() {
        "a directory"
    } else if kind.is_symlink() {
        "a symbolic link (name the file it points to)"
    } else {
        special_kind(kind)
    };
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("is {what}: vbim only creates or replaces regular files"),
    ))
}

/// Writes `text` to `path` through [`write_file`].
pub fn write_text(path: &Path, text: &str) -> Result<(), BakeError> {
    write_file(path, |tmp| {
        std::fs::write(tmp, text).map_err(|e| e.to_string())
    })
}

/// What a file that is neither a regular file, a directory nor a link is.
#[cfg(unix)]
fn special_kind(kind: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_char_device() || kind.is_block_device() {
        "a device"
    } else if kind.is_fifo() {
        "a FIFO"
    } else {
        "not a regular file"
    }
}

#[cfg(not(unix))]
fn special_kind(_: std::fs::FileType) -> &'static str {
    "not a regular file"
}

/// [`write_atomic`] for a writer whose errors are messages: errors name `path`.
pub fn write_file(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), BakeError> {
    write_atomic(
        path,
        |tmp| write(tmp).map_err(|e| out_err(path, e)),
        |e| out_err(path, e),
    )
}

/// The protocol's 8-bit export of a linear RGB buffer.
pub fn to_png8(rgb: &[f32], exposure: f32) -> Vec<u8> {
    rgb.iter()
        .map(|&v| {
            (export_curve(v, exposure) * 255.0)
                .round()
                .clamp(0.0, 255.0) as u8
        })
        .collect()
}

pub fn write_frame(
    path: &Path,
    w: usize,
    h: usize,
    rgb: &[f32],
    format: FrameFormat,
    exposure: Option<f32>,
    png16_scale: Option<f32>,
) -> Result<(), BakeError> {
    write_file(path, |tmp| match format {
        // One thread per file: exr's parallel writer stores the blocks in the order its
        // threads finish them, so the same frame came out as different bytes from run to
        // run. Callers write frames in parallel already.
        FrameFormat::Exr => {
            use exr::prelude::{Image, SpecificChannels, Vec2, WritableImage};
            let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
                let i = (y * w + x) * 3;
                (
                    f16::from_f32(rgb[i]),
                    f16::from_f32(rgb[i + 1]),
                    f16::from_f32(rgb[i + 2]),
                )
            });
            Image::from_channels((w, h), channels)
                .write()
                .non_parallel()
                .to_file(tmp)
                .map_err(|e| e.to_string())
        }
        FrameFormat::Png8 => {
            let px = to_png8(rgb, exposure.unwrap_or(1.0));
            image::RgbImage::from_raw(w as u32, h as u32, px)
                .expect("buffer size matches")
                .save(tmp)
                .map_err(|e| e.to_string())
        }
        FrameFormat::Png16 => {
            let s = png16_scale.unwrap_or(1.0);
            let px: Vec<u16> = rgb
                .iter()
                .map(|&v| (v * s).round().clamp(0.0, 65535.0) as u16)
                .collect();
            image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w as u32, h as u32, px)
                .expect("buffer size matches")
                .save(tmp)
                .map_err(|e| e.to_string())
        }
    })
}

/// A 4 × 3 grid of 12 moments of the day (every 2 hours from midnight), each tile a
/// downscaled frame through the 8-bit export curve, separated by thin dark lines.
pub fn contact_sheet(
    pre: &Precomputed,
    scene: &Scene,
    exposure: f32,
    path: &Path,
) -> Result<(), BakeError> {
    let n = scene.size;
    let tile = 160usize.min(n);
    let gap = 2;
    let (cols, rows) = (4usize, 3usize);
    let (w, h) = (
        cols * tile + (cols + 1) * gap,
        rows * tile + (rows + 1) * gap,
    );
    let mut img = image::RgbImage::from_pixel(w as u32, h as u32, image::Rgb([24, 24, 28]));
    let mut buf = vec![0f32; n * n * 3];
    for k in 0..12 {
        let i = (k * scene.frames) / 12;
        light::light_frame(pre, scene, i, &mut buf);
        let (ox, oy) = (
            gap + (k % cols) * (tile + gap),
            gap + (k / cols) * (tile + gap),
        );
        for ty in 0..tile {
            for tx in 0..tile {
                // Box filter over the source texels this tile pixel covers.
                let (x0, x1) = (tx * n / tile, ((tx + 1) * n / tile).max(tx * n / tile + 1));
                let (y0, y1) = (ty * n / tile, ((ty + 1) * n / tile).max(ty * n / tile + 1));
                let mut acc = [0f32; 3];
                for y in y0..y1 {
                    for x in x0..x1 {
                        for c in 0..3 {
                            acc[c] += buf[(y * n + x) * 3 + c];
                        }
                    }
                }
                let cnt = ((x1 - x0) * (y1 - y0)) as f32;
                let px = acc.map(|a| (export_curve(a / cnt, exposure) * 255.0).round() as u8);
                img.put_pixel((ox + tx) as u32, (oy + ty) as u32, image::Rgb(px));
            }
        }
    }
    write_file(path, |tmp| img.save(tmp).map_err(|e| e.to_string()))
}

#[cfg(test)]
mod tests {
    #[test]
    fn only_regular_files_are_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        assert!(std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let link = dir.path().join("link");
        let target = dir.path().join("target");
        std::fs::write(&target, b"keep").unwrap();
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        for (path, what) in [
            (&fifo, "a FIFO"),
            (&link, "a symbolic link"),
            (&sub, "a directory"),
        ] {
            let err = super::write_file(path, |tmp| {
                std::fs::write(tmp, b"x").map_err(|e| e.to_string())
            })
            .unwrap_err()
            .to_string();
            assert!(err.contains(what), "{err}");
        }
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo());
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
        // Nothing left behind, and a regular file is replaced as before.
        let names = std::fs::read_dir(dir.path()).unwrap().count();
        assert_eq!(names, 4);
        super::write_file(&target, |tmp| {
            std::fs::write(tmp, b"new").map_err(|e| e.to_string())
        })
        .unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }

    use super::*;

    /// A frame written twice is the same bytes (exr's parallel writer stored blocks in
    /// whatever order its threads finished, so this failed before the writer was made
    /// single-threaded per file).
    #[test]
    fn exr_frames_are_reproducible_bytes() {
        let (w, h) = (96, 80);
        let rgb: Vec<f32> = (0..w * h * 3).map(|i| (i % 997) as f32 / 97.0).collect();
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str| {
            let p = dir.path().join(name);
            write_frame(&p, w, h, &rgb, FrameFormat::Exr, None, None).unwrap();
            std::fs::read(p).unwrap()
        };
        let first = write("a.exr");
        for k in 0..8 {
            assert!(first == write(&format!("b{k}.exr")), "write {k} differs");
        }
    }

    /// (Removal itself is the interrupt handler's: `an_interrupted_exact_encode_leaves_no_
    /// file_behind` in tests/cli.rs. Calling it here would remove the files other tests of
    /// this process are writing.)
    #[test]
    fn temporaries_are_registered_while_written_and_forgotten_when_done() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join(".tmp-a"), dir.path().join(".tmp-b"));
        let writing = Temporary::new(a.clone());
        drop(Temporary::new(b.clone()));
        let listed = temporaries().clone();
        assert!(listed.contains(&a) && !listed.contains(&b), "{listed:?}");
        drop(writing);
        assert!(!temporaries().contains(&a));
        // A file written through `write_atomic` is registered only while it is written.
        let target = dir.path().join("frame.bin");
        super::write_file(&target, |tmp| {
            assert!(temporaries().iter().any(|p| p == tmp));
            std::fs::write(tmp, b"x").map_err(|e| e.to_string())
        })
        .unwrap();
        assert!(!temporaries().iter().any(|p| p.starts_with(dir.path())));
    }
}
