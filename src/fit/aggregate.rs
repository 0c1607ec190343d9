//! Robust aggregation of per-frame models (`fit --frames`): the coefficient-wise
//! median of present fits, so a few bad frames (a cut, a flash, a wrong flow) do
//! not move the result (noise: over the fits near the medoid, of their most shared
//! form, `noise_pool`). The DoF curve of the median frame (by δ at mid-range) is kept
//! whole, since curve coefficients do not average meaningfully.

use super::FitError;
use crate::model::{CameraModel, Diagnostics, LevelSource, Status, NOISE_LEVELS};

/// The median; of an even count, the mean of the middle two (the upper one alone
/// made a window of two estimates publish the larger: a contaminated noise fit
/// beside a clean one read +45% at the calibration video's level 3).
pub(crate) fn median(mut v: Vec<f32>) -> f32 {
    v.sort_by(|a, b| a.total_cmp(b));
    match v.len() {
        0 => 0.0,
        n if n % 2 == 0 => 0.5 * (v[n / 2 - 1] + v[n / 2]),
        n => v[n / 2],
    }
}

fn summary(ds: &[&Diagnostics], present: usize, total: usize) -> Diagnostics {
    let mut d = ds.first().map(|d| (*d).clone()).unwrap_or_else(|| Diagnostics::not_fitted("no frames"));
    d.samples_used = ds.iter().map(|d| d.samples_used).sum();
    d.fit_time_s = ds.iter().map(|d| d.fit_time_s).sum();
    d.reason = format!("median over {present} of {total} frames where present; {}", d.reason);
    d
}

/// Fits farther from the medoid than this many times the median distance are left
/// out of the coefficient-wise median (BENCHMARKS.md "The worker's noise at a
/// burst's start and after a reset": at 1× good fits were dropped too, and the
/// accurate tier's published error rose from 1.0% to 1.4% where every fit was good).
const NEAR_DISTANCE: f32 = 3.0;

/// Luma points (clamped into each model's range, as the renderer reads it) where
/// `noise_signature` compares noise maps.
const SIGNATURE_LUMA: [f32; 3] = [0.25, 0.5, 0.75];

/// ln std per level, channel and `SIGNATURE_LUMA` point: noise maps of any form
/// compared on what they render.
fn noise_signature(n: &crate::model::Noise) -> Vec<f32> {
    let mut v = Vec::with_capacity(n.levels.len() * 3 * SIGNATURE_LUMA.len());
    for l in &n.levels {
        for c in 0..3 {
            for &y in &SIGNATURE_LUMA {
                v.push(l.std(n.form, c, n.clamp_luma(y)).max(1e-6).ln());
            }
        }
    }
    v
}

fn l1(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum()
}

/// The present noise fits whose coefficients are medianed: coefficients only mean
/// something between maps of one form and one intensity variable, so
/// 1. the medoid — the fit whose signature (`noise_signature`) lies nearest the
///    others' (least summed L1 distance);
/// 2. the fits within `NEAR_DISTANCE` × the median distance of it (a fit far off
///    what most render is an outlier, whatever its form);
/// 3. of those, the form and intensity most share (ties: the newest fit's).
///
/// The first fit's form once decided alone: on the calibration video the burst's
/// first fit (the one frame without an aligned neighbour, +57%) outvoted the next
/// two (within 3%, of another form) and was published for three frames, then the
/// mean of it and a later fit of its form (+27%) for four more.
fn noise_pool<'a>(noise: &[&'a CameraModel]) -> Vec<&'a CameraModel> {
    let sigs: Vec<Vec<f32>> = noise.iter().map(|m| noise_signature(&m.noise)).collect();
    let cost = |i: usize| sigs.iter().map(|s| l1(s, &sigs[i])).sum::<f32>();
    let Some(medoid) = (0..noise.len()).min_by(|&a, &b| cost(a).total_cmp(&cost(b))) else { return vec![] };
    let dist: Vec<f32> = sigs.iter().map(|s| l1(s, &sigs[medoid])).collect();
    let near = NEAR_DISTANCE * median(dist.clone());
    let kept: Vec<&CameraModel> = noise.iter().zip(&dist).filter(|(_, &d)| d <= near).map(|(m, _)| *m).collect();
    let kind = |m: &CameraModel| (m.noise.form, m.noise.intensity);
    // `max_by_key` keeps the last of equals: the newest.
    let Some(base) = kept.iter().max_by_key(|b| kept.iter().filter(|m| kind(m) == kind(b)).count()) else {
        return vec![];
    };
    let base = kind(base);
    kept.into_iter().filter(|m| kind(m) == base).collect()
}

/// The pooled fits' level sources (`model::LevelSource`): a level is measured where
/// most fits measured it — over the median of their lumas, bins and errors (the
/// frames of one window share their scene and its texture, so their errors are not
/// divided by √fits) — and otherwise continued from the coarsest measured level
/// finer than it. Empty unless every pooled fit says (hand-written or accurate ones
/// do not).
fn pooled_level_sources(fits: &[&CameraModel]) -> Vec<LevelSource> {
    if fits.is_empty() || fits.iter().any(|m| m.noise.level_sources.len() != NOISE_LEVELS) {
        return vec![];
    }
    let mut out: Vec<LevelSource> = Vec::with_capacity(NOISE_LEVELS);
    for l in 0..NOISE_LEVELS {
        let measured: Vec<([f32; 2], u32, f32)> = fits
            .iter()
            .filter_map(|m| match m.noise.level_sources[l] {
                LevelSource::Measured { luma, bins, relative_stderr } => Some((luma, bins, relative_stderr)),
                LevelSource::Continued { .. } => None,
            })
            .collect();
        let finer = out.iter().rposition(|s| matches!(s, LevelSource::Measured { .. }));
        let source = match finer {
            Some(from) if 2 * measured.len() <= fits.len() => LevelSource::Continued { from: from as u32 },
            // Level 0 (or a level with no measured finer one) stays measured if any fit measured it.
            None if measured.is_empty() => return vec![],
            _ => {
                let med = |k: usize| {
                    median(measured.iter().map(|&(luma, bins, se)| [luma[0], luma[1], bins as f32, se][k]).collect())
                };
                LevelSource::Measured {
                    luma: [med(0), med(1)],
                    bins: med(2).round().max(1.0) as u32,
                    relative_stderr: med(3),
                }
            }
        };
        out.push(source);
    }
    out
}

pub fn aggregate_models(models: &[CameraModel]) -> Result<CameraModel, FitError> {
    let first = models.first().ok_or(FitError::NoFrames)?;
    let mut out = first.clone();
    // Per effect, the frames that fitted it (an update may refit only some effects:
    // the worker's per-effect cadence), so "p of n frames" counts like with like.
    let fitted =
        |d: fn(&CameraModel) -> &Diagnostics| models.iter().filter(|m| d(m).status != Status::NotFitted).count();
    let total = fitted(|m| &m.noise.diagnostics);

    let noise: Vec<&CameraModel> = models.iter().filter(|m| m.noise.present).collect();
    let same = noise_pool(&noise);
    if let Some(base) = same.last() {
        out.noise = base.noise.clone();
        for l in 0..out.noise.levels.len() {
            for c in 0..3 {
                out.noise.levels[l].slope[c] = median(same.iter().map(|m| m.noise.levels[l].slope[c]).collect());
                out.noise.levels[l].intercept[c] =
                    median(same.iter().map(|m| m.noise.levels[l].intercept[c]).collect());
            }
        }
        out.noise.level_sources = pooled_level_sources(&same);
        out.noise.lowpass = None;
        out.noise.luminance_range = [
            median(same.iter().map(|m| m.noise.luminance_range[0]).collect()),
            median(same.iter().map(|m| m.noise.luminance_range[1]).collect()),
        ];
        let ds: Vec<&Diagnostics> = same.iter().map(|m| &m.noise.diagnostics).collect();
        out.noise.diagnostics = summary(&ds, same.len(), total);
    }

    let mb: Vec<&CameraModel> = models.iter().filter(|m| m.motion_blur.exposure.is_some()).collect();
    if !mb.is_empty() {
        let lambdas: Vec<f32> = mb.iter().filter_map(|m| m.motion_blur.exposure).collect();
        let present = mb.iter().filter(|m| m.motion_blur.present).count();
        let ds: Vec<&Diagnostics> = mb.iter().map(|m| &m.motion_blur.diagnostics).collect();
        out.motion_blur.exposure = Some(median(lambdas));
        // Present if most identifiable frames say so: a frame whose visible reading
        // lies within 3 standard errors of none (`motion_blur::exposure_status`)
        // votes neither way; with no identifiable frame the aggregate says neither.
        let votes =
            mb.iter().filter(|m| matches!(m.motion_blur.diagnostics.status, Status::Present | Status::Absent)).count();
        out.motion_blur.present = 2 * present > votes;
        out.motion_blur.diagnostics = summary(&ds, present, fitted(|m| &m.motion_blur.diagnostics));
        out.motion_blur.diagnostics.status = match (out.motion_blur.present, votes) {
            (true, _) => Status::Present,
            (false, 0) => Status::NotIdentifiable,
            _ => Status::Absent,
        };
    }

    let mut dof: Vec<&CameraModel> = models.iter().filter(|m| m.depth_of_field.present).collect();
    if !dof.is_empty() {
        let mid = |m: &CameraModel| {
            let r = m.depth_of_field.depth_range;
            m.depth_of_field.sigma_px(0.5 * (r[0] + r[1]))
        };
        dof.sort_by(|a, b| mid(a).total_cmp(&mid(b)));
        let pick = dof[dof.len() / 2];
        let ds: Vec<&Diagnostics> = dof.iter().map(|m| &m.depth_of_field.diagnostics).collect();
        out.depth_of_field = pick.depth_of_field.clone();
        out.depth_of_field.diagnostics = summary(&ds, dof.len(), fitted(|m| &m.depth_of_field.diagnostics));
    }
    // Colour: the median illuminant (per channel, luma renormalised) and exposure
    // over the frames that could read them, present or absent alike (an absent
    // reading is an identity measured, not a missing one); present where most of
    // them are. Frames that could not read it do not vote. None: the newest
    // frame's (not identifiable or not fitted) stands.
    let colour: Vec<&CameraModel> =
        models.iter().filter(|m| m.colour.illuminant.is_some() && m.colour.exposure.is_some()).collect();
    if !colour.is_empty() {
        let ill: [f32; 3] =
            std::array::from_fn(|c| median(colour.iter().filter_map(|m| m.colour.illuminant.map(|i| i[c])).collect()));
        let y: f32 = (0..3).map(|c| crate::image::LUMA_WEIGHTS[c] * ill[c]).sum();
        let present = colour.iter().filter(|m| m.colour.present).count();
        let illuminant = (y > 0.0).then(|| ill.map(|v| v / y));
        let is_present = 2 * present > colour.len() && illuminant.is_some();
        let ds: Vec<&Diagnostics> = colour.iter().map(|m| &m.colour.diagnostics).collect();
        let mut diagnostics = summary(&ds, present, fitted(|m| &m.colour.diagnostics));
        diagnostics.status = if is_present { Status::Present } else { Status::Absent };
        out.colour = crate::model::Colour {
            present: is_present,
            illuminant,
            exposure: Some(median(colour.iter().filter_map(|m| m.colour.exposure).collect())),
            diagnostics,
        };
    } else if let Some(last) = models.last() {
        out.colour = last.colour.clone();
    }
    // Vignetting is fitted over its own window of frame pairs (the worker's
    // `vignetting` module): the newest reading stands.
    if let Some(m) = models.iter().rev().find(|m| m.vignetting.diagnostics.status != Status::NotFitted) {
        out.vignetting = m.vignetting.clone();
    }
    // The aberration likewise (the worker's `chromatic` module pools its frames).
    if let Some(m) = models.iter().rev().find(|m| m.chromatic_aberration.diagnostics.status != Status::NotFitted) {
        out.chromatic_aberration = m.chromatic_aberration.clone();
    }
    // Sharpening is read from each frame alone: the newest confident reading
    // (present or absent) stands, and a not-identifiable one only where no frame
    // was confident — it never hides an earlier one.
    let sharpening = |confident: bool| {
        models.iter().rev().find(|m| match m.sharpening.diagnostics.status {
            Status::Present | Status::Absent => true,
            Status::NotIdentifiable => !confident,
            Status::NotFitted => false,
        })
    };
    if let Some(m) = sharpening(true).or_else(|| sharpening(false)) {
        out.sharpening = m.sharpening.clone();
    }
    out.validate().map_err(|e| FitError::Option { option: "aggregate", problem: e.to_string() })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::compare::noise_relative_error;
    use crate::model::{NoiseForm, NoiseLevel};

    /// White sensor noise (variance affine in luma), every std scaled by `scale`.
    fn affine(scale: f32) -> CameraModel {
        let s2 = scale * scale;
        let mut m = CameraModel::empty(64, 48);
        m.noise = crate::synth::white_sensor_noise([2e-5 * s2; 3], [8e-4 * s2; 3], [0.0, 1.0]);
        m
    }

    /// The same noise as a std linear in luma (the secant through luma 0.25 and
    /// 0.75: within 3% of it at 0.5), every std scaled by `scale`.
    fn linear(scale: f32) -> CameraModel {
        let mut m = affine(scale);
        let n = m.noise.clone();
        for (l, out) in m.noise.levels.iter_mut().enumerate() {
            let s = |y: f32| std::array::from_fn::<f32, 3, _>(|c| n.levels[l].std(n.form, c, y));
            let (a, b) = (s(0.25), s(0.75));
            let slope = std::array::from_fn(|c| (b[c] - a[c]) / 0.5);
            *out = NoiseLevel { slope, intercept: std::array::from_fn(|c| a[c] - slope[c] * 0.25) };
        }
        m.noise.form = NoiseForm::LinearStd;
        m
    }

    /// A window whose first fit is far off and of another form than the rest (the
    /// calibration video's burst: the first frame fitted alone, +57%) publishes what
    /// the others agree on. Were the first fit's form to decide, the first window
    /// would publish it unchanged (+57%), the second the mean of it and the later
    /// fit of its form (+26%). Tolerance 5%: the good fits are within 2%
    /// of the truth, the linear one within 3% at mid-luma.
    #[test]
    fn one_far_fit_of_another_form_does_not_decide_the_noise() {
        let truth = affine(1.0).noise;
        for window in
            [vec![linear(1.57), affine(1.0), affine(1.02)], vec![linear(1.57), affine(1.0), affine(1.02), linear(1.0)]]
        {
            let agg = aggregate_models(&window).expect("valid");
            let err = noise_relative_error(&agg.noise, &truth).expect("present");
            assert!(err <= 0.05, "{} fits: {:.1}% off", window.len(), 100.0 * err);
        }
        // Every fit of one form and near each other: the coefficient-wise median.
        let agg = aggregate_models(&[affine(0.98), affine(1.0), affine(1.04)]).expect("valid");
        assert_eq!(agg.noise.levels, affine(1.0).noise.levels);
    }

    /// The pooled level sources: a level most fits measured is measured (medians of
    /// their lumas, bins and errors), else continued from the coarsest measured finer
    /// level; a pooled fit without sources leaves none.
    #[test]
    fn level_sources_pool_by_majority() {
        let m = |luma: [f32; 2], bins: u32, relative_stderr: f32| LevelSource::Measured { luma, bins, relative_stderr };
        let c = |from: u32| LevelSource::Continued { from };
        let with = |sources: Vec<LevelSource>| {
            let mut f = affine(1.0);
            f.noise.level_sources = sources;
            f
        };
        let fits = [
            with(vec![m([0.1, 0.7], 11, 0.1), m([0.1, 0.2], 3, 0.4), c(1), c(1)]),
            with(vec![m([0.2, 0.8], 12, 0.2), m([0.1, 0.6], 9, 0.1), m([0.2, 0.5], 4, 0.3), c(2)]),
            with(vec![m([0.1, 0.6], 10, 0.1), c(0), c(0), c(0)]),
        ];
        let agg = aggregate_models(&fits).expect("valid");
        assert_eq!(
            agg.noise.level_sources,
            vec![m([0.1, 0.7], 11, 0.1), m([0.1, 0.4], 6, 0.25), c(1), c(1)],
            "level 1: two of three measured it (medians of two are means); level 2: one of three"
        );
        let agg = aggregate_models(&[fits[0].clone(), affine(1.0)]).expect("valid");
        assert!(agg.noise.level_sources.is_empty(), "{:?}", agg.noise.level_sources);
    }

    /// A frame's exposure as a fit reports it: λ ± `stderr` with `status`.
    fn exposure(lambda: f32, stderr: f64, status: Status) -> CameraModel {
        let mut m = CameraModel::empty(64, 48);
        m.motion_blur.exposure = Some(lambda);
        m.motion_blur.present = status == Status::Present;
        m.motion_blur.diagnostics.status = status;
        m.motion_blur.diagnostics.stderr = Some(stderr);
        m
    }

    /// Presence is the majority of the frames that can tell: frames whose visible
    /// reading lies within 3 standard errors of none vote neither way (they were
    /// counted as "absent" votes: one present frame beside two unresolved ones
    /// published absent); none that can tell gives not identifiable.
    #[test]
    fn unresolved_exposures_do_not_vote() {
        use Status::*;
        let w =
            [exposure(0.5, 0.02, Present), exposure(0.3, 0.2, NotIdentifiable), exposure(0.2, 0.1, NotIdentifiable)];
        let agg = aggregate_models(&w).expect("valid");
        assert!(agg.motion_blur.present);
        assert_eq!(agg.motion_blur.diagnostics.status, Present);
        let w = [exposure(0.5, 0.02, Present), exposure(0.0, 0.05, Absent), exposure(0.001, 0.05, Absent)];
        let agg = aggregate_models(&w).expect("valid");
        assert!(!agg.motion_blur.present);
        assert_eq!(agg.motion_blur.diagnostics.status, Absent);
        let w = [exposure(0.3, 0.2, NotIdentifiable), exposure(0.2, 0.1, NotIdentifiable)];
        let agg = aggregate_models(&w).expect("valid");
        assert!(!agg.motion_blur.present);
        assert_eq!(agg.motion_blur.diagnostics.status, NotIdentifiable);
    }

    /// The frames' sharpening: the newest confident reading stands; a later
    /// not-identifiable frame does not replace it; with none confident the newest
    /// not-identifiable one.
    #[test]
    fn a_not_identifiable_sharpening_does_not_hide_a_confident_one() {
        use Status::*;
        let frame = |status: Status, amount: f32| {
            let mut m = CameraModel::empty(64, 48);
            m.sharpening.present = status == Present;
            m.sharpening.amount = Some(amount);
            m.sharpening.radius_px = Some(1.0);
            m.sharpening.diagnostics.status = status;
            m
        };
        let agg =
            aggregate_models(&[frame(Absent, 0.1), frame(Present, 1.0), frame(NotIdentifiable, 2.0)]).expect("valid");
        assert_eq!((agg.sharpening.diagnostics.status, agg.sharpening.amount), (Present, Some(1.0)));
        let agg = aggregate_models(&[frame(NotIdentifiable, 0.5), frame(NotIdentifiable, 2.0)]).expect("valid");
        assert_eq!((agg.sharpening.diagnostics.status, agg.sharpening.amount), (NotIdentifiable, Some(2.0)));
    }
}
