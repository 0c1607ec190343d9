//! How far a model is from a known truth, one number per effect, as the tier
//! benchmarks, the calibration tests and the demo report state it:
//! * noise: the median over levels 0–3, R/G/B and luma 0.2…0.8 (clamped into each
//!   model's range) of |σ_fit / σ_true − 1|, σ the level's std (per level, signed:
//!   `noise_level_errors`);
//! * motion blur: |λ_fit − λ_true| (an absent effect reads λ = 0);
//! * depth of field: the RMS of δ_fit(Z) − δ_true(Z) over the given depths (px).

use super::{CameraModel, DepthOfField, Noise};

const LUMAS: [f32; 7] = [0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8];

/// Level `l`'s signed σ_fit / σ_true − 1 over R/G/B and `LUMAS` (each clamped into
/// its model's range), where the truth's std is positive.
fn level_ratio_errors(fit: &Noise, truth: &Noise, l: usize) -> Vec<f32> {
    let (lf, lt) = (&fit.levels[l], &truth.levels[l]);
    (0..3)
        .flat_map(|c| LUMAS.iter().map(move |&y| (c, y)))
        .filter_map(|(c, y)| {
            let yf = y.clamp(fit.luminance_range[0], fit.luminance_range[1]);
            let yt = y.clamp(truth.luminance_range[0], truth.luminance_range[1]);
            let (sf, st) = (lf.std(fit.form, c, yf), lt.std(truth.form, c, yt));
            (st > 0.0).then(|| sf / st - 1.0)
        })
        .collect()
}

/// The median of `v` (the upper middle of an even count); None when empty.
fn median_of(mut v: Vec<f32>) -> Option<f32> {
    v.sort_by(f32::total_cmp);
    v.get(v.len() / 2).copied()
}

/// Levels both models have, at most 4.
fn shared_levels(fit: &Noise, truth: &Noise) -> usize {
    fit.levels.len().min(truth.levels.len()).min(4)
}

/// Median relative error of the level stds; None if either side has no noise.
pub fn noise_relative_error(fit: &Noise, truth: &Noise) -> Option<f32> {
    if !fit.present || !truth.present {
        return None;
    }
    let errs = (0..shared_levels(fit, truth)).flat_map(|l| level_ratio_errors(fit, truth, l)).map(f32::abs);
    median_of(errs.collect())
}

/// Per level 0–3, the median over R/G/B and luma 0.2…0.8 (clamped as above) of the
/// signed σ_fit / σ_true − 1: which way each level is off (the demo report's table
/// beside `Noise::level_sources`). None if either side has no noise.
pub fn noise_level_errors(fit: &Noise, truth: &Noise) -> Option<Vec<f32>> {
    if !fit.present || !truth.present {
        return None;
    }
    (0..shared_levels(fit, truth)).map(|l| median_of(level_ratio_errors(fit, truth, l))).collect()
}

/// The noise headline: level-0 std of the green channel at luma 0.5 (clamped into
/// the model's range); None when noise is absent.
pub fn noise_headline(n: &Noise) -> Option<f32> {
    if !n.present || n.levels.is_empty() {
        return None;
    }
    let y = 0.5f32.clamp(n.luminance_range[0], n.luminance_range[1]);
    Some(n.levels[0].std(n.form, 1, y))
}

/// |λ_fit − λ_true|, absent effects as λ = 0.
pub fn exposure_error(fit: &CameraModel, truth: &CameraModel) -> f32 {
    (fit.motion_blur.exposure_or_zero() - truth.motion_blur.exposure_or_zero()).abs()
}

/// RMS of δ_fit − δ_true over `depths` (px); absent effects as δ = 0.
pub fn dof_rmse_px(fit: &DepthOfField, truth: &DepthOfField, depths: &[f32]) -> Option<f32> {
    dof_rmse_px_over_floor(fit, truth, depths, 0.0)
}

/// RMSE (px) of δ(Z) over `depths` against the truth composed with a blur the
/// frames carry besides it, `floor_px` (Gaussian std; variances add):
/// √(δ_truth² + floor²). For a synthetic video rendered from a photograph at a
/// magnification, the photograph's own pixel widens every edge
/// (`SequenceSpec::source_pixel_blur_px`); a blind estimator, which measures edge
/// widths, sees that blur as well.
pub fn dof_rmse_px_over_floor(fit: &DepthOfField, truth: &DepthOfField, depths: &[f32], floor_px: f32) -> Option<f32> {
    let d: Vec<f32> = depths.iter().copied().filter(|z| z.is_finite() && *z > 0.0).collect();
    if d.is_empty() {
        return None;
    }
    let s: f32 = d.iter().map(|&z| (fit.sigma_px(z) - truth.sigma_px(z).hypot(floor_px)).powi(2)).sum();
    Some((s / d.len() as f32).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_is_exact_against_itself_and_scaled_noise_reads_its_scale() {
        let n = crate::synth::white_sensor_noise([1e-4; 3], [1e-3; 3], [0.0, 1.0]);
        assert_eq!(noise_relative_error(&n, &n), Some(0.0));
        let mut m = n.clone();
        // Affine variance ×1.21 = std ×1.1.
        for l in &mut m.levels {
            l.slope.iter_mut().chain(l.intercept.iter_mut()).for_each(|v| *v *= 1.21);
        }
        let e = noise_relative_error(&m, &n).expect("both present");
        assert!((e - 0.1).abs() < 1e-4, "{e}");
        // Per level, signed: +10% at the three scaled levels (0 at the unscaled one),
        // 1/1.1 − 1 = −9.1% where the truth is the scaled one; f32 rounding only (1e-4).
        m.levels[3] = n.levels[3];
        let e = noise_level_errors(&m, &n).expect("both present");
        assert!(e[..3].iter().all(|v| (v - 0.1).abs() < 1e-4) && e[3].abs() < 1e-6, "{e:?}");
        let e = noise_level_errors(&n, &m).expect("both present");
        assert!((e[0] + 1.0 / 11.0).abs() < 1e-4, "{e:?}");
        assert_eq!(
            noise_level_errors(&crate::model::Noise::absent(crate::model::Diagnostics::not_fitted("x")), &n),
            None
        );
    }
}
