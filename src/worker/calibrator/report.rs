//! What the calibrator reports: published models with their cost, per-frame
//! events, and the errors that name a bad input.

use crate::model::CameraModel;
use std::time::Instant;

/// Why a model was published.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpdateReason {
    Burst,
    Schedule,
    Change,
}

/// A published model and what it cost.
#[derive(Clone, Debug)]
pub struct Update {
    pub frame: u64,
    pub t_s: f64,
    pub model: CameraModel,
    pub reason: UpdateReason,
    /// Wall time of this update (analysis + fits + aggregation), s.
    pub compute_s: f64,
    /// Frames whose estimates the model aggregates.
    pub frames_used: Vec<u64>,
    /// Where `compute_s` went, in order: `analysis` (depth, pose, sparse motion),
    /// `alignment` (the previous frame warped into this one: the noise probe's and
    /// the blind noise fit's), `change probe`, `lag probe` (the noise's frame-to-frame correlation, its own
    /// alignment under `alignment`), `flow`, `references` (denoise /
    /// deblur providers), `fit.noise`, `fit.motion_blur`, `fit.depth_of_field`
    /// (each fit's own timer), `aggregation`. Seconds; a stage that did not run this
    /// frame is absent. The three fits run concurrently where the worker's pool has
    /// threads, so the stages may sum to more than `compute_s`; on one thread they
    /// add up to it less the untimed glue.
    pub stages_s: Vec<(&'static str, f64)>,
}

/// Per-frame stage timer (`Update::stages_s`).
#[derive(Debug, Default)]
pub(super) struct Stages(pub(super) Vec<(&'static str, f64)>);

impl Stages {
    /// Record the time since `since` as `name`.
    pub(super) fn add(&mut self, name: &'static str, since: Instant) {
        self.push(name, since.elapsed().as_secs_f64());
    }

    pub(super) fn push(&mut self, name: &'static str, s: f64) {
        if s > 0.0 {
            self.0.push((name, s));
        }
    }

    pub(super) fn total(&self) -> f64 {
        self.0.iter().map(|(_, s)| s).sum()
    }
}

/// What one frame did.
#[derive(Clone, Debug)]
pub enum Event {
    Published(Box<Update>),
    /// A provider could not serve this frame (the fit went on without it).
    Degraded {
        frame: u64,
        reason: String,
    },
    /// The frame was not used (and why).
    Skipped {
        frame: u64,
        reason: String,
    },
    /// A camera change was detected at this frame.
    ChangeDetected {
        frame: u64,
        t_s: f64,
        cause: String,
    },
    /// Camera tracking jumped: poses before it are no longer used.
    TrackingLoss {
        t_s: f64,
        reason: String,
    },
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CalibError {
    #[error("frame {frame} is {got_w}×{got_h}, earlier frames are {want_w}×{want_h}")]
    FrameSize { frame: u64, want_w: usize, want_h: usize, got_w: usize, got_h: usize },
    #[error("frame {frame} is empty (0×0)")]
    Empty { frame: u64 },
    #[error("frame {frame} has a non-finite value at x={x}, y={y}")]
    NonFinite { frame: u64, x: usize, y: usize },
    #[error("frame {frame} at t = {t_s} s is not later than the previous frame (t = {previous_s} s)")]
    Time { frame: u64, t_s: f64, previous_s: f64 },
    #[error("pose at t = {t_s} s: {reason}")]
    Pose { t_s: f64, reason: String },
    #[error("intrinsics are for {iw}×{ih} but the frames are {w}×{h}")]
    Intrinsics { iw: usize, ih: usize, w: usize, h: usize },
    #[error("configuration: {0}")]
    Config(String),
}
