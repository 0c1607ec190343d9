//! Session lifecycle (OpenXR spec 9.3, "Session Lifecycle"), the event queue,
//! reference spaces and views from the scripted head path, XR_FB_passthrough and
//! XR_FB_display_refresh_rate.

use crate::config::{Command, Head};
use crate::{lock, two_call, vulkan, with_instance, with_runtime, Event, Runtime, SpaceKind};
use openxr_sys as xr;
use std::f32::consts::PI;
use xr::Handle as _;

pub(crate) struct Session {
    pub handle: u64,
    pub state: xr::SessionState,
    /// Between xrBeginSession and xrEndSession.
    pub running: bool,
    pub exit_requested: bool,
    /// Paused by the script: after xrEndSession the session stays IDLE.
    pub paused: bool,
    /// Views are not located until this many frames have ended (`untracked@N..M`).
    pub untracked_until: Option<u64>,
    pub lost: bool,
    pub display_hz: f32,
    pub blend_mode: Option<xr::EnvironmentBlendMode>,
    /// Frame pacing (frame.rs).
    pub frame: crate::frame::Pacing,
}

impl Runtime {
    /// Change the session state and queue the event (spec: every transition is
    /// reported through XrEventDataSessionStateChanged, in order).
    pub(crate) fn set_state(&mut self, state: xr::SessionState) {
        let time = self.now_ns();
        let Some(s) = self.session.as_mut() else { return };
        if s.state == state {
            return;
        }
        s.state = state;
        let handle = s.handle;
        self.events.push_back(Event::State { session: handle, state, time });
        self.log(serde_json::json!({"event": "state", "state": format!("{state:?}")}));
    }

    fn state(&self) -> Option<xr::SessionState> {
        self.session.as_ref().map(|s| s.state)
    }

    /// Walk a running session down to STOPPING (spec 9.3: FOCUSED → VISIBLE →
    /// SYNCHRONIZED → STOPPING when the session should end).
    pub(crate) fn stop(&mut self) {
        use xr::SessionState as S;
        if self.state() == Some(S::FOCUSED) {
            self.set_state(S::VISIBLE);
        }
        if self.state() == Some(S::VISIBLE) {
            self.set_state(S::SYNCHRONIZED);
        }
        if matches!(self.state(), Some(S::SYNCHRONIZED) | Some(S::READY))
            && self.session.as_ref().is_some_and(|s| s.running)
        {
            self.set_state(S::STOPPING);
        }
    }

    /// Scripted commands due at `frame` (the count of xrEndFrame calls so far).
    pub(crate) fn run_script(&mut self, frame: u64) {
        let due: Vec<Command> = self.config.script.iter().filter(|(at, _)| *at == frame).map(|(_, c)| *c).collect();
        for cmd in due {
            self.log(serde_json::json!({"event": "script", "command": format!("{cmd:?}"), "frame": frame}));
            match cmd {
                Command::Exit => {
                    if let Some(s) = self.session.as_mut() {
                        s.exit_requested = true;
                    }
                    self.stop();
                }
                Command::Loss => {
                    if let Some(s) = self.session.as_mut() {
                        s.lost = true;
                    }
                    self.set_state(xr::SessionState::LOSS_PENDING);
                }
                Command::InstanceLoss => {
                    let time = self.now_ns();
                    self.events.push_back(Event::InstanceLoss { time });
                }
                Command::Unfocus => {
                    if self.state() == Some(xr::SessionState::FOCUSED) {
                        self.set_state(xr::SessionState::VISIBLE);
                    }
                }
                Command::Focus => {
                    if self.state() == Some(xr::SessionState::VISIBLE) {
                        self.set_state(xr::SessionState::FOCUSED);
                    }
                }
                Command::Pause => {
                    if let Some(s) = self.session.as_mut() {
                        s.paused = true;
                    }
                    self.stop();
                }
                Command::Untracked(until) => {
                    if let Some(s) = self.session.as_mut() {
                        s.untracked_until = Some(until);
                    }
                }
            }
        }
    }
}

/// Destroy the session's children and Vulkan state (xrDestroySession, or the
/// instance going away with a session still alive).
pub(crate) fn teardown_session(rt: &mut Runtime) {
    crate::env_depth::teardown(rt);
    rt.env_depth = None;
    let chains: Vec<u64> = rt.swapchains.keys().copied().collect();
    for h in chains {
        if let (Some(sc), Some(vk)) = (rt.swapchains.remove(&h), rt.vk.as_ref()) {
            vk.destroy_swapchain(sc);
        }
    }
    rt.spaces.clear();
    rt.passthroughs.clear();
    rt.passthrough_layers.clear();
    // Attachment is per session (spec 11.4); the sets and actions outlive it.
    rt.input.end_session();
    if let Some(vk) = rt.vk.take() {
        vk.destroy();
    }
    rt.session = None;
}

/// Run `f` on the session `session` names.
fn with_session(session: xr::Session, f: impl FnOnce(&mut Runtime) -> xr::Result) -> xr::Result {
    with_runtime(|rt| match &rt.session {
        Some(s) if s.handle == session.into_raw() => f(rt),
        _ => xr::Result::ERROR_HANDLE_INVALID,
    })
}

pub(crate) unsafe extern "system" fn create_session(
    instance: xr::Instance,
    info: *const xr::SessionCreateInfo,
    out: *mut xr::Session,
) -> xr::Result {
    with_instance(instance, |rt| {
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        if rt.session.is_some() {
            return xr::Result::ERROR_LIMIT_REACHED;
        }
        // SAFETY: non-null create info of the caller.
        let info = unsafe { &*info };
        if info.system_id.into_raw() != crate::SYSTEM_ID {
            return xr::Result::ERROR_SYSTEM_INVALID;
        }
        // The graphics binding (XR_KHR_vulkan_enable2) must be chained (spec 10.1).
        let mut binding: Option<xr::GraphicsBindingVulkanKHR> = None;
        let mut next = info.next;
        while !next.is_null() {
            // SAFETY: every chained struct begins with a BaseInStructure header.
            let base = unsafe { &*(next as *const xr::BaseInStructure) };
            if base.ty == xr::StructureType::GRAPHICS_BINDING_VULKAN_KHR {
                // SAFETY: the type tag says what the struct is.
                binding = Some(unsafe { *(next as *const xr::GraphicsBindingVulkanKHR) });
            }
            next = base.next as *const _;
        }
        let Some(binding) = binding else { return xr::Result::ERROR_GRAPHICS_DEVICE_INVALID };
        let vk = match vulkan::VkState::new(&binding) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("ba-xr-runtime: {e}");
                return xr::Result::ERROR_GRAPHICS_DEVICE_INVALID;
            }
        };
        rt.vk = Some(vk);
        let handle = rt.handle();
        let display_hz = rt.config.display_hz;
        rt.session = Some(Session {
            handle,
            state: xr::SessionState::UNKNOWN,
            running: false,
            exit_requested: false,
            paused: false,
            untracked_until: None,
            lost: false,
            display_hz,
            blend_mode: None,
            frame: crate::frame::Pacing::default(),
        });
        rt.log(serde_json::json!({"event": "session_created"}));
        rt.set_state(xr::SessionState::IDLE);
        rt.set_state(xr::SessionState::READY);
        // SAFETY: caller's output.
        unsafe { *out = xr::Session::from_raw(handle) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_session(session: xr::Session) -> xr::Result {
    // Allowed after instance loss too (the app must clean up), so not with_runtime.
    let mut guard = lock();
    let Some(rt) = guard.as_mut() else { return xr::Result::ERROR_HANDLE_INVALID };
    if rt.session.as_ref().map(|s| s.handle) != Some(session.into_raw()) {
        return xr::Result::ERROR_HANDLE_INVALID;
    }
    teardown_session(rt);
    rt.log(serde_json::json!({"event": "session_destroyed"}));
    xr::Result::SUCCESS
}

pub(crate) unsafe extern "system" fn begin_session(
    session: xr::Session,
    info: *const xr::SessionBeginInfo,
) -> xr::Result {
    with_session(session, |rt| {
        let s = rt.session.as_mut().expect("checked by with_session");
        if s.lost {
            return xr::Result::ERROR_SESSION_LOST;
        }
        if s.running {
            return xr::Result::ERROR_SESSION_RUNNING;
        }
        if s.state != xr::SessionState::READY {
            return xr::Result::ERROR_SESSION_NOT_READY;
        }
        // SAFETY: non-null begin info (the validation layer checks; we read one enum).
        if info.is_null()
            || unsafe { (*info).primary_view_configuration_type } != xr::ViewConfigurationType::PRIMARY_STEREO
        {
            return xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
        }
        s.running = true;
        rt.log(serde_json::json!({"event": "begin_session"}));
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn end_session(session: xr::Session) -> xr::Result {
    with_session(session, |rt| {
        let s = rt.session.as_mut().expect("checked by with_session");
        if s.lost {
            return xr::Result::ERROR_SESSION_LOST;
        }
        if !s.running {
            return xr::Result::ERROR_SESSION_NOT_RUNNING;
        }
        if s.state != xr::SessionState::STOPPING {
            return xr::Result::ERROR_SESSION_NOT_STOPPING;
        }
        s.running = false;
        let (exiting, paused) = (s.exit_requested, s.paused);
        rt.log(serde_json::json!({"event": "end_session"}));
        rt.set_state(xr::SessionState::IDLE);
        if exiting {
            rt.set_state(xr::SessionState::EXITING);
        } else if paused {
            // In the background: IDLE until resumed, which the script never does.
        } else {
            rt.set_state(xr::SessionState::READY);
        }
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn request_exit_session(session: xr::Session) -> xr::Result {
    with_session(session, |rt| {
        let s = rt.session.as_mut().expect("checked by with_session");
        if s.lost {
            return xr::Result::ERROR_SESSION_LOST;
        }
        if !s.running {
            return xr::Result::ERROR_SESSION_NOT_RUNNING;
        }
        s.exit_requested = true;
        rt.log(serde_json::json!({"event": "request_exit"}));
        rt.stop();
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn poll_event(instance: xr::Instance, out: *mut xr::EventDataBuffer) -> xr::Result {
    // Events (instance loss among them) are delivered even after instance loss.
    let mut guard = lock();
    let Some(rt) = guard.as_mut().filter(|rt| rt.instance == instance.into_raw()) else {
        return xr::Result::ERROR_HANDLE_INVALID;
    };
    if out.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let Some(event) = rt.events.pop_front() else { return xr::Result::EVENT_UNAVAILABLE };
    // SAFETY: XrEventDataBuffer is large enough for every event struct (spec 2.20),
    // and each written struct starts at the buffer's start.
    unsafe {
        match event {
            Event::State { session, state, time } => {
                *(out as *mut xr::EventDataSessionStateChanged) = xr::EventDataSessionStateChanged {
                    ty: xr::EventDataSessionStateChanged::TYPE,
                    next: std::ptr::null(),
                    session: xr::Session::from_raw(session),
                    state,
                    time: xr::Time::from_nanos(time),
                }
            }
            Event::InstanceLoss { time } => {
                rt.instance_lost = true;
                *(out as *mut xr::EventDataInstanceLossPending) = xr::EventDataInstanceLossPending {
                    ty: xr::EventDataInstanceLossPending::TYPE,
                    next: std::ptr::null(),
                    loss_time: xr::Time::from_nanos(time),
                }
            }
            Event::ProfileChanged { session } => {
                *(out as *mut xr::EventDataInteractionProfileChanged) = xr::EventDataInteractionProfileChanged {
                    ty: xr::EventDataInteractionProfileChanged::TYPE,
                    next: std::ptr::null(),
                    session: xr::Session::from_raw(session),
                }
            }
            Event::RefreshRate { from, to } => {
                *(out as *mut xr::EventDataDisplayRefreshRateChangedFB) = xr::EventDataDisplayRefreshRateChangedFB {
                    ty: xr::EventDataDisplayRefreshRateChangedFB::TYPE,
                    next: std::ptr::null(),
                    from_display_refresh_rate: from,
                    to_display_refresh_rate: to,
                }
            }
        }
    }
    xr::Result::SUCCESS
}

pub(crate) unsafe extern "system" fn enumerate_reference_spaces(
    session: xr::Session,
    capacity: u32,
    count: *mut u32,
    out: *mut xr::ReferenceSpaceType,
) -> xr::Result {
    with_session(session, |_| {
        let types = [xr::ReferenceSpaceType::VIEW, xr::ReferenceSpaceType::LOCAL, xr::ReferenceSpaceType::STAGE];
        // SAFETY: the caller's two-call arguments.
        unsafe { two_call(&types, capacity, count, out) }
    })
}

pub(crate) unsafe extern "system" fn create_reference_space(
    session: xr::Session,
    info: *const xr::ReferenceSpaceCreateInfo,
    out: *mut xr::Space,
) -> xr::Result {
    with_session(session, |rt| {
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null create info.
        let info = unsafe { &*info };
        let kind = match info.reference_space_type {
            xr::ReferenceSpaceType::VIEW => SpaceKind::View,
            xr::ReferenceSpaceType::LOCAL => SpaceKind::Local,
            xr::ReferenceSpaceType::STAGE => SpaceKind::Stage,
            _ => return xr::Result::ERROR_REFERENCE_SPACE_UNSUPPORTED,
        };
        let q = info.pose_in_reference_space.orientation;
        let n = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
        if !n.is_finite() || (n - 1.0).abs() > 1e-3 {
            return xr::Result::ERROR_POSE_INVALID;
        }
        let h = rt.handle();
        let session = rt.session.as_ref().map_or(0, |s| s.handle);
        rt.spaces.insert(h, (session, kind, info.pose_in_reference_space));
        // SAFETY: caller's output.
        unsafe { *out = xr::Space::from_raw(h) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn get_reference_space_bounds_rect(
    session: xr::Session,
    kind: xr::ReferenceSpaceType,
    bounds: *mut xr::Extent2Df,
) -> xr::Result {
    with_session(session, |_| {
        if kind != xr::ReferenceSpaceType::STAGE {
            return xr::Result::ERROR_REFERENCE_SPACE_UNSUPPORTED;
        }
        // SAFETY: caller's output. A 3 m × 3 m play area, as a guardian boundary.
        unsafe { *bounds = xr::Extent2Df { width: 3.0, height: 3.0 } };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_space(space: xr::Space) -> xr::Result {
    with_runtime(|rt| {
        if rt.spaces.remove(&space.into_raw()).is_some() || rt.action_spaces.remove(&space.into_raw()).is_some() {
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        }
    })
}

// ---- poses -----------------------------------------------------------------

/// A rigid transform as (rotation quaternion x, y, z, w; translation).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pose {
    pub q: [f32; 4],
    pub t: [f32; 3],
}

impl Pose {
    pub const IDENTITY: Pose = Pose { q: [0.0, 0.0, 0.0, 1.0], t: [0.0; 3] };

    pub fn from_xr(p: &xr::Posef) -> Self {
        Pose {
            q: [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w],
            t: [p.position.x, p.position.y, p.position.z],
        }
    }

    pub fn to_xr(self) -> xr::Posef {
        xr::Posef {
            orientation: xr::Quaternionf { x: self.q[0], y: self.q[1], z: self.q[2], w: self.q[3] },
            position: xr::Vector3f { x: self.t[0], y: self.t[1], z: self.t[2] },
        }
    }

    pub(crate) fn rotate(&self, v: [f32; 3]) -> [f32; 3] {
        let [x, y, z, w] = self.q;
        let u = [x, y, z];
        let cross = |a: [f32; 3], b: [f32; 3]| {
            [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        };
        let uv = cross(u, v);
        let uuv = cross(u, uv);
        [v[0] + 2.0 * (w * uv[0] + uuv[0]), v[1] + 2.0 * (w * uv[1] + uuv[1]), v[2] + 2.0 * (w * uv[2] + uuv[2])]
    }

    /// `self ∘ other` (apply `other` first).
    pub fn mul(&self, o: &Pose) -> Pose {
        let [x1, y1, z1, w1] = self.q;
        let [x2, y2, z2, w2] = o.q;
        let q = [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ];
        let r = self.rotate(o.t);
        Pose { q, t: [r[0] + self.t[0], r[1] + self.t[1], r[2] + self.t[2]] }
    }

    pub fn inverse(&self) -> Pose {
        let inv = Pose { q: [-self.q[0], -self.q[1], -self.q[2], self.q[3]], t: [0.0; 3] };
        let t = inv.rotate(self.t);
        Pose { q: inv.q, t: [-t[0], -t[1], -t[2]] }
    }
}

/// Stage floor to LOCAL: LOCAL's origin is the head at start, 1.6 m above the floor.
const EYE_HEIGHT_M: f32 = 1.6;
/// Quest 3's default inter-pupillary distance.
pub(crate) const IPD_M: f32 = 0.063;

/// Eye `e` (0 left, 1 right) in the head's frame: half the IPD to each side.
pub(crate) fn head_from_eye(e: usize) -> Pose {
    Pose { q: Pose::IDENTITY.q, t: [if e == 0 { -IPD_M / 2.0 } else { IPD_M / 2.0 }, 0.0, 0.0] }
}

/// `local_from_head` at `time_ns` on the scripted path.
pub(crate) fn head_pose(head: Head, time_ns: i64) -> Pose {
    match head {
        Head::Still => Pose::IDENTITY,
        Head::Sway => {
            // ±4 cm side to side at 0.5 Hz and ±3° of yaw a quarter period later:
            // the kind of motion a user makes looking around a room.
            let t = time_ns as f64 * 1e-9;
            let phase = (2.0 * std::f64::consts::PI * 0.5 * t) as f32;
            let yaw = 3.0f32.to_radians() * (phase + PI / 2.0).sin();
            Pose { q: [0.0, (yaw / 2.0).sin(), 0.0, (yaw / 2.0).cos()], t: [0.04 * phase.sin(), 0.0, 0.0] }
        }
    }
}

/// `local_from_space` of a space at `time_ns`.
pub(crate) fn local_from_space(rt: &Runtime, kind: SpaceKind, offset: &xr::Posef, time_ns: i64) -> Pose {
    let base = match kind {
        SpaceKind::View => head_pose(rt.config.head, time_ns),
        SpaceKind::Local => Pose::IDENTITY,
        SpaceKind::Stage => Pose { q: Pose::IDENTITY.q, t: [0.0, -EYE_HEIGHT_M, 0.0] },
    };
    base.mul(&Pose::from_xr(offset))
}

pub(crate) unsafe extern "system" fn locate_space(
    space: xr::Space,
    base: xr::Space,
    time: xr::Time,
    location: *mut xr::SpaceLocation,
) -> xr::Result {
    with_runtime(|rt| {
        if location.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        if rt.action_spaces.contains_key(&base.into_raw()) {
            // Controllers located relative to a controller: not needed by the app.
            // SAFETY: caller's output, checked non-null.
            unsafe { (*location).location_flags = xr::SpaceLocationFlags::EMPTY };
            return xr::Result::SUCCESS;
        }
        let Some(b) = rt.spaces.get(&base.into_raw()) else { return xr::Result::ERROR_HANDLE_INVALID };
        if time.as_nanos() <= 0 {
            return xr::Result::ERROR_TIME_INVALID;
        }
        let local_from_b = local_from_space(rt, b.1, &b.2, time.as_nanos());
        let b_from_a = if rt.action_spaces.contains_key(&space.into_raw()) {
            // Located only while its action is active and the device tracked.
            crate::input::locate_action_space(rt, space.into_raw(), &local_from_b)
        } else {
            let Some(a) = rt.spaces.get(&space.into_raw()) else { return xr::Result::ERROR_HANDLE_INVALID };
            Some(local_from_b.inverse().mul(&local_from_space(rt, a.1, &a.2, time.as_nanos())))
        };
        let Some(b_from_a) = b_from_a else {
            // SAFETY: caller's output, checked non-null.
            unsafe { (*location).location_flags = xr::SpaceLocationFlags::EMPTY };
            return xr::Result::SUCCESS;
        };
        // SAFETY: caller's output, checked non-null.
        unsafe {
            (*location).location_flags = xr::SpaceLocationFlags::ORIENTATION_VALID
                | xr::SpaceLocationFlags::POSITION_VALID
                | xr::SpaceLocationFlags::ORIENTATION_TRACKED
                | xr::SpaceLocationFlags::POSITION_TRACKED;
            (*location).pose = b_from_a.to_xr();
        }
        xr::Result::SUCCESS
    })
}

/// Per-eye field of view, Quest 3-like (canted outward: wider towards the temple).
pub(crate) fn eye_fov(eye: usize) -> xr::Fovf {
    let (inner, outer) = (0.70f32, 0.94f32);
    let (angle_left, angle_right) = if eye == 0 { (-outer, inner) } else { (-inner, outer) };
    xr::Fovf { angle_left, angle_right, angle_up: 0.77, angle_down: -0.87 }
}

pub(crate) unsafe extern "system" fn locate_views(
    session: xr::Session,
    info: *const xr::ViewLocateInfo,
    state: *mut xr::ViewState,
    capacity: u32,
    count: *mut u32,
    views: *mut xr::View,
) -> xr::Result {
    with_session(session, |rt| {
        if rt.session.as_ref().is_some_and(|s| s.lost) {
            return xr::Result::ERROR_SESSION_LOST;
        }
        if info.is_null() || state.is_null() || count.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null caller structs.
        let info = unsafe { &*info };
        if info.view_configuration_type != xr::ViewConfigurationType::PRIMARY_STEREO {
            return xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
        }
        if info.display_time.as_nanos() <= 0 {
            return xr::Result::ERROR_TIME_INVALID;
        }
        let Some(space) = rt.spaces.get(&info.space.into_raw()).copied() else {
            return xr::Result::ERROR_HANDLE_INVALID;
        };
        // SAFETY: non-null count.
        unsafe { *count = 2 };
        if capacity == 0 {
            return xr::Result::SUCCESS;
        }
        if capacity < 2 {
            return xr::Result::ERROR_SIZE_INSUFFICIENT;
        }
        let untracked = rt.session.as_ref().is_some_and(|s| s.untracked_until.is_some_and(|u| s.frame.ended < u));
        if untracked {
            // Tracking lost: no valid bits, and values an app must not read (spec
            // "View and Projection State"): zeroed on even frames, as a runtime may
            // leave them; on odd frames a plausible but wrong pose (turned 90°, 10 m
            // away), which only an app that reads them anyway would draw.
            let odd = rt.session.as_ref().is_some_and(|s| s.frame.ended % 2 == 1);
            let h = std::f32::consts::FRAC_1_SQRT_2;
            let (orientation, position) = if odd {
                (xr::Quaternionf { x: 0.0, y: h, z: 0.0, w: h }, xr::Vector3f { x: 10.0, y: 0.0, z: 0.0 })
            } else {
                (xr::Quaternionf { x: 0.0, y: 0.0, z: 0.0, w: 0.0 }, xr::Vector3f { x: 0.0, y: 0.0, z: 0.0 })
            };
            for e in 0..2 {
                // SAFETY: two views at `views` (capacity ≥ 2).
                unsafe {
                    (*views.add(e)).pose = xr::Posef { orientation, position };
                    (*views.add(e)).fov = eye_fov(e);
                }
            }
            // SAFETY: caller's output.
            unsafe { (*state).view_state_flags = xr::ViewStateFlags::EMPTY };
            return xr::Result::SUCCESS;
        }
        let t = info.display_time.as_nanos();
        let local_from_head = head_pose(rt.config.head, t);
        let local_from_space = local_from_space(rt, space.1, &space.2, t);
        let space_from_head = local_from_space.inverse().mul(&local_from_head);
        for e in 0..2 {
            let head_from_eye = head_from_eye(e);
            // SAFETY: two views at `views` (capacity ≥ 2); `ty`/`next` are the caller's.
            unsafe {
                (*views.add(e)).pose = space_from_head.mul(&head_from_eye).to_xr();
                (*views.add(e)).fov = eye_fov(e);
            }
        }
        // SAFETY: caller's output.
        unsafe {
            (*state).view_state_flags = xr::ViewStateFlags::ORIENTATION_VALID
                | xr::ViewStateFlags::POSITION_VALID
                | xr::ViewStateFlags::ORIENTATION_TRACKED
                | xr::ViewStateFlags::POSITION_TRACKED;
        }
        xr::Result::SUCCESS
    })
}

// ---- XR_FB_passthrough -----------------------------------------------------

pub(crate) unsafe extern "system" fn create_passthrough(
    session: xr::Session,
    info: *const xr::PassthroughCreateInfoFB,
    out: *mut xr::PassthroughFB,
) -> xr::Result {
    with_session(session, |rt| {
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null create info.
        let running = unsafe { (*info).flags }.contains(xr::PassthroughFlagsFB::IS_RUNNING_AT_CREATION);
        let h = rt.handle();
        rt.passthroughs.insert(h, running);
        rt.log(serde_json::json!({"event": "passthrough_created", "running": running}));
        // SAFETY: caller's output.
        unsafe { *out = xr::PassthroughFB::from_raw(h) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_passthrough(p: xr::PassthroughFB) -> xr::Result {
    with_runtime(|rt| match rt.passthroughs.remove(&p.into_raw()) {
        Some(_) => xr::Result::SUCCESS,
        None => xr::Result::ERROR_HANDLE_INVALID,
    })
}

fn set_passthrough(p: xr::PassthroughFB, running: bool) -> xr::Result {
    with_runtime(|rt| match rt.passthroughs.get_mut(&p.into_raw()) {
        Some(r) => {
            *r = running;
            rt.log(serde_json::json!({"event": "passthrough_running", "running": running}));
            xr::Result::SUCCESS
        }
        None => xr::Result::ERROR_HANDLE_INVALID,
    })
}

pub(crate) unsafe extern "system" fn passthrough_start(p: xr::PassthroughFB) -> xr::Result {
    set_passthrough(p, true)
}

pub(crate) unsafe extern "system" fn passthrough_pause(p: xr::PassthroughFB) -> xr::Result {
    set_passthrough(p, false)
}

pub(crate) unsafe extern "system" fn create_passthrough_layer(
    session: xr::Session,
    info: *const xr::PassthroughLayerCreateInfoFB,
    out: *mut xr::PassthroughLayerFB,
) -> xr::Result {
    with_session(session, |rt| {
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null create info.
        let info = unsafe { &*info };
        if !rt.passthroughs.contains_key(&info.passthrough.into_raw()) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        let running = info.flags.contains(xr::PassthroughFlagsFB::IS_RUNNING_AT_CREATION);
        let h = rt.handle();
        rt.passthrough_layers.insert(h, (info.passthrough.into_raw(), running));
        // SAFETY: caller's output.
        unsafe { *out = xr::PassthroughLayerFB::from_raw(h) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_passthrough_layer(l: xr::PassthroughLayerFB) -> xr::Result {
    with_runtime(|rt| match rt.passthrough_layers.remove(&l.into_raw()) {
        Some(_) => xr::Result::SUCCESS,
        None => xr::Result::ERROR_HANDLE_INVALID,
    })
}

fn set_layer(l: xr::PassthroughLayerFB, running: bool) -> xr::Result {
    with_runtime(|rt| match rt.passthrough_layers.get_mut(&l.into_raw()) {
        Some(r) => {
            r.1 = running;
            xr::Result::SUCCESS
        }
        None => xr::Result::ERROR_HANDLE_INVALID,
    })
}

pub(crate) unsafe extern "system" fn passthrough_layer_pause(l: xr::PassthroughLayerFB) -> xr::Result {
    set_layer(l, false)
}

pub(crate) unsafe extern "system" fn passthrough_layer_resume(l: xr::PassthroughLayerFB) -> xr::Result {
    set_layer(l, true)
}

pub(crate) unsafe extern "system" fn passthrough_layer_set_style(
    l: xr::PassthroughLayerFB,
    _style: *const xr::PassthroughStyleFB,
) -> xr::Result {
    with_runtime(|rt| {
        if rt.passthrough_layers.contains_key(&l.into_raw()) {
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        }
    })
}

/// Projected-surface passthrough (geometry instances) is not offered: the app uses
/// reconstruction passthrough only.
pub(crate) unsafe extern "system" fn create_geometry_instance(
    _s: xr::Session,
    _i: *const xr::GeometryInstanceCreateInfoFB,
    _o: *mut xr::GeometryInstanceFB,
) -> xr::Result {
    xr::Result::ERROR_FEATURE_UNSUPPORTED
}

pub(crate) unsafe extern "system" fn destroy_geometry_instance(_g: xr::GeometryInstanceFB) -> xr::Result {
    xr::Result::ERROR_HANDLE_INVALID
}

pub(crate) unsafe extern "system" fn geometry_instance_set_transform(
    _g: xr::GeometryInstanceFB,
    _t: *const xr::GeometryInstanceTransformFB,
) -> xr::Result {
    xr::Result::ERROR_HANDLE_INVALID
}

// ---- XR_FB_display_refresh_rate ---------------------------------------------

pub(crate) unsafe extern "system" fn enumerate_display_refresh_rates(
    session: xr::Session,
    capacity: u32,
    count: *mut u32,
    out: *mut f32,
) -> xr::Result {
    with_session(session, |rt| {
        let rates = rt.config.refresh_rates.clone();
        // SAFETY: the caller's two-call arguments.
        unsafe { two_call(&rates, capacity, count, out) }
    })
}

pub(crate) unsafe extern "system" fn get_display_refresh_rate(session: xr::Session, out: *mut f32) -> xr::Result {
    with_session(session, |rt| {
        // SAFETY: caller's output.
        unsafe { *out = rt.session.as_ref().map_or(0.0, |s| s.display_hz) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn request_display_refresh_rate(session: xr::Session, hz: f32) -> xr::Result {
    with_session(session, |rt| {
        // 0 lets the runtime choose (spec, XR_FB_display_refresh_rate).
        let to = if hz == 0.0 { rt.config.display_hz } else { hz };
        if !rt.config.refresh_rates.contains(&to) {
            return xr::Result::ERROR_DISPLAY_REFRESH_RATE_UNSUPPORTED_FB;
        }
        let s = rt.session.as_mut().expect("checked by with_session");
        let from = s.display_hz;
        if from != to {
            s.display_hz = to;
            rt.events.push_back(Event::RefreshRate { from, to });
            rt.log(serde_json::json!({"event": "refresh_rate", "from": from, "to": to}));
        }
        xr::Result::SUCCESS
    })
}
