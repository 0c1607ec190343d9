//! The passthrough camera as Android's Camera2 describes it, made device-free:
//! which camera to open (Meta's vendor keys, as JNI read them), its intrinsics at
//! the stream's size, where it sits on the head, images held until their capture
//! results arrive, a captured YUV_420_888 image turned into the worker's `Frame`
//! on the XR clock, the sensor's own exposure set beside the fitted one, and the
//! Android app's small decisions around the camera (which permissions suffice,
//! how long to wait for the spatial-data permission, when to reopen a lost
//! camera). The Android code (`platform/android.rs`, `platform/android_camera.rs`)
//! only reads values from the NDK and JNI and calls in here, so everything that
//! decides something is tested on desktop.
//!
//! Conventions (Android `CameraCharacteristics`, AOSP
//! `core/java/android/hardware/camera2/CameraCharacteristics.java`, read as Meta's
//! Passthrough Camera API samples read them; not verified on a headset here):
//! * Meta's vendor keys `com.meta.extra_metadata.position` and `…camera_source`
//!   hold one value each, stored as an array of size 1 (Meta's
//!   `oculus-samples/Unity-PassthroughCameraApiSamples`
//!   `PassthroughCamera/Scripts/PassthroughCameraUtils.cs`: "custom camera fields
//!   which are stored as arrays of size 1, instead of single values", read as
//!   `sbyte[]`); `VendorValue` is what JNI found, `VendorValue::single_int` the
//!   one reading of it;
//! * `LENS_INTRINSIC_CALIBRATION` = [fx, fy, cx, cy, s] in pixels of
//!   `SENSOR_INFO_PRE_CORRECTION_ACTIVE_ARRAY_SIZE` ("the coordinate system for
//!   this transform is the android.sensor.info.preCorrectionActiveArraySize
//!   system, where (0,0) is the top-left of the preCorrectionActiveArraySize
//!   rectangle"; Meta's sample takes that array's size as the intrinsics'
//!   resolution), continuous coordinates (pixel u covers [u, u + 1), as
//!   `Intrinsics` everywhere in this crate);
//! * an output stream whose aspect ratio differs from the array's is the largest
//!   centred crop of the array with the stream's aspect ratio, scaled uniformly
//!   (`SCALER_CROP_REGION` at its default, the whole array);
//! * `LENS_POSE_ROTATION` (x, y, z, w) is "the quaternion rotation from the
//!   Android sensor coordinate system to a camera-aligned coordinate system":
//!   p' = R p maps a point of the sensor frame into the camera's (x right and y
//!   down in the image, z along the optical axis: OpenCV's), and
//!   `LENS_POSE_TRANSLATION` t is the lens's optical centre in the sensor frame
//!   (m); together p_camera = R (p_sensor − t) (`LENS_INTRINSIC_CALIBRATION`'s
//!   P = [K 0][R −Rt]). The camera's pose in the sensor frame is therefore the
//!   inverse rotation at t — what Meta's sample computes (`q_headFromCamera =
//!   Inverse(q_cameraFromHead)`);
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
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// The Quest 3 passthrough stream the worker is built for (1280×960 @ 30 Hz).
pub const PASSTHROUGH_SIZE: (u32, u32) = (1280, 960);
/// Vendor keys of Meta's Passthrough Camera API (CameraCharacteristics; found by
/// name in `getKeys()`, as Meta's Unity sample does).
pub const META_POSITION_KEY: &str = "com.meta.extra_metadata.position";
pub const META_SOURCE_KEY: &str = "com.meta.extra_metadata.camera_source";
/// `com.meta.extra_metadata.camera_source` of a passthrough camera (Meta's Unity
/// sample: `CameraSource { Passthrough = 0 }`).
pub const META_SOURCE_PASSTHROUGH: i32 = 0;

/// Which of the two passthrough cameras (`com.meta.extra_metadata.position`: 0
/// left, 1 right; Meta's Unity sample: `CameraPosition { Left = 0, Right = 1 }`).
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

/// A vendor key's value as JNI found it: `CameraCharacteristics.get(key)` with the
/// key object `getKeys()` returned, classified by its Java class. Why not ask for
/// a type: a vendor key's Java class follows its native type (AOSP
/// `android_hardware_camera2_CameraMetadata.cpp` `getAllVendorKeys`: TYPE_BYTE →
/// `byte[]`, TYPE_INT32 → `int[]`), and a key made with another class (Meta's
/// Kotlin sample's `Key(name, Int::class.java)`) has no marshaler for a byte
/// (`MarshalQueryablePrimitive` maps Integer to TYPE_INT32 only).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum VendorValue {
    /// `byte[]` (Java bytes are signed, as Meta's `sbyte[]`).
    Bytes(Vec<i8>),
    /// `int[]`.
    Ints(Vec<i32>),
    /// `java.lang.Integer`.
    Int(i32),
    /// Anything else: its class name (or "null").
    Other(String),
}

impl VendorValue {
    /// The one integer the key holds: a `byte[]` or `int[]` of exactly one value
    /// (Meta's Unity sample skips any other length), or an `Integer`; anything
    /// else is an error saying what was found.
    pub fn single_int(&self) -> Result<i32, String> {
        match self {
            Self::Bytes(v) => match v.as_slice() {
                [b] => Ok(i32::from(*b)),
                _ => Err(format!("byte[] of {} values, not 1", v.len())),
            },
            Self::Ints(v) => match v.as_slice() {
                [i] => Ok(*i),
                _ => Err(format!("int[] of {} values, not 1", v.len())),
            },
            Self::Int(i) => Ok(*i),
            Self::Other(class) => Err(format!("a {class}, not byte[], int[] or Integer")),
        }
    }
}

/// A Meta vendor key of one camera: its integer, or why there is none.
fn vendor_int(value: &Option<VendorValue>) -> Result<i32, String> {
    value.as_ref().ok_or_else(|| "absent".to_string())?.single_int()
}

/// What the camera service reports about one camera (read from
/// `ACameraMetadata` and, for the vendor keys, `CameraCharacteristics` over JNI).
/// Serde: the desktop tests read a recorded description through the same
/// `choose_camera` as the device.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraDescription {
    pub id: String,
    /// `com.meta.extra_metadata.position`; None: the camera has no such key.
    pub meta_position: Option<VendorValue>,
    /// `com.meta.extra_metadata.camera_source`; None: no such key.
    pub meta_source: Option<VendorValue>,
    /// `ACAMERA_SENSOR_INFO_PRE_CORRECTION_ACTIVE_ARRAY_SIZE`: left, top, width,
    /// height (px) — the frame of the intrinsic calibration.
    pub pre_correction_array: Option<[i32; 4]>,
    /// `ACAMERA_SENSOR_INFO_ACTIVE_ARRAY_SIZE`: left, top, width, height (px); the
    /// calibration's frame only when no pre-correction array is reported.
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
    #[error("no passthrough camera (none carries {META_POSITION_KEY} = 0 or 1 and {META_SOURCE_KEY} = 0): {0}")]
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
/// other side when `want` is missing, noted) and whose source key says
/// passthrough — both keys required, as Meta's Unity sample requires them
/// (`if (!cameraSource.HasValue || !cameraPosition.HasValue || cameraSource.Value
/// != CameraSource.Passthrough) continue;`); the stream `size` when offered, else
/// the offered size nearest to it in pixel count (noted).
pub fn choose_camera(
    cameras: &[CameraDescription],
    want: CameraSide,
    size: (u32, u32),
) -> Result<CameraChoice, CameraError> {
    if cameras.is_empty() {
        return Err(CameraError::NoCameras);
    }
    let side_of = |c: &CameraDescription| vendor_int(&c.meta_position).ok().and_then(CameraSide::from_meta_position);
    let passthrough =
        |c: &&CameraDescription| side_of(c).is_some() && vendor_int(&c.meta_source) == Ok(META_SOURCE_PASSTHROUGH);
    let mut notes = vec![];
    let cam = match cameras.iter().filter(passthrough).find(|c| side_of(c) == Some(want)) {
        Some(c) => c,
        None => match cameras.iter().find(passthrough) {
            Some(c) => {
                notes.push(format!("no {want:?} passthrough camera: using the {:?} one", side_of(c).unwrap_or(want)));
                c
            }
            None => {
                let key = |v: &Option<VendorValue>| match vendor_int(v) {
                    Ok(i) => i.to_string(),
                    Err(why) => why,
                };
                let seen: Vec<String> = cameras
                    .iter()
                    .map(|c| format!("{} (position {}, source {})", c.id, key(&c.meta_position), key(&c.meta_source)))
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
    // The calibration's own frame is the pre-correction array (see the module's
    // conventions); the active array is the nearest stand-in when a camera does
    // not report it — said, because the two differ by the distortion correction's
    // margin on cameras that correct distortion.
    let calibration_frame = match (cam.pre_correction_array, cam.active_array) {
        (Some(pre), _) => Some(pre),
        (None, Some(active)) => {
            notes.push(
                "no pre-correction active array size: the intrinsic calibration is taken in the active array's frame"
                    .into(),
            );
            Some(active)
        }
        (None, None) => None,
    };
    // Unusable calibration or pose metadata costs pose + depth flow (the worker
    // falls back to image flow), not the calibration: noted, not fatal.
    let intrinsics = match (calibration_frame, cam.intrinsic_calibration) {
        (Some(array), Some(calib)) => stream_intrinsics(&cam.id, array, calib, chosen)
            .map_err(|e| notes.push(format!("{e}: pose + depth flow is unavailable")))
            .ok(),
        _ => {
            notes.push("no intrinsic calibration or sensor array size: pose + depth flow is unavailable".into());
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

/// Intrinsics of a `size` stream from the calibration in pixels of `array` (the
/// pre-correction active array; (0, 0) its top-left): the stream is the largest
/// centred crop of the array with the stream's aspect ratio, scaled uniformly
/// (Android's default crop region; Meta's MRUK `PassthroughCameraAccess.cs`
/// rescales the same way: fx' = fx·W/crop.w, cx' = (cx − crop.x)·W/crop.w), so
/// x_stream = (x_array − crop_left)·s.
pub fn stream_intrinsics(
    id: &str,
    array: [i32; 4],
    calib: [f32; 5],
    size: (u32, u32),
) -> Result<Intrinsics, CameraError> {
    let bad = |what: &'static str, value: String, why: &'static str| CameraError::Metadata {
        id: id.to_string(),
        what,
        value,
        why,
    };
    let [_, _, aw, ah] = array;
    if aw <= 0 || ah <= 0 {
        return Err(bad("sensor array size", format!("{array:?}"), "a side is not positive"));
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

/// `head_from_camera` (the camera's OpenCV axes in OpenXR VIEW space) from the
/// lens pose (see the module's conventions): `rotation` maps sensor (= VIEW)
/// coordinates into the camera's, so the camera's axes in the head are its
/// inverse (the conjugate of a unit quaternion), placed at `translation_m`.
/// Meta's Unity sample computes the same (`q_headFromCamera =
/// Inverse(q_cameraFromHead)` after flipping z into Unity's left-handed frame,
/// then a half turn about x for Unity's y-up camera; OpenCV's y is down, so no
/// turn here).
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
    Ok(Mat4::from_rotation_translation(q.normalize().conjugate(), t))
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
/// which is also the AImage's timestamp: `AImage_getTimestamp`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
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

    /// The result of the image stamped `sensor_timestamp_ns` has arrived.
    pub fn contains(&self, sensor_timestamp_ns: i64) -> bool {
        self.pending.iter().any(|r| r.sensor_timestamp_ns == sensor_timestamp_ns)
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

/// An image handed on with its capture result.
#[derive(Debug, PartialEq)]
pub struct Paired<I> {
    pub image: I,
    pub sensor_timestamp_ns: i64,
    pub result: CaptureResult,
}

/// Images and capture results paired by SENSOR_TIMESTAMP, in either order of
/// arrival. An image whose result has not come yet is held (at most `HELD`), not
/// handed on: without the result its exposure is unknown, and timing it at the
/// start of its exposure would put it half an exposure (and half the rolling
/// shutter's skew) early against the head poses. Capture results are delivered
/// in capture order (Camera2), so a held image older than one whose result has
/// arrived lost its result (a failed capture) and is dropped.
#[derive(Debug)]
pub struct CapturePairing<I> {
    held: VecDeque<(i64, I)>,
    results: CaptureResults,
    closed: bool,
    dropped: u64,
}

impl<I> Default for CapturePairing<I> {
    fn default() -> Self {
        Self { held: VecDeque::new(), results: CaptureResults::default(), closed: false, dropped: 0 }
    }
}

impl<I> CapturePairing<I> {
    /// Images held for their results at most: a result comes within a frame or
    /// so of its image; each held image keeps one of the image reader's buffers.
    pub const HELD: usize = 2;

    /// A capture result arrived.
    pub fn result(&mut self, r: CaptureResult) {
        self.results.record(r);
    }

    /// An image arrived: held, then every held image whose result is known handed
    /// on, oldest first. Once closed, images are dropped at once.
    pub fn image(&mut self, sensor_timestamp_ns: i64, image: I) -> Vec<Paired<I>> {
        if self.closed {
            self.dropped += 1;
            return vec![];
        }
        self.held.push_back((sensor_timestamp_ns, image));
        self.release()
    }

    /// The held images whose results have arrived, oldest first; older held
    /// images without a result are dropped, and the oldest beyond `HELD` too.
    pub fn release(&mut self) -> Vec<Paired<I>> {
        let mut out = vec![];
        if let Some(last) = self.held.iter().rposition(|(t, _)| self.results.contains(*t)) {
            for (t, image) in self.held.drain(..=last) {
                match self.results.take(t) {
                    Some(result) => out.push(Paired { image, sensor_timestamp_ns: t, result }),
                    None => self.dropped += 1,
                }
            }
        }
        while self.held.len() > Self::HELD {
            self.held.pop_front();
            self.dropped += 1;
        }
        out
    }

    /// Drop every held image and every later one (the camera is closing: its
    /// images must go before its image reader).
    pub fn close(&mut self) {
        self.closed = true;
        self.held.clear();
    }

    /// Images held now.
    pub fn held(&self) -> usize {
        self.held.len()
    }

    /// Images dropped without being handed on (their results never came, or came
    /// too late).
    pub fn dropped(&self) -> u64 {
        self.dropped
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
    /// The capture result reported the exposure (else its middle is taken at its
    /// start).
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

    /// An image the camera delivered that is not assembled (the worker was busy,
    /// or the clocks are not mapped yet): it still counts, so frame numbers are
    /// the camera's and the temporal stages, which compare frames by their number
    /// distance (`worker::calibrator::tnr`), see the true lag between the frames
    /// the worker takes.
    pub fn skip(&mut self) {
        self.next_index += 1;
    }

    /// Assemble one image with its capture result (`CapturePairing` pairs them).
    /// Its index advances even when the image is refused, so the log's frame
    /// numbers count the camera's images.
    pub fn assemble(
        &mut self,
        image: &Yuv420<'_>,
        sensor_timestamp_ns: i64,
        result: &CaptureResult,
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
        let exposure = result.exposure_ns.filter(|&e| e > 0);
        let skew = result.rolling_skew_ns.unwrap_or(0);
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
#[path = "camera_tests.rs"]
mod tests;
