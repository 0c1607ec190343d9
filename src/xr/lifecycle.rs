//! The application side of the OpenXR session state machine (spec 9.3, "Session
//! Lifecycle"): what the app must do on each XrEventDataSessionStateChanged.
//! Pure logic, so every transition — loss and exit included — is unit-tested
//! without a runtime; the frame loop (`xr::run`) carries out the actions.

use openxr::SessionState;

/// What the frame loop must do after a state change.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// Nothing beyond bookkeeping.
    None,
    /// READY: call xrBeginSession, start the frame loop.
    Begin,
    /// STOPPING: stop the frame loop, call xrEndSession.
    End,
    /// EXITING: destroy the session and leave (the runtime or the user asked).
    Exit,
    /// LOSS_PENDING: the session is lost (device gone); destroy it and leave.
    Lost,
}

/// Why the loop ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EndReason {
    Exited,
    /// The app's stop request while the session was not running (IDLE): left
    /// without waiting for EXITING, which a paused session may never reach.
    Stopped,
    SessionLost,
    InstanceLost,
}

#[derive(Debug, Default)]
pub struct Lifecycle {
    state: Option<SessionState>,
    /// Between xrBeginSession and xrEndSession: xrWaitFrame may be called.
    pub running: bool,
    /// Every state reached, in order (logged and reported).
    pub history: Vec<SessionState>,
}

impl Lifecycle {
    pub fn state(&self) -> Option<SessionState> {
        self.state
    }

    /// Record `state` and say what to do. Unknown states (a newer runtime) are
    /// logged and ignored, as the spec asks of applications.
    pub fn on_state(&mut self, state: SessionState) -> Action {
        self.state = Some(state);
        self.history.push(state);
        match state {
            SessionState::READY => {
                self.running = true;
                Action::Begin
            }
            SessionState::STOPPING => {
                self.running = false;
                Action::End
            }
            SessionState::EXITING => {
                self.running = false;
                Action::Exit
            }
            SessionState::LOSS_PENDING => {
                self.running = false;
                Action::Lost
            }
            SessionState::IDLE | SessionState::SYNCHRONIZED | SessionState::VISIBLE | SessionState::FOCUSED => {
                Action::None
            }
            other => {
                log::warn!("OpenXR: unknown session state {other:?} ignored");
                Action::None
            }
        }
    }

    /// Frames are submitted (layers drawn) only while VISIBLE or FOCUSED; in
    /// SYNCHRONIZED the loop runs but submits no layers (spec 9.3).
    pub fn visible(&self) -> bool {
        matches!(self.state, Some(SessionState::VISIBLE) | Some(SessionState::FOCUSED))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use SessionState as S;

    fn run(states: &[SessionState]) -> (Vec<Action>, Lifecycle) {
        let mut l = Lifecycle::default();
        let actions = states.iter().map(|&s| l.on_state(s)).collect();
        (actions, l)
    }

    #[test]
    fn full_lifecycle_begin_end_exit() {
        let (a, l) = run(&[
            S::IDLE,
            S::READY,
            S::SYNCHRONIZED,
            S::VISIBLE,
            S::FOCUSED,
            S::VISIBLE,
            S::SYNCHRONIZED,
            S::STOPPING,
            S::IDLE,
            S::EXITING,
        ]);
        use Action::*;
        assert_eq!(a, vec![None, Begin, None, None, None, None, None, End, None, Exit]);
        assert!(!l.running);
        assert_eq!(l.history.len(), 10);
    }

    #[test]
    fn visibility_follows_state() {
        let mut l = Lifecycle::default();
        l.on_state(S::READY);
        assert!(l.running && !l.visible());
        l.on_state(S::SYNCHRONIZED);
        assert!(!l.visible());
        l.on_state(S::VISIBLE);
        assert!(l.visible());
        l.on_state(S::FOCUSED);
        assert!(l.visible());
        l.on_state(S::STOPPING);
        assert!(!l.running && !l.visible());
    }

    #[test]
    fn loss_stops_the_loop() {
        let (a, l) = run(&[S::IDLE, S::READY, S::SYNCHRONIZED, S::VISIBLE, S::FOCUSED, S::LOSS_PENDING]);
        assert_eq!(a.last(), Some(&Action::Lost));
        assert!(!l.running);
    }

    #[test]
    fn a_stopped_session_can_begin_again() {
        // STOPPING → IDLE → READY (the runtime wants the app back, no exit).
        let (a, l) = run(&[S::READY, S::STOPPING, S::IDLE, S::READY]);
        assert_eq!(a, vec![Action::Begin, Action::End, Action::None, Action::Begin]);
        assert!(l.running);
    }

    #[test]
    fn unknown_states_are_ignored() {
        let (a, _) = run(&[SessionState::from_raw(1000)]);
        assert_eq!(a, vec![Action::None]);
    }
}
