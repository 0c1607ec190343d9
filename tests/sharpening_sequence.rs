//! The ISP sharpening term through the worker's cadence, pooling and publication:
//! 5 s at 30 Hz of 320×240 frames of straight bands turning with the head (edges of
//! blur 1.1 px; the vendored scenes hold too few isolated straight edges for this
//! term, docs/accuracy.md "Sharpening"), sharpened by a known unsharp mask, then
//! sensor noise σ 0.005 and 8-bit steps (the ISP's order); and the same frames
//! without the mask. The sharpened run must publish the term present from the
//! first refit with 20 edges on, its halo within 10% of the mask's; the clean run
//! must never publish it present.

mod common;

use blind_augment::model::{CameraModel, Status};
use blind_augment::synth::add_sharpening;
use blind_augment::synth::sequence::SequenceSpec;
use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, Event, Providers};
use common::calibration::{frame, pose, scene};

/// A phone-like mask: k 1, σ 1.5 px.
const MASK: (f32, f32) = (1.0, 1.5);
const EDGE_SIGMA_PX: f64 = 1.1;

fn phi(x: f64) -> f64 {
    0.5 * (1.0 + libm::erf(x / std::f64::consts::SQRT_2))
}

/// Bands 20 px wide at `angle_rad`, between 0.25 and 0.65, edges of blur
/// `EDGE_SIGMA_PX` point-sampled, shifted by `shift_px` along their normal.
fn bands(w: usize, h: usize, angle_rad: f64, shift_px: f64) -> blind_augment::image::Rgb {
    let (c, s) = (angle_rad.cos(), angle_rad.sin());
    let data: Vec<f32> = (0..w * h)
        .map(|i| {
            let t = (i % w) as f64 * c + (i / w) as f64 * s + shift_px;
            let u = (t + 10.0).rem_euclid(40.0) - 10.0;
            (0.25 + 0.4 * (phi(u / EDGE_SIGMA_PX) - phi((u - 20.0) / EDGE_SIGMA_PX))) as f32
        })
        .collect();
    blind_augment::image::Rgb { width: w, height: h, channels: [data.clone(), data.clone(), data] }
}

fn run(mask: Option<(f32, f32)>) -> Vec<(f64, CameraModel)> {
    let spec = SequenceSpec::motorcycle(scene(), 320, 240, 150, None);
    let mut cfg = CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, Some(spec.view));
    // The sharpening term alone is under test.
    (cfg.vignetting, cfg.chromatic_aberration, cfg.colour) = (false, false, false);
    let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast)).expect("valid config");
    cal.push_poses(&[pose(&spec, 0), pose(&spec, 1)]).expect("poses");
    let mut published = Vec::new();
    for i in 0..spec.frames {
        cal.push_poses(&[pose(&spec, i + 2)]).expect("poses");
        let mut fr = frame(&spec.frame(scene(), i));
        fr.image = bands(320, 240, 0.2 + 0.05 * i as f64, 0.7 * i as f64);
        if let Some((k, s)) = mask {
            fr.image = add_sharpening(&fr.image, k, s);
        }
        for (c, ch) in fr.image.channels.iter_mut().enumerate() {
            for (j, v) in ch.iter_mut().enumerate() {
                let n = 0.005 * blind_augment::synth::gaussian((j % 320) as u32, (j / 320) as u32, c as u32, i as u64);
                *v = ((*v + n).clamp(0.0, 1.0) * 255.0).round() / 255.0;
            }
        }
        for e in cal.push_frame(fr).expect("valid frame") {
            if let Event::Published(u) = e {
                published.push((u.t_s, u.model));
            }
        }
    }
    published
}

/// The halo the mask leaves on these edges (fraction of the step).
fn truth() -> f64 {
    blind_augment::model::Sharpening::overshoot(MASK.0 as f64, MASK.1 as f64, EDGE_SIGMA_PX)
}

#[test]
fn a_sharpening_isp_is_published_present_and_none_never_is() {
    let published = run(Some(MASK));
    let mut present = 0;
    for (t, m) in &published {
        let s = &m.sharpening;
        assert_eq!(s.present, s.diagnostics.status == Status::Present, "{t:.2} s: {}", s.diagnostics.reason);
        if present > 0 || s.present {
            // Once present, it stays present, within 10% of the truth (the target is
            // 20%; on these edges the one-frame fit reads within 8%).
            assert!(s.present, "{t:.2} s: {}", s.diagnostics.reason);
            let o = s.overshoot.expect("present has an overshoot") as f64;
            assert!((o / truth() - 1.0).abs() <= 0.1, "{t:.2} s: {o} for {}: {}", truth(), s.diagnostics.reason);
            present += 1;
        }
    }
    let mut ms: Vec<f64> =
        published.iter().map(|(_, m)| m.sharpening.diagnostics.fit_time_s * 1e3).filter(|&v| v > 0.0).collect();
    ms.sort_by(f64::total_cmp);
    eprintln!(
        "{present} of {} publications present; last: {}; refit {:.1}–{:.1} ms",
        published.len(),
        published.last().map_or(String::new(), |p| p.1.sharpening.diagnostics.reason.clone()),
        ms.first().unwrap_or(&0.0),
        ms.last().unwrap_or(&0.0)
    );
    assert!(present * 2 >= published.len(), "{present} of {} publications present", published.len());
    for (t, m) in run(None) {
        let s = &m.sharpening;
        assert!(!s.present, "{t:.2} s: {}", s.diagnostics.reason);
    }
}
