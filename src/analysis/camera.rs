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
use std::time::Duration;

/// The Quest 3 passthrough stream the worker is built for (1280×960 @ 30 Hz).
pub const PASSTHROUGH_SIZE: (u32, u32) = (1280, 960);
/// Vendor keys of Meta's Passthrough Camera API (CameraCharacteristics; found by
/// name in `getKeys()`, as Meta's Unity sample does).
pub const META_POSITION_KEY: &str = "com.meta.extra_metadata.position";
pub const META_SOURCE_KEY: &str = "com.meta.extra_metadata.camera_source";
/// `com.meta.extra_metadata.camera_source` of a passthrough camera (Meta's Unity
/// sample: `CameraSource { Passthrough = 0 }`).
pub const META_SOURCE_PASSTHROUGH: i32 = 0;
/// Each of these grants the passthrough camera (Meta's `meta-quest/agentic-tools`
/// `skills/hz-unity-passthrough-camera-access/SKILL.md`: "Either permission …
/// CAMERA grants access to both the passthrough and avatar cameras;
/// HEADSET_CAMERA grants access only to the passthrough camera").
pub const CAMERA_PERMISSION: &str = "android.permission.CAMERA";
pub const HEADSET_CAMERA_PERMISSION: &str = "horizonos.permission.HEADSET_CAMERA";

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

/// Whether the passthrough camera may be opened, from each permission and
/// whether it is granted: either camera permission suffices (see
/// `HEADSET_CAMERA_PERMISSION`; Meta's Spatial SDK scanner sample asks for
/// HEADSET_CAMERA alone).
pub fn camera_permitted(states: &[(&str, bool)]) -> bool {
    states.iter().any(|&(p, granted)| granted && (p == CAMERA_PERMISSION || p == HEADSET_CAMERA_PERMISSION))
}

/// The permissions to ask for, from each wanted one and whether it is granted:
/// every missing one, except that the two camera permissions are asked for only
/// while neither is granted (asking for CAMERA with HEADSET_CAMERA granted would
/// ask for the avatar cameras too, for nothing this app uses).
pub fn permissions_to_request<'a>(states: &[(&'a str, bool)]) -> Vec<&'a str> {
    let camera = |p: &str| p == CAMERA_PERMISSION || p == HEADSET_CAMERA_PERMISSION;
    let have_camera = camera_permitted(states);
    // Wanted: not granted, and not a camera permission once one camera permission is.
    let wanted = |p: &str, granted: bool| !(granted || (have_camera && camera(p)));
    states.iter().filter(|&&(p, granted)| wanted(p, granted)).map(|&(p, _)| p).collect()
}

/// What the activity did while the app waits for the spatial-data permission.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActivityEvent {
    /// Paused or lost focus: the permission dialog came up over it.
    Left,
    /// Resumed or regained focus.
    Returned,
    /// Destroyed: the app is ending.
    Destroyed,
}

/// The wait for `com.oculus.permission.USE_SCENE` before the OpenXR instance is
/// created. Why wait: Meta's `meta-quest/Meta-OpenXR-SDK`
/// `Samples/XrSamples/XrPassthroughOcclusion/Src/XrPassthroughOcclusion.cpp`
/// warns "com.oculus.USE_SCENE permission should be requested before creation of
/// OpenXR instance. Application will not function correctly without it.", and its
/// Java activity starts the native code only once the permission is granted.
/// NativeActivity has no `onRequestPermissionsResult`, so the answer is read by
/// polling `checkSelfPermission` and the activity's lifecycle: the system dialog
/// pauses the activity (or takes its focus) and its end resumes it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SceneWait {
    /// USE_SCENE is granted now.
    pub granted: bool,
    /// It was asked for at this start (else there is nothing to wait for).
    pub asked: bool,
    /// The activity left (the dialog came up) since the request.
    pub left: bool,
    /// …and came back after leaving: the dialog was answered.
    pub returned: bool,
    pub destroyed: bool,
    /// Since the request.
    pub elapsed: Duration,
}

/// What to do next while waiting for USE_SCENE.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneWaitStep {
    /// Poll again.
    Wait,
    /// Create the OpenXR instance now, for this reason.
    Start(SceneStart),
    /// The activity was destroyed: end without starting OpenXR.
    Quit,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneStart {
    Granted,
    /// Not asked for (the request failed): nothing to wait for.
    NotAsked,
    /// The dialog was answered without granting it.
    Answered,
    /// No dialog came up: denied for good ("don't ask again") or not declared in
    /// the manifest — the system answers those at once, without a dialog.
    NoDialog,
    /// The dialog stayed up past `SceneWait::LIMIT`.
    TimedOut,
}

impl SceneWait {
    /// A dialog that has not come up by then will not come (the system shows it
    /// within a frame or two of the request; a denial for good shows none).
    pub const DIALOG_APPEARS: Duration = Duration::from_secs(5);
    /// The longest the app waits on an open dialog. Longer than the 20 s a quick
    /// reader needs: starting before the answer costs the headset's depth for the
    /// whole session (Meta's warning above), waiting costs nothing while the user
    /// reads; but an app must not hang unseen forever behind a dialog left open.
    pub const LIMIT: Duration = Duration::from_secs(60);

    /// Fold one activity event in: coming back counts only after leaving (the
    /// activity's first resume and focus arrive after the request, before any
    /// dialog).
    pub fn on_event(&mut self, e: ActivityEvent) {
        match e {
            ActivityEvent::Left => self.left = true,
            ActivityEvent::Returned => self.returned |= self.left,
            ActivityEvent::Destroyed => self.destroyed = true,
        }
    }

    /// Whether to keep waiting (see `SceneStart` for each reason to stop).
    pub fn step(&self) -> SceneWaitStep {
        if self.destroyed {
            SceneWaitStep::Quit
        } else if self.granted {
            SceneWaitStep::Start(SceneStart::Granted)
        } else if !self.asked {
            SceneWaitStep::Start(SceneStart::NotAsked)
        } else if self.returned {
            SceneWaitStep::Start(SceneStart::Answered)
        } else if !self.left && self.elapsed >= Self::DIALOG_APPEARS {
            SceneWaitStep::Start(SceneStart::NoDialog)
        } else if self.elapsed >= Self::LIMIT {
            SceneWaitStep::Start(SceneStart::TimedOut)
        } else {
            SceneWaitStep::Wait
        }
    }
}

/// When to reopen the passthrough camera after it was disconnected (another app
/// or the system took it) or hit a device error: 1 s after the first loss,
/// doubling to 30 s while it keeps failing; a camera that streamed for a minute
/// had recovered, so its next loss starts again at 1 s. Why reopen at all: a
/// disconnected ACameraDevice stays dead (Android's `onDisconnected`: "the camera
/// device is no longer available for use"), and calibration should resume when
/// the camera comes back, not wait for the app's next start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReopenBackoff {
    failures: u32,
}

impl ReopenBackoff {
    pub const FIRST: Duration = Duration::from_secs(1);
    pub const MAX: Duration = Duration::from_secs(30);
    /// Streaming this long means the camera had recovered.
    pub const RECOVERED: Duration = Duration::from_secs(60);

    /// The camera was lost, or failed to open, after streaming for `streamed`
    /// (zero when it never opened): how long to wait before the next try.
    pub fn lost(&mut self, streamed: Duration) -> Duration {
        if streamed >= Self::RECOVERED {
            self.failures = 0;
        }
        let delay = Self::FIRST.saturating_mul(1u32 << self.failures.min(16)).min(Self::MAX);
        self.failures = self.failures.saturating_add(1);
        delay
    }
}

#[cfg(test)]
mod tests {
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
        assert!(matches!(
            a.assemble(&short, 4_000_000_000, &bare(4_000_000_000)),
            Err(CameraError::Yuv { index: 3, .. })
        ));
        // A refused frame does not move the time reference: the next one passes.
        assert_eq!(a.assemble(&img, 3_100_000_000, &bare(3_100_000_000)).unwrap().frame.index, 4);
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

    /// Either camera permission opens the passthrough camera; the pair is asked for
    /// only while neither is granted.
    #[test]
    fn either_camera_permission_suffices() {
        const SCENE: &str = "com.oculus.permission.USE_SCENE";
        let states = |camera: bool, headset: bool, scene: bool| {
            [(CAMERA_PERMISSION, camera), (HEADSET_CAMERA_PERMISSION, headset), (SCENE, scene)]
        };
        assert!(camera_permitted(&states(true, false, false)));
        assert!(camera_permitted(&states(false, true, false)));
        assert!(!camera_permitted(&states(false, false, true)));
        assert_eq!(
            permissions_to_request(&states(false, false, false)),
            [CAMERA_PERMISSION, HEADSET_CAMERA_PERMISSION, SCENE]
        );
        assert_eq!(permissions_to_request(&states(false, true, false)), [SCENE]);
        assert_eq!(permissions_to_request(&states(true, false, true)), Vec::<&str>::new());
    }

    /// The wait for USE_SCENE before the OpenXR instance: over at once when granted
    /// or not asked for; over when the dialog was answered (the activity left and
    /// came back); a dialog that never comes is waited for `DIALOG_APPEARS`, an
    /// open one up to `LIMIT`; Destroy ends the app from any state.
    #[test]
    fn scene_permission_wait() {
        let secs = Duration::from_secs;
        let asked = SceneWait { asked: true, ..Default::default() };
        assert_eq!(asked.step(), SceneWaitStep::Wait);
        assert_eq!(SceneWait { granted: true, ..asked }.step(), SceneWaitStep::Start(SceneStart::Granted));
        assert_eq!(SceneWait::default().step(), SceneWaitStep::Start(SceneStart::NotAsked));
        // The activity's own first resume, before any dialog, is not an answer.
        let mut w = asked;
        w.on_event(ActivityEvent::Returned);
        assert_eq!(w.step(), SceneWaitStep::Wait);
        w.on_event(ActivityEvent::Left);
        w.elapsed = secs(30);
        assert_eq!(w.step(), SceneWaitStep::Wait, "the dialog is up: the user is reading");
        w.on_event(ActivityEvent::Returned);
        assert_eq!(w.step(), SceneWaitStep::Start(SceneStart::Answered));
        // No dialog: the system answered at once.
        let w = SceneWait { elapsed: SceneWait::DIALOG_APPEARS - Duration::from_millis(100), ..asked };
        assert_eq!(w.step(), SceneWaitStep::Wait);
        let w = SceneWait { elapsed: SceneWait::DIALOG_APPEARS, ..asked };
        assert_eq!(w.step(), SceneWaitStep::Start(SceneStart::NoDialog));
        // A dialog left open.
        let w = SceneWait { left: true, elapsed: SceneWait::LIMIT, ..asked };
        assert_eq!(w.step(), SceneWaitStep::Start(SceneStart::TimedOut));
        let mut w = SceneWait { granted: true, ..asked };
        w.on_event(ActivityEvent::Destroyed);
        assert_eq!(w.step(), SceneWaitStep::Quit);
    }

    /// 1, 2, 4, 8, 16, 30, 30 s while the camera keeps failing; a camera that
    /// streamed for a minute starts again at 1 s.
    #[test]
    fn reopen_backoff_doubles_to_thirty_seconds() {
        let mut b = ReopenBackoff::default();
        let delays: Vec<u64> = (0..7).map(|_| b.lost(Duration::from_secs(2)).as_secs()).collect();
        assert_eq!(delays, [1, 2, 4, 8, 16, 30, 30]);
        for _ in 0..100 {
            assert_eq!(b.lost(Duration::ZERO), ReopenBackoff::MAX, "no overflow");
        }
        assert_eq!(b.lost(ReopenBackoff::RECOVERED), ReopenBackoff::FIRST);
        assert_eq!(b.lost(Duration::ZERO).as_secs(), 2);
    }
}
