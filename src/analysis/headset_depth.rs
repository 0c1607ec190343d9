//! The headset's depth for one passthrough-camera frame: the newest environment-depth
//! pair (XR_META_environment_depth, read by the frame loop) reprojected into the
//! camera at the frame's exposure middle, with the camera's pose interpolated from
//! the recent camera poses (`timing::PoseTrack`). Device-free: the Android camera
//! thread feeds it poses and depth and asks it for each frame it submits.
//!
//! Depth and frame need not be simultaneous: both are placed in the same world
//! (the frame loop's LOCAL space), so a static scene reprojects exactly whatever the
//! head did in between; what moved in between is wrong by its motion — hence the age
//! limit. Of the two eye views the one nearer the camera is used (least parallax,
//! fewest disocclusion holes); holes stay NaN, which the fits skip.

use super::reproject::{reproject_depth, DepthView, Intrinsics};
use super::timing::{PoseTrack, TimedPose};
use super::DepthMap;
use crate::model::DepthUnits;
use glam::Mat4;
use std::collections::VecDeque;

/// Camera poses kept (30 Hz camera poses or 90 Hz head poses: several seconds).
const MAX_POSES: usize = 512;
/// Depth older (or newer) than this relative to the frame is not used: Quest's
/// depth runs at tens of Hz, so fresher depth is always near.
pub const MAX_AGE_NS: i64 = 250_000_000;
/// Fraction of the camera's pixels the depth must cover to be worth handing on.
pub const MIN_COVERAGE: f32 = 0.25;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum HeadsetDepthError {
    #[error("no headset depth yet")]
    NoDepth,
    #[error("the newest headset depth is {0} ms from the frame (limit {limit} ms)", limit = MAX_AGE_NS / 1_000_000)]
    TooOld(i64),
    #[error("no camera pose at the frame's time ({0} poses kept)")]
    NoPose(usize),
    #[error("reprojection: {0}")]
    Reproject(String),
    #[error("the depth covers {0:.0}% of the camera image (below {min:.0}%)", min = MIN_COVERAGE * 100.0)]
    Coverage(f32),
}

/// Recent camera poses and the newest depth pair.
pub struct HeadsetDepth {
    camera: Intrinsics,
    poses: VecDeque<TimedPose>,
    views: Option<(i64, [DepthView; 2])>,
}

impl HeadsetDepth {
    pub fn new(camera: Intrinsics) -> Self {
        Self { camera, poses: VecDeque::new(), views: None }
    }

    /// Camera poses (`world_from_camera`, OpenCV axes); ones not later than the
    /// newest kept are dropped (the track needs strictly increasing times).
    pub fn push_poses(&mut self, poses: &[TimedPose]) {
        for p in poses {
            if self.poses.back().is_some_and(|b| p.t_ns <= b.t_ns) {
                continue;
            }
            if self.poses.len() == MAX_POSES {
                self.poses.pop_front();
            }
            self.poses.push_back(*p);
        }
    }

    /// The newest depth pair, acquired at `t_ns` (XR clock).
    pub fn set_views(&mut self, t_ns: i64, views: [DepthView; 2]) {
        self.views = Some((t_ns, views));
    }

    /// Metric z-depth at the camera's pixels for a frame whose exposure middle is
    /// `t_ns` (XR clock), NaN where the depth does not reach.
    pub fn depth_at(&self, t_ns: i64) -> Result<DepthMap, HeadsetDepthError> {
        let Some((at_ns, views)) = &self.views else { return Err(HeadsetDepthError::NoDepth) };
        let age_ns = (t_ns - at_ns).abs();
        if age_ns > MAX_AGE_NS {
            return Err(HeadsetDepthError::TooOld(age_ns / 1_000_000));
        }
        // The poses around the frame (a track of the last few suffices and keeps
        // this cheap).
        let n = self.poses.len();
        let recent: Vec<TimedPose> = self.poses.iter().skip(n.saturating_sub(64)).copied().collect();
        let pose = PoseTrack::new(recent).ok().and_then(|t| t.at(t_ns)).ok_or(HeadsetDepthError::NoPose(n))?;
        let world_from_camera = Mat4::from_rotation_translation(pose.orientation, pose.position_m);
        let nearest = views
            .iter()
            .min_by(|a, b| {
                let d = |v: &DepthView| v.world_from_view.w_axis.truncate().distance(pose.position_m);
                d(a).total_cmp(&d(b))
            })
            .ok_or(HeadsetDepthError::NoDepth)?;
        let depth = reproject_depth(nearest, &self.camera, world_from_camera)
            .map_err(|e| HeadsetDepthError::Reproject(e.to_string()))?;
        let covered = depth.data.iter().filter(|z| z.is_finite()).count() as f32 / depth.data.len().max(1) as f32;
        if covered < MIN_COVERAGE {
            return Err(HeadsetDepthError::Coverage(covered * 100.0));
        }
        Ok(DepthMap { depth, units: DepthUnits::MetricM })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};

    /// A depth view of a fronto-parallel wall `wall_m` ahead (−z), seen from `x_m`.
    fn wall_view(x_m: f32, wall_m: f32) -> DepthView {
        let (w, h, near) = (64, 64, 0.1);
        DepthView {
            width: w,
            height: h,
            ndc_depth: vec![1.0 - near / wall_m; w * h],
            near_m: near,
            far_m: f32::INFINITY,
            fov_tan: [-1.0, 1.0, 1.0, -1.0],
            world_from_view: Mat4::from_translation(Vec3::new(x_m, 0.0, 0.0)),
        }
    }

    /// A camera looking down −z (OpenCV: y and z flipped) at x = `x_m`, time `t_ns`.
    fn pose(t_ns: i64, x_m: f32) -> TimedPose {
        TimedPose {
            t_ns,
            position_m: Vec3::new(x_m, 0.0, 0.0),
            orientation: Quat::from_rotation_x(std::f32::consts::PI),
        }
    }

    fn camera() -> Intrinsics {
        Intrinsics { fx: 100.0, fy: 100.0, cx: 80.0, cy: 60.0, width: 160, height: 120 }
    }

    /// The camera moves along x while the depth was taken at one instant: the wall
    /// (2 m) reads 2 m at the frame's interpolated pose (tolerance 1e-3 m: f32
    /// reprojection of an exact NDC value).
    #[test]
    fn wall_depth_at_an_interpolated_pose() {
        let mut hd = HeadsetDepth::new(camera());
        assert_eq!(hd.depth_at(0).unwrap_err(), HeadsetDepthError::NoDepth);
        hd.set_views(1_000_000_000, [wall_view(-0.03, 2.0), wall_view(0.03, 2.0)]);
        assert!(matches!(hd.depth_at(1_000_000_000), Err(HeadsetDepthError::NoPose(0))));
        let poses: Vec<TimedPose> = (0..10).map(|k| pose(900_000_000 + k * 33_000_000, 0.01 * k as f32)).collect();
        hd.push_poses(&poses);
        // Repeated and older poses are ignored, not an error.
        hd.push_poses(&poses[..3]);
        let d = hd.depth_at(1_050_000_000).unwrap();
        assert_eq!(d.units, DepthUnits::MetricM);
        let finite: Vec<f32> = d.depth.data.iter().copied().filter(|z| z.is_finite()).collect();
        assert!(finite.len() > d.depth.data.len() * 9 / 10, "coverage {}", finite.len());
        assert!(finite.iter().all(|z| (z - 2.0).abs() < 1e-3));
        // Outside the pose track: no pose; depth too far from the frame: refused.
        assert!(matches!(hd.depth_at(1_200_000_000), Err(HeadsetDepthError::NoPose(10))));
        assert_eq!(hd.depth_at(1_251_000_000 + 1_000_000).unwrap_err(), HeadsetDepthError::TooOld(252));
    }

    /// Depth behind the camera (it looks away from the wall) covers nothing: an error,
    /// not an all-NaN map.
    #[test]
    fn depth_out_of_view_is_refused() {
        let mut hd = HeadsetDepth::new(camera());
        hd.set_views(0, [wall_view(0.0, 2.0), wall_view(0.0, 2.0)]);
        let away = |t| TimedPose { t_ns: t, position_m: Vec3::ZERO, orientation: Quat::IDENTITY };
        hd.push_poses(&[away(-10), away(10)]);
        assert!(matches!(hd.depth_at(0), Err(HeadsetDepthError::Coverage(_))));
    }
}
