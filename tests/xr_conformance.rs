//! The XR app against what the OpenXR specification and Meta's documentation say a
//! headset does, on the project's test runtime made to do it: a Quest 3 profile
//! (XR_FB_passthrough beside a listed ALPHA_BLEND, 72–120 Hz, space warp, depth),
//! tracking lost for a while (view flags cleared, values not to be read), a session
//! paused in the background that never reaches EXITING while the app is asked to
//! stop, and an XrTime epoch of days. Each of these once failed on the app.

#[path = "common/xr.rs"]
mod harness;

use blind_augment::scene::Scene;
use blind_augment::worker::ModelChannel;
use blind_augment::xr::{EndReason, FrameGeometry};
use glam::{Mat4, Vec3};
use harness::*;
use openxr::SessionState as S;

/// XR_SWAPCHAIN_USAGE_SAMPLED_BIT (OpenXR registry value).
const USAGE_SAMPLED: u64 = 0x20;

/// A runtime that behaves as a Quest 3 is documented to: the app runs
/// XR_FB_passthrough (Meta's camera API needs it) although ALPHA_BLEND is listed,
/// submits its projection layer with straight alpha as Meta's XrPassthrough
/// sample does, asks for 72 Hz (Meta's passthrough guidance) and creates the space
/// warp swapchains the compositor samples with SAMPLED usage (XR_FB_space_warp:
/// "should be created with XR_SWAPCHAIN_USAGE_SAMPLED_BIT | …"). Vulkan
/// validation on; core validation off (Debian's layer rejects the passthrough
/// layer type, see tests/xr.rs).
#[test]
fn quest3_profile_passthrough_layer_at_72_hz() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let hz = blind_augment::xr::PASSTHROUGH_DISPLAY_HZ.to_string();
    let env = [("BA_XR_PROFILE", "quest3"), ("BA_XR_DISPLAY_HZ", "90"), ("BA_TEST_APP_HZ", hz.as_str())];
    let Some(run) = run_xr_vulkan_validated("quest3", &env, 40, &models) else { return };
    assert_clean(&run, false);
    let s = &run.summary;
    assert_eq!(s.end, EndReason::Exited);
    assert_eq!(s.blend_mode, openxr::EnvironmentBlendMode::OPAQUE, "XR_FB_passthrough, not ALPHA_BLEND");
    assert!(s.passthrough && s.space_warp && s.env_depth);
    assert_eq!(s.display_hz, Some(72.0));
    let frames = frames_of(&run.report);
    let drawn: Vec<_> = frames.iter().filter(|f| !f["layers"].as_array().unwrap().is_empty()).collect();
    assert!(drawn.len() >= 40);
    for f in drawn {
        let l = f["layers"].as_array().unwrap();
        assert_eq!((&l[0]["type"], &l[1]["type"]), (&"passthrough_fb".into(), &"projection".into()), "{f}");
        assert_eq!((&l[1]["source_alpha"], &l[1]["unpremultiplied"]), (&true.into(), &true.into()), "{f}");
    }
    // Swapchains: the colour array, the status panel's (one layer), then the space
    // warp's motion vectors and depth.
    let chains: Vec<_> = run.report.iter().filter(|v| v["event"] == "swapchain").collect();
    let warp: Vec<_> = chains
        .iter()
        .filter(|c| c["width"].as_u64() != Some(EYE.0 as u64) && c["array_size"].as_u64() == Some(2))
        .collect();
    assert_eq!(warp.len(), 2, "{chains:?}");
    for c in warp {
        let usage = c["usage"].as_u64().expect("usage reported");
        assert!(usage & USAGE_SAMPLED != 0, "space-warp swapchain without SAMPLED usage: {c}");
    }
}

/// Tracking lost for ten frames: xrLocateViews clears ORIENTATION_VALID and
/// POSITION_VALID and leaves zero quaternions or a plausible wrong pose (values
/// the spec forbids the app to read). The app keeps running, shows the last tracked views again (valid
/// poses in every submitted layer: the runtime refuses an invalid one with
/// XR_ERROR_POSE_INVALID), marks those frames untracked for the calibration, and
/// takes the new views when tracking returns. Both validation layers on.
#[test]
fn lost_tracking_shows_the_last_tracked_views() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let env = [("BA_XR_SCRIPT", "untracked@10..20")];
    let Some(run) = run_xr("untracked", &env, 40, true, &models) else { return };
    assert_clean(&run, true);
    let s = &run.summary;
    assert_eq!((s.end, s.frames_rendered), (EndReason::Exited, 40));
    assert_eq!(s.frames_untracked, 10);
    let untracked: Vec<_> = run.records.iter().filter(|r| !r.views_tracked).collect();
    assert_eq!(untracked.len(), 10);
    let first = untracked[0].index as usize;
    assert!(first > 0 && run.records[first - 1].views_tracked);
    let last_tracked = &run.records[first - 1].views;
    for r in &untracked {
        assert_eq!(&r.views, last_tracked, "frame {}: not the last tracked views", r.index);
    }
    // Tracking back: new views (the runtime's head sways, so they differ).
    let after = &run.records[first + 10];
    assert!(after.views_tracked && after.views[0] != last_tracked[0]);
}

/// Android's usual shutdown: the app goes to the background (the runtime walks
/// the session to STOPPING; after xrEndSession it stays IDLE — spec "Session
/// Lifecycle": a session "temporarily paused in the background" stays IDLE — and
/// never reaches EXITING), then onDestroy asks the loop to stop and waits for it.
/// The loop must leave from IDLE; waiting for EXITING would hang (an ANR on
/// Android). A watchdog fails the test after 60 s instead of hanging CI.
#[test]
fn stop_request_while_paused_in_idle_leaves() {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let models = ModelChannel::new(model(0.4)).expect("model");
        let after = Some(std::time::Duration::from_secs(2));
        let run = run_xr_until("paused", &[("BA_XR_SCRIPT", "pause@10")], None, after, (true, true), &models);
        let _ = tx.send(run);
    });
    let run = match rx.recv_timeout(std::time::Duration::from_secs(60)) {
        Ok(run) => run,
        Err(_) => {
            // Past libtest's output capture (the process ends here).
            use std::io::Write as _;
            let _ = writeln!(
                std::io::stderr(),
                "stop_request_while_paused_in_idle_leaves: the XR loop did not leave IDLE within 60 s of a stop request"
            );
            std::process::exit(101);
        }
    };
    let Some(run) = run else { return };
    assert_clean(&run, true);
    let s = &run.summary;
    assert_eq!(s.end, EndReason::Stopped);
    assert_eq!(s.states.last(), Some(&S::IDLE), "{:?}", s.states);
    assert!(!s.states.contains(&S::EXITING));
    assert!(run.report.iter().any(|v| v["event"] == "session_destroyed"), "the session was destroyed");
    assert!(!run.report.iter().any(|v| v["event"] == "request_exit"), "xrRequestExitSession needs a running session");
}

/// XrTime counts from the runtime's epoch (the test runtime's: 3 days, as a
/// headset counts from boot). The scene's animation runs on time since the
/// session started: frames rendered at an epoch of days give the same geometry —
/// node transforms and their motion between frames — as at an epoch of seconds,
/// to f32 rounding of the transforms themselves (1e-5 m / 1e-5 of a matrix entry).
#[test]
fn animation_time_is_exact_at_an_epoch_of_days() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let Some(run) = run_xr("epoch", &[], 20, true, &models) else { return };
    assert_clean(&run, true);
    let day_ns = 86_400_000_000_000i64;
    let r0 = &run.records[0];
    assert!(r0.time_origin_ns > 2 * day_ns, "the runtime's default epoch is days ({} ns)", r0.time_origin_ns);
    let scene = Scene::from_glb(TOY, "assets/toy.glb").expect("scene");
    assert!(scene.duration_s > 0.0, "the bundled scene animates");
    let place = Mat4::from_translation(Vec3::new(0.0, 0.0, -0.6));
    let eyes = [blind_augment::xr::eye_from_view(&r0.views[0], EYE.0, EYE.1).unwrap().0; 2];
    let period = r0.predicted_display_period_ns;
    let mut moved = 0;
    for k in 1..run.records.len() {
        let (a, b) = (&run.records[k - 1], &run.records[k]);
        let prev = Some((a.predicted_display_time_ns, eyes));
        let at_days = FrameGeometry::new(
            &scene,
            (place, place),
            eyes,
            prev,
            b.predicted_display_time_ns,
            period,
            b.time_origin_ns,
        );
        // The same frame with the epoch moved to 1 s.
        let shift = b.time_origin_ns - 1_000_000_000;
        let prev_s = Some((a.predicted_display_time_ns - shift, eyes));
        let at_secs = FrameGeometry::new(
            &scene,
            (place, place),
            eyes,
            prev_s,
            b.predicted_display_time_ns - shift,
            period,
            b.time_origin_ns - shift,
        );
        let (g, h) = (&at_days.gbuffer, &at_secs.gbuffer);
        for (m, n) in g
            .pose
            .world_from_nodes
            .iter()
            .zip(&h.pose.world_from_nodes)
            .chain(g.prev_pose.world_from_nodes.iter().zip(&h.prev_pose.world_from_nodes))
        {
            assert!(m.abs_diff_eq(*n, 1e-5), "frame {k}: {m:?} vs {n:?}");
        }
        moved +=
            g.pose.world_from_nodes.iter().zip(&g.prev_pose.world_from_nodes).any(|(m, n)| !m.abs_diff_eq(*n, 1e-6))
                as usize;
    }
    assert!(moved >= run.records.len() - 2, "the animation moves every frame ({moved} of {})", run.records.len() - 1);
}
