//! addDoF: depth-dependent Gaussian defocus with per-pixel std σ(p) = δ(Z(p)).
//!
//! A gather with each pixel's own kernel costs (6σ+1)² taps (3721 at σ = 10). We
//! instead build a blur stack with nodes σ_k = k·h (h = 0.25 px) by *cascading*
//! discrete-Gaussian blurs: S_{k+1} = T(σ_{k+1}² − σ_k²) * S_k, exact by the
//! semigroup law. A pixel with σ_k ≤ σ < σ_{k+1} takes the blend
//! (1−w)·S_k + w·S_{k+1} with w = (σ² − σ_k²)/(σ_{k+1}² − σ_k²), which makes the
//! blended kernel's variance exactly σ². Exact at σ = 0 (S_0 is the image) and at
//! every node; between nodes the kernel is a two-Gaussian mixture of the right
//! variance. Cost grows like σ_max^1.5, not σ_max².
//!
//! A disc kernel (`DofKernel::Disc`, a round aperture) is not separable and has no
//! semigroup law: `add_defocus_disc` gathers each pixel's own pixel-area-sampled
//! disc of radius `kernels::disc_radius_px(σ)` directly (clamp-to-edge, like the
//! Gaussian), with the Gaussian below `kernels::DISC_MIN_SIGMA_PX`.

use crate::image::{blur_separable, discrete_gaussian_kernel, Plane, Rgb};
use crate::model::kernels::{disc_radius_px, disc_tap, DISC_MIN_SIGMA_PX};
use crate::model::{DepthOfField, DofKernel, MAX_DOF_SIGMA_PX};
use rayon::prelude::*;

pub use crate::model::DOF_NODE_SPACING_PX;

/// Walk the stack of `plane` with nodes `k·spacing` up to `max_sigma`, calling
/// `visit(k, σ_k, σ_{k+1}, S_k, S_{k+1})` for each interval in order.
pub fn for_each_cascade_interval(
    plane: &Plane,
    spacing_px: f32,
    max_sigma_px: f32,
    mut visit: impl FnMut(usize, f32, f32, &Plane, &Plane),
) {
    let intervals = (max_sigma_px / spacing_px).ceil().max(1.0) as usize;
    let mut prev = plane.clone();
    for k in 0..intervals {
        let (s0, s1) = (k as f32 * spacing_px, (k + 1) as f32 * spacing_px);
        let next = blur_separable(&prev, &discrete_gaussian_kernel(s1 * s1 - s0 * s0));
        visit(k, s0, s1, &prev, &next);
        prev = next;
    }
}

/// Per-pixel σ map from depth through the model (0 where depth is invalid).
pub fn dof_sigma_map(depth: &Plane, dof: &DepthOfField) -> Plane {
    Plane::from_vec(depth.width, depth.height, depth.data.iter().map(|&z| dof.sigma_px(z)).collect())
}

/// Blur each pixel with its own σ from `sigma_px` (clamped to [0, MAX_DOF_SIGMA_PX]).
pub fn add_defocus(sharp: &Rgb, sigma_px: &Plane) -> Rgb {
    let sig: Vec<f32> =
        sigma_px.data.iter().map(|&s| if s.is_finite() { s.clamp(0.0, MAX_DOF_SIGMA_PX) } else { 0.0 }).collect();
    let max_sigma = sig.iter().cloned().fold(0.0f32, f32::max);
    if max_sigma == 0.0 {
        return sharp.clone();
    }
    let planes: Vec<Vec<f32>> = (0..3)
        .into_par_iter()
        .map(|c| {
            let src = sharp.plane(c);
            let mut out = src.data.clone();
            for_each_cascade_interval(&src, DOF_NODE_SPACING_PX, max_sigma, |_, s0, s1, a, b| {
                let (v0, v1) = (s0 * s0, s1 * s1);
                for (i, &s) in sig.iter().enumerate() {
                    // Half-open intervals; σ = 0 keeps the exact input.
                    if s > s0 && s <= s1 {
                        let w = (s * s - v0) / (v1 - v0);
                        out[i] = (1.0 - w) * a.data[i] + w * b.data[i];
                    }
                }
            });
            out
        })
        .collect();
    let mut it = planes.into_iter();
    let mut next = || it.next().unwrap_or_default();
    Rgb { width: sharp.width, height: sharp.height, channels: [next(), next(), next()] }
}

/// Blur each pixel with its own disc of second-moment std σ from `sigma_px`
/// (clamped to [0, MAX_DOF_SIGMA_PX]); σ below `DISC_MIN_SIGMA_PX` takes the
/// Gaussian of `add_defocus`. A gather: pixel p averages the image over its own
/// disc, weights = pixel-area coverage / πR² (mass 1 exactly, `kernels::disc_tap`).
pub fn add_defocus_disc(sharp: &Rgb, sigma_px: &Plane) -> Rgb {
    let sig: Vec<f32> =
        sigma_px.data.iter().map(|&s| if s.is_finite() { s.clamp(0.0, MAX_DOF_SIGMA_PX) } else { 0.0 }).collect();
    let small = Plane::from_vec(
        sigma_px.width,
        sigma_px.height,
        sig.iter().map(|&s| if s < DISC_MIN_SIGMA_PX { s } else { 0.0 }).collect(),
    );
    let mut out = add_defocus(sharp, &small);
    let (w, h) = (sharp.width, sharp.height);
    let rows: Vec<(usize, Vec<[f32; 3]>)> = (0..h)
        .into_par_iter()
        .filter_map(|y| {
            // Kernel cache per row: constant-depth regions reuse one kernel.
            let mut cached: (f32, Vec<(isize, isize, f32)>) = (f32::NAN, vec![]);
            let mut row = vec![];
            for x in 0..w {
                let s = sig[y * w + x];
                if s < DISC_MIN_SIGMA_PX {
                    continue;
                }
                if s.to_bits() != cached.0.to_bits() {
                    let r = disc_radius_px(s).ceil() as isize + 1;
                    let taps = (-r..=r)
                        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
                        .filter_map(|(dx, dy)| {
                            let k = disc_tap(dx as f32, dy as f32, 0.5, s);
                            (k > 0.0).then_some((dx, dy, k))
                        })
                        .collect();
                    cached = (s, taps);
                }
                let mut acc = [0.0f32; 3];
                for &(dx, dy, k) in &cached.1 {
                    let xs = (x as isize + dx).clamp(0, w as isize - 1) as usize;
                    let ys = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                    let i = ys * w + xs;
                    for (c, a) in acc.iter_mut().enumerate() {
                        *a += k * sharp.channels[c][i];
                    }
                }
                row.push(acc);
            }
            (!row.is_empty()).then_some((y, row))
        })
        .collect();
    for (y, row) in rows {
        let mut it = row.into_iter();
        for x in 0..w {
            if sig[y * w + x] >= DISC_MIN_SIGMA_PX {
                if let Some(acc) = it.next() {
                    for (c, a) in acc.iter().enumerate() {
                        out.channels[c][y * w + x] = *a;
                    }
                }
            }
        }
    }
    out
}

/// addDoF(I, δ, Z) with the model's kernel shape.
pub fn add_dof(sharp: &Rgb, depth: &Plane, dof: &DepthOfField) -> Rgb {
    if !dof.present {
        return sharp.clone();
    }
    let sigma = dof_sigma_map(depth, dof);
    match dof.kernel {
        DofKernel::Gaussian => add_defocus(sharp, &sigma),
        DofKernel::Disc => add_defocus_disc(sharp, &sigma),
    }
}
