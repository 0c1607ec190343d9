//! Depth of field δ(Z), accurate and blind.
//!
//! Accurate (paper eq. 4 and its three stages): (1) per-pixel σ search over
//! [0, 10] px; (2) textureless pixels rejected; (3) robust fit of δ(Z) (`curve`).
//! Stage 1 runs on luma (DoF blur is linear and achromatic, so it commutes with
//! luma) over the same cascaded discrete-Gaussian stack `synth::add_defocus` uses,
//! with nodes every `node_spacing` px, continued at half and quarter resolution
//! once it is band-limited (`stack_levels`). Between nodes S_k, S_{k+1} the blend weight
//! that best explains a 3×3 patch of I is closed-form,
//! w = ⟨I − S_k, S_{k+1} − S_k⟩ / |S_{k+1} − S_k|², clamped to [0, 1], and σ² is
//! the variance whose exact discrete Gaussian that weight best imitates
//! (`blend::BlendMap`, from the stack's own inner products; the variance-linear
//! σ_k² + w(σ_{k+1}² − σ_k²) read up to +0.05 px long between nodes): a continuous
//! σ, not a 0.1 px grid, and one pass over the stack instead of 100 blurs.
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
//! than every textured sample does not take the nearest sample's blur.
//!
//! Present when the fitted curve reaches ≥ 0.1 px somewhere in the range (a 0.1 px
//! Gaussian removes 5% of the contrast at Nyquist: invisible) and its maximum
//! exceeds 3 standard errors.
//!
//! Blind: `blind` (Zhuo & Sim 2011's edge re-blur ratio on isolated edges, pooled
//! over views by `fit_fast_pooled`).

mod blend;
mod blind;
mod measured;

pub use blind::{fit_fast, fit_fast_pooled, POOLED_MAX_EDGE_SAMPLES};

use super::curve::fit_dof_curve;
use crate::image::{blur_separable, discrete_gaussian_kernel, gradient_sq, Plane, Rgb};
use crate::model::{DepthOfField, DepthUnits, Diagnostics, DofCurve, DofKernel, Status};
use blend::{BlendMap, Gram};
use std::time::Instant;

/// Node spacing of the fitting stack. 0.5 px keeps the stack 2× cheaper than the
/// synth reference's 0.25 px; the blend map (`blend::BlendMap`) reads exact
/// Gaussians between its nodes (measured in tests/validation.rs,
/// tests/independent_forward.rs and BENCHMARKS.md). 1 px would save a quarter of
/// the fit but reads an independent forward model 0.035 px RMSE instead of 0.028.
pub const DEFAULT_NODE_SPACING_PX: f32 = 0.5;
/// Default handoff of the DoF stack to half resolution (see `stack_levels`).
/// Measured at 512² with the blend map (BENCHMARKS.md, `cargo bench --bench
/// quality`): at 4 px the strong-blur RMSE is 0.0086 px (5 px: 0.0140; full
/// resolution: 0.0077) in 60% of the full-resolution time (19.1 vs 31.8 ms); at
/// 3 px it is 0.049 px, at the 0.05 px tolerance. (Without the map 4 px reads
/// 0.080 px: the variance-linear map's bias on the coarse grid.)
pub const DEFAULT_PYRAMID_FROM_PX: Option<f32> = Some(4.0);
const TEXTURE_MIN_GRAD_SQ: f32 = 1e-4;
/// Sample centres on multiples of 4, so each one is also a pixel of the half- and
/// quarter-resolution levels (pixel j there ↔ pixel 2j / 4j here).
const SAMPLE_STRIDE: usize = 4;
const MIN_SAMPLES: usize = 32;
/// Every how many samples' patches the blend map's Gram sums read (all of them cost
/// ~1 ms of a 20 ms fit at 512²; one in four reads the same map to ~1e-3 in w).
const GRAM_SAMPLE_STEP: usize = 4;

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
    /// Per sample, the frame cell it lies in (`Cells`): the clusters of the
    /// standard error's sandwich (`curve::cluster_stderr`); pooled fits keep each
    /// frame's cells apart.
    pub cell: Vec<u32>,
}

/// Cells of the frame whose samples are taken to share their errors (one edge, one
/// patch of texture), for the δ(Z) standard error (`curve::cluster_stderr`): a grid
/// of about `CELLS` square cells, whatever the resolution (80 px at 1280×960, 20 px
/// at 320×240), so that a cell holds a stretch of edge and its neighbourhood.
/// Measured on 24 defocus-ramp frames at 1280×960 (BENCHMARKS.md
/// "The blind δ(Z)'s standard error"): 32 / 64 / 128 px cells at 1280×960 read a
/// median 1.8 / 2.0 / 2.4× (1.2–4.1× over the frames) the sandwich with every
/// sample its own cluster — growing slowly past the scale of an edge.
pub(crate) struct Cells {
    px: usize,
    cols: usize,
}

impl Cells {
    pub(crate) fn new(w: usize, h: usize) -> Self {
        let px = (((w * h) as f64 / CELLS as f64).sqrt().round() as usize).max(4);
        Self { px, cols: w.div_ceil(px).max(1) }
    }
    pub(crate) fn of(&self, x: usize, y: usize) -> u32 {
        ((y / self.px) * self.cols + x / self.px) as u32
    }
}

/// The blind tier's edge-calibration bias, as a fraction of δ's RMS over the
/// evaluated depths (`finish`): on a texture of known blur (no blur of its own) the
/// blind curves of six procedural frames of the defocus ramps are off by
/// 0.039–0.075 px RMS, 2.8–9.9% of the truth's δ RMS (median 3.4%), while their
/// statistical error reads 0.008–0.016 px (BENCHMARKS.md "The blind δ(Z)'s
/// standard error").
const EDGE_CALIBRATION_BIAS: f64 = 0.05;
/// The accurate tier's (blend-stack) calibration bias, likewise: on the textured
/// scenes of `tests/independent_forward.rs` (another implementation's forward
/// model) its curves are off by 0.029 / 0.048 px, 1.8 / 4.0% of δ's RMS, while
/// their statistical error reads ~0.004 px.
const STACK_CALIBRATION_BIAS: f64 = 0.03;

/// About how many cells a frame is cut into (`Cells`).
const CELLS: usize = 192;

fn valid_depth(z: f32, units: DepthUnits) -> bool {
    z.is_finite() && (units == DepthUnits::RelativeInverse || z > 0.0)
}

fn depth_range(z: &[f32]) -> [f32; 2] {
    let lo = z.iter().cloned().fold(f32::INFINITY, f32::min);
    let hi = z.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    [lo, hi]
}

/// The valid depths of every `step`-th pixel in x and y.
///
/// Row by row into a vector sized for all of them: the chained `flat_map` /
/// `filter` / `collect` took ~77 instructions a value by callgrind.
fn valid_depths(depth: &Plane, units: DepthUnits, step: usize) -> Vec<f32> {
    let (w, h) = (depth.width, depth.height);
    let mut z = Vec::with_capacity(w.div_ceil(step.max(1)) * h.div_ceil(step.max(1)));
    for row in depth.data.chunks_exact(w.max(1)).step_by(step) {
        z.extend(row.iter().step_by(step).copied().filter(|&v| valid_depth(v, units)));
    }
    z
}

/// The depths the frame holds: 0.5th–99.5th percentile of its valid depths (every
/// other pixel in x and y, every k-th above ~260 000 pixels so that about 65 000
/// are read — two selections over the 307 000 of a 1280×960 frame were 3 ms of the
/// blind DoF fit), or `None` without valid depth.
fn frame_depth_span(depth: &Plane, units: DepthUnits) -> Option<[f32; 2]> {
    let step = (((depth.width * depth.height) as f64 / 65_536.0).sqrt() as usize).max(2);
    // Selected on `total_cmp`'s own integer key (the bits with the magnitude flipped
    // for negatives, compared as i32: the same order, and its own inverse), so the
    // same values, by integer comparisons instead of a comparison closure per step
    // (callgrind: ~9 M instructions of the blind defocus fit's ~143 M).
    let key = |b: i32| b ^ ((((b >> 31) as u32) >> 1) as i32);
    let mut z: Vec<i32> = valid_depths(depth, units, step).into_iter().map(|v| key(v.to_bits() as i32)).collect();
    if z.is_empty() {
        return None;
    }
    let k = |q: f64| ((z.len() - 1) as f64 * q).round() as usize;
    let (klo, khi) = (k(0.005), k(0.995));
    let lo = f32::from_bits(key(*z.select_nth_unstable(klo).1) as u32);
    let hi = f32::from_bits(key(*z.select_nth_unstable(khi).1) as u32);
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
    cell: Vec<u32>,
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
    let max_sigma = over_range(range).map(|z| dof.sigma_px(z)).fold(0.0f32, f32::max);
    let (stderr_px, stderr_note) = standard_error(method, &fit, &dof, (&z, &s, &cell), textured, units);
    // Visible and above 3 standard errors: present. Invisible (< 0.1 px) whatever the
    // error: absent. A visible curve within 3 standard errors of none says neither
    // (an edge-poor frame's curve through a narrow band of depths, extrapolated):
    // not identifiable, so that it does not vote "absent" in the worker's window.
    let status = if max_sigma < 0.1 {
        Status::Absent
    } else if (max_sigma as f64) > 3.0 * stderr_px {
        Status::Present
    } else {
        Status::NotIdentifiable
    };
    let present = status == Status::Present;
    st.lap("least_squares");
    let residuals = residual_at(&dof);
    let form = match fit.curve {
        crate::model::DofCurve::Quadratic { .. } => "quadratic",
        crate::model::DofCurve::ThinLens { .. } => "thin_lens",
        crate::model::DofCurve::Constant { .. } => "constant",
    };
    dof.present = present;
    dof.diagnostics = Diagnostics {
        status,
        reason: format!(
            "{form} kept (lower mean Huber loss, thin lens on ties; flat curves become constants); max δ {max_sigma:.3} px, \
             robust residual scale {:.3} px; fitted on textured depths [{:.3}, {:.3}], evaluated over [{:.3}, {:.3}] \
             (the frame's depths, extrapolated at most {EXTRAPOLATION_FRACTION} textured inverse-depth span); {stderr_note}; {}",
            fit.scale,
            textured[0],
            textured[1],
            range[0],
            range[1],
            match status {
                Status::Present => "visible (≥ 0.1 px) and above 3 standard errors",
                Status::Absent => "below 0.1 px",
                _ => "visible but within 3 standard errors of none: not identifiable",
            }
        ),
        method: method.into(),
        residual_before: residuals.map(|r| r.0),
        residual_after: residuals.map(|r| r.1),
        samples_used: n as u64,
        fit_time_s: started.elapsed().as_secs_f64(),
        stderr: Some(stderr_px),
        stages_s: st.done(),
    };
    let plot = DofPlotData {
        depth: z,
        sigma_px: s,
        quadratic: fit.quadratic,
        thin_lens: fit.thin_lens,
        frame_depth_span: frame_span,
        cell,
    };
    (dof, Some(plot))
}

/// 65 depths even in Z over `range`, its ends included.
fn over_range(range: [f32; 2]) -> impl Iterator<Item = f32> {
    (0..=64).map(move |i| range[0] + (range[1] - range[0]) * i as f32 / 64.0)
}

/// The δ curve's standard error (px, an RMS over the evaluated depths `dof.depth_range`)
/// and what it is made of, for the reason. scale·√(3/N) took the edges as
/// independent and the curve as known beyond them: 2–23× under the error on the
/// blind tier's known-answer ramps, none within two (BENCHMARKS.md "The blind δ(Z)'s
/// standard error"). In quadrature:
/// * the statistical error, samples clustered by frame cell (`curve::cluster_stderr`;
///   with fewer than 4 cells, each sample its own), never under the
///   independent-sample figure;
/// * beyond the textured depths, where the samples cannot choose between the two
///   forms, half their spread there (none inside);
/// * each tier's calibration bias, shared by every sample so no spread shows it (the
///   blind tier's edge ratios through `blind::calibrate`, biased by a texture's own
///   profile; the accurate tier's blend map): a measured fraction of δ's RMS.
fn standard_error(
    method: &str,
    fit: &crate::fit::curve::CurveFit,
    dof: &DepthOfField,
    (z, s, cell): (&[f32], &[f32], &[u32]),
    textured: [f32; 2],
    units: DepthUnits,
) -> (f64, String) {
    use crate::fit::curve::cluster_stderr;
    let range = dof.depth_range;
    let rms = |f: &dyn Fn(f32) -> f64| (over_range(range).map(|z| f(z).powi(2)).sum::<f64>() / 65.0).sqrt();
    // One cell per sample (else each sample its own: never a shifted pairing).
    let cells_fit = cell.len() == z.len() && s.len() == z.len();
    let found = if cells_fit { cluster_stderr(&fit.curve, z, s, cell, fit.scale, units, range) } else { None };
    let (clustered, clusters) = match found {
        Some((se, groups)) => (se, format!("samples clustered in {groups} frame cells")),
        None => {
            let own: Vec<u32> = (0..z.len() as u32).collect();
            let se = cluster_stderr(&fit.curve, z, s, &own, fit.scale, units, range).map_or(fit.stderr_px, |r| r.0);
            (se, "no frame cells (fewer than 4, or not one per sample): samples taken as independent".into())
        }
    };
    let (lo, hi) = (textured[0].min(textured[1]), textured[0].max(textured[1]));
    let beyond = match (fit.quadratic, fit.thin_lens) {
        (Some(q), Some(t)) => rms(&|z| {
            if (lo..=hi).contains(&z) {
                0.0
            } else {
                0.5 * (q.sigma_px(units, z) - t.sigma_px(units, z)) as f64
            }
        }),
        _ => 0.0,
    };
    let stat = clustered.max(fit.stderr_px).hypot(beyond);
    let (fraction, what) = if method.starts_with("fast") {
        (EDGE_CALIBRATION_BIAS, "edge-ratio calibration")
    } else {
        (STACK_CALIBRATION_BIAS, "blend-stack calibration")
    };
    let bias = fraction * rms(&|z| dof.sigma_px(z) as f64);
    let total = stat.hypot(bias);
    let note = format!(
        "standard error {total:.3} px (RMS over the evaluated depths: statistical {stat:.3} px, {clusters}, with \
         {beyond:.3} px for the forms' spread beyond the textured depths, in quadrature with {bias:.3} px of {what} \
         bias ({fraction} of δ's RMS))"
    );
    (total, note)
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
    // Per level: (first node σ, number of intervals, statistics, blend maps).
    type Level = (f32, usize, IntervalStats, Vec<BlendMap>);
    let mut levels: Vec<Level> = vec![];
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
            // Each sample's 3×3 patch in this level's pixels: its top-left index (the
            // centre clamped one pixel inside the plane, so the patch is whole). Rows
            // read as three 3-pixel slices: the iterator chain over clamped ranges
            // this replaced was ~4 ms of a 15 ms fit at 512² (perf).
            let bases: Vec<usize> = if fw >= 3 && fh >= 3 {
                centres
                    .iter()
                    .map(|&(x, y)| {
                        let (cx, cy) = ((x >> level.shift).clamp(1, fw - 2), (y >> level.shift).clamp(1, fh - 2));
                        (cy - 1) * fw + cx - 1
                    })
                    .collect()
            } else {
                vec![]
            };
            if bases.is_empty() {
                break;
            }
            let rows = |p: &Plane, b: usize| -> [[f32; 3]; 3] {
                let row = |o: usize| -> [f32; 3] {
                    let r = &p.data[o..o + 3];
                    [r[0], r[1], r[2]]
                };
                [row(b), row(b + fw), row(b + 2 * fw)]
            };
            // The stack's Gram samples for `BlendMap`, g(t_a + t_b) = ⟨S_a − m, S_b − m⟩,
            // over every `GRAM_SAMPLE_STEP`-th sample's patch: the pixels the search
            // weighs (full-plane sums cost ~1 ms at 512²).
            let gram_bases = || bases.iter().step_by(GRAM_SAMPLE_STEP);
            let pixels = (9 * gram_bases().count()).max(1) as f64;
            let m = (gram_bases().flat_map(|&b| rows(&prev, b)).flatten().map(f64::from).sum::<f64>() / pixels) as f32;
            // (⟨a − m, b − m⟩, ⟨b − m, b − m⟩) per pixel over those patches.
            let gram_sums = |a: &Plane, b: &Plane| -> (f64, f64) {
                let (mut ab, mut bb) = (0.0f64, 0.0f64);
                for &base in gram_bases() {
                    let (pa, pb) = (rows(a, base), rows(b, base));
                    let (mut pab, mut pbb) = (0.0f32, 0.0f32);
                    for (ra, rb) in pa.iter().zip(&pb) {
                        for (&u, &v) in ra.iter().zip(rb) {
                            let (u, v) = (u - m, v - m);
                            pab += u * v;
                            pbb += v * v;
                        }
                    }
                    ab += pab as f64;
                    bb += pbb as f64;
                }
                (ab / pixels, bb / pixels)
            };
            let mut gram = Gram::default();
            gram.push(2.0 * lo * lo, gram_sums(&prev, &prev).1);
            for k in 0..intervals {
                let (s0, s1) = (lo + k as f32 * spacing, lo + (k + 1) as f32 * spacing);
                if Some(s0) == next_lo {
                    handoff = Some(prev.clone());
                }
                // Increment in this level's pixel units: variances scale by 1/scale².
                let next = blur_separable(&prev, &discrete_gaussian_kernel((s1 * s1 - s0 * s0) / (scale * scale)));
                for (s, &base) in bases.iter().enumerate() {
                    let (fr, pr, qr) = (rows(&frame, base), rows(&prev, base), rows(&next, base));
                    let (mut aa, mut ad, mut dd) = (0.0f32, 0.0f32, 0.0f32);
                    for j in 0..3 {
                        for i in 0..3 {
                            let (f, p, q) = (fr[j][i], pr[j][i], qr[j][i]);
                            let (av, dv) = (f - p, q - p);
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
                let (pn, nn) = gram_sums(&prev, &next);
                gram.push(s0 * s0 + s1 * s1, pn);
                gram.push(2.0 * s1 * s1, nn);
                prev = next;
            }
            if Some(lo + intervals as f32 * spacing) == next_lo {
                handoff = Some(prev.clone());
            }
            let maps = (0..intervals)
                .map(|k| {
                    let (s0, s1) = (lo + k as f32 * spacing, lo + (k + 1) as f32 * spacing);
                    BlendMap::new(&gram, s0 * s0, s1 * s1)
                })
                .collect();
            levels.push((lo, intervals, st, maps));
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
    // Residual and best blend weight of sample s in interval k of a level (σ from
    // the weight by the interval's `BlendMap`, only for the interval chosen).
    let eval = |lv: &Level, s: usize, k: usize, wgt: Option<f32>| -> (f32, f32) {
        let (_, intervals, st, _) = lv;
        let o = s * intervals + k;
        let wgt = wgt.unwrap_or(if st.dd[o] > 1e-12 { (st.ad[o] / st.dd[o]).clamp(0.0, 1.0) } else { 0.0 });
        ((st.aa[o] - 2.0 * wgt * st.ad[o] + wgt * wgt * st.dd[o]).max(0.0), wgt)
    };
    // Coarse-to-fine choice: a level's answer stands if its minimum is interior
    // (below the next level's start + 0.25 px), else the next level decides.
    let mut zs = Vec::with_capacity(n);
    let mut sig = Vec::with_capacity(n);
    for (s, &(x, y)) in centres.iter().enumerate() {
        let mut chosen = 0.0f32;
        for (li, lv) in levels.iter().enumerate() {
            // The first interval with the least residual (as `min_by`).
            let mut best: Option<(usize, f32, f32)> = None;
            for k in 0..lv.1 {
                let (r, w) = eval(lv, s, k, None);
                if best.map_or(true, |b| r.total_cmp(&b.1).is_lt()) {
                    best = Some((k, r, w));
                }
            }
            if let Some((k, _, wgt)) = best {
                let sigma = lv.3[k].variance(wgt).sqrt();
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
        eval(lv, s, k, Some(lv.3[k].weight(sigma * sigma))).0
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
    let cells = Cells::new(depth.width, depth.height);
    let cell = centres.iter().map(|&(x, y)| cells.of(x, y)).collect();
    finish("accurate", zs.clone(), sig, cell, units, frame_depth_span(depth, units), started, st, residual_at)
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

    /// `frame_depth_span` (its row-wise sampling and integer-key selection) picks
    /// the subsampled valid depths' `total_cmp` order statistics, bit for bit: over
    /// depths with negatives, ±0, ±∞, NaN (invalid, skipped) and ties, in both
    /// units, on frames below and above the thinning size.
    #[test]
    fn frame_depth_span_is_total_cmp_selection() {
        let reference = |depth: &Plane, units: DepthUnits| -> Option<[f32; 2]> {
            let step = (((depth.width * depth.height) as f64 / 65_536.0).sqrt() as usize).max(2);
            let mut z: Vec<f32> = (0..depth.height)
                .step_by(step)
                .flat_map(|y| (0..depth.width).step_by(step).map(move |x| depth.get(x, y)))
                .filter(|&v| valid_depth(v, units))
                .collect();
            if z.is_empty() {
                return None;
            }
            let n = z.len();
            let k = |q: f64| ((n - 1) as f64 * q).round() as usize;
            let lo = *z.select_nth_unstable_by(k(0.005), |a, b| a.total_cmp(b)).1;
            let hi = *z.select_nth_unstable_by(k(0.995), |a, b| a.total_cmp(b)).1;
            Some([lo, hi])
        };
        let special = [0.0f32, -0.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 1e-30, -1e-30, 3.5];
        for (w, h) in [(40usize, 30usize), (41, 29), (700, 500), (701, 503)] {
            let data: Vec<f32> = (0..w * h)
                .map(|i| {
                    let r = (i as u64).wrapping_mul(6_364_136_223_846_793_005).rotate_left(17);
                    if r % 7 == 0 {
                        special[(r >> 8) as usize % special.len()]
                    } else {
                        ((r >> 20) % 2001) as f32 * 0.01 - 10.0
                    }
                })
                .collect();
            let depth = Plane::from_vec(w, h, data);
            for units in [DepthUnits::MetricM, DepthUnits::RelativeInverse] {
                let (got, want) = (frame_depth_span(&depth, units), reference(&depth, units));
                let bits = |s: Option<[f32; 2]>| s.map(|[a, b]| [a.to_bits(), b.to_bits()]);
                assert_eq!(bits(got), bits(want), "{w}×{h} {units:?}: {got:?} vs {want:?}");
            }
        }
        assert_eq!(frame_depth_span(&Plane::new(8, 8, f32::NAN), DepthUnits::MetricM), None);
    }
}
