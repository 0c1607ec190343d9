//! What the frame loop reports: one record per rendered frame and the run's
//! summary; and the geometry of a frame (G-buffer inputs, content corners), shared
//! by the loop and by anything that reproduces its frames.

use super::{ClockSample, EndReason, EnvironmentDepth, Toggle, View};
use crate::render::{Enabled, FrameInput, GBufferFrame};
use crate::scene::Scene;
use glam::{Mat4, Vec3};
use openxr as xr;
use std::sync::Arc;

/// One rendered frame.
#[derive(Clone, Debug)]
pub struct FrameRecord {
    pub index: u64,
    pub predicted_display_time_ns: i64,
    pub predicted_display_period_ns: i64,
    /// XrTime of the session's first frame: the scene's animation runs on
    /// `predicted_display_time_ns − time_origin_ns` (`FrameGeometry::new`).
    pub time_origin_ns: i64,
    /// The camera-model generation the whole frame used.
    pub model_generation: u64,
    /// The effects the controller toggles allowed this frame (`input.rs`).
    pub enabled: Enabled,
    /// The effects the frame applied: those allowed that the camera model has.
    pub applied: Enabled,
    /// Controller presses acted on in this frame (the app starts or stops a
    /// recording on `Toggle::Record`).
    pub pressed: Vec<Toggle>,
    /// The scene drawn: 0 the starting one, k the k-th of `XrOptions::more_scenes`.
    pub scene: usize,
    /// Where the object stood (LOCAL from scene) at this frame and at the
    /// previous one (grab-and-place moves it; the motion vectors span both).
    pub local_from_scene: Mat4,
    pub prev_local_from_scene: Mat4,
    /// CPU time of the frame outside xrWaitFrame (s).
    pub cpu_s: f64,
    /// Time blocked in xrWaitFrame (s).
    pub wait_s: f64,
    pub views: [View; 2],
    /// The runtime located these views for this frame with valid orientation and
    /// position. False: tracking was lost and `views` are the last tracked ones,
    /// shown again (the compositor reprojects them); their poses say nothing about
    /// where the head is now and must not reach the calibration.
    pub views_tracked: bool,
    /// A reading of CLOCK_MONOTONIC, CLOCK_BOOTTIME and the XrTime of the former
    /// (XR_KHR_convert_timespec_time), taken on the first frame and about once a
    /// second after: what maps camera timestamps onto the XR clock
    /// (`analysis::timing::ClockMap`). None on other frames and without the extension.
    pub clock: Option<ClockSample>,
    /// The headset's depth read back since the previous rendered frame (acquired a
    /// frame or more earlier; XR_META_environment_depth at `env_depth_hz`).
    pub env_depth: Option<Arc<EnvironmentDepth>>,
    /// The lines the status panel's quad shows in this frame (`crate::panel::draw`
    /// of them is its image); None while hidden or not yet drawn.
    pub panel: Option<Arc<[String]>>,
}

/// The frame-timing summary `blind-augment xr` prints.
#[derive(Clone, Debug)]
pub struct XrSummary {
    pub runtime: String,
    pub system: String,
    pub device: String,
    pub eye_size: (u32, u32),
    pub swapchain_format: u32,
    pub blend_mode: xr::EnvironmentBlendMode,
    pub passthrough: bool,
    /// XR_FB_space_warp in use (the compositor synthesises every other frame).
    pub space_warp: bool,
    /// XR_META_environment_depth in use.
    pub env_depth: bool,
    /// Environment-depth images read back.
    pub env_depth_reads: u64,
    pub display_hz: Option<f32>,
    pub frames_rendered: u64,
    /// Frames submitted with no layers: the session not visible, or no view tracked yet.
    pub frames_empty: u64,
    /// Frames whose views were not tracked (xrLocateViews without both valid
    /// bits, or unusable values): the last tracked views shown again, or no layer
    /// before any was tracked.
    pub frames_untracked: u64,
    /// Rendered frames that followed a skipped display slot: the frame's predicted
    /// display time lies more than 1.5 periods (`predicted_display_period`, the
    /// app's period: twice the display's under space warp) after the previous
    /// rendered frame's. Counted from the runtime's predictions, not from the
    /// display, and only between consecutive rendered frames.
    pub missed_frames: u64,
    pub cpu_s: Vec<f64>,
    pub wait_s: Vec<f64>,
    pub periods_ns: Vec<i64>,
    pub states: Vec<xr::SessionState>,
    pub end: EndReason,
    /// Vulkan validation messages (empty when clean).
    pub vulkan_messages: Vec<String>,
    /// The runtime accepted the controller bindings and the action set is attached.
    pub controls: bool,
    /// Controller presses acted on, with the rendered frame they took effect in.
    pub toggles: Vec<(u64, Toggle)>,
    /// Scene changes: the first rendered frame showing it and its index.
    pub scene_changes: Vec<(u64, usize)>,
    /// Scenes that failed to load (skipped), each with the file and why.
    pub scene_errors: Vec<String>,
    /// The status panel could be set up (its swapchain and VIEW space), and how
    /// often it was redrawn.
    pub panel: bool,
    pub panel_redraws: u64,
}

/// What the render core needs for one XR frame besides the snapshot: the
/// G-buffer inputs (both eyes now and one render frame before, the scene's node
/// transforms at both times) and the content's corners. Shared by the frame loop
/// and by anything that must reproduce its frames (the tests' desktop replay).
pub struct FrameGeometry {
    pub gbuffer: GBufferFrame,
    pub corners_now: Vec<Vec3>,
    pub corners_prev: Vec<Vec3>,
    /// Seconds between the previous rendered frame's display time and this one's:
    /// what the motion vectors span.
    pub render_interval_s: f32,
}

impl FrameGeometry {
    /// `prev`: the previous rendered frame's display time (ns) and eyes, or None
    /// for the first frame (then the eyes stand still over one display period).
    /// `origin_ns`: the XrTime the scene's animation starts from (the session's
    /// first frame).
    /// `local_from_scene`: where the object stands now and stood at the previous
    /// frame (equal unless it was moved).
    pub fn new(
        scene: &Scene,
        local_from_scene: (Mat4, Mat4),
        eyes: [crate::render::Eye; 2],
        prev: Option<(i64, [crate::render::Eye; 2])>,
        display_ns: i64,
        period_ns: i64,
        origin_ns: i64,
    ) -> Self {
        let (prev_t_ns, prev_eyes) = prev.unwrap_or((display_ns - period_ns, eyes));
        // Scene animation time: f64 seconds since the session started, from integer
        // nanoseconds. XrTime's epoch is the runtime's (often boot): as f32 seconds
        // it would step by 7.8 ms after a day awake, and motion vectors jump.
        let t_s = (display_ns - origin_ns) as f64 * 1e-9;
        let t_prev_s = (prev_t_ns - origin_ns) as f64 * 1e-9;
        let (pose, prev_pose) = (scene.pose_at(t_s, local_from_scene.0), scene.pose_at(t_prev_s, local_from_scene.1));
        let (corners_now, corners_prev) = (pose.world_corners(scene), prev_pose.world_corners(scene));
        Self {
            gbuffer: GBufferFrame {
                eyes,
                prev_eyes,
                pose,
                prev_pose,
                light_dir: crate::render::gbuffer::SCENE_LIGHT_DIR,
                ambient: crate::render::gbuffer::SCENE_AMBIENT,
            },
            corners_now,
            corners_prev,
            render_interval_s: ((display_ns - prev_t_ns) as f64 * 1e-9) as f32,
        }
    }

    pub fn input(&self) -> FrameInput<'_> {
        FrameInput { gbuffer: &self.gbuffer, corners_now: &self.corners_now, corners_prev: &self.corners_prev }
    }
}
