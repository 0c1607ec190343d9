//! Lateral chromatic aberration read blindly from one frame (`fit::chromatic`) on
//! the vendored real photographs with a known radial scale per channel applied
//! (`synth::add_lateral_ca`; corner shifts +0.6 px red, −0.4 px blue), 8-bit
//! quantised, without and with sensor noise (σ 0.01).

mod common;

use blind_augment::fit::chromatic::{estimate, ScaleEstimate};
use blind_augment::image::Rgb;
use blind_augment::synth::add_lateral_ca;
use common::grey;

fn quantise(img: &Rgb) -> Rgb {
    img.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0)
}

/// Gaussian noise of std `sigma` (encoded units), seeded.
fn noisy(img: &Rgb, sigma: f32, seed: u64) -> Rgb {
    let mut out = img.clone();
    for (c, ch) in out.channels.iter_mut().enumerate() {
        for (i, v) in ch.iter_mut().enumerate() {
            let (x, y) = ((i % img.width) as u32, (i / img.width) as u32);
            *v += sigma * blind_augment::synth::gaussian(x, y, c as u32, seed);
        }
    }
    out
}

const PHOTOS: [&str; 3] = ["astronaut.png", "chelsea.png", "rocket.jpg"];
/// Applied corner shifts (px): red outward, blue inward.
const SHIFT_PX: [f32; 2] = [0.6, -0.4];

/// (read corner shift, its σ) of both channels, px.
fn read(img: &Rgb, half_diag: f32) -> [(f64, f64); 2] {
    estimate(img).map(|e: Option<ScaleEstimate>| {
        let e = e.expect("the photograph has edges to read");
        (e.scale_minus_one * half_diag as f64, e.stderr * half_diag as f64)
    })
}

fn applied(clean: &Rgb, sigma: f32) -> (Rgb, Rgb, f32) {
    let half_diag = 0.5 * (clean.width as f32 - 1.0).hypot(clean.height as f32 - 1.0);
    let scale = SHIFT_PX.map(|s| 1.0 + s / half_diag);
    (quantise(&noisy(&add_lateral_ca(clean, scale), sigma, 3)), quantise(&noisy(clean, sigma, 3)), half_diag)
}

/// Greyscale photographs (no aberration of their own): the shift read within 10%
/// of the applied one (the target) and, without it, under 0.05 px (a
/// tenth of the applied) — the estimator's own bias on real edges.
#[test]
fn a_known_aberration_is_read_on_greyscale_photographs() {
    for name in PHOTOS {
        let clean = grey(&common::photo(name));
        for sigma in [0.0f32, 0.01] {
            let (with, without, half_diag) = applied(&clean, sigma);
            let (got, none) = (read(&with, half_diag), read(&without, half_diag));
            for k in 0..2 {
                let want = SHIFT_PX[k] as f64;
                eprintln!(
                    "{name} grey σ {sigma} ch {k}: {:.3} ± {:.3} px for {want}; without {:.3} ± {:.3}",
                    got[k].0, got[k].1, none[k].0, none[k].1
                );
                assert!(
                    (got[k].0 - want).abs() <= 0.1 * want.abs(),
                    "{name} σ {sigma} channel {k}: {:.3} px for {want}",
                    got[k].0
                );
                assert!(
                    none[k].0.abs() <= 0.05,
                    "{name} σ {sigma} channel {k}: {:.3} px read with none applied",
                    none[k].0
                );
            }
        }
    }
}

/// The colour photographs carry their own cameras' aberration (read without the
/// applied one: −0.1…+0.1 px); the applied shift is read as the difference, within
/// 10% (the target; the rocket is a JPEG, its chroma at half resolution).
#[test]
fn a_known_aberration_adds_to_a_photographs_own() {
    for name in PHOTOS {
        let clean = common::photo(name);
        let tol = 0.1;
        for sigma in [0.0f32, 0.01] {
            let (with, without, half_diag) = applied(&clean, sigma);
            let (got, own) = (read(&with, half_diag), read(&without, half_diag));
            for k in 0..2 {
                let want = SHIFT_PX[k] as f64;
                let diff = got[k].0 - own[k].0;
                eprintln!("{name} σ {sigma} ch {k}: {:.3} − own {:.3} = {diff:.3} px for {want}", got[k].0, own[k].0);
                assert!(
                    (diff - want).abs() <= tol * want.abs(),
                    "{name} σ {sigma} channel {k}: {diff:.3} px for {want}"
                );
            }
        }
    }
}
