//! File formats for the CLI: images (PNG/JPEG, 8- and 16-bit), float images (PFM,
//! `.npy`), depth (PFM, 16-bit PNG, `.npy`) and flow (Middlebury `.flo`, `.npy`
//! H×W×2, x then y), and recordings of what the calibration worker takes
//! (`recording`). Every error names the file and what is wrong.

mod float;
pub mod poses;
pub mod recording;

pub use float::{read_npy_f32, read_pfm, write_npy, write_npy_rgb, write_pfm_rgb};

use crate::image::{Flow, Plane, Rgb};
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum IoError {
    #[error("{path}: {problem}")]
    Format { path: PathBuf, problem: String },
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
}

pub(crate) fn fmt_err(path: &Path, problem: impl Into<String>) -> IoError {
    IoError::Format { path: path.to_path_buf(), problem: problem.into() }
}

fn ext(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase()
}

/// Bit depth of a decoded image, so outputs can keep it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BitDepth {
    Eight,
    Sixteen,
    Float,
}

/// Load an RGB image as floats in [0, 1] (PNG/JPEG 8/16-bit; PFM/.npy as stored).
pub fn load_rgb(path: &Path) -> Result<(Rgb, BitDepth), IoError> {
    match ext(path).as_str() {
        "pfm" => {
            let (w, h, c, data) = read_pfm(path)?;
            Ok((rgb_from_interleaved(path, w, h, c, &data)?, BitDepth::Float))
        }
        "npy" => {
            let (shape, data) = read_npy_f32(path)?;
            let (h, w, c) = match shape.as_slice() {
                [h, w] => (*h, *w, 1),
                [h, w, c] => (*h, *w, *c),
                _ => return Err(fmt_err(path, format!("expected H×W or H×W×C array, got shape {shape:?}"))),
            };
            Ok((rgb_from_interleaved(path, w, h, c, &data)?, BitDepth::Float))
        }
        _ => {
            let img = image::open(path).map_err(|e| fmt_err(path, format!("cannot decode image: {e}")))?;
            let sixteen = matches!(
                img.color(),
                image::ColorType::L16 | image::ColorType::La16 | image::ColorType::Rgb16 | image::ColorType::Rgba16
            );
            let rgb = img.to_rgb32f();
            let (w, h) = (rgb.width() as usize, rgb.height() as usize);
            let data = rgb.into_raw();
            let out = rgb_from_interleaved(path, w, h, 3, &data)?;
            Ok((out, if sixteen { BitDepth::Sixteen } else { BitDepth::Eight }))
        }
    }
}

fn rgb_from_interleaved(path: &Path, w: usize, h: usize, c: usize, data: &[f32]) -> Result<Rgb, IoError> {
    if w == 0 || h == 0 {
        return Err(fmt_err(path, "image is empty (0 pixels)"));
    }
    if !(c == 1 || c == 3 || c == 4) || data.len() != w * h * c {
        return Err(fmt_err(path, format!("expected 1, 3 or 4 channels of {w}×{h}, got {} values", data.len())));
    }
    let mut out = Rgb::new(w, h, [0.0; 3]);
    for i in 0..w * h {
        for ch in 0..3 {
            out.channels[ch][i] = data[i * c + if c == 1 { 0 } else { ch }];
        }
    }
    Ok(out)
}

/// Write an RGB image. `.npy`/`.pfm`: float32, unclipped, unquantised. PNG: 16-bit
/// if `depth` is Sixteen (or Float), else 8-bit; JPEG: 8-bit. Integer formats clip to
/// [0, 1] and round.
pub fn save_rgb(path: &Path, img: &Rgb, depth: BitDepth) -> Result<(), IoError> {
    match ext(path).as_str() {
        "npy" => write_npy_rgb(path, img),
        "pfm" => write_pfm_rgb(path, img),
        e => {
            let (w, h) = (img.width as u32, img.height as u32);
            let n = img.len();
            let res = if e == "png" && depth != BitDepth::Eight {
                let mut buf = Vec::with_capacity(n * 3);
                for i in 0..n {
                    for c in 0..3 {
                        buf.push((img.channels[c][i].clamp(0.0, 1.0) * 65535.0).round() as u16);
                    }
                }
                image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, buf)
                    .ok_or_else(|| fmt_err(path, "buffer size mismatch"))?
                    .save(path)
            } else {
                let mut buf = Vec::with_capacity(n * 3);
                for i in 0..n {
                    for c in 0..3 {
                        buf.push((img.channels[c][i].clamp(0.0, 1.0) * 255.0).round() as u8);
                    }
                }
                image::RgbImage::from_raw(w, h, buf).ok_or_else(|| fmt_err(path, "buffer size mismatch"))?.save(path)
            };
            res.map_err(|e| fmt_err(path, format!("cannot write image: {e}")))
        }
    }
}

/// Load a depth map: PFM or `.npy` (float, as stored), or 16-bit PNG (value ×
/// `png_scale`; 0 = invalid). Non-finite / non-positive values mark invalid pixels.
pub fn load_depth(path: &Path, png_scale: f32) -> Result<Plane, IoError> {
    let plane = match ext(path).as_str() {
        "pfm" => {
            let (w, h, c, data) = read_pfm(path)?;
            if c != 1 {
                return Err(fmt_err(path, format!("depth PFM must have 1 channel, got {c}")));
            }
            Plane::from_vec(w, h, data)
        }
        "npy" => {
            let (shape, data) = read_npy_f32(path)?;
            match shape.as_slice() {
                [h, w] | [h, w, 1] => Plane::from_vec(*w, *h, data),
                _ => return Err(fmt_err(path, format!("depth .npy must be H×W, got shape {shape:?}"))),
            }
        }
        "png" => {
            let img = image::open(path).map_err(|e| fmt_err(path, format!("cannot decode depth PNG: {e}")))?;
            if !matches!(img.color(), image::ColorType::L16) {
                return Err(fmt_err(path, format!("depth PNG must be 16-bit grayscale, got {:?}", img.color())));
            }
            let l = img.to_luma16();
            let (w, h) = (l.width() as usize, l.height() as usize);
            let data = l.into_raw().into_iter().map(|v| if v == 0 { f32::NAN } else { v as f32 * png_scale }).collect();
            Plane::from_vec(w, h, data)
        }
        other => return Err(fmt_err(path, format!("unsupported depth format `.{other}` (use .pfm, .png or .npy)"))),
    };
    if plane.width == 0 || plane.height == 0 {
        return Err(fmt_err(path, "depth map is empty"));
    }
    Ok(plane)
}

/// Load flow in pixels per frame: Middlebury `.flo` or `.npy` H×W×2 (x then y).
pub fn load_flow(path: &Path) -> Result<Flow, IoError> {
    let (w, h, data) = match ext(path).as_str() {
        "flo" => {
            let bytes = std::fs::read(path).map_err(|source| IoError::Io { path: path.into(), source })?;
            if bytes.len() < 12 || f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) != 202021.25 {
                return Err(fmt_err(path, "not a Middlebury .flo file (bad magic 202021.25)"));
            }
            let rd = |o: usize| i32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
            let (w, h) = (rd(4), rd(8));
            if w <= 0 || h <= 0 || w > 1 << 16 || h > 1 << 16 {
                return Err(fmt_err(path, format!("invalid .flo size {w}×{h}")));
            }
            let (w, h) = (w as usize, h as usize);
            if bytes.len() != 12 + w * h * 8 {
                return Err(fmt_err(path, format!("truncated .flo: {} bytes for {w}×{h}", bytes.len())));
            }
            let data = bytes[12..].chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
            (w, h, data)
        }
        "npy" => {
            let (shape, data) = read_npy_f32(path)?;
            match shape.as_slice() {
                [h, w, 2] => (*w, *h, data),
                _ => return Err(fmt_err(path, format!("flow .npy must be H×W×2, got shape {shape:?}"))),
            }
        }
        other => return Err(fmt_err(path, format!("unsupported flow format `.{other}` (use .flo or .npy)"))),
    };
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(fmt_err(path, format!("non-finite flow at x={}, y={}", (i / 2) % w, (i / 2) / w)));
    }
    // Flow past the frame's diagonal (`model::flow_within_frame`) is refused by name.
    if let Some(i) = data.chunks_exact(2).position(|v| !crate::model::flow_within_frame(v[0], v[1], w, h)) {
        let (u, v) = (data[2 * i], data[2 * i + 1]);
        return Err(fmt_err(
            path,
            format!(
                "flow ({u}, {v}) px/frame at x={}, y={} is longer than the {w}×{h} frame's diagonal ({:.0} px): \
                 not a displacement within the frame (Middlebury marks unknown flow with values above 1e9)",
                i % w,
                i / w,
                ((w * w + h * h) as f32).sqrt()
            ),
        ));
    }
    let mut flow = Flow::uniform(w, h, 0.0, 0.0);
    for i in 0..w * h {
        flow.dx[i] = data[2 * i];
        flow.dy[i] = data[2 * i + 1];
    }
    Ok(flow)
}

/// Write flow as `.flo` (Middlebury) or `.npy`.
pub fn save_flow(path: &Path, flow: &Flow) -> Result<(), IoError> {
    let inter: Vec<f32> = flow.dx.iter().zip(&flow.dy).flat_map(|(&x, &y)| [x, y]).collect();
    match ext(path).as_str() {
        "npy" => float::write_npy(path, &[flow.height as u64, flow.width as u64, 2], &inter),
        "flo" => {
            let mut bytes = Vec::with_capacity(12 + inter.len() * 4);
            bytes.extend_from_slice(&202021.25f32.to_le_bytes());
            bytes.extend_from_slice(&(flow.width as i32).to_le_bytes());
            bytes.extend_from_slice(&(flow.height as i32).to_le_bytes());
            inter.iter().for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
            std::fs::write(path, bytes).map_err(|source| IoError::Io { path: path.into(), source })
        }
        other => Err(fmt_err(path, format!("unsupported flow format `.{other}`"))),
    }
}

/// Write a depth map as PFM or `.npy` (float32).
pub fn save_depth(path: &Path, depth: &Plane) -> Result<(), IoError> {
    match ext(path).as_str() {
        "npy" => float::write_npy(path, &[depth.height as u64, depth.width as u64], &depth.data),
        "pfm" => float::write_pfm(path, depth.width, depth.height, 1, &depth.data),
        other => Err(fmt_err(path, format!("unsupported depth output `.{other}` (use .pfm or .npy)"))),
    }
}
