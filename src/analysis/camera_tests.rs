//! Unit tests of `analysis::camera`: camera choice, intrinsics, the lens pose, capture
//! results and frame assembly, on descriptions written as Camera2 reports them.

use super::*;
use crate::image::yuv::YuvPlane;

fn quest_like(id: &str, position: i8) -> CameraDescription {
    CameraDescription {
        id: id.into(),
        meta_position: Some(VendorValue::Bytes(vec![position])),
        meta_source: Some(VendorValue::Bytes(vec![0])),
        pre_correction_array: Some([0, 0, 1280, 1280]),
        active_array: Some([0, 0, 1280, 1280]),
        intrinsic_calibration: Some([866.0, 866.0, 640.5, 641.0, 0.0]),
        lens_pose_translation_m: Some([-0.032, -0.01, -0.04]),
        lens_pose_rotation: Some([1.0, 0.0, 0.0, 0.0]),
        lens_pose_reference: Some(1),
        yuv_sizes: vec![(320, 240), (640, 480), (800, 600), (1280, 960), (1280, 1280)],
        timestamp_realtime: true,
    }
}

#[test]
fn chooses_the_wanted_passthrough_camera() {
    let phone = CameraDescription { id: "0".into(), yuv_sizes: vec![(1280, 960)], ..Default::default() };
    let cams = [phone.clone(), quest_like("50", 0), quest_like("51", 1)];
    let c = choose_camera(&cams, CameraSide::Left, PASSTHROUGH_SIZE).unwrap();
    assert_eq!((c.id.as_str(), c.side, c.size), ("50", CameraSide::Left, (1280, 960)));
    assert!(c.notes.is_empty(), "{:?}", c.notes);
    assert_eq!(c.timestamp_source, TimestampSource::Realtime);
    let c = choose_camera(&cams, CameraSide::Right, PASSTHROUGH_SIZE).unwrap();
    assert_eq!(c.id, "51");
    // Only the right camera: taken, and said so.
    let c = choose_camera(&[phone.clone(), quest_like("51", 1)], CameraSide::Left, PASSTHROUGH_SIZE).unwrap();
    assert_eq!((c.id.as_str(), c.side), ("51", CameraSide::Right));
    assert!(c.notes[0].contains("no Left passthrough camera"), "{:?}", c.notes);
    // A non-passthrough source is not taken.
    let mut other = quest_like("52", 0);
    other.meta_source = Some(VendorValue::Bytes(vec![1]));
    let e = choose_camera(&[phone, other], CameraSide::Left, PASSTHROUGH_SIZE).unwrap_err();
    assert!(
        matches!(&e, CameraError::NoPassthrough(s) if s.contains("52 (position 0, source 1)")
            && s.contains("0 (position absent, source absent)")),
        "{e}"
    );
    assert_eq!(choose_camera(&[], CameraSide::Left, PASSTHROUGH_SIZE), Err(CameraError::NoCameras));
}

#[test]
fn falls_back_to_the_nearest_size_and_names_missing_metadata() {
    let mut cam = quest_like("50", 0);
    cam.yuv_sizes = vec![(640, 480), (1600, 1200)];
    cam.intrinsic_calibration = None;
    cam.lens_pose_rotation = None;
    cam.timestamp_realtime = false;
    let c = choose_camera(&[cam.clone()], CameraSide::Left, PASSTHROUGH_SIZE).unwrap();
    // 1280×960 has 4× the pixels of 640×480 and 0.64× those of 1600×1200.
    assert_eq!(c.size, (1600, 1200));
    assert!(c.intrinsics.is_none() && c.head_from_camera.is_none());
    assert_eq!(c.timestamp_source, TimestampSource::Unknown);
    assert_eq!(c.notes.len(), 4, "{:?}", c.notes);
    // Unusable calibration and pose: chosen all the same, both said.
    let mut bad = quest_like("50", 0);
    bad.intrinsic_calibration = Some([f32::NAN, 866.0, 640.0, 640.0, 0.0]);
    bad.lens_pose_rotation = Some([0.0, 0.0, 0.0, 3.0]);
    let c = choose_camera(&[bad], CameraSide::Left, PASSTHROUGH_SIZE).unwrap();
    assert!(c.intrinsics.is_none() && c.head_from_camera.is_none());
    assert!(c.notes.iter().any(|n| n.contains("camera 50: intrinsic calibration")), "{:?}", c.notes);
    assert!(c.notes.iter().any(|n| n.contains("camera 50: lens pose")), "{:?}", c.notes);
    cam.yuv_sizes.clear();
    assert_eq!(choose_camera(&[cam], CameraSide::Left, PASSTHROUGH_SIZE), Err(CameraError::NoYuv { id: "50".into() }));
}

/// 1280×960 from a 1280×1280 array: the rows 160..1120 are kept, unscaled; from
/// a 2560×1920 array (same aspect) everything halves. A bad calibration is an
/// error naming the camera.
#[test]
fn stream_intrinsics_crop_and_scale() {
    let k = stream_intrinsics("50", [0, 0, 1280, 1280], [866.0, 867.0, 640.5, 641.0, 0.0], (1280, 960)).unwrap();
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (866.0, 867.0, 640.5, 481.0));
    assert_eq!((k.width, k.height), (1280, 960));
    let k = stream_intrinsics("50", [0, 0, 2560, 1920], [1732.0, 1732.0, 1281.0, 961.0, 0.0], (1280, 960)).unwrap();
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (866.0, 866.0, 640.5, 480.5));
    // A tall stream from a wide array keeps the height: 960×960 from 1280×960.
    let k = stream_intrinsics("50", [0, 0, 1280, 960], [800.0, 800.0, 640.0, 480.0, 0.0], (480, 480)).unwrap();
    assert_eq!((k.fx, k.cx, k.cy), (400.0, 240.0, 240.0));
    let e = stream_intrinsics("7", [0, 0, 1280, 960], [f32::NAN, 800.0, 640.0, 480.0, 0.0], (1280, 960));
    assert!(matches!(&e, Err(CameraError::Metadata { id, .. }) if id == "7"), "{e:?}");
    assert!(stream_intrinsics("7", [0, 0, 1280, 960], [800.0, 800.0, 2000.0, 480.0, 0.0], (1280, 960)).is_err());
    assert!(stream_intrinsics("7", [0, 0, 0, 960], [800.0, 800.0, 0.0, 480.0, 0.0], (1280, 960)).is_err());
}

/// The pose chain end to end: a head at a known pose, a camera pitched 10° down
/// and offset on it; a world point on the camera's optical axis projects to the
/// principal point through the worker's convention (OpenCV `world_from_camera`),
/// one above it to a smaller row, one to the head's right to a larger column.
#[test]
fn camera_pose_chain_projects_consistently() {
    // OpenCV axes in VIEW space (x right, y down, z forward), then pitched down:
    // rotating the camera about its own x by −10° turns z (forward) downward.
    let cv = Quat::from_rotation_x(std::f32::consts::PI);
    let q = cv * Quat::from_rotation_x((-10.0f32).to_radians());
    // Android reports the rotation from the sensor frame into the camera's: q⁻¹.
    let head_from_cam = head_from_camera("50", q.inverse().to_array(), [0.03, -0.02, -0.05]).unwrap();
    let world_from_head = (Quat::from_rotation_y(0.4), Vec3::new(1.0, 1.6, -2.0));
    let pose = camera_pose(7, world_from_head, &head_from_cam);
    assert_eq!(pose.t_ns, 7);
    let world_from_camera = Mat4::from_rotation_translation(pose.orientation, pose.position_m);
    let camera_from_world = world_from_camera.inverse();
    let k = Intrinsics { fx: 800.0, fy: 800.0, cx: 640.0, cy: 480.0, width: 1280, height: 960 };
    let project = |p: Vec3| {
        let c = camera_from_world.transform_point3(p);
        assert!(c.z > 0.0, "in front of the camera");
        (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy)
    };
    let world_head = Mat4::from_rotation_translation(world_from_head.0, world_from_head.1);
    let axis = world_from_camera.transform_vector3(Vec3::Z);
    // The optical axis points forward (VIEW −z) and 10° down, in head terms.
    let axis_head = world_head.inverse().transform_vector3(axis);
    assert!((axis_head.y - (-(10.0f32).to_radians().sin())).abs() < 1e-5, "{axis_head}");
    assert!(axis_head.z < -0.98, "{axis_head}");
    let (u, v) = project(pose.position_m + 2.0 * axis);
    assert!((u - 640.0).abs() < 1e-2 && (v - 480.0).abs() < 1e-2, "({u}, {v})");
    let up = world_head.transform_vector3(Vec3::Y) * 0.2;
    let right = world_head.transform_vector3(Vec3::X) * 0.2;
    assert!(project(pose.position_m + 2.0 * axis + up).1 < 470.0);
    assert!(project(pose.position_m + 2.0 * axis + right).0 > 650.0);
    // Unknown lens pose: looking straight ahead from the head's origin.
    let ahead = camera_pose(0, (Quat::IDENTITY, Vec3::ZERO), &forward_camera());
    let m = Mat4::from_rotation_translation(ahead.orientation, ahead.position_m);
    assert!((m.transform_vector3(Vec3::Z) - Vec3::NEG_Z).length() < 1e-6);
    assert!((m.transform_vector3(Vec3::Y) - Vec3::NEG_Y).length() < 1e-6);
    assert!(head_from_camera("50", [0.0, 0.0, 0.0, 2.0], [0.0; 3]).is_err());
    assert!(head_from_camera("50", [0.0, 0.0, 0.0, 1.0], [f32::NAN, 0.0, 0.0]).is_err());
}

/// The lens pose as Android defines it (AOSP `CameraCharacteristics.java`,
/// LENS_POSE_ROTATION: "p' = Rp where p is in the device sensor coordinate
/// system, and p' is in the camera-oriented coordinate system";
/// LENS_INTRINSIC_CALIBRATION: P = [K 0][R −Rt], so p_camera = R (p − t)),
/// for a camera pitched 10° down and yawed 5° left: built here from the
/// camera's axes, not from the code under test. A head-space point on the
/// optical axis must project to the principal point, and the pose must be
/// Meta's (U74 `PassthroughCameraUtils.GetCameraPoseInWorld`, in Unity terms).
#[test]
fn lens_pose_is_the_inverse_of_the_sensor_to_camera_rotation() {
    use glam::Mat3;
    // The camera's OpenCV axes (x right, y down, z optical axis) in VIEW space
    // (x right, y up, z back): looking forward, then yawed and pitched.
    let looking_forward = Mat3::from_diagonal(Vec3::new(1.0, -1.0, -1.0));
    let turn = Mat3::from_rotation_y(5f32.to_radians()) * Mat3::from_rotation_x(-10f32.to_radians());
    let head_from_cv = turn * looking_forward;
    let axis = head_from_cv.col(2);
    assert!(axis.y < -0.17 && axis.x < -0.08 && axis.z < -0.97, "down, left, forward: {axis}");
    // Android's R maps sensor (head) coordinates into the camera's: the transpose.
    let r = head_from_cv.transpose();
    let q = Quat::from_mat3(&r).to_array();
    let t = [0.032f32, -0.01, -0.04];
    let m = head_from_camera("50", q, t).unwrap();
    let k = Intrinsics { fx: 800.0, fy: 800.0, cx: 640.0, cy: 480.0, width: 1280, height: 960 };
    let camera_from_head = m.inverse();
    let project = |p: Vec3| {
        let c = camera_from_head.transform_point3(p);
        assert!(c.z > 0.0, "{p} is behind the camera ({c})");
        (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy)
    };
    let centre = Vec3::from_array(t) + 2.0 * axis;
    let (u, v) = project(centre);
    assert!((u - 640.0).abs() < 1e-2 && (v - 480.0).abs() < 1e-2, "({u}, {v})");
    // Up in the head is up in the image, right is right.
    assert!(project(centre + 0.2 * Vec3::Y).1 < 470.0);
    assert!(project(centre + 0.2 * Vec3::X).0 > 650.0);
    // Meta's conversion, in Unity's left-handed frame (x right, y up, z
    // forward): p_headFromCamera = (t0, t1, −t2), q_cameraFromHead = (−x, −y,
    // z, w), q_headFromCamera = Inverse(q_cameraFromHead), then
    // `orientation *= Quaternion.Euler(180, 0, 0)` (a half turn about x).
    let q_camera_from_head_u = Quat::from_xyzw(-q[0], -q[1], q[2], q[3]);
    let q_u = q_camera_from_head_u.inverse() * Quat::from_xyzw(1.0, 0.0, 0.0, 0.0);
    let p_u = Vec3::new(t[0], t[1], -t[2]);
    // Unity → VIEW: z flips (S). Unity's camera looks along its +z with +y up;
    // OpenCV's y is down: head_from_cv = S · M_unity · diag(1, −1, 1).
    let s = Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0));
    let meta = s * Mat3::from_quat(q_u) * Mat3::from_diagonal(Vec3::new(1.0, -1.0, 1.0));
    let (_, rot, pos) = m.to_scale_rotation_translation();
    let ours = Mat3::from_quat(rot);
    for c in 0..3 {
        assert!((ours.col(c) - meta.col(c)).length() < 1e-5, "axis {c}: {} vs Meta's {}", ours.col(c), meta.col(c));
        assert!((ours.col(c) - head_from_cv.col(c)).length() < 1e-5, "axis {c}");
    }
    assert!((pos - s * p_u).length() < 1e-6, "{pos} vs Meta's {}", s * p_u);
}

#[test]
fn head_between_the_eyes() {
    let (q, p) = head_from_eyes(
        [Quat::from_rotation_y(0.1), Quat::from_rotation_y(0.3)],
        [Vec3::new(-0.032, 1.6, 0.0), Vec3::new(0.032, 1.6, 0.0)],
    );
    assert!(q.angle_between(Quat::from_rotation_y(0.2)) < 1e-5);
    assert!((p - Vec3::new(0.0, 1.6, 0.0)).length() < 1e-6);
}

#[test]
fn capture_results_match_by_timestamp() {
    let r = |t: i64| CaptureResult {
        sensor_timestamp_ns: t,
        exposure_ns: Some(4_000_000),
        rolling_skew_ns: None,
        frame_duration_ns: None,
    };
    let mut rs = CaptureResults::default();
    for t in 0..20 {
        rs.record(r(t * 33));
    }
    assert_eq!(rs.len(), CaptureResults::CAPACITY, "bounded");
    assert_eq!(rs.take(33), None, "evicted");
    assert_eq!(rs.take(10 * 33), Some(r(330)));
    assert_eq!(rs.len(), 9, "older results (dropped images) go with it");
    assert_eq!(rs.take(330), None);
}

/// A synthetic NV12 frame (interleaved chroma, padded rows): the assembler
/// converts it, numbers frames, puts the exposure's middle on the XR clock, and
/// refuses a frame that does not advance in time — with its index.
#[test]
fn assembles_frames_on_the_xr_clock() {
    let (w, h, stride) = (8usize, 4usize, 12usize);
    let mut y = vec![0u8; stride * h];
    for r in 0..h {
        for c in 0..w {
            y[r * stride + c] = (16 + 20 * c) as u8;
        }
    }
    let uv = vec![128u8; stride * h / 2];
    let img = Yuv420 {
        width: w,
        height: h,
        y: YuvPlane { data: &y, row_stride: stride, pixel_stride: 1 },
        u: YuvPlane { data: &uv, row_stride: stride, pixel_stride: 2 },
        v: YuvPlane { data: &uv[1..], row_stride: stride, pixel_stride: 2 },
    };
    let mut a = FrameAssembler::new(YuvMatrix::Bt709, YuvRange::Limited, TimestampSource::Realtime);
    // A result that reports no exposure: its middle is taken at its start.
    let bare = |t: i64| CaptureResult {
        sensor_timestamp_ns: t,
        exposure_ns: None,
        rolling_skew_ns: None,
        frame_duration_ns: None,
    };
    // No clock yet: the sensor's clock, said so.
    let f0 = a.assemble(&img, 1_000_000_000, &bare(1_000_000_000)).unwrap();
    assert!(!f0.on_xr_clock && !f0.exposure_known);
    assert_eq!((f0.frame.index, f0.frame.t_s), (0, 1.0));
    // Grey (Cb = Cr = 128): R = G = B = (Y − 16)/219.
    let px = f0.frame.image.channels[0][3];
    assert!((px - 60.0 / 219.0).abs() < 1e-6 && f0.frame.image.channels[2][3] == px);
    // XrTime = monotonic + 5 ms; boottime = monotonic + 2 s.
    a.set_clock(ClockMap {
        xr_minus_monotonic_ns: 5_000_000,
        boottime_minus_monotonic_ns: 2_000_000_000,
        uncertainty_ns: 0,
    });
    let result = CaptureResult {
        sensor_timestamp_ns: 3_000_000_000,
        exposure_ns: Some(8_000_000),
        rolling_skew_ns: Some(10_000_000),
        frame_duration_ns: Some(33_333_333),
    };
    let f1 = a.assemble(&img, 3_000_000_000, &result).unwrap();
    assert!(f1.on_xr_clock && f1.exposure_known);
    // Middle: boottime 3 s + 5 ms + 4 ms = 3.009 s → monotonic 1.009 s → XrTime 1.014 s.
    assert_eq!(f1.frame.index, 1);
    assert!((f1.frame.t_s - 1.014).abs() < 1e-9, "{}", f1.frame.t_s);
    let e = a.assemble(&img, 3_000_000_000, &result).unwrap_err();
    assert!(matches!(e, CameraError::Time { index: 2, .. }), "{e}");
    let short = Yuv420 { height: 40, ..img };
    assert!(matches!(a.assemble(&short, 4_000_000_000, &bare(4_000_000_000)), Err(CameraError::Yuv { index: 3, .. })));
    // A refused frame does not move the time reference: the next one passes.
    assert_eq!(a.assemble(&img, 3_100_000_000, &bare(3_100_000_000)).unwrap().frame.index, 4);
    // Images not assembled (the worker busy) still count: the camera's numbering.
    a.skip();
    a.skip();
    assert_eq!(a.assemble(&img, 3_200_000_000, &bare(3_200_000_000)).unwrap().frame.index, 7);
}

#[test]
fn exposure_check_line() {
    let mut model = CameraModel::empty(1280, 960);
    model.motion_blur.present = true;
    model.motion_blur.exposure = Some(0.24);
    model.motion_blur.diagnostics.stderr = Some(0.02);
    let c = ExposureCheck::new(Some(8_000_000), 1.0 / 30.0, &model);
    assert!((c.sensor_lambda().unwrap() - 0.24).abs() < 1e-9);
    assert_eq!(
        c.line(),
        "sensor exposure 8.00 ms (λ 0.240); fitted λ 0.240 ± 0.020 (8.00 ms); frame interval 33.33 ms"
    );
    model.motion_blur.present = false;
    let c = ExposureCheck::new(None, 1.0 / 30.0, &model);
    assert_eq!(c.fitted_lambda, None);
    assert!(c.line().starts_with("sensor exposure not reported; fitted motion blur absent"));
}

/// Meta's vendor keys are byte arrays of size 1 (Meta's Unity sample reads
/// `sbyte[]` and requires length 1); an `int[]` of one or an `Integer` (a
/// runtime declaring the key as INT32) reads the same; anything else is None
/// with the reason.
#[test]
fn vendor_values_read_as_meta_stores_them() {
    assert_eq!(VendorValue::Bytes(vec![0]).single_int(), Ok(0));
    assert_eq!(VendorValue::Bytes(vec![1]).single_int(), Ok(1));
    assert_eq!(VendorValue::Bytes(vec![-1]).single_int(), Ok(-1), "Java bytes are signed");
    assert_eq!(VendorValue::Ints(vec![1]).single_int(), Ok(1));
    assert_eq!(VendorValue::Int(1).single_int(), Ok(1));
    assert_eq!(VendorValue::Bytes(vec![]).single_int(), Err("byte[] of 0 values, not 1".into()));
    assert_eq!(VendorValue::Bytes(vec![0, 1]).single_int(), Err("byte[] of 2 values, not 1".into()));
    assert_eq!(VendorValue::Ints(vec![0, 1]).single_int(), Err("int[] of 2 values, not 1".into()));
    assert_eq!(VendorValue::Other("[J".into()).single_int(), Err("a [J, not byte[], int[] or Integer".into()));
    assert_eq!(vendor_int(&None), Err("absent".into()));
}

/// Both keys are required, as Meta's sample requires them: a camera without a
/// source key, or with an unreadable one, is not a passthrough camera; int[]
/// and Integer values are taken like byte[] ones.
#[test]
fn chooses_only_cameras_whose_keys_say_passthrough() {
    let mut ints = quest_like("50", 0);
    ints.meta_position = Some(VendorValue::Ints(vec![0]));
    ints.meta_source = Some(VendorValue::Int(0));
    assert_eq!(choose_camera(&[ints], CameraSide::Left, PASSTHROUGH_SIZE).unwrap().id, "50");
    let mut no_source = quest_like("50", 0);
    no_source.meta_source = None;
    let mut long = quest_like("51", 1);
    long.meta_position = Some(VendorValue::Bytes(vec![1, 0]));
    let mut odd = quest_like("52", 2);
    odd.meta_source = Some(VendorValue::Bytes(vec![0]));
    let e = choose_camera(&[no_source, long, odd], CameraSide::Left, PASSTHROUGH_SIZE).unwrap_err();
    let CameraError::NoPassthrough(seen) = &e else { panic!("{e}") };
    assert_eq!(
        seen,
        "50 (position 0, source absent), 51 (position byte[] of 2 values, not 1, source 0), 52 (position 2, source 0)"
    );
}

/// The calibration is in pre-correction array pixels: a stream is a crop of
/// that array, not of the active array, when the two differ; without the
/// pre-correction array the active one stands in, said in the notes.
#[test]
fn intrinsics_come_from_the_pre_correction_array() {
    let mut cam = quest_like("50", 0);
    cam.pre_correction_array = Some([0, 0, 1280, 1280]);
    cam.active_array = Some([8, 8, 1264, 1264]);
    cam.intrinsic_calibration = Some([866.0, 866.0, 640.5, 641.0, 0.0]);
    let c = choose_camera(&[cam.clone()], CameraSide::Left, PASSTHROUGH_SIZE).unwrap();
    // 1280×960 of 1280×1280: rows 160..1120, unscaled.
    let k = c.intrinsics.unwrap();
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (866.0, 866.0, 640.5, 481.0));
    assert!(c.notes.is_empty(), "{:?}", c.notes);
    cam.pre_correction_array = None;
    let c = choose_camera(&[cam], CameraSide::Left, PASSTHROUGH_SIZE).unwrap();
    // 1264×948 of 1264×1264 (rows 158..1106), scaled by 1280/1264.
    let k = c.intrinsics.unwrap();
    let s = 1280.0 / 1264.0;
    assert!((k.fx - 866.0 * s).abs() < 1e-3 && (k.cy - (641.0 - 158.0) * s).abs() < 1e-3, "{k:?}");
    assert!(c.notes.iter().any(|n| n.contains("no pre-correction active array size")), "{:?}", c.notes);
}

/// Results that come after their images: the image waits (not handed on
/// without its exposure), is handed on with its result at the next image; an
/// image whose result never comes is dropped once a later one's arrives; at
/// most `HELD` wait; after `close` nothing is held.
#[test]
fn images_wait_for_their_capture_results() {
    let r = |t: i64| CaptureResult {
        sensor_timestamp_ns: t,
        exposure_ns: Some(8_000_000),
        rolling_skew_ns: None,
        frame_duration_ns: None,
    };
    let ts = |p: &[Paired<&'static str>]| p.iter().map(|x| (x.image, x.sensor_timestamp_ns)).collect::<Vec<_>>();
    let mut p = CapturePairing::default();
    assert_eq!(p.image(100, "a"), vec![], "its result has not come");
    p.result(r(100));
    assert_eq!(ts(&p.image(200, "b")), [("a", 100)]);
    assert_eq!(p.held(), 1, "b waits");
    // b's result, then c's before its image: both handed on with c, each with
    // its own result.
    p.result(r(200));
    p.result(CaptureResult { exposure_ns: Some(9_000_000), ..r(300) });
    let out = p.image(300, "c");
    assert_eq!(ts(&out), [("b", 200), ("c", 300)]);
    assert_eq!((out[0].result.exposure_ns, out[1].result.exposure_ns), (Some(8_000_000), Some(9_000_000)));
    assert_eq!(p.held(), 0);
    // d's result never comes; e's does: d is dropped, e handed on.
    assert_eq!(p.image(400, "d"), vec![]);
    assert_eq!(p.image(500, "e"), vec![]);
    p.result(r(500));
    assert_eq!(ts(&p.release()), [("e", 500)]);
    assert_eq!((p.dropped(), p.held()), (1, 0));
    // Results that never come: at most HELD images wait.
    for t in 600..610 {
        assert_eq!(p.image(t, "f"), vec![]);
    }
    assert_eq!((p.held(), p.dropped()), (CapturePairing::<&str>::HELD, 1 + 10 - 2));
    p.close();
    assert_eq!(p.held(), 0);
    p.result(r(700));
    assert_eq!(p.image(700, "g"), vec![], "closed");
    assert_eq!(p.held(), 0);
}
