//! The headset's depth (XR_META_environment_depth: one low-resolution depth image
//! per eye view, NDC depth in [0, 1] of a projection with near plane `near_m` at 0
//! and far plane `far_m` — possibly infinite — at 1) reprojected into the
//! passthrough camera: metric z-depth at the camera's pixels, for the depth-based
//! fits (δ(Z)) and pose + depth flow. Forward splatting with a z-buffer: every
//! depth texel is unprojected to a world point, projected into the camera and drawn
//! as a square of its projected footprint, the nearest surface winning (occlusion
//! is resolved, not averaged). Camera convention as in `calibrate`'s poses.csv:
//! OpenCV (x right, y down, z forward), `world_from_camera`; the depth view in
//! OpenXR's (x right, y up, −z forward), `world_from_view`.

use crate::image::Plane;
use glam::{Mat4, Vec3};

/// One eye's environment-depth image and how it was taken.
#[derive(Clone, Debug)]
pub struct DepthView {
    pub width: usize,
    pub height: usize,
    /// Row-major NDC depth in [0, 1]; 1 (the far plane) or non-finite: no surface.
    pub ndc_depth: Vec<f32>,
    pub near_m: f32,
    /// May be `f32::INFINITY` (an infinite far plane).
    pub far_m: f32,
    /// Tangents of the view's field of view: left (< 0), right, up, down (< 0).
    pub fov_tan: [f32; 4],
    pub world_from_view: Mat4,
}

/// Pinhole intrinsics of the (undistorted) passthrough camera, in its pixels.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Intrinsics {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: usize,
    pub height: usize,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ReprojectError {
    #[error("depth image: {0}")]
    Depth(String),
    #[error("camera: {0}")]
    Camera(String),
}

impl DepthView {
    /// Metric view depth of an NDC depth, or None for "no surface".
    pub fn view_depth_m(&self, ndc: f32) -> Option<f32> {
        if !ndc.is_finite() || !(0.0..1.0).contains(&ndc) {
            return None;
        }
        let (n, f) = (self.near_m, self.far_m);
        // Inverse of d = f(z − n) / (z(f − n)) (z = view depth), or of n/z = 1 − d
        // for an infinite far plane.
        let z = if f.is_infinite() { n / (1.0 - ndc) } else { n * f / (f - ndc * (f - n)) };
        (z.is_finite() && z > 0.0).then_some(z)
    }

    fn validate(&self) -> Result<(), ReprojectError> {
        let e = |m: String| Err(ReprojectError::Depth(m));
        if self.width == 0 || self.height == 0 || self.ndc_depth.len() != self.width * self.height {
            return e(format!("{}×{} with {} values", self.width, self.height, self.ndc_depth.len()));
        }
        if !(self.near_m.is_finite() && self.near_m > 0.0 && self.far_m > self.near_m) {
            return e(format!("near {} m / far {} m: need 0 < near < far", self.near_m, self.far_m));
        }
        let [l, r, u, d] = self.fov_tan;
        if !self.fov_tan.iter().all(|t| t.is_finite()) || l >= r || d >= u {
            return e(format!("field of view tangents {:?}", self.fov_tan));
        }
        if !self.world_from_view.is_finite() {
            return e("world_from_view is not finite".into());
        }
        Ok(())
    }
}

/// Camera z-depth (m) at every camera pixel seen by `depth`, NaN elsewhere.
pub fn reproject_depth(
    depth: &DepthView,
    camera: &Intrinsics,
    world_from_camera: Mat4,
) -> Result<Plane, ReprojectError> {
    depth.validate()?;
    let c = camera;
    if c.width == 0
        || c.height == 0
        || ![c.fx, c.fy, c.cx, c.cy].iter().all(|v| v.is_finite())
        || c.fx <= 0.0
        || c.fy <= 0.0
    {
        return Err(ReprojectError::Camera(format!("intrinsics {c:?}")));
    }
    if !world_from_camera.is_finite() || world_from_camera.determinant().abs() < 1e-6 {
        return Err(ReprojectError::Camera("world_from_camera is not a finite rigid transform".into()));
    }
    let camera_from_view = world_from_camera.inverse() * depth.world_from_view;
    let [l, r, u, d] = depth.fov_tan;
    let (step_x, step_y) = ((r - l) / depth.width as f32, (u - d) / depth.height as f32);
    let mut z_buffer = vec![f32::INFINITY; c.width * c.height];
    for v in 0..depth.height {
        for x in 0..depth.width {
            let Some(z) = depth.view_depth_m(depth.ndc_depth[v * depth.width + x]) else { continue };
            // Texel centre's direction; rows run down from the top (tan up).
            let (tx, ty) = (l + (x as f32 + 0.5) * step_x, u - (v as f32 + 0.5) * step_y);
            let p_view = Vec3::new(tx * z, ty * z, -z);
            // Into the camera's own (OpenCV) axes: `world_from_camera` maps them.
            let p = camera_from_view.transform_point3(p_view);
            if p.z.is_nan() || p.z <= 1e-3 {
                continue;
            }
            let (pu, pv) = (c.fx * p.x / p.z + c.cx, c.fy * p.y / p.z + c.cy);
            // The texel's footprint in camera pixels (its angular size × the ratio of
            // distances), half of it each side, at least the pixel itself.
            let hx = (0.5 * c.fx * step_x * z / p.z).clamp(0.5, 64.0);
            let hy = (0.5 * c.fy * step_y * z / p.z).clamp(0.5, 64.0);
            let (x0, x1) = ((pu - hx).floor().max(0.0) as i64, (pu + hx).ceil().min(c.width as f32) as i64);
            let (y0, y1) = ((pv - hy).floor().max(0.0) as i64, (pv + hy).ceil().min(c.height as f32) as i64);
            for yy in y0..y1 {
                for xx in x0..x1 {
                    let cell = &mut z_buffer[yy as usize * c.width + xx as usize];
                    if p.z < *cell {
                        *cell = p.z;
                    }
                }
            }
        }
    }
    let data = z_buffer.into_iter().map(|z| if z.is_finite() { z } else { f32::NAN }).collect();
    Ok(Plane::from_vec(c.width, c.height, data))
}

/// `world_from_view` (OpenXR axes) of a camera pose given in OpenCV axes: the
/// same position, y and z flipped (a rotation of π about x).
pub fn opencv_to_openxr(world_from_camera: Mat4) -> Mat4 {
    world_from_camera * Mat4::from_scale(Vec3::new(1.0, -1.0, -1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Encode view depth z as NDC depth (the projection's forward mapping).
    fn ndc(z: f32, n: f32, f: f32) -> f32 {
        if f.is_infinite() {
            1.0 - n / z
        } else {
            f * (z - n) / (z * (f - n))
        }
    }

    fn view(depth_of: impl Fn(f32, f32) -> f32, far: f32) -> DepthView {
        let (w, h, near) = (160, 160, 0.1);
        let fov_tan = [-1.0, 1.0, 1.0, -1.0];
        let mut ndc_depth = vec![1.0; w * h];
        for v in 0..h {
            for x in 0..w {
                let (tx, ty) = (-1.0 + (x as f32 + 0.5) * 2.0 / w as f32, 1.0 - (v as f32 + 0.5) * 2.0 / h as f32);
                let z = depth_of(tx, ty);
                if z.is_finite() {
                    ndc_depth[v * w + x] = ndc(z, near, far);
                }
            }
        }
        DepthView { width: w, height: h, ndc_depth, near_m: near, far_m: far, fov_tan, world_from_view: Mat4::IDENTITY }
    }

    fn camera() -> Intrinsics {
        Intrinsics { fx: 320.0, fy: 320.0, cx: 320.0, cy: 240.0, width: 640, height: 480 }
    }

    #[test]
    fn ndc_round_trip() {
        for far in [50.0, f32::INFINITY] {
            let dv = view(|_, _| 2.0, far);
            for z in [0.2f32, 1.0, 3.7, 20.0] {
                let got = dv.view_depth_m(ndc(z, 0.1, far)).unwrap();
                assert!((got - z).abs() < 1e-3 * z, "far {far}: {z} -> {got}");
            }
            assert_eq!(dv.view_depth_m(1.0), None);
            assert_eq!(dv.view_depth_m(f32::NAN), None);
        }
    }

    /// A wall 2 m ahead, the camera 3 cm to the side of the depth view (OpenCV axes):
    /// every camera pixel that sees the wall reads 2 m (tolerance 1e-3 m: f32
    /// unprojection), and the view covers nearly all of the camera's image.
    #[test]
    fn fronto_parallel_wall() {
        let dv = view(|_, _| 2.0, f32::INFINITY);
        // The OpenCV pose of a camera at x = 3 cm looking down the world's −z.
        let world_from_camera =
            Mat4::from_translation(Vec3::new(0.03, 0.0, 0.0)) * Mat4::from_scale(Vec3::new(1.0, -1.0, -1.0));
        assert_eq!(opencv_to_openxr(world_from_camera), Mat4::from_translation(Vec3::new(0.03, 0.0, 0.0)));
        let got = reproject_depth(&dv, &camera(), world_from_camera).unwrap();
        let valid: Vec<f32> = got.data.iter().copied().filter(|z| z.is_finite()).collect();
        assert!(valid.len() as f32 > 0.95 * got.data.len() as f32, "coverage {}", valid.len());
        assert!(valid.iter().all(|z| (z - 2.0).abs() < 1e-3));
    }

    /// A tilted floor-like plane: reprojected depth against the exact ray-plane
    /// intersection of each camera pixel (tolerance 2% of depth: a splatted texel
    /// spans ≈ 1.25% of the field of view, over which a tilted plane's depth varies).
    #[test]
    fn tilted_plane_matches_ray_casting() {
        // Plane through (0, 0, −2) with normal (0, 0.6, 0.8) (world = view of the depth image).
        let n = Vec3::new(0.0, 0.6, 0.8);
        let p0 = Vec3::new(0.0, 0.0, -2.0);
        let hit = |o: Vec3, dir: Vec3| -> f32 { (p0 - o).dot(n) / dir.dot(n) };
        let dv = view(|tx, ty| hit(Vec3::ZERO, Vec3::new(tx, ty, -1.0)), 100.0);
        let cam_pos = Vec3::new(-0.05, 0.02, 0.0);
        let world_from_camera = Mat4::from_translation(cam_pos) * Mat4::from_scale(Vec3::new(1.0, -1.0, -1.0));
        let c = camera();
        let got = reproject_depth(&dv, &c, world_from_camera).unwrap();
        let mut checked = 0;
        for v in (0..c.height).step_by(7) {
            for u in (0..c.width).step_by(7) {
                let z = got.get(u, v);
                if !z.is_finite() {
                    continue;
                }
                // Camera ray (OpenCV) in world: x right, y down → −y, z forward → −z.
                let dir = Vec3::new((u as f32 + 0.5 - c.cx) / c.fx, -(v as f32 + 0.5 - c.cy) / c.fy, -1.0);
                let want = hit(cam_pos, dir);
                assert!((z - want).abs() < 0.02 * want, "pixel ({u}, {v}): {z} vs {want}");
                checked += 1;
            }
        }
        assert!(checked > 4000, "{checked}");
    }

    /// A box 1 m away in front of a wall 3 m away; the camera to the side sees both:
    /// where the box is, the box wins (nearest surface), never the wall behind it.
    #[test]
    fn nearer_surface_occludes() {
        let dv = view(|tx, ty| if tx.abs() < 0.2 && ty.abs() < 0.2 { 1.0 } else { 3.0 }, f32::INFINITY);
        let world_from_camera =
            Mat4::from_translation(Vec3::new(0.1, 0.0, 0.0)) * Mat4::from_scale(Vec3::new(1.0, -1.0, -1.0));
        let c = camera();
        let got = reproject_depth(&dv, &c, world_from_camera).unwrap();
        // The box's centre (0, 0, −1) as the camera sees it.
        let (u, v) = ((c.fx * -0.1 / 1.0 + c.cx) as usize, c.cy as usize);
        assert!((got.get(u, v) - 1.0).abs() < 1e-3, "{}", got.get(u, v));
        let near = got.data.iter().filter(|z| (**z - 1.0).abs() < 1e-3).count();
        let far = got.data.iter().filter(|z| (**z - 3.0).abs() < 1e-3).count();
        assert!(near > 1000 && far > 10 * near && near + far == got.data.iter().filter(|z| z.is_finite()).count());
    }

    #[test]
    fn bad_inputs_are_errors() {
        let mut dv = view(|_, _| 2.0, 10.0);
        let cam = Mat4::from_scale(Vec3::new(1.0, -1.0, -1.0));
        dv.ndc_depth.pop();
        assert!(matches!(reproject_depth(&dv, &camera(), cam), Err(ReprojectError::Depth(_))));
        let mut dv = view(|_, _| 2.0, 10.0);
        dv.near_m = 20.0;
        assert!(reproject_depth(&dv, &camera(), cam).is_err());
        let dv = view(|_, _| 2.0, 10.0);
        let bad = Intrinsics { fx: f32::NAN, ..camera() };
        assert!(matches!(reproject_depth(&dv, &bad, cam), Err(ReprojectError::Camera(_))));
        assert!(reproject_depth(&dv, &camera(), Mat4::from_scale(Vec3::ZERO)).is_err());
    }
}
