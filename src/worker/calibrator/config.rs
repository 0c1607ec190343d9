//! The calibrator's configuration: the tier (the user's speed/accuracy trade), its
//! schedule and window, and the analysis providers per role.

use crate::analysis::onnx::{OnnxDeblur, OnnxDenoiser, OnnxDepth, OnnxError, OnnxFlow, OnnxModel};
use crate::analysis::{
    DefocusDeblurrer, Denoiser, DepthProvider, FlowProvider, GivenFlow, Intrinsics, LucasKanadeFlow, MotionDeblurrer,
    PoseDepthFlow, Role, TemporalDenoiser, TemporalMotionDeblur,
};
use crate::fit::Effects;

/// How much compute each update may spend (the user's speed/accuracy trade).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibrationTier {
    /// The frame alone (blind estimators), every frame.
    Fast,
    /// Temporal noise reference from 4 frames; motion blur and DoF blind.
    Balanced,
    /// Temporal references for noise (8 frames) and motion blur (sharp frames).
    Accurate,
}

impl CalibrationTier {
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "fast" => Some(Self::Fast),
            "balanced" => Some(Self::Balanced),
            "accurate" => Some(Self::Accurate),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Fast => "fast",
            Self::Balanced => "balanced",
            Self::Accurate => "accurate",
        }
    }

    /// Video time between updates after the burst.
    pub fn update_interval_s(self) -> f64 {
        match self {
            Self::Fast => 0.0,
            Self::Balanced => 0.2,
            Self::Accurate => 0.1,
        }
    }
}

#[derive(Clone, Debug)]
pub struct CalibratorConfig {
    pub tier: CalibrationTier,
    /// Nominal frame interval (s): flow is per this interval.
    pub frame_interval_s: f64,
    pub intrinsics: Option<Intrinsics>,
    pub effects: Effects,
    /// Start-up burst (boundary setup): update on every frame for this long, each
    /// effect refitted every `burst_refit_s`.
    pub burst_s: f64,
    /// Video time between fits after the burst (0: every frame).
    pub update_interval_s: f64,
    /// Estimates aggregated: the last this many seconds of video.
    pub window_s: f64,
    /// Video time between refits of each effect (noise, motion blur, depth of
    /// field) after the burst; an update fits only the effects that are due, so
    /// the cost of rarely changing ones is spread out (a fixed-focus camera's DoF
    /// only changes with a detected change, which restarts the burst).
    pub refit_s: [f64; 3],
    /// The same during a burst (0: every frame). Where it is not 0 noise also takes
    /// turns with the other effects, update by update (the first frame, whose
    /// noise fit has no previous frame, aside): the fast tier refits noise on one
    /// frame and motion blur and depth of field on the next, so the noise fit's
    /// alignment and the motion-blur fit's references (~20 ms each of one core at
    /// 1280×960) never share an update, and a 30 fps burst second still holds 15
    /// fits of each.
    pub burst_refit_s: [f64; 3],
    /// Video time (≥ `window_s`) over which confident λ estimates made with a
    /// reference are combined into the published exposure (their median), back to
    /// the last detected change at most: a camera's exposure holds between changes
    /// (which `change` detects and which drop the older estimates), while a single
    /// turn gives only a few fits, each scattered by ±2–8% on real scenes made
    /// elsewhere (BENCHMARKS.md). Equal to `window_s`: the window's median alone.
    pub exposure_memory_s: f64,
    /// Outside a burst, refit motion blur only on frames whose motion (the sparse
    /// grid's largest, px per frame) shows a streak the temporal fit reads
    /// (`MB_MIN_FLOW_PX`): at rest λ is not identifiable, and a reference made
    /// then is spent for nothing.
    pub mb_moving_only: bool,
    /// Newest frames held for temporal references (besides the sharp ones).
    pub frames_held: usize,
    /// Sharp frames (head at rest) held, and how long (s).
    pub sharp_held: usize,
    pub sharp_max_age_s: f64,
    /// The blind noise fit reads a strip of full rows of about this many pixels per
    /// refit (at least `MIN_STRIP_ROWS` rows), the next strip down each time, and
    /// aligns only that strip of the previous frame (`None`: the whole frame every
    /// time). Aggregation (the median over `window_s`) then sees the whole frame.
    pub noise_strip_px: Option<usize>,
    /// The blind exposure and defocus fits' share of their sample counts
    /// (`FitOptions::fast_effort`, [0.25, 1]): speed for accuracy, measured in
    /// BENCHMARKS.md ("The fast tier's effort").
    pub fast_effort: f32,
    /// Fit the colour term (`fit::colour::fit_colour`, the frame alone whatever the
    /// tier; 5.6 ms at 1280×960) ...
    pub colour: bool,
    /// ... on the first update at least this long (video s) after the last colour
    /// fit: 0.25 s keeps 4 fits in each 1 s window, so a change is followed within
    /// 1 s, at a quarter of the cost per update of fitting every update at 0.1 s.
    pub colour_refit_s: f64,
    /// Fit the vignetting term (`fit::vignetting`, from frame pairs matched by pose
    /// and depth: needs intrinsics, poses and metric depth) ...
    pub vignetting: bool,
    /// ... pairing frames this far apart (video s): at a turning head's 20–60°/s,
    /// 0.25 s moves surfaces a tenth to a third of the frame.
    pub vignetting_refit_s: f64,
    /// Fit the lateral chromatic aberration term (`fit::chromatic`, the frame
    /// alone) ...
    pub chromatic_aberration: bool,
    /// ... on the first update at least this long (video s) after the last: a
    /// lens does not change, so a slow cadence (16 frames in its 8 s window) keeps
    /// its ~4 ms at 1280×960 off most updates.
    pub chromatic_refit_s: f64,
    /// Fit the ISP's sharpening (`fit::sharpening`, the frame alone) ...
    pub sharpening: bool,
    /// ... on the first update at least this long (video s) after the last and
    /// not taken by another slow term: an ISP does not change, so one frame per
    /// second keeps its 35–45 ms at 1280×960 off most updates.
    pub sharpening_refit_s: f64,
}

impl CalibratorConfig {
    pub fn new(tier: CalibrationTier, frame_interval_s: f64, intrinsics: Option<Intrinsics>) -> Self {
        Self {
            tier,
            frame_interval_s,
            intrinsics,
            effects: Effects::ALL,
            burst_s: 1.0,
            update_interval_s: tier.update_interval_s(),
            refit_s: match tier {
                // λ against sharp frames reads ±0.002 per fit: every 0.1 s is plenty.
                // Blind δ(Z) varies from frame to frame (0.22–0.55 px RMSE on the
                // calibration video depending on which frames it was fitted on):
                // every 0.1 s, on the updates that refit neither noise nor λ, the
                // window's median sees ten of them.
                CalibrationTier::Fast => [0.1, 0.1, 0.1],
                CalibrationTier::Balanced => [0.0, 0.0, 1.0],
                // λ on every update the head moves (`mb_moving_only`), noise every
                // 0.25 s: a turn of 0.5–1.2 s gave two to five λ fits at one update
                // per 0.25 s, each ±2–8% on real scenes made elsewhere (BENCHMARKS.md).
                CalibrationTier::Accurate => [0.25, 0.0, 1.0],
            },
            burst_refit_s: match tier {
                // 1.5 frame intervals at 30 fps: every other frame, whatever the
                // jitter of the frames' times (every third at 60 fps).
                CalibrationTier::Fast => [0.05; 3],
                _ => [0.0; 3],
            },
            window_s: 1.0,
            // Accurate: 4 s, two turns and the rest between them at a headset user's
            // pace. On the tuning split's real scenes the accurate tier's λ error
            // went 0.012 / 0.021 / 0.077 → 0.007 / 0.015 / 0.077 (median / p90 /
            // worst) with the change followed as fast (BENCHMARKS.md). The fast
            // tier's λ (sparse references, a fit every 0.1 s) keeps the window's.
            exposure_memory_s: if tier == CalibrationTier::Accurate { 4.0 } else { 1.0 },
            mb_moving_only: tier == CalibrationTier::Accurate,
            frames_held: match tier {
                CalibrationTier::Fast => 1, // the previous frame: flow fallback, noise probe
                CalibrationTier::Balanced => 6,
                CalibrationTier::Accurate => 10,
            },
            // Sharp frames (head at rest) are the motion-blur fit's I_noMB, as two
            // references with independent noise: the accurate tier aligns three
            // whole (`TemporalMotionDeblur::whole_split`), the others two sparsely
            // (`TemporalMotionDeblur::sparse`).
            sharp_held: match tier {
                CalibrationTier::Accurate => 3,
                _ => 2,
            },
            sharp_max_age_s: 3.0,
            noise_strip_px: Some(NOISE_STRIP_PX),
            fast_effort: 1.0,
            colour: true,
            colour_refit_s: 0.25,
            vignetting: true,
            vignetting_refit_s: 0.25,
            chromatic_aberration: true,
            chromatic_refit_s: 0.5,
            sharpening: true,
            sharpening_refit_s: 1.0,
        }
    }
}

/// Pixels per blind noise refit (`CalibratorConfig::noise_strip_px`): a quarter of
/// 1280×960 (its 960 rows in 4 strips of 240), all of 640×480. The fit samples
/// ~20 000 points per level whatever the size, so a strip is not short of samples;
/// its pyramid and the alignment are what scale with the pixels (60 + 37 ms of one
/// core for the whole 1280×960 frame).
pub const NOISE_STRIP_PX: usize = 320 * 1024;
/// Fewest rows in a noise strip: the fit's coarsest structure band is 1/32 of the
/// resolution.
pub const MIN_STRIP_ROWS: usize = 128;

/// The providers per role. `for_tier` picks the defaults; `--onnx` replaces them.
pub struct Providers {
    /// Depth for frames that bring none (a depth network). Frames with depth
    /// (headset-native: environment depth reprojected, depth files) use their own,
    /// moved in without a copy.
    pub depth: Option<Box<dyn DepthProvider>>,
    pub flow: Box<dyn FlowProvider>,
    /// Fallback flow when the primary one cannot serve a frame.
    pub flow_fallback: Option<Box<dyn FlowProvider>>,
    pub denoise: Option<Box<dyn Denoiser>>,
    pub motion_deblur: Option<Box<dyn MotionDeblurrer>>,
    pub defocus_deblur: Option<Box<dyn DefocusDeblurrer>>,
}

impl Providers {
    /// Headset-native depth and pose + depth flow (Lucas–Kanade when a frame has no
    /// pose or depth); temporal references for the tiers that use them.
    pub fn for_tier(tier: CalibrationTier) -> Self {
        let denoise: Option<Box<dyn Denoiser>> = match tier {
            CalibrationTier::Fast => None,
            CalibrationTier::Balanced => {
                Some(Box::new(TemporalDenoiser { frames: 4, min_frames: 3, ..Default::default() }))
            }
            CalibrationTier::Accurate => Some(Box::new(TemporalDenoiser::default())),
        };
        // I_noMB from frames taken with the head at rest, in every tier: blind, a
        // streak of ≤ 3 px (λ = 0.25 on a slow turn) is not identifiable
        // (BENCHMARKS.md), against the reference it is. Two references with
        // independent noise in every tier (the cross loss): the fast and balanced
        // tiers align two sharp frames on a sample of rows, the accurate tier three
        // whole.
        let motion_deblur: Box<dyn MotionDeblurrer> = match tier {
            CalibrationTier::Accurate => Box::new(TemporalMotionDeblur::whole_split()),
            _ => Box::new(TemporalMotionDeblur::sparse()),
        };
        Self {
            depth: None,
            flow: Box::new(PoseDepthFlow),
            flow_fallback: Some(Box::new(LucasKanadeFlow::default())),
            denoise,
            motion_deblur: Some(motion_deblur),
            defocus_deblur: None,
        }
    }

    /// Replace `role`'s provider by the ONNX model at `path` (loaded under the role's
    /// contract, `analysis::onnx`; a breach is an error naming the file). Depth:
    /// used for frames that bring none. Flow: the network first, Lucas–Kanade when
    /// it cannot serve a frame (the first one).
    pub fn with_onnx(mut self, role: Role, path: &std::path::Path) -> Result<Self, OnnxError> {
        let model = OnnxModel::load(role, path, None)?;
        match role {
            Role::Denoise => self.denoise = Some(Box::new(OnnxDenoiser::new(model))),
            Role::MotionDeblur => self.motion_deblur = Some(Box::new(OnnxDeblur { model })),
            Role::DefocusDeblur => self.defocus_deblur = Some(Box::new(OnnxDeblur { model })),
            Role::Depth => self.depth = Some(Box::new(OnnxDepth { model })),
            Role::Flow => {
                self.flow = Box::new(OnnxFlow { model });
                self.flow_fallback = Some(Box::new(LucasKanadeFlow::default()));
            }
        }
        Ok(self)
    }

    /// Flow files instead of computed flow.
    pub fn with_given_flow(mut self) -> Self {
        self.flow = Box::new(GivenFlow);
        self.flow_fallback = None;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::{Analysed, DepthMap, FrameContext};
    use crate::image::{Flow, Plane, Rgb};
    use crate::model::DepthUnits;
    use glam::{Mat4, Vec3};
    use std::sync::Arc;

    /// Every tier's motion-blur reference comes as two estimates with independent
    /// noise (`Reference::second`), so that the fit's cross loss applies: one
    /// reference averaged from the sharp frames biased the accurate tier's λ up by
    /// 0.02–0.07 on real scenes made elsewhere (`TemporalMotionDeblur::whole_split`).
    #[test]
    fn every_tier_reads_lambda_against_two_independent_references() {
        let (w, h) = (64usize, 48usize);
        let k = Intrinsics { fx: 50.0, fy: 50.0, cx: 31.5, cy: 23.5, width: w, height: h };
        let frame = |index: u64, x_m: f32| {
            let data: Vec<f32> = (0..w * h).map(|i| 0.5 + 0.3 * ((i % w) as f32 * 0.4 + index as f32).sin()).collect();
            Arc::new(Analysed {
                frame: crate::analysis::Frame {
                    index,
                    t_s: index as f64 / 30.0,
                    image: Rgb { width: w, height: h, channels: [data.clone(), data.clone(), data] },
                    depth: None,
                    flow: None,
                },
                depth: Some(DepthMap { depth: Plane::new(w, h, 2.0), units: DepthUnits::MetricM }),
                world_from_camera: Some(Mat4::from_translation(Vec3::new(x_m, 0.0, 0.0))),
                sparse_flow: Some(vec![[0.1, 0.0]; 4]),
            })
        };
        let sharp: Vec<Arc<Analysed>> = (1..=3).map(|i| frame(i, 0.01 * i as f32)).collect();
        let current = frame(9, 0.0);
        let ctx = FrameContext {
            current: &current,
            window: &sharp,
            poses: None,
            intrinsics: Some(&k),
            frame_interval_s: 1.0 / 30.0,
        };
        for tier in [CalibrationTier::Fast, CalibrationTier::Balanced, CalibrationTier::Accurate] {
            let mut p = Providers::for_tier(tier).motion_deblur.expect("a motion-blur reference in every tier");
            let r = p.deblur(&ctx, &Flow::uniform(w, h, 5.0, 0.0)).expect("reference");
            assert!(r.second.is_some(), "{tier:?}: one reference only (its noise biases λ up)");
        }
    }
}
