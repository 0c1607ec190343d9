//! Aggregation of the window's estimates into the published model: medians,
//! presence with hysteresis, validation.

use super::*;

/// How long after the start or a reset frame-alone blind noise fits wait for a fit
/// with an aligned neighbour before they are published (`Calibrator::aggregate`):
/// 9 frames at 30 Hz. The second frame brings one wherever alignment works; a worker
/// under load may see its second frame a few tenths of a second late.
const NEIGHBOUR_WAIT_S: f64 = 0.3;

/// Presence with hysteresis.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Presence {
    on: Option<bool>,
}

impl Presence {
    /// `present` of `identifiable` estimates said present.
    pub(super) fn update(&mut self, present: usize, identifiable: usize) -> bool {
        if identifiable == 0 {
            return self.on.unwrap_or(false);
        }
        let frac = present as f64 / identifiable as f64;
        let on = match self.on {
            None => frac > 0.5,
            Some(false) => frac >= 0.6,
            Some(true) => frac > 0.3,
        };
        self.on = Some(on);
        on
    }
}

impl Calibrator {
    /// Aggregate the window's estimates, apply hysteresis, validate.
    pub(super) fn aggregate(&mut self, frame: u64, t_s: f64, reason: UpdateReason, started: Instant) -> Option<Update> {
        let t_agg = Instant::now();
        let from = t_s - self.cfg.window_s;
        while self.estimates.front().is_some_and(|e| e.t_s < from) {
            self.estimates.pop_front();
        }
        let mut models: Vec<CameraModel> = self.estimates.iter().map(|e| e.model.clone()).collect();
        // Noise read off frame differences: the noise's frame-to-frame correlation
        // divided out, or the fit dropped where it is of no first-order form
        // (`tnr`): then it does not supersede the frame-alone ones below (the frame
        // alone is what is left).
        self.correct_for_correlation(&mut models);
        // Blind noise fitted on the frame alone (no aligned neighbour: the first
        // frame, a reset that dropped the held frames, a failed alignment) takes the
        // flattest texture for noise: +57% on the calibration video's first frame,
        // +208% seen on the demo's, against 2–3% with the previous frame aligned. Where
        // the window holds fits with a neighbour, those decide; where it holds none,
        // the frame-alone fits wait `NEIGHBOUR_WAIT_S` from the (re)start for one
        // (without intrinsics, depth or poses none will come, and they are all there is).
        let alone = |d: &crate::model::Diagnostics| d.method == fit::NOISE_FAST_ALONE;
        let with_neighbour =
            models.iter().any(|m| m.noise.present && m.noise.diagnostics.method == fit::NOISE_FAST_WITH_NEIGHBOUR);
        if with_neighbour || t_s - self.noise_since_s < NEIGHBOUR_WAIT_S {
            let why = if with_neighbour {
                "superseded by fits that read an aligned neighbour"
            } else {
                "fitted on the frame alone: waiting for a fit with an aligned neighbour"
            };
            for m in models.iter_mut().filter(|m| alone(&m.noise.diagnostics)) {
                m.noise = crate::model::Noise::absent(crate::model::Diagnostics::not_fitted(why));
            }
        }
        // Presence votes: every identifiable estimate.
        let count = |f: &dyn Fn(&CameraModel) -> (bool, bool)| {
            models.iter().fold((0, 0), |(p, i), m| {
                let (present, identifiable) = f(m);
                (p + present as usize, i + identifiable as usize)
            })
        };
        let ident = |s: Status| matches!(s, Status::Present | Status::Absent);
        let (np, ni) = count(&|m| (m.noise.present, ident(m.noise.diagnostics.status)));
        let (mp, mi) = count(&|m| (m.motion_blur.present, ident(m.motion_blur.diagnostics.status)));
        let (dp, di) = count(&|m| (m.depth_of_field.present, ident(m.depth_of_field.diagnostics.status)));
        // Value votes: λ only from estimates that pin it down (± 0.05); a frame with
        // little motion says "λ near 0 or anything" and would drag the median. The
        // blind estimator's root search returns the bracket end (0 or 1, with a zero
        // spread) when its balance has no sign change: no information either.
        for m in &mut models {
            let at_bracket_end = m.motion_blur.exposure.is_some_and(|l| !(1e-6..=1.0 - 1e-6).contains(&l));
            if at_bracket_end || m.motion_blur.diagnostics.stderr.map_or(true, |s| s > 0.05) {
                m.motion_blur.exposure = None;
            }
        }
        // Where the window holds estimates made with a reference (the accurate fits
        // on temporal or network references), blind estimates of that effect are
        // not mixed in: they only bridge the time until the first reference.
        let with_reference = |d: &crate::model::Diagnostics| d.method.starts_with("accurate");
        let not_fitted = || crate::model::Diagnostics::not_fitted("superseded by estimates with a reference");
        if models.iter().any(|m| with_reference(&m.noise.diagnostics) && m.noise.present) {
            for m in models.iter_mut().filter(|m| !with_reference(&m.noise.diagnostics)) {
                m.noise = crate::model::Noise::absent(not_fitted());
            }
        }
        if models.iter().any(|m| with_reference(&m.motion_blur.diagnostics) && m.motion_blur.exposure.is_some()) {
            for m in models.iter_mut().filter(|m| !with_reference(&m.motion_blur.diagnostics)) {
                m.motion_blur = crate::model::MotionBlur::absent(not_fitted());
            }
        }
        if models.iter().any(|m| with_reference(&m.depth_of_field.diagnostics) && m.depth_of_field.present) {
            for m in models.iter_mut().filter(|m| !with_reference(&m.depth_of_field.diagnostics)) {
                let units = m.depth_of_field.units;
                m.depth_of_field = crate::model::DepthOfField::absent(units, not_fitted());
            }
        }
        let mut agg = fit::aggregate_models(&models).ok()?;
        let prev = self.published.clone();
        let on = [self.presence[0].update(np, ni), self.presence[1].update(mp, mi), self.presence[2].update(dp, di)];
        // Hysteresis holds an effect on while the window's majority has flipped:
        // keep the aggregate's values if it has any, else the last published ones.
        if on[0] != agg.noise.present {
            match (&prev, on[0] && np == 0) {
                (Some(p), true) => agg.noise = p.noise.clone(),
                _ => agg.noise.present = on[0] && np > 0,
            }
        }
        if on[1] && agg.motion_blur.exposure.is_none() {
            // No confident λ in the window (e.g. the head at rest since a change):
            // keep the last published exposure rather than flicker to none.
            if let Some(p) = prev.as_ref().filter(|p| p.motion_blur.exposure.is_some()) {
                agg.motion_blur = p.motion_blur.clone();
            }
        }
        if on[1] != agg.motion_blur.present {
            agg.motion_blur.present = on[1] && agg.motion_blur.exposure.is_some();
        }
        if on[2] != agg.depth_of_field.present {
            match (&prev, on[2] && dp == 0) {
                (Some(p), true) => agg.depth_of_field = p.depth_of_field.clone(),
                _ => agg.depth_of_field.present = on[2] && agg.depth_of_field.curve.is_some(),
            }
        }
        agg.validate().ok()?;
        self.published = Some(agg.clone());
        self.stages.add("aggregation", t_agg);
        Some(Update {
            frame,
            t_s,
            model: agg,
            reason,
            compute_s: started.elapsed().as_secs_f64(),
            frames_used: self.estimates.iter().map(|e| e.frame).collect(),
            stages_s: self.stages.0.clone(),
        })
    }
}
