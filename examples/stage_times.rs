//! Per-effect fit times (from each fit's own `fit_time_s`, single thread) at
//! 1280×960, for profiling the fast tier between `cargo bench` runs.
#[path = "../tests/common/mod.rs"]
mod common;

use blind_augment::fit::{fit, FitInputs, FitOptions, Tier};
use blind_augment::image::{Flow, Plane};
use blind_augment::model::DepthUnits;

fn main() {
    // `NO_ALLOC_TUNING=1`: the C allocator's defaults (for the before/after figure).
    if !std::env::var("NO_ALLOC_TUNING").is_ok_and(|v| v == "1") {
        println!("allocator: {:?}", blind_augment::alloc::keep_freed_blocks());
    }
    let (w, h) = (1280usize, 960usize);
    let clean = common::mirror_tile(&common::photo("astronaut.png"), w, h);
    // `BENCH=1`: `benches/fit.rs`'s fast_all_effects frame (thin-lens ramp, head
    // flow ~8 px/frame at λ 0.5, white sensor noise, 8-bit); otherwise the clean
    // photograph at one depth under uniform flow.
    let (img, depth, flow) = if std::env::var("BENCH").is_ok_and(|v| v == "1") {
        let (depth, dof) = common::thin_lens_ramp(w, h);
        let flow = common::flow_field(w, h, 8.0);
        let mut truth = blind_augment::model::CameraModel::empty(w as u32, h as u32);
        truth.depth_of_field = dof;
        truth.noise = blind_augment::synth::white_sensor_noise([2e-5; 3], [8e-4; 3], [0.0, 1.0]);
        truth.motion_blur.present = true;
        truth.motion_blur.exposure = Some(0.5);
        let all = blind_augment::synth::apply_camera_model(&clean, &truth, Some(&depth), Some(&flow), 1);
        (common::quantize8(&all), depth, flow)
    } else if std::env::var("DISC").is_ok_and(|v| v == "1") {
        // `DISC=1`: the photograph at one depth under a uniform disc defocus (σ 2 px,
        // second moment), noise, 8-bit — the frame whose δ the spectrum answers alone.
        use blind_augment::model::*;
        let depth = Plane::new(w, h, 2.0);
        let mut truth = CameraModel::empty(w as u32, h as u32);
        truth.depth_of_field = DepthOfField {
            present: true,
            units: DepthUnits::MetricM,
            curve: Some(DofCurve::Constant { c: 2.0 }),
            depth_range: [2.0, 2.0],
            kernel: DofKernel::Disc,
            diagnostics: Diagnostics::not_fitted("truth"),
        };
        truth.noise = blind_augment::synth::white_sensor_noise([2e-5; 3], [8e-4; 3], [0.0, 1.0]);
        let all = blind_augment::synth::apply_camera_model(&clean, &truth, Some(&depth), None, 1);
        (common::quantize8(&all), depth, Flow::uniform(w, h, 6.0, 2.0))
    } else {
        (clean, Plane::new(w, h, 2.0), Flow::uniform(w, h, 6.0, 2.0))
    };
    // `NEIGHBOUR=1`: the noise fit with an aligned neighbour (the frame itself,
    // all valid: the cost is the same as with another exposure).
    let valid = Plane::new(w, h, 1.0);
    let with_neighbour = std::env::var("NEIGHBOUR").is_ok_and(|v| v == "1");
    let inp = FitInputs {
        depth: Some(&depth),
        depth_units: DepthUnits::MetricM,
        flow: Some(&flow),
        neighbour: with_neighbour.then_some(blind_augment::fit::Neighbour { image: &img, valid: &valid }),
        ..FitInputs::new(&img)
    };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
    // `ITERS=n` fits (3 by default; more for `perf record`).
    let iters: usize = std::env::var("ITERS").ok().and_then(|v| v.parse().ok()).unwrap_or(3);
    // `EFFORT=e`: `FitOptions::fast_effort` (1 by default).
    let fast_effort: f32 = std::env::var("EFFORT").ok().and_then(|v| v.parse().ok()).unwrap_or(1.0);
    for _ in 0..iters {
        let t = std::time::Instant::now();
        let out = pool
            .install(|| {
                fit(&inp, &FitOptions { tier: Some(Tier::Fast), effects: effects(), fast_effort, ..Default::default() })
            })
            .expect("fit");
        let m = &out.model;
        println!(
            "total {:.1} ms (λ {:?} ± {:?})",
            t.elapsed().as_secs_f64() * 1e3,
            m.motion_blur.exposure,
            m.motion_blur.diagnostics.stderr
        );
        for (name, d) in [
            ("noise", &m.noise.diagnostics),
            ("mb", &m.motion_blur.diagnostics),
            ("dof", &m.depth_of_field.diagnostics),
        ] {
            let stages: Vec<String> = d.stages_s.iter().map(|(k, v)| format!("{k} {:.1}", v * 1e3)).collect();
            println!(
                "  {name}: {:.1} ms [{}] {:?} n={}",
                d.fit_time_s * 1e3,
                stages.join(", "),
                d.status,
                d.samples_used
            );
            // `REASON=1`: each fit's reason too.
            if std::env::var("REASON").is_ok_and(|v| v == "1") {
                println!("    {}", d.reason);
            }
        }
    }
}

/// `ONLY=noise|mb|dof` profiles one effect.
fn effects() -> blind_augment::fit::Effects {
    let only = std::env::var("ONLY").unwrap_or_default();
    let all = only.is_empty();
    blind_augment::fit::Effects {
        noise: all || only == "noise",
        motion_blur: all || only == "mb",
        depth_of_field: all || only == "dof",
    }
}
