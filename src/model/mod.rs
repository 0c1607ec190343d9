//! The camera model: plain data, one versioned JSON document
//! (`"schema": "blind-augment/camera-model/5"`; version 1 documents, which have no
//! `colour`, version 2, which have no `vignetting`, version 3, which have no
//! `chromatic_aberration`, and version 4, which have no `sharpening`, still read), with
//! validation on load so that no NaN, Inf or out-of-range parameter can reach a
//! renderer.
//!
//! Every effect carries `present` (the renderer skips absent effects) and
//! `diagnostics` (how sure the estimator is, how it got there).

pub mod compare;
pub mod geometry;
pub use geometry::{covering_rect, half_rect, tile_rect, EyeChromatic, EyeGain, EyeVignette, GrainTable, Rect};
pub mod kernels;
mod validate;

use serde::{Deserialize, Serialize};
pub use validate::ModelError;

pub const SCHEMA: &str = "blind-augment/camera-model/5";
/// Schemas `CameraModel::from_json` reads: version 1 is version 2 without `colour`,
/// version 2 is version 3 without `vignetting`, version 3 is version 4 without
/// `chromatic_aberration`, version 4 is version 5 without `sharpening` (each read as not
/// fitted); files are always written as `SCHEMA`.
pub const READABLE_SCHEMAS: [&str; 5] = [
    "blind-augment/camera-model/1",
    "blind-augment/camera-model/2",
    "blind-augment/camera-model/3",
    "blind-augment/camera-model/4",
    SCHEMA,
];
/// Largest |s − 1| of a channel's lateral-aberration scale: 0.01 moves a 1280×960
/// frame's corner by 8 px. lensfun's TCA profiles stay far inside it (their 3 588
/// "linear"/"poly3" profiles at 1280×960: corner shifts of a few pixels at most,
/// median 0.1 px, `benches/chromatic.rs`); past it a reading is a failed fit, not a
/// lens.
pub const MAX_CHROMATIC_SCALE_DEVIATION: f32 = 0.01;
/// Range of the ISP's unsharp-mask amount k: 0 (none) to 4 (an edge overshooting by
/// over a third of its step; phone ISPs' strongest presets stay near 1–2).
pub const SHARPENING_AMOUNT_RANGE: [f32; 2] = [0.0, 4.0];
/// Range of the unsharp mask's Gaussian σ (reference px): under 0.3 px a 3×3
/// kernel cannot express it; past 4 px it is local contrast, not sharpening.
pub const SHARPENING_RADIUS_RANGE_PX: [f32; 2] = [0.3, 4.0];
/// Bounds of the vignetting gain V(r) over the frame (r in [0, 1]): a lens that
/// passes under 1/20 of the centre's light at its corner is outside any headset
/// camera (lensfun's 19 920 "pa" profiles: the darkest corner passes 0.13), and a
/// corner brighter than twice the centre is an ISP's over-correction no camera ships.
pub const VIGNETTING_GAIN_RANGE: [f32; 2] = [0.05, 2.0];
/// Largest linear-light gain `Colour::gains` may apply to a channel (and smallest
/// its reciprocal): six stops either way, beyond any auto-exposure's reach between
/// a lit room and the virtual content's authored level.
pub const MAX_COLOUR_GAIN: f32 = 64.0;
/// Band-pass levels of the noise pyramid (the paper's 4; the official code's 3 is
/// what the paper calls a mistake-prone simplification: see docs/camera-model.md).
pub const NOISE_LEVELS: usize = 4;

/// Luma nodes of a grain synthesis table (`synth::SynthesisTable`, `GrainTable`).
pub const GRAIN_TABLE_NODES: usize = 33;
/// Largest DoF blur std the estimators search and the model may express, in
/// reference pixels (the paper searches [0, 10]).
pub const MAX_DOF_SIGMA_PX: f32 = 10.0;
/// Depth of field is defined by a stack of discrete-Gaussian blurs with nodes this
/// far apart in σ (px), blended with variance-matched weights between nodes.
pub const DOF_NODE_SPACING_PX: f32 = 0.25;
/// Motion blur is defined as the exposure-window line integral sampled by the
/// trapezoid rule with nodes at most this far apart (px) ...
pub const MB_MAX_SAMPLE_SPACING_PX: f32 = 0.1;
/// ... and at least this many intervals per pixel. Both the CPU reference
/// (`synth`) and the GPU pass (`render`) read these, so they define one effect.
pub const MB_MIN_INTERVALS: u32 = 8;

/// Whether a flow vector (px per frame) displaces content by at most the diagonal
/// of a `width`×`height` frame. A longer one matches nothing still in the frame (a
/// flow estimator's failure, Middlebury's > 1e9 unknown-flow marker, a flow map of
/// another frame size): the fits do not sample it, `io::load_flow` and the GPU
/// motion-blur pass refuse it, `synth` takes it as no motion — its streak would
/// cost taps in proportion to its length. False for non-finite flow.
pub fn flow_within_frame(dx: f32, dy: f32, width: usize, height: usize) -> bool {
    dx * dx + dy * dy <= (width * width + height * height) as f32
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraModel {
    pub schema: String,
    pub reference: Reference,
    pub noise: Noise,
    pub motion_blur: MotionBlur,
    pub depth_of_field: DepthOfField,
    /// The camera's white balance and exposure as a virtual surface must take them;
    /// absent from version-1 files (read as not fitted).
    #[serde(default = "Colour::not_fitted")]
    pub colour: Colour,
    /// The lens's radial falloff; absent from version-1 and -2 files (read as not
    /// fitted).
    #[serde(default = "Vignetting::not_fitted")]
    pub vignetting: Vignetting,
    /// The lens's lateral chromatic aberration; absent from version-1 to -3 files
    /// (read as not fitted).
    #[serde(default = "ChromaticAberration::not_fitted")]
    pub chromatic_aberration: ChromaticAberration,
    /// The ISP's edge sharpening; absent from version-1 to -4 files (read as not
    /// fitted).
    #[serde(default = "Sharpening::not_fitted")]
    pub sharpening: Sharpening,
}

/// The ISP's sharpening as an unsharp mask on the encoded image:
/// out = in + k·(in − G_σ ∗ in), G_σ the discrete Gaussian of std `radius_px`
/// (reference px; `model::kernels::discrete_gaussian_kernel`). A step edge of
/// blur σ_e comes out as (1 + k)·Φ(t/σ_e) − k·Φ(t/√(σ_e² + σ²)): an overshoot on
/// its bright side and an undershoot on its dark side (the halo). Applied after the
/// white balance and exposure, before the noise (the ISP's order).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sharpening {
    pub present: bool,
    /// k, within `SHARPENING_AMOUNT_RANGE`. `null` when not identifiable.
    pub amount: Option<f32>,
    /// σ (reference px), within `SHARPENING_RADIUS_RANGE_PX`. `null` when not
    /// identifiable.
    pub radius_px: Option<f32>,
    /// The halo the frames' own edges show: the overshoot of their pooled profile
    /// past its bright level, as a fraction of the step (model-free: a blur alone
    /// leaves a step monotone), in [0, 1]. `null` when not measured.
    #[serde(default)]
    pub overshoot: Option<f32>,
    /// `diagnostics.stderr`: one-sigma uncertainty of `overshoot`.
    pub diagnostics: Diagnostics,
}

/// Lateral chromatic aberration: the lens images red and blue at other
/// magnifications than green, so channel c of a virtual surface's image is green's
/// image scaled by s_c about the optical centre (lensfun's "linear" TCA model,
/// r_c = s_c·r). The renderer resamples red and blue of the virtual layer at
/// c + (p − c)/s_c. Read blindly from colour fringes at radial edges
/// (`fit::chromatic`). Optics: applied with the falloff, before the ISP's colour
/// and noise.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChromaticAberration {
    pub present: bool,
    /// [s_R − 1, s_B − 1], each within ±`MAX_CHROMATIC_SCALE_DEVIATION`. `null` when
    /// not identifiable.
    pub scale_minus_one: Option<[f32; 2]>,
    /// `diagnostics.stderr`: one-sigma uncertainty of the larger channel's corner
    /// shift, in reference-frame pixels.
    pub diagnostics: Diagnostics,
}

/// The lens's radial falloff of light (and what of it the ISP's shading correction
/// leaves): a virtual surface's linear-light colour at normalised radius r is
/// multiplied by V(r) = exp(a1·r² + a2·r⁴ + a3·r⁶). r is the distance from the frame's
/// centre over its half-diagonal (1 at the corners), lensfun's convention for its
/// "pa" profiles (V = 1 + k1·r² + k2·r⁴ + k3·r⁶, r = 1 at the corner of the
/// calibration frame: lensfun `mod-color.cpp`, `rescale_polynomial_coefficients`).
/// The log-polynomial makes the fit linear in frame-to-frame log-ratios of the same
/// surface (`fit::vignetting`). Applied before every other effect (the optics'
/// order: falloff, then defocus and motion blur; then the ISP).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vignetting {
    pub present: bool,
    /// [a1, a2, a3] of log V(r) = a1·r² + a2·r⁴ + a3·r⁶ (lensfun's three even
    /// terms, in the log: 0.2% of light from its profiles where two terms leave
    /// 1.2%). `null` when not identifiable.
    pub log_falloff: Option<[f32; 3]>,
    /// `diagnostics.stderr`: one-sigma uncertainty of the corner's falloff 1 − V(1).
    pub diagnostics: Diagnostics,
}
/// The camera's rendering of a neutral surface under the room's light, relative to
/// the virtual content's neutral (ARCore's colour correction and pixel intensity
/// are the same quantities): a virtual surface's linear-light colour is multiplied
/// by `gains` = `exposure` · `illuminant`, so a virtual grey lands where the camera
/// puts a real grey of the same reflectance. Applied after motion blur and before
/// the grain (the camera's order: optics, then the ISP's white balance and gain,
/// then its noise).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Colour {
    pub present: bool,
    /// Linear RGB of a neutral surface as the camera renders it, luma 1 (Rec. 601
    /// weights, as the noise maps' luma): its chromaticity only. `null` when not
    /// identifiable.
    pub illuminant: Option<[f32; 3]>,
    /// Linear-light brightness gain: the camera's rendering of an 18% grey surface
    /// over 0.18. `null` when not identifiable.
    pub exposure: Option<f32>,
    /// `diagnostics.stderr`: one-sigma angular uncertainty of `illuminant` in degrees.
    pub diagnostics: Diagnostics,
}
/// The frames the model was fitted on, so a renderer can convert camera pixels and
/// frame intervals into its own pixels and seconds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reference {
    pub width: u32,
    pub height: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixels_per_radian: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_interval_s: Option<f32>,
}

/// How the per-level maps read: `linear_std`: std = intercept + slope·Y (the paper);
/// `affine_variance`: std² = intercept + slope·Y (Poisson–Gaussian sensor noise).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseForm {
    LinearStd,
    AffineVariance,
}

/// What a level's map reads as its intensity.
///
/// `luma` is the paper's choice (Sec. 3.2 and its supplement: one luma, Y of YCbCr,
/// drives the R, G, B stds). A sensor's shot noise follows each photosite's own
/// signal, so after white balance a channel's noise follows that channel's value:
/// on frames made that way (tests/independent_forward.rs: a Poisson sensor with
/// white-balance gains 1.9/1.0/1.6) a luma-driven fit is a median 9–12% off on
/// neutral greys, and no line in Y can fix it. The accurate fit tries both and keeps
/// the likelier (model only what the frame requires).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseIntensity {
    /// Y (Rec. 601 luma) of the content drives every channel.
    #[default]
    Luma,
    /// Channel c's own value drives channel c.
    Channel,
}

impl NoiseIntensity {
    pub fn is_luma(&self) -> bool {
        *self == NoiseIntensity::Luma
    }
}

/// One pyramid level's map from intensity (luma Y, or the channel's own value: see
/// `NoiseIntensity`) to R, G, B noise.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseLevel {
    pub slope: [f32; 3],
    pub intercept: [f32; 3],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    pub present: bool,
    pub form: NoiseForm,
    /// What the maps read as intensity; absent in files written before it existed
    /// (read as luma, which is what those files meant), so the schema is unchanged.
    #[serde(default, skip_serializing_if = "NoiseIntensity::is_luma")]
    pub intensity: NoiseIntensity,
    /// Band-pass levels 0..4, finest first.
    pub levels: Vec<NoiseLevel>,
    /// The low-pass residual's map (fitted like a band; `null` if not modelled).
    pub lowpass: Option<NoiseLevel>,
    /// Intensity range fitted on (luma, or the channels' values for
    /// `NoiseIntensity::Channel`); evaluation clamps into it (no extrapolation into
    /// clipped highlights or crushed blacks).
    pub luminance_range: [f32; 2],
    /// The blind fit's level-0 measurement per luma bin, with its confidence (empty
    /// for the accurate tier and for models written by hand).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bins: Vec<NoiseBin>,
    /// How the blind fit read each band-pass level (empty for the accurate tier and
    /// for models written by hand): measured, with its confidence, or continued from
    /// a finer level where the frame could not say.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub level_sources: Vec<LevelSource>,
    /// Block-transform compression seen in the frame (`null`: none found or not
    /// looked for). Its fine levels then hold codec artefacts as well as noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blocking: Option<Blocking>,
    pub diagnostics: Diagnostics,
}

/// One luma bin of a blind noise measurement (level 0).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseBin {
    /// Mean smoothed luma of the bin's flat samples.
    pub luma: f32,
    /// Flat samples the bin was measured on.
    pub samples: u32,
    /// Measured level-0 std per channel.
    pub std: [f32; 3],
    /// Relative standard error of `std` (mean over channels): the bin's confidence —
    /// its sampling error, and for a frame read alone the texture its flattest
    /// samples may hold (the blind fit's texture floor), in quadrature.
    pub relative_stderr: f32,
    /// Whether the fit used the bin (false: rejected as texture).
    pub used: bool,
}

/// How the blind fit read one band-pass level's map (`Noise::level_sources`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum LevelSource {
    /// Fitted on the level's own flat samples: `bins` luma bins whose mean lumas span
    /// `luma`. `relative_stderr` is the map's standard error relative to its std,
    /// mean over channels, root-mean-square over `Noise::luminance_range`: its
    /// sampling error, a prior for what the frame's texture (or, against an aligned
    /// neighbour, the scene's mismatch) adds, and beyond `luma` how far two
    /// continuations of its bins (its own line, and level 0's luma shape scaled to
    /// them) part — a level read on a few dark bins is only as sure as its line there.
    Measured { luma: [f32; 2], bins: u32, relative_stderr: f32 },
    /// Not identifiable from the frame (its flattest samples are texture, or too few
    /// flat luma bins): level `from`'s map continued by white noise's band ratios.
    Continued { from: u32 },
}

/// A periodic block grid in the frame (JPEG / MPEG-style codecs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Blocking {
    pub period_px: u32,
    /// Column and row phase of the block boundaries (x mod period, y mod period).
    pub phase_px: [u32; 2],
    /// Mean luma step across the boundary phase over the median of the other phases
    /// (the weaker of the two directions).
    pub strength: f32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionBlur {
    pub present: bool,
    /// λ ∈ [0, 1]: fraction of the frame interval the shutter is open; flow is in
    /// pixels per frame interval and the window is centred on the frame time.
    /// `null` when not identifiable.
    pub exposure: Option<f32>,
    pub diagnostics: Diagnostics,
}

/// How the depth map's values are to be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthUnits {
    /// Metric depth Z in metres along the optical axis (larger = farther).
    MetricM,
    /// Relative inverse depth as monocular networks (MiDaS/DPT) produce: affine in
    /// 1/Z, larger = nearer. The thin-lens form is then linear in the value itself.
    RelativeInverse,
}

impl DepthUnits {
    /// The quantity in which defocus is linear (thin lens: blur ∝ |1/Z − 1/Z_f|).
    #[inline]
    pub fn inverse_depth(self, z: f32) -> f32 {
        match self {
            DepthUnits::MetricM => 1.0 / z,
            DepthUnits::RelativeInverse => z,
        }
    }
}

/// δ(Z), the Gaussian blur std in reference pixels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "form", rename_all = "snake_case", deny_unknown_fields)]
pub enum DofCurve {
    /// δ = a·Z² + b·Z + c (the paper).
    Quadratic { a: f32, b: f32, c: f32 },
    /// δ = k·|u(Z) − u(Z_f)| + c0, u = inverse depth (`DepthUnits::inverse_depth`);
    /// bounded as Z → ∞.
    ThinLens { k: f32, focus_depth: f32, c0: f32 },
    /// δ = c: the fitted curve was flat within its uncertainty.
    Constant { c: f32 },
}

/// The shape of the defocus point-spread function (the image of the aperture).
/// δ(Z) is always the std of the Gaussian with the same second moment, so a model
/// switches shape without changing its curve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DofKernel {
    /// Discrete Gaussian of std δ (the paper's addDoF).
    #[default]
    Gaussian,
    /// Uniform disc (a round aperture, what real lenses draw: Neural Cameras fig. 5),
    /// radius `kernels::disc_radius_px(δ)` ≈ 2δ, pixel-area anti-aliased; below
    /// `kernels::DISC_MIN_SIGMA_PX` the Gaussian of the same δ.
    Disc,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DepthOfField {
    pub present: bool,
    pub units: DepthUnits,
    /// `null` when not identifiable.
    pub curve: Option<DofCurve>,
    /// Depth range the model holds for (fits: the frame's depths, the textured ones
    /// extrapolated a bounded distance); evaluation clamps Z into it.
    pub depth_range: [f32; 2],
    /// Kernel shape; absent in files written before it existed (read as Gaussian,
    /// which is what those files meant), so the schema version is unchanged.
    #[serde(default)]
    pub kernel: DofKernel,
    pub diagnostics: Diagnostics,
}

/// What an estimator concluded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Fitted, and the fit explains the data better than "no effect" by more than the
    /// noise floor.
    Present,
    /// Identifiable, but the effect is within the noise floor of zero.
    Absent,
    /// The data cannot tell (no flow, no texture, no depth, no reference...).
    NotIdentifiable,
    /// Not asked for (`--only`).
    NotFitted,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Diagnostics {
    pub status: Status,
    /// Human-readable reason for the status.
    pub reason: String,
    /// `accurate` (clean reference images) or `fast` (blind, frame only).
    pub method: String,
    /// Fit objective with no effect and with the fitted effect (units per effect,
    /// stated in `reason` and docs/camera-model.md).
    pub residual_before: Option<f64>,
    pub residual_after: Option<f64>,
    pub samples_used: u64,
    /// Wall time of the fit alone, without file I/O.
    pub fit_time_s: f64,
    /// One-sigma uncertainty of the headline parameter (λ; δ RMS over the range in px;
    /// relative std of the level-0 noise std at mid-range luma).
    pub stderr: Option<f64>,
    /// Wall time of the fit's stages in seconds (e.g. "blur", "search",
    /// "least_squares"), for profiling; empty when not measured.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub stages_s: std::collections::BTreeMap<String, f64>,
}

impl Diagnostics {
    pub fn status_str(&self) -> &'static str {
        match self.status {
            Status::Present => "present",
            Status::Absent => "absent",
            Status::NotIdentifiable => "not identifiable",
            Status::NotFitted => "not fitted",
        }
    }

    pub fn not_fitted(reason: &str) -> Self {
        Self {
            status: Status::NotFitted,
            reason: reason.to_string(),
            method: String::new(),
            residual_before: None,
            residual_after: None,
            samples_used: 0,
            fit_time_s: 0.0,
            stderr: None,
            stages_s: Default::default(),
        }
    }
}

impl NoiseLevel {
    pub const ZERO: NoiseLevel = NoiseLevel { slope: [0.0; 3], intercept: [0.0; 3] };

    /// Noise std of channel `c` at luma `y` (already clamped), never negative.
    #[inline]
    pub fn std(&self, form: NoiseForm, c: usize, y: f32) -> f32 {
        let v = self.intercept[c] + self.slope[c] * y;
        match form {
            NoiseForm::LinearStd => v.max(0.0),
            NoiseForm::AffineVariance => v.max(0.0).sqrt(),
        }
    }
}

impl Noise {
    pub fn absent(diagnostics: Diagnostics) -> Self {
        Self {
            present: false,
            form: NoiseForm::AffineVariance,
            intensity: NoiseIntensity::Luma,
            levels: vec![NoiseLevel::ZERO; NOISE_LEVELS],
            lowpass: None,
            luminance_range: [0.0, 1.0],
            bins: vec![],
            level_sources: vec![],
            blocking: None,
            diagnostics,
        }
    }

    #[inline]
    pub fn clamp_luma(&self, y: f32) -> f32 {
        y.clamp(self.luminance_range[0], self.luminance_range[1])
    }
}

impl DofCurve {
    /// δ at depth `z` (already clamped to the range), clamped to [0, MAX_DOF_SIGMA_PX].
    pub fn sigma_px(&self, units: DepthUnits, z: f32) -> f32 {
        let d = match *self {
            DofCurve::Quadratic { a, b, c } => (a * z + b) * z + c,
            DofCurve::ThinLens { k, focus_depth, c0 } => {
                k * (units.inverse_depth(z) - units.inverse_depth(focus_depth)).abs() + c0
            }
            DofCurve::Constant { c } => c,
        };
        if d.is_finite() {
            d.clamp(0.0, MAX_DOF_SIGMA_PX)
        } else {
            0.0
        }
    }
}

impl DepthOfField {
    pub fn absent(units: DepthUnits, diagnostics: Diagnostics) -> Self {
        Self { present: false, units, curve: None, depth_range: [0.0, 0.0], kernel: DofKernel::Gaussian, diagnostics }
    }

    /// δ(Z) in reference pixels; 0 for absent effects and invalid depth. Z is clamped
    /// to the fitted range first.
    pub fn sigma_px(&self, z: f32) -> f32 {
        match (&self.curve, self.present) {
            (Some(curve), true) if z.is_finite() => {
                curve.sigma_px(self.units, z.clamp(self.depth_range[0], self.depth_range[1]))
            }
            _ => 0.0,
        }
    }
}

impl MotionBlur {
    pub fn absent(diagnostics: Diagnostics) -> Self {
        Self { present: false, exposure: None, diagnostics }
    }

    /// λ the renderer should use: 0 when absent or unknown.
    pub fn exposure_or_zero(&self) -> f32 {
        if self.present {
            self.exposure.unwrap_or(0.0)
        } else {
            0.0
        }
    }
}

impl Colour {
    pub fn absent(diagnostics: Diagnostics) -> Self {
        Self { present: false, illuminant: None, exposure: None, diagnostics }
    }

    pub fn not_fitted() -> Self {
        Self::absent(Diagnostics::not_fitted("not fitted"))
    }

    /// The per-channel linear gain the renderer applies: 1 when absent or unknown.
    pub fn gains_or_one(&self) -> [f32; 3] {
        match (self.present, self.illuminant, self.exposure) {
            (true, Some(i), Some(e)) => i.map(|c| c * e),
            _ => [1.0; 3],
        }
    }
}

impl Vignetting {
    pub fn absent(diagnostics: Diagnostics) -> Self {
        Self { present: false, log_falloff: None, diagnostics }
    }

    pub fn not_fitted() -> Self {
        Self::absent(Diagnostics::not_fitted("not fitted"))
    }

    /// Normalised radius of a pixel position in a `w`×`h` frame (pixel centres at
    /// +0.5): its distance from the frame's centre over the half-diagonal.
    pub fn radius(w: usize, h: usize, x: f32, y: f32) -> f32 {
        let (cx, cy) = (w as f32 * 0.5, h as f32 * 0.5);
        (x - cx).hypot(y - cy) / cx.hypot(cy)
    }

    /// V(r) of `log_falloff` (r: centre-to-corner normalised radius).
    pub fn gain_at(log_falloff: [f32; 3], r: f32) -> f32 {
        let r2 = r * r;
        (r2 * (log_falloff[0] + r2 * (log_falloff[1] + r2 * log_falloff[2]))).exp()
    }

    /// The coefficients the renderer applies: `None` when absent or unknown.
    pub fn applied(&self) -> Option<[f32; 3]> {
        self.log_falloff.filter(|_| self.present)
    }
}

impl Sharpening {
    pub fn absent(diagnostics: Diagnostics) -> Self {
        Self { present: false, amount: None, radius_px: None, overshoot: None, diagnostics }
    }

    pub fn not_fitted() -> Self {
        Self::absent(Diagnostics::not_fitted("not fitted"))
    }

    /// (k, σ px) the renderer applies: `None` when absent or unknown.
    pub fn applied(&self) -> Option<(f32, f32)> {
        self.amount.zip(self.radius_px).filter(|_| self.present)
    }

    /// The edge profile after sharpening: a unit step at t = 0 blurred by
    /// `edge_sigma_px`, then the unsharp mask (k, σ), at offset `t_px`.
    pub fn edge_profile(amount: f64, radius_px: f64, edge_sigma_px: f64, t_px: f64) -> f64 {
        let phi = |x: f64| 0.5 * (1.0 + libm::erf(x / std::f64::consts::SQRT_2));
        let s1 = edge_sigma_px.max(1e-6);
        let s2 = (s1 * s1 + radius_px * radius_px).sqrt();
        (1.0 + amount) * phi(t_px / s1) - amount * phi(t_px / s2)
    }

    /// The overshoot of a unit step of blur `edge_sigma_px` past its bright side's
    /// level (fraction of the step): the halo's visible size.
    pub fn overshoot(amount: f64, radius_px: f64, edge_sigma_px: f64) -> f64 {
        let reach = 4.0 * (edge_sigma_px * edge_sigma_px + radius_px * radius_px).sqrt() + 1.0;
        (0..=400)
            .map(|i| Self::edge_profile(amount, radius_px, edge_sigma_px, reach * i as f64 / 400.0))
            .fold(1.0f64, f64::max)
            - 1.0
    }
}

impl ChromaticAberration {
    pub fn absent(diagnostics: Diagnostics) -> Self {
        Self { present: false, scale_minus_one: None, diagnostics }
    }

    pub fn not_fitted() -> Self {
        Self::absent(Diagnostics::not_fitted("not fitted"))
    }

    /// [s_R − 1, s_B − 1] the renderer applies: `None` when absent or unknown.
    pub fn applied(&self) -> Option<[f32; 2]> {
        self.scale_minus_one.filter(|_| self.present)
    }
}

impl CameraModel {
    /// A model with every effect absent, for the given reference frame size.
    pub fn empty(width: u32, height: u32) -> Self {
        Self {
            schema: SCHEMA.to_string(),
            reference: Reference { width, height, pixels_per_radian: None, frame_interval_s: None },
            noise: Noise::absent(Diagnostics::not_fitted("not fitted")),
            motion_blur: MotionBlur::absent(Diagnostics::not_fitted("not fitted")),
            depth_of_field: DepthOfField::absent(DepthUnits::MetricM, Diagnostics::not_fitted("not fitted")),
            colour: Colour::not_fitted(),
            vignetting: Vignetting::not_fitted(),
            chromatic_aberration: ChromaticAberration::not_fitted(),
            sharpening: Sharpening::not_fitted(),
        }
    }

    /// Parse and validate a JSON document (any of `READABLE_SCHEMAS`; an older one
    /// comes back as the current schema, its missing effects not fitted).
    pub fn from_json(text: &str) -> Result<Self, ModelError> {
        let mut model: CameraModel = serde_json::from_str(text).map_err(|e| ModelError::Parse(e.to_string()))?;
        if model.schema != SCHEMA && READABLE_SCHEMAS.contains(&model.schema.as_str()) {
            model.schema = SCHEMA.to_string();
        }
        model.validate()?;
        Ok(model)
    }

    /// Validate, then pretty-print.
    pub fn to_json(&self) -> Result<String, ModelError> {
        self.validate()?;
        serde_json::to_string_pretty(self).map_err(|e| ModelError::Parse(e.to_string()))
    }
}
