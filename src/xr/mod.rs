//! The OpenXR application: instance (XR_KHR_vulkan_enable2, so the runtime creates
//! the Vulkan instance and device the render core uses), session, a multiview
//! swapchain (one image array, a layer per eye) the stereo renderer's composite is
//! copied into, passthrough (XR_FB_passthrough under an alpha-blended projection
//! layer, or the ALPHA_BLEND environment blend mode where offered), the display
//! rate (XR_FB_display_refresh_rate), the headset's depth for calibration
//! (XR_META_environment_depth, `env_depth`), the session state machine and the frame
//! loop. The same code runs on the headset and, on desktop, on the project's
//! headless test runtime (`tests/xr-runtime`) through the Khronos loader.
//!
//! Teardown order (openxrs' `examples/vulkan.rs`, and the spec's parent/child
//! rule: a handle is destroyed before its parent, Vulkan objects before the
//! device the session was created with): the GPU is drained; the renderer (its
//! Vulkan objects) goes; the status panel (its upload, swapchain and VIEW space); the environment-depth read-back, swapchain and provider;
//! the passthrough layer and feature, the swapchain, the controls' action space
//! and the reference space (children of the session); the session; then the Vulkan device
//! and instance (`GpuContext`, created through the XR instance but owned by the
//! app); the XR instance last. `run` holds them as locals declared in the reverse
//! of that order, so Rust's drop order (reverse declaration) is the teardown order.
#![allow(unsafe_code)]

mod env_depth;
mod input;
mod instance;
mod layers;
mod lifecycle;
mod panel;
mod record;
mod scenes;
mod spacewarp;
mod views;
mod vulkan;

pub use env_depth::{depth_views, EnvironmentDepth, ROWS_BOTTOM_UP};
pub use lifecycle::{Action, EndReason, Lifecycle};
pub use record::{FrameGeometry, FrameRecord, XrSummary};
pub use scenes::scenes_in;
pub use views::{eye_from_view, View, ViewError};

use crate::analysis::timing::ClockSample;
use crate::gpu::{GpuContext, GpuError, GpuOptions};
use crate::model::{CameraModel, DepthOfField, DepthUnits, Diagnostics, DofCurve, MotionBlur};
use crate::render::{Enabled, ExternalTarget, LayerSettings, StereoRenderer};
use crate::scene::Scene;
use crate::worker::ModelChannel;
use ash::vk;
use ash::vk::Handle as _;
use glam::{Mat4, Quat, Vec3};
pub use input::{Placement, Toggle, Toggles};
use instance::{chained_system_properties, create_instance, sample_clocks};
use openxr as xr;
use spacewarp::space_warp_swapchains;
use std::sync::Arc;
use std::time::{Duration, Instant};
use vulkan::XrVulkan;

#[derive(Debug, thiserror::Error)]
pub enum XrError {
    #[error("no OpenXR loader: {0} (Debian: apt-get install libopenxr-loader1; Android: the APK carries libopenxr_loader.so)")]
    NoLoader(String),
    #[error(
        "no OpenXR runtime: {0} (on desktop, point XR_RUNTIME_JSON at a runtime manifest, e.g. the test runtime's printed by `cargo xtask xr-runtime`)"
    )]
    NoRuntime(String),
    #[error("the OpenXR runtime does not offer {0}, which blind-augment needs")]
    MissingExtension(&'static str),
    #[error("OpenXR call {call} failed: {result}")]
    Call { call: &'static str, result: xr::sys::Result },
    #[error("the runtime's Vulkan requirements ({min}–{max}) exclude the Vulkan 1.1 the render core needs")]
    VulkanVersion { min: String, max: String },
    #[error("no swapchain format the render core can write: the runtime offers {0:?} (needs R8G8B8A8 sRGB or UNORM)")]
    SwapchainFormat(Vec<u32>),
    #[error("the primary stereo view configuration has {0} views, not 2")]
    ViewCount(usize),
    #[error("the runtime located an unusable view: {0}")]
    View(#[from] ViewError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("environment depth: {0}")]
    EnvironmentDepth(String),
}

fn call(name: &'static str) -> impl Fn(xr::sys::Result) -> XrError {
    move |result| XrError::Call { call: name, result }
}

/// What the frame loop is asked to do.
pub struct XrOptions<'a> {
    /// Stop (request exit) after this many rendered frames; None = until the
    /// runtime ends the session.
    pub frames: Option<u64>,
    /// Enable Vulkan's validation layer when installed (tests do).
    pub validation: bool,
    /// Enable the Khronos core validation layer (XR_APILAYER_LUNARG_core_validation)
    /// when installed (tests do, except where a layer older than an extension the
    /// app uses rejects it).
    pub core_validation: bool,
    /// The starting scene.
    pub scene: &'a Scene,
    /// Scenes cycled after it (next-scene button), each loaded when asked for; one
    /// that fails to load is named and skipped.
    pub more_scenes: &'a [std::path::PathBuf],
    /// Where the virtual content stands, in the LOCAL reference space.
    pub local_from_scene: Mat4,
    /// Camera models: one snapshot is taken per frame (`ModelChannel::latest`).
    pub models: &'a ModelChannel,
    pub settings: LayerSettings,
    /// Preferred display refresh rate (Hz) when XR_FB_display_refresh_rate is offered.
    pub display_hz: f32,
    /// Read the headset's depth (XR_META_environment_depth) at most this often (Hz)
    /// into `FrameRecord::env_depth`, for calibration; 0: not used.
    pub env_depth_hz: f32,
    /// Called after each rendered frame with its record (tests, the CLI's progress).
    pub on_frame: Option<&'a mut dyn FnMut(&FrameRecord)>,
    /// Set from any thread to shut down (Ctrl-C, Android's onDestroy): the loop
    /// calls xrRequestExitSession and ends when the runtime reaches EXITING.
    pub stop: Option<&'a std::sync::atomic::AtomicBool>,
    /// Show the status panel from the start (the panel button toggles it).
    pub panel: bool,
    /// The app's lines for the status panel (camera rates, calibration phase,
    /// recording: `crate::panel::CalibrationStatus`), called when the panel is
    /// redrawn (≤ 2 Hz); it must not block.
    pub status: Option<&'a dyn Fn() -> Vec<String>>,
    /// How the loader is initialised and the instance created: `&()` on desktop,
    /// `openxr::AndroidPlatformInfo` (JavaVM + activity) on Android.
    pub platform: &'a dyn xr::PlatformInfo,
}

/// The display rate the Quest app asks for: Meta's Passthrough Best Practices
/// ("To maximize the smoothness of passthrough, it is recommended to use a 72Hz
/// refresh rate for your application. In flicker-free lighting conditions,
/// passthrough will synchronize the cameras with the display"), and the rate apps
/// get by default. 72 Hz is also the lowest rate a Quest 3 offers, so a measured
/// frame budget could only argue for a higher one, which the cameras would then
/// not follow; the loop's own measurement (`XrSummary::missed_frames`, printed by
/// `blind-augment xr`) says when even 13.9 ms is too little, and the remedy there
/// is space warp (half the rate), not a lower display rate.
pub const PASSTHROUGH_DISPLAY_HZ: f32 = 72.0;

/// How often environment depth is set up again while it is not permitted.
const ENV_DEPTH_RETRY: Duration = Duration::from_secs(1);

fn view_of(v: &xr::View) -> View {
    let q = v.pose.orientation;
    let p = v.pose.position;
    View {
        orientation: Quat::from_xyzw(q.x, q.y, q.z, q.w),
        position_m: Vec3::new(p.x, p.y, p.z),
        fov_rad: [v.fov.angle_left, v.fov.angle_right, v.fov.angle_up, v.fov.angle_down],
    }
}

/// Both views of one frame as located and usable: what the renderer draws and
/// the projection layer submits.
#[derive(Clone)]
struct TrackedViews {
    views: [View; 2],
    poses: [xr::Posef; 2],
    eyes: [crate::render::Eye; 2],
    fovs: [[f32; 4]; 2],
}

impl TrackedViews {
    /// The located views, or why they cannot be used. OpenXR 1.1, "View and
    /// Projection State": "Applications must not read any of the XrView pose
    /// orientation fields if [XR_VIEW_STATE_ORIENTATION_VALID_BIT] is unset", and
    /// likewise the positions without XR_VIEW_STATE_POSITION_VALID_BIT. Values
    /// that are present but unusable (a zero quaternion) are refused too. (The
    /// openxr 0.22 crate's `View::new` already hands back zeroed fields where a
    /// bit is unset, which the quaternion check refuses; the flags are checked
    /// here so the rule does not rest on that wrapper.)
    fn new(flags: xr::ViewStateFlags, located: &[xr::View], size: (u32, u32)) -> Result<Self, String> {
        let valid = xr::ViewStateFlags::ORIENTATION_VALID | xr::ViewStateFlags::POSITION_VALID;
        if !flags.contains(valid) {
            return Err(format!("view state flags {flags:?} lack ORIENTATION_VALID | POSITION_VALID"));
        }
        let [l, r] = located else { return Err(format!("{} views located, not 2", located.len())) };
        let views = [view_of(l), view_of(r)];
        let (le, lfov) = eye_from_view(&views[0], size.0, size.1).map_err(|e| e.to_string())?;
        let (re, rfov) = eye_from_view(&views[1], size.0, size.1).map_err(|e| e.to_string())?;
        Ok(Self { views, poses: [l.pose, r.pose], eyes: [le, re], fovs: [lfov, rfov] })
    }
}

/// The camera model used until calibration publishes one: a Quest 3-like
/// passthrough camera (1280×960 at 30 Hz, ≈ 100° horizontal field of view) with
/// moderate sensor noise, exposure λ = 0.4 and mild defocus away from 1.5 m. A
/// placeholder, stated as such in its diagnostics — not a measurement.
pub fn default_camera() -> CameraModel {
    let mut m = CameraModel::empty(1280, 960);
    m.reference.frame_interval_s = Some(1.0 / 30.0);
    m.reference.pixels_per_radian = Some(640.0 / 50.0f32.to_radians().tan());
    m.noise = crate::synth::white_sensor_noise([2e-5, 1.2e-5, 4e-5], [8e-4, 5e-4, 1.2e-3], [0.0, 1.0]);
    let placeholder = || Diagnostics::not_fitted("default model (no calibration yet)");
    m.motion_blur = MotionBlur { present: true, exposure: Some(0.4), diagnostics: placeholder() };
    m.depth_of_field = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::ThinLens { k: 1.5, focus_depth: 1.5, c0: 0.2 }),
        depth_range: [0.3, 10.0],
        kernel: crate::model::DofKernel::Gaussian,
        diagnostics: placeholder(),
    };
    m
}

/// Pick the display rate: `want` if offered, else the offered rate nearest it.
pub fn pick_refresh_rate(offered: &[f32], want: f32) -> Option<f32> {
    offered
        .iter()
        .copied()
        .filter(|r| r.is_finite() && *r > 0.0)
        .min_by(|a, b| (a - want).abs().total_cmp(&(b - want).abs()))
}

/// Run the XR app until the runtime ends the session (or `frames` are rendered).
pub fn run(mut opts: XrOptions<'_>) -> Result<XrSummary, XrError> {
    // Declared in the reverse of the teardown order (see the module doc).
    let (_entry, instance, enabled) = create_instance(opts.core_validation, opts.platform, opts.env_depth_hz > 0.0)?;
    let props = instance.properties().map_err(call("xrGetInstanceProperties"))?;
    let system = instance.system(xr::FormFactor::HEAD_MOUNTED_DISPLAY).map_err(call("xrGetSystem"))?;
    let sys_props = instance.system_properties(system).map_err(call("xrGetSystemProperties"))?;
    log::info!("OpenXR runtime {} {}, system {}", props.runtime_name, props.runtime_version, sys_props.system_name);

    let blend_modes = instance
        .enumerate_environment_blend_modes(system, xr::ViewConfigurationType::PRIMARY_STEREO)
        .map_err(call("xrEnumerateEnvironmentBlendModes"))?;
    // Passthrough: XR_FB_passthrough wherever it is offered — its layer under the
    // projection layer in an OPAQUE frame, as Meta's XrPassthrough sample submits
    // (Meta-OpenXR-SDK, Samples/XrSamples/XrPassthrough/Src/XrPassthrough.cpp) —
    // even where ALPHA_BLEND is listed too: Meta's Passthrough Camera API needs
    // passthrough running ("Passthrough feature: must be enabled to access the
    // Passthrough Camera API", Unity-PassthroughCameraApiSamples README), and the
    // calibration lives on that camera. Else ALPHA_BLEND where offered (the
    // compositor blends the layer over the real world), else nothing.
    let (blend_mode, use_fb_passthrough) = if enabled.fb_passthrough {
        (xr::EnvironmentBlendMode::OPAQUE, true)
    } else if blend_modes.contains(&xr::EnvironmentBlendMode::ALPHA_BLEND) {
        (xr::EnvironmentBlendMode::ALPHA_BLEND, false)
    } else {
        log::warn!("OpenXR: no passthrough (neither ALPHA_BLEND nor XR_FB_passthrough): virtual content over black");
        (blend_modes.first().copied().unwrap_or(xr::EnvironmentBlendMode::OPAQUE), false)
    };

    let req =
        instance.graphics_requirements::<xr::Vulkan>(system).map_err(call("xrGetVulkanGraphicsRequirements2KHR"))?;
    let v11 = xr::Version::new(1, 1, 0);
    if req.min_api_version_supported > v11 || req.max_api_version_supported.major() < 1 {
        return Err(XrError::VulkanVersion {
            min: req.min_api_version_supported.to_string(),
            max: req.max_api_version_supported.to_string(),
        });
    }
    let gpu_opts = GpuOptions { validation: opts.validation, prefer_device: None };
    let ctx = GpuContext::with_factory(&gpu_opts, &XrVulkan { instance: &instance, system })?;
    let (vk_instance, vk_physical, vk_device, family) = ctx.raw_handles();

    // SAFETY: the handles are live (owned by `ctx`, which outlives the session: it
    // is declared before it and so dropped after it), created through this instance.
    let (session, mut frame_waiter, mut frame_stream) = unsafe {
        instance.create_session::<xr::Vulkan>(
            system,
            &xr::vulkan::SessionCreateInfo {
                instance: vk_instance.as_raw() as _,
                physical_device: vk_physical.as_raw() as _,
                device: vk_device.as_raw() as _,
                queue_family_index: family,
                queue_index: 0,
            },
        )
    }
    .map_err(call("xrCreateSession"))?;

    let space = session
        .create_reference_space(xr::ReferenceSpaceType::LOCAL, xr::Posef::IDENTITY)
        .map_err(call("xrCreateReferenceSpace"))?;
    let config_views = instance
        .enumerate_view_configuration_views(system, xr::ViewConfigurationType::PRIMARY_STEREO)
        .map_err(call("xrEnumerateViewConfigurationViews"))?;
    let (w, h) = match config_views.as_slice() {
        [l, r] => (
            l.recommended_image_rect_width.max(r.recommended_image_rect_width),
            l.recommended_image_rect_height.max(r.recommended_image_rect_height),
        ),
        other => return Err(XrError::ViewCount(other.len())),
    };
    // RGBA8 only: the composite is copied bit for bit (sRGB-encoded values into an
    // SRGB image read back as the same colours). sRGB first: the compositor then
    // decodes to linear light as it must.
    let formats = session.enumerate_swapchain_formats().map_err(call("xrEnumerateSwapchainFormats"))?;
    let format = [vk::Format::R8G8B8A8_SRGB, vk::Format::R8G8B8A8_UNORM]
        .into_iter()
        .map(|f| f.as_raw() as u32)
        .find(|f| formats.contains(f))
        .ok_or_else(|| XrError::SwapchainFormat(formats.clone()))?;
    if format == vk::Format::R8G8B8A8_UNORM.as_raw() as u32 {
        log::warn!("OpenXR: no sRGB swapchain format; the compositor will treat encoded values as linear");
    }
    let mut swapchain = session
        .create_swapchain(&xr::SwapchainCreateInfo {
            create_flags: xr::SwapchainCreateFlags::EMPTY,
            usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT | xr::SwapchainUsageFlags::TRANSFER_DST,
            format,
            sample_count: 1,
            width: w,
            height: h,
            face_count: 1,
            array_size: 2,
            mip_count: 1,
        })
        .map_err(call("xrCreateSwapchain"))?;
    let images: Vec<vk::Image> = swapchain
        .enumerate_images()
        .map_err(call("xrEnumerateSwapchainImages"))?
        .into_iter()
        .map(vk::Image::from_raw)
        .collect();

    // The status panel: optional (a runtime that refuses its swapchain or the VIEW
    // space costs the panel, never the session).
    let mut status_panel = panel::Panel::new(&ctx, &session, format, opts.panel)
        .map_err(|e| log::warn!("OpenXR: no status panel ({e})"))
        .ok();

    // XR_FB_space_warp: motion vectors and depth for the compositor, which then
    // synthesises every other display frame; the runtime halves the app's rate.
    let mut space_warp = if enabled.fb_space_warp {
        space_warp_swapchains(&instance, system, &session, &formats, (w, h))?
    } else {
        None
    };

    // Passthrough feature and layer, running from creation (openxr 0.22's
    // `Passthrough::start` calls xrPassthroughPauseFB: never call it).
    let passthrough = if use_fb_passthrough {
        let pt = session
            .create_passthrough(xr::PassthroughFlagsFB::IS_RUNNING_AT_CREATION)
            .map_err(call("xrCreatePassthroughFB"))?;
        let layer = session
            .create_passthrough_layer(
                &pt,
                xr::PassthroughFlagsFB::IS_RUNNING_AT_CREATION,
                xr::PassthroughLayerPurposeFB::RECONSTRUCTION,
            )
            .map_err(call("xrCreatePassthroughLayerFB"))?;
        Some((pt, layer))
    } else {
        None
    };
    let see_through = passthrough.is_some() || blend_mode == xr::EnvironmentBlendMode::ALPHA_BLEND;

    // The headset's depth for calibration; a failure to set it up costs the depth,
    // never the session. Not permitted yet (the user may still be answering the
    // permission dialog): tried again every ENV_DEPTH_RETRY.
    let setup_env_depth = |told: bool| -> (Option<Box<env_depth::EnvDepth<'_>>>, Option<Instant>) {
        match env_depth::EnvDepth::set_up(&instance, system, &session, &ctx, opts.env_depth_hz) {
            Ok(env_depth::Setup::Ready(d)) => (Some(d), None),
            Ok(env_depth::Setup::Unsupported) => {
                log::warn!("OpenXR: the system has no environment depth: calibration runs without headset depth");
                (None, None)
            }
            Ok(env_depth::Setup::NotPermitted) => {
                if !told {
                    log::warn!(
                        "OpenXR: environment depth not permitted (the spatial-data permission com.oculus.permission.USE_SCENE): calibration runs without headset depth until it is granted"
                    );
                }
                (None, Some(Instant::now()))
            }
            Err(e) => {
                log::warn!("OpenXR: environment depth unavailable ({e}): calibration runs without headset depth");
                (None, None)
            }
        }
    };
    let (mut env_depth, mut env_depth_retry) =
        if enabled.meta_environment_depth { setup_env_depth(false) } else { (None, None) };

    let mut display_hz = None;
    if enabled.fb_display_refresh_rate {
        let rates = session.enumerate_display_refresh_rates().map_err(call("xrEnumerateDisplayRefreshRatesFB"))?;
        if let Some(r) = pick_refresh_rate(&rates, opts.display_hz) {
            session.request_display_refresh_rate(r).map_err(call("xrRequestDisplayRefreshRateFB"))?;
            log::info!("OpenXR: display refresh rate {r} Hz requested (offered {rates:?})");
            display_hz = Some(r);
        }
    }

    // The renderer and its pipelines are built here, after the session and
    // swapchains and before the first xrBeginFrame, so the first visible frame does
    // not pay for them (115–330 ms on lavapipe). Straight alpha: see
    // `layers::projection_flags`. Over passthrough the background is transparent
    // (the compositor blends the layer over the real world); without it, opaque
    // black, so the layer is opaque and its alpha unused.
    let settings = LayerSettings { straight_alpha: true, ..opts.settings };
    let background_px: [u8; 4] = if see_through { [0, 0, 0, 0] } else { [0, 0, 0, 255] };
    let warp_size = space_warp.as_ref().map(|sw| sw.size);
    // Also what a scene change rebuilds (the G-buffer's meshes, materials and
    // textures are the scene's).
    let build_renderer = |scene: &Scene| -> Result<StereoRenderer<'_>, GpuError> {
        let mut r = StereoRenderer::new(&ctx, scene, w, h, settings, None)?;
        r.set_background(&background_px.repeat((w * h * 2) as usize))?;
        if let Some((sw, sh)) = warp_size {
            r.enable_space_warp(sw, sh)?;
        }
        Ok(r)
    };
    let mut renderer = build_renderer(opts.scene)?;
    let flags = layers::projection_flags(see_through);

    let mut lifecycle = Lifecycle::default();
    let mut summary = XrSummary {
        runtime: format!("{} {}", props.runtime_name, props.runtime_version),
        system: sys_props.system_name.clone(),
        device: ctx.device_name().to_string(),
        eye_size: (w, h),
        swapchain_format: format,
        blend_mode,
        passthrough: see_through,
        space_warp: space_warp.is_some(),
        env_depth: env_depth.is_some(),
        env_depth_reads: 0,
        display_hz,
        frames_rendered: 0,
        frames_empty: 0,
        frames_untracked: 0,
        missed_frames: 0,
        cpu_s: vec![],
        wait_s: vec![],
        periods_ns: vec![],
        states: vec![],
        end: EndReason::Exited,
        vulkan_messages: vec![],
        controls: false,
        toggles: vec![],
        scene_changes: vec![],
        scene_errors: vec![],
        panel: status_panel.is_some(),
        panel_redraws: 0,
    };
    // When the snapshot's generation was first seen (the panel's model age).
    let mut generation_seen: Option<(u64, Instant)> = None;
    let mut cycle = scenes::SceneCycle::new(opts.more_scenes.to_vec());
    // Where the object stands in the reference space: moved by grab-and-place.
    let mut placement = input::Placement::new(opts.local_from_scene);
    // The scene drawn when it is not the starting one.
    let mut loaded: Option<Box<Scene>> = None;
    // Controller toggles; input is optional: without it the app runs matched.
    let controls = match input::Controls::new(&instance, enabled.meta_touch_controller_plus)
        .and_then(|mut c| c.attach(&session).map(|()| c))
    {
        Ok(c) => Some(c),
        Err(e) => {
            log::warn!("OpenXR: controller input unavailable ({e}); effects stay on");
            None
        }
    };
    summary.controls = controls.is_some();
    let mut toggles = Toggles::default();
    let mut event_buffer = xr::EventDataBuffer::new();
    let mut exit_requested = false;
    let mut prev: Option<(i64, [crate::render::Eye; 2])> = None;
    let mut last_display_ns: Option<i64> = None;
    let mut last_clock_sample: Option<Instant> = None;
    // The scene's animation clock: XrTime of the session's first frame (XrTime
    // counts from a runtime-chosen epoch, often boot; spec "XrTime").
    let mut time_origin_ns: Option<i64> = None;
    // The last views whose orientation and position were both valid, as tracked.
    let mut last_tracked: Option<TrackedViews> = None;
    let stop_requested = || opts.stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed));

    'frames: loop {
        // Drain the event queue every iteration (spec 2.20: an app that stops
        // polling may lose events).
        while let Some(event) = instance.poll_event(&mut event_buffer).map_err(call("xrPollEvent"))? {
            use xr::Event;
            match event {
                Event::SessionStateChanged(e) => {
                    log::info!("OpenXR: session state {:?}", e.state());
                    match lifecycle.on_state(e.state()) {
                        Action::Begin => {
                            session.begin(xr::ViewConfigurationType::PRIMARY_STEREO).map_err(call("xrBeginSession"))?;
                        }
                        Action::End => {
                            session.end().map_err(call("xrEndSession"))?;
                        }
                        Action::Exit => {
                            summary.end = EndReason::Exited;
                            break 'frames;
                        }
                        Action::Lost => {
                            log::warn!("OpenXR: session lost; tearing down");
                            summary.end = EndReason::SessionLost;
                            break 'frames;
                        }
                        Action::None => {}
                    }
                }
                Event::InstanceLossPending(_) => {
                    log::warn!("OpenXR: instance loss pending; tearing down");
                    summary.end = EndReason::InstanceLost;
                    break 'frames;
                }
                Event::DisplayRefreshRateChangedFB(e) => {
                    log::info!(
                        "OpenXR: display refresh rate {} → {} Hz",
                        e.from_display_refresh_rate(),
                        e.to_display_refresh_rate()
                    );
                    summary.display_hz = Some(e.to_display_refresh_rate());
                }
                Event::EventsLost(e) => log::warn!("OpenXR: {} events lost", e.lost_event_count()),
                _ => {}
            }
        }
        let stop = stop_requested();
        if !lifecycle.running {
            // Not running (IDLE before READY, or after STOPPING and xrEndSession):
            // xrRequestExitSession would fail (ERROR_SESSION_NOT_RUNNING), and on
            // Android a paused app's session stays in IDLE ("Session Lifecycle":
            // "the runtime will keep the session state at XR_SESSION_STATE_IDLE")
            // while onDestroy waits for this loop. A stop request leaves at once:
            // "xrDestroySession can be called when the session is in any session state".
            if stop {
                log::info!("OpenXR: stop requested while the session is not running: leaving");
                summary.end = EndReason::Stopped;
                break 'frames;
            }
            // IDLE/READY wait: poll without spinning (no frame loop yet or any more).
            std::thread::sleep(Duration::from_millis(5));
            continue;
        }
        if (stop || opts.frames.is_some_and(|n| summary.frames_rendered >= n)) && !exit_requested {
            session.request_exit().map_err(call("xrRequestExitSession"))?;
            exit_requested = true;
            // The state changes it causes arrive as events: handle them first.
            continue;
        }

        let wait_start = Instant::now();
        let state = match frame_waiter.wait() {
            Ok(s) => s,
            // Loss is reported by event too; the next poll ends the loop.
            Err(xr::sys::Result::ERROR_SESSION_LOST) => continue,
            Err(e) => return Err(call("xrWaitFrame")(e)),
        };
        let wait_s = wait_start.elapsed().as_secs_f64();
        let cpu_start = Instant::now();
        frame_stream.begin().map_err(call("xrBeginFrame"))?;
        // Input once per frame (spec 11.5: xrSyncActions updates every action's
        // state; an unfocused session gets XR_SESSION_NOT_FOCUSED and no presses).
        let mut pressed_now = Vec::new();
        let prev_space_from_scene = placement.space_from_scene;
        if let Some(c) = &controls {
            match c.poll(&session, &space, state.predicted_display_time) {
                Ok(input) => {
                    let was_holding = placement.holding();
                    // Steering speed per display period (the app's: twice the
                    // display's under space warp).
                    let dt_s = state.predicted_display_period.as_nanos() as f32 * 1e-9;
                    placement.update(input.grab_held, input.space_from_aim, input.stick, dt_s);
                    if placement.holding() != was_holding {
                        log::info!("input: object {}", if was_holding { "placed" } else { "grabbed" });
                    }
                    for t in input.pressed {
                        if t == Toggle::NextScene {
                            cycle.request_next();
                        }
                        if let (Toggle::Panel, Some(p)) = (t, status_panel.as_mut()) {
                            p.shown = !p.shown;
                        }
                        pressed_now.push(t);
                        toggles.apply(t);
                        summary.toggles.push((summary.frames_rendered, t));
                        log::info!("input: {t:?} → {:?}", toggles.enabled());
                    }
                }
                Err(e) => log::warn!("OpenXR: input sync failed ({e})"),
            }
        }
        let display_ns = state.predicted_display_time.as_nanos();
        let period_ns = state.predicted_display_period.as_nanos();
        let origin_ns = *time_origin_ns.get_or_insert(display_ns);
        let empty_frame = |stream: &mut xr::FrameStream<xr::Vulkan>| {
            stream.end(state.predicted_display_time, blend_mode, &[]).map_err(call("xrEndFrame"))
        };
        if !state.should_render || !lifecycle.visible() {
            empty_frame(&mut frame_stream)?;
            summary.frames_empty += 1;
            // Motion and missed slots are counted across rendered frames in a row.
            prev = None;
            last_display_ns = None;
            continue;
        }
        // Views first: a frame without usable views submits nothing else.
        let (view_flags, located) = session
            .locate_views(xr::ViewConfigurationType::PRIMARY_STEREO, state.predicted_display_time, &space)
            .map_err(call("xrLocateViews"))?;
        let tracked = match TrackedViews::new(view_flags, &located, (w, h)) {
            Ok(v) => {
                last_tracked = Some(v.clone());
                Some(v)
            }
            Err(why) => {
                if summary.frames_untracked == 0 || last_tracked.is_none() {
                    log::warn!("OpenXR: views not tracked ({why}): showing the last tracked views");
                }
                None
            }
        };
        let views_tracked = tracked.is_some();
        let Some(views) = tracked.or_else(|| last_tracked.clone()) else {
            // Nothing tracked yet: no projection layer (a frame may have none).
            empty_frame(&mut frame_stream)?;
            summary.frames_untracked += 1;
            summary.frames_empty += 1;
            continue;
        };
        if !views_tracked {
            summary.frames_untracked += 1;
        }
        // The clock mapping drifts slowly (the runtime's clock against CLOCK_MONOTONIC):
        // once a second is plenty; a failure is logged, never fatal. Taken on rendered
        // frames as they are woken, before their predicted display time.
        let clock = if enabled.khr_convert_timespec_time
            && last_clock_sample.map_or(true, |t: Instant| t.elapsed() >= Duration::from_secs(1))
        {
            last_clock_sample = Some(Instant::now());
            sample_clocks(&instance).map_err(|e| log::warn!("OpenXR: clock sample failed: {e}")).ok()
        } else {
            None
        };
        if env_depth.is_none() && env_depth_retry.is_some_and(|t| t.elapsed() >= ENV_DEPTH_RETRY) {
            (env_depth, env_depth_retry) = setup_env_depth(true);
            summary.env_depth |= env_depth.is_some();
        }
        // The headset's depth: acquired (spec: between xrBeginFrame and xrEndFrame, at
        // most once) and read back without waiting; a failure turns it off, logged.
        let depth = match env_depth.as_mut().map(|d| d.on_frame(&space, state.predicted_display_time)) {
            Some(Ok(d)) => d.map(Arc::new),
            Some(Err(e)) => {
                log::warn!("OpenXR: environment depth stops ({e}): calibration goes on without it");
                if let Some(d) = env_depth.take() {
                    summary.env_depth_reads += d.reads;
                }
                None
            }
            None => None,
        };
        // A scene the user asked for, loaded meanwhile on its own thread: the
        // renderer is rebuilt on it once the frames in flight are done (pipelines
        // and uploads: a hitch in this one frame, at the user's request). A scene
        // the GPU cannot take is named and the starting scene shown instead.
        if let Some(ready) = cycle.poll() {
            renderer.finish()?;
            let (index, next) = match ready {
                scenes::Ready::Start => (0, None),
                scenes::Ready::Loaded { index, path, scene } => {
                    log::info!("scene {index}: {}", path.display());
                    (index, Some(scene))
                }
            };
            match build_renderer(next.as_deref().unwrap_or(opts.scene)) {
                Ok(r) => {
                    renderer = r;
                    loaded = next;
                    summary.scene_changes.push((summary.frames_rendered, index));
                }
                Err(e) if index > 0 => {
                    log::warn!("scene {index} cannot be drawn ({e}): back to the starting scene");
                    cycle.errors.push(format!("scene {index}: {e}"));
                    renderer = build_renderer(opts.scene)?;
                    loaded = None;
                    cycle.reset();
                    summary.scene_changes.push((summary.frames_rendered, 0));
                }
                Err(e) => return Err(e.into()),
            }
        }
        let scene: &Scene = loaded.as_deref().unwrap_or(opts.scene);
        // One camera-model snapshot for the whole frame (hot-swap contract).
        let snapshot = opts.models.latest();
        let geometry = FrameGeometry::new(
            scene,
            (placement.space_from_scene, prev_space_from_scene),
            views.eyes,
            prev,
            display_ns,
            period_ns,
            origin_ns,
        );
        renderer.set_eye_pixels_per_radian(views.eyes[0].focal_px);
        renderer.set_render_interval_s(geometry.render_interval_s);
        let input = geometry.input();

        let index = swapchain.acquire_image().map_err(call("xrAcquireSwapchainImage"))?;
        swapchain.wait_image(xr::Duration::INFINITE).map_err(call("xrWaitSwapchainImage"))?;
        let target =
            ExternalTarget { image: images[index as usize], layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL };
        let warp_target = match space_warp.as_mut() {
            Some(sw) => Some(sw.acquire()?),
            None => None,
        };
        let enabled = toggles.enabled();
        let rendered = renderer.render_to(&snapshot, &input, enabled, Some(target), warp_target);
        // Release even after a failed render: no swapchain may stay acquired.
        swapchain.release_image().map_err(call("xrReleaseSwapchainImage"))?;
        if let Some(sw) = space_warp.as_mut() {
            sw.release()?;
        }
        let fx = rendered?;
        let applied = Enabled { noise: fx.noise, motion_blur: fx.motion_blur, dof: fx.dof };

        let now = Instant::now();
        if generation_seen.map_or(true, |(g, _)| g != snapshot.generation) {
            generation_seen = Some((snapshot.generation, now));
        }
        if let Some(p) = status_panel.as_mut() {
            let age_s = generation_seen.map(|(_, t)| now.saturating_duration_since(t).as_secs_f64());
            let lines = || panel::frame_lines(&cycle, toggles, opts.status, &snapshot, age_s);
            if let Err(e) = p.update(now, lines) {
                log::warn!("OpenXR: status panel off ({e})");
                summary.panel_redraws += p.redraws;
                status_panel = None;
            }
        }

        let submission = layers::Submission {
            space: &space,
            poses: views.poses,
            fovs: views.fovs,
            swapchain: swapchain.as_raw(),
            size: (w, h),
            space_warp: space_warp.as_ref(),
            passthrough_layer: passthrough.as_ref().map(|(_, layer)| layer.as_raw()),
            flags,
            quad: status_panel.as_ref().and_then(|p| p.layer()),
        };
        layers::end_frame(&mut frame_stream, state.predicted_display_time, blend_mode, &submission)
            .map_err(call("xrEndFrame"))?;

        let cpu_s = cpu_start.elapsed().as_secs_f64();
        if let Some(last) = last_display_ns {
            // A display slot skipped: this frame's predicted display time more than
            // 1.5 of the reported periods after the previous rendered frame's.
            if (display_ns - last) as f64 > 1.5 * period_ns as f64 {
                summary.missed_frames += 1;
            }
        }
        last_display_ns = Some(display_ns);
        let record = FrameRecord {
            index: summary.frames_rendered,
            predicted_display_time_ns: display_ns,
            predicted_display_period_ns: period_ns,
            time_origin_ns: origin_ns,
            model_generation: snapshot.generation,
            enabled,
            applied,
            pressed: pressed_now,
            scene: cycle.current(),
            local_from_scene: placement.space_from_scene,
            prev_local_from_scene: prev_space_from_scene,
            cpu_s,
            wait_s,
            views: views.views,
            views_tracked,
            clock,
            env_depth: depth,
            panel: status_panel.as_ref().and_then(|p| p.showing()),
        };
        if let Some(f) = opts.on_frame.as_mut() {
            f(&record);
        }
        summary.frames_rendered += 1;
        summary.cpu_s.push(cpu_s);
        summary.wait_s.push(wait_s);
        summary.periods_ns.push(period_ns);
        prev = Some((display_ns, views.eyes));
    }

    renderer.finish()?;
    summary.scene_errors = std::mem::take(&mut cycle.errors);
    summary.states = lifecycle.history.clone();
    summary.vulkan_messages = ctx.take_messages();
    // Explicit teardown in the documented order (the drops would do the same).
    drop(renderer);
    summary.panel_redraws += status_panel.as_ref().map_or(0, |p| p.redraws);
    drop(status_panel);
    if let Some(d) = env_depth.take() {
        summary.env_depth_reads += d.reads;
        if d.not_available > 0 {
            log::info!("OpenXR: environment depth not yet available on {} acquires", d.not_available);
        }
    }
    drop(env_depth);
    drop(passthrough);
    drop(space_warp);
    drop(swapchain);
    // The action set and the aim's action space: children of the instance and
    // session (the space holds the session alive: dropped later, the session
    // would outlive the Vulkan device it was created with).
    drop(controls);
    drop(space);
    drop(frame_stream);
    drop(frame_waiter);
    drop(session);
    drop(ctx);
    drop(instance);
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refresh_rate_nearest_offered() {
        assert_eq!(pick_refresh_rate(&[72.0, 90.0, 120.0], 90.0), Some(90.0));
        assert_eq!(pick_refresh_rate(&[72.0, 120.0], 90.0), Some(72.0));
        assert_eq!(pick_refresh_rate(&[f32::NAN, 60.0], 90.0), Some(60.0));
        assert_eq!(pick_refresh_rate(&[], 90.0), None);
    }
}
