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
//! them in. Teardown (`Drop`): wait for an in-flight read-back, then the views; the
//! command buffer and its fence, the pipeline and the output buffer (fields) after.
#![allow(unsafe_code)]

use super::fenced::FencedCommand;
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
    commands: FencedCommand<'a>,
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
        let mut me =
            Self { ctx, views: vec![], layout, width, height, commands: FencedCommand::new(ctx)?, pipeline, output };
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
        Ok(me)
    }

    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Whether a read-back is queued and not yet collected.
    pub fn busy(&self) -> bool {
        self.commands.in_flight()
    }

    /// Queue the read of image `index`; false (nothing queued) while the previous
    /// read-back has not been collected.
    pub fn start(&mut self, index: usize) -> Result<bool, GpuError> {
        if self.commands.in_flight() {
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
        let (pipeline, groups) = (&self.pipeline, [self.width.div_ceil(8), self.height.div_ceil(8), 2]);
        self.commands.submit(|cmd| {
            pipeline.record(cmd, bytemuck::bytes_of(&push), groups);
            // The shader's writes made visible to the host's reads after the fence
            // (Vulkan spec 7.9, host access: a HOST_READ barrier is still required).
            let to_host = vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                .dst_access_mask(vk::AccessFlags::HOST_READ);
            // SAFETY: recording; a plain memory barrier.
            unsafe {
                d.cmd_pipeline_barrier(
                    cmd,
                    vk::PipelineStageFlags::COMPUTE_SHADER,
                    vk::PipelineStageFlags::HOST,
                    vk::DependencyFlags::empty(),
                    &[to_host],
                    &[],
                    &[],
                )
            };
        })?;
        Ok(true)
    }

    /// The values of the read-back started last, once the GPU is done with it (never
    /// waits): 2 × width × height NDC depths, layer 0 (left eye) first, rows as stored.
    pub fn poll(&mut self) -> Result<Option<Vec<f32>>, GpuError> {
        if !self.commands.in_flight() || self.commands.busy()? {
            return Ok(None);
        }
        let bytes = self.output.read()?;
        Ok(Some(bytemuck::pod_collect_to_vec(&bytes)))
    }

    /// Block until an in-flight read-back is done (teardown, tests); `poll` then
    /// collects it.
    pub fn wait(&mut self) -> Result<(), GpuError> {
        self.commands.wait()
    }
}

impl Drop for DepthReadback<'_> {
    fn drop(&mut self) {
        if self.wait().is_err() {
            // A lost device: nothing is executing any more either way.
            // SAFETY: valid device.
            let _ = unsafe { self.ctx.device.device_wait_idle() };
        }
        // SAFETY: nothing pending uses the views (waited above).
        unsafe {
            for &v in &self.views {
                self.ctx.device.destroy_image_view(v, None);
            }
        }
    }
}
