//! The calibration tests' shared sequence and drivers: the bundled Motorcycle
//! photograph with its real depth, re-rendered along a head path and distorted by
//! a camera that changes at `CHANGE_S`, fed to a `Calibrator` as a headset would
//! (poses two frames ahead).

use blind_augment::analysis::timing::TimedPose;
use blind_augment::analysis::{DepthMap, Frame};
use blind_augment::model::compare::noise_relative_error;
use blind_augment::model::{CameraModel, DepthUnits};
use blind_augment::synth::sequence::{motorcycle, Scene, SequenceFrame, SequenceSpec};
use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, Event, Providers};
use std::sync::OnceLock;

pub const CHANGE_S: f64 = 1.5;

pub fn scene() -> &'static Scene {
    static S: OnceLock<Scene> = OnceLock::new();
    S.get_or_init(|| motorcycle().expect("bundled scene"))
}

/// 90 frames (3 s at 30 Hz) of 320×240, the camera changing at 1.5 s; rendered once.
pub fn sequence() -> &'static (SequenceSpec, Vec<blind_augment::synth::sequence::SequenceFrame>) {
    static S: OnceLock<(SequenceSpec, Vec<blind_augment::synth::sequence::SequenceFrame>)> = OnceLock::new();
    S.get_or_init(|| {
        let spec = SequenceSpec::motorcycle(scene(), 320, 240, 90, Some(CHANGE_S));
        let frames = (0..spec.frames).map(|i| spec.frame(scene(), i)).collect();
        (spec, frames)
    })
}

pub fn pose(spec: &SequenceSpec, i: usize) -> TimedPose {
    let t = spec.frame_time_s(i);
    let (_, q, p) = spec.path.world_from_camera(t).to_scale_rotation_translation();
    TimedPose { t_ns: (t * 1e9).round() as i64, position_m: p, orientation: q }
}

pub fn frame(f: &blind_augment::synth::sequence::SequenceFrame) -> Frame {
    Frame {
        index: f.index as u64,
        t_s: f.t_s,
        image: f.image.clone(),
        depth: Some(DepthMap { depth: f.depth_m.clone(), units: DepthUnits::MetricM }),
        flow: None,
    }
}

/// Feed `cal` the frames of `spec` rendered from `scene` as a headset would (poses
/// two frames ahead) and hand every event to `on` with its frame.
pub fn drive(cal: &mut Calibrator, spec: &SequenceSpec, scene: &Scene, on: impl FnMut(&SequenceFrame, Event)) {
    drive_edited(cal, spec, scene, |_| {}, on)
}

/// `drive` with every frame's image changed by `edit` before the calibrator sees it
/// (the truth stays the rendered camera's).
pub fn drive_edited(
    cal: &mut Calibrator,
    spec: &SequenceSpec,
    scene: &Scene,
    mut edit: impl FnMut(&mut Frame),
    mut on: impl FnMut(&SequenceFrame, Event),
) {
    cal.push_poses(&[pose(spec, 0), pose(spec, 1)]).expect("poses");
    for i in 0..spec.frames {
        cal.push_poses(&[pose(spec, i + 2)]).expect("poses");
        let f = spec.frame(scene, i);
        let mut input = frame(&f);
        edit(&mut input);
        for e in cal.push_frame(input).expect("valid frame") {
            on(&f, e);
        }
    }
}

/// Every published update's time and stage times (`Update::stages_s`).
pub type StageLog = Vec<(f64, Vec<(&'static str, f64)>)>;

/// Run a tier over the sequence; every published (t, model, truth) and the changes.
pub fn run(tier: CalibrationTier) -> (Vec<(f64, CameraModel, CameraModel)>, Vec<f64>) {
    let (published, changes, _) = run_with_stages(tier);
    (published, changes)
}

pub fn run_with_stages(tier: CalibrationTier) -> (Vec<(f64, CameraModel, CameraModel)>, Vec<f64>, StageLog) {
    run_configured(tier, |_| {})
}

/// `run_with_stages` with the tier's configuration changed by `configure`.
pub fn run_configured(
    tier: CalibrationTier,
    configure: impl FnOnce(&mut CalibratorConfig),
) -> (Vec<(f64, CameraModel, CameraModel)>, Vec<f64>, StageLog) {
    run_providers(tier, configure, Providers::for_tier(tier))
}

/// `run_configured` with the given providers.
pub fn run_providers(
    tier: CalibrationTier,
    configure: impl FnOnce(&mut CalibratorConfig),
    providers: Providers,
) -> (Vec<(f64, CameraModel, CameraModel)>, Vec<f64>, StageLog) {
    let (spec, frames) = sequence();
    let mut cfg = CalibratorConfig::new(tier, 1.0 / 30.0, Some(spec.view));
    configure(&mut cfg);
    let mut cal = Calibrator::new(cfg, providers).expect("valid config");
    cal.push_poses(&[pose(spec, 0), pose(spec, 1)]).expect("poses");
    let (mut out, mut changes, mut stages) = (vec![], vec![], vec![]);
    for f in frames {
        // Poses lead the camera by two frames, as on a headset.
        cal.push_poses(&[pose(spec, f.index + 2)]).expect("poses");
        for e in cal.push_frame(frame(f)).expect("valid frame") {
            match e {
                Event::Published(u) => {
                    u.model.validate().expect("every published model is valid");
                    // Each stage lies within the update's wall time (their sum may not:
                    // the three fits run concurrently where there are cores).
                    for (k, s) in &u.stages_s {
                        assert!(*s > 0.0 && *s <= u.compute_s + 1e-6, "stage {k}: {s} s of {} s", u.compute_s);
                    }
                    stages.push((u.t_s, u.stages_s));
                    out.push((u.t_s, u.model, f.truth.clone()));
                }
                Event::ChangeDetected { t_s, .. } => changes.push(t_s),
                _ => {}
            }
        }
    }
    (out, changes, stages)
}

/// Median relative noise error of the publications in the half second before the
/// change.
pub fn noise_error_before_change(published: &[(f64, CameraModel, CameraModel)]) -> f32 {
    let mut errs: Vec<f32> = published
        .iter()
        .filter(|p| p.0 >= CHANGE_S - 0.5 && p.0 < CHANGE_S)
        .filter_map(|p| noise_relative_error(&p.1.noise, &p.2.noise))
        .collect();
    errs.sort_by(f32::total_cmp);
    errs.get(errs.len() / 2).copied().unwrap_or(f32::INFINITY)
}

/// A camera whose noise is correlated from frame to frame, as an ISP's
/// motion-compensated temporal noise reduction (TNR) makes it: each frame's noise is
/// n_t = ρ·n_{t−1} (the previous frame's noise aligned into this one by pose and
/// depth) + √(1 − ρ²)·e_t, e_t the camera's own white, signal-dependent field
/// (`synth::noise_field` of `truth`), fresh where the alignment fails — the same std
/// every frame, correlation ρ between consecutive ones. With `copy` = Some(p), a
/// codec's skipped blocks besides: each 8×8 block of the previous noise is copied
/// whole with chance p (the real DivX clip copies 72% of its pixels between frames).
pub struct CorrelatedNoise {
    truth: blind_augment::model::Noise,
    rho: f32,
    copy: Option<f32>,
    view: blind_augment::analysis::Intrinsics,
    path: blind_augment::synth::sequence::HeadPath,
    previous: Option<blind_augment::analysis::Analysed>,
}

impl CorrelatedNoise {
    /// For `spec`'s frames, whose own noise is then left out (`spec.truth.noise`
    /// made absent: this adds it).
    pub fn new(spec: &mut SequenceSpec, rho: f32, copy: Option<f32>) -> Self {
        let truth = spec.truth.noise.clone();
        spec.truth.noise.present = false;
        Self { truth, rho, copy, view: spec.view, path: spec.path, previous: None }
    }

    /// The camera's noise (the truth the calibrator is scored against).
    pub fn truth(&self) -> &blind_augment::model::Noise {
        &self.truth
    }

    /// Add this frame's noise to `f` (its clean image, with depth), quantised to 8
    /// bits as a camera's output is.
    pub fn apply(&mut self, f: &mut Frame) {
        use blind_augment::analysis::{temporal, Analysed};
        let depth = f.depth.clone().expect("the sequence's depth");
        let fresh = blind_augment::synth::noise_field(&f.image.luma(), &self.truth, 1000 + f.index);
        let here = Analysed {
            frame: Frame { image: fresh.clone(), depth: None, flow: None, ..f.clone() },
            depth: Some(DepthMap { depth: depth.depth, units: DepthUnits::MetricM }),
            world_from_camera: Some(self.path.world_from_camera(f.t_s)),
            sparse_flow: None,
        };
        let mut noise = fresh.clone();
        if let Some(a) = self.previous.as_ref().and_then(|p| temporal::align(p, &here, &self.view)) {
            let keep = (1.0 - self.rho * self.rho).sqrt();
            let w = fresh.width;
            for c in 0..3 {
                for (i, v) in noise.channels[c].iter_mut().enumerate() {
                    if !a.valid[i] {
                        continue;
                    }
                    let (bx, by) = ((i % w / 8) as u32, (i / w / 8) as u32);
                    // A uniform draw per block and frame: Φ of the project's Gaussian hash.
                    let copied = self.copy.is_some_and(|p| phi(blind_augment::synth::gaussian(bx, by, 7, f.index)) < p);
                    *v = if copied {
                        a.image.channels[c][i]
                    } else {
                        self.rho * a.image.channels[c][i] + keep * fresh.channels[c][i]
                    };
                }
            }
        }
        for c in 0..3 {
            for (v, n) in f.image.channels[c].iter_mut().zip(&noise.channels[c]) {
                *v = ((*v + n).clamp(0.0, 1.0) * 255.0).round() / 255.0;
            }
        }
        self.previous = Some(Analysed { frame: Frame { image: noise, ..here.frame.clone() }, ..here });
    }
}

/// The standard normal CDF, by Abramowitz–Stegun 7.1.26 for erf (|error| < 1.5e-7).
fn phi(x: f32) -> f32 {
    let z = (x as f64 / std::f64::consts::SQRT_2).abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * z);
    let poly =
        ((((1.061_405_429 * t - 1.453_152_027) * t + 1.421_413_741) * t - 0.284_496_736) * t + 0.254_829_592) * t;
    let erf = (1.0 - poly * (-z * z).exp()).copysign(x as f64);
    (0.5 * (1.0 + erf)) as f32
}
