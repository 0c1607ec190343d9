//! Analysis providers: what the fits need besides the frame itself — depth, flow,
//! and references with an effect removed (denoised, motion-deblurred,
//! defocus-deblurred) — one trait per role, each with interchangeable providers:
//!
//! * **headset-native**: the headset's own metric depth, delivered with the frame
//!   (`Frame::depth`; on Quest, XR_META_environment_depth reprojected into the
//!   camera by `reproject`, per frame by `headset_depth`; on desktop, depth files), and flow from head pose +
//!   depth (`PoseDepthFlow`), exact for a static scene. On a headset these replace the paper's two slowest networks.
//! * **classical** (`LucasKanadeFlow`, `GivenFlow`; the blind estimators of `fit`).
//! * **video as its own reference** (`temporal`): other frames aligned by pose and
//!   depth give I_noNoise (their mean) and I_noMB (the sharpest of them).
//! * **tract-onnx**: models loaded under a documented contract per role (`onnx`).
//!
//! Providers see the frame in its context (`FrameContext`: recent frames, the pose
//! track, the intrinsics), so a temporal provider and a single-frame network have
//! the same signature. Nothing here panics on bad input: errors name the frame and
//! what is missing.

pub mod camera;
pub mod camera_access;
pub mod flow;
pub mod headset_depth;
pub mod onnx;
pub mod reproject;
pub mod temporal;
pub mod timing;

pub use flow::{GivenFlow, LucasKanadeFlow, PoseDepthFlow};
pub use reproject::Intrinsics;
pub use temporal::{TemporalDenoiser, TemporalMotionDeblur};

use crate::image::{Flow, Plane, Rgb};
use crate::model::DepthUnits;
use glam::Mat4;
use std::sync::Arc;
use timing::PoseTrack;

/// One camera frame as the worker receives it.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Position in the video (frame number), for messages and the timeline.
    pub index: u64,
    /// Middle of the frame's exposure, seconds on the video's clock.
    pub t_s: f64,
    /// Linear (or the camera's encoded) RGB in [0, 1].
    pub image: Rgb,
    /// Depth delivered with the frame (headset depth reprojected; a depth file).
    /// The worker moves it into `Analysed::depth`.
    pub depth: Option<DepthMap>,
    /// Flow delivered with the frame (a flow file), px per frame interval.
    pub flow: Option<Flow>,
}

/// A depth map and how its values read.
#[derive(Clone, Debug)]
pub struct DepthMap {
    pub depth: Plane,
    pub units: DepthUnits,
}

/// A frame and what the providers made of it, kept in the worker's window.
#[derive(Clone, Debug)]
pub struct Analysed {
    pub frame: Frame,
    pub depth: Option<DepthMap>,
    /// `world_from_camera` at the frame's time (OpenCV axes), when poses are known.
    pub world_from_camera: Option<Mat4>,
    /// Motion at a sparse grid of pixels (px per frame interval), when known: what
    /// the temporal providers compare frames by without computing dense flow.
    pub sparse_flow: Option<Vec<[f32; 2]>>,
}

impl Analysed {
    /// Largest motion over the sparse grid (px per frame interval).
    pub fn max_motion_px(&self) -> Option<f32> {
        self.sparse_flow.as_ref().map(|f| f.iter().map(|v| v[0].hypot(v[1])).fold(0.0, f32::max))
    }
}

/// What a provider sees: the frame, earlier frames (oldest first, the frame
/// itself not included), the camera's pose track and intrinsics.
#[derive(Clone, Copy)]
pub struct FrameContext<'a> {
    pub current: &'a Analysed,
    pub window: &'a [Arc<Analysed>],
    pub poses: Option<&'a PoseTrack>,
    pub intrinsics: Option<&'a Intrinsics>,
    pub frame_interval_s: f64,
}

/// A reference image with one effect removed, where it holds, and how much of the
/// frame's noise it still carries (variance relative to the frame's: 1/m for the
/// mean of m other frames; 0 for a perfect denoiser). The noise fit divides the
/// residual variance by 1 + that ratio.
#[derive(Clone, Debug)]
pub struct Reference {
    pub image: Rgb,
    pub valid: Option<Plane>,
    pub noise_variance_ratio: f32,
    /// Frames it was made from (their indices): for diagnostics, and the worker
    /// refuses leaking noise fits on such references (one estimate of several,
    /// `fit::FitOptions::noise_min_leak_ratio`); empty for a single-frame one (a
    /// network's).
    pub sources: Vec<u64>,
    /// A second estimate of the same reference whose noise is independent of
    /// `image`'s (made from other frames), valid where `valid` is; the motion-blur
    /// fit then minimises a cross loss that the references' noise does not bias
    /// (`fit::FitInputs::motion_deblurred_second`).
    pub second: Option<Rgb>,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AnalysisError {
    /// The provider cannot work on this frame (no pose, no depth, no neighbour):
    /// the worker logs it and falls back or skips the frame.
    #[error("frame {frame}: {provider}: {reason}")]
    Unavailable { frame: u64, provider: &'static str, reason: String },
    /// The provider itself is broken (a model that fails at run time).
    #[error("{provider}: {reason}")]
    Failed { provider: String, reason: String },
}

impl AnalysisError {
    pub fn unavailable(frame: u64, provider: &'static str, reason: impl Into<String>) -> Self {
        Self::Unavailable { frame, provider, reason: reason.into() }
    }
}

/// The roles a provider can fill (`--onnx ROLE=PATH`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Role {
    Depth,
    Flow,
    Denoise,
    MotionDeblur,
    DefocusDeblur,
}

impl Role {
    pub const ALL: [Role; 5] = [Role::Depth, Role::Flow, Role::Denoise, Role::MotionDeblur, Role::DefocusDeblur];

    pub fn name(self) -> &'static str {
        match self {
            Role::Depth => "depth",
            Role::Flow => "flow",
            Role::Denoise => "denoise",
            Role::MotionDeblur => "motion-deblur",
            Role::DefocusDeblur => "defocus-deblur",
        }
    }

    pub fn parse(s: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.name() == s)
    }
}

/// Depth at the current frame's pixels.
pub trait DepthProvider: Send {
    fn name(&self) -> &str;
    fn depth(&mut self, ctx: &FrameContext) -> Result<DepthMap, AnalysisError>;
}

/// Flow at the current frame, px per frame interval, centred on the frame time.
pub trait FlowProvider: Send {
    fn name(&self) -> &str;
    fn flow(&mut self, ctx: &FrameContext) -> Result<Flow, AnalysisError>;
    /// The flow where `row(y)`; other rows may hold 0. For a caller that reads part
    /// of the frame (the motion-blur fit against a sparse reference,
    /// `MotionDeblurrer::rows`). A provider that cannot restrict its work computes
    /// every row.
    fn flow_rows(&mut self, ctx: &FrameContext, row: &(dyn Fn(usize) -> bool + Sync)) -> Result<Flow, AnalysisError> {
        let _ = row;
        self.flow(ctx)
    }
}

/// I_noNoise.
pub trait Denoiser: Send {
    fn name(&self) -> &str;
    fn denoise(&mut self, ctx: &FrameContext) -> Result<Reference, AnalysisError>;
}

/// I_noMB, given the frame's flow.
pub trait MotionDeblurrer: Send {
    fn name(&self) -> &str;
    fn deblur(&mut self, ctx: &FrameContext, flow: &Flow) -> Result<Reference, AnalysisError>;
    /// The rows (`[y]`) a reference for a `width`×`height` frame can be valid on, when
    /// it is known to be fewer than all (None: any row): the flow is then needed
    /// there only (`FlowProvider::flow_rows`).
    fn rows(&self, width: usize, height: usize) -> Option<Vec<bool>> {
        let _ = (width, height);
        None
    }
    /// A reference this provider made, which its caller is done with, unchanged: the
    /// provider may reuse its buffers (a frame-sized buffer's first touch costs page
    /// faults; `TemporalMotionDeblur` writes only its bands). By default it is
    /// dropped.
    fn recycle(&mut self, spare: Reference) {
        let _ = spare;
    }
}

/// I_noDoF, given the frame's depth.
pub trait DefocusDeblurrer: Send {
    fn name(&self) -> &str;
    fn deblur(&mut self, ctx: &FrameContext, depth: &DepthMap) -> Result<Reference, AnalysisError>;
}
