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
//!   paper's linear-std form is fitted by Gauss–Newton on variance; the affine
//!   variance form (Poisson–Gaussian) by ordinary least squares; the form with the
//!   smaller relative residual is kept;
//! * the low-pass residual is fitted like a band (the paper drops it);
//! * the regressor is the window-averaged luma B(Y), matching the pooled variance;
//! * samples whose footprint touches a clipped pixel (any channel ≤ 0.5/255 or
//!   ≥ 1 − 0.5/255 in I) are excluded; the luma range of the used samples is recorded.
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

/// Sample stride at level 0. The paper's 32 leaves (512/32)² = 256 samples per
/// level at 512²; with ~60 effective samples per 9×9 window each variance sample has
/// ~18% error, giving ~1% error on the fitted std. 8 px (4096 samples) brings that
/// to ~0.3% for a negligible cost (see BENCHMARKS.md).
pub const DEFAULT_STRIDE_PX: usize = 8;
const CLIP_LO: f32 = 0.5 / 255.0;
const CLIP_HI: f32 = 1.0 - 0.5 / 255.0;
const BLIND_FLAT_FRACTION: f64 = 0.2;
const BLIND_BINS: usize = 16;
const BLIND_MIN_PER_BIN: usize = 24;

/// Per level: luma, per-channel local variance, optional per-sample weights.
type LevelPoints = (Vec<f32>, [Vec<f32>; 3], Option<Vec<f32>>);
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

#[inline]
fn local_mean(p: &Plane, x: usize, y: usize, w: &[[f32; 9]; 9]) -> f32 {
    let mut acc = 0.0;
    for (j, row) in w.iter().enumerate() {
        let yy = y as isize + j as isize - 4;
        for (i, wt) in row.iter().enumerate() {
            acc += wt * p.get_clamped(x as isize + i as isize - 4, yy);
        }
    }
    acc
}

#[inline]
fn local_mean_sq(p: &Plane, x: usize, y: usize, w: &[[f32; 9]; 9]) -> f32 {
    let mut acc = 0.0;
    for (j, row) in w.iter().enumerate() {
        let yy = y as isize + j as isize - 4;
        for (i, wt) in row.iter().enumerate() {
            let v = p.get_clamped(x as isize + i as isize - 4, yy);
            acc += wt * v * v;
        }
    }
    acc
}

/// Grid positions at a level: stride max(1, stride0 >> l), offset half a stride.
fn grid(len: usize, stride: usize) -> impl Iterator<Item = usize> {
    ((stride / 2).min(len.saturating_sub(1) / 2)..len).step_by(stride)
}

/// Per-level samples: luma and local variance per channel, clipped footprints out.
struct LevelSamples {
    y: Vec<f32>,
    var: [Vec<f32>; 3],
}

fn collect_samples(
    bands: &[Vec<Plane>; 3], // [channel][level 0..=4]
    luma: &[Plane],          // Gaussian pyramid 0..=4
    clip: &IntegralImage,
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
                var: [vec![], vec![], vec![]],
            };
            for y in grid(band0.height, stride) {
                for x in grid(band0.width, stride) {
                    let (x0, y0) = (
                        (x * scale).min(clip.width() - 1),
                        (y * scale).min(clip.height() - 1),
                    );
                    if clip.box_sum(x0, y0, radius) > 0.0 {
                        continue;
                    }
                    // Window-averaged luma: the window pools noise whose variance is
                    // affine in Y, so B(var) = a + b·B(Y) exactly — regressing on the
                    // point luma instead biases dark samples near bright ones.
                    out.y.push(local_mean(&luma[l], x, y, &win));
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
    let (a, b) = if det.abs() > 1e-12 * sw * sw {
        let b = (sw * syv - sy * sv) / det;
        ((sv - b * sy) / sw, b)
    } else {
        // All samples at one luma: a constant is all the data can say.
        (sv / sw, 0.0)
    };
    let ssr: f64 = (0..n)
        .map(|i| wts.map_or(1.0, |w| w[i] as f64) * (v[i] as f64 - a - b * y[i] as f64).powi(2))
        .sum();
    let s2 = ssr / (n as f64 - 2.0).max(1.0) / (sw / n as f64);
    let cov = if det.abs() > 1e-12 * sw * sw {
        [
            [s2 * syy / det, -s2 * sy / det],
            [-s2 * sy / det, s2 * sw / det],
        ]
    } else {
        [[s2 / sw, 0.0], [0.0, 0.0]]
    };
    Some((a, b, ssr, cov))
}

/// Gauss–Newton for v ≈ (a + b·y)², started from OLS of √v on y.
fn fit_linear_std(y: &[f32], v: &[f32], wts: Option<&[f32]>) -> Option<(f64, f64, f64)> {
    let sq: Vec<f32> = v.iter().map(|&x| x.max(0.0).sqrt()).collect();
    let (mut a, mut b, _, _) = ols(y, &sq, wts)?;
    let w = |i: usize| wts.map_or(1.0, |w| w[i] as f64);
    for _ in 0..30 {
        let (mut jtj, mut jtr) = ([[0.0f64; 2]; 2], [0.0f64; 2]);
        for i in 0..y.len() {
            let s = a + b * y[i] as f64;
            let r = v[i] as f64 - s * s;
            let j = [2.0 * s, 2.0 * s * y[i] as f64];
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
    let ssr = (0..y.len())
        .map(|i| w(i) * (v[i] as f64 - (a + b * y[i] as f64).powi(2)).powi(2))
        .sum();
    (a.is_finite() && b.is_finite()).then_some((a, b, ssr))
}

/// Per-level fits in both forms; keeps the form with the smaller relative residual.
/// `points`: per level (luma, per-channel variance, optional weights).
fn fit_levels(points: &[LevelPoints]) -> Option<LevelFit> {
    let mut affine = vec![NoiseLevel::ZERO; points.len()];
    let mut linear = vec![NoiseLevel::ZERO; points.len()];
    let mut covs = vec![[[[0.0; 2]; 2]; 3]; points.len()];
    let (mut rel_aff, mut rel_lin, mut llr) = (0.0f64, 0.0f64, 0.0f64);
    for (l, (y, var, wts)) in points.iter().enumerate() {
        for c in 0..3 {
            let norm: f64 = var[c]
                .iter()
                .map(|&v| (v as f64).powi(2))
                .sum::<f64>()
                .max(1e-300);
            let (a, b, ssr, cov) = ols(y, &var[c], wts.as_deref())?;
            affine[l].intercept[c] = a as f32;
            affine[l].slope[c] = b as f32;
            covs[l][c] = cov;
            rel_aff += ssr / norm;
            let ssr_aff = ssr;
            let (la, lb, lssr) = fit_linear_std(y, &var[c], wts.as_deref())?;
            // Keep std non-negative at the reference point: (a + b·y)² is symmetric
            // in sign, so flip to the branch with a positive std.
            let ym = y.iter().sum::<f32>() / y.len().max(1) as f32;
            let (la, lb) = if la + lb * ym as f64 >= 0.0 {
                (la, lb)
            } else {
                (-la, -lb)
            };
            linear[l].intercept[c] = la as f32;
            linear[l].slope[c] = lb as f32;
            rel_lin += lssr / norm;
            // Gaussian log-likelihood ratio of the two 2-parameter fits: n·ln(SSR ratio).
            // It weighs each level by its sample count, not by how noisy its local
            // variances are, and is the standard criterion for equal-size models.
            if ssr_aff > 0.0 && lssr > 0.0 {
                llr += y.len() as f64 * (lssr / ssr_aff).ln();
            }
        }
    }
    let m = (3 * points.len()) as f64;
    if llr < 0.0 {
        Some((NoiseForm::LinearStd, linear, covs, rel_lin / m))
    } else {
        Some((NoiseForm::AffineVariance, affine, covs, rel_aff / m))
    }
}

fn clip_mask(img: &Rgb) -> IntegralImage {
    let data = (0..img.len())
        .map(|i| {
            let clipped = (0..3).any(|c| {
                let v = img.channels[c][i];
                v <= CLIP_LO || v >= CLIP_HI
            });
            clipped as u8 as f32
        })
        .collect();
    IntegralImage::new(&Plane::from_vec(img.width, img.height, data))
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
    let lowpass = if with_lowpass && levels.len() > NOISE_LEVELS {
        Some(levels[NOISE_LEVELS])
    } else {
        None
    };
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
        let var_se = (cov[0][0] + 2.0 * ym * cov[0][1] + ym * ym * cov[1][1])
            .max(0.0)
            .sqrt();
        let s = noise.levels[0].std(form, c, ym as f32) as f64;
        std_mid += s / 3.0;
        rel += if s > 0.0 {
            var_se / (2.0 * s * s) / 3.0
        } else {
            f64::INFINITY
        };
    }
    let before: f64 = samples[0]
        .var
        .iter()
        .flatten()
        .map(|&v| (v as f64).powi(2))
        .sum::<f64>()
        / (3 * samples[0].y.len()).max(1) as f64;
    let present =
        std_mid > 1e-4 && rel.is_finite() && std_mid * (1.0 - 3.0 * rel) > 0.0 && rel < 1.0 / 3.0;
    let status = if present {
        Status::Present
    } else {
        Status::Absent
    };
    let reason = if present {
        format!(
            "level-0 std {std_mid:.5} at luma {ym:.2} (±{:.2}%); form {form:?} (mean relative residual {rel_res:.4}, chosen by likelihood ratio); \
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
        },
        ..noise
    }
}

fn plot_data(points: &[LevelPoints]) -> NoisePlotData {
    NoisePlotData {
        levels: points
            .iter()
            .map(|(y, v, _)| {
                let s = |c: usize| v[c].iter().map(|x| x.max(0.0).sqrt()).collect::<Vec<_>>();
                (y.clone(), [s(0), s(1), s(2)])
            })
            .collect(),
    }
}

fn luma_range(samples: &LevelSamples) -> [f32; 2] {
    let mut y = samples.y.clone();
    if y.is_empty() {
        return [0.0, 1.0];
    }
    let lo = percentile(&mut y, 0.005);
    let hi = percentile(&mut y, 0.995);
    [
        lo.clamp(0.0, 1.0),
        hi.clamp(0.0, 1.0).max(lo.clamp(0.0, 1.0)),
    ]
}

/// Accurate tier: I and I_noNoise.
pub fn fit_accurate(
    image: &Rgb,
    denoised: &Rgb,
    opts: &super::FitOptions,
) -> (Noise, NoisePlotData) {
    let started = Instant::now();
    let residual = Rgb {
        width: image.width,
        height: image.height,
        channels: std::array::from_fn(|c| {
            image.channels[c]
                .iter()
                .zip(&denoised.channels[c])
                .map(|(a, b)| a - b)
                .collect()
        }),
    };
    let bands = pyramids(&residual);
    let luma = gaussian_pyramid(&denoised.luma(), NOISE_LEVELS);
    let samples = collect_samples(&bands, &luma, &clip_mask(image), opts.noise_stride_px);
    // The low-pass residual is fitted when it has unclipped samples (its footprint
    // is ~90 px wide, so frames with large clipped areas may leave none).
    let usable = if samples[NOISE_LEVELS].y.is_empty() {
        NOISE_LEVELS
    } else {
        NOISE_LEVELS + 1
    };
    let points: Vec<_> = samples
        .iter()
        .take(usable)
        .map(|s| (s.y.clone(), s.var.clone(), None))
        .collect();
    let fitted = if points.iter().all(|p| !p.0.is_empty()) {
        fit_levels(&points)
    } else {
        None
    };
    let range = luma_range(&samples[0]);
    (
        finish("accurate", started, fitted, &samples, range, true),
        plot_data(&points),
    )
}

/// Fast tier: the frame alone.
///
/// Only level 0 is measured: coarser bands of a textured frame are dominated by the
/// scene, and one frame cannot tell coarse noise from texture. Flat samples are the
/// 20% with the least level-2 luma band energy in their luma bin; that band is
/// (nearly) uncorrelated with level-0 noise, so selecting on it does not bias the
/// level-0 variance the way picking the lowest variances would. Levels 1–3 follow
/// from level 0 by the white-noise band ratios c_l/c_0 (`synth::unit_band_std`): an
/// assumption (ISP-correlated noise breaks it) stated in the README.
pub fn fit_fast(image: &Rgb, opts: &super::FitOptions) -> (Noise, NoisePlotData) {
    let started = Instant::now();
    let bands = pyramids(image);
    let luma_bands = laplacian_pyramid(&image.luma(), 3);
    // Bin by a smoothed luma (one level coarser), since I's own luma carries the noise.
    let gp = gaussian_pyramid(&image.luma(), 1);
    let luma0 = crate::image::expand(&gp[1], gp[0].width, gp[0].height);
    let luma: Vec<Plane> = vec![luma0; NOISE_LEVELS + 1];
    let stride0 = (opts.noise_stride_px / 2).max(1);
    let clip = clip_mask(image);
    let win0 = window(0);
    let win2 = window(2);
    let band2 = &luma_bands.bands[2];
    // (luma, structure, var r, g, b) at level-0 grid points with unclipped footprints.
    let mut pts: Vec<(f32, f32, [f32; 3])> = vec![];
    for y in grid(image.height, stride0) {
        for x in grid(image.width, stride0) {
            if clip.box_sum(x, y, 5 * 4 + 8) > 0.0 {
                continue;
            }
            let structure = local_mean_sq(
                band2,
                (x / 4).min(band2.width - 1),
                (y / 4).min(band2.height - 1),
                &win2,
            );
            let v = std::array::from_fn(|c| local_mean_sq(&bands[c][0], x, y, &win0));
            pts.push((local_mean(&luma[0], x, y, &win0), structure, v));
        }
    }
    let (mut ys, mut vs, mut ws) = (vec![], [vec![], vec![], vec![]], vec![]);
    for b in 0..BLIND_BINS {
        let (lo, hi) = (
            b as f32 / BLIND_BINS as f32,
            (b + 1) as f32 / BLIND_BINS as f32,
        );
        let mut bin: Vec<&(f32, f32, [f32; 3])> =
            pts.iter().filter(|p| p.0 >= lo && p.0 < hi).collect();
        if bin.len() < BLIND_MIN_PER_BIN {
            continue;
        }
        bin.sort_by(|a, b| a.1.total_cmp(&b.1));
        let flat = &bin[..(bin.len() as f64 * BLIND_FLAT_FRACTION).ceil() as usize];
        let n = flat.len() as f32;
        ys.push(flat.iter().map(|p| p.0).sum::<f32>() / n);
        ws.push(n);
        for c in 0..3 {
            vs[c].push(flat.iter().map(|p| p.2[c]).sum::<f32>() / n);
        }
    }
    let samples_used = ws.iter().sum::<f32>() as usize;
    let points = vec![(ys, vs, Some(ws))];
    let fitted = if points[0].0.is_empty() {
        None
    } else {
        fit_levels(&points)
    };
    let fitted = fitted.map(|(form, lv, covs, rel)| {
        let unit = crate::synth::unit_band_std();
        let levels = (0..NOISE_LEVELS)
            .map(|l| {
                let r = unit[l] / unit[0];
                let k = if form == NoiseForm::LinearStd {
                    r
                } else {
                    r * r
                };
                NoiseLevel {
                    slope: lv[0].slope.map(|v| v * k),
                    intercept: lv[0].intercept.map(|v| v * k),
                }
            })
            .collect();
        (form, levels, covs, rel)
    });
    let range = match points.first() {
        Some((y, _, _)) if !y.is_empty() => {
            let lo = y.iter().cloned().fold(1.0f32, f32::min);
            let hi = y.iter().cloned().fold(0.0f32, f32::max);
            [lo, hi.max(lo)]
        }
        _ => [0.0, 1.0],
    };
    let level0 = LevelSamples {
        y: points[0].0.clone(),
        var: points[0].1.clone(),
    };
    let mut noise = finish("fast", started, fitted, &[level0], range, false);
    noise.diagnostics.samples_used = samples_used as u64;
    (noise, plot_data(&points))
}
