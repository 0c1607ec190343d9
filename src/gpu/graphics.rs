//! Multiview rendering: a two-layer stereo target (one render pass draws both eyes,
//! VK_KHR_multiview, core in Vulkan 1.1) and graphics pipelines drawing into it.
//!
//! On desktop the target's images are offscreen; on the headset the colour
//! attachment is an OpenXR swapchain image array with the same two layers, so the
//! render pass and pipelines are identical.
//!
//! Teardown: pipelines borrow the target's render pass through `&MultiviewTarget`,
//! so they drop first; the target destroys its framebuffer, then the render pass,
//! then its images (children before parents).
#![allow(unsafe_code)]

use super::{vkr, Buffer, GpuContext, GpuError, Image, Texture};
use ash::vk;
use std::ffi::CStr;

/// View mask and correlation mask of the stereo target: views 0 (left) and 1
/// (right), correlated (the implementation may share work between them).
const VIEW_MASK: u32 = 0b11;
/// Layers (eyes) of every stereo target.
pub const EYES: u32 = 2;

pub struct MultiviewTarget<'a> {
    ctx: &'a GpuContext,
    pub colour: Vec<Image<'a>>,
    pub depth: Image<'a>,
    render_pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    pub width: u32,
    pub height: u32,
}

impl<'a> MultiviewTarget<'a> {
    /// Colour attachments of `formats` (kept in GENERAL, also storage images, so
    /// compute passes read them directly) and a D32 depth attachment, `width ×
    /// height × 2` layers.
    pub fn new(
        ctx: &'a GpuContext,
        width: u32,
        height: u32,
        formats: &[vk::Format],
        name: &str,
    ) -> Result<Self, GpuError> {
        let mut colour = Vec::new();
        for (i, &f) in formats.iter().enumerate() {
            colour.push(Image::new(
                ctx,
                width,
                height,
                EYES,
                f,
                vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::STORAGE,
                vk::ImageLayout::GENERAL,
                &format!("{name} colour {i}"),
            )?);
        }
        let depth = Image::new(
            ctx,
            width,
            height,
            EYES,
            vk::Format::D32_SFLOAT,
            vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
            vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
            &format!("{name} depth"),
        )?;
        let mut attachments: Vec<vk::AttachmentDescription> = formats
            .iter()
            .map(|&f| {
                vk::AttachmentDescription::default()
                    .format(f)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                    .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .initial_layout(vk::ImageLayout::UNDEFINED)
                    .final_layout(vk::ImageLayout::GENERAL)
            })
            .collect();
        // Depth is needed only within the pass (the effects read linear depth from a
        // colour attachment), so it is never stored: free on tile-based GPUs.
        attachments.push(
            vk::AttachmentDescription::default()
                .format(vk::Format::D32_SFLOAT)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL),
        );
        let colour_refs: Vec<_> = (0..formats.len())
            .map(|i| vk::AttachmentReference::default().attachment(i as u32).layout(vk::ImageLayout::GENERAL))
            .collect();
        let depth_ref = vk::AttachmentReference::default()
            .attachment(formats.len() as u32)
            .layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL);
        let subpass = vk::SubpassDescription::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&colour_refs)
            .depth_stencil_attachment(&depth_ref);
        // External dependencies: earlier compute/transfer reads of these images
        // (previous frame's effects, readback) finish before the clear writes them
        // (write-after-read: execution dependency); the pass's writes are visible to
        // the compute effect passes and readback after it.
        let deps = [
            vk::SubpassDependency::default()
                .src_subpass(vk::SUBPASS_EXTERNAL)
                .dst_subpass(0)
                .src_stage_mask(
                    vk::PipelineStageFlags::COMPUTE_SHADER
                        | vk::PipelineStageFlags::TRANSFER
                        | vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                        | vk::PipelineStageFlags::LATE_FRAGMENT_TESTS,
                )
                .dst_stage_mask(
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS,
                )
                .src_access_mask(
                    vk::AccessFlags::COLOR_ATTACHMENT_WRITE | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE,
                )
                .dst_access_mask(
                    vk::AccessFlags::COLOR_ATTACHMENT_WRITE | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE,
                ),
            vk::SubpassDependency::default()
                .src_subpass(0)
                .dst_subpass(vk::SUBPASS_EXTERNAL)
                .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                .dst_stage_mask(vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER)
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::SHADER_READ | vk::AccessFlags::TRANSFER_READ),
        ];
        let view_masks = [VIEW_MASK];
        let correlation = [VIEW_MASK];
        let mut multiview =
            vk::RenderPassMultiviewCreateInfo::default().view_masks(&view_masks).correlation_masks(&correlation);
        let info = vk::RenderPassCreateInfo::default()
            .attachments(&attachments)
            .subpasses(std::slice::from_ref(&subpass))
            .dependencies(&deps)
            .push_next(&mut multiview);
        let mut me = Self {
            ctx,
            colour,
            depth,
            render_pass: vk::RenderPass::null(),
            framebuffer: vk::Framebuffer::null(),
            width,
            height,
        };
        // SAFETY: valid device; the create info and its arrays live for the call.
        // On error `Drop` destroys what exists (null handles are ignored).
        me.render_pass = unsafe { ctx.device.create_render_pass(&info, None) }.map_err(vkr("vkCreateRenderPass"))?;
        let views: Vec<vk::ImageView> = me.colour.iter().map(|i| i.view).chain([me.depth.view]).collect();
        // Multiview framebuffers have layers = 1; the views select the array layers
        // (VUID-VkFramebufferCreateInfo-renderPass-02531).
        let fb = vk::FramebufferCreateInfo::default()
            .render_pass(me.render_pass)
            .attachments(&views)
            .width(width)
            .height(height)
            .layers(1);
        // SAFETY: the views are 2-layer arrays of this size, compatible with the pass.
        me.framebuffer = unsafe { ctx.device.create_framebuffer(&fb, None) }.map_err(vkr("vkCreateFramebuffer"))?;
        ctx.set_name(me.render_pass, name);
        ctx.set_name(me.framebuffer, name);
        Ok(me)
    }

    /// Begin the render pass over `area` = [x, y, w, h] only (clamped to the
    /// target, at least 1×1), clearing colour attachment i to `clear[i]` and depth
    /// to 1: the clear and every draw are confined to it (the
    /// render area bounds the load op, and the scissor the rasteriser), so a frame
    /// whose content covers a small part of the eye pays for that part. Texels
    /// outside keep whatever they held: readers must stay inside `area`. The
    /// viewport stays the whole target, so clip space (and the projection) is
    /// unchanged. Multiview: one area for both views (Vulkan has one render area
    /// per pass), so callers pass the union of the eyes' rectangles.
    pub fn record_begin(&self, cmd: vk::CommandBuffer, clear: &[[f32; 4]], area: [u32; 4]) {
        let mut values: Vec<vk::ClearValue> = (0..self.colour.len())
            .map(|i| vk::ClearValue {
                color: vk::ClearColorValue { float32: clear.get(i).copied().unwrap_or([0.0; 4]) },
            })
            .collect();
        values.push(vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 1.0, stencil: 0 } });
        let (tw, th) = (self.width.max(1), self.height.max(1));
        let (x, y) = (area[0].min(tw - 1), area[1].min(th - 1));
        let area = vk::Rect2D::default()
            .offset(vk::Offset2D { x: x as i32, y: y as i32 })
            .extent(vk::Extent2D { width: area[2].clamp(1, tw - x), height: area[3].clamp(1, th - y) });
        let begin = vk::RenderPassBeginInfo::default()
            .render_pass(self.render_pass)
            .framebuffer(self.framebuffer)
            .render_area(area)
            .clear_values(&values);
        let viewport = vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: self.width as f32,
            height: self.height as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        };
        // SAFETY: `cmd` is recording outside a render pass; pass and framebuffer live.
        unsafe {
            self.ctx.device.cmd_begin_render_pass(cmd, &begin, vk::SubpassContents::INLINE);
            self.ctx.device.cmd_set_viewport(cmd, 0, &[viewport]);
            self.ctx.device.cmd_set_scissor(cmd, 0, &[area]);
        }
    }

    pub fn record_end(&self, cmd: vk::CommandBuffer) {
        // SAFETY: ends the render pass begun by `record_begin` in this command buffer.
        unsafe { self.ctx.device.cmd_end_render_pass(cmd) };
    }
}

impl Drop for MultiviewTarget<'_> {
    fn drop(&mut self) {
        // SAFETY: no pending submission uses them; framebuffer before render pass;
        // the images drop after this (fields).
        unsafe {
            self.ctx.device.destroy_framebuffer(self.framebuffer, None);
            self.ctx.device.destroy_render_pass(self.render_pass, None);
        }
    }
}

/// One vertex attribute of an interleaved vertex buffer.
#[derive(Clone, Copy, Debug)]
pub struct VertexAttribute {
    pub location: u32,
    pub format: vk::Format,
    pub offset: u32,
}

/// A graphics pipeline for a `MultiviewTarget`: set 0 = one uniform buffer (per
/// frame in flight), set 1 = a sampled texture + sampler (per material), push
/// constants for per-draw data. Depth test less, write on, no blending (the
/// G-buffer stores premultiplied colour of the nearest surface).
pub struct GraphicsPipeline<'a> {
    ctx: &'a GpuContext,
    layouts: [vk::DescriptorSetLayout; 2],
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::DescriptorPool,
    frame_sets: Vec<vk::DescriptorSet>,
    material_sets: Vec<vk::DescriptorSet>,
    push_size: u32,
}

/// What a `GraphicsPipeline` is built from.
pub struct GraphicsDesc<'s> {
    pub vertex: &'s [u8],
    pub vertex_entry: &'s CStr,
    pub fragment: &'s [u8],
    pub fragment_entry: &'s CStr,
    pub stride: u32,
    pub attributes: &'s [VertexAttribute],
    /// Attributes read from a second vertex buffer (binding 1) of the same
    /// stride: the G-buffer's previous-frame positions.
    pub second_binding: &'s [VertexAttribute],
    pub push_size: u32,
    pub frame_sets: u32,
    pub material_sets: u32,
}

impl<'a> GraphicsPipeline<'a> {
    pub fn new(
        ctx: &'a GpuContext,
        target: &MultiviewTarget<'a>,
        desc: &GraphicsDesc<'_>,
        name: &str,
    ) -> Result<Self, GpuError> {
        let d = &ctx.device;
        let mut p = Self {
            ctx,
            layouts: [vk::DescriptorSetLayout::null(); 2],
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            pool: vk::DescriptorPool::null(),
            frame_sets: vec![],
            material_sets: vec![],
            push_size: desc.push_size,
        };
        let stages_all = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
        let b0 = [vk::DescriptorSetLayoutBinding::default()
            .binding(0)
            .descriptor_type(vk::DescriptorType::UNIFORM_BUFFER)
            .descriptor_count(1)
            .stage_flags(stages_all)];
        let b1 = [
            vk::DescriptorSetLayoutBinding::default()
                .binding(0)
                .descriptor_type(vk::DescriptorType::SAMPLED_IMAGE)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT),
            vk::DescriptorSetLayoutBinding::default()
                .binding(1)
                .descriptor_type(vk::DescriptorType::SAMPLER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT),
            // A second texture sampled with the same sampler (the emissive map).
            vk::DescriptorSetLayoutBinding::default()
                .binding(2)
                .descriptor_type(vk::DescriptorType::SAMPLED_IMAGE)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT),
        ];
        // SAFETY (this block's calls): valid device, create infos alive for each call;
        // partially built objects are destroyed by `Drop` (null handles ignored).
        unsafe {
            p.layouts[0] = d
                .create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&b0), None)
                .map_err(vkr("vkCreateDescriptorSetLayout"))?;
            p.layouts[1] = d
                .create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&b1), None)
                .map_err(vkr("vkCreateDescriptorSetLayout"))?;
        }
        let ranges = [vk::PushConstantRange::default().stage_flags(stages_all).size(desc.push_size)];
        let layout_info = vk::PipelineLayoutCreateInfo::default()
            .set_layouts(&p.layouts)
            .push_constant_ranges(if desc.push_size > 0 { &ranges } else { &[] });
        // SAFETY: as above.
        p.layout = unsafe { d.create_pipeline_layout(&layout_info, None) }.map_err(vkr("vkCreatePipelineLayout"))?;

        let module = |bytes: &[u8]| -> Result<vk::ShaderModule, GpuError> {
            let words = ash::util::read_spv(&mut std::io::Cursor::new(bytes))
                .map_err(|e| GpuError::Input { input: "spirv", problem: e.to_string() })?;
            // SAFETY: SPIR-V validated by naga at build time, read aligned by read_spv.
            unsafe { d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None) }
                .map_err(vkr("vkCreateShaderModule"))
        };
        let vs = module(desc.vertex)?;
        let fs = match module(desc.fragment) {
            Ok(m) => m,
            Err(e) => {
                // SAFETY: unused module.
                unsafe { d.destroy_shader_module(vs, None) };
                return Err(e);
            }
        };
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(vs)
                .name(desc.vertex_entry),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(fs)
                .name(desc.fragment_entry),
        ];
        let bindings = if desc.second_binding.is_empty() { 1 } else { 2 };
        let binding: Vec<_> = (0..bindings)
            .map(|b| {
                vk::VertexInputBindingDescription::default()
                    .binding(b)
                    .stride(desc.stride)
                    .input_rate(vk::VertexInputRate::VERTEX)
            })
            .collect();
        let attrs: Vec<_> = (desc.attributes.iter().map(|a| (0, a)))
            .chain(desc.second_binding.iter().map(|a| (1, a)))
            .map(|(b, a)| {
                vk::VertexInputAttributeDescription::default()
                    .location(a.location)
                    .binding(b)
                    .format(a.format)
                    .offset(a.offset)
            })
            .collect();
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
            .vertex_binding_descriptions(&binding)
            .vertex_attribute_descriptions(&attrs);
        let assembly =
            vk::PipelineInputAssemblyStateCreateInfo::default().topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewport = vk::PipelineViewportStateCreateInfo::default().viewport_count(1).scissor_count(1);
        // No culling: glTF materials may be double-sided and the bundled objects are
        // small; the fragment shader flips back-facing normals.
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(vk::CullModeFlags::NONE)
            .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
            .line_width(1.0);
        let multisample =
            vk::PipelineMultisampleStateCreateInfo::default().rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let depth = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(true)
            .depth_write_enable(true)
            .depth_compare_op(vk::CompareOp::LESS);
        let blend_attachments: Vec<_> = target
            .colour
            .iter()
            .map(|_| vk::PipelineColorBlendAttachmentState::default().color_write_mask(vk::ColorComponentFlags::RGBA))
            .collect();
        let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
        let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .depth_stencil_state(&depth)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic)
            .layout(p.layout)
            .render_pass(target.render_pass)
            .subpass(0);
        // SAFETY: every referenced state struct, module and layout is alive.
        let created = unsafe { d.create_graphics_pipelines(vk::PipelineCache::null(), &[info], None) };
        // SAFETY: modules are only needed during creation.
        unsafe {
            d.destroy_shader_module(vs, None);
            d.destroy_shader_module(fs, None);
        }
        p.pipeline = created.map_err(|(_, r)| GpuError::Vk { call: "vkCreateGraphicsPipelines", result: r })?[0];
        ctx.set_name(p.pipeline, name);

        let (nf, nm) = (desc.frame_sets.max(1), desc.material_sets.max(1));
        let sizes = [
            vk::DescriptorPoolSize::default().ty(vk::DescriptorType::UNIFORM_BUFFER).descriptor_count(nf),
            vk::DescriptorPoolSize::default().ty(vk::DescriptorType::SAMPLED_IMAGE).descriptor_count(2 * nm),
            vk::DescriptorPoolSize::default().ty(vk::DescriptorType::SAMPLER).descriptor_count(nm),
        ];
        // SAFETY: valid device; the pool holds exactly the sets allocated below.
        p.pool = unsafe {
            d.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default().max_sets(nf + nm).pool_sizes(&sizes),
                None,
            )
        }
        .map_err(vkr("vkCreateDescriptorPool"))?;
        let frame_layouts = vec![p.layouts[0]; nf as usize];
        let material_layouts = vec![p.layouts[1]; nm as usize];
        // SAFETY: the pool was sized for these sets.
        unsafe {
            p.frame_sets = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default().descriptor_pool(p.pool).set_layouts(&frame_layouts),
                )
                .map_err(vkr("vkAllocateDescriptorSets"))?;
            p.material_sets = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default().descriptor_pool(p.pool).set_layouts(&material_layouts),
                )
                .map_err(vkr("vkAllocateDescriptorSets"))?;
        }
        Ok(p)
    }

    /// Point frame set `i` at a uniform buffer (not while a submission uses the set).
    pub fn bind_uniform(&self, i: usize, buffer: &Buffer<'_>) -> Result<(), GpuError> {
        let set =
            *self.frame_sets.get(i).ok_or(GpuError::Input {
                input: "frame set",
                problem: format!("{i} ≥ {} sets", self.frame_sets.len()),
            })?;
        let info = [vk::DescriptorBufferInfo::default().buffer(buffer.buffer).range(vk::WHOLE_SIZE)];
        let write = vk::WriteDescriptorSet::default()
            .dst_set(set)
            .dst_binding(0)
            .descriptor_type(vk::DescriptorType::UNIFORM_BUFFER)
            .buffer_info(&info);
        // SAFETY: the set is not used by a pending submission (caller contract).
        unsafe { self.ctx.device.update_descriptor_sets(&[write], &[]) };
        Ok(())
    }

    /// Point material set `i` at its two textures (binding 0 with its sampler at
    /// binding 1; binding 2, sampled with the same sampler).
    pub fn bind_textures(&self, i: usize, texture: &Texture<'_>, second: &Texture<'_>) -> Result<(), GpuError> {
        let set = *self.material_sets.get(i).ok_or(GpuError::Input {
            input: "material set",
            problem: format!("{i} ≥ {} sets", self.material_sets.len()),
        })?;
        let image = [vk::DescriptorImageInfo::default()
            .image_view(texture.image.view)
            .image_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)];
        let sampler = [vk::DescriptorImageInfo::default().sampler(texture.sampler)];
        let image2 = [vk::DescriptorImageInfo::default()
            .image_view(second.image.view)
            .image_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)];
        let writes = [
            vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(0)
                .descriptor_type(vk::DescriptorType::SAMPLED_IMAGE)
                .image_info(&image),
            vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(1)
                .descriptor_type(vk::DescriptorType::SAMPLER)
                .image_info(&sampler),
            vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(2)
                .descriptor_type(vk::DescriptorType::SAMPLED_IMAGE)
                .image_info(&image2),
        ];
        // SAFETY: as in `bind_uniform`.
        unsafe { self.ctx.device.update_descriptor_sets(&writes, &[]) };
        Ok(())
    }

    /// Bind the pipeline and frame set `frame` (inside the target's render pass).
    pub fn record_bind(&self, cmd: vk::CommandBuffer, frame: usize) {
        let set = self.frame_sets[frame.min(self.frame_sets.len() - 1)];
        // SAFETY: `cmd` is recording inside a compatible render pass; objects live.
        unsafe {
            self.ctx.device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
            self.ctx.device.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::GRAPHICS, self.layout, 0, &[set], &[]);
        }
    }

    /// Draw `index_count` u32 indices of `indices` over `vertices` with material set
    /// `material` and push constants `push` (exactly `push_size` bytes).
    pub fn record_draw(
        &self,
        cmd: vk::CommandBuffer,
        material: usize,
        vertices: &[(&Buffer<'_>, u64)],
        indices: &Buffer<'_>,
        index_count: u32,
        push: &[u8],
    ) {
        let set = self.material_sets[material.min(self.material_sets.len() - 1)];
        let d = &self.ctx.device;
        // SAFETY: recording inside the render pass after `record_bind`; buffers were
        // created with vertex/index usage and live until the submission completes.
        unsafe {
            d.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::GRAPHICS, self.layout, 1, &[set], &[]);
            if self.push_size > 0 && push.len() == self.push_size as usize {
                d.cmd_push_constants(
                    cmd,
                    self.layout,
                    vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT,
                    0,
                    push,
                );
            }
            // Binding i reads vertices[i] from its byte offset.
            let buffers: Vec<vk::Buffer> = vertices.iter().map(|(b, _)| b.buffer).collect();
            let offsets: Vec<u64> = vertices.iter().map(|(_, o)| *o).collect();
            d.cmd_bind_vertex_buffers(cmd, 0, &buffers, &offsets);
            d.cmd_bind_index_buffer(cmd, indices.buffer, 0, vk::IndexType::UINT32);
            d.cmd_draw_indexed(cmd, index_count, 1, 0, 0, 0);
        }
    }
}

impl Drop for GraphicsPipeline<'_> {
    fn drop(&mut self) {
        let d = &self.ctx.device;
        // SAFETY: no pending submission uses these; sets (via pool) and pipeline
        // before the layouts they were made from.
        unsafe {
            d.destroy_descriptor_pool(self.pool, None);
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            for l in self.layouts {
                d.destroy_descriptor_set_layout(l, None);
            }
        }
    }
}
