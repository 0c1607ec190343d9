//! Camera frames as Android delivers them (AImageReader, `AIMAGE_FORMAT_YUV_420_888`):
//! a full-resolution Y plane and half-resolution U (Cb) and V (Cr) planes, each with
//! its own row stride and pixel stride (1: planar I420; 2: interleaved NV12/NV21
//! views of one buffer), converted to R'G'B' (the camera's encoded values, what the
//! fits and the composite work in) or to linear light.
//!
//! Matrices from ITU-R BT.601 and BT.709 (the dataspace says which; Camera2's
//! YUV_420_888 output defaults to JFIF, BT.601 full range, what the app assumes); range "limited"
//! (Y 16–235, C 16–240, 8-bit) or "full" (0–255). Chroma is upsampled by
//! replication (each 2×2 block shares its sample, as the 4:2:0 siting of the
//! camera pipeline puts it: the co-sited/centred difference is under half a pixel
//! of chroma, below what the fits resolve).

use super::Rgb;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum YuvMatrix {
    Bt601,
    Bt709,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum YuvRange {
    /// Y 16–235, Cb/Cr 16–240 (8-bit "video" range).
    Limited,
    /// 0–255 ("JPEG" range).
    Full,
}

/// One plane of an AImage: its bytes, the stride between rows and between
/// successive samples of a row (bytes).
#[derive(Clone, Copy, Debug)]
pub struct YuvPlane<'a> {
    pub data: &'a [u8],
    pub row_stride: usize,
    pub pixel_stride: usize,
}

/// A YUV_420_888 frame (`width`, `height` of the Y plane; U and V are ⌈w/2⌉ × ⌈h/2⌉).
#[derive(Clone, Copy, Debug)]
pub struct Yuv420<'a> {
    pub width: usize,
    pub height: usize,
    pub y: YuvPlane<'a>,
    pub u: YuvPlane<'a>,
    pub v: YuvPlane<'a>,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum YuvError {
    #[error("YUV frame {width}×{height}: a side is 0")]
    Empty { width: usize, height: usize },
    #[error("YUV plane {plane}: {len} bytes cannot hold {rows} rows of {cols} samples (row stride {row_stride}, pixel stride {pixel_stride})")]
    Short { plane: char, len: usize, rows: usize, cols: usize, row_stride: usize, pixel_stride: usize },
}

/// Kr and Kb of the matrix (luma weights of R and B).
fn weights(m: YuvMatrix) -> (f32, f32) {
    match m {
        YuvMatrix::Bt601 => (0.299, 0.114),
        YuvMatrix::Bt709 => (0.2126, 0.0722),
    }
}

/// R'G'B' (each in [0, 1] for legal input) of one 8-bit Y'CbCr sample.
pub fn yuv_to_rgb_pixel(y: u8, cb: u8, cr: u8, matrix: YuvMatrix, range: YuvRange) -> [f32; 3] {
    let (kr, kb) = weights(matrix);
    let kg = 1.0 - kr - kb;
    let (y, cb, cr) = (y as f32, cb as f32, cr as f32);
    // Normalise: Y' to [0, 1], Pb/Pr to [−½, ½] (BT.601/709 §2/§3 quantisation).
    let (yn, pb, pr) = match range {
        YuvRange::Limited => ((y - 16.0) / 219.0, (cb - 128.0) / 224.0, (cr - 128.0) / 224.0),
        YuvRange::Full => (y / 255.0, (cb - 128.0) / 255.0, (cr - 128.0) / 255.0),
    };
    let r = yn + 2.0 * (1.0 - kr) * pr;
    let b = yn + 2.0 * (1.0 - kb) * pb;
    let g = (yn - kr * r - kb * b) / kg;
    [r, g, b]
}

/// The sRGB / BT.709-display decoding to linear light (IEC 61966-2-1).
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB encoding of linear light (IEC 61966-2-1), `srgb_to_linear`'s inverse.
pub fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

fn check(plane: char, p: &YuvPlane<'_>, cols: usize, rows: usize) -> Result<(), YuvError> {
    // The last row need not be padded to the full row stride (Android's buffers
    // often end right after the last sample).
    let need = (rows - 1) * p.row_stride + (cols - 1) * p.pixel_stride + 1;
    if p.data.len() < need || p.pixel_stride == 0 || p.row_stride < (cols - 1) * p.pixel_stride + 1 {
        return Err(YuvError::Short {
            plane,
            len: p.data.len(),
            rows,
            cols,
            row_stride: p.row_stride,
            pixel_stride: p.pixel_stride,
        });
    }
    Ok(())
}

/// Convert a frame to R'G'B' (`linear = false`: the encoded values, clamped to
/// [0, 1]) or to linear light (`linear = true`).
pub fn yuv420_to_rgb(f: &Yuv420<'_>, matrix: YuvMatrix, range: YuvRange, linear: bool) -> Result<Rgb, YuvError> {
    let (w, h) = (f.width, f.height);
    if w == 0 || h == 0 {
        return Err(YuvError::Empty { width: w, height: h });
    }
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    check('Y', &f.y, w, h)?;
    check('U', &f.u, cw, ch)?;
    check('V', &f.v, cw, ch)?;
    let mut out = Rgb::new(w, h, [0.0; 3]);
    for y in 0..h {
        for x in 0..w {
            let luma = f.y.data[y * f.y.row_stride + x * f.y.pixel_stride];
            let (cx, cy) = (x / 2, y / 2);
            let cb = f.u.data[cy * f.u.row_stride + cx * f.u.pixel_stride];
            let cr = f.v.data[cy * f.v.row_stride + cx * f.v.pixel_stride];
            let rgb = yuv_to_rgb_pixel(luma, cb, cr, matrix, range);
            for c in 0..3 {
                let v = rgb[c].clamp(0.0, 1.0);
                out.channels[c][y * w + x] = if linear { srgb_to_linear(v) } else { v };
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The forward transform of the standards (R'G'B' → 8-bit Y'CbCr), written
    /// independently of the inverse under test.
    fn rgb_to_yuv(rgb: [f32; 3], m: YuvMatrix, r: YuvRange) -> [u8; 3] {
        let (kr, kb) = match m {
            YuvMatrix::Bt601 => (0.299, 0.114),
            YuvMatrix::Bt709 => (0.2126, 0.0722),
        };
        let y = kr * rgb[0] + (1.0 - kr - kb) * rgb[1] + kb * rgb[2];
        let pb = 0.5 * (rgb[2] - y) / (1.0 - kb);
        let pr = 0.5 * (rgb[0] - y) / (1.0 - kr);
        let q = |v: f32| v.round().clamp(0.0, 255.0) as u8;
        match r {
            YuvRange::Limited => [q(16.0 + 219.0 * y), q(128.0 + 224.0 * pb), q(128.0 + 224.0 * pr)],
            YuvRange::Full => [q(255.0 * y), q(128.0 + 255.0 * pb), q(128.0 + 255.0 * pr)],
        }
    }

    /// Round trip over a grid of colours: the inverse returns the colour within
    /// the 8-bit quantisation of the forward transform (chroma steps of 1/224 map to
    /// ≤ 1.86/224 in R or B: tolerance 0.012).
    #[test]
    fn matches_the_standards_forward_transform() {
        for m in [YuvMatrix::Bt601, YuvMatrix::Bt709] {
            for r in [YuvRange::Limited, YuvRange::Full] {
                for i in 0..6 {
                    for j in 0..6 {
                        for k in 0..6 {
                            let c = [i as f32 / 5.0, j as f32 / 5.0, k as f32 / 5.0];
                            let [y, cb, cr] = rgb_to_yuv(c, m, r);
                            let back = yuv_to_rgb_pixel(y, cb, cr, m, r);
                            for ch in 0..3 {
                                assert!((back[ch] - c[ch]).abs() < 0.012, "{m:?} {r:?} {c:?} -> {back:?}");
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn reference_points() {
        // Limited-range black, white and BT.709 red (ITU-R BT.709 Table 4 codes).
        assert_eq!(yuv_to_rgb_pixel(16, 128, 128, YuvMatrix::Bt709, YuvRange::Limited), [0.0, 0.0, 0.0]);
        let white = yuv_to_rgb_pixel(235, 128, 128, YuvMatrix::Bt709, YuvRange::Limited);
        assert!(white.iter().all(|v| (v - 1.0).abs() < 1e-6));
        let red = yuv_to_rgb_pixel(63, 102, 240, YuvMatrix::Bt709, YuvRange::Limited);
        assert!((red[0] - 1.0).abs() < 0.01 && red[1].abs() < 0.01 && red[2].abs() < 0.01, "{red:?}");
        // The two matrices differ on saturated colours.
        let a = yuv_to_rgb_pixel(100, 90, 200, YuvMatrix::Bt601, YuvRange::Full);
        let b = yuv_to_rgb_pixel(100, 90, 200, YuvMatrix::Bt709, YuvRange::Full);
        assert!((a[1] - b[1]).abs() > 0.02);
    }

    /// The same frame as planar I420 and as interleaved NV12 (pixel stride 2, row
    /// padding, an odd size) converts to the same picture.
    #[test]
    fn planar_and_interleaved_layouts_agree() {
        let (w, h) = (7usize, 5usize);
        let (cw, ch) = (4usize, 3usize);
        let ys: Vec<u8> = (0..w * h).map(|i| (16 + (i * 37) % 200) as u8).collect();
        let us: Vec<u8> = (0..cw * ch).map(|i| (60 + (i * 53) % 140) as u8).collect();
        let vs: Vec<u8> = (0..cw * ch).map(|i| (70 + (i * 29) % 130) as u8).collect();
        let planar = Yuv420 {
            width: w,
            height: h,
            y: YuvPlane { data: &ys, row_stride: w, pixel_stride: 1 },
            u: YuvPlane { data: &us, row_stride: cw, pixel_stride: 1 },
            v: YuvPlane { data: &vs, row_stride: cw, pixel_stride: 1 },
        };
        // NV12 with 16-byte rows: Y padded; UV interleaved (U at 0, V at 1).
        let stride = 16;
        let mut y_pad = vec![0u8; stride * h];
        for r in 0..h {
            y_pad[r * stride..r * stride + w].copy_from_slice(&ys[r * w..(r + 1) * w]);
        }
        let mut uv = vec![0u8; stride * ch];
        for r in 0..ch {
            for c in 0..cw {
                uv[r * stride + 2 * c] = us[r * cw + c];
                uv[r * stride + 2 * c + 1] = vs[r * cw + c];
            }
        }
        let nv12 = Yuv420 {
            width: w,
            height: h,
            y: YuvPlane { data: &y_pad, row_stride: stride, pixel_stride: 1 },
            u: YuvPlane { data: &uv, row_stride: stride, pixel_stride: 2 },
            v: YuvPlane { data: &uv[1..], row_stride: stride, pixel_stride: 2 },
        };
        let a = yuv420_to_rgb(&planar, YuvMatrix::Bt709, YuvRange::Limited, false).unwrap();
        let b = yuv420_to_rgb(&nv12, YuvMatrix::Bt709, YuvRange::Limited, false).unwrap();
        assert_eq!(a, b);
        // Linear output is the sRGB decoding of the encoded one.
        let lin = yuv420_to_rgb(&planar, YuvMatrix::Bt709, YuvRange::Limited, true).unwrap();
        for c in 0..3 {
            for i in 0..w * h {
                assert!((lin.channels[c][i] - srgb_to_linear(a.channels[c][i])).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn short_or_empty_planes_are_errors() {
        let ys = vec![0u8; 10];
        let p = YuvPlane { data: &ys, row_stride: 4, pixel_stride: 1 };
        let f = Yuv420 { width: 4, height: 4, y: p, u: p, v: p };
        assert!(matches!(
            yuv420_to_rgb(&f, YuvMatrix::Bt709, YuvRange::Full, false),
            Err(YuvError::Short { plane: 'Y', .. })
        ));
        let e = Yuv420 { width: 0, height: 4, y: p, u: p, v: p };
        assert_eq!(
            yuv420_to_rgb(&e, YuvMatrix::Bt709, YuvRange::Full, false),
            Err(YuvError::Empty { width: 0, height: 4 })
        );
        let z = YuvPlane { data: &ys, row_stride: 4, pixel_stride: 0 };
        let f = Yuv420 { width: 2, height: 2, y: p, u: z, v: p };
        assert!(yuv420_to_rgb(&f, YuvMatrix::Bt709, YuvRange::Full, false).is_err());
    }
}
