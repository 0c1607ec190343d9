//! A headless OpenXR runtime for tests: the Khronos loader finds it through
//! `XR_RUNTIME_JSON` and negotiates with `xrNegotiateLoaderRuntimeInterface`
//! (OpenXR loader design doc, "Runtime Negotiation"). It implements what
//! blind-augment's XR app uses — instance and system, XR_KHR_vulkan_enable2 over
//! whatever Vulkan device the loader offers (lavapipe in CI), a primary-stereo view
//! configuration with views from a scripted head path, swapchains backed by Vulkan
//! images it owns on the application's device, `xrWaitFrame` paced at the display
//! rate, the session lifecycle with scripted exit/loss, XR_FB_passthrough,
//! XR_FB_display_refresh_rate, XR_FB_space_warp's throttling, XR_KHR_convert_
//! timespec_time, XR_META_environment_depth (the depth of a known plane) and the
//! action system with scripted controller presses (input.rs) — and it reports
//! every frame (JSON lines) and writes chosen frames' layers to PNG.
//!
//! It is one process-wide state behind a mutex (the loader allows one runtime per
//! process); handles are counters. Configuration: `config.rs`.
#![allow(clippy::missing_safety_doc)]

mod config;
mod env_depth;
mod frame;
mod input;
mod session;
mod swapchain;
mod system;
mod vulkan;

pub use config::{Command, Config, Head};

use openxr_sys as xr;
use std::collections::{HashMap, HashSet, VecDeque};
use std::ffi::{c_char, CStr};
use std::io::Write;
use std::sync::{Mutex, MutexGuard};
use std::time::Instant;
use xr::Handle as _;

/// What this runtime reports as its API version (the Debian loader is 1.0.20).
const API_VERSION: xr::Version = xr::Version::new(1, 0, 20);

pub(crate) const EXT_VULKAN2: &str = "XR_KHR_vulkan_enable2";
pub(crate) const EXT_PASSTHROUGH: &str = "XR_FB_passthrough";
pub(crate) const EXT_REFRESH: &str = "XR_FB_display_refresh_rate";
pub(crate) const EXT_SPACE_WARP: &str = "XR_FB_space_warp";
pub(crate) const EXT_TIMESPEC: &str = "XR_KHR_convert_timespec_time";
pub(crate) const EXT_ENV_DEPTH: &str = "XR_META_environment_depth";
pub(crate) const EXT_TOUCH_PLUS: &str = "XR_META_touch_controller_plus";

/// The one system this runtime has.
pub(crate) const SYSTEM_ID: u64 = 1;

pub(crate) enum Event {
    State {
        session: u64,
        state: xr::SessionState,
        time: i64,
    },
    InstanceLoss {
        time: i64,
    },
    RefreshRate {
        from: f32,
        to: f32,
    },
    /// XrEventDataInteractionProfileChanged (spec 11.4: after the runtime picks a
    /// profile for the attached action sets).
    ProfileChanged {
        session: u64,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum SpaceKind {
    View,
    Local,
    Stage,
}

pub(crate) struct Runtime {
    pub config: Config,
    pub epoch: Instant,
    /// CLOCK_MONOTONIC at `epoch` (ns).
    pub epoch_monotonic_ns: i64,
    pub instance: u64,
    pub enabled: Vec<String>,
    pub instance_lost: bool,
    pub paths: Vec<String>,
    pub events: VecDeque<Event>,
    pub next_handle: u64,
    pub session: Option<session::Session>,
    pub spaces: HashMap<u64, (u64, SpaceKind, xr::Posef)>,
    pub swapchains: HashMap<u64, vulkan::Swapchain>,
    pub passthroughs: HashMap<u64, bool>,
    pub passthrough_layers: HashMap<u64, (u64, bool)>,
    /// Handles of action sets, actions and action spaces (input.rs).
    pub actions: HashSet<u64>,
    /// Action spaces: handle → (action, pose in the action's space).
    pub action_spaces: HashMap<u64, (u64, xr::Posef)>,
    /// The input system's sets, actions, bindings and states (input.rs).
    pub input: input::Input,
    pub vk: Option<vulkan::VkState>,
    pub report: Option<std::fs::File>,
    /// XR_META_environment_depth's provider (at most one).
    pub env_depth: Option<env_depth::Provider>,
    /// Provider creations refused so far (`BA_XR_ENV_DEPTH_DENIALS`).
    pub env_depth_refused: u32,
}

impl Runtime {
    /// XrTime at `epoch` (instance creation): `BA_XR_TIME_ORIGIN_S`. The spec
    /// ("XrTime") leaves the epoch to the runtime; headsets count from boot, so the
    /// default is days, and an app that keeps XrTime in f32 seconds shows it.
    pub fn origin_ns(&self) -> i64 {
        (self.config.time_origin_s * 1e9).round() as i64
    }

    pub fn now_ns(&self) -> i64 {
        self.origin_ns() + self.epoch.elapsed().as_nanos() as i64
    }

    /// XrTime of a CLOCK_MONOTONIC reading: the runtime's clock is CLOCK_MONOTONIC
    /// (what `Instant` reads on Linux) shifted so that `epoch` is at the origin.
    pub fn xr_time_of_monotonic(&self, monotonic_ns: i64) -> i64 {
        self.origin_ns() + monotonic_ns - self.epoch_monotonic_ns
    }

    pub fn handle(&mut self) -> u64 {
        self.next_handle += 1;
        self.next_handle
    }

    pub fn has(&self, ext: &str) -> bool {
        self.enabled.iter().any(|e| e == ext)
    }

    /// One JSON line in the report file (tests read it).
    pub fn log(&mut self, value: serde_json::Value) {
        if let Some(f) = &mut self.report {
            let _ = writeln!(f, "{value}");
        }
    }
}

static RUNTIME: Mutex<Option<Runtime>> = Mutex::new(None);

pub(crate) fn lock() -> MutexGuard<'static, Option<Runtime>> {
    RUNTIME.lock().unwrap_or_else(|e| e.into_inner())
}

/// Run `f` on the live runtime of `instance` (or an error result).
pub(crate) fn with_instance(instance: xr::Instance, f: impl FnOnce(&mut Runtime) -> xr::Result) -> xr::Result {
    let mut guard = lock();
    match guard.as_mut() {
        Some(rt) if rt.instance == instance.into_raw() => {
            if rt.instance_lost {
                xr::Result::ERROR_INSTANCE_LOST
            } else {
                f(rt)
            }
        }
        _ => xr::Result::ERROR_HANDLE_INVALID,
    }
}

/// Run `f` on the runtime that owns any handle (session, space, swapchain ...).
pub(crate) fn with_runtime(f: impl FnOnce(&mut Runtime) -> xr::Result) -> xr::Result {
    let mut guard = lock();
    match guard.as_mut() {
        Some(rt) if rt.instance_lost => xr::Result::ERROR_INSTANCE_LOST,
        Some(rt) => f(rt),
        None => xr::Result::ERROR_HANDLE_INVALID,
    }
}

/// Two-call idiom (OpenXR spec 2.11, "Buffer Size Parameters").
pub(crate) unsafe fn two_call<T: Copy>(items: &[T], capacity: u32, count: *mut u32, out: *mut T) -> xr::Result {
    if count.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    // SAFETY: `count` is non-null and points to a u32 the caller owns.
    unsafe { *count = items.len() as u32 };
    if capacity == 0 {
        return xr::Result::SUCCESS;
    }
    if (capacity as usize) < items.len() {
        return xr::Result::ERROR_SIZE_INSUFFICIENT;
    }
    if out.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    // SAFETY: the caller promised `capacity` elements at `out`, and capacity ≥ len.
    unsafe { std::ptr::copy_nonoverlapping(items.as_ptr(), out, items.len()) };
    xr::Result::SUCCESS
}

pub(crate) fn write_cstr(dst: &mut [c_char], s: &str) {
    let n = s.len().min(dst.len() - 1);
    for (d, b) in dst.iter_mut().zip(s.bytes().take(n)) {
        *d = b as c_char;
    }
    dst[n] = 0;
}

/// The extensions this runtime offers under its configuration.
fn offered(config: &Config) -> Vec<(&'static str, u32)> {
    let mut v = vec![(EXT_VULKAN2, 2)];
    if config.passthrough {
        v.push((EXT_PASSTHROUGH, 4));
    }
    if config.refresh_rate {
        v.push((EXT_REFRESH, 1));
    }
    if config.space_warp {
        v.push((EXT_SPACE_WARP, 2));
    }
    if config.convert_timespec {
        v.push((EXT_TIMESPEC, 1));
    }
    if config.env_depth {
        v.push((EXT_ENV_DEPTH, 1));
    }
    if config.touch_plus {
        v.push((EXT_TOUCH_PLUS, 1));
    }
    v
}

/// The loader's entry point (loader design doc, "Runtime Interface Negotiation").
#[no_mangle]
pub unsafe extern "system" fn xrNegotiateLoaderRuntimeInterface(
    loader_info: *const xr::NegotiateLoaderInfo,
    request: *mut xr::NegotiateRuntimeRequest,
) -> xr::Result {
    if loader_info.is_null() || request.is_null() {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    // SAFETY: both pointers are non-null and point to the loader's structs.
    let (info, req) = unsafe { (&*loader_info, &mut *request) };
    if info.struct_type != xr::LoaderInterfaceStructs::LOADER_INFO
        || req.struct_type != xr::LoaderInterfaceStructs::RUNTIME_REQUEST
        || info.min_interface_version > 1
        || info.max_interface_version < 1
        || info.max_api_version.major() < 1
    {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    req.runtime_interface_version = 1;
    req.runtime_api_version = API_VERSION;
    req.get_instance_proc_addr = Some(get_instance_proc_addr);
    xr::Result::SUCCESS
}

macro_rules! pfn {
    ($f:path) => {{
        // SAFETY: the loader casts the pointer back to the signature the name has in
        // the OpenXR registry, which is the signature of `$f`.
        let p: xr::pfn::VoidFunction = unsafe { std::mem::transmute($f as *const ()) };
        Some(p)
    }};
}

unsafe extern "system" fn get_instance_proc_addr(
    instance: xr::Instance,
    name: *const c_char,
    function: *mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    if name.is_null() || function.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    // SAFETY: the loader passes a NUL-terminated name.
    let name = unsafe { CStr::from_ptr(name) }.to_str().unwrap_or("");
    let global = instance == xr::Instance::NULL;
    let f: Option<xr::pfn::VoidFunction> = match name {
        "xrEnumerateInstanceExtensionProperties" => pfn!(enumerate_instance_extension_properties),
        "xrEnumerateApiLayerProperties" => pfn!(enumerate_api_layer_properties),
        "xrCreateInstance" => pfn!(create_instance),
        "xrGetInstanceProcAddr" => pfn!(get_instance_proc_addr),
        _ if global => None,
        "xrDestroyInstance" => pfn!(destroy_instance),
        "xrGetInstanceProperties" => pfn!(get_instance_properties),
        "xrPollEvent" => pfn!(session::poll_event),
        "xrResultToString" => pfn!(result_to_string),
        "xrStructureTypeToString" => pfn!(structure_type_to_string),
        "xrGetSystem" => pfn!(system::get_system),
        "xrGetSystemProperties" => pfn!(system::get_system_properties),
        "xrEnumerateEnvironmentBlendModes" => pfn!(system::enumerate_environment_blend_modes),
        "xrEnumerateViewConfigurations" => pfn!(system::enumerate_view_configurations),
        "xrGetViewConfigurationProperties" => pfn!(system::get_view_configuration_properties),
        "xrEnumerateViewConfigurationViews" => pfn!(system::enumerate_view_configuration_views),
        "xrStringToPath" => pfn!(string_to_path),
        "xrPathToString" => pfn!(path_to_string),
        "xrCreateSession" => pfn!(session::create_session),
        "xrDestroySession" => pfn!(session::destroy_session),
        "xrBeginSession" => pfn!(session::begin_session),
        "xrEndSession" => pfn!(session::end_session),
        "xrRequestExitSession" => pfn!(session::request_exit_session),
        "xrEnumerateReferenceSpaces" => pfn!(session::enumerate_reference_spaces),
        "xrCreateReferenceSpace" => pfn!(session::create_reference_space),
        "xrGetReferenceSpaceBoundsRect" => pfn!(session::get_reference_space_bounds_rect),
        "xrLocateSpace" => pfn!(session::locate_space),
        "xrDestroySpace" => pfn!(session::destroy_space),
        "xrWaitFrame" => pfn!(frame::wait_frame),
        "xrBeginFrame" => pfn!(frame::begin_frame),
        "xrEndFrame" => pfn!(frame::end_frame),
        "xrLocateViews" => pfn!(session::locate_views),
        "xrEnumerateSwapchainFormats" => pfn!(swapchain::enumerate_swapchain_formats),
        "xrCreateSwapchain" => pfn!(swapchain::create_swapchain),
        "xrDestroySwapchain" => pfn!(swapchain::destroy_swapchain),
        "xrEnumerateSwapchainImages" => pfn!(swapchain::enumerate_swapchain_images),
        "xrAcquireSwapchainImage" => pfn!(swapchain::acquire_swapchain_image),
        "xrWaitSwapchainImage" => pfn!(swapchain::wait_swapchain_image),
        "xrReleaseSwapchainImage" => pfn!(swapchain::release_swapchain_image),
        "xrCreateActionSet" => pfn!(input::create_action_set),
        "xrDestroyActionSet" => pfn!(input::destroy_action_set),
        "xrCreateAction" => pfn!(input::create_action),
        "xrDestroyAction" => pfn!(input::destroy_action),
        "xrSuggestInteractionProfileBindings" => pfn!(input::suggest_interaction_profile_bindings),
        "xrAttachSessionActionSets" => pfn!(input::attach_session_action_sets),
        "xrGetCurrentInteractionProfile" => pfn!(input::get_current_interaction_profile),
        "xrSyncActions" => pfn!(input::sync_actions),
        "xrGetActionStateBoolean" => pfn!(input::get_action_state_boolean),
        "xrGetActionStateFloat" => pfn!(input::get_action_state_float),
        "xrGetActionStateVector2f" => pfn!(input::get_action_state_vector2f),
        "xrGetActionStatePose" => pfn!(input::get_action_state_pose),
        "xrEnumerateBoundSourcesForAction" => pfn!(input::enumerate_bound_sources_for_action),
        "xrGetInputSourceLocalizedName" => pfn!(input::get_input_source_localized_name),
        "xrCreateActionSpace" => pfn!(input::create_action_space),
        "xrApplyHapticFeedback" => pfn!(input::apply_haptic_feedback),
        "xrStopHapticFeedback" => pfn!(input::stop_haptic_feedback),
        "xrGetVulkanGraphicsRequirements2KHR" => pfn!(vulkan::get_graphics_requirements),
        "xrCreateVulkanInstanceKHR" => pfn!(vulkan::create_vulkan_instance),
        "xrGetVulkanGraphicsDevice2KHR" => pfn!(vulkan::get_graphics_device),
        "xrCreateVulkanDeviceKHR" => pfn!(vulkan::create_vulkan_device),
        "xrCreatePassthroughFB" => pfn!(session::create_passthrough),
        "xrDestroyPassthroughFB" => pfn!(session::destroy_passthrough),
        "xrPassthroughStartFB" => pfn!(session::passthrough_start),
        "xrPassthroughPauseFB" => pfn!(session::passthrough_pause),
        "xrCreatePassthroughLayerFB" => pfn!(session::create_passthrough_layer),
        "xrDestroyPassthroughLayerFB" => pfn!(session::destroy_passthrough_layer),
        "xrPassthroughLayerPauseFB" => pfn!(session::passthrough_layer_pause),
        "xrPassthroughLayerResumeFB" => pfn!(session::passthrough_layer_resume),
        "xrPassthroughLayerSetStyleFB" => pfn!(session::passthrough_layer_set_style),
        "xrCreateGeometryInstanceFB" => pfn!(session::create_geometry_instance),
        "xrDestroyGeometryInstanceFB" => pfn!(session::destroy_geometry_instance),
        "xrGeometryInstanceSetTransformFB" => pfn!(session::geometry_instance_set_transform),
        "xrEnumerateDisplayRefreshRatesFB" => pfn!(session::enumerate_display_refresh_rates),
        "xrGetDisplayRefreshRateFB" => pfn!(session::get_display_refresh_rate),
        "xrRequestDisplayRefreshRateFB" => pfn!(session::request_display_refresh_rate),
        "xrConvertTimespecTimeToTimeKHR" => pfn!(convert_timespec_time_to_time),
        "xrCreateEnvironmentDepthProviderMETA" => pfn!(env_depth::create_provider),
        "xrDestroyEnvironmentDepthProviderMETA" => pfn!(env_depth::destroy_provider),
        "xrStartEnvironmentDepthProviderMETA" => pfn!(env_depth::start_provider),
        "xrStopEnvironmentDepthProviderMETA" => pfn!(env_depth::stop_provider),
        "xrCreateEnvironmentDepthSwapchainMETA" => pfn!(env_depth::create_swapchain),
        "xrDestroyEnvironmentDepthSwapchainMETA" => pfn!(env_depth::destroy_swapchain),
        "xrEnumerateEnvironmentDepthSwapchainImagesMETA" => pfn!(env_depth::enumerate_swapchain_images),
        "xrGetEnvironmentDepthSwapchainStateMETA" => pfn!(env_depth::get_swapchain_state),
        "xrAcquireEnvironmentDepthImageMETA" => pfn!(env_depth::acquire_image),
        "xrSetEnvironmentDepthHandRemovalMETA" => pfn!(env_depth::set_hand_removal),
        "xrConvertTimeToTimespecTimeKHR" => pfn!(convert_time_to_timespec_time),
        _ => None,
    };
    // Extension functions only exist when their extension is enabled (spec 3.2).
    let f = f.filter(|_| {
        let ext = if name.ends_with("FB") && name.contains("RefreshRate") {
            EXT_REFRESH
        } else if name.ends_with("FB") {
            EXT_PASSTHROUGH
        } else if name.contains("Timespec") {
            EXT_TIMESPEC
        } else if name.ends_with("KHR") {
            EXT_VULKAN2
        } else {
            return true;
        };
        lock().as_ref().is_some_and(|rt| rt.has(ext))
    });
    // SAFETY: `function` is non-null (checked above).
    unsafe { *function = f };
    if f.is_some() {
        xr::Result::SUCCESS
    } else {
        if std::env::var_os("BA_XR_DEBUG").is_some() {
            eprintln!("ba-xr-runtime: xrGetInstanceProcAddr({name}): unsupported");
        }
        xr::Result::ERROR_FUNCTION_UNSUPPORTED
    }
}

unsafe extern "system" fn enumerate_api_layer_properties(
    _capacity: u32,
    count: *mut u32,
    _out: *mut xr::ApiLayerProperties,
) -> xr::Result {
    // SAFETY: two_call checks `count`; no layers to copy.
    unsafe { two_call::<xr::ApiLayerProperties>(&[], 0, count, std::ptr::null_mut()) }
}

unsafe extern "system" fn enumerate_instance_extension_properties(
    layer: *const c_char,
    capacity: u32,
    count: *mut u32,
    out: *mut xr::ExtensionProperties,
) -> xr::Result {
    if !layer.is_null() {
        return xr::Result::ERROR_API_LAYER_NOT_PRESENT;
    }
    let config = match Config::from_env() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("ba-xr-runtime: {e}");
            return xr::Result::ERROR_RUNTIME_FAILURE;
        }
    };
    let offered = offered(&config);
    if count.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    // SAFETY: non-null count of the caller.
    unsafe { *count = offered.len() as u32 };
    if capacity == 0 {
        return xr::Result::SUCCESS;
    }
    if (capacity as usize) < offered.len() || out.is_null() {
        return xr::Result::ERROR_SIZE_INSUFFICIENT;
    }
    for (i, (name, version)) in offered.into_iter().enumerate() {
        // SAFETY: the caller provides `capacity` elements at `out`; their `ty` and
        // `next` are the caller's (two-call idiom with structs, spec 2.11).
        let p = unsafe { &mut *out.add(i) };
        write_cstr(&mut p.extension_name, name);
        p.extension_version = version;
    }
    xr::Result::SUCCESS
}

unsafe extern "system" fn create_instance(info: *const xr::InstanceCreateInfo, out: *mut xr::Instance) -> xr::Result {
    if info.is_null() || out.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let config = match Config::from_env() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("ba-xr-runtime: {e}");
            return xr::Result::ERROR_RUNTIME_FAILURE;
        }
    };
    // SAFETY: non-null create info from the loader.
    let info = unsafe { &*info };
    let mut enabled = vec![];
    let offered = offered(&config);
    for i in 0..info.enabled_extension_count as usize {
        // SAFETY: `enabled_extension_names` holds `enabled_extension_count` C strings.
        let name = unsafe { CStr::from_ptr(*info.enabled_extension_names.add(i)) }.to_string_lossy().into_owned();
        if !offered.iter().any(|(n, _)| *n == name) {
            return xr::Result::ERROR_EXTENSION_NOT_PRESENT;
        }
        enabled.push(name);
    }
    let mut guard = lock();
    if guard.as_ref().is_some_and(|rt| rt.instance != 0) {
        // One instance at a time (a runtime may limit this: XR_ERROR_LIMIT_REACHED).
        return xr::Result::ERROR_LIMIT_REACHED;
    }
    let report = match &config.report {
        Some(p) => match std::fs::OpenOptions::new().create(true).append(true).open(p) {
            Ok(f) => Some(f),
            Err(e) => {
                eprintln!("ba-xr-runtime: BA_XR_REPORT {}: {e}", p.display());
                return xr::Result::ERROR_RUNTIME_FAILURE;
            }
        },
        None => None,
    };
    let mut rt = Runtime {
        config,
        epoch: Instant::now(),
        epoch_monotonic_ns: monotonic_ns(),
        instance: 0,
        enabled,
        instance_lost: false,
        paths: vec![],
        events: VecDeque::new(),
        next_handle: 0x1000,
        session: None,
        spaces: HashMap::new(),
        swapchains: HashMap::new(),
        passthroughs: HashMap::new(),
        passthrough_layers: HashMap::new(),
        actions: HashSet::new(),
        action_spaces: HashMap::new(),
        input: input::Input::default(),
        vk: None,
        report,
        env_depth: None,
        env_depth_refused: 0,
    };
    rt.instance = rt.handle();
    let extensions = rt.enabled.clone();
    rt.log(serde_json::json!({"event": "instance", "extensions": extensions}));
    // SAFETY: `out` is non-null.
    unsafe { *out = xr::Instance::from_raw(rt.instance) };
    *guard = Some(rt);
    xr::Result::SUCCESS
}

unsafe extern "system" fn destroy_instance(instance: xr::Instance) -> xr::Result {
    let mut guard = lock();
    match guard.as_mut() {
        Some(rt) if rt.instance == instance.into_raw() => {
            // Children go with their parent (spec 2.8: destroying a handle destroys
            // its children): swapchain images first, then the runtime's Vulkan state.
            session::teardown_session(rt);
            rt.log(serde_json::json!({"event": "instance_destroyed"}));
            *guard = None;
            xr::Result::SUCCESS
        }
        _ => xr::Result::ERROR_HANDLE_INVALID,
    }
}

unsafe extern "system" fn get_instance_properties(
    instance: xr::Instance,
    props: *mut xr::InstanceProperties,
) -> xr::Result {
    with_instance(instance, |_| {
        if props.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null output struct of the caller.
        let p = unsafe { &mut *props };
        p.runtime_version = xr::Version::new(0, 1, 0);
        write_cstr(&mut p.runtime_name, "blind-augment headless test runtime");
        xr::Result::SUCCESS
    })
}

unsafe extern "system" fn result_to_string(_i: xr::Instance, value: xr::Result, buffer: *mut c_char) -> xr::Result {
    let s = format!("{value:?}");
    // SAFETY: the buffer holds XR_MAX_RESULT_STRING_SIZE characters (spec).
    let dst = unsafe { std::slice::from_raw_parts_mut(buffer, xr::MAX_RESULT_STRING_SIZE) };
    write_cstr(dst, &s);
    xr::Result::SUCCESS
}

unsafe extern "system" fn structure_type_to_string(
    _i: xr::Instance,
    value: xr::StructureType,
    buffer: *mut c_char,
) -> xr::Result {
    let s = format!("{value:?}");
    // SAFETY: the buffer holds XR_MAX_STRUCTURE_NAME_SIZE characters (spec).
    let dst = unsafe { std::slice::from_raw_parts_mut(buffer, xr::MAX_STRUCTURE_NAME_SIZE) };
    write_cstr(dst, &s);
    xr::Result::SUCCESS
}

unsafe extern "system" fn string_to_path(instance: xr::Instance, s: *const c_char, out: *mut xr::Path) -> xr::Result {
    with_instance(instance, |rt| {
        // SAFETY: NUL-terminated string of the caller.
        let s = unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned();
        if !s.starts_with('/') || s.ends_with('/') || s.contains("//") {
            return xr::Result::ERROR_PATH_FORMAT_INVALID;
        }
        // SAFETY: caller's output.
        unsafe { *out = intern_path(rt, &s) };
        xr::Result::SUCCESS
    })
}

/// The XrPath of a well-formed path string, registered on first use.
pub(crate) fn intern_path(rt: &mut Runtime, s: &str) -> xr::Path {
    let i = match rt.paths.iter().position(|p| p == s) {
        Some(i) => i,
        None => {
            rt.paths.push(s.to_string());
            rt.paths.len() - 1
        }
    };
    xr::Path::from_raw(i as u64 + 1)
}

unsafe extern "system" fn path_to_string(
    instance: xr::Instance,
    path: xr::Path,
    capacity: u32,
    count: *mut u32,
    buffer: *mut c_char,
) -> xr::Result {
    with_instance(instance, |rt| {
        let Some(s) = (path.into_raw() as usize).checked_sub(1).and_then(|i| rt.paths.get(i)) else {
            return xr::Result::ERROR_PATH_INVALID;
        };
        let bytes: Vec<c_char> = s.bytes().map(|b| b as c_char).chain([0]).collect();
        // SAFETY: the caller's two-call arguments.
        unsafe { two_call(&bytes, capacity, count, buffer) }
    })
}

// ---- XR_KHR_convert_timespec_time -------------------------------------------

fn monotonic_ns() -> i64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a valid timespec to write; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec * 1_000_000_000 + ts.tv_nsec
}

/// xrConvertTimespecTimeToTimeKHR: a CLOCK_MONOTONIC timespec to XrTime.
unsafe extern "system" fn convert_timespec_time_to_time(
    instance: xr::Instance,
    timespec_time: *const libc::timespec,
    time: *mut xr::Time,
) -> xr::Result {
    let guard = lock();
    let Some(rt) = guard.as_ref().filter(|rt| rt.instance == instance.into_raw()) else {
        return xr::Result::ERROR_HANDLE_INVALID;
    };
    if timespec_time.is_null() || time.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    // SAFETY: non-null pointers from the application (spec: valid for the call).
    let ts = unsafe { &*timespec_time };
    let mono = ts.tv_sec * 1_000_000_000 + ts.tv_nsec;
    let t = rt.xr_time_of_monotonic(mono);
    if t <= 0 {
        return xr::Result::ERROR_TIME_INVALID;
    }
    // SAFETY: see above.
    unsafe { *time = xr::Time::from_nanos(t) };
    xr::Result::SUCCESS
}

/// xrConvertTimeToTimespecTimeKHR: the inverse.
unsafe extern "system" fn convert_time_to_timespec_time(
    instance: xr::Instance,
    time: xr::Time,
    timespec_time: *mut libc::timespec,
) -> xr::Result {
    let guard = lock();
    let Some(rt) = guard.as_ref().filter(|rt| rt.instance == instance.into_raw()) else {
        return xr::Result::ERROR_HANDLE_INVALID;
    };
    if timespec_time.is_null() || time.as_nanos() <= 0 {
        return xr::Result::ERROR_TIME_INVALID;
    }
    let mono = time.as_nanos() - rt.origin_ns() + rt.epoch_monotonic_ns;
    // SAFETY: non-null pointer from the application.
    unsafe {
        *timespec_time = libc::timespec {
            tv_sec: (mono / 1_000_000_000) as libc::time_t,
            tv_nsec: (mono % 1_000_000_000) as libc::c_long,
        }
    };
    xr::Result::SUCCESS
}
