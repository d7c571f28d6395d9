//! `vbim decode FILE --out DIR [--format exr|png8|png16]`

use vbim_bake::FrameFormat;
use vbim_bake::{frame_name, write_file, write_frame};
use vbim_format::curve::srgb_to_linear;

use crate::cli::DecodeArgs;
use crate::progress::Stages;
use crate::sequence::{to_rgb, Sequence};

pub fn run(a: DecodeArgs) -> Result<(), String> {
    let format: FrameFormat = a.format.parse()?;
    let name = a.file.display().to_string();
    let mut seq = Sequence::open(&name, a.memory.limits)?;
    if !name.ends_with(".vbim") {
        return Err(format!("{name}: not a .vbim file"));
    }
    let (w, h, ch, srgb8) = seq.shape();
    let stages = Stages::new();
    let n = seq.len();
    // A file of a few hundred bytes may claim ten million frames: one file each.
    if n > a.max_frames as usize {
        return Err(format!(
            "{name}: {n} frames would be written as {n} files, more than --max-frames {} \
             (raise it to decode them all)",
            a.max_frames
        ));
    }
    std::fs::create_dir_all(&a.out).map_err(|e| format!("{}: {e}", a.out.display()))?;
    // The HDR 8-bit and 16-bit exports need the day's scales (the EXR export and 8-bit
    // streams need none).
    let (exposure, png16_scale) = if !srgb8 && format != FrameFormat::Exr {
        let s = seq.export_scales(&stages)?;
        (Some(s.exposure), Some(s.png16_scale))
    } else {
        (None, None)
    };
    let write_one = |i: usize, stored: Vec<f32>| -> Result<(), String> {
        let path = a.out.join(frame_name(i, format));
        if srgb8 && format == FrameFormat::Png8 {
            // 8-bit files decode to their own code values.
            let px: Vec<u8> = stored
                .iter()
                .map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
                .collect();
            write_file(&path, |tmp| {
                image::RgbImage::from_raw(w as u32, h as u32, px)
                    .unwrap()
                    .save(tmp)
                    .map_err(|e| e.to_string())
            })
            .map_err(|e| e.to_string())
        } else {
            let linear: Vec<f32> = if srgb8 {
                stored.iter().map(|&c| srgb_to_linear(c)).collect()
            } else {
                stored
            };
            let scale = if srgb8 { Some(65535.0) } else { png16_scale };
            write_frame(&path, w, h, &linear, format, exposure, scale).map_err(|e| e.to_string())
        }
    };
    // Frames are decoded in order on this thread (the decoder walks the keyframe chain)
    // and written by one thread per core, as many as fit in 512 MB of frames in flight:
    // encoding an EXR or PNG costs more than decoding the frame.
    let frame_bytes = (w * h * 3 * 4).max(1);
    let writers = std::thread::available_parallelism()
        .map_or(1, |c| c.get())
        .min((512 << 20) / frame_bytes / 2)
        .max(1);
    let (tx, rx) = std::sync::mpsc::sync_channel::<(usize, Vec<f32>)>(writers);
    let rx = std::sync::Mutex::new(rx);
    let failed = std::sync::Mutex::new(None::<String>);
    std::thread::scope(|s| -> Result<(), String> {
        // Owned here, so that an early return closes the channel and the writers finish.
        let tx = tx;
        for _ in 0..writers {
            s.spawn(|| loop {
                let next = rx.lock().expect("no writer panics").recv();
                let Ok((i, stored)) = next else { break };
                if let Err(e) = write_one(i, stored) {
                    failed.lock().expect("no writer panics").get_or_insert(e);
                }
            });
        }
        for i in 0..n {
            if failed.lock().expect("no writer panics").is_some() {
                break;
            }
            let stored = to_rgb(&seq.read(i)?, ch);
            if tx.send((i, stored)).is_err() {
                break;
            }
            stages.report("decode", i as u64 + 1, n as u64);
        }
        Ok(())
    })?;
    if let Some(e) = failed.into_inner().expect("no writer panics") {
        return Err(e);
    }
    stages.finish();
    println!("decoded {n} frames of {w}×{h} into {}", a.out.display());
    Ok(())
}
