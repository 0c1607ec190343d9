//! The speed/accuracy trade of every fit setting, measured: for each setting, the
//! single-threaded median wall time of the fit (7 runs, 512×512 unless stated) next
//! to its error against known truth on the vendored photographs. Prints Markdown
//! tables for BENCHMARKS.md. Run: `cargo bench --bench quality`.

#[path = "../tests/common/mod.rs"]
mod common;

use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Tier};
use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::model::*;
use blind_augment::synth;
use std::time::Instant;

/// Median wall time (ms) of `f` over 7 runs on one thread, and its last result.
fn timed<T: Send>(pool: &rayon::ThreadPool, f: impl Fn() -> T + Sync) -> (f64, T) {
    let mut times = vec![];
    let mut last = None;
    for _ in 0..7 {
        let t = Instant::now();
        last = Some(pool.install(&f));
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(|a, b| a.total_cmp(b));
    (times[3], last.expect("ran"))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() {
    // As the app's binaries run (`blind_augment::alloc`): freed planes stay mapped.
    blind_augment::alloc::keep_freed_blocks();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
    let img = common::photo("astronaut.png");
    let (w, h) = (img.width, img.height);

    // Noise: stride of the sample grid.
    let (a, b) = ([2e-5f32, 1.2e-5, 4e-5], [8e-4f32, 5e-4, 1.2e-3]);
    let y = img.luma();
    let mut noisy = img.clone();
    for c in 0..3 {
        for i in 0..img.len() {
            let s = (a[c] + b[c] * y.data[i]).sqrt();
            noisy.channels[c][i] += s * synth::gaussian((i % w) as u32, (i / w) as u32, c as u32 + 10, 5);
        }
    }
    println!("### Noise (accurate): sample stride at level 0\n\n| noise_stride_px | stride used at 512² | median rel. error of synth std | max | time ms |\n|---|---|---|---|---|");
    for stride in [32usize, 16, 8, 4] {
        let opts = FitOptions {
            noise_stride_px: stride,
            effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
            ..Default::default()
        };
        let inp = FitInputs { denoised: Some(&img), ..FitInputs::new(&noisy) };
        let (ms, out) = timed(&pool, || fit(&inp, &opts).expect("fit"));
        let n = &out.model.noise;
        let mut errs = vec![];
        for k in 0..9 {
            let yy = n.luminance_range[0] + (n.luminance_range[1] - n.luminance_range[0]) * (k as f32 + 0.5) / 9.0;
            let f = synth::noise_field(&Plane::new(256, 256, yy), n, 77);
            for c in 0..3 {
                let s = (f.channels[c].iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / 65536.0).sqrt();
                errs.push((s / ((a[c] + b[c] * yy) as f64).sqrt() - 1.0).abs());
            }
        }
        let max = errs.iter().cloned().fold(0.0, f64::max);
        let used = blind_augment::fit::effective_noise_stride(img.len(), stride);
        println!("| {stride} | {used} | {:.2}% | {:.2}% | {ms:.1} |", 100.0 * median(errs), 100.0 * max);
    }

    // Motion blur: pixel budget.
    let mut flow = Flow::uniform(w, h, 0.0, 0.0);
    for yy in 0..h {
        for x in 0..w {
            flow.dx[yy * w + x] = 8.0 * (0.8 - 0.9 * (yy as f32 / h as f32 - 0.5));
            flow.dy[yy * w + x] = 8.0 * (0.3 + 0.9 * (x as f32 / w as f32 - 0.5));
        }
    }
    let lambdas = [0.1f32, 0.3, 0.5, 0.7, 0.9];
    let blurred: Vec<Rgb> =
        lambdas.iter().map(|&l| common::quantize8(&synth::add_motion_blur(&img, &flow, l))).collect();
    println!("\n### Motion blur (accurate): pixel budget\n\n| max samples | median abs. λ error (λ = 0.1…0.9) | max | time ms |\n|---|---|---|---|");
    for budget in [2048usize, 4096, 8192, 16384, 32768] {
        let opts = FitOptions {
            mb_max_samples: budget,
            effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
            ..Default::default()
        };
        let mut errs = vec![];
        let mut times = vec![];
        for (l, bl) in lambdas.iter().zip(&blurred) {
            let inp = FitInputs { motion_deblurred: Some(&img), flow: Some(&flow), ..FitInputs::new(bl) };
            let (ms, out) = timed(&pool, || fit(&inp, &opts).expect("fit"));
            times.push(ms);
            errs.push((out.model.motion_blur.exposure.unwrap_or(f32::NAN) - l).abs() as f64);
        }
        let max = errs.iter().cloned().fold(0.0, f64::max);
        println!("| {budget} | {:.4} | {max:.4} | {:.1} |", median(errs), median(times));
    }

    // Depth of field: stack node spacing and pyramid handoff.
    let depth = common::depth_ramp(w, h, 0.5, 4.0);
    let curves = [
        ("mild (≤ 2.6 px)", DofCurve::ThinLens { k: 3.0, focus_depth: 1.2, c0: 0.3 }),
        ("strong (≤ 9.4 px)", DofCurve::ThinLens { k: 8.0, focus_depth: 0.7, c0: 0.0 }),
    ];
    let truths: Vec<DepthOfField> = curves
        .iter()
        .map(|(_, c)| DepthOfField {
            present: true,
            units: DepthUnits::MetricM,
            curve: Some(*c),
            depth_range: [0.5, 4.0],
            kernel: blind_augment::model::DofKernel::Gaussian,
            diagnostics: Diagnostics::not_fitted("truth"),
        })
        .collect();
    let mut frames: Vec<Rgb> = truths.iter().map(|t| common::quantize8(&synth::add_dof(&img, &depth, t))).collect();
    // The mild curve once more, made by the independent forward model (sampled
    // Gaussian layers every 0.1 px, tests/common/independent.rs): not synth's kernel.
    let mild_sigma = common::independent::sigma_map(&depth, |z| truths[0].sigma_px(z));
    frames.push(common::quantize8(&common::independent::layered_defocus(&img, &mild_sigma, 0.1)));
    println!(
        "\n### Depth of field (accurate): stack node spacing and pyramid handoff\n\n| node spacing px | pyramid from px | RMSE mild px | RMSE strong px | RMSE mild, Gaussian layers px | time ms (strong) |\n|---|---|---|---|---|---|"
    );
    for (spacing, handoff) in [
        (0.25f32, None),
        (0.5, None),
        (0.5, Some(5.0f32)),
        (0.5, Some(4.0)),
        (0.5, Some(3.0)),
        (1.0, Some(5.0)),
        (1.0, Some(3.0)),
    ] {
        let opts = FitOptions {
            dof_node_spacing_px: spacing,
            dof_pyramid_from_px: handoff,
            effects: Effects { noise: false, motion_blur: false, depth_of_field: true },
            ..Default::default()
        };
        let mut cells = vec![];
        let mut ms_strong = 0.0;
        for (i, fr) in frames.iter().enumerate() {
            let t = &truths[i % 2];
            let inp = FitInputs { defocus_deblurred: Some(&img), depth: Some(&depth), ..FitInputs::new(fr) };
            let (ms, out) = timed(&pool, || fit(&inp, &opts).expect("fit"));
            if i == 1 {
                ms_strong = ms;
            }
            let d = &out.model.depth_of_field;
            let [lo, hi] = d.depth_range;
            let rmse = ((0..=200)
                .map(|i| {
                    let z = lo + (hi - lo) * i as f32 / 200.0;
                    ((d.sigma_px(z) - t.sigma_px(z)) as f64).powi(2)
                })
                .sum::<f64>()
                / 201.0)
                .sqrt();
            cells.push(format!("{rmse:.4}"));
        }
        let hand = handoff.map_or("none (full res)".to_string(), |h| format!("{h}"));
        println!("| {spacing} | {hand} | {} | {} | {} | {ms_strong:.1} |", cells[0], cells[1], cells[2]);
    }

    // Where the time goes at the defaults: the fits' own stage timers (median of 7).
    println!("\n### Stage breakdown at the defaults (512×512, one thread, ms)\n\n| fit | blur | search | least squares | total |\n|---|---|---|---|---|");
    let fits: Vec<(&str, FitInputs, FitOptions)> = vec![
        (
            "noise, accurate",
            FitInputs { denoised: Some(&img), ..FitInputs::new(&noisy) },
            FitOptions {
                effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
                ..Default::default()
            },
        ),
        (
            "motion blur, accurate",
            FitInputs { motion_deblurred: Some(&img), flow: Some(&flow), ..FitInputs::new(&blurred[2]) },
            FitOptions {
                effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
                ..Default::default()
            },
        ),
        (
            "depth of field, accurate",
            FitInputs { defocus_deblurred: Some(&img), depth: Some(&depth), ..FitInputs::new(&frames[1]) },
            FitOptions {
                effects: Effects { noise: false, motion_blur: false, depth_of_field: true },
                ..Default::default()
            },
        ),
        (
            "noise, fast",
            FitInputs::new(&noisy),
            FitOptions {
                tier: Some(Tier::Fast),
                effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
                ..Default::default()
            },
        ),
        (
            "motion blur, fast",
            FitInputs { flow: Some(&flow), ..FitInputs::new(&blurred[2]) },
            FitOptions {
                tier: Some(Tier::Fast),
                effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
                ..Default::default()
            },
        ),
        (
            "depth of field, fast",
            FitInputs { depth: Some(&depth), ..FitInputs::new(&frames[1]) },
            FitOptions {
                tier: Some(Tier::Fast),
                effects: Effects { noise: false, motion_blur: false, depth_of_field: true },
                ..Default::default()
            },
        ),
    ];
    for (name, inp, opts) in fits {
        let mut runs: Vec<(f64, std::collections::BTreeMap<String, f64>)> = (0..7)
            .map(|_| {
                let m = pool.install(|| fit(&inp, &opts).expect("fit")).model;
                let d = [&m.noise.diagnostics, &m.motion_blur.diagnostics, &m.depth_of_field.diagnostics]
                    .into_iter()
                    .find(|d| d.status != Status::NotFitted)
                    .expect("one effect fitted")
                    .clone();
                (d.fit_time_s, d.stages_s)
            })
            .collect();
        runs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (total, stages) = &runs[3];
        // A stage "search" includes its sub-stages "search.<part>".
        let ms = |k: &str| {
            let mut parts =
                stages.iter().filter(|(n, _)| *n == k || n.strip_prefix(k).is_some_and(|r| r.starts_with('.')));
            let first = parts.next().map(|(_, v)| *v);
            first.map_or("–".to_string(), |f| format!("{:.1}", (f + parts.map(|(_, v)| v).sum::<f64>()) * 1e3))
        };
        println!("| {name} | {} | {} | {} | {:.1} |", ms("blur"), ms("search"), ms("least_squares"), total * 1e3);
    }
}
