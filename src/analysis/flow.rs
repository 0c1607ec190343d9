//! Flow providers, px per frame interval centred on the frame time (the window the
//! model's λ is centred on):
//! * `PoseDepthFlow` (headset-native): each pixel's surface point (metric depth,
//!   intrinsics) carried from the camera pose at t − Δ/2 to the pose at t + Δ/2,
//!   both from the smooth pose track (`timing::PoseTrack`). Exact for a static
//!   scene, whatever its texture; moving objects are the one thing it misses.
//! * `LucasKanadeFlow` (classical): dense pyramidal Lucas–Kanade from the previous
//!   frame to this one (constant velocity over a frame assumed), for recordings
//!   without poses.
//! * `GivenFlow`: the flow delivered with the frame (flow files).

use super::{AnalysisError, FlowProvider, FrameContext, Intrinsics};
use crate::image::{blur_separable, expand, gaussian_pyramid, Flow, Plane};
use glam::{Mat4, Vec3};

/// Seconds to the pose track's nanoseconds.
pub fn to_ns(t_s: f64) -> i64 {
    (t_s * 1e9).round() as i64
}

/// Poses of the camera at t − Δ/2, t, t + Δ/2 from the context's track.
pub fn poses_around(ctx: &FrameContext, provider: &'static str) -> Result<[Mat4; 3], AnalysisError> {
    let frame = ctx.current.frame.index;
    let track = ctx.poses.ok_or_else(|| AnalysisError::unavailable(frame, provider, "no camera poses"))?;
    let t = ctx.current.frame.t_s;
    let half = 0.5 * ctx.frame_interval_s;
    let mut out = [Mat4::IDENTITY; 3];
    for (o, ts) in out.iter_mut().zip([t - half, t, t + half]) {
        let p = track.at(to_ns(ts)).ok_or_else(|| {
            AnalysisError::unavailable(frame, provider, format!("the pose track does not cover t = {ts:.4} s"))
        })?;
        *o = Mat4::from_rotation_translation(p.orientation, p.position_m);
    }
    Ok(out)
}

/// Where the pixel (x, y) at depth z of a camera at `at` is seen by the cameras
/// `before` and `after`: the displacement between them.
struct PoseFlow {
    k: Intrinsics,
    before_from_at: Mat4,
    after_from_at: Mat4,
}

impl PoseFlow {
    fn new(k: &Intrinsics, [before, at, after]: [Mat4; 3]) -> Self {
        Self { k: *k, before_from_at: before.inverse() * at, after_from_at: after.inverse() * at }
    }

    #[inline]
    fn at(&self, x: f32, y: f32, z: f32) -> [f32; 2] {
        let k = &self.k;
        let p = Vec3::new((x - k.cx) / k.fx * z, (y - k.cy) / k.fy * z, z);
        let proj = |m: &Mat4| {
            let q = m.transform_point3(p);
            let zq = q.z.max(1e-3);
            (k.fx * q.x / zq + k.cx, k.fy * q.y / zq + k.cy)
        };
        let (b, a) = (proj(&self.before_from_at), proj(&self.after_from_at));
        [a.0 - b.0, a.1 - b.1]
    }
}

fn median_depth(depth: &Plane) -> Option<f32> {
    // On a grid of at most ~65 000 pixels: the fallback depth does not need the
    // exact median, and the full one (a copy and a selection of 1.2 M values) was
    // half of the dense flow's cost at 1280×960. Sparse valid depth the grid misses
    // falls back to every pixel.
    let on_grid = |step: usize| -> Vec<f32> {
        (0..depth.height)
            .step_by(step)
            .flat_map(|y| depth.data[y * depth.width..(y + 1) * depth.width].iter().step_by(step))
            .copied()
            .filter(|z| z.is_finite() && *z > 0.0)
            .collect()
    };
    let step = ((depth.data.len() / 65_536) as f64).sqrt().floor().max(1.0) as usize;
    let mut v = on_grid(step);
    if v.is_empty() && step > 1 {
        v = on_grid(1);
    }
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    Some(*v.select_nth_unstable_by(mid, f32::total_cmp).1)
}

fn metric_depth<'a>(ctx: &'a FrameContext, provider: &'static str) -> Result<&'a Plane, AnalysisError> {
    let frame = ctx.current.frame.index;
    let d = ctx.current.depth.as_ref().ok_or_else(|| AnalysisError::unavailable(frame, provider, "no depth"))?;
    if d.units != crate::model::DepthUnits::MetricM {
        return Err(AnalysisError::unavailable(frame, provider, "depth is relative (not metric): no pose-based flow"));
    }
    Ok(&d.depth)
}

/// Headset-native flow from poses and metric depth.
#[derive(Default)]
pub struct PoseDepthFlow;

/// Sparse-grid size of `sparse_pose_flow` (columns × rows).
pub const SPARSE_GRID: (usize, usize) = (8, 6);

impl PoseDepthFlow {
    /// Flow at an 8×6 grid of pixels (cell centres), for comparing frames' motion
    /// cheaply. Pixels without depth use the frame's median depth.
    pub fn sparse(ctx: &FrameContext) -> Result<Vec<[f32; 2]>, AnalysisError> {
        let provider = "pose + depth flow";
        let k = ctx
            .intrinsics
            .ok_or_else(|| AnalysisError::unavailable(ctx.current.frame.index, provider, "no intrinsics"))?;
        let depth = metric_depth(ctx, provider)?;
        let pf = PoseFlow::new(k, poses_around(ctx, provider)?);
        let fallback = median_depth(depth).unwrap_or(2.0);
        let (gw, gh) = SPARSE_GRID;
        let mut out = Vec::with_capacity(gw * gh);
        for j in 0..gh {
            for i in 0..gw {
                let x = ((i as f32 + 0.5) / gw as f32 * depth.width as f32).min(depth.width as f32 - 1.0);
                let y = ((j as f32 + 0.5) / gh as f32 * depth.height as f32).min(depth.height as f32 - 1.0);
                let z = depth.get(x as usize, y as usize);
                out.push(pf.at(x, y, if z.is_finite() && z > 0.0 { z } else { fallback }));
            }
        }
        Ok(out)
    }
}

impl FlowProvider for PoseDepthFlow {
    fn name(&self) -> &str {
        "pose + depth flow"
    }

    fn flow(&mut self, ctx: &FrameContext) -> Result<Flow, AnalysisError> {
        self.flow_rows(ctx, &|_| true)
    }

    fn flow_rows(&mut self, ctx: &FrameContext, row: &(dyn Fn(usize) -> bool + Sync)) -> Result<Flow, AnalysisError> {
        let provider = "pose + depth flow";
        let frame = ctx.current.frame.index;
        let k = ctx.intrinsics.ok_or_else(|| AnalysisError::unavailable(frame, provider, "no intrinsics"))?;
        let depth = metric_depth(ctx, provider)?;
        if (depth.width, depth.height) != (k.width, k.height) {
            return Err(AnalysisError::unavailable(
                frame,
                provider,
                format!(
                    "depth is {}×{} but the intrinsics are for {}×{}",
                    depth.width, depth.height, k.width, k.height
                ),
            ));
        }
        let pf = PoseFlow::new(k, poses_around(ctx, provider)?);
        // Pixels without depth (sky, out of the depth sensor's range) move with the
        // frame's median depth: the rotational part, which dominates head motion, is
        // depth-independent.
        let fallback =
            median_depth(depth).ok_or_else(|| AnalysisError::unavailable(frame, provider, "no valid depth pixel"))?;
        let (w, h) = (depth.width, depth.height);
        let mut flow = Flow::uniform(w, h, 0.0, 0.0);
        for y in (0..h).filter(|&y| row(y)) {
            for x in 0..w {
                let i = y * w + x;
                let z = depth.data[i];
                let [dx, dy] = pf.at(x as f32, y as f32, if z.is_finite() && z > 0.0 { z } else { fallback });
                flow.dx[i] = dx;
                flow.dy[i] = dy;
            }
        }
        Ok(flow)
    }
}

/// The flow delivered with the frame.
#[derive(Default)]
pub struct GivenFlow;

impl FlowProvider for GivenFlow {
    fn name(&self) -> &str {
        "flow files"
    }
    fn flow(&mut self, ctx: &FrameContext) -> Result<Flow, AnalysisError> {
        let f = &ctx.current.frame;
        f.flow.clone().ok_or_else(|| AnalysisError::unavailable(f.index, "flow files", "no flow with this frame"))
    }
}

/// Dense pyramidal Lucas–Kanade on luma (Bouguet's formulation: per level, a few
/// Gauss–Newton steps of the windowed brightness-constancy least squares, the
/// window's structure tensor from the current frame's gradients).
#[derive(Clone, Debug)]
pub struct LucasKanadeFlow {
    /// Window radius (px): (2r+1)² pixels per least-squares system.
    pub window_radius: usize,
    /// Pyramid levels above the finest (each halves the size).
    pub levels: usize,
    pub iterations: usize,
}

impl Default for LucasKanadeFlow {
    fn default() -> Self {
        Self { window_radius: 4, levels: 4, iterations: 4 }
    }
}

fn gradients(p: &Plane) -> (Plane, Plane) {
    let (w, h) = (p.width, p.height);
    let mut gx = Plane::new(w, h, 0.0);
    let mut gy = Plane::new(w, h, 0.0);
    for y in 0..h {
        for x in 0..w {
            let (xi, yi) = (x as isize, y as isize);
            gx.data[y * w + x] = 0.5 * (p.get_clamped(xi + 1, yi) - p.get_clamped(xi - 1, yi));
            gy.data[y * w + x] = 0.5 * (p.get_clamped(xi, yi + 1) - p.get_clamped(xi, yi - 1));
        }
    }
    (gx, gy)
}

fn product(a: &Plane, b: &Plane) -> Plane {
    Plane::from_vec(a.width, a.height, a.data.iter().zip(&b.data).map(|(x, y)| x * y).collect())
}

impl LucasKanadeFlow {
    /// Motion of every pixel of `current` since `previous` (px).
    pub fn between(&self, previous: &Plane, current: &Plane) -> Flow {
        let max_levels = {
            let mut l = 0;
            let (mut w, mut h) = (current.width, current.height);
            while l < self.levels && w >= 32 && h >= 32 {
                w = w.div_ceil(2);
                h = h.div_ceil(2);
                l += 1;
            }
            l
        };
        let p0 = gaussian_pyramid(previous, max_levels);
        let p1 = gaussian_pyramid(current, max_levels);
        let r = self.window_radius;
        let box_kernel = vec![1.0 / (2 * r + 1) as f32; 2 * r + 1];
        let mut d: Option<(Plane, Plane)> = None;
        for l in (0..=max_levels).rev() {
            let (i0, i1) = (&p0[l], &p1[l]);
            let (w, h) = (i1.width, i1.height);
            let (mut dx, mut dy) = match d.take() {
                None => (Plane::new(w, h, 0.0), Plane::new(w, h, 0.0)),
                Some((ux, uy)) => {
                    let (mut ex, mut ey) = (expand(&ux, w, h), expand(&uy, w, h));
                    ex.data.iter_mut().for_each(|v| *v *= 2.0);
                    ey.data.iter_mut().for_each(|v| *v *= 2.0);
                    (ex, ey)
                }
            };
            let (gx, gy) = gradients(i1);
            let sxx = blur_separable(&product(&gx, &gx), &box_kernel);
            let sxy = blur_separable(&product(&gx, &gy), &box_kernel);
            let syy = blur_separable(&product(&gy, &gy), &box_kernel);
            for _ in 0..self.iterations {
                // Lucas–Kanade assumes one displacement d_i for pixel i's whole window,
                // but each window pixel j was warped by its own d_j. Linearising
                // I0(x_j − d_i) ≈ I0(x_j − d_j) + g_j·(d_j − d_i) (g = ∇I1, which equals
                // ∇I0 at the match), the window's normal equations become
                //   G_i d_i = Σ_j g_j (e_j + g_j·d_j),  e_j = I0(x_j − d_j) − I1(x_j),
                // one box filter per component: per-pixel warps with box sums
                // otherwise couple neighbours and drift.
                let mut tx = Plane::new(w, h, 0.0);
                let mut ty = Plane::new(w, h, 0.0);
                for y in 0..h {
                    for x in 0..w {
                        let i = y * w + x;
                        let (ddx, ddy) = (dx.data[i], dy.data[i]);
                        let e = i0.sample_bilinear(x as f32 - ddx, y as f32 - ddy) - i1.data[i];
                        let t = e + gx.data[i] * ddx + gy.data[i] * ddy;
                        tx.data[i] = gx.data[i] * t;
                        ty.data[i] = gy.data[i] * t;
                    }
                }
                let bx = blur_separable(&tx, &box_kernel);
                let by = blur_separable(&ty, &box_kernel);
                for i in 0..w * h {
                    let (a, b, c) = (sxx.data[i], sxy.data[i], syy.data[i]);
                    let det = a * c - b * b;
                    // Untextured or aperture-limited windows: keep the coarser
                    // level's estimate.
                    if det <= 1e-12 || det < 1e-3 * (a + c) * (a + c) {
                        continue;
                    }
                    let (rx, ry) = (bx.data[i], by.data[i]);
                    let nx = (c * rx - b * ry) / det;
                    let ny = (a * ry - b * rx) / det;
                    // At most 2 px per step (a bad linearisation cannot run away).
                    dx.data[i] += (nx - dx.data[i]).clamp(-2.0, 2.0);
                    dy.data[i] += (ny - dy.data[i]).clamp(-2.0, 2.0);
                }
            }
            d = Some((dx, dy));
        }
        let (dx, dy) = d.unwrap_or_else(|| (Plane::new(1, 1, 0.0), Plane::new(1, 1, 0.0)));
        Flow { width: dx.width, height: dx.height, dx: dx.data, dy: dy.data }
    }
}

impl FlowProvider for LucasKanadeFlow {
    fn name(&self) -> &str {
        "Lucas–Kanade flow"
    }

    fn flow(&mut self, ctx: &FrameContext) -> Result<Flow, AnalysisError> {
        let cur = &ctx.current.frame;
        let prev = ctx.window.last().ok_or_else(|| {
            AnalysisError::unavailable(cur.index, "Lucas–Kanade flow", "no previous frame to track from")
        })?;
        let gap_s = cur.t_s - prev.frame.t_s;
        if !(gap_s > 0.0 && gap_s < 4.0 * ctx.frame_interval_s) {
            return Err(AnalysisError::unavailable(
                cur.index,
                "Lucas–Kanade flow",
                format!("previous frame is {gap_s:.3} s away (more than 4 frame intervals)"),
            ));
        }
        let mut f = self.between(&prev.frame.image.luma(), &cur.image.luma());
        // Per frame interval: the displacement over the actual gap, rescaled.
        let scale = (ctx.frame_interval_s / gap_s) as f32;
        f.dx.iter_mut().chain(f.dy.iter_mut()).for_each(|v| *v *= scale);
        Ok(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texture(w: usize, h: usize, ox: f32, oy: f32) -> Plane {
        let mut p = Plane::new(w, h, 0.0);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f32 - ox, y as f32 - oy);
                p.data[y * w + x] = 0.5
                    + 0.2 * (0.31 * u).sin() * (0.23 * v).cos()
                    + 0.15 * (0.11 * u + 0.17 * v).sin()
                    + 0.1 * (0.05 * u - 0.07 * v).cos();
            }
        }
        p
    }

    /// A smooth texture translated by (3.3, −1.7) px: LK recovers it in the interior
    /// within 0.1 px everywhere and 0.03 px in the median. Not exact: bilinear
    /// warping attenuates the texture's finest component (0.31 rad/px) by up to
    /// 1.2% at half-pixel offsets, and the coarse levels see it aliased.
    #[test]
    fn lucas_kanade_recovers_a_translation() {
        let (a, b) = (texture(128, 96, 0.0, 0.0), texture(128, 96, 3.3, -1.7));
        let f = LucasKanadeFlow::default().between(&a, &b);
        let mut errs = vec![];
        for y in 16..80 {
            for x in 16..112 {
                let i = y * 128 + x;
                errs.push((f.dx[i] - 3.3).hypot(f.dy[i] + 1.7));
            }
        }
        errs.sort_by(f32::total_cmp);
        let (median, worst) = (errs[errs.len() / 2], errs[errs.len() - 1]);
        assert!(worst < 0.1 && median < 0.03, "median {median} px, worst {worst} px");
    }

    /// `flow_rows` is `flow` on its rows (bit for bit: the same code per row) and 0
    /// elsewhere.
    #[test]
    fn flow_rows_is_the_flow_on_its_rows() {
        use crate::analysis::timing::{PoseTrack, TimedPose};
        use crate::analysis::{Analysed, DepthMap, Frame, Intrinsics};
        use glam::{Quat, Vec3};
        let (w, h) = (48usize, 40usize);
        let k = Intrinsics { fx: 40.0, fy: 40.0, cx: 23.5, cy: 19.5, width: w, height: h };
        let poses = (0..5)
            .map(|i| TimedPose {
                t_ns: i * 20_000_000,
                position_m: Vec3::new(0.01 * i as f32, 0.0, 0.0),
                orientation: Quat::from_rotation_y(0.02 * i as f32),
            })
            .collect();
        let track = PoseTrack::new(poses).expect("poses");
        let mut depth = Plane::new(w, h, 2.0);
        depth.data[5] = f32::NAN; // no depth here: the fallback depth
        let current = Analysed {
            frame: Frame {
                index: 2,
                t_s: 0.04,
                image: crate::image::Rgb::new(w, h, [0.5; 3]),
                depth: None,
                flow: None,
            },
            depth: Some(DepthMap { depth, units: crate::model::DepthUnits::MetricM }),
            world_from_camera: None,
            sparse_flow: None,
        };
        let ctx = FrameContext {
            current: &current,
            window: &[],
            poses: Some(&track),
            intrinsics: Some(&k),
            frame_interval_s: 0.02,
        };
        let row = |y: usize| y % 3 == 0;
        let full = PoseDepthFlow.flow(&ctx).expect("flow");
        assert!(full.dx.iter().all(|v| *v != 0.0), "every pixel moves");
        let part = PoseDepthFlow.flow_rows(&ctx, &row).expect("flow");
        for i in 0..w * h {
            let (want_dx, want_dy) = if row(i / w) { (full.dx[i], full.dy[i]) } else { (0.0, 0.0) };
            assert_eq!((part.dx[i], part.dy[i]), (want_dx, want_dy), "pixel {i}");
        }
    }
}
