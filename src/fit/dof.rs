//! Depth of field δ(Z), accurate and blind.
//!
//! Accurate (paper eq. 4 and its three stages): (1) per-pixel σ search over
//! [0, 10] px; (2) textureless pixels rejected; (3) robust fit of δ(Z) (`curve`).
//! Stage 1 runs on luma (DoF blur is linear and achromatic, so it commutes with
//! luma) over the same cascaded discrete-Gaussian stack `synth::add_defocus` uses,
//! with nodes every `node_spacing` px. Between nodes S_k, S_{k+1} the blend weight
//! that best explains a 3×3 patch of I is closed-form,
//! w = ⟨I − S_k, S_{k+1} − S_k⟩ / |S_{k+1} − S_k|², clamped to [0, 1], and
//! σ² = σ_k² + w(σ_{k+1}² − σ_k²): a continuous σ, not a 0.1 px grid, and one pass
//! over the stack instead of 100 blurs.
//!
//! Textureless rule: a sample is kept when the mean squared luma gradient of the
//! sharp image over its 3×3 patch is ≥ 1e-4 (a 1%-per-pixel ramp) — below that the
//! patch looks the same at every σ. Pixels with invalid depth (non-finite, or ≤ 0
//! for metric depth) are skipped.
//!
//! Present when the fitted curve reaches ≥ 0.1 px somewhere in the range (a 0.1 px
//! Gaussian removes 5% of the contrast at Nyquist: invisible) and its maximum
//! exceeds 3 standard errors.
//!
//! Blind (Zhuo & Sim 2011): at edges (gradient-magnitude maxima along the gradient,
//! ≥ 0.03 per px), re-blur with σ0 = 3 px; for a Gaussian-blurred step the gradient
//! ratio R = |∇I| / |∇(I ∗ G_σ0)| gives σ = σ0/√(R² − 1). The central difference
//! and pixel sampling bias that formula at small σ, so the raw value is mapped
//! through a table from a 1-D simulation of ideally sampled blurred steps (sub-pixel
//! phases averaged): an estimator calibration, not a camera calibration.

use super::curve::fit_dof_curve;
use crate::image::{blur_separable, discrete_gaussian_kernel, gradient_sq, Plane, Rgb};
use crate::model::{DepthOfField, DepthUnits, Diagnostics, Status};
use crate::synth::for_each_cascade_interval;
use std::sync::OnceLock;
use std::time::Instant;

/// Node spacing of the fitting stack. 0.5 px keeps the stack 2× cheaper than the
/// synth reference's 0.25 px; the variance-matched blend makes the mismatch a
/// higher-order effect (measured in tests/validation.rs and BENCHMARKS.md).
pub const DEFAULT_NODE_SPACING_PX: f32 = 0.5;
const TEXTURE_MIN_GRAD_SQ: f32 = 1e-4;
const SAMPLE_STRIDE: usize = 3;
const MIN_SAMPLES: usize = 32;

#[derive(Clone, Debug, Default)]
pub struct DofPlotData {
    pub depth: Vec<f32>,
    pub sigma_px: Vec<f32>,
    pub quadratic: Option<crate::model::DofCurve>,
    pub thin_lens: Option<crate::model::DofCurve>,
}

fn valid_depth(z: f32, units: DepthUnits) -> bool {
    z.is_finite() && (units == DepthUnits::RelativeInverse || z > 0.0)
}

fn depth_range(z: &[f32]) -> [f32; 2] {
    let lo = z.iter().cloned().fold(f32::INFINITY, f32::min);
    let hi = z.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    [lo, hi]
}

/// Turn per-pixel (Z, σ) into the model; `residuals` = (before, after) if known.
#[allow(clippy::too_many_arguments)]
fn finish(
    method: &str,
    z: Vec<f32>,
    s: Vec<f32>,
    units: DepthUnits,
    started: Instant,
    residual_at: impl Fn(&DepthOfField) -> Option<(f64, f64)>,
) -> (DepthOfField, Option<DofPlotData>) {
    let n = z.len();
    if n < MIN_SAMPLES {
        let reason = format!(
            "only {n} textured pixels with valid depth (need {MIN_SAMPLES}): δ(Z) not identifiable"
        );
        let mut d = super::not_identifiable(method, reason, started);
        d.samples_used = n as u64;
        return (DepthOfField::absent(units, d), None);
    }
    let range = depth_range(&z);
    let Some(fit) = fit_dof_curve(&z, &s, units, range) else {
        let mut d = super::not_identifiable(
            method,
            "robust depth-model fit failed (degenerate design)",
            started,
        );
        d.samples_used = n as u64;
        return (DepthOfField::absent(units, d), None);
    };
    let mut dof = DepthOfField {
        present: true,
        units,
        curve: Some(fit.curve),
        depth_range: range,
        diagnostics: Diagnostics::not_fitted(""),
    };
    let max_sigma = (0..=64)
        .map(|i| dof.sigma_px(range[0] + (range[1] - range[0]) * i as f32 / 64.0))
        .fold(0.0f32, f32::max);
    let present = max_sigma >= 0.1 && (max_sigma as f64) > 3.0 * fit.stderr_px;
    let residuals = residual_at(&dof);
    let form = match fit.curve {
        crate::model::DofCurve::Quadratic { .. } => "quadratic",
        crate::model::DofCurve::ThinLens { .. } => "thin_lens",
        crate::model::DofCurve::Constant { .. } => "constant",
    };
    dof.present = present;
    dof.diagnostics = Diagnostics {
        status: if present { Status::Present } else { Status::Absent },
        reason: format!(
            "{form} kept (lower mean Huber loss, thin lens on ties; flat curves become constants); max δ {max_sigma:.3} px, \
             robust residual scale {:.3} px; {}",
            fit.scale,
            if present { "visible (≥ 0.1 px) and above 3 standard errors" } else { "below 0.1 px or within 3 standard errors" }
        ),
        method: method.into(),
        residual_before: residuals.map(|r| r.0),
        residual_after: residuals.map(|r| r.1),
        samples_used: n as u64,
        fit_time_s: started.elapsed().as_secs_f64(),
        stderr: Some(fit.stderr_px),
    };
    let plot = DofPlotData {
        depth: z,
        sigma_px: s,
        quadratic: fit.quadratic,
        thin_lens: fit.thin_lens,
    };
    (dof, Some(plot))
}

/// Per-sample sufficient statistics per stack interval, so that the residual at any
/// σ (the fitted curve's) can be evaluated after the fit: Σa², Σa·d, Σd².
struct IntervalStats {
    aa: Vec<f32>,
    ad: Vec<f32>,
    dd: Vec<f32>,
}

/// Accurate tier: I, I_noDoF and Z.
pub fn fit_accurate(
    image: &Rgb,
    sharp: &Rgb,
    depth: &Plane,
    units: DepthUnits,
    opts: &super::FitOptions,
) -> (DepthOfField, Option<DofPlotData>) {
    let started = Instant::now();
    let (yi, ys) = (image.luma(), sharp.luma());
    let grad = gradient_sq(&ys);
    let (w, h) = (yi.width, yi.height);
    // Sample centres on a stride grid; each owns a 3×3 patch.
    let mut centres = vec![];
    for y in (1..h.saturating_sub(1)).step_by(SAMPLE_STRIDE) {
        for x in (1..w.saturating_sub(1)).step_by(SAMPLE_STRIDE) {
            let z = depth.get(x, y);
            if !valid_depth(z, units) {
                continue;
            }
            let g: f32 = (0..9)
                .map(|k| grad.get(x + k % 3 - 1, y + k / 3 - 1))
                .sum::<f32>()
                / 9.0;
            if g >= TEXTURE_MIN_GRAD_SQ {
                centres.push((x, y));
            }
        }
    }
    let n = centres.len();
    let spacing = opts.dof_node_spacing_px;
    let intervals = (opts.dof_max_sigma_px / spacing).ceil() as usize;
    let mut stats = IntervalStats {
        aa: vec![0.0; n * intervals],
        ad: vec![0.0; n * intervals],
        dd: vec![0.0; n * intervals],
    };
    if n >= MIN_SAMPLES {
        for_each_cascade_interval(&ys, spacing, opts.dof_max_sigma_px, |k, _, _, a, b| {
            for (s, &(x, y)) in centres.iter().enumerate() {
                let (mut aa, mut ad, mut dd) = (0.0f32, 0.0f32, 0.0f32);
                for j in y - 1..=y + 1 {
                    for i in x - 1..=x + 1 {
                        let idx = j * w + i;
                        let av = yi.data[idx] - a.data[idx];
                        let dv = b.data[idx] - a.data[idx];
                        aa += av * av;
                        ad += av * dv;
                        dd += dv * dv;
                    }
                }
                let o = s * intervals + k;
                stats.aa[o] = aa;
                stats.ad[o] = ad;
                stats.dd[o] = dd;
            }
        });
    }
    // Residual of sample s at σ, from its interval's statistics.
    let residual = |s: usize, sigma: f32| -> f32 {
        let k = ((sigma / spacing).floor() as usize).min(intervals - 1);
        let (s0, s1) = (k as f32 * spacing, (k + 1) as f32 * spacing);
        let wgt = ((sigma * sigma - s0 * s0) / (s1 * s1 - s0 * s0)).clamp(0.0, 1.0);
        let o = s * intervals + k;
        (stats.aa[o] - 2.0 * wgt * stats.ad[o] + wgt * wgt * stats.dd[o]).max(0.0)
    };
    let mut zs = Vec::with_capacity(n);
    let mut sig = Vec::with_capacity(n);
    for (s, &(x, y)) in centres.iter().enumerate() {
        let mut best = (f32::INFINITY, 0.0f32);
        for k in 0..intervals {
            let o = s * intervals + k;
            let wgt = if stats.dd[o] > 1e-12 {
                (stats.ad[o] / stats.dd[o]).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let r = stats.aa[o] - 2.0 * wgt * stats.ad[o] + wgt * wgt * stats.dd[o];
            if r < best.0 {
                let (s0, s1) = (k as f32 * spacing, (k + 1) as f32 * spacing);
                best = (r, (s0 * s0 + wgt * (s1 * s1 - s0 * s0)).sqrt());
            }
        }
        zs.push(depth.get(x, y));
        sig.push(best.1);
    }
    let residual_at = |dof: &DepthOfField| -> Option<(f64, f64)> {
        let (mut before, mut after) = (0.0f64, 0.0f64);
        for s in 0..n {
            before += residual(s, 0.0) as f64;
            after += residual(s, dof.sigma_px(zs[s])) as f64;
        }
        let m = (9 * n).max(1) as f64;
        Some((before / m, after / m))
    };
    finish("accurate", zs.clone(), sig, units, started, residual_at)
}

/// Raw Zhuo–Sim estimate → true σ, from a 1-D simulation (see module docs).
fn zhuo_sim_table() -> &'static Vec<(f32, f32)> {
    static T: OnceLock<Vec<(f32, f32)>> = OnceLock::new();
    T.get_or_init(|| {
        let n = 96usize;
        let k0 = discrete_gaussian_kernel(ZS_SIGMA0 * ZS_SIGMA0);
        let mut table = vec![];
        for i in 0..=220 {
            let sigma = i as f32 * 0.05;
            let mut raw_sum = 0.0;
            let phases = [0.0f32, 0.25, 0.5, 0.75];
            for &ph in &phases {
                // Pixel-integrated step at n/2 + ph blurred by a Gaussian of std σ,
                // sampled at pixel centres (erf profile).
                let data: Vec<f32> = (0..n)
                    .map(|x| {
                        let d = x as f32 - (n as f32 / 2.0 + ph);
                        if sigma < 1e-3 {
                            (d > 0.0) as u8 as f32
                        } else {
                            0.5 * (1.0 + erf(d / (sigma * std::f32::consts::SQRT_2)))
                        }
                    })
                    .collect();
                let p = Plane::from_vec(n, 1, data);
                let re = blur_separable(&p, &k0);
                let g = |q: &Plane| {
                    (1..n - 1)
                        .map(|x| 0.5 * (q.get(x + 1, 0) - q.get(x - 1, 0)))
                        .fold(0.0f32, f32::max)
                };
                let r = g(&p) / g(&re);
                raw_sum += ZS_SIGMA0 / (r * r - 1.0).max(1e-6).sqrt();
            }
            table.push((raw_sum / phases.len() as f32, sigma));
        }
        table
    })
}

const ZS_SIGMA0: f32 = 3.0;

/// Abramowitz–Stegun 7.1.26 (|error| < 1.5e-7), enough for a calibration table.
fn erf(x: f32) -> f32 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let y = 1.0
        - (((((1.061_405_4 * t - 1.453_152_1) * t) + 1.421_413_8) * t - 0.284_496_74) * t
            + 0.254_829_6)
            * t
            * (-x * x).exp();
    y.copysign(x)
}

fn calibrate(raw: f32) -> f32 {
    let t = zhuo_sim_table();
    // The table is monotone in σ; interpolate raw → σ.
    if raw <= t[0].0 {
        return 0.0;
    }
    for win in t.windows(2) {
        let ((r0, s0), (r1, s1)) = (win[0], win[1]);
        if raw >= r0.min(r1) && raw <= r0.max(r1) && (r1 - r0).abs() > 1e-9 {
            return s0 + (s1 - s0) * (raw - r0) / (r1 - r0);
        }
    }
    t[t.len() - 1].1
}

/// Fast tier: the frame and Z (Zhuo & Sim 2011 edge re-blur ratio).
pub fn fit_fast(
    image: &Rgb,
    depth: &Plane,
    units: DepthUnits,
    opts: &super::FitOptions,
) -> (DepthOfField, Option<DofPlotData>) {
    let started = Instant::now();
    let y = image.luma();
    let re = blur_separable(&y, &discrete_gaussian_kernel(ZS_SIGMA0 * ZS_SIGMA0));
    let (w, h) = (y.width, y.height);
    let grad = |p: &Plane, x: usize, yy: usize| -> (f32, f32) {
        (
            0.5 * (p.get(x + 1, yy) - p.get(x - 1, yy)),
            0.5 * (p.get(x, yy + 1) - p.get(x, yy - 1)),
        )
    };
    let (mut zs, mut sig) = (vec![], vec![]);
    for py in 2..h.saturating_sub(2) {
        for px in 2..w.saturating_sub(2) {
            let z = depth.get(px, py);
            if !valid_depth(z, units) {
                continue;
            }
            let (gx, gy) = grad(&y, px, py);
            let m = (gx * gx + gy * gy).sqrt();
            if m < 0.03 {
                continue;
            }
            // Non-maximum suppression along the (rounded) gradient direction.
            let (sx, sy) = ((gx / m).round() as isize, (gy / m).round() as isize);
            let mag = |x: isize, yy: isize| {
                let (a, b) = grad(&y, x as usize, yy as usize);
                (a * a + b * b).sqrt()
            };
            let (xi, yi) = (px as isize, py as isize);
            if m < mag(xi + sx, yi + sy) || m < mag(xi - sx, yi - sy) {
                continue;
            }
            let (rx, ry) = grad(&re, px, py);
            let mr = (rx * rx + ry * ry).sqrt();
            if mr <= 0.0 {
                continue;
            }
            let r = m / mr;
            if r <= 1.0 {
                continue;
            }
            let raw = ZS_SIGMA0 / (r * r - 1.0).sqrt();
            sig.push(calibrate(raw).min(opts.dof_max_sigma_px));
            zs.push(z);
        }
    }
    finish("fast", zs, sig, units, started, |_| None)
}
