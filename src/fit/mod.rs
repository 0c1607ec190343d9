//! Estimators: image(s) in, `CameraModel` + diagnostics out. No I/O, no panics.
//!
//! Two tiers per effect:
//! * `accurate` (the paper's OPTIMIZATION setting): the frame I plus the frame
//!   with that effect removed (I_noNoise / I_noMB / I_noDoF), depth Z and flow F;
//! * `fast` (blind): the frame alone (plus Z for DoF and F for MB), cheap enough
//!   for a headset to rerun every few seconds.
//!
//! Each effect is fitted independently and reported `present` only when it passes
//! the test stated in its module.

mod aggregate;
pub mod chromatic;
pub mod colour;
mod curve;
pub mod defocus_spectrum;
mod dof;
mod isotropy_pool;
mod motion_blur;
mod noise;
pub mod noise_correlation;
pub mod sharpening;
pub mod streak_spectrum;
pub mod vignetting;

pub use aggregate::aggregate_models;
pub(crate) use aggregate::median;
pub use curve::{fit_dof_curve, CurveFit};
pub use dof::{fit_fast_pooled, DofPlotData, POOLED_MAX_EDGE_SAMPLES};
pub use isotropy_pool::{fit_fast_pooled_exposure, pooled_exposure, IsotropyEvidence, PooledExposure};
pub use motion_blur::MbPlotData;
pub use noise::compression_blocking;
/// The blind noise fit as it reads, neighbour and all (`fit` reads a frame with a
/// codec's block grid alone); for probes.
pub use noise::fit_fast as fit_noise_fast;
pub use noise::{
    effective_stride as effective_noise_stride, NoisePlotData, FAST_ALONE as NOISE_FAST_ALONE,
    FAST_WITH_NEIGHBOUR as NOISE_FAST_WITH_NEIGHBOUR, MIN_LEAK_RATIO as NOISE_MIN_LEAK_RATIO,
};

use crate::image::{Flow, Plane, Rgb};
use crate::model::{CameraModel, DepthOfField, DepthUnits, Diagnostics, MotionBlur, Noise, SCHEMA};
use std::time::Instant;

/// Which estimator to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tier {
    /// Blind: the frame alone (with depth / flow where the effect needs them).
    Fast,
    /// Reference images with the effect removed are required.
    Accurate,
}

/// Which effects to fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Effects {
    pub noise: bool,
    pub motion_blur: bool,
    pub depth_of_field: bool,
}

impl Effects {
    pub const ALL: Effects = Effects { noise: true, motion_blur: true, depth_of_field: true };
}

/// Everything an estimator may use. References are per effect (paper Tab. 1).
#[derive(Clone, Copy, Debug)]
pub struct FitInputs<'a> {
    pub image: &'a Rgb,
    pub denoised: Option<&'a Rgb>,
    pub motion_deblurred: Option<&'a Rgb>,
    /// A second I_noMB whose noise is independent of `motion_deblurred`'s (made
    /// from other frames, `analysis::Reference::second`). With it the accurate
    /// exposure fit minimises the cross loss E[(I − addMB(R₁))(I − addMB(R₂))],
    /// which the references' own noise does not bias (see `fit::motion_blur`).
    pub motion_deblurred_second: Option<&'a Rgb>,
    pub defocus_deblurred: Option<&'a Rgb>,
    pub depth: Option<&'a Plane>,
    pub depth_units: DepthUnits,
    /// Per-pixel flow in px/frame; a non-finite vector marks unknown motion
    /// there (skipped by every fit, like invalid depth).
    pub flow: Option<&'a Flow>,
    /// Where the reference images hold (> 0.5) and where they do not (≤ 0.5 or
    /// non-finite). References made from video (`analysis::temporal`: other frames
    /// aligned by pose and depth) are undefined where the scene left the view or was
    /// occluded; the accurate noise and motion-blur fits skip samples whose
    /// footprint touches such pixels. `None`: valid everywhere.
    pub reference_valid: Option<&'a Plane>,
    /// Another exposure of the same scene aligned to this frame (video: the previous
    /// frame warped by pose and depth, `analysis::temporal::align`). Not a
    /// reference: it carries its own noise. The blind noise fit uses it to cancel
    /// texture (the two exposures share the scene, not the noise).
    pub neighbour: Option<Neighbour<'a>>,
}

/// An aligned second exposure (`FitInputs::neighbour`) and where the alignment holds.
#[derive(Clone, Copy, Debug)]
pub struct Neighbour<'a> {
    pub image: &'a Rgb,
    /// > 0.5 where `image` shows this frame's scene point; elsewhere it is ignored.
    pub valid: &'a Plane,
}

impl<'a> FitInputs<'a> {
    /// The frame alone: no references, no depth, no flow (metric depth units if one
    /// is added later). Add the rest with struct-update syntax.
    pub fn new(image: &'a Rgb) -> Self {
        Self {
            image,
            denoised: None,
            motion_deblurred: None,
            motion_deblurred_second: None,
            defocus_deblurred: None,
            depth: None,
            depth_units: DepthUnits::MetricM,
            flow: None,
            reference_valid: None,
            neighbour: None,
        }
    }
}

/// Most edges one frame's sharpening fit reads (`FitOptions::sharpening`).
pub const SHARPENING_MAX_EDGES: usize = 400;

#[derive(Clone, Debug)]
pub struct FitOptions {
    /// `None`: accurate where the effect's reference image is given, fast otherwise.
    pub tier: Option<Tier>,
    pub effects: Effects,
    /// Fit the colour term (`model::Colour`, `colour::fit_colour`): the frame alone
    /// whatever the tier. Off by default: the worker fits it once per update, not
    /// in each of its per-effect fits; the `fit` command turns it on (unless
    /// `--only` leaves `colour` out).
    pub colour: bool,
    /// Fit the ISP's sharpening (`model::Sharpening`, `sharpening::estimate` over at
    /// most `SHARPENING_MAX_EDGES` edges): the frame alone whatever the tier. Off by
    /// default, like `colour`; the `fit` command turns it on (unless `--only` leaves
    /// `sharpening` out).
    pub sharpening: bool,
    /// Largest noise sample stride at level 0 in pixels, halved per level (paper: 32);
    /// small frames use a finer one to keep ~1000 samples.
    pub noise_stride_px: usize,
    /// DoF stack node spacing for the per-pixel σ search, px.
    pub dof_node_spacing_px: f32,
    /// Upper end of the per-pixel σ search, px (paper: 10).
    pub dof_max_sigma_px: f32,
    /// Continue the DoF stack at half resolution from this σ (and quarter from twice
    /// it); `None`: full resolution throughout (slower, exact). See BENCHMARKS.md.
    pub dof_pyramid_from_px: Option<f32>,
    /// Most pixels the accurate exposure fit integrates (evenly thinned).
    pub mb_max_samples: usize,
    /// Variance (px²) of a Gaussian both luma images of the accurate exposure fit
    /// pass through first (0: none). It commutes with the streak (both are
    /// convolutions) and removes the frequencies where a reference that is not a
    /// true I_noMB differs from one — resampling's attenuation near Nyquist, its own
    /// noise — which would otherwise read as blur the reference already has (λ
    /// biased low). Only the rows the reference is valid on are filtered.
    pub mb_prefilter_var_px2: f32,
    /// Pixels the accurate exposure fit reads must move at least this far per frame
    /// (px; at least 0.05). Streaks of a few px are where a reference that is not an
    /// exact I_noMB (aligned from other frames) biases λ most.
    pub mb_min_flow_px: f32,
    /// The accurate noise fit refuses ("not identifiable") where its reference
    /// leaks image structure into the residual: some band level's median sample
    /// below this share of the fit (`noise::leaks`; `NOISE_MIN_LEAK_RATIO`). None:
    /// the leak is reported in the reason, the fit kept. The worker refuses fits on
    /// references aligned from other frames, one estimate of several in its window
    /// (BENCHMARKS.md: the accurate tier's noise 5.8% → 1.9%); a single reference
    /// is kept — the shipped denoiser's always leak at the coarse levels (its 11-px
    /// receptive field), and a refusal there would leave nothing.
    pub noise_min_leak_ratio: Option<f32>,
    /// Blind exposure: also measure the isotropy evidence (`MbPlotData::isotropy`)
    /// on frames whose streak zeros answered. The worker's pooled fit needs every
    /// flow direction the head turned in, and the zeros answer in some directions
    /// only (on an oriented texture at 30° and 150° but not 90°,
    /// `tests/calibrate.rs`); costs the isotropy stage (~9 ms at 1280×960) on such
    /// frames.
    pub mb_isotropy_evidence: bool,
    /// Blind noise: grid points per pyramid level (the level-0 stride is
    /// √(pixels / this), at least 4 px; coarser levels keep about as many). The
    /// sample search's cost is linear in it; what fewer cost in accuracy is measured
    /// in BENCHMARKS.md ("Fast tier speed at 1280×960": the noise grid as a
    /// measured setting).
    pub noise_fast_samples_per_level: usize,
    /// Blind exposure and defocus: the share of their full sample counts read, in
    /// [`MIN_FAST_EFFORT`, 1] (default 1) — the isotropy's pixels (4 096), the
    /// streak's lines (~1 200) and the edge scan's rows (one in round(1/effort) of
    /// its lattice; a scan that finds too few edges reads the other rows too, which
    /// makes the full scan). The defocus spectrum keeps its tiles
    /// (fewer mistook Gaussian blur for a disc) and the blind noise grid has its own
    /// setting (`noise_fast_samples_per_level`). What each effort saves and costs in
    /// accuracy is measured in BENCHMARKS.md ("The fast tier's effort").
    pub fast_effort: f32,
}

/// Least `FitOptions::fast_effort`: a quarter of the full counts (1 024 isotropy
/// pixels, 300 streak lines, a quarter of the edge positions).
pub const MIN_FAST_EFFORT: f32 = 0.25;

/// The `q`-quantile of `v` (the element at rank round((n − 1)·q), NaN ordered by
/// `total_cmp`), partially reordering `v`; 0 when empty.
pub(crate) fn percentile(v: &mut [f32], q: f64) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    v[k]
}

/// `full` scaled by `effort` (`FitOptions::fast_effort`), rounded, at least 1; at
/// effort 1 exactly `full`.
pub(crate) fn scaled_count(full: usize, effort: f32) -> usize {
    if effort >= 1.0 {
        return full;
    }
    ((full as f64 * effort.max(0.0) as f64).round() as usize).max(1)
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            tier: None,
            effects: Effects::ALL,
            colour: false,
            sharpening: false,
            noise_stride_px: noise::DEFAULT_STRIDE_PX,
            dof_node_spacing_px: dof::DEFAULT_NODE_SPACING_PX,
            dof_max_sigma_px: crate::model::MAX_DOF_SIGMA_PX,
            dof_pyramid_from_px: dof::DEFAULT_PYRAMID_FROM_PX,
            mb_max_samples: motion_blur::DEFAULT_MAX_SAMPLES,
            mb_prefilter_var_px2: 0.0,
            mb_min_flow_px: motion_blur::MIN_FLOW_PX,
            noise_min_leak_ratio: None,
            mb_isotropy_evidence: false,
            noise_fast_samples_per_level: noise::DEFAULT_FAST_SAMPLES_PER_LEVEL,
            fast_effort: 1.0,
        }
    }
}

/// Bad input: each names the input and what is wrong with it.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    #[error("input `{input}` is empty (0×0)")]
    Empty { input: &'static str },
    #[error("input `{input}` is {got_w}×{got_h} but the image is {want_w}×{want_h}")]
    SizeMismatch { input: &'static str, want_w: usize, want_h: usize, got_w: usize, got_h: usize },
    #[error("input `{input}` has a non-finite value ({value}) at x={x}, y={y}, channel {channel}")]
    NonFinite { input: &'static str, x: usize, y: usize, channel: usize, value: f32 },
    #[error("the accurate tier for {effect} needs `{input}`, which was not given")]
    MissingReference { effect: &'static str, input: &'static str },
    #[error("no frames to aggregate")]
    NoFrames,
    #[error("invalid option `{option}`: {problem}")]
    Option { option: &'static str, problem: String },
}

/// Data behind the plots (`--plots`).
#[derive(Clone, Debug, Default)]
pub struct PlotData {
    pub noise: Option<NoisePlotData>,
    pub motion_blur: Option<MbPlotData>,
    pub depth_of_field: Option<DofPlotData>,
}

#[derive(Clone, Debug)]
pub struct FitOutput {
    pub model: CameraModel,
    pub plots: PlotData,
}

fn check_rgb(input: &'static str, img: &Rgb, w: usize, h: usize) -> Result<(), FitError> {
    if img.width != w || img.height != h {
        return Err(FitError::SizeMismatch { input, want_w: w, want_h: h, got_w: img.width, got_h: img.height });
    }
    if let Some((x, y, c)) = img.first_non_finite() {
        let value = img.channels[c][y * w + x];
        return Err(FitError::NonFinite { input, x, y, channel: c, value });
    }
    Ok(())
}

/// `luma`: the frame's shared luma where a blind fit will build it: the frame's
/// finiteness is then read from it (`Rgb::luma_checked`), and the channels are
/// scanned for the first non-finite value only where the luma is not all finite.
fn check_inputs(inp: &FitInputs, opts: &FitOptions, luma: Option<&SharedLuma>) -> Result<(), FitError> {
    let (w, h) = (inp.image.width, inp.image.height);
    if w == 0 || h == 0 {
        return Err(FitError::Empty { input: "image" });
    }
    if !luma.is_some_and(|l| l.full_is_finite()) {
        check_rgb("image", inp.image, w, h)?;
    }
    for (name, r) in [
        ("denoised", inp.denoised),
        ("motion-deblurred", inp.motion_deblurred),
        ("motion-deblurred (second)", inp.motion_deblurred_second),
        ("defocus-deblurred", inp.defocus_deblurred),
    ] {
        if let Some(r) = r {
            check_rgb(name, r, w, h)?;
        }
    }
    // Depth may mark invalid pixels with NaN/Inf/≤0 (Middlebury, KITTI): they are
    // skipped, not rejected. Only the size must match.
    let size = |input: &'static str, got_w: usize, got_h: usize| {
        if (got_w, got_h) == (w, h) {
            Ok(())
        } else {
            Err(FitError::SizeMismatch { input, want_w: w, want_h: h, got_w, got_h })
        }
    };
    if let Some(z) = inp.depth {
        size("depth", z.width, z.height)?;
    }
    if let Some(v) = inp.reference_valid {
        size("reference-valid", v.width, v.height)?;
    }
    // Flow may likewise mark pixels whose motion is unknown (occlusions, a
    // provider's holes) with NaN/Inf: every reader samples it at chosen pixels and
    // skips those (and flow past the frame's diagonal), as it skips invalid depth.
    // Not scanned here: the fits read ~1% of it, and the scan of its two 4.9 MB
    // planes at 1280×960 was ~1.5 ms of the fast tier's ~38 (BENCHMARKS.md).
    // `io::load_flow` still refuses a file holding one, by position.
    if let Some(f) = inp.flow {
        size("flow", f.width, f.height)?;
    }
    if !(opts.dof_node_spacing_px > 0.0 && opts.dof_node_spacing_px <= 2.0) {
        return Err(FitError::Option {
            option: "dof_node_spacing_px",
            problem: format!("must be in (0, 2], got {}", opts.dof_node_spacing_px),
        });
    }
    if !(opts.dof_max_sigma_px > 0.0 && opts.dof_max_sigma_px <= crate::model::MAX_DOF_SIGMA_PX) {
        return Err(FitError::Option {
            option: "dof_max_sigma_px",
            problem: format!("must be in (0, {}], got {}", crate::model::MAX_DOF_SIGMA_PX, opts.dof_max_sigma_px),
        });
    }
    if let Some(h) = opts.dof_pyramid_from_px {
        if !(h.is_finite() && h >= 2.0) {
            return Err(FitError::Option {
                option: "dof_pyramid_from_px",
                problem: format!("must be ≥ 2 px, got {h}"),
            });
        }
    }
    if opts.mb_max_samples < 64 {
        return Err(FitError::Option {
            option: "mb_max_samples",
            problem: format!("must be ≥ 64, got {}", opts.mb_max_samples),
        });
    }
    if !(opts.mb_prefilter_var_px2.is_finite() && (0.0..=16.0).contains(&opts.mb_prefilter_var_px2)) {
        return Err(FitError::Option {
            option: "mb_prefilter_var_px2",
            problem: format!("must be in [0, 16] px², got {}", opts.mb_prefilter_var_px2),
        });
    }
    if !(opts.mb_min_flow_px.is_finite() && opts.mb_min_flow_px >= motion_blur::MIN_FLOW_PX) {
        return Err(FitError::Option {
            option: "mb_min_flow_px",
            problem: format!("must be ≥ {} px, got {}", motion_blur::MIN_FLOW_PX, opts.mb_min_flow_px),
        });
    }
    if opts.noise_stride_px == 0 {
        return Err(FitError::Option { option: "noise_stride_px", problem: "must be ≥ 1".into() });
    }
    if !(opts.fast_effort >= MIN_FAST_EFFORT && opts.fast_effort <= 1.0) {
        return Err(FitError::Option {
            option: "fast_effort",
            problem: format!("must be in [{MIN_FAST_EFFORT}, 1], got {}", opts.fast_effort),
        });
    }
    if opts.noise_fast_samples_per_level < noise::MIN_FAST_SAMPLES_PER_LEVEL {
        return Err(FitError::Option {
            option: "noise_fast_samples_per_level",
            problem: format!(
                "must be ≥ {} (16 luma bins of at least {} samples each), got {}",
                noise::MIN_FAST_SAMPLES_PER_LEVEL,
                noise::MIN_FAST_SAMPLES_PER_LEVEL / 16,
                opts.noise_fast_samples_per_level
            ),
        });
    }
    Ok(())
}

/// Stage timer for `Diagnostics::stages_s`: `lap(name)` adds the time since the
/// previous lap to `name` (stages may recur, e.g. per pyramid level).
pub(crate) struct Stages {
    last: Instant,
    map: std::collections::BTreeMap<String, f64>,
}

impl Stages {
    pub(crate) fn start() -> Self {
        Self { last: Instant::now(), map: Default::default() }
    }

    pub(crate) fn lap(&mut self, name: &str) {
        let now = Instant::now();
        *self.map.entry(name.to_string()).or_insert(0.0) += (now - self.last).as_secs_f64();
        self.last = now;
    }

    pub(crate) fn done(self) -> std::collections::BTreeMap<String, f64> {
        self.map
    }
}

/// Which tier an effect runs at, or the missing-reference error.
fn tier_for(
    opts: &FitOptions,
    reference: Option<&Rgb>,
    effect: &'static str,
    input: &'static str,
) -> Result<Tier, FitError> {
    match (opts.tier, reference) {
        (Some(Tier::Accurate), None) => Err(FitError::MissingReference { effect, input }),
        (Some(t), _) => Ok(t),
        (None, Some(_)) => Ok(Tier::Accurate),
        (None, None) => Ok(Tier::Fast),
    }
}

/// Golden-section search for the minimum of a unimodal `f` on [a, b]: `steps`
/// shrinks of the bracket by 0.618, one new evaluation of `f` each; returns the
/// bracket's midpoint. The bracket ends themselves are never evaluated (callers
/// that accept an end as the answer test it). Shared by the accurate exposure fit
/// (λ to 1e-5) and the thin lens's focus search (14 steps).
fn golden_section(mut a: f64, mut b: f64, steps: usize, f: impl Fn(f64) -> f64) -> f64 {
    let g = 0.618_033_988_75;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..steps {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

/// Golden-section steps that shrink a bracket of `width` below `tol`.
fn golden_steps(width: f64, tol: f64) -> usize {
    if width <= tol {
        return 0;
    }
    ((tol / width).ln() / 0.618_033_988_75f64.ln()).ceil() as usize
}

fn not_identifiable(method: &str, reason: impl Into<String>, started: Instant) -> Diagnostics {
    Diagnostics {
        status: crate::model::Status::NotIdentifiable,
        reason: reason.into(),
        method: method.to_string(),
        residual_before: None,
        residual_after: None,
        samples_used: 0,
        fit_time_s: started.elapsed().as_secs_f64(),
        stderr: None,
        stages_s: Default::default(),
    }
}

/// Last guard before anything is written or uploaded: an effect whose fit is not a
/// valid model (e.g. a line through a handful of samples that predicts a std above 1
/// somewhere in range) is reported not identifiable, with the validation message,
/// instead of being passed on or failing the whole fit.
fn sanitize(model: &mut CameraModel) {
    let (w, h) = (model.reference.width, model.reference.height);
    let reset = |effect: &str, e: crate::model::ModelError, old: &Diagnostics| {
        let mut d = old.clone();
        d.status = crate::model::Status::NotIdentifiable;
        d.reason = format!("fit rejected ({e}); the data do not support a {effect} model");
        d
    };
    let mut probe = CameraModel::empty(w.max(1), h.max(1));
    probe.noise = model.noise.clone();
    if let Err(e) = probe.validate() {
        model.noise = Noise::absent(reset("noise", e, &model.noise.diagnostics));
    }
    let mut probe = CameraModel::empty(w.max(1), h.max(1));
    probe.motion_blur = model.motion_blur.clone();
    if let Err(e) = probe.validate() {
        model.motion_blur = MotionBlur::absent(reset("motion-blur", e, &model.motion_blur.diagnostics));
    }
    let mut probe = CameraModel::empty(w.max(1), h.max(1));
    probe.depth_of_field = model.depth_of_field.clone();
    if let Err(e) = probe.validate() {
        let units = model.depth_of_field.units;
        model.depth_of_field =
            DepthOfField::absent(units, reset("depth-of-field", e, &model.depth_of_field.diagnostics));
    }
    let mut probe = CameraModel::empty(w.max(1), h.max(1));
    probe.colour = model.colour.clone();
    if let Err(e) = probe.validate() {
        model.colour = crate::model::Colour::absent(reset("colour", e, &model.colour.diagnostics));
    }
}

/// `luma`: the frame's luma where a blind exposure or defocus fit of the same call
/// builds it anyway (`SharedLuma`), for the blind noise fit's blocking scan.
fn fit_noise(
    inp: &FitInputs,
    opts: &FitOptions,
    tier: Tier,
    luma: Option<&SharedLuma>,
) -> (Noise, Option<NoisePlotData>) {
    if !opts.effects.noise {
        return (Noise::absent(Diagnostics::not_fitted("not requested (--only)")), None);
    }
    let (noise, data) = match (tier, inp.denoised) {
        (Tier::Accurate, Some(clean)) => noise::fit_accurate(inp.image, clean, inp.reference_valid, opts),
        _ => {
            let per_level = opts.noise_fast_samples_per_level;
            // The shared luma first (where another blind fit reads it too; `fit`
            // builds it as the frame's finiteness check, and adds that time here).
            // Built inside the blocking stage it cost more than it saved (same-moment
            // A/B, BENCHMARKS.md); timed here, as the noise fit's `blur.shared_luma`.
            let built = Instant::now();
            if let Some(l) = luma {
                l.full();
            }
            let shared_luma_s = luma.map(|_| built.elapsed().as_secs_f64());
            let (mut with, data) = noise::fit_fast_with_luma(inp.image, inp.neighbour.as_ref(), per_level, luma);
            if let Some(t) = shared_luma_s {
                with.diagnostics.fit_time_s += t;
                with.diagnostics.stages_s.insert("blur.shared_luma".into(), t);
            }
            match (&with.blocking, inp.neighbour.is_some()) {
                // A block codec's inter-frame prediction copies a frame's noise into
                // the next (skipped blocks; predicted ones carry it under their
                // residual), so the difference with a neighbour holds little of it:
                // on the DivX clip (tests/data/noise_vtest; 72% of pixels identical
                // to the next frame's) level 0 read −59…−82% with a neighbour 1–10
                // frames away, −31% alone (within 20% inside the luma range it
                // measures). Where the frame shows the codec's grid, it is read alone
                // (a second fit, on such frames only: the grid is found inside the
                // fit, and `fit_noise_fast` keeps the raw difference for probes).
                (Some(_), true) => {
                    let (mut alone, data) = noise::fit_fast_with_luma(inp.image, None, per_level, luma);
                    alone.diagnostics.fit_time_s += with.diagnostics.fit_time_s;
                    alone.diagnostics.reason += "; the aligned neighbour was not used: a block codec carries noise \
                        from frame to frame, so their difference reads it low";
                    (alone, data)
                }
                _ => (with, data),
            }
        }
    };
    (noise, Some(data))
}

/// The frame's luma and its half-resolution `reduce`, each computed once, on first
/// use, for the blind fits that read them (motion blur and DoF, which may run
/// concurrently): a 1280×960 luma plane costs ~3 ms to build, its reduction ~1 ms,
/// mostly memory traffic. The reduction is always of this luma: callers never pair
/// planes themselves.
pub(super) struct SharedLuma<'a> {
    image: &'a Rgb,
    /// The luma and whether all of it is finite (`Rgb::luma_checked`).
    full: std::sync::OnceLock<(Plane, bool)>,
    half: std::sync::OnceLock<Plane>,
}

impl<'a> SharedLuma<'a> {
    fn new(image: &'a Rgb) -> Self {
        Self { image, full: Default::default(), half: Default::default() }
    }

    /// The frame's luma.
    pub(super) fn full(&self) -> &Plane {
        &self.full.get_or_init(|| self.image.luma_checked()).0
    }

    /// Whether every value of `full()` is finite (which builds it).
    fn full_is_finite(&self) -> bool {
        self.full.get_or_init(|| self.image.luma_checked()).1
    }

    /// `reduce` of the frame's luma (binomial, variance 1 px², the even pixels).
    pub(super) fn half(&self) -> &Plane {
        self.half.get_or_init(|| crate::image::reduce(self.full()))
    }
}

fn fit_motion_blur(
    inp: &FitInputs,
    opts: &FitOptions,
    tier: Tier,
    luma: &SharedLuma,
) -> (MotionBlur, Option<MbPlotData>) {
    if !opts.effects.motion_blur {
        return (MotionBlur::absent(Diagnostics::not_fitted("not requested (--only)")), None);
    }
    let started = Instant::now();
    let method = if tier == Tier::Accurate { "accurate" } else { "fast" };
    match (inp.flow, tier, inp.motion_deblurred) {
        (None, _, _) => (
            MotionBlur::absent(not_identifiable(method, "no flow map given: exposure not identifiable", started)),
            None,
        ),
        (Some(flow), Tier::Accurate, Some(sharp)) => {
            motion_blur::fit_accurate(inp.image, sharp, inp.motion_deblurred_second, flow, inp.reference_valid, opts)
        }
        (Some(flow), _, _) => motion_blur::fit_fast(luma, flow, opts.mb_isotropy_evidence, opts.fast_effort),
    }
}

fn fit_depth_of_field(
    inp: &FitInputs,
    opts: &FitOptions,
    tier: Tier,
    luma: &SharedLuma,
) -> (DepthOfField, Option<DofPlotData>) {
    if !opts.effects.depth_of_field {
        return (DepthOfField::absent(inp.depth_units, Diagnostics::not_fitted("not requested (--only)")), None);
    }
    let started = Instant::now();
    let method = if tier == Tier::Accurate { "accurate" } else { "fast" };
    match (inp.depth, tier, inp.defocus_deblurred) {
        (None, _, _) => (
            DepthOfField::absent(
                inp.depth_units,
                not_identifiable(method, "no depth map given: δ(Z) not identifiable", started),
            ),
            None,
        ),
        (Some(depth), Tier::Accurate, Some(sharp)) => dof::fit_accurate(inp.image, sharp, depth, inp.depth_units, opts),
        (Some(depth), _, _) => dof::fit_fast(luma, depth, inp.depth_units, opts),
    }
}

/// Fit the camera model of one frame.
pub fn fit(inp: &FitInputs, opts: &FitOptions) -> Result<FitOutput, FitError> {
    let fx = opts.effects;
    let tier = |wanted: bool, r: Option<&Rgb>, effect, input| {
        if wanted {
            tier_for(opts, r, effect, input)
        } else {
            Ok(Tier::Fast)
        }
    };
    // (The tiers' errors are returned after the inputs' own, as before.)
    let noise_tier = tier(fx.noise, inp.denoised, "noise", "denoised");
    let mb_tier = tier(fx.motion_blur, inp.motion_deblurred, "motion blur", "motion-deblurred");
    let dof_tier = tier(fx.depth_of_field, inp.defocus_deblurred, "depth of field", "defocus-deblurred");
    let luma = SharedLuma::new(inp.image);
    // The blind exposure and defocus fits read the frame's luma; where one of them
    // runs, the blind noise fit reads it too (built once, by whichever comes first),
    // and the input check reads the frame's finiteness from it (a 1280×960 frame's
    // three channels are 14.7 MB, scanned in ~0.5 ms; its luma is a third of that,
    // checked as it is written). Only for a non-empty frame.
    let blind_reads_luma = (fx.motion_blur && matches!(mb_tier, Ok(Tier::Fast)) && inp.flow.is_some())
        || (fx.depth_of_field && matches!(dof_tier, Ok(Tier::Fast)) && inp.depth.is_some());
    let prebuilt = (blind_reads_luma && inp.image.width > 0 && inp.image.height > 0).then_some(&luma);
    let built = Instant::now();
    let luma_s = prebuilt.map(|l| {
        l.full();
        built.elapsed().as_secs_f64()
    });
    check_inputs(inp, opts, prebuilt)?;
    let (noise_tier, mb_tier, dof_tier) = (noise_tier?, mb_tier?, dof_tier?);
    let (w, h) = (inp.image.width, inp.image.height);
    let mut model = CameraModel { schema: SCHEMA.to_string(), ..CameraModel::empty(w as u32, h as u32) };
    model.depth_of_field.units = inp.depth_units;
    let mut plots = PlotData::default();

    // The three effects are independent: fit them concurrently (rayon::join), so
    // the wall time on several cores is the slowest effect, not the sum.
    // Tiers (and missing-reference errors) only for the effects asked for.
    let noise_luma = blind_reads_luma.then_some(&luma);
    // The colour and sharpening terms read the frame alone and join them (colour:
    // 5.6 ms at 1280×960).
    let (((noise, mb), dof), (colour, sharpening)) = rayon::join(
        || {
            rayon::join(
                || {
                    rayon::join(
                        || fit_noise(inp, opts, noise_tier, noise_luma),
                        || fit_motion_blur(inp, opts, mb_tier, &luma),
                    )
                },
                || fit_depth_of_field(inp, opts, dof_tier, &luma),
            )
        },
        || {
            (
                opts.colour.then(|| colour::fit_colour(inp.image)),
                opts.sharpening.then(|| sharpening::estimate(inp.image, SHARPENING_MAX_EDGES)),
            )
        },
    );
    (model.noise, plots.noise) = noise;
    (model.motion_blur, plots.motion_blur) = mb;
    (model.depth_of_field, plots.depth_of_field) = dof;
    if let Some(c) = colour {
        model.colour = c;
    }
    if let Some(s) = sharpening {
        model.sharpening = s;
    }
    // The luma, built with the input check, has its build time added to the fit
    // stage that would otherwise build it (~0 there with the luma prebuilt): the
    // blind noise fit's `blur.shared_luma` stage, or without that fit the blind
    // defocus fit's `luma`.
    if let Some(t) = luma_s {
        let slots =
            [(&mut model.noise.diagnostics, "blur.shared_luma"), (&mut model.depth_of_field.diagnostics, "luma")];
        if let Some((d, stage)) = slots.into_iter().find(|(d, k)| d.stages_s.contains_key(*k)) {
            *d.stages_s.entry(stage.into()).or_default() += t;
            d.fit_time_s += t;
        }
    }
    sanitize(&mut model);
    Ok(FitOutput { model, plots })
}
