//! Noise estimation (paper supplement, "Fitting"), accurate and blind.
//!
//! Accurate: N = I − I_noNoise; Laplacian pyramid of N per channel (4 band-pass
//! levels + low-pass); local variance with the 9×9 Gaussian window B (σ = 4 px at
//! level 0, halved per level) on a stride grid (halved per level); least squares
//! from the denoised luma at that level to the local variance.
//!
//! Departures from the paper, each for accuracy:
//! * local variance is B(X²), not B(X²) − B(X)²: noise bands are zero-mean, so
//!   E[B(X²)] = σ² exactly, while subtracting B(X)² biases it low by a factor that
//!   depends on the band's autocorrelation (worst at level 3, where B spans ~3
//!   samples);
//! * regression is on variance, not std: E[√v̂] < σ (Jensen), E[v̂] = σ². The
//!   paper's linear-std form is fitted by Gauss–Newton on variance, the affine
//!   variance form (Poisson–Gaussian) by least squares, both weighted by 1/σ⁴ (the
//!   sampling variance of a variance estimate), so dark lumas are fitted as well as
//!   bright ones; the form with the higher likelihood is kept;
//! * the low-pass residual is fitted like a band (the paper drops it);
//! * the regressor is the window-averaged luma B(Y), matching the pooled variance;
//! * samples whose footprint touches a clipped pixel (`clip_mask`: a repeated
//!   extreme value in any channel of I) are excluded; the luma range of the used
//!   samples is recorded.
//!
//! Blind (`fit_fast`, in `blind.rs`): every band-pass level measured on I alone, at
//! its flattest samples per luma bin (flatness judged two levels coarser); a
//! confidence per luma bin and codec blocking (`blocking.rs`) are reported; the
//! low-pass is not identifiable from one frame (it is the image itself) and is left
//! out. Both tiers leave out samples on clipped pixels (`clip.rs`).
//!
//! Present when the level-0 std at mid-range luma exceeds 3 standard errors and
//! 1e-4 (0.026/255: far below visibility).

use super::percentile;
use crate::image::{laplacian_pyramid, IntegralImage, Plane, Rgb, LUMA_WEIGHTS};
use crate::model::{Diagnostics, Noise, NoiseForm, NoiseIntensity, NoiseLevel, Status, NOISE_LEVELS};
use rayon::prelude::*;
use std::time::Instant;

mod bands;
mod blind;
mod blocking;
pub use blocking::compression_blocking;
mod clip;
mod measured;
mod regress;
mod sources;
pub(super) use blind::fit_fast_with_luma;
pub use blind::{
    fit_fast, DEFAULT_FAST_SAMPLES_PER_LEVEL, FAST_ALONE, FAST_WITH_NEIGHBOUR, MIN_FAST_SAMPLES_PER_LEVEL,
};
use clip::*;
use regress::{fit_linear_std, neg2_log_likelihood, ols, precision_weights};

/// Largest sample stride at level 0, halved per level. Measured at 512²
/// (BENCHMARKS.md): the paper's 32 gives a 0.4% median but 1.9% worst-luma error of
/// synth's std; 16 keeps the worst case at 0.8% for 3 ms more; 8 and 4 buy nothing.
pub const DEFAULT_STRIDE_PX: usize = 16;

/// The stride actually used: at most `max_stride`, and small enough that a frame
/// keeps ≥ ~1000 level-0 samples (√(pixels/1000), at least 4). At 512² and above
/// that is `max_stride`; a 451×300 frame gets 11 (its error at 16 px: 1.3%, at
/// 11 px: see tests/validation.rs).
pub fn effective_stride(pixels: usize, max_stride: usize) -> usize {
    (((pixels as f64 / 1000.0).sqrt()) as usize).clamp(4.min(max_stride), max_stride.max(1))
}

/// Regression data of one level: window moments of luma B(Y), B(Y²), per-channel
/// local variance, optional per-sample weights.
#[derive(Clone, Default)]
struct LevelPoints {
    y: Vec<f32>,
    y2: Vec<f32>,
    /// Per channel, window moments of that channel's own value (B(v_c), B(v_c²)),
    /// for `NoiseIntensity::Channel`; `None` where only luma was collected.
    own: Option<[(Vec<f32>, Vec<f32>); 3]>,
    var: [Vec<f32>; 3],
    weights: Option<Vec<f32>>,
}

impl LevelPoints {
    /// The regressor moments of channel c under `intensity`.
    fn regressor(&self, intensity: NoiseIntensity, c: usize) -> Option<(&[f32], &[f32])> {
        match (intensity, &self.own) {
            (NoiseIntensity::Luma, _) => Some((&self.y, &self.y2)),
            (NoiseIntensity::Channel, Some(own)) => Some((&own[c].0, &own[c].1)),
            (NoiseIntensity::Channel, None) => None,
        }
    }
}

/// The fit of one intensity variable: chosen form, per-level maps, per-level
/// per-channel OLS covariance, mean relative residual, −2·log-likelihood.
struct LevelFit {
    form: NoiseForm,
    intensity: NoiseIntensity,
    levels: Vec<NoiseLevel>,
    covs: Vec<[[[f64; 2]; 2]; 3]>,
    rel_res: f64,
    nll: f64,
}

/// Samples behind the noise plot: per level (4 = low-pass), luma and per-channel std.
#[derive(Clone, Debug, Default)]
pub struct NoisePlotData {
    pub levels: Vec<(Vec<f32>, [Vec<f32>; 3])>,
}

/// 9×9 window weights with σ = 4/2^l, normalised: the outer product of
/// `window_1d(level)` (a separable Gaussian, so whole-plane window sums can use
/// `blur_separable` with the 1-D factor and agree with these per-sample sums).
fn window(level: usize) -> [[f32; 9]; 9] {
    let w1 = window_1d(level);
    std::array::from_fn(|j| std::array::from_fn(|i| w1[j] * w1[i]))
}

/// The normalised 1-D Gaussian (σ = 4/2^level px, 9 taps) whose outer product is
/// `window(level)`.
fn window_1d(level: usize) -> [f32; 9] {
    let s = 4.0 / (1u32 << level) as f32;
    let mut w: [f32; 9] = std::array::from_fn(|i| (-((i as f32 - 4.0).powi(2)) / (2.0 * s * s)).exp());
    let sum: f32 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= sum);
    w
}

/// Window-weighted sum of f(value) around (x, y); direct slices in the interior,
/// clamp-to-edge reads only where the 9×9 window leaves the plane.
#[inline]
fn window_sum(p: &Plane, x: usize, y: usize, w: &[[f32; 9]; 9], f: impl Fn(f32) -> f32) -> f32 {
    let mut acc = 0.0;
    if x >= 4 && y >= 4 && x + 4 < p.width && y + 4 < p.height {
        for (j, row) in w.iter().enumerate() {
            let start = (y + j - 4) * p.width + x - 4;
            for (wt, &v) in row.iter().zip(&p.data[start..start + 9]) {
                acc += wt * f(v);
            }
        }
        return acc;
    }
    for (j, row) in w.iter().enumerate() {
        let yy = y as isize + j as isize - 4;
        for (i, wt) in row.iter().enumerate() {
            acc += wt * f(p.get_clamped(x as isize + i as isize - 4, yy));
        }
    }
    acc
}

#[inline]
fn local_mean(p: &Plane, x: usize, y: usize, w: &[[f32; 9]; 9]) -> f32 {
    window_sum(p, x, y, w, |v| v)
}

#[inline]
fn local_mean_sq(p: &Plane, x: usize, y: usize, w: &[[f32; 9]; 9]) -> f32 {
    window_sum(p, x, y, w, |v| v * v)
}

/// Mean and its standard error (0 for fewer than 2 values).
fn mean_se(v: &[f32]) -> (f32, f32) {
    let n = v.len().max(1) as f64;
    let mean = v.iter().map(|&x| x as f64).sum::<f64>() / n;
    let var = v.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean as f32, if v.len() < 2 { 0.0 } else { (var / n).sqrt() as f32 })
}

/// (window mean, window mean of squares) in one pass over the window.
#[inline]
fn local_moments(p: &Plane, x: usize, y: usize, w: &[[f32; 9]; 9]) -> (f32, f32) {
    let (mut m1, mut m2) = (0.0f32, 0.0f32);
    if x >= 4 && y >= 4 && x + 4 < p.width && y + 4 < p.height {
        for (j, row) in w.iter().enumerate() {
            let start = (y + j - 4) * p.width + x - 4;
            for (wt, &v) in row.iter().zip(&p.data[start..start + 9]) {
                m1 += wt * v;
                m2 += wt * (v * v);
            }
        }
        return (m1, m2);
    }
    (local_mean(p, x, y, w), local_mean_sq(p, x, y, w))
}

/// `local_mean_sq` (`SQ`) or `local_moments`' two sums of three planes at once, each
/// plane's sums in `window_sum`'s order (the same values): one window's sum is a
/// chain of 81 dependent additions, and three (or six) chains side by side keep
/// the adder busy — the sample search (7 windows a sample) was ~40% of a fresh
/// accurate noise fit at 512² (perf).
#[inline]
fn local_sums3<const MOMENTS: bool>(p: [&Plane; 3], x: usize, y: usize, w: &[[f32; 9]; 9]) -> [(f32, f32); 3] {
    let (width, height) = (p[0].width, p[0].height);
    let same = p.iter().all(|q| q.width == width && q.height == height);
    if !(same && x >= 4 && y >= 4 && x + 4 < width && y + 4 < height) {
        return std::array::from_fn(|c| {
            if MOMENTS {
                local_moments(p[c], x, y, w)
            } else {
                (0.0, local_mean_sq(p[c], x, y, w))
            }
        });
    }
    let (mut m1, mut m2) = ([0.0f32; 3], [0.0f32; 3]);
    for (j, row) in w.iter().enumerate() {
        let start = (y + j - 4) * width + x - 4;
        let rows: [&[f32]; 3] = std::array::from_fn(|c| &p[c].data[start..start + 9]);
        for (i, wt) in row.iter().enumerate() {
            for c in 0..3 {
                let v = rows[c][i];
                if MOMENTS {
                    m1[c] += wt * v;
                }
                m2[c] += wt * (v * v);
            }
        }
    }
    std::array::from_fn(|c| (m1[c], m2[c]))
}

/// Grid positions at a level: stride max(1, stride0 >> l), offset half a stride.
fn grid(len: usize, stride: usize) -> impl Iterator<Item = usize> {
    ((stride / 2).min(len.saturating_sub(1) / 2)..len).step_by(stride)
}

/// Per-level samples: luma, local variance per channel, and (accurate tier) each
/// channel's own window moments; clipped footprints out.
struct LevelSamples {
    y: Vec<f32>,
    y2: Vec<f32>,
    own: Option<[(Vec<f32>, Vec<f32>); 3]>,
    var: [Vec<f32>; 3],
}

fn collect_samples(
    bands: &[Vec<Plane>; 3],       // [channel][level 0..=4]
    luma: &[Plane],                // Gaussian pyramid 0..=4
    own: Option<&[Vec<Plane>; 3]>, // per channel, Gaussian pyramid 0..=4 of the clean frame
    clip: &ClipMask,
    stride0: usize,
) -> Vec<LevelSamples> {
    (0..=NOISE_LEVELS)
        .into_par_iter()
        .map(|l| {
            let win = window(l);
            let stride = (stride0 >> l).max(1);
            let band0 = &bands[0][l];
            let scale = 1usize << l;
            // Footprint of a level-l sample in level-0 pixels: the band's support (the
            // reduce chain and one expand, ~5 px per level-l pixel) plus the window's
            // 2σ radius, which is 8 level-0 px at every level (σ halves as pixels double).
            let radius = 5 * scale + 8;
            let mut out = LevelSamples {
                y: vec![],
                y2: vec![],
                own: own.map(|_| std::array::from_fn(|_| (vec![], vec![]))),
                var: [vec![], vec![], vec![]],
            };
            for y in grid(band0.height, stride) {
                for x in grid(band0.width, stride) {
                    if clip.touches(x * scale, y * scale, radius, l >= 3) {
                        continue;
                    }
                    // Window-averaged luma: the window pools noise whose variance is
                    // affine in Y, so B(var) = a + b·B(Y) exactly — regressing on the
                    // point luma instead biases dark samples near bright ones.
                    // Both moments in one pass (the same sums as two).
                    let (m1, m2) = local_moments(&luma[l], x, y, &win);
                    out.y.push(m1);
                    out.y2.push(m2);
                    if let (Some(pyr), Some(dst)) = (own, out.own.as_mut()) {
                        let m = local_sums3::<true>([&pyr[0][l], &pyr[1][l], &pyr[2][l]], x, y, &win);
                        for c in 0..3 {
                            dst[c].0.push(m[c].0);
                            dst[c].1.push(m[c].1);
                        }
                    }
                    let v = local_sums3::<false>([&bands[0][l], &bands[1][l], &bands[2][l]], x, y, &win);
                    for c in 0..3 {
                        out.var[c].push(v[c].1);
                    }
                }
            }
            out
        })
        .collect()
}

/// Per-level fits in both forms by iteratively reweighted least squares (3 rounds
/// of 1/pred² weights); the form with the higher heteroscedastic Gaussian
/// likelihood (summed over levels and channels) is kept.
fn fit_levels(points: &[LevelPoints], intensity: NoiseIntensity, with_linear: bool) -> Option<LevelFit> {
    let mut affine = vec![NoiseLevel::ZERO; points.len()];
    let mut linear = vec![NoiseLevel::ZERO; points.len()];
    let mut covs = vec![[[[0.0; 2]; 2]; 3]; points.len()];
    let (mut nll_aff, mut nll_lin, mut rel_aff, mut rel_lin) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (l, pts) in points.iter().enumerate() {
        let wts = &pts.weights;
        for c in 0..3 {
            let (y, y2) = pts.regressor(intensity, c)?;
            let v = &pts.var[c];
            // Affine variance: v ≈ a + b·y.
            let (mut a, mut b, _, mut cov) = ols(y, v, wts.as_deref())?;
            for _ in 0..3 {
                let w = precision_weights(&predicted(NoiseForm::AffineVariance, a, b, y, y2), wts.as_deref());
                (a, b, _, cov) = ols(y, v, Some(&w))?;
            }
            let pred_aff = predicted(NoiseForm::AffineVariance, a, b, y, y2);
            affine[l].intercept[c] = a as f32;
            affine[l].slope[c] = b as f32;
            covs[l][c] = cov;
            // The low-pass residual carries ~0.1% of white noise's variance and its
            // few, wide samples are the least reliable: measured on a Poisson sensor
            // (tests/independent_forward.rs) its likelihood alone flipped the form
            // from the affine variance every band preferred to a linear std (3.0%
            // instead of 0.7% median error). Forms (and intensities) are chosen by
            // the band-pass levels.
            let band = l < NOISE_LEVELS;
            if band {
                nll_aff += neg2_log_likelihood(v, &pred_aff);
            }
            if !with_linear {
                nll_lin = f64::INFINITY;
                rel_aff += rel_of(v, &pred_aff);
                continue;
            }
            // Linear std: v ≈ (a + b·y)².
            let lin_pred = |a: f64, b: f64| predicted(NoiseForm::LinearStd, a, b, y, y2);
            let (mut la, mut lb, _) = fit_linear_std(y, y2, v, wts.as_deref())?;
            for _ in 0..3 {
                let w = precision_weights(&lin_pred(la, lb), wts.as_deref());
                (la, lb, _) = fit_linear_std(y, y2, v, Some(&w))?;
            }
            let pred_lin = lin_pred(la, lb);
            if band {
                nll_lin += neg2_log_likelihood(v, &pred_lin);
            }
            // Keep std non-negative at the reference point: (a + b·y)² is symmetric
            // in sign, so flip to the branch with a positive std.
            let ym = y.iter().sum::<f32>() / y.len().max(1) as f32;
            let (la, lb) = if la + lb * ym as f64 >= 0.0 { (la, lb) } else { (-la, -lb) };
            linear[l].intercept[c] = la as f32;
            linear[l].slope[c] = lb as f32;
            rel_aff += rel_of(v, &pred_aff);
            rel_lin += rel_of(v, &pred_lin);
        }
    }
    let m = (3 * points.len()) as f64;
    let (form, levels, rel_res, nll) = if nll_lin < nll_aff {
        (NoiseForm::LinearStd, linear, rel_lin / m, nll_lin)
    } else {
        (NoiseForm::AffineVariance, affine, rel_aff / m, nll_aff)
    };
    Some(LevelFit { form, intensity, levels, covs, rel_res, nll })
}

/// Relative squared residual Σ(v − pred)² / Σv².
fn rel_of(v: &[f32], pred: &[f64]) -> f64 {
    v.iter().zip(pred).map(|(&vi, &p)| (vi as f64 - p).powi(2)).sum::<f64>()
        / v.iter().map(|&vi| (vi as f64).powi(2)).sum::<f64>().max(1e-300)
}

/// Both intensity variables where the points carry each channel's own moments:
/// the intensity by the affine-variance likelihood (same variance samples, same
/// likelihood: comparable; the affine fit is a few weighted OLS passes, the
/// linear-std Gauss–Newton is what costs), then both forms at that intensity.
fn fit_levels_any_intensity(points: &[LevelPoints]) -> Option<LevelFit> {
    let intensity = if points.iter().all(|p| p.own.is_some()) {
        let luma = fit_levels(points, NoiseIntensity::Luma, false).map_or(f64::INFINITY, |f| f.nll);
        let own = fit_levels(points, NoiseIntensity::Channel, false).map_or(f64::INFINITY, |f| f.nll);
        if own < luma {
            NoiseIntensity::Channel
        } else {
            NoiseIntensity::Luma
        }
    } else {
        NoiseIntensity::Luma
    };
    fit_levels(points, intensity, true)
}

/// Predicted local variance of samples with window moments m1 = B(Y), m2 = B(Y²)
/// under a level map (a, b) of `form`: a + b·m1, or B((a + b·Y)²) = a² + 2ab·m1 +
/// b²·m2 (see `fit_linear_std`).
fn predicted(form: NoiseForm, a: f64, b: f64, m1: &[f32], m2: &[f32]) -> Vec<f64> {
    match form {
        NoiseForm::AffineVariance => m1.iter().map(|&y| a + b * y as f64).collect(),
        NoiseForm::LinearStd => {
            m1.iter().zip(m2).map(|(&y, &y2)| a * a + 2.0 * a * b * y as f64 + b * b * y2 as f64).collect()
        }
    }
}

/// The fit's predicted local variance of every sample of level `l`, channel `c`.
fn level_pred(fit: &LevelFit, pts: &LevelPoints, l: usize, c: usize) -> Option<Vec<f64>> {
    let (y, y2) = pts.regressor(fit.intensity, c)?;
    let lv = fit.levels.get(l)?;
    Some(predicted(fit.form, lv.intercept[c] as f64, lv.slope[c] as f64, y, y2))
}

/// A band level and channel whose median sample reads below its least-squares
/// fit by more than sampling explains (`leaks`).
#[derive(Clone, Copy, Debug)]
struct Leak {
    level: usize,
    channel: usize,
    /// Median sample / prediction, over white noise's median-to-mean: 1 for noise.
    ratio: f32,
}

impl std::fmt::Display for Leak {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "level {} channel {} ×{:.2}", self.level, self.channel, self.ratio)
    }
}

/// Standard errors by which a level's median sample must fall short before it
/// counts as a leak (`leaks`): 12 tests per fit (4 band levels × 3 channels) at
/// 3σ, about one false report in 60 fits, and that one near 1.
const LEAK_Z: f32 = 3.0;

/// Lowest median ratio (`Leak::ratio`) a fit that may refuse
/// (`FitOptions::noise_min_leak_ratio`) publishes. Below it the
/// structure a reference left behind is not a minority of samples but the bulk:
/// on the calibration video a reference of three frames moving 8 px per frame
/// read ×0.56 at level 3 (the fit +93% there, still +42% scaled to its median),
/// while the video's other fits read ×0.80 at worst (level 3, ~300 samples). Such a fit
/// says "not identifiable" instead.
pub const MIN_LEAK_RATIO: f32 = 0.75;

/// Leakage test of an accurate fit. A reference that does not quite match the
/// frame (aligned video: a little more or less motion blur, a depth edge,
/// sub-pixel misregistration) leaves image structure in I − I_noNoise, which
/// least squares takes for noise, most at the coarse levels where the noise is
/// weakest. It raises the mean of a level's samples more than their median: a
/// level whose median ratio of sample to prediction lies more than `LEAK_Z`
/// standard errors below white noise's median-to-mean
/// (`white_noise_median_to_mean`) leaks. The median's standard error comes from
/// the order statistics (ranks n/2 ± √n/2 span about ±1 SE). Only the band
/// levels: the low-pass residual's few, wide samples have no measured median.
fn leaks(points: &[LevelPoints], fit: &LevelFit) -> Vec<Leak> {
    let mut out = vec![];
    for (l, pts) in points.iter().enumerate().take(NOISE_LEVELS) {
        let expected = white_noise_median_to_mean(l);
        for c in 0..3 {
            let Some(pred) = level_pred(fit, pts, l, c) else { continue };
            let mut r: Vec<f32> =
                pred.iter().zip(&pts.var[c]).filter(|(p, _)| **p > 0.0).map(|(p, v)| v / *p as f32).collect();
            let n = r.len();
            if n < 16 {
                continue;
            }
            r.sort_by(f32::total_cmp);
            let half = ((n as f32).sqrt() / 2.0).ceil() as usize;
            let med = r[n / 2];
            let se = 0.5 * (r[(n / 2 + half).min(n - 1)] - r[n / 2 - half.min(n / 2)]);
            if med + LEAK_Z * se < expected {
                out.push(Leak { level: l, channel: c, ratio: med / expected });
            }
        }
    }
    out
}

fn pyramids(img: &Rgb) -> [Vec<Plane>; 3] {
    let v: Vec<Vec<Plane>> = (0..3)
        .into_par_iter()
        .map(|c| {
            let p = laplacian_pyramid(&img.plane(c), NOISE_LEVELS);
            let mut levels = p.bands;
            levels.push(p.lowpass);
            levels
        })
        .collect();
    let mut it = v.into_iter();
    let mut next = || it.next().unwrap_or_default();
    [next(), next(), next()]
}

fn finish(
    method: &str,
    started: Instant,
    fitted: Option<LevelFit>,
    samples: &[LevelSamples],
    luma_range: [f32; 2],
    with_lowpass: bool,
) -> Noise {
    let n_used: usize = samples.iter().map(|s| s.y.len()).sum();
    let Some(LevelFit { form, intensity, mut levels, covs, rel_res, .. }) = fitted else {
        let reason = "too few unclipped samples to fit the noise model";
        let mut d = super::not_identifiable(method, reason, started);
        d.samples_used = n_used as u64;
        return Noise::absent(d);
    };
    let lowpass = if with_lowpass && levels.len() > NOISE_LEVELS { Some(levels[NOISE_LEVELS]) } else { None };
    levels.truncate(NOISE_LEVELS);
    let noise = Noise {
        present: false,
        form,
        intensity,
        levels,
        lowpass,
        luminance_range: luma_range,
        bins: vec![],
        level_sources: vec![],
        blocking: None,
        diagnostics: Diagnostics::not_fitted(""),
    };
    // Uncertainty of the level-0 std at mid-range luma, from the affine-variance
    // covariance (delta method: δstd = δvar / (2·std)), averaged over channels.
    let ym = 0.5 * (luma_range[0] + luma_range[1]) as f64;
    let mut rel = 0.0;
    let mut std_mid = 0.0;
    for c in 0..3 {
        let cov = covs[0][c];
        let var_se = (cov[0][0] + 2.0 * ym * cov[0][1] + ym * ym * cov[1][1]).max(0.0).sqrt();
        let s = noise.levels[0].std(form, c, ym as f32) as f64;
        std_mid += s / 3.0;
        rel += if s > 0.0 { var_se / (2.0 * s * s) / 3.0 } else { f64::INFINITY };
    }
    let before: f64 = samples[0].var.iter().flatten().map(|&v| (v as f64).powi(2)).sum::<f64>()
        / (3 * samples[0].y.len()).max(1) as f64;
    let present = std_mid > 1e-4 && rel.is_finite() && std_mid * (1.0 - 3.0 * rel) > 0.0 && rel < 1.0 / 3.0;
    // A reading well above visibility whose standard error does not exclude zero
    // says the frame cannot tell, not that the camera has no noise: on real
    // in-camera JPEG shots (PolyU, `cargo xtask bench-quality`) the blind tier read
    // level-0 stds of 3–4/1000 (0.8–1.1 DN, the truth 1–2 DN) with too few agreeing
    // luma bins to pin them, and called that "absent".
    let status = if present {
        Status::Present
    } else if std_mid.is_finite() && std_mid > 1e-4 {
        Status::NotIdentifiable
    } else {
        Status::Absent
    };
    let reason = if present {
        format!(
            "level-0 std {std_mid:.5} at {} {ym:.2} (±{:.2}%); form {form:?} (mean relative residual {rel_res:.4}, chosen by likelihood); \
             intensity {intensity:?}{}; residuals are mean squared local-variance errors at level 0",
            if intensity.is_luma() { "luma" } else { "intensity" },
            100.0 * rel,
            if method == "accurate" { " (luma or each channel's own value, chosen by likelihood)" } else { "" }
        )
    } else {
        match status {
            Status::NotIdentifiable => format!(
                "not identifiable: level-0 std {std_mid:.2e} at luma {ym:.2} is within 3 standard errors (±{:.0}%) of zero: \
                 the frame cannot tell this noise from none",
                100.0 * rel
            ),
            _ => format!("level-0 std {std_mid:.2e} at luma {ym:.2} is below 1e-4 (invisible): absent"),
        }
    };
    Noise {
        present,
        diagnostics: Diagnostics {
            status,
            reason,
            method: method.into(),
            residual_before: Some(before),
            residual_after: Some(before * rel_res.min(1.0)),
            samples_used: n_used as u64,
            fit_time_s: started.elapsed().as_secs_f64(),
            stderr: Some(if rel.is_finite() { rel } else { 1.0 }),
            stages_s: Default::default(),
        },
        ..noise
    }
}

fn plot_data(points: &[LevelPoints]) -> NoisePlotData {
    NoisePlotData {
        levels: points
            .iter()
            .map(|p| {
                let s = |c: usize| p.var[c].iter().map(|x| x.max(0.0).sqrt()).collect::<Vec<_>>();
                (p.y.clone(), [s(0), s(1), s(2)])
            })
            .collect(),
    }
}

fn intensity_range(mut y: Vec<f32>) -> [f32; 2] {
    if y.is_empty() {
        return [0.0, 1.0];
    }
    // 1st–99th percentile: the luma range the samples actually constrain.
    let lo = percentile(&mut y, 0.01);
    let hi = percentile(&mut y, 0.99);
    [lo.clamp(0.0, 1.0), hi.clamp(0.0, 1.0).max(lo.clamp(0.0, 1.0))]
}

/// Accurate tier: I and I_noNoise.
pub fn fit_accurate(
    image: &Rgb,
    denoised: &Rgb,
    valid: Option<&Plane>,
    opts: &super::FitOptions,
) -> (Noise, NoisePlotData) {
    let started = Instant::now();
    let mut st = super::Stages::start();
    let residual = Rgb {
        width: image.width,
        height: image.height,
        // Zero where the reference does not hold: those pixels then only dilute a
        // footprint (bounded by MAX_INVALID_FRACTION), never add to it.
        channels: std::array::from_fn(|c| {
            let res = image.channels[c].iter().zip(&denoised.channels[c]).map(|(a, b)| a - b);
            match valid {
                Some(v) => res.zip(&v.data).map(|(r, m)| if *m > 0.5 { r } else { 0.0 }).collect(),
                None => res.collect(),
            }
        }),
    };
    let bands = pyramids(&residual);
    let own: Vec<Vec<Plane>> =
        (0..3).into_par_iter().map(|c| crate::image::gaussian_pyramid_of(denoised.plane(c), NOISE_LEVELS)).collect();
    let own: [Vec<Plane>; 3] = own.try_into().unwrap_or_else(|_| std::array::from_fn(|_| vec![]));
    // The pyramid is linear: luma's levels are the weighted sums of the channels'.
    let luma: Vec<Plane> = (0..own[0].len())
        .map(|l| {
            let [r, g, b] = [&own[0][l], &own[1][l], &own[2][l]];
            let data = (r.data.iter().zip(&g.data).zip(&b.data))
                .map(|((r, g), b)| LUMA_WEIGHTS[0] * r + LUMA_WEIGHTS[1] * g + LUMA_WEIGHTS[2] * b)
                .collect();
            Plane::from_vec(r.width, r.height, data)
        })
        .collect();
    st.lap("blur");
    let stride = effective_stride(image.len(), opts.noise_stride_px);
    let samples = collect_samples(&bands, &luma, Some(&own), &clip_mask(image, 1, valid), stride);
    st.lap("search");
    // The low-pass residual is fitted when it has unclipped samples (its footprint
    // is ~90 px wide, so frames with large clipped areas may leave none).
    let usable = if samples[NOISE_LEVELS].y.is_empty() { NOISE_LEVELS } else { NOISE_LEVELS + 1 };
    let points: Vec<LevelPoints> = samples
        .iter()
        .take(usable)
        .map(|s| LevelPoints {
            y: s.y.clone(),
            y2: s.y2.clone(),
            own: s.own.clone(),
            var: s.var.clone(),
            weights: None,
        })
        .collect();
    let fitted = if points.iter().all(|p| !p.y.is_empty()) { fit_levels_any_intensity(&points) } else { None };
    let leaked = fitted.as_ref().map_or(vec![], |f| leaks(&points, f));
    st.lap("least_squares");
    let range = match (&fitted, &samples[0].own) {
        (Some(f), Some(own)) if f.intensity == NoiseIntensity::Channel => {
            // The channel values the samples constrain, pooled over channels.
            let pooled: Vec<f32> = own.iter().flat_map(|(m1, _)| m1.iter().copied()).collect();
            intensity_range(pooled)
        }
        _ => intensity_range(samples[0].y.clone()),
    };
    let mut noise = finish("accurate", started, fitted, &samples, range, true);
    if let Some(worst) = leaked.iter().min_by(|a, b| a.ratio.total_cmp(&b.ratio)) {
        let list = leaked.iter().map(|a| a.to_string()).collect::<Vec<_>>().join(", ");
        if opts.noise_min_leak_ratio.is_some_and(|min| worst.ratio < min) {
            let reason = format!(
                "the reference leaves image structure in the residual: at level {} the median sample lies {:.0}% below the fit (median ratios: {list})",
                worst.level,
                100.0 * (1.0 - worst.ratio)
            );
            let mut d = super::not_identifiable("accurate", reason, started);
            d.samples_used = noise.diagnostics.samples_used;
            noise = Noise::absent(d);
        } else if noise.present {
            noise.diagnostics.reason += &format!("; the reference may leak structure (median ratios: {list})");
        }
    }
    noise.diagnostics.stages_s = st.done();
    (noise, plot_data(&points))
}

/// Median / mean of level-`l` local variances (9×9 window of σ = 4/2^l) of white
/// noise's band l: texture leaking into the "flat" set only ever adds variance, and
/// a median ignores a minority of such samples where a mean does not. The window
/// holds fewer independent samples at coarser levels (σ = 0.5 px at level 3), so
/// the ratio falls with l. Measured once on a 512×512×3 field (relative standard
/// error ≤ 0.3% at level 0, ≤ 1.5% at level 3); stored in `measured.rs`
/// (`measure_white_noise_median_to_mean`; see `crate::synth::measured_check` for why).
fn white_noise_median_to_mean(level: usize) -> f32 {
    measured::WHITE_NOISE_MEDIAN_TO_MEAN[level.min(NOISE_LEVELS - 1)]
}

#[cfg(test)]
fn measure_white_noise_median_to_mean() -> [f32; NOISE_LEVELS] {
    let n = 512usize;
    let mut v: Vec<Vec<f32>> = vec![vec![]; NOISE_LEVELS];
    let mut sums = [0.0f64; NOISE_LEVELS];
    for c in 0..3u32 {
        let data = (0..n * n).map(|i| crate::synth::gaussian((i % n) as u32, (i / n) as u32, c, 0xb1d)).collect();
        let pyr = laplacian_pyramid(&Plane::from_vec(n, n, data), NOISE_LEVELS);
        for (l, band) in pyr.bands.iter().enumerate() {
            let win = window(l);
            let stride = (4 >> l).max(1);
            for y in grid(band.height, stride) {
                for x in grid(band.width, stride) {
                    let m = local_mean_sq(band, x, y, &win);
                    sums[l] += m as f64;
                    v[l].push(m);
                }
            }
        }
    }
    std::array::from_fn(|l| {
        let mean = (sums[l] / v[l].len() as f64) as f32;
        percentile(&mut v[l], 0.5) / mean
    })
}

#[cfg(test)]
mod tests;
