//! The system and its primary-stereo view configuration: xrGetSystem, the
//! system's properties, blend modes and the views' recommended sizes.

use crate::{two_call, with_instance, write_cstr, EXT_ENV_DEPTH, EXT_PASSTHROUGH, EXT_SPACE_WARP, SYSTEM_ID};
use openxr_sys as xr;

pub(crate) unsafe extern "system" fn get_system(
    instance: xr::Instance,
    info: *const xr::SystemGetInfo,
    out: *mut xr::SystemId,
) -> xr::Result {
    with_instance(instance, |_| {
        // SAFETY: non-null checked by the validation layer; checked again here.
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: as above.
        if unsafe { (*info).form_factor } != xr::FormFactor::HEAD_MOUNTED_DISPLAY {
            return xr::Result::ERROR_FORM_FACTOR_UNSUPPORTED;
        }
        // SAFETY: as above.
        unsafe { *out = xr::SystemId::from_raw(SYSTEM_ID) };
        xr::Result::SUCCESS
    })
}

/// Walk an output struct's `next` chain (spec 2.7: chained structs).
pub(crate) unsafe fn out_chain(mut next: *mut std::ffi::c_void, mut f: impl FnMut(*mut xr::BaseOutStructure)) {
    while !next.is_null() {
        let base = next as *mut xr::BaseOutStructure;
        f(base);
        // SAFETY: every chained struct begins with a BaseOutStructure header.
        next = unsafe { (*base).next } as *mut std::ffi::c_void;
    }
}

pub(crate) unsafe extern "system" fn get_system_properties(
    instance: xr::Instance,
    system: xr::SystemId,
    props: *mut xr::SystemProperties,
) -> xr::Result {
    with_instance(instance, |rt| {
        if system.into_raw() != SYSTEM_ID {
            return xr::Result::ERROR_SYSTEM_INVALID;
        }
        if props.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null output struct.
        let p = unsafe { &mut *props };
        p.system_id = system;
        p.vendor_id = 0xba;
        write_cstr(&mut p.system_name, "blind-augment headless HMD");
        p.graphics_properties.max_layer_count = 16;
        p.graphics_properties.max_swapchain_image_width = 8192;
        p.graphics_properties.max_swapchain_image_height = 8192;
        p.tracking_properties.orientation_tracking = xr::TRUE;
        p.tracking_properties.position_tracking = xr::TRUE;
        let (passthrough, space_warp, env_depth) =
            (rt.has(EXT_PASSTHROUGH), rt.has(EXT_SPACE_WARP), rt.has(EXT_ENV_DEPTH));
        let (w, h) = rt.config.eye_size;
        // SAFETY: the chain is the caller's, each struct starts with a header.
        unsafe {
            out_chain(p.next, |s| match (*s).ty {
                xr::StructureType::SYSTEM_PASSTHROUGH_PROPERTIES_FB if passthrough => {
                    (*(s as *mut xr::SystemPassthroughPropertiesFB)).supports_passthrough = xr::TRUE;
                }
                xr::StructureType::SYSTEM_SPACE_WARP_PROPERTIES_FB if space_warp => {
                    let sw = &mut *(s as *mut xr::SystemSpaceWarpPropertiesFB);
                    // Quest recommends motion vectors at a fraction of the eye size.
                    sw.recommended_motion_vector_image_rect_width = w.div_ceil(4);
                    sw.recommended_motion_vector_image_rect_height = h.div_ceil(4);
                }
                xr::StructureType::SYSTEM_ENVIRONMENT_DEPTH_PROPERTIES_META if env_depth => {
                    let d = &mut *(s as *mut xr::SystemEnvironmentDepthPropertiesMETA);
                    d.supports_environment_depth = xr::TRUE;
                    d.supports_hand_removal = xr::TRUE;
                }
                _ => {}
            })
        };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn enumerate_environment_blend_modes(
    instance: xr::Instance,
    system: xr::SystemId,
    config: xr::ViewConfigurationType,
    capacity: u32,
    count: *mut u32,
    out: *mut xr::EnvironmentBlendMode,
) -> xr::Result {
    with_instance(instance, |rt| {
        if system.into_raw() != SYSTEM_ID {
            return xr::Result::ERROR_SYSTEM_INVALID;
        }
        if config != xr::ViewConfigurationType::PRIMARY_STEREO {
            return xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
        }
        let modes = rt.config.blend_modes.clone();
        // SAFETY: the caller's two-call arguments.
        unsafe { two_call(&modes, capacity, count, out) }
    })
}

pub(crate) unsafe extern "system" fn enumerate_view_configurations(
    instance: xr::Instance,
    system: xr::SystemId,
    capacity: u32,
    count: *mut u32,
    out: *mut xr::ViewConfigurationType,
) -> xr::Result {
    with_instance(instance, |_| {
        if system.into_raw() != SYSTEM_ID {
            return xr::Result::ERROR_SYSTEM_INVALID;
        }
        // SAFETY: the caller's two-call arguments.
        unsafe { two_call(&[xr::ViewConfigurationType::PRIMARY_STEREO], capacity, count, out) }
    })
}

pub(crate) unsafe extern "system" fn get_view_configuration_properties(
    instance: xr::Instance,
    system: xr::SystemId,
    config: xr::ViewConfigurationType,
    props: *mut xr::ViewConfigurationProperties,
) -> xr::Result {
    with_instance(instance, |_| {
        if system.into_raw() != SYSTEM_ID {
            return xr::Result::ERROR_SYSTEM_INVALID;
        }
        if config != xr::ViewConfigurationType::PRIMARY_STEREO {
            return xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
        }
        // SAFETY: caller's output struct.
        unsafe {
            (*props).view_configuration_type = config;
            (*props).fov_mutable = xr::FALSE;
        }
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn enumerate_view_configuration_views(
    instance: xr::Instance,
    system: xr::SystemId,
    config: xr::ViewConfigurationType,
    capacity: u32,
    count: *mut u32,
    out: *mut xr::ViewConfigurationView,
) -> xr::Result {
    with_instance(instance, |rt| {
        if system.into_raw() != SYSTEM_ID {
            return xr::Result::ERROR_SYSTEM_INVALID;
        }
        if config != xr::ViewConfigurationType::PRIMARY_STEREO {
            return xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
        }
        if count.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null count.
        unsafe { *count = 2 };
        if capacity == 0 {
            return xr::Result::SUCCESS;
        }
        if capacity < 2 {
            return xr::Result::ERROR_SIZE_INSUFFICIENT;
        }
        let (w, h) = rt.config.eye_size;
        for i in 0..2 {
            // SAFETY: two elements at `out` (capacity ≥ 2); `ty`/`next` are the caller's.
            let v = unsafe { &mut *out.add(i) };
            v.recommended_image_rect_width = w;
            v.recommended_image_rect_height = h;
            v.max_image_rect_width = 8192;
            v.max_image_rect_height = 8192;
            v.recommended_swapchain_sample_count = 1;
            v.max_swapchain_sample_count = 1;
        }
        xr::Result::SUCCESS
    })
}
