//! A sequence of frames from either a .vbim file (decoded by the reference decoder) or
//! image files, read frame by frame as stored values: sRGB code value / 255 for 8-bit
//! sequences, linear light for HDR ones.

use std::fs::File;
use std::io::BufReader;

use vbim_encoder::{FrameSet, InputKind};
use vbim_format::decode::{Decoder, Output};
use vbim_format::{ColorEncoding, Reader};

pub enum Sequence {
    Frames(FrameSet),
    Vbim {
        name: String,
        dec: Box<Decoder<BufReader<File>>>,
    },
}

impl Sequence {
    pub fn open(spec: &str) -> Result<Sequence, String> {
        if spec.ends_with(".vbim") {
            let f = File::open(spec).map_err(|e| format!("{spec}: {e}"))?;
            let r = Reader::open(BufReader::new(f)).map_err(|e| format!("{spec}: {e}"))?;
            return Ok(Sequence::Vbim {
                name: spec.to_string(),
                dec: Box::new(Decoder::new(r)),
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
    pub fn metadata(&mut self) -> Option<serde_json::Value> {
        let text = match self {
            Sequence::Frames(f) => f
                .manifest
                .as_ref()
                .and_then(|m| std::fs::read_to_string(m).ok()),
            Sequence::Vbim { dec, .. } => dec.reader().metadata().ok().flatten(),
        }?;
        serde_json::from_str(&text).ok()
    }
}

/// Interleaved frame → RGB (a Y-only frame is repeated into all three channels).
pub fn to_rgb(data: &[f32], channels: usize) -> Vec<f32> {
    if channels == 3 {
        data.to_vec()
    } else {
        data.iter().flat_map(|&v| [v, v, v]).collect()
    }
}
