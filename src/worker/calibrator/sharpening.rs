//! The ISP sharpening term's video: each update at
//! `CalibratorConfig::sharpening_refit_s` reads the frame's straight edges
//! (`fit::sharpening::frame_costs`, at most `EDGES_PER_FRAME`) and decides on the
//! tables of the last `SHARPENING_WINDOW_S` summed (`fit::sharpening::decide`): an
//! ISP's sharpening does not change with the scene, and one frame seldom holds the
//! 20 isolated straight edges a reading needs.

use super::*;
use crate::fit::sharpening::{self, SharpeningCosts};

/// Frames pooled: the last this many seconds of video (8 frames at one per 1 s).
pub(super) const SHARPENING_WINDOW_S: f64 = 8.0;
/// Candidate edges fitted per frame: ~0.4 ms each on one core, so 60 keep a refit
/// at 22–47 ms (320×240 to 1280×960; BENCHMARKS.md "Sharpening"); 8 s of frames
/// pool up to 480.
pub(super) const EDGES_PER_FRAME: usize = 60;

/// The sharpening fit's state: the frames' tables of the window and the last
/// refit's time.
#[derive(Default)]
pub(super) struct SharpeningVideo {
    frames: VecDeque<(f64, SharpeningCosts)>,
    last_t_s: Option<f64>,
}

impl Calibrator {
    /// The sharpening term at this frame when its cadence comes and the update is
    /// not `busy` with another slow term (`None`: not refitted this update; a busy
    /// update defers it to the next).
    pub(super) fn fit_sharpening_at(
        &mut self,
        current: &Arc<Analysed>,
        busy: bool,
    ) -> Option<crate::model::Sharpening> {
        let t_s = current.frame.t_s;
        let s = &mut self.sharpening;
        let due = s.last_t_s.map_or(true, |l| t_s < l || t_s - l >= self.cfg.sharpening_refit_s - 1e-9);
        if !self.cfg.sharpening || !due || busy {
            return None;
        }
        s.last_t_s = Some(t_s);
        let started = Instant::now();
        let costs = sharpening::frame_costs(&current.frame.image, EDGES_PER_FRAME);
        if costs.edges > 0 {
            s.frames.push_back((t_s, costs));
        }
        s.frames.retain(|f| f.0 <= t_s && f.0 > t_s - SHARPENING_WINDOW_S);
        let mut pooled = SharpeningCosts::default();
        for f in &s.frames {
            pooled.add(&f.1);
        }
        Some(sharpening::decide(&pooled, "video", started))
    }
}
