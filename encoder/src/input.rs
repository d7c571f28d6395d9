//! Input frames: a directory, a glob or a printf pattern (`frames/%04d.exr`) of EXR (half
//! or float; RGB, RGBA or Y) or PNG (8- or 16-bit) files. Every frame is validated — same
//! size and channels, finite, non-negative — with errors naming the file and texel.

mod band_read;

use std::path::{Path, PathBuf};
use vbim_files::Manifest;

use crate::EncodeError;

/// How the input's values are represented.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputKind {
    /// Linear light: EXR, or 16-bit PNG divided by its scale.
    Hdr,
    /// 8-bit PNG: sRGB code values / 255.
    Srgb8,
}

/// A sequence of frame files (a directory, a glob or a `%04d` pattern), opened: the files in
/// order and the shape every one of them must have.
#[derive(Clone, Debug)]
pub struct FrameSet {
    /// The frame files, in order.
    pub paths: Vec<PathBuf>,
    /// What the files hold.
    pub kind: InputKind,
    /// Frame width, texels.
    pub width: usize,
    /// Frame height, texels.
    pub height: usize,
    /// 1 (Y) or 3 (RGB).
    pub channels: usize,
    /// 16-bit PNG: stored value = linear × scale (from the bake's manifest; else 65535).
    pub png16_scale: f32,
    /// The bake's manifest found beside the frames, if any.
    pub manifest: Option<PathBuf>,
    /// Files skipped (not images), for the user to see.
    pub notes: Vec<String>,
}

fn is_image(p: &Path) -> bool {
    matches!(
        p.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("exr") | Some("png")
    )
}

/// Expands a directory, glob or printf pattern into the ordered list of frame files.
pub fn list(spec: &str) -> Result<(Vec<PathBuf>, Vec<String>, PathBuf), EncodeError> {
    let p = Path::new(spec);
    let mut notes = Vec::new();
    if p.is_dir() {
        let mut files = Vec::new();
        let rd = std::fs::read_dir(p).map_err(|e| EncodeError::Input(format!("{spec}: {e}")))?;
        for entry in rd {
            let path = entry
                .map_err(|e| EncodeError::Input(format!("{spec}: {e}")))?
                .path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            // Frames are numbered image files; anything else (a contact sheet, notes) is
            // skipped with a note, hidden files and the manifest silently.
            let numbered = path
                .file_stem()
                .and_then(|s| s.to_str())
                .is_some_and(|s| s.ends_with(|c: char| c.is_ascii_digit()));
            if path.is_file() && is_image(&path) && numbered && !name.starts_with('.') {
                files.push(path);
            } else if path.is_file() && !name.starts_with('.') && name != Manifest::FILE_NAME {
                notes.push(format!(
                    "ignored {} (not a numbered EXR or PNG frame)",
                    path.display()
                ));
            }
        }
        if files.is_empty() {
            return Err(EncodeError::Input(format!(
                "{spec}: no .exr or .png frames in this directory"
            )));
        }
        sort_and_check_numbering(spec, &mut files)?;
        return Ok((files, notes, p.to_path_buf()));
    }
    let dir = p
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    if let Some(files) = printf_pattern(spec)? {
        return Ok((files, notes, dir));
    }
    if spec.contains(['*', '?', '[']) {
        let mut files: Vec<PathBuf> = glob::glob(spec)
            .map_err(|e| EncodeError::Input(format!("{spec}: {e}")))?
            .filter_map(Result::ok)
            .filter(|p| p.is_file() && is_image(p))
            .collect();
        files.sort();
        if files.is_empty() {
            return Err(EncodeError::Input(format!(
                "{spec}: the pattern matches no .exr or .png file"
            )));
        }
        return Ok((files, notes, dir));
    }
    if p.is_file() && is_image(p) {
        return Ok((vec![p.to_path_buf()], notes, dir));
    }
    Err(EncodeError::Input(format!(
        "{spec}: no such directory, file or pattern"
    )))
}

/// A numbered file's name before its number, and the number (`frame_0012.exr` →
/// (`frame_`, 12)).
fn numbering(p: &Path) -> (String, u64) {
    let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("");
    let prefix = stem.trim_end_matches(|c: char| c.is_ascii_digit());
    let number = stem[prefix.len()..].parse().unwrap_or(u64::MAX);
    (prefix.to_string(), number)
}

/// Orders a directory's frames by number (`frame_2` before `frame_10`) and refuses a gap
/// or two sequences in one directory: either would silently shift the day's timing.
fn sort_and_check_numbering(spec: &str, files: &mut [PathBuf]) -> Result<(), EncodeError> {
    files.sort_by_cached_key(|p| numbering(p));
    for pair in files.windows(2) {
        let ((pa, a), (pb, b)) = (numbering(&pair[0]), numbering(&pair[1]));
        if pa != pb {
            return Err(EncodeError::Input(format!(
                "{spec}: two sequences in one directory ({} and {}); name one with a pattern",
                pair[0].display(),
                pair[1].display()
            )));
        }
        if b != a + 1 {
            return Err(EncodeError::Input(format!(
                "{spec}: frame {} is missing between {} and {} (a gap would shift the timing \
                 of every later frame)",
                a + 1,
                pair[0].display(),
                pair[1].display()
            )));
        }
    }
    Ok(())
}

/// `frames/%04d.exr`: frames from 0 (or 1) upwards until the first missing number.
fn printf_pattern(spec: &str) -> Result<Option<Vec<PathBuf>>, EncodeError> {
    let Some(start) = spec.find('%') else {
        return Ok(None);
    };
    let rest = &spec[start + 1..];
    let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
    if !rest[digits.len()..].starts_with('d') {
        return Ok(None);
    }
    // A frame number has at most 20 digits; a wider field is a mistake (and Rust's
    // formatting panics on widths past 65535).
    let width = match digits.trim_start_matches('0') {
        "" => 0,
        w => w
            .parse::<usize>()
            .ok()
            .filter(|&w| w <= 20)
            .ok_or_else(|| {
                EncodeError::Input(format!("{spec}: field width {w} (at most 20 digits)"))
            })?,
    };
    let (head, tail) = (&spec[..start], &rest[digits.len() + 1..]);
    let name = |i: usize| PathBuf::from(format!("{head}{i:0width$}{tail}"));
    let first = if name(0).is_file() { 0 } else { 1 };
    let files: Vec<PathBuf> = (first..).map(name).take_while(|p| p.is_file()).collect();
    if files.is_empty() {
        return Err(EncodeError::Input(format!(
            "{spec}: no frame matches (tried {})",
            name(0).display()
        )));
    }
    Ok(Some(files))
}

/// One decoded input frame: interleaved channels, linear (HDR) or code / 255 (8-bit).
pub struct Frame {
    /// Width, texels.
    pub width: usize,
    /// Height, texels.
    pub height: usize,
    /// Channels per texel: 1 (Y) or 3 (RGB).
    pub channels: usize,
    /// What the file held.
    pub kind: InputKind,
    /// The values, row by row, channels interleaved.
    pub data: Vec<f32>,
}

impl Frame {
    /// Rows `rows` of this frame, as a frame of their own.
    pub fn rows(mut self, rows: std::ops::Range<usize>) -> Frame {
        let row = self.width * self.channels;
        self.data.truncate(rows.end * row);
        self.data.drain(..rows.start * row);
        self.height = rows.len();
        self
    }
}

/// Reads one frame file, whatever its format.
pub fn read_file(path: &Path, png16_scale: f32) -> Result<Frame, EncodeError> {
    let err = |m: String| EncodeError::Input(format!("{}: {m}", path.display()));
    // Opening a FIFO for reading blocks until a writer comes: refuse it first.
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => return Err(err("not a regular file".into())),
        Err(e) => return Err(err(e.to_string())),
        Ok(_) => {}
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext == "exr" {
        // Flat single-layer files by their blocks, straight into the frame (14% less
        // encode time at 4096² than the image reader and its per-channel copies); the
        // image reader for anything else.
        if let Some(f) = band_read::exr_rows(path, None).map_err(err)? {
            return Ok(f);
        }
        use exr::prelude::*;
        let img = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_file(path)
            .map_err(|e| err(e.to_string()))?;
        let layer = &img.layer_data;
        let (w, h) = (layer.size.width(), layer.size.height());
        let find = |name: &str| layer.channel_data.list.iter().find(|c| c.name.eq(name));
        let chans: Vec<&AnyChannel<FlatSamples>> =
            match (find("R"), find("G"), find("B"), find("Y")) {
                (Some(r), Some(g), Some(b), _) => vec![r, g, b],
                (_, _, _, Some(y)) => vec![y],
                _ => return Err(err("no R, G, B or Y channel".into())),
            };
        let planes: Vec<Vec<f32>> = chans
            .iter()
            .map(|c| c.sample_data.values_as_f32().collect())
            .collect();
        let n = chans.len();
        let mut data = vec![0f32; w * h * n];
        for (c, p) in planes.iter().enumerate() {
            if p.len() != w * h {
                return Err(err(format!("channel has {} samples for {w}×{h}", p.len())));
            }
            for (i, v) in p.iter().enumerate() {
                data[i * n + c] = *v;
            }
        }
        return Ok(Frame {
            width: w,
            height: h,
            channels: n,
            kind: InputKind::Hdr,
            data,
        });
    }
    band_read::png_rows(path, None, png16_scale).map_err(err)
}

/// The first row of a frame file and the file's height: its shape, without reading the
/// whole frame (0.8 GB at 8192² for an encode the memory plan may then refuse). Files
/// that cannot be read by rows (layered or mip-mapped EXR) are read whole.
fn first_row(path: &Path, png16_scale: f32) -> Result<(Frame, usize), EncodeError> {
    let err = |m: String| EncodeError::Input(format!("{}: {m}", path.display()));
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    // Only a regular file is opened here (a FIFO would block); anything else goes
    // through `read_file`, which says what is wrong with it.
    let regular = std::fs::metadata(path).is_ok_and(|m| m.is_file());
    let height = if !regular {
        None
    } else if ext.eq_ignore_ascii_case("exr") {
        exr::meta::MetaData::read_from_file(path, false)
            .ok()
            .and_then(|m| m.headers.first().map(|h| h.layer_size.1))
    } else if ext.eq_ignore_ascii_case("png") {
        std::fs::File::open(path)
            .ok()
            .and_then(|f| {
                png::Decoder::new(std::io::BufReader::new(f))
                    .read_info()
                    .ok()
            })
            .map(|r| r.info().height as usize)
    } else {
        None
    };
    if let Some(h) = height.filter(|&h| h > 0) {
        let row = if ext.eq_ignore_ascii_case("exr") {
            band_read::exr_rows(path, Some(0..1)).map_err(err)?
        } else {
            Some(band_read::png_rows(path, Some(0..1), png16_scale).map_err(err)?)
        };
        if let Some(row) = row {
            return Ok((row, h));
        }
    }
    let f = read_file(path, png16_scale)?;
    let h = f.height;
    Ok((f, h))
}

impl FrameSet {
    /// Lists the frames and reads the first one's shape.
    pub fn open(spec: &str) -> Result<FrameSet, EncodeError> {
        let (paths, notes, dir) = list(spec)?;
        let manifest = Some(dir.join(Manifest::FILE_NAME)).filter(|m| m.is_file());
        let png16_scale = manifest
            .as_ref()
            .and_then(|m| Manifest::read(m).ok())
            .and_then(|m| m.png16_scale)
            .unwrap_or(65535.0);
        let (first, height) = first_row(&paths[0], png16_scale)?;
        Ok(FrameSet {
            kind: first.kind,
            width: first.width,
            height,
            channels: first.channels,
            paths,
            png16_scale,
            manifest,
            notes,
        })
    }

    /// Frames in the sequence.
    pub fn len(&self) -> usize {
        self.paths.len()
    }

    /// Whether it has no frame.
    pub fn is_empty(&self) -> bool {
        self.paths.is_empty()
    }

    /// Reads frame `i` and checks it against the sequence: shape, finite, non-negative.
    pub fn read(&self, i: usize) -> Result<Frame, EncodeError> {
        let path = &self.paths[i];
        let f = read_file(path, self.png16_scale)?;
        check(&self.info(), &path.display().to_string(), i, &f)?;
        Ok(f)
    }
}

/// The shape of a sequence.
#[derive(Clone, Debug)]
pub struct SourceInfo {
    /// Frame width, texels.
    pub width: usize,
    /// Frame height, texels.
    pub height: usize,
    /// Channels per texel: 1 (Y) or 3 (RGB).
    pub channels: usize,
    /// What the frames hold.
    pub kind: InputKind,
    /// Frames in the sequence.
    pub frames: usize,
    /// What to call the sequence in messages.
    pub name: String,
}

/// Anything the encoder can read frames from: files ([`FrameSet`]) or memory.
pub trait FrameSource: Sync {
    /// The sequence's shape.
    fn info(&self) -> SourceInfo;
    /// Frame `i`, interleaved; implementations check it with `input::check`.
    fn read(&self, i: usize) -> Result<Frame, EncodeError>;
    /// Rows `rows` of frame `i` (a frame `rows.len()` high), checked as [`Self::read`]
    /// checks a frame. Large frames are coded a band of rows at a time, so a source that
    /// can read part of a frame for less than the whole should.
    fn read_rows(&self, i: usize, rows: std::ops::Range<usize>) -> Result<Frame, EncodeError> {
        let f = self.read(i)?;
        Ok(f.rows(rows))
    }
    /// The files the frames are read from (none for frames in memory): an output must
    /// not be one of them.
    fn files(&self) -> &[PathBuf] {
        &[]
    }
}

impl FrameSource for FrameSet {
    fn info(&self) -> SourceInfo {
        SourceInfo {
            width: self.width,
            height: self.height,
            channels: self.channels,
            kind: self.kind,
            frames: self.paths.len(),
            name: self
                .paths
                .first()
                .and_then(|p| p.parent())
                .map_or(String::new(), |p| p.display().to_string()),
        }
    }
    fn read(&self, i: usize) -> Result<Frame, EncodeError> {
        FrameSet::read(self, i)
    }
    fn read_rows(&self, i: usize, rows: std::ops::Range<usize>) -> Result<Frame, EncodeError> {
        let path = &self.paths[i];
        let err = |m: String| EncodeError::Input(format!("{}: {m}", path.display()));
        let exr = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        let f = if exr {
            match band_read::exr_rows(path, Some(rows.clone())).map_err(err)? {
                Some(f) => f,
                None => read_file(path, self.png16_scale)?.rows(rows.clone()),
            }
        } else {
            band_read::png_rows(path, Some(rows.clone()), self.png16_scale).map_err(err)?
        };
        let info = SourceInfo {
            height: rows.len(),
            ..self.info()
        };
        check(&info, &path.display().to_string(), i, &f)?;
        Ok(f)
    }
    fn files(&self) -> &[PathBuf] {
        &self.paths
    }
}

/// Frames held in memory (synthetic sequences, tests, other front ends).
pub struct MemorySource {
    /// The sequence's shape.
    pub info: SourceInfo,
    /// Each frame's values, row by row, channels interleaved.
    pub frames: Vec<Vec<f32>>,
}

impl MemorySource {
    /// `frames` of `width × height × channels` interleaved values each.
    pub fn new(
        name: &str,
        width: usize,
        height: usize,
        channels: usize,
        kind: InputKind,
        frames: Vec<Vec<f32>>,
    ) -> MemorySource {
        MemorySource {
            info: SourceInfo {
                width,
                height,
                channels,
                kind,
                frames: frames.len(),
                name: name.into(),
            },
            frames,
        }
    }
}

impl FrameSource for MemorySource {
    fn info(&self) -> SourceInfo {
        self.info.clone()
    }
    fn read(&self, i: usize) -> Result<Frame, EncodeError> {
        let f = Frame {
            width: self.info.width,
            height: self.info.height,
            channels: self.info.channels,
            kind: self.info.kind,
            data: self.frames[i].clone(),
        };
        check(&self.info, &self.info.name, i, &f)?;
        Ok(f)
    }
}

/// Checks frame `i` (from `name`) against the sequence: shape, finite, non-negative.
pub fn check(info: &SourceInfo, name: &str, i: usize, f: &Frame) -> Result<(), EncodeError> {
    let (width, height, channels, kind) = (info.width, info.height, info.channels, info.kind);
    if (f.width, f.height, f.channels, f.kind) != (width, height, channels, kind)
        || f.data.len() != width * height * channels
    {
        return Err(EncodeError::Input(format!(
            "{name}: frame {i} is {}×{} with {} channel(s) ({:?}), the sequence is {width}×{height} with {channels} ({kind:?})",
            f.width, f.height, f.channels, f.kind
        )));
    }
    // A branch-free pass first (it vectorises); the texel is looked for only on failure.
    let valid = |v: &f32| *v >= 0.0 && *v <= f32::MAX; // false for NaN and ±inf too
    let all_valid = f
        .data
        .chunks(4096)
        .all(|c| c.iter().fold(true, |ok, v| ok & valid(v)));
    if all_valid {
        return Ok(());
    }
    if let Some(k) = f.data.iter().position(|v| !valid(v)) {
        let t = k / f.channels;
        return Err(EncodeError::Input(format!(
            "{name}: frame {i}, texel ({}, {}) channel {}: value {} (must be finite and ≥ 0)",
            t % f.width,
            t / f.width,
            k % f.channels,
            f.data[k]
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_directory_of_frames_is_ordered_by_number_and_a_gap_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let img = image::RgbImage::new(2, 2);
        for i in [1, 2, 10, 3, 4, 5, 6, 7, 8, 9] {
            img.save(dir.path().join(format!("f_{i}.png"))).unwrap();
        }
        let (files, _, _) = super::list(dir.path().to_str().unwrap()).unwrap();
        let names: Vec<_> = files
            .iter()
            .map(|f| f.file_name().unwrap().to_str().unwrap().to_string())
            .collect();
        assert_eq!(names[..3], ["f_1.png", "f_2.png", "f_3.png"]);
        assert_eq!(names[9], "f_10.png");
        std::fs::remove_file(dir.path().join("f_5.png")).unwrap();
        let e = super::list(dir.path().to_str().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("frame 5 is missing"), "{e}");
    }

    #[test]
    fn a_printf_pattern_with_an_absurd_width_is_refused() {
        for spec in ["frames/%70000d.exr", "frames/%99999999999999999999999d.exr"] {
            let e = super::printf_pattern(spec).unwrap_err().to_string();
            assert!(e.contains(spec) && e.contains("at most 20"), "{e}");
        }
        // An ordinary one that matches nothing says what it tried.
        let e = super::printf_pattern("/nonexistent/%04d.exr")
            .unwrap_err()
            .to_string();
        assert!(e.contains("0000.exr"), "{e}");
    }

    #[test]
    fn opening_learns_the_shape_from_the_first_frames_header_and_row() {
        use crate::FrameSource;
        let dir = tempfile::tempdir().unwrap();
        // 16-bit grey PNG and an RGB f32 EXR, 5 × 7: the shape, as the whole reader
        // gives it.
        let grey = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(5, 7, |x, y| {
            image::Luma([(x * 1000 + y) as u16])
        });
        grey.save(dir.path().join("g_0.png")).unwrap();
        grey.save(dir.path().join("g_1.png")).unwrap();
        exr::prelude::write_rgb_file(dir.path().join("c_0.exr"), 5, 7, |x, y| {
            (x as f32, y as f32, 1.0f32)
        })
        .unwrap();
        for (spec, channels, kind) in [
            ("g_%d.png", 1, super::InputKind::Hdr),
            ("c_%d.exr", 3, super::InputKind::Hdr),
        ] {
            let set = super::FrameSet::open(dir.path().join(spec).to_str().unwrap()).unwrap();
            let info = set.info();
            assert_eq!(
                (info.width, info.height, info.channels),
                (5, 7, channels),
                "{spec}"
            );
            assert_eq!(info.kind, kind, "{spec}");
            let f = set.read(0).unwrap();
            assert_eq!((f.width, f.height, f.channels), (5, 7, channels), "{spec}");
        }
    }

    #[test]
    fn a_first_frame_that_is_not_a_regular_file_is_refused_without_blocking() {
        // (Listing skips such files; one can still take a frame's place after it.)
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("f_0.png");
        assert!(std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let e = super::first_row(&fifo, 65535.0)
            .err()
            .expect("a FIFO is not a frame")
            .to_string();
        assert!(
            e.contains("f_0.png") && e.contains("not a regular file"),
            "{e}"
        );
    }
}
