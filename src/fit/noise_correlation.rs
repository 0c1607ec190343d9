//! The camera noise's correlation from frame to frame (an ISP's motion-compensated
//! temporal noise reduction, TNR), estimated from the noise of frame differences
//! at several lags, and the factors that divide it out of difference-based fits.
//!
//! A fit that reads noise off `I_t − I_{t−k}` (the blind fit against an aligned
//! neighbour, the accurate fit against a mean of other frames) assumes the two
//! exposures' noise independent. Under TNR it is not: for a first-order
//! (autoregressive) correlation ρ per frame — what a recursive TNR filter
//! n_t = ρ·n_{t−1} + √(1 − ρ²)·e_t makes in motion-compensated coordinates —
//! Var(n_t − n_{t−k}) = 2σ²(1 − ρ^k), so the fit reads σ²(1 − ρ) at lag 1
//! (measured on the calibration video: the fast tier 26% low at ρ 0.5, 52% at 0.8;
//! BENCHMARKS.md "Temporally correlated noise"). The ratio of the difference's std
//! at lag k to the one at lag 1 is then
//!
//!   r_k = √((1 − ρ^k)/(1 − ρ)) = √(1 + ρ + … + ρ^{k−1}),
//!
//! free of σ, of the luminance mix and of the scene (the same pixels at both lags).
//! Two lags give ρ and a check of the first-order form: a stream whose lag ratios
//! no single ρ explains (a block codec copying noise between some frames and not
//! others: the DivX clip reads r_2 = 1.8, where ρ < 1 allows at most √2) is
//! reported not identifiable, and its difference-based fits are not to be trusted.

use crate::model::Status;

/// A ρ whose fit explains the lag ratios below this much is not divided out: its
/// correction (a variance ×1/(1 − ρ) ≤ 1.11) is within what the fast tier's noise
/// fit resolves (its published error 2–5% in std on the calibration video), while
/// the estimate's own bias at ρ = 0 (interpolation of a neighbour farther away)
/// would be divided in.
pub const MIN_RHO: f32 = 0.1;
/// Largest ρ reported: near 1 the correction 1/(1 − ρ) diverges, and a camera whose
/// noise is that persistent has no temporal noise to measure.
pub const MAX_RHO: f32 = 0.95;
/// Fewest ratios per lag for an estimate (their median and its standard error).
pub const MIN_RATIOS: usize = 5;
/// χ² (one degree of freedom per lag beyond the first) above which the first-order
/// form does not explain the lag ratios: 3 standard errors.
const MAX_CHI2_PER_DOF: f32 = 9.0;

/// Lag ratios measured at one lag: std of the frame difference at `lag` frames over
/// the std at lag 1, on the same pixels, one per probe.
#[derive(Clone, Debug)]
pub struct LagRatios<'a> {
    pub lag: u32,
    pub ratios: &'a [f32],
}

/// The estimate of ρ, with how sure it is.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseCorrelation {
    /// `Present`: ρ ≥ `MIN_RHO` and more than two standard errors from 0; `Absent`:
    /// identifiable and within that of 0 (ρ is then 0); `NotIdentifiable`: too few
    /// ratios, non-finite ones, or lag ratios no first-order ρ explains.
    pub status: Status,
    /// Correlation of the noise between consecutive frames (0 unless present).
    pub rho: f32,
    /// The fit's ρ before the presence test and its one-sigma error (None when not
    /// identifiable).
    pub rho_fitted: Option<f32>,
    pub stderr: Option<f32>,
    /// Ratios used, all lags together.
    pub samples: usize,
    /// The lag ratios were measured and no first-order correlation explains them
    /// (not identifiable for that reason, not for want of ratios): the noise is
    /// copied between frames in another way, and fits on frame differences are not
    /// to be trusted.
    pub inconsistent: bool,
    pub reason: String,
}

impl NoiseCorrelation {
    fn not_identifiable(samples: usize, reason: String) -> Self {
        Self {
            status: Status::NotIdentifiable,
            rho: 0.0,
            rho_fitted: None,
            stderr: None,
            samples,
            inconsistent: false,
            reason,
        }
    }
}

/// r_k(ρ) = √(1 + ρ + … + ρ^{k−1}): the lag-k over lag-1 std ratio of a first-order
/// correlation ρ.
pub fn lag_ratio(rho: f32, lag: u32) -> f32 {
    let mut sum = 0.0f64;
    let mut p = 1.0f64;
    for _ in 0..lag {
        sum += p;
        p *= rho as f64;
    }
    sum.sqrt() as f32
}

/// Var(n_t − n_{t−lag}) / (2σ²) = 1 − ρ^lag: what a fit of the difference's
/// variance halved reads per unit of true variance.
pub fn difference_variance_factor(rho: f32, lag: u32) -> f32 {
    1.0 - rho.powi(lag as i32)
}

/// Var(n_0 − mean_i n_{−k_i}) / σ² for the noise n_0 of this frame and the mean of
/// the frames `lags` back (each ≥ 1; lag 0 would be this frame), under a first-order
/// correlation ρ: 1 + (1/m²)·Σ_ij ρ^|k_i−k_j| − (2/m)·Σ_i ρ^k_i. With ρ = 0 it is
/// 1 + 1/m, the factor the accurate fit against a temporal mean already divides out.
pub fn mean_reference_variance_factor(rho: f32, lags: &[u64]) -> f32 {
    if lags.is_empty() {
        return 1.0;
    }
    let m = lags.len() as f64;
    let rho = rho as f64;
    let pow = |k: u64| rho.powi(k.min(i32::MAX as u64) as i32);
    let mut within = 0.0;
    for &a in lags {
        for &b in lags {
            within += pow(a.abs_diff(b));
        }
    }
    let across: f64 = lags.iter().map(|&k| pow(k)).sum();
    (1.0 + within / (m * m) - 2.0 * across / m) as f32
}

/// Median and its standard error (1.2533 · 1.4826 · MAD / √n: the median's
/// efficiency against the mean, the MAD's Gaussian scale).
fn median_se(v: &[f32]) -> (f32, f32) {
    let med = crate::fit::median(v.to_vec());
    let mad = crate::fit::median(v.iter().map(|x| (x - med).abs()).collect());
    (med, 1.2533 * 1.4826 * mad / (v.len() as f32).sqrt())
}

/// ρ from the lag ratios (lags ≥ 2; lag-1 ratios are 1 by definition and carry
/// nothing): per lag the median ratio and its standard error, then the ρ in
/// [−0.5, `MAX_RHO`] that minimises χ² = Σ_k ((m_k − r_k(ρ)) / s_k)² (a grid of
/// 0.001: the curve is smooth and one-dimensional), its standard error from the
/// curvature. The standard error per lag has a floor of 0.01 (the lag ratios'
/// interpolation bias at ρ = 0 is of that size), so a long window does not make a
/// bias significant.
pub fn noise_correlation(lags: &[LagRatios]) -> NoiseCorrelation {
    let samples: usize = lags.iter().map(|l| l.ratios.len()).sum();
    if let Some(l) = lags.iter().find(|l| l.lag < 2) {
        return NoiseCorrelation::not_identifiable(samples, format!("lag {} given: lags of 2 or more", l.lag));
    }
    if lags.iter().flat_map(|l| l.ratios).any(|r| !r.is_finite() || *r <= 0.0) {
        return NoiseCorrelation::not_identifiable(samples, "a lag ratio is not finite and positive".into());
    }
    let used: Vec<(u32, f32, f32)> = lags
        .iter()
        .filter(|l| l.ratios.len() >= MIN_RATIOS)
        .map(|l| {
            let (m, s) = median_se(l.ratios);
            (l.lag, m, s.max(0.01))
        })
        .collect();
    if used.is_empty() {
        return NoiseCorrelation::not_identifiable(
            samples,
            format!("fewer than {MIN_RATIOS} lag ratios at every lag ({samples} in all)"),
        );
    }
    let chi2 = |rho: f32| -> f32 { used.iter().map(|&(k, m, s)| ((m - lag_ratio(rho, k)) / s).powi(2)).sum() };
    let grid = (-500..=(MAX_RHO * 1000.0).round() as i32).map(|i| i as f32 * 1e-3);
    let (rho, best) = grid.map(|r| (r, chi2(r))).min_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or((0.0, f32::INFINITY));
    let medians: Vec<String> = used.iter().map(|(k, m, s)| format!("r_{k} {m:.3} ± {s:.3}")).collect();
    let medians = medians.join(", ");
    let dof = used.len().saturating_sub(1);
    if dof > 0 && best > MAX_CHI2_PER_DOF * dof as f32 {
        return NoiseCorrelation {
            inconsistent: true,
            ..NoiseCorrelation::not_identifiable(
                samples,
                format!(
                    "the lag ratios ({medians}) fit no first-order correlation (χ² {best:.1} at ρ {rho:.2}): the \
                     noise is copied between frames in another way (a codec?)"
                ),
            )
        };
    }
    if dof == 0 && best > MAX_CHI2_PER_DOF {
        // One lag: beyond what ρ ∈ [−0.5, MAX_RHO] can make.
        return NoiseCorrelation {
            inconsistent: true,
            ..NoiseCorrelation::not_identifiable(
                samples,
                format!("the lag ratio ({medians}) is beyond any first-order correlation up to ρ {MAX_RHO}"),
            )
        };
    }
    // Standard error from the curvature: 1/√(Σ (r_k'(ρ)/s_k)²).
    let h = 1e-3f32;
    let info: f32 =
        used.iter().map(|&(k, _, s)| ((lag_ratio(rho + h, k) - lag_ratio(rho - h, k)) / (2.0 * h) / s).powi(2)).sum();
    let se = 1.0 / info.max(1e-12).sqrt();
    let present = rho >= MIN_RHO && rho > 2.0 * se;
    NoiseCorrelation {
        status: if present { Status::Present } else { Status::Absent },
        rho: if present { rho } else { 0.0 },
        rho_fitted: Some(rho),
        stderr: Some(se),
        samples,
        inconsistent: false,
        reason: format!(
            "frame-to-frame noise correlation ρ {rho:.2} ± {se:.2} from {medians}{}",
            if present { "" } else { " (within noise of none, or below 0.1: not divided out)" }
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ratios scattered around the first-order model's, as a probe reads them.
    fn scattered(rho: f32, lag: u32, n: usize, spread: f32, seed: u64) -> Vec<f32> {
        (0..n as u32).map(|i| lag_ratio(rho, lag) * (1.0 + spread * crate::synth::gaussian(i, lag, 0, seed))).collect()
    }

    #[test]
    fn lag_ratio_and_factors_match_their_closed_forms() {
        // Tolerance 1e-6: f32 rounding of sums of a few terms.
        assert!((lag_ratio(0.5, 2) - 1.5f32.sqrt()).abs() < 1e-6);
        assert!((lag_ratio(0.5, 3) - 1.75f32.sqrt()).abs() < 1e-6);
        assert!((lag_ratio(0.0, 3) - 1.0).abs() < 1e-6);
        assert!((difference_variance_factor(0.5, 1) - 0.5).abs() < 1e-6);
        // Independent frames: the mean of m carries 1/m.
        assert!((mean_reference_variance_factor(0.0, &[1, 2, 3, 4]) - 1.25).abs() < 1e-6);
        // One frame one back: the difference itself, 2(1 − ρ).
        assert!((mean_reference_variance_factor(0.6, &[1]) - 0.8).abs() < 1e-6);
        // Two frames: 1 + (2 + 2ρ)/4 − (ρ + ρ²) at ρ 0.5 → 1.75 − 0.75 = 1.0.
        assert!((mean_reference_variance_factor(0.5, &[1, 2]) - 1.0).abs() < 1e-6);
        assert_eq!(mean_reference_variance_factor(0.5, &[]), 1.0);
    }

    /// The factor is a variance: never negative, whatever ρ and lags (extremes).
    #[test]
    fn mean_reference_factor_is_a_variance_at_the_extremes() {
        for rho in [-0.5f32, 0.0, 0.3, 0.9, 0.95, 0.999] {
            for lags in [&[1u64][..], &[1, 2, 3], &[5, 9], &[1, 1_000_000], &[u64::MAX]] {
                let f = mean_reference_variance_factor(rho, lags);
                assert!(f.is_finite() && f >= -1e-5, "ρ {rho} lags {lags:?}: {f}");
            }
        }
    }

    /// Known answers: ratios made from ρ with a probe's scatter (p10–p90 of the
    /// measured lag ratios at ρ 0 span ±9%: a Gaussian spread of 7%), 20 per lag
    /// (two seconds of probes, each lag every other one). Tolerance 0.08: about
    /// 2.5 of the estimate's standard errors at that spread.
    #[test]
    fn recovers_rho_from_two_lags() {
        for (i, &rho) in [0.0f32, 0.3, 0.5, 0.8].iter().enumerate() {
            let r2 = scattered(rho, 2, 20, 0.07, 10 + i as u64);
            let r3 = scattered(rho, 3, 20, 0.07, 20 + i as u64);
            let e = noise_correlation(&[LagRatios { lag: 2, ratios: &r2 }, LagRatios { lag: 3, ratios: &r3 }]);
            let fitted = e.rho_fitted.expect("identifiable");
            assert!((fitted - rho).abs() < 0.08, "ρ {rho}: {e:?}");
            let se = e.stderr.expect("a standard error");
            assert!(se > 0.0 && se < 0.08, "ρ {rho}: {e:?}");
            if rho == 0.0 {
                assert_eq!(e.status, Status::Absent, "{e:?}");
                assert_eq!(e.rho, 0.0);
            } else {
                assert_eq!(e.status, Status::Present, "ρ {rho}: {e:?}");
            }
        }
    }

    /// The DivX clip's lag ratio (r_2 = 1.8, beyond √2) and lag ratios of two
    /// different correlations are not a first-order correlation.
    #[test]
    fn ratios_no_first_order_correlation_makes_are_not_identifiable() {
        let r2 = scattered(0.0, 2, 20, 0.03, 1).iter().map(|r| r * 1.8).collect::<Vec<_>>();
        let e = noise_correlation(&[LagRatios { lag: 2, ratios: &r2 }]);
        assert_eq!(e.status, Status::NotIdentifiable, "{e:?}");
        assert!(e.inconsistent);
        // r_2 of ρ 0.8 with r_3 of ρ 0: inconsistent.
        let a = scattered(0.8, 2, 20, 0.03, 2);
        let b = scattered(0.0, 3, 20, 0.03, 3);
        let e = noise_correlation(&[LagRatios { lag: 2, ratios: &a }, LagRatios { lag: 3, ratios: &b }]);
        assert_eq!(e.status, Status::NotIdentifiable, "{e:?}");
        assert!(e.inconsistent && e.reason.contains("first-order"), "{}", e.reason);
    }

    /// Bad input: too few ratios, NaN, zero, lag 1 — an answer naming why, no panic.
    #[test]
    fn bad_input_is_not_identifiable() {
        let few = [1.0f32; 4];
        let e = noise_correlation(&[LagRatios { lag: 2, ratios: &few }]);
        assert_eq!(e.status, Status::NotIdentifiable);
        assert!(!e.inconsistent && e.reason.contains("fewer than"), "{}", e.reason);
        let nan = [1.0, f32::NAN, 1.0, 1.0, 1.0, 1.0];
        assert_eq!(noise_correlation(&[LagRatios { lag: 3, ratios: &nan }]).status, Status::NotIdentifiable);
        let zero = [1.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        assert_eq!(noise_correlation(&[LagRatios { lag: 3, ratios: &zero }]).status, Status::NotIdentifiable);
        let ok = [1.0f32; 8];
        assert_eq!(noise_correlation(&[LagRatios { lag: 1, ratios: &ok }]).status, Status::NotIdentifiable);
        assert_eq!(noise_correlation(&[]).status, Status::NotIdentifiable);
        // Identical ratios (MAD 0): the floor keeps the error finite.
        let e = noise_correlation(&[LagRatios { lag: 3, ratios: &ok }]);
        assert_eq!(e.status, Status::Absent, "{e:?}");
        assert!(e.stderr.is_some_and(|s| s.is_finite() && s > 0.0));
    }
}
