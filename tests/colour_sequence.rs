//! The colour term through the worker: a recorded-like sequence (the motorcycle
//! scene along the default head path, 320×240 at 30 Hz) whose camera's white
//! balance and exposure change mid-run (frames rendered under a tungsten light
//! without correction and one stop darker, from 2 s). The published colour must
//! follow within 1 s, the cast it reads after the change must be the applied one
//! times what the estimator reads on the scene's own (uncast) frames — it scales
//! exactly with a per-channel gain, so only the scene's own colours stand between
//! it and the cast, and those it reports as its error — and every publication's
//! `present` agrees with its status.

mod common;

use blind_augment::fit::colour::{angular_error_deg, illuminant, LinearFrame, ESTIMATOR, WORK_SIDE_PX};
use blind_augment::image::yuv::srgb_to_linear;
use blind_augment::model::{CameraModel, Status};
use blind_augment::synth::sequence::SequenceSpec;
use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, Event, Providers};
use common::calibration::{frame, pose, scene};

/// CIE illuminant A's colour in linear sRGB relative to D65, luma 1 (as
/// benches/colour.rs derives it from x = 0.44757, y = 0.40745).
fn tungsten() -> [f32; 3] {
    let (x, y) = (0.44757f64, 0.40745f64);
    let m = [[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]];
    let lin = |v: [f64; 3]| -> [f64; 3] { std::array::from_fn(|r| (0..3).map(|c| m[r][c] * v[c]).sum()) };
    let d65 = lin([0.31271 / 0.32902, 1.0, (1.0 - 0.31271 - 0.32902) / 0.32902]);
    let a = lin([x / y, 1.0, (1.0 - x - y) / y]);
    let g: [f64; 3] = std::array::from_fn(|c| a[c] / d65[c]);
    let l: f64 = g[0] * 0.299 + g[1] * 0.587 + g[2] * 0.114;
    g.map(|v| (v / l) as f32)
}

fn encode(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    let e = if v <= 0.0031308 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
    (e * 255.0).round() / 255.0
}

const CHANGE_S: f64 = 2.0;
/// The change's exposure: one stop down.
const EXPOSURE_STEP: f32 = 0.5;

#[test]
fn a_white_balance_change_is_followed_within_a_second() {
    let spec = SequenceSpec::motorcycle(scene(), 320, 240, 120, None);
    let frames: Vec<_> = (0..spec.frames).map(|i| spec.frame(scene(), i)).collect();
    let cast = tungsten();
    let step = cast.map(|g| g * EXPOSURE_STEP);
    // Per frame, the truth after the change (the view moves, so each publication —
    // the median over its 1 s window — is held to its window's frames):
    // * the illuminant: the estimator's reading of the uncast frame times the cast
    //   (the published one before the change may be neutral: a scene's bias within
    //   its error is not modelled);
    // * the exposure: the frame's grey-world brightness as the camera renders it
    //   after the change (step × cast on each pixel's linear colour, clipped at 1: a
    //   red scene under tungsten is brighter) over 0.18.
    let truths: Vec<([f64; 3], f64)> = frames
        .iter()
        .map(|f| {
            let own = illuminant(&LinearFrame::from_encoded(&f.image, WORK_SIDE_PX), ESTIMATOR)
                .expect("the scene shows its illuminant");
            let lum: f64 = (0..f.image.len())
                .map(|p| {
                    (0..3)
                        .map(|c| [0.299, 0.587, 0.114][c] * (step[c] * srgb_to_linear(f.image.channels[c][p])).min(1.0))
                        .sum::<f32>() as f64
                })
                .sum();
            (std::array::from_fn(|k| own.rgb[k] * cast[k] as f64), lum / f.image.len() as f64 / 0.18)
        })
        .collect();
    let mut cal = Calibrator::new(
        CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, Some(spec.view)),
        Providers::for_tier(CalibrationTier::Fast),
    )
    .expect("valid config");
    cal.push_poses(&[pose(&spec, 0), pose(&spec, 1)]).expect("poses");
    let mut published: Vec<(f64, CameraModel)> = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        cal.push_poses(&[pose(&spec, i + 2)]).expect("poses");
        let mut fr = frame(f);
        if fr.t_s >= CHANGE_S {
            for (ch, g) in fr.image.channels.iter_mut().zip(step) {
                for v in ch.iter_mut() {
                    *v = encode(srgb_to_linear(*v) * g);
                }
            }
        }
        for e in cal.push_frame(fr).expect("valid frame") {
            if let Event::Published(u) = e {
                published.push((u.t_s, u.model));
            }
        }
    }
    for (t, m) in &published {
        let c = &m.colour;
        assert_eq!(c.present, c.diagnostics.status == Status::Present, "{t:.2} s: {}", c.diagnostics.reason);
        assert!(c.illuminant.is_some(), "{t:.2} s: colour not identifiable ({})", c.diagnostics.reason);
    }
    // Within 1 s of the change and from then on: the illuminant within 1° of its
    // window's per-frame truths' median (what remains is 8-bit rounding and the
    // pixels the darker frame no longer clips), the exposure within 5% of its
    // window's range (the same).
    let after: Vec<&(f64, CameraModel)> = published.iter().filter(|(t, _)| *t >= CHANGE_S + 1.0).collect();
    assert!(after.len() >= 3, "only {} publications after the change settled", after.len());
    for (t, m) in after {
        let c = &m.colour;
        assert!(c.present, "{t:.2} s: a tungsten cast one stop down read as absent: {}", c.diagnostics.reason);
        let window: Vec<usize> = (0..spec.frames).filter(|&i| (t - 1.0..=*t).contains(&spec.frame_time_s(i))).collect();
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let truth: [f64; 3] = std::array::from_fn(|k| median(window.iter().map(|&i| truths[i].0[k]).collect()));
        let i = c.illuminant.expect("read");
        let err = angular_error_deg(i.map(f64::from), truth);
        assert!(err < 1.0, "{t:.2} s: illuminant read {i:?} for {truth:?}: {err:.2}° off");
        let (lo, hi) = window.iter().fold((f64::MAX, f64::MIN), |(a, b), &i| (a.min(truths[i].1), b.max(truths[i].1)));
        let e = c.exposure.expect("read") as f64;
        assert!(e >= 0.95 * lo && e <= 1.05 * hi, "{t:.2} s: exposure {e:.3}, its window's frames {lo:.3}…{hi:.3}");
    }
}
