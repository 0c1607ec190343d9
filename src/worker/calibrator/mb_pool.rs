//! Blind motion blur pooled over flow directions: the isotropy evidence of the
//! blind fits of the last seconds, one joint fit of λ and the texture's anisotropy
//! (`fit::fit_fast_pooled_exposure`). A single frame's isotropy root is biased by
//! the texture's own anisotropy, which is fixed in the image while the streak turns
//! with the flow: a head that looks around gives the directions that separate them.

use super::*;

/// One blind motion-blur fit's isotropy evidence, kept for the pooled fit.
#[derive(Debug)]
pub(super) struct PooledIsotropy {
    t_s: f64,
    evidence: fit::IsotropyEvidence,
}

/// How long a frame's isotropy evidence stays in the pool (s of video) and the
/// most frames it holds. The exposure only changes with a detected change (which
/// empties the pool from then back); the pool needs a head that has turned more
/// than one way, which takes seconds, so it reaches past the 1 s aggregation window.
const MB_POOL_S: f64 = 4.0;
const MB_POOL_FRAMES: usize = 64;

impl Calibrator {
    /// This frame's isotropy evidence joins the pool (every blind fit carries it:
    /// the worker asks for it on frames the streak zeros answered too,
    /// `FitOptions::mb_isotropy_evidence`), and the pooled blind λ replaces the
    /// frame's own where it pins λ down better (a smaller standard error, or the
    /// frame alone not identifiable) — the zeros' answers (± 0.005–0.03) mostly
    /// stand, isotropy's (± 0.05–0.3, or none) give way. The pooled fit's time
    /// counts with the motion-blur fit's.
    pub(super) fn pool_mb(&mut self, t_s: f64, evidence: Option<fit::IsotropyEvidence>, model: &mut CameraModel) {
        let Some(evidence) = evidence else { return };
        self.mb_pool.push_back(PooledIsotropy { t_s, evidence });
        self.mb_pool.retain(|p| t_s - p.t_s <= MB_POOL_S);
        while self.mb_pool.len() > MB_POOL_FRAMES {
            self.mb_pool.pop_front();
        }
        let frames: Vec<&fit::IsotropyEvidence> = self.mb_pool.iter().map(|p| &p.evidence).collect();
        let mut pooled = fit::fit_fast_pooled_exposure(&frames);
        let own = &model.motion_blur.diagnostics;
        // A frame with a reading (present, absent, or a visible λ within 3 standard
        // errors of none: `fit::motion_blur::exposure_status`) gives way to a smaller
        // standard error; one without (not identifiable, no λ) to any identifiable
        // pooled fit.
        let better = match (pooled.diagnostics.stderr, own.stderr, model.motion_blur.exposure) {
            _ if pooled.diagnostics.status == crate::model::Status::NotIdentifiable => false,
            (Some(p), Some(o), Some(_)) => p < o,
            (Some(_), _, _) => true,
            (None, _, _) => false,
        };
        if better {
            pooled.diagnostics.fit_time_s += own.fit_time_s;
            pooled.diagnostics.stages_s = own.stages_s.clone();
            pooled.diagnostics.reason = format!("{}; this frame alone: {}", pooled.diagnostics.reason, own.reason);
            model.motion_blur = pooled;
        }
    }

    /// Drop the pooled evidence of frames before `since_s` (a detected camera change:
    /// an exposure change is one).
    pub(super) fn forget_mb_before(&mut self, since_s: f64) {
        self.mb_pool.retain(|p| p.t_s >= since_s);
    }
}
