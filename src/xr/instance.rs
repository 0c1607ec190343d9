//! The XR instance and system-level calls: loading the Khronos loader and creating
//! the instance with what the runtime offers, the clock conversion
//! (XR_KHR_convert_timespec_time) and system properties with an extension's
//! struct chained.

use super::{call, XrError};
use crate::analysis::timing::ClockSample;
use openxr as xr;

const CORE_VALIDATION: &str = "XR_APILAYER_LUNARG_core_validation";

/// Load the loader and create the instance with what the runtime offers.
pub(super) fn create_instance(
    validation: bool,
    platform: &dyn xr::PlatformInfo,
    env_depth: bool,
) -> Result<(xr::Entry, xr::Instance, xr::ExtensionSet), XrError> {
    // SAFETY: the Khronos loader (Debian's libopenxr_loader.so.1; the APK's
    // libopenxr_loader.so) conforms to the spec.
    let entry = unsafe { xr::Entry::load(platform) }.map_err(|e| XrError::NoLoader(e.to_string()))?;
    let available = match entry.enumerate_extensions() {
        Ok(a) => a,
        Err(e) if e == xr::sys::Result::ERROR_RUNTIME_UNAVAILABLE || e == xr::sys::Result::ERROR_RUNTIME_FAILURE => {
            return Err(XrError::NoRuntime(format!("the loader found none ({e})")))
        }
        Err(e) => return Err(call("xrEnumerateInstanceExtensionProperties")(e)),
    };
    if !available.khr_vulkan_enable2 {
        return Err(XrError::MissingExtension("XR_KHR_vulkan_enable2"));
    }
    let mut want = xr::ExtensionSet::default();
    want.khr_vulkan_enable2 = true;
    // Android: the instance is created with the JavaVM and activity (required there;
    // the field exists only in Android builds of the openxr crate).
    #[cfg(target_os = "android")]
    {
        want.khr_android_create_instance = true;
    }
    for (offered, flag, name, consequence) in [
        (available.fb_passthrough, &mut want.fb_passthrough, "XR_FB_passthrough", "no passthrough layer"),
        (
            available.fb_display_refresh_rate,
            &mut want.fb_display_refresh_rate,
            "XR_FB_display_refresh_rate",
            "the display runs at the runtime's default rate",
        ),
        (available.fb_space_warp, &mut want.fb_space_warp, "XR_FB_space_warp", "every display frame is rendered"),
        (
            available.meta_touch_controller_plus,
            &mut want.meta_touch_controller_plus,
            "XR_META_touch_controller_plus",
            "Quest 3's Touch Plus controllers answer to the Touch bindings",
        ),
        (
            available.khr_convert_timespec_time,
            &mut want.khr_convert_timespec_time,
            "XR_KHR_convert_timespec_time",
            "camera frames cannot be put on the XR clock (calibration runs without head poses)",
        ),
    ] {
        if offered {
            *flag = true;
        } else {
            log::info!("OpenXR: {name} not offered: {consequence}");
        }
    }
    // The headset's depth feeds calibration (the worker), not the renderer: enabled
    // only when asked for.
    if env_depth && available.meta_environment_depth {
        want.meta_environment_depth = true;
    } else if env_depth {
        log::info!("OpenXR: XR_META_environment_depth not offered: calibration runs without headset depth");
    }
    let mut layers = vec![];
    if validation {
        match entry.enumerate_layers() {
            Ok(l) if l.iter().any(|l| l.layer_name == CORE_VALIDATION) => layers.push(CORE_VALIDATION),
            _ => log::warn!("OpenXR: {CORE_VALIDATION} not installed (Debian: openxr-layer-corevalidation)"),
        }
    }
    let app = xr::ApplicationInfo {
        application_name: "blind-augment",
        application_version: 1,
        engine_name: "blind-augment",
        engine_version: 1,
        api_version: xr::Version::new(1, 0, 0),
    };
    let instance = entry.create_instance(&app, &want, &layers, platform).map_err(|e| match e {
        xr::sys::Result::ERROR_RUNTIME_UNAVAILABLE | xr::sys::Result::ERROR_RUNTIME_FAILURE => {
            XrError::NoRuntime(format!("xrCreateInstance: {e}"))
        }
        e => call("xrCreateInstance")(e),
    })?;
    Ok((entry, instance, want))
}

/// Read a clock (CLOCK_MONOTONIC, CLOCK_BOOTTIME) in ns.
fn clock_ns(clock: libc::clockid_t) -> i64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; both clocks exist on Linux and
    // Android (clock_gettime(2)), so the call cannot fail on them.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec * 1_000_000_000 + ts.tv_nsec
}

/// One clock reading through XR_KHR_convert_timespec_time: CLOCK_MONOTONIC just
/// before and after converting the first reading to XrTime, CLOCK_BOOTTIME between
/// (the Camera2 timestamps' clock).
pub(super) fn sample_clocks(instance: &xr::Instance) -> Result<ClockSample, XrError> {
    let convert = instance
        .exts()
        .khr_convert_timespec_time
        .as_ref()
        .ok_or(XrError::MissingExtension("XR_KHR_convert_timespec_time"))?
        .convert_timespec_time_to_time;
    let before = clock_ns(libc::CLOCK_MONOTONIC);
    let boottime = clock_ns(libc::CLOCK_BOOTTIME);
    let ts = libc::timespec {
        tv_sec: (before / 1_000_000_000) as libc::time_t,
        tv_nsec: (before % 1_000_000_000) as libc::c_long,
    };
    let mut xr_time = xr::sys::Time::from_nanos(0);
    // SAFETY: the function pointer was loaded for this instance with its extension
    // enabled; `ts` and `xr_time` are valid for the call.
    let r = unsafe { convert(instance.as_raw(), &ts, &mut xr_time) };
    if r.into_raw() < 0 {
        return Err(call("xrConvertTimespecTimeToTimeKHR")(r));
    }
    let after = clock_ns(libc::CLOCK_MONOTONIC);
    Ok(ClockSample {
        monotonic_before_ns: before,
        monotonic_after_ns: after,
        boottime_ns: boottime,
        xr_time_ns: xr_time.as_nanos(),
    })
}

/// xrGetSystemProperties with an extension's properties struct chained (openxr 0.22's
/// `system_properties` chains nothing).
///
/// # Safety
/// `next` points at a live, writable properties struct of an enabled extension,
/// beginning with its `ty`/`next` header, whose own `next` is null.
pub(super) unsafe fn chained_system_properties(
    instance: &xr::Instance,
    system: xr::SystemId,
    next: *mut std::ffi::c_void,
    call_name: &'static str,
) -> Result<(), XrError> {
    let mut props = xr::sys::SystemProperties {
        ty: xr::sys::SystemProperties::TYPE,
        next,
        // SAFETY: plain data (ids, arrays, flags); zero is a valid bit pattern.
        ..unsafe { std::mem::zeroed() }
    };
    // SAFETY: a live instance and system; `props` and what it chains (the caller's
    // contract) live for the call.
    let r = unsafe { (instance.fp().get_system_properties)(instance.as_raw(), system, &mut props) };
    if r.into_raw() < 0 {
        return Err(call(call_name)(r));
    }
    Ok(())
}
