//! The test runtime's configuration, read from `BA_XR_*` environment variables when
//! an instance is created (the Khronos loader gives a runtime no other channel).
//!
//! | variable | meaning | default |
//! |---|---|---|
//! | `BA_XR_PROFILE` | `quest3`: the defaults below become a Meta Quest 3's as Meta documents it (see `Profile`); other variables still override | none |
//! | `BA_XR_TIME_ORIGIN_S` | XrTime at instance creation, s (headsets count from boot) | 259200 (3 days) |
//! | `BA_XR_DISPLAY_HZ` | display refresh rate at start | 90 |
//! | `BA_XR_REFRESH_RATES` | rates XR_FB_display_refresh_rate offers | 72,90,120 |
//! | `BA_XR_EYE_SIZE` | recommended image rect per eye, `WxH` | 1680x1760 |
//! | `BA_XR_EXTENSIONS` | optional extensions offered: `passthrough`, `refresh_rate`, `space_warp`, `convert_timespec`, `env_depth` (XR_META_environment_depth), `touch_plus` (XR_META_touch_controller_plus), or `none` | refresh_rate,space_warp,convert_timespec (quest3: all) |
//! | `BA_XR_ENV_DEPTH_DENIALS` | refuse this many environment-depth provider creations (XR_ERROR_NOT_PERMITTED_PASSTHROUGH_FB: the spatial-data permission not yet granted) | 0 |
//! | `BA_XR_BLEND_MODES` | environment blend modes: `opaque`, `alpha_blend`, `additive` (`opaque` alone: Quest-like, passthrough only through XR_FB_passthrough) | opaque,alpha_blend |
//! | `BA_XR_SCRIPT` | session events at frame numbers: `exit@N`, `loss@N`, `instance_loss@N`, `unfocus@N`, `focus@N`, `pause@N` (the session is stopped and stays IDLE after xrEndSession, as an Android app put in the background: no EXITING), `untracked@N..M` (xrLocateViews for frames N to M − 1 without ORIENTATION_VALID/POSITION_VALID: zero quaternions on even frames, a plausible wrong pose on odd ones), `press:PATH@N` (the controller component PATH, e.g. `/user/hand/right/input/a/click`, reads true in the xrSyncActions calls made while frame N is produced; `@N..M`: held for frames N to M − 1) | none |
//! | `BA_XR_SCRIPT` `aim:X;Y;Z;YAW;PITCH@N` | the right controller's grip and aim pose in LOCAL from frame N on (m, degrees; yaw about +Y, pitch about +X); untracked before the first | none |
//! | `BA_XR_SCRIPT` `stick:X;Y@N..M` | the right thumbstick deflected (each in [−1, 1]) from frame N to M − 1 | centred |
//! | `BA_XR_CONTROLLER` | the controllers: `touch` (answer to Oculus Touch bindings, else the simple controller's), `touch_plus` (Meta Touch Plus bindings, else Touch's, else the simple controller's), `simple` (the Khronos simple controller only) or `none` | touch |
//! | `BA_XR_PNG_DIR`, `BA_XR_PNG_FRAMES` | write the submitted layers of these frames (0-based `xrEndFrame` count) to PNG | none |
//! | `BA_XR_REPORT` | JSON lines: one per state change and per `xrEndFrame` | none |
//! | `BA_XR_HEAD` | head path: `sway` (±4 cm at 0.5 Hz, ±3° yaw) or `still` | sway |
//! | `BA_XR_DEBUG` | set: log every function name xrGetInstanceProcAddr cannot resolve | unset |

use std::path::PathBuf;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// The runtime asks the application to exit (as the user quitting from the system UI).
    Exit,
    /// Session loss (device unplugged): XR_SESSION_STATE_LOSS_PENDING.
    Loss,
    /// XrEventDataInstanceLossPending.
    InstanceLoss,
    /// FOCUSED → VISIBLE (a system dialog over the app) ...
    Unfocus,
    /// ... and back.
    Focus,
    /// STOPPING, then IDLE after xrEndSession, and nothing more (spec "Session
    /// Lifecycle": a session "temporarily paused in the background" stays IDLE).
    Pause,
    /// Views not located (no valid bits) from this frame up to the given one.
    Untracked(u64),
}

/// A device whose documented behaviour the runtime imitates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    /// Meta Quest 3: XR_FB_passthrough, space warp, XR_META_environment_depth,
    /// display refresh rates 72, 80, 90 and 120 Hz at 72 Hz by default (Meta's
    /// display refresh rate docs: "The default display refresh rate for apps is 72
    /// Hz"), 1680×1760 recommended per eye; OPAQUE and ALPHA_BLEND both listed,
    /// the harder case for the app's choice: Meta's camera API still needs
    /// passthrough running through XR_FB_passthrough.
    Quest3,
}

/// The controllers the runtime has (`BA_XR_CONTROLLER`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Controller {
    Touch,
    /// Quest 3's Touch Plus: its own profile where the app suggested it, else the
    /// Touch bindings (a Meta runtime maps them onto Touch Plus controllers).
    TouchPlus,
    Simple,
    None,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Head {
    Sway,
    Still,
}

#[derive(Clone, Debug)]
pub struct Config {
    pub display_hz: f32,
    pub refresh_rates: Vec<f32>,
    pub eye_size: (u32, u32),
    pub passthrough: bool,
    pub refresh_rate: bool,
    pub space_warp: bool,
    /// XR_KHR_convert_timespec_time (XrTime ↔ CLOCK_MONOTONIC).
    pub convert_timespec: bool,
    /// XR_META_environment_depth (the depth of a known plane, `env_depth.rs`).
    pub env_depth: bool,
    /// XR_META_touch_controller_plus (its interaction profile path is valid only
    /// with the extension enabled).
    pub touch_plus: bool,
    pub env_depth_denials: u32,
    pub blend_modes: Vec<openxr_sys::EnvironmentBlendMode>,
    pub script: Vec<(u64, Command)>,
    /// Scripted button presses: (first frame, frame after the last, component path).
    pub presses: Vec<(u64, u64, String)>,
    /// Scripted right-controller poses in LOCAL (`aim:X;Y;Z;YAW;PITCH@N`, metres and
    /// degrees): from frame N on, until the next; before the first, not tracked.
    pub aims: Vec<(u64, [f32; 5])>,
    /// Scripted right thumbstick deflections (`stick:X;Y@N..M`, each in [−1, 1]):
    /// held from frame N to M − 1, centred otherwise.
    pub sticks: Vec<(u64, u64, [f32; 2])>,
    pub controller: Controller,
    pub png_dir: Option<PathBuf>,
    pub png_frames: Vec<u64>,
    pub report: Option<PathBuf>,
    pub head: Head,
    pub profile: Option<Profile>,
    /// XrTime at instance creation (s).
    pub time_origin_s: f64,
}

fn var(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|s| !s.trim().is_empty())
}

impl Config {
    /// Read the environment; a malformed value is an error naming the variable.
    pub fn from_env() -> Result<Self, String> {
        let profile = match var("BA_XR_PROFILE").as_deref() {
            None => None,
            Some("quest3") => Some(Profile::Quest3),
            Some(other) => return Err(format!("BA_XR_PROFILE: unknown profile {other:?} (known: quest3)")),
        };
        let quest3 = profile == Some(Profile::Quest3);
        let display_hz = match var("BA_XR_DISPLAY_HZ") {
            Some(s) => s
                .trim()
                .parse::<f32>()
                .ok()
                .filter(|v| v.is_finite() && *v > 0.0 && *v <= 1000.0)
                .ok_or(format!("BA_XR_DISPLAY_HZ={s:?}: expected a refresh rate in Hz, e.g. 90"))?,
            None if quest3 => 72.0,
            None => 90.0,
        };
        let refresh_rates = match var("BA_XR_REFRESH_RATES") {
            Some(s) => s
                .split(',')
                .map(|r| r.trim().parse::<f32>().ok().filter(|v| v.is_finite() && *v > 0.0))
                .collect::<Option<Vec<_>>>()
                .ok_or(format!("BA_XR_REFRESH_RATES={s:?}: expected comma-separated rates in Hz"))?,
            None if quest3 => vec![72.0, 80.0, 90.0, 120.0],
            None => vec![72.0, 90.0, 120.0],
        };
        let eye_size = match var("BA_XR_EYE_SIZE") {
            Some(s) => {
                let parsed =
                    s.split_once(['x', 'X']).and_then(|(w, h)| Some((w.trim().parse().ok()?, h.trim().parse().ok()?)));
                parsed
                    .filter(|&(w, h): &(u32, u32)| (8..=8192).contains(&w) && (8..=8192).contains(&h))
                    .ok_or(format!("BA_XR_EYE_SIZE={s:?}: expected WxH between 8 and 8192"))?
            }
            None => (1680, 1760),
        };
        let extensions = var("BA_XR_EXTENSIONS").unwrap_or_else(|| {
            // Without a profile: a generic runtime, passthrough by ALPHA_BLEND only
            // (the path Debian's core validation layer accepts: it rejects
            // XrCompositionLayerPassthroughFB).
            if quest3 {
                "passthrough,refresh_rate,space_warp,convert_timespec,env_depth,touch_plus"
            } else {
                "refresh_rate,space_warp,convert_timespec"
            }
            .into()
        });
        let mut ext = (false, false, false, false);
        let (mut env_depth, mut touch_plus) = (false, false);
        for e in extensions.split(',').map(str::trim) {
            match e {
                "passthrough" => ext.0 = true,
                "refresh_rate" => ext.1 = true,
                "space_warp" => ext.2 = true,
                "convert_timespec" => ext.3 = true,
                "env_depth" => env_depth = true,
                "touch_plus" => touch_plus = true,
                "none" => {}
                other => return Err(format!("BA_XR_EXTENSIONS: unknown extension {other:?}")),
            }
        }
        let mut blend_modes = vec![];
        // Default: both, so the app takes ALPHA_BLEND — the passthrough path that
        // Debian's core validation layer (1.0.20) accepts (it rejects the FB
        // passthrough layer type).
        for b in var("BA_XR_BLEND_MODES").unwrap_or_else(|| "opaque,alpha_blend".into()).split(',').map(str::trim) {
            blend_modes.push(match b {
                "opaque" => openxr_sys::EnvironmentBlendMode::OPAQUE,
                "alpha_blend" => openxr_sys::EnvironmentBlendMode::ALPHA_BLEND,
                "additive" => openxr_sys::EnvironmentBlendMode::ADDITIVE,
                other => return Err(format!("BA_XR_BLEND_MODES: unknown blend mode {other:?}")),
            });
        }
        let mut script = vec![];
        let mut presses = vec![];
        let mut aims = vec![];
        let mut sticks = vec![];
        if let Some(s) = var("BA_XR_SCRIPT") {
            for item in s.split(',').map(str::trim) {
                let (what, at) = item.rsplit_once('@').ok_or(format!("BA_XR_SCRIPT: {item:?} is not COMMAND@FRAME"))?;
                if let Some(values) = what.strip_prefix("stick:") {
                    let v: Vec<f32> = values.split(';').filter_map(|x| x.trim().parse().ok()).collect();
                    let range =
                        at.split_once("..").and_then(|(a, b)| Some((a.parse::<u64>().ok()?, b.parse::<u64>().ok()?)));
                    match (v.as_slice(), range) {
                        ([x, y], Some((from, to))) if from < to && x.abs() <= 1.0 && y.abs() <= 1.0 => {
                            sticks.push((from, to, [*x, *y]))
                        }
                        _ => return Err(format!("BA_XR_SCRIPT: {item:?}: expected stick:X;Y@N..M, |X|, |Y| ≤ 1")),
                    }
                    continue;
                }
                if let Some(values) = what.strip_prefix("aim:") {
                    let v: Vec<f32> = values.split(';').filter_map(|x| x.trim().parse().ok()).collect();
                    let frame = at.parse::<u64>().ok();
                    match (v.as_slice(), frame) {
                        ([x, y, z, yaw, pitch], Some(n)) if v.iter().all(|x| x.is_finite()) => {
                            aims.push((n, [*x, *y, *z, *yaw, *pitch]))
                        }
                        _ => return Err(format!("BA_XR_SCRIPT: {item:?}: expected aim:X;Y;Z;YAW;PITCH@N")),
                    }
                    continue;
                }
                if let Some(path) = what.strip_prefix("press:") {
                    // `@N`: frame N only; `@N..M`: held from N to M − 1.
                    let (from, to) = match at.split_once("..") {
                        Some((a, b)) => (a.parse::<u64>().ok(), b.parse::<u64>().ok()),
                        None => (at.parse::<u64>().ok(), at.parse::<u64>().ok().map(|a| a + 1)),
                    };
                    let (Some(from), Some(to)) = (from, to) else {
                        return Err(format!("BA_XR_SCRIPT: {item:?}: expected press:PATH@N or @N..M"));
                    };
                    if from >= to {
                        return Err(format!("BA_XR_SCRIPT: {item:?}: expected N < M"));
                    }
                    presses.push((from, to, path.to_string()));
                    continue;
                }
                let cmd = match what {
                    "exit" => Command::Exit,
                    "loss" => Command::Loss,
                    "instance_loss" => Command::InstanceLoss,
                    "unfocus" => Command::Unfocus,
                    "focus" => Command::Focus,
                    "pause" => Command::Pause,
                    "untracked" => {
                        let (from, to) = at
                            .split_once("..")
                            .and_then(|(a, b)| Some((a.parse::<u64>().ok()?, b.parse::<u64>().ok()?)))
                            .filter(|(a, b)| a < b)
                            .ok_or(format!("BA_XR_SCRIPT: {item:?}: expected untracked@N..M with N < M"))?;
                        script.push((from, Command::Untracked(to)));
                        continue;
                    }
                    other => return Err(format!("BA_XR_SCRIPT: unknown command {other:?}")),
                };
                let at: u64 = at.parse().map_err(|_| format!("BA_XR_SCRIPT: {item:?}: frame is not a number"))?;
                script.push((at, cmd));
            }
        }
        let png_frames = match var("BA_XR_PNG_FRAMES") {
            Some(s) => s
                .split(',')
                .map(|f| f.trim().parse::<u64>().ok())
                .collect::<Option<Vec<_>>>()
                .ok_or(format!("BA_XR_PNG_FRAMES={s:?}: expected comma-separated frame numbers"))?,
            None => vec![],
        };
        let env_depth_denials = match var("BA_XR_ENV_DEPTH_DENIALS") {
            Some(s) => s.trim().parse().map_err(|_| format!("BA_XR_ENV_DEPTH_DENIALS={s:?}: expected a count"))?,
            None => 0,
        };
        let time_origin_s = match var("BA_XR_TIME_ORIGIN_S") {
            Some(s) => s
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 1.0 && *v <= 1e8)
                .ok_or(format!("BA_XR_TIME_ORIGIN_S={s:?}: expected seconds between 1 and 1e8"))?,
            None => 3.0 * 86_400.0,
        };
        let head = match var("BA_XR_HEAD").as_deref() {
            None | Some("sway") => Head::Sway,
            Some("still") => Head::Still,
            Some(other) => return Err(format!("BA_XR_HEAD: unknown head path {other:?}")),
        };
        let controller = match var("BA_XR_CONTROLLER").as_deref() {
            None | Some("touch") => Controller::Touch,
            Some("touch_plus") => Controller::TouchPlus,
            Some("simple") => Controller::Simple,
            Some("none") => Controller::None,
            Some(other) => return Err(format!("BA_XR_CONTROLLER: unknown controller {other:?}")),
        };
        Ok(Self {
            display_hz,
            refresh_rates,
            eye_size,
            passthrough: ext.0,
            refresh_rate: ext.1,
            space_warp: ext.2,
            convert_timespec: ext.3,
            env_depth,
            touch_plus,
            env_depth_denials,
            blend_modes,
            script,
            presses,
            aims,
            sticks,
            controller,
            png_dir: var("BA_XR_PNG_DIR").map(PathBuf::from),
            png_frames,
            report: var("BA_XR_REPORT").map(PathBuf::from),
            head,
            profile,
            time_origin_s,
        })
    }
}
