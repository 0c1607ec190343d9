//! The calibration loop, frame by frame, as plain code: the worker thread and
//! `calibrate` (a recorded sequence) run exactly this. Frames in (with the camera
//! poses known so far), camera models out:
//!
//! 1. **Analyse** every frame: pose at its time from the smooth pose track, depth
//!    (provider), motion at a sparse grid (pose + depth); keep it in a bounded
//!    window (the newest `frames_held`, plus the sharpest frames seen recently, the
//!    references for motion blur).
//! 2. **Fit** when due: every frame during the start-up burst (boundary setup) and
//!    after a detected change (each effect every `burst_refit_s`: the fast tier
//!    alternates noise with motion blur and depth of field), then every
//!    `update_interval_s` of video. The tier
//!    decides the references: `fast` fits the frame alone (blind); `balanced` and
//!    `accurate` use video as its own reference (aligned mean as I_noNoise, the
//!    sharpest aligned frames as I_noMB; `analysis::temporal`) or the providers
//!    given by `--onnx`. Depth of field has no video reference (the focus does not
//!    change), so it runs blind unless a defocus-deblur provider is given.
//! 3. **Aggregate** the estimates of the last `window_s` seconds of video: the
//!    coefficient-wise median (`fit::aggregate_models`: outliers do not move it;
//!    noise over the fits near the medoid, of the form most of them share),
//!    presence with hysteresis (on at ≥ 60% of identifiable estimates, off at
//!    ≤ 30%) so effects do not flicker; confident λ fitted against references over
//!    `exposure_memory_s` since the last change (the accurate tier: 4 s).
//! 4. **Detect change** (`change.rs`): a shift of the luminance histogram, a step in
//!    the noise probe (this frame minus the previous one aligned, every 0.1 s), or
//!    two confident exposure estimates in a row off the model beyond their own and
//!    the window's scatter (an exposure, gain or focus change) drops the estimates
//!    and held frames from before it and restarts the burst, so the new camera is
//!    published within a few frames.
//!
//! Every published model is validated (no NaN, nothing out of range).

mod aggregate;
mod change;
mod chromatic;
mod config;
mod dof_pool;
mod mb_pool;
mod noise_fit;
mod report;
mod sharpening;
mod tnr;
mod vignetting;

pub use config::{CalibrationTier, CalibratorConfig, Providers, MIN_STRIP_ROWS, NOISE_STRIP_PX};
use report::Stages;
pub use report::{CalibError, Event, Update, UpdateReason};

use crate::analysis::timing::{PoseTrack, TimedPose};
use crate::analysis::{Analysed, AnalysisError, Frame, FrameContext, PoseDepthFlow};
use crate::fit::{self, Effects, FitInputs, FitOptions};
use crate::model::{CameraModel, Status};
use aggregate::Presence;
use change::{luma_histogram, Probe, PROBE_INTERVAL_S};
use dof_pool::{dof_still, PooledEdges};
use mb_pool::PooledIsotropy;
use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

/// Longest an effect's refit waits, past its interval, for an update that is not
/// busy with another costly fit (`Calibrator::fit_frame`).
const PHASE_WAIT_S: f64 = 0.1;

/// How often the stream is checked for a block codec's grid (`Calibrator::
/// codec_grid`): a property of the stream, not of the frame, and 10–13 ms of one core
/// at 1280×960.
const CODEC_GRID_RECHECK_S: f64 = 1.0;

/// One fit's result, kept for aggregation.
#[derive(Clone, Debug)]
struct Estimate {
    frame: u64,
    t_s: f64,
    model: CameraModel,
    /// Lags (in frames) of the other frames its noise fit read a difference with:
    /// one for the blind fit against the previous frame aligned, the sources of a
    /// temporal mean; empty for a fit on the frame alone or a network's reference.
    /// The aggregation divides the noise's frame-to-frame correlation out of these
    /// (`tnr`).
    noise_lags: Vec<u64>,
    /// The frame's image speed (px/frame, 90th percentile of the pose + depth flow
    /// at the sparse grid); None without poses and depth. A motion-blur reading of
    /// "absent" is evidence only where the held exposure would have streaked
    /// (`aggregate`).
    speed_px: Option<f32>,
}

/// Variance (px²) of the Gaussian both sides of the temporal motion-blur fit pass
/// through (`FitOptions::mb_prefilter_var_px2`).
const MB_PREFILTER_VAR_PX2: f32 = 1.0;
/// Shortest flow (px per frame) a pixel of the temporal motion-blur fit may have
/// (`FitOptions::mb_min_flow_px`). Against references aligned from other frames,
/// short streaks read λ low: measured on the calibration video at 320×240 (two
/// sharp frames, cross loss), λ = 0.5 read 0.18 at 1.6 px/frame, 0.44 at 4, 0.47
/// at 6.4, 0.49 at 8 (and 0.42 at 3.6 px, 0.49 at 7 px at 1280×960): a fixed
/// blur deficit of a few hundredths of a px² along the flow, which only short
/// streaks feel. Its cause is not pinned down (a larger prefilter made it worse, so
/// it is not resampling's attenuation near Nyquist alone). Applied to every
/// motion-blur reference the worker is given.
const MB_MIN_FLOW_PX: f32 = 4.0;
/// Pixels the temporal motion-blur fit reads (`FitOptions::mb_max_samples`): half
/// the default. Two references double each sample's cost, and at 512² 2048
/// samples already read λ within 0.001 (BENCHMARKS.md, "Motion blur (accurate):
/// pixel budget").
const MB_MAX_SAMPLES: usize = 2048;
/// A held sharp frame's age counts as this much motion per second when the
/// oldest-or-blurriest one makes room (`Calibrator::push_frame`).
const SHARP_AGE_PX_PER_S: f64 = 0.5;

/// Where the calibration stands (`Calibrator::phase`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Phase {
    /// No frame yet since the start or a restart.
    #[default]
    Waiting,
    /// Updating every frame: the start-up burst (boundary setup: the user should
    /// look around), or the shorter one after a detected camera change.
    Burst { elapsed_s: f64, of_s: f64, after_change: bool },
    /// Updating on schedule.
    Steady,
}

pub struct Calibrator {
    cfg: CalibratorConfig,
    providers: Providers,
    poses: Vec<TimedPose>,
    track: Option<PoseTrack>,
    window: VecDeque<Arc<Analysed>>,
    sharp: VecDeque<Arc<Analysed>>,
    estimates: VecDeque<Estimate>,
    size: Option<(usize, usize)>,
    last_t_s: Option<f64>,
    burst_until_s: f64,
    /// The start or the last reset: frame-alone noise fits wait from here for one
    /// with an aligned neighbour (`aggregate`).
    noise_since_s: f64,
    last_fit_s: f64,
    histogram: Option<[f32; 16]>,
    probes: VecDeque<Probe>,
    last_probe_s: f64,
    last_effect_fit_s: [f64; 3],
    /// Confident λ estimates with a reference (time, λ) of the last
    /// `exposure_memory_s` since the last change (`aggregate`).
    exposure_history: VecDeque<(f64, f32)>,
    /// The published λ and its estimates' scatter a first off-model λ estimate was
    /// judged against, and that estimate's time (`check_exposure`).
    exposure_suspect: Option<(f32, f32, f64)>,
    /// Whether the last update refitted noise with a neighbour (the fast tier's
    /// burst alternates noise with the other effects: `fit_frame`).
    noise_last_update: bool,
    /// Video time of the last colour fit (`CalibratorConfig::colour_refit_s`).
    colour_last_t_s: Option<f64>,
    vignetting: vignetting::VignettingVideo,
    chromatic: chromatic::ChromaticVideo,
    sharpening: sharpening::SharpeningVideo,
    after_change: bool,
    presence: [Presence; 3],
    published: Option<CameraModel>,
    /// The previous frame aligned into the frame of this index (`change::
    /// aligned_previous`): made once, read by the noise probe and the blind noise fit.
    aligned_previous: Option<(u64, Option<Arc<crate::analysis::temporal::Aligned>>)>,
    /// Blind noise refits so far: which strip the next one reads (`noise_strip`).
    noise_strips_fitted: usize,
    /// The blind DoF fits' edge samples of the last `DOF_POOL_S` (`pool_dof`).
    dof_pool: VecDeque<PooledEdges>,
    /// The blind motion-blur fits' isotropy evidence of the last `MB_POOL_S` (`pool_mb`).
    mb_pool: VecDeque<PooledIsotropy>,
    /// Whether the stream shows a block codec's grid, and when that was last checked
    /// (`codec_grid`).
    codec_grid: Option<(f64, bool)>,
    /// The newest frames, for the lag probes (`tnr`): the noise's frame-to-frame
    /// correlation.
    lagged: VecDeque<Arc<Analysed>>,
    /// Lag probes of the last `tnr::TNR_WINDOW_S`, how many have run (which lag is
    /// next), and the correlation they give.
    lag_ratios: VecDeque<tnr::LagProbe>,
    lag_probes_run: usize,
    noise_correlation: Option<fit::noise_correlation::NoiseCorrelation>,
    /// This frame's stage times.
    stages: Stages,
}

/// Head motion no tracker reports for a real head (m/s, rad/s): a tracking loss.
const MAX_SPEED_M_S: f32 = 5.0;
const MAX_ANGULAR_SPEED_RAD_S: f32 = 20.0;
/// Pose history kept (s).
const POSE_HISTORY_S: f64 = 4.0;

impl Calibrator {
    pub fn new(cfg: CalibratorConfig, providers: Providers) -> Result<Self, CalibError> {
        if !(cfg.frame_interval_s.is_finite() && cfg.frame_interval_s > 0.0 && cfg.frame_interval_s < 1.0) {
            return Err(CalibError::Config(format!("frame interval {} s: need 0 < Δ < 1 s", cfg.frame_interval_s)));
        }
        if !(cfg.window_s > 0.0 && cfg.burst_s >= 0.0 && cfg.update_interval_s >= 0.0) {
            return Err(CalibError::Config("window, burst and update interval must be ≥ 0 (window > 0)".into()));
        }
        if !(cfg.fast_effort >= fit::MIN_FAST_EFFORT && cfg.fast_effort <= 1.0) {
            return Err(CalibError::Config(format!(
                "fast effort {}: need {} ≤ effort ≤ 1",
                cfg.fast_effort,
                fit::MIN_FAST_EFFORT
            )));
        }
        if let Some(k) = &cfg.intrinsics {
            if ![k.fx, k.fy, k.cx, k.cy].iter().all(|v| v.is_finite()) || k.fx <= 0.0 || k.fy <= 0.0 {
                return Err(CalibError::Config(format!("intrinsics {k:?}: need finite values and fx, fy > 0")));
            }
        }
        Ok(Self {
            cfg,
            providers,
            poses: vec![],
            track: None,
            window: VecDeque::new(),
            sharp: VecDeque::new(),
            estimates: VecDeque::new(),
            size: None,
            last_t_s: None,
            burst_until_s: f64::NEG_INFINITY,
            noise_since_s: f64::NEG_INFINITY,
            last_fit_s: f64::NEG_INFINITY,
            histogram: None,
            probes: VecDeque::new(),
            last_probe_s: f64::NEG_INFINITY,
            last_effect_fit_s: [f64::NEG_INFINITY; 3],
            exposure_history: VecDeque::new(),
            exposure_suspect: None,
            noise_last_update: false,
            colour_last_t_s: None,
            vignetting: Default::default(),
            chromatic: Default::default(),
            sharpening: Default::default(),
            after_change: false,
            presence: Default::default(),
            published: None,
            aligned_previous: None,
            noise_strips_fitted: 0,
            dof_pool: VecDeque::new(),
            mb_pool: VecDeque::new(),
            codec_grid: None,
            lagged: VecDeque::new(),
            lag_ratios: VecDeque::new(),
            lag_probes_run: 0,
            noise_correlation: None,
            stages: Stages::default(),
        })
    }

    pub fn config(&self) -> &CalibratorConfig {
        &self.cfg
    }

    /// The last published model.
    pub fn current(&self) -> Option<&CameraModel> {
        self.published.as_ref()
    }

    /// The noise's frame-to-frame correlation as the lag probes read it now (None
    /// before the first lag probe, without intrinsics, or since a change).
    pub fn noise_correlation(&self) -> Option<&fit::noise_correlation::NoiseCorrelation> {
        self.noise_correlation.as_ref()
    }

    /// Camera poses (`world_from_camera`, OpenCV axes) as they become known, in time
    /// order. Bad poses are errors; an impossible jump is a tracking loss: the
    /// history before it is dropped (reported as an event).
    /// Start over as at start-up (the user's "restart calibration": a new room,
    /// a camera setting changed by hand): every estimate, reference frame, pool and
    /// presence vote is forgotten, and the next frame opens a full start-up burst.
    /// The pose track and the last frame time stay (poses and frames go on); the
    /// renderer keeps the model it has until the burst publishes a new one.
    pub fn restart(&mut self) {
        let providers = std::mem::replace(&mut self.providers, Providers::for_tier(self.cfg.tier));
        match Calibrator::new(self.cfg.clone(), providers) {
            Ok(mut fresh) => {
                fresh.poses = std::mem::take(&mut self.poses);
                fresh.track = self.track.take();
                fresh.last_t_s = self.last_t_s;
                *self = fresh;
            }
            // The configuration was accepted when this calibrator was made, so a
            // fresh one cannot be refused; if it were, go on as before.
            Err(e) => log::error!("calibration: restart refused ({e}); going on without it"),
        }
    }

    /// Where the calibration stands at the last frame (the headset's status
    /// panel: "look around" while the start-up burst runs).
    pub fn phase(&self) -> Phase {
        match self.last_t_s {
            _ if self.burst_until_s == f64::NEG_INFINITY => Phase::Waiting,
            Some(t_s) if t_s < self.burst_until_s => {
                // A change's burst is half the start-up one (`change::on_change`).
                let of_s = if self.after_change { 0.5 * self.cfg.burst_s } else { self.cfg.burst_s };
                Phase::Burst { elapsed_s: t_s - (self.burst_until_s - of_s), of_s, after_change: self.after_change }
            }
            Some(_) => Phase::Steady,
            None => Phase::Waiting,
        }
    }

    pub fn push_poses(&mut self, poses: &[TimedPose]) -> Result<Vec<Event>, CalibError> {
        let mut events = vec![];
        for p in poses {
            let t_s = p.t_ns as f64 * 1e-9;
            if !p.position_m.is_finite() || !p.orientation.is_finite() {
                return Err(CalibError::Pose { t_s, reason: "not finite".into() });
            }
            if (p.orientation.length() - 1.0).abs() > 1e-3 {
                return Err(CalibError::Pose {
                    t_s,
                    reason: format!("quaternion of length {} (not a unit quaternion)", p.orientation.length()),
                });
            }
            if let Some(last) = self.poses.last() {
                if p.t_ns <= last.t_ns {
                    return Err(CalibError::Pose { t_s, reason: "not later than the previous pose".into() });
                }
                let dt = (p.t_ns - last.t_ns) as f32 * 1e-9;
                let speed = (p.position_m - last.position_m).length() / dt;
                let angular = last.orientation.angle_between(p.orientation) / dt;
                if speed > MAX_SPEED_M_S || angular > MAX_ANGULAR_SPEED_RAD_S {
                    events.push(Event::TrackingLoss {
                        t_s,
                        reason: format!(
                            "the camera jumped ({speed:.1} m/s, {angular:.1} rad/s): earlier poses dropped"
                        ),
                    });
                    self.poses.clear();
                    // Frames held from before the jump are in another frame of reference.
                    self.window.clear();
                    self.sharp.clear();
                    self.lagged.clear();
                }
            }
            self.poses.push(*p);
        }
        if let Some(last) = self.poses.last() {
            let keep_from = last.t_ns - (POSE_HISTORY_S * 1e9) as i64;
            let cut = self.poses.partition_point(|q| q.t_ns < keep_from);
            self.poses.drain(..cut);
        }
        self.track = if self.poses.len() >= 2 { PoseTrack::new(self.poses.clone()).ok() } else { None };
        Ok(events)
    }

    fn check_frame(&mut self, frame: &Frame) -> Result<(), CalibError> {
        let (w, h) = (frame.image.width, frame.image.height);
        if w == 0 || h == 0 {
            return Err(CalibError::Empty { frame: frame.index });
        }
        if let Some((ww, wh)) = self.size {
            if (w, h) != (ww, wh) {
                return Err(CalibError::FrameSize { frame: frame.index, want_w: ww, want_h: wh, got_w: w, got_h: h });
            }
        }
        if let Some(k) = &self.cfg.intrinsics {
            if (k.width, k.height) != (w, h) {
                return Err(CalibError::Intrinsics { iw: k.width, ih: k.height, w, h });
            }
        }
        if let Some((x, y, _)) = frame.image.first_non_finite() {
            return Err(CalibError::NonFinite { frame: frame.index, x, y });
        }
        if let Some(prev) = self.last_t_s {
            if frame.t_s.partial_cmp(&prev) != Some(std::cmp::Ordering::Greater) {
                return Err(CalibError::Time { frame: frame.index, t_s: frame.t_s, previous_s: prev });
            }
        }
        self.size = Some((w, h));
        self.last_t_s = Some(frame.t_s);
        Ok(())
    }

    fn held(&self) -> Vec<Arc<Analysed>> {
        let mut v: Vec<Arc<Analysed>> = self.sharp.iter().chain(self.window.iter()).cloned().collect();
        v.sort_by(|a, b| a.frame.t_s.total_cmp(&b.frame.t_s));
        v.dedup_by(|a, b| a.frame.index == b.frame.index);
        v
    }

    /// Analyse `frame`, fit when due, publish when the aggregate changes.
    pub fn push_frame(&mut self, frame: Frame) -> Result<Vec<Event>, CalibError> {
        self.check_frame(&frame)?;
        let started = Instant::now();
        self.stages = Stages::default();
        let mut events = vec![];
        let (index, t_s) = (frame.index, frame.t_s);
        if self.burst_until_s == f64::NEG_INFINITY {
            self.burst_until_s = t_s + self.cfg.burst_s;
            self.noise_since_s = t_s;
        }

        // 1. Analysis.
        let pose = self.track.as_ref().and_then(|tr| tr.at(crate::analysis::flow::to_ns(t_s)));
        let mut analysed = Analysed {
            frame,
            depth: None,
            world_from_camera: pose.as_ref().map(crate::analysis::temporal::pose_matrix),
            sparse_flow: None,
        };
        let held = self.held();
        let (track, k, dt) = (self.track.as_ref(), self.cfg.intrinsics.as_ref(), self.cfg.frame_interval_s);
        let depth = match (analysed.frame.depth.take(), self.providers.depth.as_mut()) {
            (Some(d), _) => Ok(d),
            (None, Some(p)) => p.depth(&FrameContext {
                current: &analysed,
                window: &held,
                poses: track,
                intrinsics: k,
                frame_interval_s: dt,
            }),
            (None, None) => {
                Err(AnalysisError::unavailable(index, "depth", "no depth with this frame and no depth provider"))
            }
        };
        match depth {
            Ok(d) if (d.depth.width, d.depth.height) == (analysed.frame.image.width, analysed.frame.image.height) => {
                analysed.depth = Some(d)
            }
            Ok(d) => events.push(Event::Degraded {
                frame: index,
                reason: format!("depth is {}×{}, the frame is not: depth ignored", d.depth.width, d.depth.height),
            }),
            Err(e) => events.push(Event::Degraded { frame: index, reason: e.to_string() }),
        }
        if analysed.world_from_camera.is_some() && analysed.depth.is_some() && self.cfg.intrinsics.is_some() {
            analysed.sparse_flow = PoseDepthFlow::sparse(&FrameContext {
                current: &analysed,
                window: &held,
                poses: track,
                intrinsics: k,
                frame_interval_s: dt,
            })
            .ok();
        }

        self.stages.add("analysis", started);
        // 2. Change detection on the luminance histogram.
        let hist = luma_histogram(&analysed.frame);
        let mut change = None;
        if let Some(base) = &self.histogram {
            let l1: f32 = base.iter().zip(&hist).map(|(a, b)| (a - b).abs()).sum();
            if l1 > 0.5 {
                change = Some(format!("luminance histogram moved by {l1:.2} (L1)"));
            }
        }
        self.histogram = Some(match &self.histogram {
            Some(b) if change.is_none() => std::array::from_fn(|i| 0.9 * b[i] + 0.1 * hist[i]),
            _ => hist,
        });
        if let Some(cause) = change {
            self.on_change(index, t_s, t_s, cause, &mut events);
        }

        // 3. Blind probe (change detection): the fast tier's own fit serves as the
        //    probe; the slower tiers run the blind estimators every `PROBE_INTERVAL_S`.
        let probe_due = t_s - self.last_probe_s >= PROBE_INTERVAL_S - 1e-9;
        if probe_due {
            self.last_probe_s = t_s;
            let (t0, before) = (Instant::now(), self.stages.total());
            let v = self.noise_probe(&analysed);
            // The alignment it made is its own stage.
            self.stages.push("change probe", t0.elapsed().as_secs_f64() - (self.stages.total() - before));
            self.push_probe(t_s, v);
        }
        // The noise's frame-to-frame correlation, on the probe's bands (`tnr`): with
        // every noise probe, and on every frame of a burst until it is first
        // estimated (the burst's difference-based noise fits wait for it).
        if self.cfg.intrinsics.is_some() && self.cfg.effects.noise && (probe_due || self.lag_probe_hurried(t_s)) {
            self.lag_probe(&analysed);
        }
        if probe_due {
            if let Some((since, cause)) = self.detect_change() {
                self.on_change(index, t_s, since, cause, &mut events);
            }
        }

        // 4. Fit when due.
        let in_burst = t_s < self.burst_until_s;
        if !in_burst {
            self.after_change = false;
        }
        let due = in_burst || t_s - self.last_fit_s >= self.cfg.update_interval_s - 1e-9;
        let analysed = Arc::new(analysed);
        if due {
            self.last_fit_s = t_s;
            match self.fit_frame(&analysed, &held, &mut events) {
                Some((model, noise_lags)) => {
                    // Not in a change's burst: its model still holds the λ from before
                    // the change until new estimates come, and they are following it
                    // (no reading there starts a suspicion either).
                    let following = in_burst && self.after_change;
                    if following {
                        self.exposure_suspect = None;
                    } else if let Some((cause, since)) = self.check_exposure(&model, t_s) {
                        self.on_change(index, t_s, since, cause, &mut events);
                    }
                    let speed_px = analysed.sparse_flow.as_deref().and_then(sparse_speed_px);
                    self.estimates.push_back(Estimate { frame: index, t_s, model, noise_lags, speed_px });
                    let reason = if in_burst && self.after_change {
                        UpdateReason::Change
                    } else if in_burst {
                        UpdateReason::Burst
                    } else {
                        UpdateReason::Schedule
                    };
                    if let Some(update) = self.aggregate(index, t_s, reason, started) {
                        events.push(Event::Published(Box::new(update)));
                    }
                }
                None => events.push(Event::Skipped { frame: index, reason: "no effect could be fitted".into() }),
            }
        }

        // 5. Hold the frame for later references.
        self.hold_lagged(&analysed);
        if self.cfg.frames_held > 0 {
            self.window.push_back(analysed.clone());
            while self.window.len() > self.cfg.frames_held {
                self.window.pop_front();
            }
        }
        if self.cfg.sharp_held > 0 {
            if let Some(m) = analysed.max_motion_px() {
                if m <= 0.5 {
                    self.sharp.push_back(analysed);
                    // Full: drop the least useful, its motion plus its age at
                    // `SHARP_AGE_PX_PER_S` — the sharpest frames of the latest rest.
                    // A reference with motion m carries a streak of λ·m and reads λ
                    // low on short streaks; an old one may no longer overlap the view.
                    while self.sharp.len() > self.cfg.sharp_held {
                        let cost = |a: &Arc<Analysed>| {
                            a.max_motion_px().unwrap_or(f32::INFINITY) as f64 + SHARP_AGE_PX_PER_S * (t_s - a.frame.t_s)
                        };
                        let worst = (0..self.sharp.len())
                            .max_by(|&i, &j| cost(&self.sharp[i]).total_cmp(&cost(&self.sharp[j])));
                        self.sharp.remove(worst.unwrap_or(0));
                    }
                }
            }
            let max_age = self.cfg.sharp_max_age_s;
            self.sharp.retain(|a| t_s - a.frame.t_s <= max_age);
        }
        Ok(events)
    }

    /// One frame's fit at the configured tier.
    fn fit_frame(
        &mut self,
        current: &Arc<Analysed>,
        held: &[Arc<Analysed>],
        events: &mut Vec<Event>,
    ) -> Option<(CameraModel, Vec<u64>)> {
        let index = current.frame.index;
        // Per-effect cadence (`CalibratorConfig::refit_s`, `burst_refit_s` during a
        // burst): each effect when its interval has passed and its phase comes.
        let t_s = current.frame.t_s;
        let in_burst = t_s < self.burst_until_s;
        // The blind noise refit waits for a frame the noise probe has already
        // aligned (the probe runs every `PROBE_INTERVAL_S`): both read the same
        // aligned previous frame, the largest single cost of a fast update (37 ms of
        // one core at 1280×960). Out of phase they made two alignments per 0.1 s.
        let aligned_now = self.aligned_previous.as_ref().is_some_and(|(i, a)| *i == index && a.is_some());
        // Without a previous frame held (a burst's first frame, a reset that dropped
        // them) the noise fit reads the frame alone and is superseded by the first
        // fit with an aligned neighbour: that one comes on the next frame, whatever
        // the burst's cadence.
        let noise_alone = in_burst && self.window.is_empty();
        // In a burst that spaces its refits, noise takes turns with the others,
        // update by update, whatever the frame rate (a fixed interval let noise take
        // every update at 20 fps or less, or when frames are dropped under load).
        let noise_turn = !self.noise_last_update || !(self.cfg.effects.motion_blur || self.cfg.effects.depth_of_field);
        let mut due = |k: usize, wanted: bool, busy: bool| {
            let since = t_s - self.last_effect_fit_s[k];
            let every_frame = in_burst && self.cfg.burst_refit_s[k] <= 0.0;
            let interval = if in_burst { self.cfg.burst_refit_s[k] } else { self.cfg.refit_s[k] } - 1e-9;
            // Noise waits for an aligned frame (in a burst it aligns its own, on
            // the updates after one that did not refit it);
            // motion blur for an update that does not refit noise; depth of field
            // for one that refits neither, in a burst one that does not refit noise
            // (the costly parts of the fast tier on separate updates). Each waits at
            // most `PHASE_WAIT_S` past its interval.
            let in_phase = match k {
                0 if in_burst => noise_turn,
                0 => aligned_now,
                _ => !busy,
            } || since >= interval + PHASE_WAIT_S
                || every_frame;
            let ok = wanted && since >= interval && in_phase;
            if ok && !(k == 0 && noise_alone) {
                self.last_effect_fit_s[k] = t_s;
            }
            ok
        };
        let noise = due(0, self.cfg.effects.noise, false);
        self.noise_last_update = noise && !noise_alone;
        let moving = current.max_motion_px().map_or(true, |m| m >= MB_MIN_FLOW_PX);
        let motion_blur =
            due(1, self.cfg.effects.motion_blur && (in_burst || moving || !self.cfg.mb_moving_only), noise);
        // Depth of field waits for a frame with the head at rest once the edge pool
        // holds one (`pool_dof`): a moving frame's edges carry motion blur.
        let dof_wanted = self.cfg.effects.depth_of_field && (self.dof_pool.is_empty() || dof_still(current));
        let dof_busy = noise || (motion_blur && !in_burst);
        let fx = Effects { noise, motion_blur, depth_of_field: due(2, dof_wanted, dof_busy) };
        // The blind noise fit reads texture off the previous exposure aligned by pose
        // and depth (`fit::Neighbour`): on the calibration video its error falls from
        // ~20% to ~5% (BENCHMARKS.md).
        // Not where the lag probes found the noise copied between frames otherwise
        // than a first-order correlation could explain (`tnr`): the frame alone then.
        let copied = self.noise_copied_otherwise();
        let neighbour =
            if fx.noise && self.providers.denoise.is_none() && !copied { self.aligned_previous(current) } else { None };
        // The frame a neighbour would be: the previous one held (`align_previous`).
        let neighbour_lag = self.window.back().map(|p| index.saturating_sub(p.frame.index));
        let mut noise_lags = vec![];
        // Checked before `ctx` borrows the calibrator (see the denoised reference).
        let codec_grid = fx.noise && self.providers.denoise.is_some() && self.codec_grid(current);
        let ctx = FrameContext {
            current,
            window: held,
            poses: self.track.as_ref(),
            intrinsics: self.cfg.intrinsics.as_ref(),
            frame_interval_s: self.cfg.frame_interval_s,
        };
        // The flow where the motion-blur reference can be valid (`MotionDeblurrer::
        // rows`: a sparse reference's bands); every row if the reference fails and
        // the fit runs blind.
        let image = &current.frame.image;
        let rows = match (fx.motion_blur, self.providers.motion_deblur.as_ref()) {
            (true, Some(p)) => p.rows(image.width, image.height),
            _ => None,
        };
        let tflow = Instant::now();
        let mut flow =
            if fx.motion_blur { flow_on(&mut self.providers, &ctx, rows.as_deref(), index, events) } else { None };
        if fx.motion_blur {
            self.stages.add("flow", tflow);
        }
        let depth = current.depth.as_ref();
        // The effects without a reference run blind, at the configured effort.
        let fast_effort = self.cfg.fast_effort;
        let only = |n, m, d| FitOptions {
            effects: Effects { noise: n, motion_blur: m, depth_of_field: d },
            fast_effort,
            ..Default::default()
        };
        let fast_opts =
            |e: Effects| FitOptions { tier: Some(fit::Tier::Fast), effects: e, fast_effort, ..Default::default() };

        // References per effect (None: that effect runs blind).
        let t_refs = Instant::now();
        let denoised = match (fx.noise, self.providers.denoise.as_mut()) {
            (true, Some(p)) => match p.denoise(&ctx) {
                // A reference made of other frames holds the noise a block codec
                // copied into them (skipped and predicted blocks): against the mean
                // of the 8 frames around it the DivX clip's level 0 read −39%, its
                // level 3 −83% (BENCHMARKS.md "Noise from video on a block codec's
                // stream"). Where the frame shows the codec's grid, noise runs blind
                // (which reads such a frame alone).
                Ok(r) if !r.sources.is_empty() && codec_grid => {
                    events.push(Event::Degraded {
                        frame: index,
                        reason: "temporal noise reference not used: the frame shows a block codec's grid, and the \
                                 codec copies noise between frames"
                            .into(),
                    });
                    None
                }
                Ok(r) if !r.sources.is_empty() && copied => {
                    events.push(Event::Degraded {
                        frame: index,
                        reason: "temporal noise reference not used: the lag probes found the noise copied between \
                                 frames otherwise than a first-order correlation explains"
                            .into(),
                    });
                    None
                }
                Ok(r) => Some(r),
                Err(e) => {
                    events.push(Event::Degraded { frame: index, reason: e.to_string() });
                    None
                }
            },
            _ => None,
        };
        let sharp = match (fx.motion_blur, flow.as_ref(), self.providers.motion_deblur.as_mut()) {
            (true, Some(f), Some(p)) => match p.deblur(&ctx, f) {
                Ok(r) => Some(r),
                Err(e) => {
                    events.push(Event::Degraded { frame: index, reason: e.to_string() });
                    None
                }
            },
            _ => None,
        };
        let in_focus = match (fx.depth_of_field, depth, self.providers.defocus_deblur.as_mut()) {
            (true, Some(d), Some(p)) => match p.deblur(&ctx, d) {
                Ok(r) => Some(r),
                Err(e) => {
                    events.push(Event::Degraded { frame: index, reason: e.to_string() });
                    None
                }
            },
            _ => None,
        };

        // The effects without references in one blind call; each reference its own
        // accurate call (their validity masks differ).
        let blind = Effects {
            noise: fx.noise && denoised.is_none(),
            motion_blur: fx.motion_blur && sharp.is_none(),
            depth_of_field: fx.depth_of_field && in_focus.is_none(),
        };
        // Timed whenever a provider was asked, served or not (a failed reference
        // costs time too).
        let asked = (fx.noise && self.providers.denoise.is_some())
            || (fx.motion_blur && flow.is_some() && self.providers.motion_deblur.is_some())
            || (fx.depth_of_field && depth.is_some() && self.providers.defocus_deblur.is_some());
        if asked {
            self.stages.add("references", t_refs);
        }
        if sharp.is_none() && rows.is_some() && flow.is_some() {
            let tflow = Instant::now();
            flow = flow_on(&mut self.providers, &ctx, None, index, events);
            self.stages.add("flow", tflow);
        }
        let base = FitInputs {
            depth: depth.map(|d| &d.depth),
            depth_units: depth.map_or(crate::model::DepthUnits::MetricM, |d| d.units),
            flow: flow.as_ref(),
            ..FitInputs::new(image)
        };
        // Blind noise on this update's strip (`noise_strip`), with the previous frame
        // aligned there; the other blind effects on the whole frame.
        // Every frame's isotropy evidence for the pooled exposure (`pool_mb`).
        let blind_opts = FitOptions { mb_isotropy_evidence: true, ..fast_opts(Effects { noise: false, ..blind }) };
        let mut model = match fit::fit(&base, &blind_opts) {
            Ok(o) => {
                let mut model = o.model;
                if blind.depth_of_field {
                    let edges = o.plots.depth_of_field.filter(|_| dof_still(current));
                    self.pool_dof(t_s, edges, &mut model);
                }
                if blind.motion_blur {
                    self.pool_mb(t_s, o.plots.motion_blur.and_then(|p| p.isotropy), &mut model);
                }
                model
            }
            Err(e) => {
                events.push(Event::Skipped { frame: index, reason: e.to_string() });
                return None;
            }
        };
        if blind.noise {
            self.fit_noise_strip(current, neighbour, neighbour_lag, &mut model, &mut noise_lags, events);
        }
        if let Some(r) = &denoised {
            self.fit_noise_on_reference(&base, r, index, &mut model, &mut noise_lags, events);
        }
        if let Some(r) = &sharp {
            let inp = FitInputs {
                motion_deblurred: Some(&r.image),
                motion_deblurred_second: r.second.as_ref(),
                reference_valid: r.valid.as_ref(),
                ..base
            };
            let opts = FitOptions {
                tier: Some(fit::Tier::Accurate),
                mb_prefilter_var_px2: MB_PREFILTER_VAR_PX2,
                mb_min_flow_px: MB_MIN_FLOW_PX,
                mb_max_samples: MB_MAX_SAMPLES,
                ..only(false, true, false)
            };
            match fit::fit(&inp, &opts) {
                Ok(o) => {
                    model.motion_blur = o.model.motion_blur;
                    model.motion_blur.diagnostics.method = "accurate (temporal reference)".into();
                }
                Err(e) => events.push(Event::Degraded { frame: index, reason: format!("motion-blur fit: {e}") }),
            }
        }
        if let Some(r) = &in_focus {
            let inp = FitInputs { defocus_deblurred: Some(&r.image), ..base };
            match fit::fit(&inp, &FitOptions { tier: Some(fit::Tier::Accurate), ..only(false, false, true) }) {
                Ok(o) => model.depth_of_field = o.model.depth_of_field,
                Err(e) => events.push(Event::Degraded { frame: index, reason: format!("DoF fit: {e}") }),
            }
        }
        // Its frame-sized buffers serve the next update (`recycle`: no page faults).
        if let (Some(r), Some(p)) = (sharp, self.providers.motion_deblur.as_mut()) {
            p.recycle(r);
        }
        // Each fit's own timer (the accurate refits replaced the blind ones' models).
        self.stages.push("fit.noise", model.noise.diagnostics.fit_time_s);
        self.stages.push("fit.motion_blur", model.motion_blur.diagnostics.fit_time_s);
        self.stages.push("fit.depth_of_field", model.depth_of_field.diagnostics.fit_time_s);
        // Colour at its own cadence: a camera's AE/AWB moves over ~0.5 s, and the
        // window's median follows a change within 1 s at one fit per 0.25 s.
        let t_s = current.frame.t_s;
        let colour_due = self.cfg.colour
            && self.colour_last_t_s.map_or(true, |l| t_s < l || t_s - l >= self.cfg.colour_refit_s - 1e-9);
        if colour_due {
            let t = Instant::now();
            model.colour = fit::colour::fit_colour(&current.frame.image);
            self.stages.add("fit.colour", t);
            self.colour_last_t_s = Some(t_s);
        }
        let t = Instant::now();
        if let Some(v) = self.fit_vignetting_at(current) {
            model.vignetting = v;
            self.stages.add("fit.vignetting", t);
        }
        let t = Instant::now();
        // The aberration waits for an update neither colour nor vignetting fitted
        // in, so the three slow terms' costs do not add up in one update.
        let busy = colour_due || model.vignetting.diagnostics.status != Status::NotFitted;
        let mut busy = busy;
        if let Some(c) = self.fit_chromatic_at(current, busy) {
            model.chromatic_aberration = c;
            self.stages.add("fit.chromatic", t);
            busy = true;
        }
        // Sharpening likewise waits for an update none of the others fitted in.
        let t = Instant::now();
        if let Some(s) = self.fit_sharpening_at(current, busy) {
            model.sharpening = s;
            self.stages.add("fit.sharpening", t);
        }
        model.reference.frame_interval_s = Some(self.cfg.frame_interval_s as f32);
        model.reference.pixels_per_radian = self.cfg.intrinsics.map(|k| k.fx);
        model.validate().ok().map(|_| (model, noise_lags))
    }
}

/// The flow of `ctx`'s frame from the providers (the fallback when the primary one
/// cannot serve it; either failure is an event), on the rows where `rows[y]` (None:
/// every row).
fn flow_on(
    providers: &mut Providers,
    ctx: &FrameContext,
    rows: Option<&[bool]>,
    index: u64,
    events: &mut Vec<Event>,
) -> Option<crate::image::Flow> {
    let row = |y: usize| rows.map_or(true, |r| r.get(y).copied().unwrap_or(false));
    match providers.flow.flow_rows(ctx, &row) {
        Ok(f) => Some(f),
        Err(e) => match providers.flow_fallback.as_mut().map(|p| p.flow_rows(ctx, &row)) {
            Some(Ok(f)) => {
                events.push(Event::Degraded { frame: index, reason: format!("{e}; Lucas–Kanade flow used") });
                Some(f)
            }
            Some(Err(e2)) => {
                events.push(Event::Degraded { frame: index, reason: format!("{e}; {e2}") });
                None
            }
            None => {
                events.push(Event::Degraded { frame: index, reason: e.to_string() });
                None
            }
        },
    }
}

impl std::fmt::Debug for Calibrator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Calibrator").field("tier", &self.cfg.tier).field("frames_held", &self.window.len()).finish()
    }
}

/// The 90th percentile of |flow| over the sparse grid's finite vectors (px/frame),
/// as `fit::motion_blur`'s `visible_speed_px` reads a dense flow.
fn sparse_speed_px(flow: &[[f32; 2]]) -> Option<f32> {
    let mut v: Vec<f32> = flow.iter().map(|f| f[0].hypot(f[1])).filter(|s| s.is_finite()).collect();
    (!v.is_empty()).then(|| fit::percentile(&mut v, 0.9))
}
