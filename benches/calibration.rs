//! The measured speed/accuracy trade of live calibration (the paper's FULLPIPELINE
//! experiment, Sec. 4.5): recorded video with known truth — the Motorcycle
//! photograph with its real depth, re-rendered along a head path of fixations and
//! turns, distorted by a camera whose exposure and gain change mid-sequence — run
//! through the worker's calibration loop per tier. Accuracy and convergence on
//! 320×240 frames (5 s, the change at 2.5 s); compute per update single-threaded
//! on 1280×960 frames (the Quest camera's), the same head path. Prints a markdown
//! table and writes the Pareto plot to benches/results/calibration_pareto.png.
//!
//! `cargo bench --bench calibration` (part of `cargo xtask bench`).

use blind_augment::analysis::timing::TimedPose;
use blind_augment::analysis::{DepthMap, Frame};
use blind_augment::model::compare::{dof_rmse_px, dof_rmse_px_over_floor, exposure_error, noise_relative_error};
use blind_augment::model::{CameraModel, DepthUnits};
use blind_augment::plots::{panels_plot, Panel, Series};
use blind_augment::synth::sequence::{motorcycle, procedural, Scene, SequenceFrame, SequenceSpec};
use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, Event, Providers};
use plotters::style::RGBColor;
use std::time::Instant;

const TIERS: [CalibrationTier; 3] = [CalibrationTier::Fast, CalibrationTier::Balanced, CalibrationTier::Accurate];
const CHANGE_S: f64 = 2.5;
/// "Converged": λ within 0.05 and noise within 10% (the fast tier's targets).
const CONVERGED_LAMBDA: f32 = 0.05;
const CONVERGED_NOISE: f32 = 0.10;

/// A tier's point on the Pareto plot: compute per update (ms), λ error, noise
/// error, time to converge after the change.
type Point = (CalibrationTier, f64, f64, f64, Option<f64>);

struct Published {
    t_s: f64,
    model: CameraModel,
    truth: CameraModel,
    /// The blur the frames carry besides the truth's δ(Z): the photograph's own
    /// pixel, magnified (`SequenceSpec::source_pixel_blur_px`).
    floor_px: f32,
    compute_s: f64,
    stages_s: Vec<(&'static str, f64)>,
}

struct Run {
    published: Vec<Published>,
    changes: Vec<f64>,
    frame_s: Vec<f64>,
    fps: f64,
}

fn pose(spec: &SequenceSpec, i: usize) -> TimedPose {
    let t = spec.frame_time_s(i);
    let (_, q, p) = spec.path.world_from_camera(t).to_scale_rotation_translation();
    TimedPose { t_ns: (t * 1e9).round() as i64, position_m: p, orientation: q }
}

fn run(tier: CalibrationTier, spec: &SequenceSpec, frames: &[SequenceFrame], floor_px: f32) -> Run {
    let cfg = CalibratorConfig::new(tier, 1.0 / spec.fps as f64, Some(spec.view));
    let mut cal = Calibrator::new(cfg, Providers::for_tier(tier)).expect("config");
    cal.push_poses(&[pose(spec, 0), pose(spec, 1)]).expect("poses");
    let mut r = Run { published: vec![], changes: vec![], frame_s: vec![], fps: spec.fps as f64 };
    for f in frames {
        cal.push_poses(&[pose(spec, f.index + 2)]).expect("poses");
        let frame = Frame {
            index: f.index as u64,
            t_s: f.t_s,
            image: f.image.clone(),
            depth: Some(DepthMap { depth: f.depth_m.clone(), units: DepthUnits::MetricM }),
            flow: None,
        };
        let t0 = Instant::now();
        let events = cal.push_frame(frame).expect("frame");
        r.frame_s.push(t0.elapsed().as_secs_f64());
        for e in events {
            match e {
                Event::Published(u) => r.published.push(Published {
                    t_s: u.t_s,
                    model: u.model,
                    truth: f.truth.clone(),
                    floor_px,
                    compute_s: u.compute_s,
                    stages_s: u.stages_s,
                }),
                Event::ChangeDetected { t_s, .. } => r.changes.push(t_s),
                _ => {}
            }
        }
    }
    r
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(v[v.len() / 2])
}

fn percentile(mut v: Vec<f64>, p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// λ error, noise error, δ RMSE against the truth and against the truth ⊕ the
/// photograph's own pixel (what the frames hold).
fn errs(p: &Published) -> (f32, Option<f32>, Option<f32>, Option<f32>) {
    let r = p.truth.depth_of_field.depth_range;
    let depths: Vec<f32> = (0..16).map(|i| r[0] + (r[1] - r[0]) * (i as f32 + 0.5) / 16.0).collect();
    (
        exposure_error(&p.model, &p.truth),
        noise_relative_error(&p.model.noise, &p.truth.noise),
        dof_rmse_px(&p.model.depth_of_field, &p.truth.depth_of_field, &depths),
        dof_rmse_px_over_floor(&p.model.depth_of_field, &p.truth.depth_of_field, &depths, p.floor_px),
    )
}

fn converged(p: &Published) -> bool {
    let (l, n, _, _) = errs(p);
    l <= CONVERGED_LAMBDA && n.is_some_and(|n| n <= CONVERGED_NOISE)
}

/// Video time from `from_s` to the first converged publication before `until_s`
/// (None: never), and the share of publications from then on that stay converged.
fn time_to_converge(r: &Run, from_s: f64, until_s: f64) -> (Option<f64>, f64) {
    let seg: Vec<&Published> = r.published.iter().filter(|p| p.t_s >= from_s && p.t_s < until_s).collect();
    match seg.iter().position(|p| converged(p)) {
        None => (None, 0.0),
        Some(i) => {
            let rest = &seg[i..];
            (Some(seg[i].t_s - from_s), rest.iter().filter(|p| converged(p)).count() as f64 / rest.len() as f64)
        }
    }
}

fn fmt_opt(v: Option<f64>, scale: f64, digits: usize, unit: &str) -> String {
    v.map_or("—".into(), |x| format!("{:.*}{unit}", digits, x * scale))
}

/// One row of the stage table: mean time per steady update per stage, and the
/// worker's compute per second of video over the steady frames.
fn stage_line(tier: CalibrationTier, r: &Run, steady_frames: usize) -> String {
    let steady: Vec<&Published> = r.published.iter().filter(|p| p.t_s >= 1.0).collect();
    let mut names: Vec<&'static str> = vec![];
    for p in &steady {
        for (k, _) in &p.stages_s {
            if !names.contains(k) {
                names.push(k);
            }
        }
    }
    let n = steady.len().max(1) as f64;
    let mean =
        |k: &str| steady.iter().flat_map(|p| &p.stages_s).filter(|(n, _)| *n == k).map(|(_, s)| s).sum::<f64>() / n;
    let total: f64 = names.iter().map(|k| mean(k)).sum();
    let cells: Vec<String> = names
        .iter()
        .map(|k| format!("{k} {:.1} ({:.0}%)", mean(k) * 1e3, 100.0 * mean(k) / total.max(1e-12)))
        .collect();
    let steady_s: f64 = r.frame_s.iter().rev().take(steady_frames).sum();
    let video_s = steady_frames as f64 / r.fps;
    format!("| {} | {} | {:.2} |", tier.name(), cells.join(", "), steady_s / video_s)
}

fn frames(scene: &Scene, spec: &SequenceSpec, n: usize) -> Vec<SequenceFrame> {
    (0..n).map(|i| spec.frame(scene, i)).collect()
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        // `cargo test --benches` lists benchmarks; nothing to list here.
        return;
    }
    // As the app's binaries run (`blind_augment::alloc`): freed planes stay mapped.
    blind_augment::alloc::keep_freed_blocks();
    let scene = motorcycle().expect("bundled scene");
    let small = SequenceSpec::motorcycle(&scene, 320, 240, 150, Some(CHANGE_S));
    eprintln!("rendering 150 frames of 320×240 …");
    let small_frames = frames(&scene, &small, small.frames);
    // The Quest camera's 1280×960, 2 s: the 1 s start-up burst (every effect every
    // frame), then the tier's steady schedule.
    let big = SequenceSpec::motorcycle(&scene, 1280, 960, 60, None);
    eprintln!("rendering 60 frames of 1280×960 …");
    let big_frames = frames(&scene, &big, big.frames);
    // δ(Z) where the frames' own blur is known: the same geometry and head path
    // under a procedural texture of hard-edged shapes sampled 1:1 at 1280×960
    // (`synth::sequence::procedural`): the Motorcycle's 4× magnified pixels carry
    // the photograph's own blur (read at 1–2 px on its effect-free frames), which no
    // truth states.
    let textured = procedural(&scene, 4, 11);
    let known = SequenceSpec::motorcycle(&textured, 1280, 960, 60, None);
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
    // CALIB_BENCH_REFERENCES=1: only the noise-reference comparison (quick).
    if std::env::var("CALIB_BENCH_REFERENCES").is_ok_and(|v| v == "1") {
        noise_references(&big, &big_frames, &one);
        return;
    }

    println!("## Live calibration: the speed/accuracy trade per tier (`cargo bench --bench calibration`)\n");
    println!("Accuracy: 320×240, 150 frames at 30 Hz, the camera changing at {CHANGE_S} s (λ 0.5 → 0.25, noise std ×1.5). Compute: 1280×960, 60 frames (2 s), one thread: per update during the 1 s start-up burst (an update every frame; the fast tier refits noise and λ on alternate frames) and after it (the tier's schedule), and per frame without an update (analysis and the change probe only); its accuracy over its second after the burst (the camera before the change; δ in pixels of 1280×960, 4× those of 320×240 for the same blur). The frames are the 497×333 photograph re-rendered, so every edge also carries the photograph's own pixel, magnified: {:.2} px at 320×240, {:.2} px at 1280×960 (std of a box one source pixel wide); a blind estimator measures it with the truth's δ, hence the second δ figure, against √(δ² + that²). The column \"texture of known blur\": the same geometry, head path and camera at 1280×960 under a procedural texture of hard-edged shapes (`synth::sequence::procedural`, 4×4 area-sampled, 1:1 with the view: its own blur a one-pixel box, {:.2} px, below what the blind estimator resolves), δ against the truth over the second after the burst. \"Converged\": λ within {CONVERGED_LAMBDA} and noise within {:.0}% at every publication from then on.\n", small.source_pixel_blur_px(&scene), big.source_pixel_blur_px(&scene), known.source_pixel_blur_px(&textured), 100.0 * CONVERGED_NOISE);
    println!("| tier | update at 1280×960, 1 thread: burst (median) / steady (median, p95) | frame without update | λ error before / after change | noise error before / after | δ RMSE (px): against the truth (against truth ⊕ the photograph's pixel) | at 1280×960, steady: λ / noise / δ RMSE (⊕ pixel) | δ RMSE at 1280×960, steady, texture of known blur | converged after start (share staying) | change detected after | converged after change (share staying) |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    eprintln!("rendering 60 frames of 1280×960 of the procedural texture …");
    let known_frames = frames(&textured, &known, known.frames);
    let mut points = vec![];
    let mut stage_lines = vec![];
    // One tier by name (`CALIB_BENCH_TIER=accurate`): a third of the run.
    let tier_only = std::env::var("CALIB_BENCH_TIER").ok();
    for tier in TIERS.into_iter().filter(|t| tier_only.as_deref().map_or(true, |n| n == t.name())) {
        let r = run(tier, &small, &small_frames, small.source_pixel_blur_px(&scene));
        let big_run = one.install(|| run(tier, &big, &big_frames, big.source_pixel_blur_px(&scene)));
        let burst: Vec<f64> = big_run.published.iter().filter(|p| p.t_s < 1.0).map(|p| p.compute_s).collect();
        let updates: Vec<f64> = big_run.published.iter().filter(|p| p.t_s >= 1.0).map(|p| p.compute_s).collect();
        let (upd_med, upd_p95) = (median(updates.clone()).unwrap_or(f64::NAN), percentile(updates.clone(), 0.95));
        let n_upd = updates.len();
        let idle: Vec<f64> = {
            // Frames that published nothing: the analysis and probe cost alone.
            let published_frames = big_run.published.len();
            let mut f = big_run.frame_s.clone();
            f.sort_by(f64::total_cmp);
            f.truncate(big_run.frame_s.len().saturating_sub(published_frames));
            f
        };
        let stats = |r: &Run, from: f64, to: f64| {
            let seg: Vec<&Published> = r.published.iter().filter(|p| p.t_s >= from && p.t_s < to).collect();
            let l = median(seg.iter().map(|p| errs(p).0 as f64).collect());
            let n = median(seg.iter().filter_map(|p| errs(p).1.map(f64::from)).collect());
            let d = median(seg.iter().filter_map(|p| errs(p).2.map(f64::from)).collect());
            let df = median(seg.iter().filter_map(|p| errs(p).3.map(f64::from)).collect());
            (l, n, d, df)
        };
        // Steady state: the second before the change and the last second.
        let (lb, nb, db, dfb) = stats(&r, CHANGE_S - 1.0, CHANGE_S);
        let (la, na, _, _) = stats(&r, small.frame_time_s(small.frames - 1) - 1.0, f64::INFINITY);
        // The Quest camera's size (the targets are stated at it): the
        // 1280×960 run's second after its burst (no change in it).
        let (lq, nq, dq, dfq) = stats(&big_run, 1.0, f64::INFINITY);
        let known_run = run(tier, &known, &known_frames, known.source_pixel_blur_px(&textured));
        let (_, _, dk, _) = stats(&known_run, 1.0, f64::INFINITY);
        let detect = r.changes.iter().find(|t| **t >= CHANGE_S).map(|t| t - CHANGE_S);
        let (conv0, stay0) = time_to_converge(&r, 0.0, CHANGE_S);
        let (conv1, stay1) = time_to_converge(&r, CHANGE_S, f64::INFINITY);
        let steady_frames = big_run.frame_s.len() - 30;
        println!(
            "| {} | {:.0} ms / {:.1} ms, {:.1} ms ({n_upd} updates in {steady_frames} frames) | {} | {} / {} | {} / {} | {} ({}) | {} / {} / {} ({}) | {} | {} ({:.0}%) | {} | {} ({:.0}%) |",
            tier.name(),
            median(burst).unwrap_or(f64::NAN) * 1e3,
            upd_med * 1e3,
            upd_p95 * 1e3,
            fmt_opt(median(idle), 1e3, 1, " ms"),
            fmt_opt(lb, 1.0, 3, ""),
            fmt_opt(la, 1.0, 3, ""),
            fmt_opt(nb, 100.0, 1, "%"),
            fmt_opt(na, 100.0, 1, "%"),
            fmt_opt(db, 1.0, 3, ""),
            fmt_opt(dfb, 1.0, 3, ""),
            fmt_opt(lq, 1.0, 3, ""),
            fmt_opt(nq, 100.0, 1, "%"),
            fmt_opt(dq, 1.0, 2, " px"),
            fmt_opt(dfq, 1.0, 2, " px"),
            fmt_opt(dk, 1.0, 3, " px"),
            fmt_opt(conv0, 1.0, 2, " s"),
            100.0 * stay0,
            fmt_opt(detect, 1.0, 2, " s"),
            fmt_opt(conv1, 1.0, 2, " s"),
            100.0 * stay1,
        );
        points.push((tier, upd_med * 1e3, lb.unwrap_or(f64::NAN), nb.unwrap_or(f64::NAN), conv1));
        stage_lines.push(stage_line(tier, &big_run, steady_frames));
    }
    println!("\nWhere the steady updates' time goes at 1280×960, one thread (mean per update over the updates after the burst; each stage's share of the sum), and the worker's load: all its compute over those frames per second of video (1.0 = one core busy):\n");
    println!("| tier | stages: mean ms per update (share) | load (cores) |");
    println!("|---|---|---|");
    for l in stage_lines {
        println!("{l}");
    }
    let colours = [RGBColor(220, 50, 47), RGBColor(230, 150, 0), RGBColor(38, 110, 210)];
    let panel = |title: &str, y: &str, get: &dyn Fn(&Point) -> f64| Panel {
        title: title.into(),
        x_desc: "compute per update at 1280×960, one thread (ms, log)".into(),
        y_desc: y.into(),
        series: points
            .iter()
            .zip(colours)
            .map(|(p, c)| Series { label: p.0.name().into(), points: vec![(p.1, get(p))], colour: c, dots: true })
            .collect(),
        log_x: true,
    };
    let panels = [
        panel("exposure λ: error before the change", "|λ − λ_true|", &|p| p.2),
        panel("noise: median relative error of the level stds", "relative error", &|p| p.3),
        panel("time to converge after the camera change (video)", "s (missing: never)", &|p| p.4.unwrap_or(f64::NAN)),
    ];
    // Written next to this file: BENCHMARKS.md shows it (a measured figure, committed
    // with the table it belongs to).
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/results/calibration_pareto.png");
    if let Some(dir) = path.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    match panels_plot(&path, &panels, 900, 300) {
        Ok(()) => eprintln!("wrote {}", path.display()),
        Err(e) => eprintln!("plot: {e}"),
    }
    noise_references(&big, &big_frames, &one);
}

/// Noise references compared on single 1280×960 frames of the same video, one
/// thread: the shipped network (`assets/models/denoise.onnx`, tiled over its sample
/// regions) feeding the accurate noise fit, against the blind fit of the frame
/// alone. (The temporal reference's figures are the accurate tier's, above.)
fn noise_references(spec: &SequenceSpec, frames: &[SequenceFrame], pool: &rayon::ThreadPool) {
    use blind_augment::analysis::onnx::{OnnxDenoiser, OnnxModel};
    use blind_augment::analysis::{Analysed, Denoiser, FrameContext, Role};
    use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Tier};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/models/denoise.onnx");
    let mut net = OnnxDenoiser::new(OnnxModel::load(Role::Denoise, &path, None).expect("shipped model"));
    let only_noise = Effects { noise: true, motion_blur: false, depth_of_field: false };
    let (mut t_net, mut t_fit, mut t_blind, mut e_net, mut e_blind) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut t_align, mut t_nb, mut e_nb) = (vec![], vec![], vec![]);
    let with_pose = |f: &SequenceFrame| Analysed {
        frame: Frame { index: f.index as u64, t_s: f.t_s, image: f.image.clone(), depth: None, flow: None },
        depth: Some(DepthMap { depth: f.depth_m.clone(), units: DepthUnits::MetricM }),
        world_from_camera: Some(f.world_from_camera),
        sparse_flow: None,
    };
    // Frames 1, 11, …: each has a previous frame for the fast tier's neighbour.
    for f in frames.iter().skip(1).step_by(10).take(5) {
        let a = Analysed {
            frame: Frame { index: f.index as u64, t_s: f.t_s, image: f.image.clone(), depth: None, flow: None },
            depth: None,
            world_from_camera: None,
            sparse_flow: None,
        };
        let ctx =
            FrameContext { current: &a, window: &[], poses: None, intrinsics: None, frame_interval_s: 1.0 / 30.0 };
        pool.install(|| {
            let t0 = Instant::now();
            let r = net.denoise(&ctx).expect("network denoises");
            t_net.push(t0.elapsed().as_secs_f64());
            let mut inp = FitInputs::new(&f.image);
            inp.denoised = Some(&r.image);
            inp.reference_valid = r.valid.as_ref();
            let t0 = Instant::now();
            let m = fit(&inp, &FitOptions { tier: Some(Tier::Accurate), effects: only_noise, ..Default::default() })
                .expect("fit");
            t_fit.push(t0.elapsed().as_secs_f64());
            e_net.push(noise_relative_error(&m.model.noise, &spec.truth.noise).map_or(f64::NAN, |e| e as f64));
            let t0 = Instant::now();
            let b = fit(
                &FitInputs::new(&f.image),
                &FitOptions { tier: Some(Tier::Fast), effects: only_noise, ..Default::default() },
            )
            .expect("fit");
            t_blind.push(t0.elapsed().as_secs_f64());
            e_blind.push(noise_relative_error(&b.model.noise, &spec.truth.noise).map_or(f64::NAN, |e| e as f64));
            // The fast tier's path: the previous frame aligned by pose and depth.
            let (prev, cur) = (with_pose(&frames[f.index - 1]), with_pose(f));
            let t0 = Instant::now();
            let al = blind_augment::analysis::temporal::align(&prev, &cur, &spec.view).expect("poses and depth");
            t_align.push(t0.elapsed().as_secs_f64());
            let valid = blind_augment::image::Plane::from_vec(
                al.image.width,
                al.image.height,
                al.valid.iter().map(|&v| f32::from(u8::from(v))).collect(),
            );
            let mut inp = FitInputs::new(&f.image);
            inp.neighbour = Some(blind_augment::fit::Neighbour { image: &al.image, valid: &valid });
            let t0 = Instant::now();
            let b = fit(&inp, &FitOptions { tier: Some(Tier::Fast), effects: only_noise, ..Default::default() })
                .expect("fit");
            t_nb.push(t0.elapsed().as_secs_f64());
            e_nb.push(noise_relative_error(&b.model.noise, &spec.truth.noise).map_or(f64::NAN, |e| e as f64));
        });
    }
    let med = |v: &[f64]| median(v.to_vec()).unwrap_or(f64::NAN);
    let regions = net.regions(spec.view.width, spec.view.height);
    println!("\n## Noise references on single 1280×960 frames (one thread, median of {} frames)\n", t_net.len());
    println!("| reference | reference ms | noise fit ms | noise error (median level-std error) |");
    println!("|---|---|---|---|");
    println!(
        "| shipped network, {} regions of 240² ({} px) | {:.0} | {:.0} | {:.1}% |",
        regions.len(),
        regions.iter().map(|r| r.width * r.height).sum::<usize>(),
        med(&t_net) * 1e3,
        med(&t_fit) * 1e3,
        med(&e_net) * 100.0
    );
    println!("| none (blind fit of the frame) | — | {:.0} | {:.1}% |", med(&t_blind) * 1e3, med(&e_blind) * 100.0);
    println!(
        "| the previous frame aligned by pose + depth (blind fit with `FitInputs::neighbour`: the fast tier) | {:.0} | {:.0} | {:.1}% |",
        med(&t_align) * 1e3,
        med(&t_nb) * 1e3,
        med(&e_nb) * 100.0
    );
}
