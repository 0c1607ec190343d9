//! Camera frame timing against the headset's clock: Android's SENSOR_TIMESTAMP
//! (CLOCK_BOOTTIME when SENSOR_INFO_TIMESTAMP_SOURCE is REALTIME, else an
//! unspecified clock) mapped to XrTime through CLOCK_MONOTONIC, which
//! XR_KHR_convert_timespec_time converts; the middle of a frame's exposure; and
//! the head pose at any time by smooth interpolation of timestamped poses (a
//! straight average of the neighbouring poses biases the motion inside an
//! exposure, hence the estimated λ). Plain numbers here (ns as i64): the platform
//! code reads the clocks and calls the runtime.

use glam::{Quat, Vec3};

/// Which clock SENSOR_TIMESTAMP counts (ACAMERA_SENSOR_INFO_TIMESTAMP_SOURCE).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimestampSource {
    /// CLOCK_BOOTTIME (comparable with other sensors and the runtime).
    Realtime,
    /// Unknown: only differences between frames are meaningful.
    Unknown,
}

/// One reading of the clocks: CLOCK_MONOTONIC just before and just after asking
/// the runtime for the XrTime of `monotonic_ns` (xrConvertTimespecTimeToTimeKHR),
/// and CLOCK_BOOTTIME read between them.
#[derive(Clone, Copy, Debug)]
pub struct ClockSample {
    pub monotonic_before_ns: i64,
    pub monotonic_after_ns: i64,
    pub boottime_ns: i64,
    /// XrTime of `monotonic_before_ns`.
    pub xr_time_ns: i64,
}

/// Affine map from camera timestamps to XrTime (slope 1: all three clocks tick
/// in SI nanoseconds; suspend is excluded by keeping the map fresh).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockMap {
    pub xr_minus_monotonic_ns: i64,
    pub boottime_minus_monotonic_ns: i64,
    /// How uncertain the boottime offset is: the tightest sample's read window.
    pub uncertainty_ns: i64,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TimingError {
    #[error("no clock samples")]
    NoSamples,
    #[error("clock sample {0}: the monotonic clock went backwards")]
    Backwards(usize),
    #[error("the camera's timestamp source is unknown: its frames cannot be placed on the headset's clock")]
    UnknownSource,
    #[error("pose track: {0}")]
    Poses(String),
}

impl ClockMap {
    /// From samples: the one read in the shortest window wins (the thread was
    /// least likely preempted between the clock reads).
    pub fn from_samples(samples: &[ClockSample]) -> Result<Self, TimingError> {
        let mut best: Option<(i64, &ClockSample)> = None;
        for (i, s) in samples.iter().enumerate() {
            let window = s.monotonic_after_ns - s.monotonic_before_ns;
            if window < 0 {
                return Err(TimingError::Backwards(i));
            }
            match best {
                Some((w, _)) if w <= window => {}
                _ => best = Some((window, s)),
            }
        }
        let (window, s) = best.ok_or(TimingError::NoSamples)?;
        Ok(Self {
            xr_minus_monotonic_ns: s.xr_time_ns - s.monotonic_before_ns,
            // BOOTTIME was read somewhere inside the window: its middle is the estimate.
            boottime_minus_monotonic_ns: s.boottime_ns - (s.monotonic_before_ns + window / 2),
            uncertainty_ns: window / 2,
        })
    }

    /// XrTime of a camera timestamp.
    pub fn xr_time_ns(&self, sensor_timestamp_ns: i64, source: TimestampSource) -> Result<i64, TimingError> {
        match source {
            TimestampSource::Realtime => {
                Ok(sensor_timestamp_ns - self.boottime_minus_monotonic_ns + self.xr_minus_monotonic_ns)
            }
            TimestampSource::Unknown => Err(TimingError::UnknownSource),
        }
    }
}

/// The middle of a frame's exposure: SENSOR_TIMESTAMP is the start of the first
/// row's exposure; a rolling shutter starts the last row `rolling_skew_ns` later,
/// so the frame's centre row is exposed around start + skew/2 + exposure/2.
pub fn exposure_middle_ns(sensor_timestamp_ns: i64, exposure_ns: i64, rolling_skew_ns: i64) -> i64 {
    sensor_timestamp_ns + rolling_skew_ns.max(0) / 2 + exposure_ns.max(0) / 2
}

/// A head (or camera) pose at a time: `world_from_x`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedPose {
    pub t_ns: i64,
    pub position_m: Vec3,
    pub orientation: Quat,
}

/// Poses sorted by time, interpolated smoothly: centripetal-free uniform
/// Catmull–Rom (cubic Hermite with central-difference tangents, scaled for uneven
/// spacing) for position, slerp for orientation.
#[derive(Clone, Debug)]
pub struct PoseTrack {
    poses: Vec<TimedPose>,
}

impl PoseTrack {
    /// Poses must be finite, strictly increasing in time, with unit quaternions.
    pub fn new(poses: Vec<TimedPose>) -> Result<Self, TimingError> {
        for (i, p) in poses.iter().enumerate() {
            if !p.position_m.is_finite() || !p.orientation.is_finite() || (p.orientation.length() - 1.0).abs() > 1e-3 {
                return Err(TimingError::Poses(format!("pose {i} is not finite or not a unit quaternion")));
            }
            if i > 0 && p.t_ns <= poses[i - 1].t_ns {
                return Err(TimingError::Poses(format!("pose {i} is not later than pose {}", i - 1)));
            }
        }
        if poses.len() < 2 {
            return Err(TimingError::Poses(format!("{} poses: at least 2 are needed", poses.len())));
        }
        Ok(Self { poses })
    }

    /// The pose at `t_ns`, or None outside the track (never extrapolated).
    pub fn at(&self, t_ns: i64) -> Option<TimedPose> {
        let p = &self.poses;
        if t_ns < p[0].t_ns || t_ns > p[p.len() - 1].t_ns {
            return None;
        }
        let i = p.partition_point(|q| q.t_ns <= t_ns).clamp(1, p.len() - 1) - 1;
        let (a, b) = (&p[i], &p[i + 1]);
        let dt = (b.t_ns - a.t_ns) as f64;
        let s = ((t_ns - a.t_ns) as f64 / dt) as f32;
        // Tangents (m per segment) from the neighbours, one-sided at the ends.
        let tangent = |k: usize| -> Vec3 {
            let (l, r) = (k.saturating_sub(1), (k + 1).min(p.len() - 1));
            let span = (p[r].t_ns - p[l].t_ns) as f64;
            (p[r].position_m - p[l].position_m) * (dt / span) as f32
        };
        let (m0, m1) = (tangent(i), tangent(i + 1));
        let (s2, s3) = (s * s, s * s * s);
        let position_m = a.position_m * (2.0 * s3 - 3.0 * s2 + 1.0)
            + m0 * (s3 - 2.0 * s2 + s)
            + b.position_m * (-2.0 * s3 + 3.0 * s2)
            + m1 * (s3 - s2);
        Some(TimedPose { t_ns, position_m, orientation: a.orientation.slerp(b.orientation, s).normalize() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_map_takes_the_tightest_sample() {
        // True offsets: XrTime = monotonic + 5 ms; boottime = monotonic + 2 s.
        let sample = |before: i64, window: i64| ClockSample {
            monotonic_before_ns: before,
            monotonic_after_ns: before + window,
            boottime_ns: before + window / 2 + 2_000_000_000,
            xr_time_ns: before + 5_000_000,
        };
        let m = ClockMap::from_samples(&[sample(1_000, 80_000), sample(9_000_000, 2_000), sample(20_000_000, 50_000)])
            .unwrap();
        assert_eq!(m.xr_minus_monotonic_ns, 5_000_000);
        assert_eq!(m.boottime_minus_monotonic_ns, 2_000_000_000);
        assert_eq!(m.uncertainty_ns, 1_000);
        // A frame stamped at boottime 3 s is at monotonic 1 s, XrTime 1.005 s.
        assert_eq!(m.xr_time_ns(3_000_000_000, TimestampSource::Realtime), Ok(1_005_000_000));
        assert_eq!(m.xr_time_ns(3_000_000_000, TimestampSource::Unknown), Err(TimingError::UnknownSource));
        assert_eq!(ClockMap::from_samples(&[]), Err(TimingError::NoSamples));
        let mut bad = sample(0, 10);
        bad.monotonic_after_ns = -5;
        assert_eq!(ClockMap::from_samples(&[bad]), Err(TimingError::Backwards(0)));
    }

    #[test]
    fn exposure_middle() {
        assert_eq!(exposure_middle_ns(1_000_000, 8_000_000, 10_000_000), 10_000_000);
        assert_eq!(exposure_middle_ns(1_000, -5, -7), 1_000);
    }

    /// On a smooth head path (sinusoidal sway sampled at 30 Hz, like tracking
    /// poses), the track's position between samples is far closer to the truth than
    /// the straight average of the neighbours; orientation follows slerp.
    #[test]
    fn pose_track_interpolates_smoothly() {
        let truth = |t: f64| Vec3::new((0.04 * (std::f64::consts::TAU * 0.5 * t).sin()) as f32, 0.0, 0.0);
        let poses: Vec<TimedPose> = (0..60)
            .map(|k| {
                let t = k as f64 / 30.0;
                TimedPose {
                    t_ns: (t * 1e9) as i64,
                    position_m: truth(t),
                    orientation: Quat::from_rotation_y(0.05 * t as f32),
                }
            })
            .collect();
        let track = PoseTrack::new(poses.clone()).unwrap();
        let (mut err_track, mut err_avg) = (0.0f32, 0.0f32);
        for k in 5..50 {
            let t = (k as f64 + 0.5) / 30.0;
            let p = track.at((t * 1e9) as i64).unwrap();
            err_track = err_track.max((p.position_m - truth(t)).length());
            err_avg = err_avg.max(((poses[k].position_m + poses[k + 1].position_m) * 0.5 - truth(t)).length());
            let want_q = Quat::from_rotation_y(0.05 * t as f32);
            assert!(p.orientation.angle_between(want_q) < 1e-4);
        }
        // Averaging errs by ≈ 0.04·(1 − cos(π/30))·… ≈ 0.2 mm at the sway's extremes;
        // the cubic is two orders of magnitude closer.
        assert!(err_track < 0.01 * err_avg, "track {err_track} m vs average {err_avg} m");
        assert!(track.at(-1).is_none() && track.at(poses[59].t_ns + 1).is_none(), "no extrapolation");
        assert_eq!(track.at(poses[3].t_ns).unwrap().position_m, poses[3].position_m);
    }

    #[test]
    fn bad_tracks_are_refused() {
        let p = |t: i64, q: Quat| TimedPose { t_ns: t, position_m: Vec3::ZERO, orientation: q };
        assert!(PoseTrack::new(vec![p(0, Quat::IDENTITY)]).is_err());
        assert!(PoseTrack::new(vec![p(0, Quat::IDENTITY), p(0, Quat::IDENTITY)]).is_err());
        assert!(PoseTrack::new(vec![p(0, Quat::IDENTITY), p(5, Quat::from_xyzw(0.0, 0.0, 0.0, 2.0))]).is_err());
        let nan = TimedPose { t_ns: 9, position_m: Vec3::NAN, orientation: Quat::IDENTITY };
        assert!(PoseTrack::new(vec![p(0, Quat::IDENTITY), nan]).is_err());
    }
}
