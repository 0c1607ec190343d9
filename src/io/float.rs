//! Float formats: PFM (Portable Float Map; bottom-to-top rows, sign of the scale
//! gives endianness) and NumPy `.npy` through the `npyz` crate.

use super::{fmt_err, IoError};
use crate::image::Rgb;
use npyz::WriterBuilder;
use std::path::Path;

/// Read a PFM: (width, height, channels, row-major top-to-bottom interleaved data).
pub fn read_pfm(path: &Path) -> Result<(usize, usize, usize, Vec<f32>), IoError> {
    let bytes = std::fs::read(path).map_err(|source| IoError::Io { path: path.into(), source })?;
    // Header: three whitespace-separated tokens after the magic, then one byte.
    let mut tokens = vec![];
    let mut pos = 0;
    while tokens.len() < 4 && pos < bytes.len() {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..pos]).to_string());
    }
    pos += 1; // the single whitespace byte before the data
    if tokens.len() < 4 {
        return Err(fmt_err(path, "truncated PFM header"));
    }
    let channels = match tokens[0].as_str() {
        "PF" => 3,
        "Pf" => 1,
        m => return Err(fmt_err(path, format!("not a PFM file (magic `{m}`)"))),
    };
    let parse = |t: &str, what: &str| t.parse::<f64>().map_err(|_| fmt_err(path, format!("bad PFM {what} `{t}`")));
    let (w, h, scale) = (parse(&tokens[1], "width")?, parse(&tokens[2], "height")?, parse(&tokens[3], "scale")?);
    if w < 1.0 || h < 1.0 || w > 65536.0 || h > 65536.0 || scale == 0.0 || !scale.is_finite() {
        return Err(fmt_err(path, format!("invalid PFM header {w}×{h} scale {scale}")));
    }
    let (w, h) = (w as usize, h as usize);
    let n = w * h * channels;
    if bytes.len() < pos + n * 4 {
        return Err(fmt_err(path, format!("truncated PFM data: need {} bytes, have {}", n * 4, bytes.len() - pos)));
    }
    let little = scale < 0.0;
    let mut data = vec![0.0f32; n];
    for row in 0..h {
        // PFM rows run bottom to top.
        let src_row = h - 1 - row;
        for i in 0..w * channels {
            let o = pos + (src_row * w * channels + i) * 4;
            let b = [bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]];
            data[row * w * channels + i] = if little { f32::from_le_bytes(b) } else { f32::from_be_bytes(b) };
        }
    }
    Ok((w, h, channels, data))
}

pub fn write_pfm(path: &Path, w: usize, h: usize, channels: usize, data: &[f32]) -> Result<(), IoError> {
    let mut out = format!("{}\n{} {}\n-1.0\n", if channels == 3 { "PF" } else { "Pf" }, w, h).into_bytes();
    for row in (0..h).rev() {
        for v in &data[row * w * channels..(row + 1) * w * channels] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(path, out).map_err(|source| IoError::Io { path: path.into(), source })
}

pub fn write_pfm_rgb(path: &Path, img: &Rgb) -> Result<(), IoError> {
    write_pfm(path, img.width, img.height, 3, &interleave(img))
}

fn interleave(img: &Rgb) -> Vec<f32> {
    (0..img.len()).flat_map(|i| [img.channels[0][i], img.channels[1][i], img.channels[2][i]]).collect()
}

/// Read a `.npy` of f32 or f64 (C order) as f32: (shape, data).
pub fn read_npy_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>), IoError> {
    let bytes = std::fs::read(path).map_err(|source| IoError::Io { path: path.into(), source })?;
    let npy = npyz::NpyFile::new(&bytes[..]).map_err(|e| fmt_err(path, format!("not a .npy file: {e}")))?;
    if npy.order() != npyz::Order::C {
        return Err(fmt_err(path, "Fortran-order .npy is not supported (save with C order)"));
    }
    let shape: Vec<usize> = npy.shape().iter().map(|&d| d as usize).collect();
    let dtype = npy.dtype();
    let data: Vec<f32> = match dtype.descr().trim_matches('\'') {
        "<f4" => npy.into_vec::<f32>().map_err(|e| fmt_err(path, e.to_string()))?,
        "<f8" => {
            npy.into_vec::<f64>().map_err(|e| fmt_err(path, e.to_string()))?.into_iter().map(|v| v as f32).collect()
        }
        d => return Err(fmt_err(path, format!("unsupported .npy dtype {d} (use float32 or float64)"))),
    };
    Ok((shape, data))
}

pub fn write_npy(path: &Path, shape: &[u64], data: &[f32]) -> Result<(), IoError> {
    let mut buf = vec![];
    {
        let mut w = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(shape)
            .writer(&mut buf)
            .begin_nd()
            .map_err(|e| fmt_err(path, e.to_string()))?;
        w.extend(data.iter().copied()).map_err(|e| fmt_err(path, e.to_string()))?;
        w.finish().map_err(|e| fmt_err(path, e.to_string()))?;
    }
    std::fs::write(path, buf).map_err(|source| IoError::Io { path: path.into(), source })
}

pub fn write_npy_rgb(path: &Path, img: &Rgb) -> Result<(), IoError> {
    write_npy(path, &[img.height as u64, img.width as u64, 3], &interleave(img))
}
