//! Depth of field δ(Z), accurate and blind.
//!
//! Accurate (paper eq. 4 and its three stages): (1) per-pixel σ search over
//! [0, 10] px; (2) textureless pixels rejected; (3) robust fit of δ(Z) (`curve`).
//! Stage 1 runs on luma (DoF blur is linear and achromatic, so it commutes with
//! luma) over the same cascaded discrete-Gaussian stack `synth::add_defocus` uses,
//! with nodes every `node_spacing` px, continued at half and quarter resolution
//! once it is band-limited (`stack_levels`). Between nodes S_k, S_{k+1} the blend weight
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
//! Range: the curve is fitted on the textured samples' depths and evaluated over
//! the depths the frame holds (0.5–99.5th percentile of its valid depth), with at
//! most `EXTRAPOLATION_FRACTION` of the textured inverse-depth span of
//! extrapolation on each side — δ(Z) clamps Z into that range, so content nearer
//! than every textured sample no longer takes the nearest sample's blur.
//!
//! Present when the fitted curve reaches ≥ 0.1 px somewhere in the range (a 0.1 px
//! Gaussian removes 5% of the contrast at Nyquist: invisible) and its maximum
//! exceeds 3 standard errors.
//!
//! Blind (Zhuo & Sim 2011): at edges (gradient-magnitude maxima along the gradient,
//! ≥ 0.03 per px), re-blur with σ0 = 3 px; for a Gaussian-blurred step the gradient
//! ratio R = |∇I| / |∇(I ∗ G_σ0)| gives σ = σ0/√(R² − 1). Both gradients are
//! averaged over 5 pixels along the edge (`EDGE_TANGENT_TAPS`): noise at the
//! gradient maximum otherwise reads δ low (−45% on a noisy 2 px test frame). Only
//! isolated edges count (`isolated`: no other edge within 7 px along the normal):
//! the ratio assumes one step, and a thin bar's two edges cancel in the re-blur
//! (δ read low; on a texture of known blur RMSE 0.24 px before, 0.045 px after).
//! The
//! central difference and pixel sampling bias that formula at small σ, so the raw
//! value is mapped through a table from a 1-D simulation of ideally sampled
//! blurred steps (sub-pixel phases averaged): an estimator calibration, not a
//! camera calibration.
//! The re-blurred image is built at half resolution (`reblur_half`: the pyramid's
//! reduce, variance 1 px², then the remaining 8 px² at half resolution — the
//! σ0 = 3 px blur is band-limited far below the half-resolution Nyquist) and its
//! gradient read by bilinear interpolation; the table simulates exactly that
//! pipeline, so the approximation is calibrated out. A full-resolution blur of
//! 25 taps per pass cost 11 ms of the fast tier at 1280×960; this costs ~2 ms.
//!
//! Kernel shape (blind): `defocus_spectrum::disc_signature` looks for a round
//! aperture's disc in the frame's mean log spectrum over tiles with valid depth. A
//! disc sets `DofKernel::Disc` and maps the edge ratios through a table simulated
//! with the disc's edge-spread function instead of erf; when the frame holds one
//! depth (inverse depth's 5–95% spread ≤ 2%), the δ(Z) curve is the constant σ of
//! the disc radius itself, with the split-half standard error — edge ratios on a
//! uniformly defocused page of text are biased by its thin strokes (they read
//! 1.96 px for the 2.79 px of tests/real_blur.rs).

use super::curve::fit_dof_curve;
use crate::image::{blur_separable, discrete_gaussian_kernel, gradient_sq, reduce, Plane, Rgb};
use crate::model::{DepthOfField, DepthUnits, Diagnostics, DofCurve, DofKernel, Status};
use std::sync::OnceLock;
use std::time::Instant;

/// Node spacing of the fitting stack. 0.5 px keeps the stack 2× cheaper than the
/// synth reference's 0.25 px; the variance-matched blend makes the mismatch a
/// higher-order effect (measured in tests/validation.rs and BENCHMARKS.md).
pub const DEFAULT_NODE_SPACING_PX: f32 = 0.5;
/// Default handoff of the DoF stack to half resolution (see `stack_levels`).
/// Measured at 512² (BENCHMARKS.md): at 5 px the strong-blur RMSE is 0.009 px
/// (full resolution: 0.005) for two thirds of the time; at 3 px it is 0.046 px,
/// too close to the 0.05 px tolerance for 6 ms.
pub const DEFAULT_PYRAMID_FROM_PX: Option<f32> = Some(5.0);
const TEXTURE_MIN_GRAD_SQ: f32 = 1e-4;
/// Sample centres on multiples of 4, so each one is also a pixel of the half- and
/// quarter-resolution levels (pixel j there ↔ pixel 2j / 4j here).
const SAMPLE_STRIDE: usize = 4;
const MIN_SAMPLES: usize = 32;

#[derive(Clone, Debug, Default)]
pub struct DofPlotData {
    pub depth: Vec<f32>,
    pub sigma_px: Vec<f32>,
    pub quadratic: Option<crate::model::DofCurve>,
    pub thin_lens: Option<crate::model::DofCurve>,
    /// The depths the frame held (0.5–99.5th percentile of its valid depth), the
    /// evaluation range's outer bound (`evaluation_range`); pooled fits take the
    /// union over their frames.
    pub frame_depth_span: Option<[f32; 2]>,
}

fn valid_depth(z: f32, units: DepthUnits) -> bool {
    z.is_finite() && (units == DepthUnits::RelativeInverse || z > 0.0)
}

fn depth_range(z: &[f32]) -> [f32; 2] {
    let lo = z.iter().cloned().fold(f32::INFINITY, f32::min);
    let hi = z.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    [lo, hi]
}

/// The valid depths of every `step`-th pixel in x and y.
fn valid_depths(depth: &Plane, units: DepthUnits, step: usize) -> Vec<f32> {
    (0..depth.height)
        .step_by(step)
        .flat_map(|y| (0..depth.width).step_by(step).map(move |x| (x, y)))
        .map(|(x, y)| depth.get(x, y))
        .filter(|&v| valid_depth(v, units))
        .collect()
}

/// The depths the frame holds: 0.5th–99.5th percentile of its valid depths (every
/// other pixel in x and y), or `None` without valid depth.
fn frame_depth_span(depth: &Plane, units: DepthUnits) -> Option<[f32; 2]> {
    let mut z = valid_depths(depth, units, 2);
    if z.is_empty() {
        return None;
    }
    let k = |q: f64| ((z.len() - 1) as f64 * q).round() as usize;
    let (klo, khi) = (k(0.005), k(0.995));
    let lo = *z.select_nth_unstable_by(klo, |a, b| a.total_cmp(b)).1;
    let hi = *z.select_nth_unstable_by(khi, |a, b| a.total_cmp(b)).1;
    Some([lo, hi])
}

/// Extrapolation beyond the textured depths, as a fraction of their span in inverse
/// depth (where the thin lens is linear), toward the depths the frame holds. Chosen
/// by measurement (tests/independent_forward.rs, BENCHMARKS.md): on five scenes —
/// two fully textured, one with 14% of the frame textureless and nearer than every
/// textured sample (thin lens and quadratic truth), one with a textureless far band
/// — 0 (the textured depths only: nearer content took the nearest sample's blur,
/// 0.68 px frame RMSE) / 0.5 / 1 / 2 / unbounded gave worst-case frame RMSE 0.68 /
/// 0.35 / 0.20 / 0.23 / 0.23 px and medians 0.090 / 0.076 / 0.067 / 0.066 / 0.066 px:
/// 1 has the best worst case, and bounds how far a curve fitted on a narrow textured
/// span is trusted.
pub const EXTRAPOLATION_FRACTION: f32 = 1.0;

/// The range the model is evaluated over (δ(Z) clamps Z into it): the textured
/// samples' depths, extended toward the frame's depths by at most
/// `EXTRAPOLATION_FRACTION` of their inverse-depth span on each side.
fn evaluation_range(textured: [f32; 2], frame: Option<[f32; 2]>, units: DepthUnits) -> [f32; 2] {
    let Some(frame) = frame else { return textured };
    let m = EXTRAPOLATION_FRACTION;
    // Inverse depth u: near is large u for metric depth, and z itself for
    // relative inverse depth.
    let u = |z: f32| units.inverse_depth(z);
    let from_u = |u: f32| match units {
        DepthUnits::MetricM => 1.0 / u,
        DepthUnits::RelativeInverse => u,
    };
    let (ua, ub) = (u(textured[0]), u(textured[1]));
    let (ulo, uhi) = (ua.min(ub), ua.max(ub));
    let span = (uhi - ulo).max(0.0);
    let (fa, fb) = (u(frame[0]), u(frame[1]));
    let (flo, fhi) = (fa.min(fb), fa.max(fb));
    let new_lo = flo.max(ulo - m * span).min(ulo);
    let new_hi = fhi.min(uhi + m * span).max(uhi);
    // Metric depth: u ≤ 0 is infinitely far, so keep the far end finite; relative
    // inverse depth may be ≤ 0 (it is affine in 1/Z) and is taken as it is.
    let new_lo = if units == DepthUnits::MetricM { new_lo.max(1e-6) } else { new_lo };
    let (za, zb) = (from_u(new_lo), from_u(new_hi));
    [za.min(zb), za.max(zb)]
}

/// Turn per-pixel (Z, σ) into the model; `residuals` = (before, after) if known.
#[allow(clippy::too_many_arguments)]
fn finish(
    method: &str,
    z: Vec<f32>,
    s: Vec<f32>,
    units: DepthUnits,
    frame_span: Option<[f32; 2]>,
    started: Instant,
    mut st: super::Stages,
    residual_at: impl Fn(&DepthOfField) -> Option<(f64, f64)>,
) -> (DepthOfField, Option<DofPlotData>) {
    let n = z.len();
    if n < MIN_SAMPLES {
        let reason = format!("only {n} textured pixels with valid depth (need {MIN_SAMPLES}): δ(Z) not identifiable");
        let mut d = super::not_identifiable(method, reason, started);
        d.samples_used = n as u64;
        return (DepthOfField::absent(units, d), None);
    }
    let textured = depth_range(&z);
    let range = evaluation_range(textured, frame_span, units);
    st.lap("search");
    let Some(fit) = fit_dof_curve(&z, &s, units, textured) else {
        let mut d = super::not_identifiable(method, "robust depth-model fit failed (degenerate design)", started);
        d.samples_used = n as u64;
        return (DepthOfField::absent(units, d), None);
    };
    let mut dof = DepthOfField {
        present: true,
        units,
        curve: Some(fit.curve),
        depth_range: range,
        kernel: crate::model::DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted(""),
    };
    let max_sigma =
        (0..=64).map(|i| dof.sigma_px(range[0] + (range[1] - range[0]) * i as f32 / 64.0)).fold(0.0f32, f32::max);
    let present = max_sigma >= 0.1 && (max_sigma as f64) > 3.0 * fit.stderr_px;
    st.lap("least_squares");
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
             robust residual scale {:.3} px; fitted on textured depths [{:.3}, {:.3}], evaluated over [{:.3}, {:.3}] \
             (the frame's depths, extrapolated at most {EXTRAPOLATION_FRACTION} textured inverse-depth span); {}",
            fit.scale,
            textured[0],
            textured[1],
            range[0],
            range[1],
            if present { "visible (≥ 0.1 px) and above 3 standard errors" } else { "below 0.1 px or within 3 standard errors" }
        ),
        method: method.into(),
        residual_before: residuals.map(|r| r.0),
        residual_after: residuals.map(|r| r.1),
        samples_used: n as u64,
        fit_time_s: started.elapsed().as_secs_f64(),
        stderr: Some(fit.stderr_px),
        stages_s: st.done(),
    };
    let plot = DofPlotData {
        depth: z,
        sigma_px: s,
        quadratic: fit.quadratic,
        thin_lens: fit.thin_lens,
        frame_depth_span: frame_span,
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

/// One resolution of the multi-resolution stack: pixels of `1 << shift` full-res
/// pixels, nodes σ_k = `lo + k·spacing` (full-res px) up to `hi`.
struct StackLevel {
    shift: usize,
    lo: f32,
    hi: f32,
}

/// The stack's resolutions for a handoff σ_h (`FitOptions::dof_pyramid_from_px`):
/// full resolution to σ_h + 0.5, half resolution from σ_h to 2σ_h + 0.5, quarter
/// resolution from 2σ_h on; `None` keeps everything at full resolution (exactly the
/// reference's stack). Past σ_h the stack is band-limited (at σ_h = 3 its response at
/// the half-res Nyquist frequency is e^(−2π²·9/16) ≈ 1.5e-5), but a discrete Gaussian
/// of variance t/4 on the coarse grid is not the full-res one of variance t: their
/// responses differ in the 4th order, which biases coarse-level σ slightly (measured
/// in BENCHMARKS.md: the speed/accuracy trade of this option). Levels overlap by
/// 0.5 px so a sample near a boundary is judged where its minimum is interior.
fn stack_levels(handoff_px: Option<f32>) -> Vec<StackLevel> {
    match handoff_px {
        None => vec![StackLevel { shift: 0, lo: 0.0, hi: f32::INFINITY }],
        Some(h) => vec![
            StackLevel { shift: 0, lo: 0.0, hi: h + 0.5 },
            StackLevel { shift: 1, lo: h, hi: 2.0 * h + 0.5 },
            StackLevel { shift: 2, lo: 2.0 * h, hi: f32::INFINITY },
        ],
    }
}

/// Every other pixel in x and y (pixel j ↔ pixel 2j): no prefilter; callers only
/// decimate band-limited planes (or the frame, whose relevant pixels are blurred).
fn decimate(p: &Plane) -> Plane {
    let (w, h) = (p.width.div_ceil(2), p.height.div_ceil(2));
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            out.push(p.get(2 * x, 2 * y));
        }
    }
    Plane::from_vec(w, h, out)
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
    let mut st = super::Stages::start();
    let (yi, ys) = (image.luma(), sharp.luma());
    let grad = gradient_sq(&ys);
    let (w, h) = (yi.width, yi.height);
    // Sample centres on a stride grid; each owns a 3×3 patch.
    let mut centres = vec![];
    for y in (SAMPLE_STRIDE..h.saturating_sub(1)).step_by(SAMPLE_STRIDE) {
        for x in (SAMPLE_STRIDE..w.saturating_sub(1)).step_by(SAMPLE_STRIDE) {
            let z = depth.get(x, y);
            if !valid_depth(z, units) {
                continue;
            }
            let g: f32 = (0..9).map(|k| grad.get(x + k % 3 - 1, y + k / 3 - 1)).sum::<f32>() / 9.0;
            if g >= TEXTURE_MIN_GRAD_SQ {
                centres.push((x, y));
            }
        }
    }
    let n = centres.len();
    let spacing = opts.dof_node_spacing_px;
    let max_sigma = opts.dof_max_sigma_px;
    // Per level: (first node σ, number of intervals, statistics).
    let mut levels: Vec<(f32, usize, IntervalStats)> = vec![];
    if n >= MIN_SAMPLES {
        let mut frame = yi.clone();
        let mut start_plane = ys.clone();
        let stack = stack_levels(opts.dof_pyramid_from_px);
        for level in stack.iter() {
            if level.lo >= max_sigma {
                break;
            }
            let lo = (level.lo / spacing).floor() * spacing;
            let hi = level.hi.min(max_sigma);
            let intervals = ((hi - lo) / spacing).ceil().max(1.0) as usize;
            let scale = (1usize << level.shift) as f32;
            let mut st = IntervalStats {
                aa: vec![0.0; n * intervals],
                ad: vec![0.0; n * intervals],
                dd: vec![0.0; n * intervals],
            };
            let (fw, fh) = (frame.width, frame.height);
            let mut handoff: Option<Plane> = None;
            let next_lo = stack.get(level.shift + 1).map(|l| (l.lo / spacing).floor() * spacing);
            let mut prev = start_plane.clone();
            for k in 0..intervals {
                let (s0, s1) = (lo + k as f32 * spacing, lo + (k + 1) as f32 * spacing);
                if Some(s0) == next_lo {
                    handoff = Some(prev.clone());
                }
                // Increment in this level's pixel units: variances scale by 1/scale².
                let next = blur_separable(&prev, &discrete_gaussian_kernel((s1 * s1 - s0 * s0) / (scale * scale)));
                for (s, &(x, y)) in centres.iter().enumerate() {
                    let (cx, cy) =
                        ((x >> level.shift).clamp(1, fw.max(3) - 2), (y >> level.shift).clamp(1, fh.max(3) - 2));
                    let (mut aa, mut ad, mut dd) = (0.0f32, 0.0f32, 0.0f32);
                    for j in cy.saturating_sub(1)..(cy + 2).min(fh) {
                        for i in cx.saturating_sub(1)..(cx + 2).min(fw) {
                            let idx = j * fw + i;
                            let av = frame.data[idx] - prev.data[idx];
                            let dv = next.data[idx] - prev.data[idx];
                            aa += av * av;
                            ad += av * dv;
                            dd += dv * dv;
                        }
                    }
                    let o = s * intervals + k;
                    st.aa[o] = aa;
                    st.ad[o] = ad;
                    st.dd[o] = dd;
                }
                prev = next;
            }
            if Some(lo + intervals as f32 * spacing) == next_lo {
                handoff = Some(prev.clone());
            }
            levels.push((lo, intervals, st));
            match handoff {
                Some(p) if fw > 3 && fh > 3 => {
                    start_plane = decimate(&p);
                    frame = decimate(&frame);
                }
                _ => break,
            }
        }
    }
    st.lap("blur");
    // Residual and best blend of sample s in interval k of a level.
    let eval = |lv: &(f32, usize, IntervalStats), s: usize, k: usize, wgt: Option<f32>| -> (f32, f32) {
        let (lo, intervals, st) = lv;
        let o = s * intervals + k;
        let wgt = wgt.unwrap_or(if st.dd[o] > 1e-12 { (st.ad[o] / st.dd[o]).clamp(0.0, 1.0) } else { 0.0 });
        let r = (st.aa[o] - 2.0 * wgt * st.ad[o] + wgt * wgt * st.dd[o]).max(0.0);
        let (s0, s1) = (lo + k as f32 * spacing, lo + (k + 1) as f32 * spacing);
        (r, (s0 * s0 + wgt * (s1 * s1 - s0 * s0)).sqrt())
    };
    // Coarse-to-fine choice: a level's answer stands if its minimum is interior
    // (below the next level's start + 0.25 px), else the next level decides.
    let mut zs = Vec::with_capacity(n);
    let mut sig = Vec::with_capacity(n);
    for (s, &(x, y)) in centres.iter().enumerate() {
        let mut chosen = 0.0f32;
        for (li, lv) in levels.iter().enumerate() {
            let best = (0..lv.1).map(|k| eval(lv, s, k, None)).min_by(|a, b| a.0.total_cmp(&b.0));
            if let Some((_, sigma)) = best {
                chosen = sigma;
                let limit = levels.get(li + 1).map_or(f32::INFINITY, |next| next.0 + 0.25);
                if sigma < limit {
                    break;
                }
            }
        }
        zs.push(depth.get(x, y));
        sig.push(chosen);
    }
    // Residual at σ: from the level whose range holds σ (coarser levels see every
    // 2nd/4th pixel of the same residual field, so the means are comparable).
    let residual = |s: usize, sigma: f32| -> f32 {
        let li = levels.iter().rposition(|lv| sigma >= lv.0 + 0.25 || lv.0 == 0.0).unwrap_or(0);
        let lv = &levels[li];
        let k = (((sigma - lv.0) / spacing).floor().max(0.0) as usize).min(lv.1 - 1);
        let (s0, s1) = (lv.0 + k as f32 * spacing, lv.0 + (k + 1) as f32 * spacing);
        let wgt = ((sigma * sigma - s0 * s0) / (s1 * s1 - s0 * s0)).clamp(0.0, 1.0);
        eval(lv, s, k, Some(wgt)).0
    };
    let residual_at = |dof: &DepthOfField| -> Option<(f64, f64)> {
        if levels.is_empty() {
            return None;
        }
        let (mut before, mut after) = (0.0f64, 0.0f64);
        for s in 0..n {
            before += residual(s, 0.0) as f64;
            after += residual(s, dof.sigma_px(zs[s])) as f64;
        }
        let m = (9 * n).max(1) as f64;
        Some((before / m, after / m))
    };
    finish("accurate", zs.clone(), sig, units, frame_depth_span(depth, units), started, st, residual_at)
}

/// Edge-spread function of a unit step at distance `d` (px) blurred by `kernel` of
/// second-moment std `sigma`: erf for the Gaussian; for the disc of radius R the
/// integral of its line-spread function (2/(πR²))·√(R² − t²).
fn edge_spread(kernel: DofKernel, d: f32, sigma: f32) -> f32 {
    if sigma < 1e-3 {
        return (d > 0.0) as u8 as f32;
    }
    match kernel {
        DofKernel::Gaussian => 0.5 * (1.0 + erf(d / (sigma * std::f32::consts::SQRT_2))),
        DofKernel::Disc => {
            let r = crate::model::kernels::disc_radius_px(sigma).max(1e-3);
            let t = (d / r).clamp(-1.0, 1.0);
            0.5 + (t * (1.0 - t * t).sqrt() + t.asin()) / std::f32::consts::PI
        }
    }
}

/// Raw Zhuo–Sim estimate → true σ for each kernel shape, from a 1-D simulation
/// (see module docs).
fn zhuo_sim_table(kernel: DofKernel) -> &'static Vec<(f32, f32)> {
    static GAUSSIAN: OnceLock<Vec<(f32, f32)>> = OnceLock::new();
    static DISC: OnceLock<Vec<(f32, f32)>> = OnceLock::new();
    let cell = match kernel {
        DofKernel::Gaussian => &GAUSSIAN,
        DofKernel::Disc => &DISC,
    };
    cell.get_or_init(|| {
        let n = 96usize;
        let mut table = vec![];
        for i in 0..=220 {
            let sigma = i as f32 * 0.05;
            let mut raw_sum = 0.0;
            // Sub-pixel phases over the half-resolution grid's 2-px period.
            let phases: Vec<f32> = (0..8).map(|k| k as f32 * 0.25).collect();
            for &ph in &phases {
                // Step at n/2 + ph blurred by the kernel of std σ, sampled at pixel
                // centres.
                let data: Vec<f32> =
                    (0..n).map(|x| edge_spread(kernel, x as f32 - (n as f32 / 2.0 + ph), sigma)).collect();
                let p = Plane::from_vec(n, 1, data);
                let re = reblur_half(&reduce(&p));
                let g = (1..n - 1).map(|x| 0.5 * (p.get(x + 1, 0) - p.get(x - 1, 0))).fold(0.0f32, f32::max);
                let g_re = (1..n - 1).map(|x| reblur_grad(&re, x, 0).0).fold(0.0f32, f32::max);
                let r = g / g_re;
                raw_sum += ZS_SIGMA0 / (r * r - 1.0).max(1e-6).sqrt();
            }
            table.push((raw_sum / phases.len() as f32, sigma));
        }
        table
    })
}

/// The Zhuo–Sim re-blur (Gaussian of std `ZS_SIGMA0`) of the frame at half
/// resolution, from `half` = `reduce(y)` (binomial, variance 1 px², keeps the even
/// pixels; shared with the motion-blur fit's coarse scale): a discrete Gaussian of
/// the remaining (σ0² − 1)/4 half-resolution px².
fn reblur_half(half: &Plane) -> Plane {
    blur_separable(half, &discrete_gaussian_kernel((ZS_SIGMA0 * ZS_SIGMA0 - 1.0) / 4.0))
}

/// Gradient (per full-resolution px) of the re-blurred image at full-resolution
/// pixel (x, y): central differences of its bilinear interpolation (full-resolution
/// pixel x sits at half-resolution x/2).
#[inline]
fn reblur_grad(half: &Plane, x: usize, y: usize) -> (f32, f32) {
    // Bilinear weights at (x/2, y/2) over the half-resolution central differences.
    let (hx, hy) = (0.5 * x as f32, 0.5 * y as f32);
    let (x0, y0) = (hx.floor() as isize, hy.floor() as isize);
    let (fx, fy) = (hx - x0 as f32, hy - y0 as f32);
    let g = |i: isize, j: isize| {
        (
            0.25 * (half.get_clamped(i + 1, j) - half.get_clamped(i - 1, j)),
            0.25 * (half.get_clamped(i, j + 1) - half.get_clamped(i, j - 1)),
        )
    };
    let (a, b, c, d) = (g(x0, y0), g(x0 + 1, y0), g(x0, y0 + 1), g(x0 + 1, y0 + 1));
    let lerp = |a: f32, b: f32, c: f32, d: f32| (1.0 - fy) * ((1.0 - fx) * a + fx * b) + fy * ((1.0 - fx) * c + fx * d);
    (lerp(a.0, b.0, c.0, d.0), lerp(a.1, b.1, c.1, d.1))
}

const ZS_SIGMA0: f32 = 3.0;

/// Least gradient magnitude (per px) of an edge sample, on the pixel's own central
/// difference and again on the average along the edge.
const EDGE_MIN_GRAD: f32 = 0.03;

/// Each edge sample's gradients (frame and re-blurred) are the mean of 2k + 1
/// pixels along the edge's tangent (rounded to one of 8 directions, so every tap
/// is a pixel and nothing is interpolated). A straight edge's gradient is the same
/// along its tangent, so the mean keeps the edge profile the table was simulated
/// for while dividing the noise variance by 2k + 1. Why it matters: the ratio
/// takes the frame's gradient at its maximum, where noise adds to it — on the
/// calibration video at 1280×960 (noise std ≈ 0.02, edges blurred 1.4–2.9 px)
/// single-pixel ratios read δ up to 0.7 px (25%) low, and noise maxima in flat
/// regions (|∇n| of white noise exceeds 0.03 in ~10% of pixels there) entered as
/// sharp edges. k = 2 measured (BENCHMARKS.md): the noisy and the noise-free
/// frames then read within 0.16 px of each other; k = 4 read curved edges wider
/// (+0.2–0.3 px on noise-free frames).
const EDGE_TANGENT_TAPS: isize = 2;

/// Most edge samples the fast tier's curve fit takes (see `fit_fast`): 1280×960
/// frames give ~32 000; 8 192 keep the standard error within 2× of all of them at a
/// quarter of the cost.
const FAST_MAX_EDGE_SAMPLES: usize = 8192;

/// Least re-blurred gradient magnitude (per px, averaged along the edge like the
/// frame's) of an edge sample. The frame's own gradient threshold selects edges
/// whose gradient noise happened to push them over it, and those read δ low (a
/// larger frame gradient, a larger ratio); the re-blurred gradient is nearly
/// noise-free, so selecting on it does not bias the ratio, and at 0.04 the frame's
/// threshold no longer binds (the frame's gradient is the re-blurred one × R > 1).
/// Blurry edges have the lowest gradients, so they felt it most: on the
/// procedural texture at 1280×960 with the video's noise, δ 2.7 px read for 2.87
/// at the near end, 2.81 with this threshold (noise-free: 2.82–2.85).
const EDGE_MIN_REBLUR_GRAD: f32 = 0.04;

/// How far along the normal another edge biases the re-blur ratio: the re-blurred
/// gradient at the edge weighs a neighbour at distance d by exp(−d²/2σ0²) — 0.14
/// at 2σ0 = 6 px, 0.07 at 7 px.
const INTERFERENCE_REACH_PX: f32 = 7.0;
/// Largest share of the edge's own gradient the profile along its normal may show
/// again within the reach (a rise past its running minimum, or a gradient of the
/// opposite sign: a neighbouring edge).
const INTERFERENCE_MAX_FRACTION: f32 = 0.2;

/// Whether the edge at `c` (gradient direction rounded to `s`, unit `normal`,
/// tangent-averaged magnitude `peak`) is alone within `INTERFERENCE_REACH_PX`
/// along its normal: the gradient projected on the normal (averaged along the
/// tangent like the edge itself) falls off on both sides without rising again or
/// changing sign by more than `INTERFERENCE_MAX_FRACTION` of the peak. Zhuo–Sim's
/// ratio assumes one step: a thin line's two edges cancel in the re-blur and read
/// δ low, a staircase's add and read it high. Near the border the walk stops
/// (nothing seen is nothing against).
fn isolated(y: &Plane, c: (isize, isize), s: (isize, isize), normal: (f32, f32), peak: f32) -> bool {
    let (w, h) = (y.width as isize, y.height as isize);
    let step = ((s.0 * s.0 + s.1 * s.1) as f32).sqrt();
    let reach = (INTERFERENCE_REACH_PX / step).ceil() as isize;
    let lim = INTERFERENCE_MAX_FRACTION * peak;
    let (t, k) = ((-s.1, s.0), EDGE_TANGENT_TAPS);
    let taps = (2 * k + 1) as f32;
    for dir in [-1isize, 1] {
        let mut low = peak;
        for d in 1..=reach {
            let (cx, cy) = (c.0 + dir * d * s.0, c.1 + dir * d * s.1);
            let (ax, ay, bx, by) = (cx - k * t.0, cy - k * t.1, cx + k * t.0, cy + k * t.1);
            if ax.min(bx) < 1 || ay.min(by) < 1 || ax.max(bx) >= w - 1 || ay.max(by) >= h - 1 {
                break;
            }
            let mut p = 0.0;
            for j in -k..=k {
                let (qx, qy) = ((cx + j * t.0) as usize, (cy + j * t.1) as usize);
                let gx = 0.5 * (y.get(qx + 1, qy) - y.get(qx - 1, qy));
                let gy = 0.5 * (y.get(qx, qy + 1) - y.get(qx, qy - 1));
                p += gx * normal.0 + gy * normal.1;
            }
            p /= taps;
            if p < -lim || p > low + lim {
                return false;
            }
            low = low.min(p);
        }
    }
    true
}

/// Abramowitz–Stegun 7.1.26 (|error| < 1.5e-7), enough for a calibration table.
fn erf(x: f32) -> f32 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let y = 1.0
        - (((((1.061_405_4 * t - 1.453_152_1) * t) + 1.421_413_8) * t - 0.284_496_74) * t + 0.254_829_6)
            * t
            * (-x * x).exp();
    y.copysign(x)
}

fn calibrate(raw: f32, kernel: DofKernel) -> f32 {
    let t = zhuo_sim_table(kernel);
    // Below σ ≈ 0.25 px the raw value dips under its σ = 0 value (the central
    // difference cannot resolve such blur): anything up to t[0] reads 0, and above
    // it the raw value rises with σ from `i0` on (asserted by
    // `zhuo_sim_tables_are_monotone`): a binary search there, then linear
    // interpolation raw → σ between the neighbouring entries.
    if raw.is_nan() || raw <= t[0].0 {
        return 0.0;
    }
    let i0 = t.iter().position(|e| e.0 > t[0].0).unwrap_or(t.len());
    let i = i0 + t[i0..].partition_point(|e| e.0 < raw);
    if i >= t.len() {
        return t[t.len() - 1].1;
    }
    let ((r0, s0), (r1, s1)) = (t[i - 1], t[i]);
    s0 + (s1 - s0) * (raw - r0) / (r1 - r0).max(1e-9)
}

/// Fast tier: the frame and Z (Zhuo & Sim 2011 edge re-blur ratio).
pub fn fit_fast(
    luma: &super::SharedLuma,
    depth: &Plane,
    units: DepthUnits,
    opts: &super::FitOptions,
) -> (DepthOfField, Option<DofPlotData>) {
    let started = Instant::now();
    let mut st = super::Stages::start();
    let (y, re) = (luma.full(), reblur_half(luma.half()));
    st.lap("blur");
    let (w, h) = (y.width, y.height);
    let grad = |p: &Plane, x: usize, yy: usize| -> (f32, f32) {
        (0.5 * (p.get(x + 1, yy) - p.get(x - 1, yy)), 0.5 * (p.get(x, yy + 1) - p.get(x, yy - 1)))
    };
    let (mut zs, mut sig) = (vec![], vec![]);
    // Every other row and column above 400k pixels: edges are lines, so a quarter of
    // their pixels still gives thousands of samples, at a quarter of the scan.
    let step = if w * h > 400_000 { 2 } else { 1 };
    for py in (2..h.saturating_sub(2)).step_by(step) {
        for px in (2..w.saturating_sub(2)).step_by(step) {
            let z = depth.get(px, py);
            if !valid_depth(z, units) {
                continue;
            }
            let (gx, gy) = grad(y, px, py);
            let m = (gx * gx + gy * gy).sqrt();
            if m < EDGE_MIN_GRAD {
                continue;
            }
            // Non-maximum suppression along the (rounded) gradient direction.
            let (sx, sy) = ((gx / m).round() as isize, (gy / m).round() as isize);
            let mag = |x: isize, yy: isize| {
                let (a, b) = grad(y, x as usize, yy as usize);
                (a * a + b * b).sqrt()
            };
            let (xi, yi) = (px as isize, py as isize);
            if m < mag(xi + sx, yi + sy) || m < mag(xi - sx, yi - sy) {
                continue;
            }
            // The gradients averaged along the edge (its rounded tangent, ±
            // `EDGE_TANGENT_TAPS` px; see the constant), and the edge threshold
            // applied again to the average.
            let (tx, ty) = (-sy, sx);
            let k = EDGE_TANGENT_TAPS;
            let inside = |t: isize| {
                let (x, yy) = (xi + t * tx, yi + t * ty);
                x >= 2 && yy >= 2 && x < w as isize - 2 && yy < h as isize - 2
            };
            if !inside(-k) || !inside(k) {
                continue;
            }
            let (mut g, mut gr) = ((0.0f32, 0.0f32), (0.0f32, 0.0f32));
            for t in -k..=k {
                let (qx, qy) = ((xi + t * tx) as usize, (yi + t * ty) as usize);
                let (a, b) = grad(y, qx, qy);
                let (c, d) = reblur_grad(&re, qx, qy);
                g = (g.0 + a, g.1 + b);
                gr = (gr.0 + c, gr.1 + d);
            }
            let taps = (2 * k + 1) as f32;
            let m = (g.0 * g.0 + g.1 * g.1).sqrt() / taps;
            if m < EDGE_MIN_GRAD {
                continue;
            }
            let mr = (gr.0 * gr.0 + gr.1 * gr.1).sqrt() / taps;
            if mr < EDGE_MIN_REBLUR_GRAD {
                continue;
            }
            let r = m / mr;
            if r <= 1.0 {
                continue;
            }
            let normal = (g.0 / (m * taps), g.1 / (m * taps));
            if !isolated(y, (xi, yi), (sx, sy), normal, m) {
                continue;
            }
            sig.push(ZS_SIGMA0 / (r * r - 1.0).sqrt());
            zs.push(z);
        }
    }
    st.lap("search.edges");
    // Kernel shape (and a uniformly defocused frame's blur) from the spectrum, over
    // tiles whose depth is valid.
    let tile_ok = |x0: usize, y0: usize, t: usize| {
        (y0..y0 + t).step_by(8).all(|yy| (x0..x0 + t).step_by(8).all(|x| valid_depth(depth.get(x, yy), units)))
    };
    let spectrum = super::defocus_spectrum::disc_signature(y, tile_ok);
    st.lap("search.spectrum");
    let kernel = match &spectrum {
        Some(s) if s.is_disc => DofKernel::Disc,
        _ => DofKernel::Gaussian,
    };
    let shape_note = match &spectrum {
        Some(s) => format!(
            "kernel {} (spectrum over {} tiles of {} px: cepstral ring z {:.1} at R {:.2} px, second-notch contrast {:.3}; \
             a disc needs z ≥ {} and contrast ≥ {})",
            if s.is_disc { "disc" } else { "gaussian" },
            s.tiles,
            s.tile_px,
            s.ring_z,
            s.radius_px,
            s.notch_contrast,
            super::defocus_spectrum::RING_MIN_Z,
            super::defocus_spectrum::NOTCH_MIN_CONTRAST
        ),
        None => "kernel gaussian (too few textured tiles with valid depth for the spectrum)".into(),
    };
    // One depth across the frame: the spectrum's disc is the answer (edge ratios are
    // biased by thin strokes and texture; the ring measures the aperture itself).
    if let (Some(s), Some(range)) = (spectrum.as_ref().filter(|s| s.is_disc), constant_depth(depth, units)) {
        let c = s.sigma_px.min(opts.dof_max_sigma_px);
        let present = c >= 0.1 && c > 3.0 * s.stderr_px;
        let dof = DepthOfField {
            present,
            units,
            curve: Some(DofCurve::Constant { c }),
            depth_range: range,
            kernel,
            diagnostics: Diagnostics {
                status: if present { Status::Present } else { Status::Absent },
                reason: format!(
                    "one depth across the frame: constant δ {c:.3} px from the disc radius ({} px, second moment); \
                     {shape_note}; {} edge samples not used",
                    s.radius_px,
                    sig.len()
                ),
                method: "fast".into(),
                residual_before: None,
                residual_after: None,
                samples_used: s.tiles as u64,
                fit_time_s: started.elapsed().as_secs_f64(),
                stderr: Some(s.stderr_px as f64),
                stages_s: st.done(),
            },
        };
        return (dof, None);
    }
    // Beyond `FAST_MAX_EDGE_SAMPLES` edges the robust curve fit (linear in the
    // samples) would cost more than the rest of the fit while its standard error
    // falls only as 1/√n: every k-th edge in raster order (spread over the frame and
    // its depths) is kept, and the reported standard error is that of the kept ones.
    let keep = sig.len().div_ceil(FAST_MAX_EDGE_SAMPLES).max(1);
    let zs: Vec<f32> = zs.into_iter().step_by(keep).collect();
    let sig: Vec<f32> =
        sig.into_iter().step_by(keep).map(|raw| calibrate(raw, kernel).min(opts.dof_max_sigma_px)).collect();
    let (mut dof, plot) = finish("fast", zs, sig, units, frame_depth_span(depth, units), started, st, |_| None);
    if dof.curve.is_some() {
        dof.kernel = kernel;
        dof.diagnostics.reason = format!("{}; {shape_note}", dof.diagnostics.reason);
    }
    (dof, plot)
}

/// Most edge samples a pooled fit takes (`fit_fast_pooled`): one frame's
/// (`FAST_MAX_EDGE_SAMPLES`), so pooling costs one more curve fit however many
/// frames the pool holds (at 1280×960: 9.3 ms for the 11 000 samples of ten
/// frames, ~2.4 ms for one frame's ~4 000 isolated edges).
pub const POOLED_MAX_EDGE_SAMPLES: usize = FAST_MAX_EDGE_SAMPLES;

/// One δ(Z) curve fitted on the edge samples of several blind fits (`fit_fast`'s
/// plot data) of one fixed-focus camera: every frame gives an equal share of at
/// most `POOLED_MAX_EDGE_SAMPLES` (every k-th of its samples), the evaluation
/// range bounds extrapolation by the union of the frames' depths. Why: one frame's
/// curve follows the depths its view holds textured — on the calibration video
/// views differ by 0.2–0.4 px RMSE — while the camera's δ(Z) is one curve; the
/// union of views pins it over the depths all of them saw.
/// `kernel` is the kernel the samples' σ were calibrated for (`fit_fast` maps
/// each edge ratio through that kernel's table): callers pool frames of one
/// kernel. Below `MIN_SAMPLES` in all: absent, status not identifiable.
pub fn fit_fast_pooled(
    frames: &[&DofPlotData],
    units: DepthUnits,
    kernel: DofKernel,
) -> (DepthOfField, Option<DofPlotData>) {
    let started = Instant::now();
    let mut st = super::Stages::start();
    let share = POOLED_MAX_EDGE_SAMPLES / frames.len().max(1);
    let (mut z, mut s) = (vec![], vec![]);
    let mut span: Option<[f32; 2]> = None;
    for f in frames {
        let n = f.depth.len().min(f.sigma_px.len());
        let keep = n.div_ceil(share.max(1)).max(1);
        z.extend(f.depth[..n].iter().step_by(keep));
        s.extend(f.sigma_px[..n].iter().step_by(keep));
        if let Some([lo, hi]) = f.frame_depth_span {
            span = Some(span.map_or([lo, hi], |[a, b]| [a.min(lo), b.max(hi)]));
        }
    }
    st.lap("pool");
    let method = format!("fast (edges pooled over {} frames)", frames.len());
    let (mut dof, plot) = finish(&method, z, s, units, span, started, st, |_| None);
    if dof.curve.is_some() {
        dof.kernel = kernel;
    }
    (dof, plot)
}

/// The depth range when the frame holds one depth (inverse depth's 5–95% spread
/// within 2% of its median, over every 4th pixel), else `None`.
fn constant_depth(depth: &Plane, units: DepthUnits) -> Option<[f32; 2]> {
    let mut z = valid_depths(depth, units, 4);
    if z.len() < MIN_SAMPLES {
        return None;
    }
    z.sort_by(f32::total_cmp);
    let n = z.len();
    let (lo, mid, hi) = (z[n / 20], z[n / 2], z[n - 1 - n / 20]);
    let (ul, um, uh) = (units.inverse_depth(lo), units.inverse_depth(mid), units.inverse_depth(hi));
    ((uh - ul).abs() <= 0.02 * um.abs().max(1e-6)).then_some([z[0], z[n - 1]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `calibrate`'s binary search needs the raw Zhuo–Sim value to rise strictly
    /// with σ from the first entry above the σ = 0 value on (below it, σ < 0.3 px,
    /// the raw value dips: unresolvable, read as 0); the mapping then inverts the
    /// table there (to 1e-3 px: float rounding of the interpolation).
    #[test]
    fn zhuo_sim_tables_are_monotone() {
        for kernel in [DofKernel::Gaussian, DofKernel::Disc] {
            let t = zhuo_sim_table(kernel);
            let i0 = t.iter().position(|e| e.0 > t[0].0).expect("the raw value rises");
            assert!(t[i0].1 <= 0.5, "{kernel:?}: resolvable only from σ {}", t[i0].1);
            for w in t[i0..].windows(2) {
                assert!(w[1].0 > w[0].0, "{kernel:?}: raw {} at σ {} then {} at σ {}", w[0].0, w[0].1, w[1].0, w[1].1);
            }
            for &(raw, sigma) in &t[i0..] {
                assert!((calibrate(raw, kernel) - sigma).abs() < 1e-3, "{kernel:?} σ {sigma}");
            }
            assert_eq!(calibrate(t[0].0, kernel), 0.0);
        }
    }
}

#[cfg(test)]
mod range_tests {
    use super::*;

    /// The evaluation range at the extremes: no frame depths → the textured range;
    /// a frame far wider than the textured span → at most one span on each side (in
    /// inverse depth); relative inverse depth below zero stays below zero; a single
    /// textured depth does not extend.
    #[test]
    fn evaluation_range_is_bounded_and_keeps_units() {
        let m = DepthUnits::MetricM;
        assert_eq!(evaluation_range([1.0, 2.0], None, m), [1.0, 2.0]);
        // Textured u ∈ [0.5, 1]: span 0.5 → u ∈ [0, 1.5] at most → z ∈ [0.667, 1e6].
        let r = evaluation_range([1.0, 2.0], Some([0.01, 1e9]), m);
        assert!((r[0] - 1.0 / 1.5).abs() < 1e-5 && r[1] == 1e6, "{r:?}");
        // Inside the bound the frame's own depths are used.
        let r = evaluation_range([1.0, 2.0], Some([0.8, 3.0]), m);
        assert!((r[0] - 0.8).abs() < 1e-5 && (r[1] - 3.0).abs() < 1e-4, "{r:?}");
        let r = evaluation_range([-0.5, 0.5], Some([-10.0, 10.0]), DepthUnits::RelativeInverse);
        assert_eq!(r, [-1.5, 1.5]);
        assert_eq!(evaluation_range([2.0, 2.0], Some([0.1, 50.0]), m), [2.0, 2.0]);
    }
}

#[cfg(test)]
mod pooled_tests {
    use super::*;

    /// Edge samples of a thin lens (k = 4 px per m⁻¹, focus 2.5 m, c0 0.3 px) at the
    /// depths `z`, with a deterministic ±0.3 px scatter (a robust fit's noise).
    fn frame(z: Vec<f32>, span: [f32; 2]) -> DofPlotData {
        let truth = |z: f32| 4.0 * (1.0 / z - 1.0 / 2.5).abs() + 0.3;
        let sigma_px =
            z.iter().enumerate().map(|(i, &z)| truth(z) + 0.3 * ((i * 7919) % 13) as f32 / 6.0 - 0.3).collect();
        DofPlotData { depth: z, sigma_px, quadratic: None, thin_lens: None, frame_depth_span: Some(span) }
    }

    /// Two views of one camera, one seeing only near depths (1–2 m, ten times the
    /// samples), one only far (3–6 m): the pooled curve follows the camera over
    /// both (RMSE ≤ 0.1 px: the samples' scatter averaged over thousands, plus the
    /// thin lens's focus search on a grid), each view gets an equal share of the
    /// sample budget (the near view alone would not pin the far side), and the
    /// evaluation range is the union of the views' depths.
    #[test]
    fn pooled_views_pin_the_curve_over_their_union() {
        let near = frame((0..20_000).map(|i| 1.0 + (i % 1000) as f32 / 1000.0).collect(), [1.0, 2.0]);
        let far = frame((0..2_000).map(|i| 3.0 + 3.0 * (i % 500) as f32 / 500.0).collect(), [3.0, 6.0]);
        let (dof, plot) = fit_fast_pooled(&[&near, &far], DepthUnits::MetricM, DofKernel::Gaussian);
        assert!(dof.present, "{}", dof.diagnostics.reason);
        assert_eq!(dof.depth_range, [1.0, 6.0]);
        let plot = plot.expect("plot data");
        let from_far = plot.depth.iter().filter(|&&z| z >= 3.0).count();
        assert!(from_far >= 2_000 && plot.depth.len() <= POOLED_MAX_EDGE_SAMPLES, "{from_far} of {}", plot.depth.len());
        let truth = |z: f32| 4.0 * (1.0 / z - 1.0 / 2.5).abs() + 0.3;
        let zs: Vec<f32> = (0..50).map(|i| 1.0 + 5.0 * i as f32 / 49.0).collect();
        let rmse = (zs.iter().map(|&z| (dof.sigma_px(z) - truth(z)).powi(2)).sum::<f32>() / zs.len() as f32).sqrt();
        assert!(rmse <= 0.1, "pooled RMSE {rmse} px: {}", dof.diagnostics.reason);
        assert!(dof.diagnostics.method.contains("2 frames"), "{}", dof.diagnostics.method);
    }

    /// No samples at all: absent and not identifiable, never a curve.
    #[test]
    fn an_empty_pool_is_not_identifiable() {
        let (dof, plot) = fit_fast_pooled(&[], DepthUnits::MetricM, DofKernel::Gaussian);
        assert!(!dof.present && dof.curve.is_none() && plot.is_none());
        assert_eq!(dof.diagnostics.status, Status::NotIdentifiable);
    }
}
