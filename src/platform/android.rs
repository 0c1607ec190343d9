//! The Quest app's entry point (`android_main`, android-activity's NativeActivity
//! glue): logging to logcat, runtime permissions, assets through the
//! AssetManager, the activity lifecycle driving the OpenXR frame loop of
//! `xr::run` on its own thread, and live calibration: the passthrough camera
//! (`android_camera`) feeding the calibration worker, whose models the frame loop
//! renders with. Calibration starts as soon as the camera permissions are granted
//! — during boundary setup, the worker's start-up burst — and refreshes from
//! then on; the last model is stored in the app's internal storage and is the
//! next start's first model. With the spatial-data permission the frame loop also
//! reads the headset's depth (XR_META_environment_depth), which the camera thread
//! reprojects into each frame it submits (`analysis::headset_depth`): metric depth
//! for δ(Z) and pose + depth flow. Wiring only: every decision it relies on is tested
//! on desktop; this file itself has not run on a headset (no device here).
#![allow(unsafe_code)]

use crate::analysis::camera::{
    camera_pose, choose_camera, forward_camera, head_from_eyes, CameraSide, CaptureResult, ExposureCheck,
    FrameAssembler, PASSTHROUGH_SIZE,
};
use crate::analysis::headset_depth::HeadsetDepth;
use crate::analysis::timing::{ClockMap, ClockSample, TimedPose, TimestampSource};
use crate::android_camera::{CameraManager, PassthroughCamera};
use crate::image::yuv::{Yuv420, YuvMatrix, YuvRange};
use crate::model::CameraModel;
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

/// The permissions the camera path needs (manifest: uses-permission); asked for
/// at start. Without them the app renders with the stored or default camera model.
const CAMERA_PERMISSIONS: [&str; 2] = ["android.permission.CAMERA", "horizonos.permission.HEADSET_CAMERA"];
/// Spatial data (XR_META_environment_depth): asked for with the camera's; without
/// it calibration runs on image flow and blind DoF (the frame loop retries the
/// depth provider, so a grant during the session takes effect).
const SCENE_PERMISSION: &str = "com.oculus.permission.USE_SCENE";
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

/// Ask for the camera and spatial-data permissions (Activity.requestPermissions
/// over JNI) and report which are granted now; the answer to the request comes later, through
/// the system dialog (NativeActivity has no onRequestPermissionsResult), so the
/// camera path checks again when it starts.
fn request_permissions(app: &AndroidApp) -> Result<Vec<(&'static str, bool)>, jni::errors::Error> {
    use jni::objects::{JObject, JValue};
    use jni::{jni_sig, jni_str};
    with_activity(app, |env, activity| {
        let all = [CAMERA_PERMISSIONS[0], CAMERA_PERMISSIONS[1], SCENE_PERMISSION];
        let granted = permission_states(env, activity, &all)?;
        let missing: Vec<&str> = granted.iter().filter(|(_, g)| !g).map(|(p, _)| *p).collect();
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
        Ok(granted)
    })
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
}

impl LiveInputs {
    fn on_frame(&self, r: &FrameRecord) {
        let (q, p) = head_from_eyes(
            [r.views[0].orientation, r.views[1].orientation],
            [r.views[0].position_m, r.views[1].position_m],
        );
        let mut heads = self.heads.lock().unwrap_or_else(|e| e.into_inner());
        if heads.len() == MAX_HEADS {
            heads.pop_front();
        }
        heads.push_back((r.predicted_display_time_ns, q, p));
        drop(heads);
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

/// Whether every camera permission is granted now.
fn camera_permitted(app: &AndroidApp) -> Result<bool, jni::errors::Error> {
    with_activity(app, |env, activity| {
        Ok(permission_states(env, activity, &CAMERA_PERMISSIONS)?.iter().all(|(_, g)| *g))
    })
}

/// Meta's vendor keys of camera `id` (position, source): `CameraCharacteristics`
/// with `new CameraCharacteristics.Key(name, Integer.class)` (public since API 29),
/// because the NDK cannot look a vendor tag up by name. None where the key or the
/// call is missing.
fn meta_keys(app: &AndroidApp, id: &str) -> crate::android_camera::MetaKeys {
    use crate::analysis::camera::{META_POSITION_KEY, META_SOURCE_KEY};
    use jni::objects::JValue;
    use jni::{jni_sig, jni_str};
    let read = |key_name: &str| -> Option<i32> {
        with_activity(app, |env, activity| {
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
            let integer = env.find_class(jni_str!("java/lang/Integer"))?;
            let key_class = env.find_class(jni_str!("android/hardware/camera2/CameraCharacteristics$Key"))?;
            let name = env.new_string(key_name)?;
            let key = env.new_object(
                &key_class,
                jni_sig!("(Ljava/lang/String;Ljava/lang/Class;)V"),
                &[JValue::Object(&name), JValue::Object(&integer)],
            )?;
            let value = env
                .call_method(
                    &chars,
                    jni_str!("get"),
                    jni_sig!("(Landroid/hardware/camera2/CameraCharacteristics$Key;)Ljava/lang/Object;"),
                    &[JValue::Object(&key)],
                )?
                .l()?;
            if value.is_null() {
                return Ok(None);
            }
            Ok(Some(env.call_method(&value, jni_str!("intValue"), jni_sig!("()I"), &[])?.i()?))
        })
        .unwrap_or_else(|e| {
            log::warn!("camera {id}: {key_name} unreadable ({e})");
            None
        })
    };
    (read(META_POSITION_KEY), read(META_SOURCE_KEY))
}

/// The camera → worker path: wait for the permissions, choose and open the
/// passthrough camera, run the calibration worker on its frames until `stop`.
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
        match camera_permitted(app) {
            Ok(true) => break,
            Ok(false) if !told => {
                log::info!("calibration waits for the camera permissions (rendering with the current model)");
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
    let head_from_camera: Mat4 = choice.head_from_camera.unwrap_or_else(forward_camera);
    // Camera2's YUV_420_888 is JFIF (BT.601, full range) unless a dataspace says
    // otherwise (the HAL's default for camera YUV output).
    let mut assembler = FrameAssembler::new(YuvMatrix::Bt601, YuvRange::Full, choice.timestamp_source);
    let realtime = choice.timestamp_source == TimestampSource::Realtime;
    // The headset's depth needs the camera's intrinsics and poses on the XR clock.
    let mut headset = choice.intrinsics.filter(|_| realtime).map(HeadsetDepth::new);
    let mut depth_note = Instant::now() - Duration::from_secs(60);
    let (w, l) = (worker.clone(), live.clone());
    let handler = Box::new(move |yuv: &Yuv420<'_>, timestamp_ns: i64, result: Option<CaptureResult>| {
        if let Some(map) = l.new_clock_map() {
            assembler.set_clock(map);
        }
        // Frames and poses share a clock only once the clocks are mapped; before
        // that (the first rendered frame brings a sample) frames wait and the head
        // poses stay queued; a camera on an unknown clock calibrates without poses.
        if realtime && assembler.clock().is_none() {
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
            return;
        }
        match assembler.assemble(yuv, timestamp_ns, result.as_ref()) {
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
    });
    let camera = PassthroughCamera::open(&manager, &choice, handler)?;
    log::info!("camera {} streaming: start-up calibration running", choice.id);
    let mut last_report = Instant::now();
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(200));
        if camera.lost() {
            log::warn!("camera lost: calibration stops (the current model stays)");
            break;
        }
        if last_report.elapsed() >= Duration::from_secs(10) {
            last_report = Instant::now();
            let snapshot = models.latest();
            let check = ExposureCheck::new(camera.last_exposure_ns(), FRAME_INTERVAL_S, &snapshot.model);
            log::info!(
                "model generation {}: {}; {} failed captures",
                snapshot.generation,
                check.line(),
                camera.failures()
            );
        }
    }
    // The handler (holding a worker reference) goes with the camera's reader.
    drop(camera);
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

fn run(app: &AndroidApp) -> Result<(), String> {
    match request_permissions(app) {
        Ok(states) => {
            for (p, granted) in states {
                match (granted, p == SCENE_PERMISSION) {
                    (true, _) => {}
                    (false, false) => log::warn!(
                        "{p} not granted (asked): until it is, the camera model is the stored or default one"
                    ),
                    (false, true) => {
                        log::warn!("{p} not granted (asked): until it is, calibration runs without headset depth")
                    }
                }
            }
        }
        Err(e) => {
            log::warn!("camera permissions could not be requested ({e}): rendering with the default camera model")
        }
    }
    let scene = Scene::from_glb(&asset(app, "toy.glb")?, "toy.glb").map_err(|e| e.to_string())?;
    let models = ModelChannel::new(first_model(app)?).map_err(|e| e.to_string())?;
    let live = Arc::new(LiveInputs::default());
    // Raw pointers are not Send: carried as addresses into the XR thread.
    let (vm, activity) = (app.vm_as_ptr() as usize, app.activity_as_ptr() as usize);
    let stop = AtomicBool::new(false);
    let camera_stop = AtomicBool::new(false);
    let done = AtomicBool::new(false);
    let result = std::thread::scope(|s| {
        let camera_thread = s.spawn(|| {
            if let Err(e) = calibrate_live(app, &models, &live, &camera_stop) {
                log::error!("live calibration stopped: {e} (rendering with the current model)");
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
                local_from_scene: Mat4::from_translation(Vec3::new(0.0, 0.0, -1.5)),
                models: &models,
                settings: LayerSettings::default(),
                display_hz: 90.0,
                env_depth_hz: ENV_DEPTH_HZ,
                on_frame: Some(&mut on_frame),
                stop: Some(&stop),
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
