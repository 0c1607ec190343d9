//! The blind tier on real blur: a real photograph defocused by a round aperture
//! (vendored, tests/data/ATTRIBUTION.md) and synthetic disc/Gaussian known answers.

mod common;

use blind_augment::fit::defocus_spectrum::disc_signature;
use blind_augment::fit::{fit, FitInputs, FitOptions, Tier};
use blind_augment::image::{Plane, Rgb};
use blind_augment::model::{DepthOfField, DofCurve, DofKernel};
use blind_augment::synth::{add_defocus, add_defocus_disc};
use common::*;

fn q8(img: &Rgb, seed: u64) -> Rgb {
    // 8-bit with a little white sensor noise (std 0.01), like a real frame.
    quantize8(&add_sensor_noise(img, [1e-4; 3], [0.0; 3], seed))
}

/// Blind DoF of the fast tier with one constant depth (the photo's depth is unknown:
/// a frame defocused uniformly has a single δ).
fn fit_constant_depth(img: &Rgb) -> DepthOfField {
    let depth = Plane::new(img.width, img.height, 2.0);
    let mut inp = FitInputs::new(img);
    inp.depth = Some(&depth);
    let opts = FitOptions { tier: Some(Tier::Fast), ..FitOptions::default() };
    fit(&inp, &opts).expect("fit").model.depth_of_field
}

/// The OpenCV tutorial's real out-of-focus photograph ("the out-of-focus was
/// achieved manually by camera optics"; its restoration uses a circular PSF). The
/// tutorial states R = 53 px for its full-resolution input, whose size is not
/// published, so the PSF is measured here on the shipped 640×480 by a method
/// independent of the estimator: the first zero of the radially averaged power
/// spectrum (Bessel J₁: f₀ = 3.8317/(2πR)) lies at 0.110 cycles/px → R = 5.54 px,
/// second-moment σ = √(R²/4 + 1/12) = 2.79 px. (The "19 px diameter" would
/// put that zero at 0.064 cycles/px, where the spectrum has none.) Tolerance: 25% of
/// σ (the issue's). Measured: disc, σ 2.75 px (−1.3%), ring z 31, notch 0.22.
#[test]
fn real_defocused_photo_reads_as_a_disc_of_the_measured_size() {
    let img = photo("defocus_disc_opencv.jpg");
    let truth_sigma = (5.54f32 * 5.54 / 4.0 + 1.0 / 12.0).sqrt();
    let s = disc_signature(&img.luma(), |_, _, _| true).expect("textured");
    assert!(s.is_disc, "{s:?}");
    let dof = fit_constant_depth(&img);
    assert!(dof.present, "{:?}", dof.diagnostics);
    assert_eq!(dof.kernel, DofKernel::Disc);
    let Some(DofCurve::Constant { c }) = dof.curve else { panic!("{:?}", dof.curve) };
    assert!((c / truth_sigma - 1.0).abs() <= 0.25, "σ {c} vs {truth_sigma}");
    assert!(dof.diagnostics.stderr.is_some_and(|e| e > 0.0 && e < 0.5), "{:?}", dof.diagnostics.stderr);
}

/// Known answers with the project's disc and Gaussian kernels on the two bundled
/// photographs (8-bit, noise std 0.01). Discs are recognised and sized within 10% of
/// their σ (measured: −5.0% … +1.0%) where the frame holds enough 256-px tiles (the
/// 512² astronaut: σ 1.5–8) or, on the 451×300 cat (128-px tiles only), σ 3–4.5
/// (larger rings fall below z 4 there: reported as Gaussian, measured z 3.8 at
/// σ 6.5); Gaussians of σ 1–8 and the sharp frames never read as discs (measured
/// notch contrasts ≤ 0.13 against the 0.18 threshold; discs ≥ 0.29).
#[test]
fn synthetic_discs_and_gaussians_are_told_apart() {
    for (name, disc_sigmas) in [("astronaut.png", &[1.5f32, 3.0, 4.5, 6.5, 8.0][..]), ("chelsea.png", &[3.0, 4.5][..])]
    {
        let img = photo(name);
        let (w, h) = (img.width, img.height);
        let sharp = disc_signature(&q8(&img, 1).luma(), |_, _, _| true).expect("textured");
        assert!(!sharp.is_disc, "{name} sharp: {sharp:?}");
        for &sigma in disc_sigmas {
            let b = q8(&add_defocus_disc(&img, &Plane::new(w, h, sigma)), 2);
            let s = disc_signature(&b.luma(), |_, _, _| true).expect("textured");
            assert!(s.is_disc, "{name} disc σ {sigma}: {s:?}");
            assert!((s.sigma_px / sigma - 1.0).abs() <= 0.10, "{name} disc σ {sigma}: {s:?}");
        }
        for sigma in [1.0f32, 2.0, 3.0, 5.0, 8.0] {
            let b = q8(&add_defocus(&img, &Plane::new(w, h, sigma)), 3);
            let s = disc_signature(&b.luma(), |_, _, _| true).expect("textured");
            assert!(!s.is_disc, "{name} Gaussian σ {sigma}: {s:?}");
        }
    }
}

/// The fit end to end: a uniformly disc-defocused frame (constant depth) is present,
/// disc-shaped, δ within 10%; the same δ drawn as a Gaussian stays Gaussian.
#[test]
fn fast_fit_carries_the_kernel_shape() {
    let img = photo("astronaut.png");
    let (w, h) = (img.width, img.height);
    let disc = fit_constant_depth(&q8(&add_defocus_disc(&img, &Plane::new(w, h, 3.5)), 4));
    assert!(disc.present && disc.kernel == DofKernel::Disc, "{:?}", disc.diagnostics);
    let c = disc.sigma_px(2.0);
    assert!((c / 3.5 - 1.0).abs() <= 0.10, "disc δ {c}");
    let gauss = fit_constant_depth(&q8(&add_defocus(&img, &Plane::new(w, h, 3.5)), 5));
    assert_eq!(gauss.kernel, DofKernel::Gaussian, "{:?}", gauss.diagnostics);
}
