//! The worker's two noise fits on one update: blind on this update's strip (with
//! the previous frame aligned there, or the frame alone), or accurate against a
//! temporal reference; and the stream-level facts they read (the strip in turn,
//! the codec's grid).

use super::report::Event;
use super::{Calibrator, CODEC_GRID_RECHECK_S, MIN_STRIP_ROWS};
use crate::analysis::temporal::Aligned;
use crate::analysis::{Analysed, Reference};
use crate::fit::{self, Effects, FitInputs, FitOptions};
use crate::model::{CameraModel, NoiseForm};
use std::sync::Arc;
use std::time::Instant;

/// Scale a fitted noise model by `variance_factor` (the temporal reference's
/// leftover noise divided out).
pub(super) fn scale_noise(m: &mut CameraModel, variance_factor: f32) {
    let s = match m.noise.form {
        NoiseForm::AffineVariance => variance_factor,
        NoiseForm::LinearStd => variance_factor.sqrt(),
    };
    for l in m.noise.levels.iter_mut().chain(m.noise.lowpass.iter_mut()) {
        l.slope.iter_mut().chain(l.intercept.iter_mut()).for_each(|v| *v *= s);
    }
}

impl Calibrator {
    /// The rows the next blind noise refit reads (`CalibratorConfig::noise_strip_px`):
    /// strips of a whole number of 16-row blocks (compression blocks keep their
    /// phase), top to bottom in turn.
    pub(super) fn noise_strip(&self, w: usize, h: usize) -> std::ops::Range<usize> {
        let Some(px) = self.cfg.noise_strip_px else { return 0..h };
        let n = (w * h).div_ceil(px.max(w * MIN_STRIP_ROWS).max(1)).max(1);
        let rows = h.div_ceil(n).next_multiple_of(16).min(h).max(1);
        let y0 = (self.noise_strips_fitted % h.div_ceil(rows)) * rows;
        y0..(y0 + rows).min(h)
    }

    /// Whether the stream shows a block codec's grid (`fit::compression_blocking`),
    /// checked on this frame if the last check is `CODEC_GRID_RECHECK_S` old.
    pub(super) fn codec_grid(&mut self, current: &Analysed) -> bool {
        let t_s = current.frame.t_s;
        match self.codec_grid {
            Some((at, grid)) if (t_s - at).abs() < CODEC_GRID_RECHECK_S => grid,
            _ => {
                let grid = fit::compression_blocking(&current.frame.image).is_some();
                self.codec_grid = Some((t_s, grid));
                grid
            }
        }
    }

    /// The blind noise fit on this update's strip (`noise_strip`) into `model.noise`,
    /// with `neighbour` (the previous frame aligned) where given, and the lag it read
    /// a difference at into `noise_lags`.
    pub(super) fn fit_noise_strip(
        &mut self,
        current: &Analysed,
        neighbour: Option<Arc<Aligned>>,
        neighbour_lag: Option<u64>,
        model: &mut CameraModel,
        noise_lags: &mut Vec<u64>,
        events: &mut Vec<Event>,
    ) {
        let index = current.frame.index;
        let image = &current.frame.image;
        let fast_opts = FitOptions {
            tier: Some(fit::Tier::Fast),
            effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
            ..Default::default()
        };
        let t0 = Instant::now();
        let (w, h) = (image.width, image.height);
        let strip = self.noise_strip(w, h);
        // A temporal denoiser that failed leaves the fit blind: it still reads
        // the previous frame aligned (`aligned_strip`).
        let neighbour = match neighbour {
            None if self.providers.denoise.is_some() && !self.noise_copied_otherwise() => {
                self.aligned_strip(current, strip.clone())
            }
            n => n,
        };
        self.noise_strips_fitted += 1;
        let (y0, rows) = (strip.start, strip.len());
        let crop = |img: &crate::image::Rgb| img.crop(0, y0, w, rows);
        let neighbour_strip = neighbour.as_ref().and_then(|a| {
            let valid = a.valid[y0 * w..strip.end * w].iter().map(|&v| if v { 1.0 } else { 0.0 }).collect();
            Some((crop(&a.image)?, crate::image::Plane::from_vec(w, rows, valid)))
        });
        let strip_image = crop(image);
        let glue_s = t0.elapsed().as_secs_f64();
        match strip_image {
            Some(strip_image) => {
                let inp = FitInputs {
                    neighbour: neighbour_strip.as_ref().map(|(image, valid)| fit::Neighbour { image, valid }),
                    ..FitInputs::new(&strip_image)
                };
                match fit::fit(&inp, &fast_opts) {
                    Ok(o) => {
                        model.noise = o.model.noise;
                        if model.noise.diagnostics.method == fit::NOISE_FAST_WITH_NEIGHBOUR {
                            noise_lags.extend(neighbour_lag);
                        }
                    }
                    Err(e) => events.push(Event::Degraded { frame: index, reason: format!("noise fit: {e}") }),
                }
            }
            None => events.push(Event::Degraded { frame: index, reason: format!("noise strip {strip:?} of {h} rows") }),
        }
        // The strip's copies count with the fit.
        model.noise.diagnostics.fit_time_s += glue_s;
    }

    /// The accurate noise fit against the temporal reference `r` (the mean of
    /// aligned other frames, or a network's output) into `model.noise`, its leftover
    /// noise divided out, and the lags of the frames it was made from into
    /// `noise_lags`.
    pub(super) fn fit_noise_on_reference(
        &self,
        base: &FitInputs,
        r: &Reference,
        index: u64,
        model: &mut CameraModel,
        noise_lags: &mut Vec<u64>,
        events: &mut Vec<Event>,
    ) {
        let inp = FitInputs { denoised: Some(&r.image), reference_valid: r.valid.as_ref(), ..*base };
        // A reference aligned from other frames is refused where it leaks (one
        // estimate of several in the window); a network's is kept.
        let refuse = (!r.sources.is_empty()).then_some(fit::NOISE_MIN_LEAK_RATIO);
        let opts = FitOptions {
            tier: Some(fit::Tier::Accurate),
            noise_min_leak_ratio: refuse,
            effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
            ..Default::default()
        };
        match fit::fit(&inp, &opts) {
            Ok(o) => {
                model.noise = o.model.noise;
                // I − mean carries (1 + ratio)·σ².
                scale_noise(model, 1.0 / (1.0 + r.noise_variance_ratio));
                model.noise.diagnostics.method = "accurate (temporal reference)".into();
                *noise_lags = r.sources.iter().map(|&s| index.saturating_sub(s)).collect();
            }
            Err(e) => events.push(Event::Degraded { frame: index, reason: format!("noise fit: {e}") }),
        }
    }
}
