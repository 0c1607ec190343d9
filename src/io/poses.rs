//! `poses.csv` of a recorded sequence: header `frame,t_s,tx,ty,tz,qx,qy,qz,qw`, one
//! row per frame, `world_from_camera` with the camera in OpenCV axes (x right,
//! y down, z forward), metres and seconds; `t_s` is the middle of the frame's
//! exposure. Missing fields, non-finite values, non-unit quaternions, repeated or
//! decreasing times are errors naming the row.

use super::{fmt_err, IoError};
use crate::analysis::timing::TimedPose;
use glam::{Quat, Vec3};
use std::path::Path;

pub const POSES_HEADER: &str = "frame,t_s,tx,ty,tz,qx,qy,qz,qw";

/// One row: the frame number it belongs to and the pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseRow {
    pub frame: u64,
    pub t_s: f64,
    pub pose: TimedPose,
}

/// `t_s,tx,ty,tz,qx,qy,qz,qw` of one row (both files' columns after the frame):
/// finite numbers and a unit quaternion, else an error starting with `at`.
fn parse_pose(fields: &[&str], at: &str) -> Result<(f64, TimedPose), String> {
    let mut v = [0f64; 8];
    for (k, f) in fields.iter().enumerate() {
        let x: f64 = f.parse().map_err(|_| format!("{at}: `{f}` is not a number"))?;
        if !x.is_finite() {
            return Err(format!("{at}: non-finite value `{f}`"));
        }
        v[k] = x;
    }
    let q = Quat::from_xyzw(v[4] as f32, v[5] as f32, v[6] as f32, v[7] as f32);
    let len = q.length();
    if (len - 1.0).abs() > 1e-3 {
        return Err(format!("{at}: quaternion of length {len:.5}, not a unit quaternion"));
    }
    let pose = TimedPose {
        t_ns: (v[0] * 1e9).round() as i64,
        position_m: Vec3::new(v[1] as f32, v[2] as f32, v[3] as f32),
        orientation: q.normalize(),
    };
    Ok((v[0], pose))
}

pub fn read_poses_csv(path: &Path) -> Result<Vec<PoseRow>, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::Io { path: path.to_path_buf(), source })?;
    parse_poses_csv(&text).map_err(|problem| fmt_err(path, problem))
}

pub fn parse_poses_csv(text: &str) -> Result<Vec<PoseRow>, String> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let header = lines.next().map(|(_, l)| l.trim().replace(' ', "")).unwrap_or_default();
    if header != POSES_HEADER {
        return Err(format!("header must be `{POSES_HEADER}`, found `{header}`"));
    }
    let mut rows: Vec<PoseRow> = vec![];
    for (n, line) in lines {
        let row = n + 1; // 1-based line number
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != 9 {
            return Err(format!("line {row}: {} fields, 9 expected", fields.len()));
        }
        let frame: u64 =
            fields[0].parse().map_err(|_| format!("line {row}: frame `{}` is not a whole number", fields[0]))?;
        let (t_s, pose) = parse_pose(&fields[1..], &format!("line {row} (frame {frame})"))?;
        if let Some(prev) = rows.last() {
            if t_s <= prev.t_s {
                return Err(format!(
                    "line {row} (frame {frame}): t_s {t_s} is not later than the previous row's {}",
                    prev.t_s
                ));
            }
            if frame <= prev.frame {
                return Err(format!("line {row}: frame {frame} does not follow frame {}", prev.frame));
            }
        }
        rows.push(PoseRow { frame, t_s, pose });
    }
    if rows.is_empty() {
        return Err("no pose rows".into());
    }
    Ok(rows)
}

/// Header of `pose_track.csv`: every pose a recording's worker received, keyed by
/// time alone (a headset tracks the head at its display rate, not per frame).
pub const POSE_TRACK_HEADER: &str = "t_s,tx,ty,tz,qx,qy,qz,qw";

pub fn read_pose_track_csv(path: &Path) -> Result<Vec<TimedPose>, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::Io { path: path.to_path_buf(), source })?;
    parse_pose_track_csv(&text).map_err(|problem| fmt_err(path, problem))
}

/// `pose_track.csv`: rows as in `poses.csv` without the frame column; the same
/// checks (finite values, unit quaternions, increasing times), each error naming
/// the line.
pub fn parse_pose_track_csv(text: &str) -> Result<Vec<TimedPose>, String> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let header = lines.next().map(|(_, l)| l.trim().replace(' ', "")).unwrap_or_default();
    if header != POSE_TRACK_HEADER {
        return Err(format!("header must be `{POSE_TRACK_HEADER}`, found `{header}`"));
    }
    let mut out: Vec<TimedPose> = vec![];
    for (n, line) in lines {
        let row = n + 1;
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != 8 {
            return Err(format!("line {row}: {} fields, 8 expected", fields.len()));
        }
        let (t_s, pose) = parse_pose(&fields, &format!("line {row}"))?;
        if out.last().is_some_and(|prev| pose.t_ns <= prev.t_ns) {
            return Err(format!("line {row}: t_s {t_s} is not later than the previous row's"));
        }
        out.push(pose);
    }
    if out.is_empty() {
        return Err("no pose rows".into());
    }
    Ok(out)
}

/// The CSV text of a pose track.
pub fn format_pose_track_csv(poses: &[TimedPose]) -> String {
    let mut s = format!("{POSE_TRACK_HEADER}\n");
    for p in poses {
        let (t, q) = (p.position_m, p.orientation);
        s += &format!("{:.9},{},{},{},{},{},{},{}\n", p.t_ns as f64 * 1e-9, t.x, t.y, t.z, q.x, q.y, q.z, q.w);
    }
    s
}

/// The CSV text of `rows` (what `synth-video` writes).
pub fn format_poses_csv(rows: &[PoseRow]) -> String {
    let mut s = format!("{POSES_HEADER}\n");
    for r in rows {
        let (p, q) = (r.pose.position_m, r.pose.orientation);
        s += &format!("{},{:.9},{},{},{},{},{},{},{}\n", r.frame, r.t_s, p.x, p.y, p.z, q.x, q.y, q.z, q.w);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_track_round_trips_and_bad_rows_are_named() {
        let track: Vec<TimedPose> = (0..3)
            .map(|k| TimedPose {
                t_ns: 1_000_000_000 + k * 13_888_889,
                position_m: Vec3::new(k as f32 * 0.25, -0.5, 2.0),
                orientation: Quat::from_rotation_y(0.1 * k as f32),
            })
            .collect();
        let back = parse_pose_track_csv(&format_pose_track_csv(&track)).unwrap();
        assert_eq!(back.len(), 3);
        for (a, b) in track.iter().zip(&back) {
            assert_eq!(a.t_ns, b.t_ns);
            assert!((a.position_m - b.position_m).length() < 1e-6 && a.orientation.dot(b.orientation) > 1.0 - 1e-6);
        }
        let e = parse_pose_track_csv("t_s,tx,ty,tz,qx,qy,qz,qw\n0.5,0,0,0,0,0,0,1\n0.4,0,0,0,0,0,0,1\n").unwrap_err();
        assert!(e.contains("line 3") && e.contains("not later"), "{e}");
        let e = parse_pose_track_csv("t_s,tx,ty,tz,qx,qy,qz,qw\n0.5,0,0,0,0,0,0,2\n").unwrap_err();
        assert!(e.contains("line 2") && e.contains("unit quaternion"), "{e}");
        assert!(parse_pose_track_csv(POSES_HEADER).unwrap_err().contains("header"));
    }

    #[test]
    fn rows_round_trip_and_bad_rows_are_named() {
        let rows = vec![
            PoseRow {
                frame: 0,
                t_s: 0.0,
                pose: TimedPose { t_ns: 0, position_m: Vec3::ZERO, orientation: Quat::IDENTITY },
            },
            PoseRow {
                frame: 1,
                t_s: 1.0 / 30.0,
                pose: TimedPose {
                    t_ns: 33_333_333,
                    position_m: Vec3::new(0.01, 0.0, 0.0),
                    orientation: Quat::from_rotation_y(0.01),
                },
            },
        ];
        let back = parse_poses_csv(&format_poses_csv(&rows)).expect("round trip");
        assert_eq!(back.len(), 2);
        assert!((back[1].pose.orientation.dot(rows[1].pose.orientation) - 1.0).abs() < 1e-6);
        let e = parse_poses_csv("frame,t_s,tx,ty,tz,qx,qy,qz,qw\n0,0,0,0,0,0,0,0,2\n").unwrap_err();
        assert!(e.contains("line 2") && e.contains("not a unit quaternion"), "{e}");
        let e = parse_poses_csv("frame,t_s,tx,ty,tz,qx,qy,qz,qw\n0,0,0,0,NaN,0,0,0,1\n").unwrap_err();
        assert!(e.contains("line 2") && e.contains("non-finite"), "{e}");
        let e = parse_poses_csv("frame,t_s,tx,ty,tz,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n").unwrap_err();
        assert!(e.contains("8 fields"), "{e}");
        let e = parse_poses_csv("frame,t,tx\n").unwrap_err();
        assert!(e.contains("header"), "{e}");
    }
}
