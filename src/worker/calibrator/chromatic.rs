//! The lateral chromatic aberration term's video: each update at
//! `CalibratorConfig::chromatic_refit_s` reads the frame's red and blue scales from
//! a few hundred edge windows (`fit::chromatic::estimate_with`) and pools the
//! estimates of the last `CHROMATIC_WINDOW_S` (`fit::chromatic::pool`). A lens's
//! aberration does not change with the scene, so the window is long; frames
//! without enough radial edges add nothing.

use super::*;
use crate::fit::chromatic::{self, ScaleEstimate};

/// Frames pooled: the last this many seconds of video (16 frames at one per 0.5 s).
pub(super) const CHROMATIC_WINDOW_S: f64 = 8.0;
/// Edge windows read per frame: 250 cost 3.6 ms at 1280×960 on one thread from
/// the last reading, 4.7 ms from none (the one-frame estimator's 1 000, 13 ms,
/// spread over four frames; BENCHMARKS.md "Lateral chromatic aberration").
pub(super) const WINDOWS_PER_FRAME: usize = 250;

/// The aberration fit's state: the frames' estimates of the window (time, [red,
/// blue]) and the last refit's time.
#[derive(Default)]
pub(super) struct ChromaticVideo {
    frames: VecDeque<(f64, [Option<ScaleEstimate>; 2])>,
    last_t_s: Option<f64>,
}

impl Calibrator {
    /// The aberration term at this frame when its cadence comes and the update is
    /// not `busy` with another slow term (`None`: not refitted this update; a busy
    /// update defers it to the next).
    pub(super) fn fit_chromatic_at(
        &mut self,
        current: &Arc<Analysed>,
        busy: bool,
    ) -> Option<crate::model::ChromaticAberration> {
        let t_s = current.frame.t_s;
        let c = &mut self.chromatic;
        let due = c.last_t_s.map_or(true, |l| t_s < l || t_s - l >= self.cfg.chromatic_refit_s - 1e-9);
        if !self.cfg.chromatic_aberration || !due || busy {
            return None;
        }
        c.last_t_s = Some(t_s);
        let image = &current.frame.image;
        // The passes start from the newest reading of each channel (a lens does not
        // change: one pass instead of three to six, 3.6 ms instead of 4.7 at
        // 1280×960).
        let start: [f64; 2] =
            std::array::from_fn(|k| c.frames.iter().rev().find_map(|f| f.1[k]).map_or(0.0, |e| e.scale_minus_one));
        let estimate = chromatic::estimate_from(image, WINDOWS_PER_FRAME, start);
        if estimate.iter().any(Option::is_some) {
            c.frames.push_back((t_s, estimate));
        }
        c.frames.retain(|f| f.0 <= t_s && f.0 > t_s - CHROMATIC_WINDOW_S);
        let half_diag_px = ((image.width as f64 - 1.0) * 0.5).hypot((image.height as f64 - 1.0) * 0.5);
        let frames: Vec<[Option<ScaleEstimate>; 2]> = c.frames.iter().map(|f| f.1).collect();
        Some(chromatic::pool(&frames, half_diag_px))
    }
}
