//! XR_KHR_vulkan_enable2 (the app's Vulkan instance and device are created through
//! the runtime) and the swapchains' Vulkan side: images the runtime owns on the
//! app's device, kept in the layout XR_KHR_vulkan_enable prescribes between release
//! and acquire (COLOR_ATTACHMENT_OPTIMAL / DEPTH_STENCIL_ATTACHMENT_OPTIMAL), read
//! back for PNG. The swapchain entry points (acquire → wait → release, spec 10.1)
//! are in `swapchain.rs`.

pub(crate) use crate::swapchain::Swapchain;
use crate::{with_instance, SYSTEM_ID};
use ash::vk;
use ash::vk::Handle as _;
use openxr_sys as xr;
use std::collections::VecDeque;
use std::sync::Mutex;

/// Swapchain images per swapchain (triple buffering, as Quest's compositor).
const IMAGES: u32 = 3;

/// The Vulkan instance created through xrCreateVulkanInstanceKHR (needed to resolve
/// vkCreateDevice for xrCreateVulkanDeviceKHR, whose create info names no instance).
static VK_INSTANCE: Mutex<u64> = Mutex::new(0);

pub(crate) struct VkState {
    _entry: ash::Entry,
    instance: ash::Instance,
    device: ash::Device,
    queue: vk::Queue,
    pool: vk::CommandPool,
    memory: vk::PhysicalDeviceMemoryProperties,
    pub(crate) formats: Vec<vk::Format>,
}

fn vk_err(call: &str) -> impl Fn(vk::Result) -> String + '_ {
    move |r| format!("{call}: {r}")
}

impl VkState {
    /// Adopt the app's instance and device from its graphics binding.
    pub fn new(b: &xr::GraphicsBindingVulkanKHR) -> Result<Self, String> {
        // SAFETY: loads the system Vulkan loader — the same library the app's handles
        // come from (one process), so they are valid through it.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("Vulkan loader: {e}"))?;
        let instance_h = vk::Instance::from_raw(b.instance as u64);
        // SAFETY: `instance_h` is the app's live instance (spec: valid until the
        // session is destroyed).
        let instance = unsafe { ash::Instance::load(entry.static_fn(), instance_h) };
        let physical = vk::PhysicalDevice::from_raw(b.physical_device as u64);
        // SAFETY: the app's live device on that instance.
        let device = unsafe { ash::Device::load(instance.fp_v1_0(), vk::Device::from_raw(b.device as u64)) };
        // SAFETY: the binding names a queue the app created.
        let queue = unsafe { device.get_device_queue(b.queue_family_index, b.queue_index) };
        let info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(b.queue_family_index)
            .flags(vk::CommandPoolCreateFlags::TRANSIENT);
        // SAFETY: valid device.
        let pool = unsafe { device.create_command_pool(&info, None) }.map_err(vk_err("vkCreateCommandPool"))?;
        // SAFETY: valid physical device.
        let memory = unsafe { instance.get_physical_device_memory_properties(physical) };
        let candidates = [
            (vk::Format::R8G8B8A8_SRGB, false),
            (vk::Format::B8G8R8A8_SRGB, false),
            (vk::Format::R8G8B8A8_UNORM, false),
            (vk::Format::B8G8R8A8_UNORM, false),
            (vk::Format::R16G16B16A16_SFLOAT, false),
            (vk::Format::D32_SFLOAT, true),
            (vk::Format::D24_UNORM_S8_UINT, true),
        ];
        let formats = candidates
            .iter()
            .filter(|(f, depth)| {
                // SAFETY: valid physical device.
                let p = unsafe { instance.get_physical_device_format_properties(physical, *f) };
                let need = if *depth {
                    vk::FormatFeatureFlags::DEPTH_STENCIL_ATTACHMENT
                } else {
                    vk::FormatFeatureFlags::COLOR_ATTACHMENT | vk::FormatFeatureFlags::TRANSFER_SRC
                };
                p.optimal_tiling_features.contains(need)
            })
            .map(|(f, _)| *f)
            .collect();
        Ok(Self { _entry: entry, instance, device, queue, pool, memory, formats })
    }

    pub fn destroy(self) {
        // SAFETY: no runtime command buffer is pending (every submission is waited
        // on); the pool is the runtime's own. The app owns the device and instance.
        unsafe { self.device.destroy_command_pool(self.pool, None) };
        let _ = &self.instance;
    }

    pub fn destroy_swapchain(&self, sc: Swapchain) {
        // SAFETY: the queue is idle before the images go (the app's rendering into
        // them and the runtime's read-backs have finished).
        unsafe {
            let _ = self.device.queue_wait_idle(self.queue);
            for (image, memory) in sc.images {
                self.device.destroy_image(image, None);
                self.device.free_memory(memory, None);
            }
        }
    }

    /// One-time commands on the app's queue, waited for (the spec lets the runtime
    /// use the queue inside xrCreateSwapchain and xrEndFrame; the app synchronises).
    fn submit(&self, f: impl FnOnce(vk::CommandBuffer)) -> Result<(), String> {
        let alloc = vk::CommandBufferAllocateInfo::default().command_pool(self.pool).command_buffer_count(1);
        // SAFETY: valid pool of this device.
        let cmd =
            unsafe { self.device.allocate_command_buffers(&alloc) }.map_err(vk_err("vkAllocateCommandBuffers"))?[0];
        // SAFETY: fresh command buffer, recorded, submitted and waited for; freed after.
        let r = unsafe {
            self.device
                .begin_command_buffer(
                    cmd,
                    &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .map_err(vk_err("vkBeginCommandBuffer"))
                .and_then(|_| {
                    f(cmd);
                    self.device.end_command_buffer(cmd).map_err(vk_err("vkEndCommandBuffer"))
                })
                .and_then(|_| {
                    let submit = vk::SubmitInfo::default().command_buffers(std::slice::from_ref(&cmd));
                    self.device.queue_submit(self.queue, &[submit], vk::Fence::null()).map_err(vk_err("vkQueueSubmit"))
                })
                .and_then(|_| self.device.queue_wait_idle(self.queue).map_err(vk_err("vkQueueWaitIdle")))
        };
        // SAFETY: the queue is idle: the command buffer is not pending.
        unsafe { self.device.free_command_buffers(self.pool, &[cmd]) };
        r
    }

    fn barrier(
        &self,
        cmd: vk::CommandBuffer,
        image: vk::Image,
        depth: bool,
        from: vk::ImageLayout,
        to: vk::ImageLayout,
    ) {
        let aspect = if depth { vk::ImageAspectFlags::DEPTH } else { vk::ImageAspectFlags::COLOR };
        let b = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::MEMORY_WRITE | vk::AccessFlags::MEMORY_READ)
            .dst_access_mask(vk::AccessFlags::MEMORY_WRITE | vk::AccessFlags::MEMORY_READ)
            .old_layout(from)
            .new_layout(to)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(vk::ImageSubresourceRange {
                aspect_mask: aspect,
                base_mip_level: 0,
                level_count: 1,
                base_array_layer: 0,
                layer_count: vk::REMAINING_ARRAY_LAYERS,
            });
        // SAFETY: `cmd` is recording outside a render pass; the image is ours.
        unsafe {
            self.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[b],
            )
        };
    }

    pub(crate) fn create_swapchain(&self, info: &xr::SwapchainCreateInfo) -> Result<Swapchain, xr::Result> {
        let format = vk::Format::from_raw(info.format as i32);
        if !self.formats.contains(&format) {
            return Err(xr::Result::ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED);
        }
        if info.face_count != 1 || info.mip_count != 1 || info.sample_count != 1 || info.array_size == 0 {
            return Err(xr::Result::ERROR_FEATURE_UNSUPPORTED);
        }
        if info.width == 0 || info.height == 0 || info.width > 8192 || info.height > 8192 {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let depth = matches!(format, vk::Format::D32_SFLOAT | vk::Format::D24_UNORM_S8_UINT);
        let u = info.usage_flags;
        let mut usage = vk::ImageUsageFlags::TRANSFER_SRC;
        let map = [
            (xr::SwapchainUsageFlags::COLOR_ATTACHMENT, vk::ImageUsageFlags::COLOR_ATTACHMENT),
            (xr::SwapchainUsageFlags::DEPTH_STENCIL_ATTACHMENT, vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT),
            (xr::SwapchainUsageFlags::UNORDERED_ACCESS, vk::ImageUsageFlags::STORAGE),
            (xr::SwapchainUsageFlags::TRANSFER_SRC, vk::ImageUsageFlags::TRANSFER_SRC),
            (xr::SwapchainUsageFlags::TRANSFER_DST, vk::ImageUsageFlags::TRANSFER_DST),
            (xr::SwapchainUsageFlags::SAMPLED, vk::ImageUsageFlags::SAMPLED),
        ];
        for (x, v) in map {
            if u.contains(x) {
                usage |= v;
            }
        }
        // The runtime's layout transitions and read-back need one of these anyway.
        usage |=
            if depth { vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT } else { vk::ImageUsageFlags::COLOR_ATTACHMENT };
        let mut images = vec![];
        let fail = |images: &mut Vec<(vk::Image, vk::DeviceMemory)>| {
            for (i, m) in images.drain(..) {
                // SAFETY: unused images of ours.
                unsafe {
                    self.device.destroy_image(i, None);
                    self.device.free_memory(m, None);
                }
            }
            xr::Result::ERROR_RUNTIME_FAILURE
        };
        for _ in 0..IMAGES {
            let ci = vk::ImageCreateInfo::default()
                .image_type(vk::ImageType::TYPE_2D)
                .format(format)
                .extent(vk::Extent3D { width: info.width, height: info.height, depth: 1 })
                .mip_levels(1)
                .array_layers(info.array_size)
                .samples(vk::SampleCountFlags::TYPE_1)
                .tiling(vk::ImageTiling::OPTIMAL)
                .usage(usage)
                .sharing_mode(vk::SharingMode::EXCLUSIVE)
                .initial_layout(vk::ImageLayout::UNDEFINED);
            // SAFETY: valid device and create info.
            let Ok(image) = (unsafe { self.device.create_image(&ci, None) }) else { return Err(fail(&mut images)) };
            // SAFETY: just created.
            let req = unsafe { self.device.get_image_memory_requirements(image) };
            let Some(ty) = (0..self.memory.memory_type_count).find(|&i| {
                req.memory_type_bits & (1 << i) != 0
                    && self.memory.memory_types[i as usize]
                        .property_flags
                        .contains(vk::MemoryPropertyFlags::DEVICE_LOCAL)
            }) else {
                // SAFETY: unbound image of ours.
                unsafe { self.device.destroy_image(image, None) };
                return Err(fail(&mut images));
            };
            let alloc = vk::MemoryAllocateInfo::default().allocation_size(req.size).memory_type_index(ty);
            // SAFETY: valid allocation for this device.
            let Ok(mem) = (unsafe { self.device.allocate_memory(&alloc, None) }) else {
                // SAFETY: unbound image of ours.
                unsafe { self.device.destroy_image(image, None) };
                return Err(fail(&mut images));
            };
            images.push((image, mem));
            // SAFETY: compatible memory, offset 0, both unbound.
            if unsafe { self.device.bind_image_memory(image, mem, 0) }.is_err() {
                return Err(fail(&mut images));
            }
        }
        let steady = if depth {
            vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL
        } else {
            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL
        };
        let r = self.submit(|cmd| {
            for (image, _) in &images {
                self.barrier(cmd, *image, depth, vk::ImageLayout::UNDEFINED, steady);
            }
        });
        if r.is_err() {
            return Err(fail(&mut images));
        }
        Ok(Swapchain {
            width: info.width,
            height: info.height,
            array_size: info.array_size,
            format,
            depth,
            images,
            acquired: VecDeque::new(),
            waited: None,
            next: 0,
            last_released: None,
        })
    }

    /// The last released image's layer `layer` as RGBA8, row-major (8-bit colour
    /// formats only).
    pub fn read_layer(&self, sc: &Swapchain, layer: u32) -> Result<Vec<u8>, String> {
        let bgra = match sc.format {
            vk::Format::R8G8B8A8_SRGB | vk::Format::R8G8B8A8_UNORM => false,
            vk::Format::B8G8R8A8_SRGB | vk::Format::B8G8R8A8_UNORM => true,
            f => return Err(format!("read-back of format {f:?} is not supported")),
        };
        let index = sc.last_released.ok_or("no image released")?;
        let image = sc.images[index as usize].0;
        let size = sc.width as u64 * sc.height as u64 * 4;
        let bi = vk::BufferCreateInfo::default().size(size).usage(vk::BufferUsageFlags::TRANSFER_DST);
        // SAFETY: valid device and create info.
        let buffer = unsafe { self.device.create_buffer(&bi, None) }.map_err(vk_err("vkCreateBuffer"))?;
        // SAFETY: just created.
        let req = unsafe { self.device.get_buffer_memory_requirements(buffer) };
        let want = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let ty = (0..self.memory.memory_type_count).find(|&i| {
            req.memory_type_bits & (1 << i) != 0 && self.memory.memory_types[i as usize].property_flags.contains(want)
        });
        let result = (|| {
            let ty = ty.ok_or("no host-visible memory")?;
            let alloc = vk::MemoryAllocateInfo::default().allocation_size(req.size).memory_type_index(ty);
            // SAFETY: valid allocation info.
            let mem = unsafe { self.device.allocate_memory(&alloc, None) }.map_err(vk_err("vkAllocateMemory"))?;
            let r = (|| {
                // SAFETY: unbound buffer, compatible memory.
                unsafe { self.device.bind_buffer_memory(buffer, mem, 0) }.map_err(vk_err("vkBindBufferMemory"))?;
                let steady = vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL;
                self.submit(|cmd| {
                    // Everything the app submitted before xrEndFrame is ordered before
                    // this copy by the queue and the ALL_COMMANDS barrier.
                    self.barrier(cmd, image, false, steady, vk::ImageLayout::TRANSFER_SRC_OPTIMAL);
                    let region = vk::BufferImageCopy::default()
                        .image_subresource(vk::ImageSubresourceLayers {
                            aspect_mask: vk::ImageAspectFlags::COLOR,
                            mip_level: 0,
                            base_array_layer: layer,
                            layer_count: 1,
                        })
                        .image_extent(vk::Extent3D { width: sc.width, height: sc.height, depth: 1 });
                    // SAFETY: recording; image in TRANSFER_SRC_OPTIMAL, buffer large enough.
                    unsafe {
                        self.device.cmd_copy_image_to_buffer(
                            cmd,
                            image,
                            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                            buffer,
                            &[region],
                        )
                    };
                    self.barrier(cmd, image, false, vk::ImageLayout::TRANSFER_SRC_OPTIMAL, steady);
                })?;
                let mut out = vec![0u8; size as usize];
                // SAFETY: host-visible coherent memory, the copy finished (queue idle).
                unsafe {
                    let p = self
                        .device
                        .map_memory(mem, 0, size, vk::MemoryMapFlags::empty())
                        .map_err(vk_err("vkMapMemory"))?;
                    std::ptr::copy_nonoverlapping(p as *const u8, out.as_mut_ptr(), out.len());
                    self.device.unmap_memory(mem);
                }
                Ok::<_, String>(out)
            })();
            // SAFETY: not in use (queue idle).
            unsafe { self.device.free_memory(mem, None) };
            r
        })();
        // SAFETY: not in use (queue idle).
        unsafe { self.device.destroy_buffer(buffer, None) };
        let mut out = result?;
        if bgra {
            for px in out.chunks_exact_mut(4) {
                px.swap(0, 2);
            }
        }
        Ok(out)
    }
}

/// XR_META_environment_depth's images: D16_UNORM, two layers, SAMPLED and
/// TRANSFER_DST only (the app must sample them: no TRANSFER_SRC, which a runtime
/// need not grant), kept in SHADER_READ_ONLY_OPTIMAL between writes.
pub(crate) const ENV_DEPTH_LAYOUT: vk::ImageLayout = vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL;

impl VkState {
    /// Find a memory type with `props` among `bits`.
    fn memory_type(&self, bits: u32, props: vk::MemoryPropertyFlags) -> Option<u32> {
        (0..self.memory.memory_type_count)
            .find(|&i| bits & (1 << i) != 0 && self.memory.memory_types[i as usize].property_flags.contains(props))
    }

    /// `count` environment-depth images of `width`×`height` (see ENV_DEPTH_LAYOUT).
    pub fn create_depth_images(
        &self,
        count: u32,
        width: u32,
        height: u32,
    ) -> Result<Vec<(vk::Image, vk::DeviceMemory)>, String> {
        let mut images: Vec<(vk::Image, vk::DeviceMemory)> = vec![];
        let result = (|| {
            for _ in 0..count {
                let ci = vk::ImageCreateInfo::default()
                    .image_type(vk::ImageType::TYPE_2D)
                    .format(vk::Format::D16_UNORM)
                    .extent(vk::Extent3D { width, height, depth: 1 })
                    .mip_levels(1)
                    .array_layers(2)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .tiling(vk::ImageTiling::OPTIMAL)
                    .usage(vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST)
                    .sharing_mode(vk::SharingMode::EXCLUSIVE)
                    .initial_layout(vk::ImageLayout::UNDEFINED);
                // SAFETY: valid device and create info.
                let image = unsafe { self.device.create_image(&ci, None) }.map_err(vk_err("vkCreateImage"))?;
                // SAFETY: just created.
                let req = unsafe { self.device.get_image_memory_requirements(image) };
                let Some(ty) = self.memory_type(req.memory_type_bits, vk::MemoryPropertyFlags::DEVICE_LOCAL) else {
                    // SAFETY: unbound image of ours.
                    unsafe { self.device.destroy_image(image, None) };
                    return Err("no device-local memory for a depth image".to_string());
                };
                let alloc = vk::MemoryAllocateInfo::default().allocation_size(req.size).memory_type_index(ty);
                // SAFETY: valid allocation for this device.
                let mem = match unsafe { self.device.allocate_memory(&alloc, None) } {
                    Ok(m) => m,
                    Err(e) => {
                        // SAFETY: unbound image of ours.
                        unsafe { self.device.destroy_image(image, None) };
                        return Err(vk_err("vkAllocateMemory")(e));
                    }
                };
                images.push((image, mem));
                // SAFETY: compatible memory, offset 0, both unbound.
                unsafe { self.device.bind_image_memory(image, mem, 0) }.map_err(vk_err("vkBindImageMemory"))?;
            }
            self.submit(|cmd| {
                for (image, _) in &images {
                    self.barrier(cmd, *image, true, vk::ImageLayout::UNDEFINED, ENV_DEPTH_LAYOUT);
                }
            })
        })();
        if let Err(e) = result {
            self.destroy_images(images);
            return Err(e);
        }
        Ok(images)
    }

    pub fn destroy_images(&self, images: Vec<(vk::Image, vk::DeviceMemory)>) {
        // SAFETY: the queue is idle before the images go (the app's reads of them
        // have finished); they are ours.
        unsafe {
            let _ = self.device.queue_wait_idle(self.queue);
            for (image, memory) in images {
                self.device.destroy_image(image, None);
                self.device.free_memory(memory, None);
            }
        }
    }

    /// Write both layers of a depth image (`texels`: layer-major, rows as stored),
    /// waiting for the app's earlier work on the queue first.
    pub fn write_depth(&self, image: vk::Image, width: u32, height: u32, texels: &[u16]) -> Result<(), String> {
        let size = texels.len() as u64 * 2;
        if texels.len() != 2 * (width * height) as usize {
            return Err(format!("{} texels for two {width}×{height} layers", texels.len()));
        }
        let bi = vk::BufferCreateInfo::default().size(size).usage(vk::BufferUsageFlags::TRANSFER_SRC);
        // SAFETY: valid device and create info.
        let buffer = unsafe { self.device.create_buffer(&bi, None) }.map_err(vk_err("vkCreateBuffer"))?;
        // SAFETY: just created.
        let req = unsafe { self.device.get_buffer_memory_requirements(buffer) };
        let want = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let result = (|| {
            let ty = self.memory_type(req.memory_type_bits, want).ok_or("no host-visible memory")?;
            let alloc = vk::MemoryAllocateInfo::default().allocation_size(req.size).memory_type_index(ty);
            // SAFETY: valid allocation info.
            let mem = unsafe { self.device.allocate_memory(&alloc, None) }.map_err(vk_err("vkAllocateMemory"))?;
            let r = (|| {
                // SAFETY: unbound buffer, compatible memory; mapped, written in
                // bounds and unmapped before the GPU reads it.
                unsafe {
                    self.device.bind_buffer_memory(buffer, mem, 0).map_err(vk_err("vkBindBufferMemory"))?;
                    let p = self
                        .device
                        .map_memory(mem, 0, size, vk::MemoryMapFlags::empty())
                        .map_err(vk_err("vkMapMemory"))?;
                    std::ptr::copy_nonoverlapping(texels.as_ptr() as *const u8, p as *mut u8, size as usize);
                    self.device.unmap_memory(mem);
                }
                self.submit(|cmd| {
                    self.barrier(cmd, image, true, ENV_DEPTH_LAYOUT, vk::ImageLayout::TRANSFER_DST_OPTIMAL);
                    let regions: Vec<vk::BufferImageCopy> = (0..2)
                        .map(|layer| {
                            vk::BufferImageCopy::default()
                                .buffer_offset(layer as u64 * (width * height) as u64 * 2)
                                .image_subresource(vk::ImageSubresourceLayers {
                                    aspect_mask: vk::ImageAspectFlags::DEPTH,
                                    mip_level: 0,
                                    base_array_layer: layer,
                                    layer_count: 1,
                                })
                                .image_extent(vk::Extent3D { width, height, depth: 1 })
                        })
                        .collect();
                    // SAFETY: recording; image in TRANSFER_DST_OPTIMAL, buffer large enough.
                    unsafe {
                        self.device.cmd_copy_buffer_to_image(
                            cmd,
                            buffer,
                            image,
                            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                            &regions,
                        )
                    };
                    self.barrier(cmd, image, true, vk::ImageLayout::TRANSFER_DST_OPTIMAL, ENV_DEPTH_LAYOUT);
                })
            })();
            // SAFETY: not in use (queue idle after submit, or never submitted).
            unsafe { self.device.free_memory(mem, None) };
            r
        })();
        // SAFETY: not in use (as above).
        unsafe { self.device.destroy_buffer(buffer, None) };
        result
    }
}

// ---- entry points ------------------------------------------------------------

pub(crate) unsafe extern "system" fn get_graphics_requirements(
    instance: xr::Instance,
    system: xr::SystemId,
    req: *mut xr::GraphicsRequirementsVulkanKHR,
) -> xr::Result {
    with_instance(instance, |_| {
        if system.into_raw() != SYSTEM_ID {
            return xr::Result::ERROR_SYSTEM_INVALID;
        }
        // SAFETY: caller's output. Multiview needs Vulkan 1.1.
        unsafe {
            (*req).min_api_version_supported = xr::Version::new(1, 1, 0);
            (*req).max_api_version_supported = xr::Version::new(1, 3, 0);
        }
        xr::Result::SUCCESS
    })
}

type GetProc = unsafe extern "system" fn(vk::Instance, *const std::ffi::c_char) -> vk::PFN_vkVoidFunction;

pub(crate) unsafe extern "system" fn create_vulkan_instance(
    instance: xr::Instance,
    info: *const xr::VulkanInstanceCreateInfoKHR,
    out: *mut xr::platform::VkInstance,
    vk_result: *mut xr::platform::VkResult,
) -> xr::Result {
    with_instance(instance, |_| {
        if info.is_null() || out.is_null() || vk_result.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null create info of the caller.
        let info = unsafe { &*info };
        if info.system_id.into_raw() != SYSTEM_ID {
            return xr::Result::ERROR_SYSTEM_INVALID;
        }
        let Some(gpa) = info.pfn_get_instance_proc_addr else { return xr::Result::ERROR_VALIDATION_FAILURE };
        // SAFETY: the app's vkGetInstanceProcAddr has this signature.
        let gpa: GetProc = unsafe { std::mem::transmute(gpa) };
        // SAFETY: global command lookup (VK spec: vkGetInstanceProcAddr with NULL).
        let Some(create) = (unsafe { gpa(vk::Instance::null(), c"vkCreateInstance".as_ptr()) }) else {
            return xr::Result::ERROR_RUNTIME_FAILURE;
        };
        // SAFETY: the looked-up function is vkCreateInstance.
        let create: vk::PFN_vkCreateInstance = unsafe { std::mem::transmute(create) };
        let mut handle = vk::Instance::null();
        // SAFETY: the app's create info and allocator, passed through unchanged (the
        // runtime needs no extra instance extensions).
        let r = unsafe {
            create(
                info.vulkan_create_info as *const vk::InstanceCreateInfo,
                info.vulkan_allocator as *const _,
                &mut handle,
            )
        };
        // SAFETY: caller's outputs.
        unsafe {
            *vk_result = r.as_raw();
            *out = handle.as_raw() as xr::platform::VkInstance;
        }
        if r == vk::Result::SUCCESS {
            *VK_INSTANCE.lock().unwrap_or_else(|e| e.into_inner()) = handle.as_raw();
        }
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn get_graphics_device(
    instance: xr::Instance,
    info: *const xr::VulkanGraphicsDeviceGetInfoKHR,
    out: *mut xr::platform::VkPhysicalDevice,
) -> xr::Result {
    with_instance(instance, |_| {
        if info.is_null() || out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null get info.
        let info = unsafe { &*info };
        // SAFETY: the system loader, as in VkState::new.
        let Ok(entry) = (unsafe { ash::Entry::load() }) else { return xr::Result::ERROR_RUNTIME_FAILURE };
        let vk_instance = vk::Instance::from_raw(info.vulkan_instance as u64);
        // SAFETY: the app's live instance.
        let inst = unsafe { ash::Instance::load(entry.static_fn(), vk_instance) };
        // SAFETY: valid instance.
        let Ok(devices) = (unsafe { inst.enumerate_physical_devices() }) else {
            return xr::Result::ERROR_RUNTIME_FAILURE;
        };
        // The "HMD's" GPU: the first with a graphics + compute queue.
        let chosen = devices.into_iter().find(|&pd| {
            // SAFETY: `pd` belongs to `inst`.
            unsafe { inst.get_physical_device_queue_family_properties(pd) }
                .iter()
                .any(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE))
        });
        let Some(pd) = chosen else { return xr::Result::ERROR_RUNTIME_FAILURE };
        *VK_INSTANCE.lock().unwrap_or_else(|e| e.into_inner()) = vk_instance.as_raw();
        // SAFETY: caller's output.
        unsafe { *out = pd.as_raw() as xr::platform::VkPhysicalDevice };
        xr::Result::SUCCESS
    })
}

pub(crate) unsafe extern "system" fn create_vulkan_device(
    instance: xr::Instance,
    info: *const xr::VulkanDeviceCreateInfoKHR,
    out: *mut xr::platform::VkDevice,
    vk_result: *mut xr::platform::VkResult,
) -> xr::Result {
    with_instance(instance, |_| {
        if info.is_null() || out.is_null() || vk_result.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null create info.
        let info = unsafe { &*info };
        let Some(gpa) = info.pfn_get_instance_proc_addr else { return xr::Result::ERROR_VALIDATION_FAILURE };
        // SAFETY: the app's vkGetInstanceProcAddr has this signature.
        let gpa: GetProc = unsafe { std::mem::transmute(gpa) };
        let vk_instance = vk::Instance::from_raw(*VK_INSTANCE.lock().unwrap_or_else(|e| e.into_inner()));
        if vk_instance == vk::Instance::null() {
            // xrGetVulkanGraphicsDevice2KHR must come first (spec, XR_KHR_vulkan_enable2).
            return xr::Result::ERROR_CALL_ORDER_INVALID;
        }
        // SAFETY: instance-level lookup on the app's instance.
        let Some(create) = (unsafe { gpa(vk_instance, c"vkCreateDevice".as_ptr()) }) else {
            return xr::Result::ERROR_RUNTIME_FAILURE;
        };
        // SAFETY: the looked-up function is vkCreateDevice.
        let create: vk::PFN_vkCreateDevice = unsafe { std::mem::transmute(create) };
        let mut handle = vk::Device::null();
        // SAFETY: the app's physical device, create info and allocator, unchanged.
        let r = unsafe {
            create(
                vk::PhysicalDevice::from_raw(info.vulkan_physical_device as u64),
                info.vulkan_create_info as *const vk::DeviceCreateInfo,
                info.vulkan_allocator as *const _,
                &mut handle,
            )
        };
        // SAFETY: caller's outputs.
        unsafe {
            *vk_result = r.as_raw();
            *out = handle.as_raw() as xr::platform::VkDevice;
        }
        xr::Result::SUCCESS
    })
}
