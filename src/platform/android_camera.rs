//! The Quest passthrough camera through the Camera2 NDK (`libcamera2ndk`) and an
//! AImageReader (`libmediandk`, YUV_420_888): the cameras described (what
//! `analysis::camera::choose_camera` decides on), the chosen one opened with a
//! repeating preview request whose images reach a handler together with their
//! capture results (SENSOR_TIMESTAMP, SENSOR_EXPOSURE_TIME, ROLLING_SHUTTER_SKEW,
//! FRAME_DURATION): an image whose result has not arrived yet is held until it
//! does (`analysis::camera::CapturePairing`). A disconnect or device error marks
//! the camera lost; its owner reopens it (`analysis::camera::ReopenBackoff`).
//! Raw NDK calls only; every decision is in `analysis::camera`, tested on desktop.
//! Compiled for Android only and never run here (no headset): what it must do on
//! a device is in docs/xr.md's "not verified" list.
//!
//! Teardown (`Drop for PassthroughCamera`, in this order): stop the repeating
//! request; close the capture session; free the request, the output target, the
//! session output container and the session output; close the device — the NDK
//! closes it synchronously, after which no device or capture callback runs (so
//! their context may go); drop the images held for their results and refuse new
//! ones (they must not outlive their reader); delete the image reader (no buffer
//! can be queued into it any more, and its listener has returned); drop the
//! callback context last.
#![allow(unsafe_code)]

use crate::analysis::camera::{CameraChoice, CameraDescription, CapturePairing, CaptureResult, VendorValue};
use crate::image::yuv::{Yuv420, YuvPlane};
use ndk::media::image_reader::{AcquireResult, Image, ImageFormat, ImageReader};
use ndk_sys as sys;
use std::ffi::{c_void, CStr, CString};
use std::ptr::null_mut;
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

// ndk-sys declares the Camera2 functions but links no library for them.
#[link(name = "camera2ndk")]
extern "C" {}

/// `ACAMERA_SENSOR_INFO_TIMESTAMP_SOURCE_REALTIME`.
const TIMESTAMP_SOURCE_REALTIME: u8 = 1;
/// `ACAMERA_SCALER_AVAILABLE_STREAM_CONFIGURATIONS_OUTPUT`.
const STREAM_OUTPUT: i32 = 0;
/// Images the reader may have out at once: those held for their capture results,
/// and two for `AImageReader_acquireLatestImage` (it acquires the next image
/// before releasing the one it skips).
const MAX_IMAGES: i32 = CapturePairing::<HeldImage>::HELD as i32 + 2;

fn check(status: sys::camera_status_t, what: &str) -> Result<(), String> {
    if status == sys::camera_status_t::ACAMERA_OK {
        Ok(())
    } else {
        Err(format!("{what} failed (camera_status_t {})", status.0))
    }
}

/// One metadata entry, or None when absent or of another type/length.
///
/// SAFETY (callers): `meta` is a live ACameraMetadata.
unsafe fn entry(
    meta: *const sys::ACameraMetadata,
    tag: sys::acamera_metadata_tag,
) -> Option<sys::ACameraMetadata_const_entry> {
    let mut e = std::mem::MaybeUninit::<sys::ACameraMetadata_const_entry>::zeroed();
    // SAFETY: `meta` is live (caller), `e` a valid out pointer.
    let status = unsafe { sys::ACameraMetadata_getConstEntry(meta, tag.0, e.as_mut_ptr()) };
    // SAFETY: written by a successful call.
    (status == sys::camera_status_t::ACAMERA_OK).then(|| unsafe { e.assume_init() })
}

macro_rules! values {
    ($name:ident, $field:ident, $t:ty, $type_tag:expr) => {
        /// The entry's values (copied out of the metadata, which owns them).
        ///
        /// SAFETY (callers): `meta` is a live ACameraMetadata.
        unsafe fn $name(meta: *const sys::ACameraMetadata, tag: sys::acamera_metadata_tag) -> Vec<$t> {
            // SAFETY: forwarded from the caller.
            match unsafe { entry(meta, tag) } {
                Some(e) if e.type_ as u32 == $type_tag as u32 && e.count > 0 => {
                    // SAFETY: the entry's union member of its declared type points
                    // to `count` values owned by `meta`, live for this call.
                    unsafe { std::slice::from_raw_parts(e.data.$field, e.count as usize) }.to_vec()
                }
                _ => vec![],
            }
        }
    };
}
values!(u8s, u8_, u8, sys::ACAMERA_TYPE_BYTE);
values!(i32s, i32_, i32, sys::ACAMERA_TYPE_INT32);
values!(i64s, i64_, i64, sys::ACAMERA_TYPE_INT64);
values!(f32s, f, f32, sys::ACAMERA_TYPE_FLOAT);

/// Meta's vendor keys of one camera as JNI found them: (position, source); None
/// where the camera lists no such key.
pub type MetaKeys = (Option<VendorValue>, Option<VendorValue>);

/// The camera service (`ACameraManager`).
pub struct CameraManager(*mut sys::ACameraManager);

impl CameraManager {
    pub fn new() -> Result<Self, String> {
        // SAFETY: no preconditions; null on failure.
        let m = unsafe { sys::ACameraManager_create() };
        if m.is_null() {
            return Err("ACameraManager_create returned null".into());
        }
        Ok(Self(m))
    }

    /// Every camera as `choose_camera` needs it; `vendor_keys(id)` reads Meta's
    /// position and source keys (CameraCharacteristics over JNI: the NDK cannot
    /// look up a vendor tag by name).
    pub fn describe(&self, vendor_keys: &mut dyn FnMut(&str) -> MetaKeys) -> Result<Vec<CameraDescription>, String> {
        let mut list: *mut sys::ACameraIdList = null_mut();
        // SAFETY: a live manager and a valid out pointer.
        check(unsafe { sys::ACameraManager_getCameraIdList(self.0, &mut list) }, "ACameraManager_getCameraIdList")?;
        let mut ids = vec![];
        // SAFETY: a successful call returned a list of `numCameras` NUL-terminated
        // ids, valid until deleteCameraIdList.
        unsafe {
            for i in 0..(*list).numCameras.max(0) as usize {
                ids.push(CStr::from_ptr(*(*list).cameraIds.add(i)).to_string_lossy().into_owned());
            }
            sys::ACameraManager_deleteCameraIdList(list);
        }
        let mut out = vec![];
        for id in ids {
            let cid = CString::new(id.clone()).map_err(|_| format!("camera id {id:?} has a NUL"))?;
            let mut meta: *mut sys::ACameraMetadata = null_mut();
            // SAFETY: live manager, NUL-terminated id, valid out pointer.
            let status = unsafe { sys::ACameraManager_getCameraCharacteristics(self.0, cid.as_ptr(), &mut meta) };
            if let Err(e) = check(status, &format!("characteristics of camera {id}")) {
                log::warn!("{e}: camera skipped");
                continue;
            }
            use sys::acamera_metadata_tag as t;
            // SAFETY: `meta` is live until ACameraMetadata_free below.
            let d = unsafe {
                let array = i32s(meta, t::ACAMERA_SENSOR_INFO_ACTIVE_ARRAY_SIZE);
                // The intrinsic calibration's own frame (see analysis::camera).
                let pre = i32s(meta, t::ACAMERA_SENSOR_INFO_PRE_CORRECTION_ACTIVE_ARRAY_SIZE);
                let calib = f32s(meta, t::ACAMERA_LENS_INTRINSIC_CALIBRATION);
                let pose_t = f32s(meta, t::ACAMERA_LENS_POSE_TRANSLATION);
                let pose_r = f32s(meta, t::ACAMERA_LENS_POSE_ROTATION);
                let configs = i32s(meta, t::ACAMERA_SCALER_AVAILABLE_STREAM_CONFIGURATIONS);
                let yuv = sys::AIMAGE_FORMATS::AIMAGE_FORMAT_YUV_420_888.0 as i32;
                let yuv_sizes = configs
                    .chunks_exact(4)
                    .filter(|c| c[0] == yuv && c[3] == STREAM_OUTPUT && c[1] > 0 && c[2] > 0)
                    .map(|c| (c[1] as u32, c[2] as u32))
                    .collect();
                let (meta_position, meta_source) = vendor_keys(&id);
                CameraDescription {
                    id: id.clone(),
                    meta_position,
                    meta_source,
                    pre_correction_array: pre.get(..4).map(|a| [a[0], a[1], a[2], a[3]]),
                    active_array: array.get(..4).map(|a| [a[0], a[1], a[2], a[3]]),
                    intrinsic_calibration: calib.get(..5).map(|c| [c[0], c[1], c[2], c[3], c[4]]),
                    lens_pose_translation_m: pose_t.get(..3).map(|v| [v[0], v[1], v[2]]),
                    lens_pose_rotation: pose_r.get(..4).map(|v| [v[0], v[1], v[2], v[3]]),
                    lens_pose_reference: u8s(meta, t::ACAMERA_LENS_POSE_REFERENCE).first().copied(),
                    yuv_sizes,
                    timestamp_realtime: u8s(meta, t::ACAMERA_SENSOR_INFO_TIMESTAMP_SOURCE).first()
                        == Some(&TIMESTAMP_SOURCE_REALTIME),
                }
            };
            // SAFETY: allocated by getCameraCharacteristics, not used after.
            unsafe { sys::ACameraMetadata_free(meta) };
            out.push(d);
        }
        Ok(out)
    }
}

impl Drop for CameraManager {
    fn drop(&mut self) {
        // SAFETY: created by ACameraManager_create; every camera opened through it
        // is closed first (PassthroughCamera borrows the manager).
        unsafe { sys::ACameraManager_delete(self.0) };
    }
}

/// An acquired image held (in `Shared::pairing`) until its capture result comes.
struct HeldImage(Image);

// SAFETY: an AImage is a plain NDK object, not tied to the thread that acquired
// it; a held one is touched only under `Shared::pairing`'s lock or by the one
// thread that took it out of it, never by two threads at once.
unsafe impl Send for HeldImage {}

/// What the NDK's callback threads share with the camera's owner.
#[derive(Default)]
struct Shared {
    /// Images waiting for their capture results, and results for their images.
    pairing: Mutex<CapturePairing<HeldImage>>,
    /// The newest SENSOR_EXPOSURE_TIME seen (0: none).
    last_exposure_ns: AtomicI64,
    failures: AtomicU64,
    /// Images handed to the handler.
    images: AtomicU64,
    disconnected: AtomicBool,
    /// The device error `onError` reported (0: none).
    error: AtomicI32,
}

/// What the camera hands its user per image: the planes (borrowed from the
/// AImage for the call), its SENSOR_TIMESTAMP, and its capture result (an image
/// waits for its result; one whose result never comes is dropped).
pub type ImageHandler = Box<dyn FnMut(&Yuv420<'_>, i64, CaptureResult) + Send>;

/// The opened passthrough camera streaming into an image reader. See the
/// module doc for the teardown order.
pub struct PassthroughCamera<'m> {
    _manager: &'m CameraManager,
    device: *mut sys::ACameraDevice,
    session: *mut sys::ACameraCaptureSession,
    request: *mut sys::ACaptureRequest,
    target: *mut sys::ACameraOutputTarget,
    container: *mut sys::ACaptureSessionOutputContainer,
    output: *mut sys::ACaptureSessionOutput,
    reader: Option<ImageReader>,
    device_callbacks: Box<sys::ACameraDevice_StateCallbacks>,
    session_callbacks: Box<sys::ACameraCaptureSession_stateCallbacks>,
    capture_callbacks: Box<sys::ACameraCaptureSession_captureCallbacks>,
    shared: Arc<Shared>,
}

// The device callbacks only mark the camera lost: the NDK's device is unusable
// after either (ACameraDevice_StateCallbacks: onDisconnected "the camera device is
// no longer available for use"; onError "a camera device has encountered a
// serious error"), and closing and reopening belong to its owner's thread
// (`PassthroughCamera::lost`, then drop and `open` again after a backoff).
unsafe extern "C" fn on_disconnected(context: *mut c_void, _device: *mut sys::ACameraDevice) {
    // SAFETY: `context` is the camera's `Shared`, alive until after the device closes.
    let shared = unsafe { &*(context as *const Shared) };
    shared.disconnected.store(true, Ordering::SeqCst);
    log::warn!("camera: disconnected (another app or the system took it)");
}

unsafe extern "C" fn on_error(context: *mut c_void, _device: *mut sys::ACameraDevice, error: std::os::raw::c_int) {
    // SAFETY: as in `on_disconnected`.
    let shared = unsafe { &*(context as *const Shared) };
    shared.error.store(error, Ordering::SeqCst);
    shared.disconnected.store(true, Ordering::SeqCst);
    log::error!("camera: device error {error}");
}

unsafe extern "C" fn on_capture_completed(
    context: *mut c_void,
    _session: *mut sys::ACameraCaptureSession,
    _request: *mut sys::ACaptureRequest,
    result: *const sys::ACameraMetadata,
) {
    // SAFETY: as in `on_disconnected`; `result` is live for the callback.
    let (shared, r) = unsafe {
        use sys::acamera_metadata_tag as t;
        let Some(&ts) = i64s(result, t::ACAMERA_SENSOR_TIMESTAMP).first() else { return };
        (
            &*(context as *const Shared),
            CaptureResult {
                sensor_timestamp_ns: ts,
                exposure_ns: i64s(result, t::ACAMERA_SENSOR_EXPOSURE_TIME).first().copied(),
                rolling_skew_ns: i64s(result, t::ACAMERA_SENSOR_ROLLING_SHUTTER_SKEW).first().copied(),
                frame_duration_ns: i64s(result, t::ACAMERA_SENSOR_FRAME_DURATION).first().copied(),
            },
        )
    };
    if let Some(e) = r.exposure_ns {
        shared.last_exposure_ns.store(e, Ordering::Relaxed);
    }
    shared.pairing.lock().unwrap_or_else(|p| p.into_inner()).result(r);
}

unsafe extern "C" fn on_capture_failed(
    context: *mut c_void,
    _session: *mut sys::ACameraCaptureSession,
    _request: *mut sys::ACaptureRequest,
    _failure: *mut sys::ACameraCaptureFailure,
) {
    // SAFETY: as in `on_disconnected`.
    let shared = unsafe { &*(context as *const Shared) };
    shared.failures.fetch_add(1, Ordering::Relaxed);
}

impl<'m> PassthroughCamera<'m> {
    /// Open `choice` and start streaming its YUV_420_888 images into `handler`
    /// (called on the image reader's thread; it should return quickly when it has
    /// no use for the image).
    pub fn open(manager: &'m CameraManager, choice: &CameraChoice, mut handler: ImageHandler) -> Result<Self, String> {
        let shared = Arc::new(Shared::default());
        let ctx = Arc::as_ptr(&shared) as *mut c_void;
        let mut cam = PassthroughCamera {
            _manager: manager,
            device: null_mut(),
            session: null_mut(),
            request: null_mut(),
            target: null_mut(),
            container: null_mut(),
            output: null_mut(),
            reader: None,
            device_callbacks: Box::new(sys::ACameraDevice_StateCallbacks {
                context: ctx,
                onDisconnected: Some(on_disconnected),
                onError: Some(on_error),
            }),
            session_callbacks: Box::new(sys::ACameraCaptureSession_stateCallbacks {
                context: ctx,
                onClosed: None,
                onReady: None,
                onActive: None,
            }),
            capture_callbacks: Box::new(sys::ACameraCaptureSession_captureCallbacks {
                context: ctx,
                onCaptureStarted: None,
                onCaptureProgressed: None,
                onCaptureCompleted: Some(on_capture_completed),
                onCaptureFailed: Some(on_capture_failed),
                onCaptureSequenceCompleted: None,
                onCaptureSequenceAborted: None,
                onCaptureBufferLost: None,
            }),
            shared: shared.clone(),
        };
        // From here on an early return drops `cam`, which frees what was made.
        let (w, h) = (choice.size.0 as i32, choice.size.1 as i32);
        let mut reader = ImageReader::new(w, h, ImageFormat::YUV_420_888, MAX_IMAGES)
            .map_err(|e| format!("AImageReader {w}×{h} YUV_420_888: {e}"))?;
        let listener_shared = shared.clone();
        reader
            .set_image_listener(Box::new(move |r: &ImageReader| {
                let image = match r.acquire_latest_image() {
                    Ok(AcquireResult::Image(i)) => i,
                    Ok(_) => return,
                    Err(e) => {
                        log::warn!("camera: acquiring an image failed: {e}");
                        return;
                    }
                };
                // AImage_getTimestamp is the image's SENSOR_TIMESTAMP: the key its
                // capture result is matched by.
                let Ok(timestamp_ns) = image.timestamp() else {
                    log::warn!("camera: an image without a timestamp was skipped");
                    return;
                };
                // The image waits for its capture result (it may come later, on the
                // capture callback's thread); those whose results are in come out,
                // oldest first. Converted outside the lock.
                let ready = listener_shared
                    .pairing
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .image(timestamp_ns, HeldImage(image));
                for paired in ready {
                    let image = &paired.image.0;
                    let yuv = (|| {
                        let (w, h) = (image.width().ok()? as usize, image.height().ok()? as usize);
                        let plane = |i: i32| -> Option<YuvPlane<'_>> {
                            Some(YuvPlane {
                                data: image.plane_data(i).ok()?,
                                row_stride: image.plane_row_stride(i).ok()? as usize,
                                pixel_stride: image.plane_pixel_stride(i).ok()? as usize,
                            })
                        };
                        Some(Yuv420 { width: w, height: h, y: plane(0)?, u: plane(1)?, v: plane(2)? })
                    })();
                    let Some(yuv) = yuv else {
                        log::warn!("camera: an image without readable planes was skipped");
                        continue;
                    };
                    listener_shared.images.fetch_add(1, Ordering::Relaxed);
                    handler(&yuv, paired.sensor_timestamp_ns, paired.result);
                }
            }))
            .map_err(|e| format!("AImageReader_setImageListener: {e}"))?;
        let window = reader.window().map_err(|e| format!("AImageReader_getWindow: {e}"))?;
        let anw = window.ptr().as_ptr() as *mut sys::ACameraWindowType;
        cam.reader = Some(reader);

        let id = CString::new(choice.id.clone()).map_err(|_| format!("camera id {:?} has a NUL", choice.id))?;
        // SAFETY (this block): every pointer passed is live — the manager (borrowed
        // for 'm), the id, the boxed callbacks (owned by `cam`, freed after the
        // device closes), the reader's window (kept by the reader) — and every out
        // pointer is a field of `cam`, freed by its Drop when non-null.
        unsafe {
            check(
                sys::ACameraManager_openCamera(manager.0, id.as_ptr(), &mut *cam.device_callbacks, &mut cam.device),
                &format!("opening camera {}", choice.id),
            )?;
            check(
                sys::ACaptureSessionOutputContainer_create(&mut cam.container),
                "ACaptureSessionOutputContainer_create",
            )?;
            check(sys::ACaptureSessionOutput_create(anw, &mut cam.output), "ACaptureSessionOutput_create")?;
            check(
                sys::ACaptureSessionOutputContainer_add(cam.container, cam.output),
                "ACaptureSessionOutputContainer_add",
            )?;
            check(
                sys::ACameraDevice_createCaptureRequest(
                    cam.device,
                    sys::ACameraDevice_request_template::TEMPLATE_PREVIEW,
                    &mut cam.request,
                ),
                "ACameraDevice_createCaptureRequest",
            )?;
            check(sys::ACameraOutputTarget_create(anw, &mut cam.target), "ACameraOutputTarget_create")?;
            check(sys::ACaptureRequest_addTarget(cam.request, cam.target), "ACaptureRequest_addTarget")?;
            check(
                sys::ACameraDevice_createCaptureSession(
                    cam.device,
                    cam.container,
                    &*cam.session_callbacks,
                    &mut cam.session,
                ),
                "ACameraDevice_createCaptureSession",
            )?;
            let mut requests = [cam.request];
            check(
                sys::ACameraCaptureSession_setRepeatingRequest(
                    cam.session,
                    &mut *cam.capture_callbacks,
                    1,
                    requests.as_mut_ptr(),
                    null_mut(),
                ),
                "ACameraCaptureSession_setRepeatingRequest",
            )?;
        }
        // The reader keeps its window (ANativeWindow reference) alive itself.
        drop(window);
        Ok(cam)
    }

    /// The newest SENSOR_EXPOSURE_TIME reported (ns), if any.
    pub fn last_exposure_ns(&self) -> Option<i64> {
        Some(self.shared.last_exposure_ns.load(Ordering::Relaxed)).filter(|&e| e > 0)
    }

    /// Captures the camera reported as failed.
    pub fn failures(&self) -> u64 {
        self.shared.failures.load(Ordering::Relaxed)
    }

    /// Images handed to the handler so far.
    pub fn images(&self) -> u64 {
        self.shared.images.load(Ordering::Relaxed)
    }

    /// Images dropped because their capture results never came.
    pub fn dropped_images(&self) -> u64 {
        self.shared.pairing.lock().unwrap_or_else(|p| p.into_inner()).dropped()
    }

    /// The camera was disconnected or hit a device error (`error`): drop it and
    /// reopen.
    pub fn lost(&self) -> bool {
        self.shared.disconnected.load(Ordering::SeqCst)
    }

    /// The device error `onError` reported (ACameraDevice ERROR_* codes), if any.
    pub fn error(&self) -> Option<i32> {
        Some(self.shared.error.load(Ordering::SeqCst)).filter(|&e| e != 0)
    }
}

impl Drop for PassthroughCamera<'_> {
    fn drop(&mut self) {
        // SAFETY: each handle was created by the matching NDK call (non-null) and is
        // released once, in the order of the module doc.
        unsafe {
            if !self.session.is_null() {
                sys::ACameraCaptureSession_stopRepeating(self.session);
                sys::ACameraCaptureSession_close(self.session);
            }
            if !self.request.is_null() {
                sys::ACaptureRequest_free(self.request);
            }
            if !self.target.is_null() {
                sys::ACameraOutputTarget_free(self.target);
            }
            if !self.container.is_null() {
                sys::ACaptureSessionOutputContainer_free(self.container);
            }
            if !self.output.is_null() {
                sys::ACaptureSessionOutput_free(self.output);
            }
            if !self.device.is_null() {
                sys::ACameraDevice_close(self.device);
            }
        }
        // Now no device or capture callback can run. The held images go before their
        // reader, and the listener (still possibly running until the reader is
        // deleted) holds no new one; then the reader, then the callbacks' context.
        self.shared.pairing.lock().unwrap_or_else(|p| p.into_inner()).close();
        self.reader = None;
    }
}
