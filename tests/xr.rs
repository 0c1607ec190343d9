//! The XR app end to end through the real Khronos loader (Debian's
//! libopenxr-loader1) on the project's headless test runtime (tests/xr-runtime),
//! with the Khronos core validation layer (openxr-layer-corevalidation) and the
//! Vulkan validation layer on: any message from either fails the test.
//!
//! One exception, stated where it applies: Debian's core validation layer (1.0.20)
//! rejects XrCompositionLayerPassthroughFB, a valid layer type of XR_FB_passthrough
//! ("XrCompositionLayerBaseHeader has an invalid XrStructureType 0x3b9c96f3"), and
//! then refuses the whole xrEndFrame; the XR_FB_passthrough frame path is therefore
//! tested with the Vulkan validation layer only. Passthrough through the
//! ALPHA_BLEND environment blend mode runs under the core validation layer.
//!
//! Skipped, with a message, on machines without the loader or a Vulkan device —
//! unless REQUIRE_GPU=1 (CI), where that is a failure.

#[path = "common/xr.rs"]
mod harness;

use blind_augment::worker::ModelChannel;
use blind_augment::xr::{EndReason, FrameRecord};
use glam::{Mat4, Vec3};
use harness::*;
use openxr::SessionState as S;
use std::path::PathBuf;

const FULL: [S; 10] = [
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
];

/// 120 frames on a 90 Hz display (the app asked for 90 from 72) without space
/// warp (every display frame rendered), passthrough by ALPHA_BLEND (a runtime
/// without XR_FB_passthrough), every session state from IDLE to EXITING, under
/// both validation layers; frame 12 as the runtime composes it over the real
/// world matches the desktop render composed as the spec says.
#[test]
fn lifecycle_120_frames_alpha_blend_validated() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let env = [
        ("BA_XR_DISPLAY_HZ", "72"),
        ("BA_XR_BLEND_MODES", "opaque,alpha_blend"),
        ("BA_XR_EXTENSIONS", "refresh_rate,convert_timespec"),
        ("BA_XR_PNG_DIR", "{dir}"),
        ("BA_XR_PNG_FRAMES", "12"),
    ];
    let Some(run) = run_xr("lifecycle", &env, 120, true, &models) else { return };
    assert_clean(&run, true);
    let empty_before = frames_of(&run.report).iter().take_while(|f| f["layers"].as_array().unwrap().is_empty()).count();
    let replay = desktop_replay(&run.records, &models, 12 - empty_before);
    assert_composed_as_the_spec_says(&PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xr/lifecycle"), 12, &replay);
    let s = &run.summary;
    assert_eq!(s.end, EndReason::Exited);
    assert_eq!(s.states, FULL, "every transition, in order");
    assert_eq!(s.frames_rendered, 120);
    assert_eq!(s.blend_mode, openxr::EnvironmentBlendMode::ALPHA_BLEND);
    assert!(s.passthrough);
    assert_eq!(s.display_hz, Some(90.0));
    assert!(!s.space_warp);
    // Every rendered frame paced at the 90 Hz display (1 ns rounding).
    assert!(s.periods_ns.iter().all(|&p| (p - 11_111_111).abs() <= 1), "{:?}", &s.periods_ns[..5]);
    let refresh: Vec<_> = run.report.iter().filter(|v| v["event"] == "refresh_rate").collect();
    assert_eq!(refresh.len(), 1);
    assert_eq!((refresh[0]["from"].as_f64(), refresh[0]["to"].as_f64()), (Some(72.0), Some(90.0)));
    // Display times strictly increase by whole display periods.
    let t: Vec<i64> = run.records.iter().map(|r| r.predicted_display_time_ns).collect();
    assert!(t.windows(2).all(|w| w[1] > w[0] && (w[1] - w[0]) % 11_111_111 <= 120), "display times {t:?}");
    // The submitted layers: one straight-alpha projection layer, both eyes
    // from one two-layer swapchain image array, no FB passthrough layer.
    let frames = frames_of(&run.report);
    let with_layers: Vec<_> = frames.iter().filter(|f| !f["layers"].as_array().unwrap().is_empty()).collect();
    assert_eq!(with_layers.len(), 120);
    for f in with_layers {
        let layers = f["layers"].as_array().unwrap();
        assert_eq!(layers.len(), 1, "{f}");
        let p = &layers[0];
        assert_eq!(p["type"], "projection");
        assert_eq!(p["source_alpha"], true);
        assert_eq!(p["unpremultiplied"], true);
        assert_eq!(f["blend_mode"], "ALPHA_BLEND");
        let views = p["views"].as_array().unwrap();
        assert_eq!((views[0]["array_index"].as_u64(), views[1]["array_index"].as_u64()), (Some(0), Some(1)));
        assert!(views.iter().all(|v| v["swapchain_array_size"] == 2 && v["format"] == 43), "sRGB RGBA8 array");
    }
    // Clock samples (XR_KHR_convert_timespec_time): on the first frame and about
    // once a second (120 frames at 90 Hz: 2, or 3 on a slow machine). Each maps
    // CLOCK_MONOTONIC onto the runtime's clock: a frame's predicted display time,
    // read through the mapping taken on that frame, lies ahead of the sample by at
    // most the runtime's pacing (one display period plus the app's budget: < 50 ms
    // here, generous for a loaded CI machine).
    let samples: Vec<_> = run.records.iter().filter_map(|r| r.clock.map(|c| (r, c))).collect();
    assert!(run.records[0].clock.is_some() && (2..=4).contains(&samples.len()), "{} samples", samples.len());
    for (r, c) in &samples {
        assert!(c.monotonic_before_ns <= c.monotonic_after_ns && c.boottime_ns >= c.monotonic_before_ns);
        let ahead_ns = r.predicted_display_time_ns - c.xr_time_ns;
        assert!((0..50_000_000).contains(&ahead_ns), "display {} ns ahead of the clock sample", ahead_ns);
    }
    let map =
        blind_augment::analysis::timing::ClockMap::from_samples(&samples.iter().map(|(_, c)| *c).collect::<Vec<_>>())
            .expect("clock map");
    // The test runtime's XrTime is CLOCK_MONOTONIC shifted by a constant: every
    // sample agrees on it to the width of its own window.
    for (_, c) in &samples {
        let offset = c.xr_time_ns - c.monotonic_before_ns;
        assert!((offset - map.xr_minus_monotonic_ns).abs() <= map.uncertainty_ns.max(1), "{offset} vs {map:?}");
    }
}

/// 120 frames on a 90 Hz display with XR_FB_space_warp: the app submits motion
/// vectors and depth with every projection view, the runtime throttles it to 45 Hz
/// (predicted display period 22.2 ms) from the first such frame on, under both
/// validation layers.
#[test]
fn space_warp_renders_at_half_the_display_rate() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let Some(run) = run_xr("space_warp", &[], 120, true, &models) else { return };
    assert_clean(&run, true);
    let s = &run.summary;
    assert_eq!(s.end, EndReason::Exited);
    assert!(s.space_warp);
    assert_eq!(s.frames_rendered, 120);
    assert_eq!(s.display_hz, Some(90.0));
    // The first frame is requested before any space-warp data was submitted.
    assert_eq!(s.periods_ns[0], 11_111_111);
    assert!(s.periods_ns[1..].iter().all(|&p| (p - 22_222_222).abs() <= 2), "{:?}", &s.periods_ns[..5]);
    let t: Vec<i64> = run.records.iter().map(|r| r.predicted_display_time_ns).collect();
    assert!(t.windows(2).skip(1).all(|w| w[1] - w[0] >= 22_222_220), "45 Hz display times {t:?}");
    let mut chains = std::collections::BTreeSet::new();
    for f in frames_of(&run.report).iter().filter(|f| !f["layers"].as_array().unwrap().is_empty()) {
        let views = f["layers"][0]["views"].as_array().unwrap();
        assert!(views.iter().all(|v| v["space_warp"] == true), "{f}");
    }
    for v in run.report.iter().filter(|v| v["event"] == "swapchain") {
        chains.insert((
            v["format"].as_i64().unwrap(),
            v["depth"].as_bool().unwrap(),
            v["array_size"].as_i64().unwrap(),
        ));
    }
    // Colour (sRGB RGBA8), motion vectors (RGBA16F) and depth (D32), two layers
    // each; the status panel's (sRGB RGBA8, one layer).
    let want: std::collections::BTreeSet<_> = [(43, false, 1), (43, false, 2), (97, false, 2), (126, true, 2)].into();
    assert_eq!(chains, want);
}

/// XR_FB_passthrough under the projection layer: the layer the runtime wrote to
/// PNG is the desktop render of the same views (the effects reach the swapchain),
/// and the runtime's composition — in linear light, as the spec composes — shows
/// the render's colour at its coverage over passthrough: blurred edges neither
/// darkened nor brightened. Core validation off (Debian's 1.0.20 layer rejects the
/// passthrough layer type: see the file's doc); Vulkan validation on.
#[test]
fn fb_passthrough_frames_match_the_desktop_render() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let env = [
        ("BA_XR_PNG_DIR", "{dir}"),
        ("BA_XR_PNG_FRAMES", "12"),
        ("BA_XR_EXTENSIONS", "passthrough,refresh_rate"),
        // Quest-like: passthrough only through the FB layer.
        ("BA_XR_BLEND_MODES", "opaque"),
    ];
    let Some(run) = run_xr_vulkan_validated("passthrough", &env, 20, &models) else { return };
    assert_clean(&run, false);
    assert_eq!(run.summary.blend_mode, openxr::EnvironmentBlendMode::OPAQUE);
    assert!(run.summary.passthrough);
    let frames = frames_of(&run.report);
    for f in frames.iter().filter(|f| !f["layers"].as_array().unwrap().is_empty()) {
        let l = f["layers"].as_array().unwrap();
        assert_eq!((l.len(), &l[0]["type"], &l[0]["running"]), (2, &"passthrough_fb".into(), &true.into()), "{f}");
        assert_eq!((&l[1]["type"], &l[1]["source_alpha"]), (&"projection".into(), &true.into()));
        assert_eq!(l[1]["unpremultiplied"], true, "straight colour, said so: {f}");
    }
    // Runtime frame numbers count every xrEndFrame, empty ones too.
    let empty_before = frames.iter().take_while(|f| f["layers"].as_array().unwrap().is_empty()).count();
    let k = 12 - empty_before;
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xr/passthrough");
    let replay = desktop_replay(&run.records, &models, k);
    assert_composed_as_the_spec_says(&dir, 12, &replay);
}

/// A runtime with none of the optional extensions: no passthrough (content over
/// black, the layer opaque), the runtime's display rate, every frame rendered.
#[test]
fn runtime_without_optional_extensions_falls_back() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let env = [("BA_XR_EXTENSIONS", "none"), ("BA_XR_BLEND_MODES", "opaque")];
    let Some(run) = run_xr("fallback", &env, 30, true, &models) else { return };
    assert_clean(&run, true);
    let s = &run.summary;
    assert_eq!(s.end, EndReason::Exited);
    assert!(!s.passthrough);
    assert_eq!(s.display_hz, None);
    assert_eq!(s.frames_rendered, 30);
    assert!(run.records.iter().all(|r| r.clock.is_none()), "no XR_KHR_convert_timespec_time: no clock samples");
    for f in frames_of(&run.report).iter().filter(|f| !f["layers"].as_array().unwrap().is_empty()) {
        let l = f["layers"].as_array().unwrap();
        assert_eq!((l.len(), &l[0]["source_alpha"]), (1, &false.into()), "opaque projection only: {f}");
    }
}

/// XR_META_environment_depth end to end: the provider refused once (the spatial-data
/// permission not yet granted) and set up again a second later; hand removal on;
/// depth acquired inside frames and read back from the runtime's D16 images by the
/// GPU (sampled: the runtime grants no TRANSFER_SRC) without the frame loop waiting.
/// Every delivered pair is held to what the runtime reported for that acquire — the
/// view poses and fields of view — and to its scene: each texel's depth, unprojected
/// along its ray, lies on the runtime's plane. Tolerance: two D16 steps of view
/// depth, 2·z²/(near·65535) along a ray up to 1.6× the view axis (the texels are
/// quantised to 1/65535 of NDC depth), + 0.1 mm of f32. A row order, a field of view
/// or an NDC convention read wrongly puts points tens of centimetres off the tilted
/// plane.
///
/// Vulkan validation on; the OpenXR core validation layer off: Debian's (1.0.20)
/// predates XR_META_environment_depth and fails xrGetSystemProperties when
/// XrSystemEnvironmentDepthPropertiesMETA is chained ("Invalid structure(s) in
/// next chain", VUID-XrSystemProperties-next-next), so under it the app rightly
/// finds no environment depth.
#[test]
fn environment_depth_read_back_matches_the_runtime_scene() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let env =
        [("BA_XR_EXTENSIONS", "passthrough,refresh_rate,convert_timespec,env_depth"), ("BA_XR_ENV_DEPTH_DENIALS", "1")];
    let Some(run) = run_xr_vulkan_validated("env_depth", &env, 200, &models) else { return };
    assert_clean(&run, false);
    assert!(run.summary.env_depth, "environment depth set up after the refusal");
    let events = |name: &str| run.report.iter().filter(|v| v["event"] == name).collect::<Vec<_>>();
    assert_eq!(events("env_depth_refused").len(), 1);
    assert_eq!(events("env_depth_hand_removal").first().map(|v| v["enabled"].clone()), Some(true.into()));
    let started = events("env_depth_provider");
    assert_eq!(started.first().map(|v| v["started"].clone()), Some(true.into()), "{started:?}");
    assert_eq!(started.last().map(|v| v["started"].clone()), Some(false.into()), "stopped at teardown");
    let acquires = events("env_depth");
    let delivered: Vec<_> = run.records.iter().filter_map(|r| r.env_depth.clone()).collect();
    assert!(delivered.len() >= 5, "{} depth pairs delivered of {} acquires", delivered.len(), acquires.len());
    assert_eq!(run.summary.env_depth_reads as usize, delivered.len());
    let f32s = |v: &serde_json::Value| -> Vec<f32> {
        v.as_array().expect("array").iter().map(|x| x.as_f64().expect("number") as f32).collect()
    };
    for d in &delivered {
        let a = acquires
            .iter()
            .find(|a| a["display_time"].as_i64() == Some(d.acquired_at_ns))
            .unwrap_or_else(|| panic!("no acquire reported at {}", d.acquired_at_ns));
        let (p0, n) = (Vec3::from_slice(&f32s(&a["plane"]["point"])), Vec3::from_slice(&f32s(&a["plane"]["normal"])));
        for (e, view) in d.views.iter().enumerate() {
            let rv = &a["views"][e];
            let (t, q) = (f32s(&rv["t"]), f32s(&rv["q"]));
            let want = Mat4::from_rotation_translation(glam::Quat::from_slice(&q), Vec3::from_slice(&t));
            assert!(view.world_from_view.abs_diff_eq(want, 1e-5), "eye {e} pose");
            let fov: Vec<f32> = f32s(&rv["fov"]).iter().map(|x| x.tan()).collect();
            assert!(view.fov_tan.iter().zip(&fov).all(|(a, b)| (a - b).abs() < 1e-5), "eye {e} fov");
            assert_eq!((view.width, view.height), (320, 320));
            assert!(view.far_m.is_infinite() && (view.near_m - 0.1).abs() < 1e-6);
            let [l, r, u, dn] = view.fov_tan;
            let (mut on_plane, mut worst) = (0, 0.0f32);
            for y in (0..view.height).step_by(7) {
                for x in (0..view.width).step_by(7) {
                    let Some(z) = view.view_depth_m(view.ndc_depth[y * view.width + x]) else { continue };
                    let tx = l + (x as f32 + 0.5) * (r - l) / view.width as f32;
                    let ty = u - (y as f32 + 0.5) * (u - dn) / view.height as f32;
                    let p = view.world_from_view.transform_point3(Vec3::new(tx * z, ty * z, -z));
                    let off = (p - p0).dot(n).abs();
                    let tol = 2.0 * 1.6 * z * z / (0.1 * 65535.0) + 1e-4;
                    assert!(off <= tol, "eye {e} texel ({x}, {y}): {off} m off the plane (z {z} m, tolerance {tol})");
                    worst = worst.max(off / tol);
                    on_plane += 1;
                }
            }
            assert!(on_plane > 2000, "eye {e}: {on_plane} texels with depth");
            eprintln!("eye {e}: {on_plane} texels on the plane, worst {:.2} of the tolerance", worst);
        }
    }
}

/// Session loss (LOSS_PENDING): the loop stops, the session and everything
/// under it are torn down without a validation message.
#[test]
fn session_loss_tears_down_cleanly() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let Some(run) = run_xr("loss", &[("BA_XR_SCRIPT", "loss@20")], 1000, true, &models) else { return };
    assert_clean(&run, true);
    assert_eq!(run.summary.end, EndReason::SessionLost);
    assert_eq!(run.summary.states.last(), Some(&S::LOSS_PENDING));
    assert!(run.summary.frames_rendered >= 15 && run.summary.frames_rendered < 25);
    assert!(run.report.iter().any(|v| v["event"] == "session_destroyed"));
}

/// Instance loss: the loop stops at once and tears down.
#[test]
fn instance_loss_tears_down_cleanly() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let Some(run) = run_xr("instance_loss", &[("BA_XR_SCRIPT", "instance_loss@15")], 1000, true, &models) else {
        return;
    };
    assert_eq!(run.summary.end, EndReason::InstanceLost);
    assert!(run.summary.vulkan_messages.is_empty());
}

/// The runtime takes focus away and back (a system dialog), then asks the app to
/// exit: frames keep coming while VISIBLE; the exit walks down to EXITING.
#[test]
fn focus_changes_and_runtime_exit_request() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let env = [("BA_XR_SCRIPT", "unfocus@10,focus@20,exit@40")];
    let Some(run) = run_xr("focus", &env, 1000, true, &models) else { return };
    assert_clean(&run, true);
    let s = &run.summary;
    assert_eq!(s.end, EndReason::Exited);
    let expected = [
        S::IDLE,
        S::READY,
        S::SYNCHRONIZED,
        S::VISIBLE,
        S::FOCUSED,
        S::VISIBLE,
        S::FOCUSED,
        S::VISIBLE,
        S::SYNCHRONIZED,
        S::STOPPING,
        S::IDLE,
        S::EXITING,
    ];
    assert_eq!(s.states, expected);
    let visible_frames = frames_of(&run.report)
        .iter()
        .filter(|f| f["state"] == "VISIBLE" && !f["layers"].as_array().unwrap().is_empty())
        .count();
    assert!(visible_frames >= 9, "frames are rendered while visible but unfocused ({visible_frames})");
    assert!(s.frames_rendered >= 38 && s.frames_rendered <= 41, "{}", s.frames_rendered);
}

/// Models published from another thread while the XR loop runs: every frame
/// takes one snapshot (its generation is reported per frame), generations only
/// move forward, new ones reach frames, and the loop never waits for the worker.
#[test]
fn camera_model_hot_swapped_during_the_xr_loop() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let models = ModelChannel::new(model(0.1)).expect("model");
    let stop = Arc::new(AtomicBool::new(false));
    let publisher = {
        let (models, stop) = (models.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut n = 0u64;
            while !stop.load(Ordering::SeqCst) {
                n += 1;
                models.publish(model(0.1 + 0.8 * ((n % 10) as f32 / 10.0))).expect("valid model");
                std::thread::sleep(std::time::Duration::from_micros(500));
            }
            n
        })
    };
    let run = run_xr("hotswap", &[], 120, true, &models);
    stop.store(true, Ordering::SeqCst);
    let published = publisher.join().expect("publisher");
    let Some(run) = run else { return };
    assert_clean(&run, true);
    let g: Vec<u64> = run.records.iter().map(|r| r.model_generation).collect();
    assert!(g.windows(2).all(|w| w[1] >= w[0]), "generations move forward: {g:?}");
    let distinct = g.windows(2).filter(|w| w[1] != w[0]).count();
    assert!(distinct >= 60, "new models reach frames ({distinct} changes over 120 frames, {published} published)");
    assert!(g.iter().all(|&x| x <= published), "no frame sees a generation that was never published");
}

/// The binary, without the test runtime's variables other tests set in this process.
fn cli() -> std::process::Command {
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_blind-augment"));
    for v in VARS {
        cmd.env_remove(v);
    }
    cmd
}

/// Shutdown from another thread (Ctrl-C, Android's onDestroy): the app asks the
/// runtime to exit and ends only when the session has walked down to EXITING.
#[test]
fn stop_flag_requests_exit_and_ends_cleanly() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let run = run_xr_until("stop", &[], None, Some(std::time::Duration::from_secs(3)), (true, true), &models);
    let Some(run) = run else { return };
    assert_clean(&run, true);
    assert_eq!(run.summary.end, EndReason::Exited);
    assert_eq!(run.summary.states, FULL);
    assert!(run.summary.frames_rendered > 0);
    assert!(run.report.iter().any(|v| v["event"] == "request_exit"), "the app asked for the exit");
}

/// `blind-augment xr` without a runtime: a clear error, non-zero exit, no panic.
#[test]
fn xr_command_without_runtime_is_a_clear_error() {
    if manifest().is_none() {
        return;
    }
    let _guard = serial();
    let dir = tmp("no_runtime");
    let out = cli()
        .args(["xr", "--frames", "5"])
        .env("XR_RUNTIME_JSON", dir.join("missing.json"))
        .output()
        .expect("binary runs");
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(text.contains("no OpenXR runtime"), "{text}");
    assert!(!text.contains("panicked"), "{text}");
}

/// `blind-augment xr --frames N` on the test runtime prints its timing summary.
#[test]
fn xr_command_prints_a_timing_summary() {
    let Some(manifest) = manifest() else { return };
    let _guard = serial();
    let dir = tmp("cli");
    let out = cli()
        .args(["xr", "--frames", "30", "--validation"])
        .env("XR_RUNTIME_JSON", &manifest)
        .env("XR_CORE_VALIDATION_EXPORT_TYPE", "text")
        .env("XR_CORE_VALIDATION_FILE_NAME", dir.join("core_validation.txt"))
        .env("BA_XR_EYE_SIZE", "96x96")
        .env("BA_XR_BLEND_MODES", "opaque,alpha_blend")
        .output()
        .expect("binary runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    if !out.status.success() && !required() && text.contains("Vulkan") {
        eprintln!("skipping: {text}");
        return;
    }
    assert!(out.status.success(), "{text}");
    for want in [
        "frames: 30 rendered",
        "CPU per frame",
        "waiting in xrWaitFrame",
        "space warp on",
        "predicted display period 22.22 ms",
        "ended: Exited",
    ] {
        assert!(text.contains(want), "missing {want:?} in:\n{text}");
    }
    let log = std::fs::read_to_string(dir.join("core_validation.txt")).unwrap_or_default();
    assert!(!log.contains("VALID_"), "{log}");
}

/// The binary prints the library's warnings: on a runtime with neither
/// XR_FB_passthrough nor ALPHA_BLEND the fallback ("no passthrough …") reaches
/// stderr without RUST_LOG, and RUST_LOG=error silences it.
#[test]
fn xr_command_prints_fallback_warnings() {
    let Some(manifest) = manifest() else { return };
    let _guard = serial();
    let run = |rust_log: Option<&str>| {
        let mut cmd = cli();
        cmd.args(["xr", "--frames", "3"])
            .env("XR_RUNTIME_JSON", &manifest)
            .env("BA_XR_EYE_SIZE", "64x64")
            .env("BA_XR_EXTENSIONS", "none")
            .env("BA_XR_BLEND_MODES", "opaque")
            .env_remove("RUST_LOG");
        if let Some(l) = rust_log {
            cmd.env("RUST_LOG", l);
        }
        let out = cmd.output().expect("binary runs");
        (out.status.success(), String::from_utf8_lossy(&out.stderr).to_string())
    };
    let (ok, stderr) = run(None);
    if !ok && !required() && stderr.contains("Vulkan") {
        eprintln!("skipping: {stderr}");
        return;
    }
    assert!(ok, "{stderr}");
    assert!(stderr.contains("no passthrough"), "the fallback warning is missing from stderr:\n{stderr}");
    let (ok, quiet) = run(Some("error"));
    assert!(ok && !quiet.contains("no passthrough"), "RUST_LOG=error still shows warnings:\n{quiet}");
}

/// Controller toggles through OpenXR actions (spec chapter 11), under the core
/// validation layer: on Touch controllers, A switches matched ↔ naive, B the
/// noise, X the motion blur, Y the DoF. Scripted presses act once, on the press,
/// in the order made — a button held for six frames toggles once, and a press
/// while the session is not focused (a system menu over the app) does nothing; a naive frame applies nothing, and
/// coming back restores the per-effect switches; an effect the model lacks
/// (this model has no noise) is never applied whatever the switch says. The
/// runtime logs each boolean action's change (pressed, then released).
#[test]
fn controller_presses_toggle_matched_and_each_effect() {
    use blind_augment::render::Enabled;
    use blind_augment::xr::Toggle;
    let models = ModelChannel::new(model(0.4)).expect("model");
    let env = [
        (
            "BA_XR_SCRIPT",
            "press:/user/hand/right/input/a/click@20,press:/user/hand/left/input/y/click@30,\
         press:/user/hand/right/input/a/click@40,press:/user/hand/left/input/x/click@50,\
         press:/user/hand/right/input/b/click@60..66,\
         unfocus@70,press:/user/hand/right/input/a/click@72,focus@75,\
         press:/user/hand/left/input/thumbstick/click@80",
        ),
        ("BA_XR_PNG_DIR", "{dir}"),
        ("BA_XR_PNG_FRAMES", "15,25,45,55"),
    ];
    let Some(run) = run_xr("controls", &env, 90, true, &models) else { return };
    assert_clean(&run, true);
    let s = &run.summary;
    assert!(s.controls, "the bindings were accepted and the set attached");
    let kinds: Vec<Toggle> = s.toggles.iter().map(|(_, t)| *t).collect();
    assert_eq!(
        kinds,
        [Toggle::Matched, Toggle::Dof, Toggle::Matched, Toggle::MotionBlur, Toggle::Noise, Toggle::Record]
    );
    // The record button reaches the app in the frame it was pressed, once, and
    // leaves the effects as they were.
    let recorded: Vec<&FrameRecord> = run.records.iter().filter(|r| !r.pressed.is_empty()).collect();
    assert_eq!(recorded.iter().filter(|r| r.pressed.contains(&Toggle::Record)).count(), 1);
    let at = recorded.iter().position(|r| r.pressed.contains(&Toggle::Record)).expect("record press");
    let k = recorded[at].index as usize;
    assert_eq!(run.records[k].enabled, run.records[k - 1].enabled, "recording toggles no effect");
    let on = |noise, motion_blur, dof| Enabled { noise, motion_blur, dof };
    let mut seen: Vec<Enabled> = run.records.iter().map(|r| r.enabled).collect();
    seen.dedup();
    assert_eq!(
        seen,
        [
            on(true, true, true),
            on(false, false, false),
            on(true, true, false),
            on(true, false, false),
            on(false, false, false)
        ],
        "the toggles in the order pressed"
    );
    for r in &run.records {
        // The model has MB and DoF, no noise: applied = allowed ∧ present.
        assert_eq!(r.applied, on(false, r.enabled.motion_blur, r.enabled.dof), "frame {}", r.index);
    }
    // Each press is one frame long: pressed, then released, as the runtime saw it.
    let changes: Vec<bool> = run
        .report
        .iter()
        .filter(|v| v["event"] == "input")
        .flat_map(|v| v["changes"].as_array().cloned().unwrap_or_default())
        .map(|c| c["state"] == true)
        .collect();
    assert_eq!(
        changes,
        [true, false].repeat(6),
        "{:?}",
        run.report.iter().filter(|v| v["event"] == "input").collect::<Vec<_>>()
    );
    assert!(run
        .report
        .iter()
        .any(|v| v["event"] == "attach" && v["profile"] == "/interaction_profiles/oculus/touch_controller"));
    // What was submitted: matched (15), naive (25), DoF off (45), DoF and MB off
    // (55). Each frame is the desktop render with those switches, composed as the
    // spec says; and each switched frame differs from the all-matched render.
    let empty_before = frames_of(&run.report).iter().take_while(|f| f["layers"].as_array().unwrap().is_empty()).count();
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xr/controls");
    for (frame, want) in [
        (15, on(true, true, true)),
        (25, on(false, false, false)),
        (45, on(true, true, false)),
        (55, on(true, false, false)),
    ] {
        let k = frame - empty_before;
        assert_eq!(run.records[k].enabled, want, "runtime frame {frame}");
        let replay = desktop_replay(&run.records, &models, k);
        let blurred = want.dof;
        assert_composed_with(&dir, frame as u64, &replay, if blurred { 20 } else { 0 });
        let matched = desktop_replay_with(&run.records, &models, k, Some(on(true, true, true)));
        let differ = replay.iter().zip(&matched).filter(|(a, b)| a.abs_diff(**b) > 2).count();
        if want == on(true, true, true) {
            assert_eq!(differ, 0, "frame {frame}: matched is matched");
        } else {
            assert!(differ > 0, "frame {frame}: switching {want:?} changes the render");
        }
    }
}

/// A runtime whose controllers only answer to the Khronos simple controller
/// profile picks the app's simple-controller bindings: select toggles matched ↔
/// naive; Touch's buttons do not exist there. With no controllers at all the app
/// runs matched, presses doing nothing.
#[test]
fn simple_controller_toggles_matched_and_no_controller_keeps_effects() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let env = [
        ("BA_XR_CONTROLLER", "simple"),
        ("BA_XR_SCRIPT", "press:/user/hand/right/input/select/click@20,press:/user/hand/right/input/a/click@30"),
    ];
    let Some(run) = run_xr("controls_simple", &env, 40, true, &models) else { return };
    assert_clean(&run, true);
    assert_eq!(run.summary.toggles.len(), 1, "{:?}", run.summary.toggles);
    assert!(!run.records.last().expect("frames").enabled.dof, "naive after select");
    assert!(run
        .report
        .iter()
        .any(|v| v["event"] == "attach" && v["profile"] == "/interaction_profiles/khr/simple_controller"));

    let env = [("BA_XR_CONTROLLER", "none"), ("BA_XR_SCRIPT", "press:/user/hand/right/input/a/click@20")];
    let Some(run) = run_xr("controls_none", &env, 30, true, &models) else { return };
    assert!(run.summary.toggles.is_empty());
    assert!(run.records.iter().all(|r| r.enabled.dof && r.enabled.motion_blur));
}

/// Quest 3's Touch Plus controllers: with XR_META_touch_controller_plus offered the
/// app enables it and suggests the profile (a path valid only with the extension),
/// and the runtime binds it; without the extension the app never names the path
/// and the controllers answer to the Touch bindings, as a Meta runtime maps them.
#[test]
fn touch_plus_controllers_bind_with_or_without_their_extension() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let press = "press:/user/hand/right/input/a/click@20";
    for (extensions, profile) in [
        ("refresh_rate,space_warp,convert_timespec,touch_plus", "/interaction_profiles/meta/touch_controller_plus"),
        ("refresh_rate,space_warp,convert_timespec", "/interaction_profiles/oculus/touch_controller"),
    ] {
        let env = [("BA_XR_CONTROLLER", "touch_plus"), ("BA_XR_EXTENSIONS", extensions), ("BA_XR_SCRIPT", press)];
        let Some(run) = run_xr("controls_touch_plus", &env, 30, true, &models) else { return };
        assert_clean(&run, true);
        assert!(
            run.report.iter().any(|v| v["event"] == "attach" && v["profile"] == profile),
            "{extensions}: {:?}",
            run.report.iter().filter(|v| v["event"] == "attach").collect::<Vec<_>>()
        );
        assert!(!run.report.iter().any(|v| v["event"] == "bindings_refused"), "every suggestion accepted");
        assert_eq!(run.summary.toggles.len(), 1, "A toggles on {profile}");
        assert!(!run.records.last().expect("frames").enabled.dof, "naive after A");
    }
}

/// The next-scene button (right thumbstick click) cycles the user's scenes: the
/// toy, a glTF sample, a broken file (named and skipped), and the toy again; each
/// scene is drawn from the frame it is ready in, and the submitted layers differ.
#[test]
fn next_scene_cycles_and_skips_a_broken_file() {
    let models = ModelChannel::new(model(0.4)).expect("model");
    let dir = tmp("scenes");
    let box_gltf =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/gltf_samples/webp-box/box-textured-separate.gltf");
    let broken = dir.join("broken.glb");
    std::fs::write(&broken, b"glTF not really").expect("write");
    let scenes = format!("{},{}", box_gltf.display(), broken.display());
    let click = "/user/hand/right/input/thumbstick/click";
    let script = format!("press:{click}@10,press:{click}@40");
    let env = [
        ("BA_TEST_SCENES", scenes.as_str()),
        ("BA_XR_SCRIPT", &script),
        ("BA_XR_PNG_DIR", "{dir}"),
        ("BA_XR_PNG_FRAMES", "30,65"),
    ];
    let Some(run) = run_xr("scenes", &env, 70, true, &models) else { return };
    assert_clean(&run, true);
    let s = &run.summary;
    let order: Vec<usize> = s.scene_changes.iter().map(|c| c.1).collect();
    assert_eq!(order, [1, 0], "the sample, then (the broken file skipped) the toy: {:?}", s.scene_changes);
    assert_eq!(s.scene_errors.len(), 1, "{:?}", s.scene_errors);
    assert!(s.scene_errors[0].contains("broken.glb"), "{:?}", s.scene_errors);
    for (frame, index) in &s.scene_changes {
        let r = &run.records[*frame as usize];
        assert_eq!(r.scene, *index, "frame {frame} draws the scene it changed to");
        assert_eq!(run.records[*frame as usize - 1].scene, if *index == 1 { 0 } else { 1 });
    }
    assert!(run.records.iter().any(|r| r.scene == 1) && run.records.last().expect("frames").scene == 0);
    // What was submitted: at runtime frame 30 the sample, which the toy's desktop
    // replay does not match; at 65 the toy again, matched as the spec composes it.
    let empty_before = frames_of(&run.report).iter().take_while(|f| f["layers"].as_array().unwrap().is_empty()).count();
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xr/scenes");
    let toy = desktop_replay(&run.records, &models, 30 - empty_before);
    let submitted = image::open(dir.join("frame_0030_eye0.png")).expect("runtime PNG").to_rgba8();
    let n = (EYE.0 * EYE.1) as usize;
    // Pixels where either shows content (alpha) and the two disagree by more
    // than 16 levels of alpha: the sample box covers other pixels than the toy.
    let differ = (0..n).filter(|&i| (submitted.as_raw()[i * 4 + 3] as i32 - toy[i * 4 + 3] as i32).abs() > 16).count();
    assert!(differ > n / 50, "frame 30 shows the sample, not the toy ({differ} of {n} pixels differ in coverage)");
    assert_composed_as_the_spec_says(&dir, 65, &desktop_replay(&run.records, &models, 65 - empty_before));
}

/// Grab-and-place: the right controller (aim pose located through its action
/// space) squeezes at the object, turns 30° to the left, pushes the thumbstick
/// forward for five frames and lets go: the object is carried rigidly with the aim
/// ray, pushed along it, and stays where it was put; the submitted layer after the
/// release is the desktop render at the new place.
#[test]
fn grab_and_place_moves_the_object_with_the_aim() {
    use glam::{Mat4, Quat, Vec3};
    let models = ModelChannel::new(model(0.4)).expect("model");
    let squeeze = "/user/hand/right/input/squeeze/value";
    let script = format!("aim:0.2;-0.3;-0.2;0;0@5,press:{squeeze}@20..40,aim:0.2;-0.3;-0.2;30;0@30,stick:0;1@33..38");
    let env = [("BA_XR_SCRIPT", script.as_str()), ("BA_XR_PNG_DIR", "{dir}"), ("BA_XR_PNG_FRAMES", "60")];
    let Some(run) = run_xr("grab", &env, 70, true, &models) else { return };
    assert_clean(&run, true);
    let start = Mat4::from_translation(Vec3::new(0.0, 0.0, -0.6));
    let aim0 = Mat4::from_translation(Vec3::new(0.2, -0.3, -0.2));
    let aim1 = aim0 * Mat4::from_quat(Quat::from_rotation_y(30f32.to_radians()));
    let empty_before = frames_of(&run.report).iter().take_while(|f| f["layers"].as_array().unwrap().is_empty()).count();
    // Pushed at full deflection for runtime frames 33–37: 1 m/s over each frame's
    // display period, along the aim ray.
    let push_m: f32 = (33..38).map(|f| run.records[f - empty_before].predicted_display_period_ns as f32 * 1e-9).sum();
    let want = aim1 * Mat4::from_translation(Vec3::new(0.0, 0.0, -push_m)) * aim0.inverse() * start;
    let first = &run.records[0];
    assert!(first.local_from_scene.abs_diff_eq(start, 1e-6), "the object starts where the app put it");
    let last = run.records.last().expect("frames");
    // Tolerance 1e-4: f32 poses through the runtime's quaternion algebra.
    assert!(
        last.local_from_scene.abs_diff_eq(want, 1e-4),
        "placed at {:?}, want {:?}",
        last.local_from_scene.w_axis,
        want.w_axis
    );
    let moved: Vec<usize> = run
        .records
        .iter()
        .filter(|r| !r.local_from_scene.abs_diff_eq(r.prev_local_from_scene, 1e-7))
        .map(|r| r.index as usize + empty_before)
        .collect();
    assert_eq!(moved, [30, 33, 34, 35, 36, 37], "moved by the turn, then by each frame of the push");
    let after = moved[moved.len() - 1] - empty_before;
    assert!(
        run.records[after..].iter().all(|r| r.local_from_scene == last.local_from_scene),
        "it stays where it was put"
    );
    // What was submitted after the release is the render at the new place.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xr/grab");
    assert_composed_with(&dir, 60, &desktop_replay(&run.records, &models, 60 - empty_before), 0);
}
