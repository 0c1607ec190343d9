//! When the passthrough camera and the spatial-data permission may be used, and
//! when a lost camera is opened again: the Quest app's Android-free decisions
//! (`platform/android.rs` only asks the activity and acts), unit-tested on desktop.

use std::time::Duration;

/// Each of these grants the passthrough camera (Meta's `meta-quest/agentic-tools`
/// `skills/hz-unity-passthrough-camera-access/SKILL.md`: "Either permission …
/// CAMERA grants access to both the passthrough and avatar cameras;
/// HEADSET_CAMERA grants access only to the passthrough camera").
pub const CAMERA_PERMISSION: &str = "android.permission.CAMERA";
pub const HEADSET_CAMERA_PERMISSION: &str = "horizonos.permission.HEADSET_CAMERA";

/// Whether the passthrough camera may be opened, from each permission and
/// whether it is granted: either camera permission suffices (see
/// `HEADSET_CAMERA_PERMISSION`; Meta's Spatial SDK scanner sample asks for
/// HEADSET_CAMERA alone).
pub fn camera_permitted(states: &[(&str, bool)]) -> bool {
    states.iter().any(|&(p, granted)| granted && (p == CAMERA_PERMISSION || p == HEADSET_CAMERA_PERMISSION))
}

/// The permissions to ask for, from each wanted one and whether it is granted:
/// every missing one, except that the two camera permissions are asked for only
/// while neither is granted (asking for CAMERA with HEADSET_CAMERA granted would
/// ask for the avatar cameras too, for nothing this app uses).
pub fn permissions_to_request<'a>(states: &[(&'a str, bool)]) -> Vec<&'a str> {
    let camera = |p: &str| p == CAMERA_PERMISSION || p == HEADSET_CAMERA_PERMISSION;
    let have_camera = camera_permitted(states);
    // Wanted: not granted, and not a camera permission once one camera permission is.
    let wanted = |p: &str, granted: bool| !(granted || (have_camera && camera(p)));
    states.iter().filter(|&&(p, granted)| wanted(p, granted)).map(|&(p, _)| p).collect()
}

/// What the activity did while the app waits for the spatial-data permission.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActivityEvent {
    /// Paused or lost focus: the permission dialog came up over it.
    Left,
    /// Resumed or regained focus.
    Returned,
    /// Destroyed: the app is ending.
    Destroyed,
}

/// The wait for `com.oculus.permission.USE_SCENE` before the OpenXR instance is
/// created. Why wait: Meta's `meta-quest/Meta-OpenXR-SDK`
/// `Samples/XrSamples/XrPassthroughOcclusion/Src/XrPassthroughOcclusion.cpp`
/// warns "com.oculus.USE_SCENE permission should be requested before creation of
/// OpenXR instance. Application will not function correctly without it.", and its
/// Java activity starts the native code only once the permission is granted.
/// NativeActivity has no `onRequestPermissionsResult`, so the answer is read by
/// polling `checkSelfPermission` and the activity's lifecycle: the system dialog
/// pauses the activity (or takes its focus) and its end resumes it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SceneWait {
    /// USE_SCENE is granted now.
    pub granted: bool,
    /// It was asked for at this start (else there is nothing to wait for).
    pub asked: bool,
    /// The activity left (the dialog came up) since the request.
    pub left: bool,
    /// …and came back after leaving: the dialog was answered.
    pub returned: bool,
    pub destroyed: bool,
    /// Since the request.
    pub elapsed: Duration,
}

/// What to do next while waiting for USE_SCENE.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneWaitStep {
    /// Poll again.
    Wait,
    /// Create the OpenXR instance now, for this reason.
    Start(SceneStart),
    /// The activity was destroyed: end without starting OpenXR.
    Quit,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneStart {
    Granted,
    /// Not asked for (the request failed): nothing to wait for.
    NotAsked,
    /// The dialog was answered without granting it.
    Answered,
    /// No dialog came up: denied for good ("don't ask again") or not declared in
    /// the manifest — the system answers those at once, without a dialog.
    NoDialog,
    /// The dialog stayed up past `SceneWait::LIMIT`.
    TimedOut,
}

impl SceneWait {
    /// A dialog that has not come up by then will not come (the system shows it
    /// within a frame or two of the request; a denial for good shows none).
    pub const DIALOG_APPEARS: Duration = Duration::from_secs(5);
    /// The longest the app waits on an open dialog. Longer than the 20 s a quick
    /// reader needs: starting before the answer costs the headset's depth for the
    /// whole session (Meta's warning above), waiting costs nothing while the user
    /// reads; but an app must not hang unseen forever behind a dialog left open.
    pub const LIMIT: Duration = Duration::from_secs(60);

    /// Fold one activity event in: coming back counts only after leaving (the
    /// activity's first resume and focus arrive after the request, before any
    /// dialog).
    pub fn on_event(&mut self, e: ActivityEvent) {
        match e {
            ActivityEvent::Left => self.left = true,
            ActivityEvent::Returned => self.returned |= self.left,
            ActivityEvent::Destroyed => self.destroyed = true,
        }
    }

    /// Whether to keep waiting (see `SceneStart` for each reason to stop).
    pub fn step(&self) -> SceneWaitStep {
        if self.destroyed {
            SceneWaitStep::Quit
        } else if self.granted {
            SceneWaitStep::Start(SceneStart::Granted)
        } else if !self.asked {
            SceneWaitStep::Start(SceneStart::NotAsked)
        } else if self.returned {
            SceneWaitStep::Start(SceneStart::Answered)
        } else if !self.left && self.elapsed >= Self::DIALOG_APPEARS {
            SceneWaitStep::Start(SceneStart::NoDialog)
        } else if self.elapsed >= Self::LIMIT {
            SceneWaitStep::Start(SceneStart::TimedOut)
        } else {
            SceneWaitStep::Wait
        }
    }
}

/// When to reopen the passthrough camera after it was disconnected (another app
/// or the system took it) or hit a device error: 1 s after the first loss,
/// doubling to 30 s while it keeps failing; a camera that streamed for a minute
/// had recovered, so its next loss starts again at 1 s. Why reopen at all: a
/// disconnected ACameraDevice stays dead (Android's `onDisconnected`: "the camera
/// device is no longer available for use"), and calibration should resume when
/// the camera comes back, not wait for the app's next start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReopenBackoff {
    failures: u32,
}

impl ReopenBackoff {
    pub const FIRST: Duration = Duration::from_secs(1);
    pub const MAX: Duration = Duration::from_secs(30);
    /// Streaming this long means the camera had recovered.
    pub const RECOVERED: Duration = Duration::from_secs(60);

    /// The camera was lost, or failed to open, after streaming for `streamed`
    /// (zero when it never opened): how long to wait before the next try.
    pub fn lost(&mut self, streamed: Duration) -> Duration {
        if streamed >= Self::RECOVERED {
            self.failures = 0;
        }
        let delay = Self::FIRST.saturating_mul(1u32 << self.failures.min(16)).min(Self::MAX);
        self.failures = self.failures.saturating_add(1);
        delay
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Either camera permission opens the passthrough camera; the pair is asked for
    /// only while neither is granted.
    #[test]
    fn either_camera_permission_suffices() {
        const SCENE: &str = "com.oculus.permission.USE_SCENE";
        let states = |camera: bool, headset: bool, scene: bool| {
            [(CAMERA_PERMISSION, camera), (HEADSET_CAMERA_PERMISSION, headset), (SCENE, scene)]
        };
        assert!(camera_permitted(&states(true, false, false)));
        assert!(camera_permitted(&states(false, true, false)));
        assert!(!camera_permitted(&states(false, false, true)));
        assert_eq!(
            permissions_to_request(&states(false, false, false)),
            [CAMERA_PERMISSION, HEADSET_CAMERA_PERMISSION, SCENE]
        );
        assert_eq!(permissions_to_request(&states(false, true, false)), [SCENE]);
        assert_eq!(permissions_to_request(&states(true, false, true)), Vec::<&str>::new());
    }

    /// The wait for USE_SCENE before the OpenXR instance: over at once when granted
    /// or not asked for; over when the dialog was answered (the activity left and
    /// came back); a dialog that never comes is waited for `DIALOG_APPEARS`, an
    /// open one up to `LIMIT`; Destroy ends the app from any state.
    #[test]
    fn scene_permission_wait() {
        let secs = Duration::from_secs;
        let asked = SceneWait { asked: true, ..Default::default() };
        assert_eq!(asked.step(), SceneWaitStep::Wait);
        assert_eq!(SceneWait { granted: true, ..asked }.step(), SceneWaitStep::Start(SceneStart::Granted));
        assert_eq!(SceneWait::default().step(), SceneWaitStep::Start(SceneStart::NotAsked));
        // The activity's own first resume, before any dialog, is not an answer.
        let mut w = asked;
        w.on_event(ActivityEvent::Returned);
        assert_eq!(w.step(), SceneWaitStep::Wait);
        w.on_event(ActivityEvent::Left);
        w.elapsed = secs(30);
        assert_eq!(w.step(), SceneWaitStep::Wait, "the dialog is up: the user is reading");
        w.on_event(ActivityEvent::Returned);
        assert_eq!(w.step(), SceneWaitStep::Start(SceneStart::Answered));
        // No dialog: the system answered at once.
        let w = SceneWait { elapsed: SceneWait::DIALOG_APPEARS - Duration::from_millis(100), ..asked };
        assert_eq!(w.step(), SceneWaitStep::Wait);
        let w = SceneWait { elapsed: SceneWait::DIALOG_APPEARS, ..asked };
        assert_eq!(w.step(), SceneWaitStep::Start(SceneStart::NoDialog));
        // A dialog left open.
        let w = SceneWait { left: true, elapsed: SceneWait::LIMIT, ..asked };
        assert_eq!(w.step(), SceneWaitStep::Start(SceneStart::TimedOut));
        let mut w = SceneWait { granted: true, ..asked };
        w.on_event(ActivityEvent::Destroyed);
        assert_eq!(w.step(), SceneWaitStep::Quit);
    }

    /// 1, 2, 4, 8, 16, 30, 30 s while the camera keeps failing; a camera that
    /// streamed for a minute starts again at 1 s.
    #[test]
    fn reopen_backoff_doubles_to_thirty_seconds() {
        let mut b = ReopenBackoff::default();
        let delays: Vec<u64> = (0..7).map(|_| b.lost(Duration::from_secs(2)).as_secs()).collect();
        assert_eq!(delays, [1, 2, 4, 8, 16, 30, 30]);
        for _ in 0..100 {
            assert_eq!(b.lost(Duration::ZERO), ReopenBackoff::MAX, "no overflow");
        }
        assert_eq!(b.lost(ReopenBackoff::RECOVERED), ReopenBackoff::FIRST);
        assert_eq!(b.lost(Duration::ZERO).as_secs(), 2);
    }
}
