//! Layered 2-D images (the stereo target and G-buffer: one array layer per eye),
//! sampled textures, and their staging upload/readback.
//!
//! Layouts: storage and attachment images live in `GENERAL` once created (one
//! transition at creation), so render-pass outputs are read by compute without
//! per-frame layout bookkeeping (Vulkan spec §12.4: GENERAL is valid for every
//! access; on tile-based GPUs the cost is in the render pass's store, which the
//! pass already pays). Textures are `SHADER_READ_ONLY_OPTIMAL` after their upload.
#![allow(unsafe_code)]

use super::{vkr, Buffer, GpuContext, GpuError};
use ash::vk;

/// An image with one view over all its array layers; freed on drop.
pub struct Image<'a> {
    ctx: &'a GpuContext,
    pub(crate) image: vk::Image,
    memory: vk::DeviceMemory,
    pub(crate) view: vk::ImageView,
    pub format: vk::Format,
    pub width: u32,
    pub height: u32,
    pub layers: u32,
    pub(crate) aspect: vk::ImageAspectFlags,
    /// Layout the image is kept in between passes.
    pub(crate) layout: vk::ImageLayout,
}

/// Bytes per texel of the formats this project uses.
pub fn texel_bytes(format: vk::Format) -> Result<u32, GpuError> {
    Ok(match format {
        vk::Format::R8G8B8A8_UNORM | vk::Format::R8G8B8A8_SRGB | vk::Format::R32_SFLOAT | vk::Format::D32_SFLOAT => 4,
        vk::Format::R16G16B16A16_SFLOAT => 8,
        vk::Format::R32G32B32A32_SFLOAT => 16,
        _ => return Err(GpuError::Input { input: "format", problem: format!("{format:?} is not supported") }),
    })
}

impl<'a> Image<'a> {
    /// A device-local `width × height × layers` image of `format`, usable as
    /// `usage` (plus transfer source/destination), transitioned to `layout`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        ctx: &'a GpuContext,
        width: u32,
        height: u32,
        layers: u32,
        format: vk::Format,
        usage: vk::ImageUsageFlags,
        layout: vk::ImageLayout,
        name: &str,
    ) -> Result<Self, GpuError> {
        if width == 0 || height == 0 || layers == 0 {
            return Err(GpuError::Input {
                input: "image size",
                problem: format!("{name}: {width}×{height}×{layers} has no texels"),
            });
        }
        texel_bytes(format)?;
        let aspect =
            if format == vk::Format::D32_SFLOAT { vk::ImageAspectFlags::DEPTH } else { vk::ImageAspectFlags::COLOR };
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D { width, height, depth: 1 })
            .mip_levels(1)
            .array_layers(layers)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage | vk::ImageUsageFlags::TRANSFER_SRC | vk::ImageUsageFlags::TRANSFER_DST)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        let d = &ctx.device;
        // SAFETY: valid device and create info.
        let image = unsafe { d.create_image(&info, None) }.map_err(vkr("vkCreateImage"))?;
        let mut me = Self {
            ctx,
            image,
            memory: vk::DeviceMemory::null(),
            view: vk::ImageView::null(),
            format,
            width,
            height,
            layers,
            aspect,
            layout,
        };
        // SAFETY: `image` was just created on this device.
        let reqs = unsafe { d.get_image_memory_requirements(image) };
        let type_index = ctx
            .memory_type(reqs.memory_type_bits, vk::MemoryPropertyFlags::DEVICE_LOCAL)
            .ok_or(GpuError::NoMemoryType("image"))?;
        let alloc = vk::MemoryAllocateInfo::default().allocation_size(reqs.size).memory_type_index(type_index);
        // SAFETY: valid allocation info; on any error below `Drop` frees what exists
        // (null handles are ignored by vkDestroy*/vkFreeMemory).
        me.memory = unsafe { d.allocate_memory(&alloc, None) }.map_err(vkr("vkAllocateMemory (image)"))?;
        // SAFETY: compatible memory type and size, offset 0, both unbound.
        unsafe { d.bind_image_memory(image, me.memory, 0) }.map_err(vkr("vkBindImageMemory"))?;
        let view_info = vk::ImageViewCreateInfo::default()
            .image(image)
            // Single-layer images (textures) are plain 2-D views, as shaders declare
            // them (VUID-vkCmdDraw-viewType-07752).
            .view_type(if layers == 1 { vk::ImageViewType::TYPE_2D } else { vk::ImageViewType::TYPE_2D_ARRAY })
            .format(format)
            .subresource_range(me.range());
        // SAFETY: the image is bound to memory; the range covers existing layers.
        me.view = unsafe { d.create_image_view(&view_info, None) }.map_err(vkr("vkCreateImageView"))?;
        ctx.set_name(image, name);
        ctx.set_name(me.view, name);
        if layout != vk::ImageLayout::UNDEFINED {
            ctx.submit_and_wait(|cmd| me.record_transition(cmd, vk::ImageLayout::UNDEFINED, layout))?;
        }
        Ok(me)
    }

    pub(crate) fn range(&self) -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange::default().aspect_mask(self.aspect).level_count(1).layer_count(self.layers)
    }

    fn layers(&self) -> vk::ImageSubresourceLayers {
        vk::ImageSubresourceLayers::default().aspect_mask(self.aspect).layer_count(self.layers)
    }

    /// Byte size of all layers, tightly packed (layer-major, then rows).
    pub fn byte_size(&self) -> u64 {
        let texel = texel_bytes(self.format).unwrap_or(4) as u64;
        self.width as u64 * self.height as u64 * self.layers as u64 * texel
    }

    /// Record a full-image layout transition with a conservative (all-commands)
    /// dependency: used for one-off transitions only, never per frame.
    pub(crate) fn record_transition(&self, cmd: vk::CommandBuffer, from: vk::ImageLayout, to: vk::ImageLayout) {
        let barrier = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
            .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE)
            .old_layout(from)
            .new_layout(to)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(self.image)
            .subresource_range(self.range());
        // SAFETY: `cmd` is recording; the image is live and owned by this device.
        unsafe {
            self.ctx.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier],
            )
        };
    }

    /// Record a copy of every layer into `dst`, an image this context does not own
    /// (an OpenXR swapchain image of the same size, layer count and a format of the
    /// same texel layout), kept in `dst_layout` before and after (XR_KHR_vulkan_enable:
    /// swapchain colour images are COLOR_ATTACHMENT_OPTIMAL between acquire and
    /// release). Bits are copied unchanged: sRGB-encoded values written to an
    /// RGBA8 UNORM image read as the same colours from an RGBA8 SRGB image.
    pub fn record_copy_to_external(&self, cmd: vk::CommandBuffer, dst: vk::Image, dst_layout: vk::ImageLayout) {
        let range = self.range();
        let barrier = |image, from, to, src, dst_access| image_barrier(image, range, from, to, src, dst_access);
        let before = [
            // The effect chain's writes to the output, before the copy reads them
            // (in TRANSFER_SRC_OPTIMAL for the copy, then back to its own layout).
            barrier(
                self.image,
                self.layout,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                vk::AccessFlags::SHADER_WRITE,
                vk::AccessFlags::TRANSFER_READ,
            ),
            barrier(
                dst,
                dst_layout,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                vk::AccessFlags::empty(),
                vk::AccessFlags::TRANSFER_WRITE,
            ),
        ];
        let after = [
            barrier(
                dst,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                dst_layout,
                vk::AccessFlags::TRANSFER_WRITE,
                vk::AccessFlags::MEMORY_READ,
            ),
            // The next frame's chain may overwrite the output only after the copy.
            barrier(
                self.image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                self.layout,
                vk::AccessFlags::TRANSFER_READ,
                vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::SHADER_READ,
            ),
        ];
        let region = vk::ImageCopy::default()
            .src_subresource(self.layers())
            .dst_subresource(self.layers())
            .extent(vk::Extent3D { width: self.width, height: self.height, depth: 1 });
        // SAFETY: `cmd` is recording outside a render pass; `dst` is a live image of
        // this device at least as large, with as many layers (the caller's contract);
        // the barriers order the chain's writes, the copy and the compositor's read.
        unsafe {
            let d = &self.ctx.device;
            let stages = vk::PipelineStageFlags::ALL_COMMANDS;
            d.cmd_pipeline_barrier(
                cmd,
                stages,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &before,
            );
            d.cmd_copy_image(
                cmd,
                self.image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                dst,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[region],
            );
            d.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::TRANSFER,
                stages,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &after,
            );
        }
    }

    /// Replace the contents with `data` (tightly packed, layer-major).
    pub fn upload(&self, data: &[u8]) -> Result<(), GpuError> {
        if data.len() as u64 != self.byte_size() {
            return Err(GpuError::Input {
                input: "image data",
                problem: format!("{} bytes for an image of {} bytes", data.len(), self.byte_size()),
            });
        }
        let staging = Buffer::new(
            self.ctx,
            self.byte_size(),
            vk::BufferUsageFlags::TRANSFER_SRC,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
            "image staging",
        )?;
        staging.write(data)?;
        // Uploads replace everything: from UNDEFINED (contents discarded) to
        // TRANSFER_DST_OPTIMAL for the copy, then back to the kept layout.
        let target = vk::ImageLayout::TRANSFER_DST_OPTIMAL;
        self.ctx.submit_and_wait(|cmd| {
            self.record_transition(cmd, vk::ImageLayout::UNDEFINED, target);
            let region = vk::BufferImageCopy::default().image_subresource(self.layers()).image_extent(vk::Extent3D {
                width: self.width,
                height: self.height,
                depth: 1,
            });
            // SAFETY: the staging buffer holds exactly the image's bytes; the image is
            // in TRANSFER_DST_OPTIMAL.
            unsafe {
                self.ctx.device.cmd_copy_buffer_to_image(cmd, staging.buffer, self.image, target, &[region]);
            }
            self.record_transition(cmd, target, self.layout);
        })
    }

    /// Read all layers back (tightly packed, layer-major).
    pub fn download(&self) -> Result<Vec<u8>, GpuError> {
        let readback = Buffer::new(
            self.ctx,
            self.byte_size(),
            vk::BufferUsageFlags::TRANSFER_DST,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
            "image readback",
        )?;
        self.ctx.submit_and_wait(|cmd| {
            let region = vk::BufferImageCopy::default().image_subresource(self.layers()).image_extent(vk::Extent3D {
                width: self.width,
                height: self.height,
                depth: 1,
            });
            // Readback is a test/export path: move to TRANSFER_SRC_OPTIMAL for the
            // copy and back, contents preserved (spec §12.4: only UNDEFINED discards).
            let src = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
            self.record_transition(cmd, self.layout, src);
            // SAFETY: earlier submissions were waited on; the image is in a layout
            // valid for transfer reads.
            unsafe {
                self.ctx.device.cmd_copy_image_to_buffer(cmd, self.image, src, readback.buffer, &[region]);
            }
            self.record_transition(cmd, src, self.layout);
        })?;
        readback.read()
    }
}

impl Drop for Image<'_> {
    fn drop(&mut self) {
        // SAFETY: every submission using the image was waited on; view before image
        // before memory (children before parents).
        unsafe {
            self.ctx.device.destroy_image_view(self.view, None);
            self.ctx.device.destroy_image(self.image, None);
            self.ctx.device.free_memory(self.memory, None);
        }
    }
}

/// A sampled RGBA8 (sRGB) texture with its sampler: glTF base colour maps.
pub struct Texture<'a> {
    ctx: &'a GpuContext,
    pub image: Image<'a>,
    pub(crate) sampler: vk::Sampler,
}

impl<'a> Texture<'a> {
    /// `rgba`: `width × height` sRGB-encoded RGBA8 texels. Bilinear, repeat (glTF's
    /// default wrap); no mipmaps (the bundled objects are small on screen).
    pub fn new(ctx: &'a GpuContext, width: u32, height: u32, rgba: &[u8], name: &str) -> Result<Self, GpuError> {
        let image = Image::new(
            ctx,
            width,
            height,
            1,
            vk::Format::R8G8B8A8_SRGB,
            vk::ImageUsageFlags::SAMPLED,
            vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
            name,
        )?;
        image.upload(rgba)?;
        let info = vk::SamplerCreateInfo::default()
            .mag_filter(vk::Filter::LINEAR)
            .min_filter(vk::Filter::LINEAR)
            .mipmap_mode(vk::SamplerMipmapMode::NEAREST)
            .address_mode_u(vk::SamplerAddressMode::REPEAT)
            .address_mode_v(vk::SamplerAddressMode::REPEAT)
            .address_mode_w(vk::SamplerAddressMode::REPEAT)
            .max_lod(0.0);
        // SAFETY: valid device and create info.
        let sampler = unsafe { ctx.device.create_sampler(&info, None) }.map_err(vkr("vkCreateSampler"))?;
        ctx.set_name(sampler, name);
        Ok(Self { ctx, image, sampler })
    }
}

impl Drop for Texture<'_> {
    fn drop(&mut self) {
        // SAFETY: no pending submission uses the sampler; the image drops after.
        unsafe { self.ctx.device.destroy_sampler(self.sampler, None) };
    }
}

/// A layout transition / memory dependency on `range` of `image` (same queue family).
pub(crate) fn image_barrier(
    image: vk::Image,
    range: vk::ImageSubresourceRange,
    from: vk::ImageLayout,
    to: vk::ImageLayout,
    src_access: vk::AccessFlags,
    dst_access: vk::AccessFlags,
) -> vk::ImageMemoryBarrier<'static> {
    vk::ImageMemoryBarrier::default()
        .src_access_mask(src_access)
        .dst_access_mask(dst_access)
        .old_layout(from)
        .new_layout(to)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .image(image)
        .subresource_range(range)
}

/// Record a copy of `src` (f32 depth texels, tightly packed, layer-major) into the
/// depth aspect of `dst`, a D32_SFLOAT image this context does not own (the
/// OpenXR depth swapchain image for XR_FB_space_warp), kept in `dst_layout` before
/// and after. Depth images cannot be storage images, so a compute pass writes the
/// buffer and this copy fills the image (buffer→image copies of the depth aspect of
/// D32_SFLOAT are allowed: Vulkan spec, "Copying Data Between Buffers and Images").
pub fn record_copy_to_external_depth(
    ctx: &GpuContext,
    cmd: vk::CommandBuffer,
    src: &Buffer<'_>,
    dst: vk::Image,
    dst_layout: vk::ImageLayout,
    size: [u32; 3],
) {
    let range = vk::ImageSubresourceRange::default()
        .aspect_mask(vk::ImageAspectFlags::DEPTH)
        .level_count(1)
        .layer_count(size[2]);
    let barrier = |from, to, src_access, dst_access| image_barrier(dst, range, from, to, src_access, dst_access);
    let to_dst = barrier(
        dst_layout,
        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        vk::AccessFlags::empty(),
        vk::AccessFlags::TRANSFER_WRITE,
    );
    let back = barrier(
        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        dst_layout,
        vk::AccessFlags::TRANSFER_WRITE,
        vk::AccessFlags::MEMORY_READ,
    );
    let written = vk::BufferMemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE)
        .dst_access_mask(vk::AccessFlags::TRANSFER_READ)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .buffer(src.buffer)
        .size(vk::WHOLE_SIZE);
    let region = vk::BufferImageCopy::default()
        .image_subresource(
            vk::ImageSubresourceLayers::default().aspect_mask(vk::ImageAspectFlags::DEPTH).layer_count(size[2]),
        )
        .image_extent(vk::Extent3D { width: size[0], height: size[1], depth: 1 });
    // SAFETY: `cmd` is recording outside a render pass; `dst` is a live D32_SFLOAT
    // image of this device with at least `size` texels and layers, `src` holds them
    // (the caller's contract); the barriers order the shader's writes, the copy and
    // the compositor's read.
    unsafe {
        let d = &ctx.device;
        let all = vk::PipelineStageFlags::ALL_COMMANDS;
        d.cmd_pipeline_barrier(
            cmd,
            all,
            vk::PipelineStageFlags::TRANSFER,
            vk::DependencyFlags::empty(),
            &[],
            &[written],
            &[to_dst],
        );
        d.cmd_copy_buffer_to_image(cmd, src.buffer, dst, vk::ImageLayout::TRANSFER_DST_OPTIMAL, &[region]);
        d.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            all,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[back],
        );
    }
}
