//! Asynchronous read-back of an OpenXR runtime's depth images (XR_META_environment_
//! depth: VK_FORMAT_D16_UNORM, two array layers) into host memory, for calibration.
//! The frame loop starts a read-back between xrBeginFrame and xrEndFrame (the spec
//! lets the app queue GPU work on an acquired depth image until the next xrEndFrame,
//! and the runtime writes new depth only after that work completes) and collects it
//! on a later frame by polling a fence: the frame loop never waits on the GPU for it.
//!
//! The images are the runtime's: they are read with texel fetches through image views
//! this struct owns (SAMPLED usage, which images made to be sampled carry — not
//! TRANSFER_SRC, which a runtime need not grant), in the layout the runtime keeps
//! them in. Teardown (`Drop`): wait for an in-flight read-back, then the fence, the
//! command buffer and the views; the pipeline and the output buffer (fields) after.
#![allow(unsafe_code)]

use super::{vkr, Buffer, ComputePipeline, GpuContext, GpuError, Resource};
use ash::vk;

const SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/env_depth.main.spv"));

/// Push constants of `env_depth.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Push {
    width: u32,
    height: u32,
}
const _: () = assert!(std::mem::size_of::<Push>() == 8);

/// Reads one of a fixed set of two-layer depth images at a time.
pub struct DepthReadback<'a> {
    ctx: &'a GpuContext,
    views: Vec<vk::ImageView>,
    layout: vk::ImageLayout,
    width: u32,
    height: u32,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    in_flight: bool,
    pipeline: ComputePipeline<'a>,
    /// Host-visible: 2 × width × height f32, layer-major, rows as stored.
    output: Buffer<'a>,
}

impl<'a> DepthReadback<'a> {
    /// Views on `images` (each `format`, `width`×`height`, two layers, kept by their
    /// owner in `layout`, a layout shader reads are allowed in).
    pub fn new(
        ctx: &'a GpuContext,
        images: &[vk::Image],
        format: vk::Format,
        width: u32,
        height: u32,
        layout: vk::ImageLayout,
    ) -> Result<Self, GpuError> {
        if images.is_empty() || width == 0 || height == 0 || width > 4096 || height > 4096 {
            return Err(GpuError::Input {
                input: "depth images",
                problem: format!("{} images of {width}×{height}", images.len()),
            });
        }
        let pipeline = ComputePipeline::with_layout(
            ctx,
            SPIRV,
            &[vk::DescriptorType::SAMPLED_IMAGE, vk::DescriptorType::STORAGE_BUFFER],
            std::mem::size_of::<Push>() as u32,
            1,
            "env_depth",
        )?;
        let output = Buffer::new(
            ctx,
            2 * width as u64 * height as u64 * 4,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
            "env_depth values",
        )?;
        let mut me = Self {
            ctx,
            views: vec![],
            layout,
            width,
            height,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            in_flight: false,
            pipeline,
            output,
        };
        for &image in images {
            let info = vk::ImageViewCreateInfo::default()
                .image(image)
                .view_type(vk::ImageViewType::TYPE_2D_ARRAY)
                .format(format)
                .subresource_range(vk::ImageSubresourceRange {
                    aspect_mask: vk::ImageAspectFlags::DEPTH,
                    base_mip_level: 0,
                    level_count: 1,
                    base_array_layer: 0,
                    layer_count: 2,
                });
            // SAFETY: a live image of this device (the runtime's, valid for the depth
            // swapchain's lifetime, which outlives this struct); on error `Drop`
            // destroys the views made so far.
            let view = unsafe { ctx.device.create_image_view(&info, None) }.map_err(vkr("vkCreateImageView"))?;
            me.views.push(view);
        }
        me.cmd = ctx.allocate_command_buffer()?;
        // SAFETY: valid device; destroyed in `Drop`.
        me.fence =
            unsafe { ctx.device.create_fence(&vk::FenceCreateInfo::default(), None) }.map_err(vkr("vkCreateFence"))?;
        Ok(me)
    }

    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Whether a read-back is queued and not yet collected.
    pub fn busy(&self) -> bool {
        self.in_flight
    }

    /// Queue the read of image `index`; false (nothing queued) while the previous
    /// read-back has not been collected.
    pub fn start(&mut self, index: usize) -> Result<bool, GpuError> {
        if self.in_flight {
            return Ok(false);
        }
        let Some(&view) = self.views.get(index) else {
            return Err(GpuError::Input {
                input: "depth image index",
                problem: format!("{index} of {} images", self.views.len()),
            });
        };
        // The set is free: the last submission that read it was collected (fence).
        self.pipeline.bind_resources(
            0,
            &[Resource::SampledView { view, layout: self.layout }, Resource::Buffer(&self.output)],
        )?;
        let d = &self.ctx.device;
        let push = Push { width: self.width, height: self.height };
        let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the command buffer is not pending (never submitted, or its fence was
        // seen signalled and reset); recorded, ended and submitted on this thread.
        unsafe {
            d.begin_command_buffer(self.cmd, &begin).map_err(vkr("vkBeginCommandBuffer"))?;
        }
        self.pipeline.record(self.cmd, bytemuck::bytes_of(&push), [self.width.div_ceil(8), self.height.div_ceil(8), 2]);
        // The shader's writes made visible to the host's reads after the fence
        // (Vulkan spec 7.9, host access: a HOST_READ barrier is still required).
        let to_host = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        // SAFETY: recording; a plain memory barrier.
        unsafe {
            d.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[to_host],
                &[],
                &[],
            );
            d.end_command_buffer(self.cmd).map_err(vkr("vkEndCommandBuffer"))?;
            let submit = vk::SubmitInfo::default().command_buffers(std::slice::from_ref(&self.cmd));
            d.queue_submit(self.ctx.queue, &[submit], self.fence).map_err(vkr("vkQueueSubmit"))?;
        }
        self.in_flight = true;
        Ok(true)
    }

    /// The values of the read-back started last, once the GPU is done with it (never
    /// waits): 2 × width × height NDC depths, layer 0 (left eye) first, rows as stored.
    pub fn poll(&mut self) -> Result<Option<Vec<f32>>, GpuError> {
        if !self.in_flight {
            return Ok(None);
        }
        let d = &self.ctx.device;
        // SAFETY: a fence of this device.
        if !unsafe { d.get_fence_status(self.fence) }.map_err(vkr("vkGetFenceStatus"))? {
            return Ok(None);
        }
        // SAFETY: signalled, so not in use by a pending submission.
        unsafe { d.reset_fences(&[self.fence]) }.map_err(vkr("vkResetFences"))?;
        self.in_flight = false;
        let bytes = self.output.read()?;
        Ok(Some(bytemuck::pod_collect_to_vec(&bytes)))
    }

    /// Block until an in-flight read-back is done (teardown, tests).
    pub fn wait(&mut self) -> Result<(), GpuError> {
        if self.in_flight {
            // SAFETY: a fence of this device with a pending submission.
            unsafe { self.ctx.device.wait_for_fences(&[self.fence], true, u64::MAX) }
                .map_err(vkr("vkWaitForFences"))?;
        }
        Ok(())
    }
}

impl Drop for DepthReadback<'_> {
    fn drop(&mut self) {
        if self.wait().is_err() {
            // A lost device: nothing is executing any more either way.
            // SAFETY: valid device.
            let _ = unsafe { self.ctx.device.device_wait_idle() };
        }
        let d = &self.ctx.device;
        // SAFETY: nothing pending uses the command buffer, fence or views (waited
        // above); null handles (a failed `new`) are ignored by vkDestroy*/vkFree*.
        unsafe {
            d.destroy_fence(self.fence, None);
            if self.cmd != vk::CommandBuffer::null() {
                d.free_command_buffers(self.ctx.command_pool, &[self.cmd]);
            }
            for &v in &self.views {
                d.destroy_image_view(v, None);
            }
        }
    }
}
