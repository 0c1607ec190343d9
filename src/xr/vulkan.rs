//! The Vulkan instance and device of the render core, created through the OpenXR
//! runtime (XR_KHR_vulkan_enable2): `gpu::GpuContext::with_factory` builds the
//! create infos, this factory hands them to the runtime.

use crate::gpu::{GpuError, VulkanFactory};
use ash::vk;
use ash::vk::Handle as _;
use openxr as xr;

/// The Vulkan instance and device, created through the OpenXR runtime
/// (XR_KHR_vulkan_enable2, spec 12.21).
pub(super) struct XrVulkan<'a> {
    pub instance: &'a xr::Instance,
    pub system: xr::SystemId,
}

fn runtime_err(call: &'static str, e: xr::sys::Result) -> GpuError {
    GpuError::Input { input: call, problem: format!("OpenXR: {e}") }
}

impl VulkanFactory for XrVulkan<'_> {
    fn create_instance(&self, entry: &ash::Entry, info: &vk::InstanceCreateInfo<'_>) -> Result<vk::Instance, GpuError> {
        let gipa = entry.static_fn().get_instance_proc_addr;
        // SAFETY: `gipa` is the loader's vkGetInstanceProcAddr (the same C signature
        // openxr-sys declares); `info` is a valid VkInstanceCreateInfo for the call.
        let r = unsafe {
            self.instance.create_vulkan_instance(
                self.system,
                std::mem::transmute::<vk::PFN_vkGetInstanceProcAddr, xr::sys::platform::VkGetInstanceProcAddr>(gipa),
                info as *const _ as *const _,
            )
        };
        match r {
            Ok(Ok(raw)) => Ok(vk::Instance::from_raw(raw as u64)),
            Ok(Err(v)) => Err(GpuError::Vk { call: "xrCreateVulkanInstanceKHR", result: vk::Result::from_raw(v) }),
            Err(e) => Err(runtime_err("xrCreateVulkanInstanceKHR", e)),
        }
    }

    fn physical_device(&self, instance: &ash::Instance) -> Result<Option<vk::PhysicalDevice>, GpuError> {
        // SAFETY: a live instance created through this XR instance.
        let raw = unsafe { self.instance.vulkan_graphics_device(self.system, instance.handle().as_raw() as _) }
            .map_err(|e| runtime_err("xrGetVulkanGraphicsDevice2KHR", e))?;
        Ok(Some(vk::PhysicalDevice::from_raw(raw as u64)))
    }

    fn create_device(
        &self,
        entry: &ash::Entry,
        _instance: &ash::Instance,
        physical: vk::PhysicalDevice,
        info: &vk::DeviceCreateInfo<'_>,
    ) -> Result<vk::Device, GpuError> {
        let gipa = entry.static_fn().get_instance_proc_addr;
        // SAFETY: as in create_instance; `physical` came from xrGetVulkanGraphicsDevice2KHR.
        let r = unsafe {
            self.instance.create_vulkan_device(
                self.system,
                std::mem::transmute::<vk::PFN_vkGetInstanceProcAddr, xr::sys::platform::VkGetInstanceProcAddr>(gipa),
                physical.as_raw() as _,
                info as *const _ as *const _,
            )
        };
        match r {
            Ok(Ok(raw)) => Ok(vk::Device::from_raw(raw as u64)),
            Ok(Err(v)) => Err(GpuError::Vk { call: "xrCreateVulkanDeviceKHR", result: vk::Result::from_raw(v) }),
            Err(e) => Err(runtime_err("xrCreateVulkanDeviceKHR", e)),
        }
    }
}
