//! The noise's frame-to-frame correlation (a camera's temporal noise reduction,
//! TNR): lag probes beside the noise probe, the estimate over the last seconds
//! (`fit::noise_correlation`), and its correction of the noise fits that read
//! frame differences.
//!
//! The fast tier's noise fit against the previous frame aligned reads σ²(1 − ρ), the
//! accurate tier's against a mean of other frames a like fraction
//! (`fit::noise_correlation::mean_reference_variance_factor`): measured on the
//! calibration video with a recursive TNR of ρ 0.5, 26% and 6% low (BENCHMARKS.md
//! "Temporally correlated noise"). Each noise probe (every `PROBE_INTERVAL_S`) also
//! aligns the frame 2 or 3 back (in turn) over the probe's bands and reads the
//! difference's spread there against the lag-1 one on the same pixels; the ratios of
//! the last `TNR_WINDOW_S` give ρ and whether a first-order correlation explains them.

use super::noise_fit::scale_noise;
use super::*;
use crate::analysis::temporal::{band_stride, in_band, BAND_ROWS};
use crate::fit::noise_correlation::{self, LagRatios, NoiseCorrelation};

/// Lags probed, in turn (one alignment per probe, on half the noise probe's bands). Two lags test the first-order form; 3 is the most sensitive
/// to ρ of the two (dr/dρ 0.68 against 0.41 at ρ 0.3).
pub(super) const TNR_LAGS: [u32; 2] = [2, 3];
/// Lag ratios pooled: the last this many seconds of video (15 per lag at one
/// probe per 0.1 s; `fit::noise_correlation::MIN_RATIOS` per lag, 1 s, for a first
/// estimate).
pub(super) const TNR_WINDOW_S: f64 = 3.0;

/// One lag probe: std of the difference at `lag` over the std at lag 1.
#[derive(Clone, Copy, Debug)]
pub(super) struct LagProbe {
    pub(super) t_s: f64,
    pub(super) lag: u32,
    pub(super) ratio: f32,
}

impl Calibrator {
    /// Frames held for the lag probes (the newest `max(TNR_LAGS)`), where they can
    /// run: with intrinsics (alignment needs them) and noise fitted.
    pub(super) fn hold_lagged(&mut self, analysed: &Arc<Analysed>) {
        if self.cfg.intrinsics.is_none() || !self.cfg.effects.noise {
            return;
        }
        self.lagged.push_back(analysed.clone());
        let keep = TNR_LAGS.iter().copied().max().unwrap_or(0) as usize;
        while self.lagged.len() > keep {
            self.lagged.pop_front();
        }
    }

    /// The lag probe of this frame (run with the noise probe): the frame `lag` back
    /// aligned over the probe's bands, its difference's spread over the lag-1 one on
    /// the same pixels; then ρ re-estimated. Nothing when this frame or the one
    /// before cannot be aligned, or the frame `lag` back is not held (a dropped
    /// frame: the lags would not be what they say).
    pub(super) fn lag_probe(&mut self, current: &Analysed) {
        let lag = TNR_LAGS[self.lag_probes_run % TNR_LAGS.len()];
        self.lag_probes_run += 1;
        let index = current.frame.index;
        let Some(k) = self.cfg.intrinsics else { return };
        let previous_is_lag_1 = self.window.back().is_some_and(|p| p.frame.index + 1 == index);
        let source = self.lagged.iter().find(|a| a.frame.index + lag as u64 == index).cloned();
        let (Some(source), true) = (source, previous_is_lag_1) else { return };
        let Some(a1) = self.aligned_previous(current) else { return };
        let img = &current.frame.image;
        // The noise probe's bands; where those are a sample of the frame's rows
        // (frames above `PROBE_PX`) every other one: half the alignment's cost (11–15
        // ms of one core at 1280×960 for all of them) on a sample still twice the
        // 320×240 frame's. At 320×240 half the rows read ρ 0.8 as well but
        // scattered more early on (the fast tier's published error 7.3% → 11.1%;
        // BENCHMARKS.md "A camera's temporal noise reduction, measured and divided out").
        let stride = band_stride(img.width, img.height, change::PROBE_PX);
        let row = |y: usize| in_band(y, stride) && (stride == 1 || (y / BAND_ROWS / stride) % 2 == 0);
        let t0 = Instant::now();
        let ak = crate::analysis::temporal::align_rows(&source, current, &k, &row);
        self.stages.add("alignment", t0);
        let t0 = Instant::now();
        let spreads = ak.and_then(|ak| crate::analysis::temporal::noise_probe_lags(&[&a1, &ak], current, &row));
        if let Some([s1, sk]) = spreads.as_deref() {
            if *s1 > 0.0 && sk.is_finite() {
                self.lag_ratios.push_back(LagProbe { t_s: current.frame.t_s, lag, ratio: sk / s1 });
            }
        }
        let t_s = current.frame.t_s;
        while self.lag_ratios.front().is_some_and(|p| p.t_s < t_s - TNR_WINDOW_S) {
            self.lag_ratios.pop_front();
        }
        let per_lag: Vec<Vec<f32>> = TNR_LAGS
            .iter()
            .map(|&l| self.lag_ratios.iter().filter(|p| p.lag == l).map(|p| p.ratio).collect())
            .collect();
        let lags: Vec<LagRatios> =
            TNR_LAGS.iter().zip(&per_lag).map(|(&lag, ratios)| LagRatios { lag, ratios }).collect();
        self.noise_correlation = Some(noise_correlation::noise_correlation(&lags));
        self.stages.add("lag probe", t0);
    }

    /// Whether a lag probe runs on this frame besides the noise probe's cadence: in
    /// a burst (the start, after a change) until the correlation has a first
    /// estimate (identifiable or found of another form).
    pub(super) fn lag_probe_hurried(&self, t_s: f64) -> bool {
        t_s < self.burst_until_s
            && !self.noise_correlation.as_ref().is_some_and(|c| c.rho_fitted.is_some() || c.inconsistent)
    }

    /// Whether the lag probes found the noise copied between frames in a way no
    /// first-order correlation explains: then no noise fit may read a frame
    /// difference (the fast tier reads the frame alone; the accurate tier leaves its
    /// temporal reference unused).
    pub(super) fn noise_copied_otherwise(&self) -> bool {
        self.noise_correlation.as_ref().is_some_and(|c| c.inconsistent)
    }

    /// The window's noise estimates that read frame differences, corrected for the
    /// noise's correlation (its estimate now: the whole window takes the latest ρ),
    /// or dropped where the lag probes found a correlation of another form.
    /// Until the first estimate (lag probes on every frame of a burst: after
    /// `MIN_RATIOS` per lag, ~13 frames, 0.43 s at 30 Hz) such fits count as
    /// measured, and say so: low by √(1 − ρ) under a TNR, which is nearer the truth
    /// than publishing no noise while ρ is measured.
    pub(super) fn correct_for_correlation(&self, models: &mut [CameraModel]) {
        let c = self.noise_correlation.as_ref().filter(|c| c.rho_fitted.is_some() || c.inconsistent);
        for (m, e) in models.iter_mut().zip(&self.estimates) {
            if !m.noise.present || e.noise_lags.is_empty() {
                continue;
            }
            let Some(c) = c else {
                let d = &mut m.noise.diagnostics;
                d.reason = format!("{}; the noise's frame-to-frame correlation not measured yet", d.reason);
                continue;
            };
            if c.inconsistent {
                m.noise = crate::model::Noise::absent(crate::model::Diagnostics::not_fitted(&format!(
                    "read a frame difference, but {}",
                    c.reason
                )));
            } else if c.status == Status::Present {
                correct_noise(m, c, &e.noise_lags);
            }
        }
    }
}

/// Divide a difference-based noise fit's correlation out: it divided its variance
/// by the factor of independent frames (`mean_reference_variance_factor(0, lags)`:
/// 2 for one neighbour, 1 + 1/m for a mean of m), where ρ makes it
/// `mean_reference_variance_factor(ρ, lags)`.
fn correct_noise(m: &mut CameraModel, c: &NoiseCorrelation, lags: &[u64]) {
    let independent = noise_correlation::mean_reference_variance_factor(0.0, lags);
    let correlated = noise_correlation::mean_reference_variance_factor(c.rho, lags);
    // Bounded by `MAX_RHO`: at ρ 0.95 one neighbour gives ×20 in variance.
    if !(correlated > 1e-3 && correlated.is_finite()) {
        return;
    }
    let factor = independent / correlated;
    scale_noise(m, factor);
    let d = &mut m.noise.diagnostics;
    d.reason = format!("{}; ×{factor:.2} in variance for the {}", d.reason, c.reason);
}
