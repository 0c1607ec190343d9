//! The Quest app's entry point (`android_main`, android-activity's NativeActivity
//! glue): logging to logcat, runtime permissions, assets through the
//! AssetManager, and the activity lifecycle driving the OpenXR frame loop of
//! `xr::run` on its own thread. Wiring only: everything it runs is tested on
//! desktop; this file itself has not run on a headset (no device here).
#![allow(unsafe_code)]

use crate::model::CameraModel;
use crate::render::LayerSettings;
use crate::scene::Scene;
use crate::worker::ModelChannel;
use crate::xr::{self, XrOptions};
use android_activity::{AndroidApp, MainEvent, PollEvent};
use glam::{Mat4, Vec3};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// The permissions the camera path needs (manifest: uses-permission); asked for
/// at start. Without them the app renders with the stored or default camera model.
const CAMERA_PERMISSIONS: [&str; 2] = ["android.permission.CAMERA", "horizonos.permission.HEADSET_CAMERA"];

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

/// Ask for the camera permissions (Activity.requestPermissions over JNI) and
/// report which are granted now; the answer to the request comes later, through
/// the system dialog (NativeActivity has no onRequestPermissionsResult), so the
/// camera path checks again when it starts.
fn request_camera_permissions(app: &AndroidApp) -> Result<Vec<(&'static str, bool)>, jni::errors::Error> {
    use jni::objects::{JObject, JValue};
    use jni::{jni_sig, jni_str};
    // SAFETY: android-activity's JavaVM and Activity pointers are valid while the
    // activity lives (we are called before Destroy).
    let vm = unsafe { jni::JavaVM::from_raw(app.vm_as_ptr().cast()) };
    vm.attach_current_thread(|env| {
        // SAFETY: a live global reference to the activity (android-activity).
        let activity = unsafe { JObject::from_raw(env, app.activity_as_ptr().cast()) };
        let string_class = env.find_class(jni_str!("java/lang/String"))?;
        let names = env.new_object_array(CAMERA_PERMISSIONS.len() as i32, &string_class, JObject::null())?;
        let mut granted = vec![];
        for (i, p) in CAMERA_PERMISSIONS.iter().enumerate() {
            let name = env.new_string(p)?;
            let state = env
                .call_method(
                    &activity,
                    jni_str!("checkSelfPermission"),
                    jni_sig!("(Ljava/lang/String;)I"),
                    &[JValue::Object(&name)],
                )?
                .i()?;
            // PackageManager.PERMISSION_GRANTED = 0.
            granted.push((*p, state == 0));
            names.set_element(env, i, &name)?;
        }
        if granted.iter().any(|(_, g)| !g) {
            env.call_method(
                &activity,
                jni_str!("requestPermissions"),
                jni_sig!("([Ljava/lang/String;I)V"),
                &[JValue::Object(&names), JValue::Int(1)],
            )?;
        }
        // `activity` wraps android-activity's global reference without owning it
        // (JObject deletes nothing on drop).
        Ok(granted)
    })
}

fn run(app: &AndroidApp) -> Result<(), String> {
    match request_camera_permissions(app) {
        Ok(states) => {
            for (p, granted) in states {
                if !granted {
                    log::warn!("{p} not granted (asked): until it is, the camera model is the stored or default one");
                }
            }
        }
        Err(e) => {
            log::warn!("camera permissions could not be requested ({e}): rendering with the default camera model")
        }
    }
    let scene = Scene::from_glb(&asset(app, "toy.glb")?, "toy.glb").map_err(|e| e.to_string())?;
    // Calibration (the worker) publishes here once it exists; until then the
    // bundled default model, or a stored one.
    let model = match asset(app, "camera.json") {
        Ok(bytes) => {
            CameraModel::from_json(&String::from_utf8_lossy(&bytes)).map_err(|e| format!("camera.json: {e}"))?
        }
        Err(_) => {
            log::info!("no stored camera model: using the default until calibration publishes one");
            crate::xr::default_camera()
        }
    };
    let models = ModelChannel::new(model).map_err(|e| e.to_string())?;
    // Raw pointers are not Send: carried as addresses into the XR thread.
    let (vm, activity) = (app.vm_as_ptr() as usize, app.activity_as_ptr() as usize);
    let stop = AtomicBool::new(false);
    let done = AtomicBool::new(false);
    std::thread::scope(|s| {
        let xr_thread = s.spawn(|| {
            // SAFETY: valid JavaVM and Activity pointers for this activity's
            // lifetime, which outlives this thread (joined below before returning).
            let platform = unsafe { openxr::AndroidPlatformInfo::new(vm as *mut _, activity as *mut _) };
            let result = xr::run(XrOptions {
                frames: None,
                validation: false,
                scene: &scene,
                local_from_scene: Mat4::from_translation(Vec3::new(0.0, 0.0, -1.5)),
                models: &models,
                settings: LayerSettings::default(),
                display_hz: 90.0,
                on_frame: None,
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
        match xr_thread.join() {
            Ok(Ok(summary)) => {
                log::info!("XR loop ended ({:?}) after {} frames", summary.end, summary.frames_rendered);
                Ok(())
            }
            Ok(Err(e)) => Err(format!("XR: {e}")),
            Err(_) => Err("the XR thread panicked".into()),
        }
    })
}
