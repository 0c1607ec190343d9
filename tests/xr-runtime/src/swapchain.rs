//! Swapchain entry points (spec 10.1): formats, create/destroy, the images handed
//! out in acquire → wait → release order, on the images `vulkan::VkState` owns.

use crate::{two_call, with_runtime};
use ash::vk;
use ash::vk::Handle as _;
use openxr_sys as xr;
use std::collections::VecDeque;
use xr::Handle as _;

/// One swapchain: images on the app's device (`vulkan::VkState::create_swapchain`)
/// and where each is in the acquire → wait → release cycle.
pub(crate) struct Swapchain {
    pub width: u32,
    pub height: u32,
    pub array_size: u32,
    pub format: vk::Format,
    pub(crate) depth: bool,
    pub(crate) images: Vec<(vk::Image, vk::DeviceMemory)>,
    pub(crate) acquired: VecDeque<u32>,
    pub(crate) waited: Option<u32>,
    pub(crate) next: u32,
    pub last_released: Option<u32>,
}

pub(crate) unsafe extern "system" fn enumerate_swapchain_formats(
    session: xr::Session,
    capacity: u32,
    count: *mut u32,
    out: *mut i64,
) -> xr::Result {
    with_runtime(|rt| {
        if rt.session.as_ref().map(|s| s.handle) != Some(session.into_raw()) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        let formats: Vec<i64> =
            rt.vk.as_ref().map_or(vec![], |v| v.formats.iter().map(|f| f.as_raw() as i64).collect());
        // SAFETY: the caller's two-call arguments.
        unsafe { two_call(&formats, capacity, count, out) }
    })
}

pub(crate) unsafe extern "system" fn create_swapchain(
    session: xr::Session,
    info: *const xr::SwapchainCreateInfo,
    out: *mut xr::Swapchain,
) -> xr::Result {
    with_runtime(|rt| {
        if rt.session.as_ref().map(|s| s.handle) != Some(session.into_raw()) {
            return xr::Result::ERROR_HANDLE_INVALID;
        }
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        let Some(vk) = rt.vk.as_ref() else { return xr::Result::ERROR_GRAPHICS_DEVICE_INVALID };
        // SAFETY: non-null create info.
        let info = unsafe { &*info };
        match vk.create_swapchain(info) {
            Ok(sc) => {
                rt.log(serde_json::json!({"event": "swapchain", "format": sc.format.as_raw(), "width": sc.width, "height": sc.height, "array_size": sc.array_size, "depth": sc.depth, "usage": info.usage_flags.into_raw()}));
                let h = rt.handle();
                rt.swapchains.insert(h, sc);
                // SAFETY: caller's output.
                unsafe { *out = xr::Swapchain::from_raw(h) };
                xr::Result::SUCCESS
            }
            Err(r) => r,
        }
    })
}

pub(crate) unsafe extern "system" fn destroy_swapchain(swapchain: xr::Swapchain) -> xr::Result {
    with_runtime(|rt| match rt.swapchains.remove(&swapchain.into_raw()) {
        Some(sc) => {
            if let Some(vk) = rt.vk.as_ref() {
                vk.destroy_swapchain(sc);
            }
            xr::Result::SUCCESS
        }
        None => xr::Result::ERROR_HANDLE_INVALID,
    })
}

pub(crate) unsafe extern "system" fn enumerate_swapchain_images(
    swapchain: xr::Swapchain,
    capacity: u32,
    count: *mut u32,
    out: *mut xr::SwapchainImageBaseHeader,
) -> xr::Result {
    with_runtime(|rt| {
        let Some(sc) = rt.swapchains.get(&swapchain.into_raw()) else { return xr::Result::ERROR_HANDLE_INVALID };
        // SAFETY: the caller's two-call arguments.
        unsafe { enumerate_images(&sc.images, capacity, count, out) }
    })
}

/// The two-call enumeration of Vulkan swapchain images (xrEnumerateSwapchainImages
/// and XR_META_environment_depth's twin): the app passes an array of
/// XrSwapchainImageVulkanKHR (its graphics API's struct, spec 10.1) with
/// `capacity` elements, each typed.
pub(crate) unsafe fn enumerate_images(
    images: &[(vk::Image, vk::DeviceMemory)],
    capacity: u32,
    count: *mut u32,
    out: *mut xr::SwapchainImageBaseHeader,
) -> xr::Result {
    if count.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    // SAFETY: non-null count.
    unsafe { *count = images.len() as u32 };
    if capacity == 0 {
        return xr::Result::SUCCESS;
    }
    if (capacity as usize) < images.len() || out.is_null() {
        return xr::Result::ERROR_SIZE_INSUFFICIENT;
    }
    let out = out as *mut xr::SwapchainImageVulkanKHR;
    for (i, (image, _)) in images.iter().enumerate() {
        // SAFETY: `capacity` ≥ images.len() elements at `out` (the caller's contract).
        unsafe {
            if (*out.add(i)).ty != xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR {
                return xr::Result::ERROR_VALIDATION_FAILURE;
            }
            (*out.add(i)).image = image.as_raw();
        }
    }
    xr::Result::SUCCESS
}

fn with_swapchain(swapchain: xr::Swapchain, f: impl FnOnce(&mut Swapchain) -> xr::Result) -> xr::Result {
    with_runtime(|rt| match rt.swapchains.get_mut(&swapchain.into_raw()) {
        Some(sc) => f(sc),
        None => xr::Result::ERROR_HANDLE_INVALID,
    })
}

pub(crate) unsafe extern "system" fn acquire_swapchain_image(
    swapchain: xr::Swapchain,
    _info: *const xr::SwapchainImageAcquireInfo,
    index: *mut u32,
) -> xr::Result {
    with_swapchain(swapchain, |sc| {
        if sc.acquired.len() == sc.images.len() {
            return xr::Result::ERROR_CALL_ORDER_INVALID;
        }
        let i = sc.next;
        sc.next = (sc.next + 1) % sc.images.len() as u32;
        sc.acquired.push_back(i);
        // SAFETY: caller's output.
        unsafe { *index = i };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn wait_swapchain_image(
    swapchain: xr::Swapchain,
    _info: *const xr::SwapchainImageWaitInfo,
) -> xr::Result {
    with_swapchain(swapchain, |sc| {
        if sc.waited.is_some() || sc.acquired.is_empty() {
            return xr::Result::ERROR_CALL_ORDER_INVALID;
        }
        // The compositor is done with the image as soon as it is acquired (the
        // runtime reads back inside xrEndFrame, synchronously).
        sc.waited = sc.acquired.front().copied();
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn release_swapchain_image(
    swapchain: xr::Swapchain,
    _info: *const xr::SwapchainImageReleaseInfo,
) -> xr::Result {
    with_swapchain(swapchain, |sc| {
        let Some(i) = sc.waited.take() else { return xr::Result::ERROR_CALL_ORDER_INVALID };
        sc.acquired.pop_front();
        sc.last_released = Some(i);
        xr::Result::SUCCESS
    })
}
