//! Spatially correlated sensor noise (real camera noise is not white): demosaicing, an ISP's denoiser and a codec correlate it between
//! neighbouring pixels, so its band stds decay slower across the pyramid than white
//! noise's. On video the blind fit reads every level from the frame against the
//! previous one aligned (texture cancels in the difference); one frame alone cannot
//! (the scene's own texture fills its flattest samples at the coarse levels) and
//! must say which levels it did not measure. Frames: the calibration video (the
//! Motorcycle along the head path, 640×480), its noise made by
//! `synth::correlated_sensor_noise`. BENCHMARKS.md "Correlated noise on video".

mod common;

use blind_augment::analysis::temporal::align;
use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Neighbour, Tier};
use blind_augment::image::{blur_separable, discrete_gaussian_kernel, laplacian_pyramid, Plane, Rgb};
use blind_augment::model::{LevelSource, Noise, NOISE_LEVELS};
use blind_augment::synth::correlated_sensor_noise;
use blind_augment::synth::sequence::{motorcycle, SequenceSpec};
use common::{analysed, median};

/// Per level, the median signed relative error of the fitted std against the truth
/// over 9 lumas inside the fit's range × 3 channels.
fn level_errors(n: &Noise, t: &Noise) -> Vec<f64> {
    let [lo, hi] = n.luminance_range;
    (0..NOISE_LEVELS)
        .map(|l| {
            median(
                (0..27)
                    .map(|k| {
                        let (y, c) = (lo + (hi - lo) * ((k / 3) as f32 + 0.5) / 9.0, k % 3);
                        (n.levels[l].std(n.form, c, y) / t.levels[l].std(t.form, c, y) - 1.0) as f64
                    })
                    .collect(),
            )
        })
        .collect()
}

/// Per frame of `frames`: the fit with the previous frame aligned and the fit of the
/// frame alone, under noise with these level std ratios.
fn fits(ratios: [f32; NOISE_LEVELS - 1], frames: std::ops::Range<usize>) -> (Noise, Vec<(Noise, Noise)>) {
    let truth = correlated_sensor_noise([3e-5, 2e-5, 5e-5], [6e-4, 4e-4, 9e-4], [0.0, 1.0], ratios).expect("ratios");
    let scene = motorcycle().expect("bundled scene");
    let mut spec = SequenceSpec::motorcycle(&scene, 640, 480, 150, None);
    spec.truth.noise = truth.clone();
    let opts = FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
        ..Default::default()
    };
    let mut prev = analysed(&spec.frame(&scene, frames.start - 1));
    let mut out = vec![];
    for i in frames {
        let f = spec.frame(&scene, i);
        let cur = analysed(&f);
        let a = align(&prev, &cur, &spec.view).expect("poses and depth align");
        let valid = Plane::from_vec(640, 480, a.valid.iter().map(|&v| v as u8 as f32).collect());
        let inp =
            FitInputs { neighbour: Some(Neighbour { image: &a.image, valid: &valid }), ..FitInputs::new(&f.image) };
        let with = fit(&inp, &opts).expect("fit").model.noise;
        let alone = fit(&FitInputs::new(&f.image), &opts).expect("fit").model.noise;
        out.push((with, alone));
        prev = cur;
    }
    (truth, out)
}

/// The levels the fit continued from a finer one (`LevelSource::Continued`), empty
/// when it measured every level; the reason must name the same ones.
fn derived(n: &Noise) -> Vec<usize> {
    assert_eq!(n.level_sources.len(), NOISE_LEVELS, "a blind fit says how it read every level");
    let d: Vec<usize> =
        (0..NOISE_LEVELS).filter(|&l| matches!(n.level_sources[l], LevelSource::Continued { .. })).collect();
    if !d.is_empty() {
        let r = &n.diagnostics.reason;
        assert!(r.contains(&format!("levels {d:?} not identifiable")), "continued {d:?}, reason: {r}");
    }
    d
}

/// Each measured level's median error over its stated relative standard error
/// (`LevelSource::Measured`).
fn error_over_stated(n: &Noise, e: &[f64]) -> Vec<f64> {
    n.level_sources
        .iter()
        .zip(e)
        .filter_map(|(s, e)| match *s {
            LevelSource::Measured { relative_stderr, .. } => Some(e.abs() / relative_stderr.max(1e-6) as f64),
            LevelSource::Continued { .. } => None,
        })
        .collect()
}

/// Two noise spectra far from white: a codec's (the vtest clip's measured ratios,
/// level 1/0 0.45, then 0.72, 0.72) and a demosaic's (white noise low-passed by a
/// Gaussian of std 0.7 px: 0.58, 0.53, 0.51); white noise's are 0.24, 0.44, 0.49.
/// With the neighbour every level is measured; measured 2026-11-28 over frames 55–58:
/// every frame and level within −4.4…+5.2%. Tolerances: a level's median over the 4
/// frames within 8%, each frame's within 15% — level 3 at 640×480 is 80×60 px, whose
/// std a frame reads to a few percent, and what the difference leaves of the scene
/// where the two exposures differ reads as noise. The frame alone measured level 0
/// within +3…+4% but derived levels 1–3 (codec) or 2–3 (demosaic, some frames) by
/// white noise's ratios, −25…−77%: it must name them.
#[test]
fn correlated_noise_is_read_per_level_against_the_aligned_previous_frame() {
    for (name, ratios) in [("codec", [0.45, 0.72, 0.72]), ("demosaic", [0.58, 0.53, 0.51])] {
        check(name, ratios, 55..59, 0.15, [0.08; NOISE_LEVELS]);
    }
}

/// White noise is the weakest at the coarse levels, so what the difference leaves of
/// the scene where the two exposures differ counts most there. Measured over frames
/// 55–62: levels 2 / 3 +5.5 / +14% in median, each frame within +21%; with the flat
/// samples chosen two levels coarser than the band, as for the frame alone (before
/// 2026-11-28), +8 / +23%, level 3 +13…+25% on seven of eight frames (BENCHMARKS.md
/// "Correlated noise on video"). Tolerances: each frame within 25%; level 2's median
/// within 10%, level 3's within 18% (the previous choice fails it).
#[test]
fn white_noise_coarse_levels_against_the_aligned_previous_frame() {
    check("white", [0.2445, 0.436, 0.493], 55..63, 0.25, [0.05, 0.05, 0.10, 0.18]);
}

fn check(
    name: &str,
    ratios: [f32; NOISE_LEVELS - 1],
    frames: std::ops::Range<usize>,
    per_frame: f64,
    in_median: [f64; NOISE_LEVELS],
) {
    let (truth, frames) = fits(ratios, frames);
    let mut per_level = vec![vec![]; NOISE_LEVELS];
    let mut over_stated: Vec<f64> = vec![];
    for (k, (with, alone)) in frames.iter().enumerate() {
        over_stated.extend(error_over_stated(with, &level_errors(with, &truth)));
        over_stated.extend(error_over_stated(alone, &level_errors(alone, &truth)));
        assert!(with.present && alone.present, "{name}, frame {k}: noise present");
        let e = level_errors(with, &truth);
        println!(
            "{name}, frame {k}: with the neighbour {:?}, levels {:?} not identifiable; alone {:?}, levels {:?} not \
             identifiable",
            e.iter().map(|v| format!("{:+.1}%", 100.0 * v)).collect::<Vec<_>>(),
            derived(with),
            level_errors(alone, &truth).iter().map(|v| format!("{:+.1}%", 100.0 * v)).collect::<Vec<_>>(),
            derived(alone)
        );
        for (l, v) in e.iter().enumerate() {
            assert!(v.abs() <= per_frame, "{name}, frame {k}, level {l}: {:+.1}%", 100.0 * v);
            per_level[l].push(*v);
        }
        let e0 = level_errors(alone, &truth)[0];
        assert!(e0.abs() <= 0.10, "{name}, frame {k}: alone, level 0 {:+.1}%", 100.0 * e0);
        if name != "white" {
            assert!(derived(with).is_empty(), "{name}, frame {k}: every level measured; {}", with.diagnostics.reason);
            let d = derived(alone);
            assert!(d.contains(&2) && d.contains(&3), "{name}, frame {k}: alone, levels {d:?} not identifiable");
            // A level 1 it measured stood on a few dark bins here (luma 0.10–0.22 of
            // 0.10–0.71, reading −9…−28% in median): the reason must say so.
            if !d.contains(&1) {
                let r = &alone.diagnostics.reason;
                assert!(r.contains("level 1 measured over luma"), "{name}, frame {k}: alone, level 1's lumas: {r}");
            }
        }
    }
    for (l, v) in per_level.into_iter().enumerate() {
        let m = median(v);
        assert!(m.abs() <= in_median[l], "{name}, level {l}: median {:+.1}%", 100.0 * m);
    }
    // Each measured level's stated error (`LevelSource::Measured`) covers its error:
    // within 2 stated errors (95% of a normal error) on at least 90% of the (frame,
    // fit, level) readings. Measured: all 82 here; over 16 runs (these spectra and a
    // low-passed one, 640×480 and the worker's strips at 1280×960, frames 55–62 and
    // 100–107; BENCHMARKS.md "The blind noise's level sources") 4 of 725 lie beyond. 90%, not 95%: the
    // residue priors were read on this clip's frames 55–62, and a set of 16–40
    // readings may hold a few beyond by chance.
    let within = over_stated.iter().filter(|&&r| r <= 2.0).count();
    println!("{name}: measured levels within 2 stated errors: {within} of {}", over_stated.len());
    assert!(
        within as f64 >= 0.9 * over_stated.len() as f64,
        "{name}: measured levels within 2 stated errors: {within} of {} ({over_stated:.2?})",
        over_stated.len()
    );
}

/// The estimator itself on correlated noise: a texture-free ramp (luma 0.1–0.9) under
/// sensor noise whose every pixel is white noise low-passed by a Gaussian of std s
/// (correlated within each band too, as a demosaic's), one frame, no neighbour. The
/// truth per level is the low-passed field's own band stds (measured on 768²).
/// Measured 2026-11-28: levels 0–2 within −1.2…+0.2% at s 0 / 0.5 / 0.7 / 1 px, level
/// 3 −4.9…−6.9%. Tolerance: 3% at levels 0–2 (a frame's sampling and 8-bit
/// quantisation), 10% at level 3 (80×60 px). So the frame alone's misses on video
/// are the scene's, not the estimator's: its medians are calibrated on white noise
/// (`white_noise_median_to_mean`), and correlated noise does not move them here.
#[test]
fn one_frame_without_texture_reads_low_passed_noise_per_level() {
    let (w, h) = (640usize, 480usize);
    let ramp = Plane::from_vec(w, h, (0..w * h).map(|i| 0.1 + 0.8 * (i % w) as f32 / w as f32).collect());
    let (a, b) = ([3e-5f32, 2e-5, 5e-5], [6e-4f32, 4e-4, 9e-4]);
    let white = |w: usize, h: usize, c: u32, seed: u64| {
        Plane::from_vec(
            w,
            h,
            (0..w * h).map(|i| blind_augment::synth::gaussian((i % w) as u32, (i / w) as u32, c, seed)).collect(),
        )
    };
    let opts = FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
        ..Default::default()
    };
    for s in [0.5f32, 0.7, 1.0] {
        let k = discrete_gaussian_kernel(s * s);
        // Unit-variance low-passed noise's band stds.
        let big = blur_separable(&white(768, 768, 0, 77), &k);
        let norm = (big.data.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / big.data.len() as f64).sqrt();
        let unit: Vec<f64> = laplacian_pyramid(&big, NOISE_LEVELS)
            .bands
            .iter()
            .map(|band| {
                (band.data.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / band.data.len() as f64).sqrt() / norm
            })
            .collect();
        let planes: [Plane; 3] = std::array::from_fn(|c| {
            let n = blur_separable(&white(w, h, c as u32, 9), &k);
            let data = ramp
                .data
                .iter()
                .zip(&n.data)
                .map(|(&y, &v)| {
                    let noisy = y as f64 + ((a[c] + b[c] * y) as f64).sqrt() * v as f64 / norm;
                    ((noisy.clamp(0.0, 1.0) * 255.0).round() / 255.0) as f32
                })
                .collect();
            Plane::from_vec(w, h, data)
        });
        let n = fit(&FitInputs::new(&Rgb::from_planes(planes)), &opts).expect("fit").model.noise;
        let [lo, hi] = n.luminance_range;
        for (l, unit_l) in unit.iter().enumerate() {
            let e = median(
                (0..27)
                    .map(|k| {
                        let (y, c) = (lo + (hi - lo) * ((k / 3) as f32 + 0.5) / 9.0, k % 3);
                        n.levels[l].std(n.form, c, y) as f64 / (((a[c] + b[c] * y) as f64).sqrt() * unit_l) - 1.0
                    })
                    .collect(),
            );
            println!("low-passed by {s} px, level {l}: {:+.1}%", 100.0 * e);
            let tol = if l < 3 { 0.03 } else { 0.10 };
            assert!(e.abs() <= tol, "low-passed by {s} px, level {l}: {:+.1}%; {}", 100.0 * e, n.diagnostics.reason);
        }
    }
}
