//! Live calibration end to end on recorded video with known truth (the bundled
//! Motorcycle photograph with its real depth, re-rendered along a head path and
//! distorted by a camera that changes mid-sequence): the calibrator converges, it
//! follows the change within 1 s of video, the worker thread publishes through the
//! channel without blocking the submitter, and bad input is refused by name. The
//! worker's noise on the same video: tests/calibrate_noise.rs.

mod common;

use blind_augment::analysis::Frame;
use blind_augment::image::Rgb;
use blind_augment::model::compare::{dof_rmse_px, exposure_error, noise_relative_error};
use blind_augment::model::CameraModel;
use blind_augment::synth::sequence::{procedural, SequenceSpec};
use blind_augment::worker::{
    CalibError, CalibrationTier, Calibrator, CalibratorConfig, Event, ModelChannel, Phase, Providers, UpdateReason,
    Worker,
};
use common::calibration::*;

/// Blind δ(Z) from video, where the frames' own blur is known: the calibration
/// video's depth and head path under `synth::sequence::procedural`'s hard-edged
/// texture, 640×480 (sampled 1:1 from a 2× texture: its own blur a one-pixel box,
/// 0.29 px, below what the edge ratio resolves), 45 frames, the fast tier. Every
/// publication from 0.5 s on (the first turn starts at 0.4 s; mid-turn frames,
/// whose motion blur widens edges, must not enter the pooled curve) reads the truth
/// within 0.1 px RMSE over its depth range (the accurate tier's target;
/// measured 0.024–0.040 px; with the moving frames let into the pool it read
/// 0.27 px at 1.23 s).
#[test]
fn fast_tier_reads_depth_of_field_on_a_texture_of_known_blur() {
    let textured = procedural(scene(), 2, 11);
    let spec = SequenceSpec::motorcycle(&textured, 640, 480, 45, None);
    let cfg = CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, Some(spec.view));
    let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast)).expect("valid config");
    let r = spec.truth.depth_of_field.depth_range;
    let depths: Vec<f32> = (0..16).map(|i| r[0] + (r[1] - r[0]) * (i as f32 + 0.5) / 16.0).collect();
    let mut checked = 0;
    drive(&mut cal, &spec, &textured, |f, e| {
        let Event::Published(u) = e else { return };
        if u.t_s < 0.5 {
            return;
        }
        let d = &u.model.depth_of_field;
        let rmse = dof_rmse_px(d, &f.truth.depth_of_field, &depths).expect("δ(Z) published");
        assert!(rmse <= 0.1, "t = {:.2} s: δ RMSE {rmse:.3} px ({})", u.t_s, d.diagnostics.reason);
        checked += 1;
    });
    assert!(checked >= 10, "{checked} publications checked");
}

/// The accurate tier (video as its own reference) before and after the change.
/// Tolerances, from the accurate tier's targets where this 320×240 sequence
/// meets them, wider where it cannot and why:
/// * λ within 0.02 before the change (goal 0.01; measured 0.006–0.011: the first
///   estimates come from frames early in a turn, with 3–5 px of motion);
/// * noise within 6% (goal 3%; measured 2–5%: at 320×240 the coarse levels have
///   few samples, and bicubic alignment lowers the reference's level-0 noise
///   below the 1/m the fit divides out);
/// * after the change at 1.5 s: a change is detected within 1 s of video, and the
///   model published 1 s after the change has λ within 0.03 of the new 0.25.
#[test]
fn accurate_tier_converges_and_follows_a_camera_change() {
    let (published, changes) = run(CalibrationTier::Accurate);
    assert!(!published.is_empty());
    let before: Vec<&(f64, CameraModel, CameraModel)> =
        published.iter().filter(|p| p.0 > 1.0 && p.0 < CHANGE_S).collect();
    let last_before = before.last().expect("a model published before the change");
    let lam = exposure_error(&last_before.1, &last_before.2);
    let noise = noise_relative_error(&last_before.1.noise, &last_before.2.noise).expect("noise present");
    eprintln!("before the change: λ error {lam:.4}, noise {:.1}%", 100.0 * noise);
    assert!(lam < 0.02, "λ error {lam}");
    assert!(noise < 0.06, "noise error {noise}");
    let detected = changes.iter().find(|t| **t >= CHANGE_S).expect("the change is detected");
    eprintln!("change at {CHANGE_S} s detected at {detected:.2} s; all detections {changes:?}");
    assert!(*detected <= CHANGE_S + 1.0, "detected at {detected}");
    let after = published.iter().rfind(|p| p.0 <= CHANGE_S + 1.0).expect("published");
    let lam = exposure_error(&after.1, &after.2);
    eprintln!("1 s after the change: λ {:?} (truth 0.25), error {lam:.4}", after.1.motion_blur.exposure);
    assert!(lam < 0.03, "λ error {lam} at {}", after.0);
}

/// The fast tier (blind fits; the previous frame aligned for noise) publishes every
/// frame and never anything invalid, presence does not flicker, and:
/// * noise within the fast tier's 10% target in the half second before the change
///   (median of the publications; measured ~5% on the 150-frame bench sequence);
/// * λ within the fast tier's 0.05 target just before the change and 1 s after it
///   (measured 0.005 and 0.0001; the blind estimators alone held no λ after the
///   change: its ≤ 2.3 px streaks are not identifiable from one frame);
/// * after the burst, the previous frame is aligned at most once per 0.1 s of video
///   (the noise probe's interval): the noise refit waits for a frame the probe
///   aligned instead of aligning again out of phase (which would align twice per
///   0.1 s; the alignment is the largest single cost of a fast update);
/// * in the start-up burst each effect is refitted on every other frame, noise
///   never on the update that refits motion blur (the noise fit's alignment and
///   the motion-blur fit's references, ~20 ms each at 1280×960, on separate
///   updates; the first frame, with nothing to align and no references, aside),
///   and each 13–16 times in the burst's other 29 frames.
#[test]
fn fast_tier_publishes_every_frame_and_presence_does_not_flicker() {
    let (published, _, stages) = run_with_stages(CalibrationTier::Fast);
    assert_eq!(published.len(), sequence().1.len(), "one model per frame");
    // Hysteresis: once on, noise stays on.
    let flips = published.windows(2).filter(|w| w[0].1.noise.present != w[1].1.noise.present).count();
    assert!(flips <= 1, "noise presence flipped {flips} times");
    let median = noise_error_before_change(&published);
    eprintln!("fast tier noise error before the change: median {:.1}%", 100.0 * median);
    assert!(median < 0.10, "noise error {median}");
    // λ against two sharp frames aligned sparsely (the cross loss), the fast
    // tier's target of 0.05: before the change, and 1 s after it.
    let last_before = published.iter().rfind(|p| p.0 < CHANGE_S).expect("published before the change");
    let after = published.iter().rfind(|p| p.0 <= CHANGE_S + 1.0).expect("published after the change");
    let (lam_before, lam_after) = (exposure_error(&last_before.1, &last_before.2), exposure_error(&after.1, &after.2));
    eprintln!(
        "fast tier λ: {:?} before the change (error {lam_before:.4}), {:?} 1 s after (truth 0.25, error {lam_after:.4})",
        last_before.1.motion_blur.exposure, after.1.motion_blur.exposure
    );
    assert!(lam_before < 0.05, "λ error {lam_before} before the change");
    assert!(lam_after < 0.05, "λ error {lam_after} 1 s after the change");
    // Steady state between the start-up burst (1 s) and the change (its burst).
    let aligned: Vec<f64> = stages
        .iter()
        .filter(|(t, s)| *t >= 1.0 && *t < CHANGE_S && s.iter().any(|(k, _)| *k == "alignment"))
        .map(|(t, _)| *t)
        .collect();
    let span_s = CHANGE_S - 1.0;
    eprintln!("alignments at {aligned:?}");
    assert!(!aligned.is_empty(), "the fast tier aligns the previous frame");
    assert!(aligned.len() as f64 <= span_s / 0.1 + 1.0, "{} alignments in {span_s} s", aligned.len());
    // The burst's first frame has no previous frame: nothing to align, no references.
    let burst: Vec<&(f64, Vec<(&str, f64)>)> = stages.iter().filter(|(t, _)| *t > 1e-9 && *t < 1.0 - 1e-9).collect();
    let fits = |u: &(f64, Vec<(&str, f64)>), k: &str| u.1.iter().any(|(s, _)| *s == k);
    let both: Vec<f64> =
        burst.iter().filter(|u| fits(u, "fit.noise") && fits(u, "fit.motion_blur")).map(|u| u.0).collect();
    assert!(both.is_empty(), "noise and motion blur refitted on the same burst updates at {both:?}");
    for k in ["fit.noise", "fit.motion_blur"] {
        let n = burst.iter().filter(|u| fits(u, k)).count();
        assert!((13..=16).contains(&n), "{k} on {n} of the burst's {} updates", burst.len());
    }
}

/// The worker thread: frames submitted far faster than it fits are dropped (the
/// slot holds one), models arrive through the channel in generation order, the
/// thread and its fit pool run at lowered priority, and stopping it joins.
#[test]
fn worker_thread_drops_frames_and_publishes_through_the_channel() {
    let (spec, frames) = sequence();
    let channel = ModelChannel::new(CameraModel::empty(320, 240)).expect("valid initial model");
    let tier = CalibrationTier::Accurate;
    let cal = Calibrator::new(CalibratorConfig::new(tier, 1.0 / 30.0, Some(spec.view)), Providers::for_tier(tier))
        .expect("config");
    let worker = Worker::spawn(cal, channel.clone()).expect("thread");
    assert!(worker.wants_frame(), "an idle worker wants a frame");
    // Poses alone (the frame loop's) queue until the next frame takes them.
    worker.submit_poses(&[pose(spec, 0), pose(spec, 1)]);
    worker.submit(frame(&frames[0]), &[pose(spec, 2)]);
    assert!(worker.wait_idle(std::time::Duration::from_secs(60)));
    assert!(worker.wants_frame());
    // A burst with no waiting: most of these replace each other in the slot.
    for f in &frames[1..40] {
        worker.submit(frame(f), &[pose(spec, f.index + 2)]);
    }
    assert!(worker.wait_idle(std::time::Duration::from_secs(120)));
    // Every calibration thread — the worker and its fit pool — runs at nice 19; a
    // fit on the shared pool would run at normal priority beside the frame loop.
    #[cfg(target_os = "linux")]
    {
        let mut nices = vec![];
        for t in std::fs::read_dir("/proc/self/task").expect("/proc").flatten() {
            let comm = std::fs::read_to_string(t.path().join("comm")).unwrap_or_default();
            if comm.trim().starts_with("calibration") {
                let stat = std::fs::read_to_string(t.path().join("stat")).unwrap_or_default();
                // Fields after the parenthesised name: state is field 3, nice field 19.
                let rest = stat.rsplit_once(')').map_or("", |r| r.1);
                let nice: i32 = rest.split_whitespace().nth(16).and_then(|v| v.parse().ok()).unwrap_or(0);
                nices.push((comm.trim().to_string(), nice));
            }
        }
        assert!(nices.len() >= 2, "worker and pool threads: {nices:?}");
        assert!(nices.iter().all(|(_, n)| *n == 19), "calibration threads not at nice 19: {nices:?}");
    }
    // What the status panel reads while the worker runs: idle, it has counted
    // everything `stop` then reports, and 40 frames at 30 fps are past the burst.
    let live = worker.status();
    let stats = worker.stop();
    assert_eq!(
        (live.submitted, live.dropped, live.processed, live.published, live.errors),
        (stats.submitted, stats.dropped, stats.processed, stats.published.len() as u64, stats.errors.len() as u64)
    );
    assert_eq!(live.phase, Phase::Steady);
    eprintln!(
        "submitted {}, dropped {}, processed {}, published {}, priority error {:?}",
        stats.submitted,
        stats.dropped,
        stats.processed,
        stats.published.len(),
        stats.priority_error
    );
    assert_eq!(stats.submitted, 40);
    assert_eq!(stats.processed + stats.dropped, 40, "every frame is processed or dropped, none queued");
    assert!(stats.dropped > 0, "a burst must overflow a one-frame slot");
    assert!(!stats.published.is_empty());
    let gens: Vec<u64> = stats.published.iter().map(|p| p.generation).collect();
    assert!(gens.windows(2).all(|w| w[1] > w[0]), "generations increase: {gens:?}");
    assert_eq!(channel.latest().generation, *gens.last().expect("published"));
    #[cfg(target_os = "linux")]
    assert!(stats.priority_error.is_none(), "priority not lowered: {:?}", stats.priority_error);
}

/// Bad input: each is refused with an error naming it (or reported as an event),
/// never a panic, never an invalid model.
#[test]
fn bad_input_is_refused_by_name() {
    let (spec, frames) = sequence();
    let tier = CalibrationTier::Accurate;
    let mut cal = Calibrator::new(CalibratorConfig::new(tier, 1.0 / 30.0, Some(spec.view)), Providers::for_tier(tier))
        .expect("config");
    cal.push_poses(&[pose(spec, 0), pose(spec, 1), pose(spec, 2)]).expect("poses");
    cal.push_frame(frame(&frames[0])).expect("first frame");
    // A frame of another size.
    let mut small = frame(&frames[1]);
    small.image = Rgb::new(160, 120, [0.5; 3]);
    let e = cal.push_frame(small).unwrap_err();
    assert!(matches!(e, CalibError::Intrinsics { .. } | CalibError::FrameSize { .. }), "{e}");
    // A frame with NaN.
    let mut nan = frame(&frames[1]);
    nan.image.channels[1][5] = f32::NAN;
    assert!(matches!(cal.push_frame(nan).unwrap_err(), CalibError::NonFinite { frame: 1, .. }));
    // Time going backwards.
    let mut back = frame(&frames[1]);
    back.t_s = -1.0;
    assert!(matches!(cal.push_frame(back).unwrap_err(), CalibError::Time { .. }));
    // A non-unit quaternion.
    let mut p = pose(spec, 3);
    p.orientation = p.orientation * 2.0;
    let e = cal.push_poses(&[p]).unwrap_err();
    assert!(e.to_string().contains("not a unit quaternion"), "{e}");
    // A tracking loss (a 3 m jump in one frame): reported, history dropped, no panic.
    let mut jump = pose(spec, 3);
    jump.position_m.x += 3.0;
    let events = cal.push_poses(&[jump]).expect("a jump is an event, not an error");
    assert!(events.iter().any(|e| matches!(e, Event::TrackingLoss { .. })), "{events:?}");
    // A frame without depth, after the loss (no poses around it either): the fit
    // goes on without the providers that need them, and says so.
    let mut no_depth = frame(&frames[2]);
    no_depth.depth = None;
    let events = cal.push_frame(no_depth).expect("a frame without depth is degraded, not refused");
    assert!(events.iter().any(|e| matches!(e, Event::Degraded { .. })), "{events:?}");
    for e in &events {
        if let Event::Published(u) = e {
            u.model.validate().expect("valid");
        }
    }
    // A bad configuration.
    let mut cfg = CalibratorConfig::new(tier, 0.0, Some(spec.view));
    assert!(matches!(Calibrator::new(cfg.clone(), Providers::for_tier(tier)).unwrap_err(), CalibError::Config(_)));
    cfg.frame_interval_s = 1.0 / 30.0;
    // The blind fits' effort outside [0.25, 1] (`FitOptions::fast_effort`): refused
    // when the worker is made, not on every frame.
    for bad in [0.2f32, 1.5, f32::NAN] {
        let cfg = CalibratorConfig { fast_effort: bad, ..cfg.clone() };
        let err = Calibrator::new(cfg, Providers::for_tier(tier)).unwrap_err();
        assert!(matches!(&err, CalibError::Config(m) if m.contains("fast effort")), "{bad}: {err}");
    }
    cfg.intrinsics.as_mut().expect("set").fx = f32::NAN;
    assert!(matches!(Calibrator::new(cfg, Providers::for_tier(tier)).unwrap_err(), CalibError::Config(_)));
}

fn cli(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_blind-augment")).args(args).output().expect("the binary runs")
}

/// `synth-video` then `calibrate` on its files: the recorded-sequence path end to
/// end (files, poses.csv, intrinsics, timeline, plots), and its bad inputs.
#[test]
fn calibrate_command_on_a_recorded_sequence() {
    let dir = std::env::temp_dir().join(format!("ba-calibrate-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let seq = dir.join("seq");
    let out = cli(&["synth-video", "--out", seq.to_str().unwrap(), "--frames", "24", "--size", "160x120"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let intrinsics = std::fs::read_to_string(seq.join("intrinsics.txt")).expect("intrinsics.txt");
    let s = |p: &str| seq.join(p).to_str().unwrap().to_string();
    let cam = dir.join("camera.json");
    let timeline = dir.join("timeline.jsonl");
    let plots = dir.join("plots");
    let args = [
        "calibrate",
        "--frames",
        &s("frames"),
        "--depth",
        &s("depth"),
        "--poses",
        &s("poses.csv"),
        "--intrinsics",
        intrinsics.trim(),
        "--tier",
        "balanced",
        "--out",
        cam.to_str().unwrap(),
        "--timeline",
        timeline.to_str().unwrap(),
        "--plots",
        plots.to_str().unwrap(),
        "--truth",
        &s("truth.jsonl"),
    ];
    let out = cli(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("against the truth"), "{err}");
    let model = CameraModel::from_json(&std::fs::read_to_string(&cam).expect("camera.json")).expect("valid model");
    assert_eq!((model.reference.width, model.reference.height), (160, 120));
    let lines = std::fs::read_to_string(&timeline).expect("timeline");
    assert!(lines.lines().count() >= 5, "{lines}");
    for l in lines.lines() {
        let v: serde_json::Value = serde_json::from_str(l).expect("one JSON object per line");
        assert!(v["frame"].is_u64() && v["t_s"].is_f64() && v["model"].is_object(), "{l}");
    }
    assert!(plots.join("timeline.png").exists());

    // Bad inputs, each named.
    let bad = |args: &[&str], needle: &str| {
        let out = cli(args);
        let err = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(!out.status.success() && err.contains(needle), "expected `{needle}` in: {err}");
    };
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).expect("mkdir");
    bad(&["calibrate", "--frames", empty.to_str().unwrap(), "--out", cam.to_str().unwrap()], "holds no images");
    let poses_text = std::fs::read_to_string(seq.join("poses.csv")).expect("poses");
    let broken = dir.join("broken.csv");
    let mut lines: Vec<String> = poses_text.lines().map(str::to_string).collect();
    let mut fields: Vec<&str> = lines[3].split(',').collect();
    fields[8] = "1.5"; // qw: the quaternion is no longer unit length
    lines[3] = fields.join(",");
    std::fs::write(&broken, lines.join("\n")).expect("write");
    bad(
        &[
            "calibrate",
            "--frames",
            &s("frames"),
            "--poses",
            broken.to_str().unwrap(),
            "--intrinsics",
            intrinsics.trim(),
            "--out",
            cam.to_str().unwrap(),
        ],
        "not a unit quaternion",
    );
    let short = dir.join("short.csv");
    std::fs::write(&short, poses_text.lines().take(5).collect::<Vec<_>>().join("\n")).expect("write");
    bad(
        &[
            "calibrate",
            "--frames",
            &s("frames"),
            "--poses",
            short.to_str().unwrap(),
            "--intrinsics",
            intrinsics.trim(),
            "--out",
            cam.to_str().unwrap(),
        ],
        "has no row",
    );
    bad(
        &["calibrate", "--frames", &s("frames"), "--poses", &s("poses.csv"), "--out", cam.to_str().unwrap()],
        "--intrinsics",
    );
    let mixed = dir.join("mixed");
    std::fs::create_dir_all(&mixed).expect("mkdir");
    std::fs::copy(seq.join("frames/0000.png"), mixed.join("0000.png")).expect("copy");
    image::RgbImage::new(32, 32).save(mixed.join("0001.png")).expect("png");
    bad(&["calibrate", "--frames", mixed.to_str().unwrap(), "--out", cam.to_str().unwrap()], "32×32");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The fast tier pools motion blur over flow directions (`fit_fast_pooled_exposure`
/// in the worker): a camera panning over a strongly anisotropic texture (σ 3 px
/// along x, 1.2 along y: ~6× the gradient energy along y) at 12 px/frame, λ 0.5,
/// under σ 1.2 px defocus and noise, 320×240, flow given; the pan turns between
/// 90°, 30° and 150° every 4 frames. Along 90° the frame alone cannot answer
/// (57% more gradient energy along the flow than across, before any streak: *not
/// identifiable*); along 30° the streak's zeros read 0.525 ± 0.018 but their first
/// side lobe lies under the noise floor — what an oriented texture 10° off the flow
/// shows too — so they are not taken (`streak_spectrum::MIN_SIDE_LOBE`), and no
/// single frame answers. Checked: (a) once the pool holds three directions (from
/// the first 150° frame), every frame's estimate counts in the window (the pooled
/// λ replaces its *not identifiable*): the published "median over p of n" has
/// p ≥ n − 8 at every later 90° frame (the first eight frames, before a third
/// direction, stay out); (b) every λ published from then on is within 0.05 of 0.5,
/// the fast tier's target (measured 0.479–0.502).
#[test]
fn fast_tier_pools_motion_blur_over_flow_directions() {
    use blind_augment::fit::Effects;
    use blind_augment::image::{Flow, Plane};
    use blind_augment::synth::{add_defocus, add_motion_blur, gaussian, sequence::anisotropic_texture};
    let (w, h, speed, lambda) = (320usize, 240usize, 12.0f32, 0.5f32);
    let big = anisotropic_texture(800, 700, 3.0, 1.2, 17);
    let mut cfg = CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, None);
    cfg.effects = Effects { noise: false, motion_blur: true, depth_of_field: false };
    let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast).with_given_flow()).expect("config");
    // The crop's top-left corner pans along the flow (a camera turning over a wall).
    let (mut x, mut y) = (200.0f32, 200.0f32);
    let (mut checked, mut pooled_checked) = (0, 0);
    for i in 0..36usize {
        let deg = [90.0f32, 30.0, 150.0][(i / 4) % 3];
        // Back along the same lines on every other round (the crop stays on the
        // texture; a direction and its opposite are one direction to a streak).
        let sign = if (i / 12) % 2 == 0 { 1.0 } else { -1.0 };
        let (dx, dy) = (sign * speed * deg.to_radians().cos(), sign * speed * deg.to_radians().sin());
        // Frame content: the texture under the crop, streaked by the pan.
        let (cx, cy) = (x.round() as usize, y.round() as usize);
        let sharp = {
            let mut c = Rgb::new(w, h, [0.0; 3]);
            for ch in 0..3 {
                for r in 0..h {
                    let src = (cy + r) * big.width + cx;
                    c.channels[ch][r * w..(r + 1) * w].copy_from_slice(&big.channels[ch][src..src + w]);
                }
            }
            c
        };
        // The pan moves the scene by −(dx, dy) in the frame; a streak is a streak
        // either way along its line.
        let flow = Flow::uniform(w, h, dx, dy);
        // A soft lens (σ 1.5 px) and sensor noise (std 0.01): what leaves a 4 px
        // streak's spectral zeros unidentified, so the frames answer by isotropy.
        let mut image = add_defocus(&add_motion_blur(&sharp, &flow, lambda), &Plane::new(w, h, 1.2));
        for (c, ch) in image.channels.iter_mut().enumerate() {
            for (k, v) in ch.iter_mut().enumerate() {
                *v += 0.01 * gaussian((k % w) as u32, (k / w) as u32, c as u32, i as u64);
            }
        }
        let image = image.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
        let frame = Frame { index: i as u64, t_s: i as f64 / 30.0, image, depth: None, flow: Some(flow) };
        for e in cal.push_frame(frame).expect("valid frame") {
            let Event::Published(u) = e else { continue };
            let mb = &u.model.motion_blur;
            eprintln!("t {:.2} s ({deg}°): λ {:?} — {}", u.t_s, mb.exposure, mb.diagnostics.reason);
            if i < 8 {
                continue;
            }
            let got = mb.exposure.expect("λ published");
            assert!((got - lambda).abs() <= 0.05, "t {:.2}: λ {got} for {lambda} — {}", u.t_s, mb.diagnostics.reason);
            if i >= 12 && deg == 90.0 {
                // "median over {present} of {total} frames" (`fit::aggregate_models`).
                let counts: Vec<usize> = mb
                    .diagnostics
                    .reason
                    .trim_start_matches("median over ")
                    .split(" frames")
                    .next()
                    .unwrap_or_default()
                    .split(" of ")
                    .filter_map(|v| v.parse().ok())
                    .collect();
                assert_eq!(counts.len(), 2, "reason: {}", mb.diagnostics.reason);
                assert!(counts[0] + 8 >= counts[1], "t {:.2}: frames left out: {}", u.t_s, mb.diagnostics.reason);
                pooled_checked += 1;
            }
            checked += 1;
        }
        x += dx;
        y += dy;
    }
    assert!(checked >= 20 && pooled_checked >= 4, "{checked} publications checked, {pooled_checked} at 90°");
}

/// The camera changes a run detects (time, cause) and every published (time, λ).
type ChangesAndLambdas = (Vec<(f64, String)>, Vec<(f64, Option<f32>)>);

/// Run a tier over `spec` (rendered here); the times of the camera changes it
/// detects, with their causes, and every published (t, λ).
fn changes_over(tier: CalibrationTier, spec: &SequenceSpec) -> ChangesAndLambdas {
    let mut cal = Calibrator::new(CalibratorConfig::new(tier, 1.0 / 30.0, Some(spec.view)), Providers::for_tier(tier))
        .expect("valid config");
    let (mut changes, mut lambdas) = (vec![], vec![]);
    drive(&mut cal, spec, scene(), |_, e| match e {
        Event::ChangeDetected { t_s, cause, .. } => changes.push((t_s, cause)),
        Event::Published(u) => lambdas.push((u.t_s, u.model.motion_blur.exposure)),
        _ => {}
    });
    (changes, lambdas)
}

/// The demo's camera (`blind-augment demo`: λ 0.4, its noise and thin-lens δ(Z)),
/// which never changes: neither tier may report a camera change. The sharp-frame
/// λ reference drifted during the sequence's long turn (the fast tier's fits read
/// 0.32 … 0.64 on frames 20–29, the reprojected rest frames' depth edges); judged
/// against the estimates' own standard errors (0.01–0.02) two of them read as an
/// exposure change — at 0.63 s (accurate) and 0.90 s (fast) before
/// `exposure_scatter` — and the restart published the drifted λ (fast: 0.534 from
/// 0.9 s on). Every published λ within 0.05 (fast) and 0.06 (accurate) of 0.4:
/// measured 0.018 and 0.033, against 0.081 and 0.140 with the depth edges in the
/// reference (`analysis::temporal::DEPTH_EDGE_PX`).
#[test]
fn a_drifting_reference_is_not_a_camera_change() {
    let mut spec = SequenceSpec::motorcycle(scene(), 320, 240, 45, None);
    common::demo_camera(&mut spec);
    for (tier, bound) in [(CalibrationTier::Fast, 0.05f32), (CalibrationTier::Accurate, 0.06)] {
        let (changes, lambdas) = changes_over(tier, &spec);
        assert!(changes.is_empty(), "{tier:?}: {changes:?}");
        let worst = lambdas.iter().filter_map(|l| l.1).map(|l| (l - 0.4).abs()).fold(0.0f32, f32::max);
        eprintln!("{tier:?}: worst published λ error {worst:.3}");
        assert!(worst <= bound, "{tier:?}: a published λ {worst:.3} off 0.4");
    }
}

/// An exposure change alone (λ 0.5 → 0.25 at 1 s, the noise unchanged, so the noise
/// probe cannot see it). The fast tier still finds it by its λ estimates (measured
/// 0.97 s after it, before and after `exposure_scatter`; bound 1.5 s), and both tiers'
/// publications follow the new λ: the last within 0.03 (measured 0.263 fast, 0.249
/// accurate). The accurate tier reports no change here, before and after: its λ
/// refits are too sparse for two in a row off the model before the window turns
/// over; the aggregation follows the new λ anyway.
#[test]
fn an_exposure_change_alone_is_found_by_the_estimates() {
    let mut spec = SequenceSpec::motorcycle(scene(), 320, 240, 75, None);
    let mut after = spec.truth.clone();
    after.motion_blur.exposure = Some(0.25);
    spec.change = Some((1.0, after));
    for tier in [CalibrationTier::Fast, CalibrationTier::Accurate] {
        let (changes, lambdas) = changes_over(tier, &spec);
        eprintln!("{tier:?}: changes {changes:?}; last λ {:?}", lambdas.last());
        assert!(changes.iter().all(|c| c.0 >= 1.0), "{tier:?}: a change before it: {changes:?}");
        if tier == CalibrationTier::Fast {
            let found = changes.first().unwrap_or_else(|| panic!("{tier:?}: not found"));
            assert!(found.0 <= 2.5, "{tier:?}: found at {} s", found.0);
        }
        let last = lambdas.last().and_then(|l| l.1).expect("a λ published");
        assert!((last - 0.25).abs() <= 0.03, "{tier:?}: last λ {last}");
    }
}

/// The user's "restart calibration": after the start-up burst the fast tier
/// publishes on its schedule; restarted at 1.2 s, the next frames publish as a
/// start-up burst again (every frame, reason Burst), and the phase the status
/// panel shows follows (waiting, burst counting up to `burst_s`, steady, waiting
/// after the restart, burst again), from frames after the restart
/// only, and frame times and poses go on as before.
#[test]
fn restart_opens_a_new_start_up_burst() {
    let (spec, frames) = sequence();
    let mut cal = Calibrator::new(
        CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, Some(spec.view)),
        Providers::for_tier(CalibrationTier::Fast),
    )
    .expect("valid config");
    cal.push_poses(&[pose(spec, 0), pose(spec, 1)]).expect("poses");
    let mut reasons: Vec<(usize, UpdateReason)> = vec![];
    let burst_s = cal.config().burst_s;
    assert_eq!(cal.phase(), Phase::Waiting);
    for f in &frames[..44] {
        if f.index == 36 {
            cal.restart();
            assert_eq!(cal.phase(), Phase::Waiting, "restarted: waiting for the burst's first frame");
        }
        cal.push_poses(&[pose(spec, f.index + 2)]).expect("poses");
        for e in cal.push_frame(frame(f)).expect("valid frame") {
            if let Event::Published(u) = e {
                reasons.push((f.index, u.reason));
            }
        }
        // Frame times from the burst's first frame (0 or 36) at 30 fps.
        let since_s = (f.index - if f.index >= 36 { 36 } else { 0 }) as f64 / 30.0;
        let phase = cal.phase();
        if since_s < burst_s - 1e-6 {
            match phase {
                Phase::Burst { elapsed_s, of_s, after_change: false } => {
                    assert!((elapsed_s - since_s).abs() < 1e-6 && of_s == burst_s, "frame {}: {phase:?}", f.index)
                }
                other => panic!("frame {}: {other:?} during the burst", f.index),
            }
        } else {
            assert_eq!(phase, Phase::Steady, "frame {}", f.index);
        }
    }
    let burst = |range: std::ops::Range<usize>| {
        reasons.iter().filter(|(i, _)| range.contains(i)).map(|(_, r)| *r == UpdateReason::Burst).collect::<Vec<_>>()
    };
    assert!(burst(31..36).iter().all(|b| !b), "after the first burst, on schedule: {reasons:?}");
    let after = burst(36..44);
    assert!(!after.is_empty() && after.iter().all(|b| *b), "a burst again after the restart: {reasons:?}");
}

/// The fast tier's burst alternates noise with motion blur at any frame rate: with
/// every other frame of the 30 fps sequence dropped (a 15 fps camera, or a worker
/// dropping frames under load), noise and motion blur still never refit on the same
/// update after the first frame, and each takes about half of the burst's updates
/// (a fixed 0.05 s interval alone let noise take every update there and motion
/// blur only every third, beside it).
#[test]
fn fast_burst_alternates_at_fifteen_fps() {
    let (spec, frames) = sequence();
    let cfg = CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, Some(spec.view));
    let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast)).expect("valid config");
    cal.push_poses(&[pose(spec, 0)]).expect("poses");
    let mut burst = vec![];
    for f in frames.iter().filter(|f| f.index % 2 == 0) {
        cal.push_poses(&[pose(spec, f.index + 1), pose(spec, f.index + 2)]).expect("poses");
        for e in cal.push_frame(frame(f)).expect("valid frame") {
            if let Event::Published(u) = e {
                if u.t_s > 1e-9 && u.t_s < 1.0 - 1e-9 {
                    let fits = |k: &str| u.stages_s.iter().any(|(s, _)| *s == k);
                    burst.push((u.t_s, fits("fit.noise"), fits("fit.motion_blur")));
                }
            }
        }
    }
    eprintln!("burst updates (t, noise, motion blur): {burst:?}");
    assert!(burst.len() >= 13, "{} burst updates", burst.len());
    assert!(burst.iter().all(|&(_, n, m)| !(n && m)), "noise and motion blur on one update: {burst:?}");
    for (name, count) in
        [("noise", burst.iter().filter(|b| b.1).count()), ("motion blur", burst.iter().filter(|b| b.2).count())]
    {
        assert!(2 * count + 2 >= burst.len(), "{name} on {count} of {} burst updates", burst.len());
    }
}

/// The accurate tier refits λ on every update (one per 0.1 s) while the head moves
/// and not at rest (`CalibratorConfig::mb_moving_only`). The calibration video's
/// head, 2.5 s of it turning faster (0.08 rad in 0.4 s, rests of 0.4 s: up to ~8
/// px/frame): after the 1 s start-up burst, every update that refits motion blur is
/// on a frame moving ≥ 3.5 px/frame at its fastest (the worker's rule is ≥ 4 px on
/// the sparse grid, which the truth flow's maximum over every pixel bounds from
/// above, less 0.5 px for the pose track's interpolation), and the moving frames
/// get at least one λ fit per 0.15 s of video (one update per 0.25 s gave two to
/// five λ fits on a turn of 0.5–1.2 s, each ±2–8% on real scenes made elsewhere:
/// BENCHMARKS.md).
#[test]
fn accurate_tier_refits_motion_blur_while_the_head_moves() {
    let mut spec = SequenceSpec::motorcycle(scene(), 320, 240, 75, None);
    spec.path.yaw_amplitude_rad = 0.08;
    spec.path.move_s = 0.4;
    let frames: Vec<_> = (0..spec.frames).map(|i| spec.frame(scene(), i)).collect();
    let max_speed = |i: usize| {
        let f = &frames[i.min(frames.len() - 1)].flow;
        f.dx.iter().zip(&f.dy).map(|(x, y)| x.hypot(*y)).fold(0.0f32, f32::max)
    };
    let cfg = CalibratorConfig::new(CalibrationTier::Accurate, 1.0 / 30.0, Some(spec.view));
    let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Accurate)).expect("valid config");
    cal.push_poses(&[pose(&spec, 0), pose(&spec, 1)]).expect("poses");
    let mut mb_fits = vec![];
    for f in &frames {
        cal.push_poses(&[pose(&spec, f.index + 2)]).expect("poses");
        for e in cal.push_frame(frame(f)).expect("valid frame") {
            if let Event::Published(u) = e {
                if u.t_s >= 1.0 && u.stages_s.iter().any(|(k, _)| *k == "fit.motion_blur") {
                    mb_fits.push((u.t_s, max_speed(f.index)));
                }
            }
        }
    }
    let moving_s = (30..frames.len()).filter(|&i| max_speed(i) >= 4.0).count() as f64 / spec.fps as f64;
    eprintln!("λ fits after the burst (t, fastest px/frame): {mb_fits:?}; moving {moving_s:.2} s of it");
    assert!(moving_s >= 0.5, "the sequence must move after the burst: {moving_s} s");
    for (t, speed) in &mb_fits {
        assert!(*speed >= 3.5, "λ refitted at {t:.2} s with the head at rest ({speed:.2} px/frame)");
    }
    assert!(
        mb_fits.len() as f64 >= (moving_s / 0.15).floor(),
        "{} λ fits in {moving_s:.2} s of moving video",
        mb_fits.len()
    );
}
