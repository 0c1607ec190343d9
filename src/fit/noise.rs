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
//! Blind (`fit_fast`): every band-pass level measured on I alone, at its flattest
//! samples per luma bin (flatness judged two levels coarser); a confidence per luma
//! bin and codec blocking are reported; the low-pass is not identifiable from one
//! frame (it is the image itself) and is left out.
//!
//! Present when the level-0 std at mid-range luma exceeds 3 standard errors and
//! 1e-4 (0.026/255: far below visibility).

use crate::image::{gaussian_pyramid, laplacian_pyramid, IntegralImage, Plane, Rgb, LUMA_WEIGHTS};
use crate::model::{Diagnostics, Noise, NoiseForm, NoiseIntensity, NoiseLevel, Status, NOISE_LEVELS};
use rayon::prelude::*;
use std::time::Instant;

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
const BLIND_FLAT_FRACTION: f64 = 0.2;
/// Default of `FitOptions::noise_fast_samples_per_level`. Measured over 27 frames of
/// known noise and the real DivX clip (`examples/noise_budget_probe.rs`,
/// BENCHMARKS.md "noise samples per level"): level 0's error is the same from 40 000
/// down to 5 000 (median 10–11%: texture in the flattest samples, not sampling),
/// the clip's level 0 inside its range 18.4% at 20 000 and 16.8% here; the noise
/// fit at 1280×960 takes 15.4 ms instead of 18.5. 10 000, not 5 000: at 5 000
/// level 2 was measured on none of the 27 frames (6 here, 4 at 20 000) and derived
/// instead, which on real correlated noise is what costs most.
pub const DEFAULT_FAST_SAMPLES_PER_LEVEL: usize = 10_000;
/// Fewest grid points per level `FitOptions::noise_fast_samples_per_level` takes:
/// every luma bin could then still hold `BLIND_MIN_PER_BIN` samples.
pub const MIN_FAST_SAMPLES_PER_LEVEL: usize = BLIND_BINS * BLIND_MIN_PER_BIN;
/// The blind tier's finest level-0 grid: only 20% of its samples are kept (the
/// flattest), so it samples denser than the accurate tier.
const BLIND_STRIDE_PX: usize = 4;
const BLIND_BINS: usize = 16;
const BLIND_MIN_PER_BIN: usize = 24;
/// Largest std ratio of a level to the next finer one that still reads as noise.
/// Measured: white noise 0.25 (level 1/0), 0.45, 0.50; the vtest clip's codec noise
/// 0.50, 0.65, 0.67 (temporal reference); the flattest samples of textured frames
/// 1.1–3 (the astronaut's level 2 over level 1, the vtest frame's levels 1–3).
const MAX_LEVEL_STD_RATIO: f32 = 0.8;
/// Fewest flat samples a bin is measured on (a median of fewer scatters by > 25% at level 3).
const BLIND_MIN_FLAT: usize = 12;

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

/// Window mean of the product of two planes of one size.
#[inline]
fn local_mean_prod(p: &Plane, q: &Plane, x: usize, y: usize, w: &[[f32; 9]; 9]) -> f32 {
    let mut acc = 0.0;
    if x >= 4 && y >= 4 && x + 4 < p.width && y + 4 < p.height {
        for (j, row) in w.iter().enumerate() {
            let start = (y + j - 4) * p.width + x - 4;
            for ((wt, &a), &b) in row.iter().zip(&p.data[start..start + 9]).zip(&q.data[start..start + 9]) {
                acc += wt * a * b;
            }
        }
        return acc;
    }
    for (j, row) in w.iter().enumerate() {
        let yy = y as isize + j as isize - 4;
        for (i, wt) in row.iter().enumerate() {
            let xx = x as isize + i as isize - 4;
            acc += wt * p.get_clamped(xx, yy) * q.get_clamped(xx, yy);
        }
    }
    acc
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

/// The blind tier's window sums in separable form: per window column, a weighted
/// sum down its 9 rows (9 independent accumulators, which the compiler keeps in
/// vector lanes), then the columns' weighted sum — Σ_i w_i Σ_j w_j f(v_ji), the
/// window of `window(l)` (its outer product) up to float rounding. Why: the 2-D
/// serial sums are 81 dependent additions per sample, bound by the adder's latency
/// (by perf ~60% of the blind noise fit's sample search at 1280×960). The accurate
/// tier keeps the serial sums: on a flat frame its regression relies on their exact
/// cancellation (tests/extremes.rs::flat_textureless_frame; a reordered sum there
/// lost the noise, see BENCHMARKS.md). Border samples take the clamped 2-D sums.
struct SepWindow {
    w1: [f32; 9],
    w2: [[f32; 9]; 9],
}

impl SepWindow {
    fn new(level: usize) -> Self {
        Self { w1: window_1d(level), w2: window(level) }
    }

    #[inline]
    fn interior(p: &Plane, x: usize, y: usize) -> bool {
        x >= 4 && y >= 4 && x + 4 < p.width && y + 4 < p.height
    }

    /// Σ_i w_i c_i: the column sums' weighted sum, as a pairwise tree (four
    /// dependent additions instead of nine in a chain).
    #[inline]
    fn across(&self, c: &[f32; 9]) -> f32 {
        let p: [f32; 9] = std::array::from_fn(|i| c[i] * self.w1[i]);
        ((p[0] + p[1]) + (p[2] + p[3])) + ((p[4] + p[5]) + (p[6] + p[7])) + p[8]
    }

    /// (window mean, window mean of squares) of `p` at (x, y).
    #[inline]
    fn moments(&self, p: &Plane, x: usize, y: usize) -> (f32, f32) {
        if !Self::interior(p, x, y) {
            return (local_mean(p, x, y, &self.w2), local_mean_sq(p, x, y, &self.w2));
        }
        let (mut c1, mut c2) = ([0.0f32; 9], [0.0f32; 9]);
        for (j, &wj) in self.w1.iter().enumerate() {
            let start = (y + j - 4) * p.width + x - 4;
            for ((a, b), &v) in c1.iter_mut().zip(c2.iter_mut()).zip(&p.data[start..start + 9]) {
                *a += wj * v;
                *b += wj * (v * v);
            }
        }
        (self.across(&c1), self.across(&c2))
    }

    /// Window mean of the squares of `p` at (x, y).
    #[inline]
    fn mean_sq(&self, p: &Plane, x: usize, y: usize) -> f32 {
        if !Self::interior(p, x, y) {
            return local_mean_sq(p, x, y, &self.w2);
        }
        let mut c = [0.0f32; 9];
        for (j, &wj) in self.w1.iter().enumerate() {
            let start = (y + j - 4) * p.width + x - 4;
            for (a, &v) in c.iter_mut().zip(&p.data[start..start + 9]) {
                *a += wj * (v * v);
            }
        }
        self.across(&c)
    }

    /// Window mean of the product of `p` and `q` (one size) at (x, y).
    #[inline]
    fn mean_prod(&self, p: &Plane, q: &Plane, x: usize, y: usize) -> f32 {
        if !Self::interior(p, x, y) {
            return local_mean_prod(p, q, x, y, &self.w2);
        }
        let mut c = [0.0f32; 9];
        for (j, &wj) in self.w1.iter().enumerate() {
            let start = (y + j - 4) * p.width + x - 4;
            for ((a, &u), &v) in c.iter_mut().zip(&p.data[start..start + 9]).zip(&q.data[start..start + 9]) {
                *a += wj * (u * v);
            }
        }
        self.across(&c)
    }
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
            let win = window(l.min(3) + (l == NOISE_LEVELS) as usize);
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
                    out.y.push(local_mean(&luma[l], x, y, &win));
                    out.y2.push(local_mean_sq(&luma[l], x, y, &win));
                    if let (Some(pyr), Some(dst)) = (own, out.own.as_mut()) {
                        for c in 0..3 {
                            let (m1, m2) = local_moments(&pyr[c][l], x, y, &win);
                            dst[c].0.push(m1);
                            dst[c].1.push(m2);
                        }
                    }
                    for c in 0..3 {
                        out.var[c].push(local_mean_sq(&bands[c][l], x, y, &win));
                    }
                }
            }
            out
        })
        .collect()
}

/// OLS of v on (1, y): returns (intercept, slope, ssr, covariance[2][2]).
fn ols(y: &[f32], v: &[f32], wts: Option<&[f32]>) -> Option<(f64, f64, f64, [[f64; 2]; 2])> {
    let n = y.len();
    if n == 0 {
        return None;
    }
    let (mut sw, mut sy, mut syy, mut sv, mut syv) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
    for i in 0..n {
        let w = wts.map_or(1.0, |w| w[i] as f64);
        let (yi, vi) = (y[i] as f64, v[i] as f64);
        sw += w;
        sy += w * yi;
        syy += w * yi * yi;
        sv += w * vi;
        syv += w * yi * vi;
    }
    let det = sw * syy - sy * sy;
    // Fewer than 4 points, or all at one luma: a constant is all the data can say.
    let (a, b) = if n >= 4 && det.abs() > 1e-12 * sw * sw {
        let b = (sw * syv - sy * sv) / det;
        ((sv - b * sy) / sw, b)
    } else {
        (sv / sw, 0.0)
    };
    let ssr: f64 = (0..n).map(|i| wts.map_or(1.0, |w| w[i] as f64) * (v[i] as f64 - a - b * y[i] as f64).powi(2)).sum();
    // Weighted LS: Cov(β) = (Σ w r² / (n − 2)) · (XᵀWX)⁻¹, for weights of any scale.
    let s2 = ssr / (n as f64 - 2.0).max(1.0);
    let cov = if n >= 4 && det.abs() > 1e-12 * sw * sw {
        [[s2 * syy / det, -s2 * sy / det], [-s2 * sy / det, s2 * sw / det]]
    } else {
        [[s2 / sw, 0.0], [0.0, 0.0]]
    };
    Some((a, b, ssr, cov))
}

/// Gauss–Newton for v ≈ B((a + b·Y)²) = a² + 2ab·m1 + b²·m2 (m1 = B(Y),
/// m2 = B(Y²): the window pools the squared std, so this is exact where
/// (a + b·B(Y))² would be biased up by b²·Var_B(Y)). Started from OLS of √v on m1.
fn fit_linear_std(m1: &[f32], m2: &[f32], v: &[f32], wts: Option<&[f32]>) -> Option<(f64, f64, f64)> {
    let sq: Vec<f32> = v.iter().map(|&x| x.max(0.0).sqrt()).collect();
    let (mut a, mut b, _, _) = ols(m1, &sq, wts)?;
    let w = |i: usize| wts.map_or(1.0, |w| w[i] as f64);
    let pred = |a: f64, b: f64, i: usize| a * a + 2.0 * a * b * m1[i] as f64 + b * b * m2[i] as f64;
    for _ in 0..30 {
        let (mut jtj, mut jtr) = ([[0.0f64; 2]; 2], [0.0f64; 2]);
        for i in 0..v.len() {
            let r = v[i] as f64 - pred(a, b, i);
            let j = [2.0 * a + 2.0 * b * m1[i] as f64, 2.0 * a * m1[i] as f64 + 2.0 * b * m2[i] as f64];
            for p in 0..2 {
                jtr[p] += w(i) * j[p] * r;
                for q in 0..2 {
                    jtj[p][q] += w(i) * j[p] * j[q];
                }
            }
        }
        let det = jtj[0][0] * jtj[1][1] - jtj[0][1] * jtj[1][0];
        if det.abs() < 1e-30 {
            break;
        }
        let da = (jtj[1][1] * jtr[0] - jtj[0][1] * jtr[1]) / det;
        let db = (jtj[0][0] * jtr[1] - jtj[1][0] * jtr[0]) / det;
        a += da;
        b += db;
        if da.abs() + db.abs() < 1e-12 {
            break;
        }
    }
    let ssr = (0..v.len()).map(|i| w(i) * (v[i] as f64 - pred(a, b, i)).powi(2)).sum();
    (a.is_finite() && b.is_finite()).then_some((a, b, ssr))
}

/// Weights 1/pred² (times the optional base weights): the sampling variance of a
/// local-variance estimate grows like σ⁴, so unweighted least squares would let the
/// bright end dictate the dark end. Predictions are floored at 1e-3 of their
/// maximum so a line through zero cannot produce infinite weights.
fn precision_weights(pred: &[f64], base: Option<&[f32]>) -> Vec<f32> {
    let floor = pred.iter().cloned().fold(0.0f64, f64::max) * 1e-3 + 1e-30;
    pred.iter().enumerate().map(|(i, &p)| (base.map_or(1.0, |b| b[i] as f64) / p.max(floor).powi(2)) as f32).collect()
}

/// −2·log-likelihood (up to a constant) of variance samples `v` under predictions
/// `pred` with sampling std ∝ pred: Σ ln pred² + n·ln(mean((v − pred)²/pred²)).
fn neg2_log_likelihood(v: &[f32], pred: &[f64]) -> f64 {
    let floor = pred.iter().cloned().fold(0.0f64, f64::max) * 1e-3 + 1e-30;
    let n = v.len() as f64;
    let (mut logs, mut rel) = (0.0f64, 0.0f64);
    for (&vi, &p) in v.iter().zip(pred) {
        let p = p.max(floor);
        logs += 2.0 * p.ln();
        rel += (vi as f64 - p).powi(2) / (p * p);
    }
    logs + n * (rel / n).max(1e-300).ln()
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

/// Clipped pixels: a channel is clipped at its maximum (minimum) when that exact
/// value repeats in at least 0.05% of the pixels (and 2) and is bright, ≥ 0.6
/// (dark, ≤ 0.1). This finds 8-bit 255s, 16-bit 65535s and float frames clipped at
/// any white level, while unclipped float frames (over- and undershoot included)
/// have no repeated extreme and lose nothing.
fn clip_mask(img: &Rgb, block: usize, valid: Option<&Plane>) -> ClipMask {
    clip_mask_of(img, &clip_limits(img), block, valid, &[0, 1, 2])
}

/// Per channel, the clipped low and high values (see `clip_mask`), if any.
type ClipLimits = [(Option<f32>, Option<f32>); 3];

/// The clipped extremes of every channel (`channel_clip_limits`; the accurate
/// tier's — the blind tier reads them from tile extremes, `blind_clip_masks`).
fn clip_limits(img: &Rgb) -> ClipLimits {
    let min_count = clip_min_count(img.len());
    std::array::from_fn(|c| channel_clip_limits(&img.channels[c], min_count))
}

/// How often a channel's extreme must repeat to be a clip level (`clip_mask`):
/// 0.05% of the pixels, and at least 2.
fn clip_min_count(pixels: usize) -> usize {
    (pixels / 2000).max(2)
}

/// A channel's clip levels from its extremes and their counts (`clip_mask`): the
/// minimum when dark (≤ 0.1), the maximum when bright (≥ 0.6), each repeated at
/// least `min_count` times.
fn clip_levels(lo: (f32, usize), hi: (f32, usize), min_count: usize) -> (Option<f32>, Option<f32>) {
    ((lo.0 <= 0.1 && lo.1 >= min_count).then_some(lo.0), (hi.0 >= 0.6 && hi.1 >= min_count).then_some(hi.0))
}

/// One channel's `clip_limits`, in one pass over 8 independent lanes: per lane the
/// extremes and how often each was seen (a new extreme restarts its count), then
/// the lanes merged (the channel's extreme counts in every lane that reached it).
/// Measured both ways, in different surroundings: while the blocking scan before it
/// read every row (the frame cached), a lane-wise single pass was 2× slower than a
/// pass for the extremes and another counting them; with blocking on half the rows
/// the passes are bound by memory (three 4.9 MB planes at 1280×960), and one pass
/// read 3.7 ms against 4.4 ms for two (`search.clipping`, `BENCH=1 stage_times`).
/// The lanes compare with `<`/`>`: the fit's input is checked finite first.
fn channel_clip_limits(ch: &[f32], min_count: usize) -> (Option<f32>, Option<f32>) {
    const LANES: usize = 8;
    let (mut lo, mut hi) = ([f32::INFINITY; LANES], [f32::NEG_INFINITY; LANES]);
    let (mut nlo, mut nhi) = ([0u32; LANES], [0u32; LANES]);
    let mut see = |i: usize, v: f32| {
        nlo[i] = if v < lo[i] { 1 } else { nlo[i] + (v == lo[i]) as u32 };
        lo[i] = if v < lo[i] { v } else { lo[i] };
        nhi[i] = if v > hi[i] { 1 } else { nhi[i] + (v == hi[i]) as u32 };
        hi[i] = if v > hi[i] { v } else { hi[i] };
    };
    let chunks = ch.chunks_exact(LANES);
    let tail = chunks.remainder();
    for k in chunks {
        for (i, &v) in k.iter().enumerate() {
            see(i, v);
        }
    }
    for (i, &v) in tail.iter().enumerate() {
        see(i, v);
    }
    let merge = |ext: &[f32; LANES], n: &[u32; LANES], better: fn(f32, f32) -> f32| {
        let e = ext.iter().copied().fold(ext[0], better);
        let count: usize = ext.iter().zip(n).filter(|(x, _)| **x == e).map(|(_, &c)| c as usize).sum();
        (e, count)
    };
    clip_levels(merge(&lo, &nlo, f32::min), merge(&hi, &nhi, f32::max), min_count)
}

/// `clip_mask` counting clipped values in `channels` only (the blind tier measures
/// each channel where that channel is unclipped: on the vtest clip the dark grass's
/// blue channel sits at 0 in 8% of the pixels, which would otherwise take the green
/// and red noise of the whole lawn with it).
fn clip_mask_of(img: &Rgb, limits: &ClipLimits, block: usize, valid: Option<&Plane>, channels: &[usize]) -> ClipMask {
    // Pixels where the reference does not hold: a sample is kept while they are at
    // most `MAX_INVALID_FRACTION` of its footprint (the residual is zero there, so
    // they lower its variance by at most that fraction). Excluding every footprint
    // that touches one would empty the coarse levels, whose windows are ~70 px wide.
    let holds = |x: f32| x > 0.5; // NaN: does not hold
    let invalid = valid.filter(|v| v.data.iter().any(|x| !holds(*x))).map(|v| {
        IntegralImage::new(&Plane::from_vec(
            v.width,
            v.height,
            v.data.iter().map(|x| if holds(*x) { 0.0 } else { 1.0 }).collect(),
        ))
    });
    let channels: Vec<usize> =
        channels.iter().copied().filter(|&c| limits[c].0.is_some() || limits[c].1.is_some()).collect();
    if channels.is_empty() {
        return ClipMask { clipped: None, invalid };
    }
    // Mark block×block tiles holding any clipped pixel; footprint tests then run on
    // the tile grid (conservative by up to one tile). The accurate tier uses 1 (exact),
    // the blind tier 8 (a 1/64-size table; it can afford to lose border samples).
    let (bw, bh) = (img.width.div_ceil(block), img.height.div_ceil(block));
    let mut blocks = Plane::new(bw, bh, 0.0);
    for &c in &channels {
        let (lo, hi) = limits[c];
        let (lo, hi) = (lo.unwrap_or(f32::NAN), hi.unwrap_or(f32::NAN)); // NaN equals nothing
        for (y, row) in img.channels[c].chunks_exact(img.width).enumerate() {
            // Whole tiles at once (no early exit: a branch-free fold vectorises).
            for (bx, tile) in row.chunks(block).enumerate() {
                if tile.iter().fold(false, |a, &v| a | (v == lo) | (v == hi)) {
                    blocks.data[(y / block) * bw + bx] = 1.0;
                }
            }
        }
    }
    ClipMask { clipped: Some((IntegralImage::new(&blocks), block)), invalid }
}

/// The blind tier's clip limits and per-channel tile masks (`clip_limits` and
/// `clip_mask_of(img, limits, block, None, &[c])` for each channel c, exactly) from
/// one pass per channel: every tile's lowest and highest value. A channel's extreme
/// is the extreme of its tiles' extremes; only tiles that reach it are read again
/// to count it (a frame clipped over a fifth of its area reads a fifth again), and
/// a tile holds a clipped pixel exactly when its extreme is the clip level. Two
/// full passes per channel (the lane-wise counts, then the tile fold) read 3.6 ms
/// at 1280×960 (`search.clipping`, `BENCH=1 stage_times`); this reads each value
/// once, as element-wise minima and maxima down each band of `block` rows.
fn blind_clip_masks(img: &Rgb, block: usize) -> (ClipLimits, [ClipMask; 3]) {
    let (w, h) = (img.width, img.height);
    let min_count = clip_min_count(img.len());
    let (bw, bh) = (w.div_ceil(block), h.div_ceil(block));
    let per_channel = |c: usize| -> ((Option<f32>, Option<f32>), ClipMask) {
        let ch = &img.channels[c];
        let (mut tlo, mut thi) = (Vec::with_capacity(bw * bh), Vec::with_capacity(bw * bh));
        let (mut col_lo, mut col_hi) = (vec![0.0f32; w], vec![0.0f32; w]);
        for by in 0..bh {
            let rows = by * block..((by + 1) * block).min(h);
            col_lo.copy_from_slice(&ch[rows.start * w..(rows.start + 1) * w]);
            col_hi.copy_from_slice(&col_lo);
            for y in rows.skip(1) {
                // `if` selects, not `f32::min`: the input is finite (checked by `fit`),
                // and the plain comparison vectorises to one min/max per lane.
                for ((l, u), &v) in col_lo.iter_mut().zip(col_hi.iter_mut()).zip(&ch[y * w..(y + 1) * w]) {
                    *l = if v < *l { v } else { *l };
                    *u = if v > *u { v } else { *u };
                }
            }
            for (a, b) in col_lo.chunks(block).zip(col_hi.chunks(block)) {
                tlo.push(a.iter().copied().fold(f32::INFINITY, |m, v| if v < m { v } else { m }));
                thi.push(b.iter().copied().fold(f32::NEG_INFINITY, |m, v| if v > m { v } else { m }));
            }
        }
        // How often `e` occurs in the tiles whose extreme it is, up to `min_count`
        // (so at most `min_count` tiles are read again, whatever the frame).
        let count = |tiles: &[f32], e: f32| {
            let mut n = 0usize;
            for (t, _) in tiles.iter().enumerate().filter(|(_, &v)| v == e) {
                let (bx, by) = (t % bw, t / bw);
                for y in by * block..((by + 1) * block).min(h) {
                    n += ch[y * w + bx * block..y * w + ((bx + 1) * block).min(w)].iter().filter(|&&v| v == e).count();
                }
                if n >= min_count {
                    break;
                }
            }
            n
        };
        let lo = tlo.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = thi.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let (lo, hi) = clip_levels((lo, count(&tlo, lo)), (hi, count(&thi, hi)), min_count);
        if lo.is_none() && hi.is_none() {
            return ((lo, hi), ClipMask { clipped: None, invalid: None });
        }
        let blocks: Vec<f32> =
            tlo.iter().zip(&thi).map(|(&a, &b)| (Some(a) == lo || Some(b) == hi) as u8 as f32).collect();
        let ii = IntegralImage::new(&Plane::from_vec(bw, bh, blocks));
        ((lo, hi), ClipMask { clipped: Some((ii, block)), invalid: None })
    };
    let [(l0, m0), (l1, m1), (l2, m2)] = std::array::from_fn(per_channel);
    ([l0, l1, l2], [m0, m1, m2])
}

/// Largest share of a noise sample's footprint where the reference may not hold.
const MAX_INVALID_FRACTION: f64 = 0.02;

/// Clipped-tile counts over boxes (and the tile size; `None` when the frame has no
/// clipping at all), and the invalid-reference pixel counts (`None`: valid
/// everywhere).
struct ClipMask {
    clipped: Option<(IntegralImage, usize)>,
    invalid: Option<IntegralImage>,
}

impl ClipMask {
    /// Whether any clipped pixel may lie within `r` of (x, y) (level-0 pixels):
    /// the box is widened to whole tiles, so the test errs on the safe side.
    ///
    /// `coarse`: levels 3 and the low-pass, whose footprints are ~100–180 px wide, so
    /// that one clipped pixel anywhere near would empty them on a small frame;
    /// there a footprint may hold up to `MAX_INVALID_FRACTION` clipped pixels (they
    /// carry no noise: the variance is diluted by at most that fraction).
    fn touches(&self, x: usize, y: usize, r: usize, coarse: bool) -> bool {
        let span = |c: usize, r: usize, n: usize| ((c + r + 1).min(n) - c.saturating_sub(r)) as f64;
        let clipped = match &self.clipped {
            None => false,
            Some((ii, block)) => {
                let (bx, by) = ((x / block).min(ii.width() - 1), (y / block).min(ii.height() - 1));
                let rb = r.div_ceil(*block);
                let count = ii.box_sum(bx, by, rb);
                if coarse {
                    count > MAX_INVALID_FRACTION * span(bx, rb, ii.width()) * span(by, rb, ii.height())
                } else {
                    count > 0.0
                }
            }
        };
        clipped
            || self.invalid.as_ref().is_some_and(|ii| {
                let (cx, cy) = (x.min(ii.width() - 1), y.min(ii.height() - 1));
                let area = span(cx, r, ii.width()) * span(cy, r, ii.height());
                ii.box_sum(cx, cy, r) > MAX_INVALID_FRACTION * area
            })
    }
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

fn percentile(v: &mut [f32], q: f64) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    v[k]
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
    let status = if present { Status::Present } else { Status::Absent };
    let reason = if present {
        format!(
            "level-0 std {std_mid:.5} at {} {ym:.2} (±{:.2}%); form {form:?} (mean relative residual {rel_res:.4}, chosen by likelihood); \
             intensity {intensity:?}{}; residuals are mean squared local-variance errors at level 0",
            if intensity.is_luma() { "luma" } else { "intensity" },
            100.0 * rel,
            if method == "accurate" { " (luma or each channel's own value, chosen by likelihood)" } else { "" }
        )
    } else {
        format!("level-0 std {std_mid:.2e} at luma {ym:.2} is within 3 standard errors of zero or below 1e-4")
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
        (0..3).into_par_iter().map(|c| gaussian_pyramid(&denoised.plane(c), NOISE_LEVELS)).collect();
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
/// error ≤ 0.3% at level 0, ≤ 1.5% at level 3).
fn white_noise_median_to_mean(level: usize) -> f32 {
    static R: std::sync::OnceLock<[f32; NOISE_LEVELS]> = std::sync::OnceLock::new();
    R.get_or_init(|| {
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
    })[level.min(NOISE_LEVELS - 1)]
}

/// Share of white noise's level-`l` band variance that survives a Catmull–Rom
/// bicubic resampling at a sub-pixel offset (what `analysis::temporal::align` does
/// to the neighbour frame), averaged over offsets on a 4×4 grid of phases: the
/// bicubic kernel low-passes, most at level 0. Measured once on a 256² field.
fn bicubic_noise_transmission(level: usize) -> f32 {
    static K: std::sync::OnceLock<[f32; NOISE_LEVELS]> = std::sync::OnceLock::new();
    K.get_or_init(|| {
        let n = 256usize;
        let data = (0..n * n).map(|i| crate::synth::gaussian((i % n) as u32, (i / n) as u32, 7, 0x5eed)).collect();
        let field = Plane::from_vec(n, n, data);
        let var_of = |p: &Plane| -> [f64; NOISE_LEVELS] {
            let pyr = laplacian_pyramid(p, NOISE_LEVELS);
            std::array::from_fn(|l| {
                // The inner half: away from the clamped borders.
                let b = &pyr.bands[l];
                let (x0, y0) = (b.width / 4, b.height / 4);
                let mut acc = 0.0f64;
                let mut m = 0usize;
                for y in y0..b.height - y0 {
                    for x in x0..b.width - x0 {
                        acc += (b.get(x, y) as f64).powi(2);
                        m += 1;
                    }
                }
                acc / m.max(1) as f64
            })
        };
        let base = var_of(&field);
        let mut sum = [0.0f64; NOISE_LEVELS];
        let phases = [0.125f32, 0.375, 0.625, 0.875];
        for &u in &phases {
            for &v in &phases {
                let mut shifted = Plane::new(n, n, 0.0);
                for y in 0..n {
                    for x in 0..n {
                        shifted.data[y * n + x] = crate::image::sample_bicubic(&field, x as f32 + u, y as f32 + v);
                    }
                }
                let s = var_of(&shifted);
                for l in 0..NOISE_LEVELS {
                    sum[l] += s[l] / base[l] / (phases.len() * phases.len()) as f64;
                }
            }
        }
        sum.map(|k| k as f32)
    })[level.min(NOISE_LEVELS - 1)]
}

/// One luma bin's blind measurement at one level.
struct BinMeasure {
    y: f32,
    y2: f32,
    var: [f32; 3],
    n: usize,
    /// Relative standard error of the bin's std (mean over channels).
    rel_se: f32,
}

/// Periodic block-grid discontinuities of a block-transform codec (JPEG, MPEG-4,
/// H.264 at 8 px): the mean absolute luma step across each column (row) phase mod 8,
/// over the flatter half of the frame (where blocking shows and texture does not
/// mask it). Blocking is reported when one phase exceeds the median of the other
/// seven by `BLOCKING_RATIO` in both directions; unblocked frames measured here stay
/// below 1.05 (the astronaut, the cat, synthetic noise), the vtest clip's DivX
/// frames reach ~1.3 (tests/real_noise.rs).
fn detect_blocking(img: &Rgb, structure: &Plane, scale: usize) -> Option<crate::model::Blocking> {
    const PERIOD: usize = 8;
    let (w, h) = (img.width, img.height);
    if w < 4 * PERIOD || h < 4 * PERIOD {
        return None;
    }
    // Flat pixels: structure magnitude below its median (structure is a signed band
    // at 1/scale resolution).
    let mut s: Vec<f32> = structure.data.iter().map(|v| v.abs()).collect();
    let med = percentile(&mut s, 0.5);
    // Row by row, the luma computed on the fly (two rows live, no full-frame plane),
    // the flat mask as 0/1 weights and the phase sums over 8-px chunks: branch-free,
    // so the 8 phases vectorise.
    let lw = crate::image::LUMA_WEIGHTS;
    let luma_row = |y: usize, out: &mut [f32]| {
        let i = y * w;
        for (x, o) in out.iter_mut().enumerate() {
            *o = lw[0] * img.channels[0][i + x] + lw[1] * img.channels[1][i + x] + lw[2] * img.channels[2][i + x];
        }
    };
    let (mut cur, mut next, mut flat) = (vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]);
    luma_row(0, &mut cur);
    let (mut col, mut ncol, mut row, mut nrow) =
        ([0.0f64; PERIOD], [0.0f64; PERIOD], [0.0f64; PERIOD], [0.0f64; PERIOD]);
    // Above 400k pixels every other band of `PERIOD` rows: each band still holds
    // every row phase and the column sums half the frame's flat pixels (~150 000 at
    // 1280×960), far more than the boundary/interior contrast needs (unblocked
    // frames < 1.05, the vtest clip's ~1.3); the scan was 3 ms of the blind tier.
    let band_stride = if w * h > 400_000 { 2 } else { 1 };
    let mut have = 0usize; // the row whose luma `cur` holds
    for y in 0..h - 1 {
        if (y / PERIOD) % band_stride != 0 {
            continue;
        }
        if have != y {
            luma_row(y, &mut cur);
        }
        luma_row(y + 1, &mut next);
        have = y + 1;
        let sy = (y / scale).min(structure.height - 1);
        for (x, f) in flat.iter_mut().enumerate() {
            let v = structure.data[sy * structure.width + (x / scale).min(structure.width - 1)];
            *f = (v.abs() <= med) as u8 as f32;
        }
        // The last column has no right neighbour: its horizontal step is left out.
        flat[w - 1] = 0.0;
        let (mut c, mut nc, mut r) = ([0.0f32; PERIOD], [0.0f32; PERIOD], [0.0f32; PERIOD]);
        let n = (w - 1) / PERIOD * PERIOD;
        for x0 in (0..n).step_by(PERIOD) {
            for k in 0..PERIOD {
                let x = x0 + k;
                let m = flat[x];
                c[k] += m * (cur[x + 1] - cur[x]).abs();
                r[k] += m * (next[x] - cur[x]).abs();
                nc[k] += m;
            }
        }
        for x in n..w - 1 {
            let m = flat[x];
            c[x % PERIOD] += m * (cur[x + 1] - cur[x]).abs();
            r[x % PERIOD] += m * (next[x] - cur[x]).abs();
            nc[x % PERIOD] += m;
        }
        let (rs, rn): (f32, f32) = (r.iter().sum(), nc.iter().sum());
        for k in 0..PERIOD {
            col[k] += c[k] as f64;
            ncol[k] += nc[k] as f64;
        }
        row[y % PERIOD] += rs as f64;
        nrow[y % PERIOD] += rn as f64;
        std::mem::swap(&mut cur, &mut next);
    }
    let peak = |sum: &[f64; PERIOD], n: &[f64; PERIOD]| -> Option<(usize, f32)> {
        let m: Vec<f64> = (0..PERIOD).map(|i| sum[i] / n[i].max(1.0)).collect();
        let k = (0..PERIOD).max_by(|&a, &b| m[a].total_cmp(&m[b]))?;
        let mut rest: Vec<f32> = (0..PERIOD).filter(|&i| i != k).map(|i| m[i] as f32).collect();
        let base = percentile(&mut rest, 0.5) as f64;
        (base > 0.0).then(|| (k, (m[k] / base) as f32))
    };
    let (px, rx) = peak(&col, &ncol)?;
    let (py, ry) = peak(&row, &nrow)?;
    let strength = rx.min(ry);
    (strength >= BLOCKING_RATIO).then_some(crate::model::Blocking {
        period_px: PERIOD as u32,
        phase_px: [px as u32, py as u32],
        strength,
    })
}

/// Smallest boundary/interior step ratio reported as blocking (see `detect_blocking`).
const BLOCKING_RATIO: f32 = 1.15;

/// Fast tier: the frame alone.
///
/// Every band-pass level is measured on the frame itself (real noise is shaped by
/// demosaicing, in-camera denoising, sharpening and compression, so coarse levels do
/// not follow from level 0 by white-noise ratios — on the vtest clip level 1 holds
/// 0.45× level 0's std where white noise would hold 0.49×, and level 3 1.6× the white
/// prediction). At level l, per luma bin (16 bins of the smoothed luma), the flat
/// samples are the `BLIND_FLAT_FRACTION` with the least luma energy two levels
/// coarser (band l+2: structure that spans the level-l window, and nearly
/// uncorrelated with level-l noise, so selecting on it does not bias the level-l
/// variance the way picking the lowest variances would); their median local
/// variance, calibrated by `white_noise_median_to_mean(l)`, is the bin's value.
/// Binning by luma means dark bins are measured on dark samples: shadows are never
/// judged flat or textured by the bright parts' standard. Bins more than 30% above
/// their level's fitted line are texture and dropped (one-sided). The low-pass is
/// not identifiable from one frame (it is the image itself) and is left out.
pub fn fit_fast(image: &Rgb, neighbour: Option<&super::Neighbour>, samples_per_level: usize) -> (Noise, NoisePlotData) {
    let started = Instant::now();
    let mut st = super::Stages::start();
    // With an aligned neighbour (another exposure of the same scene): the band-pass
    // levels of D = I − I' per channel (0 where the alignment does not hold; samples
    // whose footprint holds more than `MAX_INVALID_FRACTION` of such pixels are
    // skipped), so that each flat sample reads B(b·b_D) = B(b²) − B(b·b'): the two
    // exposures' noise is independent, their texture the same, so the product with
    // the neighbour's band cancels the texture and keeps the noise (see `fit_fast`).
    let (fw, fh) = (image.width, image.height);
    let neighbour = neighbour.filter(|n| (n.image.width, n.image.height) == (fw, fh));
    let cross: Option<Vec<Vec<Plane>>> = neighbour.map(|n| {
        (0..3)
            .into_par_iter()
            .map(|c| {
                let d: Vec<f32> = image.channels[c]
                    .iter()
                    .zip(&n.image.channels[c])
                    .zip(&n.valid.data)
                    .map(|((a, b), v)| if *v > 0.5 { a - b } else { 0.0 })
                    .collect();
                channel_pyramids(&d, fw, fh, NOISE_LEVELS).1
            })
            .collect()
    });
    st.lap("blur.neighbour");
    // One Gaussian pyramid per channel, levels 0..=L+2, and its band-pass levels
    // 0..L+2. Everything the fit reads of the luma follows by linearity (luma is a
    // fixed weighted sum of the channels, and reduce/expand are linear), so no luma
    // pyramid is built: G_Y[l] = Σ w_c G_c[l]; the smoothed luma used for binning
    // level l (I's own luma carries the noise) is expand(G_Y[l+1]) = Σ w_c (G_c[l] −
    // band_c[l]); level l's structure measure is the luma band l+2 = Σ w_c band_c[l+2].
    // Level 0 is the frame's own channel (borrowed, not copied).
    let pyr: Vec<(Vec<Plane>, Vec<Plane>)> =
        (0..3).into_par_iter().map(|c| channel_pyramids(&image.channels[c], fw, fh, NOISE_LEVELS + 2)).collect();
    st.lap("blur.pyramids");
    let luma_of = |c: [&[f32]; 3], like: &Plane| -> Plane {
        let w = crate::image::LUMA_WEIGHTS;
        let mut out: Vec<f32> = c[0].iter().map(|v| w[0] * v).collect();
        for k in 1..3 {
            out.iter_mut().zip(c[k]).for_each(|(o, v)| *o += w[k] * v);
        }
        Plane::from_vec(like.width, like.height, out)
    };
    // pyr[c].0[l] is G_c[l + 1].
    let gauss = |l: usize| -> [&[f32]; 3] {
        std::array::from_fn(|c| if l == 0 { &image.channels[c][..] } else { &pyr[c].0[l - 1].data[..] })
    };
    let band = |l: usize| -> [&Plane; 3] { std::array::from_fn(|c| &pyr[c].1[l]) };
    // expand(G_Y[l+1]) from the coarse luma (reduce is linear): one plane expanded
    // instead of six level-l planes read (`blur.luma` 2.3 → 1.6 ms at 1280×960, the
    // same values to rounding).
    let smooth: Vec<Plane> = (0..NOISE_LEVELS)
        .into_par_iter()
        .map(|l| {
            let like = &pyr[0].1[l];
            crate::image::expand(&luma_of(gauss(l + 1), &pyr[0].0[l]), like.width, like.height)
        })
        .collect();
    let structure: Vec<Plane> =
        (2..NOISE_LEVELS + 2).into_par_iter().map(|k| luma_of(band(k).map(|b| &b.data[..]), &pyr[0].1[k])).collect();
    let bands: Vec<Vec<Plane>> = pyr.into_iter().map(|(_, b)| b.into_iter().take(NOISE_LEVELS).collect()).collect();
    st.lap("blur.luma");
    let blocking = detect_blocking(image, &structure[0], 4);
    st.lap("search.blocking");
    // About `samples_per_level` grid points per level whatever the frame size
    // (`level_stride`).
    let stride0 = ((image.len() as f64 / samples_per_level.max(1) as f64).sqrt() as f32).max(BLIND_STRIDE_PX as f32);
    let (limits, clip) = blind_clip_masks(image, 8);
    // Where the neighbour's alignment fails: one table for all channels.
    let misaligned = neighbour.map(|n| clip_mask_of(image, &limits, 8, Some(n.valid), &[]));
    st.lap("search.clipping");
    let measured: Vec<Vec<BinMeasure>> = (0..NOISE_LEVELS)
        .into_par_iter()
        .map(|l| {
            let cross = cross.as_deref().zip(misaligned.as_ref());
            measure_level(l, &bands, cross, &smooth[l], &structure[l], &clip, stride0)
        })
        .collect();
    st.lap("search.samples");
    // Levels with fewer than 3 usable bins (tiny or fully textured frames) cannot be
    // fitted on their own: they follow the finest measured level by white-noise band
    // ratios, and the reason says so.
    // Levels are measured finest first. A level stops being identifiable where the
    // frame's flattest samples are texture rather than noise: with fewer than 3 flat
    // bins, or when its median std over the bins it shares with the finer level
    // exceeds `MAX_LEVEL_STD_RATIO` times that level's (camera noise falls toward
    // coarse levels, texture does not). It and every coarser level then follow the
    // finest measured level by the measured per-level decay (the two finest measured
    // levels' excess over white, see below) or, with one level, the white-noise
    // ratios; the reason names them.
    let (mut points, mut measured_levels, mut derived): (Vec<LevelPoints>, Vec<usize>, Vec<usize>) =
        (vec![], vec![], vec![]);
    let mut prev: Option<Vec<&BinMeasure>> = None;
    let mut level0_untrimmed = false;
    for (l, bins) in measured.iter().enumerate() {
        // A level whose bins no line explains (fewer than 3 agree) is texture, not
        // noise: measured on the calibration video (Motorcycle, 320×240), keeping
        // every bin there let levels 1–3 read 5–20× the truth on 1 frame in 5.
        // Level 0 keeps its bins (its samples are the most numerous, and without
        // it there is no map at all); the reason says it was not trimmed.
        let (bins, untrimmed) = match trim_textured(bins) {
            Some(b) => (b, false),
            None if l == 0 => (bins.iter().collect(), true),
            None => (vec![], true),
        };
        if untrimmed && l == 0 {
            level0_untrimmed = true;
        }
        let grows = prev.as_ref().is_some_and(|p| median_std_ratio(&bins, p).map_or(true, |r| r > MAX_LEVEL_STD_RATIO));
        // Level 0 may stand on fewer than 3 bins (a narrow-luma frame); coarser ones not.
        let too_few = bins.is_empty() || (l > 0 && bins.len() < 3);
        if !derived.is_empty() || grows || too_few {
            derived.push(l);
            continue;
        }
        measured_levels.push(l);
        points.push(LevelPoints {
            y: bins.iter().map(|b| b.y).collect(),
            y2: bins.iter().map(|b| b.y2).collect(),
            own: None,
            var: std::array::from_fn(|c| bins.iter().map(|b| b.var[c]).collect()),
            weights: Some(bins.iter().map(|b| b.n as f32).collect()),
        });
        prev = Some(bins);
    }
    let fitted =
        if measured_levels.first() == Some(&0) { fit_levels(&points, NoiseIntensity::Luma, true) } else { None };
    let fitted = fitted.map(|LevelFit { form, intensity, levels: lv, covs, rel_res, nll }| {
        let unit = crate::synth::unit_band_std();
        let last = lv.len() - 1;
        // Beyond the finest measured levels: white noise's per-level ratios, scaled
        // by how much slower than white the two finest measured levels decayed
        // (correlated noise decays slower; at most `MAX_LEVEL_STD_RATIO` per level).
        let excess = if lv.len() >= 2 {
            let s = |i: usize| {
                (0..3)
                    .map(|c| lv[i].std(form, c, luma_span(&points[i].y).map_or(0.5, |[lo, hi]| 0.5 * (lo + hi))))
                    .sum::<f32>()
            };
            let (m1, m0) = (measured_levels[last], measured_levels[last - 1]);
            (s(last) / s(last - 1).max(1e-12)) / (unit[m1] / unit[m0])
        } else {
            1.0
        };
        let levels = (0..NOISE_LEVELS)
            .map(|l| match measured_levels.iter().position(|&m| m == l) {
                Some(i) => lv[i],
                None => {
                    let from = measured_levels[last];
                    let r: f32 =
                        (from + 1..=l).map(|k| (excess * unit[k] / unit[k - 1]).min(MAX_LEVEL_STD_RATIO)).product();
                    let k = if form == NoiseForm::LinearStd { r } else { r * r };
                    NoiseLevel { slope: lv[last].slope.map(|v| v * k), intercept: lv[last].intercept.map(|v| v * k) }
                }
            })
            .collect();
        LevelFit { form, intensity, levels, covs, rel_res, nll }
    });
    // The luma range is what level 0's used bins cover: no value outside it.
    let y0 = points.first().map(|p| p.y.clone()).unwrap_or_default();
    let range = luma_span(&y0).unwrap_or([0.0, 1.0]);
    let samples: Vec<LevelSamples> = points
        .iter()
        .map(|p| LevelSamples { y: p.y.clone(), y2: p.y2.clone(), own: None, var: p.var.clone() })
        .collect();
    st.lap("least_squares");
    let samples_used: usize = points.iter().flat_map(|p| p.weights.iter().flatten()).map(|&w| w as usize).sum();
    let mut noise = finish("fast", started, fitted, &samples, range, false);
    noise.diagnostics.samples_used = samples_used as u64;
    noise.diagnostics.stages_s = st.done();
    // Confidence per luma bin (level 0): every measured bin, whether the fit used it.
    let used0: Vec<f32> = points.first().map(|p| p.y.clone()).unwrap_or_default();
    noise.bins = measured[0]
        .iter()
        .map(|b| crate::model::NoiseBin {
            luma: b.y,
            samples: b.n as u32,
            std: b.var.map(|v| v.max(0.0).sqrt()),
            relative_stderr: b.rel_se,
            used: used0.contains(&b.y),
        })
        .collect();
    if noise.present && level0_untrimmed {
        noise.diagnostics.reason +=
            "; level 0's luma bins agree with no common line (3 or more within 1.2× in variance): \
             all were used, texture may be counted as noise";
    }
    if noise.present && !derived.is_empty() {
        noise.diagnostics.reason += &format!(
            "; levels {derived:?} not identifiable from this frame (texture exceeds the noise there, or too few flat luma bins): \
             they continue the finest measured level by the measured per-level decay"
        );
    }
    if let Some(b) = blocking {
        noise.diagnostics.reason += &format!(
            "; compression blocking: {} px grid at phase ({}, {}), boundary steps {:.2}× the interior's — the fine levels hold codec artefacts, not only sensor noise",
            b.period_px, b.phase_px[0], b.phase_px[1], b.strength
        );
    }
    noise.blocking = blocking;
    (noise, plot_data(&points))
}

/// One channel's Gaussian pyramid G[1..=levels] (`.0[l]` is G[l + 1]; G[0] is
/// `data` itself, not copied) and its band-pass levels 0..levels, by the clamp-free
/// interior `reduce`/`expand`.
fn channel_pyramids(data: &[f32], w: usize, h: usize, levels: usize) -> (Vec<Plane>, Vec<Plane>) {
    let g = gaussian_pyramid(&crate::image::reduce_slice(data, w, h), levels);
    let bands = (0..levels)
        .map(|l| {
            let (fine, fw, fh) =
                if l == 0 { (data, w, h) } else { (&g[l - 1].data[..], g[l - 1].width, g[l - 1].height) };
            let mut b = crate::image::expand(&g[l], fw, fh);
            for (v, gv) in b.data.iter_mut().zip(fine) {
                *v = gv - *v;
            }
            b
        })
        .collect();
    (g, bands)
}

/// The lowest and highest of the lumas `y` (`None` when empty).
fn luma_span(y: &[f32]) -> Option<[f32; 2]> {
    let lo = y.iter().cloned().reduce(f32::min)?;
    let hi = y.iter().cloned().reduce(f32::max)?;
    Some([lo, hi])
}

/// Median over the luma bins two levels share of the coarse level's std over the
/// fine level's (channel-pooled); `None` when they share no bin.
fn median_std_ratio(coarse: &[&BinMeasure], fine: &[&BinMeasure]) -> Option<f32> {
    let std = |b: &BinMeasure| (b.var.iter().sum::<f32>() / 3.0).max(0.0).sqrt();
    let mut r: Vec<f32> = coarse
        .iter()
        .filter_map(|c| {
            let bin = (c.y * BLIND_BINS as f32) as usize;
            fine.iter().find(|f| (f.y * BLIND_BINS as f32) as usize == bin).map(|f| std(c) / std(f).max(1e-12))
        })
        .collect();
    (!r.is_empty()).then(|| percentile(&mut r, 0.5))
}

/// The blind tier's sample stride at level `l`: about `n` samples per level
/// (`stride0` = √(pixels / n), at least `BLIND_STRIDE_PX`; n =
/// `FitOptions::noise_fast_samples_per_level`), the level-0 stride rounded down and
/// coarser ones to the nearest (n = 10 000 at 1280×960: 11, 6, 3, 1; at 20 000: 7,
/// 4, 2, 1) — halving an integer stride instead gave level 2 of a 1280×960 frame
/// 77 000 samples at stride 1, 4× the others and 40% of the search.
fn level_stride(stride0: f32, l: usize) -> usize {
    if l == 0 {
        stride0 as usize
    } else {
        ((stride0 / (1u32 << l) as f32).round() as usize).max(1)
    }
}

/// Per-bin measurements of level `l` (see `fit_fast`).
fn measure_level(
    l: usize,
    bands: &[Vec<Plane>],
    cross: Option<(&[Vec<Plane>], &ClipMask)>,
    luma: &Plane,
    structure: &Plane,
    clip: &[ClipMask; 3],
    stride0: f32,
) -> Vec<BinMeasure> {
    let scale = 1usize << l;
    let stride = level_stride(stride0, l);
    let win = SepWindow::new(l);
    // The structure energy (window mean of the squared structure band) of every
    // structure pixel, by one separable blur: at the coarse levels many samples
    // share a structure pixel, and 18 taps per pixel beat 81 per sample.
    let energy = {
        let sq = Plane::from_vec(structure.width, structure.height, structure.data.iter().map(|v| v * v).collect());
        crate::image::blur_separable(&sq, &window_1d((l + 2).min(3)))
    };
    // Footprint of the measured band in level-0 pixels (as in `collect_samples`); clipping
    // under the structure band only makes a sample look textured, it biases nothing.
    let radius = 5 * scale + 8;
    let (w, h) = (luma.width, luma.height);
    // (x, y, B(Y), B(Y²), structure, unclipped-channel bits)
    type Sample = (usize, usize, f32, f32, f32, u8);
    let mut pts: Vec<Sample> = vec![];
    for y in grid(h, stride) {
        for x in grid(w, stride) {
            let ok = (0..3).fold(0u8, |m, c| m | ((!clip[c].touches(x * scale, y * scale, radius, l >= 2) as u8) << c));
            if ok == 0 || cross.is_some_and(|(_, bad)| bad.touches(x * scale, y * scale, radius, l >= 2)) {
                continue;
            }
            let s = energy.get((x / 4).min(energy.width - 1), (y / 4).min(energy.height - 1));
            let (m1, m2) = win.moments(luma, x, y);
            pts.push((x, y, m1, m2, s, ok));
        }
    }
    let m2m = white_noise_median_to_mean(l);
    let mut out = vec![];
    // The samples of luma bin b, [b/16, (b + 1)/16), in grid order: one pass over
    // them all (a filter per bin read every sample 16 times). BLIND_BINS is a power
    // of two, so ⌊16·y⌋ is exact and the bins are the comparisons' bins.
    const _: () = assert!(BLIND_BINS.is_power_of_two());
    let mut bins: Vec<Vec<&Sample>> = vec![vec![]; BLIND_BINS];
    for p in &pts {
        // y ≥ 0 (NaN fails): truncation is the floor, without a libm call.
        if p.2 >= 0.0 {
            let b = (p.2 * BLIND_BINS as f32) as usize;
            if b < BLIND_BINS {
                bins[b].push(p);
            }
        }
    }
    for mut bin in bins {
        bin.sort_by(|a, b| a.4.total_cmp(&b.4));
        // Each channel's flat set: the flattest fraction of the bin's samples where
        // that channel is unclipped; the bin counts when every channel has one.
        let flats: [Vec<_>; 3] = std::array::from_fn(|c| {
            let mine: Vec<_> = bin.iter().filter(|p| p.5 & (1 << c) != 0).copied().collect();
            let k = (mine.len() as f64 * BLIND_FLAT_FRACTION).ceil() as usize;
            if mine.len() < BLIND_MIN_PER_BIN || k < BLIND_MIN_FLAT {
                vec![]
            } else {
                mine[..k].to_vec()
            }
        });
        if flats.iter().any(|f| f.is_empty()) {
            continue;
        }
        let flat = &flats[1];
        let n = flat.len() as f32;
        let mut var = [0.0f32; 3];
        let mut rel_se = 0.0f32;
        for c in 0..3 {
            let n = flats[c].len() as f32;
            // With a neighbour — level 0: B(b·b_D), first order in a texture mismatch
            // between the exposures but free of the alignment's low-pass; coarser
            // levels: B(b_D²) / (1 + κ_l), the texture mismatch entering squared, κ_l
            // the alignment's noise transmission (≈ 1 there). Measured on the
            // calibration video (BENCHMARKS.md): the product at every level reads
            // levels 1–3 2–5× high while the head turns (the exposures' motion blur
            // differs, and texture dwarfs the noise there).
            if let Some((cross, _)) = cross.filter(|_| l == 0) {
                let v: Vec<f32> =
                    flats[c].iter().map(|p| win.mean_prod(&bands[c][l], &cross[c][l], p.0, p.1)).collect();
                let (mean, se) = mean_se(&v);
                var[c] = mean;
                rel_se += if mean > 0.0 { se / (2.0 * mean) / 3.0 } else { 1.0 / 3.0 };
                continue;
            }
            let (plane, gain) = match cross {
                Some((d, _)) => (&d[c][l], 1.0 + bicubic_noise_transmission(l)),
                None => (&bands[c][l], 1.0),
            };
            let mut v: Vec<f32> = flats[c].iter().map(|p| win.mean_sq(plane, p.0, p.1)).collect();
            let med = percentile(&mut v, 0.5);
            let iqr = percentile(&mut v, 0.75) - percentile(&mut v, 0.25);
            var[c] = med / m2m / gain;
            // SE of a median: 1.2533·sd/√n with sd from the IQR; half of it in std terms.
            rel_se += if med > 0.0 { 1.2533 * iqr / 1.349 / n.sqrt() / (2.0 * med) / 3.0 } else { 1.0 / 3.0 };
        }
        out.push(BinMeasure {
            y: flat.iter().map(|p| p.2).sum::<f32>() / n,
            y2: flat.iter().map(|p| p.3).sum::<f32>() / n,
            var,
            n: flat.len(),
            rel_se,
        });
    }
    out
}

/// One-sided robust line: texture leaking into a bin only raises it, so the noise is
/// the *lower envelope* of the bins. Every line through two bins (channel-pooled
/// variance) is scored by the bins it explains — within [1/1.2, 1.2]× — and rejected
/// outright when a bin lies below 0.7× it (noise cannot be lower than itself); the
/// best line's inliers are kept (ties: the lower line). A plain refit-and-trim loop
/// fails on real frames whose dark half is all texture (the vtest lawn: its bins
/// pull the first line up so far that the flat road's bins look like outliers).
/// Fewer than 4 bins are kept as they are; `None` when no line explains 3 of 4 or
/// more (the bins scatter: texture, not a noise map).
fn trim_textured(bins: &[BinMeasure]) -> Option<Vec<&BinMeasure>> {
    if bins.len() < 4 {
        return Some(bins.iter().collect());
    }
    let v: Vec<f64> = bins.iter().map(|b| b.var.iter().map(|&x| x as f64).sum::<f64>() / 3.0).collect();
    let y: Vec<f64> = bins.iter().map(|b| b.y as f64).collect();
    let mut best: Option<(usize, f64, Vec<bool>)> = None;
    for i in 0..bins.len() {
        for j in i..bins.len() {
            // j == i: the flat line through one bin.
            let slope = if j == i || (y[j] - y[i]).abs() < 1e-6 { 0.0 } else { (v[j] - v[i]) / (y[j] - y[i]) };
            let line = |k: usize| v[i] + slope * (y[k] - y[i]);
            if (0..bins.len()).any(|k| line(k) <= 0.0 || v[k] < 0.7 * line(k)) {
                continue;
            }
            let inl: Vec<bool> = (0..bins.len()).map(|k| v[k] <= 1.2 * line(k) && v[k] >= line(k) / 1.2).collect();
            let count = inl.iter().filter(|&&x| x).count();
            let level: f64 = (0..bins.len()).map(line).sum();
            let better = match &best {
                None => true,
                Some((c, l, _)) => count > *c || (count == *c && level < *l),
            };
            if better {
                best = Some((count, level, inl));
            }
        }
    }
    match best {
        Some((count, _, inl)) if count >= 3 => Some(bins.iter().zip(inl).filter(|(_, k)| *k).map(|(b, _)| b).collect()),
        _ => None,
    }
}

#[cfg(test)]
mod valid_mask_tests {
    use super::*;

    /// The one-pass lane-wise extremes and counts are the plain two-pass ones:
    /// extremes repeated in different lanes, restarted counts, a tail shorter than
    /// the lanes, an extreme seen only in the tail, and unclipped data (exact).
    #[test]
    fn one_pass_clip_limits_are_the_two_pass_ones() {
        let naive = |ch: &[f32], min_count: usize| {
            let lo = ch.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = ch.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let (nlo, nhi) = (ch.iter().filter(|&&v| v == lo).count(), ch.iter().filter(|&&v| v == hi).count());
            ((lo <= 0.1 && nlo >= min_count).then_some(lo), (hi >= 0.6 && nhi >= min_count).then_some(hi))
        };
        let wavy =
            |n: usize| -> Vec<f32> { (0..n).map(|i| 0.5 + 0.45 * ((i * 7919 % 1013) as f32 / 1013.0 - 0.5)).collect() };
        let mut cases: Vec<Vec<f32>> = vec![wavy(1003), wavy(5), vec![]];
        // Clipped at both ends, in several lanes, with decoys before the clip level.
        let mut clipped = wavy(2051);
        for i in (0..2051).step_by(13) {
            clipped[i] = 1.0;
        }
        for i in (3..2051).step_by(17) {
            clipped[i] = 0.0;
        }
        cases.push(clipped.clone());
        // The maximum seen only in the tail.
        clipped[2050] = 1.5;
        cases.push(clipped);
        for ch in &cases {
            for min_count in [1, 2, 50, 10_000] {
                assert_eq!(
                    channel_clip_limits(ch, min_count),
                    naive(ch, min_count),
                    "len {} min {min_count}",
                    ch.len()
                );
            }
        }
    }

    /// The blind tier's one-pass tile extremes give exactly `clip_limits` and each
    /// channel's `clip_mask_of`: frames whose size is no multiple of the tile
    /// (partial tiles at the right and bottom), clipped at both ends in some
    /// channels, clipped too rarely to count (below 0.05%), and unclipped; the
    /// masks compared through `touches` at every tile and radius the fit uses.
    #[test]
    fn tile_extreme_clip_masks_are_the_two_pass_ones() {
        for (w, h) in [(83usize, 61usize), (64, 48), (9, 7)] {
            let mut img = Rgb::new(w, h, [0.0; 3]);
            for c in 0..3 {
                for (i, v) in img.channels[c].iter_mut().enumerate() {
                    *v = 0.3 + 0.4 * (((i * (7919 + c * 13)) % 1013) as f32 / 1013.0);
                }
            }
            // Red clipped high in a blob and low along a row; green clipped high at
            // two pixels only (too rare for large frames); blue untouched.
            for y in h / 3..h / 2 {
                for x in w / 2..w.min(w / 2 + 11) {
                    img.channels[0][y * w + x] = 1.0;
                }
            }
            for x in 0..w / 3 {
                img.channels[0][(h - 1) * w + x] = 0.0;
            }
            img.channels[1][w + 1] = 1.0;
            img.channels[1][w * h - 1] = 1.0;
            let limits = clip_limits(&img);
            let (fused, masks) = blind_clip_masks(&img, 8);
            assert_eq!(fused, limits, "{w}×{h}");
            for c in 0..3 {
                let reference = clip_mask_of(&img, &limits, 8, None, &[c]);
                for y in (0..h).step_by(3) {
                    for x in (0..w).step_by(3) {
                        for r in [0, 5, 13, 40] {
                            for coarse in [false, true] {
                                assert_eq!(
                                    masks[c].touches(x, y, r, coarse),
                                    reference.touches(x, y, r, coarse),
                                    "{w}×{h} channel {c} at ({x}, {y}) r {r}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// A reference that does not hold in a 2-px border and a 12-px square: the
    /// noise fit skips samples whose footprint holds more than 2% of such pixels
    /// and still recovers the noise (within 5%; 1.1% with a clean reference
    /// everywhere: the mask costs samples, not accuracy);
    /// the invalid pixels hold garbage (0.5 of a grey) that would ruin the fit if
    /// used.
    #[test]
    fn invalid_reference_pixels_are_skipped() {
        let (w, h) = (320, 240);
        // A luma ramp 0.2 … 0.8, so the per-luma map is identifiable.
        let mut clean = Rgb::new(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    clean.channels[c][y * w + x] = 0.2 + 0.6 * x as f32 / (w - 1) as f32;
                }
            }
        }
        let truth = crate::synth::white_sensor_noise([1e-4; 3], [4e-4; 3], [0.0, 1.0]);
        let noisy = crate::synth::add_noise(&clean, &truth, 3);
        let mut reference = clean.clone();
        let mut valid = Plane::new(w, h, 1.0);
        for y in 0..h {
            for x in 0..w {
                let border = x < 2 || y < 2 || x >= w - 2 || y >= h - 2;
                let square = (150..162).contains(&x) && (100..112).contains(&y);
                if border || square {
                    valid.data[y * w + x] = 0.0;
                    for c in 0..3 {
                        reference.channels[c][y * w + x] = 0.0;
                    }
                }
            }
        }
        let (fitted, _) = fit_accurate(&noisy, &reference, Some(&valid), &Default::default());
        assert!(fitted.present, "{}", fitted.diagnostics.reason);
        let e = crate::model::compare::noise_relative_error(&fitted, &truth).expect("present");
        assert!(e < 0.05, "median relative error {e}");
    }
}

#[cfg(test)]
mod leakage_tests {
    use super::*;

    /// Random grey tiles (16 px, 0.2 … 0.8, 1-px linear ramps between them)
    /// sampled at x + `dx`: the edges are what a misregistered reference leaves
    /// behind.
    fn tiles(w: usize, h: usize, dx: f32) -> Rgb {
        let tile = |tx: i64, ty: i64| {
            let v = crate::synth::gaussian(tx as u32, ty as u32, 0, 0x711e);
            0.5 + 0.3 * (v / 3.0).clamp(-1.0, 1.0)
        };
        let at = |x: f32, y: f32| {
            // Ramps, not steps: a sub-pixel shift then moves the edge by exactly dx.
            let (fx, fy) = (x / 16.0, y / 16.0);
            let (tx, ty) = (fx.floor() as i64, fy.floor() as i64);
            let (ux, uy) = (((fx - tx as f32) * 16.0).min(1.0), ((fy - ty as f32) * 16.0).min(1.0));
            let a = tile(tx - 1, ty - 1) * (1.0 - ux) + tile(tx, ty - 1) * ux;
            let b = tile(tx - 1, ty) * (1.0 - ux) + tile(tx, ty) * ux;
            a * (1.0 - uy) + b * uy
        };
        let mut img = Rgb::new(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                let v = at(x as f32 + 32.0 + dx, y as f32 + 32.0);
                for c in 0..3 {
                    img.channels[c][y * w + x] = v;
                }
            }
        }
        img
    }

    /// A reference misregistered by 0.3 px leaves the tiles' edges in I − I_noNoise:
    /// least squares reads them as noise (+122% median error, measured with the
    /// leak test off), the median samples do not follow: the fit reports the leak,
    /// and where asked to refuse (`FitOptions::noise_min_leak_ratio`) says "not
    /// identifiable". A registered reference reports no leak and reads the noise
    /// within 3% (the fit's known answer on white noise; ~1% measured).
    #[test]
    fn a_misregistered_reference_is_reported_or_refused_a_registered_one_is_not() {
        let (w, h) = (320, 240);
        let clean = tiles(w, h, 0.0);
        let truth = crate::synth::white_sensor_noise([4e-5; 3], [1.6e-4; 3], [0.0, 1.0]);
        let noisy = crate::synth::add_noise(&clean, &truth, 5);
        let (registered, _) = fit_accurate(&noisy, &clean, None, &Default::default());
        assert!(registered.present, "{}", registered.diagnostics.reason);
        assert!(!registered.diagnostics.reason.contains("leak"), "{}", registered.diagnostics.reason);
        let e = crate::model::compare::noise_relative_error(&registered, &truth).expect("present");
        assert!(e < 0.03, "registered: median relative error {e}");

        let refuse = crate::fit::FitOptions { noise_min_leak_ratio: Some(MIN_LEAK_RATIO), ..Default::default() };
        let (kept, _) = fit_accurate(&noisy, &tiles(w, h, 0.3), None, &Default::default());
        assert!(kept.present && kept.diagnostics.reason.contains("leak"), "{}", kept.diagnostics.reason);
        let (fit, _) = fit_accurate(&noisy, &tiles(w, h, 0.3), None, &refuse);
        assert_eq!(fit.diagnostics.status, Status::NotIdentifiable, "{}", fit.diagnostics.reason);
        assert!(!fit.present);
        assert!(fit.diagnostics.reason.contains("image structure"), "{}", fit.diagnostics.reason);
    }
}
