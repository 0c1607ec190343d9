//! GPU effect passes on the local Vulkan device (lavapipe in CI-class machines):
//! GPU time from timestamp queries (dispatches only, no uploads/readbacks) at the
//! Quest 3 default eye size (1680×1760) and at 2064×2208, next to the CPU twin's
//! wall time on all threads. Median of 3 runs after a warm-up. Prints Markdown for
//! BENCHMARKS.md. Run: `cargo bench --bench gpu` (part of `cargo xtask bench`).
//! Without a device it prints why and exits successfully.

#[path = "../tests/common/mod.rs"]
mod common;

use blind_augment::gpu::{GpuContext, GpuOptions};
use blind_augment::model::*;
use blind_augment::render::{DofPass, GrainPass, GrainTable, MotionBlurPass};
use blind_augment::synth::{self, SynthesisTable};
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// (GPU ms, CPU-twin ms), medians of 3 after one warm-up run of each.
fn measure(ctx: &GpuContext, gpu: impl Fn(), cpu: impl Fn()) -> (f64, f64) {
    gpu();
    let g: Vec<f64> = (0..3)
        .map(|_| {
            ctx.set_timing(true);
            gpu();
            let ms = ctx.gpu_time_ms();
            ctx.set_timing(false);
            ms
        })
        .collect();
    cpu();
    let c: Vec<f64> = (0..3)
        .map(|_| {
            let t = Instant::now();
            cpu();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    (median(g), median(c))
}

fn main() {
    let ctx = match GpuContext::new(&GpuOptions { validation: false, prefer_device: None }) {
        Ok(c) if c.has_timestamps() => c,
        Ok(c) => return println!("{}: no timestamp queries; GPU benchmark skipped", c.device_name()),
        Err(e) => return println!("no Vulkan device ({e}); GPU benchmark skipped"),
    };
    let photo = common::photo("astronaut.png");
    println!("### GPU effect passes on {}\n", ctx.device_name());
    println!("| pass | eye size | GPU (timestamps) | CPU twin, all threads |\n|---|---|---|---|");
    let mb = MotionBlurPass::new(&ctx).expect("pipeline");
    let dof = DofPass::new(&ctx).expect("pipelines");
    let grain = GrainPass::new(&ctx).expect("pipelines");
    let noise = synth::white_sensor_noise([2e-5; 3], [8e-4; 3], [0.02, 0.98]);
    let t = SynthesisTable::new(&noise);
    let table = GrainTable { luma_range: t.luma_range(), nodes: t.nodes() as u32, weights: t.weights_flat() };
    let dof_model = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::ThinLens { k: 3.0, focus_depth: 1.2, c0: 0.3 }),
        depth_range: [0.5, 4.0],
        kernel: blind_augment::model::DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("bench"),
    };
    for (w, h) in [(1680usize, 1760usize), (2064, 2208)] {
        let img = common::mirror_tile(&photo, w, h);
        let planar: Vec<f32> = img.channels.iter().flatten().copied().collect();
        let flow = common::flow_field(w, h, 8.0);
        let flow_xy: Vec<f32> = flow.dx.iter().zip(&flow.dy).flat_map(|(&x, &y)| [x, y]).collect();
        let sigma = synth::dof_sigma_map(&common::depth_ramp(w, h, 0.5, 4.0), &dof_model);
        let luma = img.luma();
        let size = format!("{w}×{h}");
        let (g, c) = measure(
            &ctx,
            || drop(mb.run(w, h, &planar, &flow_xy, 0.5).expect("mb")),
            || drop(synth::add_motion_blur(&img, &flow, 0.5)),
        );
        println!("| motion blur (λ = 0.5, 8 px/frame) | {size} | {g:.2} ms | {c:.1} ms |");
        let (g, c) = measure(
            &ctx,
            || drop(dof.run(w, h, &planar, &sigma.data).expect("dof")),
            || drop(synth::add_defocus(&img, &sigma)),
        );
        println!("| depth of field (σ ≤ 2.6 px) | {size} | {g:.2} ms | {c:.1} ms |");
        let (g, c) = measure(
            &ctx,
            || drop(grain.run(w, h, &luma.data, &table, 1).expect("grain")),
            || drop(synth::noise_field(&luma, &noise, 1)),
        );
        println!("| grain (4 levels + low-pass) | {size} | {g:.2} ms | {c:.1} ms |");
    }
}
