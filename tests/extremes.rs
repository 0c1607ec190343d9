//! Numerical stability at the extremes and bad input: every fit returns a finite,
//! valid model or a clear error naming the input; nothing panics.

// Per-channel loops index several parallel arrays; see src/lib.rs.
#![allow(clippy::needless_range_loop)]

mod common;

use blind_augment::fit::{fit, Effects, FitError, FitInputs, FitOptions, Tier};
use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::model::*;
use blind_augment::synth::{self, add_motion_blur, noise_field};
use common::*;
use proptest::prelude::*;

fn all_refs<'a>(image: &'a Rgb, clean: &'a Rgb, depth: &'a Plane, flow: &'a Flow) -> FitInputs<'a> {
    FitInputs {
        denoised: Some(clean),
        motion_deblurred: Some(clean),
        defocus_deblurred: Some(clean),
        depth: Some(depth),
        depth_units: DepthUnits::MetricM,
        flow: Some(flow),
        ..FitInputs::new(image)
    }
}

#[test]
fn exposure_at_zero_and_one() {
    let img = photo("astronaut.png");
    let flow = flow_field(512, 512, 6.0);
    for (lambda, present) in [(0.0f32, false), (1.0, true)] {
        let blurred = quantize8(&add_motion_blur(&img, &flow, lambda));
        let inp = FitInputs { motion_deblurred: Some(&img), flow: Some(&flow), ..FitInputs::new(&blurred) };
        let opts = FitOptions {
            effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
            ..Default::default()
        };
        let mb = fit(&inp, &opts).expect("valid").model.motion_blur;
        let got = mb.exposure.expect("identifiable");
        // 0.005: the boundary cases must land on the boundary, not near it.
        assert!((got - lambda).abs() <= 0.005, "λ {lambda}: {got}");
        assert_eq!(mb.present, present);
        assert_eq!(mb.diagnostics.status, if present { Status::Present } else { Status::Absent });
    }
}

#[test]
fn zero_noise_is_absent_not_invented() {
    let img = photo("chelsea.png");
    let inp = FitInputs { denoised: Some(&img), ..FitInputs::new(&img) };
    let noise = fit(&inp, &FitOptions::default()).expect("valid").model.noise;
    assert!(!noise.present, "{:?}", noise.diagnostics);
    for l in &noise.levels {
        for c in 0..3 {
            assert!(l.std(noise.form, c, 0.5) <= 1e-4);
        }
    }
}

/// Std 0.2 noise (unclipped float frames, as `.npy` carries them): still fitted,
/// median relative error ≤ 3% (local-variance estimates get no worse relatively,
/// but clipping-free luma ranges are what makes this possible).
#[test]
fn strong_noise_std_0_2() {
    let clean = photo("astronaut.png");
    let noisy = add_sensor_noise(&clean, [0.04; 3], [0.0; 3], 4);
    let mut inp = FitInputs { denoised: Some(&clean), ..FitInputs::new(&noisy) };
    inp.denoised = Some(&clean);
    let out = fit(
        &inp,
        &FitOptions {
            effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
            ..Default::default()
        },
    )
    .expect("valid");
    let noise = out.model.noise;
    assert!(noise.present);
    let f = noise_field(&Plane::new(256, 256, 0.5), &noise, 1);
    for c in 0..3 {
        let s = (f.channels[c].iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / f.channels[c].len() as f64).sqrt();
        assert!((s / 0.2 - 1.0).abs() < 0.03, "channel {c}: std {s}");
    }
}

/// Saturated and black regions: clipped pixels are excluded, the luma range stays
/// inside the unclipped data, and the noise in the rest is still right.
#[test]
fn saturated_and_black_regions_are_excluded() {
    let mut clean = photo("astronaut.png");
    for c in 0..3 {
        for y in 0..512 {
            for x in 0..512 {
                if x < 128 {
                    clean.channels[c][y * 512 + x] = 1.0;
                } else if x >= 384 {
                    clean.channels[c][y * 512 + x] = 0.0;
                }
            }
        }
    }
    let (a, b) = ([1e-4f32; 3], [0.0f32; 3]);
    // Clip like a sensor (and an 8-bit file) would.
    let noisy = quantize8(&add_sensor_noise(&clean, a, b, 2));
    let inp = FitInputs { denoised: Some(&clean), ..FitInputs::new(&noisy) };
    let noise = fit(
        &inp,
        &FitOptions {
            effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
            ..Default::default()
        },
    )
    .expect("valid")
    .model
    .noise;
    assert!(noise.present, "{:?}", noise.diagnostics);
    assert!(noise.luminance_range[1] < 0.99 && noise.luminance_range[0] > 0.0, "{:?}", noise.luminance_range);
    let f = noise_field(&Plane::new(256, 256, 0.5), &noise, 1);
    let s = (f.channels[1].iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / f.channels[1].len() as f64).sqrt();
    // 8-bit quantisation adds (1/255)²/12 of variance: truth √(1e-4 + 1.28e-6).
    let truth = (1e-4f64 + 1.0 / (255.0f64 * 255.0 * 12.0)).sqrt();
    assert!((s / truth - 1.0).abs() < 0.03, "std {s} vs {truth}");
}

/// Flat, textureless frames: blur is not identifiable (never guessed); noise on a
/// single luma is a constant.
#[test]
fn flat_textureless_frame() {
    let clean = Rgb::new(200, 150, [0.4, 0.5, 0.6]);
    let noisy = add_sensor_noise(&clean, [4e-4; 3], [0.0; 3], 1);
    let depth = depth_ramp(200, 150, 1.0, 3.0);
    let flow = Flow::uniform(200, 150, 5.0, 1.0);
    let out = fit(&all_refs(&noisy, &clean, &depth, &flow), &FitOptions::default()).expect("valid").model;
    assert_eq!(out.motion_blur.diagnostics.status, Status::NotIdentifiable);
    assert_eq!(out.motion_blur.exposure, None);
    assert_eq!(out.depth_of_field.diagnostics.status, Status::NotIdentifiable);
    assert!(out.depth_of_field.curve.is_none());
    assert!(out.noise.present);
    // Fast tier on the same frame: also no invented blur.
    let fast = fit(
        &FitInputs { depth: Some(&depth), flow: Some(&flow), ..FitInputs::new(&noisy) },
        &FitOptions { tier: Some(Tier::Fast), ..Default::default() },
    )
    .expect("valid")
    .model;
    assert!(!fast.motion_blur.present && !fast.depth_of_field.present);
}

#[test]
fn tiny_and_odd_sizes() {
    for (w, h) in [(1usize, 1usize), (3, 3), (1, 7), (17, 5), (33, 31)] {
        let clean = Rgb::new(w, h, [0.3, 0.5, 0.7]);
        let img = add_sensor_noise(&clean, [1e-4; 3], [0.0; 3], 3);
        let depth = depth_ramp(w, h, 1.0, 2.0);
        let flow = Flow::uniform(w, h, 2.0, 0.0);
        for tier in [Tier::Fast, Tier::Accurate] {
            let out =
                fit(&all_refs(&img, &clean, &depth, &flow), &FitOptions { tier: Some(tier), ..Default::default() })
                    .unwrap_or_else(|e| panic!("{w}×{h} {tier:?}: {e}"));
            out.model.validate().expect("valid model");
            // The model must also apply to a frame of the same size.
            let synthesized = synth::apply_camera_model(&clean, &out.model, Some(&depth), Some(&flow), 0);
            assert!(synthesized.first_non_finite().is_none());
        }
    }
}

#[test]
fn non_finite_pixels_are_named() {
    let clean = Rgb::new(16, 16, [0.5; 3]);
    let mut bad = clean.clone();
    bad.channels[2][5 * 16 + 3] = f32::NAN;
    let err = fit(&FitInputs { denoised: Some(&bad), ..FitInputs::new(&clean) }, &FitOptions::default()).unwrap_err();
    assert!(matches!(err, FitError::NonFinite { input: "denoised", x: 3, y: 5, channel: 2, .. }), "{err}");
    assert!(err.to_string().contains("denoised") && err.to_string().contains("x=3, y=5"));
    bad.channels[2][5 * 16 + 3] = f32::INFINITY;
    let err = fit(&FitInputs::new(&bad), &FitOptions::default()).unwrap_err();
    assert!(matches!(err, FitError::NonFinite { input: "image", .. }));
}

/// Where a blind exposure or defocus fit reads the frame's luma, the input check
/// reads the frame's finiteness from that luma: a non-finite value in any channel
/// (NaN, ±∞, +∞ and −∞ in two channels of one pixel) is still named at its pixel
/// and channel, and a frame of finite values whose luma overflows (near f32::MAX)
/// is not rejected.
#[test]
fn non_finite_pixels_are_named_through_the_shared_luma() {
    let (w, h) = (40, 30);
    let clean = Rgb::new(w, h, [0.5; 3]);
    let depth = depth_ramp(w, h, 1.0, 2.0);
    let flow = Flow::uniform(w, h, 4.0, 0.0);
    let blind = |img: &Rgb| {
        let inp = FitInputs { depth: Some(&depth), flow: Some(&flow), ..FitInputs::new(img) };
        fit(&inp, &FitOptions { tier: Some(Tier::Fast), ..Default::default() })
    };
    for (bad, at) in [(vec![(1, f32::NAN)], 1), (vec![(2, f32::INFINITY)], 2), (vec![(0, f32::NEG_INFINITY)], 0)]
        .into_iter()
        .chain([(vec![(1, f32::INFINITY), (2, f32::NEG_INFINITY)], 1)])
    {
        let mut img = clean.clone();
        for &(c, v) in &bad {
            img.channels[c][7 * w + 11] = v;
        }
        let err = blind(&img).expect_err("a non-finite frame is an error");
        assert!(
            matches!(err, FitError::NonFinite { input: "image", x: 11, y: 7, channel, .. } if channel == at),
            "{err}"
        );
    }
    let mut huge = clean.clone();
    for c in 0..3 {
        huge.channels[c][3 * w + 5] = f32::MAX;
    }
    if let Err(e) = blind(&huge) {
        assert!(!matches!(e, FitError::NonFinite { .. }), "finite values are not rejected: {e}");
    }
}

/// Non-finite flow marks unknown motion, as invalid depth does: both tiers skip
/// those pixels and answer from the rest (NaN, ±∞, in one component or both), and
/// a flow with no finite vector leaves the exposure *not identifiable* — never an
/// error, a NaN or a panic.
#[test]
fn non_finite_flow_is_unknown_motion() {
    let clean = photo("astronaut.png");
    let (w, h) = (clean.width, clean.height);
    let flow = flow_field(w, h, 16.0);
    let img = quantize8(&add_sensor_noise(&add_motion_blur(&clean, &flow, 0.5), [2e-5; 3], [4e-4; 3], 7));
    let exposure_only = |tier| FitOptions {
        tier: Some(tier),
        effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
        ..Default::default()
    };
    let model_of = |f: &Flow, tier| {
        let inp = FitInputs { motion_deblurred: Some(&clean), flow: Some(f), ..FitInputs::new(&img) };
        let m = fit(&inp, &exposure_only(tier))
            .unwrap_or_else(|e| panic!("{tier:?}: unknown motion is not an error: {e}"))
            .model;
        m.validate().unwrap_or_else(|e| panic!("{tier:?}: {e}"));
        m.motion_blur
    };
    for tier in [Tier::Fast, Tier::Accurate] {
        let whole = model_of(&flow, tier);
        // Every 7th pixel (raster order) and a band of a third of the rows unknown,
        // cycling through the kinds of non-finite vector.
        let mut holes = flow.clone();
        let kinds = [(f32::NAN, 1.0), (f32::INFINITY, f32::INFINITY), (2.0, f32::NEG_INFINITY), (f32::NAN, f32::NAN)];
        for (k, i) in (0..w * h).filter(|&i| i % 7 == 0 || (h / 3..2 * h / 3).contains(&(i / w))).enumerate() {
            (holes.dx[i], holes.dy[i]) = kinds[k % kinds.len()];
        }
        let mb = model_of(&holes, tier);
        // Tolerance: the truth (λ 0.5) within two of the fit's stated standard
        // errors, as with the whole flow (fast 0.467 ± 0.036, accurate 0.499 ±
        // 0.002 when written) — from fewer samples: the holes were skipped.
        for (m, what) in [(&whole, "whole flow"), (&mb, "with holes")] {
            let (got, se) = (m.exposure.expect("identified"), m.diagnostics.stderr.expect("stated"));
            assert!((got as f64 - 0.5).abs() <= 2.0 * se, "{tier:?} {what}: λ {got} ± {se} for 0.5");
        }
        assert!(mb.diagnostics.samples_used < whole.diagnostics.samples_used, "{tier:?}");
        // No finite vector at all: nothing to measure the exposure on.
        let mb = model_of(&Flow::uniform(w, h, f32::NAN, f32::NAN), tier);
        assert_eq!(mb.diagnostics.status, Status::NotIdentifiable, "{tier:?}: {}", mb.diagnostics.reason);
        assert!(mb.exposure.is_none() && !mb.present, "{tier:?}");
    }
}

#[test]
fn mismatched_sizes_and_missing_references_are_named() {
    let a = Rgb::new(16, 16, [0.5; 3]);
    let b = Rgb::new(16, 15, [0.5; 3]);
    let err = fit(&FitInputs { motion_deblurred: Some(&b), ..FitInputs::new(&a) }, &FitOptions::default()).unwrap_err();
    assert_eq!(err, FitError::SizeMismatch { input: "motion-deblurred", want_w: 16, want_h: 16, got_w: 16, got_h: 15 });
    let depth = Plane::new(15, 16, 1.0);
    let err = fit(&FitInputs { depth: Some(&depth), ..FitInputs::new(&a) }, &FitOptions::default()).unwrap_err();
    assert!(matches!(err, FitError::SizeMismatch { input: "depth", .. }));
    let err = fit(&FitInputs::new(&a), &FitOptions { tier: Some(Tier::Accurate), ..Default::default() }).unwrap_err();
    assert!(matches!(err, FitError::MissingReference { input: "denoised", .. }), "{err}");
    let empty = Rgb::new(0, 0, [0.0; 3]);
    assert!(matches!(fit(&FitInputs::new(&empty), &FitOptions::default()), Err(FitError::Empty { .. })));
}

/// A speed/accuracy setting out of its range is refused by name, never clamped in
/// silence: the blind noise grid below 16 bins × 24 samples per level, and at that
/// minimum the fit still returns a valid model (present or not, never a panic); the
/// fast tier's effort outside [0.25, 1], and at both ends a valid model.
#[test]
fn out_of_range_settings_are_named() {
    let img = quantize8(&add_sensor_noise(&photo("chelsea.png"), [2e-5; 3], [8e-4; 3], 5));
    let tiny = FitOptions { noise_fast_samples_per_level: 383, ..FitOptions::default() };
    let err = fit(&FitInputs::new(&img), &tiny).unwrap_err();
    assert!(matches!(err, FitError::Option { option: "noise_fast_samples_per_level", .. }), "{err}");
    assert!(err.to_string().contains("≥ 384") && err.to_string().contains("383"), "{err}");
    let least = FitOptions { noise_fast_samples_per_level: 384, ..FitOptions::default() };
    let model = fit(&FitInputs::new(&img), &least).expect("the least budget is valid").model;
    assert!(model.validate().is_ok(), "{:?}", model.validate());
    let err = fit(&FitInputs::new(&img), &FitOptions { mb_max_samples: 63, ..FitOptions::default() }).unwrap_err();
    assert!(matches!(err, FitError::Option { option: "mb_max_samples", .. }), "{err}");
    // The fast tier's effort: [0.25, 1], NaN and infinities refused by name too.
    for bad in [0.249f32, 1.001, 0.0, -1.0, f32::NAN, f32::INFINITY] {
        let err = fit(&FitInputs::new(&img), &FitOptions { fast_effort: bad, ..FitOptions::default() }).unwrap_err();
        assert!(matches!(err, FitError::Option { option: "fast_effort", .. }), "{bad}: {err}");
        assert!(err.to_string().contains("[0.25, 1]"), "{err}");
    }
    // Both ends are valid, with depth and flow so every scaled count is reached.
    let depth = Plane::new(img.width, img.height, 2.0);
    let flow = Flow::uniform(img.width, img.height, 20.0, 5.0);
    for ok in [blind_augment::fit::MIN_FAST_EFFORT, 1.0] {
        let inp = FitInputs { depth: Some(&depth), flow: Some(&flow), ..FitInputs::new(&img) };
        let model = fit(&inp, &FitOptions { fast_effort: ok, ..FitOptions::default() }).expect("valid effort").model;
        assert!(model.validate().is_ok(), "effort {ok}: {:?}", model.validate());
    }
}

/// Forcing the accurate tier only requires the references of the effects asked for.
#[test]
fn accurate_tier_needs_only_the_requested_references() {
    let img = photo("chelsea.png");
    let flow = Flow::uniform(img.width, img.height, 4.0, 1.0);
    let blurred = quantize8(&add_motion_blur(&img, &flow, 0.5));
    let inp = FitInputs { motion_deblurred: Some(&img), flow: Some(&flow), ..FitInputs::new(&blurred) };
    let opts = FitOptions {
        tier: Some(Tier::Accurate),
        effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
        ..Default::default()
    };
    let mb = fit(&inp, &opts).expect("no other reference needed").model.motion_blur;
    assert!((mb.exposure.expect("identifiable") - 0.5).abs() < 0.01);
}

#[test]
fn depth_with_only_invalid_values_is_not_identifiable() {
    let img = photo("chelsea.png");
    let depth = Plane::new(img.width, img.height, f32::NAN);
    let out = fit(
        &FitInputs { defocus_deblurred: Some(&img), depth: Some(&depth), ..FitInputs::new(&img) },
        &FitOptions::default(),
    )
    .expect("invalid depth pixels are skipped, not fatal");
    assert_eq!(out.model.depth_of_field.diagnostics.status, Status::NotIdentifiable);
}

fn arb_frame() -> impl Strategy<Value = (usize, usize, Vec<f32>, u64, f32, f32, f32)> {
    (1usize..40, 1usize..40).prop_flat_map(|(w, h)| {
        (
            Just(w),
            Just(h),
            // Values outside [0, 1] included: HDR floats and over/undershoot.
            proptest::collection::vec(-0.5f32..1.5, w * h * 3),
            any::<u64>(),
            0.0f32..0.3,
            -20.0f32..20.0,
            0.01f32..100.0,
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    /// Whatever the input, both tiers give a finite model that passes validation
    /// (or a clear error, never a panic).
    #[test]
    fn every_fitted_model_is_finite_and_in_range((w, h, data, seed, noise, flow_px, depth_m) in arb_frame()) {
        let mut clean = Rgb::new(w, h, [0.0; 3]);
        for i in 0..w * h {
            for c in 0..3 {
                clean.channels[c][i] = data[3 * i + c];
            }
        }
        let noisy = add_sensor_noise(&clean, [noise * noise; 3], [0.0; 3], seed);
        let mut depth = depth_ramp(w, h, depth_m, depth_m * 3.0);
        depth.data[0] = f32::NAN;
        let flow = Flow::uniform(w, h, flow_px, -0.5 * flow_px);
        for tier in [Tier::Fast, Tier::Accurate] {
            let out = fit(&all_refs(&noisy, &clean, &depth, &flow), &FitOptions { tier: Some(tier), ..Default::default() });
            let model = out.expect("valid inputs fit without error").model;
            prop_assert!(model.validate().is_ok());
            let json = model.to_json().expect("serialisable");
            prop_assert_eq!(CameraModel::from_json(&json).expect("round trip"), model.clone());
            if let Some(l) = model.motion_blur.exposure {
                prop_assert!((0.0..=1.0).contains(&l));
            }
            for z in [0.0f32, depth_m, 1e6] {
                let s = model.depth_of_field.sigma_px(z);
                prop_assert!(s.is_finite() && (0.0..=MAX_DOF_SIGMA_PX).contains(&s));
            }
        }
    }
}

/// The exposure fits at the extremes (the blind tier's single-frame paths, and the
/// accurate tier on the same flows), on frames large enough
/// to reach all of them (the proptest's ≤ 40 px frames reach none): the streak
/// zeros' 128-px lines, the derivative autocorrelation's crop (from 160 px), the
/// along-flow dip and the zeros' check (streaks of 20–57 px). Frames: constant
/// black, grey and white, clipped white noise of std 0.3, 1-px stripes across and
/// along the flow (Nyquist), one step edge, and a photograph streaked by the flow
/// itself at λ 1 (streaks of 3–60 px). Flows: uniform at speeds just under and
/// over the estimators' 3 px/frame floor, at the check's 57 px bound and past it,
/// 400 px (longer than the crop's lags) and 1e5 px/frame, at 0°, 33° and 90°; the
/// frame's diagonal and just past it; a swirl (no streak length to read). What
/// must hold: no panic, a model that validates, an exposure in [0, 1] or none, a
/// finite standard error wherever an exposure is reported, and "present" only with
/// an exposure; a flow past the frame's diagonal is not identifiable (its streak
/// cannot be in the frame), and says so. (Non-finite flow is refused by `fit` with
/// an error naming it: `non_finite_pixels_are_named`.) Without the profiles' node
/// cap, a 1e5 px/frame flow takes the fit 100 s per 160×160 frame.
#[test]
fn exposure_paths_at_extreme_frames_and_flows() {
    let sizes = [(160usize, 160usize), (512, 384), (700, 130)];
    let photo = photo("astronaut.png");
    for (w, h) in sizes {
        let textured = mirror_tile(&photo, w, h);
        let stripes = |across: bool| {
            let mut img = Rgb::new(w, h, [0.0; 3]);
            for y in 0..h {
                for x in 0..w {
                    let v = if (if across { x } else { y }) % 2 == 0 { 0.9 } else { 0.1 };
                    for c in 0..3 {
                        img.channels[c][y * w + x] = v;
                    }
                }
            }
            img
        };
        let mut edge = Rgb::new(w, h, [0.2; 3]);
        for y in 0..h {
            for x in w / 2..w {
                for c in 0..3 {
                    edge.channels[c][y * w + x] = 0.8;
                }
            }
        }
        let mut noise = Rgb::new(w, h, [0.5; 3]);
        for c in 0..3 {
            for (i, v) in noise.channels[c].iter_mut().enumerate() {
                let e = synth::gaussian((i % w) as u32, (i / w) as u32, c as u32, 11);
                *v = (*v + 0.3 * e).clamp(0.0, 1.0);
            }
        }
        let frames: Vec<(&str, Rgb)> = vec![
            ("black", Rgb::new(w, h, [0.0; 3])),
            ("grey", Rgb::new(w, h, [0.5; 3])),
            ("white", Rgb::new(w, h, [1.0; 3])),
            ("noise", noise),
            ("stripes across x", stripes(true)),
            ("stripes across y", stripes(false)),
            ("edge", edge),
        ];
        let mut flows: Vec<(String, Flow)> = vec![];
        for speed in [2.99f32, 3.01, 21.0, 57.0, 58.0, 400.0, 1e5] {
            for deg in [0.0f32, 33.0, 90.0] {
                let (dx, dy) = (speed * deg.to_radians().cos(), speed * deg.to_radians().sin());
                flows.push((format!("{speed} px at {deg}°"), Flow::uniform(w, h, dx, dy)));
            }
        }
        // A flow of the frame's diagonal and one just past it (not sampled).
        let diagonal = ((w * w + h * h) as f32).sqrt();
        for k in [1.0f32, 1.01] {
            flows.push((format!("{k} × the diagonal"), Flow::uniform(w, h, 0.6 * k * diagonal, 0.8 * k * diagonal)));
        }
        let mut swirl = Flow::uniform(w, h, 0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let (rx, ry) = (x as f32 - w as f32 / 2.0, y as f32 - h as f32 / 2.0);
                swirl.dx[y * w + x] = -0.2 * ry;
                swirl.dy[y * w + x] = 0.2 * rx;
            }
        }
        flows.push(("swirl".into(), swirl));
        for (flow_name, flow) in &flows {
            // The photograph streaked by this flow where synth's streak is short
            // enough to make (a 1e5 px streak is not a frame anyone sees).
            let speed = (flow.dx[w * h - 1].powi(2) + flow.dy[w * h - 1].powi(2)).sqrt();
            let streaked = (speed <= 60.0).then(|| add_motion_blur(&textured, flow, 1.0));
            let cases = frames.iter().map(|(n, f)| (*n, f)).chain(streaked.as_ref().map(|s| ("streaked photo", s)));
            // The accurate tier on the same flows (the frame its own sharp
            // reference): bounded by the same cap, refusing the same flows.
            let accurate = fit(
                &FitInputs { flow: Some(flow), motion_deblurred: Some(&textured), ..FitInputs::new(&textured) },
                &FitOptions {
                    tier: Some(Tier::Accurate),
                    effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
                    ..Default::default()
                },
            )
            .unwrap_or_else(|e| panic!("{w}×{h}, accurate, flow {flow_name}: {e}"));
            accurate.model.validate().unwrap_or_else(|e| panic!("{w}×{h}, accurate, flow {flow_name}: {e}"));
            if flow.dx[0].hypot(flow.dy[0]) > 1.001 * ((w * w + h * h) as f32).sqrt() {
                let d = &accurate.model.motion_blur.diagnostics;
                assert_eq!(d.status, Status::NotIdentifiable, "{w}×{h}, accurate, flow {flow_name}");
                assert!(d.reason.contains("diagonal"), "{w}×{h}, accurate, flow {flow_name}: {}", d.reason);
            }
            for (frame_name, frame) in cases {
                for evidence in [false, true] {
                    let opts = FitOptions {
                        tier: Some(Tier::Fast),
                        effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
                        mb_isotropy_evidence: evidence,
                        ..Default::default()
                    };
                    let what = format!("{w}×{h}, {frame_name}, flow {flow_name}, evidence {evidence}");
                    let out = fit(&FitInputs { flow: Some(flow), ..FitInputs::new(frame) }, &opts)
                        .unwrap_or_else(|e| panic!("{what}: {e}"));
                    let mb = &out.model.motion_blur;
                    out.model.validate().unwrap_or_else(|e| panic!("{what}: invalid model: {e}"));
                    if let Some(l) = mb.exposure {
                        assert!((0.0..=1.0).contains(&l), "{what}: λ {l}");
                        let se = mb.diagnostics.stderr.unwrap_or_else(|| panic!("{what}: λ {l} without an error"));
                        assert!(se.is_finite() && se >= 0.0, "{what}: λ {l} ± {se}");
                    }
                    assert!(!mb.present || mb.exposure.is_some(), "{what}: present without an exposure");
                    if flow.dx[0].hypot(flow.dy[0]) > 1.001 * ((w * w + h * h) as f32).sqrt() {
                        assert_eq!(mb.diagnostics.status, Status::NotIdentifiable, "{what}");
                        assert!(mb.diagnostics.reason.contains("diagonal"), "{what}: {}", mb.diagnostics.reason);
                    }
                }
            }
        }
    }
}

/// The DoF and noise fits at the extremes, on frames large enough for their
/// full-size paths (the spectrum's 128/256-px tiles, the edge scan's subsampling,
/// every noise level and the codec-grid scan): constant, clipped noise of std 0.3,
/// Nyquist stripes, an 8×8 block pattern (a codec grid with nothing else), HDR
/// values to 1e3, one step edge, and a photograph; depths constant, spanning 1e-3
/// to 1e6 m, one valid pixel, relative inverse depth with zeros, and half invalid.
/// Each under sensor noise, fitted by the fast tier and by the accurate tier (the
/// clean frame its references). What must hold: no panic, a model that validates,
/// every δ(Z) finite and within range at the depths given and beyond.
#[test]
fn defocus_and_noise_at_extreme_frames_and_depths() {
    let photo = photo("chelsea.png");
    for (w, h) in [(160usize, 160usize), (512, 384), (700, 130)] {
        let fill = |f: &dyn Fn(usize, usize) -> f32| {
            let mut img = Rgb::new(w, h, [0.0; 3]);
            for y in 0..h {
                for x in 0..w {
                    for c in 0..3 {
                        img.channels[c][y * w + x] = f(x, y) * [1.0, 0.9, 0.8][c];
                    }
                }
            }
            img
        };
        let noise = fill(&|x, y| (0.5 + 0.3 * synth::gaussian(x as u32, y as u32, 0, 5)).clamp(0.0, 1.0));
        let frames: Vec<(&str, Rgb)> = vec![
            ("black", Rgb::new(w, h, [0.0; 3])),
            ("white", Rgb::new(w, h, [1.0; 3])),
            ("noise", noise),
            ("stripes", fill(&|x, _| if x % 2 == 0 { 0.9 } else { 0.1 })),
            ("8×8 blocks", fill(&|x, y| 0.2 + 0.6 * (((x / 8) * 7 + (y / 8) * 13) % 5) as f32 / 4.0)),
            ("HDR to 1e3", fill(&|x, y| if (x / 16 + y / 16) % 2 == 0 { 1e3 } else { 0.01 })),
            ("edge", fill(&|x, _| if x < w / 2 { 0.2 } else { 0.8 })),
            ("photo", mirror_tile(&photo, w, h)),
        ];
        let mut one_valid = Plane::new(w, h, f32::NAN);
        one_valid.data[(h / 2) * w + w / 2] = 2.0;
        let mut half_invalid = depth_ramp(w, h, 0.5, 4.0);
        for v in half_invalid.data.iter_mut().step_by(2) {
            *v = -1.0;
        }
        let mut inverse = depth_ramp(w, h, 0.0, 1.0);
        inverse.data[..w].iter_mut().for_each(|v| *v = 0.0);
        let depths: Vec<(&str, Plane, DepthUnits)> = vec![
            ("constant 2 m", Plane::new(w, h, 2.0), DepthUnits::MetricM),
            ("1e-3 to 1e6 m", depth_ramp(w, h, 1e-3, 1e6), DepthUnits::MetricM),
            ("one valid pixel", one_valid, DepthUnits::MetricM),
            ("half invalid", half_invalid, DepthUnits::MetricM),
            ("relative inverse with zeros", inverse, DepthUnits::RelativeInverse),
        ];
        for (frame_name, frame) in &frames {
            let noisy = add_sensor_noise(frame, [1e-4; 3], [1e-5; 3], 9);
            for ((depth_name, depth, units), tier) in depths.iter().flat_map(|d| [(d, Tier::Fast), (d, Tier::Accurate)])
            {
                let what = format!("{w}×{h}, {frame_name}, depth {depth_name}, {tier:?}");
                let opts = FitOptions {
                    tier: Some(tier),
                    effects: Effects { noise: true, motion_blur: false, depth_of_field: true },
                    ..Default::default()
                };
                // The frame under sensor noise; the accurate tier with the clean frame
                // as its references.
                let inputs = FitInputs {
                    depth: Some(depth),
                    depth_units: *units,
                    denoised: Some(frame),
                    defocus_deblurred: Some(frame),
                    ..FitInputs::new(&noisy)
                };
                let out = fit(&inputs, &opts).unwrap_or_else(|e| panic!("{what}: {e}"));
                out.model.validate().unwrap_or_else(|e| panic!("{what}: invalid model: {e}"));
                let method = if tier == Tier::Fast { "fast" } else { "accurate" };
                assert_eq!(out.model.noise.diagnostics.method, method, "{what}");
                for z in [0.0f32, 1e-3, 0.5, 2.0, 1e6, f32::MAX] {
                    let s = out.model.depth_of_field.sigma_px(z);
                    assert!(s.is_finite() && (0.0..=MAX_DOF_SIGMA_PX).contains(&s), "{what}: δ({z}) = {s}");
                }
            }
        }
    }
}
