//! The streak zeros' standard error against what they miss by: long exposures on
//! an isotropic texture under defocus, sensor noise and 8-bit quantisation, where
//! the zeros answer with a strong side lobe and a sampling spread of a few
//! hundredths of a pixel — while the template's model (sinc² over a flat noise
//! floor, read through a Hann window) puts the zero 2–5% short
//! (`fit::motion_blur::ZEROS_MODEL_ERROR`).

use blind_augment::fit::{fit, FitInputs};
use blind_augment::image::Flow;
use blind_augment::synth;

#[path = "common/mod.rs"]
mod common;

/// An isotropic texture (σ 1.2 px) at λ 0.75, 0.9 and 1 under 8 and 16 px/frame
/// at 0° and 30°, σ 1.2 px defocus, noise, 8-bit: every exposure the streak zeros
/// answer must hold the truth within two standard errors, and the zeros must answer
/// most of these frames (a test of the zeros, not of the fallback). Tolerance: two
/// standard errors, the coverage the fit's reported error claims (~95%); 12 frames,
/// so one miss would be in keeping with that and is allowed. Without the model
/// error 8 of the 10 zeros answers here missed (λ 0.860 ± 0.011 for 0.9, 0.730 ±
/// 0.008 for 0.75 …; at 800×700, 16 of 20);
/// with it, none.
#[test]
fn streak_zeros_error_holds_their_model_error() {
    let (w, h) = (640usize, 480usize);
    let opts = common::fast_exposure_only();
    let tex = synth::sequence::anisotropic_texture(w, h, 1.2, 1.2, 3);
    let (mut zeros, mut missed, mut frames) = (0, vec![], 0);
    for deg in [0.0f32, 30.0] {
        let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
        for speed in [8.0f32, 16.0] {
            let flow = Flow::uniform(w, h, speed * c, speed * s);
            for truth in [0.75f32, 0.9, 1.0] {
                let img = common::defocus_noise_8bit(&synth::add_motion_blur(&tex, &flow, truth), 1.2, 3);
                let out = fit(&FitInputs { flow: Some(&flow), ..FitInputs::new(&img) }, &opts).expect("fit");
                let mb = &out.model.motion_blur;
                frames += 1;
                let reason = &mb.diagnostics.reason;
                let (got, se) = (mb.exposure.unwrap_or(f32::NAN), mb.diagnostics.stderr.unwrap_or(0.0));
                println!("{deg}° {speed} px/frame λ {truth}: {got:.4} ± {se:.4} — {reason}");
                if !reason.contains("from the streak's spectral zeros") {
                    continue;
                }
                zeros += 1;
                assert!(se.is_finite() && se > 0.0, "{reason}");
                if ((got - truth).abs() as f64) > 2.0 * se {
                    missed.push(format!("{deg}°, {speed} px/frame, λ {truth}: read {got:.4} ± {se:.4}"));
                }
            }
        }
    }
    assert!(zeros >= frames - 4, "the zeros answered {zeros} of {frames} frames");
    assert!(
        missed.len() <= 1,
        "{} of {zeros} zeros answers miss by more than two standard errors: {missed:#?}",
        missed.len()
    );
}
