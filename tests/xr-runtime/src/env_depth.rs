//! XR_META_environment_depth: a provider (created stopped, started and stopped by
//! the app, hand removal settable), its one swapchain of D16 image pairs on the
//! app's device, and acquires that write the depth of a known scene — the plane
//! `PLANE` in LOCAL space — as seen from each eye 30 ms before the display time
//! (the depth's own capture, as on a headset: its poses are not the display's).
//! Row 0 of each layer is the top of the view: the extension says the view "is
//! never flipped horizontally nor vertically", and under Vulkan an image's origin is
//! its top-left corner (XR_KHR_vulkan_enable2, "Swapchain Images"); the
//! projection has near plane `NEAR_M` and an infinite far plane (farZ = +∞); texels
//! that see no plane hold 1 (the far plane). Checked as the spec says: one acquire
//! per frame, inside xrBeginFrame/xrEndFrame, on a started provider. Every acquire
//! is reported (JSON line `env_depth`) with the views, so tests can hold the app's
//! decoded depth to the scene.

use crate::session::{eye_fov, head_pose, Pose};
use crate::{with_runtime, Runtime, SpaceKind};
use ash::vk;
use openxr_sys as xr;
use xr::Handle as _;

/// Quest 3's environment-depth size per eye.
pub(crate) const SIZE: (u32, u32) = (320, 320);
const IMAGES: u32 = 3;
pub(crate) const NEAR_M: f32 = 0.1;
/// How long before the display time the depth was captured.
const CAPTURE_LEAD_NS: i64 = 30_000_000;
/// The scene: a plane through `PLANE.0` with unit normal `PLANE.1` (LOCAL space),
/// tilted about both axes so depth varies along rows and columns.
pub(crate) const PLANE: ([f32; 3], [f32; 3]) = ([0.2, -0.1, -2.2], [0.2, 0.3, 0.932_737_9]);

pub(crate) struct Provider {
    pub handle: u64,
    pub started: bool,
    pub hand_removal: bool,
    pub swapchain: Option<DepthChain>,
    /// `Pacing::ended` when the last acquire happened (one per frame).
    pub acquired_in_frame: Option<u64>,
    /// Acquires after start; the first answers "not available yet", as a headset
    /// does while its depth pipeline spins up.
    pub acquires: u64,
}

pub(crate) struct DepthChain {
    pub handle: u64,
    pub images: Vec<(vk::Image, vk::DeviceMemory)>,
    next: u32,
}

/// The plane's depth along each texel's ray, NDC-encoded (row 0 at the top).
fn render(world_from_view: &Pose, fov: &xr::Fovf, texels: &mut Vec<u16>) {
    let (w, h) = SIZE;
    let (p0, n) = PLANE;
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let o = world_from_view.t;
    let (l, r, u, d) = (fov.angle_left.tan(), fov.angle_right.tan(), fov.angle_up.tan(), fov.angle_down.tan());
    let to_plane = dot([p0[0] - o[0], p0[1] - o[1], p0[2] - o[2]], n);
    for row in 0..h {
        let ty = u - (row as f32 + 0.5) * (u - d) / h as f32;
        for col in 0..w {
            let tx = l + (col as f32 + 0.5) * (r - l) / w as f32;
            // View ray (tx, ty, −1): its parameter at the plane is the view depth.
            let dir = world_from_view.rotate([tx, ty, -1.0]);
            let denom = dot(dir, n);
            let z = if denom.abs() > 1e-6 { to_plane / denom } else { -1.0 };
            let ndc = if z > NEAR_M { 1.0 - NEAR_M / z } else { 1.0 };
            texels.push((ndc.clamp(0.0, 1.0) * 65535.0).round() as u16);
        }
    }
}

fn with_provider(p: xr::EnvironmentDepthProviderMETA, f: impl FnOnce(&mut Runtime) -> xr::Result) -> xr::Result {
    with_runtime(|rt| match &rt.env_depth {
        Some(d) if d.handle == p.into_raw() => f(rt),
        _ => xr::Result::ERROR_HANDLE_INVALID,
    })
}

/// Destroy the provider's images (xrDestroyEnvironmentDepthSwapchainMETA, or the
/// session going away).
pub(crate) fn teardown(rt: &mut Runtime) {
    if let Some(chain) = rt.env_depth.as_mut().and_then(|d| d.swapchain.take()) {
        if let Some(vk) = rt.vk.as_ref() {
            vk.destroy_images(chain.images);
        }
    }
}

pub(crate) unsafe extern "system" fn create_provider(
    session: xr::Session,
    info: *const xr::EnvironmentDepthProviderCreateInfoMETA,
    out: *mut xr::EnvironmentDepthProviderMETA,
) -> xr::Result {
    with_runtime(|rt| {
        if rt.session.as_ref().map(|s| s.handle) != Some(session.into_raw()) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        // SAFETY: checked non-null before reading.
        if info.is_null() || out.is_null() || unsafe { (*info).ty } != xr::EnvironmentDepthProviderCreateInfoMETA::TYPE
        {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        if rt.config.env_depth_denials > rt.env_depth_refused {
            // The spatial-data permission not (yet) granted.
            rt.env_depth_refused += 1;
            rt.log(serde_json::json!({"event": "env_depth_refused"}));
            return xr::Result::ERROR_NOT_PERMITTED_PASSTHROUGH_FB;
        }
        if rt.env_depth.is_some() {
            return xr::Result::ERROR_LIMIT_REACHED;
        }
        let handle = rt.handle();
        rt.env_depth = Some(Provider {
            handle,
            started: false,
            hand_removal: false,
            swapchain: None,
            acquired_in_frame: None,
            acquires: 0,
        });
        // SAFETY: caller's output.
        unsafe { *out = xr::EnvironmentDepthProviderMETA::from_raw(handle) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_provider(p: xr::EnvironmentDepthProviderMETA) -> xr::Result {
    with_provider(p, |rt| {
        teardown(rt);
        rt.env_depth = None;
        xr::Result::SUCCESS
    })
}

fn set_started(p: xr::EnvironmentDepthProviderMETA, on: bool) -> xr::Result {
    with_provider(p, |rt| {
        let Some(d) = rt.env_depth.as_mut() else { return xr::Result::ERROR_HANDLE_INVALID };
        if d.started == on {
            return xr::Result::ERROR_UNEXPECTED_STATE_PASSTHROUGH_FB;
        }
        d.started = on;
        d.acquires = 0;
        rt.log(serde_json::json!({"event": "env_depth_provider", "started": on}));
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn start_provider(p: xr::EnvironmentDepthProviderMETA) -> xr::Result {
    set_started(p, true)
}

pub(crate) unsafe extern "system" fn stop_provider(p: xr::EnvironmentDepthProviderMETA) -> xr::Result {
    set_started(p, false)
}

pub(crate) unsafe extern "system" fn set_hand_removal(
    p: xr::EnvironmentDepthProviderMETA,
    info: *const xr::EnvironmentDepthHandRemovalSetInfoMETA,
) -> xr::Result {
    with_provider(p, |rt| {
        if info.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null caller struct.
        let on = unsafe { (*info).enabled } == xr::TRUE;
        if let Some(d) = rt.env_depth.as_mut() {
            d.hand_removal = on;
        }
        rt.log(serde_json::json!({"event": "env_depth_hand_removal", "enabled": on}));
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn create_swapchain(
    p: xr::EnvironmentDepthProviderMETA,
    info: *const xr::EnvironmentDepthSwapchainCreateInfoMETA,
    out: *mut xr::EnvironmentDepthSwapchainMETA,
) -> xr::Result {
    with_provider(p, |rt| {
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        if rt.env_depth.as_ref().is_some_and(|d| d.swapchain.is_some()) {
            return xr::Result::ERROR_LIMIT_REACHED;
        }
        let Some(vk) = rt.vk.as_ref() else { return xr::Result::ERROR_GRAPHICS_DEVICE_INVALID };
        let images = match vk.create_depth_images(IMAGES, SIZE.0, SIZE.1) {
            Ok(i) => i,
            Err(e) => {
                eprintln!("ba-xr-runtime: environment depth images: {e}");
                return xr::Result::ERROR_RUNTIME_FAILURE;
            }
        };
        let handle = rt.handle();
        if let Some(d) = rt.env_depth.as_mut() {
            d.swapchain = Some(DepthChain { handle, images, next: 0 });
        }
        // SAFETY: caller's output.
        unsafe { *out = xr::EnvironmentDepthSwapchainMETA::from_raw(handle) };
        xr::Result::SUCCESS
    })
}

fn with_chain(sc: xr::EnvironmentDepthSwapchainMETA, f: impl FnOnce(&mut Runtime) -> xr::Result) -> xr::Result {
    with_runtime(|rt| match rt.env_depth.as_ref().and_then(|d| d.swapchain.as_ref()) {
        Some(c) if c.handle == sc.into_raw() => f(rt),
        _ => xr::Result::ERROR_HANDLE_INVALID,
    })
}

pub(crate) unsafe extern "system" fn destroy_swapchain(sc: xr::EnvironmentDepthSwapchainMETA) -> xr::Result {
    with_chain(sc, |rt| {
        teardown(rt);
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn get_swapchain_state(
    sc: xr::EnvironmentDepthSwapchainMETA,
    state: *mut xr::EnvironmentDepthSwapchainStateMETA,
) -> xr::Result {
    with_chain(sc, |_| {
        // SAFETY: checked non-null before writing.
        if state.is_null() || unsafe { (*state).ty } != xr::EnvironmentDepthSwapchainStateMETA::TYPE {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null caller output.
        unsafe {
            (*state).width = SIZE.0;
            (*state).height = SIZE.1;
        }
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn enumerate_swapchain_images(
    sc: xr::EnvironmentDepthSwapchainMETA,
    capacity: u32,
    count: *mut u32,
    out: *mut xr::SwapchainImageBaseHeader,
) -> xr::Result {
    with_chain(sc, |rt| {
        let Some(chain) = rt.env_depth.as_ref().and_then(|d| d.swapchain.as_ref()) else {
            return xr::Result::ERROR_HANDLE_INVALID;
        };
        // SAFETY: the caller's two-call arguments.
        unsafe { crate::swapchain::enumerate_images(&chain.images, capacity, count, out) }
    })
}

pub(crate) unsafe extern "system" fn acquire_image(
    p: xr::EnvironmentDepthProviderMETA,
    info: *const xr::EnvironmentDepthImageAcquireInfoMETA,
    out: *mut xr::EnvironmentDepthImageMETA,
) -> xr::Result {
    with_provider(p, |rt| {
        // SAFETY: checked non-null before reading.
        if info.is_null() || out.is_null() || unsafe { (*out).ty } != xr::EnvironmentDepthImageMETA::TYPE {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null caller struct.
        let info = unsafe { &*info };
        let Some((in_frame, ended)) = rt.session.as_ref().map(|s| (s.frame.in_frame, s.frame.ended)) else {
            return xr::Result::ERROR_SESSION_LOST;
        };
        let Some(d) = rt.env_depth.as_mut() else { return xr::Result::ERROR_HANDLE_INVALID };
        // Spec: only between xrBeginFrame and xrEndFrame, at most once per frame.
        if !in_frame || d.acquired_in_frame == Some(ended) || !d.started || d.swapchain.is_none() {
            return xr::Result::ERROR_CALL_ORDER_INVALID;
        }
        d.acquired_in_frame = Some(ended);
        d.acquires += 1;
        if d.acquires == 1 {
            return xr::Result::ENVIRONMENT_DEPTH_NOT_AVAILABLE_META;
        }
        let Some(space) = rt.spaces.get(&info.space.into_raw()).copied() else {
            return xr::Result::ERROR_HANDLE_INVALID;
        };
        let t = info.display_time.as_nanos();
        if t <= 0 {
            return xr::Result::ERROR_TIME_INVALID;
        }
        let capture = t - CAPTURE_LEAD_NS;
        let local_from_head = head_pose(rt.config.head, capture);
        let local_from_space = match space.1 {
            SpaceKind::Local => Pose::from_xr(&space.2),
            _ => {
                // The app reads depth in LOCAL; other spaces are not modelled here.
                return xr::Result::ERROR_VALIDATION_FAILURE;
            }
        };
        let mut texels = Vec::with_capacity(2 * (SIZE.0 * SIZE.1) as usize);
        let mut views = vec![];
        // SAFETY: non-null caller output (checked above).
        let out = unsafe { &mut *out };
        for e in 0..2 {
            let local_from_view = local_from_head.mul(&crate::session::head_from_eye(e));
            let fov = eye_fov(e);
            render(&local_from_view, &fov, &mut texels);
            let pose = local_from_space.inverse().mul(&local_from_view);
            out.views[e].pose = pose.to_xr();
            out.views[e].fov = fov;
            views.push(serde_json::json!({"q": pose.q, "t": pose.t, "fov": [fov.angle_left, fov.angle_right, fov.angle_up, fov.angle_down]}));
        }
        let Some(d) = rt.env_depth.as_mut() else { return xr::Result::ERROR_HANDLE_INVALID };
        let Some(chain) = d.swapchain.as_mut() else { return xr::Result::ERROR_CALL_ORDER_INVALID };
        let index = chain.next;
        chain.next = (chain.next + 1) % chain.images.len() as u32;
        let image = chain.images[index as usize].0;
        let Some(vk) = rt.vk.as_ref() else { return xr::Result::ERROR_GRAPHICS_DEVICE_INVALID };
        if let Err(e) = vk.write_depth(image, SIZE.0, SIZE.1, &texels) {
            eprintln!("ba-xr-runtime: writing environment depth: {e}");
            return xr::Result::ERROR_RUNTIME_FAILURE;
        }
        out.swapchain_index = index;
        out.near_z = NEAR_M;
        out.far_z = f32::INFINITY;
        rt.log(serde_json::json!({
            "event": "env_depth",
            "frame": ended,
            "display_time": t,
            "index": index,
            "near": NEAR_M,
            "plane": {"point": PLANE.0, "normal": PLANE.1},
            "views": views,
        }));
        xr::Result::SUCCESS
    })
}
