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
//! * I_noMB (`TemporalMotionDeblur`): the sharpest frames held in the window (the
//!   head at rest: motion ≤ `max_motion_px` per frame), aligned, as the mean of one
//!   half and `Reference::second`, the mean of the other (`split`).
//!
//! Alignment (`align`) warps a source frame into the current camera: each current
//! pixel's surface point (its depth, the intrinsics, `world_from_camera`) is
//! projected into the source camera and sampled there (Catmull–Rom bicubic: its
//! second moment is zero at every offset, so it adds no blur that λ would absorb).
//! A pixel is invalid where the point falls outside the source frame or the source
//! saw a nearer surface there (occlusion: source depth more than 3% nearer).

use super::{Analysed, AnalysisError, Denoiser, FrameContext, Intrinsics, MotionDeblurrer, Reference};
use crate::image::{sample_bicubic_rgb_interior, Flow, Plane, Rgb};
use crate::model::DepthUnits;
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
///
/// Per pixel: the surface point is z·r(x, y) in the destination camera, with
/// r = ((x − cx)/fx, (y − cy)/fy, 1), so in the source camera it is
/// z·R·r + t — and R·r is affine along a row (one add per pixel). The three
/// channels share one set of bicubic weights (`sample_bicubic_rgb_interior`); rows
/// run in parallel. At 1280×960 on one core this takes about a quarter of the
/// per-channel clamped sampling it replaces (BENCHMARKS.md).
pub fn align(src: &Analysed, dst: &Analysed, k: &Intrinsics) -> Option<Aligned> {
    align_rows(src, dst, k, &|_| true)
}

/// Rows in bands of this height when only part of a frame is aligned
/// (`align_bands`): tall enough that a streak of a turning head (a few px per
/// frame, mostly horizontal) fits inside one.
pub const BAND_ROWS: usize = 32;

/// `align` on a subset of the rows: bands of `BAND_ROWS`, every `stride`-th one
/// (`in_band`); the other rows are invalid. Costs ~1/`stride` of `align`: the rows
/// a sparse `TemporalMotionDeblur` reference covers (which warps them itself, a row
/// at a time, `aligned_mean`).
pub fn align_bands(src: &Analysed, dst: &Analysed, k: &Intrinsics, stride: usize) -> Option<Aligned> {
    let stride = stride.max(1);
    align_rows(src, dst, k, &|y| in_band(y, stride))
}

/// Whether row `y` is in one of `align_bands`' bands: the middle band of each run
/// of `stride` (the frame's edges are where alignment fails first).
pub fn in_band(y: usize, stride: usize) -> bool {
    let stride = stride.max(1);
    (y / BAND_ROWS) % stride == stride / 2
}

/// The band stride (`in_band`) that keeps a `w`×`h` frame's bands within about
/// `max_px` pixels (1: every row).
pub fn band_stride(w: usize, h: usize, max_px: usize) -> usize {
    (w * h).div_ceil(max_px.max(w * BAND_ROWS).max(1)).max(1)
}

/// The rows of `align_bands`' bands in a frame `h` rows tall.
fn band_rows(h: usize, stride: usize) -> Vec<usize> {
    (0..h).filter(|&y| in_band(y, stride)).collect()
}

/// `align` where `row(y)`; other rows are left invalid (and cost nothing but their
/// share of the zeroed allocation): what a caller that reads part of the frame
/// needs (the worker's noise probe and its noise fit's strip).
pub fn align_rows(
    src: &Analysed,
    dst: &Analysed,
    k: &Intrinsics,
    row: &(dyn Fn(usize) -> bool + Sync),
) -> Option<Aligned> {
    use rayon::prelude::*;
    let warp = Warp::new(src, dst, k)?;
    let (w, h) = (warp.w, warp.h);
    let mut image = Rgb::new(w, h, [0.0; 3]);
    let mut valid = vec![false; w * h];
    let [r, g, b] = &mut image.channels;
    r.par_chunks_mut(w)
        .zip(g.par_chunks_mut(w))
        .zip(b.par_chunks_mut(w))
        .zip(valid.par_chunks_mut(w))
        .enumerate()
        .filter(|(y, _)| row(*y))
        .for_each(|(y, (((r, g), b), ok))| warp.row(y, [r, g, b], ok));
    Some(Aligned { image, valid })
}

/// One source frame's warp into a destination camera (`align`), row by row.
struct Warp<'a> {
    w: usize,
    h: usize,
    k: Intrinsics,
    rot: glam::Mat3,
    t: Vec3,
    step: Vec3,
    src_img: &'a Rgb,
    src_depth: &'a Plane,
    dst_depth: &'a Plane,
}

impl<'a> Warp<'a> {
    fn new(src: &'a Analysed, dst: &'a Analysed, k: &Intrinsics) -> Option<Self> {
        let (src_pose, dst_pose) = (src.world_from_camera?, dst.world_from_camera?);
        let (src_depth, dst_depth) = (metric(src)?, metric(dst)?);
        let (w, h) = (dst.frame.image.width, dst.frame.image.height);
        if (src.frame.image.width, src.frame.image.height) != (w, h)
            || (dst_depth.width, dst_depth.height) != (w, h)
            || (src_depth.width, src_depth.height) != (w, h)
        {
            return None;
        }
        let src_from_dst = src_pose.inverse() * dst_pose;
        let rot = glam::Mat3::from_mat4(src_from_dst);
        Some(Self {
            w,
            h,
            k: *k,
            rot,
            t: src_from_dst.w_axis.truncate(),
            step: rot * Vec3::new(1.0 / k.fx, 0.0, 0.0),
            src_img: &src.frame.image,
            src_depth,
            dst_depth,
        })
    }

    /// Where the surface at pixel centre `p` of the destination is in the source
    /// (`row`'s projection and occlusion test for one point).
    fn point(&self, p: [f32; 2]) -> Option<[f32; 2]> {
        let (w, h, k) = (self.w, self.h, &self.k);
        let (x, y) = (p[0] - 0.5, p[1] - 0.5);
        if !(x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h) {
            return None;
        }
        let z = self.dst_depth.get(x as usize, y as usize);
        let ray = self.rot * Vec3::new((x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0);
        let q = ray * z + self.t;
        if !(z.is_finite() && z > 0.0) || q.z <= 1e-3 {
            return None;
        }
        let (u, v) = (k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy);
        if !(u >= BORDER_PX && v >= BORDER_PX && u <= w as f32 - 1.0 - BORDER_PX && v <= h as f32 - 1.0 - BORDER_PX) {
            return None;
        }
        let zs = self.src_depth.get((u + 0.5) as usize, (v + 0.5) as usize);
        if zs.is_finite() && zs < q.z * (1.0 - OCCLUSION_TOLERANCE) {
            return None;
        }
        Some([u + 0.5, v + 0.5])
    }

    /// Row `y` of the warped source into `rgb` and `ok` (each `w` long); pixels that
    /// do not hold are left as they are, `ok` false.
    fn row(&self, y: usize, rgb: [&mut [f32]; 3], ok: &mut [bool]) {
        let (w, h, k) = (self.w, self.h, &self.k);
        let [r, g, b] = rgb;
        let row_start = self.rot * Vec3::new(-k.cx / k.fx, (y as f32 - k.cy) / k.fy, 1.0);
        let depth_row = &self.dst_depth.data[y * w..(y + 1) * w];
        let mut ray = row_start;
        for x in 0..w {
            ok[x] = false;
            // A running sum, re-anchored every 32 px: its rounding stays below
            // ~1e-6 of the ray (≪ 0.01 px) where 1280 unanchored adds drift up to
            // ~1e-4 (0.05 px); start + x·step at every pixel costs 15% more here.
            if x % 32 == 0 {
                ray = row_start + self.step * x as f32;
            }
            let z = depth_row[x];
            let q = ray * z + self.t;
            ray += self.step;
            if !(z.is_finite() && z > 0.0) || q.z <= 1e-3 {
                continue;
            }
            let inv_z = 1.0 / q.z;
            let (u, v) = (k.fx * q.x * inv_z + k.cx, k.fy * q.y * inv_z + k.cy);
            if !(u >= BORDER_PX && v >= BORDER_PX && u <= w as f32 - 1.0 - BORDER_PX && v <= h as f32 - 1.0 - BORDER_PX)
            {
                continue;
            }
            // u, v ≥ 2: adding ½ and truncating rounds without a libm call.
            let zs = self.src_depth.get((u + 0.5) as usize, (v + 0.5) as usize);
            if zs.is_finite() && zs < q.z * (1.0 - OCCLUSION_TOLERANCE) {
                continue;
            }
            // BORDER_PX ≥ 2 keeps every tap inside, so this is always Some.
            if let Some([sr, sg, sb]) = sample_bicubic_rgb_interior(self.src_img, u, v) {
                (r[x], g[x], b[x]) = (sr, sg, sb);
                ok[x] = true;
            }
        }
    }
}

/// Where the surfaces at `points` (pixel centres of `dst`) are seen in `src`, by pose
/// and metric depth as `align` warps: the pairs (point in `dst`, position in `src`)
/// that hold (inside `src` by the bicubic border, not occluded there). `None` where
/// either frame lacks a pose or metric depth or the sizes differ. What the
/// vignetting fit (`fit::vignetting`) reads: the same surface at two image radii.
pub fn correspond(
    src: &Analysed,
    dst: &Analysed,
    k: &Intrinsics,
    points: &[[f32; 2]],
) -> Option<Vec<([f32; 2], [f32; 2])>> {
    let warp = Warp::new(src, dst, k)?;
    Some(points.iter().filter_map(|&p| warp.point(p).map(|q| (p, q))).collect())
}

/// Largest difference in sparse-grid motion between two frames (px per interval).
fn motion_difference(a: &Analysed, b: &Analysed) -> Option<f32> {
    let (fa, fb) = (a.sparse_flow.as_ref()?, b.sparse_flow.as_ref()?);
    (fa.len() == fb.len()).then(|| fa.iter().zip(fb).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).fold(0.0, f32::max))
}

/// Mean of `sources` aligned into `current` (on `align_bands`' rows for `stride`);
/// valid where every source is (so the noise ratio is the same 1/m at every valid
/// pixel). Invalid pixels in the aligned rows hold the current frame's value; the
/// rows not aligned hold 0 (invalid). Each source is warped a row at a time into a
/// row buffer and summed there: a sparse reference costs its bands, and no
/// frame-sized buffer besides its output (a zeroed frame per source would cost as
/// much as the alignment itself at 1280×960).
fn aligned_mean(
    current: &Analysed,
    sources: &[&Arc<Analysed>],
    k: &Intrinsics,
    stride: usize,
    pool: &mut Pool,
) -> Option<(Rgb, Plane)> {
    use rayon::prelude::*;
    let cur = &current.frame.image;
    let (w, h) = (cur.width, cur.height);
    let warps: Vec<Warp> = sources.iter().map(|s| Warp::new(s, current, k)).collect::<Option<_>>()?;
    let m = warps.len().max(1) as f32;
    pool.keep_only((w, h, stride));
    let mut out = pool.rgb.pop().unwrap_or_else(|| Rgb::new(w, h, [0.0; 3]));
    let mut valid = pool.plane.pop().unwrap_or_else(|| Plane::new(w, h, 0.0));
    let [r, g, b] = &mut out.channels;
    r.par_chunks_mut(w)
        .zip(g.par_chunks_mut(w))
        .zip(b.par_chunks_mut(w))
        .zip(valid.data.par_chunks_mut(w))
        .enumerate()
        .filter(|(y, _)| in_band(*y, stride))
        // Row buffers: one set per worker thread, not per row.
        .for_each_init(
            || ([vec![0.0; w], vec![0.0; w], vec![0.0; w]], vec![false; w], vec![true; w]),
            |(buf, ok, all), (y, (((r, g), b), v))| {
                // A recycled buffer holds the last reference here.
                [&mut *r, &mut *g, &mut *b].into_iter().for_each(|o| o.fill(0.0));
                all.fill(true);
                for warp in &warps {
                    let [br, bg, bb] = buf;
                    warp.row(y, [br, bg, bb], ok);
                    for (o, s) in [&mut *r, &mut *g, &mut *b].into_iter().zip(buf.iter()) {
                        o.iter_mut().zip(s).for_each(|(o, s)| *o += s);
                    }
                    all.iter_mut().zip(ok.iter()).for_each(|(a, o)| *a &= *o);
                }
                let span = y * w..(y + 1) * w;
                for (c, o) in [&mut *r, &mut *g, &mut *b].into_iter().enumerate() {
                    for ((o, a), cv) in o.iter_mut().zip(all.iter()).zip(&cur.channels[c][span.clone()]) {
                        *o = if *a { *o / m } else { *cv };
                    }
                }
                v.iter_mut().zip(all.iter()).for_each(|(v, a)| *v = if *a { 1.0 } else { 0.0 });
            },
        );
    Some((out, valid))
}

/// Frame-sized buffers of earlier references, for a sparse reference to reuse
/// (`MotionDeblurrer::recycle`): only its bands are written, so a recycled buffer's
/// other rows still hold the zeros of its first allocation, and its pages are
/// mapped already. Fresh, a 1280×960 sparse reference's buffers cost more in page
/// faults (when written and when the fit first reads them) than its alignment.
#[derive(Clone, Debug, Default)]
struct Pool {
    /// (width, height, band stride) the buffers were made for.
    key: (usize, usize, usize),
    rgb: Vec<Rgb>,
    plane: Vec<Plane>,
}

impl Pool {
    /// Drop buffers made for another size or set of bands.
    fn keep_only(&mut self, key: (usize, usize, usize)) {
        if self.key != key {
            *self = Self { key, ..Default::default() };
        }
    }
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

/// The mean of `picked` aligned to the current frame as a reference (on every
/// `stride`-th band of rows, `align_bands`), refused when the aligned frames cover
/// less than a quarter of the rows aligned (`what` names them). With `split`, the
/// first half of `picked` makes the reference and the second half
/// `Reference::second` (valid where both are).
fn mean_reference(
    ctx: &FrameContext,
    picked: &[&Arc<Analysed>],
    stride: usize,
    split: bool,
    provider: &'static str,
    what: &str,
    pool: &mut Pool,
) -> Result<Reference, AnalysisError> {
    let k = needs(ctx, provider)?;
    let f = ctx.current.frame.index;
    let failed = || AnalysisError::unavailable(f, provider, "alignment failed");
    let (first, rest) = if split && picked.len() >= 2 { picked.split_at(picked.len() / 2) } else { (picked, &[][..]) };
    let (image, mut valid) = aligned_mean(ctx.current, first, k, stride, pool).ok_or_else(failed)?;
    let rows = band_rows(valid.height, stride);
    let w = valid.width;
    let second = if rest.is_empty() {
        None
    } else {
        let (image2, valid2) = aligned_mean(ctx.current, rest, k, stride, pool).ok_or_else(failed)?;
        for &y in &rows {
            let span = y * w..(y + 1) * w;
            valid.data[span.clone()].iter_mut().zip(&valid2.data[span]).for_each(|(a, b)| *a = a.min(*b));
        }
        pool.plane.push(valid2);
        Some(image2)
    };
    let covered_px: usize =
        rows.iter().map(|&y| valid.data[y * w..(y + 1) * w].iter().filter(|v| **v > 0.5).count()).sum();
    let covered = covered_px as f32 / (rows.len() * w).max(1) as f32;
    if covered < 0.25 {
        return Err(AnalysisError::unavailable(f, provider, format!("{what} overlap less than 25% of this one")));
    }
    Ok(Reference {
        image,
        valid: Some(valid),
        noise_variance_ratio: 1.0 / first.len() as f32,
        sources: picked.iter().map(|a| a.frame.index).collect(),
        second,
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
        needs(ctx, P)?;
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
        mean_reference(ctx, &picked, 1, false, P, "the aligned frames", &mut Pool::default())
    }
}

/// I_noMB from the sharpest aligned frames the window holds.
#[derive(Clone, Debug)]
pub struct TemporalMotionDeblur {
    /// Most motion a frame may have (px per frame interval) to count as sharp.
    pub max_motion_px: f32,
    /// Sharp frames averaged (averaging lowers the reference's noise).
    pub frames: usize,
    /// Align at most about this many pixels per sharp frame (`None`: all): bands of
    /// rows spread over the frame (`align_bands`), the rest invalid. The accurate
    /// motion-blur fit reads a few thousand pixels anyway (`mb_max_samples`), so a
    /// sample of the rows serves it at a fraction of the alignment's cost (the fast
    /// tier's budget).
    pub max_aligned_px: Option<usize>,
    /// Split the sharp frames into two halves, the reference and
    /// `Reference::second`: two estimates of I_noMB with independent noise, for the
    /// motion-blur fit's cross loss (`fit::motion_blur`), which a noisy reference
    /// does not bias.
    pub split: bool,
    /// Buffers of recycled references (`MotionDeblurrer::recycle`).
    pool: Pool,
}

impl Default for TemporalMotionDeblur {
    fn default() -> Self {
        Self { max_motion_px: 0.5, frames: 3, max_aligned_px: None, split: false, pool: Pool::default() }
    }
}

impl TemporalMotionDeblur {
    /// The fast and balanced tiers': the two sharpest frames, as two independent
    /// references (`split`), each aligned on about a sixth of a 1280×960 frame (all
    /// of it up to 640×320). At 1280×960 one full alignment is 37 ms of one core
    /// (BENCHMARKS.md). One frame alone, unsplit, read λ = 0.5 as 0.66 on 3.6 px
    /// streaks at 1280×960: its noise, averaged by the streak, lowers the loss at
    /// long λ.
    pub fn sparse() -> Self {
        Self { frames: 2, max_aligned_px: Some(204_800), split: true, ..Default::default() }
    }

    /// The accurate tier's: the three sharpest frames aligned whole, split into two
    /// references with independent noise (one frame and the mean of two) for the
    /// cross loss. Averaged into one reference instead, their noise biased λ up on
    /// real scenes made elsewhere (`cargo xtask bench-quality`, tuning split:
    /// 0.265 / 0.458 for 0.2 / 0.4 at 12 px/frame, 0.318 / 0.649 for 0.3 / 0.6 at
    /// 5–6 px/frame; the same fit against a noise-free reference 0.207 / 0.390 and
    /// 0.304 / 0.610, against one with the camera's noise 0.248 / 0.435 and 0.360 /
    /// 0.664): a streak averages the reference's noise, which lowers the squared
    /// loss at long λ.
    pub fn whole_split() -> Self {
        Self { split: true, ..Default::default() }
    }

    /// Band stride that keeps a `w`×`h` frame within `max_aligned_px`.
    fn stride(&self, w: usize, h: usize) -> usize {
        self.max_aligned_px.map_or(1, |n| band_stride(w, h, n))
    }
}

impl MotionDeblurrer for TemporalMotionDeblur {
    fn name(&self) -> &str {
        "sharpest aligned frames"
    }

    fn rows(&self, width: usize, height: usize) -> Option<Vec<bool>> {
        let stride = self.stride(width, height);
        (stride > 1).then(|| (0..height).map(|y| in_band(y, stride)).collect())
    }

    fn deblur(&mut self, ctx: &FrameContext, _flow: &Flow) -> Result<Reference, AnalysisError> {
        const P: &str = "temporal motion deblur";
        needs(ctx, P)?;
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
        let picked: Vec<&Arc<Analysed>> = sharp.iter().take(self.frames.max(1)).map(|(a, _)| *a).collect();
        let img = &ctx.current.frame.image;
        let stride = self.stride(img.width, img.height);
        let mut r = mean_reference(ctx, &picked, stride, self.split, P, "the sharp frames", &mut self.pool)?;
        // Not near depth edges (`DEPTH_EDGE_PX`); a step beyond the occlusion
        // tolerance is another surface.
        if let (Some(valid), Some(depth)) = (r.valid.as_mut(), metric(ctx.current)) {
            crate::image::clear_near_depth_steps(valid, depth, DEPTH_EDGE_PX, OCCLUSION_TOLERANCE, &|y| {
                in_band(y, stride)
            });
        }
        Ok(r)
    }

    fn recycle(&mut self, spare: Reference) {
        let (w, h) = (spare.image.width, spare.image.height);
        // Only buffers of this size and band set (`Pool::keep_only`).
        if self.pool.key == (w, h, self.stride(w, h)) {
            self.pool.rgb.extend(std::iter::once(spare.image).chain(spare.second));
            self.pool.plane.extend(spare.valid);
        }
    }
}

/// Pixels of a sharp-frame reference this close (px, Chebyshev) to a depth
/// discontinuity of the current frame are left out of it. The reference is a rest
/// frame reprojected by depth, ever farther as a turn goes on; at a depth edge
/// parallax, disocclusion and the defocus that straddles the edge do not move with
/// either surface, and both halves of a split reference carry the same error, so
/// the cross loss (which cancels only independent noise) took it for blur. On the
/// demo's camera (near δ 3.8 px) the fast tier's λ climbed 0.32 → 0.64 over one
/// turn for a truth of 0.40, and swapping the two halves moved single fits from
/// 0.39 to 0.00; without the edges' 3 px it reads 0.35–0.40 over that turn (0.29 on
/// its last two frames), the halves agree within 0.02, and on the calibration
/// bench's camera λ is as before within 0.003 (BENCHMARKS.md "The worker's noise at
/// a burst's start and after a reset"). 6 px kept half the pixels and read no better.
const DEPTH_EDGE_PX: usize = 3;

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
///
/// It reads the rows where `row(y)` (the caller keeps them the same from frame to
/// frame, so the probes compare like with like).
pub fn noise_probe(a: &Aligned, current: &Analysed, row: &dyn Fn(usize) -> bool) -> Option<f32> {
    noise_probe_lags(&[a], current, row).map(|v| v[0])
}

/// `noise_probe` against several aligned frames at once (other lags), on the same
/// pixels: those valid in every one, the flattest third of them by this frame's
/// gradient. Their ratios are free of the scene, the luminance mix and the probe's
/// steady bias, which is what the noise's frame-to-frame correlation is read from
/// (`fit::noise_correlation`). None with fewer than 300 such pixels or no frames.
pub fn noise_probe_lags(aligned: &[&Aligned], current: &Analysed, row: &dyn Fn(usize) -> bool) -> Option<Vec<f32>> {
    let img = &current.frame.image;
    let (w, h) = (img.width, img.height);
    if aligned.is_empty() || aligned.iter().any(|a| a.valid.len() != w * h || a.image.len() != w * h) {
        return None;
    }
    let g = &img.channels[1];
    let valid = |i: usize| aligned.iter().all(|a| a.valid[i]);
    let mut cand: Vec<(f32, usize)> = vec![];
    for y in (1..h.saturating_sub(1)).step_by(2).filter(|&y| row(y)) {
        for x in (1..w.saturating_sub(1)).step_by(2) {
            let i = y * w + x;
            if !(valid(i) && valid(i - 1) && valid(i + 1) && valid(i - w) && valid(i + w)) {
                continue;
            }
            let grad = (g[i + 1] - g[i - 1]).abs() + (g[i + w] - g[i - w]).abs();
            cand.push((grad, i));
        }
    }
    if cand.len() < 300 {
        return None;
    }
    let third = cand.len() / 3;
    cand.select_nth_unstable_by(third, |p, q| p.0.total_cmp(&q.0));
    let flat = &cand[..third];
    let spread = |a: &Aligned| -> f32 {
        let mut d: Vec<f32> = flat.iter().map(|p| g[p.1] - a.image.channels[1][p.1]).collect();
        let mid = d.len() / 2;
        let median = *d.select_nth_unstable_by(mid, f32::total_cmp).1;
        let mut dev: Vec<f32> = d.iter().map(|v| (v - median).abs()).collect();
        dev.sort_by(f32::total_cmp);
        let inner = &dev[..(dev.len() * 9 / 10).max(1)];
        let mean = inner.iter().sum::<f32>() / inner.len() as f32;
        // E|X| = σ·√(2/π) for a Gaussian; trimming the top 10% lowers it by a fixed factor.
        mean * (std::f32::consts::PI / 2.0).sqrt() / std::f32::consts::SQRT_2
    };
    Some(aligned.iter().map(|a| spread(a)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::{DepthMap, Frame};
    use crate::image::sample_bicubic;

    fn analysed(image: Rgb, depth: Plane, world_from_camera: Mat4) -> Analysed {
        Analysed {
            frame: Frame { index: 0, t_s: 0.0, image, depth: None, flow: None },
            depth: Some(DepthMap { depth, units: DepthUnits::MetricM }),
            world_from_camera: Some(world_from_camera),
            sparse_flow: None,
        }
    }

    fn pattern(w: usize, h: usize) -> Rgb {
        let mut img = Rgb::new(w, h, [0.0; 3]);
        for c in 0..3 {
            for (i, v) in img.channels[c].iter_mut().enumerate() {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                *v = 0.5 + 0.4 * ((0.37 + 0.1 * c as f32) * x).sin() * (0.23 * y + c as f32).cos();
            }
        }
        img
    }

    /// The row-affine, shared-weight `align` is the per-pixel projection and
    /// per-channel clamped sampling it replaced (kept here as the reference):
    /// same valid pixels, same values (tolerance: the two orders of f32 operations
    /// differ by ~1e-6 px in the sample position and by summation order in the
    /// 16-tap sum; the value moves by that times the image gradient, < 1e-4 here).
    #[test]
    fn align_matches_the_per_pixel_reference() {
        let (w, h) = (96usize, 72usize);
        let k = Intrinsics { fx: 80.0, fy: 80.0, cx: 47.5, cy: 35.5, width: w, height: h };
        // A tilted plane in front of the camera and a nearer box (occlusion).
        let depth = |shift: f32| {
            Plane::from_vec(
                w,
                h,
                (0..w * h)
                    .map(|i| {
                        let (x, y) = (i % w, i / w);
                        if (30..50).contains(&x) && (20..40).contains(&y) {
                            1.2
                        } else {
                            2.0 + 0.01 * (x as f32 + shift) + 0.005 * y as f32
                        }
                    })
                    .collect(),
            )
        };
        let src_pose = Mat4::from_rotation_translation(glam::Quat::from_rotation_y(0.02), Vec3::new(0.03, -0.01, 0.0));
        let src = analysed(pattern(w, h), depth(1.5), src_pose);
        let dst = analysed(pattern(w, h), depth(0.0), Mat4::IDENTITY);
        let a = align(&src, &dst, &k).expect("aligned");

        let src_from_dst = src_pose.inverse();
        let planes = [src.frame.image.plane(0), src.frame.image.plane(1), src.frame.image.plane(2)];
        let (sd, dd) = (metric(&src).unwrap(), metric(&dst).unwrap());
        let (mut n_valid, mut n_occluded) = (0, 0);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let z = dd.data[i];
                let q = src_from_dst.transform_point3(Vec3::new(
                    (x as f32 - k.cx) / k.fx * z,
                    (y as f32 - k.cy) / k.fy * z,
                    z,
                ));
                let (u, v) = (k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy);
                let inside = u >= BORDER_PX
                    && v >= BORDER_PX
                    && u <= w as f32 - 1.0 - BORDER_PX
                    && v <= h as f32 - 1.0 - BORDER_PX;
                let occluded =
                    inside && sd.get(u.round() as usize, v.round() as usize) < q.z * (1.0 - OCCLUSION_TOLERANCE);
                n_occluded += occluded as usize;
                let expect_valid = inside && !occluded;
                // Pixels within 1e-3 px of the border or of a rounding edge may
                // legitimately flip; none does in this setup.
                assert_eq!(a.valid[i], expect_valid, "valid at ({x}, {y})");
                if expect_valid {
                    n_valid += 1;
                    for c in 0..3 {
                        let want = sample_bicubic(&planes[c], u, v);
                        assert!(
                            (a.image.channels[c][i] - want).abs() < 1e-4,
                            "({x}, {y}) c{c}: {} vs {want}",
                            a.image.channels[c][i]
                        );
                    }
                }
            }
        }
        assert!(n_valid > w * h / 2, "most of the frame aligns: {n_valid}");
        assert!(n_occluded > 0, "the box occludes part of the plane in the source view");
    }

    /// A camera moved sideways by exactly 3 px at the depth of a fronto-parallel
    /// wall sees the source shifted by 3 px: the aligned frame is the source, shifted,
    /// to rounding (Catmull–Rom interpolates at integer positions).
    #[test]
    fn integer_shift_reproduces_the_source() {
        let (w, h) = (64usize, 48usize);
        let k = Intrinsics { fx: 50.0, fy: 50.0, cx: 31.5, cy: 23.5, width: w, height: h };
        let z = 2.0;
        let wall = Plane::new(w, h, z);
        let shift_px = 3.0;
        // Source camera 3 px · z / fx to the right: a destination pixel x is at x − 3 in the source.
        let src_pose = Mat4::from_translation(Vec3::new(shift_px * z / k.fx, 0.0, 0.0));
        let src = analysed(pattern(w, h), wall.clone(), src_pose);
        let dst = analysed(pattern(w, h), wall, Mat4::IDENTITY);
        let a = align(&src, &dst, &k).expect("aligned");
        let mut n = 0;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if !a.valid[i] {
                    continue;
                }
                n += 1;
                for c in 0..3 {
                    let want = src.frame.image.channels[c][i - 3];
                    assert!((a.image.channels[c][i] - want).abs() < 1e-4, "({x}, {y}) c{c}");
                }
            }
        }
        // Valid: x − 3 ∈ [2, w − 3] (x ≤ w − 1), y ∈ [2, h − 3]: 59 × 44 pixels, one
        // column fewer where the translation's rounding puts u a hair below 2.
        assert!((58 * 44..=59 * 44).contains(&n), "valid region: {n}");
    }

    /// `align_bands` is `align` on its bands (bit for bit: the same code per row) and
    /// invalid elsewhere; every stride keeps some rows and covers ~1/stride of them.
    #[test]
    fn bands_are_the_full_alignment_on_their_rows() {
        let (w, h) = (64usize, 200usize);
        let k = Intrinsics { fx: 50.0, fy: 50.0, cx: 31.5, cy: 99.5, width: w, height: h };
        let wall = Plane::new(w, h, 2.0);
        let src_pose = Mat4::from_translation(Vec3::new(0.05, 0.02, 0.0));
        let src = analysed(pattern(w, h), wall.clone(), src_pose);
        let dst = analysed(pattern(w, h), wall, Mat4::IDENTITY);
        let full = align(&src, &dst, &k).expect("aligned");
        for stride in [1usize, 2, 3, 6] {
            let part = align_bands(&src, &dst, &k, stride).expect("aligned");
            let rows = (0..h).filter(|&y| in_band(y, stride)).count();
            assert!(rows > 0 && rows <= h.div_ceil(stride) + BAND_ROWS, "stride {stride}: {rows} rows");
            for i in 0..w * h {
                if in_band(i / w, stride) {
                    assert_eq!(part.valid[i], full.valid[i], "stride {stride}, pixel {i}");
                    for c in 0..3 {
                        assert_eq!(part.image.channels[c][i], full.image.channels[c][i]);
                    }
                } else {
                    assert!(!part.valid[i], "stride {stride}: row {} is not aligned", i / w);
                }
            }
        }
    }

    /// A sparse reference made in recycled buffers (`MotionDeblurrer::recycle`) is
    /// the one made in fresh ones, bit for bit: the last reference leaves nothing
    /// behind, in its bands or outside them.
    #[test]
    fn a_recycled_reference_is_a_fresh_one() {
        let (w, h) = (64usize, 200usize);
        let k = Intrinsics { fx: 50.0, fy: 50.0, cx: 31.5, cy: 99.5, width: w, height: h };
        let at_rest = |image: Rgb, x_m: f32, index: u64| {
            let mut a = analysed(image, Plane::new(w, h, 2.0), Mat4::from_translation(Vec3::new(x_m, 0.0, 0.0)));
            a.frame.index = index;
            a.sparse_flow = Some(vec![[0.1, 0.0]; 4]);
            Arc::new(a)
        };
        let shifted = |d: f32| {
            let mut img = pattern(w, h);
            img.channels.iter_mut().for_each(|c| c.iter_mut().for_each(|v| *v = (*v + d).min(1.0)));
            img
        };
        let window = [at_rest(pattern(w, h), 0.03, 1), at_rest(shifted(0.1), -0.02, 2)];
        let other = [at_rest(shifted(0.2), 0.01, 3), at_rest(shifted(0.05), 0.04, 4)];
        let reference = |p: &mut TemporalMotionDeblur, window: &[Arc<Analysed>], x_m: f32| {
            let current =
                analysed(pattern(w, h), Plane::new(w, h, 2.0), Mat4::from_translation(Vec3::new(x_m, 0.0, 0.0)));
            let ctx = FrameContext {
                current: &current,
                window,
                poses: None,
                intrinsics: Some(&k),
                frame_interval_s: 1.0 / 30.0,
            };
            p.deblur(&ctx, &Flow::uniform(w, h, 0.0, 0.0)).expect("reference")
        };
        let sparse = || TemporalMotionDeblur { max_aligned_px: Some(w * h / 3 + 1), ..TemporalMotionDeblur::sparse() };
        assert_eq!(sparse().stride(w, h), 3);
        let mut recycled = sparse();
        let first = reference(&mut recycled, &window, 0.0);
        recycled.recycle(first);
        let again = reference(&mut recycled, &other, 0.01);
        let fresh = reference(&mut sparse(), &other, 0.01);
        assert!(recycled.pool.rgb.is_empty() && recycled.pool.plane.len() == 1, "the buffers were reused");
        assert_eq!(again.image, fresh.image);
        assert_eq!(again.second, fresh.second);
        assert_eq!(again.valid, fresh.valid);
        assert!(fresh.second.is_some() && fresh.valid.as_ref().is_some_and(|v| v.data.iter().any(|v| *v > 0.5)));
    }
}
