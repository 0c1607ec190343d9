//! The blind noise fit on real sensor noise: one frame of a real static-camera clip
//! (OpenCV's `vtest.avi`, DivX-compressed; tests/data/ATTRIBUTION.md) against a
//! temporal reference measured over its 795 frames by an independent script
//! (`tests/data/noise_vtest/make_reference.py`): per Laplacian level, channel and
//! luma bin, the std of (frame − temporal mean) over the static observations.

mod common;

use blind_augment::fit::{fit, FitInputs, FitOptions, Tier};
use blind_augment::image::{gaussian_pyramid, laplacian_pyramid, Rgb};
use blind_augment::model::{LevelSource, Noise, NOISE_LEVELS};
use blind_augment::synth::noise_field;
use common::vtest::{cells, reference};
use common::*;

fn blind_noise(img: &Rgb) -> Noise {
    let opts = FitOptions { tier: Some(Tier::Fast), ..FitOptions::default() };
    fit(&FitInputs::new(img), &opts).expect("fit").model.noise
}

fn median_abs(v: &[f64]) -> f64 {
    median(v.iter().map(|e| e.abs()).collect())
}

/// The model's own per-level stds, evaluated where the renderer evaluates them (luma
/// clamped to the fitted range), against the temporal reference.
///
/// The goal — median |relative error| ≤ 20% over every level, channel and
/// bin — is NOT met on this frame, and the test says what is: measured 2026-11-23,
/// level 0 −34% over all bins but within 20% (median) over the bins inside the luma
/// range the fit measured (0.53–0.78, the road); levels 1–3 −69…−80%. Why: the
/// reference shows this codec's "noise" is texture-dependent (1.1 DN on the road,
/// 1.8–2 DN on the lawn, where it re-quantises the grass differently every frame),
/// and the frame's flattest samples at levels 1–3 carry 1.7–3× the noise's std
/// (make_reference.py's data: the 0.5th percentile of the frame's level-2 local std
/// is 0.73 DN against the noise's median 0.44 DN). One frame cannot separate them;
/// the fit therefore reports levels 1–3 as not identifiable and continues level 0
/// by white-noise ratios (which decay faster than this codec's noise: hence the
/// coarse levels' large negative error). Tolerances below: the goal's 20% where
/// the fit claims a measurement; everywhere else only "within the stated miss + 10
/// points", so a regression still fails.
#[test]
fn one_real_frame_reads_the_temporal_noise_per_level_and_luma() {
    let frame = photo("noise_vtest/frame.png");
    let noise = blind_noise(&frame);
    assert!(noise.present, "real sensor noise must read as present: {}", noise.diagnostics.reason);
    let r = reference();
    let cells = cells(&r);
    assert!(cells.len() >= 100, "reference cells: {}", cells.len());
    let mut errs = vec![vec![]; NOISE_LEVELS];
    let mut in_range = vec![];
    let [lo, hi] = noise.luminance_range;
    for &(l, c, luma, s) in &cells {
        let mid = 0.5 * (luma[0] + luma[1]);
        let got = noise.levels[l].std(noise.form, c, noise.clamp_luma(mid));
        let e = (got / s - 1.0) as f64;
        errs[l].push(e);
        if l == 0 && luma[1] > lo && luma[0] < hi {
            in_range.push(e);
        }
    }
    for (l, e) in errs.iter().enumerate() {
        eprintln!(
            "level {l}: median error {:+.1}% (|·| {:.1}%) over {} cells",
            100.0 * median(e.clone()),
            100.0 * median_abs(e),
            e.len()
        );
    }
    let all: Vec<f64> = errs.concat();
    eprintln!(
        "all levels: median |error| {:.1}%; level 0 inside the fitted range {:?}: {:.1}% over {} cells; {}",
        100.0 * median_abs(&all),
        noise.luminance_range,
        100.0 * median_abs(&in_range),
        in_range.len(),
        noise.diagnostics.reason
    );
    assert!(in_range.len() >= 9, "level-0 cells inside the fitted range: {}", in_range.len());
    assert!(median_abs(&in_range) <= 0.20, "level 0 inside the fitted range: {:.1}%", 100.0 * median_abs(&in_range));
    assert!(median_abs(&errs[0]) <= 0.45, "level 0, all bins: {:.1}%", 100.0 * median_abs(&errs[0]));
    assert!(median_abs(&all) <= 0.80, "all levels: {:.1}%", 100.0 * median_abs(&all));
    // The fit must say that it could not measure the coarse levels here.
    assert!(noise.diagnostics.reason.contains("levels [1, 2, 3] not identifiable"), "{}", noise.diagnostics.reason);
    // And the model says so per level: level 0 measured over the fitted range, the
    // others continued from it.
    assert!(
        matches!(noise.level_sources[0], LevelSource::Measured { luma, .. } if luma == noise.luminance_range),
        "{:?}",
        noise.level_sources
    );
    assert!(
        noise.level_sources[1..].iter().all(|s| *s == LevelSource::Continued { from: 0 }),
        "{:?}",
        noise.level_sources
    );
}

/// The fitted model synthesised through `synth` onto the clip's clean (temporal
/// mean) image, analysed with the same pyramid and binned like the reference: level
/// 0 inside the fitted luma range within 20% (the goal's tolerance; measured
/// 2026-11-23: see the printout), every cell together within the stated miss of the
/// test above (median 69% measured; 80% asserted).
#[test]
fn synthesised_noise_matches_the_real_clip_per_level_and_luma() {
    let frame = photo("noise_vtest/frame.png");
    let clean = photo("noise_vtest/mean.png");
    let noise = blind_noise(&frame);
    let field = noise_field(&clean.luma(), &noise, 7);
    let luma = gaussian_pyramid(&clean.luma(), NOISE_LEVELS);
    let bands: Vec<_> = (0..3).map(|c| laplacian_pyramid(&field.plane(c), NOISE_LEVELS).bands).collect();
    let r = reference();
    let [lo, hi] = noise.luminance_range;
    let (mut errs, mut in_range) = (vec![], vec![]);
    for &(l, c, lum, s) in &cells(&r) {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (v, y) in bands[c][l].data.iter().zip(&luma[l].data) {
            if *y >= lum[0] && *y < lum[1] {
                sum += (*v as f64).powi(2);
                n += 1;
            }
        }
        if n >= 16 {
            let e = (sum / n as f64).sqrt() / s as f64 - 1.0;
            errs.push(e);
            if l == 0 && lum[1] > lo && lum[0] < hi {
                in_range.push(e);
            }
        }
    }
    eprintln!(
        "synthesised vs temporal reference: median |error| {:.1}% over {} cells; level 0 inside the fitted range {:.1}% over {}",
        100.0 * median_abs(&errs),
        errs.len(),
        100.0 * median_abs(&in_range),
        in_range.len()
    );
    assert!(in_range.len() >= 9);
    assert!(median_abs(&in_range) <= 0.20, "level 0 inside the fitted range: {:.1}%", 100.0 * median_abs(&in_range));
    assert!(median_abs(&errs) <= 0.80, "all cells: {:.1}%", 100.0 * median_abs(&errs));
}

/// The clip is DivX (MPEG-4 part 2, 8×8 DCT): the blind fit says so; the vendored
/// lossless photographs carry no block grid.
#[test]
fn compression_blocking_is_recognised() {
    let noise = blind_noise(&photo("noise_vtest/frame.png"));
    let b = noise.blocking.expect("the DivX frame's 8-px block grid");
    assert_eq!(b.period_px, 8);
    // The detector alone (`fit::compression_blocking`, for callers without a fit)
    // finds the same grid.
    let alone = blind_augment::fit::compression_blocking(&photo("noise_vtest/frame.png")).expect("the grid, alone");
    eprintln!("in the fit {b:?}; alone {alone:?}");
    assert_eq!((alone.period_px, alone.phase_px), (b.period_px, b.phase_px));
    assert!(noise.diagnostics.reason.contains("blocking"), "{}", noise.diagnostics.reason);
    for name in ["astronaut.png", "chelsea.png"] {
        let n = blind_noise(&quantize8(&add_sensor_noise(&photo(name), [4e-5; 3], [1e-4; 3], 3)));
        assert!(n.blocking.is_none(), "{name}: {:?}", n.blocking);
        assert!(blind_augment::fit::compression_blocking(&photo(name)).is_none(), "{name}");
    }
}

/// A block codec predicts each frame from the last: skipped blocks copy its noise
/// exactly, predicted ones carry it under their residual. On this clip 72% of frame
/// 400's pixels equal frame 401's, and the blind fit with a neighbour 1–10 frames
/// away reads level 0 at −59…−82% (against the temporal reference; alone −31%). So where the frame shows the codec's grid the
/// fit reads it alone and says why. Checked with the extreme of a copy — the frame
/// itself as its own aligned neighbour: the difference holds no noise at all (no
/// model, or level 0 below a fifth of the frame-alone fit's), while `fit` returns
/// the frame-alone model unchanged.
#[test]
fn a_neighbour_is_not_used_on_a_frame_with_a_codec_grid() {
    use blind_augment::fit::{fit_noise_fast, Neighbour};
    let frame = photo("noise_vtest/frame.png");
    let alone = blind_noise(&frame);
    let valid = blind_augment::image::Plane::new(frame.width, frame.height, 1.0);
    let nb = Neighbour { image: &frame, valid: &valid };
    let opts = FitOptions { tier: Some(Tier::Fast), ..FitOptions::default() };
    let raw = fit_noise_fast(&frame, Some(&nb), opts.noise_fast_samples_per_level).0;
    let std0 = |n: &Noise| n.levels[0].std(n.form, 1, n.clamp_luma(0.6));
    eprintln!(
        "level 0 at luma 0.6: alone {:.5}, difference with a copy {:?}",
        std0(&alone),
        raw.present.then(|| std0(&raw))
    );
    assert!(!raw.present || std0(&raw) < 0.2 * std0(&alone), "the copy's difference held noise");
    let got = fit(&FitInputs { neighbour: Some(nb), ..FitInputs::new(&frame) }, &opts).expect("fit").model.noise;
    assert_eq!(got.diagnostics.method, "fast");
    assert!(got.diagnostics.reason.contains("neighbour was not used"), "{}", got.diagnostics.reason);
    assert_eq!((got.form, got.intensity, got.luminance_range), (alone.form, alone.intensity, alone.luminance_range));
    for (a, b) in got.levels.iter().zip(&alone.levels) {
        assert_eq!((a.slope, a.intercept), (b.slope, b.intercept));
    }
}

/// Every measured luma bin reports its confidence, and the model says nothing
/// outside the lumas it measured. A bin's confidence is its sampling error (< 0.5
/// here) and the texture floor's bias (≤ 1: this clip's noise, ~0.004 in level-0
/// std, lies within a natural scene's floor of 0.006, so one frame cannot tell it
/// from texture), in quadrature: below √1.25.
#[test]
fn bins_report_confidence_and_the_range_is_the_measured_one() {
    let noise = blind_noise(&photo("noise_vtest/frame.png"));
    assert!(noise.bins.len() >= 8, "bins: {}", noise.bins.len());
    for b in &noise.bins {
        assert!(
            b.relative_stderr.is_finite() && b.relative_stderr > 0.0 && b.relative_stderr < 1.25f32.sqrt(),
            "{b:?}"
        );
        assert!(b.samples >= 12, "{b:?}");
    }
    let used: Vec<f32> = noise.bins.iter().filter(|b| b.used).map(|b| b.luma).collect();
    let lo = used.iter().cloned().fold(1.0, f32::min);
    let hi = used.iter().cloned().fold(0.0, f32::max);
    assert_eq!(noise.luminance_range, [lo, hi]);
}
