//! Controller input through OpenXR actions (spec chapter 11, "Input and
//! Haptics"): the buttons that switch matched ↔ naive and each effect on its own,
//! so the comparison the paper's evaluation rests on can be made on the headset.
//!
//! One action set with six boolean actions (four toggles, the record button and
//! the next scene); bindings are suggested for Meta Touch Plus (Quest 3's controllers,
//! XR_META_touch_controller_plus, when the runtime offers it), Oculus Touch (Quest 2
//! and Pro; Quest runtimes also map Touch Plus onto this profile) and the Khronos
//! simple controller (spec 6.4, "Interaction Profile Paths"), each suggestion on its
//! own so a runtime that does not know a profile (XR_ERROR_PATH_UNSUPPORTED) leaves
//! the others in place. The set is attached
//! once to the session; every frame xrSyncActions is called and a button acts on
//! its press (current state true with `changedSinceLastSync`), as Meta's
//! XrSamples' input handling does. An unfocused session (XR_SESSION_NOT_FOCUSED,
//! a system menu over the app) reads every action inactive: nothing toggles.

use super::call;
use super::XrError;
use crate::render::Enabled;
use openxr as xr;

const TOUCH: &str = "/interaction_profiles/oculus/touch_controller";
const SIMPLE: &str = "/interaction_profiles/khr/simple_controller";
/// Quest 3's controllers (XR_META_touch_controller_plus; the path is valid only
/// with the extension enabled under OpenXR 1.0). Same buttons as Touch for what
/// the app binds, so it takes Touch's bindings; suggested on its own so a runtime
/// that prefers the exact profile finds one.
const TOUCH_PLUS: &str = "/interaction_profiles/meta/touch_controller_plus";

/// What each action does, its name, and its bindings per profile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Toggle {
    /// Every effect on (matched) or off (naive).
    Matched,
    Noise,
    MotionBlur,
    Dof,
    /// Start or stop a recording of what the calibration worker takes (the app
    /// acts on it: `FrameRecord::pressed`); the effects stay as they are.
    Record,
    /// The next of the user's scenes (`scenes::SceneCycle`).
    NextScene,
}

/// (toggle, action name, localized name, Touch binding, simple-controller binding).
const ACTIONS: [(Toggle, &str, &str, &str, Option<&str>); 6] = [
    (
        Toggle::Matched,
        "toggle_matched",
        "Matched / naive",
        "/user/hand/right/input/a/click",
        Some("/user/hand/right/input/select/click"),
    ),
    (Toggle::Noise, "toggle_noise", "Sensor noise", "/user/hand/right/input/b/click", None),
    (Toggle::MotionBlur, "toggle_motion_blur", "Motion blur", "/user/hand/left/input/x/click", None),
    (Toggle::Dof, "toggle_dof", "Depth of field", "/user/hand/left/input/y/click", None),
    // The left thumbstick's click: the Touch profile's one remaining button a user
    // does not press by accident while toggling (the menu button is the system's
    // on the right hand and the app's on the left, where Meta's apps open menus).
    (Toggle::Record, "toggle_recording", "Record calibration input", "/user/hand/left/input/thumbstick/click", None),
    // The simple controller's menu click: its only other button (the left one is
    // the app's on Quest; the right one the system's, which the runtime keeps).
    (
        Toggle::NextScene,
        "next_scene",
        "Next scene",
        "/user/hand/right/input/thumbstick/click",
        Some("/user/hand/left/input/menu/click"),
    ),
];

/// The toggles' state: which effects the frame may apply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Toggles {
    pub matched: bool,
    pub effects: Enabled,
}

impl Default for Toggles {
    fn default() -> Self {
        Self { matched: true, effects: Enabled::matched(true) }
    }
}

impl Toggles {
    /// What the renderer gets: nothing when naive, else the per-effect switches.
    pub fn enabled(&self) -> Enabled {
        if self.matched {
            self.effects
        } else {
            Enabled::matched(false)
        }
    }

    pub fn apply(&mut self, t: Toggle) {
        match t {
            Toggle::Matched => self.matched = !self.matched,
            Toggle::Noise => self.effects.noise = !self.effects.noise,
            Toggle::MotionBlur => self.effects.motion_blur = !self.effects.motion_blur,
            Toggle::Dof => self.effects.dof = !self.effects.dof,
            Toggle::Record | Toggle::NextScene => {}
        }
    }
}

pub struct Controls {
    set: xr::ActionSet,
    actions: Vec<(Toggle, xr::Action<bool>)>,
}

impl Controls {
    /// Creates the action set and its actions and suggests their bindings.
    /// Fails only if the set or an action cannot be created, or if no profile's
    /// bindings are accepted.
    pub fn new(instance: &xr::Instance, touch_plus: bool) -> Result<Self, XrError> {
        let set = instance.create_action_set("blind_augment", "Blind augment", 0).map_err(call("xrCreateActionSet"))?;
        let mut actions = Vec::with_capacity(ACTIONS.len());
        for (toggle, name, localized, _, _) in ACTIONS {
            let action = set.create_action::<bool>(name, localized, &[]).map_err(call("xrCreateAction"))?;
            actions.push((toggle, action));
        }
        let mut accepted = 0;
        let profiles: &[&str] = if touch_plus { &[TOUCH_PLUS, TOUCH, SIMPLE] } else { &[TOUCH, SIMPLE] };
        for &profile in profiles {
            let path = |p: &str| instance.string_to_path(p).map_err(call("xrStringToPath"));
            let mut bindings = Vec::new();
            for ((_, _, _, touch, simple), (_, action)) in ACTIONS.iter().zip(&actions) {
                let binding = if profile == SIMPLE { *simple } else { Some(*touch) };
                if let Some(b) = binding {
                    bindings.push(xr::Binding::new(action, path(b)?));
                }
            }
            match instance.suggest_interaction_profile_bindings(path(profile)?, &bindings) {
                Ok(()) => accepted += 1,
                Err(e) => {
                    log::warn!("OpenXR: bindings for {profile} not accepted ({e}); that controller cannot toggle")
                }
            }
        }
        if accepted == 0 {
            return Err(XrError::Call {
                call: "xrSuggestInteractionProfileBindings",
                result: xr::sys::Result::ERROR_PATH_UNSUPPORTED,
            });
        }
        Ok(Self { set, actions })
    }

    /// Attaches the action set to the session (once per session, spec 11.4).
    pub fn attach<G>(&self, session: &xr::Session<G>) -> Result<(), XrError> {
        session.attach_action_sets(&[&self.set]).map_err(call("xrAttachSessionActionSets"))
    }

    /// Syncs the actions and returns the toggles pressed since the last sync.
    pub fn poll<G>(&self, session: &xr::Session<G>) -> Result<Vec<Toggle>, XrError> {
        session.sync_actions(&[xr::ActiveActionSet::new(&self.set)]).map_err(call("xrSyncActions"))?;
        let mut pressed = Vec::new();
        for (toggle, action) in &self.actions {
            let s = action.state(session, xr::Path::NULL).map_err(call("xrGetActionStateBoolean"))?;
            if s.is_active && s.changed_since_last_sync && s.current_state {
                pressed.push(*toggle);
            }
        }
        Ok(pressed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn naive_turns_every_effect_off_and_back_as_it_was() {
        let mut t = Toggles::default();
        t.apply(Toggle::Dof);
        assert_eq!(t.enabled(), Enabled { noise: true, motion_blur: true, dof: false });
        t.apply(Toggle::Matched);
        assert_eq!(t.enabled(), Enabled::matched(false));
        t.apply(Toggle::Matched);
        assert_eq!(t.enabled(), Enabled { noise: true, motion_blur: true, dof: false });
    }
}
