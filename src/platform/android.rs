//! The Quest app's entry point (`android_main`, android-activity's NativeActivity
//! glue): logging to logcat, runtime permissions, assets through the
//! AssetManager, the activity lifecycle driving the OpenXR frame loop of
//! `xr::run` on its own thread, and live calibration: the passthrough camera
//! (`android_camera`) feeding the calibration worker, whose models the frame loop
//! renders with. The spatial-data permission is asked for and answered before the
//! OpenXR instance is created (Meta's XrPassthroughOcclusion sample: the app "will
//! not function correctly" otherwise). Calibration starts as soon as a camera
//! permission is granted — during boundary setup, the worker's start-up burst —
//! and refreshes from then on, reopening the camera after a disconnect; the last
//! model is stored in the app's internal storage and is the next start's first
//! model. With the spatial-data permission the frame loop also reads the
//! headset's depth (XR_META_environment_depth), which the camera thread
//! reprojects into each frame it submits (`analysis::headset_depth`): metric depth
//! for δ(Z) and pose + depth flow. Wiring only: every decision it relies on is
//! tested on desktop; this file itself has not run on a headset (no device here).
#![allow(unsafe_code)]

use crate::analysis::camera::{
    camera_pose, choose_camera, forward_camera, head_from_eyes, CameraSide, CaptureResult, ExposureCheck,
    FrameAssembler, VendorValue, META_POSITION_KEY, META_SOURCE_KEY, PASSTHROUGH_SIZE,
};
use crate::analysis::camera_access::{
    camera_permitted, permissions_to_request, ActivityEvent, ReopenBackoff, SceneStart, SceneWait, SceneWaitStep,
    CAMERA_PERMISSION, HEADSET_CAMERA_PERMISSION,
};
use crate::analysis::headset_depth::HeadsetDepth;
use crate::analysis::timing::{ClockMap, ClockSample, TimedPose, TimestampSource};
use crate::android_camera::{CameraManager, PassthroughCamera};
use crate::image::yuv::{Yuv420, YuvMatrix, YuvRange};
use crate::io::recording::{RecordLimits, Recorder, RecordingInfo};
use crate::model::CameraModel;
use crate::panel::CalibrationStatus;
use crate::render::LayerSettings;
use crate::scene::Scene;
use crate::worker::{CalibrationTier, Calibrator, CalibratorConfig, ModelChannel, Providers, Worker};
use crate::xr::{self, EnvironmentDepth, FrameRecord, XrOptions};
use android_activity::{AndroidApp, MainEvent, PollEvent};
use glam::{Mat4, Quat, Vec3};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The permissions the camera path may use (manifest: uses-permission); either
/// suffices (`analysis::camera_access::camera_permitted`), asked for at start while
/// neither is granted. Without one the app renders with the stored or default
/// camera model.
const CAMERA_PERMISSIONS: [&str; 2] = [CAMERA_PERMISSION, HEADSET_CAMERA_PERMISSION];
/// Spatial data (XR_META_environment_depth): asked for with the camera's, and
/// waited for before the OpenXR instance is created (`SceneWait`); without it
/// calibration runs on image flow and blind DoF.
const SCENE_PERMISSION: &str = "com.oculus.permission.USE_SCENE";
/// How often the wait for the spatial-data permission looks at it again.
const SCENE_POLL: Duration = Duration::from_millis(100);
/// The display refresh rate asked of XR_FB_display_refresh_rate. Meta's
/// Passthrough Best Practices: "To maximize the smoothness of passthrough, it is
/// recommended to use a 72Hz refresh rate for your application. In flicker-free
/// lighting conditions, passthrough will synchronize the cameras with the
/// display" — and this app's content is composited over passthrough.
const DISPLAY_HZ: f32 = 72.0;
/// How often the frame loop reads the headset's depth back (Hz): the worker takes
/// a frame every few hundred ms, and `headset_depth::MAX_AGE_NS` allows 250 ms.
const ENV_DEPTH_HZ: f32 = 5.0;

#[no_mangle]
fn android_main(app: AndroidApp) {
    android_logger::init_once(
        android_logger::Config::default().with_tag("blind-augment").with_max_level(log::LevelFilter::Info),
    );
    log::info!("blind-augment {} starting", env!("CARGO_PKG_VERSION"));
    if let Err(e) = run(&app) {
        log::error!("blind-augment stopped: {e}");
    }
}

/// Read an APK asset (`assets/` of the repository, bundled by `cargo xtask apk`).
fn asset(app: &AndroidApp, name: &str) -> Result<Vec<u8>, String> {
    let cname = std::ffi::CString::new(name).map_err(|_| format!("asset name {name:?} has a NUL"))?;
    let mut a = app.asset_manager().open(&cname).ok_or_else(|| format!("asset {name} is not in the APK"))?;
    let bytes = a.buffer().map_err(|e| format!("asset {name}: {e}"))?;
    Ok(bytes.to_vec())
}

/// The APK's bundled scene (`BUNDLED_SCENE`, a `.glb` or a `.gltf` whose buffers
/// and images sit beside it in the assets), its notes logged.
fn bundled_scene(app: &AndroidApp) -> Result<Scene, String> {
    let dir = BUNDLED_SCENE.rsplit_once('/').map_or("", |(d, _)| d);
    let read = |rel: &str| asset(app, &if dir.is_empty() { rel.to_string() } else { format!("{dir}/{rel}") });
    let scene = Scene::from_bytes_with(&asset(app, BUNDLED_SCENE)?, BUNDLED_SCENE, &read).map_err(|e| e.to_string())?;
    for note in &scene.notes {
        log::warn!("{BUNDLED_SCENE}: {note}");
    }
    Ok(scene)
}

/// The scene the app shows, a path inside the APK's assets.
const BUNDLED_SCENE: &str = "toy.glb";

/// Ask for the camera and spatial-data permissions that are missing
/// (`permissions_to_request`; Activity.requestPermissions over JNI) and report
/// which are granted now and which were asked for; the answer comes later,
/// through the system dialog (NativeActivity has no onRequestPermissionsResult),
/// so `wait_for_scene_permission` and the camera path check again.
fn request_permissions(app: &AndroidApp) -> Result<Requested, jni::errors::Error> {
    use jni::objects::{JObject, JValue};
    use jni::{jni_sig, jni_str};
    with_activity(app, |env, activity| {
        let all = [CAMERA_PERMISSIONS[0], CAMERA_PERMISSIONS[1], SCENE_PERMISSION];
        let granted = permission_states(env, activity, &all)?;
        let missing = permissions_to_request(&granted);
        if !missing.is_empty() {
            let string_class = env.find_class(jni_str!("java/lang/String"))?;
            let names = env.new_object_array(missing.len() as i32, &string_class, JObject::null())?;
            for (i, p) in missing.iter().enumerate() {
                let name = env.new_string(p)?;
                names.set_element(env, i, &name)?;
            }
            env.call_method(
                activity,
                jni_str!("requestPermissions"),
                jni_sig!("([Ljava/lang/String;I)V"),
                &[JValue::Object(&names), JValue::Int(1)],
            )?;
        }
        Ok(Requested { granted, asked: missing })
    })
}

/// What `request_permissions` found and did.
struct Requested {
    /// Each permission and whether it was granted before asking.
    granted: Vec<(&'static str, bool)>,
    /// Those asked for.
    asked: Vec<&'static str>,
}

/// Each of `permissions` and whether it is granted now
/// (Activity.checkSelfPermission; PackageManager.PERMISSION_GRANTED = 0).
fn permission_states(
    env: &mut jni::Env,
    activity: &jni::objects::JObject,
    permissions: &[&'static str],
) -> Result<Vec<(&'static str, bool)>, jni::errors::Error> {
    use jni::objects::JValue;
    use jni::{jni_sig, jni_str};
    let mut states = vec![];
    for &p in permissions {
        let name = env.new_string(p)?;
        let state = env
            .call_method(
                activity,
                jni_str!("checkSelfPermission"),
                jni_sig!("(Ljava/lang/String;)I"),
                &[JValue::Object(&name)],
            )?
            .i()?;
        states.push((p, state == 0));
    }
    Ok(states)
}

/// The camera's nominal frame interval (Quest 3 passthrough: 30 Hz); the
/// calibrator's flow and λ are per this interval.
const FRAME_INTERVAL_S: f64 = 1.0 / 30.0;
/// Head poses and clock samples kept for the camera thread (90 Hz: 45 s of poses).
const MAX_HEADS: usize = 4096;
const MAX_CLOCKS: usize = 16;
/// Where the last calibrated model is kept between runs (internal storage).
const STORED_MODEL: &str = "camera.json";

/// What the frame loop hands the camera thread: head poses (`local_from_head`
/// at predicted display times, OpenXR VIEW space) and clock samples.
#[derive(Default)]
struct LiveInputs {
    heads: Mutex<VecDeque<(i64, Quat, Vec3)>>,
    clocks: Mutex<(VecDeque<ClockSample>, bool)>,
    /// The newest headset depth not yet taken by the camera thread.
    depth: Mutex<Option<Arc<EnvironmentDepth>>>,
    /// Record-button presses not yet acted on (the camera thread starts or stops
    /// the recording: the frame loop never touches storage).
    record_presses: std::sync::atomic::AtomicU32,
    /// A restart-calibration press not yet acted on.
    restart: AtomicBool,
    /// The status panel's camera and calibration lines (`panel::CalibrationStatus`),
    /// refreshed by the camera thread.
    status: Mutex<Vec<String>>,
}

impl LiveInputs {
    fn on_frame(&self, r: &FrameRecord) {
        for t in &r.pressed {
            if *t == crate::xr::Toggle::Record {
                self.record_presses.fetch_add(1, Ordering::SeqCst);
            }
            if *t == crate::xr::Toggle::RestartCalibration {
                self.restart.store(true, Ordering::SeqCst);
            }
        }
        // Untracked views are the last tracked ones shown again (FrameRecord::
        // views_tracked): they say nothing about where the head is at this frame's
        // time, and a pose track holding them would pair frames with wrong poses.
        if r.views_tracked {
            let (q, p) = head_from_eyes(
                [r.views[0].orientation, r.views[1].orientation],
                [r.views[0].position_m, r.views[1].position_m],
            );
            let mut heads = self.heads.lock().unwrap_or_else(|e| e.into_inner());
            if heads.len() == MAX_HEADS {
                heads.pop_front();
            }
            heads.push_back((r.predicted_display_time_ns, q, p));
        }
        if let Some(d) = &r.env_depth {
            *self.depth.lock().unwrap_or_else(|e| e.into_inner()) = Some(d.clone());
        }
        if let Some(c) = r.clock {
            let mut clocks = self.clocks.lock().unwrap_or_else(|e| e.into_inner());
            if clocks.0.len() == MAX_CLOCKS {
                clocks.0.pop_front();
            }
            clocks.0.push_back(c);
            clocks.1 = true;
        }
    }

    fn set_status(&self, lines: Vec<String>) {
        *self.status.lock().unwrap_or_else(|e| e.into_inner()) = lines;
    }

    fn status(&self) -> Vec<String> {
        self.status.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    fn take_depth(&self) -> Option<Arc<EnvironmentDepth>> {
        self.depth.lock().unwrap_or_else(|e| e.into_inner()).take()
    }

    fn take_heads(&self) -> Vec<(i64, Quat, Vec3)> {
        self.heads.lock().unwrap_or_else(|e| e.into_inner()).drain(..).collect()
    }

    /// A clock map from the recent samples, when a new one arrived.
    fn new_clock_map(&self) -> Option<ClockMap> {
        let mut clocks = self.clocks.lock().unwrap_or_else(|e| e.into_inner());
        if !std::mem::take(&mut clocks.1) {
            return None;
        }
        ClockMap::from_samples(clocks.0.make_contiguous()).map_err(|e| log::warn!("clock samples: {e}")).ok()
    }
}

/// Run `f` with the activity on a JNI-attached thread, clearing any Java
/// exception a call left pending (a failed call is an error, never a crash).
fn with_activity<T>(
    app: &AndroidApp,
    f: impl FnOnce(&mut jni::Env, &jni::objects::JObject) -> Result<T, jni::errors::Error>,
) -> Result<T, jni::errors::Error> {
    // SAFETY: android-activity's JavaVM pointer is valid while the app lives.
    let vm = unsafe { jni::JavaVM::from_raw(app.vm_as_ptr().cast()) };
    vm.attach_current_thread(|env| {
        // SAFETY: a live global reference to the activity (android-activity); the
        // JObject wrapper does not own it (deletes nothing on drop).
        let activity = unsafe { jni::objects::JObject::from_raw(env, app.activity_as_ptr().cast()) };
        let r = f(env, &activity);
        if r.is_err() {
            env.exception_clear();
        }
        r
    })
}

/// Longest recording an intent may ask for (s): about 2 GB of 16-bit frames at the
/// worker's rate; the free-space floor still applies.
const MAX_INTENT_RECORD_S: i32 = 300;

/// The launching intent's `record_s` extra (`adb shell am start -n
/// org.blindaugment.app/android.app.NativeActivity --ei record_s 20`): record that
/// many seconds of what calibration takes, from the first camera frames on, without
/// a controller (scripted data collection). None without it; values outside
/// 1..=MAX_INTENT_RECORD_S are refused by name.
fn intent_record_s(app: &AndroidApp) -> Result<Option<f64>, String> {
    use jni::objects::JValue;
    use jni::{jni_sig, jni_str};
    let value = with_activity(app, |env, activity| {
        let intent =
            env.call_method(activity, jni_str!("getIntent"), jni_sig!("()Landroid/content/Intent;"), &[])?.l()?;
        if intent.is_null() {
            return Ok(0);
        }
        let key = env.new_string("record_s")?;
        env.call_method(
            &intent,
            jni_str!("getIntExtra"),
            jni_sig!("(Ljava/lang/String;I)I"),
            &[JValue::Object(&key), JValue::Int(0)],
        )?
        .i()
    })
    .map_err(|e| format!("the launching intent is unreadable ({e})"))?;
    match value {
        0 => Ok(None),
        1..=MAX_INTENT_RECORD_S => Ok(Some(value as f64)),
        v => Err(format!("intent extra record_s = {v}: expected 1 to {MAX_INTENT_RECORD_S} seconds")),
    }
}

/// Whether a camera permission is granted now (either suffices:
/// `analysis::camera_access::camera_permitted`).
fn camera_permission(app: &AndroidApp) -> Result<bool, jni::errors::Error> {
    with_activity(app, |env, activity| Ok(camera_permitted(&permission_states(env, activity, &CAMERA_PERMISSIONS)?)))
}

/// Meta's vendor keys of camera `id` (position, source) as JNI finds them, for
/// `VendorValue::single_int` to read. How, after Meta's Unity sample
/// (`PassthroughCameraUtils.cs`): walk `CameraCharacteristics.getKeys()`, compare
/// each key's `getName()` with the key's name (ignoring case, as the sample does),
/// and `get()` the value with the key object the camera itself returned — its
/// Java class is the one the camera service gave the vendor tag (`byte[]` for
/// Meta's), where a key made here with a class of our choosing
/// (`new Key(name, Integer.class)`) fails to unmarshal a byte. The NDK cannot
/// look a vendor tag up by name. None where the key or the call is missing.
fn meta_keys(app: &AndroidApp, id: &str) -> crate::android_camera::MetaKeys {
    use jni::objects::{JString, JValue};
    use jni::{jni_sig, jni_str};
    let read = with_activity(app, |env, activity| {
        let service = env.new_string("camera")?;
        let manager = env
            .call_method(
                activity,
                jni_str!("getSystemService"),
                jni_sig!("(Ljava/lang/String;)Ljava/lang/Object;"),
                &[JValue::Object(&service)],
            )?
            .l()?;
        let jid = env.new_string(id)?;
        let chars = env
            .call_method(
                &manager,
                jni_str!("getCameraCharacteristics"),
                jni_sig!("(Ljava/lang/String;)Landroid/hardware/camera2/CameraCharacteristics;"),
                &[JValue::Object(&jid)],
            )?
            .l()?;
        let keys = env.call_method(&chars, jni_str!("getKeys"), jni_sig!("()Ljava/util/List;"), &[])?.l()?;
        let count = env.call_method(&keys, jni_str!("size"), jni_sig!("()I"), &[])?.i()?;
        let (mut position, mut source) = (None, None);
        for i in 0..count {
            // A frame per key: a camera lists a hundred or more, and each turn
            // makes a few local references.
            env.with_local_frame(8, |env| -> Result<(), jni::errors::Error> {
                let key = env
                    .call_method(&keys, jni_str!("get"), jni_sig!("(I)Ljava/lang/Object;"), &[JValue::Int(i)])?
                    .l()?;
                let name = env.call_method(&key, jni_str!("getName"), jni_sig!("()Ljava/lang/String;"), &[])?.l()?;
                let name = env.cast_local::<JString>(name)?.try_to_string(env)?;
                let slot = if name.eq_ignore_ascii_case(META_POSITION_KEY) {
                    &mut position
                } else if name.eq_ignore_ascii_case(META_SOURCE_KEY) {
                    &mut source
                } else {
                    return Ok(());
                };
                let value = env
                    .call_method(
                        &chars,
                        jni_str!("get"),
                        jni_sig!("(Landroid/hardware/camera2/CameraCharacteristics$Key;)Ljava/lang/Object;"),
                        &[JValue::Object(&key)],
                    )?
                    .l()?;
                *slot = Some(vendor_value(env, &value)?);
                Ok(())
            })?;
        }
        Ok((position, source))
    });
    read.unwrap_or_else(|e: jni::errors::Error| {
        log::warn!("camera {id}: Meta's vendor keys unreadable ({e})");
        (None, None)
    })
}

/// A vendor key's value by its Java class (see `VendorValue`): `byte[]`, `int[]`
/// and `Integer` read out, anything else named.
fn vendor_value(env: &mut jni::Env, value: &jni::objects::JObject) -> Result<VendorValue, jni::errors::Error> {
    use jni::objects::{JByteArray, JIntArray, JString};
    use jni::{jni_sig, jni_str};
    /// Longer arrays are not Meta's one-value keys: named, not read.
    const MAX_LEN: usize = 16;
    if value.is_null() {
        return Ok(VendorValue::Other("null".into()));
    }
    if env.is_instance_of(value, jni_str!("[B"))? {
        let array = env.as_cast::<JByteArray>(value)?;
        let len = array.len(env)?;
        if len > MAX_LEN {
            return Ok(VendorValue::Other(format!("byte[{len}]")));
        }
        let mut v = vec![0i8; len];
        array.get_region(env, 0, &mut v)?;
        return Ok(VendorValue::Bytes(v));
    }
    if env.is_instance_of(value, jni_str!("[I"))? {
        let array = env.as_cast::<JIntArray>(value)?;
        let len = array.len(env)?;
        if len > MAX_LEN {
            return Ok(VendorValue::Other(format!("int[{len}]")));
        }
        let mut v = vec![0i32; len];
        array.get_region(env, 0, &mut v)?;
        return Ok(VendorValue::Ints(v));
    }
    if env.is_instance_of(value, jni_str!("java/lang/Integer"))? {
        return Ok(VendorValue::Int(env.call_method(value, jni_str!("intValue"), jni_sig!("()I"), &[])?.i()?));
    }
    let class = env.call_method(value, jni_str!("getClass"), jni_sig!("()Ljava/lang/Class;"), &[])?.l()?;
    let name = env.call_method(&class, jni_str!("getName"), jni_sig!("()Ljava/lang/String;"), &[])?.l()?;
    Ok(VendorValue::Other(env.cast_local::<JString>(name)?.try_to_string(env)?))
}

/// Sleep `d`, or less when `stop` is set meanwhile.
fn sleep_unless(stop: &AtomicBool, d: Duration) {
    let until = Instant::now() + d;
    while !stop.load(Ordering::SeqCst) {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return;
        }
        std::thread::sleep(left.min(Duration::from_millis(200)));
    }
}

/// The camera → worker path: wait for a camera permission, choose and open the
/// passthrough camera, run the calibration worker on its frames until `stop`,
/// reopening the camera after each disconnect or device error
/// (`ReopenBackoff`).
fn calibrate_live(
    app: &AndroidApp,
    models: &ModelChannel,
    live: &Arc<LiveInputs>,
    stop: &AtomicBool,
) -> Result<(), String> {
    let mut told = false;
    loop {
        if stop.load(Ordering::SeqCst) {
            return Ok(());
        }
        match camera_permission(app) {
            Ok(true) => break,
            Ok(false) if !told => {
                log::info!("calibration waits for a camera permission (rendering with the current model)");
                live.set_status(vec!["!calibration waits for a camera permission (Settings → Apps)".into()]);
                told = true;
            }
            Ok(false) => {}
            Err(e) => return Err(format!("camera permissions unreadable ({e})")),
        }
        std::thread::sleep(Duration::from_secs(1));
    }
    let manager = CameraManager::new()?;
    let cameras = manager.describe(&mut |id| meta_keys(app, id))?;
    for c in &cameras {
        log::info!("camera {c:?}");
    }
    let choice = choose_camera(&cameras, CameraSide::Left, PASSTHROUGH_SIZE).map_err(|e| e.to_string())?;
    log::info!(
        "calibrating from camera {} ({:?}, {}×{}), intrinsics {:?}, head_from_camera {:?}",
        choice.id,
        choice.side,
        choice.size.0,
        choice.size.1,
        choice.intrinsics,
        choice.head_from_camera
    );
    for n in &choice.notes {
        log::warn!("camera {}: {n}", choice.id);
    }
    let tier = CalibrationTier::Fast;
    let calibrator =
        Calibrator::new(CalibratorConfig::new(tier, FRAME_INTERVAL_S, choice.intrinsics), Providers::for_tier(tier))
            .map_err(|e| e.to_string())?;
    let worker = Arc::new(Worker::spawn(calibrator, models.clone()).map_err(|e| format!("calibration thread: {e}"))?);
    let mut recorder = Recorder::new(
        app.external_data_path().map(|d| d.join("recordings")),
        RecordingInfo {
            device: "Meta Quest (Android)".into(),
            app_version: env!("CARGO_PKG_VERSION").into(),
            camera_id: choice.id.clone(),
            stream_size: choice.size,
            timestamps: format!("{:?} camera timestamps, mapped to XrTime", choice.timestamp_source),
            frame_interval_s: FRAME_INTERVAL_S,
            intrinsics: choice.intrinsics,
            tier: tier.name().into(),
        },
    );
    let head_from_camera: Mat4 = choice.head_from_camera.unwrap_or_else(forward_camera);
    // Camera2's YUV_420_888 is JFIF (BT.601, full range) unless a dataspace says
    // otherwise (the HAL's default for camera YUV output).
    let mut assembler = FrameAssembler::new(YuvMatrix::Bt601, YuvRange::Full, choice.timestamp_source);
    let realtime = choice.timestamp_source == TimestampSource::Realtime;
    // The headset's depth needs the camera's intrinsics and poses on the XR clock.
    let mut headset = choice.intrinsics.filter(|_| realtime).map(HeadsetDepth::new);
    let mut depth_note = Instant::now() - Duration::from_secs(60);
    let (w, l) = (worker.clone(), live.clone());
    // One handler for every opening of the camera (frame numbers, the clock map
    // and the headset depth carry over a reopen): shared, each opening's
    // ImageHandler a thin forwarder.
    type Handler = dyn FnMut(&Yuv420<'_>, i64, CaptureResult) + Send;
    let handle = move |yuv: &Yuv420<'_>, timestamp_ns: i64, result: CaptureResult| {
        if let Some(map) = l.new_clock_map() {
            assembler.set_clock(map);
        }
        // Frames and poses share a clock only once the clocks are mapped; before
        // that (the first rendered frame brings a sample) frames wait and the head
        // poses stay queued; a camera on an unknown clock calibrates without poses.
        if realtime && assembler.clock().is_none() {
            assembler.skip();
            return;
        }
        let heads = l.take_heads();
        let poses: Vec<TimedPose> = if realtime {
            heads.into_iter().map(|(t, q, p)| camera_pose(t, (q, p), &head_from_camera)).collect()
        } else {
            vec![]
        };
        if let Some(h) = headset.as_mut() {
            h.push_poses(&poses);
            if let Some(d) = l.take_depth() {
                h.set_views(d.acquired_at_ns, d.views.clone());
            }
        }
        if !w.wants_frame() {
            w.submit_poses(&poses);
            // Counted, so frame numbers are the camera's (the temporal stages
            // compare frames by their number distance).
            assembler.skip();
            return;
        }
        match assembler.assemble(yuv, timestamp_ns, &result) {
            Ok(mut a) => {
                if let (Some(h), true) = (headset.as_ref(), a.on_xr_clock) {
                    match h.depth_at((a.frame.t_s * 1e9).round() as i64) {
                        Ok(d) => a.frame.depth = Some(d),
                        // Why a frame goes without depth, at most every 10 s.
                        Err(e) if depth_note.elapsed() >= Duration::from_secs(10) => {
                            depth_note = Instant::now();
                            log::info!("camera frame {} without headset depth: {e}", a.frame.index);
                        }
                        Err(_) => {}
                    }
                }
                w.submit(a.frame, &poses)
            }
            Err(e) => log::warn!("camera: {e}"),
        }
    };
    let handler: Arc<Mutex<Box<Handler>>> = Arc::new(Mutex::new(Box::new(handle)));
    let mut backoff = ReopenBackoff::default();
    let mut last_report = Instant::now();
    let mut first = true;
    let mut panel = CalibrationStatus::new(tier.name());
    // A recording the launching intent asks for starts with the first streaming camera.
    let mut intent_recording = match intent_record_s(app) {
        Ok(r) => r,
        Err(e) => {
            log::warn!("{e}: not recording");
            None
        }
    };
    // Camera images delivered by the openings before the current one.
    let mut images_before = 0u64;
    while !stop.load(Ordering::SeqCst) {
        let forward = handler.clone();
        let opened = PassthroughCamera::open(
            &manager,
            &choice,
            Box::new(move |yuv: &Yuv420<'_>, timestamp_ns: i64, result: CaptureResult| {
                (forward.lock().unwrap_or_else(|e| e.into_inner()))(yuv, timestamp_ns, result)
            }),
        );
        let camera = match opened {
            Ok(c) => c,
            Err(e) => {
                let delay = backoff.lost(Duration::ZERO);
                log::warn!("camera {}: {e}: trying again in {delay:?} (the current model stays)", choice.id);
                live.set_status(vec![format!("!camera {}: {e}: trying again in {delay:.0?}", choice.id)]);
                sleep_unless(stop, delay);
                continue;
            }
        };
        let since = Instant::now();
        if first {
            log::info!("camera {} streaming: start-up calibration running", choice.id);
            first = false;
        } else {
            log::info!("camera {} reopened: calibration resumes", choice.id);
        }
        if let Some(max_s) = intent_recording.take() {
            log::info!("recording {max_s} s as the launching intent asks (record_s)");
            recorder.start_with(&worker, RecordLimits { max_s, ..RecordLimits::default() });
        }
        while !stop.load(Ordering::SeqCst) && !camera.lost() {
            std::thread::sleep(Duration::from_millis(200));
            recorder.poll(live.record_presses.swap(0, Ordering::SeqCst), &worker);
            live.set_status(panel.lines(
                Instant::now(),
                images_before + camera.images(),
                &worker.status(),
                recorder.current(),
            ));
            if live.restart.swap(false, Ordering::SeqCst) {
                log::info!("calibration restarted by the user: look around (start-up burst)");
                worker.restart();
            }
            if last_report.elapsed() >= Duration::from_secs(10) {
                last_report = Instant::now();
                let snapshot = models.latest();
                let check = ExposureCheck::new(camera.last_exposure_ns(), FRAME_INTERVAL_S, &snapshot.model);
                log::info!(
                    "model generation {}: {}; {} failed captures, {} images without their capture results",
                    snapshot.generation,
                    check.line(),
                    camera.failures(),
                    camera.dropped_images()
                );
            }
        }
        let (lost, error) = (camera.lost(), camera.error());
        // Streamed: only a camera that delivered images had recovered.
        let streamed = if camera.images() > 0 { since.elapsed() } else { Duration::ZERO };
        images_before += camera.images();
        drop(camera);
        if lost {
            let delay = backoff.lost(streamed);
            let why = error.map_or_else(|| "disconnected".to_string(), |e| format!("device error {e}"));
            log::warn!("camera {} {why}: reopening in {delay:?} (the current model stays)", choice.id);
            live.set_status(vec![format!("!camera {} {why}: reopening in {delay:.0?}", choice.id)]);
            sleep_unless(stop, delay);
        }
    }
    // The handler holds a worker reference: gone with the last camera's reader
    // and this one.
    drop(handler);
    recorder.poll(0, &worker);
    recorder.stop(&worker);
    match Arc::try_unwrap(worker) {
        Ok(w) => {
            let s = w.stop();
            log::info!(
                "calibration: {} frames submitted, {} dropped, {} fitted, {} models published, {} errors",
                s.submitted,
                s.dropped,
                s.processed,
                s.published.len(),
                s.errors.len()
            );
        }
        Err(_) => log::warn!("calibration worker still referenced at exit: not joined"),
    }
    Ok(())
}

/// The first model: the one stored by the last run, else the APK's
/// `camera.json`, else the default.
fn first_model(app: &AndroidApp) -> Result<CameraModel, String> {
    if let Some(path) = app.internal_data_path().map(|d| d.join(STORED_MODEL)) {
        match std::fs::read_to_string(&path) {
            Ok(text) => match CameraModel::from_json(&text) {
                Ok(m) => {
                    log::info!("camera model from the last run ({})", path.display());
                    return Ok(m);
                }
                Err(e) => log::warn!("{}: {e} (ignored)", path.display()),
            },
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => log::warn!("{}: {e} (ignored)", path.display()),
        }
    }
    match asset(app, "camera.json") {
        Ok(bytes) => CameraModel::from_json(&String::from_utf8_lossy(&bytes)).map_err(|e| format!("camera.json: {e}")),
        Err(_) => {
            log::info!("no stored camera model: using the default until calibration publishes one");
            Ok(crate::xr::default_camera())
        }
    }
}

/// Keep the newest calibrated model for the next run (written beside, then
/// renamed: a crash mid-write leaves the old one).
fn store_model(app: &AndroidApp, models: &ModelChannel) {
    let snapshot = models.latest();
    if snapshot.generation == 0 {
        return; // nothing calibrated this run
    }
    let Some(dir) = app.internal_data_path() else { return };
    let result = snapshot.model.to_json().map_err(|e| e.to_string()).and_then(|json| {
        let tmp = dir.join(format!("{STORED_MODEL}.tmp"));
        std::fs::write(&tmp, json).map_err(|e| e.to_string())?;
        std::fs::rename(&tmp, dir.join(STORED_MODEL)).map_err(|e| e.to_string())
    });
    match result {
        Ok(()) => log::info!("camera model generation {} stored for the next run", snapshot.generation),
        Err(e) => log::warn!("camera model not stored: {e}"),
    }
}

/// Wait for the answer to the spatial-data permission before the OpenXR instance
/// exists (see `SceneWait` for why and when the wait ends): checkSelfPermission
/// every `SCENE_POLL`, the activity's lifecycle events in between. Why the wait
/// ended; None: the activity was destroyed meanwhile.
fn wait_for_scene_permission(app: &AndroidApp, asked: bool) -> Option<SceneStart> {
    let start = Instant::now();
    let mut wait = SceneWait { asked, ..Default::default() };
    loop {
        wait.granted = match with_activity(app, |env, a| permission_states(env, a, &[SCENE_PERMISSION])) {
            Ok(states) => states.iter().all(|(_, g)| *g),
            Err(e) => {
                // Nothing to wait for that cannot be read.
                log::warn!("{SCENE_PERMISSION} unreadable ({e}): not waiting for it");
                wait.asked = false;
                false
            }
        };
        wait.elapsed = start.elapsed();
        match wait.step() {
            SceneWaitStep::Wait => {}
            SceneWaitStep::Start(why) => return Some(why),
            SceneWaitStep::Quit => return None,
        }
        app.poll_events(Some(SCENE_POLL), |event| {
            if let PollEvent::Main(main) = event {
                match main {
                    // The dialog is another activity over this one: it pauses this
                    // one or takes its focus, and gives them back when answered.
                    MainEvent::Pause | MainEvent::LostFocus => wait.on_event(ActivityEvent::Left),
                    MainEvent::Resume { .. } | MainEvent::GainedFocus => wait.on_event(ActivityEvent::Returned),
                    MainEvent::Destroy => wait.on_event(ActivityEvent::Destroyed),
                    _ => {}
                }
            }
        });
    }
}

fn run(app: &AndroidApp) -> Result<(), String> {
    let scene_asked = match request_permissions(app) {
        Ok(r) => {
            for &(p, granted) in &r.granted {
                if !granted {
                    log::info!("{p} not granted{}", if r.asked.contains(&p) { ": asked" } else { "" });
                }
            }
            r.asked.contains(&SCENE_PERMISSION)
        }
        Err(e) => {
            log::warn!("permissions could not be requested ({e}): rendering with the default camera model");
            false
        }
    };
    // Meta: USE_SCENE must be granted before the OpenXR instance is created
    // (SceneWait's doc); the camera permissions need no such wait (the camera
    // thread polls them).
    match wait_for_scene_permission(app, scene_asked) {
        None => {
            log::info!("activity destroyed while waiting for {SCENE_PERMISSION}: not starting");
            return Ok(());
        }
        Some(SceneStart::Granted) => {}
        Some(why) => {
            log::warn!("{SCENE_PERMISSION} not granted ({why:?}): calibration runs without headset depth this session")
        }
    }
    let scene = bundled_scene(app)?;
    // The user's scenes, cycled after the bundled one by the next-scene button:
    // glTF files pushed to the app's external files folder
    // (`adb push model.glb /sdcard/Android/data/org.blindaugment.app/files/scenes/`).
    let more_scenes = app.external_data_path().map(|d| xr::scenes_in(&d.join("scenes"))).unwrap_or_default();
    log::info!("{} scene(s) of the user's to cycle: {:?}", more_scenes.len(), more_scenes);
    let models = ModelChannel::new(first_model(app)?).map_err(|e| e.to_string())?;
    let live = Arc::new(LiveInputs::default());
    live.set_status(vec!["calibration: opening the passthrough camera".into()]);
    // Raw pointers are not Send: carried as addresses into the XR thread.
    let (vm, activity) = (app.vm_as_ptr() as usize, app.activity_as_ptr() as usize);
    let stop = AtomicBool::new(false);
    let camera_stop = AtomicBool::new(false);
    let done = AtomicBool::new(false);
    let result = std::thread::scope(|s| {
        let camera_thread = s.spawn(|| {
            if let Err(e) = calibrate_live(app, &models, &live, &camera_stop) {
                log::error!("live calibration stopped: {e} (rendering with the current model)");
                live.set_status(vec![format!("!live calibration stopped: {e}")]);
            }
        });
        let xr_thread = s.spawn(|| {
            // SAFETY: valid JavaVM and Activity pointers for this activity's
            // lifetime, which outlives this thread (joined below before returning).
            let platform = unsafe { openxr::AndroidPlatformInfo::new(vm as *mut _, activity as *mut _) };
            let mut on_frame = |r: &FrameRecord| live.on_frame(r);
            let result = xr::run(XrOptions {
                frames: None,
                validation: false,
                core_validation: false,
                scene: &scene,
                more_scenes: &more_scenes,
                local_from_scene: Mat4::from_translation(Vec3::new(0.0, 0.0, -1.5)),
                models: &models,
                settings: LayerSettings::default(),
                display_hz: DISPLAY_HZ,
                env_depth_hz: ENV_DEPTH_HZ,
                on_frame: Some(&mut on_frame),
                stop: Some(&stop),
                // Shown at start-up: the boundary-setup burst asks the user to
                // look around; the left trigger hides it.
                panel: true,
                status: Some(&|| live.status()),
                platform: &platform,
            });
            done.store(true, Ordering::SeqCst);
            result
        });
        // The activity's lifecycle: Destroy (or the XR loop ending) ends the app.
        // The XR session's own states (focus, visibility) come from the runtime.
        while !done.load(Ordering::SeqCst) {
            app.poll_events(Some(Duration::from_millis(50)), |event| {
                if let PollEvent::Main(main) = event {
                    match main {
                        MainEvent::Destroy => {
                            log::info!("activity destroyed: requesting the XR session's exit");
                            stop.store(true, Ordering::SeqCst);
                        }
                        MainEvent::Pause => log::info!("activity paused"),
                        MainEvent::Resume { .. } => log::info!("activity resumed"),
                        MainEvent::InitWindow { .. } | MainEvent::TerminateWindow { .. } => {}
                        _ => {}
                    }
                }
            });
        }
        camera_stop.store(true, Ordering::SeqCst);
        let xr_result = xr_thread.join();
        if camera_thread.join().is_err() {
            log::error!("the camera thread panicked");
        }
        match xr_result {
            Ok(Ok(summary)) => {
                log::info!("XR loop ended ({:?}) after {} frames", summary.end, summary.frames_rendered);
                Ok(())
            }
            Ok(Err(e)) => Err(format!("XR: {e}")),
            Err(_) => Err("the XR thread panicked".into()),
        }
    });
    store_model(app, &models);
    result
}
