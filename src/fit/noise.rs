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
//! Blind (`fit_fast`): level-0 statistics of I alone at its flattest samples per luma
//! bin, coarser levels by white-noise band ratios; the low-pass is not identifiable
//! from one frame (it is the image itself) and is left out.
//!
//! Present when the level-0 std at mid-range luma exceeds 3 standard errors and
//! 1e-4 (0.026/255: far below visibility).

use crate::image::{gaussian_pyramid, laplacian_pyramid, IntegralImage, Plane, Rgb};
use crate::model::{Diagnostics, Noise, NoiseForm, NoiseLevel, Status, NOISE_LEVELS};
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
/// The blind tier's finest level-0 grid: only 20% of its samples are kept (the
/// flattest), so it samples denser than the accurate tier.
const BLIND_STRIDE_PX: usize = 4;
const BLIND_BINS: usize = 16;
const BLIND_MIN_PER_BIN: usize = 24;

/// Regression data of one level: window moments of luma B(Y), B(Y²), per-channel
/// local variance, optional per-sample weights.
#[derive(Clone, Default)]
struct LevelPoints {
    y: Vec<f32>,
    y2: Vec<f32>,
    var: [Vec<f32>; 3],
    weights: Option<Vec<f32>>,
}
/// Chosen form, per-level maps, per-level per-channel OLS covariance, mean relative residual.
type LevelFit = (NoiseForm, Vec<NoiseLevel>, Vec<[[[f64; 2]; 2]; 3]>, f64);

/// Samples behind the noise plot: per level (4 = low-pass), luma and per-channel std.
#[derive(Clone, Debug, Default)]
pub struct NoisePlotData {
    pub levels: Vec<(Vec<f32>, [Vec<f32>; 3])>,
}

/// 9×9 window weights with σ = 4/2^l, normalised.
fn window(level: usize) -> [[f32; 9]; 9] {
    let s = 4.0 / (1u32 << level) as f32;
    let mut w = [[0.0f32; 9]; 9];
    let mut sum = 0.0;
    for (j, row) in w.iter_mut().enumerate() {
        for (i, v) in row.iter_mut().enumerate() {
            let (dx, dy) = (i as f32 - 4.0, j as f32 - 4.0);
            *v = (-(dx * dx + dy * dy) / (2.0 * s * s)).exp();
            sum += *v;
        }
    }
    w.iter_mut().flatten().for_each(|v| *v /= sum);
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

/// Grid positions at a level: stride max(1, stride0 >> l), offset half a stride.
fn grid(len: usize, stride: usize) -> impl Iterator<Item = usize> {
    ((stride / 2).min(len.saturating_sub(1) / 2)..len).step_by(stride)
}

/// Per-level samples: luma and local variance per channel, clipped footprints out.
struct LevelSamples {
    y: Vec<f32>,
    y2: Vec<f32>,
    var: [Vec<f32>; 3],
}

fn collect_samples(
    bands: &[Vec<Plane>; 3], // [channel][level 0..=4]
    luma: &[Plane],          // Gaussian pyramid 0..=4
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
            let mut out = LevelSamples { y: vec![], y2: vec![], var: [vec![], vec![], vec![]] };
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
fn fit_levels(points: &[LevelPoints]) -> Option<LevelFit> {
    let mut affine = vec![NoiseLevel::ZERO; points.len()];
    let mut linear = vec![NoiseLevel::ZERO; points.len()];
    let mut covs = vec![[[[0.0; 2]; 2]; 3]; points.len()];
    let (mut nll_aff, mut nll_lin, mut rel_aff, mut rel_lin) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (l, pts) in points.iter().enumerate() {
        let (y, y2, wts) = (&pts.y, &pts.y2, &pts.weights);
        for c in 0..3 {
            let v = &pts.var[c];
            // Affine variance: v ≈ a + b·y.
            let (mut a, mut b, _, mut cov) = ols(y, v, wts.as_deref())?;
            for _ in 0..3 {
                let pred: Vec<f64> = y.iter().map(|&yi| a + b * yi as f64).collect();
                let w = precision_weights(&pred, wts.as_deref());
                (a, b, _, cov) = ols(y, v, Some(&w))?;
            }
            let pred_aff: Vec<f64> = y.iter().map(|&yi| a + b * yi as f64).collect();
            affine[l].intercept[c] = a as f32;
            affine[l].slope[c] = b as f32;
            covs[l][c] = cov;
            nll_aff += neg2_log_likelihood(v, &pred_aff);
            // Linear std: v ≈ (a + b·y)².
            let lin_pred = |a: f64, b: f64| -> Vec<f64> {
                (0..y.len()).map(|i| a * a + 2.0 * a * b * y[i] as f64 + b * b * y2[i] as f64).collect()
            };
            let (mut la, mut lb, _) = fit_linear_std(y, y2, v, wts.as_deref())?;
            for _ in 0..3 {
                let w = precision_weights(&lin_pred(la, lb), wts.as_deref());
                (la, lb, _) = fit_linear_std(y, y2, v, Some(&w))?;
            }
            let pred_lin = lin_pred(la, lb);
            nll_lin += neg2_log_likelihood(v, &pred_lin);
            // Keep std non-negative at the reference point: (a + b·y)² is symmetric
            // in sign, so flip to the branch with a positive std.
            let ym = y.iter().sum::<f32>() / y.len().max(1) as f32;
            let (la, lb) = if la + lb * ym as f64 >= 0.0 { (la, lb) } else { (-la, -lb) };
            linear[l].intercept[c] = la as f32;
            linear[l].slope[c] = lb as f32;
            let rel = |pred: &[f64]| {
                v.iter().zip(pred).map(|(&vi, &p)| (vi as f64 - p).powi(2)).sum::<f64>()
                    / v.iter().map(|&vi| (vi as f64).powi(2)).sum::<f64>().max(1e-300)
            };
            rel_aff += rel(&pred_aff);
            rel_lin += rel(&pred_lin);
        }
    }
    let m = (3 * points.len()) as f64;
    if nll_lin < nll_aff {
        Some((NoiseForm::LinearStd, linear, covs, rel_lin / m))
    } else {
        Some((NoiseForm::AffineVariance, affine, covs, rel_aff / m))
    }
}

/// Clipped pixels: a channel is clipped at its maximum (minimum) when that exact
/// value repeats in at least 0.05% of the pixels (and 2) and is bright, ≥ 0.6
/// (dark, ≤ 0.1). This finds 8-bit 255s, 16-bit 65535s and float frames clipped at
/// any white level, while unclipped float frames (over- and undershoot included)
/// have no repeated extreme and lose nothing.
fn clip_mask(img: &Rgb, block: usize, valid: Option<&Plane>) -> ClipMask {
    let n = img.len();
    let min_count = (n / 2000).max(2);
    // One pass per channel: extremes and how often each occurs.
    let limits: Vec<(Option<f32>, Option<f32>)> = img
        .channels
        .iter()
        .map(|ch| {
            let (mut lo, mut hi, mut nlo, mut nhi) = (f32::INFINITY, f32::NEG_INFINITY, 0usize, 0usize);
            for &v in ch {
                if v < lo {
                    (lo, nlo) = (v, 1);
                } else if v == lo {
                    nlo += 1;
                }
                if v > hi {
                    (hi, nhi) = (v, 1);
                } else if v == hi {
                    nhi += 1;
                }
            }
            ((lo <= 0.1 && nlo >= min_count).then_some(lo), (hi >= 0.6 && nhi >= min_count).then_some(hi))
        })
        .collect();
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
    if limits.iter().all(|l| l.0.is_none() && l.1.is_none()) {
        return ClipMask { clipped: None, invalid };
    }
    // Mark block×block tiles holding any clipped pixel; footprint tests then run on
    // the tile grid (conservative by up to one tile). The accurate tier uses 1 (exact),
    // the blind tier 8 (a 1/64-size table; it can afford to lose border samples).
    let (bw, bh) = (img.width.div_ceil(block), img.height.div_ceil(block));
    let mut blocks = Plane::new(bw, bh, 0.0);
    for i in 0..n {
        let clipped = (0..3).any(|c| {
            let v = img.channels[c][i];
            limits[c].0 == Some(v) || limits[c].1 == Some(v)
        });
        if clipped {
            let (x, y) = (i % img.width, i / img.width);
            blocks.data[(y / block) * bw + x / block] = 1.0;
        }
    }
    ClipMask { clipped: Some((IntegralImage::new(&blocks), block)), invalid }
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
    let Some((form, mut levels, covs, rel_res)) = fitted else {
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
        levels,
        lowpass,
        luminance_range: luma_range,
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
            "level-0 std {std_mid:.5} at luma {ym:.2} (±{:.2}%); form {form:?} (mean relative residual {rel_res:.4}, chosen by likelihood); \
             residuals are mean squared local-variance errors at level 0",
            100.0 * rel
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

fn luma_range(samples: &LevelSamples) -> [f32; 2] {
    let mut y = samples.y.clone();
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
    let luma = gaussian_pyramid(&denoised.luma(), NOISE_LEVELS);
    st.lap("blur");
    let stride = effective_stride(image.len(), opts.noise_stride_px);
    let samples = collect_samples(&bands, &luma, &clip_mask(image, 1, valid), stride);
    st.lap("search");
    // The low-pass residual is fitted when it has unclipped samples (its footprint
    // is ~90 px wide, so frames with large clipped areas may leave none).
    let usable = if samples[NOISE_LEVELS].y.is_empty() { NOISE_LEVELS } else { NOISE_LEVELS + 1 };
    let points: Vec<LevelPoints> = samples
        .iter()
        .take(usable)
        .map(|s| LevelPoints { y: s.y.clone(), y2: s.y2.clone(), var: s.var.clone(), weights: None })
        .collect();
    let fitted = if points.iter().all(|p| !p.y.is_empty()) { fit_levels(&points) } else { None };
    st.lap("least_squares");
    let range = luma_range(&samples[0]);
    let mut noise = finish("accurate", started, fitted, &samples, range, true);
    noise.diagnostics.stages_s = st.done();
    (noise, plot_data(&points))
}

/// Median / mean of level-0 local variances (9×9, σ = 4 window) of white noise:
/// texture leaking into the "flat" set only ever adds variance, and a median
/// ignores a minority of such samples where a mean does not. Measured once on a
/// 256×256×3 field (relative standard error ≈ 0.3%).
fn white_noise_median_to_mean() -> f32 {
    static R: std::sync::OnceLock<f32> = std::sync::OnceLock::new();
    *R.get_or_init(|| {
        let n = 256usize;
        let mut v = vec![];
        let mut sum = 0.0f64;
        let win = window(0);
        for c in 0..3u32 {
            let data = (0..n * n).map(|i| crate::synth::gaussian((i % n) as u32, (i / n) as u32, c, 0xb1d)).collect();
            let band = laplacian_pyramid(&Plane::from_vec(n, n, data), 1).bands.swap_remove(0);
            for y in grid(n, 4) {
                for x in grid(n, 4) {
                    let m = local_mean_sq(&band, x, y, &win);
                    sum += m as f64;
                    v.push(m);
                }
            }
        }
        let mean = (sum / v.len() as f64) as f32;
        percentile(&mut v, 0.5) / mean
    })
}

/// Fast tier: the frame alone.
///
/// Only level 0 is measured: coarser bands of a textured frame are dominated by the
/// scene, and one frame cannot tell coarse noise from texture. Flat samples are the
/// 20% with the least level-2 luma band energy in their luma bin (their median
/// variance, calibrated by `white_noise_median_to_mean`); that band is
/// (nearly) uncorrelated with level-0 noise, so selecting on it does not bias the
/// level-0 variance the way picking the lowest variances would. Levels 1–3 follow
/// from level 0 by the white-noise band ratios c_l/c_0 (`synth::unit_band_std`): an
/// assumption (ISP-correlated noise breaks it) stated in the README.
pub fn fit_fast(image: &Rgb) -> (Noise, NoisePlotData) {
    let started = Instant::now();
    let mut st = super::Stages::start();
    // Only level 0 of each channel is needed: band = x − expand(reduce(x)).
    let bands: Vec<Plane> =
        (0..3).into_par_iter().map(|c| laplacian_pyramid(&image.plane(c), 1).bands.swap_remove(0)).collect();
    // Luma Gaussian pyramid 0..=3: level 1 (expanded) is the smoothed luma used for
    // binning, since I's own luma carries the noise; band 2 = G2 − expand(G3) is the
    // structure measure.
    let gp = gaussian_pyramid(&image.luma(), 3);
    let luma0 = crate::image::expand(&gp[1], gp[0].width, gp[0].height);
    let mut band2 = crate::image::expand(&gp[3], gp[2].width, gp[2].height);
    for (b, g) in band2.data.iter_mut().zip(&gp[2].data) {
        *b = g - *b;
    }
    st.lap("blur");
    // About 20 000 grid points whatever the frame size (4 px at 512², 8 px at 1280×960).
    let stride0 = ((image.len() as f64 / 20_000.0).sqrt() as usize).max(BLIND_STRIDE_PX);
    let clip = clip_mask(image, 8, None);
    let win0 = window(0);
    let win2 = window(2);
    // Phase 1, cheap: (B(Y), B(Y²), structure) at level-0 grid points with
    // unclipped footprints. Phase 2 computes the three channel variances only for
    // the flattest BLIND_FLAT_FRACTION of each luma bin.
    let mut pts: Vec<(usize, usize, f32, f32, f32)> = vec![];
    for y in grid(image.height, stride0) {
        for x in grid(image.width, stride0) {
            if clip.touches(x, y, 5 * 4 + 8, false) {
                continue;
            }
            let structure = local_mean_sq(&band2, (x / 4).min(band2.width - 1), (y / 4).min(band2.height - 1), &win2);
            pts.push((x, y, local_mean(&luma0, x, y, &win0), local_mean_sq(&luma0, x, y, &win0), structure));
        }
    }
    st.lap("search");
    let median_to_mean = white_noise_median_to_mean();
    let (mut ys, mut y2s, mut vs, mut ws) = (vec![], vec![], [vec![], vec![], vec![]], vec![]);
    for b in 0..BLIND_BINS {
        let (lo, hi) = (b as f32 / BLIND_BINS as f32, (b + 1) as f32 / BLIND_BINS as f32);
        let mut bin: Vec<&(usize, usize, f32, f32, f32)> = pts.iter().filter(|p| p.2 >= lo && p.2 < hi).collect();
        if bin.len() < BLIND_MIN_PER_BIN {
            continue;
        }
        bin.sort_by(|a, b| a.4.total_cmp(&b.4));
        let flat = &bin[..(bin.len() as f64 * BLIND_FLAT_FRACTION).ceil() as usize];
        let n = flat.len() as f32;
        ys.push(flat.iter().map(|p| p.2).sum::<f32>() / n);
        y2s.push(flat.iter().map(|p| p.3).sum::<f32>() / n);
        ws.push(n);
        for c in 0..3 {
            let mut v: Vec<f32> = flat.iter().map(|p| local_mean_sq(&bands[c], p.0, p.1, &win0)).collect();
            vs[c].push(percentile(&mut v, 0.5) / median_to_mean);
        }
    }
    // One-sided trimming: texture leaking into a bin only raises it, so bins more
    // than 30% above the affine-variance line (any channel) are dropped and the
    // line refitted, up to 3 rounds, keeping at least 3 bins.
    for _ in 0..3 {
        if ys.len() <= 3 {
            break;
        }
        let lines: Vec<_> = (0..3).filter_map(|c| ols(&ys, &vs[c], Some(&ws))).collect();
        if lines.len() < 3 {
            break;
        }
        let keep: Vec<bool> = (0..ys.len())
            .map(|i| (0..3).all(|c| vs[c][i] as f64 <= 1.3 * (lines[c].0 + lines[c].1 * ys[i] as f64).max(1e-12)))
            .collect();
        if keep.iter().all(|&k| k) || keep.iter().filter(|&&k| k).count() < 3 {
            break;
        }
        let filt = |v: &Vec<f32>| v.iter().zip(&keep).filter(|(_, &k)| k).map(|(x, _)| *x).collect::<Vec<f32>>();
        ys = filt(&ys);
        y2s = filt(&y2s);
        ws = filt(&ws);
        vs = [filt(&vs[0]), filt(&vs[1]), filt(&vs[2])];
    }
    let samples_used = ws.iter().sum::<f32>() as usize;
    let points = vec![LevelPoints { y: ys, y2: y2s, var: vs, weights: Some(ws) }];
    let fitted = if points[0].y.is_empty() { None } else { fit_levels(&points) };
    let fitted = fitted.map(|(form, lv, covs, rel)| {
        let unit = crate::synth::unit_band_std();
        let levels = (0..NOISE_LEVELS)
            .map(|l| {
                let r = unit[l] / unit[0];
                let k = if form == NoiseForm::LinearStd { r } else { r * r };
                NoiseLevel { slope: lv[0].slope.map(|v| v * k), intercept: lv[0].intercept.map(|v| v * k) }
            })
            .collect();
        (form, levels, covs, rel)
    });
    let y = &points[0].y;
    let range = if y.is_empty() {
        [0.0, 1.0]
    } else {
        let lo = y.iter().cloned().fold(1.0f32, f32::min);
        let hi = y.iter().cloned().fold(0.0f32, f32::max);
        [lo, hi.max(lo)]
    };
    let level0 = LevelSamples { y: y.clone(), y2: points[0].y2.clone(), var: points[0].var.clone() };
    st.lap("least_squares");
    let mut noise = finish("fast", started, fitted, &[level0], range, false);
    noise.diagnostics.samples_used = samples_used as u64;
    noise.diagnostics.stages_s = st.done();
    (noise, plot_data(&points))
}

#[cfg(test)]
mod valid_mask_tests {
    use super::*;

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
