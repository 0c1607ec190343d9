//! Recorded video with known truth (the paper's FULLPIPELINE experiment, Sec. 4.5):
//! a real photograph with real depth, seen by a camera moving along a smooth head
//! path, re-rendered per frame by depth-based reprojection and distorted by a
//! known camera model that may change mid-sequence (an exposure or gain change).
//! What `calibrate`, the worker tests, the tier benchmarks and the demo run on.
//!
//! World = the photograph's camera (OpenCV axes: x right, y down, z forward,
//! metres); frame poses are `world_from_camera` in the same axes, as in
//! `calibrate`'s poses.csv. The truth flow is the displacement of each pixel's
//! world point between the poses half a frame interval before and after the
//! frame time (the window the model's λ is centred on), computed here with full
//! 4×4 projections, independently of `analysis::flow`.

use crate::analysis::reproject::Intrinsics;
use crate::image::{sample_bicubic, Flow, Plane, Rgb};
use crate::model::{CameraModel, DepthOfField, DepthUnits, Diagnostics, DofCurve, MotionBlur};
use glam::{Mat4, Quat, Vec3, Vec4};

/// The bundled photograph and its disparity ×64 (assets/ATTRIBUTION.md).
pub const PHOTO: &[u8] = include_bytes!("../../assets/motorcycle_left_333x497.png");
pub const DISPARITY_X64: &[u8] = include_bytes!("../../assets/motorcycle_disp_333x497_x64.png");
/// Middlebury 2014 Motorcycle calibration at the ¼ scale of the bundled crop
/// (assets/ATTRIBUTION.md): Z = f·B / (d + doffs).
pub const MOTORCYCLE_FOCAL_PX: f32 = 3979.911 / 4.0;
const BASELINE_M: f32 = 0.193001;
const DOFFS_PX: f32 = 124.343 / 4.0;

/// A photograph with metric depth at every pixel, taken by `intrinsics` at the
/// world origin.
#[derive(Clone, Debug)]
pub struct Scene {
    pub image: Rgb,
    pub depth_m: Plane,
    pub intrinsics: Intrinsics,
}

/// An encoded 8/16-bit image as RGB floats in [0, 1].
pub fn decode_rgb(bytes: &[u8]) -> Result<Rgb, String> {
    let img = image::load_from_memory(bytes).map_err(|e| e.to_string())?.to_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let raw = img.into_raw();
    let mut out = Rgb::new(w, h, [0.0; 3]);
    for i in 0..w * h {
        for c in 0..3 {
            out.channels[c][i] = raw[3 * i + c];
        }
    }
    Ok(out)
}

/// The bundled Middlebury Motorcycle photograph with its ground-truth depth
/// (pixels without ground truth filled from their row's nearest valid pixel, so
/// every pixel of the scene has a surface).
pub fn motorcycle() -> Result<Scene, String> {
    let image = decode_rgb(PHOTO).map_err(|e| format!("bundled photograph: {e}"))?;
    let disp = image::load_from_memory(DISPARITY_X64).map_err(|e| format!("bundled disparity: {e}"))?.to_luma16();
    let (w, h) = (disp.width() as usize, disp.height() as usize);
    if (w, h) != (image.width, image.height) {
        return Err(format!("bundled disparity is {w}×{h}, the photograph {}×{}", image.width, image.height));
    }
    let z: Vec<f32> = disp
        .into_raw()
        .into_iter()
        .map(|v| if v == 0 { f32::NAN } else { MOTORCYCLE_FOCAL_PX * BASELINE_M / (v as f32 / 64.0 + DOFFS_PX) })
        .collect();
    scene_from_depth(image, Plane::from_vec(w, h, z), MOTORCYCLE_FOCAL_PX)
}

/// A photograph with measured depth (metres; non-finite or ≤ 0 where unknown, filled
/// by `fill_holes`) taken with focal length `focal_px` and the principal point at the
/// centre: the bundled Motorcycle, or a scene from another dataset.
pub fn scene_from_depth(image: Rgb, depth_m: Plane, focal_px: f32) -> Result<Scene, String> {
    let (w, h) = (image.width, image.height);
    if (depth_m.width, depth_m.height) != (w, h) {
        return Err(format!("depth is {}×{}, the photograph {w}×{h}", depth_m.width, depth_m.height));
    }
    if !(focal_px.is_finite() && focal_px > 0.0) {
        return Err(format!("focal length {focal_px} px is not a positive number"));
    }
    let known = depth_m.data.iter().filter(|v| v.is_finite() && **v > 0.0).count();
    if known * 2 < depth_m.data.len() {
        return Err(format!("depth is known at {known} of {} pixels (under half)", depth_m.data.len()));
    }
    let intrinsics =
        Intrinsics { fx: focal_px, fy: focal_px, cx: w as f32 / 2.0, cy: h as f32 / 2.0, width: w, height: h };
    Ok(Scene { image, depth_m: fill_holes(depth_m), intrinsics })
}

/// A scene with the Motorcycle's geometry and a texture whose own blur is known:
/// `base`'s depth magnified `scale`× (nearest pixel: depth edges stay edges), under
/// a procedural texture of hard-edged shapes — rotated rectangles (bars down to
/// one pixel wide, where edge estimators read thin strokes) and discs of random
/// colour — each pixel the mean of 4×4 sub-samples. Why: the bundled photograph is
/// 497×333, so a 1280×960 view magnifies it 4× together with its own optical blur
/// and pixel (the blind DoF estimator reads its effect-free frames at 1–2 px,
/// varying over the frame); here every edge carries only the area sampling of one
/// source pixel (`SequenceSpec::source_pixel_blur_px`), and at `scale` = 4 a
/// 1280×960 view samples it 1:1. Deterministic in `seed`.
pub fn procedural(base: &Scene, scale: usize, seed: u64) -> Scene {
    let scale = scale.max(1);
    let (bw, bh) = (base.intrinsics.width, base.intrinsics.height);
    let (w, h) = (bw * scale, bh * scale);
    let depth: Vec<f32> =
        (0..h).flat_map(|y| (0..w).map(move |x| (x / scale, y / scale))).map(|(x, y)| base.depth_m.get(x, y)).collect();
    let mut rng = super::training::SplitMix(seed);
    let mut img = Rgb::new(w, h, [0.45, 0.42, 0.40]);
    // Shapes per source area: about one per 40×40 px of the magnified frame, sizes
    // spread log-uniformly from 1 px bars to 160 px blocks.
    let count = (w * h) / 1600;
    for _ in 0..count {
        let colour: [f32; 3] = {
            let l = rng.uniform(0.05, 0.95);
            std::array::from_fn(|_| (l * rng.uniform(0.8, 1.2)).clamp(0.0, 1.0))
        };
        let (cx, cy) = (rng.uniform(0.0, w as f32), rng.uniform(0.0, h as f32));
        let long = (rng.uniform(1.5f32.ln(), 160f32.ln())).exp();
        let disc = rng.uniform(0.0, 1.0) < 0.3;
        let short = if disc { long } else { (rng.uniform(1f32.ln(), long.ln())).exp() };
        let angle = rng.uniform(0.0, std::f32::consts::PI);
        let (ca, sa) = (angle.cos(), angle.sin());
        let inside = |x: f32, y: f32| {
            let (dx, dy) = (x - cx, y - cy);
            if disc {
                dx * dx + dy * dy <= 0.25 * long * long
            } else {
                let (u, v) = (dx * ca + dy * sa, -dx * sa + dy * ca);
                u.abs() <= 0.5 * long && v.abs() <= 0.5 * short
            }
        };
        let r = 0.5 * long + 1.0;
        let (x0, x1) = ((cx - r).floor().max(0.0) as usize, ((cx + r).ceil() as usize).min(w));
        let (y0, y1) = ((cy - r).floor().max(0.0) as usize, ((cy + r).ceil() as usize).min(h));
        for y in y0..y1 {
            for x in x0..x1 {
                let mut cover = 0u32;
                for sy in 0..4 {
                    for sx in 0..4 {
                        cover += inside(x as f32 + (sx as f32 + 0.5) / 4.0, y as f32 + (sy as f32 + 0.5) / 4.0) as u32;
                    }
                }
                if cover > 0 {
                    let a = cover as f32 / 16.0;
                    for c in 0..3 {
                        let v = &mut img.channels[c][y * w + x];
                        *v = (1.0 - a) * *v + a * colour[c];
                    }
                }
            }
        }
    }
    let k = &base.intrinsics;
    let s = scale as f32;
    // Pixel centres: source pixel u ↔ magnified pixels [s·u, s·u + s), centre
    // s·u + (s − 1)/2.
    let intrinsics = Intrinsics {
        fx: k.fx * s,
        fy: k.fy * s,
        cx: k.cx * s + 0.5 * (s - 1.0),
        cy: k.cy * s + 0.5 * (s - 1.0),
        width: w,
        height: h,
    };
    Scene { image: img, depth_m: Plane::from_vec(w, h, depth), intrinsics }
}

/// An anisotropic random texture: white noise smoothed by a Gaussian of σ
/// `sigma_x_px` along x and `sigma_y_px` along y, mid-grey ± ~0.2 — with σ 3 and
/// 1.2 px its gradient energy along y is ~6× that along x, an orientation as strong
/// as text lines or shelves. Why: the blind motion-blur estimator's isotropy
/// assumption fails on such texture by the flow's direction (the pooled fit's
/// tests). Oriented along x: `sigma_x_px` below `sigma_y_px` is taken as equal.
/// Deterministic in `seed`.
pub fn anisotropic_texture(width: usize, height: usize, sigma_x_px: f32, sigma_y_px: f32, seed: u64) -> Rgb {
    use crate::image::{blur_separable, blur_x, discrete_gaussian_kernel};
    let noise: Vec<f32> =
        (0..width * height).map(|i| super::gaussian((i % width) as u32, (i / width) as u32, 0, seed)).collect();
    // σ_y on both axes, then the rest of σ_x² along x alone (variances add).
    let (vx, vy) = (sigma_x_px * sigma_x_px, sigma_y_px * sigma_y_px);
    let p = blur_separable(&Plane::from_vec(width, height, noise), &discrete_gaussian_kernel(vx.min(vy)));
    let p = if vx > vy { blur_x(&p, &discrete_gaussian_kernel(vx - vy)) } else { p };
    let mut out = Rgb::new(width, height, [0.0; 3]);
    for c in 0..3 {
        out.channels[c] = p.data.iter().map(|v| (0.5 + 1.5 * v).clamp(0.0, 1.0)).collect();
    }
    out
}

/// Non-finite depth replaced by the farther of the nearest valid pixels left and
/// right in its row (disocclusion holes belong to the background), else the median.
fn fill_holes(mut z: Plane) -> Plane {
    let (w, h) = (z.width, z.height);
    let mut valid: Vec<f32> = z.data.iter().copied().filter(|v| v.is_finite() && *v > 0.0).collect();
    valid.sort_by(f32::total_cmp);
    let median = valid.get(valid.len() / 2).copied().unwrap_or(1.0);
    for y in 0..h {
        let row = &mut z.data[y * w..(y + 1) * w];
        let ok = |v: f32| v.is_finite() && v > 0.0;
        let src: Vec<f32> = row.to_vec();
        for x in 0..w {
            if ok(src[x]) {
                continue;
            }
            let left = (0..x).rev().map(|i| src[i]).find(|v| ok(*v));
            let right = (x + 1..w).map(|i| src[i]).find(|v| ok(*v));
            row[x] = match (left, right) {
                (Some(a), Some(b)) => a.max(b),
                (Some(a), None) | (None, Some(a)) => a,
                (None, None) => median,
            };
        }
    }
    z
}

/// A head path of fixations and saccade-like turns, as people look around a room:
/// the head holds still for `hold_s` (frames free of motion blur: the sharp
/// references video provides), then moves for `move_s` to the next target with a
/// C²-smooth profile (smootherstep). Yaw, pitch and sideways sway switch together,
/// their signs cycling through four patterns so that the motion direction varies
/// from turn to turn.
#[derive(Clone, Copy, Debug)]
pub struct HeadPath {
    pub yaw_amplitude_rad: f32,
    pub pitch_amplitude_rad: f32,
    pub sway_m: f32,
    pub move_s: f32,
    pub hold_s: f32,
}

impl Default for HeadPath {
    /// Peak angular speed 1.875·2·0.05/0.8 ≈ 0.23 rad/s (yaw): about 8 px per 30 Hz
    /// frame at the Motorcycle's focal length; stays inside the photograph for a
    /// 320×240 view.
    fn default() -> Self {
        Self { yaw_amplitude_rad: 0.05, pitch_amplitude_rad: 0.02, sway_m: 0.02, move_s: 0.8, hold_s: 0.4 }
    }
}

impl HeadPath {
    /// Target k's (yaw, pitch, sway) signs.
    fn target(&self, k: i64) -> Vec3 {
        const SIGNS: [[f32; 3]; 4] = [[1.0, 1.0, 1.0], [-1.0, 1.0, -1.0], [1.0, -1.0, -1.0], [-1.0, -1.0, 1.0]];
        let s = SIGNS[k.rem_euclid(4) as usize];
        Vec3::new(s[0] * self.yaw_amplitude_rad, s[1] * self.pitch_amplitude_rad, s[2] * self.sway_m)
    }

    /// (yaw, pitch, sway) at `t_s`: hold target k, then move to k + 1.
    fn state(&self, t_s: f64) -> Vec3 {
        let cycle = (self.move_s + self.hold_s) as f64;
        let k = (t_s / cycle).floor();
        let into = (t_s - k * cycle) as f32;
        let (a, b) = (self.target(k as i64), self.target(k as i64 + 1));
        let s = ((into - self.hold_s) / self.move_s).clamp(0.0, 1.0);
        let smoother = s * s * s * (s * (6.0 * s - 15.0) + 10.0);
        a + (b - a) * smoother
    }

    /// `world_from_camera` at time `t_s` (OpenCV axes).
    pub fn world_from_camera(&self, t_s: f64) -> Mat4 {
        let v = self.state(t_s);
        // Yaw about the camera's y (down) axis, pitch about x.
        let rotation = Quat::from_rotation_y(v.x) * Quat::from_rotation_x(v.y);
        Mat4::from_rotation_translation(rotation, Vec3::new(v.z, 0.0, 0.0))
    }
}

/// Projection of camera-space points to pixels (OpenCV axes), as a 4×4 matrix:
/// [u·w, v·w, ·, w] = P · X with w = z.
fn projection(k: &Intrinsics) -> Mat4 {
    Mat4::from_cols(
        Vec4::new(k.fx, 0.0, 0.0, 0.0),
        Vec4::new(0.0, k.fy, 0.0, 0.0),
        Vec4::new(k.cx, k.cy, 0.0, 1.0),
        Vec4::new(0.0, 0.0, 1.0, 0.0),
    )
}

fn project(m: &Mat4, p: Vec3) -> Option<(f32, f32, f32)> {
    let q = *m * p.extend(1.0);
    (q.w > 1e-3).then(|| (q.x / q.w, q.y / q.w, q.w))
}

/// The scene seen by a camera `view` at `world_from_camera`: colour and z-depth.
/// Depth by forward splatting of the scene's points (z-buffer, 2×2 footprints,
/// remaining holes filled from the nearest row neighbours); colour by projecting
/// each pixel's surface point back into the photograph (bicubic).
pub fn render_view(scene: &Scene, view: &Intrinsics, world_from_camera: Mat4) -> (Rgb, Plane) {
    let (w, h) = (view.width, view.height);
    let src = &scene.intrinsics;
    let view_from_world = projection(view) * world_from_camera.inverse();
    let mut z_buf = vec![f32::INFINITY; w * h];
    for v in 0..src.height {
        for u in 0..src.width {
            let z = scene.depth_m.data[v * src.width + u];
            let p = Vec3::new((u as f32 - src.cx) / src.fx * z, (v as f32 - src.cy) / src.fy * z, z);
            let Some((x, y, zc)) = project(&view_from_world, p) else { continue };
            // Footprint: the source pixel's size in view pixels, at least 1.
            let half = (0.5 * view.fx / src.fx * z / zc).max(0.5);
            let (x0, x1) = ((x - half).round().max(0.0) as usize, ((x + half).round().max(0.0) as usize).min(w));
            let (y0, y1) = ((y - half).round().max(0.0) as usize, ((y + half).round().max(0.0) as usize).min(h));
            for yy in y0..y1 {
                for xx in x0..x1 {
                    let cell = &mut z_buf[yy * w + xx];
                    *cell = cell.min(zc);
                }
            }
        }
    }
    let depth = fill_holes(Plane::from_vec(
        w,
        h,
        z_buf.into_iter().map(|z| if z.is_finite() { z } else { f32::NAN }).collect(),
    ));
    let src_from_world = projection(src);
    let planes = [scene.image.plane(0), scene.image.plane(1), scene.image.plane(2)];
    let mut img = Rgb::new(w, h, [0.0; 3]);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let z = depth.data[i];
            let pc = Vec3::new((x as f32 - view.cx) / view.fx * z, (y as f32 - view.cy) / view.fy * z, z);
            let pw = world_from_camera.transform_point3(pc);
            if let Some((u, v, _)) = project(&src_from_world, pw) {
                for c in 0..3 {
                    img.channels[c][i] = sample_bicubic(&planes[c], u, v).clamp(0.0, 1.0);
                }
            }
        }
    }
    (img, depth)
}

/// Truth flow (px per frame interval, centred on the frame time) of the pixels
/// of a view with z-depth `depth`, for camera poses `before` (t − Δ/2) and
/// `after` (t + Δ/2) around `at` (t).
pub fn truth_flow(view: &Intrinsics, depth: &Plane, before: Mat4, at: Mat4, after: Mat4) -> Flow {
    let (w, h) = (view.width, view.height);
    let p = projection(view);
    let (pb, pa) = (p * before.inverse(), p * after.inverse());
    let mut flow = Flow::uniform(w, h, 0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let z = depth.data[i];
            let pw = at.transform_point3(Vec3::new(
                (x as f32 - view.cx) / view.fx * z,
                (y as f32 - view.cy) / view.fy * z,
                z,
            ));
            if let (Some(b), Some(a)) = (project(&pb, pw), project(&pa, pw)) {
                flow.dx[i] = a.0 - b.0;
                flow.dy[i] = a.1 - b.1;
            }
        }
    }
    flow
}

/// What a sequence looks like and which camera made it.
#[derive(Clone, Debug)]
pub struct SequenceSpec {
    pub frames: usize,
    pub fps: f32,
    pub view: Intrinsics,
    pub path: HeadPath,
    /// The camera before the change ...
    pub truth: CameraModel,
    /// ... and after it, from `change_at_s` on (None: no change).
    pub change: Option<(f64, CameraModel)>,
    pub seed: u64,
}

/// One frame: the camera's image (8-bit quantised, as a video would deliver it),
/// its clean rendering, depth, pose, truth flow and truth camera.
#[derive(Clone, Debug)]
pub struct SequenceFrame {
    pub index: usize,
    pub t_s: f64,
    pub image: Rgb,
    pub clean: Rgb,
    pub depth_m: Plane,
    pub world_from_camera: Mat4,
    pub flow: Flow,
    pub truth: CameraModel,
}

impl SequenceSpec {
    /// A `width`×`height` view of the Motorcycle with the default head path at 30 Hz,
    /// the focal length scaled so the field of view is that of a 320×240 crop of the
    /// photograph (1280×960: ×4). Truth: thin-lens DoF focused at 3.1 m, λ = 0.5,
    /// Poisson–Gaussian noise; at `change_at_s` the exposure halves and the gain
    /// rises by 1.5× in std (what an auto-exposure step does).
    pub fn motorcycle(scene: &Scene, width: usize, height: usize, frames: usize, change_at_s: Option<f64>) -> Self {
        let scale = width as f32 / 320.0;
        // The photograph's focal length, whatever the scene's resolution
        // (`procedural` magnifies it): the field of view stays the same.
        let view = Intrinsics {
            fx: MOTORCYCLE_FOCAL_PX * scale,
            fy: MOTORCYCLE_FOCAL_PX * scale,
            cx: width as f32 / 2.0,
            cy: height as f32 / 2.0,
            width,
            height,
        };
        let fps = 30.0;
        let mut truth = CameraModel::empty(width as u32, height as u32);
        truth.reference.frame_interval_s = Some(1.0 / fps);
        truth.reference.pixels_per_radian = Some(view.fx);
        truth.noise = super::white_sensor_noise([3e-5, 2e-5, 5e-5], [6e-4, 4e-4, 9e-4], [0.0, 1.0]);
        truth.motion_blur =
            MotionBlur { present: true, exposure: Some(0.5), diagnostics: Diagnostics::not_fitted("ground truth") };
        let mut valid: Vec<f32> = scene.depth_m.data.clone();
        valid.sort_by(f32::total_cmp);
        let (lo, hi) = (valid[0], valid[valid.len() - 1]);
        truth.depth_of_field = DepthOfField {
            present: true,
            units: DepthUnits::MetricM,
            // 1.2 px per dioptre away from 3.1 m at the 320-px view, scaled with it.
            curve: Some(DofCurve::ThinLens { k: 1.2 * scale * 3.0, focus_depth: 3.1, c0: 0.3 * scale }),
            depth_range: [lo, hi],
            kernel: crate::model::DofKernel::Gaussian,
            diagnostics: Diagnostics::not_fitted("ground truth"),
        };
        let change = change_at_s.map(|t| {
            let mut after = truth.clone();
            after.motion_blur.exposure = Some(0.25);
            after.noise = super::white_sensor_noise([6.75e-5, 4.5e-5, 1.125e-4], [1.35e-3, 9e-4, 2.025e-3], [0.0, 1.0]);
            (t, after)
        });
        Self { frames, fps, view, path: HeadPath::default(), truth, change, seed: 7 }
    }

    /// The blur (Gaussian std, px of the view) the frames carry besides the
    /// truth's δ(Z): the photograph's own pixel, a box one source pixel wide
    /// (variance 1/12 source px²), magnified by the view (view px per source px).
    /// At 320×240 the view is about 1:1 (0.29 px); at 1280×960 it is 4× (1.15 px).
    /// The blind DoF estimator reads effect-free frames of the video at 0.22–0.36 px
    /// and 1.05–1.31 px (BENCHMARKS.md).
    pub fn source_pixel_blur_px(&self, scene: &Scene) -> f32 {
        (self.view.fx / scene.intrinsics.fx) / 12f32.sqrt()
    }

    pub fn truth_at(&self, t_s: f64) -> &CameraModel {
        match &self.change {
            Some((t, after)) if t_s >= *t => after,
            _ => &self.truth,
        }
    }

    pub fn frame_time_s(&self, index: usize) -> f64 {
        index as f64 / self.fps as f64
    }

    /// Render frame `index` (deterministic: the noise is seeded by the index).
    pub fn frame(&self, scene: &Scene, index: usize) -> SequenceFrame {
        let t_s = self.frame_time_s(index);
        let dt = 0.5 / self.fps as f64;
        let at = self.path.world_from_camera(t_s);
        let (clean, depth_m) = render_view(scene, &self.view, at);
        let flow = truth_flow(
            &self.view,
            &depth_m,
            self.path.world_from_camera(t_s - dt),
            at,
            self.path.world_from_camera(t_s + dt),
        );
        let truth = self.truth_at(t_s).clone();
        let distorted = super::apply_camera_model(
            &clean,
            &truth,
            Some(&depth_m),
            Some(&flow),
            self.seed.wrapping_add(index as u64),
        );
        let image = distorted.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
        SequenceFrame { index, t_s, image, clean, depth_m, world_from_camera: at, flow, truth }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rendered view at the identity pose is the photograph's centre crop (up to
    /// bicubic resampling at integer offsets, which is exact), and the truth flow of a
    /// pure yaw is f·ω·Δ at the centre.
    #[test]
    fn identity_view_is_the_centre_crop_and_flow_matches_rotation() {
        let scene = motorcycle().expect("bundled scene");
        // The photograph's principal point is at (248.5, 166.5): a view centred at
        // (160.5, 120.5) sees it at whole-pixel offsets.
        let view = Intrinsics {
            fx: scene.intrinsics.fx,
            fy: scene.intrinsics.fy,
            cx: 160.5,
            cy: 120.5,
            width: 320,
            height: 240,
        };
        let (img, depth) = render_view(&scene, &view, Mat4::IDENTITY);
        let (ox, oy) = ((scene.intrinsics.cx - 160.5) as usize, (scene.intrinsics.cy - 120.5) as usize);
        let mut worst = 0.0f32;
        for y in 0..240 {
            for x in 0..320 {
                let a = img.channels[1][y * 320 + x];
                let b = scene.image.channels[1][(y + oy) * scene.image.width + x + ox];
                worst = worst.max((a - b).abs());
            }
        }
        // Whole-pixel offsets: Catmull–Rom weights are (0, 1, 0, 0); the f32 round
        // trip through depth and back lands ~1e-5 px off, hence 1e-4.
        assert!(worst < 1e-4, "worst {worst}");
        assert!(depth.data.iter().all(|z| z.is_finite() && *z > 0.0));
        let omega = 0.1f32; // rad per frame interval
        let before = Mat4::from_rotation_y(-0.5 * omega);
        let after = Mat4::from_rotation_y(0.5 * omega);
        let flow = truth_flow(&view, &depth, before, Mat4::IDENTITY, after);
        let i = 120 * 320 + 160; // the principal point's pixel (±0.5)
                                 // Camera yaws right (+y rotation turns +z towards +x... world points move left).
        let expect = -2.0 * view.fx * (0.5 * omega).tan();
        assert!((flow.dx[i] - expect).abs() < 0.05, "{} vs {expect}", flow.dx[i]);
        assert!(flow.dy[i].abs() < 0.05);
    }

    /// The procedural scene: the base's depth magnified (nearest pixel), values in
    /// [0, 1], deterministic in its seed, different across seeds, and unblurred:
    /// most horizontal neighbours are exactly equal (inside a shape; only pixels a
    /// shape's edge crosses mix), which no blurred texture has.
    #[test]
    fn procedural_scene_is_deterministic_and_sharp() {
        let base = motorcycle().expect("bundled scene");
        let a = procedural(&base, 2, 3);
        let b = procedural(&base, 2, 3);
        let c = procedural(&base, 2, 4);
        assert_eq!((a.image.width, a.image.height), (2 * base.image.width, 2 * base.image.height));
        assert_eq!(a.image.channels, b.image.channels);
        assert_ne!(a.image.channels, c.image.channels);
        assert!(a.image.channels.iter().flatten().all(|v| (0.0..=1.0).contains(v)));
        assert_eq!(a.depth_m.get(7, 9), base.depth_m.get(3, 4));
        let g = &a.image.channels[1];
        let w = a.image.width;
        let equal = (0..g.len() - 1).filter(|&i| (i + 1) % w != 0 && g[i] == g[i + 1]).count();
        let share = equal as f64 / (g.len() - a.image.height) as f64;
        assert!(share > 0.5, "{share:.2} of horizontal neighbours equal");
        assert_eq!(a.intrinsics.fx, 2.0 * base.intrinsics.fx);
    }
}
