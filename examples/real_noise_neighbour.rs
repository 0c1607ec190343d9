//! Probe: the blind noise fit on the real clip's frame 400 (tests/data/noise_vtest)
//! alone and with another decoded frame of the clip as its aligned neighbour (a
//! static camera: the identity alignment), each against the temporal reference, per
//! level (median signed error over the reference's cells), as the difference reads it
//! and as `fit` reads it (alone: the frame shows the codec's grid). `SKIP=1` leaves out the
//! 8×8 blocks the neighbour copies exactly (a codec's skipped blocks). Frames come
//! from the clip (`make_reference.py`'s docstring says where to get it), e.g.
//! `python -c "import cv2; c=cv2.VideoCapture('vtest.avi'); [c.read() for _ in range(401)]; cv2.imwrite('vt401.png', c.read()[1])"`
//! (that writes frame 401). `cargo run --release --example real_noise_neighbour -- vt399.png vt401.png …`
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::fit::{fit, FitInputs, FitOptions, Neighbour, Tier};
use blind_augment::image::{Plane, Rgb};
use blind_augment::model::{Noise, NOISE_LEVELS};

fn report(name: &str, noise: &Noise) {
    if !noise.present {
        return println!("{name}: no noise model ({})", noise.diagnostics.reason);
    }
    let mut errs = vec![vec![]; NOISE_LEVELS];
    for &(l, c, luma, s) in &common::vtest::cells(&common::vtest::reference()) {
        let got = noise.levels[l].std(noise.form, c, noise.clamp_luma(0.5 * (luma[0] + luma[1])));
        errs[l].push((got / s - 1.0) as f64);
    }
    let per: Vec<String> = errs.into_iter().map(|e| format!("{:+.0}%", 100.0 * common::median(e))).collect();
    println!("{name}: per level {per:?}; luma range {:?}; {}", noise.luminance_range, noise.diagnostics.method);
}

/// Where the neighbour equals the frame over a whole 8×8 block: 0, else 1.
fn not_copied(frame: &Rgb, nb: &Rgb) -> Plane {
    let (w, h) = (frame.width, frame.height);
    let mut valid = Plane::new(w, h, 1.0);
    for by in 0..h / 8 {
        for bx in 0..w / 8 {
            let at = |y: usize, x: usize| (by * 8 + y) * w + bx * 8 + x;
            let copied = (0..64)
                .all(|k| (0..3).all(|c| frame.channels[c][at(k / 8, k % 8)] == nb.channels[c][at(k / 8, k % 8)]));
            if copied {
                (0..64).for_each(|k| valid.data[at(k / 8, k % 8)] = 0.0);
            }
        }
    }
    valid
}

fn main() {
    let frame = common::photo("noise_vtest/frame.png");
    let opts = FitOptions { tier: Some(Tier::Fast), ..FitOptions::default() };
    report("alone", &fit(&FitInputs::new(&frame), &opts).expect("fit").model.noise);
    // MEAN=path: the accurate fit against that image as I_noNoise (e.g. the mean of
    // the 8 frames around 400, as the worker's temporal denoiser makes it; the
    // mean's own 1/8 of the noise variance is not divided out: −6% in std).
    if let Some(path) = std::env::var_os("MEAN") {
        if let Ok((mean, _)) = blind_augment::io::load_rgb(std::path::Path::new(&path)) {
            let inp = FitInputs { denoised: Some(&mean), ..FitInputs::new(&frame) };
            let effects = blind_augment::fit::Effects { noise: true, motion_blur: false, depth_of_field: false };
            let acc = FitOptions { tier: Some(Tier::Accurate), effects, ..FitOptions::default() };
            report("accurate against MEAN", &fit(&inp, &acc).expect("fit").model.noise);
        }
    }
    for path in std::env::args().skip(1) {
        let Ok((nb, _)) = blind_augment::io::load_rgb(std::path::Path::new(&path)) else {
            eprintln!("{path}: not a readable image");
            continue;
        };
        let valid = if std::env::var_os("SKIP").is_some() {
            not_copied(&frame, &nb)
        } else {
            Plane::new(nb.width, nb.height, 1.0)
        };
        let kept = valid.data.iter().sum::<f32>() / valid.data.len() as f32;
        let inp = FitInputs { neighbour: Some(Neighbour { image: &nb, valid: &valid }), ..FitInputs::new(&frame) };
        let raw =
            blind_augment::fit::fit_noise_fast(&frame, inp.neighbour.as_ref(), opts.noise_fast_samples_per_level).0;
        report(&format!("{path} (valid {kept:.2}), the difference"), &raw);
        report(&format!("{path}, as `fit` reads it"), &fit(&inp, &opts).expect("fit").model.noise);
    }
}
