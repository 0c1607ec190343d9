//! Probe: the blind DoF fit on single frames of the calibration video, against the
//! truth's δ(Z), with and without the video's other effects and its added defocus.
use blind_augment::fit::{self, Effects, FitInputs, FitOptions, Tier};
use blind_augment::model::DepthUnits;
use blind_augment::synth::sequence::*;

fn main() {
    blind_augment::alloc::keep_freed_blocks();
    let args: Vec<String> = std::env::args().collect();
    let w: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(320);
    let mut scene = motorcycle().unwrap();
    // SCENE=procedural: the Motorcycle's depth under a texture of known blur, one
    // source pixel per view pixel from 1280 px wide
    // (`synth::sequence::procedural`).
    if std::env::var("SCENE").is_ok_and(|s| s == "procedural") {
        scene = procedural(&scene, (w / 320).max(1), 11);
    }
    let spec = SequenceSpec::motorcycle(&scene, w, w * 3 / 4, 150, None);
    let truth = spec.truth.clone();
    let r = truth.depth_of_field.depth_range;
    let depths: Vec<f32> = (0..8).map(|i| r[0] + (r[1] - r[0]) * (i as f32 + 0.5) / 8.0).collect();
    println!("depths {:?}", depths.iter().map(|z| (z * 100.0).round() / 100.0).collect::<Vec<_>>());
    println!(
        "truth  {:?}",
        depths.iter().map(|&z| (truth.depth_of_field.sigma_px(z) * 100.0).round() / 100.0).collect::<Vec<_>>()
    );
    let floor = spec.source_pixel_blur_px(&scene);
    println!(
        "truth ⊕ the photograph's pixel ({floor:.2} px) {:?}",
        depths
            .iter()
            .map(|&z| (truth.depth_of_field.sigma_px(z).hypot(floor) * 100.0).round() / 100.0)
            .collect::<Vec<_>>()
    );
    // POOL=i,j,…: those frames (every effect on), each frame's curve, the pooled
    // curve (`fit::fit_fast_pooled`) and the raw edge samples' median per depth bin.
    if let Ok(list) = std::env::var("POOL") {
        let idx: Vec<usize> = list.split(',').filter_map(|s| s.parse().ok()).collect();
        let mut plots = vec![];
        for &i in &idx {
            let f = spec.frame(&scene, i);
            let o = fit_dof(&f);
            let d = &o.model.depth_of_field;
            let motion = f.flow.dx.iter().zip(&f.flow.dy).map(|(x, y)| x.hypot(*y)).fold(0.0f32, f32::max);
            let still: f32 = std::env::var("STILL").ok().and_then(|s| s.parse().ok()).unwrap_or(f32::INFINITY);
            if motion > still {
                continue;
            }
            println!(
                "frame {i:3} (motion {motion:.1} px/frame): {:?} [{:.1} ms: {}]",
                depths.iter().map(|&z| (d.sigma_px(z) * 100.0).round() / 100.0).collect::<Vec<_>>(),
                d.diagnostics.fit_time_s * 1e3,
                d.diagnostics
                    .stages_s
                    .iter()
                    .map(|(k, v)| format!("{k} {:.1}", v * 1e3))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            if let Some(p) = o.plots.depth_of_field {
                plots.push(p);
            }
        }
        let refs: Vec<&fit::DofPlotData> = plots.iter().collect();
        let (d, _) = fit::fit_fast_pooled(&refs, DepthUnits::MetricM, blind_augment::model::DofKernel::Gaussian);
        println!(
            "pooled ({:.1} ms: {}): {:?}",
            d.diagnostics.fit_time_s * 1e3,
            d.diagnostics.stages_s.iter().map(|(k, v)| format!("{k} {:.1}", v * 1e3)).collect::<Vec<_>>().join(", "),
            depths.iter().map(|&z| (d.sigma_px(z) * 100.0).round() / 100.0).collect::<Vec<_>>()
        );
        // Raw samples' median per bin of the 8 depths (± half a bin).
        let half = 0.5 * (r[1] - r[0]) / 8.0;
        let med: Vec<String> = depths
            .iter()
            .map(|&z| {
                let mut v: Vec<f32> = plots
                    .iter()
                    .flat_map(|p| p.depth.iter().zip(&p.sigma_px))
                    .filter(|(d, _)| (**d - z).abs() <= half)
                    .map(|(_, s)| *s)
                    .collect();
                v.sort_by(f32::total_cmp);
                match v.len() {
                    0 => "-".into(),
                    n => format!("{:.2}({n})", v[n / 2]),
                }
            })
            .collect();
        println!("raw median per depth bin (samples): {}", med.join(" "));
        return;
    }
    let cases = std::env::var("CASES").unwrap_or("all,dof only,none".into());
    for case in cases.split(',') {
        for i in [10usize, 40, 70, 100] {
            let mut s = spec.clone();
            match case {
                "dof only" => {
                    s.truth.noise.present = false;
                    s.truth.motion_blur.exposure = Some(0.0);
                }
                "dof+noise" => s.truth.motion_blur.exposure = Some(0.0),
                "dof+mb" => s.truth.noise.present = false,
                "none" => {
                    s.truth.noise.present = false;
                    s.truth.motion_blur.exposure = Some(0.0);
                    s.truth.depth_of_field.present = false;
                }
                _ => {}
            }
            let o = fit_dof(&s.frame(&scene, i));
            let d = &o.model.depth_of_field;
            // RMSE over the 8 depths against the truth ⊕ the photograph's pixel (none
            // for "none"), next to the fit's own standard error and status.
            let want = |z: f32| s.truth.depth_of_field.sigma_px(z).hypot(floor);
            let rmse = (depths.iter().map(|&z| ((d.sigma_px(z) - want(z)) as f64).powi(2)).sum::<f64>() / 8.0).sqrt();
            println!(
                "{case:9} frame {i:3}: {:?} RMSE {rmse:.2} ± {:.2} px {:?} [{}]",
                depths.iter().map(|&z| (d.sigma_px(z) * 100.0).round() / 100.0).collect::<Vec<_>>(),
                d.diagnostics.stderr.unwrap_or(f64::NAN),
                d.diagnostics.status,
                d.diagnostics.reason.chars().take(100).collect::<String>()
            );
        }
    }
}

/// The blind DoF fit alone on one frame of the video.
fn fit_dof(f: &SequenceFrame) -> fit::FitOutput {
    let inp = FitInputs { depth: Some(&f.depth_m), depth_units: DepthUnits::MetricM, ..FitInputs::new(&f.image) };
    let opts = FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: false, motion_blur: false, depth_of_field: true },
        ..Default::default()
    };
    fit::fit(&inp, &opts).unwrap()
}
