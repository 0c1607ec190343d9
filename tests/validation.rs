//! Accurate tier (the paper's OPTIMIZATION setting) on real photographs with known
//! synthetic distortions, against the core tolerances:
//! median |λ error| ≤ 0.01 (sub-2-px streaks included), δ RMSE ≤ 0.05 px over the
//! fitted depth range, noise std of `synth` on flat greys within a median 1.5%.
//! Distorted frames go through 8-bit quantisation, as a PNG round trip would.

// Per-channel loops index several parallel arrays; see src/lib.rs.
#![allow(clippy::needless_range_loop)]

mod common;

use blind_augment::fit::{fit, Effects, FitInputs, FitOptions};
use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::model::*;
use blind_augment::synth::{self, add_dof, add_motion_blur};
use common::*;

fn only(noise: bool, mb: bool, dof: bool) -> FitOptions {
    FitOptions { effects: Effects { noise, motion_blur: mb, depth_of_field: dof }, ..Default::default() }
}

fn fit_lambda(sharp: &Rgb, flow: &Flow, lambda: f32) -> MotionBlur {
    let blurred = quantize8(&add_motion_blur(sharp, flow, lambda));
    let inp = FitInputs { motion_deblurred: Some(sharp), flow: Some(flow), ..FitInputs::new(&blurred) };
    fit(&inp, &only(false, true, false)).expect("valid inputs").model.motion_blur
}

/// λ over the range, with 8 px/frame flow and with 1.5 px/frame flow (streaks of
/// 0.3–1.35 px, which a 10-step grid on a coarse sampler cannot see), at 512² and at
/// an odd size (451×300).
#[test]
fn exposure_accurate_median_error_within_0_01() {
    let astronaut = photo("astronaut.png");
    let chelsea = photo("chelsea.png");
    let mut errors = vec![];
    let cases: [(&Rgb, f32, &[f32]); 3] = [
        (&astronaut, 8.0, &[0.0, 0.1, 0.25, 0.5, 0.75, 1.0]),
        (&astronaut, 1.5, &[0.2, 0.5, 0.9]),
        (&chelsea, 5.0, &[0.3, 0.7]),
    ];
    for (img, scale, lambdas) in cases {
        let flow = flow_field(img.width, img.height, scale);
        for &lambda in lambdas {
            let mb = fit_lambda(img, &flow, lambda);
            let got = mb.exposure.expect("identifiable");
            println!(
                "{}×{} flow {scale} px: λ {lambda} → {got:.4} ({:?})",
                img.width, img.height, mb.diagnostics.status
            );
            errors.push((got - lambda).abs() as f64);
            // No single case may be far off either: 0.04 covers the 8-bit
            // quantisation of sub-pixel streaks (their whole signal is a few 1/255 steps).
            assert!((got - lambda).abs() <= 0.04, "λ {lambda} at {scale} px/frame: got {got}");
            assert_eq!(mb.present, lambda > 0.0, "presence for λ = {lambda}");
        }
    }
    let med = median(errors);
    println!("median |λ error| = {med:.4}");
    assert!(med <= 0.01, "median |λ error| {med} > 0.01");
}

fn dof_rmse(fitted: &DepthOfField, truth: &DepthOfField) -> f64 {
    let [lo, hi] = fitted.depth_range;
    let n = 200;
    let sse: f64 = (0..=n)
        .map(|i| {
            let z = lo + (hi - lo) * i as f32 / n as f32;
            (fitted.sigma_px(z) - truth.sigma_px(z)) as f64
        })
        .map(|e| e * e)
        .sum();
    (sse / (n + 1) as f64).sqrt()
}

fn truth_dof(units: DepthUnits, curve: DofCurve, range: [f32; 2]) -> DepthOfField {
    DepthOfField {
        present: true,
        units,
        curve: Some(curve),
        depth_range: range,
        kernel: blind_augment::model::DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("truth"),
    }
}

fn fit_dof_with(
    sharp: &Rgb,
    depth: &Plane,
    units: DepthUnits,
    truth: &DepthOfField,
    opts: &FitOptions,
) -> DepthOfField {
    let blurred = quantize8(&add_dof(sharp, depth, truth));
    let inp = FitInputs {
        defocus_deblurred: Some(sharp),
        depth: Some(depth),
        depth_units: units,
        ..FitInputs::new(&blurred)
    };
    fit(&inp, opts).expect("valid inputs").model.depth_of_field
}

fn fit_dof(sharp: &Rgb, depth: &Plane, units: DepthUnits, truth: &DepthOfField) -> DepthOfField {
    fit_dof_with(sharp, depth, units, truth, &only(false, false, true))
}

/// The full-resolution stack (no pyramid handoff) on the strongest case (to 9.4 px)
/// must be 5× inside the tolerance, which is what the faster default spends.
/// Measured 0.0077 px (0.0049 without the fit's blend map: the fit's 0.5 px blends
/// and synth's 0.25 px blends then share the same excess of high frequency, which
/// partly cancels; with it the fit reads exact Gaussians, and synth's blends within
/// −0.013 px of their δ — tests/independent_forward.rs).
#[test]
fn dof_full_resolution_stack_is_exact() {
    let img = photo("astronaut.png");
    let depth = depth_ramp(img.width, img.height, 0.5, 4.0);
    let truth = truth_dof(DepthUnits::MetricM, DofCurve::ThinLens { k: 8.0, focus_depth: 0.7, c0: 0.0 }, [0.5, 4.0]);
    let opts = FitOptions { dof_pyramid_from_px: None, ..only(false, false, true) };
    let got = fit_dof_with(&img, &depth, DepthUnits::MetricM, &truth, &opts);
    let rmse = dof_rmse(&got, &truth);
    println!("full-resolution stack: RMSE {rmse:.4} px");
    assert!(rmse <= 0.01, "δ RMSE {rmse} px");
}

/// Both forms as truth on a 512² photo with metric depth 0.5–4 m.
#[test]
fn dof_accurate_rmse_within_0_05_px_metric() {
    let img = photo("astronaut.png");
    let depth = depth_ramp(img.width, img.height, 0.5, 4.0);
    for curve in [
        DofCurve::ThinLens { k: 3.0, focus_depth: 1.2, c0: 0.3 },
        DofCurve::Quadratic { a: 0.3, b: -1.0, c: 1.5 },
        DofCurve::ThinLens { k: 8.0, focus_depth: 0.7, c0: 0.0 }, // up to 9.4 px at 4 m
    ] {
        let truth = truth_dof(DepthUnits::MetricM, curve, [0.5, 4.0]);
        let got = fit_dof(&img, &depth, DepthUnits::MetricM, &truth);
        let rmse = dof_rmse(&got, &truth);
        println!("truth {curve:?}: got {:?}, RMSE {rmse:.4} px", got.curve);
        assert!(got.present);
        assert!(rmse <= 0.05, "δ RMSE {rmse} px > 0.05 for {curve:?}");
    }
}

/// Real ground-truth disparity (Middlebury Motorcycle, 497×333, odd size, invalid
/// pixels present) as relative inverse depth.
#[test]
fn dof_accurate_rmse_within_0_05_px_real_disparity() {
    let (img, _) = blind_augment::io::load_rgb(&asset("motorcycle_left_333x497.png")).expect("asset");
    let disparity =
        blind_augment::io::load_depth(&asset("motorcycle_disp_333x497_x64.png"), 1.0 / 64.0).expect("asset");
    let truth =
        truth_dof(DepthUnits::RelativeInverse, DofCurve::ThinLens { k: 0.12, focus_depth: 30.0, c0: 0.2 }, [7.0, 61.0]);
    let got = fit_dof(&img, &disparity, DepthUnits::RelativeInverse, &truth);
    let rmse = dof_rmse(&got, &truth);
    println!("real disparity: got {:?} over {:?}, RMSE {rmse:.4} px", got.curve, got.depth_range);
    assert!(rmse <= 0.05, "δ RMSE {rmse} px > 0.05");
    assert!(matches!(got.curve, Some(DofCurve::ThinLens { .. })), "thin lens truth kept as thin lens");
}

const A: [f32; 3] = [2e-5, 1.2e-5, 4e-5];
const B: [f32; 3] = [8e-4, 5e-4, 1.2e-3];

/// Poisson–Gaussian truth (variance affine in Y): the affine-variance form must be
/// chosen where the luma range can tell the forms apart, and synth's std must match within a median 1.5%, at 512² and 451×300.
#[test]
fn noise_accurate_median_relative_error_within_1_5_percent() {
    for name in ["astronaut.png", "chelsea.png"] {
        let clean = photo(name);
        let noisy = add_sensor_noise(&clean, A, B, 5);
        let inp = FitInputs { denoised: Some(&clean), ..FitInputs::new(&noisy) };
        let noise = fit(&inp, &only(true, false, false)).expect("valid").model.noise;
        assert!(noise.present);
        let errs = noise_errors(&noise, |c, y| ((A[c] + B[c] * y) as f64).sqrt());
        let med = median(errs.iter().map(|e| e.abs()).collect());
        let max = errs.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        println!("{name}: {:?} over {:?}, median |rel err| {med:.4}, max {max:.4}", noise.form, noise.luminance_range);
        // Over a wide luma range the Poisson–Gaussian truth must be recognised; over a
        // narrow one (chelsea: mostly mid-tones) both forms fit equally well.
        if noise.luminance_range[1] - noise.luminance_range[0] > 0.6 {
            assert_eq!(noise.form, NoiseForm::AffineVariance, "{name}");
        }
        assert!(med <= 0.015, "{name}: median relative error {med} > 1.5%");
    }
}

/// The paper's own form as truth (std linear in Y): the linear-std form is chosen.
#[test]
fn noise_accurate_picks_linear_std_when_std_is_linear() {
    let clean = photo("astronaut.png");
    let (s0, s1) = ([0.004f32, 0.003, 0.006], [0.03f32, 0.02, 0.035]);
    let y = clean.luma();
    let mut noisy = clean.clone();
    for c in 0..3 {
        for i in 0..clean.len() {
            let s = s0[c] + s1[c] * y.data[i];
            noisy.channels[c][i] += s * synth::gaussian((i % 512) as u32, (i / 512) as u32, c as u32 + 20, 8);
        }
    }
    let inp = FitInputs { denoised: Some(&clean), ..FitInputs::new(&noisy) };
    let noise = fit(&inp, &only(true, false, false)).expect("valid").model.noise;
    assert_eq!(noise.form, NoiseForm::LinearStd);
    let errs = noise_errors(&noise, |c, y| (s0[c] + s1[c] * y) as f64);
    let med = median(errs.iter().map(|e| e.abs()).collect());
    println!("linear-std truth: median |rel err| {med:.4} over {:?}", noise.luminance_range);
    assert!(med <= 0.015, "median relative error {med}");
}

/// The low-pass residual, decided by measurement: fitted like a band, it carries
/// c_4² of white noise's variance (≈0.1%); dropping it must change synth's std
/// by less than 0.5% anywhere, which is what "costs nothing" means here.
#[test]
fn noise_lowpass_residual_is_measured() {
    let clean = photo("astronaut.png");
    let noisy = add_sensor_noise(&clean, A, B, 6);
    let inp = FitInputs { denoised: Some(&clean), ..FitInputs::new(&noisy) };
    let noise = fit(&inp, &only(true, false, false)).expect("valid").model.noise;
    let unit = synth::unit_band_std();
    let share = unit[NOISE_LEVELS].powi(2) / unit.iter().map(|u| u * u).sum::<f32>();
    println!("low-pass share of white-noise variance: {:.5}; fitted: {:?}", share, noise.lowpass);
    let mut without = noise.clone();
    without.lowpass = None;
    for y in [0.2f32, 0.5, 0.8] {
        let (a, b) = (synth_flat_std(&noise, y), synth_flat_std(&without, y));
        for c in 0..3 {
            let d = (a[c] / b[c] - 1.0).abs();
            assert!(d < 0.005, "dropping the low-pass changes std by {d} at Y={y}");
        }
    }
}

fn asset(name: &str) -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("assets").join(name)
}
