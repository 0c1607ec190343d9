//! Tests of the streak zeros' line sampling: which lines count, and the noise
//! correlation their bilinear sampling gives.

use super::*;

/// Lines over noise alone carry no streak and are left out; the same noise over
/// texture is kept. 400×300 at 20 px/frame along 30°: of white noise of 2 DN
/// (8-bit scale) alone at most a fifth of the pairs survive, and over a smooth
/// texture (periods 23–61 px, 10× the noise's std) every line that fits the
/// frame counts, as without the noise.
#[test]
fn lines_of_noise_alone_are_left_out() {
    let (w, h) = (400usize, 300usize);
    let noise = |x: usize, y: usize| 2.0 / 255.0 * crate::synth::gaussian(x as u32, y as u32, 0, 7);
    let texture = |x: usize, y: usize| {
        let (x, y) = (x as f32, y as f32);
        0.5 + 0.05 * (std::f32::consts::TAU * x / 37.0).sin() * (std::f32::consts::TAU * y / 23.0).cos()
            + 0.03 * (std::f32::consts::TAU * (x + y) / 61.0).sin()
    };
    let plane = |f: &dyn Fn(usize, usize) -> f32| Plane::from_vec(w, h, (0..w * h).map(|i| f(i % w, i / w)).collect());
    let (c, sn) = (30f32.to_radians().cos(), 30f32.to_radians().sin());
    let flow = Flow::uniform(w, h, 20.0 * c, 20.0 * sn);
    let alone = streak_signature(&plane(&|x, y| 0.5 + noise(x, y)), &flow, |_, _| true);
    let clean = streak_signature(&plane(&texture), &flow, |_, _| true).expect("texture fits the frame");
    let noisy = streak_signature(&plane(&|x, y| texture(x, y) + noise(x, y)), &flow, |_, _| true).expect("texture");
    assert!(clean.lines >= 100, "lines over texture: {}", clean.lines);
    assert_eq!(noisy.lines, clean.lines, "texture under noise keeps its lines");
    // The bilinear sampling at 30° low-passes the noise (tilt ~2) and a few
    // pairs' scatter passes `FLAT_LINE_TILT`: measured 26 of the pairs the
    // texture keeps; without the gate every one.
    let kept = alone.map_or(0, |s| s.lines);
    assert!(kept * 5 <= clean.lines, "noise alone kept {kept} of {} lines", clean.lines);
}

/// The noise correlation against white noise actually read along the lines:
/// lags 0–2 of 64 lines at 10° (and an axis-aligned one, which reads whole
/// pixels) over a 400×300 plane of unit Gaussian noise. Tolerance 0.03 on the
/// correlation coefficient: ~10 000 products per lag, each of variance ≤ 1,
/// give a standard error ~0.01.
#[test]
fn interpolated_noise_correlation_matches_sampled_noise() {
    let (w, h) = (400usize, 300usize);
    let noise: Vec<f32> = (0..w * h).map(|i| crate::synth::gaussian((i % w) as u32, (i / w) as u32, 0, 3)).collect();
    let plane = Plane::from_vec(w, h, noise);
    let n = LINE_PX;
    for deg in [0.0f32, 10.0] {
        let (dx, dy) = (deg.to_radians().cos(), deg.to_radians().sin());
        let (mut measured, mut predicted) = ([0.0f64; 3], [0.0f64; 3]);
        for k in 0..64 {
            let (x0, y0) = (20.0 + (k % 8) as f32 * 30.0, 20.0 + (k / 8) as f32 * 30.0);
            let v: Vec<f64> =
                (0..n).map(|j| plane.sample_bilinear(x0 + j as f32 * dx, y0 + j as f32 * dy) as f64).collect();
            let r = interpolated_noise_correlation(x0, y0, dx, dy, n);
            for m in 0..3 {
                measured[m] += (0..n - m).map(|j| v[j] * v[j + m]).sum::<f64>() / (n - m) as f64 / 64.0;
                predicted[m] += r[m] / 64.0;
            }
        }
        for m in 0..3 {
            let (a, b) = (measured[m] / measured[0], predicted[m] / predicted[0]);
            assert!((a - b).abs() <= 0.03, "{deg}°, lag {m}: sampled {a:.3}, predicted {b:.3}");
        }
        if deg == 0.0 {
            assert_eq!(predicted, [1.0, 0.0, 0.0], "whole pixels read white noise");
        } else {
            // The phase-averaged value: B₃(cos 10°)·B₃(sin 10°) / (2/3)² ≈ 0.25.
            let rho = predicted[1] / predicted[0];
            assert!((0.2..=0.3).contains(&rho), "10°: lag-1 correlation {rho:.3}");
        }
    }
}

/// The one walk over the samples (positions j, j + 1, j + 2 shared by the three
/// lags) adds, per lag, the terms one loop per lag adds, in the same order: the
/// same bits, against that loop written out here, for line lengths around the
/// stride and the shipped one, axis-aligned, oblique and backward lines.
#[test]
fn noise_correlation_walk_is_the_per_lag_sum() {
    let per_lag = |x0: f32, y0: f32, dx: f32, dy: f32, n: usize| -> [f64; 3] {
        let ov = |a: f64, b: f64| -> f64 {
            let (ia, ib) = (a as i64, b as i64);
            let (ta, tb) = (a - ia as f64, b - ib as f64);
            match ib - ia {
                0 => (1.0 - ta) * (1.0 - tb) + ta * tb,
                1 => ta * (1.0 - tb),
                -1 => (1.0 - ta) * tb,
                _ => 0.0,
            }
        };
        let pos = |j: usize| (x0 as f64 + j as f64 * dx as f64, y0 as f64 + j as f64 * dy as f64);
        std::array::from_fn(|m| {
            let (mut sum, mut count) = (0.0, 0usize);
            for j in (0..n - m).step_by(NOISE_R_STRIDE) {
                let ((xa, ya), (xb, yb)) = (pos(j), pos(j + m));
                sum += ov(xa, xb) * ov(ya, yb);
                count += 1;
            }
            sum / count.max(1) as f64
        })
    };
    for n in [2usize, 3, 4, 5, 6, 7, 8, 9, 31, 32, 33, 127, LINE_PX, 129] {
        for (x0, y0, deg) in
            [(200.0f32, 150.0f32, 0.0f32), (150.3, 100.7, 10.0), (300.9, 250.2, 200.0), (50.5, 40.25, 95.0)]
                .into_iter()
                .chain([(0.0, 0.0, 45.0), (0.999, 2.0, 30.0), (7.5, 300.0, 271.0), (3.0, 3.0, 225.0)])
        {
            let (dx, dy) = (deg.to_radians().cos(), deg.to_radians().sin());
            // The streak's lines lie inside the frame: positions ≥ 0 (the last one
            // off it is the 225° line's, past n = 4; a chunk's terms past the end
            // are formed there and must not count).
            let last = (n - 1) as f32;
            if x0 + last * dx < 0.0 || y0 + last * dy < 0.0 {
                continue;
            }
            let got = interpolated_noise_correlation(x0, y0, dx, dy, n);
            let want = per_lag(x0, y0, dx, dy, n);
            assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "n {n}, {deg}° from ({x0}, {y0})");
        }
    }
}
