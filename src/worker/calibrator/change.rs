//! Change detection: the noise probe (every `PROBE_INTERVAL_S` of video) and
//! confident exposure estimates, and what a detected change does to the state.

use super::*;
use crate::analysis::temporal::{band_stride, in_band};

/// Video time between noise probes (change detection), every tier.
pub(super) const PROBE_INTERVAL_S: f64 = 0.1;
/// How long a first off-model λ reading waits for its second (`check_exposure`):
/// λ refits come every 0.1 s after the burst, so a few of them.
const SUSPECT_MAX_AGE_S: f64 = 0.5;

/// Pixels the temporal noise probe reads at most: above this, bands of rows spread
/// over the frame (`temporal::in_band`), the same ones every time. Its threshold was
/// set at 320×240, where it reads every row; at 1280×960 it reads a quarter of
/// them (4× the samples it was set on) and aligns only those.
pub(super) const PROBE_PX: usize = 307_200;

/// A noise probe's value.
#[derive(Clone, Copy, Debug)]
pub(super) struct Probe {
    pub(super) t_s: f64,
    pub(super) noise: Option<f32>,
}

/// Luma histogram of a frame on a sparse grid (16 bins, normalised).
pub(super) fn luma_histogram(frame: &Frame) -> [f32; 16] {
    let img = &frame.image;
    let mut h = [0f32; 16];
    let step = ((img.len() / 4096) as f64).sqrt().max(1.0) as usize;
    let mut n = 0.0f32;
    for y in (0..img.height).step_by(step) {
        for x in (0..img.width).step_by(step) {
            let i = y * img.width + x;
            let l = 0.2126 * img.channels[0][i] + 0.7152 * img.channels[1][i] + 0.0722 * img.channels[2][i];
            h[((l.clamp(0.0, 1.0) * 16.0) as usize).min(15)] += 1.0;
            n += 1.0;
        }
    }
    h.iter_mut().for_each(|v| *v /= n.max(1.0));
    h
}

impl Calibrator {
    /// A change first seen at `since_s`: estimates and held frames from before it
    /// were made with the old camera (no references from them).
    pub(super) fn on_change(&mut self, frame: u64, t_s: f64, since_s: f64, cause: String, events: &mut Vec<Event>) {
        events.push(Event::ChangeDetected { frame, t_s, cause });
        self.estimates.retain(|e| e.t_s >= since_s);
        self.exposure_history.retain(|e| e.0 >= since_s);
        self.probes.retain(|p| p.t_s >= since_s);
        self.burst_until_s = t_s + 0.5 * self.cfg.burst_s;
        self.noise_since_s = t_s;
        self.after_change = true;
        self.exposure_suspect = None;
        self.window.retain(|a| a.frame.t_s >= since_s);
        self.sharp.retain(|a| a.frame.t_s >= since_s);
        self.lagged.retain(|a| a.frame.t_s >= since_s);
        // The new camera's noise reduction may differ: its lag ratios start afresh.
        self.lag_ratios.retain(|p| p.t_s >= since_s);
        self.noise_correlation = None;
        self.forget_dof_before(since_s);
        self.forget_mb_before(since_s);
    }

    /// Change detection on the noise probes (every `PROBE_INTERVAL_S`), each
    /// compared with the probes before it: three in a row beyond ×1.22 (|ln| > 0.2)
    /// on the same side of the median of the earlier ones (at least five, within
    /// 2 s) is a change, dated at the first of the three. The threshold is 2.5× the
    /// temporal probe's scatter on the Motorcycle sequence (±8% with head motion);
    /// the blind probe (no poses) scatters ±25% from view to view, so it only sees
    /// steps beyond that (|ln| > 0.35).
    pub(super) fn detect_change(&mut self) -> Option<(f64, String)> {
        const RECENT: usize = 3;
        let n = self.probes.len();
        if n < RECENT + 5 {
            return None;
        }
        let (older, recent) = self.probes.make_contiguous().split_at(n - RECENT);
        let median = |v: Vec<f32>| -> Option<f32> {
            let mut v = v;
            if v.len() < 5 {
                return None;
            }
            v.sort_by(f32::total_cmp);
            Some(v[v.len() / 2])
        };
        let since = recent[0].t_s;
        let limit = if self.cfg.intrinsics.is_some() { 0.2 } else { 0.35 };
        let base = median(older.iter().filter_map(|p| p.noise).collect());
        if let Some(b) = base.filter(|b| *b > 0.0) {
            let r: Vec<f32> = recent.iter().filter_map(|p| p.noise.map(|x| (x / b).ln())).collect();
            if r.len() == RECENT && (r.iter().all(|x| *x > limit) || r.iter().all(|x| *x < -limit)) {
                return Some((since, format!("blind noise level moved ×{:.2}", r[RECENT - 1].exp())));
            }
        }
        None
    }

    pub(super) fn push_probe(&mut self, t_s: f64, noise: Option<f32>) {
        self.probes.push_back(Probe { t_s, noise });
        while self.probes.front().is_some_and(|p| p.t_s < t_s - 2.0) {
            self.probes.pop_front();
        }
    }

    /// The noise probe of this frame: the temporal one (`analysis::temporal::
    /// noise_probe`, against the previous frame) with poses and depth (None when
    /// this frame cannot be aligned: the two kinds are not mixed), else the blind
    /// noise estimator.
    pub(super) fn noise_probe(&mut self, current: &Analysed) -> Option<f32> {
        if self.cfg.intrinsics.is_some() {
            let aligned = self.aligned_previous(current)?;
            let img = &current.frame.image;
            let stride = band_stride(img.width, img.height, PROBE_PX);
            return crate::analysis::temporal::noise_probe(&aligned, current, &|y| in_band(y, stride));
        }
        let opts = FitOptions {
            tier: Some(fit::Tier::Fast),
            effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
            ..Default::default()
        };
        fit::fit(&FitInputs::new(&current.frame.image), &opts)
            .ok()
            .and_then(|o| crate::model::compare::noise_headline(&o.model.noise))
    }

    /// The previous frame aligned into `current` by pose and depth (None without
    /// intrinsics, poses or depth, or when the previous frame is more than 2.5 frame
    /// intervals old), made once per frame: the noise probe and the blind noise fit
    /// both read it, so it holds the rows of both — the probe's bands and, where the
    /// noise fit is blind, its next strip (`Calibrator::noise_strip`) — and no others.
    pub(super) fn aligned_previous(&mut self, current: &Analysed) -> Option<Arc<crate::analysis::temporal::Aligned>> {
        let index = current.frame.index;
        if let Some((i, a)) = &self.aligned_previous {
            if *i == index {
                return a.clone();
            }
        }
        let img = &current.frame.image;
        // The strip only where the noise fit reads the neighbour (blind noise: no
        // denoiser); the slower tiers' probe aligns its bands alone.
        let strip = if self.cfg.effects.noise && self.providers.denoise.is_none() {
            self.noise_strip(img.width, img.height)
        } else {
            0..0
        };
        let stride = band_stride(img.width, img.height, PROBE_PX);
        let aligned = self.align_previous(current, &|y| in_band(y, stride) || strip.contains(&y));
        self.aligned_previous = Some((index, aligned.clone()));
        aligned
    }

    /// The previous frame aligned into `current` over `strip`: the blind noise
    /// fit's neighbour where the temporal denoiser was asked first and failed (too
    /// few earlier frames moving alike, a burst's start). `aligned_previous` holds
    /// only the probe's bands then; where they cover the strip (frames up to
    /// `PROBE_PX`) it serves (made now if the probe has not run on this frame),
    /// else the strip alone is aligned (not cached: a fallback's cost). Without it
    /// the fallback fitted the frame alone, and on the demo's video every other
    /// such fit read levels 1–3 at +110…+710% (texture in the flattest samples):
    /// published for 0.2 s after a reset (BENCHMARKS.md, "The worker's noise at a
    /// burst's start and after a reset").
    pub(super) fn aligned_strip(
        &mut self,
        current: &Analysed,
        strip: std::ops::Range<usize>,
    ) -> Option<Arc<crate::analysis::temporal::Aligned>> {
        let img = &current.frame.image;
        let stride = band_stride(img.width, img.height, PROBE_PX);
        if strip.clone().all(|y| in_band(y, stride)) {
            self.aligned_previous(current)
        } else {
            self.align_previous(current, &|y| strip.contains(&y))
        }
    }

    /// `current`'s previous frame in the window aligned into it over the rows `row`
    /// accepts (None: see `aligned_previous`).
    fn align_previous(
        &mut self,
        current: &Analysed,
        row: &(dyn Fn(usize) -> bool + Sync),
    ) -> Option<Arc<crate::analysis::temporal::Aligned>> {
        let k = self.cfg.intrinsics.as_ref()?;
        let prev = self.window.back()?;
        if current.frame.t_s - prev.frame.t_s > 2.5 * self.cfg.frame_interval_s {
            return None;
        }
        let t0 = Instant::now();
        let aligned = crate::analysis::temporal::align_rows(prev, current, k, row).map(Arc::new);
        self.stages.add("alignment", t0);
        aligned
    }

    /// Two consecutive confident estimates of λ by the same method, both off the
    /// published λ by more than 4 standard errors and 0.1: an exposure change. The
    /// standard error is the estimate's own in quadrature with the scatter of the
    /// window's estimates by that method (`exposure_scatter`): an estimate's stated
    /// error is statistical, and the sharp-frame reference's drift over a long turn
    /// is not in it. Without the scatter the demo's video read two such estimates
    /// as a change in both tiers (the accurate: 0.356 twice against a model of
    /// 0.460; the fast: 0.55 and 0.60 against 0.43; truth 0.40 throughout), and the
    /// restart published the drifted values (BENCHMARKS.md "The worker's noise at
    /// a burst's start and after a reset"). Not checked in a change's burst
    /// (`push_frame`): the model holds the old λ until the new estimates come.
    ///
    /// The second estimate is judged against the model and scatter the first one
    /// was (`exposure_suspect`): the first new reading already moves a window of few
    /// λ estimates, and the two readings then widen its scatter, so the second
    /// judged against the moved model hid the change (an exposure change alone, the
    /// fast tier refitting λ every other frame of its burst: published λ 0.36 and a
    /// scatter of 0.19 after one reading of 0.23 against 0.50). The change dates
    /// from the first reading (the estimates and sharp frames from then on are the
    /// new camera's; with per-effect refits the update before the second is not the
    /// first).
    pub(super) fn check_exposure(&mut self, m: &CameraModel, t_s: f64) -> Option<(String, f64)> {
        let agg = self.published.as_ref()?;
        let (a, mb) = (agg.motion_blur.exposure?, &m.motion_blur);
        let (b, se) = (mb.exposure?, mb.diagnostics.stderr?);
        if mb.diagnostics.status != Status::Present
            || se > 0.05
            || agg.motion_blur.diagnostics.method != mb.diagnostics.method
        {
            return None;
        }
        // Two in a row means two readings close in time: a first one older than
        // `SUSPECT_MAX_AGE_S` (a rest between, whose readings are not confident) is
        // forgotten, and this one judged afresh.
        if self.exposure_suspect.is_some_and(|(_, _, t0)| t_s - t0 > SUSPECT_MAX_AGE_S) {
            self.exposure_suspect = None;
        }
        let (a, spread, since_s) = match self.exposure_suspect {
            Some(first) => first,
            // Fewer than two confident estimates in the window: the published λ is a
            // held value (kept through a rest, or from before a change found by
            // the noise), not a reading these estimates contradict; the window's
            // median follows them without a restart. (Restarted there, the
            // Middlebury 2005 Moebius run dropped a second of noise estimates after
            // the noise had already found the change: accurate noise 1.6 → 5.3%.)
            None => (a, self.exposure_scatter(&mb.diagnostics.method)?, t_s),
        };
        if (a - b).abs() as f64 > (4.0 * se.hypot(spread as f64)).max(0.1) {
            if self.exposure_suspect.take().is_some() {
                let cause = format!(
                    "two estimates in a row read λ ≈ {b:.3}, the model {a:.3} (scatter of its estimates {spread:.3})"
                );
                return Some((cause, since_s));
            }
            self.exposure_suspect = Some((a, spread, t_s));
        } else {
            self.exposure_suspect = None;
        }
        None
    }

    /// Robust spread of the window's confident λ estimates by `method` (1.4826 × the
    /// median absolute deviation; `None` with fewer than two): how far apart this
    /// method's estimates of one camera fall.
    fn exposure_scatter(&self, method: &str) -> Option<f32> {
        let lambdas: Vec<f32> = self
            .estimates
            .iter()
            .map(|e| &e.model.motion_blur)
            .filter(|mb| {
                mb.diagnostics.status == Status::Present
                    && mb.diagnostics.method == method
                    && mb.diagnostics.stderr.is_some_and(|se| se <= 0.05)
            })
            .filter_map(|mb| mb.exposure)
            .collect();
        if lambdas.len() < 2 {
            return None;
        }
        let med = crate::fit::median(lambdas.clone());
        Some(1.4826 * crate::fit::median(lambdas.iter().map(|l| (l - med).abs()).collect()))
    }
}
