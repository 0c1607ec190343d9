//! Probe: the calibrator over a synthetic sequence, per tier.
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::analysis::timing::TimedPose;
use blind_augment::analysis::{DepthMap, Frame};
use blind_augment::model::compare::*;
use blind_augment::model::{DepthUnits, LevelSource};
use blind_augment::synth::sequence::*;
use blind_augment::worker::*;

/// (t_s, λ error, noise error, δ RMSE, δ RMSE against truth ⊕ the photograph's pixel).
type Errors = (f64, f32, Option<f32>, Option<f32>, Option<f32>);

fn main() {
    blind_augment::alloc::keep_freed_blocks();
    let args: Vec<String> = std::env::args().collect();
    let tier = CalibrationTier::parse(args.get(1).map(|s| s.as_str()).unwrap_or("fast")).unwrap();
    let frames: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(60);
    let w: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(320);
    let mut scene = motorcycle().unwrap();
    // SCENE=procedural: the Motorcycle's depth under a texture of known blur, one
    // source pixel per view pixel from 1280 px wide
    // (`synth::sequence::procedural`).
    if std::env::var("SCENE").is_ok_and(|s| s == "procedural") {
        scene = procedural(&scene, (w / 320).max(1), 11);
    }
    // NOCHANGE=1: no camera change (the bench's 1280×960 run).
    let change = std::env::var_os("NOCHANGE").is_none().then_some(frames as f64 / 60.0);
    let mut spec = SequenceSpec::motorcycle(&scene, w, w * 3 / 4, frames, change);
    // DEMO_TRUTH=1: the camera `blind-augment demo` distorts its live video with.
    if std::env::var_os("DEMO_TRUTH").is_some() {
        common::demo_camera(&mut spec);
    }
    // NODOF=1: the camera without depth of field (the temporal λ's end-of-turn
    // bias is the rest frames' other defocus: `examples/defocus_change_probe.rs`).
    if std::env::var_os("NODOF").is_some() {
        spec.truth.depth_of_field.present = false;
    }
    // RATIOS=r1,r2,r3: spatially correlated sensor noise (`synth::correlated_sensor_noise`,
    // level std ratios 1/0, 2/1, 3/2 on the truth's level 0), before and after the change.
    if let Some(r) =
        std::env::var("RATIOS").ok().map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect::<Vec<f32>>())
    {
        let ratios: [f32; blind_augment::model::NOISE_LEVELS - 1] = std::array::from_fn(|i| r[i.min(r.len() - 1)]);
        let correlate = |n: &mut blind_augment::model::Noise| {
            // The white model's level-0 map: variance = intercept + slope·Y, over c_0².
            let c0 = blind_augment::synth::unit_band_std()[0].powi(2);
            let (a, b) = (n.levels[0].intercept.map(|v| v / c0), n.levels[0].slope.map(|v| v / c0));
            *n = blind_augment::synth::correlated_sensor_noise(a, b, n.luminance_range, ratios).expect("RATIOS");
        };
        correlate(&mut spec.truth.noise);
        if let Some((_, after)) = spec.change.as_mut() {
            correlate(&mut after.noise);
        }
    }
    let mut cfg = CalibratorConfig::new(tier, 1.0 / 30.0, Some(spec.view));
    // WINDOW=s: the aggregation window (a tiny one publishes each fit as it is).
    if let Some(w) = std::env::var("WINDOW").ok().and_then(|s| s.parse().ok()) {
        cfg.window_s = w;
    }
    let mut cal = Calibrator::new(cfg, Providers::for_tier(tier)).unwrap();
    let pose = |i: usize| {
        let t = spec.frame_time_s(i);
        let m = spec.path.world_from_camera(t);
        let (_, q, p) = m.to_scale_rotation_translation();
        TimedPose { t_ns: (t * 1e9).round() as i64, position_m: p, orientation: q }
    };
    cal.push_poses(&[pose(0), pose(1)]).unwrap();
    // (t_s, λ error, noise error, δ RMSE over the truth's depth range) per publication,
    // for the summary: the bench's statistics (medians over the second before the
    // change and over the last second).
    let mut errs: Vec<Errors> = vec![];
    // NOISE=1: per level, publications whose measured level's error lies within 1, 2,
    // or beyond 2 of its stated relative standard errors.
    let mut coverage = [[0usize; 3]; blind_augment::model::NOISE_LEVELS];
    let floor_px = spec.source_pixel_blur_px(&scene);
    for i in 0..frames {
        cal.push_poses(&[pose(i + 2)]).unwrap();
        let f = spec.frame(&scene, i);
        let truth = f.truth.clone();
        let t0 = std::time::Instant::now();
        let ev = cal
            .push_frame(Frame {
                index: i as u64,
                t_s: f.t_s,
                image: f.image,
                depth: Some(DepthMap { depth: f.depth_m, units: DepthUnits::MetricM }),
                flow: None,
            })
            .unwrap();
        let dt = t0.elapsed().as_secs_f64();
        // The bench's depths: 16 over the truth's range.
        let r = truth.depth_of_field.depth_range;
        let depths: Vec<f32> = (0..16).map(|i| r[0] + (r[1] - r[0]) * (i as f32 + 0.5) / 16.0).collect();
        for e in &ev {
            if let Event::Published(u) = e {
                errs.push((
                    u.t_s,
                    exposure_error(&u.model, &truth),
                    noise_relative_error(&u.model.noise, &truth.noise),
                    dof_rmse_px(&u.model.depth_of_field, &truth.depth_of_field, &depths),
                    dof_rmse_px_over_floor(&u.model.depth_of_field, &truth.depth_of_field, &depths, floor_px),
                ));
            }
        }
        for e in &ev {
            match e {
                Event::Published(u) if std::env::var_os("MB").is_some() => {
                    println!(
                        "{i:3} t={:.2} λ err {:.3}: {}",
                        u.t_s,
                        exposure_error(&u.model, &truth),
                        u.model.motion_blur.diagnostics.reason
                    )
                }
                Event::Published(u) if std::env::var_os("DOF").is_some() => {
                    let fl = spec.source_pixel_blur_px(&scene);
                    let d = &u.model.depth_of_field;
                    let tr = &truth.depth_of_field;
                    let want: Vec<f32> = depths
                        .iter()
                        .step_by(3)
                        .map(|&z| ((tr.sigma_px(z).powi(2) + fl * fl).sqrt() * 100.0).round() / 100.0)
                        .collect();
                    println!(
                        "{i:3} t={:.2} δ RMSE {:?} (⊕ pixel {:?}) δ at the depths {:?} (truth ⊕ pixel {want:?}): {}",
                        u.t_s,
                        dof_rmse_px(d, &truth.depth_of_field, &depths),
                        dof_rmse_px_over_floor(d, &truth.depth_of_field, &depths, fl),
                        depths.iter().step_by(3).map(|&z| (d.sigma_px(z) * 100.0).round() / 100.0).collect::<Vec<_>>(),
                        d.diagnostics
                            .reason
                            .chars()
                            .take(std::env::var("DOF").ok().and_then(|s| s.parse().ok()).unwrap_or(60))
                            .collect::<String>()
                    )
                }
                Event::Published(u) if std::env::var_os("NOISE").is_some() => {
                    // Signed per-level error (fit/truth − 1, %) at luma 0.3 / 0.5 / 0.7, green.
                    let (n, t) = (&u.model.noise, &truth.noise);
                    let per: Vec<String> = n
                        .levels
                        .iter()
                        .zip(&t.levels)
                        .take(4)
                        .map(|(lf, lt)| {
                            [0.3f32, 0.5, 0.7]
                                .iter()
                                .map(|&y| {
                                    let yf = y.clamp(n.luminance_range[0], n.luminance_range[1]);
                                    format!("{:+.0}", 100.0 * (lf.std(n.form, 1, yf) / lt.std(t.form, 1, y) - 1.0))
                                })
                                .collect::<Vec<_>>()
                                .join("/")
                        })
                        .collect();
                    // Each level's median error over 9 lumas of the range × 3 channels
                    // against its stated error (`level_sources`), counted for the summary.
                    let sources: Vec<String> = n
                        .level_sources
                        .iter()
                        .enumerate()
                        .map(|(l, src)| {
                            let [lo, hi] = n.luminance_range;
                            let mut e: Vec<f32> = (0..27)
                                .map(|k| {
                                    let (y, c) = (lo + (hi - lo) * ((k / 3) as f32 + 0.5) / 9.0, k % 3);
                                    n.levels[l].std(n.form, c, y) / t.levels[l].std(t.form, c, y) - 1.0
                                })
                                .collect();
                            e.sort_by(f32::total_cmp);
                            match *src {
                                LevelSource::Measured { relative_stderr, .. } => {
                                    let k =
                                        (e[13].abs() / relative_stderr.max(1e-6)).ceil().clamp(1.0, 3.0) as usize - 1;
                                    coverage[l][k] += 1;
                                    format!("M{:+.0}±{:.0}", 100.0 * e[13], 100.0 * relative_stderr)
                                }
                                LevelSource::Continued { from } => format!("C{from}{:+.0}", 100.0 * e[13]),
                            }
                        })
                        .collect();
                    println!(
                        "{i:3} t={:.2} noise_err={:?} per level (g, luma .3/.5/.7, %): {} [{}] range {:?} sources {}",
                        u.t_s,
                        noise_relative_error(n, t),
                        per.join("  "),
                        n.diagnostics.method,
                        n.luminance_range,
                        sources.join(" ")
                    )
                }
                Event::Published(u) => println!(
                    "{i:3} t={:.2} λ={:?}({:.3}) noise_err={:?} dof_rmse={:?} {:?} {:.0} ms  [mb {}] [n {}] [{}]",
                    u.t_s,
                    u.model.motion_blur.exposure.map(|x| (x * 1000.0).round() / 1000.0),
                    exposure_error(&u.model, &truth),
                    noise_relative_error(&u.model.noise, &truth.noise),
                    dof_rmse_px(&u.model.depth_of_field, &truth.depth_of_field, &depths),
                    u.reason,
                    dt * 1e3,
                    u.model.motion_blur.diagnostics.method,
                    u.model.noise.diagnostics.method,
                    u.stages_s.iter().map(|(k, v)| format!("{k} {:.1}", v * 1e3)).collect::<Vec<_>>().join(", ")
                ),
                Event::Degraded { reason, .. } => println!("    degraded: {reason}"),
                other => println!("    {other:?}"),
            }
        }
    }
    if std::env::var_os("NOISE").is_some() {
        println!("published measured levels within 1 / 2 / beyond 2 stated errors, per level: {coverage:?}");
    }
    let change_s = spec.change.as_ref().map_or(spec.frame_time_s(frames - 1) + 1.0, |c| c.0);
    let med = |v: Vec<f32>| {
        let mut v: Vec<f32> = v.into_iter().filter(|x| x.is_finite()).collect();
        v.sort_by(f32::total_cmp);
        v.get(v.len() / 2).copied()
    };
    let end_s = spec.frame_time_s(frames - 1);
    for (name, from, to) in [("before change", change_s - 1.0, change_s), ("last second", end_s - 1.0, end_s + 1.0)] {
        let seg: Vec<_> = errs.iter().filter(|e| e.0 >= from && e.0 < to).collect();
        println!(
            "summary {name} [{from:.2}, {to:.2}): {} publications, median λ err {:?}, noise err {:?}, δ RMSE {:?} (against truth ⊕ the photograph's pixel: {:?})",
            seg.len(),
            med(seg.iter().map(|e| e.1).collect()),
            med(seg.iter().filter_map(|e| e.2).collect()),
            med(seg.iter().filter_map(|e| e.3).collect()),
            med(seg.iter().filter_map(|e| e.4).collect()),
        );
    }
}
