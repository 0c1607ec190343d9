//! The blind noise fit's provenance per level (`model::LevelSource`): which levels
//! the frame measured, over which lumas and how surely, and which it continued.

use super::LevelPoints;
use crate::model::{LevelSource, Noise, NOISE_LEVELS};

/// Lumas across the model's range, ends included (where a line extrapolated from a
/// few bins is least sure), at which a level's error is evaluated.
const EVAL_POINTS: usize = 9;

/// The std (0–1 pixel values, any band-pass level ≥ 1) that the difference against
/// an aligned neighbour leaves of the scene where the two exposures differ (motion
/// blur, parallax, resampling), read as noise. Measured on the calibration video
/// (white noise, whose coarse levels are weakest, frames 55–62): √(read² − truth²) at mid luma, levels 2 and 3,
/// −0.0001…+0.0008 at 640×480 full frames and +0.0000…+0.0010 in the worker's
/// 240-row strips at 1280×960, median 0.00043 (level 1: −0.0004…+0.0007); taken
/// as 0.0005.
const NEIGHBOUR_RESIDUE_STD: f32 = 0.0005;
/// The same for a frame read alone at levels 1–3: the scene's texture in the flattest
/// samples of a coarse level that passed the fit's checks (`MAX_LEVEL_STD_RATIO`,
/// `trim_textured`). Measured alike at level 1 in the worker's strips at 1280×960,
/// frames 55–62, where the frame alone measured it on every frame: white noise
/// +0.0010…+0.0041, the codec's +0.0002…+0.0060; median 0.0030. Level 0's is
/// `blind::TEXTURE_FLOOR_STD`, twice it.
const ALONE_RESIDUE_STD: f32 = 0.003;

/// Least share of level 0's luma span a coarser level's bins span unremarked.
const PARTIAL_LEVEL_SPAN: f32 = 0.5;

/// Every level's source for a blind fit whose levels `measured` (finest first,
/// level 0 among them) were fitted — on `points`, with the affine-variance
/// covariance per channel `covs` (`fit_levels`) and their bins' median relative
/// standard error `bin_rel_se`, one each — and the rest continued from the coarsest
/// of them.
///
/// A measured level's relative standard error is, at each luma of
/// `noise.luminance_range`, in quadrature:
/// - sampling: the delta method on its variance line's covariance (δstd = δvar /
///   (2·std)), floored by its bins' own median error over √bins (a line through 3
///   bins has one residual degree of freedom: its scatter may read near 0 by chance);
/// - continuation, beyond the lumas its bins span: the relative difference between
///   its own map and level 0's map scaled to it at its bins' mean luma. The data
///   cannot choose between the two there: a level's luma dependence is the sensor's
///   (the same as level 0's) unless processing reshaped it, and a line on three dark
///   bins (demosaic-like noise on the calibration video: BENCHMARKS.md "Correlated
///   noise on video") is as likely either;
/// - `level0_bias` for level 0 only: the texture the frame alone leaves in its
///   flattest samples (`texture_bias`, measured at level 0; 0 with a neighbour);
/// - at levels 1–3, an additive std T read as noise (relative bias √(1 + (T/σ)²) −
///   1): with a neighbour, what the difference leaves of the scene where the two
///   exposures differ (`NEIGHBOUR_RESIDUE_STD`); alone, texture in the flattest
///   samples (`ALONE_RESIDUE_STD`).
///
/// Root-mean-square over `EVAL_POINTS` lumas of the range, mean over channels, each
/// luma's capped at 1 (a std that could be none or twice itself: nothing known).
/// The two residues are priors from one scene (BENCHMARKS.md "The blind noise's
/// level sources": how often the error exceeds the stated one, held-out frames too).
pub(super) fn level_sources(
    noise: &Noise,
    measured: &[usize],
    points: &[LevelPoints],
    covs: &[[[[f64; 2]; 2]; 3]],
    bin_rel_se: &[f32],
    level0_bias: f32,
    with_neighbour: bool,
) -> Vec<LevelSource> {
    let Some(&coarsest) = measured.last() else { return vec![] };
    let [lo, hi] = noise.luminance_range;
    let lumas: Vec<f32> = (0..EVAL_POINTS).map(|i| lo + (hi - lo) * i as f32 / (EVAL_POINTS - 1) as f32).collect();
    let form = noise.form;
    let level0 = &noise.levels[0];
    (0..NOISE_LEVELS)
        .map(|l| {
            let Some(i) = measured.iter().position(|&m| m == l) else {
                return LevelSource::Continued { from: coarsest as u32 };
            };
            let y = &points[i].y;
            let Some(span) = luma_span(y) else {
                return LevelSource::Continued { from: coarsest as u32 };
            };
            let mean_y = y.iter().sum::<f32>() / y.len() as f32;
            let floor = bin_rel_se[i] / (y.len() as f32).sqrt();
            let own = &noise.levels[l];
            let sum_sq = lumas
                .iter()
                .map(|&yl| {
                    (0..3)
                        .map(|c| {
                            let std = own.std(form, c, yl) as f64;
                            if std <= 0.0 {
                                return 1.0;
                            }
                            let cov = covs[i][c];
                            let yd = yl as f64;
                            let var_se = (cov[0][0] + 2.0 * yd * cov[0][1] + yd * yd * cov[1][1]).max(0.0).sqrt();
                            let sampling = (var_se / (2.0 * std * std)).max(floor as f64);
                            let outside = yl < span[0] || yl > span[1];
                            let continuation = if outside && l > 0 {
                                let at = (own.std(form, c, mean_y) / level0.std(form, c, mean_y).max(1e-12)) as f64;
                                let alt = at * level0.std(form, c, yl) as f64;
                                (std - alt).abs() / std.max(alt)
                            } else {
                                0.0
                            };
                            let bias = match (l, with_neighbour) {
                                (0, _) => level0_bias as f64,
                                (_, true) => (1.0 + (NEIGHBOUR_RESIDUE_STD as f64 / std).powi(2)).sqrt() - 1.0,
                                (_, false) => (1.0 + (ALONE_RESIDUE_STD as f64 / std).powi(2)).sqrt() - 1.0,
                            };
                            // 1: the std could be none or twice itself — nothing known.
                            (sampling.powi(2) + continuation.powi(2) + bias.powi(2)).min(1.0) / 3.0
                        })
                        .sum::<f64>()
                })
                .sum::<f64>();
            let rms = (sum_sq / EVAL_POINTS as f64).sqrt();
            LevelSource::Measured {
                luma: [span[0].clamp(0.0, 1.0), span[1].clamp(0.0, 1.0)],
                bins: y.len() as u32,
                relative_stderr: rms as f32,
            }
        })
        .collect()
}

/// The reason's note on each coarser level measured on bins spanning under
/// `PARTIAL_LEVEL_SPAN` of level 0's lumas: its line is extrapolated over the rest
/// (one frame of demosaic-like noise read level 1 on three dark bins, −9…−28%:
/// BENCHMARKS.md "Correlated noise on video"). Empty when there is none.
pub(super) fn partial_level_notes(noise: &Noise) -> String {
    let [lo0, hi0] = noise.luminance_range;
    let mut out = String::new();
    for (l, source) in noise.level_sources.iter().enumerate().skip(1) {
        if let LevelSource::Measured { luma: [a, b], bins, relative_stderr } = *source {
            if hi0 > lo0 && b - a < PARTIAL_LEVEL_SPAN * (hi0 - lo0) {
                out += &format!(
                    "; level {l} measured over luma {a:.2}–{b:.2} only ({bins} bins), its line extrapolated over \
                     level 0's range (±{:.0}% over it)",
                    100.0 * relative_stderr
                );
            }
        }
    }
    out
}

/// The lowest and highest of the lumas `y` (`None` when empty).
pub(super) fn luma_span(y: &[f32]) -> Option<[f32; 2]> {
    let lo = y.iter().cloned().reduce(f32::min)?;
    let hi = y.iter().cloned().reduce(f32::max)?;
    Some([lo, hi])
}
