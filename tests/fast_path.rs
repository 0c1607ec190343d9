//! Fast (blind) tier: the frame alone (plus depth for DoF and flow for MB). The
//! tolerances are the measured behaviour of these estimators on real photographs,
//! stated here and in the README; they are far looser than the accurate tier's
//! because a single frame cannot separate the scene from the camera exactly.

// Per-channel loops index several parallel arrays; see src/lib.rs.
#![allow(clippy::needless_range_loop)]

mod common;

use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Tier};
use blind_augment::image::Plane;
use blind_augment::model::*;
use blind_augment::synth::{add_dof, add_motion_blur, noise_field};
use common::*;

fn opts(noise: bool, mb: bool, dof: bool) -> FitOptions {
    FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise, motion_blur: mb, depth_of_field: dof },
        ..Default::default()
    }
}

/// Blind noise: every level measured on the frame (flattest samples per luma bin),
/// level 2–3 found texture-dominated here and continued from level 1. Measured
/// median |relative error| of synth's flat-grey std on astronaut over sensor-noise
/// seeds 3, 9, 11: 5.9–6.9% (4.3–5.3% when levels 1–3 came from level 0 by
/// white-noise ratios — exact for this white noise, wrong for real noise; texture
/// leaks into level 1's flattest samples); tolerance 10%. `SEED=n` reruns with another seed.
#[test]
fn fast_noise_within_stated_tolerance() {
    let clean = photo("astronaut.png");
    let (a, b) = ([2e-5f32, 1.2e-5, 4e-5], [8e-4f32, 5e-4, 1.2e-3]);
    let seed: u64 = std::env::var("SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(9);
    let noisy = add_sensor_noise(&clean, a, b, seed);
    let inp = FitInputs::new(&noisy);
    let noise = fit(&inp, &opts(true, false, false)).expect("valid").model.noise;
    assert!(noise.present);
    assert_eq!(noise.diagnostics.method, "fast");
    let [lo, hi] = noise.luminance_range;
    let mut errs = vec![];
    for k in 0..9 {
        let y = lo + (hi - lo) * (k as f32 + 0.5) / 9.0;
        let f = noise_field(&Plane::new(256, 256, y), &noise, 3);
        for c in 0..3 {
            let s =
                (f.channels[c].iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / f.channels[c].len() as f64).sqrt();
            errs.push((s / ((a[c] + b[c] * y) as f64).sqrt() - 1.0).abs());
        }
    }
    let med = median(errs);
    println!("fast noise: {:?} {:?} median |rel err| {med:.4}", noise.form, noise.levels[0]);
    assert!(med <= 0.10, "median relative error {med}");
}

/// Blind exposure from gradient-energy isotropy, 8 px/frame flow on astronaut.
/// Measured errors ≤ 0.1 (λ = 1 reads ≈ 0.90); tolerance 0.15 per case. Scene
/// anisotropy is the limit (on the Motorcycle photo, flow along x and along y give
/// 0.49 and 0.23 for λ = 0.4): see README.
#[test]
fn fast_exposure_within_stated_tolerance() {
    let img = photo("astronaut.png");
    let flow = flow_field(img.width, img.height, 8.0);
    for lambda in [0.0f32, 0.1, 0.5, 1.0] {
        let blurred = quantize8(&add_motion_blur(&img, &flow, lambda));
        let inp = FitInputs { flow: Some(&flow), ..FitInputs::new(&blurred) };
        let mb = fit(&inp, &opts(false, true, false)).expect("valid").model.motion_blur;
        let got = mb.exposure.expect("identifiable with 8 px flow");
        println!("fast λ {lambda} → {got:.3} ± {:?}", mb.diagnostics.stderr);
        assert!((got - lambda).abs() <= 0.15, "λ {lambda}: got {got}");
    }
}

/// The isotropy estimator's standard error must not claim more than it knows: where
/// defocus swamps a short streak, the along/across balance barely moves with λ and a
/// natural texture anisotropy would place the root almost anywhere. Astronaut,
/// 8 px/frame flow, λ 0.5 (4 px streak) under a uniform Gaussian defocus of σ 2.5
/// px, 8-bit: each answer is either *not identifiable* or within 2.5 of its own
/// standard errors of the truth. Measured: both defocused cases read *not
/// identifiable* (band [0, 1]; λ 0.134 and 0.194 by isotropy); without the texture
/// prior they read 0.134 ± 0.22 and 0.194 ± 0.25, absent — covered here by the
/// two-scale term, which misses on the 1280×960 bench frame (0 ± 0.033 for 0.5,
/// BENCHMARKS.md). The sharp case reads 0.524 ± 0.020 from the streak's zeros and
/// must stay within the stated 0.15.
#[test]
fn fast_exposure_uncertainty_covers_its_error_under_defocus() {
    let img = photo("astronaut.png");
    let flow = flow_field(img.width, img.height, 8.0);
    let depth = Plane::new(img.width, img.height, 2.0);
    for (sigma_px, lambda) in [(2.5f32, 0.5f32), (2.5, 0.0), (0.0, 0.5)] {
        let dof = DepthOfField {
            present: true,
            units: DepthUnits::MetricM,
            curve: Some(DofCurve::Constant { c: sigma_px }),
            depth_range: [1.0, 3.0],
            kernel: DofKernel::Gaussian,
            diagnostics: Diagnostics::not_fitted("truth"),
        };
        let blurred = add_motion_blur(&img, &flow, lambda);
        let frame = quantize8(&if sigma_px > 0.0 { add_dof(&blurred, &depth, &dof) } else { blurred });
        let inp = FitInputs { flow: Some(&flow), ..FitInputs::new(&frame) };
        let mb = fit(&inp, &opts(false, true, false)).expect("valid").model.motion_blur;
        let d = &mb.diagnostics;
        println!("σ {sigma_px} λ {lambda}: {:?} ± {:?} {:?} — {}", mb.exposure, d.stderr, d.status, d.reason);
        if d.status == Status::NotIdentifiable {
            assert!(sigma_px > 0.0, "a sharp streak is identifiable: {}", d.reason);
            continue;
        }
        let got = mb.exposure_or_zero();
        let se = d.stderr.expect("a fitted λ carries its standard error") as f32;
        if sigma_px > 0.0 {
            assert!((got - lambda).abs() <= 2.5 * se, "λ {lambda} under σ {sigma_px}: {got} ± {se} — {}", d.reason);
        } else {
            assert!((got - lambda).abs() <= 0.15, "λ {lambda}: got {got}");
        }
    }
}

/// Blind δ(Z) (Zhuo–Sim re-blur ratio on isolated edges + the same robust curve
/// fit) on two textures, a thin-lens and a quadratic truth each, 0.5–4 m ramp:
/// * a procedural texture of hard-edged shapes (`synth::sequence::procedural`, each
///   pixel the mean of 4×4 sub-samples: its own blur is a 1-px box, std 0.29 px,
///   which the estimator reads as 0.23–0.25 px, below what it resolves): measured
///   RMSE 0.056 / 0.041 px against the truth; tolerance 0.1 px (the 0.05 px of the
///   accurate tier's goal plus room for the 8-bit quantisation and the sample
///   scatter of another seed);
/// * the astronaut photograph, whose own edges are soft (the fit reads the
///   unblurred photograph at 0.8–1.3 px): against the truth alone it reads the sum
///   (RMSE 0.42 / 0.52 px), against the truth ⊕ its own blur read on the unblurred
///   photograph (blurs of independent causes add in variance) 0.091 / 0.055 px;
///   tolerance 0.2 px (that composition is itself an estimate from one fit).
///
/// Without requiring edges to be isolated (`fit::dof::blind::isolated`) the
/// procedural texture reads 0.244 / 0.195 px (thin bars' two edges cancel in the
/// re-blur and read δ low), and without selecting edges on the re-blurred gradient
/// the astronaut reads 0.142 / 0.062 against the truth ⊕ its own blur.
#[test]
fn fast_dof_within_stated_tolerance() {
    use blind_augment::synth::sequence::{motorcycle, procedural};
    let astronaut = photo("astronaut.png");
    let texture = procedural(&motorcycle().expect("bundled scene"), 2, 5).image;
    for (name, img, tol) in [("procedural", texture, 0.1), ("astronaut", astronaut, 0.2)] {
        let depth = depth_ramp(img.width, img.height, 0.5, 4.0);
        let own =
            fit(&FitInputs { depth: Some(&depth), ..FitInputs::new(&quantize8(&img)) }, &opts(false, false, true))
                .expect("valid")
                .model
                .depth_of_field;
        for curve in
            [DofCurve::ThinLens { k: 3.0, focus_depth: 1.2, c0: 0.3 }, DofCurve::Quadratic { a: 0.3, b: -1.0, c: 1.5 }]
        {
            let truth = DepthOfField {
                present: true,
                units: DepthUnits::MetricM,
                curve: Some(curve),
                depth_range: [0.5, 4.0],
                kernel: blind_augment::model::DofKernel::Gaussian,
                diagnostics: Diagnostics::not_fitted("truth"),
            };
            let blurred = quantize8(&add_dof(&img, &depth, &truth));
            let inp = FitInputs { depth: Some(&depth), ..FitInputs::new(&blurred) };
            let got = fit(&inp, &opts(false, false, true)).expect("valid").model.depth_of_field;
            let [lo, hi] = got.depth_range;
            let rmse = |want: &dyn Fn(f32) -> f32| {
                ((0..=100)
                    .map(|i| {
                        let z = lo + (hi - lo) * i as f32 / 100.0;
                        ((got.sigma_px(z) - want(z)) as f64).powi(2)
                    })
                    .sum::<f64>()
                    / 101.0)
                    .sqrt()
            };
            let (alone, composed) = (rmse(&|z| truth.sigma_px(z)), rmse(&|z| truth.sigma_px(z).hypot(own.sigma_px(z))));
            println!("fast DoF, {name}, {curve:?}: got {:?}, RMSE {alone:.3} (⊕ own blur {composed:.3})", got.curve);
            let measured = if name == "procedural" { alone } else { composed };
            assert!(measured <= tol, "{name} {curve:?}: RMSE {measured:.3} px (tolerance {tol})");
        }
    }
}

/// Blind δ is not pulled down by noise: each edge's gradients are averaged along
/// its tangent (`fit::dof`, `EDGE_TANGENT_TAPS`). Astronaut on a 0.5–4 m ramp,
/// blurred by a constant 2 px (Gaussian), quantised; the noisy frame adds the
/// calibration video's sensor noise after its change (std ≈ 0.035 at mid-grey).
/// Measured δ at 1.5 m: clean 2.35 px, noisy 2.34 px (−0.2%; both read the
/// photograph's own ~1.1 px with the 2 px: √(4 + 1.2) ≈ 2.3); with single-pixel
/// gradients clean 1.83 px, noisy 1.01 px (−45%); with averaged gradients but
/// without requiring isolated edges, clean 1.93 px, noisy 2.08 px (+8%).
/// Tolerance 12%, set from that +8%.
#[test]
fn fast_dof_reads_a_noisy_frame_like_a_clean_one() {
    let img = photo("astronaut.png");
    let depth = depth_ramp(img.width, img.height, 0.5, 4.0);
    let truth = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::Quadratic { a: 0.0, b: 0.0, c: 2.0 }),
        depth_range: [0.5, 4.0],
        kernel: blind_augment::model::DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("truth"),
    };
    let blurred = add_dof(&img, &depth, &truth);
    let read = |frame: &blind_augment::image::Rgb| {
        let inp = FitInputs { depth: Some(&depth), ..FitInputs::new(frame) };
        let got = fit(&inp, &opts(false, false, true)).expect("valid").model.depth_of_field;
        got.sigma_px(1.5)
    };
    let clean = read(&quantize8(&blurred));
    let noisy =
        read(&quantize8(&add_sensor_noise(&blurred, [6.75e-5, 4.5e-5, 1.125e-4], [1.35e-3, 9e-4, 2.025e-3], 5)));
    println!("fast DoF at 1.5 m: clean {clean:.3} px, noisy {noisy:.3} px");
    assert!(clean > 1.5 && clean < 3.0, "clean frame reads {clean} px for 2 px");
    assert!((noisy / clean - 1.0).abs() <= 0.12, "noisy {noisy} px vs clean {clean} px");
}

/// Blind noise's coarse levels on the calibration video (the Motorcycle photograph
/// re-rendered along a head path, 320×240, Poisson–Gaussian noise ×1.5 after the
/// camera change — `synth::sequence`): on frames 110–125 the flattest samples of
/// levels 1–3 scatter by luma bin (texture in some bins, noise in others) and no
/// line explains three of them. Keeping every bin would put levels 1–3 at up to 21×
/// the truth (1 frame in 12 over 3× across the 150-frame video); such a level
/// counts as not identifiable and continues the finest measured one. Measured: the
/// worst level 1–3 std over all 150 frames is 1.86× the truth (the
/// level-0 texture inflation this scene carries through), 1.05× on these frames.
/// Bound: within 2× either way on every frame.
#[test]
fn coarse_noise_levels_never_run_away_on_the_calibration_video() {
    use blind_augment::synth::sequence::{motorcycle, SequenceSpec};
    let scene = motorcycle().expect("bundled scene");
    let spec = SequenceSpec::motorcycle(&scene, 320, 240, 150, Some(2.5));
    for i in 110..125 {
        let f = spec.frame(&scene, i);
        let noise = fit(&FitInputs::new(&f.image), &opts(true, false, false)).expect("valid").model.noise;
        assert!(noise.present, "frame {i}: {}", noise.diagnostics.reason);
        let truth = &f.truth.noise;
        let at =
            |n: &Noise, l: usize| n.levels[l].std(n.form, 1, 0.4f32.clamp(n.luminance_range[0], n.luminance_range[1]));
        for l in 1..4 {
            let ratio = at(&noise, l) / at(truth, l);
            assert!(
                (0.5..=2.0).contains(&ratio),
                "frame {i} level {l}: {ratio:.2}× the truth; {}",
                noise.diagnostics.reason
            );
        }
    }
}

/// Blind noise with the previous exposure aligned by pose and depth
/// (`FitInputs::neighbour`, what the worker's fast tier passes): texture is common to
/// the two exposures and the noise is not, so level 0 reads B(b·(b − b')) and the
/// coarser levels B((b − b')²)/(1 + κ_l). Calibration video (Motorcycle along the
/// head path, 320×240), frames 55–64: measured median error 7.7%, worst 10.9%
/// (the frame alone: median 28%, worst 36% — its flattest samples are texture).
/// Bounds: median 10% (the fast tier's target on video), every frame 15%.
#[test]
fn noise_with_an_aligned_neighbour_reads_through_texture_on_video() {
    use blind_augment::analysis::temporal::align;
    use blind_augment::fit::Neighbour;
    use blind_augment::model::compare::noise_relative_error;
    use blind_augment::synth::sequence::{motorcycle, SequenceSpec};
    let scene = motorcycle().expect("bundled scene");
    let spec = SequenceSpec::motorcycle(&scene, 320, 240, 150, Some(2.5));
    let mut prev = analysed(&spec.frame(&scene, 54));
    let (mut with, mut alone) = (vec![], vec![]);
    for i in 55..65 {
        let f = spec.frame(&scene, i);
        let cur = analysed(&f);
        let a = align(&prev, &cur, &spec.view).expect("poses and depth align");
        let valid = Plane::from_vec(320, 240, a.valid.iter().map(|&v| v as u8 as f32).collect());
        let inp =
            FitInputs { neighbour: Some(Neighbour { image: &a.image, valid: &valid }), ..FitInputs::new(&f.image) };
        let n = fit(&inp, &opts(true, false, false)).expect("valid").model.noise;
        let e = noise_relative_error(&n, &f.truth.noise).expect("present");
        assert!(e <= 0.15, "frame {i}: {:.1}% off; {}", 100.0 * e, n.diagnostics.reason);
        with.push(e);
        let n1 = fit(&FitInputs::new(&f.image), &opts(true, false, false)).expect("valid").model.noise;
        alone.push(noise_relative_error(&n1, &f.truth.noise).unwrap_or(f32::NAN));
        prev = cur;
    }
    let median = |v: &mut Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let (m, m1) = (median(&mut with), median(&mut alone));
    println!("median error with the neighbour {:.1}%, the frame alone {:.1}%", 100.0 * m, 100.0 * m1);
    assert!(m <= 0.10, "median {:.1}%", 100.0 * m);
}

/// Levels the blind noise fit cannot measure continue the finest measured level by
/// white-noise band ratios: they carry that level's error and no more. The case is
/// the astronaut under weak sensor noise (below; 1280×960, seed 3), where texture
/// reads level 1 high (measured +56%). A continuation scaled by the measured levels'
/// decay against white, which there is that texture, reads levels 2–3 at +110 /
/// +185% (BENCHMARKS.md "The blind noise fit's derived levels"). Tolerance 1 point:
/// the continuation is the measured level's map times a constant per level, so its
/// relative error is that level's, up to rounding.
#[test]
fn derived_noise_levels_carry_the_measured_error_and_no_more() {
    let (a, b) = ([5e-6f32; 3], [2e-4f32; 3]);
    let img = quantize8(&add_sensor_noise(&mirror_tile(&photo("astronaut.png"), 1280, 960), a, b, 3));
    let opts = opts(true, false, false);
    let n = fit(&FitInputs::new(&img), &opts).expect("fit").model.noise;
    let unit = blind_augment::synth::unit_band_std();
    let [lo, hi] = n.luminance_range;
    // Median signed error over 9 lumas × 3 channels against the added white noise.
    let error = |l: usize| {
        median(
            (0..27)
                .map(|k| {
                    let (y, c) = (lo + (hi - lo) * ((k / 3) as f32 + 0.5) / 9.0, k % 3);
                    let truth = unit[l] as f64 * ((a[c] + b[c] * y) as f64).sqrt();
                    n.levels[l].std(n.form, c, y) as f64 / truth - 1.0
                })
                .collect(),
        )
    };
    let reason = &n.diagnostics.reason;
    let derived: Vec<usize> = (1..NOISE_LEVELS)
        .filter(|l| {
            reason
                .split("levels [")
                .nth(1)
                .and_then(|s| s.split(']').next())
                .is_some_and(|s| s.split(", ").any(|v| v == l.to_string()))
        })
        .collect();
    let finest = (0..NOISE_LEVELS).rev().find(|l| !derived.contains(l)).expect("level 0 is measured");
    eprintln!(
        "measured up to level {finest}, derived {derived:?}; errors {:?}",
        (0..NOISE_LEVELS).map(error).collect::<Vec<_>>()
    );
    assert!(finest >= 1 && !derived.is_empty(), "the case needs a coarse level measured and one derived: {reason}");
    for &l in &derived {
        assert!(
            error(l) <= error(finest) + 0.01,
            "level {l}: {:+.3} against level {finest}'s {:+.3}",
            error(l),
            error(finest)
        );
    }
}

/// The frame-alone noise fit's standard error holds its level-0 error at mid luma
/// within two standard errors, texture in the flattest samples included. Four
/// natural scenes the texture floor was fitted on (the astronaut, chelsea, the
/// Motorcycle view, the vtest clip's temporal mean) and one it was not (the rocket),
/// under a weak noise and the bench's noise, 1280×960, 8-bit, seed 3. Measured:
/// errors +1.8…+34.6%, 9 of 10 held (not: the Motorcycle under the bench's noise,
/// +23.7% against ± 8.6%; 7 of its 9 frames at three strengths and three seeds
/// held); with the sampling error alone (± 0.3–2.5%) 1 of 10. Tolerance: 9
/// of 10, and a median standard error ≤ 25% (measured 17.6%), so that no inflated
/// figure passes. On the clip's temporal mean the error itself is held to 12%.
#[test]
fn blind_noise_standard_error_covers_texture_in_the_flat_samples() {
    let (w, h) = (1280, 960);
    let scenes = [
        ("astronaut", photo("astronaut.png")),
        ("chelsea", photo("chelsea.png")),
        ("motorcycle", asset_photo("motorcycle_left_333x497.png")),
        ("vtest mean", photo("noise_vtest/mean.png")),
        ("rocket (held out)", photo("rocket.jpg")),
    ];
    let strengths: [([f32; 3], [f32; 3]); 2] = [([5e-6; 3], [2e-4; 3]), ([2e-5, 1.2e-5, 4e-5], [8e-4, 5e-4, 1.2e-3])];
    let unit = blind_augment::synth::unit_band_std();
    let (mut held, mut ses) = (0, vec![]);
    for (name, clean) in &scenes {
        let clean = mirror_tile(clean, w, h);
        for (a, b) in strengths {
            let img = quantize8(&add_sensor_noise(&clean, a, b, 3));
            let n = fit(&FitInputs::new(&img), &opts(true, false, false)).expect("fit").model.noise;
            assert!(n.present, "{name}: {}", n.diagnostics.reason);
            let ym = 0.5 * (n.luminance_range[0] + n.luminance_range[1]);
            let (mut got, mut want) = (0.0f64, 0.0f64);
            for c in 0..3 {
                got += n.levels[0].std(n.form, c, ym) as f64 / 3.0;
                want += unit[0] as f64 * ((a[c] + b[c] * ym) as f64).sqrt() / 3.0;
            }
            let (err, se) = (got / want - 1.0, n.diagnostics.stderr.expect("a standard error"));
            eprintln!(
                "{name} b {:.0e}: level-0 error at luma {ym:.2} {:+.1}%, reported ± {:.1}%",
                b[0],
                100.0 * err,
                100.0 * se
            );
            held += (err.abs() <= 2.0 * se) as usize;
            ses.push(se);
            // The clip's temporal mean carries no noise of its own to speak of (the
            // fit reads 0.0020 on it alone, texture included: at most +1.6% on the
            // weakest noise here), so its error is the estimator's: measured +4.7 /
            // +7.9% (seeds 3, 9, 11: +4.7…+5.6 / +7.5…+8.0%); tolerance 12%.
            if *name == "vtest mean" {
                assert!(err.abs() <= 0.12, "{name}: level-0 error {err:+.3} on a scene without noise of its own");
            }
        }
    }
    let med = median(ses);
    eprintln!("held {held} of 10; median standard error {:.1}%", 100.0 * med);
    assert!(held >= 9, "two standard errors held {held} of 10");
    assert!(med <= 0.25, "median standard error {med}");
}

/// `FitOptions::fast_effort` (BENCHMARKS.md "The fast tier's effort"), at 1280×960
/// where every scaled count applies: at effort 0.5 the exposure fit reads fewer
/// streak lines and the defocus fit fewer edges (every other row of its scan, said
/// in the reason), with answers near full effort's; an edge-poor frame's reduced
/// scan finds too few edges and the other rows are read too — the full scan's
/// edges, so the same curve as at full effort. Tolerances, from measurements over
/// 24 defocus-ramp frames (BENCHMARKS.md "The fast tier's effort"): λ within 0.05 of
/// the truth at both efforts (measured here 0.499 → 0.501; over two seeds
/// 0.495–0.519); δ(Z) RMSE at effort 0.5 within 0.1 px of full effort's (measured
/// here 0.458 → 0.456 px against the lens alone — the photograph's own blur is in
/// both; over the 24 ramp frames the median moved by 0.000 px, the largest by 0.014).
#[test]
fn fast_effort_reads_fewer_samples_and_keeps_edge_poor_frames() {
    let (w, h) = (1280, 960);
    let at = |effort: f32, mb: bool, dof: bool| FitOptions { fast_effort: effort, ..opts(false, mb, dof) };
    let astronaut = mirror_tile(&photo("astronaut.png"), w, h);
    // Exposure: a 12 px streak at 30° (24 px/frame, λ 0.5), read by the zeros.
    let a = 30f32.to_radians();
    let flow = blind_augment::image::Flow::uniform(w, h, 24.0 * a.cos(), 24.0 * a.sin());
    let frame = quantize8(&add_sensor_noise(&add_motion_blur(&astronaut, &flow, 0.5), [2e-5; 3], [8e-4; 3], 1));
    let inp = FitInputs { flow: Some(&flow), ..FitInputs::new(&frame) };
    let [full, half] = [1.0, 0.5].map(|e| fit(&inp, &at(e, true, false)).expect("valid").model.motion_blur);
    println!(
        "effort 1: {:?} from {} lines; 0.5: {:?} from {}",
        full.exposure, full.diagnostics.samples_used, half.exposure, half.diagnostics.samples_used
    );
    for mb in [&full, &half] {
        let got = mb.exposure.expect("identified by the zeros");
        assert!((got - 0.5).abs() <= 0.05, "λ {got}: {}", mb.diagnostics.reason);
    }
    assert!(half.diagnostics.samples_used < full.diagnostics.samples_used);
    // Defocus on a thin-lens ramp: edge-rich (astronaut, ~2 900 edges at full
    // effort) and edge-poor (chelsea, ~240).
    let depth = depth_ramp(w, h, 0.5, 4.0);
    let (_, lens) = thin_lens_ramp(w, h);
    let chelsea = mirror_tile(&photo("chelsea.png"), w, h);
    for (name, img) in [("astronaut", &astronaut), ("chelsea", &chelsea)] {
        let frame = quantize8(&add_sensor_noise(&add_dof(img, &depth, &lens), [1e-4; 3], [0.0; 3], 3));
        let inp = FitInputs { depth: Some(&depth), ..FitInputs::new(&frame) };
        let [full, half] = [1.0, 0.5].map(|e| fit(&inp, &at(e, false, true)).expect("valid").model.depth_of_field);
        let rmse = |d: &DepthOfField| {
            ((0..=100)
                .map(|i| {
                    let z = 0.5 + 3.5 * i as f32 / 100.0;
                    ((d.sigma_px(z) - lens.sigma_px(z)) as f64).powi(2)
                })
                .sum::<f64>()
                / 101.0)
                .sqrt()
        };
        let (n_full, n_half) = (full.diagnostics.samples_used, half.diagnostics.samples_used);
        println!(
            "{name}: {n_full} → {n_half} edges, RMSE {:.3} → {:.3}; {}",
            rmse(&full),
            rmse(&half),
            half.diagnostics.reason
        );
        assert!(half.diagnostics.reason.contains("edge scan on one row in 2"), "{}", half.diagnostics.reason);
        if name == "chelsea" {
            assert!(half.diagnostics.reason.contains("the other rows were read too"), "{}", half.diagnostics.reason);
            // The full scan's edges in its order: the same curve, bit for bit.
            assert_eq!(n_half, n_full, "the full scan's edges");
            assert_eq!(half.curve, full.curve);
        } else {
            assert!(n_half < n_full && n_half >= 600, "{n_full} → {n_half}");
            assert!((rmse(&half) - rmse(&full)).abs() <= 0.1, "RMSE {} → {}", rmse(&full), rmse(&half));
        }
    }
}

/// The blind δ(Z)'s standard error (δ RMS over the evaluated depths) holds its
/// error, or the fit says *not identifiable*. The standard error is a
/// cluster-robust sandwich over frame cells, the two forms' spread beyond the
/// textured depths and 5% of δ for the edge calibration (BENCHMARKS.md "The blind
/// δ(Z)'s standard error"); scale·√(3/N), the edges taken as independent and the
/// curve as known beyond them, is 6–25× under the error on 24 defocus-ramp frames
/// (none within two standard errors). Two of those frames at 1280×960:
/// * a texture with no blur of its own (the procedural shapes) under a thin lens
///   k 2, focus 2.5 m — the worst relative miss of the ramp frames there (0.075 px
///   RMSE, 10% of δ's RMS), where scale·√(3/N) reports ± 0.011 px and the sandwich
///   ± 0.039: the RMSE must lie within two standard errors (tolerance: the
///   definition of "covered" over the ramp frames, 18 of their 21 answered);
/// * an edge-poor frame (the rocket: ~240 edges, all at 1.6–3.0 m of a 0.5–4 m
///   ramp) under k 3, focus 1.2 m: scale·√(3/N) reads a quadratic 0.78 px RMSE off
///   at ± 0.066 px, *present*; with the sandwich the curve through that band,
///   extrapolated to 1.1–4 m, is within three of its standard errors of none: *not
///   identifiable* — or, if present, covered like the first.
#[test]
fn blind_dof_standard_error_covers_its_error_or_says_not_identifiable() {
    use blind_augment::synth::sequence::{motorcycle, procedural};
    let (w, h) = (1280, 960);
    let depth = depth_ramp(w, h, 0.5, 4.0);
    let texture = mirror_tile(&procedural(&motorcycle().expect("bundled scene"), 4, 5).image, w, h);
    let rocket = mirror_tile(&photo("rocket.jpg"), w, h);
    for (name, img, lens) in [
        ("procedural", &texture, DofCurve::ThinLens { k: 2.0, focus_depth: 2.5, c0: 0.2 }),
        ("rocket", &rocket, DofCurve::ThinLens { k: 3.0, focus_depth: 1.2, c0: 0.3 }),
    ] {
        let truth = DepthOfField {
            present: true,
            units: DepthUnits::MetricM,
            curve: Some(lens),
            depth_range: [0.5, 4.0],
            kernel: DofKernel::Gaussian,
            diagnostics: Diagnostics::not_fitted("truth"),
        };
        let frame = quantize8(&add_sensor_noise(&add_dof(img, &depth, &truth), [1e-4; 3], [0.0; 3], 3));
        let inp = FitInputs { depth: Some(&depth), ..FitInputs::new(&frame) };
        let dof = fit(&inp, &opts(false, false, true)).expect("valid").model.depth_of_field;
        let [lo, hi] = dof.depth_range;
        // Against the lens alone: neither texture has blur of its own at this scale
        // (the rocket's, read at one depth, is 0.0 px).
        let rmse = ((0..=100)
            .map(|i| {
                let z = lo + (hi - lo) * i as f32 / 100.0;
                ((dof.sigma_px(z) - truth.sigma_px(z)) as f64).powi(2)
            })
            .sum::<f64>()
            / 101.0)
            .sqrt();
        let se = dof.diagnostics.stderr.expect("a standard error");
        println!(
            "{name}: {:?}, {} edges, RMSE {rmse:.3} px, ± {se:.3} px: {}",
            dof.diagnostics.status, dof.diagnostics.samples_used, dof.diagnostics.reason
        );
        assert!(se.is_finite() && se > 0.0, "{name}: standard error {se}");
        match (name, dof.diagnostics.status) {
            ("rocket", Status::NotIdentifiable) => assert!(!dof.present),
            (_, Status::Present) => assert!(rmse <= 2.0 * se, "{name}: RMSE {rmse:.3} px beyond 2 × {se:.3} px"),
            (_, s) => panic!("{name}: {s:?}: {}", dof.diagnostics.reason),
        }
    }
}

/// Past the curve fit's edge cap (`FAST_MAX_EDGE_SAMPLES`, every k-th edge kept) each
/// kept edge keeps its own frame cell: the standard error is clustered, not taken
/// over samples paired with other edges' cells (which falls back to independent
/// samples). The sharp astronaut mirror-tiled to 2560×1920 gives ~10 700 edges,
/// so every 2nd is kept (5 345, measured). Fails with the cells thinned twice.
#[test]
fn thinned_edges_keep_their_cells() {
    let (w, h) = (2560, 1920);
    let img = quantize8(&mirror_tile(&photo("astronaut.png"), w, h));
    let depth = depth_ramp(w, h, 0.5, 4.0);
    let inp = FitInputs { depth: Some(&depth), ..FitInputs::new(&img) };
    let dof = fit(&inp, &opts(false, false, true)).expect("valid").model.depth_of_field;
    println!("{} edges: {}", dof.diagnostics.samples_used, dof.diagnostics.reason);
    assert!((4097..=8192).contains(&dof.diagnostics.samples_used), "{}", dof.diagnostics.samples_used);
    assert!(dof.diagnostics.reason.contains("samples clustered in"), "{}", dof.diagnostics.reason);
    assert!(!dof.diagnostics.reason.contains("taken as independent"), "{}", dof.diagnostics.reason);
}

/// A blind reading of a visible streak that its standard error cannot tell from none
/// is *not identifiable*, not *absent* (`fit::motion_blur::exposure_status`):
/// called absent, it would be a vote for "no motion blur" in the worker's window
/// however right the reading (30 of 123 box streaks on photographs and text pages,
/// among them the astronaut's 8 px read 8.0 ± 3.2 px). Frames: the astronaut and the
/// rocket mirror-tiled to 640×480, uniform flow of 50 px/frame at 0° and 90°, box
/// streaks of 8 px (λ 0.16) and none, 3 DN of sensor noise, 8-bit. Each streak must
/// read present or not identifiable with the truth within two standard errors (its
/// error holds it), never absent; no streak must never read present.
#[test]
fn a_visible_streak_within_its_error_is_not_identifiable_not_absent() {
    let (w, h) = (640, 480);
    let mut called_absent = vec![];
    for name in ["astronaut.png", "rocket.jpg"] {
        let clean = mirror_tile(&photo(name), w, h);
        for angle_deg in [0.0f32, 90.0] {
            let (s, c) = angle_deg.to_radians().sin_cos();
            let flow = blind_augment::image::Flow::uniform(w, h, 50.0 * c, 50.0 * s);
            for lambda in [0.0f32, 0.16] {
                // 3 DN of white noise: variance (3/255)² at every luma.
                let var = (3.0f32 / 255.0).powi(2);
                let frame =
                    quantize8(&add_sensor_noise(&add_motion_blur(&clean, &flow, lambda), [var; 3], [0.0; 3], 5));
                let inp = FitInputs { flow: Some(&flow), ..FitInputs::new(&frame) };
                let mb = fit(&inp, &opts(false, true, false)).expect("valid").model.motion_blur;
                let d = &mb.diagnostics;
                let (got, se) = (mb.exposure.unwrap_or(0.0), d.stderr.unwrap_or(f64::NAN) as f32);
                println!(
                    "{name} {angle_deg}° λ {lambda}: {:.1} ± {:.1} px {:?} — {}",
                    50.0 * got,
                    50.0 * se,
                    d.status,
                    d.reason
                );
                if lambda == 0.0 {
                    assert_ne!(d.status, Status::Present, "{name} {angle_deg}° without a streak: {}", d.reason);
                    continue;
                }
                if d.status == Status::Absent {
                    called_absent.push(format!("{name} {angle_deg}°: {got} ± {se}"));
                }
                if d.status == Status::NotIdentifiable && mb.exposure.is_some() {
                    assert!((got - lambda).abs() <= 2.0 * se, "{name} {angle_deg}°: {got} ± {se} for {lambda}");
                }
            }
        }
    }
    assert!(called_absent.is_empty(), "visible streaks called absent: {called_absent:?}");
}
