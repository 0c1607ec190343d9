//! Controller input through OpenXR actions (spec chapter 11, "Input and
//! Haptics"): the buttons that switch matched ↔ naive and each effect on its own,
//! so the comparison the paper's evaluation rests on can be made on the headset.
//!
//! One action set with eight buttons (four toggles, record, next scene, restart
//! calibration, the status panel), the grab, the aim pose and the thumbstick; bindings are suggested for Meta Touch Plus (Quest 3's controllers,
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
    /// Restart the calibration from scratch (the app acts on it:
    /// `FrameRecord::pressed`).
    RestartCalibration,
    /// Show or hide the status panel (`panel`).
    Panel,
}

/// (toggle, action name, localized name, Touch binding, simple-controller binding).
const ACTIONS: [(Toggle, &str, &str, &str, Option<&str>); 8] = [
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
    // Touch's left menu button (the app's; the right one is the system's).
    (
        Toggle::RestartCalibration,
        "restart_calibration",
        "Restart calibration",
        "/user/hand/left/input/menu/click",
        None,
    ),
    // The left trigger (a boolean action on a value input: the runtime thresholds
    // it, spec 11.4): the left hand's one free button, the right hand's trigger
    // staying free for pointing.
    (Toggle::Panel, "toggle_panel", "Status panel", "/user/hand/left/input/trigger/value", None),
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
            Toggle::Record | Toggle::NextScene | Toggle::RestartCalibration | Toggle::Panel => {}
        }
    }
}

/// Grab-and-place (`Placement`): the right controller's squeeze holds the object,
/// its aim pose carries it. Touch and Touch Plus only: the simple controller has
/// no second button to spare.
const GRAB_TOUCH: &str = "/user/hand/right/input/squeeze/value";
/// The aim pose (spec 6.3 "Standard pose identifiers": the ray pointing forward
/// from the controller), on every profile.
const AIM: &str = "/user/hand/right/input/aim/pose";
/// While held: up/down pushes the object along the aim ray or pulls it in,
/// left/right shrinks or grows it.
const STICK_TOUCH: &str = "/user/hand/right/input/thumbstick";
/// Distance change at full deflection (m/s) and scale change (e-folds per second).
const PUSH_M_PER_S: f32 = 1.0;
const SCALE_PER_S: f32 = 0.7;
/// Nearest the object comes along the aim ray (m), and the scale range (× the
/// scene's own size): a held stick never puts it behind the controller or makes it
/// vanish or fill the room.
const MIN_REACH_M: f32 = 0.1;
const SCALE_RANGE: [f32; 2] = [0.05, 20.0];
/// Deflections below this read as centred (a resting stick is never exactly 0).
const STICK_DEADZONE: f32 = 0.15;

/// What one xrSyncActions read.
pub struct ControllerState {
    /// Buttons pressed since the last sync.
    pub pressed: Vec<Toggle>,
    /// The grab button is held.
    pub grab_held: bool,
    /// The right controller's aim pose in the reference space, when located
    /// (position and orientation valid).
    pub space_from_aim: Option<glam::Mat4>,
    /// The right thumbstick (x right, y up, each in [−1, 1]); centred when inactive.
    pub stick: [f32; 2],
}

pub struct Controls {
    set: xr::ActionSet,
    actions: Vec<(Toggle, xr::Action<bool>)>,
    grab: xr::Action<bool>,
    aim: xr::Action<xr::Posef>,
    aim_space: Option<xr::Space>,
    stick: xr::Action<xr::Vector2f>,
    /// Reading the aim failed once (logged once).
    aim_failed: std::sync::atomic::AtomicBool,
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
        let grab = set.create_action::<bool>("grab", "Grab the object", &[]).map_err(call("xrCreateAction"))?;
        let aim = set.create_action::<xr::Posef>("aim", "Aim", &[]).map_err(call("xrCreateAction"))?;
        let stick =
            set.create_action::<xr::Vector2f>("place", "Push / pull and scale", &[]).map_err(call("xrCreateAction"))?;
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
            // A boolean action on a float input: the runtime thresholds it (spec
            // 11.4, "Suggested bindings": boolean to value conversion).
            if profile != SIMPLE {
                bindings.push(xr::Binding::new(&grab, path(GRAB_TOUCH)?));
                bindings.push(xr::Binding::new(&stick, path(STICK_TOUCH)?));
            }
            bindings.push(xr::Binding::new(&aim, path(AIM)?));
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
        Ok(Self { set, actions, grab, aim, aim_space: None, stick, aim_failed: Default::default() })
    }

    /// Attaches the action set to the session (once per session, spec 11.4) and
    /// creates the aim pose's action space.
    pub fn attach<G>(&mut self, session: &xr::Session<G>) -> Result<(), XrError> {
        session.attach_action_sets(&[&self.set]).map_err(call("xrAttachSessionActionSets"))?;
        let space = self.aim.create_space(session, xr::Path::NULL, xr::Posef::IDENTITY);
        self.aim_space = Some(space.map_err(call("xrCreateActionSpace"))?);
        Ok(())
    }

    /// Syncs the actions: the toggles pressed since the last sync, the grab
    /// button, and the aim pose in `base` at `time` (the frame's display time).
    pub fn poll<G>(
        &self,
        session: &xr::Session<G>,
        base: &xr::Space,
        time: xr::Time,
    ) -> Result<ControllerState, XrError> {
        session.sync_actions(&[xr::ActiveActionSet::new(&self.set)]).map_err(call("xrSyncActions"))?;
        let mut pressed = Vec::new();
        for (toggle, action) in &self.actions {
            let s = action.state(session, xr::Path::NULL).map_err(call("xrGetActionStateBoolean"))?;
            if s.is_active && s.changed_since_last_sync && s.current_state {
                pressed.push(*toggle);
            }
        }
        let g = self.grab.state(session, xr::Path::NULL).map_err(call("xrGetActionStateBoolean"))?;
        // The aim is optional: a failure to read it leaves the object unmoved and
        // never costs the presses read above (they are reported once).
        let mut space_from_aim = None;
        if let Some(space) = &self.aim_space {
            match self
                .aim
                .is_active(session, xr::Path::NULL)
                .and_then(|a| a.then(|| space.locate(base, time)).transpose())
            {
                Ok(Some(l)) => {
                    let valid = xr::SpaceLocationFlags::POSITION_VALID | xr::SpaceLocationFlags::ORIENTATION_VALID;
                    if l.location_flags.contains(valid) {
                        space_from_aim = pose_matrix(&l.pose);
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    if !self.aim_failed.swap(true, std::sync::atomic::Ordering::Relaxed) {
                        log::warn!("OpenXR: the aim pose could not be read ({e}); the object stays where it is");
                    }
                }
            }
        }
        let stick = match self.stick.state(session, xr::Path::NULL) {
            Ok(v) if v.is_active => [v.current_state.x, v.current_state.y],
            _ => [0.0; 2],
        };
        Ok(ControllerState { pressed, grab_held: g.is_active && g.current_state, space_from_aim, stick })
    }
}

/// A located pose as a matrix; None for a non-finite or non-unit orientation (a
/// runtime's bad value never reaches the renderer).
fn pose_matrix(p: &xr::Posef) -> Option<glam::Mat4> {
    let q = glam::Quat::from_xyzw(p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w);
    let t = glam::Vec3::new(p.position.x, p.position.y, p.position.z);
    (q.is_finite() && t.is_finite() && (q.length() - 1.0).abs() < 1e-3)
        .then(|| glam::Mat4::from_rotation_translation(q.normalize(), t))
}

/// Where the object stands, and the grab that moves it: while the grab button is
/// held the object keeps its pose relative to the aim ray (picked up where it
/// is, carried rigidly); released, it stays where it was put, in the reference
/// space (LOCAL: it keeps its place in the room).
#[derive(Clone, Copy, Debug)]
pub struct Placement {
    pub space_from_scene: glam::Mat4,
    /// `aim_from_scene` while held.
    held: Option<glam::Mat4>,
    /// The object's scale relative to where it started.
    scale: f32,
}

impl Placement {
    pub fn new(space_from_scene: glam::Mat4) -> Self {
        Self { space_from_scene, held: None, scale: 1.0 }
    }

    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// The thumbstick while held, over `dt_s`: y pushes the object along the aim
    /// ray (−z of the aim) or pulls it in, x grows or shrinks it about its own
    /// origin. Bounded: never nearer than `MIN_REACH_M`, scale within `SCALE_RANGE`.
    fn steer(&mut self, aim_from_scene: glam::Mat4, stick: [f32; 2], dt_s: f32) -> glam::Mat4 {
        let dead = |v: f32| if v.is_finite() && v.abs() >= STICK_DEADZONE { v.clamp(-1.0, 1.0) } else { 0.0 };
        let (x, y) = (dead(stick[0]), dead(stick[1]));
        let dt = if dt_s.is_finite() { dt_s.clamp(0.0, 0.1) } else { 0.0 };
        let mut m = aim_from_scene;
        if y != 0.0 {
            let reach = -m.w_axis.z;
            let to = (reach + y * PUSH_M_PER_S * dt).max(MIN_REACH_M);
            m = glam::Mat4::from_translation(glam::Vec3::new(0.0, 0.0, reach - to)) * m;
        }
        if x != 0.0 {
            let want = (self.scale * (x * SCALE_PER_S * dt).exp()).clamp(SCALE_RANGE[0], SCALE_RANGE[1]);
            m *= glam::Mat4::from_scale(glam::Vec3::splat(want / self.scale));
            self.scale = want;
        }
        m
    }

    pub fn holding(&self) -> bool {
        self.held.is_some()
    }

    /// One frame's controller state. A grab starts on the first frame the button
    /// is held with the aim located; an aim lost while held leaves the object
    /// where it was until it is located again.
    pub fn update(&mut self, grab_held: bool, space_from_aim: Option<glam::Mat4>, stick: [f32; 2], dt_s: f32) {
        match (grab_held, space_from_aim, self.held) {
            (false, _, _) => self.held = None,
            (true, Some(a), None) => self.held = Some(a.inverse() * self.space_from_scene),
            (true, Some(a), Some(aim_from_scene)) => {
                let steered = self.steer(aim_from_scene, stick, dt_s);
                self.held = Some(steered);
                let m = a * steered;
                // Only a finite, invertible placement reaches the renderer.
                if m.is_finite() && m.determinant().abs() > 1e-12 {
                    self.space_from_scene = m;
                }
            }
            (true, None, _) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Picked up where it is, carried rigidly with the aim, left where released.
    #[test]
    fn a_grab_carries_the_object_rigidly_and_leaves_it_in_place() {
        use glam::{Mat4, Quat, Vec3};
        let start = Mat4::from_translation(Vec3::new(0.0, 0.0, -1.5));
        let mut p = Placement::new(start);
        let aim0 = Mat4::from_translation(Vec3::new(0.2, -0.3, -0.2));
        p.update(false, Some(aim0), [0.0; 2], 0.01);
        assert_eq!(p.space_from_scene, start, "no grab, no move");
        p.update(true, Some(aim0), [0.0; 2], 0.01);
        assert!(p.holding());
        assert!(p.space_from_scene.abs_diff_eq(start, 1e-6), "picking up does not move it");
        // The controller turns 90° to the left about its own origin: the object,
        // 1.3 m ahead of it, swings to its left.
        let aim1 = aim0 * Mat4::from_quat(Quat::from_rotation_y(std::f32::consts::FRAC_PI_2));
        p.update(true, Some(aim1), [0.0; 2], 0.01);
        let at = p.space_from_scene.transform_point3(Vec3::ZERO);
        assert!(at.abs_diff_eq(Vec3::new(0.2 - 1.3, 0.0, -0.2 + 0.2), 1e-5), "{at}");
        p.update(true, None, [0.0; 2], 0.01);
        assert!(p.space_from_scene.transform_point3(Vec3::ZERO).abs_diff_eq(at, 1e-6), "aim lost: stays");
        p.update(false, Some(aim0), [0.0; 2], 0.01);
        assert!(!p.holding());
        assert!(p.space_from_scene.transform_point3(Vec3::ZERO).abs_diff_eq(at, 1e-6), "released: stays");
        // A degenerate aim never reaches the renderer.
        p.update(true, Some(aim0), [0.0; 2], 0.01);
        p.update(true, Some(Mat4::from_scale(Vec3::ZERO)), [0.0; 2], 0.01);
        assert!(p.space_from_scene.transform_point3(Vec3::ZERO).abs_diff_eq(at, 1e-6));
    }

    /// The thumbstick while held: pushed 1 s at full deflection, the object goes
    /// 1 m further along the ray; pulled, it stops at the nearest reach; scaled,
    /// it stays within the range; a resting stick (dead zone) and NaN do nothing.
    #[test]
    fn the_thumbstick_pushes_pulls_and_scales_within_bounds() {
        use glam::{Mat4, Vec3};
        let mut p = Placement::new(Mat4::from_translation(Vec3::new(0.0, 0.0, -1.0)));
        let aim = Mat4::IDENTITY;
        p.update(true, Some(aim), [0.0; 2], 0.01);
        for _ in 0..100 {
            p.update(true, Some(aim), [0.1, f32::NAN], 0.01);
        }
        assert!(p.space_from_scene.abs_diff_eq(Mat4::from_translation(Vec3::new(0.0, 0.0, -1.0)), 1e-6));
        for _ in 0..100 {
            p.update(true, Some(aim), [0.0, 1.0], 0.01);
        }
        let z = p.space_from_scene.w_axis.z;
        assert!((z + 2.0).abs() < 1e-4, "pushed 1 m: {z}");
        for _ in 0..1000 {
            p.update(true, Some(aim), [0.0, -1.0], 0.01);
        }
        assert!((p.space_from_scene.w_axis.z + MIN_REACH_M).abs() < 1e-5, "{}", p.space_from_scene.w_axis.z);
        for _ in 0..10_000 {
            p.update(true, Some(aim), [1.0, 0.0], 0.01);
        }
        assert!((p.scale() - SCALE_RANGE[1]).abs() < 1e-3, "{}", p.scale());
        let size = p.space_from_scene.x_axis.truncate().length();
        assert!((size - SCALE_RANGE[1]).abs() < 1e-2, "the matrix carries the scale: {size}");
        for _ in 0..10_000 {
            p.update(true, Some(aim), [-1.0, 0.0], 1e9);
        }
        assert!((p.scale() - SCALE_RANGE[0]).abs() < 1e-5, "{}", p.scale());
    }

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
