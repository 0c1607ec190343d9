//! The input system (OpenXR 1.0 spec chapter 11, "Input and Haptics") of a
//! headset with one pair of controllers: action sets and actions are kept with
//! their names and types, suggested bindings are checked against the interaction
//! profile's component paths (spec 6.4, "Interaction Profile Paths": Oculus Touch
//! and the Khronos simple controller; Meta Touch Plus with XR_META_touch_controller_plus
//! enabled), and after xrAttachSessionActionSets the
//! runtime picks the profile its controllers match among those the app suggested
//! (Touch first, then the simple controller, as a runtime may remap) and queues
//! XrEventDataInteractionProfileChanged at the first sync of the running session.
//! Buttons are pressed by the script (`press:PATH@N`: true in the xrSyncActions
//! calls made while frame N is being produced, false otherwise; `@N..M` held), so boolean actions report `currentState`,
//! `changedSinceLastSync` and `lastChangeTime` as the spec defines them; an
//! unfocused session syncs nothing (XR_SESSION_NOT_FOCUSED, every action
//! inactive). Pose actions are active where bound and focused, and their action
//! spaces are located at the scripted right controller pose (`aim:…@N`; not
//! tracked before the first); the right thumbstick's vector action reads the
//! scripted deflection (`stick:X;Y@N..M`); float actions stay inactive. Every core function must
//! resolve through xrGetInstanceProcAddr (spec 3.2).

use crate::{two_call, with_instance, with_runtime};
use openxr_sys as xr;
use std::collections::HashMap;
use std::ffi::c_char;
use xr::Handle as _;

pub(crate) const TOUCH: &str = "/interaction_profiles/oculus/touch_controller";
pub(crate) const SIMPLE: &str = "/interaction_profiles/khr/simple_controller";
/// XR_META_touch_controller_plus: valid only while that extension is enabled
/// (the extension's "New Interaction Profile Paths"; OpenXR 1.1 made it core).
pub(crate) const TOUCH_PLUS: &str = "/interaction_profiles/meta/touch_controller_plus";

/// Component paths (after `/user/hand/{left,right}/`) of each profile, spec 6.4.
/// An identifier without its component (`input/a`, `input/trigger`) is accepted
/// too: the spec lets the runtime pick the component ("Binding to an input
/// source without a component").
fn supports(profile: &str, binding: &str) -> bool {
    let (hand, component) = match (binding.strip_prefix("/user/hand/left/"), binding.strip_prefix("/user/hand/right/"))
    {
        (Some(c), _) => ("left", c),
        (_, Some(c)) => ("right", c),
        _ => return false,
    };
    let mut known: Vec<&str> = Vec::new();
    match profile {
        SIMPLE => known.extend([
            "input/select/click",
            "input/menu/click",
            "input/grip/pose",
            "input/aim/pose",
            "output/haptic",
        ]),
        TOUCH | TOUCH_PLUS => {
            if profile == TOUCH_PLUS {
                // What Touch Plus adds to Touch's components (the extension's
                // profile table).
                known.extend([
                    "input/thumb_meta/proximity_meta",
                    "input/trigger/proximity_meta",
                    "input/trigger/curl_meta",
                    "input/trigger/slide_meta",
                    "input/trigger/force",
                ]);
            }
            known.extend([
                "input/squeeze/value",
                "input/trigger/value",
                "input/trigger/touch",
                "input/thumbstick",
                "input/thumbstick/x",
                "input/thumbstick/y",
                "input/thumbstick/click",
                "input/thumbstick/touch",
                "input/thumbrest/touch",
                "input/grip/pose",
                "input/aim/pose",
                "output/haptic",
            ]);
            if hand == "left" {
                known.extend(["input/x/click", "input/x/touch", "input/y/click", "input/y/touch", "input/menu/click"]);
            } else {
                known.extend([
                    "input/a/click",
                    "input/a/touch",
                    "input/b/click",
                    "input/b/touch",
                    "input/system/click",
                ]);
            }
        }
        _ => return false,
    }
    known.iter().any(|k| *k == component || k.strip_prefix(component).is_some_and(|rest| rest.starts_with('/')))
}

pub(crate) struct Action {
    set: u64,
    name: String,
    ty: xr::ActionType,
    /// Boolean state at the last sync: (current, changed since the sync before, last change time, active).
    state: (bool, bool, i64, bool),
}

/// The instance's action sets, actions and bindings (Runtime::input).
#[derive(Default)]
pub(crate) struct Input {
    sets: HashMap<u64, String>,
    actions: HashMap<u64, Action>,
    /// Profile path → the (action, binding path) pairs last suggested for it
    /// (a later suggestion for the same profile replaces the earlier, spec 11.4).
    bindings: HashMap<String, Vec<(u64, String)>>,
    /// Sets attached to the session (spec: at most once per session).
    attached: Vec<u64>,
    /// Sets ever attached: their actions and bindings are fixed for good (spec
    /// 11.3/11.4: XR_ERROR_ACTIONSETS_ALREADY_ATTACHED once a set "has been
    /// included in a call to xrAttachSessionActionSets").
    ever_attached: Vec<u64>,
    /// XrEventDataInteractionProfileChanged is owed: queued at the first sync of a
    /// running session (the spec queues it for running sessions only).
    profile_event_pending: bool,
    /// The interaction profile chosen at attach time, if the app suggested one
    /// the controllers match.
    pub profile: Option<String>,
}

impl Input {
    /// The session ended: nothing attached, no profile, every action inactive.
    pub(crate) fn end_session(&mut self) {
        self.attached.clear();
        self.profile = None;
        self.profile_event_pending = false;
        for a in self.actions.values_mut() {
            a.state = (false, false, 0, false);
        }
    }
}

fn session_ok(rt: &crate::Runtime, session: xr::Session) -> bool {
    rt.session.as_ref().is_some_and(|s| s.handle == session.into_raw())
}

/// A NUL-terminated fixed-size name field as a String.
fn name_of(chars: &[c_char]) -> String {
    let bytes: Vec<u8> = chars.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

fn path_string(rt: &crate::Runtime, path: xr::Path) -> Option<String> {
    (path.into_raw() as usize).checked_sub(1).and_then(|i| rt.paths.get(i)).cloned()
}

pub(crate) unsafe extern "system" fn create_action_set(
    instance: xr::Instance,
    info: *const xr::ActionSetCreateInfo,
    out: *mut xr::ActionSet,
) -> xr::Result {
    with_instance(instance, |rt| {
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: the caller's create info.
        let name = name_of(unsafe { &(*info).action_set_name });
        if name.is_empty() || rt.input.sets.values().any(|n| *n == name) {
            return xr::Result::ERROR_NAME_INVALID;
        }
        let h = rt.handle();
        rt.actions.insert(h);
        rt.input.sets.insert(h, name);
        // SAFETY: caller's output.
        unsafe { *out = xr::ActionSet::from_raw(h) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_action_set(set: xr::ActionSet) -> xr::Result {
    with_runtime(|rt| {
        if rt.actions.remove(&set.into_raw()) {
            rt.input.sets.remove(&set.into_raw());
            rt.input.actions.retain(|_, a| a.set != set.into_raw());
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        }
    })
}

pub(crate) unsafe extern "system" fn create_action(
    set: xr::ActionSet,
    info: *const xr::ActionCreateInfo,
    out: *mut xr::Action,
) -> xr::Result {
    with_runtime(|rt| {
        if !rt.input.sets.contains_key(&set.into_raw()) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // Spec 11.3: an action set's actions cannot change once it is attached.
        if rt.input.ever_attached.contains(&set.into_raw()) {
            return xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED;
        }
        // SAFETY: the caller's create info.
        let (name, ty) = unsafe { (name_of(&(*info).action_name), (*info).action_type) };
        if name.is_empty() || rt.input.actions.values().any(|a| a.set == set.into_raw() && a.name == name) {
            return xr::Result::ERROR_NAME_INVALID;
        }
        let h = rt.handle();
        rt.actions.insert(h);
        rt.input.actions.insert(h, Action { set: set.into_raw(), name, ty, state: (false, false, 0, false) });
        // SAFETY: caller's output.
        unsafe { *out = xr::Action::from_raw(h) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_action(action: xr::Action) -> xr::Result {
    with_runtime(|rt| {
        if rt.actions.remove(&action.into_raw()) {
            rt.input.actions.remove(&action.into_raw());
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        }
    })
}

pub(crate) unsafe extern "system" fn suggest_interaction_profile_bindings(
    instance: xr::Instance,
    suggested: *const xr::InteractionProfileSuggestedBinding,
) -> xr::Result {
    with_instance(instance, |rt| {
        if suggested.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: the caller's struct and its array of count_suggested_bindings.
        let (profile, list) = unsafe {
            let s = &*suggested;
            if s.suggested_bindings.is_null() || s.count_suggested_bindings == 0 {
                return xr::Result::ERROR_VALIDATION_FAILURE;
            }
            (
                s.interaction_profile,
                std::slice::from_raw_parts(s.suggested_bindings, s.count_suggested_bindings as usize),
            )
        };
        let Some(profile) = path_string(rt, profile) else { return xr::Result::ERROR_PATH_INVALID };
        let known = profile == TOUCH || profile == SIMPLE || (profile == TOUCH_PLUS && rt.has(crate::EXT_TOUCH_PLUS));
        if !known {
            rt.log(serde_json::json!({"event": "bindings_refused", "profile": profile}));
            return xr::Result::ERROR_PATH_UNSUPPORTED;
        }
        let mut pairs = Vec::with_capacity(list.len());
        for b in list {
            let Some(path) = path_string(rt, b.binding) else { return xr::Result::ERROR_PATH_INVALID };
            if !supports(&profile, &path) {
                rt.log(serde_json::json!({"event": "bindings_refused", "profile": profile, "binding": path}));
                return xr::Result::ERROR_PATH_UNSUPPORTED;
            }
            let Some(action) = rt.input.actions.get(&b.action.into_raw()) else {
                return xr::Result::ERROR_HANDLE_INVALID;
            };
            // Spec 11.4: suggestions for an attached set's actions are an error.
            if rt.input.ever_attached.contains(&action.set) {
                return xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED;
            }
            pairs.push((b.action.into_raw(), path));
        }
        rt.log(serde_json::json!({"event": "bindings", "profile": profile, "count": pairs.len()}));
        rt.input.bindings.insert(profile, pairs);
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn attach_session_action_sets(
    session: xr::Session,
    info: *const xr::SessionActionSetsAttachInfo,
) -> xr::Result {
    with_runtime(|rt| {
        if !session_ok(rt, session) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        if !rt.input.attached.is_empty() {
            return xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED;
        }
        if info.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: the caller's struct and its array of count_action_sets handles.
        let sets = unsafe {
            let i = &*info;
            if i.action_sets.is_null() || i.count_action_sets == 0 {
                return xr::Result::ERROR_VALIDATION_FAILURE;
            }
            std::slice::from_raw_parts(i.action_sets, i.count_action_sets as usize)
        };
        if sets.iter().any(|s| !rt.input.sets.contains_key(&s.into_raw())) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        rt.input.attached = sets.iter().map(|s| s.into_raw()).collect();
        for s in sets {
            if !rt.input.ever_attached.contains(&s.into_raw()) {
                rt.input.ever_attached.push(s.into_raw());
            }
        }
        // The controllers (`BA_XR_CONTROLLER`) answer to these profiles, best first.
        let offered: &[&str] = match rt.config.controller {
            crate::config::Controller::Touch => &[TOUCH, SIMPLE],
            crate::config::Controller::TouchPlus => &[TOUCH_PLUS, TOUCH, SIMPLE],
            crate::config::Controller::Simple => &[SIMPLE],
            crate::config::Controller::None => &[],
        };
        rt.input.profile = offered.iter().find(|p| rt.input.bindings.contains_key(**p)).map(|p| p.to_string());
        rt.log(serde_json::json!({"event": "attach", "profile": rt.input.profile}));
        rt.input.profile_event_pending = rt.input.profile.is_some();
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn get_current_interaction_profile(
    session: xr::Session,
    user_path: xr::Path,
    out: *mut xr::InteractionProfileState,
) -> xr::Result {
    with_runtime(|rt| {
        if !session_ok(rt, session) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        if rt.input.attached.is_empty() {
            return xr::Result::ERROR_ACTIONSET_NOT_ATTACHED;
        }
        let hand = path_string(rt, user_path);
        if !matches!(hand.as_deref(), Some("/user/hand/left" | "/user/hand/right")) {
            return xr::Result::ERROR_PATH_UNSUPPORTED;
        }
        let profile = match rt.input.profile.clone() {
            Some(p) => crate::intern_path(rt, &p),
            None => xr::Path::NULL,
        };
        if out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: caller's output, checked non-null.
        unsafe { (*out).interaction_profile = profile };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn sync_actions(
    session: xr::Session,
    info: *const xr::ActionsSyncInfo,
) -> xr::Result {
    with_runtime(|rt| {
        if !session_ok(rt, session) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        if info.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: the caller's struct and its array of count_active_action_sets.
        let active = unsafe {
            let i = &*info;
            if i.count_active_action_sets > 0 && i.active_action_sets.is_null() {
                return xr::Result::ERROR_VALIDATION_FAILURE;
            }
            if i.count_active_action_sets == 0 {
                &[][..]
            } else {
                std::slice::from_raw_parts(i.active_action_sets, i.count_active_action_sets as usize)
            }
        };
        if active.iter().any(|a| !rt.input.attached.contains(&a.action_set.into_raw())) {
            return xr::Result::ERROR_ACTIONSET_NOT_ATTACHED;
        }
        let Some(s) = rt.session.as_ref() else { return xr::Result::ERROR_HANDLE_INVALID };
        let (focused, running, frame, handle) =
            (s.state == xr::SessionState::FOCUSED, s.running, s.frame.ended, s.handle);
        if running && std::mem::take(&mut rt.input.profile_event_pending) {
            rt.events.push_back(crate::Event::ProfileChanged { session: handle });
        }
        let now = rt.now_ns();
        let pressed: Vec<String> = rt
            .config
            .presses
            .iter()
            .filter(|(from, to, _)| (*from..*to).contains(&frame))
            .map(|(_, _, p)| p.clone())
            .collect();
        let synced: Vec<u64> = active.iter().map(|a| a.action_set.into_raw()).collect();
        let bound = rt.input.profile.as_ref().and_then(|p| rt.input.bindings.get(p)).cloned().unwrap_or_default();
        // Spec (XrActionStatePose::isActive): true only while an input source is
        // bound and tracked; the scripted controller is tracked once posed.
        let tracked = controller_pose(rt).is_some();
        let mut changes = Vec::new();
        for (h, a) in rt.input.actions.iter_mut() {
            // Spec (xrSyncActions): only the listed sets are active; the others'
            // actions read inactive and false until synced again.
            if !synced.contains(&a.set) {
                a.state = (false, false, a.state.2, false);
                continue;
            }
            let paths: Vec<&String> = bound.iter().filter(|(act, _)| act == h).map(|(_, p)| p).collect();
            // Spec 11.5: not focused, every action is inactive and reads false.
            let active = focused
                && !paths.is_empty()
                && match a.ty {
                    xr::ActionType::BOOLEAN_INPUT | xr::ActionType::VECTOR2F_INPUT => true,
                    xr::ActionType::POSE_INPUT => tracked,
                    _ => false,
                };
            let current = active && a.ty == xr::ActionType::BOOLEAN_INPUT && paths.iter().any(|p| pressed.contains(p));
            let changed = active && a.state.3 && current != a.state.0;
            let time = if changed { now } else { a.state.2 };
            if changed {
                changes.push(serde_json::json!({"action": a.name, "state": current}));
            }
            a.state = (current, changed, time, active);
        }
        if !changes.is_empty() {
            rt.log(serde_json::json!({"event": "input", "frame": frame, "changes": changes}));
        }
        if focused {
            xr::Result::SUCCESS
        } else {
            xr::Result::SESSION_NOT_FOCUSED
        }
    })
}

/// The checks every xrGetActionState* makes (spec 11.5): a live session, non-null
/// arguments, a known action of the expected type in an attached set; the action.
fn checked_action(
    rt: &crate::Runtime,
    session: xr::Session,
    info: *const xr::ActionStateGetInfo,
    out_null: bool,
    ty: xr::ActionType,
) -> Result<&Action, xr::Result> {
    if !session_ok(rt, session) {
        return Err(xr::Result::ERROR_HANDLE_INVALID);
    }
    if info.is_null() || out_null {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    // SAFETY: the caller's info, checked non-null.
    let action = unsafe { (*info).action.into_raw() };
    let a = rt.input.actions.get(&action).ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
    if a.ty != ty {
        return Err(xr::Result::ERROR_ACTION_TYPE_MISMATCH);
    }
    if !rt.input.attached.contains(&a.set) {
        return Err(xr::Result::ERROR_ACTIONSET_NOT_ATTACHED);
    }
    Ok(a)
}

pub(crate) unsafe extern "system" fn get_action_state_boolean(
    session: xr::Session,
    info: *const xr::ActionStateGetInfo,
    state: *mut xr::ActionStateBoolean,
) -> xr::Result {
    with_runtime(|rt| {
        let a = match checked_action(rt, session, info, state.is_null(), xr::ActionType::BOOLEAN_INPUT) {
            Ok(a) => a,
            Err(e) => return e,
        };
        let (current, changed, time, active) = a.state;
        // SAFETY: caller's output.
        unsafe {
            (*state).current_state = current.into();
            (*state).changed_since_last_sync = changed.into();
            (*state).last_change_time = xr::Time::from_nanos(time);
            (*state).is_active = active.into();
        }
        xr::Result::SUCCESS
    })
}

macro_rules! inactive_state {
    ($name:ident, $ty:ty) => {
        pub(crate) unsafe extern "system" fn $name(
            session: xr::Session,
            _info: *const xr::ActionStateGetInfo,
            state: *mut $ty,
        ) -> xr::Result {
            with_runtime(|rt| {
                if !session_ok(rt, session) {
                    return xr::Result::ERROR_HANDLE_INVALID;
                }
                if state.is_null() {
                    return xr::Result::ERROR_VALIDATION_FAILURE;
                }
                // SAFETY: caller's output, checked non-null; no analog input is
                // scripted, so it is inactive.
                unsafe { (*state).is_active = xr::FALSE };
                xr::Result::SUCCESS
            })
        }
    };
}
inactive_state!(get_action_state_float, xr::ActionStateFloat);

pub(crate) unsafe extern "system" fn get_action_state_vector2f(
    session: xr::Session,
    info: *const xr::ActionStateGetInfo,
    state: *mut xr::ActionStateVector2f,
) -> xr::Result {
    with_runtime(|rt| {
        let a = match checked_action(rt, session, info, state.is_null(), xr::ActionType::VECTOR2F_INPUT) {
            Ok(a) => a,
            Err(e) => return e,
        };
        let active = a.state.3;
        let frame = rt.session.as_ref().map_or(0, |s| s.frame.ended);
        let v = if active {
            rt.config.sticks.iter().find(|(from, to, _)| (*from..*to).contains(&frame)).map_or([0.0; 2], |s| s.2)
        } else {
            [0.0; 2]
        };
        // SAFETY: caller's output, checked non-null.
        unsafe {
            (*state).current_state = xr::Vector2f { x: v[0], y: v[1] };
            (*state).changed_since_last_sync = xr::FALSE;
            (*state).last_change_time = xr::Time::from_nanos(0);
            (*state).is_active = active.into();
        }
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn get_action_state_pose(
    session: xr::Session,
    info: *const xr::ActionStateGetInfo,
    state: *mut xr::ActionStatePose,
) -> xr::Result {
    with_runtime(|rt| {
        let a = match checked_action(rt, session, info, state.is_null(), xr::ActionType::POSE_INPUT) {
            Ok(a) => a,
            Err(e) => return e,
        };
        // SAFETY: caller's output, checked non-null.
        unsafe { (*state).is_active = a.state.3.into() };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn enumerate_bound_sources_for_action(
    session: xr::Session,
    _info: *const xr::BoundSourcesForActionEnumerateInfo,
    capacity: u32,
    count: *mut u32,
    out: *mut xr::Path,
) -> xr::Result {
    with_runtime(|rt| {
        if !session_ok(rt, session) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        // SAFETY: the caller's two-call arguments; nothing is bound.
        unsafe { two_call::<xr::Path>(&[], capacity, count, out) }
    })
}

pub(crate) unsafe extern "system" fn get_input_source_localized_name(
    session: xr::Session,
    _info: *const xr::InputSourceLocalizedNameGetInfo,
    capacity: u32,
    count: *mut u32,
    out: *mut c_char,
) -> xr::Result {
    with_runtime(|rt| {
        if !session_ok(rt, session) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        // SAFETY: the caller's two-call arguments: the empty string.
        unsafe { two_call::<c_char>(&[0], capacity, count, out) }
    })
}

pub(crate) unsafe extern "system" fn create_action_space(
    session: xr::Session,
    info: *const xr::ActionSpaceCreateInfo,
    out: *mut xr::Space,
) -> xr::Result {
    with_runtime(|rt| {
        if !session_ok(rt, session) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        if out.is_null() || info.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: the caller's struct, checked non-null.
        let info = unsafe { &*info };
        let Some(a) = rt.input.actions.get(&info.action.into_raw()) else { return xr::Result::ERROR_HANDLE_INVALID };
        // Spec (xrCreateActionSpace): only pose actions have spaces.
        if a.ty != xr::ActionType::POSE_INPUT {
            return xr::Result::ERROR_ACTION_TYPE_MISMATCH;
        }
        let h = rt.handle();
        rt.action_spaces.insert(h, (info.action.into_raw(), info.pose_in_action_space));
        // SAFETY: caller's output, checked non-null.
        unsafe { *out = xr::Space::from_raw(h) };
        xr::Result::SUCCESS
    })
}

/// The scripted right controller's pose in LOCAL at the frame being produced,
/// if one is scripted by then.
pub(crate) fn controller_pose(rt: &crate::Runtime) -> Option<crate::session::Pose> {
    let frame = rt.session.as_ref()?.frame.ended;
    let &(_, [x, y, z, yaw, pitch]) = rt.config.aims.iter().filter(|(n, _)| *n <= frame).max_by_key(|(n, _)| *n)?;
    let (yaw, pitch) = (yaw.to_radians(), pitch.to_radians());
    let q_yaw = crate::session::Pose { q: [0.0, (yaw / 2.0).sin(), 0.0, (yaw / 2.0).cos()], t: [x, y, z] };
    let q_pitch = crate::session::Pose { q: [(pitch / 2.0).sin(), 0.0, 0.0, (pitch / 2.0).cos()], t: [0.0; 3] };
    Some(q_yaw.mul(&q_pitch))
}

/// `base_from_space` of an action space at the frame being produced (spec
/// xrLocateSpace): the scripted controller pose while its pose action is active,
/// else None (no valid bits).
pub(crate) fn locate_action_space(
    rt: &crate::Runtime,
    space: u64,
    local_from_base: &crate::session::Pose,
) -> Option<crate::session::Pose> {
    let &(action, offset) = rt.action_spaces.get(&space)?;
    let local_from_controller = controller_pose(rt).filter(|_| pose_active(rt, action))?;
    Some(local_from_base.inverse().mul(&local_from_controller.mul(&crate::session::Pose::from_xr(&offset))))
}

/// Whether action `action` (a pose action) is active: synced, bound in the
/// chosen profile, the session focused (the state of the last xrSyncActions).
pub(crate) fn pose_active(rt: &crate::Runtime, action: u64) -> bool {
    rt.input.actions.get(&action).is_some_and(|a| a.state.3)
}

pub(crate) unsafe extern "system" fn apply_haptic_feedback(
    session: xr::Session,
    _info: *const xr::HapticActionInfo,
    _feedback: *const xr::HapticBaseHeader,
) -> xr::Result {
    with_runtime(|rt| if session_ok(rt, session) { xr::Result::SUCCESS } else { xr::Result::ERROR_HANDLE_INVALID })
}

pub(crate) unsafe extern "system" fn stop_haptic_feedback(
    session: xr::Session,
    _info: *const xr::HapticActionInfo,
) -> xr::Result {
    with_runtime(|rt| if session_ok(rt, session) { xr::Result::SUCCESS } else { xr::Result::ERROR_HANDLE_INVALID })
}
