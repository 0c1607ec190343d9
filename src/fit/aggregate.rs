//! Robust aggregation of per-frame models (`fit --frames`): the coefficient-wise
//! median of present fits, so a few bad frames (a cut, a flash, a wrong flow) do
//! not move the result. The DoF curve of the median frame (by δ at mid-range) is
//! kept whole, since curve coefficients do not average meaningfully.

use super::FitError;
use crate::model::{CameraModel, Diagnostics, Status};

/// The median; of an even count, the mean of the middle two (the upper one alone
/// made a window of two estimates publish the larger: a contaminated noise fit
/// beside a clean one read +45% at the calibration video's level 3).
fn median(mut v: Vec<f32>) -> f32 {
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

pub fn aggregate_models(models: &[CameraModel]) -> Result<CameraModel, FitError> {
    let first = models.first().ok_or(FitError::NoFrames)?;
    let mut out = first.clone();
    let total = models.len();

    let noise: Vec<&CameraModel> = models.iter().filter(|m| m.noise.present).collect();
    if let Some(base) = noise.first() {
        // Medians of coefficients only mean something between maps of one form and
        // one intensity variable.
        let (form, intensity) = (base.noise.form, base.noise.intensity);
        let same: Vec<&&CameraModel> =
            noise.iter().filter(|m| m.noise.form == form && m.noise.intensity == intensity).collect();
        out.noise = base.noise.clone();
        for l in 0..out.noise.levels.len() {
            for c in 0..3 {
                out.noise.levels[l].slope[c] = median(same.iter().map(|m| m.noise.levels[l].slope[c]).collect());
                out.noise.levels[l].intercept[c] =
                    median(same.iter().map(|m| m.noise.levels[l].intercept[c]).collect());
            }
        }
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
        // Present if most identifiable frames say so.
        out.motion_blur.present = 2 * present > mb.len();
        out.motion_blur.diagnostics = summary(&ds, present, total);
        out.motion_blur.diagnostics.status = if out.motion_blur.present { Status::Present } else { Status::Absent };
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
        out.depth_of_field.diagnostics = summary(&ds, dof.len(), total);
    }
    out.validate().map_err(|e| FitError::Option { option: "aggregate", problem: e.to_string() })?;
    Ok(out)
}
