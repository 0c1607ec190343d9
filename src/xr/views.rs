//! OpenXR views → the render core's pinhole eyes. The render core draws square
//! pixels (one focal length); an OpenXR field of view need not give square pixels
//! at the recommended image size, so the eye keeps the horizontal field of view
//! and the top edge, and the layer submits the field of view it actually rendered
//! (the bottom angle recomputed): the compositor then maps every pixel to its true
//! direction (OpenXR spec 10.5.2, XrCompositionLayerProjectionView.fov "is the
//! field of view used to render the image").

use crate::render::Eye;
use glam::{Mat4, Quat, Vec3};

/// A view's pose (`local_from_view`: OpenXR view space is x right, y up, −z
/// forward, the render core's view space too) and angles (rad; left and down
/// negative), as located for one display time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub orientation: Quat,
    pub position_m: Vec3,
    /// (left, right, up, down), radians.
    pub fov_rad: [f32; 4],
}

/// Why a located view cannot be rendered.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ViewError {
    #[error("view pose is not finite or its orientation is not a unit quaternion ({0})")]
    Pose(String),
    #[error("field of view {0:?} is not finite or not left < right, down < up within ±89°")]
    Fov([f32; 4]),
}

const MAX_ANGLE_RAD: f32 = 89.0 * std::f32::consts::PI / 180.0;

/// The eye the render core draws for `view` into a `width × height` image, and
/// the field of view to submit with it (left, right, up, down).
pub fn eye_from_view(view: &View, width: u32, height: u32) -> Result<(Eye, [f32; 4]), ViewError> {
    let q = view.orientation;
    if !q.is_finite() || !view.position_m.is_finite() || (q.length() - 1.0).abs() > 1e-3 {
        return Err(ViewError::Pose(format!("q = {q:?}, p = {:?}", view.position_m)));
    }
    let [l, r, u, d] = view.fov_rad;
    let ok = view.fov_rad.iter().all(|a| a.is_finite() && a.abs() < MAX_ANGLE_RAD) && l < r && d < u;
    if !ok {
        return Err(ViewError::Fov(view.fov_rad));
    }
    let (tl, tr, tu) = (l.tan(), r.tan(), u.tan());
    let focal_px = width as f32 / (tr - tl);
    // Pixel rows run down from the top edge, which sits at tan(up).
    let centre_px = [-tl * focal_px, tu * focal_px];
    let down = (-(height as f32 - centre_px[1]) / focal_px).atan();
    let world_from_view = Mat4::from_rotation_translation(q.normalize(), view.position_m);
    let eye = Eye { focal_px, centre_px, view_from_world: world_from_view.inverse() };
    Ok((eye, [l, r, u, down]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::gbuffer::clip_from_view;

    /// A direction at the submitted field of view's corners lands on the image's
    /// corners (tolerance 1e-3 px: f32 trigonometry on ~1000 px).
    #[test]
    fn submitted_fov_maps_image_corners() {
        let view = View { orientation: Quat::IDENTITY, position_m: Vec3::ZERO, fov_rad: [-0.94, 0.70, 0.77, -0.87] };
        let (w, h) = (1680, 1760);
        let (eye, fov) = eye_from_view(&view, w, h).unwrap();
        let m = clip_from_view(eye.focal_px, eye.centre_px, w, h, 0.05, 100.0);
        for (tx, ty, px, py) in
            [(fov[0].tan(), fov[2].tan(), 0.0, 0.0), (fov[1].tan(), fov[3].tan(), w as f32, h as f32)]
        {
            let c = m * glam::Vec4::new(tx, ty, -1.0, 1.0);
            let (x, y) = ((c.x / c.w + 1.0) * 0.5 * w as f32, (c.y / c.w + 1.0) * 0.5 * h as f32);
            assert!((x - px).abs() < 1e-3 && (y - py).abs() < 1e-3, "({x}, {y}) vs ({px}, {py})");
        }
        // Left, right and up are kept; only the bottom is recomputed.
        assert_eq!(&fov[..3], &view.fov_rad[..3]);
    }

    #[test]
    fn view_pose_becomes_view_from_world() {
        let q = Quat::from_rotation_y(0.3);
        let p = Vec3::new(0.1, 1.6, -0.2);
        let view = View { orientation: q, position_m: p, fov_rad: [-0.8, 0.8, 0.8, -0.8] };
        let (eye, _) = eye_from_view(&view, 100, 100).unwrap();
        // The eye's own position maps to the view-space origin; its forward to −z.
        assert!((eye.view_from_world.transform_point3(p)).length() < 1e-6);
        let ahead = eye.view_from_world.transform_point3(p + q * Vec3::new(0.0, 0.0, -1.0));
        assert!((ahead - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-5);
    }

    #[test]
    fn bad_views_are_refused() {
        let good = View { orientation: Quat::IDENTITY, position_m: Vec3::ZERO, fov_rad: [-0.8, 0.8, 0.8, -0.8] };
        let cases = [
            View { orientation: Quat::from_xyzw(0.0, 0.0, 0.0, 0.5), ..good },
            View { position_m: Vec3::new(f32::NAN, 0.0, 0.0), ..good },
            View { fov_rad: [0.8, -0.8, 0.8, -0.8], ..good },
            View { fov_rad: [-1.6, 0.8, 0.8, -0.8], ..good },
            View { fov_rad: [-0.8, 0.8, f32::INFINITY, -0.8], ..good },
        ];
        for v in cases {
            assert!(eye_from_view(&v, 64, 64).is_err(), "{v:?}");
        }
    }
}
