//! The status of a motion-blur reading (present / absent / not identifiable), shared
//! by both tiers' single-frame fits and the worker's pooled fit: the negligible-streak
//! bounds and the flow speed they are judged at.

use crate::image::Flow;
use crate::model::Status;

/// Above this half-width of the isotropy estimator's 90% band its λ is reported
/// not identifiable: the band then spans more than half of [0, 1]. The worker's
/// pooled isotropy (`fit::isotropy_pool`) holds its standard error to the same.
pub(crate) const MAX_ISOTROPY_HALF_BAND: f64 = 0.25;

/// Least exposure read as a streak at all (a 0.1 px streak at 20 px/frame).
pub(crate) const MIN_EXPOSURE: f32 = 0.005;

/// Shortest streak (px) that is not negligible: a box of this length has a standard
/// deviation of 0.1 px (L/√12), the defocus fit's bound for an invisible blur
/// (`dof::finish`: δ under 0.1 px is absent), so the two effects call "absent" the
/// same amount of blur.
pub(crate) const INVISIBLE_STREAK_PX: f32 = 0.35;

/// A flow's speed (px/frame) for `exposure_status`: the 90th percentile of |F| over
/// a grid of about 4 096 of its pixels (finite vectors only), so that "negligible"
/// means negligible where the flow is fast too (a head turn's edges move ~2× its
/// centre). `None` without a finite vector.
pub(crate) fn visible_speed_px(flow: &Flow) -> Option<f32> {
    let (w, h) = (flow.width, flow.height);
    let step = (((w * h) as f64 / 4096.0).sqrt() as usize).max(1);
    let mut v: Vec<f32> = (0..h)
        .step_by(step)
        .flat_map(|y| (0..w).step_by(step).map(move |x| y * w + x))
        .map(|i| flow.dx[i].hypot(flow.dy[i]))
        .filter(|s| s.is_finite())
        .collect();
    (!v.is_empty()).then(|| crate::fit::percentile(&mut v, 0.9))
}

/// What a reading λ ± `stderr` says, both tiers alike. Present: above 3 standard
/// errors and `MIN_EXPOSURE`. Absent: the reading itself is negligible — under
/// `MIN_EXPOSURE`, or a streak under `INVISIBLE_STREAK_PX` at `speed_px`
/// (`visible_speed_px`) where the flow is known. Otherwise not identifiable: a
/// visible streak that the standard error cannot tell from none. (Called absent,
/// that case would take in 30 of the 123 box streaks of the evaluation frames, most
/// read within two standard errors of the truth — the astronaut's 8 px as 8.0 ±
/// 3.2 px —, and vote "no motion blur" in the worker's window.) A flow too slow
/// for even a whole-interval exposure to streak visibly (under `INVISIBLE_STREAK_PX`
/// per frame: a still head) cannot show the exposure at all: not identifiable,
/// whatever the reading. NaN is not identifiable.
pub(crate) fn exposure_status(lambda: f32, stderr: f64, speed_px: Option<f32>) -> Status {
    if lambda >= MIN_EXPOSURE && (lambda as f64) > 3.0 * stderr {
        Status::Present
    } else if speed_px.is_some_and(|s| s < INVISIBLE_STREAK_PX) {
        Status::NotIdentifiable
    } else if lambda < MIN_EXPOSURE || speed_px.is_some_and(|s| lambda * s < INVISIBLE_STREAK_PX) {
        Status::Absent
    } else {
        Status::NotIdentifiable
    }
}

/// The status's clause for a fit's reason (`exposure_status`).
pub(crate) fn exposure_status_note(status: Status, speed_px: Option<f32>) -> String {
    match status {
        Status::Present => format!("above 3 standard errors and {MIN_EXPOSURE}: present"),
        Status::Absent => match speed_px {
            Some(s) => format!(
                "negligible (below {MIN_EXPOSURE}, or a streak under {INVISIBLE_STREAK_PX} px at the flow's \
                 90th-percentile speed {s:.1} px/frame): absent"
            ),
            None => format!("negligible (below {MIN_EXPOSURE}): absent"),
        },
        _ => match speed_px {
            Some(s) => format!(
                "a visible streak ({INVISIBLE_STREAK_PX} px or more at the flow's 90th-percentile speed {s:.1} \
                 px/frame) but within 3 standard errors of none: not identifiable"
            ),
            None => "visible but within 3 standard errors of none: not identifiable".into(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The three outcomes on readings whose answer is known by the rule's definition,
    /// and the degenerate ones (NaN, no flow speed, a zero standard error).
    #[test]
    fn exposure_status_splits_negligible_from_unresolved() {
        // 0.3 ± 0.05: 6 standard errors, visible — present at any speed.
        assert_eq!(exposure_status(0.3, 0.05, Some(8.0)), Status::Present);
        // Present does not depend on visibility: the accurate tier resolves 0.3 px
        // streaks (tests/validation.rs, λ 0.2 at 1.5 px/frame).
        assert_eq!(exposure_status(0.2, 0.01, Some(1.5)), Status::Present);
        // 0.16 ± 0.076 at 50 px/frame: an 8 px streak within 3 errors of none.
        assert_eq!(exposure_status(0.16, 0.076, Some(50.0)), Status::NotIdentifiable);
        // The same reading at 2 px/frame: a 0.32 px streak, negligible.
        assert_eq!(exposure_status(0.16, 0.076, Some(2.0)), Status::Absent);
        // Below MIN_EXPOSURE: negligible whatever the speed, or without one.
        assert_eq!(exposure_status(0.004, 1e-4, Some(500.0)), Status::Absent);
        assert_eq!(exposure_status(0.0, 0.2, None), Status::Absent);
        // No speed known: a reading above MIN_EXPOSURE within its error says neither.
        assert_eq!(exposure_status(0.16, 0.076, None), Status::NotIdentifiable);
        // The boundary of visibility, and an exact zero error.
        assert_eq!(exposure_status(0.0069, 0.01, Some(50.0)), Status::Absent);
        assert_eq!(exposure_status(0.0071, 0.01, Some(50.0)), Status::NotIdentifiable);
        assert_eq!(exposure_status(0.5, 0.0, Some(8.0)), Status::Present);
        // A still head (0.2 px/frame: a whole-interval exposure would streak 0.2 px)
        // shows no exposure: a reading of none there is not identifiable, not absent.
        assert_eq!(exposure_status(0.0, 0.0, Some(0.2)), Status::NotIdentifiable);
        assert_eq!(exposure_status(0.004, 1e-4, Some(0.0)), Status::NotIdentifiable);
        // NaN reads nothing.
        assert_eq!(exposure_status(f32::NAN, 0.01, Some(8.0)), Status::NotIdentifiable);
        assert_eq!(exposure_status(0.5, f64::NAN, Some(8.0)), Status::NotIdentifiable);
    }

    /// The 90th percentile of |F| over the grid; non-finite vectors skipped; none
    /// without a finite one.
    #[test]
    fn visible_speed_is_the_fast_end_of_the_flow() {
        let uniform = Flow::uniform(64, 48, 3.0, 4.0);
        assert_eq!(visible_speed_px(&uniform), Some(5.0));
        // Speeds 0..10 rising along x: the 90th percentile of the columns read.
        let mut ramp = Flow::uniform(100, 10, 0.0, 0.0);
        for y in 0..10 {
            for x in 0..100 {
                ramp.dx[y * 100 + x] = x as f32 / 10.0;
            }
        }
        let s = visible_speed_px(&ramp).expect("finite flow");
        assert!((s - 8.9).abs() <= 0.11, "{s}");
        let mut holes = Flow::uniform(8, 8, 2.0, 0.0);
        holes.dx[0] = f32::NAN;
        holes.dy[1] = f32::INFINITY;
        assert_eq!(visible_speed_px(&holes), Some(2.0));
        let none = Flow { width: 2, height: 1, dx: vec![f32::NAN; 2], dy: vec![0.0; 2] };
        assert_eq!(visible_speed_px(&none), None);
        assert_eq!(visible_speed_px(&Flow::uniform(0, 0, 1.0, 1.0)), None);
    }
}
