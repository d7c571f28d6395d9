//! A sequence of frames from either a .vbim file (decoded by the reference decoder) or
//! image files, read frame by frame as stored values: sRGB code value / 255 for 8-bit
//! sequences, linear light for HDR ones.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use vbim_bake::Manifest;
use vbim_encoder::{FrameSet, InputKind};
use vbim_format::curve::{exposure_from_max_greens, max_green};
use vbim_format::decode::{Decoder, Output};
use vbim_format::metrics::Metric;
use vbim_format::{ColorEncoding, Limits, Reader};

use crate::progress::Stages;

pub enum Sequence {
    Frames(FrameSet),
    Vbim {
        name: String,
        dec: Box<Decoder<BufReader<File>>>,
    },
}

impl Sequence {
    /// A sequence from a `.vbim` file (decoded within `limits`) or image files.
    pub fn open(spec: &str, limits: Limits) -> Result<Sequence, String> {
        if spec.ends_with(".vbim") {
            let f = open_input(Path::new(spec))?;
            let r = Reader::open(BufReader::new(f)).map_err(|e| format!("{spec}: {e}"))?;
            let dec = Decoder::with_limits(r, limits).map_err(|e| format!("{spec}: {e}"))?;
            return Ok(Sequence::Vbim {
                name: spec.to_string(),
                dec: Box::new(dec),
            });
        }
        FrameSet::open(spec)
            .map(Sequence::Frames)
            .map_err(|e| e.to_string())
    }

    pub fn len(&self) -> usize {
        match self {
            Sequence::Frames(f) => f.len(),
            Sequence::Vbim { dec, .. } => dec.header().frame_count as usize,
        }
    }

    /// (width, height, channels, 8-bit?)
    pub fn shape(&self) -> (usize, usize, usize, bool) {
        match self {
            Sequence::Frames(f) => (f.width, f.height, f.channels, f.kind == InputKind::Srgb8),
            Sequence::Vbim { dec, .. } => {
                let h = dec.header();
                (
                    h.width as usize,
                    h.height as usize,
                    h.channels as usize,
                    h.color == ColorEncoding::Srgb8,
                )
            }
        }
    }

    pub fn read(&mut self, i: usize) -> Result<Vec<f32>, String> {
        match self {
            Sequence::Frames(f) => f.read(i).map(|fr| fr.data).map_err(|e| e.to_string()),
            Sequence::Vbim { name, dec } => {
                let h = dec.header();
                let mut out = vec![0f32; h.texel_count() * h.channels as usize];
                dec.frame(i as f64, Output::Stored, &mut out)
                    .map_err(|e| format!("{name}: frame {i}: {e}"))?;
                Ok(out)
            }
        }
    }

    /// The bake manifest in the .vbim's metadata chunk, or beside the frames.
    pub fn manifest(&mut self) -> Option<Manifest> {
        match self {
            Sequence::Frames(f) => f.manifest.as_ref().and_then(|m| Manifest::read(m).ok()),
            Sequence::Vbim { dec, name } => {
                // A damaged manifest costs the bake's scales and sky, not the frames: say
                // so and go on (it used to be dropped without a word).
                let text = match dec.reader().metadata() {
                    Ok(text) => text?,
                    Err(e) => {
                        eprintln!("vbim: warning: {name}: {e}; going on without its manifest");
                        return None;
                    }
                };
                // (Metadata that is not a bake manifest is someone else's: not damage.)
                Manifest::parse(&text).ok()
            }
        }
    }

    /// How the 8-bit and 16-bit exports scale this (HDR) sequence: the bake's values
    /// from its manifest; what the manifest lacks is measured in one pass over every
    /// frame (docs/CONVENTIONS.md). The one place the command line picks an exposure.
    pub fn export_scales(&mut self, stages: &Stages) -> Result<ExportScales, String> {
        let m = self.manifest();
        let (mut exposure, mut png16_scale) = (
            m.as_ref().and_then(|m| m.exposure),
            m.as_ref().and_then(|m| m.png16_scale),
        );
        if exposure.is_none() || png16_scale.is_none() {
            let (n, ch) = (self.len(), self.shape().2);
            let (mut greens, mut max) = (Vec::with_capacity(n), 0f32);
            for i in 0..n {
                let rgb = to_rgb(&self.read(i)?, ch);
                greens.push(max_green(&rgb, 3));
                max = rgb.iter().copied().fold(max, f32::max);
                stages.report("measure", i as u64 + 1, n as u64);
            }
            exposure.get_or_insert(exposure_from_max_greens(&greens));
            png16_scale.get_or_insert(if max > 0.0 { 65535.0 / max } else { 1.0 });
        }
        Ok(ExportScales {
            exposure: exposure.expect("set above"),
            png16_scale: png16_scale.expect("set above"),
        })
    }

    /// The metric this sequence is measured with: 8-bit code values, or the export curve
    /// at the sequence's exposure.
    pub fn metric(&mut self, stages: &Stages) -> Result<Metric, String> {
        if self.shape().3 {
            return Ok(Metric::Srgb8);
        }
        Ok(Metric::Hdr {
            exposure: self.exposure(stages)?,
        })
    }

    /// The export curve's exposure ([`Sequence::export_scales`]).
    pub fn exposure(&mut self, stages: &Stages) -> Result<f32, String> {
        Ok(self.export_scales(stages)?.exposure)
    }
}

/// The scales of an HDR sequence's exports.
pub struct ExportScales {
    /// The 8-bit export curve's exposure.
    pub exposure: f32,
    /// 16-bit PNG: stored value = linear × this.
    pub png16_scale: f32,
}

/// Interleaved frame → RGB (a Y-only frame is repeated into all three channels).
pub fn to_rgb(data: &[f32], channels: usize) -> Vec<f32> {
    if channels == 3 {
        data.to_vec()
    } else {
        data.iter().flat_map(|&v| [v, v, v]).collect()
    }
}

/// Opens an input file, refusing anything but a regular file first: opening a FIFO for
/// reading blocks until a writer comes, and a device or a directory is no `.vbim`.
pub fn open_input(path: &Path) -> Result<File, String> {
    let name = path.display();
    let meta = std::fs::metadata(path).map_err(|e| format!("{name}: {e}"))?;
    if !meta.is_file() {
        return Err(format!(
            "{name}: not a regular file (a FIFO, a device or a directory cannot be read)"
        ));
    }
    File::open(path).map_err(|e| format!("{name}: {e}"))
}
