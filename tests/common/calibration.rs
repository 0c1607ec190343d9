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
