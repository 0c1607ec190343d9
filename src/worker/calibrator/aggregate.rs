//! Aggregation of the window's estimates into the published model: medians,
//! presence with hysteresis, validation.

use super::*;

/// How long after the start or a reset frame-alone blind noise fits wait for a fit
/// with an aligned neighbour before they are published (`Calibrator::aggregate`):
/// 9 frames at 30 Hz. The second frame brings one wherever alignment works; a worker
/// under load may see its second frame a few tenths of a second late.
const NEIGHBOUR_WAIT_S: f64 = 0.3;

/// Streak (px) the held exposure must predict at a frame's speed for that frame's
/// "absent" reading to count against it: twice the negligible streak
/// (`fit::motion_blur`'s `INVISIBLE_STREAK_PX`, 0.35 px), so that the streak the
/// frame failed to show was clearly visible.
const SHOWN_STREAK_PX: f32 = 0.7;

/// Fewest "absent" votes in the window that drop an effect once it is on. One
/// reading is not evidence enough: as a turn decelerates, a temporal reference
/// aligned from ~40 px away read λ = 0.000 ± 0.013 (confident) where the truth was
/// 0.4 (a Middlebury scene of `cargo xtask bench-quality`), and once the turn's
/// present readings had left the window that lone vote dropped the exposure for
/// the whole rest that followed. Three readings span a tenth of a second in an
/// accurate-tier burst at 30 Hz, about two tenths in the fast tier's (each effect
/// every other frame), and a few tenths on schedule.
const MIN_ABSENT_VOTES: usize = 3;

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
        let absent = identifiable.saturating_sub(present);
        let on = match self.on {
            None => frac > 0.5,
            Some(false) => frac >= 0.6,
            Some(true) => frac > 0.3 || absent < MIN_ABSENT_VOTES,
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
        // Presence votes: every identifiable estimate. A motion-blur "absent" is a
        // vote only where the exposure held so far would have streaked visibly
        // (`SHOWN_STREAK_PX` at that frame's speed): a still or slow head shows no
        // streak whatever the exposure, and the camera's exposure does not vanish
        // when the head stops.
        let held_exposure =
            self.published.as_ref().filter(|p| p.motion_blur.present).and_then(|p| p.motion_blur.exposure);
        let speeds: Vec<Option<f32>> = self.estimates.iter().map(|e| e.speed_px).collect();
        let count = |f: &dyn Fn(usize, &CameraModel) -> (bool, bool)| {
            models.iter().enumerate().fold((0, 0), |(p, i), (k, m)| {
                let (present, identifiable) = f(k, m);
                (p + (present && identifiable) as usize, i + identifiable as usize)
            })
        };
        let ident = |s: Status| matches!(s, Status::Present | Status::Absent);
        let mb_vote = |k: usize, m: &CameraModel| {
            let d = &m.motion_blur.diagnostics;
            let shows = match (d.status, held_exposure, speeds.get(k).copied().flatten()) {
                (Status::Absent, Some(lambda), Some(speed)) => lambda * speed >= SHOWN_STREAK_PX,
                _ => true,
            };
            (m.motion_blur.present, ident(d.status) && shows)
        };
        let (np, ni) = count(&|_, m| (m.noise.present, ident(m.noise.diagnostics.status)));
        let (mp, mi) = count(&mb_vote);
        let (dp, di) = count(&|_, m| (m.depth_of_field.present, ident(m.depth_of_field.diagnostics.status)));
        // Value votes: λ only from estimates that pin it down (± 0.05); a frame with
        // little motion says "λ near 0 or anything" and would drag the median. The
        // blind estimator's root search returns the bracket end (0 or 1, with a zero
        // spread) when its balance has no sign change: no information either.
        for m in &mut models {
            let at_bracket_end = m.motion_blur.exposure.is_some_and(|l| !(1e-6..=1.0 - 1e-6).contains(&l));
            if at_bracket_end || m.motion_blur.diagnostics.stderr.map_or(true, |s| s > 0.05) {
                // Its presence vote is counted above; as a value it says nothing,
                // and "present" without a value is no model (`validate`).
                m.motion_blur.exposure = None;
                m.motion_blur.present = false;
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
        // The newest estimate's λ, if confident and made with a reference, joins the
        // exposure history; where the window's λ comes from such estimates, the
        // history's median (back to `exposure_memory_s` or the last change) is
        // published instead of the window's alone.
        let reference_lambda =
            |m: &CameraModel| m.motion_blur.exposure.filter(|_| with_reference(&m.motion_blur.diagnostics));
        if let Some(l) = models.last().and_then(reference_lambda) {
            self.exposure_history.push_back((t_s, l));
        }
        let memory_from = t_s - self.cfg.exposure_memory_s.max(self.cfg.window_s);
        while self.exposure_history.front().is_some_and(|e| e.0 < memory_from) {
            self.exposure_history.pop_front();
        }
        let mut agg = fit::aggregate_models(&models).ok()?;
        if self.cfg.exposure_memory_s > self.cfg.window_s
            && agg.motion_blur.exposure.is_some()
            && models.iter().any(|m| reference_lambda(m).is_some())
        {
            let mut v: Vec<f32> = self.exposure_history.iter().map(|e| e.1).collect();
            v.sort_by(f32::total_cmp);
            if let Some(&m) = v.get(v.len() / 2) {
                agg.motion_blur.exposure = Some(m);
            }
        }
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
        // A view that cannot show the illuminant (one colour fills it, all
        // clipped) keeps the last colour read: not identifiable is not absent.
        if agg.colour.illuminant.is_none() {
            if let Some(p) = prev.as_ref().filter(|p| p.colour.illuminant.is_some()) {
                agg.colour = p.colour.clone();
            }
        }
        // Vignetting likewise: a head at rest shows no surface at two radii.
        if agg.vignetting.log_falloff.is_none() {
            if let Some(p) = prev.as_ref().filter(|p| p.vignetting.log_falloff.is_some()) {
                agg.vignetting = p.vignetting.clone();
            }
        }
        // The aberration likewise: a view without radial edges shows no fringe.
        if agg.chromatic_aberration.scale_minus_one.is_none() {
            if let Some(p) = prev.as_ref().filter(|p| p.chromatic_aberration.scale_minus_one.is_some()) {
                agg.chromatic_aberration = p.chromatic_aberration.clone();
            }
        }
        // Sharpening likewise: a view without isolated straight edges shows no halo.
        if agg.sharpening.amount.is_none() {
            if let Some(p) = prev.as_ref().filter(|p| p.sharpening.amount.is_some()) {
                agg.sharpening = p.sharpening.clone();
            }
        }
        if on[2] != agg.depth_of_field.present {
            match (&prev, on[2] && dp == 0) {
                (Some(p), true) => agg.depth_of_field = p.depth_of_field.clone(),
                _ => agg.depth_of_field.present = on[2] && agg.depth_of_field.curve.is_some(),
            }
        }
        // What is published says one thing per effect: `present` (the hysteresis'
        // decision) and the status agree, a present motion blur carries its
        // exposure and an absent one none. Not identifiable (no identifiable
        // estimate in the window) stays distinct from absent.
        settle(&mut agg.noise.diagnostics, agg.noise.present, on[0], (np, ni));
        settle(&mut agg.depth_of_field.diagnostics, agg.depth_of_field.present, on[2], (dp, di));
        if agg.motion_blur.present && agg.motion_blur.exposure.is_none() {
            agg.motion_blur.present = false;
        }
        if !agg.motion_blur.present {
            agg.motion_blur.exposure = None;
        }
        settle(&mut agg.motion_blur.diagnostics, agg.motion_blur.present, on[1], (mp, mi));
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

/// Sets a published effect's status from its presence, the hysteresis' decision
/// `on` and the window's votes (`present` of `identifiable`), saying so in the
/// reason where it changes. Voted present (`on`) but with no value to publish (no
/// reading pinned it down) is "not identifiable": the evidence is for the effect,
/// so it is never "absent".
fn settle(d: &mut crate::model::Diagnostics, present: bool, on: bool, (present_votes, identifiable): (usize, usize)) {
    let status = if present {
        Status::Present
    } else if on {
        Status::NotIdentifiable
    } else if identifiable > 0 {
        Status::Absent
    } else if d.status == Status::NotFitted {
        return; // not requested, or not yet fitted: says so already
    } else {
        Status::NotIdentifiable
    };
    if d.status != status {
        let word = match status {
            Status::Present => "present",
            Status::Absent => "absent",
            _ => "not identifiable",
        };
        d.reason = format!(
            "{word} by the window's vote ({present_votes} of {identifiable} identifiable estimates present, with \
             hysteresis); the aggregate said: {}",
            d.reason
        );
        d.status = status;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Diagnostics, MotionBlur};
    use crate::worker::{CalibrationTier, CalibratorConfig, Providers};

    fn estimate(frame: u64, status: Status, exposure: Option<f32>, speed_px: f32) -> Estimate {
        let mut model = CameraModel::empty(320, 240);
        let mut d = Diagnostics::not_fitted("test reading");
        (d.status, d.method, d.stderr) = (status, "fast".into(), Some(0.01));
        model.motion_blur = MotionBlur { present: status == Status::Present, exposure, diagnostics: d };
        Estimate { frame, t_s: frame as f64 / 30.0, model, noise_lags: Vec::new(), speed_px: Some(speed_px) }
    }

    /// A confident λ, then a second of slow-head frames whose readings say
    /// "absent" at 0.5 px/frame (the held λ 0.5 would streak 0.25 px there: not
    /// visible, so no evidence): the exposure is kept, present, with status
    /// present. Then a second of frames at 8 px/frame that show no streak where
    /// 4 px were due: dropped, absent, no exposure. Every publication consistent.
    #[test]
    fn absent_readings_count_only_where_the_held_exposure_would_show() {
        let cfg = CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, None);
        let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast)).expect("config");
        let publish = |cal: &mut Calibrator, e: Estimate| {
            let (frame, t_s) = (e.frame, e.t_s);
            cal.estimates.push_back(e);
            let m = cal.aggregate(frame, t_s, UpdateReason::Schedule, Instant::now()).expect("published").model;
            let mb = &m.motion_blur;
            assert_eq!(
                mb.present,
                mb.diagnostics.status == Status::Present,
                "frame {frame}: {}",
                mb.diagnostics.reason
            );
            assert_eq!(
                mb.present,
                mb.exposure.is_some(),
                "frame {frame}: present {} exposure {:?}",
                mb.present,
                mb.exposure
            );
            m
        };
        let m = publish(&mut cal, estimate(0, Status::Present, Some(0.5), 8.0));
        assert!(m.motion_blur.present);
        for f in 1..=40 {
            let m = publish(&mut cal, estimate(f, Status::Absent, Some(0.0), 0.5));
            assert!(m.motion_blur.present, "frame {f}: dropped on readings that could not show it");
            assert_eq!(m.motion_blur.exposure, Some(0.5), "frame {f}");
        }
        let mut last = None;
        for f in 41..=80 {
            last = Some(publish(&mut cal, estimate(f, Status::Absent, Some(0.0), 8.0)));
        }
        let m = last.expect("published");
        assert!(!m.motion_blur.present, "absence shown at 8 px/frame must drop the exposure");
        assert_eq!(m.motion_blur.diagnostics.status, Status::Absent);
    }

    /// Present readings through a turn, one confident "absent" as it decelerates
    /// (5 px/frame, where the held λ would streak 2.5 px), then two seconds of rest
    /// (readings at 0.2 px/frame, no evidence either way): the exposure is held
    /// through the rest — one reading is not the evidence that drops it.
    #[test]
    fn one_absent_reading_does_not_drop_the_exposure_over_the_rest_after_it() {
        let cfg = CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, None);
        let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast)).expect("config");
        let mut frames = vec![];
        frames.extend((0..15).map(|f| estimate(f, Status::Present, Some(0.5), 8.0)));
        frames.push(estimate(15, Status::Absent, Some(0.0), 5.0));
        frames.extend((16..76).map(|f| estimate(f, Status::Absent, Some(0.0), 0.2)));
        for e in frames {
            let (frame, t_s) = (e.frame, e.t_s);
            cal.estimates.push_back(e);
            let m = cal.aggregate(frame, t_s, UpdateReason::Schedule, Instant::now()).expect("published").model;
            assert!(m.motion_blur.present, "frame {frame}: dropped: {}", m.motion_blur.diagnostics.reason);
            assert_eq!(m.motion_blur.exposure, Some(0.5), "frame {frame}");
            assert_eq!(m.motion_blur.diagnostics.status, Status::Present, "frame {frame}");
        }
    }

    /// The accurate tier's exposure memory (`CalibratorConfig::exposure_memory_s`,
    /// 4 s): two turns 2 s apart, the first reading λ 0.43–0.45, the second 0.35–
    /// 0.38 (single fits scatter like that on real scenes made elsewhere), with a
    /// rest between them that reads nothing: at the end of the second turn the
    /// published λ is the median of all seven readings (0.38), not of the second
    /// turn's alone (the 1 s window's: 0.37). After a detected change the readings
    /// from before it are gone: the new camera's 0.8 is published alone.
    #[test]
    fn the_accurate_exposure_is_the_median_since_the_last_change() {
        let cfg = CalibratorConfig::new(CalibrationTier::Accurate, 1.0 / 30.0, None);
        let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Accurate)).expect("config");
        let reading = |frame: u64, lambda: Option<f32>| {
            let status = if lambda.is_some() { Status::Present } else { Status::NotIdentifiable };
            let mut e = estimate(frame, status, lambda, if lambda.is_some() { 8.0 } else { 0.2 });
            e.model.motion_blur.diagnostics.method = "accurate".into();
            e
        };
        let publish = |cal: &mut Calibrator, e: Estimate| {
            let (frame, t_s) = (e.frame, e.t_s);
            cal.estimates.push_back(e);
            cal.aggregate(frame, t_s, UpdateReason::Schedule, Instant::now()).expect("published").model
        };
        // Turn one: frames 0, 3, 6 (every 0.1 s); rest: frames 9…57, nothing read;
        // turn two: frames 60, 63, 66, 69.
        for (f, l) in [(0, 0.44), (3, 0.43), (6, 0.45)] {
            publish(&mut cal, reading(f, Some(l)));
        }
        for f in (9..60).step_by(3) {
            let m = publish(&mut cal, reading(f, None));
            assert_eq!(m.motion_blur.exposure, Some(0.44), "frame {f}: the rest keeps the first turn's median");
        }
        let mut last = None;
        for (f, l) in [(60, 0.36), (63, 0.37), (66, 0.35), (69, 0.38)] {
            last = Some(publish(&mut cal, reading(f, Some(l))));
        }
        let m = last.expect("published");
        assert_eq!(m.motion_blur.exposure, Some(0.38), "the median of both turns' seven readings");
        let mut events = vec![];
        cal.on_change(70, 70.0 / 30.0, 70.0 / 30.0, "test".into(), &mut events);
        let m = publish(&mut cal, reading(72, Some(0.8)));
        assert_eq!(m.motion_blur.exposure, Some(0.8), "readings from before the change are forgotten");
    }

    /// A window whose only identifiable reading says "present" but pins λ down to
    /// no better than ± 0.05 (a short streak at the start of a turn) publishes
    /// "not identifiable" — never "absent", which would tell the renderer the
    /// camera has no exposure (seen on a Middlebury scene's first turn: "absent by
    /// the window's vote (1 of 1 identifiable estimates present)").
    #[test]
    fn a_present_reading_without_a_confident_exposure_is_not_absent() {
        let cfg = CalibratorConfig::new(CalibrationTier::Fast, 1.0 / 30.0, None);
        let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast)).expect("config");
        let mut e = estimate(0, Status::Present, Some(0.45), 8.0);
        e.model.motion_blur.diagnostics.stderr = Some(0.08);
        cal.estimates.push_back(e);
        let m = cal.aggregate(0, 0.0, UpdateReason::Schedule, Instant::now()).expect("published").model;
        let mb = &m.motion_blur;
        assert!(!mb.present && mb.exposure.is_none(), "no confident λ: nothing to render ({:?})", mb.exposure);
        assert_eq!(mb.diagnostics.status, Status::NotIdentifiable, "{}", mb.diagnostics.reason);
    }
}
