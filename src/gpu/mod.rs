//! Vulkan (ash) foundation: instance and device, validation-message capture, RAII
//! buffers with staging upload/readback, compute pipelines, one-shot submission.
//!
//! Teardown order (enforced by lifetimes, not by convention): every `Buffer<'a>` and
//! `ComputePipeline<'a>` borrows the `GpuContext`, so the borrow checker makes them
//! drop first; `GpuContext::drop` then waits for the device to idle and destroys the
//! command pool, the device, the debug messenger and the instance, in that order
//! (Vulkan spec: child objects before their parents, VUID-vkDestroyDevice-device-
//! 05137, VUID-vkDestroyInstance-instance-00629).
#![allow(unsafe_code)]

mod depth_readback;
mod fenced;
mod frames;
mod graphics;
mod image;
mod pipeline;
mod query;
mod upload;

pub use depth_readback::DepthReadback;
pub use frames::{FrameRing, FrameSlot};
pub use graphics::{GraphicsDesc, GraphicsPipeline, MultiviewTarget, VertexAttribute, EYES};
pub use image::{record_copy_to_external_depth, texel_bytes, Image, Texture};
pub use pipeline::{ComputePipeline, Resource};
pub use query::{QueryPool, Statistics};
pub use upload::ImageUpload;

use ash::vk;
use std::ffi::{c_void, CStr};
use std::sync::{Arc, Mutex};

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("Vulkan loader not available: {0}")]
    Loader(String),
    #[error("no Vulkan device with a graphics+compute queue")]
    NoDevice,
    #[error("Vulkan call {call} failed: {result}")]
    Vk { call: &'static str, result: vk::Result },
    #[error("no memory type for {0}")]
    NoMemoryType(&'static str),
    #[error("invalid input `{input}`: {problem}")]
    Input { input: &'static str, problem: String },
}

/// `map_err` helper naming the failed call.
pub(crate) fn vkr(call: &'static str) -> impl Fn(vk::Result) -> GpuError {
    move |result| GpuError::Vk { call, result }
}

/// Options for context creation.
#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// Enable VK_LAYER_KHRONOS_validation when installed (tests do).
    pub validation: bool,
    /// Substring of the device name to prefer (e.g. "llvmpipe"); else discrete >
    /// integrated > CPU.
    pub prefer_device: Option<String>,
}

/// Who creates the Vulkan instance and device. On desktop, the context does
/// (`DirectVulkan`); under OpenXR (XR_KHR_vulkan_enable2) the *runtime* must, with
/// the create infos the context built (the runtime may add what its compositor
/// needs), and the runtime picks the physical device its HMD is connected to. The
/// context owns (and destroys) whatever the factory created either way: the spec
/// leaves the instance and device to the application.
pub trait VulkanFactory {
    /// Create the instance from `info` (layers and extensions the context needs).
    fn create_instance(&self, entry: &ash::Entry, info: &vk::InstanceCreateInfo<'_>) -> Result<vk::Instance, GpuError>;
    /// The physical device to use, or None to let the context choose.
    fn physical_device(&self, instance: &ash::Instance) -> Result<Option<vk::PhysicalDevice>, GpuError>;
    /// Create the device on `physical` from `info`.
    fn create_device(
        &self,
        entry: &ash::Entry,
        instance: &ash::Instance,
        physical: vk::PhysicalDevice,
        info: &vk::DeviceCreateInfo<'_>,
    ) -> Result<vk::Device, GpuError>;
}

/// Plain Vulkan: the context creates everything itself.
pub struct DirectVulkan;

impl VulkanFactory for DirectVulkan {
    fn create_instance(&self, entry: &ash::Entry, info: &vk::InstanceCreateInfo<'_>) -> Result<vk::Instance, GpuError> {
        // SAFETY: `info` and everything it points to live until the call returns.
        unsafe { entry.create_instance(info, None) }.map(|i| i.handle()).map_err(vkr("vkCreateInstance"))
    }

    fn physical_device(&self, _instance: &ash::Instance) -> Result<Option<vk::PhysicalDevice>, GpuError> {
        Ok(None)
    }

    fn create_device(
        &self,
        _entry: &ash::Entry,
        instance: &ash::Instance,
        physical: vk::PhysicalDevice,
        info: &vk::DeviceCreateInfo<'_>,
    ) -> Result<vk::Device, GpuError> {
        // SAFETY: `physical` belongs to `instance`; `info` valid for the call.
        unsafe { instance.create_device(physical, info, None) }.map(|d| d.handle()).map_err(vkr("vkCreateDevice"))
    }
}

/// Severity-filtered validation and driver messages, kept for the caller to check.
type Messages = Arc<Mutex<Vec<String>>>;

pub struct GpuContext {
    // Field order is not the drop order: `Drop` below destroys explicitly.
    _entry: ash::Entry,
    instance: ash::Instance,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT, *const Mutex<Vec<String>>)>,
    debug_device: Option<ash::ext::debug_utils::Device>,
    messages: Messages,
    validation: bool,
    physical: vk::PhysicalDevice,
    memory: vk::PhysicalDeviceMemoryProperties,
    pub(crate) device: ash::Device,
    pub(crate) queue: vk::Queue,
    queue_family: u32,
    pub(crate) command_pool: vk::CommandPool,
    device_name: String,
    timestamp_period_ns: Option<f32>,
    statistics: bool,
    /// When set, `dispatch_and_wait` brackets its commands with timestamps and adds
    /// the GPU time to `gpu_time_ms` (benchmarks; off by default).
    timing: std::cell::Cell<bool>,
    gpu_time_ms: std::cell::Cell<f64>,
}

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: `data` is valid for the duration of the callback (Vulkan spec,
    // PFN_vkDebugUtilsMessengerCallbackEXT); `user` is the `Mutex` leaked from an
    // `Arc` in `GpuContext::new`, alive until the messenger is destroyed in `Drop`.
    let (text, sink) = unsafe {
        let text = (*data).message_as_c_str().map(|m| m.to_string_lossy().into_owned()).unwrap_or_default();
        (text, &*(user as *const Mutex<Vec<String>>))
    };
    if severity
        .intersects(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR)
    {
        if let Ok(mut v) = sink.lock() {
            v.push(text);
        }
    }
    vk::FALSE
}

impl GpuContext {
    /// Load Vulkan, create an instance (validation if asked and installed), pick a
    /// device with a compute queue, create it.
    pub fn new(opts: &GpuOptions) -> Result<Self, GpuError> {
        Self::with_factory(opts, &DirectVulkan)
    }

    /// As `new`, with the instance and device created by `factory` (OpenXR).
    pub fn with_factory(opts: &GpuOptions, factory: &dyn VulkanFactory) -> Result<Self, GpuError> {
        // SAFETY: loading the system Vulkan loader library; no other Vulkan state
        // exists yet.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| GpuError::Loader(e.to_string()))?;
        // SAFETY: plain queries on a loaded entry.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }.map_err(vkr("enumerate layers"))?;
        let extensions =
            unsafe { entry.enumerate_instance_extension_properties(None) }.map_err(vkr("enumerate extensions"))?;
        let has_layer = |name: &CStr| layers.iter().any(|l| l.layer_name_as_c_str() == Ok(name));
        let has_ext = |name: &CStr| extensions.iter().any(|e| e.extension_name_as_c_str() == Ok(name));
        let validation = c"VK_LAYER_KHRONOS_validation";
        let use_validation = opts.validation && has_layer(validation);
        let use_debug = has_ext(ash::ext::debug_utils::NAME);
        let layer_ptrs: Vec<*const std::ffi::c_char> = if use_validation { vec![validation.as_ptr()] } else { vec![] };
        let ext_ptrs: Vec<*const std::ffi::c_char> =
            if use_debug { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
        let app = vk::ApplicationInfo::default()
            .application_name(c"blind-augment")
            .engine_name(c"blind-augment")
            .api_version(vk::API_VERSION_1_1);
        let info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_ptrs)
            .enabled_extension_names(&ext_ptrs);
        let handle = factory.create_instance(&entry, &info)?;
        // SAFETY: a live instance created from `entry`'s loader with `info`.
        let instance = unsafe { ash::Instance::load(entry.static_fn(), handle) };

        let messages: Messages = Arc::new(Mutex::new(Vec::new()));
        let debug = if use_debug {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let user = Arc::into_raw(messages.clone());
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(on_message))
                .user_data(user as *mut c_void);
            // SAFETY: valid instance with the debug-utils extension enabled; `user`
            // stays alive (leaked Arc) until `Drop` destroys the messenger first.
            match unsafe { loader.create_debug_utils_messenger(&info, None) } {
                Ok(m) => Some((loader, m, user)),
                Err(_) => {
                    // SAFETY: reclaim the leaked Arc; no messenger refers to it.
                    drop(unsafe { Arc::from_raw(user) });
                    None
                }
            }
        } else {
            None
        };

        match create_device(&entry, &instance, opts, factory) {
            Ok(parts) => {
                let debug_device = debug.as_ref().map(|_| ash::ext::debug_utils::Device::new(&instance, &parts.device));
                Ok(Self {
                    _entry: entry,
                    instance,
                    debug,
                    debug_device,
                    messages,
                    validation: use_validation,
                    physical: parts.physical,
                    memory: parts.memory,
                    device: parts.device,
                    queue: parts.queue,
                    queue_family: parts.family,
                    command_pool: parts.command_pool,
                    device_name: parts.name,
                    timestamp_period_ns: parts.timestamp_period_ns,
                    statistics: parts.statistics,
                    timing: std::cell::Cell::new(false),
                    gpu_time_ms: std::cell::Cell::new(0.0),
                })
            }
            Err(e) => {
                // SAFETY: nothing created from the instance survives; destroy in order.
                unsafe {
                    if let Some((loader, m, user)) = debug {
                        loader.destroy_debug_utils_messenger(m, None);
                        drop(Arc::from_raw(user));
                    }
                    instance.destroy_instance(None);
                }
                Err(e)
            }
        }
    }

    pub fn device_name(&self) -> &str {
        &self.device_name
    }

    /// Whether VK_LAYER_KHRONOS_validation is active on this instance.
    pub fn validation_enabled(&self) -> bool {
        self.validation
    }

    pub fn physical_device(&self) -> vk::PhysicalDevice {
        self.physical
    }

    /// Raw handles for an OpenXR graphics binding (XrGraphicsBindingVulkan2KHR):
    /// instance, physical device, device, queue family; queue index 0.
    pub fn raw_handles(&self) -> (vk::Instance, vk::PhysicalDevice, vk::Device, u32) {
        (self.instance.handle(), self.physical, self.device.handle(), self.queue_family)
    }

    /// Validation/driver warnings and errors since the last call (tests fail on any).
    pub fn take_messages(&self) -> Vec<String> {
        self.messages.lock().map(|mut v| std::mem::take(&mut *v)).unwrap_or_default()
    }

    /// Name a Vulkan object for debuggers and validation messages (no-op without
    /// VK_EXT_debug_utils).
    pub fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Some(dd) = &self.debug_device else { return };
        let Ok(cname) = std::ffi::CString::new(name) else { return };
        let info = vk::DebugUtilsObjectNameInfoEXT::default().object_handle(handle).object_name(&cname);
        // SAFETY: `handle` is a live object of this device; the name outlives the call.
        let _ = unsafe { dd.set_debug_utils_object_name(&info) };
    }

    pub(crate) fn memory_type(&self, bits: u32, props: vk::MemoryPropertyFlags) -> Option<u32> {
        (0..self.memory.memory_type_count)
            .find(|&i| bits & (1 << i) != 0 && self.memory.memory_types[i as usize].property_flags.contains(props))
    }

    /// One primary command buffer from the context's pool (freed by the caller).
    pub(crate) fn allocate_command_buffer(&self) -> Result<vk::CommandBuffer, GpuError> {
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(self.command_pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool belongs to this device and is only used from this thread
        // (GpuContext is not Sync).
        Ok(unsafe { self.device.allocate_command_buffers(&alloc) }.map_err(vkr("allocate command buffer"))?[0])
    }

    /// Record with `f` into a fresh command buffer, submit, wait (fence).
    pub fn submit_and_wait(&self, f: impl FnOnce(vk::CommandBuffer)) -> Result<(), GpuError> {
        let cmd = self.allocate_command_buffer()?;
        let result = (|| {
            let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            // SAFETY: freshly allocated primary command buffer.
            unsafe { self.device.begin_command_buffer(cmd, &begin) }.map_err(vkr("begin command buffer"))?;
            f(cmd);
            // SAFETY: recording state, ends the recording started above.
            unsafe { self.device.end_command_buffer(cmd) }.map_err(vkr("end command buffer"))?;
            // SAFETY: valid device.
            let fence = unsafe { self.device.create_fence(&vk::FenceCreateInfo::default(), None) }
                .map_err(vkr("create fence"))?;
            let submit = vk::SubmitInfo::default().command_buffers(std::slice::from_ref(&cmd));
            // SAFETY: executable command buffer, unsignalled fence; we wait before
            // destroying either.
            let r = unsafe {
                self.device
                    .queue_submit(self.queue, &[submit], fence)
                    .and_then(|_| self.device.wait_for_fences(&[fence], true, u64::MAX))
            };
            // SAFETY: the fence is signalled or the submit failed; not in use.
            unsafe { self.device.destroy_fence(fence, None) };
            r.map_err(vkr("queue submit / wait"))
        })();
        // SAFETY: execution finished (or never started).
        unsafe { self.device.free_command_buffers(self.command_pool, &[cmd]) };
        result
    }

    /// Whether pipeline-statistics queries were enabled (device feature).
    pub fn has_pipeline_statistics(&self) -> bool {
        self.statistics
    }

    /// Nanoseconds per timestamp tick, when timestamps are supported.
    pub fn timestamp_period_ns(&self) -> Option<f32> {
        self.timestamp_period_ns
    }

    /// Whether the device supports timestamp queries on the compute queue.
    pub fn has_timestamps(&self) -> bool {
        self.timestamp_period_ns.is_some()
    }

    /// Start (or stop) accumulating GPU time of `dispatch_and_wait`; resets the total.
    pub fn set_timing(&self, on: bool) {
        self.timing.set(on && self.has_timestamps());
        self.gpu_time_ms.set(0.0);
    }

    /// GPU time (ms) of the dispatches since `set_timing(true)`.
    pub fn gpu_time_ms(&self) -> f64 {
        self.gpu_time_ms.get()
    }

    /// `submit_and_wait` for compute work: when timing is on, the commands are
    /// bracketed by timestamps (top and bottom of pipe) and their GPU time added to
    /// `gpu_time_ms`. Transfers use plain `submit_and_wait` and are not counted.
    pub fn dispatch_and_wait(&self, f: impl FnOnce(vk::CommandBuffer)) -> Result<(), GpuError> {
        let Some(period_ns) = self.timestamp_period_ns.filter(|_| self.timing.get()) else {
            return self.submit_and_wait(f);
        };
        let info = vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(2);
        // SAFETY: valid device; the pool is destroyed below after the fenced wait.
        let pool = unsafe { self.device.create_query_pool(&info, None) }.map_err(vkr("vkCreateQueryPool"))?;
        let result = self.submit_and_wait(|cmd| {
            // SAFETY: `cmd` is recording; queries 0 and 1 of a live pool, reset first.
            unsafe {
                self.device.cmd_reset_query_pool(cmd, pool, 0, 2);
                self.device.cmd_write_timestamp(cmd, vk::PipelineStageFlags::TOP_OF_PIPE, pool, 0);
            }
            f(cmd);
            // SAFETY: as above.
            unsafe { self.device.cmd_write_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, pool, 1) };
        });
        let mut ticks = [0u64; 2];
        let read = result.and_then(|_| {
            // SAFETY: the submission completed (fenced); both queries were written.
            unsafe {
                self.device.get_query_pool_results(
                    pool,
                    0,
                    &mut ticks,
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
            }
            .map_err(vkr("vkGetQueryPoolResults"))
        });
        // SAFETY: no pending use of the pool remains.
        unsafe { self.device.destroy_query_pool(pool, None) };
        read?;
        let ms = ticks[1].saturating_sub(ticks[0]) as f64 * period_ns as f64 * 1e-6;
        self.gpu_time_ms.set(self.gpu_time_ms.get() + ms);
        Ok(())
    }

    /// A device-local storage buffer holding `data`, uploaded through a staging buffer.
    pub fn upload(&self, data: &[u8], name: &str) -> Result<Buffer<'_>, GpuError> {
        self.upload_as(data, vk::BufferUsageFlags::empty(), name)
    }

    /// As `upload`, with extra usage (vertex, index buffers).
    pub fn upload_as(&self, data: &[u8], usage: vk::BufferUsageFlags, name: &str) -> Result<Buffer<'_>, GpuError> {
        let size = data.len().max(4) as u64;
        let staging = Buffer::new(
            self,
            size,
            vk::BufferUsageFlags::TRANSFER_SRC,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
            &format!("{name} (staging)"),
        )?;
        staging.write(data)?;
        let buffer = Buffer::new(
            self,
            size,
            usage
                | vk::BufferUsageFlags::STORAGE_BUFFER
                | vk::BufferUsageFlags::TRANSFER_DST
                | vk::BufferUsageFlags::TRANSFER_SRC,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            name,
        )?;
        self.submit_and_wait(|cmd| {
            let region = vk::BufferCopy::default().size(size);
            // SAFETY: both buffers are live, large enough, and not in use elsewhere.
            unsafe { self.device.cmd_copy_buffer(cmd, staging.buffer, buffer.buffer, &[region]) };
        })?;
        Ok(buffer)
    }

    /// An uninitialised device-local storage buffer (also a copy source/target).
    pub fn storage_buffer(&self, size: u64, name: &str) -> Result<Buffer<'_>, GpuError> {
        Buffer::new(
            self,
            size.max(4),
            vk::BufferUsageFlags::STORAGE_BUFFER
                | vk::BufferUsageFlags::TRANSFER_DST
                | vk::BufferUsageFlags::TRANSFER_SRC,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            name,
        )
    }

    /// Record a copy of the first `size` bytes of `src` into `dst`.
    pub fn record_copy(&self, cmd: vk::CommandBuffer, src: &Buffer<'_>, dst: &Buffer<'_>, size: u64) {
        let region = vk::BufferCopy::default().size(size.min(src.size).min(dst.size));
        // SAFETY: `cmd` is recording; both buffers are live for the submission
        // (callers wait on it before dropping them) and the region is in bounds.
        unsafe { self.device.cmd_copy_buffer(cmd, src.buffer, dst.buffer, &[region]) };
    }

    /// Copy a device buffer back to the host.
    pub fn download(&self, src: &Buffer<'_>) -> Result<Vec<u8>, GpuError> {
        let readback = Buffer::new(
            self,
            src.size,
            vk::BufferUsageFlags::TRANSFER_DST,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
            "readback",
        )?;
        self.submit_and_wait(|cmd| {
            let region = vk::BufferCopy::default().size(src.size);
            // SAFETY: both buffers live; the caller's earlier submissions completed
            // (submit_and_wait waits), so `src` is not being written.
            unsafe { self.device.cmd_copy_buffer(cmd, src.buffer, readback.buffer, &[region]) };
        })?;
        readback.read()
    }
}

/// Record a full memory barrier (all commands, all memory): used once at the start
/// of a frame's effect chain, where it orders the previous frame's reads before
/// this frame's writes of the same images and buffers.
pub fn record_full_barrier(ctx: &GpuContext, cmd: vk::CommandBuffer) {
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::MEMORY_WRITE | vk::AccessFlags::MEMORY_READ)
        .dst_access_mask(vk::AccessFlags::MEMORY_WRITE | vk::AccessFlags::MEMORY_READ);
    // SAFETY: `cmd` is recording outside a render pass.
    unsafe {
        ctx.device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::DependencyFlags::empty(),
            &[barrier],
            &[],
            &[],
        )
    };
}

/// What `create_device` hands back to `GpuContext::new`.
struct DeviceParts {
    family: u32,
    timestamp_period_ns: Option<f32>,
    statistics: bool,
    physical: vk::PhysicalDevice,
    memory: vk::PhysicalDeviceMemoryProperties,
    device: ash::Device,
    queue: vk::Queue,
    command_pool: vk::CommandPool,
    name: String,
}

/// Pick a device with a compute queue (preferred name, else discrete > integrated >
/// CPU) and create it with one queue and a command pool. Cleans up after itself on
/// error; the caller owns the instance.
fn create_device(
    entry: &ash::Entry,
    instance: &ash::Instance,
    opts: &GpuOptions,
    factory: &dyn VulkanFactory,
) -> Result<DeviceParts, GpuError> {
    // The factory's device (the HMD's GPU) when it names one; else every device.
    let devices = match factory.physical_device(instance)? {
        Some(pd) => vec![pd],
        // SAFETY: valid instance.
        None => unsafe { instance.enumerate_physical_devices() }.map_err(vkr("enumerate devices"))?,
    };
    let mut candidates = vec![];
    for pd in devices {
        // SAFETY: `pd` comes from this instance.
        let props = unsafe { instance.get_physical_device_properties(pd) };
        let name = props.device_name_as_c_str().map(|c| c.to_string_lossy().into_owned()).unwrap_or_default();
        // SAFETY: as above.
        let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
        let Some(qf) =
            families.iter().position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE | vk::QueueFlags::GRAPHICS))
        else {
            continue;
        };
        let rank = match (&opts.prefer_device, props.device_type) {
            (Some(want), _) if name.contains(want.as_str()) => 0,
            (_, vk::PhysicalDeviceType::DISCRETE_GPU) => 1,
            (_, vk::PhysicalDeviceType::INTEGRATED_GPU) => 2,
            _ => 3,
        };
        candidates.push((rank, pd, qf as u32, name));
    }
    candidates.sort_by_key(|c| c.0);
    let (_, physical, family, name) = candidates.into_iter().next().ok_or(GpuError::NoDevice)?;
    let priorities = [1.0f32];
    let queue_info = vk::DeviceQueueCreateInfo::default().queue_family_index(family).queue_priorities(&priorities);
    // Pipeline-statistics queries (fragment/compute invocation counts for the
    // coverage benchmark) are an optional feature: enabled where supported.
    // SAFETY: `physical` belongs to `instance`.
    let supported = unsafe { instance.get_physical_device_features(physical) };
    let statistics = supported.pipeline_statistics_query == vk::TRUE;
    let features = vk::PhysicalDeviceFeatures::default().pipeline_statistics_query(statistics);
    // Multiview (Vulkan 1.1 core; the stereo target is one render pass over two
    // layers). Required: every Vulkan 1.1 device supports it (spec, Feature
    // Requirements: multiview is mandatory in 1.1).
    let mut multiview = vk::PhysicalDeviceMultiviewFeatures::default().multiview(true);
    let info = vk::DeviceCreateInfo::default()
        .queue_create_infos(std::slice::from_ref(&queue_info))
        .enabled_features(&features)
        .push_next(&mut multiview);
    let handle = factory.create_device(entry, instance, physical, &info)?;
    // SAFETY: a live device created on `physical` with `info`.
    let device = unsafe { ash::Device::load(instance.fp_v1_0(), handle) };
    // SAFETY: family/index 0 were requested at device creation.
    let queue = unsafe { device.get_device_queue(family, 0) };
    let pool_info = vk::CommandPoolCreateInfo::default()
        .queue_family_index(family)
        .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
    // SAFETY: valid device.
    let command_pool = match unsafe { device.create_command_pool(&pool_info, None) } {
        Ok(p) => p,
        Err(r) => {
            // SAFETY: the device has no children yet.
            unsafe { device.destroy_device(None) };
            return Err(GpuError::Vk { call: "vkCreateCommandPool", result: r });
        }
    };
    // SAFETY: valid physical device.
    let memory = unsafe { instance.get_physical_device_memory_properties(physical) };
    // Timestamps need a non-zero period and valid bits on the queue family.
    // SAFETY: valid physical device.
    let (props, families) = unsafe {
        (
            instance.get_physical_device_properties(physical),
            instance.get_physical_device_queue_family_properties(physical),
        )
    };
    let valid_bits = families.get(family as usize).map_or(0, |f| f.timestamp_valid_bits);
    let timestamp_period_ns =
        (valid_bits > 0 && props.limits.timestamp_period > 0.0).then_some(props.limits.timestamp_period);
    Ok(DeviceParts { family, timestamp_period_ns, statistics, physical, memory, device, queue, command_pool, name })
}

impl Drop for GpuContext {
    fn drop(&mut self) {
        // SAFETY: all child objects (buffers, pipelines) borrow `self` and are gone;
        // wait for the queue, then destroy children before parents.
        unsafe {
            let _ = self.device.device_wait_idle();
            self.device.destroy_command_pool(self.command_pool, None);
            self.device.destroy_device(None);
            if let Some((loader, m, user)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(m, None);
                drop(Arc::from_raw(user));
            }
            self.instance.destroy_instance(None);
        }
    }
}

/// A buffer and its memory, freed on drop; cannot outlive its context.
pub struct Buffer<'a> {
    ctx: &'a GpuContext,
    pub(crate) buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    pub size: u64,
}

impl<'a> Buffer<'a> {
    pub fn new(
        ctx: &'a GpuContext,
        size: u64,
        usage: vk::BufferUsageFlags,
        props: vk::MemoryPropertyFlags,
        name: &str,
    ) -> Result<Self, GpuError> {
        let info = vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid device and create info.
        let buffer = unsafe { ctx.device.create_buffer(&info, None) }.map_err(vkr("vkCreateBuffer"))?;
        // SAFETY: `buffer` was just created on this device.
        let reqs = unsafe { ctx.device.get_buffer_memory_requirements(buffer) };
        let Some(type_index) = ctx.memory_type(reqs.memory_type_bits, props) else {
            // SAFETY: unbound, unused buffer.
            unsafe { ctx.device.destroy_buffer(buffer, None) };
            return Err(GpuError::NoMemoryType("buffer"));
        };
        let alloc = vk::MemoryAllocateInfo::default().allocation_size(reqs.size).memory_type_index(type_index);
        // SAFETY: valid allocation info for this device.
        let memory = match unsafe { ctx.device.allocate_memory(&alloc, None) } {
            Ok(m) => m,
            Err(r) => {
                // SAFETY: unbound, unused buffer.
                unsafe { ctx.device.destroy_buffer(buffer, None) };
                return Err(GpuError::Vk { call: "vkAllocateMemory", result: r });
            }
        };
        // SAFETY: memory of a compatible type and size, offset 0, both unbound.
        if let Err(r) = unsafe { ctx.device.bind_buffer_memory(buffer, memory, 0) } {
            // SAFETY: neither object is in use.
            unsafe {
                ctx.device.destroy_buffer(buffer, None);
                ctx.device.free_memory(memory, None);
            }
            return Err(GpuError::Vk { call: "vkBindBufferMemory", result: r });
        }
        ctx.set_name(buffer, name);
        Ok(Self { ctx, buffer, memory, size })
    }

    /// Copy `data` in (host-visible, coherent buffers only).
    pub fn write(&self, data: &[u8]) -> Result<(), GpuError> {
        let n = (data.len() as u64).min(self.size) as usize;
        // SAFETY: host-visible coherent memory, mapped for its whole size, written
        // within bounds, unmapped before any GPU use (callers submit afterwards).
        unsafe {
            let ptr = self
                .ctx
                .device
                .map_memory(self.memory, 0, self.size, vk::MemoryMapFlags::empty())
                .map_err(vkr("vkMapMemory"))? as *mut u8;
            std::ptr::copy_nonoverlapping(data.as_ptr(), ptr, n);
            self.ctx.device.unmap_memory(self.memory);
        }
        Ok(())
    }

    /// Copy the contents out (host-visible, coherent buffers only).
    pub fn read(&self) -> Result<Vec<u8>, GpuError> {
        let mut out = vec![0u8; self.size as usize];
        // SAFETY: as in `write`; the GPU finished writing (submit_and_wait waited).
        unsafe {
            let ptr = self
                .ctx
                .device
                .map_memory(self.memory, 0, self.size, vk::MemoryMapFlags::empty())
                .map_err(vkr("vkMapMemory"))? as *const u8;
            std::ptr::copy_nonoverlapping(ptr, out.as_mut_ptr(), out.len());
            self.ctx.device.unmap_memory(self.memory);
        }
        Ok(out)
    }
}

impl Drop for Buffer<'_> {
    fn drop(&mut self) {
        // SAFETY: every submission that used this buffer was waited on
        // (submit_and_wait); buffer before memory.
        unsafe {
            self.ctx.device.destroy_buffer(self.buffer, None);
            self.ctx.device.free_memory(self.memory, None);
        }
    }
}
