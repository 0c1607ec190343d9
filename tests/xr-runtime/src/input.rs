//! The input system (OpenXR spec 11) of a headset with no controllers attached:
//! action sets, actions and bindings are accepted and kept, every action state is
//! inactive, no source is bound, action spaces are never located, haptics have
//! nothing to drive. Every core function must resolve through
//! xrGetInstanceProcAddr (spec 3.2), and the app's OpenXR bindings load them all.

use crate::{two_call, with_instance, with_runtime};
use openxr_sys as xr;
use std::ffi::c_char;
use xr::Handle as _;

fn session_ok(rt: &crate::Runtime, session: xr::Session) -> bool {
    rt.session.as_ref().is_some_and(|s| s.handle == session.into_raw())
}

pub(crate) unsafe extern "system" fn create_action_set(
    instance: xr::Instance,
    _info: *const xr::ActionSetCreateInfo,
    out: *mut xr::ActionSet,
) -> xr::Result {
    with_instance(instance, |rt| {
        let h = rt.handle();
        rt.actions.insert(h);
        // SAFETY: caller's output.
        unsafe { *out = xr::ActionSet::from_raw(h) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_action_set(set: xr::ActionSet) -> xr::Result {
    with_runtime(|rt| {
        if rt.actions.remove(&set.into_raw()) {
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        }
    })
}

pub(crate) unsafe extern "system" fn create_action(
    set: xr::ActionSet,
    _info: *const xr::ActionCreateInfo,
    out: *mut xr::Action,
) -> xr::Result {
    with_runtime(|rt| {
        if !rt.actions.contains(&set.into_raw()) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        let h = rt.handle();
        rt.actions.insert(h);
        // SAFETY: caller's output.
        unsafe { *out = xr::Action::from_raw(h) };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn destroy_action(action: xr::Action) -> xr::Result {
    with_runtime(|rt| {
        if rt.actions.remove(&action.into_raw()) {
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        }
    })
}

pub(crate) unsafe extern "system" fn suggest_interaction_profile_bindings(
    instance: xr::Instance,
    _bindings: *const xr::InteractionProfileSuggestedBinding,
) -> xr::Result {
    with_instance(instance, |_| xr::Result::SUCCESS)
}

pub(crate) unsafe extern "system" fn attach_session_action_sets(
    session: xr::Session,
    _info: *const xr::SessionActionSetsAttachInfo,
) -> xr::Result {
    with_runtime(|rt| if session_ok(rt, session) { xr::Result::SUCCESS } else { xr::Result::ERROR_HANDLE_INVALID })
}

pub(crate) unsafe extern "system" fn get_current_interaction_profile(
    session: xr::Session,
    _user_path: xr::Path,
    out: *mut xr::InteractionProfileState,
) -> xr::Result {
    with_runtime(|rt| {
        if !session_ok(rt, session) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        // SAFETY: caller's output. No controller: no interaction profile.
        unsafe { (*out).interaction_profile = xr::Path::NULL };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn sync_actions(
    session: xr::Session,
    _info: *const xr::ActionsSyncInfo,
) -> xr::Result {
    with_runtime(|rt| {
        if session_ok(rt, session) {
            xr::Result::SESSION_NOT_FOCUSED
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        }
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
                // SAFETY: caller's output; no source is bound, so it is inactive.
                unsafe { (*state).is_active = xr::FALSE };
                xr::Result::SUCCESS
            })
        }
    };
}
inactive_state!(get_action_state_boolean, xr::ActionStateBoolean);
inactive_state!(get_action_state_float, xr::ActionStateFloat);
inactive_state!(get_action_state_vector2f, xr::ActionStateVector2f);
inactive_state!(get_action_state_pose, xr::ActionStatePose);

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
    _info: *const xr::ActionSpaceCreateInfo,
    out: *mut xr::Space,
) -> xr::Result {
    with_runtime(|rt| {
        if !session_ok(rt, session) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        let h = rt.handle();
        rt.actions.insert(h);
        // SAFETY: caller's output. Located as untracked (no controller).
        unsafe { *out = xr::Space::from_raw(h) };
        xr::Result::SUCCESS
    })
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
