//! The accurate exposure fit against references made from other frames: the cross
//! loss of two independently noisy references (`FitInputs::motion_deblurred_second`)
//! against one noisy reference, and a reference valid only on bands of rows.
mod common;

use blind_augment::fit::*;
use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::synth::add_motion_blur;
use common::*;

fn exposure(image: &Rgb, sharp: &Rgb, second: Option<&Rgb>, flow: &Flow, valid: Option<&Plane>) -> f32 {
    let opts = FitOptions {
        tier: Some(Tier::Accurate),
        effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
        mb_prefilter_var_px2: 1.0,
        ..Default::default()
    };
    let inp = FitInputs {
        motion_deblurred: Some(sharp),
        motion_deblurred_second: second,
        flow: Some(flow),
        reference_valid: valid,
        ..FitInputs::new(image)
    };
    fit(&inp, &opts).expect("valid inputs").model.motion_blur.exposure.expect("λ")
}

/// A 2.4 px streak (λ = 0.4 of 6 px/frame) against references carrying white
/// noise of std 0.05 (each its own draw, as two frames would). One reference reads λ
/// high — its noise, averaged by longer streaks, lowers the loss there (measured
/// +0.044 to +0.066 over four seeds); the cross loss of two has no such term
/// (measured 0.392–0.408 over the same seeds: its own scatter, hence 0.015).
#[test]
fn cross_loss_of_two_noisy_references_is_unbiased() {
    let clean = crop(&photo("astronaut.png"), 64, 64, 256, 256);
    let flow = Flow::uniform(256, 256, 6.0, 0.0);
    let image = add_sensor_noise(&add_motion_blur(&clean, &flow, 0.4), [0.0; 3], [4e-4; 3], 1);
    let r1 = add_sensor_noise(&clean, [2.5e-3; 3], [0.0; 3], 2);
    let r2 = add_sensor_noise(&clean, [2.5e-3; 3], [0.0; 3], 3);
    let one = exposure(&image, &r1, None, &flow, None);
    let two = exposure(&image, &r1, Some(&r2), &flow, None);
    let clean_ref = exposure(&image, &clean, None, &flow, None);
    eprintln!("λ = 0.4: noise-free reference {clean_ref:.4}, one noisy {one:.4}, two (cross loss) {two:.4}");
    assert!((clean_ref - 0.4).abs() < 0.005, "noise-free reference {clean_ref}");
    assert!(one - 0.4 > 0.03, "one noisy reference should read high here: {one}");
    assert!((two - 0.4).abs() < 0.015, "cross loss {two}");
}

/// A reference valid only on bands of rows (a sparse alignment; the rest of it 0,
/// as `analysis::temporal::align_bands` leaves it): the fit reads only rows whose
/// prefilter stays inside a band and reads λ as the full reference does (within
/// 0.005: the two read different pixels of the same frame).
#[test]
fn a_reference_on_bands_of_rows_reads_like_the_full_one() {
    let clean = crop(&photo("astronaut.png"), 0, 0, 320, 320);
    let flow = Flow::uniform(320, 320, 5.0, 3.0);
    let image = add_motion_blur(&clean, &flow, 0.5);
    let band = |y: usize| (y / 32) % 3 == 1;
    let mut sparse = clean.clone();
    let mut valid = Plane::new(320, 320, 0.0);
    for y in 0..320 {
        for x in 0..320 {
            let i = y * 320 + x;
            if band(y) {
                valid.data[i] = 1.0;
            } else {
                for c in 0..3 {
                    sparse.channels[c][i] = 0.0;
                }
            }
        }
    }
    let full = exposure(&image, &clean, None, &flow, None);
    let banded = exposure(&image, &sparse, None, &flow, Some(&valid));
    eprintln!("λ = 0.5: full reference {full:.4}, bands {banded:.4}");
    assert!((full - 0.5).abs() < 0.005, "full reference {full}");
    assert!((banded - full).abs() < 0.005, "banded reference {banded} vs {full}");
}
