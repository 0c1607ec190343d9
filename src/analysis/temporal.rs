//! Video as its own reference. A headset sees the same static surfaces many times
//! with different head motion, so other frames, aligned to this one by pose and
//! metric depth, stand in for the references the accurate fits need:
//! * I_noNoise (`TemporalDenoiser`): the mean of m other frames whose motion matches
//!   this one's (their motion blur then matches too, so the residual I − mean is
//!   noise alone). The mean still carries 1/m of the noise variance; the noise fit
//!   divides it out (`Reference::noise_variance_ratio`). Bicubic alignment
//!   low-passes the aligned frames' finest band a little, so at level 0 the true
//!   ratio is somewhat below 1/m (≈ 0.7/m): a bias ≤ 2% in std for m = 8, none at
//!   coarser levels.
//! * I_noMB (`TemporalMotionDeblur`): the mean of the sharpest frames held in the
//!   window (the head at rest: motion ≤ `max_motion_px` per frame), aligned.
//!
//! Alignment (`align`) warps a source frame into the current camera: each current
//! pixel's surface point (its depth, the intrinsics, `world_from_camera`) is
//! projected into the source camera and sampled there (Catmull–Rom bicubic: its
//! second moment is zero at every offset, so it adds no blur that λ would absorb).
//! A pixel is invalid where the point falls outside the source frame or the source
//! saw a nearer surface there (occlusion: source depth more than 3% nearer).

use super::{Analysed, AnalysisError, Denoiser, FrameContext, Intrinsics, MotionDeblurrer, Reference};
use crate::image::{Flow, Plane, Rgb};
use crate::model::DepthUnits;
use crate::synth::sequence::sample_bicubic;
use glam::{Mat4, Vec3};
use std::sync::Arc;

/// A frame warped into another camera, and where the warp holds.
pub struct Aligned {
    pub image: Rgb,
    pub valid: Vec<bool>,
}

/// Relative depth difference beyond which the source saw another surface.
const OCCLUSION_TOLERANCE: f32 = 0.03;
/// Bicubic support: samples this close to the border read clamped pixels.
const BORDER_PX: f32 = 2.0;

fn metric(a: &Analysed) -> Option<&Plane> {
    a.depth.as_ref().filter(|d| d.units == DepthUnits::MetricM).map(|d| &d.depth)
}

/// `src` seen from the camera of `dst` (both need a pose and metric depth).
pub fn align(src: &Analysed, dst: &Analysed, k: &Intrinsics) -> Option<Aligned> {
    let (src_pose, dst_pose) = (src.world_from_camera?, dst.world_from_camera?);
    let (src_depth, dst_depth) = (metric(src)?, metric(dst)?);
    let (w, h) = (dst.frame.image.width, dst.frame.image.height);
    if (src.frame.image.width, src.frame.image.height) != (w, h) || (dst_depth.width, dst_depth.height) != (w, h) {
        return None;
    }
    let src_from_dst = src_pose.inverse() * dst_pose;
    let planes = [src.frame.image.plane(0), src.frame.image.plane(1), src.frame.image.plane(2)];
    let mut image = Rgb::new(w, h, [0.0; 3]);
    let mut valid = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let z = dst_depth.data[i];
            if !(z.is_finite() && z > 0.0) {
                continue;
            }
            let q =
                src_from_dst.transform_point3(Vec3::new((x as f32 - k.cx) / k.fx * z, (y as f32 - k.cy) / k.fy * z, z));
            if q.z <= 1e-3 {
                continue;
            }
            let (u, v) = (k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy);
            if !(u >= BORDER_PX && v >= BORDER_PX && u <= w as f32 - 1.0 - BORDER_PX && v <= h as f32 - 1.0 - BORDER_PX)
            {
                continue;
            }
            let zs = src_depth.get(u.round() as usize, v.round() as usize);
            if zs.is_finite() && zs < q.z * (1.0 - OCCLUSION_TOLERANCE) {
                continue;
            }
            for c in 0..3 {
                image.channels[c][i] = sample_bicubic(&planes[c], u, v);
            }
            valid[i] = true;
        }
    }
    Some(Aligned { image, valid })
}

/// Largest difference in sparse-grid motion between two frames (px per interval).
fn motion_difference(a: &Analysed, b: &Analysed) -> Option<f32> {
    let (fa, fb) = (a.sparse_flow.as_ref()?, b.sparse_flow.as_ref()?);
    (fa.len() == fb.len()).then(|| fa.iter().zip(fb).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).fold(0.0, f32::max))
}

/// Mean of `sources` aligned into `current`; valid where every source is (so the
/// noise ratio is the same 1/m at every valid pixel). Invalid pixels hold the
/// current frame's value.
fn aligned_mean(current: &Analysed, sources: &[&Arc<Analysed>], k: &Intrinsics) -> Option<(Rgb, Plane)> {
    let (w, h) = (current.frame.image.width, current.frame.image.height);
    let mut sum = Rgb::new(w, h, [0.0; 3]);
    let mut all_valid = vec![true; w * h];
    for s in sources {
        let a = align(s, current, k)?;
        for c in 0..3 {
            for (o, v) in sum.channels[c].iter_mut().zip(&a.image.channels[c]) {
                *o += v;
            }
        }
        for (o, v) in all_valid.iter_mut().zip(&a.valid) {
            *o &= *v;
        }
    }
    let m = sources.len() as f32;
    for c in 0..3 {
        for (i, o) in sum.channels[c].iter_mut().enumerate() {
            *o = if all_valid[i] { *o / m } else { current.frame.image.channels[c][i] };
        }
    }
    let valid = Plane::from_vec(w, h, all_valid.into_iter().map(|v| if v { 1.0 } else { 0.0 }).collect());
    Some((sum, valid))
}

fn needs<'a>(ctx: &'a FrameContext, provider: &'static str) -> Result<&'a Intrinsics, AnalysisError> {
    let f = ctx.current.frame.index;
    let k = ctx.intrinsics.ok_or_else(|| AnalysisError::unavailable(f, provider, "no intrinsics"))?;
    if ctx.current.world_from_camera.is_none() {
        return Err(AnalysisError::unavailable(f, provider, "no camera pose at this frame"));
    }
    if metric(ctx.current).is_none() {
        return Err(AnalysisError::unavailable(f, provider, "no metric depth at this frame"));
    }
    Ok(k)
}

/// The mean of `picked` aligned to the current frame as a reference, refused when
/// the aligned frames cover less than a quarter of it (`what` names them).
fn mean_reference(
    ctx: &FrameContext,
    picked: &[&Arc<Analysed>],
    k: &Intrinsics,
    provider: &'static str,
    what: &str,
) -> Result<Reference, AnalysisError> {
    let f = ctx.current.frame.index;
    let (image, valid) = aligned_mean(ctx.current, picked, k)
        .ok_or_else(|| AnalysisError::unavailable(f, provider, "alignment failed"))?;
    let covered = valid.data.iter().filter(|v| **v > 0.5).count() as f32 / valid.data.len().max(1) as f32;
    if covered < 0.25 {
        return Err(AnalysisError::unavailable(f, provider, format!("{what} overlap less than 25% of this one")));
    }
    Ok(Reference {
        image,
        valid: Some(valid),
        noise_variance_ratio: 1.0 / picked.len() as f32,
        sources: picked.iter().map(|a| a.frame.index).collect(),
    })
}

/// I_noNoise from the mean of aligned frames with matching motion.
#[derive(Clone, Debug)]
pub struct TemporalDenoiser {
    /// Frames averaged (m): the reference keeps 1/m of the noise variance.
    pub frames: usize,
    /// Largest motion difference to the current frame (px per frame interval) for
    /// a frame to be averaged: its streaks then differ by at most λ times that.
    pub max_motion_difference_px: f32,
    /// Fewest frames worth a reference.
    pub min_frames: usize,
}

impl Default for TemporalDenoiser {
    fn default() -> Self {
        Self { frames: 8, max_motion_difference_px: 0.5, min_frames: 3 }
    }
}

impl Denoiser for TemporalDenoiser {
    fn name(&self) -> &str {
        "temporal mean of aligned frames"
    }

    fn denoise(&mut self, ctx: &FrameContext) -> Result<Reference, AnalysisError> {
        const P: &str = "temporal denoiser";
        let k = needs(ctx, P)?;
        let f = ctx.current.frame.index;
        // Newest first: the scene changes least.
        let picked: Vec<&Arc<Analysed>> = ctx
            .window
            .iter()
            .rev()
            .filter(|a| a.world_from_camera.is_some() && metric(a).is_some())
            .filter(|a| motion_difference(a, ctx.current).is_some_and(|d| d <= self.max_motion_difference_px))
            .take(self.frames)
            .collect();
        if picked.len() < self.min_frames {
            return Err(AnalysisError::unavailable(
                f,
                P,
                format!(
                    "{} earlier frames move like this one (within {} px/frame; {} needed)",
                    picked.len(),
                    self.max_motion_difference_px,
                    self.min_frames
                ),
            ));
        }
        mean_reference(ctx, &picked, k, P, "the aligned frames")
    }
}

/// I_noMB from the sharpest aligned frames the window holds.
#[derive(Clone, Debug)]
pub struct TemporalMotionDeblur {
    /// Most motion a frame may have (px per frame interval) to count as sharp.
    pub max_motion_px: f32,
    /// Sharp frames averaged (averaging lowers the reference's noise).
    pub frames: usize,
}

impl Default for TemporalMotionDeblur {
    fn default() -> Self {
        Self { max_motion_px: 0.5, frames: 3 }
    }
}

impl MotionDeblurrer for TemporalMotionDeblur {
    fn name(&self) -> &str {
        "sharpest aligned frames"
    }

    fn deblur(&mut self, ctx: &FrameContext, _flow: &Flow) -> Result<Reference, AnalysisError> {
        const P: &str = "temporal motion deblur";
        let k = needs(ctx, P)?;
        let f = ctx.current.frame.index;
        let mut sharp: Vec<(&Arc<Analysed>, f32)> = ctx
            .window
            .iter()
            .filter(|a| a.world_from_camera.is_some() && metric(a).is_some())
            .filter_map(|a| a.max_motion_px().map(|m| (a, m)))
            .filter(|(_, m)| *m <= self.max_motion_px)
            .collect();
        if sharp.is_empty() {
            return Err(AnalysisError::unavailable(
                f,
                P,
                format!("no frame in the window was taken with the head at rest (≤ {} px/frame)", self.max_motion_px),
            ));
        }
        // Sharpest first; ties to the newest.
        sharp.sort_by(|a, b| a.1.total_cmp(&b.1).then(b.0.frame.t_s.total_cmp(&a.0.frame.t_s)));
        let picked: Vec<&Arc<Analysed>> = sharp.iter().take(self.frames).map(|(a, _)| *a).collect();
        mean_reference(ctx, &picked, k, P, "the sharp frames")
    }
}

/// For callers that compare two frames' poses: `world_from_camera` as a matrix.
pub fn pose_matrix(p: &super::timing::TimedPose) -> Mat4 {
    Mat4::from_rotation_translation(p.orientation, p.position_m)
}

/// A cheap, view-independent noise probe for change detection: the previous frame
/// aligned into this one (`align`) and subtracted; in the flattest third of the valid pixels
/// (smallest gradient of this frame) the difference is the two frames' noise, so
/// its robust spread (green channel: the mean absolute deviation from the median
/// of the inner 90%, scaled to a Gaussian std, over √2) tracks the noise level; a
/// mean rather than a MAD because 8-bit frames make a median step in 1/255. Not
/// an estimate of it — alignment low-passes the previous frame's noise and motion
/// differs slightly between frames — but a quantity with a steady bias, whose
/// steps are steps of the camera's noise.
pub fn noise_probe(a: &Aligned, current: &Analysed) -> Option<f32> {
    let img = &current.frame.image;
    let (w, h) = (img.width, img.height);
    let g = &img.channels[1];
    let mut cand: Vec<(f32, f32)> = vec![];
    for y in (1..h.saturating_sub(1)).step_by(2) {
        for x in (1..w.saturating_sub(1)).step_by(2) {
            let i = y * w + x;
            if !(a.valid[i] && a.valid[i - 1] && a.valid[i + 1] && a.valid[i - w] && a.valid[i + w]) {
                continue;
            }
            let grad = (g[i + 1] - g[i - 1]).abs() + (g[i + w] - g[i - w]).abs();
            cand.push((grad, g[i] - a.image.channels[1][i]));
        }
    }
    if cand.len() < 300 {
        return None;
    }
    let third = cand.len() / 3;
    cand.select_nth_unstable_by(third, |p, q| p.0.total_cmp(&q.0));
    let mut d: Vec<f32> = cand[..third].iter().map(|p| p.1).collect();
    let mid = d.len() / 2;
    let median = *d.select_nth_unstable_by(mid, f32::total_cmp).1;
    let mut dev: Vec<f32> = d.iter().map(|v| (v - median).abs()).collect();
    dev.sort_by(f32::total_cmp);
    let inner = &dev[..(dev.len() * 9 / 10).max(1)];
    let mean = inner.iter().sum::<f32>() / inner.len() as f32;
    // E|X| = σ·√(2/π) for a Gaussian; trimming the top 10% lowers it by a fixed factor.
    Some(mean * (std::f32::consts::PI / 2.0).sqrt() / std::f32::consts::SQRT_2)
}
