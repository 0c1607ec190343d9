//! Asynchronous upload of CPU-drawn RGBA8 images into images the app does not own
//! (an OpenXR swapchain's: the status panel). The copy is recorded and submitted
//! with a fence and never waited for: the next upload is refused (`busy`) until the
//! fence says the previous one finished, so the staging buffer is never rewritten
//! under a pending copy and the frame loop never stalls on it.
//!
//! Layouts (XR_KHR_vulkan_enable2, "Swapchain Image Layout"): a colour swapchain
//! image is in COLOR_ATTACHMENT_OPTIMAL when acquired and must be back in it when
//! released; the copy moves it to TRANSFER_DST_OPTIMAL and back, discarding the old
//! contents (every upload rewrites the whole image). Teardown: the command buffer
//! (`FencedCommand` waits for a copy in flight), then the staging buffer (fields
//! in that order).
#![allow(unsafe_code)]

use super::fenced::FencedCommand;
use super::image::image_barrier;
use super::{Buffer, GpuContext, GpuError};
use ash::vk;

pub struct ImageUpload<'a> {
    ctx: &'a GpuContext,
    width: u32,
    height: u32,
    commands: FencedCommand<'a>,
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
        Ok(Self { ctx, width, height, commands: FencedCommand::new(ctx)?, staging })
    }

    /// Whether the last upload is still executing (polls its fence; never waits).
    pub fn busy(&mut self) -> Result<bool, GpuError> {
        self.commands.busy()
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
        let to_dst = image_barrier(
            image,
            range,
            vk::ImageLayout::UNDEFINED,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            vk::AccessFlags::empty(),
            vk::AccessFlags::TRANSFER_WRITE,
        );
        // Back to the swapchain's layout, the copy's writes made available to the
        // compositor's reads (it samples the image after xrReleaseSwapchainImage).
        let to_steady = image_barrier(
            image,
            range,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            vk::AccessFlags::TRANSFER_WRITE,
            vk::AccessFlags::SHADER_READ | vk::AccessFlags::COLOR_ATTACHMENT_READ,
        );
        let region = vk::BufferImageCopy::default()
            .image_subresource(vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: layer,
                layer_count: 1,
            })
            .image_extent(vk::Extent3D { width: self.width, height: self.height, depth: 1 });
        let (d, staging) = (&self.ctx.device, self.staging.buffer);
        self.commands.submit(|cmd| {
            // SAFETY: `cmd` is recording; `image` is a live image of this device in the
            // stated layout, at least width×height with `layer` among its layers (the
            // caller's contract); the staging buffer holds the whole image.
            unsafe {
                // After everything before it on the queue: a runtime may read its
                // swapchain images with work on the app's queue (XR_KHR_vulkan_enable
                // lets it use the queue in xrEndFrame and xrReleaseSwapchainImage).
                d.cmd_pipeline_barrier(
                    cmd,
                    vk::PipelineStageFlags::ALL_COMMANDS,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[to_dst],
                );
                d.cmd_copy_buffer_to_image(cmd, staging, image, vk::ImageLayout::TRANSFER_DST_OPTIMAL, &[region]);
                d.cmd_pipeline_barrier(
                    cmd,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::ALL_COMMANDS,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[to_steady],
                );
            }
        })
    }

    /// Block until an in-flight upload is done (teardown, tests).
    pub fn wait(&mut self) -> Result<(), GpuError> {
        self.commands.wait()
    }
}
