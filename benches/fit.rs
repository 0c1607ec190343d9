//! Fit benchmarks: each estimator at 512×512 and at 1280×960 (Quest 3 passthrough
//! camera frame), single-threaded and on all threads. Inputs are the vendored
//! astronaut photograph (mirror-tiled to 1280×960) with known synthetic distortions.
//! Run: `cargo bench --bench fit` (or `cargo xtask bench`); figures in BENCHMARKS.md.

#[path = "../tests/common/mod.rs"]
mod common;

use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Tier};
use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::model::*;
use blind_augment::synth;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use std::time::Duration;

struct Case {
    name: String,
    clean: Rgb,
    noisy: Rgb,
    blurred_mb: Rgb,
    blurred_dof: Rgb,
    all: Rgb,
    depth: Plane,
    flow: Flow,
}

fn case(w: usize, h: usize) -> Case {
    let clean = common::mirror_tile(&common::photo("astronaut.png"), w, h);
    // The thin-lens ramp (σ up to 3.8 px near) and head-motion flow (~8 px/frame).
    let (depth, dof) = common::thin_lens_ramp(w, h);
    let flow = common::flow_field(w, h, 8.0);
    let mut truth = CameraModel::empty(w as u32, h as u32);
    truth.depth_of_field = dof;
    truth.noise = synth::white_sensor_noise([2e-5; 3], [8e-4; 3], [0.0, 1.0]);
    truth.motion_blur =
        MotionBlur { present: true, exposure: Some(0.5), diagnostics: Diagnostics::not_fitted("truth") };
    let q = |i: &Rgb| i.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
    Case {
        name: format!("{w}x{h}"),
        noisy: q(&synth::add_noise(&clean, &truth.noise, 1)),
        blurred_mb: q(&synth::add_motion_blur(&clean, &flow, 0.5)),
        blurred_dof: q(&synth::add_dof(&clean, &depth, &truth.depth_of_field)),
        all: q(&synth::apply_camera_model(&clean, &truth, Some(&depth), Some(&flow), 1)),
        clean,
        depth,
        flow,
    }
}

fn inputs<'a>(c: &'a Case, image: &'a Rgb) -> FitInputs<'a> {
    FitInputs { depth: Some(&c.depth), flow: Some(&c.flow), ..FitInputs::new(image) }
}

fn only(noise: bool, mb: bool, dof: bool, tier: Tier) -> FitOptions {
    FitOptions {
        tier: Some(tier),
        effects: Effects { noise, motion_blur: mb, depth_of_field: dof },
        ..Default::default()
    }
}

fn bench(cr: &mut Criterion) {
    // As the app's binaries run (`blind_augment::alloc`): freed planes stay mapped.
    blind_augment::alloc::keep_freed_blocks();
    let single = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("1-thread pool");
    let all = rayon::ThreadPoolBuilder::new().build().expect("default pool");
    let threads = all.current_num_threads();
    for (w, h) in [(512usize, 512usize), (1280, 960)] {
        let c = case(w, h);
        let mut g = cr.benchmark_group(format!("fit_{}", c.name));
        g.sample_size(20).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
        // Every benchmarked fit must succeed: timing an early error would be a lie.
        for (pool_name, pool) in [("1thread", &single), ("all_threads", &all)] {
            let label = if pool_name == "1thread" { pool_name.to_string() } else { format!("{threads}threads") };
            g.bench_function(BenchmarkId::new("noise_accurate", &label), |b| {
                let inp = FitInputs { denoised: Some(&c.clean), ..inputs(&c, &c.noisy) };
                b.iter(|| pool.install(|| fit(&inp, &only(true, false, false, Tier::Accurate)).expect("fit")))
            });
            g.bench_function(BenchmarkId::new("motion_blur_accurate", &label), |b| {
                let inp = FitInputs { motion_deblurred: Some(&c.clean), ..inputs(&c, &c.blurred_mb) };
                b.iter(|| pool.install(|| fit(&inp, &only(false, true, false, Tier::Accurate)).expect("fit")))
            });
            g.bench_function(BenchmarkId::new("dof_accurate", &label), |b| {
                let inp = FitInputs { defocus_deblurred: Some(&c.clean), ..inputs(&c, &c.blurred_dof) };
                b.iter(|| pool.install(|| fit(&inp, &only(false, false, true, Tier::Accurate)).expect("fit")))
            });
            g.bench_function(BenchmarkId::new("fast_all_effects", &label), |b| {
                let inp = inputs(&c, &c.all);
                b.iter(|| pool.install(|| fit(&inp, &only(true, true, true, Tier::Fast)).expect("fit")))
            });
            // The fast tier at half effort (`FitOptions::fast_effort`; its accuracy:
            // BENCHMARKS.md "The fast tier's effort"), one thread.
            if pool_name == "1thread" {
                g.bench_function(BenchmarkId::new("fast_all_effects_effort_0.5", &label), |b| {
                    let inp = inputs(&c, &c.all);
                    let opts = FitOptions { fast_effort: 0.5, ..only(true, true, true, Tier::Fast) };
                    b.iter(|| pool.install(|| fit(&inp, &opts).expect("fit")))
                });
            }
        }
        g.finish();
    }
}

/// The fast tier at 1280×960, all three effects, one thread: median wall time of 11
/// fits and each effect's stage timers (`diagnostics.stages_s`, medians), as a
/// markdown table for BENCHMARKS.md (target: ≤ 30 ms).
fn fast_stages(_: &mut Criterion) {
    blind_augment::alloc::keep_freed_blocks();
    let single = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("1-thread pool");
    let c = case(1280, 960);
    let inp = inputs(&c, &c.all);
    let opts = only(true, true, true, Tier::Fast);
    let mut totals = vec![];
    let mut stages: std::collections::BTreeMap<(usize, String), Vec<f64>> = Default::default();
    for _ in 0..11 {
        let t = std::time::Instant::now();
        let m = single.install(|| fit(&inp, &opts).expect("fit")).model;
        totals.push(t.elapsed().as_secs_f64() * 1e3);
        for (e, d) in
            [&m.noise.diagnostics, &m.motion_blur.diagnostics, &m.depth_of_field.diagnostics].into_iter().enumerate()
        {
            for (k, v) in &d.stages_s {
                stages.entry((e, k.clone())).or_default().push(v * 1e3);
            }
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let total = median(&mut totals);
    println!("\n### fast tier, 1280×960, all three effects, 1 thread: median {total:.1} ms of 11 fits\n");
    let mb = single.install(|| fit(&inp, &opts).expect("fit")).model.motion_blur;
    println!("motion blur (truth λ 0.5): {}…\n", mb.diagnostics.reason.chars().take(160).collect::<String>());
    println!("| effect | stage | median | share of the total |\n|---|---|---|---|");
    for ((e, k), v) in stages.iter_mut() {
        let ms = median(v);
        let name = ["noise", "motion blur", "depth of field"][*e];
        println!("| {name} | {k} | {ms:.1} ms | {:.0}% |", 100.0 * ms / total);
    }
}

/// The fast tier's blind exposure at 1280×960 where it falls back past the streak's
/// zeros under a uniform flow, so the derivative autocorrelation's shape runs
/// (`fit::motion_blur::acf_shape`): astronaut, a 20 px streak at 30° (40 px/frame, λ
/// 0.5), 3 DN of noise, 8-bit; one thread, median stage times of 11 fits and the
/// reason's first words (which path answered).
fn fast_mb_uniform_flow(_: &mut Criterion) {
    blind_augment::alloc::keep_freed_blocks();
    let single = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("1-thread pool");
    let (w, h) = (1280, 960);
    let clean = common::mirror_tile(&common::photo("astronaut.png"), w, h);
    let a = 30f32.to_radians();
    let flow = Flow::uniform(w, h, 40.0 * a.cos(), 40.0 * a.sin());
    let noise = synth::white_sensor_noise([1.4e-4; 3], [0.0; 3], [0.0, 1.0]);
    let frame = synth::add_noise(&synth::add_motion_blur(&clean, &flow, 0.5), &noise, 3)
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
    let inp = FitInputs { flow: Some(&flow), ..FitInputs::new(&frame) };
    let opts = only(false, true, false, Tier::Fast);
    let mut totals = vec![];
    let mut stages: std::collections::BTreeMap<String, Vec<f64>> = Default::default();
    let mut reason = String::new();
    for _ in 0..11 {
        let t = std::time::Instant::now();
        let m = single.install(|| fit(&inp, &opts).expect("fit")).model;
        totals.push(t.elapsed().as_secs_f64() * 1e3);
        for (k, v) in &m.motion_blur.diagnostics.stages_s {
            stages.entry(k.clone()).or_default().push(v * 1e3);
        }
        reason = m.motion_blur.diagnostics.reason.chars().take(110).collect();
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "\n### fast blind exposure, 1280×960, uniform flow, 1 thread: median {:.1} ms of 11 fits",
        median(&mut totals)
    );
    println!("{reason}…\n\n| stage | median |\n|---|---|");
    for (k, v) in stages.iter_mut() {
        println!("| {k} | {:.2} ms |", median(v));
    }
}

criterion_group!(benches, bench, fast_stages, fast_mb_uniform_flow);
criterion_main!(benches);
