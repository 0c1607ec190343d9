//! Asynchronous upload of CPU-drawn RGBA8 images into images the app does not own
//! (an OpenXR swapchain's: the status panel). The copy is recorded and submitted
//! with a fence and never waited for: the next upload is refused (`busy`) until the
//! fence says the previous one finished, so the staging buffer is never rewritten
//! under a pending copy and the frame loop never stalls on it.
//!
//! Layouts (XR_KHR_vulkan_enable2, "Swapchain Image Layout"): a colour swapchain
//! image is in COLOR_ATTACHMENT_OPTIMAL when acquired and must be back in it when
//! released; the copy moves it to TRANSFER_DST_OPTIMAL and back, discarding the old
//! contents (every upload rewrites the whole image). Teardown (`Drop`): wait for an
//! in-flight copy, then the fence and the command buffer; the staging buffer (a
//! field) after.
#![allow(unsafe_code)]

use super::{vkr, Buffer, GpuContext, GpuError};
use ash::vk;

pub struct ImageUpload<'a> {
    ctx: &'a GpuContext,
    width: u32,
    height: u32,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    in_flight: bool,
    /// Host-visible, coherent: width × height × 4 bytes.
    staging: Buffer<'a>,
}

impl<'a> ImageUpload<'a> {
    /// Uploads of `width`×`height` RGBA8 images (any 4-byte format the caller's
    /// images have: the bytes are copied as they are).
    pub fn new(ctx: &'a GpuContext, width: u32, height: u32) -> Result<Self, GpuError> {
        if width == 0 || height == 0 || width > 8192 || height > 8192 {
            return Err(GpuError::Input { input: "upload size", problem: format!("{width}×{height}") });
        }
        let staging = Buffer::new(
            ctx,
            width as u64 * height as u64 * 4,
            vk::BufferUsageFlags::TRANSFER_SRC,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
            "image upload staging",
        )?;
        let mut me = Self {
            ctx,
            width,
            height,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            in_flight: false,
            staging,
        };
        me.cmd = ctx.allocate_command_buffer()?;
        // SAFETY: valid device; destroyed in `Drop`.
        me.fence =
            unsafe { ctx.device.create_fence(&vk::FenceCreateInfo::default(), None) }.map_err(vkr("vkCreateFence"))?;
        Ok(me)
    }

    /// Whether the last upload is still executing (polls its fence; never waits).
    pub fn busy(&mut self) -> Result<bool, GpuError> {
        if !self.in_flight {
            return Ok(false);
        }
        let d = &self.ctx.device;
        // SAFETY: a fence of this device.
        if !unsafe { d.get_fence_status(self.fence) }.map_err(vkr("vkGetFenceStatus"))? {
            return Ok(true);
        }
        // SAFETY: signalled, so no pending submission uses it.
        unsafe { d.reset_fences(&[self.fence]) }.map_err(vkr("vkResetFences"))?;
        self.in_flight = false;
        Ok(false)
    }

    /// Queue the copy of `rgba` (rows top-down, tightly packed) into array layer
    /// `layer` of `image`, which is in COLOR_ATTACHMENT_OPTIMAL and is left in it.
    /// Refused while the previous upload is executing (`busy`).
    pub fn start(&mut self, rgba: &[u8], image: vk::Image, layer: u32) -> Result<(), GpuError> {
        if self.busy()? {
            return Err(GpuError::Input {
                input: "image upload",
                problem: "the previous upload is still executing".into(),
            });
        }
        if rgba.len() as u64 != self.staging.size {
            return Err(GpuError::Input {
                input: "image upload data",
                problem: format!("{} bytes for {}×{} RGBA8", rgba.len(), self.width, self.height),
            });
        }
        self.staging.write(rgba)?;
        let d = &self.ctx.device;
        let range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: layer,
            layer_count: 1,
        };
        // Old contents discarded (UNDEFINED): every upload rewrites the whole image.
        // The host's staging write is made visible by the submission itself
        // (Vulkan 7.9: queue submission is a host-write domain operation).
        let to_dst = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::empty())
            .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(range);
        // Back to the swapchain's layout, the copy's writes made available to the
        // compositor's reads (it samples the image after xrReleaseSwapchainImage).
        let to_steady = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::SHADER_READ | vk::AccessFlags::COLOR_ATTACHMENT_READ)
            .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(range);
        let region = vk::BufferImageCopy::default()
            .image_subresource(vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: layer,
                layer_count: 1,
            })
            .image_extent(vk::Extent3D { width: self.width, height: self.height, depth: 1 });
        let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the command buffer is not pending (never submitted, or its fence was
        // seen signalled and reset by `busy`); recorded, ended and submitted on this
        // thread; `image` is a live image of this device in the stated layout, at
        // least width×height with `layer` among its layers (the caller's contract).
        unsafe {
            d.begin_command_buffer(self.cmd, &begin).map_err(vkr("vkBeginCommandBuffer"))?;
            // After everything before it on the queue: a runtime may read its
            // swapchain images with work on the app's queue (XR_KHR_vulkan_enable
            // lets it use the queue in xrEndFrame and xrReleaseSwapchainImage).
            d.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_dst],
            );
            d.cmd_copy_buffer_to_image(
                self.cmd,
                self.staging.buffer,
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[region],
            );
            d.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_steady],
            );
            d.end_command_buffer(self.cmd).map_err(vkr("vkEndCommandBuffer"))?;
            let submit = vk::SubmitInfo::default().command_buffers(std::slice::from_ref(&self.cmd));
            d.queue_submit(self.ctx.queue, &[submit], self.fence).map_err(vkr("vkQueueSubmit"))?;
        }
        self.in_flight = true;
        Ok(())
    }

    /// Block until an in-flight upload is done (teardown, tests).
    pub fn wait(&mut self) -> Result<(), GpuError> {
        if self.in_flight {
            // SAFETY: a fence of this device with a pending submission.
            unsafe { self.ctx.device.wait_for_fences(&[self.fence], true, u64::MAX) }
                .map_err(vkr("vkWaitForFences"))?;
            // SAFETY: signalled; nothing pending uses it.
            unsafe { self.ctx.device.reset_fences(&[self.fence]) }.map_err(vkr("vkResetFences"))?;
            self.in_flight = false;
        }
        Ok(())
    }
}

impl Drop for ImageUpload<'_> {
    fn drop(&mut self) {
        if self.wait().is_err() {
            // A lost device: nothing is executing any more either way.
            // SAFETY: valid device.
            let _ = unsafe { self.ctx.device.device_wait_idle() };
        }
        let d = &self.ctx.device;
        // SAFETY: nothing pending uses the command buffer or fence (waited above);
        // null handles (a failed `new`) are ignored by vkDestroy*/vkFree*.
        unsafe {
            d.destroy_fence(self.fence, None);
            if self.cmd != vk::CommandBuffer::null() {
                d.free_command_buffers(self.ctx.command_pool, &[self.cmd]);
            }
        }
    }
}
