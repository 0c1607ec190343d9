//! Colour, blind: the camera's white balance and exposure as a virtual surface
//! must take them (`model::Colour`), from the frame's own statistics.
//!
//! The illuminant as the camera renders it is estimated by the general grey-world
//! family (van de Weijer, Gevers & Gijsenij, "Edge-based color constancy", IEEE TIP
//! 2007): e_c ∝ (Σ |∂ⁿ f_c|^p)^(1/p) over the frame's linear-light values f (n = 0:
//! grey-world, p = 1, and shades of grey, Finlayson & Trezzi 2004; n = 1: grey-edge,
//! the gradient magnitude). Which member is measured on real photographs with a
//! colour checker's illuminant (`benches/colour.rs`, BENCHMARKS.md "White balance on
//! real photographs"): `ESTIMATOR` is the one that did best on the tuning split.
//! The exposure is the grey-world brightness: the frame's mean linear luma over
//! 0.18, the middle grey a camera's auto-exposure aims the mean at.
//!
//! Confidence: the frame is cut into 4×4 tiles and the estimate jackknifed over them
//! (how much one region decides it), in quadrature with `CONTENT_FLOOR_DEG`, the
//! error the estimator makes on real photographs whatever the tiles say (a scene's
//! own colours are not grey on average): a cast within twice that of neutral is
//! not modelled.

use crate::image::{Rgb, LUMA_WEIGHTS};
use crate::model::{Colour, Diagnostics, Status, MAX_COLOUR_GAIN};
use std::time::Instant;

/// A member of the general grey-world family: derivative order `order` (0 or 1),
/// Minkowski norm `p` (`f32::INFINITY`: the maximum, white patch).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GreyFamily {
    pub order: u8,
    pub p: f32,
}

impl GreyFamily {
    pub fn name(&self) -> String {
        let n = if self.order == 0 { "grey-world" } else { "grey-edge" };
        if self.p.is_infinite() {
            format!("{n}, max")
        } else {
            format!("{n}, p = {}", self.p)
        }
    }
}

/// The estimator `fit_colour` uses, chosen on the tuning split of real photographs
/// (`benches/colour.rs`, 7 180 photographs of 9 cameras): grey-edge with p = 2 had
/// the lowest mean (3.49°) and p90 (7.60°) of the 14 members tried, its median
/// (2.56°) within 0.03° of the lowest.
pub const ESTIMATOR: GreyFamily = GreyFamily { order: 1, p: 2.0 };
/// Longest side of the working frame (a box average in linear light of the
/// frame): grey statistics need no more, and it is the grey-edge's smoothing scale.
pub const WORK_SIDE_PX: usize = 256;
/// The error the estimator makes on real photographs that no tile statistic of one
/// frame shows (a scene's own colours are not grey on average): set so the stated
/// error (jackknife ⊕ this) holds 68% of the tuning split's errors, a one-sigma
/// error (`benches/colour.rs` bisects it: 3.69°). The errors are heavy-tailed: 2σ
/// then holds about 90%, not 95%.
pub const CONTENT_FLOOR_DEG: f64 = 3.7;
/// Tiles per side of the jackknife.
const TILES: usize = 4;
/// Least share of the working frame's pixels that must be unclipped and lit for
/// the illuminant to be identifiable.
const MIN_VALID_FRACTION: f64 = 0.05;
/// Largest one-sigma angular uncertainty (degrees) at which an illuminant is still
/// reported: beyond it the frame cannot tell (one colour fills it).
const MAX_STDERR_DEG: f64 = 8.0;
/// The middle grey a camera's auto-exposure puts a scene's mean at (linear light).
const MIDDLE_GREY: f64 = 0.18;
/// Encoded values at or above this are clipped: their colour is the clip's.
const CLIP_ENCODED: f32 = 0.98;
/// Linear luma below which a pixel carries no colour (black level and noise).
const DARK_LINEAR: f32 = 0.002;

/// A frame in linear light at working size, with the pixels whose colour can be
/// read (neither clipped nor black).
#[derive(Clone, Debug)]
pub struct LinearFrame {
    pub width: usize,
    pub height: usize,
    pub rgb: [Vec<f32>; 3],
    pub valid: Vec<bool>,
}

impl LinearFrame {
    /// Box-average `values(c, x, y)` (linear light) down so the longer side is at
    /// most `max_side`; a working pixel is valid when none of its source pixels is
    /// `clipped` and its luma is above the dark floor.
    pub fn downsample(
        width: usize,
        height: usize,
        max_side: usize,
        values: impl Fn(usize, usize, usize) -> f32,
        clipped: impl Fn(usize, usize) -> bool,
    ) -> Self {
        let k = width.max(height).div_ceil(max_side.max(1)).max(1);
        let (w, h) = (width / k, height / k);
        let mut rgb: [Vec<f32>; 3] = std::array::from_fn(|_| vec![0.0; w * h]);
        let mut bad = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                for sy in y * k..(y + 1) * k {
                    for sx in x * k..(x + 1) * k {
                        bad[i] |= clipped(sx, sy);
                        for (c, ch) in rgb.iter_mut().enumerate() {
                            ch[i] += values(c, sx, sy);
                        }
                    }
                }
            }
        }
        Self::from_sums(w, h, rgb, bad, k * k)
    }

    /// The working frame from per-box sums of `per_box` samples each and the boxes
    /// holding a clipped sample: the means, valid where unclipped and lit.
    fn from_sums(w: usize, h: usize, mut rgb: [Vec<f32>; 3], bad: Vec<bool>, per_box: usize) -> Self {
        let inv = 1.0 / per_box.max(1) as f32;
        let valid = (0..w * h)
            .map(|i| {
                for ch in rgb.iter_mut() {
                    ch[i] *= inv;
                }
                let luma: f32 = (0..3).map(|c| LUMA_WEIGHTS[c] * rgb[c][i]).sum();
                !bad[i] && luma.is_finite() && luma > DARK_LINEAR
            })
            .collect();
        Self { width: w, height: h, rgb, valid }
    }

    /// An encoded (sRGB) camera frame: decoded to linear light, clipped where any
    /// channel reaches `CLIP_ENCODED` (or is not finite). Each box is read on every
    /// other row and column (9 pixels of each 5×5 box at the headset's 1280×960):
    /// grey statistics need no more, and decoding every pixel cost 12 ms there. Row
    /// by row over the channel slices.
    pub fn from_encoded(image: &Rgb, max_side: usize) -> Self {
        let (width, height) = (image.width, image.height);
        let k = width.max(height).div_ceil(max_side.max(1)).max(1);
        let (w, h) = (width / k, height / k);
        let step = if k >= 2 { 2 } else { 1 };
        let lut = srgb_lut();
        let mut rgb: [Vec<f32>; 3] = std::array::from_fn(|_| vec![0.0; w * h]);
        let mut bad = vec![false; w * h];
        // Every box reads the same rows of its own (stepping within each box, not
        // across the frame: with an odd box side, a frame-wide step would give
        // alternate box rows 3 and 2 of their 5 rows).
        for y in (0..h).flat_map(|by| (by * k..(by + 1) * k).step_by(step)) {
            let out = (y / k) * w;
            for c in 0..3 {
                let row = &image.channels[c][y * width..y * width + w * k];
                let acc = &mut rgb[c][out..out + w];
                let flags = &mut bad[out..out + w];
                for ((chunk, a), f) in row.chunks_exact(k).zip(acc.iter_mut()).zip(flags.iter_mut()) {
                    let mut s = 0.0f32;
                    for &v in chunk.iter().step_by(step) {
                        // NaN fails the comparison: marked clipped, and its decoded
                        // value (NaN) makes the box's luma non-finite: not valid.
                        *f |= v.is_nan() || v >= CLIP_ENCODED;
                        s += srgb_decode_with(lut, v);
                    }
                    *a += s;
                }
            }
        }
        let per_box = k.div_ceil(step);
        Self::from_sums(w, h, rgb, bad, per_box * per_box)
    }
}

/// An illuminant estimate: linear RGB with luma 1, and its jackknife angular
/// standard error over the tiles (degrees; sampling only).
#[derive(Clone, Copy, Debug)]
pub struct IlluminantEstimate {
    pub rgb: [f64; 3],
    pub jackknife_deg: f64,
    pub valid_fraction: f64,
}

/// Angle between two RGB vectors in degrees (the colour-constancy error measure).
pub fn angular_error_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot: f64 = (0..3).map(|c| a[c] * b[c]).sum();
    let na = a.iter().map(|v| v * v).sum::<f64>().sqrt();
    let nb = b.iter().map(|v| v * v).sum::<f64>().sqrt();
    (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
}

fn unit_luma(v: [f64; 3]) -> Option<[f64; 3]> {
    let y: f64 = (0..3).map(|c| LUMA_WEIGHTS[c] as f64 * v[c]).sum();
    (y.is_finite() && y > 0.0 && v.iter().all(|c| c.is_finite() && *c > 0.0)).then(|| v.map(|c| c / y))
}

/// Per tile: Σ v^p per channel (or the max for p = ∞) and the count.
#[derive(Clone, Copy, Default)]
struct TileSums {
    s: [f64; 3],
    n: f64,
}

fn combine(tiles: &[TileSums], p: f32, skip: Option<usize>) -> Option<[f64; 3]> {
    let mut s = [0.0f64; 3];
    let mut n = 0.0;
    for (i, t) in tiles.iter().enumerate() {
        if Some(i) == skip {
            continue;
        }
        for c in 0..3 {
            s[c] = if p.is_infinite() { s[c].max(t.s[c]) } else { s[c] + t.s[c] };
        }
        n += t.n;
    }
    if n <= 0.0 {
        return None;
    }
    unit_luma(if p.is_infinite() { s } else { s.map(|v| (v / n).powf(1.0 / p as f64)) })
}

/// The illuminant of a linear frame by `est`; `None` where too little of it is
/// readable (`MIN_VALID_FRACTION`, fewer than 4 tiles with samples).
pub fn illuminant(frame: &LinearFrame, est: GreyFamily) -> Option<IlluminantEstimate> {
    let (w, h) = (frame.width, frame.height);
    if w < 2 * TILES || h < 2 * TILES {
        return None;
    }
    let mut tiles = vec![TileSums::default(); TILES * TILES];
    let mut used = 0usize;
    let p = est.p;
    let acc = |t: &mut TileSums, v: [f32; 3]| {
        for c in 0..3 {
            let v = v[c].max(0.0) as f64;
            // p = 1 and 2 multiplied out: `powf` per value was a third of the fit.
            t.s[c] = match p {
                _ if p.is_infinite() => t.s[c].max(v),
                1.0 => t.s[c] + v,
                2.0 => t.s[c] + v * v,
                _ => t.s[c] + v.powf(p as f64),
            };
        }
        t.n += 1.0;
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let v = if est.order == 0 {
                if !frame.valid[i] {
                    continue;
                }
                std::array::from_fn(|c| frame.rgb[c][i])
            } else {
                // Forward differences where the pixel and both neighbours are readable.
                if x + 1 >= w || y + 1 >= h || !frame.valid[i] || !frame.valid[i + 1] || !frame.valid[i + w] {
                    continue;
                }
                std::array::from_fn(|c| {
                    let ch = &frame.rgb[c];
                    (ch[i + 1] - ch[i]).hypot(ch[i + w] - ch[i])
                })
            };
            let t = (y * TILES / h) * TILES + x * TILES / w;
            acc(&mut tiles[t], v);
            used += 1;
        }
    }
    let valid_fraction = used as f64 / (w * h) as f64;
    let occupied: Vec<usize> = (0..tiles.len()).filter(|&i| tiles[i].n > 0.0).collect();
    if valid_fraction < MIN_VALID_FRACTION || occupied.len() < 4 {
        return None;
    }
    let rgb = combine(&tiles, p, None)?;
    // Jackknife over the occupied tiles: var = (m − 1)/m · Σ θᵢ².
    let m = occupied.len() as f64;
    let mut sum_sq = 0.0;
    for &i in &occupied {
        let e = combine(&tiles, p, Some(i))?;
        sum_sq += angular_error_deg(e, rgb).powi(2);
    }
    Some(IlluminantEstimate { rgb, jackknife_deg: ((m - 1.0) / m * sum_sq).sqrt(), valid_fraction })
}

/// The grey-world brightness: the mean linear luma of the working frame (every
/// box counted, clipped ones at their clipped value: the box average is linear, so
/// this is the frame's own mean) over `MIDDLE_GREY`, and its jackknife relative
/// standard error over the 4×4 tiles.
fn exposure(frame: &LinearFrame) -> Option<(f64, f64)> {
    let (w, h) = (frame.width, frame.height);
    if w < TILES || h < TILES {
        return None;
    }
    let mut sums = vec![(0.0f64, 0.0f64); TILES * TILES];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let l: f32 = (0..3).map(|c| LUMA_WEIGHTS[c] * frame.rgb[c][i]).sum();
            if l.is_finite() {
                let t = &mut sums[(y * TILES / h) * TILES + x * TILES / w];
                t.0 += l as f64;
                t.1 += 1.0;
            }
        }
    }
    let (s, n) = sums.iter().fold((0.0, 0.0), |a, t| (a.0 + t.0, a.1 + t.1));
    let mean = s / n;
    if !(mean.is_finite() && mean > 0.0) || sums.iter().any(|t| t.1 == 0.0) {
        return None;
    }
    let m = sums.len() as f64;
    let sum_sq: f64 = sums.iter().map(|t| (((s - t.0) / (n - t.1)) / mean - 1.0).powi(2)).sum();
    Some((mean / MIDDLE_GREY, ((m - 1.0) / m * sum_sq).sqrt()))
}

/// Intervals of the sRGB decoding table (`srgb_decode_with`).
const LUT_INTERVALS: usize = 4096;

/// The sRGB decoding table: every pixel of the frame is decoded, and `powf` per
/// value would cost more than the rest of the fit.
pub(crate) fn srgb_lut() -> &'static [f32] {
    static LUT: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    LUT.get_or_init(|| {
        (0..=LUT_INTERVALS).map(|i| crate::image::yuv::srgb_to_linear(i as f32 / LUT_INTERVALS as f32)).collect()
    })
}

/// sRGB decoding by table, linear between its 4097 nodes (≤ 2e-5 off the curve,
/// below an 8-bit input's step); values outside [0, 1] clamp, NaN stays NaN.
#[inline]
pub(crate) fn srgb_decode_with(lut: &[f32], v: f32) -> f32 {
    if v.is_nan() {
        return v;
    }
    let t = v.clamp(0.0, 1.0) * LUT_INTERVALS as f32;
    let i = (t as usize).min(LUT_INTERVALS - 1);
    lut[i] + (lut[i + 1] - lut[i]) * (t - i as f32)
}

/// Fit the colour term of one encoded camera frame (the fast tier; the frame alone).
pub fn fit_colour(image: &Rgb) -> Colour {
    let started = Instant::now();
    let diag = |status, reason: String, stderr: Option<f64>, samples: u64| Diagnostics {
        status,
        reason,
        method: "fast".into(),
        residual_before: None,
        residual_after: None,
        samples_used: samples,
        fit_time_s: started.elapsed().as_secs_f64(),
        stderr,
        stages_s: Default::default(),
    };
    let frame = LinearFrame::from_encoded(image, WORK_SIDE_PX);
    let est = illuminant(&frame, ESTIMATOR);
    let exp = exposure(&frame);
    let samples = frame.valid.iter().filter(|v| **v).count() as u64;
    let (Some(est), Some((e, e_se))) = (est, exp) else {
        return Colour::absent(diag(
            Status::NotIdentifiable,
            "too little of the frame is lit and unclipped to read the illuminant".into(),
            None,
            samples,
        ));
    };
    let se = est.jackknife_deg.hypot(CONTENT_FLOOR_DEG);
    if se > MAX_STDERR_DEG {
        return Colour::absent(diag(
            Status::NotIdentifiable,
            format!("illuminant ± {se:.1}° (over {MAX_STDERR_DEG}°): a few regions decide it"),
            Some(se),
            samples,
        ));
    }
    let gain_range = (1.0 / MAX_COLOUR_GAIN as f64)..=(MAX_COLOUR_GAIN as f64);
    let cast_deg = angular_error_deg(est.rgb, [1.0; 3]);
    let cast = cast_deg > 2.0 * se;
    let bright = e.ln().abs() > 2.0 * e_se;
    let in_range = est.rgb.iter().all(|v| gain_range.contains(v)) && gain_range.contains(&e);
    if !in_range {
        return Colour::absent(diag(
            Status::NotIdentifiable,
            format!("illuminant {:?} × exposure {e:.3} out of the model's range", est.rgb),
            Some(se),
            samples,
        ));
    }
    let illuminant = if cast { est.rgb.map(|v| v as f32) } else { [1.0; 3] };
    let reason = format!(
        "{}: cast {cast_deg:.1}° ± {se:.1}° ({}), exposure {e:.3} ± {:.0}% ({})",
        ESTIMATOR.name(),
        if cast { "modelled" } else { "within 2σ of neutral: not modelled" },
        100.0 * e_se,
        if bright { "modelled" } else { "within 2σ of 1: not modelled" },
    );
    if !cast && !bright {
        let mut c = Colour::absent(diag(Status::Absent, reason, Some(se), samples));
        c.illuminant = Some([1.0; 3]);
        c.exposure = Some(1.0);
        return c;
    }
    Colour {
        present: true,
        illuminant: Some(illuminant),
        exposure: Some(if bright { e as f32 } else { 1.0 }),
        diagnostics: diag(Status::Present, reason, Some(se), samples),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> Rgb {
        let mut img = Rgb::new(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                let v = f(x, y);
                for c in 0..3 {
                    img.channels[c][y * w + x] = v[c];
                }
            }
        }
        img
    }

    fn encode(v: f32) -> f32 {
        if v <= 0.0031308 {
            v * 12.92
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        }
    }

    /// A grey scene of varied reflectances under a known cast: every member of the
    /// family reads the cast itself (the scene's mean is grey), within 0.5° (the
    /// 8-bit-free float frame's only error is the working frame's box average).
    #[test]
    fn a_cast_over_a_grey_scene_is_read_by_every_member() {
        let cast = [1.3f32, 1.0, 0.6];
        let img = frame(320, 240, |x, y| {
            let r = 0.05 + 0.3 * (((x / 7) * 31 + (y / 5) * 17) % 13) as f32 / 13.0;
            cast.map(|g| encode(r * g))
        });
        let lin = LinearFrame::from_encoded(&img, WORK_SIDE_PX);
        for est in [
            GreyFamily { order: 0, p: 1.0 },
            GreyFamily { order: 0, p: 6.0 },
            GreyFamily { order: 1, p: 1.0 },
            GreyFamily { order: 1, p: 6.0 },
        ] {
            let e = illuminant(&lin, est).expect("identifiable");
            let err = angular_error_deg(e.rgb, cast.map(|v| v as f64));
            assert!(err < 0.5, "{}: {err:.2}°", est.name());
        }
        let c = fit_colour(&img);
        assert!(c.present, "{}", c.diagnostics.reason);
        assert_eq!(c.diagnostics.status, Status::Present);
    }

    /// One flat colour filling the frame: its colour and the light's cannot be told
    /// apart and no tile says otherwise; it must not read as a confident cast...
    /// and a frame that is all clipped or all black is not identifiable.
    #[test]
    fn clipped_or_black_frames_are_not_identifiable() {
        for v in [[1.0f32; 3], [0.0; 3], [1.0, 0.99, 0.2]] {
            let c = fit_colour(&frame(64, 48, |_, _| v));
            assert_eq!(c.diagnostics.status, Status::NotIdentifiable, "{v:?}: {}", c.diagnostics.reason);
            assert!(!c.present);
            assert_eq!(c.gains_or_one(), [1.0; 3]);
        }
    }

    /// A neutral scene at middle grey: nothing to model, reported absent (not
    /// unidentifiable), with the identity it measured.
    #[test]
    fn a_neutral_mid_grey_scene_is_absent() {
        let img = frame(320, 240, |x, y| {
            let r = 0.18 * (0.6 + 0.8 * (((x / 9) * 7 + (y / 11) * 13) % 5) as f32 / 4.0);
            [encode(r); 3]
        });
        let c = fit_colour(&img);
        assert_eq!(c.diagnostics.status, Status::Absent, "{}", c.diagnostics.reason);
        assert_eq!(c.gains_or_one(), [1.0; 3]);
    }

    /// At the headset's 1280×960 (boxes of 5×5, each read on a 3×3 subgrid) a
    /// uniform grey reads its own brightness exactly (to the decoding table's 2e-5)
    /// and a cast over a textured grey scene within 0.5°, as at small sizes: every
    /// box reads the same share of its pixels.
    #[test]
    fn the_headset_frame_size_reads_like_a_small_one() {
        let v = 0.5f32;
        let flat = frame(1280, 960, |_, _| [v; 3]);
        let lin = LinearFrame::from_encoded(&flat, WORK_SIDE_PX);
        let expect = crate::image::yuv::srgb_to_linear(v);
        for c in 0..3 {
            for (i, x) in lin.rgb[c].iter().enumerate() {
                assert!((x - expect).abs() < 1e-4, "box {i} channel {c}: {x} for {expect}");
            }
        }
        let cast = [0.8f32, 1.05, 1.3];
        let img = frame(1280, 960, |x, y| {
            let r = 0.05 + 0.3 * (((x / 23) * 31 + (y / 17) * 17) % 13) as f32 / 13.0;
            cast.map(|g| encode(r * g))
        });
        let e = illuminant(&LinearFrame::from_encoded(&img, WORK_SIDE_PX), ESTIMATOR).expect("identifiable");
        let err = angular_error_deg(e.rgb, cast.map(|v| v as f64));
        assert!(err < 0.5, "{err:.2}°");
    }

    /// A non-finite frame never yields a non-finite or out-of-range gain.
    #[test]
    fn non_finite_pixels_never_reach_the_gains() {
        let img = frame(64, 48, |x, _| if x % 2 == 0 { [f32::NAN, 0.5, f32::INFINITY] } else { [0.4, 0.5, 0.3] });
        let c = fit_colour(&img);
        let mut m = crate::model::CameraModel::empty(64, 48);
        m.colour = c;
        m.validate().expect("valid");
        assert!(m.colour.gains_or_one().iter().all(|g| g.is_finite()));
    }
}
