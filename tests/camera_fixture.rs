//! The Quest passthrough camera's metadata as Meta documents it
//! (`tests/data/quest3_camera/characteristics.json`: vendor keys as 1-byte arrays,
//! a non-passthrough camera listed first, a non-identity lens pose, a
//! pre-correction array unlike the active array, capture results after their
//! images) read through the device's own decisions: `CameraDescription` and
//! `VendorValue` as JNI and the NDK fill them, `choose_camera`, `CapturePairing`
//! and `FrameAssembler`. The expected values are derived here from the Android and
//! Meta definitions, not from the code under test.

use blind_augment::analysis::camera::{
    choose_camera, CameraDescription, CameraError, CameraSide, CapturePairing, CaptureResult, FrameAssembler,
    VendorValue, PASSTHROUGH_SIZE,
};
use blind_augment::analysis::timing::TimestampSource;
use blind_augment::image::yuv::{Yuv420, YuvMatrix, YuvPlane, YuvRange};
use glam::{Mat3, Quat, Vec3};
use serde::Deserialize;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Fixture {
    #[allow(dead_code)] // read by people: where the values come from
    about: Vec<String>,
    cameras: Vec<CameraDescription>,
    captures: Vec<Capture>,
}

/// What reached the app, in the order it arrived.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
enum Capture {
    /// An image and its `AImage_getTimestamp` (= SENSOR_TIMESTAMP).
    Image(i64),
    Result(CaptureResult),
}

fn fixture() -> Fixture {
    serde_json::from_str(include_str!("data/quest3_camera/characteristics.json")).expect("the fixture parses")
}

fn camera<'a>(f: &'a Fixture, id: &str) -> &'a CameraDescription {
    f.cameras.iter().find(|c| c.id == id).expect("the fixture lists the camera")
}

/// Camera 1 carries position 0 but source 1 (not passthrough) and comes first;
/// camera 0 has no vendor keys: the left passthrough camera is 50, the right 51,
/// with nothing to note. Read as `Integer`, the 1-byte keys would be absent: no
/// passthrough camera at all.
#[test]
fn chooses_the_passthrough_cameras_by_their_byte_array_keys() {
    let f = fixture();
    assert_eq!(camera(&f, "50").meta_position, Some(VendorValue::Bytes(vec![0])));
    let left = choose_camera(&f.cameras, CameraSide::Left, PASSTHROUGH_SIZE).unwrap();
    assert_eq!((left.id.as_str(), left.side, left.size), ("50", CameraSide::Left, (1280, 960)));
    assert!(left.notes.is_empty(), "{:?}", left.notes);
    assert_eq!(left.timestamp_source, TimestampSource::Realtime);
    let right = choose_camera(&f.cameras, CameraSide::Right, PASSTHROUGH_SIZE).unwrap();
    assert_eq!((right.id.as_str(), right.side), ("51", CameraSide::Right));
    let unread: Vec<CameraDescription> =
        f.cameras.iter().map(|c| CameraDescription { meta_position: None, meta_source: None, ..c.clone() }).collect();
    assert!(matches!(choose_camera(&unread, CameraSide::Left, PASSTHROUGH_SIZE), Err(CameraError::NoPassthrough(_))));
}

/// LENS_INTRINSIC_CALIBRATION is in pre-correction array pixels (AOSP
/// `CameraCharacteristics.java`): 1280×960 is rows 160..1120 of the 1280×1280
/// pre-correction array, unscaled — not a crop of the 1264×1264 active array.
#[test]
fn intrinsics_are_scaled_from_the_pre_correction_array() {
    let f = fixture();
    let k = choose_camera(&f.cameras, CameraSide::Left, PASSTHROUGH_SIZE).unwrap().intrinsics.unwrap();
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (866.2, 866.2, 632.5, 646.0 - 160.0));
    assert_eq!((k.width, k.height), (1280, 960));
}

/// Android: p_camera = R (p_sensor − t), R from LENS_POSE_ROTATION, camera axes x
/// right, y down, z the optical axis. So the optical axis in the head (= sensor)
/// frame is Rᵀ ẑ, and a head point on it projects to the principal point. The
/// fixture's left camera looks down and to the left, its right one down and to
/// the right.
#[test]
fn the_lens_pose_puts_the_optical_axis_on_the_principal_point() {
    let f = fixture();
    for (side, id, leftward) in [(CameraSide::Left, "50", true), (CameraSide::Right, "51", false)] {
        let d = camera(&f, id);
        let q = Quat::from_array(d.lens_pose_rotation.unwrap());
        let t = Vec3::from_array(d.lens_pose_translation_m.unwrap());
        let r = Mat3::from_quat(q);
        let axis = r.transpose() * Vec3::Z;
        assert!(axis.z < -0.97 && axis.y < -0.17 && (axis.x < 0.0) == leftward, "camera {id}: {axis}");
        let c = choose_camera(&f.cameras, side, PASSTHROUGH_SIZE).unwrap();
        let k = c.intrinsics.unwrap();
        let camera_from_head = c.head_from_camera.unwrap().inverse();
        let project = |p: Vec3| {
            let v = camera_from_head.transform_point3(p);
            // The definition itself gives the same camera coordinates.
            assert!((v - r * (p - t)).length() < 1e-5, "camera {id}: {v} vs {}", r * (p - t));
            (k.fx * v.x / v.z + k.cx, k.fy * v.y / v.z + k.cy)
        };
        let (u, v) = project(t + 1.5 * axis);
        assert!((u - k.cx).abs() < 1e-2 && (v - k.cy).abs() < 1e-2, "camera {id}: ({u}, {v})");
        // Up in the head is up in the image.
        assert!(project(t + 1.5 * axis + 0.1 * Vec3::Y).1 < k.cy - 10.0);
    }
}

/// The fixture's results come after their images (one before, one never): every
/// image is handed on with its own result, so each frame is timed at its
/// exposure's middle (SENSOR_TIMESTAMP is the first row's exposure start: + half
/// the rolling-shutter skew + half the exposure), never at its start; the image
/// whose result never came is dropped, the last one still waits.
#[test]
fn frames_are_timed_with_results_that_come_after_their_images() {
    let f = fixture();
    let (y, uv) = (vec![128u8; 8 * 4], vec![128u8; 8 * 2]);
    let img = Yuv420 {
        width: 8,
        height: 4,
        y: YuvPlane { data: &y, row_stride: 8, pixel_stride: 1 },
        u: YuvPlane { data: &uv, row_stride: 8, pixel_stride: 2 },
        v: YuvPlane { data: &uv[1..], row_stride: 8, pixel_stride: 2 },
    };
    let mut pairing = CapturePairing::default();
    let mut assembler = FrameAssembler::new(YuvMatrix::Bt601, YuvRange::Full, TimestampSource::Realtime);
    let mut timed = vec![];
    for c in &f.captures {
        let ready = match c {
            Capture::Image(t) => pairing.image(*t, ()),
            Capture::Result(r) => {
                pairing.result(*r);
                vec![]
            }
        };
        for p in ready {
            let a = assembler.assemble(&img, p.sensor_timestamp_ns, &p.result).unwrap();
            assert!(a.exposure_known);
            timed.push((p.sensor_timestamp_ns, a.frame.t_s));
        }
    }
    // From the fixture: exposures 4, 6, 8, (lost), 10 ms; skew 12 ms.
    let t0 = 5_000_000_000_000i64;
    let expected = [
        (t0, t0 + 6_000_000 + 2_000_000),
        (t0 + 33_333_333, t0 + 33_333_333 + 6_000_000 + 3_000_000),
        (t0 + 66_666_666, t0 + 66_666_666 + 6_000_000 + 4_000_000),
        (t0 + 133_333_333, t0 + 133_333_333 + 6_000_000 + 5_000_000),
    ];
    assert_eq!(timed.len(), expected.len(), "{timed:?}");
    for ((ts, t_s), (ets, middle_ns)) in timed.iter().zip(expected) {
        assert_eq!(*ts, ets);
        assert!((t_s - middle_ns as f64 * 1e-9).abs() < 1e-9, "{ts}: {t_s} s, expected {middle_ns} ns");
    }
    assert_eq!((pairing.dropped(), pairing.held()), (1, 1));
}
