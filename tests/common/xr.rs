//! The XR tests' harness: the project's headless OpenXR runtime (tests/xr-runtime)
//! built and found through the real Khronos loader, the app's loop run in-process
//! against it, its report read back, and frames replayed on a desktop renderer.
//! Skipped, with a message, on machines without the loader or a Vulkan device —
//! unless REQUIRE_GPU=1 (CI), where that is a failure.

#![allow(dead_code)]

use blind_augment::model::{CameraModel, DepthOfField, DepthUnits, Diagnostics, DofCurve, MotionBlur};
use blind_augment::render::{LayerSettings, StereoRenderer};
use blind_augment::scene::Scene;
use blind_augment::worker::ModelChannel;
use blind_augment::xr::{self, eye_from_view, FrameGeometry, FrameRecord, XrOptions, XrSummary};
use glam::{Mat4, Vec3};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, OnceLock};

pub const TOY: &[u8] = include_bytes!("../../assets/toy.glb");
/// Small eye buffers: the loop, not lavapipe's fill rate, is under test.
pub const EYE: (u32, u32) = (96, 96);

pub fn required() -> bool {
    std::env::var("REQUIRE_GPU").as_deref() == Ok("1")
}

/// `target/<profile>` of this test binary (…/deps/xr-hash → …).
pub fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    exe.parent().and_then(Path::parent).expect("target dir").to_path_buf()
}

/// Build the test runtime (same profile as this test) and write its manifest, once.
pub fn manifest() -> Option<PathBuf> {
    static MANIFEST: OnceLock<Option<PathBuf>> = OnceLock::new();
    MANIFEST
        .get_or_init(|| {
            let loader = ["/usr/lib/x86_64-linux-gnu/libopenxr_loader.so.1", "/usr/lib/libopenxr_loader.so.1"];
            if !loader.iter().any(|p| Path::new(p).exists()) {
                let msg = "no OpenXR loader (apt-get install libopenxr-loader1 openxr-layer-corevalidation)";
                assert!(!required(), "{msg}");
                eprintln!("skipping XR tests: {msg}");
                return None;
            }
            let dir = target_dir();
            let profile = dir.file_name().and_then(|n| n.to_str()).unwrap_or("debug").to_string();
            let mut cmd = std::process::Command::new(env!("CARGO"));
            cmd.args(["build", "-p", "ba-xr-runtime"]).current_dir(env!("CARGO_MANIFEST_DIR"));
            if profile == "release" {
                cmd.arg("--release");
            }
            let status = cmd.status().expect("cargo runs");
            assert!(status.success(), "building the test runtime failed");
            let lib = dir.join("libba_xr_runtime.so");
            assert!(lib.exists(), "{} missing after the build", lib.display());
            let template =
                std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/xr-runtime/runtime.json.in"))
                    .expect("manifest template");
            let path = dir.join("ba_xr_runtime_tests.json");
            let lib_json = serde_json::to_string(&lib.display().to_string()).expect("path");
            std::fs::write(&path, template.replace("\"@LIB@\"", &lib_json)).expect("writing the manifest");
            Some(path)
        })
        .clone()
}

/// The XR tests share process-wide state (environment variables the loader and
/// the runtime read, the runtime's one instance): one at a time.
pub fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

pub const VARS: &[&str] = &[
    "BA_XR_DISPLAY_HZ",
    "BA_XR_REFRESH_RATES",
    "BA_XR_EYE_SIZE",
    "BA_XR_EXTENSIONS",
    "BA_XR_BLEND_MODES",
    "BA_XR_SCRIPT",
    "BA_XR_PNG_DIR",
    "BA_XR_PNG_FRAMES",
    "BA_XR_REPORT",
    "BA_XR_HEAD",
    "BA_XR_ENV_DEPTH_DENIALS",
    "BA_XR_PROFILE",
    "BA_XR_TIME_ORIGIN_S",
    "BA_XR_CONTROLLER",
    "BA_TEST_APP_HZ",
    "BA_TEST_SCENES",
    "BA_TEST_PANEL",
];

pub fn tmp(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xr").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("tmp dir");
    d
}

/// A model with every effect present and deterministic output (no grain: the
/// desktop replay must match bit for bit; grain is covered by the GPU twin tests).
pub fn model(exposure: f32) -> CameraModel {
    let mut m = CameraModel::empty(1280, 960);
    m.reference.frame_interval_s = Some(1.0 / 30.0);
    m.reference.pixels_per_radian = Some(60.0);
    m.motion_blur =
        MotionBlur { present: true, exposure: Some(exposure), diagnostics: Diagnostics::not_fitted("test") };
    m.depth_of_field = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::ThinLens { k: 1.5, focus_depth: 3.0, c0: 0.2 }),
        depth_range: [0.3, 10.0],
        kernel: blind_augment::model::DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("test"),
    };
    m
}

pub struct Run {
    pub summary: XrSummary,
    pub records: Vec<FrameRecord>,
    pub report: Vec<serde_json::Value>,
    /// Core validation layer output of this run.
    pub xr_validation: String,
}

/// Run the XR loop in-process on the test runtime configured by `env`.
/// `validation`: both layers (Vulkan's and the OpenXR core validation layer).
pub fn run_xr(name: &str, env: &[(&str, &str)], frames: u64, validation: bool, models: &ModelChannel) -> Option<Run> {
    run_xr_until(name, env, Some(frames), None, (validation, validation), models)
}

/// As `run_xr`, with Vulkan validation on and the OpenXR core validation layer off.
pub fn run_xr_vulkan_validated(name: &str, env: &[(&str, &str)], frames: u64, models: &ModelChannel) -> Option<Run> {
    run_xr_until(name, env, Some(frames), None, (true, false), models)
}

/// The display rate the tests' app asks for (the Quest app asks for
/// `xr::PASSTHROUGH_DISPLAY_HZ`; 90 here shows the request being honoured).
pub const APP_DISPLAY_HZ: f32 = 90.0;

/// As `run_xr`, ending after `frames` or when another thread sets the stop flag
/// `stop_after` into the run; `validation`: (Vulkan, OpenXR core) layers.
pub fn run_xr_until(
    name: &str,
    env: &[(&str, &str)],
    frames: Option<u64>,
    stop_after: Option<std::time::Duration>,
    (validation, core_validation): (bool, bool),
    models: &ModelChannel,
) -> Option<Run> {
    let manifest = manifest()?;
    let _guard = serial();
    let dir = tmp(name);
    let report = dir.join("report.jsonl");
    let xr_log = dir.join("core_validation.txt");
    // SAFETY (set_var): the lock above serialises every XR test; nothing else in
    // this binary reads these variables concurrently.
    for v in VARS {
        std::env::remove_var(v);
    }
    std::env::set_var("XR_RUNTIME_JSON", &manifest);
    std::env::set_var("XR_CORE_VALIDATION_EXPORT_TYPE", "text");
    std::env::set_var("XR_CORE_VALIDATION_FILE_NAME", &xr_log);
    std::env::set_var("BA_XR_EYE_SIZE", format!("{}x{}", EYE.0, EYE.1));
    std::env::set_var("BA_XR_REPORT", &report);
    if core_validation {
        // Under the core validation layer, passthrough by ALPHA_BLEND (the FB
        // passthrough layer is refused by Debian's 1.0.20 layer: see the file doc).
        std::env::set_var("BA_XR_BLEND_MODES", "opaque,alpha_blend");
    }
    for (k, v) in env {
        std::env::set_var(k, v.replace("{dir}", &dir.display().to_string()));
    }
    let scene = Scene::from_glb(TOY, "assets/toy.glb").expect("bundled scene");
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stopper = stop_after.map(|after| {
        let stop = stop.clone();
        std::thread::spawn(move || {
            std::thread::sleep(after);
            stop.store(true, std::sync::atomic::Ordering::SeqCst);
        })
    });
    let mut records = vec![];
    let mut on_frame = |r: &FrameRecord| records.push(r.clone());
    // Scenes the next-scene button cycles through after the toy (comma-separated).
    let more_scenes: Vec<PathBuf> = std::env::var("BA_TEST_SCENES")
        .map(|v| v.split(',').filter(|p| !p.is_empty()).map(PathBuf::from).collect())
        .unwrap_or_default();
    let result = xr::run(XrOptions {
        frames,
        validation,
        core_validation,
        scene: &scene,
        more_scenes: &more_scenes,
        // Close enough to fill a good part of the small eye buffers.
        local_from_scene: Mat4::from_translation(Vec3::new(0.0, 0.0, -0.6)),
        models,
        settings: LayerSettings::default(),
        display_hz: std::env::var("BA_TEST_APP_HZ").ok().and_then(|s| s.parse().ok()).unwrap_or(APP_DISPLAY_HZ),
        // Used where the runtime offers XR_META_environment_depth (`env_depth` in
        // BA_XR_EXTENSIONS); ignored elsewhere.
        env_depth_hz: 30.0,
        on_frame: Some(&mut on_frame),
        stop: Some(&stop),
        // Shown from the start with BA_TEST_PANEL=1 (else the left trigger shows it).
        panel: std::env::var("BA_TEST_PANEL").is_ok_and(|v| v == "1"),
        status: Some(&|| vec!["test status line".to_string()]),
        platform: &(),
    });
    if let Some(t) = stopper {
        t.join().expect("stopper thread");
    }
    let summary = match result {
        Ok(s) => s,
        Err(xr::XrError::Gpu(e)) if !required() => {
            eprintln!("skipping {name}: no Vulkan device ({e})");
            return None;
        }
        Err(e) => panic!("{name}: {e}"),
    };
    let report = std::fs::read_to_string(&report)
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).expect("report line is JSON"))
        .collect();
    let xr_validation = std::fs::read_to_string(&xr_log).unwrap_or_default();
    Some(Run { summary, records, report, xr_validation })
}

pub fn assert_clean(run: &Run, core_validation: bool) {
    let errors: Vec<&str> = run.xr_validation.lines().filter(|l| l.contains("VALID_")).collect();
    assert!(errors.is_empty(), "core validation: {errors:#?}");
    assert!(run.summary.vulkan_messages.is_empty(), "Vulkan validation: {:#?}", run.summary.vulkan_messages);
    if core_validation {
        // Proof the layer ran (it announces its output type once per process;
        // the file exists when it opened it).
        assert!(run.summary.states.len() > 2);
    }
}

pub fn frames_of(report: &[serde_json::Value]) -> Vec<&serde_json::Value> {
    report.iter().filter(|v| v["event"] == "frame").collect()
}

/// Replay `records` on a desktop Vulkan context (same scene, model, views and
/// effect toggles)
/// and return frame `k`'s composite over a transparent background (RGBA8,
/// eye-major), premultiplied as the desktop stores it: the virtual colour and
/// coverage the app means, independent of how it submits them.
pub fn desktop_replay(records: &[FrameRecord], models: &ModelChannel, k: usize) -> Vec<u8> {
    desktop_replay_with(records, models, k, None)
}

/// `desktop_replay` with each frame's effects as the record says it applied them
/// (`FrameRecord::enabled`: the controller toggles), or all as `force` says.
pub fn desktop_replay_with(
    records: &[FrameRecord],
    models: &ModelChannel,
    k: usize,
    force: Option<blind_augment::render::Enabled>,
) -> Vec<u8> {
    let ctx = blind_augment::gpu::GpuContext::new(&Default::default()).expect("Vulkan");
    let scene = Scene::from_glb(TOY, "assets/toy.glb").expect("scene");
    let (w, h) = EYE;
    let mut renderer: Option<StereoRenderer<'_>> = None;
    let mut prev = None;
    for r in &records[..=k] {
        let eyes = [eye_from_view(&r.views[0], w, h).unwrap().0, eye_from_view(&r.views[1], w, h).unwrap().0];
        let g = FrameGeometry::new(
            &scene,
            (r.local_from_scene, r.prev_local_from_scene),
            eyes,
            prev,
            r.predicted_display_time_ns,
            r.predicted_display_period_ns,
            r.time_origin_ns,
        );
        let ren = renderer.get_or_insert_with(|| {
            let ren =
                StereoRenderer::new(&ctx, &scene, w, h, LayerSettings::default(), Some(eyes[0].focal_px)).unwrap();
            ren.set_background(&vec![0u8; (w * h * 8) as usize]).unwrap();
            ren
        });
        ren.set_render_interval_s(g.render_interval_s);
        ren.render_to(&models.latest(), &g.input(), force.unwrap_or(r.enabled), None, None).unwrap();
        prev = Some((r.predicted_display_time_ns, eyes));
    }
    let out = renderer.as_ref().unwrap().read_output().unwrap();
    assert!(ctx.take_messages().is_empty());
    out
}

pub fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

pub fn linear_to_srgb(v: f64) -> f64 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Frame `frame` as the runtime composed it (`<dir>/frame_NNNN_eyeE_*.png`, the
/// spec's composition in linear light) against what should be seen: the desktop
/// render's virtual colour c (sRGB-encoded, straight: its premultiplied P / α) at
/// coverage α over the passthrough image, `α·decode(c) + (1 − α)·decode(pt)`,
/// encoded. The expectation is an interval: P and α are 8-bit (c = P/α known to
/// ±0.5/α levels), the submitted straight colour is rounded again (±0.5 level),
/// the composite PNG rounds once more (±1 level on the interval's ends). Checked
/// where α ≥ 0.25 (c known to ±2.5 levels; below, P/α says little) and, where
/// α = 0, that passthrough shows unchanged. A premultiplied layer composed as
/// straight, or straight as premultiplied, misses by tens of levels at α ≈ 0.5.
/// Also: the submitted layer is the render's straight colour (S·α = P within 1.5
/// levels: both roundings of the same f32 value) with its alpha.
pub fn assert_composed_as_the_spec_says(dir: &Path, frame: u64, replay: &[u8]) {
    assert_composed_with(dir, frame, replay, 20)
}

/// `assert_composed_as_the_spec_says` requiring at least `min_partial` pixels of
/// partial coverage (a naive frame has none: no blur, no multisampling); with 0,
/// only that some covered pixels were checked.
pub fn assert_composed_with(dir: &Path, frame: u64, replay: &[u8], min_partial: usize) {
    let (w, h) = EYE;
    let n = (w * h * 4) as usize;
    for eye in 0..2 {
        let png = |suffix: &str| dir.join(format!("frame_{frame:04}_eye{eye}{suffix}.png"));
        let submitted = image::open(png("")).expect("runtime PNG").to_rgba8();
        let composed = image::open(png("_composited")).expect("composited PNG").to_rgb8();
        let pt = image::open(png("_passthrough")).expect("passthrough PNG").to_rgb8();
        let want = &replay[eye * n..(eye + 1) * n];
        let (mut partial, mut checked) = (0, 0);
        for (i, ((s, c), p)) in submitted.pixels().zip(composed.pixels()).zip(pt.pixels()).enumerate() {
            let d = &want[i * 4..i * 4 + 4];
            // Same device, same commands: bit-identical expected; 1 level allowed
            // for a driver that schedules the same work differently.
            assert!(
                s.0[3].abs_diff(d[3]) <= 1,
                "eye {eye} pixel {i}: submitted alpha {} vs the render's {}",
                s.0[3],
                d[3]
            );
            let a = d[3] as f64 / 255.0;
            for k in 0..3 {
                let straight_times_alpha = s.0[k] as f64 * s.0[3] as f64 / 255.0;
                assert!(
                    (straight_times_alpha - d[k] as f64).abs() <= 1.5,
                    "eye {eye} pixel {i}: submitted colour {:?} (×α {straight_times_alpha:.1}) is not the render's straight colour (premultiplied {:?})",
                    s.0,
                    d
                );
            }
            if d[3] == 0 {
                assert!(
                    (0..3).all(|k| c.0[k].abs_diff(p.0[k]) <= 1),
                    "eye {eye} pixel {i}: {c:?} over empty ≠ passthrough {p:?}"
                );
                continue;
            }
            if a < 0.25 {
                continue;
            }
            partial += (d[3] < 255) as usize;
            checked += 1;
            for k in 0..3 {
                let world = srgb_to_linear(p.0[k] as f64 / 255.0);
                let shown = |c_levels: f64| {
                    let c = (c_levels / 255.0).clamp(0.0, 1.0);
                    255.0 * linear_to_srgb(a * srgb_to_linear(c) + (1.0 - a) * world)
                };
                let c_mid = d[k] as f64 / a;
                let spread = 0.5 / a + 0.5;
                let (lo, hi) = (shown(c_mid - spread) - 1.0, shown(c_mid + spread) + 1.0);
                let got = c.0[k] as f64;
                assert!(
                    (lo..=hi).contains(&got),
                    "eye {eye} pixel {i} channel {k}: composed {got}, the spec's composition of the render gives {lo:.1}–{hi:.1} (α {a:.3}, premultiplied {:?}, passthrough {p:?})",
                    d
                );
            }
        }
        // Non-vacuity: blurred edges (partial coverage) were checked, and fully
        // covered pixels too — except with `min_partial` 0, where the frame may be
        // all edge (a long render interval smears a spinning object whole).
        let full_checked = min_partial == 0 || checked > partial;
        assert!(
            checked > 0 && partial >= min_partial && full_checked,
            "eye {eye}: {partial} partial of {checked} checked pixels"
        );
    }
}
