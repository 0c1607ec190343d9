//! The blind DoF's Zhuo–Sim calibration tables simulated afresh (`measured.rs` stores
//! them; `UPDATE_TABLES=1 cargo test --lib measured_tables` rewrites it) and the test
//! holding the stored ones to the simulation.

use super::*;

/// Edge-spread function of a unit step at distance `d` (px) blurred by `kernel` of
/// second-moment std `sigma`: erf for the Gaussian; for the disc of radius R the
/// integral of its line-spread function (2/(πR²))·√(R² − t²).
fn edge_spread(kernel: DofKernel, d: f32, sigma: f32) -> f32 {
    if sigma < 1e-3 {
        return (d > 0.0) as u8 as f32;
    }
    match kernel {
        DofKernel::Gaussian => 0.5 * (1.0 + erf(d / (sigma * std::f32::consts::SQRT_2))),
        DofKernel::Disc => {
            let r = crate::model::kernels::disc_radius_px(sigma).max(1e-3);
            let t = (d / r).clamp(-1.0, 1.0);
            0.5 + (t * (1.0 - t * t).sqrt() + t.asin()) / std::f32::consts::PI
        }
    }
}

/// Abramowitz–Stegun 7.1.26 (|error| < 1.5e-7), enough for a calibration table.
fn erf(x: f32) -> f32 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let y = 1.0
        - (((((1.061_405_4 * t - 1.453_152_1) * t) + 1.421_413_8) * t - 0.284_496_74) * t + 0.254_829_6)
            * t
            * (-x * x).exp();
    y.copysign(x)
}

pub(super) fn measure_zhuo_sim_table(kernel: DofKernel) -> Vec<(f32, f32)> {
    let n = 96usize;
    let mut table = vec![];
    for i in 0..=220 {
        let sigma = i as f32 * 0.05;
        let mut raw_sum = 0.0;
        // Sub-pixel phases over the half-resolution grid's 2-px period.
        let phases: Vec<f32> = (0..8).map(|k| k as f32 * 0.25).collect();
        for &ph in &phases {
            // Step at n/2 + ph blurred by the kernel of std σ, sampled at pixel
            // centres.
            let data: Vec<f32> = (0..n).map(|x| edge_spread(kernel, x as f32 - (n as f32 / 2.0 + ph), sigma)).collect();
            let p = Plane::from_vec(n, 1, data);
            let re = Reblurred::new(reblur_half(&crate::image::reduce(&p)));
            let g = (1..n - 1).map(|x| 0.5 * (p.get(x + 1, 0) - p.get(x - 1, 0))).fold(0.0f32, f32::max);
            let g_re = (1..n - 1).map(|x| re.grad(x, 0).0).fold(0.0f32, f32::max);
            let r = g / g_re;
            raw_sum += ZS_SIGMA0 / (r * r - 1.0).max(1e-6).sqrt();
        }
        table.push((raw_sum / phases.len() as f32, sigma));
    }
    table
}

/// The stored Zhuo–Sim tables equal a fresh simulation (tolerance in
/// `crate::synth::measured_check::check`).
#[test]
fn measured_tables_fit_dof() {
    use crate::synth::measured_check::{check, Table};
    let table = |kernel: DofKernel, name: &'static str, doc: &'static str| {
        let fresh = measure_zhuo_sim_table(kernel);
        let flat = |t: &[(f32, f32)]| -> Vec<f64> { t.iter().flat_map(|&(a, b)| [a as f64, b as f64]).collect() };
        Table {
            name,
            ty: "[(f32, f32); 221]",
            doc,
            stored: flat(zhuo_sim_table(kernel)),
            fresh: flat(&fresh),
            literal: format!("{fresh:?}"),
        }
    };
    check(
        "src/fit/dof/measured.rs",
        "The blind defocus fit's Zhuo–Sim calibration tables (`blind.rs`), simulated once.",
        &[
            table(
                DofKernel::Gaussian,
                "ZHUO_SIM_GAUSSIAN",
                "/// `blind::tables::measure_zhuo_sim_table(Gaussian)`: (raw estimate, true σ px) pairs.",
            ),
            table(
                DofKernel::Disc,
                "ZHUO_SIM_DISC",
                "/// `blind::tables::measure_zhuo_sim_table(Disc)`: (raw estimate, true σ px) pairs.",
            ),
        ],
    );
}
