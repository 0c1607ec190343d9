//! Properties of the CPU reference effects (the ground truth the GPU passes will be
//! held to) and the image operations under them.

// Per-channel loops index several parallel arrays; see src/lib.rs.
#![allow(clippy::needless_range_loop)]

mod common;

use blind_augment::image::{discrete_gaussian_kernel, laplacian_pyramid, Flow, Plane, Rgb};
use blind_augment::model::*;
use blind_augment::synth::{self, add_defocus, add_defocus_disc, add_dof, add_motion_blur, noise_field};
use common::*;

/// Laplacian collapse is exact for every size (1e-5: f32 rounding over 4 levels).
#[test]
fn laplacian_pyramid_reconstructs_exactly() {
    for (w, h) in [(1, 1), (2, 3), (7, 5), (64, 64), (101, 37)] {
        let data: Vec<f32> = (0..w * h).map(|i| ((i * 7919) % 101) as f32 / 101.0).collect();
        let p = Plane::from_vec(w, h, data.clone());
        let back = laplacian_pyramid(&p, 4).collapse();
        assert_eq!((back.width, back.height), (w, h));
        for (a, b) in back.data.iter().zip(&data) {
            assert!((a - b).abs() < 1e-5, "{w}×{h}: {a} vs {b}");
        }
    }
}

/// σ = 0 everywhere is the identity, bit for bit; λ = 0 likewise.
#[test]
fn effects_are_exact_at_zero() {
    let img = photo("chelsea.png");
    let zero = Plane::new(img.width, img.height, 0.0);
    assert_eq!(add_defocus(&img, &zero), img);
    let flow = flow_field(img.width, img.height, 10.0);
    assert_eq!(add_motion_blur(&img, &flow, 0.0), img);
}

/// A uniform σ on an impulse gives a kernel with variance σ² per axis, for σ on and
/// between stack nodes (variance-matched blend), within 1% (interior impulse, f32).
#[test]
fn defocus_kernel_has_the_requested_variance() {
    let n = 97;
    let mut img = Rgb::new(n, n, [0.0; 3]);
    for c in 0..3 {
        img.channels[c][48 * n + 48] = 1.0;
    }
    for sigma in [0.1f32, 0.25, 0.6, 1.0, 2.37, 5.0, 9.9] {
        let out = add_defocus(&img, &Plane::new(n, n, sigma));
        let ch = &out.channels[1];
        let sum: f64 = ch.iter().map(|&v| v as f64).sum();
        let var_x: f64 = (0..n * n).map(|i| ch[i] as f64 * ((i % n) as f64 - 48.0).powi(2)).sum::<f64>() / sum;
        assert!((sum - 1.0).abs() < 1e-4, "σ {sigma}: mass {sum}");
        assert!((var_x / (sigma as f64).powi(2) - 1.0).abs() < 0.01, "σ {sigma}: variance {var_x}");
    }
    // The discrete Gaussian itself: variance exact (see image::blur tests).
    assert_eq!(discrete_gaussian_kernel(0.0).len(), 1);
}

/// The disc kernel on an impulse: mass 1, per-axis variance σ² (within 3.3% for
/// radii under 4 px, 0.6% above: the lattice effect bounded in model::kernels), a
/// flat top (every pixel well inside the disc has the same weight, unlike any
/// Gaussian) and nothing beyond the radius; below 1 px it is the Gaussian.
#[test]
fn disc_defocus_kernel_is_a_disc_of_the_requested_second_moment() {
    let n = 65;
    let c0 = 32;
    let mut img = Rgb::new(n, n, [0.0; 3]);
    for c in 0..3 {
        img.channels[c][c0 * n + c0] = 1.0;
    }
    for sigma in [1.0f32, 2.75, 4.5, 9.9] {
        let out = add_defocus_disc(&img, &Plane::new(n, n, sigma));
        let ch = &out.channels[0];
        let sum: f64 = ch.iter().map(|&v| v as f64).sum();
        let var_x: f64 = (0..n * n).map(|i| ch[i] as f64 * ((i % n) as f64 - c0 as f64).powi(2)).sum::<f64>() / sum;
        let r = kernels::disc_radius_px(sigma);
        let bound = if r >= 4.0 { 0.006 } else { 0.033 };
        assert!((sum - 1.0).abs() < 1e-4, "σ {sigma}: mass {sum}");
        assert!((var_x / (sigma as f64).powi(2) - 1.0).abs() < bound, "σ {sigma}: variance {var_x}");
        let at = |dx: i32, dy: i32| ch[((c0 as i32 + dy) * n as i32 + c0 as i32 + dx) as usize];
        let inner = (r - 1.0).floor() as i32;
        if inner >= 1 {
            assert!((at(inner, 0) - at(0, 0)).abs() < 1e-6, "σ {sigma}: not flat inside");
        }
        let outer = (r + 1.0).ceil() as i32;
        assert_eq!(at(outer, 0), 0.0, "σ {sigma}: weight beyond the radius");
    }
    // Below DISC_MIN_SIGMA_PX the Gaussian, exactly.
    let s = Plane::new(n, n, 0.6);
    assert_eq!(add_defocus_disc(&img, &s), add_defocus(&img, &s));
}

/// add_dof draws the model's kernel shape: the same δ(Z) gives a disc or a Gaussian.
#[test]
fn add_dof_follows_the_kernel_shape() {
    let img = crop(&photo("chelsea.png"), 0, 0, 96, 80);
    let depth = Plane::new(96, 80, 1.0);
    let mut dof = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::Constant { c: 3.0 }),
        depth_range: [0.5, 2.0],
        kernel: DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("test"),
    };
    let gauss = add_dof(&img, &depth, &dof);
    assert_eq!(gauss, add_defocus(&img, &Plane::new(96, 80, 3.0)));
    dof.kernel = DofKernel::Disc;
    let disc = add_dof(&img, &depth, &dof);
    assert_eq!(disc, add_defocus_disc(&img, &Plane::new(96, 80, 3.0)));
    let diff: f32 = disc.channels[1].iter().zip(&gauss.channels[1]).map(|(a, b)| (a - b).abs()).sum::<f32>()
        / disc.channels[1].len() as f32;
    assert!(diff > 1e-3, "disc and Gaussian agree (mean |Δ| {diff})");
}

/// Motion blur of a vertical edge moving horizontally is a linear ramp of exactly
/// λ·|F| pixels: the 10–90% width of the profile is 0.8·λ|F| (±0.1 px).
#[test]
fn motion_blur_streak_has_the_exposure_length() {
    let (w, h) = (80, 4);
    let mut img = Rgb::new(w, h, [0.0; 3]);
    for c in 0..3 {
        for y in 0..h {
            for x in 40..w {
                img.channels[c][y * w + x] = 1.0;
            }
        }
    }
    // Streaks ≥ 8 px: shorter ones are dominated by the 1 px ramp that bilinear
    // interpolation gives a pixel-sampled edge.
    for (speed, lambda) in [(20.0f32, 0.5f32), (10.0, 1.0), (32.0, 0.25)] {
        let out = add_motion_blur(&img, &Flow::uniform(w, h, speed, 0.0), lambda);
        let row: Vec<f32> = (0..w).map(|x| out.channels[0][w + x]).collect();
        let cross = |t: f32| {
            let i = row.iter().position(|&v| v >= t).expect("edge");
            (i - 1) as f32 + (t - row[i - 1]) / (row[i] - row[i - 1])
        };
        let width = cross(0.9) - cross(0.1);
        let want = 0.8 * lambda * speed;
        assert!((width - want).abs() < 0.1, "speed {speed} λ {lambda}: 10–90% width {width} vs {want}");
    }
}

fn band_stds(p: &Plane) -> Vec<f64> {
    let pyr = laplacian_pyramid(p, 4);
    pyr.bands
        .iter()
        .map(|b| (b.data.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / b.data.len() as f64).sqrt())
        .collect()
}

/// Grain statistics on flat greys, for a noise spectrum far from white: the
/// per-level stds of demosaic-like correlated noise (white noise blurred by a
/// σ = 0.7 px Gaussian) become the model; the synthesised noise, re-analysed, must
/// reproduce them per level — which is what the synthesis calibration is for.
/// Tolerance 4%: at level 3 a 512² field has 64² samples per channel (≈1.1%
/// standard error of a std), so 3.5 standard errors.
#[test]
fn noise_synthesis_matches_the_model_per_level() {
    let n = 512;
    let k = discrete_gaussian_kernel(0.49);
    let truth: Vec<Vec<f64>> = (0..3u32)
        .map(|c| {
            let white = Plane::from_vec(
                n,
                n,
                (0..n * n).map(|i| synth::gaussian((i % n) as u32, (i / n) as u32, c, 21)).collect(),
            );
            let mut b = blind_augment::image::blur_separable(&white, &k);
            b.data.iter_mut().for_each(|v| *v *= 0.02 * (1.0 + c as f32 * 0.3));
            band_stds(&b)
        })
        .collect();
    let level = |l: usize| NoiseLevel { slope: [0.0; 3], intercept: std::array::from_fn(|c| truth[c][l] as f32) };
    let noise = Noise {
        present: true,
        form: NoiseForm::LinearStd,
        intensity: NoiseIntensity::Luma,
        levels: (0..NOISE_LEVELS).map(level).collect(),
        lowpass: None,
        luminance_range: [0.0, 1.0],
        bins: vec![],
        level_sources: vec![],
        blocking: None,
        diagnostics: Diagnostics::not_fitted("test"),
    };
    let field = noise_field(&Plane::new(n, n, 0.4), &noise, 11);
    for c in 0..3 {
        let got = band_stds(&field.plane(c));
        for l in 0..NOISE_LEVELS {
            assert!((got[l] / truth[c][l] - 1.0).abs() < 0.04, "c {c} level {l}: {} vs {}", got[l], truth[c][l]);
        }
    }
}

/// `synth::correlated_sensor_noise`: the synthesised field decays across the levels by
/// the ratios asked for (level 0 as white sensor noise's), on a flat grey at three
/// lumas; and a ratio that is not finite and positive is refused by name. Tolerance
/// 5% on a ratio of two stds: at level 3 a 512² field has 64² samples per channel
/// (≈1.1% standard error of a std, ~1.6% of a ratio), three channels pooled, so
/// about 3 standard errors.
#[test]
fn correlated_sensor_noise_decays_by_its_ratios() {
    let ratios = [0.45f32, 0.72, 0.72];
    let (a, b) = ([3e-5f32, 2e-5, 5e-5], [6e-4f32, 4e-4, 9e-4]);
    let noise = synth::correlated_sensor_noise(a, b, [0.0, 1.0], ratios).expect("valid ratios");
    let white = synth::white_sensor_noise(a, b, [0.0, 1.0]);
    let n = 512;
    for grey in [0.2f32, 0.5, 0.8] {
        let field = noise_field(&Plane::new(n, n, grey), &noise, 5);
        let stds: Vec<Vec<f64>> = (0..3).map(|c| band_stds(&field.plane(c))).collect();
        for l in 0..NOISE_LEVELS - 1 {
            let got = (0..3).map(|c| stds[c][l + 1] / stds[c][l]).sum::<f64>() / 3.0;
            assert!((got / ratios[l] as f64 - 1.0).abs() < 0.05, "grey {grey}, level {} over {l}: {got:.3}", l + 1);
        }
        for c in 0..3 {
            let want = white.levels[0].std(white.form, c, grey) as f64;
            assert!(
                (stds[c][0] / want - 1.0).abs() < 0.03,
                "grey {grey}, channel {c}: level 0 {} vs {want}",
                stds[c][0]
            );
        }
    }
    for bad in [f32::NAN, 0.0, -0.5, f32::INFINITY] {
        let e = synth::correlated_sensor_noise(a, b, [0.0, 1.0], [0.45, bad, 0.72]).expect_err("a bad ratio");
        assert!(e.contains("level ratio 1 (level 2 over level 1)"), "{e}");
    }
}

/// A model round trip: the same seed gives the same frame, another seed another.
#[test]
fn synthesis_is_deterministic_per_seed() {
    let img = photo("chelsea.png");
    let mut model = CameraModel::empty(img.width as u32, img.height as u32);
    model.noise = Noise {
        present: true,
        form: NoiseForm::AffineVariance,
        intensity: NoiseIntensity::Luma,
        levels: vec![NoiseLevel { slope: [1e-4; 3], intercept: [1e-5; 3] }; NOISE_LEVELS],
        lowpass: None,
        luminance_range: [0.0, 1.0],
        bins: vec![],
        level_sources: vec![],
        blocking: None,
        diagnostics: Diagnostics::not_fitted("test"),
    };
    let a = synth::apply_camera_model(&img, &model, None, None, 1);
    let b = synth::apply_camera_model(&img, &model, None, None, 1);
    let c = synth::apply_camera_model(&img, &model, None, None, 2);
    assert_eq!(a, b);
    assert_ne!(a, c);
}

/// A model whose maps read each channel's own value: on a coloured flat patch,
/// channel c's synthesised std is the map at c's value, not at the patch's luma
/// (`noise_field_rgb`); `noise_field` (the GPU grain's twin) reads luma. Tolerance
/// 2%: 256² samples give a 0.3% standard error, the rest is the band table's
/// interpolation between its 33 nodes.
#[test]
fn channel_intensity_noise_reads_each_channels_value() {
    let mut noise = synth::white_sensor_noise([1e-5; 3], [4e-4, 2e-4, 3e-4], [0.0, 1.0]);
    noise.intensity = NoiseIntensity::Channel;
    let colour = [0.8f32, 0.3, 0.1];
    let patch = Rgb::new(256, 256, colour);
    let own = synth::noise_field_rgb(&patch, &noise, 9);
    let at_luma = noise_field(&patch.luma(), &noise, 9);
    let y = patch.luma().data[0];
    let std = |v: &[f32]| (v.iter().map(|x| (*x as f64).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
    let a = [1e-5f64; 3];
    let b = [4e-4f64, 2e-4, 3e-4];
    for c in 0..3 {
        let want_own = (a[c] + b[c] * colour[c] as f64).sqrt();
        let want_luma = (a[c] + b[c] * y as f64).sqrt();
        let (got_own, got_luma) = (std(&own.channels[c]), std(&at_luma.channels[c]));
        println!("channel {c}: own {got_own:.5} (want {want_own:.5}), luma {got_luma:.5} (want {want_luma:.5})");
        assert!((got_own / want_own - 1.0).abs() < 0.02, "channel {c} at its own value");
        assert!((got_luma / want_luma - 1.0).abs() < 0.02, "channel {c} at luma");
    }
}

/// Flow no frame can hold (past the diagonal: Middlebury's 1e9 unknown marker) is
/// no motion, like non-finite flow: the pixel keeps its value, at no cost in taps
/// (a tap every 0.1 px of a 1e9 px streak would be 1e10 per pixel), and the other
/// pixels are blurred as before.
#[test]
fn flow_past_the_diagonal_is_no_motion() {
    let img = photo("chelsea.png").crop(0, 0, 64, 48).expect("crop");
    let mut flow = Flow::uniform(64, 48, 6.0, 2.0);
    let streaked = add_motion_blur(&img, &flow, 1.0);
    let (i, j) = (20 * 64 + 30, 20 * 64 + 31);
    flow.dx[i] = 1e9;
    flow.dy[j] = -80.1; // past the 80 px diagonal of 64×48
    let out = add_motion_blur(&img, &flow, 1.0);
    for c in 0..3 {
        for k in [i, j] {
            assert_eq!(out.channels[c][k], img.channels[c][k], "channel {c}, pixel {k}");
        }
        for k in (0..64 * 48).filter(|&k| k != i && k != j) {
            assert_eq!(out.channels[c][k], streaked.channels[c][k], "channel {c}, pixel {k}");
        }
    }
}
