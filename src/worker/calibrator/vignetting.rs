//! The vignetting term's video: each update at `CalibratorConfig::vignetting_refit_s`
//! pairs the frame with the one held from the last such update, matches a grid of
//! its surfaces there by pose and depth (`analysis::temporal::correspond`), keeps
//! the flat samples' log-ratios (`fit::vignetting::pair_rows`) and refits over the
//! pairs of the last `VIGNETTING_WINDOW_S` (`fit::vignetting::fit_vignetting`).
//! A lens's falloff does not change with the scene, so the window is long; pairs
//! where the head barely moved (every surface at the same radius twice) carry no
//! information and are not kept, so a rest does not dilute it.

use super::*;
use crate::fit::vignetting::{self, Row};

/// Frame pairs pooled: the last this many seconds of video (32 pairs at one per
/// 0.25 s).
pub(super) const VIGNETTING_WINDOW_S: f64 = 8.0;
/// Rows kept per pair: a grid-ordered subsample past this many. At 320×240 a pair
/// keeps 15–120 of its 1 131 boxes (`tests/vignetting_sequence.rs`), under the cap;
/// at 1280×960 the cap bounds the window's IRLS to 12 800 rows (the refit's
/// 1.5–2.6 ms there, BENCHMARKS.md "Vignetting").
const MAX_ROWS_PER_PAIR: usize = 400;
/// A pair whose samples moved in r² by less than this RMS shows no falloff
/// difference (a head at rest): not kept.
const MIN_RMS_DELTA_R2: f64 = 0.01;

/// The vignetting fit's state: the frame held from the last update and the pairs'
/// rows of the window (time, rows).
#[derive(Default)]
pub(super) struct VignettingVideo {
    held: Option<Arc<Analysed>>,
    pairs: VecDeque<(f64, Vec<Row>)>,
    last_t_s: Option<f64>,
    /// The last fit and the pairs' (count, newest time) it was made from: a head at
    /// rest adds no pair, and the same pairs give the same fit.
    last_fit: Option<(crate::model::Vignetting, (usize, f64))>,
}

impl Calibrator {
    /// The vignetting term at this frame, when its cadence comes and the frame has a
    /// pose and metric depth (`None`: not refitted this update).
    pub(super) fn fit_vignetting_at(&mut self, current: &Arc<Analysed>) -> Option<crate::model::Vignetting> {
        let t_s = current.frame.t_s;
        let v = &mut self.vignetting;
        let due = v.last_t_s.map_or(true, |l| t_s < l || t_s - l >= self.cfg.vignetting_refit_s - 1e-9);
        if !self.cfg.vignetting || !due {
            return None;
        }
        let k = self.cfg.intrinsics?;
        v.last_t_s = Some(t_s);
        let previous = v.held.replace(current.clone());
        if let Some(src) = previous.filter(|p| p.frame.t_s < t_s) {
            let (w, h) = (current.frame.image.width, current.frame.image.height);
            let points = vignetting::sample_points(w, h);
            if let Some(matches) = crate::analysis::temporal::correspond(&src, current, &k, &points) {
                let mut rows = vignetting::pair_rows(&current.frame.image, &src.frame.image, &matches);
                if rows.len() > MAX_ROWS_PER_PAIR {
                    let step = rows.len().div_ceil(MAX_ROWS_PER_PAIR);
                    rows = rows.into_iter().step_by(step).collect();
                }
                let n = rows.len().max(1) as f64;
                let rms = (rows.iter().map(|r| (r[0] as f64).powi(2)).sum::<f64>() / n).sqrt();
                if rows.len() >= vignetting::MIN_ROWS_PER_PAIR && rms >= MIN_RMS_DELTA_R2 {
                    v.pairs.push_back((t_s, rows));
                }
            }
        }
        v.pairs.retain(|p| p.0 <= t_s && p.0 > t_s - VIGNETTING_WINDOW_S);
        let key = (v.pairs.len(), v.pairs.back().map_or(f64::NEG_INFINITY, |p| p.0));
        if let Some((fit, k)) = &v.last_fit {
            if *k == key {
                return Some(fit.clone());
            }
        }
        let refs: Vec<&[Row]> = v.pairs.iter().map(|p| p.1.as_slice()).collect();
        let fit = vignetting::fit_vignetting(&refs);
        v.last_fit = Some((fit.clone(), key));
        Some(fit)
    }
}
