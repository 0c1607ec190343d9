//! The passthrough camera as Android's Camera2 describes it, made device-free:
//! which camera to open (Meta's vendor keys), its intrinsics at the stream's size,
//! where it sits on the head, capture results matched to their images, a captured
//! YUV_420_888 image turned into the worker's `Frame` on the XR clock, and the
//! sensor's own exposure set beside the fitted one. The Android code
//! (`platform/android_camera.rs`) only reads these values from the NDK and calls in
//! here, so everything that decides something is tested on desktop.
//!
//! Conventions (Android `CameraCharacteristics`, read as Meta's Passthrough Camera
//! API samples read them; not verified on a headset here):
//! * `LENS_INTRINSIC_CALIBRATION` = [fx, fy, cx, cy, s] in pixels of the sensor's
//!   active array, continuous coordinates (pixel u covers [u, u + 1), as
//!   `Intrinsics` everywhere in this crate);
//! * an output stream whose aspect ratio differs from the active array's is the
//!   largest centred crop of the array with the stream's aspect ratio, scaled
//!   uniformly (`SCALER_CROP_REGION` at its default, the whole array);
//! * `LENS_POSE_ROTATION` (x, y, z, w) is the orientation of the camera's axes —
//!   x right and y down in the image, z along the optical axis (OpenCV's) — in the
//!   Android sensor frame, and `LENS_POSE_TRANSLATION` the lens centre there (m);
//! * the Android sensor frame of a headset (x right, y up, z towards the face) has
//!   the axes of OpenXR's VIEW space; its origin is `LENS_POSE_REFERENCE`'s (the
//!   IMU for GYROSCOPE). `head_from_sensor` is therefore a rotation-free identity
//!   here: the few millimetres between the IMU and the VIEW origin are below what
//!   pose + depth flow resolves at passthrough distances.

use super::reproject::Intrinsics;
use super::timing::{exposure_middle_ns, ClockMap, TimedPose, TimestampSource};
use super::Frame;
use crate::image::yuv::{yuv420_to_rgb, Yuv420, YuvError, YuvMatrix, YuvRange};
use crate::model::CameraModel;
use glam::{Mat4, Quat, Vec3};
use std::collections::VecDeque;

/// The Quest 3 passthrough stream the worker is built for (1280×960 @ 30 Hz).
pub const PASSTHROUGH_SIZE: (u32, u32) = (1280, 960);
/// Vendor keys of Meta's Passthrough Camera API (CameraCharacteristics, Integer).
pub const META_POSITION_KEY: &str = "com.meta.extra_metadata.position";
pub const META_SOURCE_KEY: &str = "com.meta.extra_metadata.camera_source";
/// `com.meta.extra_metadata.camera_source` of a passthrough camera.
pub const META_SOURCE_PASSTHROUGH: i32 = 0;

/// Which of the two passthrough cameras (`com.meta.extra_metadata.position`: 0
/// left, 1 right).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraSide {
    Left,
    Right,
}

impl CameraSide {
    pub fn from_meta_position(v: i32) -> Option<Self> {
        match v {
            0 => Some(Self::Left),
            1 => Some(Self::Right),
            _ => None,
        }
    }
}

/// What the camera service reports about one camera (read from
/// `ACameraMetadata` and, for the vendor keys, `CameraCharacteristics` over JNI).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraDescription {
    pub id: String,
    /// `com.meta.extra_metadata.position`; None: the camera has no such key.
    pub meta_position: Option<i32>,
    /// `com.meta.extra_metadata.camera_source`; None: no such key.
    pub meta_source: Option<i32>,
    /// `ACAMERA_SENSOR_INFO_ACTIVE_ARRAY_SIZE`: left, top, width, height (px).
    pub active_array: Option<[i32; 4]>,
    /// `ACAMERA_LENS_INTRINSIC_CALIBRATION`: fx, fy, cx, cy, skew (px).
    pub intrinsic_calibration: Option<[f32; 5]>,
    /// `ACAMERA_LENS_POSE_TRANSLATION` (m) and `ACAMERA_LENS_POSE_ROTATION` (x, y, z, w).
    pub lens_pose_translation_m: Option<[f32; 3]>,
    pub lens_pose_rotation: Option<[f32; 4]>,
    /// `ACAMERA_LENS_POSE_REFERENCE` (0 primary camera, 1 gyroscope, 2 undefined).
    pub lens_pose_reference: Option<u8>,
    /// YUV_420_888 output sizes (`ACAMERA_SCALER_AVAILABLE_STREAM_CONFIGURATIONS`).
    pub yuv_sizes: Vec<(u32, u32)>,
    /// `ACAMERA_SENSOR_INFO_TIMESTAMP_SOURCE` is REALTIME (CLOCK_BOOTTIME).
    pub timestamp_realtime: bool,
}

/// The camera to open and what is known about it.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraChoice {
    pub id: String,
    pub side: CameraSide,
    pub size: (u32, u32),
    /// At `size`; None when the camera reports no calibration (the worker then
    /// runs without pose + depth flow).
    pub intrinsics: Option<Intrinsics>,
    /// `head_from_camera` (OpenCV camera axes in OpenXR VIEW space), when the lens
    /// pose is reported.
    pub head_from_camera: Option<Mat4>,
    pub timestamp_source: TimestampSource,
    /// What was not as wanted, for the log (other side taken, size, missing keys).
    pub notes: Vec<String>,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CameraError {
    #[error("the camera service reports no camera")]
    NoCameras,
    #[error("no passthrough camera (no camera carries {META_POSITION_KEY} = 0 or 1 with a passthrough source): {0}")]
    NoPassthrough(String),
    #[error("camera {id}: no YUV_420_888 output size is offered")]
    NoYuv { id: String },
    #[error("camera {id}: {what} = {value}: {why}")]
    Metadata { id: String, what: &'static str, value: String, why: &'static str },
    #[error("frame {index}: {source}")]
    Yuv { index: u64, source: YuvError },
    #[error("frame {index}: sensor timestamp {timestamp_ns} ns is not after the previous frame's ({previous_ns} ns)")]
    Time { index: u64, timestamp_ns: i64, previous_ns: i64 },
}

/// Pick the passthrough camera: one whose Meta position key says `want` (the
/// other side when `want` is missing, noted), whose source key (when present)
/// says passthrough; the stream `size` when offered, else the offered size nearest
/// to it in pixel count (noted).
pub fn choose_camera(
    cameras: &[CameraDescription],
    want: CameraSide,
    size: (u32, u32),
) -> Result<CameraChoice, CameraError> {
    if cameras.is_empty() {
        return Err(CameraError::NoCameras);
    }
    let passthrough = |c: &&CameraDescription| {
        c.meta_position.and_then(CameraSide::from_meta_position).is_some()
            && c.meta_source.map_or(true, |s| s == META_SOURCE_PASSTHROUGH)
    };
    let side_of = |c: &CameraDescription| c.meta_position.and_then(CameraSide::from_meta_position);
    let mut notes = vec![];
    let cam = match cameras.iter().filter(passthrough).find(|c| side_of(c) == Some(want)) {
        Some(c) => c,
        None => match cameras.iter().find(passthrough) {
            Some(c) => {
                notes.push(format!("no {want:?} passthrough camera: using the {:?} one", side_of(c).unwrap_or(want)));
                c
            }
            None => {
                let seen: Vec<String> = cameras
                    .iter()
                    .map(|c| format!("{} (position {:?}, source {:?})", c.id, c.meta_position, c.meta_source))
                    .collect();
                return Err(CameraError::NoPassthrough(seen.join(", ")));
            }
        },
    };
    let side = side_of(cam).unwrap_or(want);
    let chosen = if cam.yuv_sizes.contains(&size) {
        size
    } else {
        let want_px = size.0 as f64 * size.1 as f64;
        let nearest = cam
            .yuv_sizes
            .iter()
            .copied()
            .filter(|&(w, h)| w > 0 && h > 0)
            .min_by(|a, b| {
                let d = |s: (u32, u32)| ((s.0 as f64 * s.1 as f64) / want_px).ln().abs();
                d(*a).total_cmp(&d(*b))
            })
            .ok_or_else(|| CameraError::NoYuv { id: cam.id.clone() })?;
        notes.push(format!("{}×{} is not offered: using {}×{}", size.0, size.1, nearest.0, nearest.1));
        nearest
    };
    // Unusable calibration or pose metadata costs pose + depth flow (the worker
    // falls back to image flow), not the calibration: noted, not fatal.
    let intrinsics = match (cam.active_array, cam.intrinsic_calibration) {
        (Some(array), Some(calib)) => stream_intrinsics(&cam.id, array, calib, chosen)
            .map_err(|e| notes.push(format!("{e}: pose + depth flow is unavailable")))
            .ok(),
        _ => {
            notes.push("no intrinsic calibration or active array size: pose + depth flow is unavailable".into());
            None
        }
    };
    let head_from_camera = match (cam.lens_pose_rotation, cam.lens_pose_translation_m) {
        (Some(q), Some(t)) => head_from_camera(&cam.id, q, t)
            .map_err(|e| notes.push(format!("{e}: the camera is taken at the head's origin, looking forward")))
            .ok(),
        _ => {
            notes.push("no lens pose: the camera is taken at the head's origin, looking forward".into());
            None
        }
    };
    if cam.lens_pose_reference.is_some_and(|r| r != 1) {
        notes.push(format!(
            "lens pose reference {:?} (not the gyroscope): its origin is taken as the head's",
            cam.lens_pose_reference
        ));
    }
    let timestamp_source = if cam.timestamp_realtime {
        TimestampSource::Realtime
    } else {
        notes.push("sensor timestamps are not on CLOCK_BOOTTIME: frames cannot be matched to head poses".into());
        TimestampSource::Unknown
    };
    Ok(CameraChoice { id: cam.id.clone(), side, size: chosen, intrinsics, head_from_camera, timestamp_source, notes })
}

/// Intrinsics of a `size` stream from the calibration in active-array pixels: the
/// stream is the largest centred crop of the array with its aspect ratio, scaled
/// uniformly (Android's default crop region), so x_stream = (x_array − crop_left)·s.
pub fn stream_intrinsics(
    id: &str,
    active_array: [i32; 4],
    calib: [f32; 5],
    size: (u32, u32),
) -> Result<Intrinsics, CameraError> {
    let bad = |what: &'static str, value: String, why: &'static str| CameraError::Metadata {
        id: id.to_string(),
        what,
        value,
        why,
    };
    let [_, _, aw, ah] = active_array;
    if aw <= 0 || ah <= 0 {
        return Err(bad("active array size", format!("{active_array:?}"), "a side is not positive"));
    }
    let [fx, fy, cx, cy, _skew] = calib;
    if !calib.iter().all(|v| v.is_finite()) || fx <= 0.0 || fy <= 0.0 {
        return Err(bad("intrinsic calibration", format!("{calib:?}"), "not finite or a focal length ≤ 0"));
    }
    if !(0.0..=aw as f32).contains(&cx) || !(0.0..=ah as f32).contains(&cy) {
        return Err(bad("intrinsic calibration", format!("{calib:?}"), "the principal point is outside the array"));
    }
    let (w, h) = (size.0 as f64, size.1 as f64);
    let (aw, ah) = (aw as f64, ah as f64);
    // The crop keeps the full width when the stream is wider than the array.
    let (crop_w, crop_h) = if w / h >= aw / ah { (aw, aw * h / w) } else { (ah * w / h, ah) };
    let (left, top) = ((aw - crop_w) / 2.0, (ah - crop_h) / 2.0);
    let s = w / crop_w;
    Ok(Intrinsics {
        fx: (fx as f64 * s) as f32,
        fy: (fy as f64 * s) as f32,
        cx: ((cx as f64 - left) * s) as f32,
        cy: ((cy as f64 - top) * s) as f32,
        width: size.0 as usize,
        height: size.1 as usize,
    })
}

/// `head_from_camera` from the lens pose (see the module's conventions): the
/// camera's OpenCV axes rotated by `rotation` and placed at `translation_m` in the
/// sensor frame, whose axes are OpenXR VIEW space's.
pub fn head_from_camera(id: &str, rotation: [f32; 4], translation_m: [f32; 3]) -> Result<Mat4, CameraError> {
    let q = Quat::from_array(rotation);
    let t = Vec3::from_array(translation_m);
    if !q.is_finite() || !t.is_finite() || (q.length() - 1.0).abs() > 1e-2 {
        return Err(CameraError::Metadata {
            id: id.to_string(),
            what: "lens pose",
            value: format!("rotation {rotation:?}, translation {translation_m:?}"),
            why: "not finite or not a unit quaternion",
        });
    }
    Ok(Mat4::from_rotation_translation(q.normalize(), t))
}

/// Where a camera looking straight ahead sits when the lens pose is unknown: at
/// the head's origin, OpenCV axes (y down, z forward) in VIEW space (y up, −z
/// forward): a half turn about x.
pub fn forward_camera() -> Mat4 {
    Mat4::from_quat(Quat::from_rotation_x(std::f32::consts::PI))
}

/// The head (OpenXR VIEW space) from the two eyes' poses at one time: midway
/// between the eyes, their mean orientation.
pub fn head_from_eyes(orientations: [Quat; 2], positions_m: [Vec3; 2]) -> (Quat, Vec3) {
    (orientations[0].slerp(orientations[1], 0.5).normalize(), (positions_m[0] + positions_m[1]) * 0.5)
}

/// The camera's pose (`world_from_camera`, OpenCV axes: what the worker's pose
/// track holds) from the head's at `t_ns`.
pub fn camera_pose(t_ns: i64, world_from_head: (Quat, Vec3), head_from_camera: &Mat4) -> TimedPose {
    let world_from_camera = Mat4::from_rotation_translation(world_from_head.0, world_from_head.1) * *head_from_camera;
    let (_, orientation, position_m) = world_from_camera.to_scale_rotation_translation();
    TimedPose { t_ns, position_m, orientation: orientation.normalize() }
}

/// What a capture result says about one image (matched by SENSOR_TIMESTAMP,
/// which is also the AImage's timestamp).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CaptureResult {
    pub sensor_timestamp_ns: i64,
    /// `ACAMERA_SENSOR_EXPOSURE_TIME`, when the result carries it.
    pub exposure_ns: Option<i64>,
    /// `ACAMERA_SENSOR_ROLLING_SHUTTER_SKEW`.
    pub rolling_skew_ns: Option<i64>,
    /// `ACAMERA_SENSOR_FRAME_DURATION`.
    pub frame_duration_ns: Option<i64>,
}

/// Capture results waiting for their images (they come on another thread, in
/// either order); bounded: the oldest go first.
#[derive(Debug, Default)]
pub struct CaptureResults {
    pending: VecDeque<CaptureResult>,
}

impl CaptureResults {
    /// A camera delivers an image within a few frames of its result.
    pub const CAPACITY: usize = 16;

    pub fn record(&mut self, r: CaptureResult) {
        if self.pending.len() == Self::CAPACITY {
            self.pending.pop_front();
        }
        self.pending.push_back(r);
    }

    /// The result of the image stamped `sensor_timestamp_ns`, removed with every
    /// older one (their images were dropped).
    pub fn take(&mut self, sensor_timestamp_ns: i64) -> Option<CaptureResult> {
        let i = self.pending.iter().position(|r| r.sensor_timestamp_ns == sensor_timestamp_ns)?;
        let r = self.pending[i];
        self.pending.drain(..=i);
        Some(r)
    }

    pub fn len(&self) -> usize {
        self.pending.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }
}

/// Turns captured images into the worker's frames: encoded R'G'B' (what the fits
/// work in), numbered, timed at the middle of the exposure on the XR clock when
/// the clocks are mapped (else on the sensor's clock: then no pose can be matched).
#[derive(Debug)]
pub struct FrameAssembler {
    pub matrix: YuvMatrix,
    pub range: YuvRange,
    pub timestamp_source: TimestampSource,
    clock: Option<ClockMap>,
    next_index: u64,
    last_timestamp_ns: Option<i64>,
}

/// A frame and how its time was found.
#[derive(Debug)]
pub struct Assembled {
    pub frame: Frame,
    /// `frame.t_s` is on the XR clock (poses can be matched to it).
    pub on_xr_clock: bool,
    /// The exposure's middle had to be guessed (no capture result with exposure).
    pub exposure_known: bool,
}

impl FrameAssembler {
    pub fn new(matrix: YuvMatrix, range: YuvRange, timestamp_source: TimestampSource) -> Self {
        Self { matrix, range, timestamp_source, clock: None, next_index: 0, last_timestamp_ns: None }
    }

    /// A new mapping between the clocks (refreshed as the runtime's clock drifts).
    pub fn set_clock(&mut self, clock: ClockMap) {
        self.clock = Some(clock);
    }

    pub fn clock(&self) -> Option<&ClockMap> {
        self.clock.as_ref()
    }

    /// Assemble one image. Its index advances even when the image is refused, so
    /// the log's frame numbers count the camera's images.
    pub fn assemble(
        &mut self,
        image: &Yuv420<'_>,
        sensor_timestamp_ns: i64,
        result: Option<&CaptureResult>,
    ) -> Result<Assembled, CameraError> {
        let index = self.next_index;
        self.next_index += 1;
        if let Some(prev) = self.last_timestamp_ns {
            if sensor_timestamp_ns <= prev {
                return Err(CameraError::Time { index, timestamp_ns: sensor_timestamp_ns, previous_ns: prev });
            }
        }
        let rgb = yuv420_to_rgb(image, self.matrix, self.range, false)
            .map_err(|source| CameraError::Yuv { index, source })?;
        self.last_timestamp_ns = Some(sensor_timestamp_ns);
        let exposure = result.and_then(|r| r.exposure_ns).filter(|&e| e > 0);
        let skew = result.and_then(|r| r.rolling_skew_ns).unwrap_or(0);
        let middle_ns = exposure_middle_ns(sensor_timestamp_ns, exposure.unwrap_or(0), skew);
        let xr_ns = self.clock.as_ref().and_then(|c| c.xr_time_ns(middle_ns, self.timestamp_source).ok());
        let t_ns = xr_ns.unwrap_or(middle_ns);
        Ok(Assembled {
            frame: Frame { index, t_s: t_ns as f64 * 1e-9, image: rgb, depth: None, flow: None },
            on_xr_clock: xr_ns.is_some(),
            exposure_known: exposure.is_some(),
        })
    }
}

/// The sensor's exposure (`SENSOR_EXPOSURE_TIME`) beside the worker's estimate:
/// λ is the exposure as a fraction of the frame interval, so the sensor's λ is
/// exposure / interval. Quest's passthrough cameras take no exposure control, so
/// this is a check of the fit, not an input to it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExposureCheck {
    pub sensor_exposure_s: Option<f64>,
    pub frame_interval_s: f64,
    /// The model's λ (None: motion blur absent or not identified).
    pub fitted_lambda: Option<f32>,
    pub fitted_stderr: Option<f64>,
}

impl ExposureCheck {
    pub fn new(sensor_exposure_ns: Option<i64>, frame_interval_s: f64, model: &CameraModel) -> Self {
        let mb = &model.motion_blur;
        Self {
            sensor_exposure_s: sensor_exposure_ns.filter(|&e| e > 0).map(|e| e as f64 * 1e-9),
            frame_interval_s,
            fitted_lambda: if mb.present { mb.exposure } else { None },
            fitted_stderr: mb.diagnostics.stderr,
        }
    }

    /// The sensor's exposure as a fraction of the frame interval.
    pub fn sensor_lambda(&self) -> Option<f64> {
        self.sensor_exposure_s.filter(|_| self.frame_interval_s > 0.0).map(|e| e / self.frame_interval_s)
    }

    /// One log line.
    pub fn line(&self) -> String {
        let ms = |s: f64| s * 1e3;
        let sensor = match (self.sensor_exposure_s, self.sensor_lambda()) {
            (Some(e), Some(l)) => format!("sensor exposure {:.2} ms (λ {l:.3})", ms(e)),
            _ => "sensor exposure not reported".to_string(),
        };
        let fitted = match self.fitted_lambda {
            Some(l) => {
                let e = l as f64 * self.frame_interval_s;
                match self.fitted_stderr {
                    Some(se) => format!("fitted λ {l:.3} ± {se:.3} ({:.2} ms)", ms(e)),
                    None => format!("fitted λ {l:.3} ({:.2} ms)", ms(e)),
                }
            }
            None => "fitted motion blur absent or not identified".to_string(),
        };
        format!("{sensor}; {fitted}; frame interval {:.2} ms", ms(self.frame_interval_s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::yuv::YuvPlane;

    fn quest_like(id: &str, position: i32) -> CameraDescription {
        CameraDescription {
            id: id.into(),
            meta_position: Some(position),
            meta_source: Some(0),
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
        other.meta_source = Some(1);
        let e = choose_camera(&[phone, other], CameraSide::Left, PASSTHROUGH_SIZE).unwrap_err();
        assert!(
            matches!(&e, CameraError::NoPassthrough(s) if s.contains("52 (position Some(0), source Some(1))")),
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
        assert_eq!(
            choose_camera(&[cam], CameraSide::Left, PASSTHROUGH_SIZE),
            Err(CameraError::NoYuv { id: "50".into() })
        );
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
        let head_from_cam = head_from_camera("50", q.to_array(), [0.03, -0.02, -0.05]).unwrap();
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
        // No clock yet: the sensor's clock, said so.
        let f0 = a.assemble(&img, 1_000_000_000, None).unwrap();
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
        let f1 = a.assemble(&img, 3_000_000_000, Some(&result)).unwrap();
        assert!(f1.on_xr_clock && f1.exposure_known);
        // Middle: boottime 3 s + 5 ms + 4 ms = 3.009 s → monotonic 1.009 s → XrTime 1.014 s.
        assert_eq!(f1.frame.index, 1);
        assert!((f1.frame.t_s - 1.014).abs() < 1e-9, "{}", f1.frame.t_s);
        let e = a.assemble(&img, 3_000_000_000, None).unwrap_err();
        assert!(matches!(e, CameraError::Time { index: 2, .. }), "{e}");
        let short = Yuv420 { height: 40, ..img };
        assert!(matches!(a.assemble(&short, 4_000_000_000, None), Err(CameraError::Yuv { index: 3, .. })));
        // A refused frame does not move the time reference: the next one passes.
        assert_eq!(a.assemble(&img, 3_100_000_000, None).unwrap().frame.index, 4);
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
}
