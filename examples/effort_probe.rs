//! What `FitOptions::fast_effort` costs in accuracy: the blind exposure and defocus
//! fits at each effort on the same frames (known answers at 1280×960 made with the
//! project's `synth`, and the vendored real photographs with stated blur), for
//! BENCHMARKS.md "The fast tier's effort". The time per effort is measured apart,
//! alternating in one process-free loop: `EFFORT=e BENCH=1 stage_times`.
//!
//!     cargo run --release --example effort_probe [-- 1 0.75 0.5 0.35 0.25]
#[path = "../tests/common/mod.rs"]
mod common;

use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Tier};
use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::model::*;
use blind_augment::synth::{add_defocus_disc, add_dof, add_motion_blur};

enum Truth {
    /// λ, and the streak per unit λ (px) at the frame's centre.
    Exposure { lambda: f32, speed_px: f32 },
    /// δ(Z) (with the photograph's own blur in quadrature where given).
    Curve { truth: Box<DepthOfField>, own: Option<Box<DepthOfField>> },
    /// A uniform disc of this second-moment σ at one depth.
    Disc { sigma_px: f32 },
}

struct Case {
    set: &'static str,
    name: String,
    img: Rgb,
    depth: Option<Plane>,
    flow: Option<Flow>,
    truth: Truth,
}

fn q8(img: &Rgb, a: f32, b: f32, seed: u64) -> Rgb {
    common::quantize8(&common::add_sensor_noise(img, [a; 3], [b; 3], seed))
}

fn uniform_flow(w: usize, h: usize, deg: f32, speed_px: f32) -> Flow {
    let a = deg.to_radians();
    Flow::uniform(w, h, speed_px * a.cos(), speed_px * a.sin())
}

fn cases() -> Vec<Case> {
    let (w, h) = (1280usize, 960usize);
    let scene = blind_augment::synth::sequence::motorcycle().expect("bundled scene");
    let procedural = blind_augment::synth::sequence::procedural(&scene, 4, 5).image;
    let procedural = common::mirror_tile(&procedural, w, h);
    let photos: Vec<(&str, Rgb)> = ["astronaut.png", "chelsea.png", "rocket.jpg"]
        .iter()
        .map(|n| (*n, common::mirror_tile(&common::photo(n), w, h)))
        .collect();
    let mut out = vec![];
    // Exposure: the bench's head flow (~7 px/frame at the centre, turning across the
    // frame) and uniform flows of 24 px/frame at 30° and 40 px/frame at 120°, under
    // the bench's white sensor noise, 8-bit, two seeds.
    for (pname, img) in &photos {
        let head = common::flow_field(w, h, 8.0);
        let c = (h / 2) * w + w / 2;
        let head_speed = head.dx[c].hypot(head.dy[c]);
        let flows: Vec<(String, Flow, f32, Vec<f32>)> = vec![
            ("head 8".into(), head, head_speed, vec![0.0, 0.25, 0.5, 1.0]),
            ("24 px at 30°".into(), uniform_flow(w, h, 30.0, 24.0), 24.0, vec![0.25, 0.5, 1.0]),
            ("40 px at 120°".into(), uniform_flow(w, h, 120.0, 40.0), 40.0, vec![0.5]),
        ];
        for (fname, flow, speed_px, lambdas) in flows {
            for lambda in lambdas {
                let blurred = add_motion_blur(img, &flow, lambda);
                for seed in [1u64, 2] {
                    out.push(Case {
                        set: "exposure 1280×960",
                        name: format!("{pname} {fname} λ {lambda} seed {seed}"),
                        img: q8(&blurred, 2e-5, 8e-4, seed),
                        depth: None,
                        flow: Some(flow.clone()),
                        truth: Truth::Exposure { lambda, speed_px },
                    });
                }
            }
        }
    }
    // Defocus: a 0.5–4 m ramp through a thin lens and a quadratic (Gaussian kernel),
    // 8-bit with noise std 0.01 (two seeds); the photographs' own blur (read at full effort on
    // the unblurred frame) in quadrature with the truth, the procedural texture's none.
    let depth = common::depth_ramp(w, h, 0.5, 4.0);
    let mut dof_images: Vec<(&str, Rgb)> = vec![("procedural", procedural)];
    dof_images.extend(photos.iter().map(|(n, i)| (*n, i.clone())));
    for (pname, img) in &dof_images {
        // The photograph's own blur does not vary with the ramp's depth: read at one
        // depth (a constant, the edges' median), so that an edge-poor frame's curve
        // through a narrow band of depths does not enter the reference.
        let own = (*pname != "procedural").then(|| {
            let sharp = q8(img, 1e-4, 0.0, 9);
            let one_depth = Plane::new(w, h, 2.0);
            let inp = FitInputs { depth: Some(&one_depth), ..FitInputs::new(&sharp) };
            let own = fit(&inp, &opts(1.0, false, true)).expect("valid").model.depth_of_field;
            eprintln!("{pname}: own blur {:?} ({})", own.curve, own.diagnostics.reason);
            own
        });
        for curve in [
            DofCurve::ThinLens { k: 3.0, focus_depth: 1.2, c0: 0.3 },
            DofCurve::ThinLens { k: 2.0, focus_depth: 2.5, c0: 0.2 },
            DofCurve::Quadratic { a: 0.3, b: -1.0, c: 1.5 },
        ] {
            let truth = DepthOfField {
                present: true,
                units: DepthUnits::MetricM,
                curve: Some(curve),
                depth_range: [0.5, 4.0],
                kernel: DofKernel::Gaussian,
                diagnostics: Diagnostics::not_fitted("truth"),
            };
            let blurred = add_dof(img, &depth, &truth);
            for seed in [3u64, 4] {
                out.push(Case {
                    set: "defocus ramp 1280×960",
                    name: format!("{pname} {curve:?} seed {seed}"),
                    img: q8(&blurred, 1e-4, 0.0, seed),
                    depth: Some(depth.clone()),
                    flow: None,
                    truth: Truth::Curve { truth: Box::new(truth.clone()), own: own.clone().map(Box::new) },
                });
            }
        }
    }
    // A uniform disc at one depth (the spectrum alone answers): σ 2 and 4 px.
    for (pname, img) in &photos {
        for sigma_px in [2.0f32, 4.0] {
            out.push(Case {
                set: "defocus disc 1280×960",
                name: format!("{pname} disc σ {sigma_px}"),
                img: q8(&add_defocus_disc(img, &Plane::new(w, h, sigma_px)), 1e-4, 0.0, 4),
                depth: Some(Plane::new(w, h, 2.0)),
                flow: None,
                truth: Truth::Disc { sigma_px },
            });
        }
    }
    // The vendored real photographs (tests/real_blur.rs): stated streaks along a
    // given direction (50 px/frame nominal) and measured discs.
    for (file, deg, px) in
        [("motion_licenseplate_opencv.jpg", 135.0f32, 22.0f32), ("motion_text_opencv.jpg", 86.0, 31.0)]
    {
        let img = common::photo(file);
        let flow = uniform_flow(img.width, img.height, deg, 50.0);
        out.push(Case {
            set: "real",
            name: format!("{file} ({px} px)"),
            img,
            depth: None,
            flow: Some(flow),
            truth: Truth::Exposure { lambda: px / 50.0, speed_px: 50.0 },
        });
    }
    for (file, radius_px) in [("defocus_disc_opencv.jpg", 5.54f32), ("defocus_text_opencv.jpg", 9.5)] {
        let img = common::photo(file);
        let (w, h) = (img.width, img.height);
        out.push(Case {
            set: "real",
            name: format!("{file} (R {radius_px} px)"),
            img,
            depth: Some(Plane::new(w, h, 2.0)),
            flow: None,
            truth: Truth::Disc { sigma_px: (radius_px * radius_px / 4.0 + 1.0 / 12.0).sqrt() },
        });
    }
    out
}

fn opts(effort: f32, mb: bool, dof: bool) -> FitOptions {
    FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: false, motion_blur: mb, depth_of_field: dof },
        fast_effort: effort,
        ..FitOptions::default()
    }
}

/// One fit's score: a relative error (streak length or σ; a curve's RMSE in px),
/// whether it answered, whether two standard errors cover the truth.
struct Score {
    err: f64,
    answered: bool,
    covered: bool,
    detail: String,
    /// The effect's own fit time (s).
    time_s: f64,
}

fn score(case: &Case, effort: f32) -> Score {
    let inp = FitInputs { depth: case.depth.as_ref(), flow: case.flow.as_ref(), ..FitInputs::new(&case.img) };
    match &case.truth {
        Truth::Exposure { lambda, speed_px } => {
            let mb = fit(&inp, &opts(effort, true, false)).expect("valid").model.motion_blur;
            // As in benches/streak_acf/fallback.py: relative to the streak, or to 4 px
            // where there is none; a frame not identifiable scores 0 px.
            let got = mb.exposure.unwrap_or(0.0);
            let err = ((got - lambda) * speed_px).abs() as f64 / (lambda * speed_px).max(4.0) as f64;
            let se = mb.diagnostics.stderr.unwrap_or(f64::INFINITY);
            Score {
                err,
                answered: mb.exposure.is_some(),
                covered: mb.exposure.is_some() && ((got - lambda) as f64).abs() <= 2.0 * se,
                detail: format!("λ {got:.3} ± {se:.3} ({:?})", mb.diagnostics.status),
                time_s: mb.diagnostics.fit_time_s,
            }
        }
        Truth::Curve { truth, own } => {
            let got = fit(&inp, &opts(effort, false, true)).expect("valid").model.depth_of_field;
            let [lo, hi] = got.depth_range;
            let rmse = ((0..=100)
                .map(|i| {
                    let z = lo + (hi - lo) * i as f32 / 100.0;
                    let want = own.as_ref().map_or(truth.sigma_px(z), |o| truth.sigma_px(z).hypot(o.sigma_px(z)));
                    ((got.sigma_px(z) - want) as f64).powi(2)
                })
                .sum::<f64>()
                / 101.0)
                .sqrt();
            // The truth's own δ RMS over the same depths (the scale of a relative error).
            let truth_rms = ((0..=100)
                .map(|i| {
                    let z = lo + (hi - lo) * i as f32 / 100.0;
                    (truth.sigma_px(z) as f64).powi(2)
                })
                .sum::<f64>()
                / 101.0)
                .sqrt();
            let se = got.diagnostics.stderr.unwrap_or(f64::INFINITY);
            let answered = got.present && got.curve.is_some() && got.kernel == truth.kernel;
            Score {
                err: rmse,
                // A curve, with the truth's kernel shape; covered: its RMSE within two
                // of its reported standard errors (δ RMS over the range).
                answered,
                covered: answered && rmse <= 2.0 * se,
                detail: format!(
                    "{:?} {:?} ({} edges, ± {se:.3} px, {:?}; truth's δ RMS {truth_rms:.3} px)",
                    got.kernel, got.curve, got.diagnostics.samples_used, got.diagnostics.status
                ),
                time_s: got.diagnostics.fit_time_s,
            }
        }
        Truth::Disc { sigma_px } => {
            let got = fit(&inp, &opts(effort, false, true)).expect("valid").model.depth_of_field;
            let c = match got.curve {
                Some(DofCurve::Constant { c }) => Some(c),
                _ => None,
            };
            let se = got.diagnostics.stderr.unwrap_or(f64::INFINITY);
            let err = c.map_or(1.0, |c| (c / sigma_px - 1.0).abs() as f64);
            Score {
                err,
                answered: got.present && c.is_some() && got.kernel == DofKernel::Disc,
                covered: got.present && c.is_some_and(|c| ((c - sigma_px) as f64).abs() <= 2.0 * se),
                detail: format!("{:?} {c:?} ± {se:.3} ({:?})", got.kernel, got.diagnostics.status),
                time_s: got.diagnostics.fit_time_s,
            }
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let efforts: Vec<f32> = {
        let a: Vec<f32> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
        if a.is_empty() {
            vec![1.0, 0.75, 0.5, 0.35, 0.25]
        } else {
            a
        }
    };
    eprintln!("building the frames …");
    let cases = cases();
    eprintln!("{} frames; efforts {efforts:?}", cases.len());
    let verbose = std::env::var("DETAIL").is_ok_and(|v| v == "1");
    let sets = ["exposure 1280×960", "defocus ramp 1280×960", "defocus disc 1280×960", "real"];
    // Per frame, every effort in turn (the order rotated per frame and repeated
    // `REPEAT` times, each effort's fastest kept), so that the VM's drift spreads
    // over all efforts alike; the fits are deterministic, only the times differ.
    let repeat: usize = std::env::var("REPEAT").ok().and_then(|v| v.parse().ok()).unwrap_or(3);
    let mut all: Vec<Vec<Option<Score>>> = efforts.iter().map(|_| cases.iter().map(|_| None).collect()).collect();
    for (i, case) in cases.iter().enumerate() {
        for r in 0..repeat * efforts.len() {
            let k = (i + r) % efforts.len();
            let s = score(case, efforts[k]);
            let slot = &mut all[k][i];
            if slot.as_ref().map_or(true, |old| s.time_s < old.time_s) {
                *slot = Some(s);
            }
        }
        if (i + 1) % 10 == 0 {
            eprintln!("  {} / {} frames", i + 1, cases.len());
        }
    }
    let full: Vec<f64> = all[0].iter().map(|s| s.as_ref().map_or(f64::NAN, |s| s.err)).collect();
    for (k, &e) in efforts.iter().enumerate() {
        let scores: Vec<Score> = all[k].iter_mut().map(|s| s.take().expect("scored")).collect();
        for set in sets {
            let idx: Vec<usize> = (0..cases.len()).filter(|&i| cases[i].set == set).collect();
            let errs: Vec<f64> = idx.iter().map(|&i| scores[i].err).collect();
            let within = |t: f64| errs.iter().filter(|&&x| x <= t).count();
            let unit = if set.starts_with("defocus ramp") { "px RMSE" } else { "relative" };
            // How far each frame moved from the first effort's answer.
            let moved = median(idx.iter().map(|&i| (scores[i].err - full[i]).abs()).collect());
            println!(
                "effort {e:.2} | {set} ({} frames) | fit time {:.1} ms in all | median {:.3} {unit}, worst {:.3} | within 15%/0.15 px {} | beyond 30%/0.3 px {} | answered {} | covered {} | median change from effort {:.2}: {moved:.3}",
                idx.len(),
                1e3 * idx.iter().map(|&i| scores[i].time_s).sum::<f64>(),
                median(errs.clone()),
                errs.iter().cloned().fold(0.0, f64::max),
                within(0.15),
                errs.iter().filter(|&&x| x > 0.3).count(),
                idx.iter().filter(|&&i| scores[i].answered).count(),
                idx.iter().filter(|&&i| scores[i].covered).count(),
                efforts[0]
            );
            if verbose {
                for &i in &idx {
                    println!("    {:50} err {:.3}  {}", cases[i].name, scores[i].err, scores[i].detail);
                }
            }
        }
    }
}
