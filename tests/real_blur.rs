//! The blind tier on real blur: a real photograph defocused by a round aperture
//! (vendored, tests/data/ATTRIBUTION.md) and synthetic disc/Gaussian known answers.

mod common;

use blind_augment::fit::defocus_spectrum::disc_signature;
use blind_augment::image::{Plane, Rgb};
use blind_augment::synth::{add_defocus, add_defocus_disc};
use common::*;

fn q8(img: &Rgb, seed: u64) -> Rgb {
    // 8-bit with a little sensor noise (std 0.01), like a real frame.
    let mut s = seed;
    let mut out = img.clone();
    for c in 0..3 {
        for v in out.channels[c].iter_mut() {
            // Box–Muller on a splitmix64 stream.
            let mut next = || {
                s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
                let mut z = s;
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
            };
            let (u1, u2) = (next().max(1e-12), next());
            let n = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
            *v = ((*v + 0.01 * n as f32).clamp(0.0, 1.0) * 255.0).round() / 255.0;
        }
    }
    out
}

#[test]
fn explore() {
    let real = photo("defocus_disc_opencv.jpg");
    let s = disc_signature(&real.luma(), |_, _, _| true);
    eprintln!("real: {s:?}");
    for name in ["chelsea.png", "astronaut.png"] {
        let img = photo(name);
        let (w, h) = (img.width, img.height);
        eprintln!("{name} sharp: {:?}", disc_signature(&q8(&img, 1).luma(), |_, _, _| true));
        for sigma in [1.5f32, 3.0, 4.5, 6.5, 8.0] {
            let b = q8(&add_defocus_disc(&img, &Plane::new(w, h, sigma)), 2);
            eprintln!("{name} disc σ {sigma}: {:?}", disc_signature(&b.luma(), |_, _, _| true));
        }
        for sigma in [1.0f32, 2.0, 3.0, 5.0, 8.0] {
            let b = q8(&add_defocus(&img, &Plane::new(w, h, sigma)), 3);
            eprintln!("{name} gauss σ {sigma}: {:?}", disc_signature(&b.luma(), |_, _, _| true));
        }
    }
}
