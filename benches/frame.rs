//! Frame-cost benchmark of the stereo renderer (`cargo bench --bench frame`, run by
//! `cargo xtask bench`): GPU time per stage from timestamp queries and shader
//! invocations from pipeline-statistics queries, at the Quest 3 default eye size
//! (1680×1760) and at 2064×2208, with the virtual content covering 10% and 50% of
//! the eye; then, per quality setting, the error against the CPU reference next to
//! the GPU work it costs. Prints Markdown tables for BENCHMARKS.md.

use blind_augment::gpu::{GpuContext, GpuOptions};
use blind_augment::model::*;
use blind_augment::render::layer::LayerSettings;
use blind_augment::render::stereo::FrameProfile;
use blind_augment::render::{Eye, FrameInput, GBufferFrame, StereoRenderer};
use blind_augment::scene::Scene;
use blind_augment::synth::layer::{defocus_layer_exact, motion_blur_layer, Layer, Rect};
use blind_augment::synth::white_sensor_noise;
use blind_augment::worker::Snapshot;
use glam::{Mat4, Vec3};

const TOY: &[u8] = include_bytes!("../assets/toy.glb");
/// Quest 3 passthrough camera: 1280 px over ≈ 100° → f ≈ 537 px; eye buffer
/// 1680 px over ≈ 97° → f ≈ 743 px (scaled with the eye width for 2064).
const CAMERA_FOCAL_PX: f32 = 537.0;
const OBJECT_DEPTH_M: f32 = 2.0;
/// Frames timed per configuration (median taken); FRAME_BENCH_REPS overrides (a
/// real GPU's sub-millisecond passes want more than lavapipe's slow ones allow).
fn reps() -> usize {
    std::env::var("FRAME_BENCH_REPS").ok().and_then(|v| v.parse().ok()).filter(|&n| n > 0).unwrap_or(3)
}

/// Milliseconds with three significant figures at most (lavapipe: tens of ms; a
/// discrete GPU: tenths or hundredths).
fn ms(v: f64) -> String {
    if v >= 10.0 {
        format!("{v:.1}")
    } else if v >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

fn model() -> CameraModel {
    let mut m = CameraModel::empty(1280, 960);
    m.reference.frame_interval_s = Some(1.0 / 30.0);
    m.reference.pixels_per_radian = Some(CAMERA_FOCAL_PX);
    m.noise = white_sensor_noise([2e-5, 1.2e-5, 4e-5], [8e-4, 5e-4, 1.2e-3], [0.0, 1.0]);
    m.motion_blur = MotionBlur { present: true, exposure: Some(0.4), diagnostics: Diagnostics::not_fitted("bench") };
    // The demo's camera: focused at 3.14 m; at the object's 2 m, δ = 4.4 camera px.
    m.depth_of_field = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::ThinLens { k: 23.04, focus_depth: 3.143, c0: 0.2 }),
        depth_range: [0.3, 10.0],
        kernel: blind_augment::model::DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("bench"),
    };
    // FRAME_BENCH_COLOUR=1: with the demo camera's white balance and exposure
    // (`model::Colour`, applied in the luma and composite passes).
    if std::env::var("FRAME_BENCH_COLOUR").is_ok_and(|v| v == "1") {
        m.colour = blind_augment::model::Colour {
            present: true,
            illuminant: Some([1.22, 0.946, 0.70]),
            exposure: Some(0.63),
            diagnostics: Diagnostics::not_fitted("bench"),
        };
    }
    // FRAME_BENCH_VIGNETTING=1: with the demo camera's lens falloff (corner V 0.70;
    // `model::Vignetting`, applied with the colour gain in the luma and composite
    // passes).
    if std::env::var("FRAME_BENCH_VIGNETTING").is_ok_and(|v| v == "1") {
        m.vignetting = blind_augment::model::Vignetting {
            present: true,
            log_falloff: Some([-0.2, -0.3, 0.14]),
            diagnostics: Diagnostics::not_fitted("bench"),
        };
    }
    // FRAME_BENCH_CHROMATIC=1: with the demo camera's lateral aberration (red 1.002,
    // blue 0.999; `model::ChromaticAberration`, red and blue resampled in the
    // composite).
    if std::env::var("FRAME_BENCH_CHROMATIC").is_ok_and(|v| v == "1") {
        m.chromatic_aberration = blind_augment::model::ChromaticAberration {
            present: true,
            scale_minus_one: Some([0.002, -0.001]),
            diagnostics: Diagnostics::not_fitted("bench"),
        };
    }
    // FRAME_BENCH_SHARPENING=1: with an ISP's unsharp mask (k 1, σ 1.5 camera px;
    // `model::Sharpening`, two separable passes on the layer before the composite).
    if std::env::var("FRAME_BENCH_SHARPENING").is_ok_and(|v| v == "1") {
        m.sharpening = blind_augment::model::Sharpening {
            present: true,
            amount: Some(1.0),
            radius_px: Some(1.5),
            overshoot: None,
            diagnostics: Diagnostics::not_fitted("bench"),
        };
    }
    m
}

fn eyes(x_m: f32, f: f32, w: u32, h: u32) -> [Eye; 2] {
    std::array::from_fn(|e| Eye {
        focal_px: f,
        centre_px: [w as f32 / 2.0, h as f32 / 2.0],
        view_from_world: Mat4::from_translation(Vec3::new(x_m + if e == 0 { -0.032 } else { 0.032 }, 0.0, 0.0))
            .inverse(),
    })
}

struct Setup {
    frame: GBufferFrame,
    now: Vec<Vec3>,
    before: Vec<Vec3>,
}

/// The toy at 2 m, scaled so its projected bounds cover `coverage` of eye 0; the
/// head moving 0.6 m/s sideways and the toy animating.
fn setup(scene: &Scene, r: &StereoRenderer<'_>, f: f32, coverage: f64) -> (Setup, f64) {
    setup_from(scene, r, f, coverage, Mat4::IDENTITY)
}

/// `setup` with `base` applied to the scene before it is scaled and placed.
fn setup_from(scene: &Scene, r: &StereoRenderer<'_>, f: f32, coverage: f64, base: Mat4) -> (Setup, f64) {
    let (w, h) = r.size();
    let t = 0.7f32;
    let dt = 1.0 / 45.0;
    let build = |scale: f32| {
        let place =
            Mat4::from_translation(Vec3::new(0.0, 0.0, -OBJECT_DEPTH_M)) * Mat4::from_scale(Vec3::splat(scale)) * base;
        Setup {
            frame: GBufferFrame {
                eyes: eyes(0.6 * t, f, w, h),
                prev_eyes: eyes(0.6 * (t - dt), f, w, h),
                pose: scene.pose_at(t as f64, place),
                prev_pose: scene.pose_at((t - dt) as f64, place),
                light_dir: blind_augment::render::gbuffer::SCENE_LIGHT_DIR,
                ambient: blind_augment::render::gbuffer::SCENE_AMBIENT,
            },
            now: scene.world_corners(t as f64, place),
            before: scene.world_corners((t - dt) as f64, place),
        }
    };
    let frac = |s: &Setup| {
        let rect = r.rects(&s.frame.eyes, &s.frame.prev_eyes, &s.now, &s.before, 0)[0];
        rect.area() as f64 / (w as f64 * h as f64)
    };
    let (mut lo, mut hi) = (0.1f32, 20.0f32);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if frac(&build(mid)) < coverage {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let s = build(lo);
    let c = frac(&s);
    (s, c)
}

/// Median profile of `reps()` frames (after three warm-up frames).
fn profile(r: &mut StereoRenderer<'_>, snap: &Snapshot, s: &Setup, matched: bool) -> FrameProfile {
    let input = FrameInput { gbuffer: &s.frame, corners_now: &s.now, corners_prev: &s.before };
    let mut runs = vec![];
    // Warm-up frames first: pipelines' first use and, on a real GPU, clocks ramping.
    let warm = 3;
    for i in 0..warm + reps() {
        r.render(snap, &input, matched).expect("render");
        let p = r.last_profile().expect("profile").expect("profiling on");
        if i >= warm {
            runs.push(p);
        }
    }
    runs.sort_by(|a, b| total(a).total_cmp(&total(b)));
    runs[runs.len() / 2]
}

/// Invocations of the full-eye composite (8×8 groups over both eyes), which the
/// effects' compute-invocation figures leave out.
fn composite_invocations(w: u32, h: u32) -> u64 {
    (w.div_ceil(8) * 8) as u64 * (h.div_ceil(8) * 8) as u64 * 2
}

/// A profiling renderer at `w × h` per eye with the default settings over a grey
/// background, and its focal length (the Quest 3 eye's 743 px at 1680 wide, scaled).
fn profiled_renderer<'a>(ctx: &'a GpuContext, scene: &'a Scene, w: u32, h: u32) -> (StereoRenderer<'a>, f32) {
    let f = 743.0 * w as f32 / 1680.0;
    let mut r = StereoRenderer::new(ctx, scene, w, h, LayerSettings::default(), Some(f)).expect("renderer");
    r.enable_profiling().expect("timestamps");
    r.set_background(&vec![128u8; (w * h * 4 * 2) as usize]).expect("background");
    (r, f)
}

fn total(p: &FrameProfile) -> f64 {
    p.gbuffer_ms + p.dof_ms + p.mb_ms + p.grain_ms + p.composite_ms
}

fn main() {
    let ctx = match GpuContext::new(&GpuOptions {
        validation: false,
        prefer_device: std::env::var("BLIND_AUGMENT_DEVICE").ok(),
    }) {
        Ok(c) => c,
        Err(e) => {
            println!("frame benchmark skipped: no Vulkan device ({e})");
            return;
        }
    };
    let scene = Scene::from_glb(TOY, "toy.glb").expect("bundled asset");
    let snap = Snapshot::new(1, model());
    println!("## Frame cost on {} (GPU timestamps, median of {})\n", ctx.device_name(), reps());
    println!("Composite = over the background (on the headset: the compositor's layer blend). Effects = DoF + MB + grain. Compute invocations of the effects exclude the full-screen composite.\n");
    println!("| eye (px) | coverage | G-buffer ms | DoF ms | MB ms | grain ms | composite ms | naive frame ms | matched frame ms | effects / G-buffer | fragment inv. (G-buffer) | compute inv. (effects) |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    // FRAME_BENCH_QUICK=1: only 1680×1760 at 10%, no settings table (for profiling
    // between full runs; BENCHMARKS.md figures come from the full run).
    let quick = std::env::var("FRAME_BENCH_QUICK").is_ok_and(|v| v == "1");
    // FRAME_BENCH_WORKER=1: only the render-thread frame time with the worker off/on.
    if std::env::var("FRAME_BENCH_WORKER").is_ok_and(|v| v == "1") {
        worker_on_off(&ctx, &scene);
        return;
    }
    // FRAME_BENCH_SCENES=1: only the glTF scale rows (FRAME_BENCH_GLTF: more files).
    if std::env::var("FRAME_BENCH_SCENES").is_ok_and(|v| v == "1") {
        scene_rows(&ctx, &snap);
        return;
    }
    // FRAME_BENCH_KERNEL=1: only the DoF kernel-shape rows (Gaussian vs disc).
    if std::env::var("FRAME_BENCH_KERNEL").is_ok_and(|v| v == "1") {
        kernel_rows(&ctx, &scene);
        return;
    }
    let sizes: &[(u32, u32)] = if quick { &[(1680, 1760)] } else { &[(1680, 1760), (2064, 2208)] };
    let coverages: &[f64] = if quick { &[0.1] } else { &[0.1, 0.5] };
    for &(w, h) in sizes {
        let (mut r, f) = profiled_renderer(&ctx, &scene, w, h);
        let composite_inv = composite_invocations(w, h);
        for &coverage in coverages {
            let (s, got) = setup(&scene, &r, f, coverage);
            let naive = profile(&mut r, &snap, &s, false);
            let m = profile(&mut r, &snap, &s, true);
            let effects = m.dof_ms + m.mb_ms + m.grain_ms;
            println!(
                "| {w}×{h} | {:.0}% | {} | {} | {} | {} | {} | {} | {} | {:.2} | {} | {} |",
                got * 100.0,
                ms(m.gbuffer_ms),
                ms(m.dof_ms),
                ms(m.mb_ms),
                ms(m.grain_ms),
                ms(m.composite_ms),
                ms(naive.gbuffer_ms + naive.composite_ms),
                ms(total(&m)),
                effects / m.gbuffer_ms,
                m.gbuffer_stats.fragment_invocations,
                m.effects_stats.compute_invocations.saturating_sub(composite_inv),
            );
        }
    }
    if !quick {
        scene_rows(&ctx, &snap);
        near_focus_rows(&ctx, &scene);
        kernel_rows(&ctx, &scene);
        settings_table(&ctx, &scene, &snap);
        worker_on_off(&ctx, &scene);
    }
}

/// The render thread's wall time per frame (render + reading the newest snapshot,
/// as the frame loop does) with the calibration worker off, then on: a camera
/// thread delivers a 1280×960 30 Hz video (the Quest camera frame) in real time to
/// the accurate-tier worker (nice 19), which is then busy all the time (an update
/// costs ~0.8 s of one core). Eye 840×880 (half the Quest 3 eye per axis) keeps
/// lavapipe's frame near the 45 Hz budget of this 2-core machine. On lavapipe the
/// GPU work runs on the same CPU cores as the worker, so this is a worst case: on
/// the headset the GPU is separate.
fn worker_on_off(ctx: &GpuContext, scene: &Scene) {
    use blind_augment::analysis::{timing::TimedPose, DepthMap, Frame};
    use blind_augment::synth::sequence::{motorcycle, SequenceSpec};
    use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, ModelChannel, Providers, Worker};
    let (w, h) = (840u32, 880u32);
    let f = 743.0 * w as f32 / 1680.0;
    let mut r = StereoRenderer::new(ctx, scene, w, h, LayerSettings::default(), Some(f)).expect("renderer");
    r.set_background(&vec![128u8; (w * h * 4 * 2) as usize]).expect("background");
    let (s, _) = setup(scene, &r, f, 0.1);
    let input = FrameInput { gbuffer: &s.frame, corners_now: &s.now, corners_prev: &s.before };
    // 45 video frames (1.5 s), rendered before timing starts, looped by time.
    let video = motorcycle().expect("bundled scene");
    let spec = SequenceSpec::motorcycle(&video, 1280, 960, 45, None);
    let frames: Vec<_> = (0..spec.frames).map(|i| spec.frame(&video, i)).collect();
    let channel = ModelChannel::new(spec.truth.clone()).expect("truth is valid");
    let n = 90usize;
    let time_frames = |r: &mut StereoRenderer<'_>| -> Vec<f64> {
        (0..n + 3)
            .map(|_| {
                let t0 = std::time::Instant::now();
                let snap = channel.latest();
                r.render(&snap, &input, true).expect("render");
                t0.elapsed().as_secs_f64() * 1e3
            })
            .skip(3)
            .collect()
    };
    let off = time_frames(&mut r);
    let tier = CalibrationTier::Accurate;
    let cal =
        Calibrator::new(CalibratorConfig::new(tier, 1.0 / spec.fps as f64, Some(spec.view)), Providers::for_tier(tier))
            .expect("calibrator");
    let worker = std::sync::Arc::new(Worker::spawn(cal, channel.clone()).expect("worker thread"));
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (w2, stop2) = (worker.clone(), stop.clone());
    let camera = std::thread::spawn(move || {
        let started = std::time::Instant::now();
        let pose = |i: usize| {
            let t = spec.frame_time_s(i % spec.frames);
            let (_, q, p) = spec.path.world_from_camera(t).to_scale_rotation_translation();
            TimedPose { t_ns: (spec.frame_time_s(i) * 1e9).round() as i64, position_m: p, orientation: q }
        };
        let mut i = 0usize;
        while !stop2.load(std::sync::atomic::Ordering::Relaxed) {
            let t_s = i as f64 / spec.fps as f64;
            if let Some(wait) = std::time::Duration::from_secs_f64(t_s).checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
            let fr = &frames[i % frames.len()];
            let frame = Frame {
                index: i as u64,
                t_s,
                image: fr.image.clone(),
                depth: Some(DepthMap { depth: fr.depth_m.clone(), units: DepthUnits::MetricM }),
                flow: None,
            };
            w2.submit(frame, &[pose(i)]);
            i += 1;
        }
    });
    // Let the worker reach its steady state (start-up burst over) before timing.
    std::thread::sleep(std::time::Duration::from_secs(2));
    let on = time_frames(&mut r);
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let _ = camera.join();
    let stats = std::sync::Arc::try_unwrap(worker).ok().map(|w| w.stop());
    let pct = |v: &[f64], q: f64| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q).round() as usize]
    };
    println!(
        "\n## Render thread with the calibration worker off / on ({}, eye {w}×{h}, {n} frames)\n",
        ctx.device_name()
    );
    println!("| worker | median ms | p95 ms | max ms |");
    println!("|---|---|---|---|");
    for (name, v) in [("off", &off), ("on (accurate tier, 1280×960 at 30 Hz)", &on)] {
        println!("| {name} | {} | {} | {} |", ms(pct(v, 0.5)), ms(pct(v, 0.95)), ms(pct(v, 1.0)));
    }
    if let Some(st) = stats {
        println!(
            "\nWorker meanwhile: {} frames submitted, {} processed, {} dropped (latest-frame slot), {} models published.",
            st.submitted,
            st.processed,
            st.dropped,
            st.published.len()
        );
    }
}

/// The same frame with the camera focused at 1.6 m, near the toy's visible surface:
/// most covered pixels get a small σ while the content's depth span (1.3–2.7 m)
/// still sets a long radius — the case the per-tile DoF reach is for.
fn near_focus_rows(ctx: &GpuContext, scene: &Scene) {
    let mut m = model();
    m.depth_of_field.curve = Some(DofCurve::ThinLens { k: 23.04, focus_depth: 1.6, c0: 0.2 });
    let snap = Snapshot::new(3, m);
    println!("\n## Camera focused near the object (1.6 m), 10% coverage\n");
    println!("| eye (px) | G-buffer ms | DoF ms | MB ms | grain ms | effects / G-buffer | compute inv. (effects) |");
    println!("|---|---|---|---|---|---|---|");
    for (w, h) in [(1680u32, 1760u32), (2064, 2208)] {
        let (mut r, f) = profiled_renderer(ctx, scene, w, h);
        let (s, _) = setup(scene, &r, f, 0.1);
        let p = profile(&mut r, &snap, &s, true);
        println!(
            "| {w}×{h} | {} | {} | {} | {} | {:.2} | {} |",
            ms(p.gbuffer_ms),
            ms(p.dof_ms),
            ms(p.mb_ms),
            ms(p.grain_ms),
            (p.dof_ms + p.mb_ms + p.grain_ms) / p.gbuffer_ms,
            p.effects_stats.compute_invocations.saturating_sub(composite_invocations(w, h)),
        );
    }
}

/// The DoF stage with each kernel shape the model can carry (`DofKernel`): the
/// demo's camera (focused at 3.14 m, δ = 4.4 camera px at the object), the same
/// second moment drawn as a Gaussian (`layer_dof_h`/`_v`, separable) or as a disc
/// (`layer_dof_disc`, a 2-D gather over the disc of radius 2σ), both at half
/// resolution. Same frames, same rectangles: only the kernel differs.
fn kernel_rows(ctx: &GpuContext, scene: &Scene) {
    use blind_augment::model::DofKernel;
    println!("\n## DoF kernel shape: Gaussian vs disc (same σ map)\n");
    println!("| eye (px) | coverage | kernel | DoF ms | matched frame ms | compute inv. (effects) |");
    println!("|---|---|---|---|---|---|");
    for (w, h) in [(1680u32, 1760u32), (2064, 2208)] {
        let (mut r, f) = profiled_renderer(ctx, scene, w, h);
        for coverage in [0.1, 0.5] {
            let (s, got) = setup(scene, &r, f, coverage);
            for (id, kernel) in [(10, DofKernel::Gaussian), (11, DofKernel::Disc)] {
                let mut m = model();
                m.depth_of_field.kernel = kernel;
                let p = profile(&mut r, &Snapshot::new(id, m), &s, true);
                println!(
                    "| {w}×{h} | {:.0}% | {kernel:?} | {} | {} | {} |",
                    got * 100.0,
                    ms(p.dof_ms),
                    ms(total(&p)),
                    p.effects_stats.compute_invocations.saturating_sub(composite_invocations(w, h)),
                );
            }
        }
    }
}

fn fixed_mb(samples: u32) -> LayerSettings {
    LayerSettings { mb_samples: samples, mb_taps_per_px: 0.0, ..Default::default() }
}

fn adaptive_mb(samples: u32, taps_per_px: f32) -> LayerSettings {
    LayerSettings { mb_samples: samples, mb_taps_per_px: taps_per_px, ..Default::default() }
}

/// Per quality setting at 1680×1760, 10% coverage: GPU cost of the stage and its
/// error against the CPU reference (DoF: the exact 2-D scatter; MB: the twin with
/// 64 taps, the reconstruction's converged result).
fn settings_table(ctx: &GpuContext, scene: &Scene, snap: &Snapshot) {
    let (w, h) = (1680u32, 1760u32);
    let f = 743.0;
    println!("\n## Quality settings at {w}×{h}, 10% coverage: error vs the CPU reference, next to GPU cost\n");
    println!("Error over the work rectangle of eye 0, premultiplied RGBA, in 8-bit steps (×255).\n");
    println!("| effect | setting | MAE ×255 | p99 ×255 | GPU ms | compute invocations |");
    println!("|---|---|---|---|---|---|");
    let mut dof_only = snap.model.clone();
    dof_only.motion_blur.present = false;
    dof_only.noise.present = false;
    let mut mb_only = snap.model.clone();
    mb_only.depth_of_field.present = false;
    mb_only.noise.present = false;
    let half_f16 = |b: &[u8]| -> Vec<[f32; 4]> {
        let v: Vec<f32> = b.chunks_exact(2).map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32()).collect();
        v.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect()
    };
    let n = (w * h) as usize;
    let mut reference_dof: Option<Vec<[f32; 4]>> = None;
    let mut reference_mb: Option<Vec<[f32; 4]>> = None;
    let configs: Vec<(&str, String, LayerSettings, &CameraModel)> = vec![
        (
            "DoF",
            "full resolution, step 1".into(),
            LayerSettings { dof_half_res: false, dof_step_px: 1, ..Default::default() },
            &dof_only,
        ),
        (
            "DoF",
            "full resolution, step 2".into(),
            LayerSettings { dof_half_res: false, dof_step_px: 2, ..Default::default() },
            &dof_only,
        ),
        (
            "DoF",
            "half resolution, step 1 (default)".into(),
            LayerSettings { dof_half_res: true, ..Default::default() },
            &dof_only,
        ),
        (
            "DoF",
            "half resolution, step 2".into(),
            LayerSettings { dof_half_res: true, dof_step_px: 2, ..Default::default() },
            &dof_only,
        ),
        ("MB", "6 taps".into(), fixed_mb(6), &mb_only),
        ("MB", "12 taps (default)".into(), fixed_mb(12), &mb_only),
        ("MB", "24 taps".into(), fixed_mb(24), &mb_only),
        ("MB", "≤ 12 taps, 1 per streak px".into(), adaptive_mb(12, 1.0), &mb_only),
        ("MB", "≤ 12 taps, 2 per streak px".into(), adaptive_mb(12, 2.0), &mb_only),
        ("MB", "≤ 24 taps, 2 per streak px".into(), adaptive_mb(24, 2.0), &mb_only),
    ];
    for (effect, name, settings, model) in configs {
        let mut r = StereoRenderer::new(ctx, scene, w, h, settings, Some(f)).expect("renderer");
        r.enable_profiling().expect("timestamps");
        r.set_background(&vec![128u8; n * 8]).expect("background");
        let (s, _) = setup(scene, &r, f, 0.1);
        let snap_local = Snapshot::new(2, model.clone());
        let p = profile(&mut r, &snap_local, &s, true);
        let fx = r.last_effects.expect("effects");
        let rect = fx.rects[0];
        let colour = half_f16(&r.gbuffer().colour().download().expect("colour"));
        let motion = half_f16(&r.gbuffer().motion().download().expect("motion"));
        // Only the G-buffer pass's area was written this frame: empty elsewhere.
        let area = r.gbuffer_area();
        let keep = |v: &[[f32; 4]]| -> Vec<[f32; 4]> {
            (0..n)
                .map(|i| if area.contains((i % w as usize) as i32, (i / w as usize) as i32) { v[i] } else { [0.0; 4] })
                .collect()
        };
        let layer = Layer { width: w as usize, height: h as usize, colour: keep(&colour), motion: keep(&motion) };
        let (gpu, reference, gpu_ms) = if effect == "DoF" {
            let gpu = half_f16(&r.effects().dof_out.download().expect("dof"))[..n].to_vec();
            let reference = reference_dof
                .get_or_insert_with(|| defocus_layer_exact(&layer, &model.depth_of_field, fx.ppr_ratio))
                .clone();
            (gpu, reference, p.dof_ms)
        } else {
            let gpu = half_f16(&r.effects().mb_out.download().expect("mb"))[..n].to_vec();
            let reference = reference_mb
                .get_or_insert_with(|| {
                    motion_blur_layer(
                        &layer.colour,
                        &layer.motion,
                        w as usize,
                        h as usize,
                        fx.exposure_ratio,
                        settings.mb_tile_px,
                        64,
                        0.0,
                        fx.frame,
                        0,
                        rect,
                    )
                })
                .clone();
            (gpu, reference, p.mb_ms)
        };
        let (mae, p99) = error_in(&gpu, &reference, rect, w as usize);
        println!(
            "| {effect} | {name} | {:.3} | {:.2} | {} | {} |",
            mae * 255.0,
            p99 * 255.0,
            ms(gpu_ms),
            p.effects_stats.compute_invocations.saturating_sub(composite_invocations(w, h))
        );
    }
}

fn error_in(a: &[[f32; 4]], b: &[[f32; 4]], rect: Rect, w: usize) -> (f64, f64) {
    let mut errs = vec![];
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let i = y as usize * w + x as usize;
            for c in 0..4 {
                errs.push((a[i][c] - b[i][c]).abs() as f64);
            }
        }
    }
    if errs.is_empty() {
        return (0.0, 0.0);
    }
    let mae = errs.iter().sum::<f64>() / errs.len() as f64;
    let k = ((errs.len() - 1) as f64 * 0.99) as usize;
    let p99 = *errs.select_nth_unstable_by(k, |x, y| x.total_cmp(y)).1;
    (mae, p99)
}

/// `n` unit cubes, each its own node, mesh and primitive (one draw each), on a
/// grid: the many-primitive scene a CAD export or a kit-bashed room gives.
fn many_primitives(n: usize) -> Scene {
    use base64::Engine as _;
    let (p, idx) = {
        let mut p: Vec<[f32; 3]> = Vec::new();
        let mut idx: Vec<u16> = Vec::new();
        // 6 faces × 4 vertices (flat normals come from the loader), CCW outward.
        let faces: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
            ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
            ([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
            ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]),
            ([0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            ([0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]),
        ];
        for (k, (nrm, u, v)) in faces.iter().enumerate() {
            for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                p.push(std::array::from_fn(|i| 0.5 * (nrm[i] + a * u[i] + b * v[i])));
            }
            let o = (4 * k) as u16;
            idx.extend_from_slice(&[o, o + 1, o + 2, o, o + 2, o + 3]);
        }
        (p, idx)
    };
    let mut bin: Vec<u8> = bytemuck::cast_slice(&p).to_vec();
    bin.extend_from_slice(bytemuck::cast_slice(&idx));
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin));
    let side = (n as f64).cbrt().ceil() as usize;
    let nodes: Vec<serde_json::Value> = (0..n)
        .map(|i| {
            let (x, y, z) = (i % side, (i / side) % side, i / (side * side));
            serde_json::json!({"mesh": i, "translation": [2.0 * x as f32, 2.0 * y as f32, 2.0 * z as f32]})
        })
        .collect();
    let meshes: Vec<serde_json::Value> = (0..n)
        .map(|_| serde_json::json!({"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}))
        .collect();
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": (0..n).collect::<Vec<_>>()}],
        "nodes": nodes, "meshes": meshes,
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.5, 0.3, 1.0]}}],
        "buffers": [{"uri": uri, "byteLength": bin.len()}],
        "bufferViews": [{"buffer": 0, "byteLength": 288}, {"buffer": 0, "byteOffset": 288, "byteLength": 72}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 24, "type": "VEC3", "min": [-0.5, -0.5, -0.5], "max": [0.5, 0.5, 0.5]},
            {"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"}
        ]
    });
    Scene::from_glb(&serde_json::to_vec(&doc).expect("json"), "many_primitives.gltf").expect("generated scene")
}

/// glTF scenes at scale, at the Quest 3 eye (1680×1760) with the object covering
/// ~30% of it: load time, the CPU time of a frame's two poses (`Scene::pose_at`,
/// now and one frame ago: node matrices, skinning, morphing), and the GPU's
/// G-buffer and matched-frame time. Scenes: the bundled toy, 500 single-primitive
/// cubes, and each file in FRAME_BENCH_GLTF (paths separated by `:`; e.g. a large
/// textured model and a skinned one from a git mirror).
fn scene_rows(ctx: &GpuContext, snap: &Snapshot) {
    use std::time::Instant;
    let mut scenes: Vec<(String, Box<dyn Fn() -> Scene>)> = vec![
        ("assets/toy.glb".into(), Box::new(|| Scene::from_glb(TOY, "toy.glb").expect("toy"))),
        ("500 cubes, one primitive each (generated)".into(), Box::new(|| many_primitives(500))),
    ];
    for path in std::env::var("FRAME_BENCH_GLTF").unwrap_or_default().split(':').filter(|p| !p.is_empty()) {
        let path = std::path::PathBuf::from(path);
        scenes.push((
            path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned()),
            Box::new(move || Scene::load(&path).expect("FRAME_BENCH_GLTF file loads")),
        ));
    }
    println!("\n### glTF scenes at scale (1680×1760, ~30% coverage)\n");
    println!("| scene | primitives | triangles | deforming vertices | texels | load ms | two poses ms (CPU) | G-buffer ms | matched frame ms |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let (w, h) = (1680u32, 1760u32);
    for (name, make) in &scenes {
        let start = Instant::now();
        let scene = make();
        let load_ms = start.elapsed().as_secs_f64() * 1e3;
        let tris: usize = scene.meshes.iter().map(|m| m.indices.len() / 3).sum();
        let deforming: usize = scene.meshes.iter().filter(|m| m.deform.is_some()).map(|m| m.vertices.len()).sum();
        let texels: u64 = scene.textures.iter().map(|t| t.width as u64 * t.height as u64).sum();
        // Unit size, centred: every scene placed alike.
        let c = scene.world_corners(0.0, Mat4::IDENTITY);
        let (lo, hi) =
            c.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(a, b), p| (a.min(*p), b.max(*p)));
        let base = Mat4::from_scale(Vec3::splat(1.0 / (hi - lo).max_element().max(1e-6)))
            * Mat4::from_translation(-(lo + hi) * 0.5);
        let mut poses = vec![];
        for k in 0..21 {
            let t = 0.7 + k as f64 / 45.0;
            let start = Instant::now();
            let a = scene.pose_at(t, base);
            let b = scene.pose_at(t - 1.0 / 45.0, base);
            poses.push(start.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box((a, b));
        }
        poses.sort_by(f64::total_cmp);
        let (mut r, f) = profiled_renderer(ctx, &scene, w, h);
        let (s, _) = setup_from(&scene, &r, f, 0.3, base);
        let m = profile(&mut r, snap, &s, true);
        println!(
            "| {name} | {} | {tris} | {deforming} | {texels} | {} | {} | {} | {} |",
            scene.meshes.len(),
            ms(load_ms),
            ms(poses[poses.len() / 2]),
            ms(m.gbuffer_ms),
            ms(total(&m)),
        );
    }
}
