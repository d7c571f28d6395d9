//! Reading a band of rows of a frame file for less than the whole file: EXR files by
//! their blocks of lines or tiles (the offset table says where each block of lines is), PNG row by
//! row (decoding stops at the band's last row). The encoder reads each large frame once
//! whole for the segment search, then once by bands for the model.

use std::fs::File;
use std::io::BufReader;
use std::ops::Range;
use std::path::Path;

use super::{Frame, InputKind};

/// Rows `rows` of an EXR file (all of them: the whole image), or `None` where the file is not a single-layer flat image
/// of scan lines or tiles at one resolution (the caller reads it whole). Values are those the whole-file reader
/// gives: the R, G, B channels, or Y alone.
pub fn exr_rows(path: &Path, rows: Option<Range<usize>>) -> Result<Option<Frame>, String> {
    use exr::block::reader::ChunksReader;
    use exr::meta::attribute::SampleType;
    use exr::meta::attribute::{LevelMode, TileDescription};
    use exr::meta::BlockDescription;
    let file = File::open(path).map_err(|e| e.to_string())?;
    let reader = exr::block::read(BufReader::new(file), false).map_err(|e| e.to_string())?;
    let layers = reader.headers().len();
    let Some(header) = reader.headers().first().cloned() else {
        return Ok(None);
    };
    let channels = &header.channels.list;
    if layers != 1
        || header.deep
        || !matches!(
            header.blocks,
            BlockDescription::ScanLines
                | BlockDescription::Tiles(TileDescription {
                    level_mode: LevelMode::Singular,
                    ..
                })
        )
        || channels
            .iter()
            .any(|c| c.sampling.0 != 1 || c.sampling.1 != 1)
    {
        return Ok(None);
    }
    let (w, h) = (header.layer_size.0, header.layer_size.1);
    let rows = rows.unwrap_or(0..h);
    if rows.end > h || rows.is_empty() {
        return Err(format!("rows {rows:?} of a frame {h} high"));
    }
    let find = |name: &str| channels.iter().position(|c| c.name.eq(name));
    let wanted: Vec<usize> = match (find("R"), find("G"), find("B"), find("Y")) {
        (Some(r), Some(g), Some(b), _) => vec![r, g, b],
        (_, _, _, Some(y)) => vec![y],
        _ => return Err("no R, G, B or Y channel".into()),
    };
    let n = wanted.len();
    // Each channel's slot in the frame (None: not read), and its sample size.
    let slot: Vec<Option<usize>> = (0..channels.len())
        .map(|c| wanted.iter().position(|&k| k == c))
        .collect();
    let sizes: Vec<usize> = channels
        .iter()
        .map(|c| match c.sample_type {
            SampleType::F16 => 2,
            SampleType::F32 | SampleType::U32 => 4,
        })
        .collect();
    let mut data = vec![0f32; w * rows.len() * n];
    // A line of one channel as f32 (converted a line at a time: a call per value was a
    // tenth of a small frame's encode).
    let mut line: Vec<f32> = Vec::new();
    let mut halves: Vec<half::f16> = Vec::new();
    let filtered = reader
        .filter_chunks(false, |_, _, block| {
            let y = block.pixel_position.1;
            y < rows.end && y + block.pixel_size.1 > rows.start
        })
        .map_err(|e| e.to_string())?;
    filtered
        .decompress_sequential(false, |_, block| {
            let (x0, y0) = (block.index.pixel_position.0, block.index.pixel_position.1);
            let (bw, bh) = (block.index.pixel_size.0, block.index.pixel_size.1);
            // A block holds its lines one after another, and each line its channels one
            // after another, native-endian.
            let line_bytes: usize = sizes.iter().map(|s| s * bw).sum();
            if block.data.len() < line_bytes * bh || x0 + bw > w {
                return Err(exr::error::Error::Invalid(
                    "block smaller than its lines".into(),
                ));
            }
            for l in 0..bh {
                let y = y0 + l;
                if !rows.contains(&y) {
                    continue;
                }
                let mut at = l * line_bytes;
                for (c, ch) in channels.iter().enumerate() {
                    let bytes = &block.data[at..at + sizes[c] * bw];
                    at += sizes[c] * bw;
                    let Some(k) = slot[c] else { continue };
                    let out = (y - rows.start) * w + x0;
                    line.clear();
                    match ch.sample_type {
                        SampleType::F16 => {
                            use half::slice::HalfFloatSliceExt;
                            halves.clear();
                            halves.extend(
                                bytes
                                    .chunks_exact(2)
                                    .map(|s| half::f16::from_ne_bytes([s[0], s[1]])),
                            );
                            line.resize(bw, 0.0);
                            halves.convert_to_f32_slice(&mut line);
                        }
                        SampleType::F32 => line.extend(
                            bytes
                                .chunks_exact(4)
                                .map(|s| f32::from_ne_bytes([s[0], s[1], s[2], s[3]])),
                        ),
                        SampleType::U32 => line.extend(
                            bytes
                                .chunks_exact(4)
                                .map(|s| u32::from_ne_bytes([s[0], s[1], s[2], s[3]]) as f32),
                        ),
                    }
                    for (d, &v) in data[out * n..(out + bw) * n]
                        .iter_mut()
                        .skip(k)
                        .step_by(n)
                        .zip(&line)
                    {
                        *d = v;
                    }
                }
            }
            Ok(())
        })
        .map_err(|e| e.to_string())?;
    Ok(Some(Frame {
        width: w,
        height: rows.len(),
        channels: n,
        kind: InputKind::Hdr,
        data,
    }))
}

/// Rows `rows` of a PNG file (all of them: the whole image), decoded row by row and
/// stopping after the last one wanted, as the encoder reads every PNG: grey stays one
/// channel, colour is RGB (alpha dropped, grey with alpha repeated), 8-bit values are
/// code / 255 and 16-bit values are divided by `png16_scale`.
pub fn png_rows(
    path: &Path,
    rows: Option<Range<usize>>,
    png16_scale: f32,
) -> Result<Frame, String> {
    use png::{BitDepth, ColorType, Transformations};
    let file = File::open(path).map_err(|e| e.to_string())?;
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(|e| e.to_string())?;
    let (w, h) = {
        let i = reader.info();
        (i.width as usize, i.height as usize)
    };
    let rows = rows.unwrap_or(0..h);
    if rows.end > h || rows.is_empty() {
        return Err(format!("rows {rows:?} of a frame {h} high"));
    }
    let (color, depth) = reader.output_color_type();
    let (src_ch, n) = match color {
        ColorType::Grayscale => (1, 1),
        ColorType::GrayscaleAlpha => (2, 3),
        ColorType::Rgb => (3, 3),
        ColorType::Rgba => (4, 3),
        ColorType::Indexed => return Err("unsupported PNG pixel format".into()),
    };
    let (kind, wide) = match depth {
        BitDepth::Eight => (InputKind::Srgb8, false),
        BitDepth::Sixteen => (InputKind::Hdr, true),
        _ => return Err("unsupported PNG pixel format".into()),
    };
    let scale = if wide { png16_scale } else { 255.0 };
    let mut data = Vec::with_capacity(w * rows.len() * n);
    let mut put = |row: &[u8]| {
        let sample = |i: usize| -> f32 {
            if wide {
                u16::from_be_bytes([row[2 * i], row[2 * i + 1]]) as f32 / scale
            } else {
                row[i] as f32 / scale
            }
        };
        for x in 0..w {
            let s = x * src_ch;
            match src_ch {
                1 => data.push(sample(s)),
                2 => data.extend([sample(s); 3]),
                _ => data.extend([sample(s), sample(s + 1), sample(s + 2)]),
            }
        }
    };
    if reader.info().interlaced {
        // Interlaced rows come in passes: decode the whole image.
        let mut buf = vec![0; reader.output_buffer_size().ok_or("image too large")?];
        let out = reader.next_frame(&mut buf).map_err(|e| e.to_string())?;
        for y in rows.clone() {
            put(&buf[y * out.line_size..(y + 1) * out.line_size]);
        }
    } else {
        for y in 0..rows.end {
            let row = reader
                .next_row()
                .map_err(|e| e.to_string())?
                .ok_or_else(|| format!("image ends at row {y} of {h}"))?;
            if y >= rows.start {
                put(row.data());
            }
        }
    }
    Ok(Frame {
        width: w,
        height: rows.len(),
        channels: n,
        kind,
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::*;

    const W: usize = 37;
    const H: usize = 29;

    fn value(x: usize, y: usize, c: usize) -> f32 {
        ((x * 7 + y * 13 + c * 5) % 23) as f32 * 0.37 + c as f32
    }

    /// Bands of rows of `path`, against the image reader's whole file.
    fn check_exr(path: &Path) {
        let whole = read_first_rgba_layer_from_file(
            path,
            |res, _| vec![[0f32; 3]; res.width() * res.height()],
            |px: &mut Vec<[f32; 3]>, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * W + pos.x()] = [r, g, b]
            },
        )
        .unwrap()
        .layer_data
        .channel_data
        .pixels;
        for rows in [0..H, 0..1, 5..23, 28..29] {
            let band = exr_rows(path, Some(rows.clone())).unwrap().unwrap();
            assert_eq!((band.width, band.height, band.channels), (W, rows.len(), 3));
            let want: Vec<f32> = whole[rows.start * W..rows.end * W]
                .iter()
                .flatten()
                .copied()
                .collect();
            assert_eq!(band.data, want, "rows {rows:?}");
        }
    }

    #[test]
    fn bands_of_exr_scan_lines_and_tiles_are_the_image_readers_rows() {
        let dir = tempfile::tempdir().unwrap();
        // f32 scan lines in blocks of 16 (ZIP), and f16 tiles of 8 × 8 (RLE): bands that
        // start and end inside a block.
        let lines = dir.path().join("lines.exr");
        Image::from_encoded_channels(
            (W, H),
            Encoding {
                compression: Compression::ZIP16,
                blocks: Blocks::ScanLines,
                line_order: LineOrder::Increasing,
            },
            SpecificChannels::rgb(|Vec2(x, y)| (value(x, y, 0), value(x, y, 1), value(x, y, 2))),
        )
        .write()
        .to_file(&lines)
        .unwrap();
        check_exr(&lines);
        let tiles = dir.path().join("tiles.exr");
        Image::from_encoded_channels(
            (W, H),
            Encoding {
                compression: Compression::RLE,
                blocks: Blocks::Tiles(Vec2(8, 8)),
                line_order: LineOrder::Increasing,
            },
            SpecificChannels::rgb(|Vec2(x, y)| {
                (
                    f16::from_f32(value(x, y, 0)),
                    f16::from_f32(value(x, y, 1)),
                    f16::from_f32(value(x, y, 2)),
                )
            }),
        )
        .write()
        .to_file(&tiles)
        .unwrap();
        check_exr(&tiles);
    }

    #[test]
    fn bands_of_png_rows_are_the_image_readers_rows() {
        let dir = tempfile::tempdir().unwrap();
        let rgba = dir.path().join("rgba.png");
        let px: Vec<u8> = (0..W * H * 4).map(|i| (i * 37 % 251) as u8).collect();
        image::RgbaImage::from_raw(W as u32, H as u32, px)
            .unwrap()
            .save(&rgba)
            .unwrap();
        let grey = dir.path().join("grey16.png");
        let px: Vec<u16> = (0..W * H * 2).map(|i| (i * 4099 % 65521) as u16).collect();
        image::ImageBuffer::<image::LumaA<u16>, _>::from_raw(W as u32, H as u32, px)
            .unwrap()
            .save(&grey)
            .unwrap();
        let want_rgba: Vec<f32> = image::open(&rgba)
            .unwrap()
            .to_rgb8()
            .into_raw()
            .iter()
            .map(|&v| v as f32 / 255.0)
            .collect();
        let want_grey: Vec<f32> = image::open(&grey)
            .unwrap()
            .to_rgb16()
            .into_raw()
            .iter()
            .map(|&v| v as f32 / 1000.0)
            .collect();
        for rows in [0..H, 0..1, 5..23, 28..29] {
            let r = png_rows(&rgba, Some(rows.clone()), 1000.0).unwrap();
            assert_eq!((r.kind, r.channels), (InputKind::Srgb8, 3));
            assert_eq!(r.data, want_rgba[rows.start * W * 3..rows.end * W * 3]);
            let g = png_rows(&grey, Some(rows.clone()), 1000.0).unwrap();
            assert_eq!((g.kind, g.channels), (InputKind::Hdr, 3));
            assert_eq!(g.data, want_grey[rows.start * W * 3..rows.end * W * 3]);
        }
    }
}
