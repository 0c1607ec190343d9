//! Probe: the blind noise fit on video whose sensor noise is spatially correlated
//! (demosaicing, in-camera denoising, a codec's quantisation make real noise decay
//! slower than white across the pyramid's levels). Per frame of the calibration video
//! (the Motorcycle along the head path), the fit with the previous frame aligned and
//! the frame alone, each level's median error against the truth over 9 lumas × 3
//! channels, and whether the fit measured or derived the level.
//! `cargo run --release --example correlated_noise_probe -- FROM TO WIDTH`. Options:
//! - `RATIOS=r1,r2,r3`: the truth's level std ratios 1/0, 2/1, 3/2 (default: the vtest
//!   clip's, 0.45,0.72,0.72; white noise's are about 0.24,0.44,0.49);
//! - `LOWPASS=s`: instead, white noise low-passed by a Gaussian of std s px added to
//!   each frame (correlated within each band too, as a demosaic's);
//! - `STRIP=rows`: a strip of that many full rows, the next one down per frame (the
//!   worker's way);
//! - `MISMATCH=1`: the previous frame's scene aligned without its noise, fresh noise
//!   added after (what the difference leaves of the scene);
//! - `PERFECT=1`: the frame's own scene with independent noise as the neighbour
//!   (`SHIFT=u,v`: that noise resampled at a sub-pixel offset);
//! - `REASON=1`: both fits' reasons;
//! - `SCENE=procedural`: a procedural texture of hard-edged shapes on the
//!   Motorcycle's depth instead of the photograph (a second scene);
//! - `SOURCES=1`: both fits' level sources (measured ± stated error, or continued),
//!   and how often a measured level's error lies within its stated error.
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::analysis::temporal::align;
use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Neighbour, Tier};
use blind_augment::image::Plane;
use blind_augment::model::{LevelSource, Noise, NOISE_LEVELS};
use blind_augment::synth::sequence::{motorcycle, procedural, SequenceFrame, SequenceSpec};
use common::analysed;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let from: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(55);
    let to: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(65);
    let w: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(320);
    let ratios: Vec<f32> = std::env::var("RATIOS")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .unwrap_or_else(|| vec![0.45, 0.72, 0.72]);
    let mut scene = motorcycle().expect("bundled scene");
    // SCENE=procedural: the Motorcycle's depth under a procedural texture of
    // hard-edged shapes (`synth::sequence::procedural`, as `calib_probe`'s): a
    // second scene for the priors read on the Motorcycle (`SOURCES=1`, `RESIDUE=1`).
    if std::env::var("SCENE").is_ok_and(|s| s == "procedural") {
        scene = procedural(&scene, (w / 320).max(1), 11);
    }
    let mut spec = SequenceSpec::motorcycle(&scene, w, w * 3 / 4, 150, None);
    let (a, b) = ([3e-5f32, 2e-5, 5e-5], [6e-4f32, 4e-4, 9e-4]);
    // LOWPASS=s: instead of synth's per-level grain (white within each band), the
    // camera's own kind of correlated noise: std √(a + b·Y) times white noise
    // low-passed by a Gaussian of std s px (normalised to unit variance), added to
    // each frame; the truth per level is that field's measured band stds.
    let lowpass: Option<f32> = std::env::var("LOWPASS").ok().and_then(|s| s.parse().ok());
    // The low-passed field's band stds and normalising std, measured once.
    let reference = lowpass.map(lowpass_band_stds);
    let truth = match lowpass.zip(reference) {
        Some((s, (u, norm))) => {
            let unit = blind_augment::synth::unit_band_std();
            let s0 = (u[0] / unit[0]).powi(2);
            let r: [f32; NOISE_LEVELS - 1] = std::array::from_fn(|l| u[l + 1] / u[l]);
            println!("low-passed white noise, s {s} px: band stds {u:?} (unit variance: ÷{norm:.4}), ratios {r:?}");
            blind_augment::synth::correlated_sensor_noise(a.map(|v| v * s0), b.map(|v| v * s0), [0.0, 1.0], r)
        }
        None => blind_augment::synth::correlated_sensor_noise(
            a,
            b,
            [0.0, 1.0],
            std::array::from_fn(|i| ratios[i.min(ratios.len() - 1)]),
        ),
    }
    .expect("RATIOS");
    spec.truth.noise = truth.clone();
    if lowpass.is_some() {
        spec.truth.noise.present = false;
    }
    let opts = FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
        ..Default::default()
    };
    // The frame, with the low-passed noise added where asked (8-bit, as the video).
    let frame = |i: usize| -> SequenceFrame {
        let mut f = spec.frame(&scene, i);
        if let Some((s, (_, norm))) = lowpass.zip(reference) {
            let mut model = f.truth.clone();
            model.noise.present = false;
            let clean = blind_augment::synth::apply_camera_model(&f.clean, &model, Some(&f.depth_m), Some(&f.flow), 0);
            let y = clean.luma();
            for c in 0..3 {
                let n = lowpass_field(f.image.width, f.image.height, s, c as u32, 1000 + i as u64);
                for (k, v) in f.image.channels[c].iter_mut().enumerate() {
                    let sd = (a[c] + b[c] * y.data[k].clamp(0.0, 1.0)).sqrt();
                    *v = ((clean.channels[c][k] + sd * n.data[k] / norm).clamp(0.0, 1.0) * 255.0).round() / 255.0;
                }
            }
        }
        f
    };
    let mut prev = analysed(&frame(from.saturating_sub(1)));
    // SOURCES=1: per level, measured frames whose median error lies within 1, 2, or
    // beyond 2 of the stated relative standard errors.
    let (mut cover_with, mut cover_alone) = ([[0usize; 3]; NOISE_LEVELS], [[0usize; 3]; NOISE_LEVELS]);
    let (mut with_all, mut alone_all) = (vec![vec![]; NOISE_LEVELS], vec![vec![]; NOISE_LEVELS]);
    for i in from..to {
        let fr = frame(i);
        let cur = analysed(&fr);
        let mut a = align(&prev, &cur, &spec.view).expect("poses and depth align");
        if std::env::var_os("MISMATCH").is_some() {
            // The previous frame's scene aligned, without its noise; fresh noise on it
            // (not interpolated): what is left is the scene's mismatch.
            let mut quiet = spec.clone();
            quiet.truth.noise.present = false;
            let p = quiet.frame(&scene, i - 1);
            let pa = analysed(&p);
            let a2 = align(&pa, &cur, &spec.view).expect("align");
            let noisy = blind_augment::synth::add_noise(&a2.image, &truth, 7000 + i as u64);
            a.image = noisy.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
            a.valid = a2.valid;
        }
        if std::env::var_os("PERFECT").is_some() {
            // The same frame's scene with independent noise, nothing interpolated.
            let mut model = fr.truth.clone();
            model.noise.present = false;
            let clean =
                blind_augment::synth::apply_camera_model(&fr.clean, &model, Some(&fr.depth_m), Some(&fr.flow), 0);
            let mut noisy = blind_augment::synth::add_noise(&clean, &truth, 5000 + i as u64);
            // SHIFT=u,v: the neighbour's noise (only) resampled at that sub-pixel offset.
            if let Some((u, v)) = std::env::var("SHIFT").ok().and_then(|s| {
                let mut it = s.split(',').filter_map(|t| t.parse::<f32>().ok());
                Some((it.next()?, it.next()?))
            }) {
                for c in 0..3 {
                    let n = Plane::from_vec(
                        clean.width,
                        clean.height,
                        noisy.channels[c].iter().zip(&clean.channels[c]).map(|(a, b)| a - b).collect(),
                    );
                    for y in 0..clean.height {
                        for x in 0..clean.width {
                            let k = y * clean.width + x;
                            noisy.channels[c][k] = clean.channels[c][k]
                                + blind_augment::image::sample_bicubic(&n, x as f32 + u, y as f32 + v);
                        }
                    }
                }
            }
            a.image = noisy.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
            a.valid.iter_mut().for_each(|v| *v = true);
        }
        // STRIP=rows: the worker's way at 1280×960 (`NOISE_STRIP_PX`): a strip of
        // full rows, the next one down per frame, the neighbour cropped alike.
        let h = w * 3 / 4;
        let rows: usize = std::env::var("STRIP").ok().and_then(|s| s.parse().ok()).unwrap_or(h).min(h);
        let y0 = ((i - from) * rows) % (h - rows + 1);
        let valid =
            Plane::from_vec(w, rows, a.valid[y0 * w..(y0 + rows) * w].iter().map(|&v| v as u8 as f32).collect());
        let crop = |img: &blind_augment::image::Rgb| img.crop(0, y0, w, rows).expect("strip inside the frame");
        let (image, nb) = (crop(&fr.image), crop(&a.image));
        let inp = FitInputs { neighbour: Some(Neighbour { image: &nb, valid: &valid }), ..FitInputs::new(&image) };
        let with = fit(&inp, &opts).expect("fit").model.noise;
        let alone = fit(&FitInputs::new(&image), &opts).expect("fit").model.noise;
        let (ew, ea) = (level_errors(&with, &truth), level_errors(&alone, &truth));
        for l in 0..NOISE_LEVELS {
            with_all[l].push(ew[l]);
            alone_all[l].push(ea[l]);
        }
        println!(
            "frame {i}: with the neighbour {} [{}]; alone {} [{}]",
            fmt(&ew),
            derived(&with),
            fmt(&ea),
            derived(&alone)
        );
        if std::env::var_os("SOURCES").is_some() {
            println!("  sources with: {}\n  sources alone: {}", sources(&with, &ew), sources(&alone, &ea));
            for (n, e, cov) in [(&with, &ew, &mut cover_with), (&alone, &ea, &mut cover_alone)] {
                for (l, src) in n.level_sources.iter().enumerate() {
                    if let LevelSource::Measured { relative_stderr, .. } = *src {
                        let k = (e[l].abs() / relative_stderr as f64).ceil().clamp(1.0, 3.0) as usize - 1;
                        cov[l][k] += 1;
                    }
                }
            }
        }
        if std::env::var_os("RESIDUE").is_some() {
            // The std the neighbour fit reads beyond the truth, √(read² − truth²) per
            // level at the range's mid luma (channel mean): an additive residue's size.
            // A continued level's is marked `c`.
            for (fit, name) in [(&with, "with"), (&alone, "alone")] {
                let ym = 0.5 * (fit.luminance_range[0] + fit.luminance_range[1]);
                let r: Vec<String> = (0..NOISE_LEVELS)
                    .map(|l| {
                        let (mut t, mut n) = (0.0f32, 0.0f32);
                        for c in 0..3 {
                            let (g, s) = (fit.levels[l].std(fit.form, c, ym), truth.levels[l].std(truth.form, c, ym));
                            t += (g * g - s * s).signum() * (g * g - s * s).abs().sqrt() / 3.0;
                            n += s / 3.0;
                        }
                        let c = if matches!(fit.level_sources.get(l), Some(LevelSource::Continued { .. })) {
                            "c"
                        } else {
                            ""
                        };
                        format!("{t:+.5}{c} (truth {n:.5})")
                    })
                    .collect();
                println!("  residue {name}: {}", r.join(" | "));
            }
        }
        if std::env::var_os("REASON").is_some() {
            println!("  with: {}\n  alone: {}", with.diagnostics.reason, alone.diagnostics.reason);
        }
        prev = cur;
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let summary =
        |all: &mut Vec<Vec<f64>>| all.iter_mut().map(|v| format!("{:+.1}%", 100.0 * med(v))).collect::<Vec<_>>();
    println!("median per level, with the neighbour: {:?}", summary(&mut with_all));
    println!("median per level, the frame alone:    {:?}", summary(&mut alone_all));
    if std::env::var_os("SOURCES").is_some() {
        println!("measured levels' errors within 1 / 2 / beyond 2 stated errors, with the neighbour: {cover_with:?}");
        println!("measured levels' errors within 1 / 2 / beyond 2 stated errors, the frame alone:    {cover_alone:?}");
    }
}

/// Each level's source as the fit wrote it, with its error: `M 3%±5%` (measured,
/// error, stated relative standard error) or `C0` (continued from level 0).
fn sources(n: &Noise, e: &[f64]) -> String {
    n.level_sources
        .iter()
        .zip(e)
        .map(|(s, e)| match *s {
            LevelSource::Measured { luma: [a, b], bins, relative_stderr } => {
                format!("M {:+.0}%±{:.0}% ({bins} bins {a:.2}–{b:.2})", 100.0 * e, 100.0 * relative_stderr)
            }
            LevelSource::Continued { from } => format!("C{from} {:+.0}%", 100.0 * e),
        })
        .collect::<Vec<_>>()
        .join(" | ")
}

/// Per level, the median signed relative error of the fitted std against the truth
/// over 9 lumas inside the fit's range × 3 channels.
fn level_errors(n: &Noise, t: &Noise) -> Vec<f64> {
    let [lo, hi] = n.luminance_range;
    (0..NOISE_LEVELS)
        .map(|l| {
            let mut e: Vec<f64> = (0..27)
                .map(|k| {
                    let (y, c) = (lo + (hi - lo) * ((k / 3) as f32 + 0.5) / 9.0, k % 3);
                    (n.levels[l].std(n.form, c, y) / t.levels[l].std(t.form, c, y) - 1.0) as f64
                })
                .collect();
            e.sort_by(f64::total_cmp);
            if n.present {
                e[13]
            } else {
                f64::NAN
            }
        })
        .collect()
}

fn fmt(e: &[f64]) -> String {
    e.iter().map(|v| format!("{:+.0}%", 100.0 * v)).collect::<Vec<_>>().join(" ")
}

/// The levels the fit's reason calls not identifiable (derived), as written there.
fn derived(n: &Noise) -> String {
    n.diagnostics
        .reason
        .split("levels [")
        .nth(1)
        .and_then(|t| t.split(']').next())
        .map_or("all measured".into(), |s| format!("derived {s}"))
}

/// White noise (seeded) low-passed by a Gaussian of std `s` px (not normalised).
fn lowpass_field(w: usize, h: usize, s: f32, c: u32, seed: u64) -> Plane {
    let white = Plane::from_vec(
        w,
        h,
        (0..w * h).map(|i| blind_augment::synth::gaussian((i % w) as u32, (i / w) as u32, c, seed)).collect(),
    );
    blind_augment::image::blur_separable(&white, &blind_augment::image::discrete_gaussian_kernel(s * s))
}

/// The band stds (levels 0..NOISE_LEVELS) of unit-variance low-passed white noise,
/// and the std of the low-passed field that normalises it (measured on 768²).
fn lowpass_band_stds(s: f32) -> ([f32; NOISE_LEVELS], f32) {
    let p = lowpass_field(768, 768, s, 0, 77);
    let norm = (p.data.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / p.data.len() as f64).sqrt() as f32;
    let pyr = blind_augment::image::laplacian_pyramid(&p, NOISE_LEVELS);
    (
        std::array::from_fn(|l| {
            let b = &pyr.bands[l];
            ((b.data.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / b.data.len() as f64).sqrt() as f32) / norm
        }),
        norm,
    )
}
