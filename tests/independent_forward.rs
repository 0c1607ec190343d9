//! The accurate tier on frames made by a second, independent forward model
//! (`common::independent`: Gaussian layers, bicubic MB, Poisson noise after the MB),
//! not by the project's own `synth`. Errors are measured over every
//! pixel of the frame with valid depth — where virtual content may be placed — not
//! only over the depths the fit found texture at.

#![allow(clippy::needless_range_loop)]

mod common;

use blind_augment::fit::{fit, Effects, FitInputs, FitOptions};
use blind_augment::image::{Plane, Rgb};
use blind_augment::model::*;
use common::independent::{cubic_motion_blur, layered_defocus, sigma_map, Sensor};
use common::*;

fn only(noise: bool, mb: bool, dof: bool) -> FitOptions {
    FitOptions { effects: Effects { noise, motion_blur: mb, depth_of_field: dof }, ..Default::default() }
}

/// Layer spacing of the independent defocus: the paper's 100 steps over [0, 10] px.
const LAYER_STEP_PX: f32 = 0.1;

struct DofScene {
    name: &'static str,
    image: Rgb,
    depth: Plane,
    truth: DofCurve,
}

/// Replace rows [0, rows) of `img` by a smooth vertical ramp between two colours:
/// a textureless region (a wall, the sky), whose blur no fit can measure.
fn flatten_rows(img: &mut Rgb, rows: std::ops::Range<usize>, top: [f32; 3], bottom: [f32; 3]) {
    let n = rows.len().max(1) as f32;
    let y0 = rows.start;
    for y in rows {
        let t = (y - y0) as f32 / n;
        for x in 0..img.width {
            for c in 0..3 {
                img.channels[c][y * img.width + x] = top[c] + (bottom[c] - top[c]) * t;
            }
        }
    }
}

/// Depth rows: `near` rows ramp from `z_near` to `z_mid`, the rest is `depth_ramp`
/// from `z_mid` to `z_far` (rows only: the textureless band is one depth span).
fn scenes() -> Vec<DofScene> {
    let astro = photo("astronaut.png");
    let (w, h) = (astro.width, astro.height);
    let mut out = vec![];
    let ramp = depth_ramp(w, h, 0.5, 4.0);
    out.push(DofScene {
        name: "textured 0.5–4 m, thin lens",
        image: astro.clone(),
        depth: ramp.clone(),
        truth: DofCurve::ThinLens { k: 3.0, focus_depth: 1.2, c0: 0.3 },
    });
    out.push(DofScene {
        name: "textured 0.5–4 m, quadratic",
        image: astro.clone(),
        depth: ramp.clone(),
        truth: DofCurve::Quadratic { a: 0.3, b: -1.0, c: 1.5 },
    });
    // The failure case to cover: 14% of the frame nearer than every textured sample.
    let band = h * 14 / 100;
    let mut img = astro.clone();
    flatten_rows(&mut img, 0..band, [0.62, 0.60, 0.58], [0.60, 0.58, 0.57]);
    let mut depth = Plane::new(w, h, 0.0);
    for y in 0..h {
        for x in 0..w {
            let v = (y as f32 + 0.5) / h as f32;
            depth.data[y * w + x] = if y < band {
                0.2 + 0.3 * (y as f32 + 0.5) / band as f32
            } else {
                0.5 + 3.5 * ((v - 0.14) / 0.86 + 0.05 * (6.0 * x as f32 / w as f32).sin()).clamp(0.0, 1.0)
            };
        }
    }
    out.push(DofScene {
        name: "14% textureless nearer (0.2–0.5 m), thin lens",
        image: img.clone(),
        depth: depth.clone(),
        truth: DofCurve::ThinLens { k: 1.5, focus_depth: 2.0, c0: 0.2 },
    });
    out.push(DofScene {
        name: "14% textureless nearer (0.2–0.5 m), quadratic",
        image: img,
        depth,
        truth: DofCurve::Quadratic { a: 0.25, b: -1.8, c: 3.6 },
    });
    // A textureless far band (sky) beyond the textured depths.
    let mut img = astro.clone();
    let sky = h - h * 20 / 100;
    flatten_rows(&mut img, sky..h, [0.55, 0.66, 0.80], [0.58, 0.68, 0.82]);
    let mut depth = Plane::new(w, h, 0.0);
    for y in 0..h {
        for x in 0..w {
            let v = (y as f32 + 0.5) / h as f32;
            depth.data[y * w + x] = if y >= sky {
                4.0 + 8.0 * (y - sky) as f32 / (h - sky) as f32
            } else {
                0.5 + 3.5 * (v / 0.8 + 0.05 * (6.0 * x as f32 / w as f32).sin()).clamp(0.0, 1.0)
            };
        }
    }
    out.push(DofScene {
        name: "20% textureless farther (4–12 m), thin lens",
        image: img,
        depth,
        truth: DofCurve::ThinLens { k: 2.0, focus_depth: 1.0, c0: 0.0 },
    });
    out
}

/// RMSE of the fitted δ against the truth over every valid-depth pixel of the frame.
fn frame_rmse(fitted: &DepthOfField, truth: &DofCurve, depth: &Plane) -> f64 {
    let mut sse = 0.0;
    let mut n = 0usize;
    for &z in &depth.data {
        if z.is_finite() && z > 0.0 {
            let e = (fitted.sigma_px(z) - truth.sigma_px(DepthUnits::MetricM, z)) as f64;
            sse += e * e;
            n += 1;
        }
    }
    (sse / n.max(1) as f64).sqrt()
}

/// δ(Z) over the whole frame under Gaussian layers. Measured (BENCHMARKS.md): frame
/// RMSE 0.029 / 0.048 px on the fully textured scenes, 0.19 / 0.066 px with 14% of
/// the frame textureless and nearer than every textured sample (0.68 / 0.12 px with
/// the model clamped to the textured depths), 0.049 px with a textureless far
/// band; median **0.049 px**, the target 0.05 (0.067 without the blend map of
/// `constant_blur_reads_its_sigma_under_three_kernels`). Tolerances: the median
/// 0.05 px (the target); 0.06 px per scene where the frame is textured (a
/// sampled Gaussian of std σ still reads +0.01…+0.06 px long, see the test below);
/// 0.25 px where the frame holds depths without texture, whose δ is extrapolated (at
/// most one textured inverse-depth span, see `fit::dof::EXTRAPOLATION_FRACTION`).
#[test]
fn dof_on_independent_gaussian_layers() {
    let mut rmses = vec![];
    for scene in scenes() {
        let sig = sigma_map(&scene.depth, |z| scene.truth.sigma_px(DepthUnits::MetricM, z));
        let blurred = quantize8(&layered_defocus(&scene.image, &sig, LAYER_STEP_PX));
        let inp = FitInputs {
            defocus_deblurred: Some(&scene.image),
            depth: Some(&scene.depth),
            depth_units: DepthUnits::MetricM,
            ..FitInputs::new(&blurred)
        };
        let got = fit(&inp, &only(false, false, true)).expect("valid inputs").model.depth_of_field;
        let rmse = frame_rmse(&got, &scene.truth, &scene.depth);
        println!(
            "{}: got {:?} over {:?} (max truth σ {:.2} px) → frame RMSE {rmse:.4} px (± {:.4} px reported)",
            scene.name,
            got.curve,
            got.depth_range,
            sig.iter().cloned().fold(0.0f32, f32::max),
            got.diagnostics.stderr.unwrap_or(f64::NAN)
        );
        {
            let [lo, hi] = got.depth_range;
            let rms = ((0..=64).map(|i| (got.sigma_px(lo + (hi - lo) * i as f32 / 64.0) as f64).powi(2)).sum::<f64>()
                / 65.0)
                .sqrt();
            println!("   δ RMS over the range {rms:.3}; {}", got.diagnostics.reason);
        }
        assert!(got.present, "{}", scene.name);
        let textureless = scene.name.contains("textureless");
        let tol = if textureless { 0.25 } else { 0.06 };
        assert!(rmse <= tol, "{}: frame RMSE {rmse} px > {tol}", scene.name);
        if scene.name.contains("nearer") {
            // The model covers the frame's near depths (0.2–0.5 m), not only the
            // textured ones from 0.5 m.
            assert!(got.depth_range[0] < 0.3, "{}: range {:?}", scene.name, got.depth_range);
        }
        rmses.push(rmse);
    }
    let med = median(rmses.clone());
    println!("median frame RMSE {med:.4} px, worst {:.4}", rmses.iter().cloned().fold(0.0, f64::max));
    assert!(med <= 0.05, "median frame RMSE {med} px");
}

/// One depth, one σ, three forward models: the exact discrete Gaussian of variance
/// σ² (what δ means in this project), `synth`'s variance-matched blend of its
/// 0.25 px nodes (what the renderer draws) and the independent Gaussian layers
/// (sampled Gaussians). The per-pixel search blends stack nodes 0.5 px apart, and a
/// blend of two Gaussians carries more high frequency than the Gaussian of its
/// variance: read through the variance-linear map it overstated σ between nodes by
/// up to +0.041 / +0.050 px (astronaut / chelsea at σ 0.7; 0 on the nodes). With the
/// map corrected for the frame's own spectrum (`fit::dof` `BlendMap`) the exact
/// Gaussian reads within ±0.005 px at every σ measured (tolerance 0.01: twice
/// that), `synth`'s blends within −0.013 px (they carry the same excess at their
/// 0.25 px spacing; tolerance 0.02). The sampled Gaussians read +0.011…+0.058 px
/// long: a sampled Gaussian of std σ has the variance σ² (σ ≥ 0.7) but not the
/// discrete Gaussian's fourth cumulant, so the best-matching discrete Gaussian is
/// wider — a kernel-family difference, stated, not asserted beyond 0.08 px.
#[test]
fn constant_blur_reads_its_sigma_under_three_kernels() {
    use blind_augment::image::{blur_separable, discrete_gaussian_kernel};
    for name in ["astronaut.png", "chelsea.png"] {
        let img = photo(name);
        let (w, h) = (img.width, img.height);
        let depth = Plane::from_vec(w, h, vec![1.0; w * h]);
        let mut line = format!("{name} (exact / synth / layers, px):");
        for &s in &[0.5f32, 0.7, 1.0, 1.3, 1.7, 2.5, 4.0] {
            let k = discrete_gaussian_kernel(s * s);
            let mut exact = img.clone();
            for c in 0..3 {
                exact.channels[c] = blur_separable(&img.plane(c), &k).data;
            }
            let frames = [
                quantize8(&exact),
                quantize8(&blind_augment::synth::add_defocus(&img, &Plane::from_vec(w, h, vec![s; w * h]))),
                quantize8(&layered_defocus(&img, &vec![s; w * h], LAYER_STEP_PX)),
            ];
            let mut err = [0.0f32; 3];
            for (e, f) in err.iter_mut().zip(&frames) {
                let inp = FitInputs {
                    defocus_deblurred: Some(&img),
                    depth: Some(&depth),
                    depth_units: DepthUnits::MetricM,
                    ..FitInputs::new(f)
                };
                let dof = fit(&inp, &only(false, false, true)).expect("valid inputs").model.depth_of_field;
                assert!(dof.present, "{name} σ {s}");
                *e = dof.sigma_px(1.0) - s;
            }
            line += &format!(" {s}: {:+.3}/{:+.3}/{:+.3}", err[0], err[1], err[2]);
            assert!(err[0].abs() <= 0.01, "{name} σ {s}: exact Gaussian read {:+.4} px off", err[0]);
            assert!(err[1].abs() <= 0.02, "{name} σ {s}: synth's blend read {:+.4} px off", err[1]);
            assert!(err[2].abs() <= 0.08, "{name} σ {s}: sampled Gaussian read {:+.4} px off", err[2]);
        }
        println!("{line}");
    }
}

/// λ under interpolation-free (bicubic, midpoint) streaks. Measured: 0.1/0.3/0.5/
/// 0.7/0.9 → 0.034/0.234/0.456/0.666/0.874 at ~7 px/frame. The accurate fit, like
/// synth and the GPU pass it is twinned with, reads the sharp frame bilinearly, and
/// a bilinear read between pixels blurs by a tent of variance t(1 − t) (1/6 px² on
/// average) along the streak; a band-limited streak of the same λ lacks it, so the
/// fit shortens the streak by about that variance (L² / 12 → L² / 12 − 1/6). Not the
/// accurate tier's 0.01 target: a convention difference, not a fit error — rendering the fitted
/// λ with the renderer's bilinear taps reproduces the camera's streak. Tolerance
/// 0.08 (the measured −0.066 worst case plus margin); a sign test pins the direction.
#[test]
fn exposure_on_independent_bicubic_blur() {
    let img = photo("astronaut.png");
    let flow = flow_field(img.width, img.height, 8.0);
    for lambda in [0.1f32, 0.3, 0.5, 0.7, 0.9] {
        let blurred = quantize8(&cubic_motion_blur(&img, &flow, lambda));
        let inp = FitInputs { motion_deblurred: Some(&img), flow: Some(&flow), ..FitInputs::new(&blurred) };
        let mb = fit(&inp, &only(false, true, false)).expect("valid").model.motion_blur;
        let got = mb.exposure.expect("identifiable");
        println!("λ {lambda} → {got:.4} ({:?})", mb.diagnostics.status);
        assert!(mb.present, "λ {lambda}");
        assert!((got - lambda).abs() <= 0.08, "λ {lambda}: got {got}");
        assert!(got < lambda, "λ {lambda}: the bilinear convention reads band-limited streaks short, got {got}");
    }
}

const SENSOR: Sensor = Sensor { full_well_e: 1500.0, wb_gain: [1.9, 1.0, 1.6], read_std: [0.004, 0.003, 0.005] };

/// 8-bit quantisation of a noisy signal adds Δ²/12 to its variance: the camera's
/// output carries it, so the truth does too.
fn truth_std(c: usize, v: f32) -> f64 {
    (SENSOR.std_at(c, v as f64).powi(2) + (1.0f64 / 255.0).powi(2) / 12.0).sqrt()
}

/// The same sensor's noise driven by the frame's luma instead of each photosite's
/// signal (what the paper's model assumes), drawn with the independent generator.
fn luma_driven_noise(clean: &Rgb, seed: u64) -> Rgb {
    let y = clean.luma();
    let mut rng = common::independent::SplitMix(seed);
    let mut out = clean.clone();
    for c in 0..3 {
        for i in 0..out.len() {
            let v = clean.channels[c][i] as f64 + rng.normal() * SENSOR.std_at(c, y.data[i] as f64);
            out.channels[c][i] = ((v.clamp(0.0, 1.0) * 255.0).round() / 255.0) as f32;
        }
    }
    out
}

/// The test double itself: on flat greys its std is the stated one (256² pixels per
/// cell: the std's standard error is 0.3%, so 1.5% is 5 standard errors).
#[test]
fn independent_sensor_has_its_stated_std() {
    for v in [0.05f32, 0.2, 0.5, 0.8] {
        let out = SENSOR.expose(&Rgb::new(256, 256, [v; 3]), 3);
        for c in 0..3 {
            let x = &out.channels[c];
            let m = x.iter().map(|&a| a as f64).sum::<f64>() / x.len() as f64;
            let s = (x.iter().map(|&a| (a as f64 - m).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
            assert!((m - v as f64).abs() < 1e-3, "mean {m} at {v}");
            assert!((s / truth_std(c, v) - 1.0).abs() < 0.015, "std {s} at {v}, channel {c}");
        }
    }
}

/// Photosite noise after the bicubic MB (the clean reference is the blurred frame):
/// each channel's noise follows its own value, which the fit must recognise; synth's
/// std on flat greys within the target median 1.5% (measured: 0.73% astronaut,
/// 0.26% chelsea; a luma-driven fit was 11.9% / 9.2% off). Luma-driven noise from the
/// same generator must keep the paper's luma intensity (measured 0.33% / 0.57%).
#[test]
fn noise_after_independent_motion_blur() {
    for name in ["astronaut.png", "chelsea.png"] {
        let sharp = photo(name);
        let flow = flow_field(sharp.width, sharp.height, 8.0);
        let clean = cubic_motion_blur(&sharp, &flow, 0.5);
        for (driver, noisy, want) in [
            ("photosite", SENSOR.expose(&clean, 17), NoiseIntensity::Channel),
            ("luma", luma_driven_noise(&clean, 5), NoiseIntensity::Luma),
        ] {
            let inp = FitInputs { denoised: Some(&clean), ..FitInputs::new(&noisy) };
            let noise = fit(&inp, &only(true, false, false)).expect("valid").model.noise;
            // On a grey every channel's value is its luma.
            let errs = noise_errors(&noise, truth_std);
            let med = median(errs.iter().map(|e| e.abs()).collect());
            println!(
                "{name}, {driver}-driven: {:?}, {:?} over {:?}: median |rel err| {med:.4}",
                noise.intensity, noise.form, noise.luminance_range
            );
            assert_eq!(noise.intensity, want, "{name}, {driver}-driven noise");
            assert!(med <= 0.015, "{name}, {driver}-driven: median relative error {med} > 1.5%");
        }
    }
}
