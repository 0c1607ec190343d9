//! Compute pipelines with push constants and bindings 0..n of storage (or uniform)
//! buffers, with one or more descriptor sets (one per frame in flight, so a set is
//! never updated while a submitted frame still reads it).
#![allow(unsafe_code)]

use super::{vkr, Buffer, GpuContext, GpuError, Image};
use ash::vk;

/// One descriptor: a whole buffer (storage or uniform), a storage image (all
/// layers, in its kept layout), or a view of an image someone else owns, read with
/// texel fetches (SAMPLED_IMAGE, no sampler: the OpenXR runtime's environment-depth
/// images, which are made to be sampled).
#[derive(Clone, Copy)]
pub enum Resource<'r, 'c> {
    Buffer(&'r Buffer<'c>),
    Image(&'r Image<'c>),
    SampledView { view: vk::ImageView, layout: vk::ImageLayout },
}

/// A compute pipeline and its descriptor set; destroyed on drop, before its context.
pub struct ComputePipeline<'a> {
    ctx: &'a GpuContext,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::DescriptorPool,
    sets: Vec<vk::DescriptorSet>,
    types: Vec<vk::DescriptorType>,
    push_size: u32,
}

impl<'a> ComputePipeline<'a> {
    /// `spirv`: SPIR-V bytes (entry point `main`); `bindings` storage buffers;
    /// `push_size` bytes of push constants; one descriptor set.
    pub fn new(ctx: &'a GpuContext, spirv: &[u8], bindings: u32, push_size: u32, name: &str) -> Result<Self, GpuError> {
        Self::with_layout(ctx, spirv, &vec![vk::DescriptorType::STORAGE_BUFFER; bindings as usize], push_size, 1, name)
    }

    /// As `new`, with the descriptor type of each binding and `sets` descriptor sets.
    pub fn with_layout(
        ctx: &'a GpuContext,
        spirv: &[u8],
        types: &[vk::DescriptorType],
        push_size: u32,
        sets: u32,
        name: &str,
    ) -> Result<Self, GpuError> {
        let words = ash::util::read_spv(&mut std::io::Cursor::new(spirv))
            .map_err(|e| GpuError::Input { input: "spirv", problem: e.to_string() })?;
        let d = &ctx.device;
        // Build step by step; on error, destroy what exists (in reverse).
        let mut p = Self {
            ctx,
            set_layout: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            pool: vk::DescriptorPool::null(),
            sets: vec![],
            types: types.to_vec(),
            push_size,
        };
        let binding_info: Vec<_> = types
            .iter()
            .enumerate()
            .map(|(b, &ty)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b as u32)
                    .descriptor_type(ty)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        // SAFETY (this and the calls below): valid device, create infos alive for
        // the call; partially built objects are destroyed by `Drop` (null handles
        // are ignored by vkDestroy*, Vulkan spec "Object Lifetime").
        p.set_layout = unsafe {
            d.create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&binding_info), None)
        }
        .map_err(vkr("vkCreateDescriptorSetLayout"))?;
        let ranges = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::COMPUTE).size(push_size)];
        let set_layouts = [p.set_layout];
        let layout_info = vk::PipelineLayoutCreateInfo::default()
            .set_layouts(&set_layouts)
            .push_constant_ranges(if push_size > 0 { &ranges } else { &[] });
        // SAFETY: valid device; `layout_info` and the set layout it names are alive.
        p.layout = unsafe { d.create_pipeline_layout(&layout_info, None) }.map_err(vkr("vkCreatePipelineLayout"))?;
        // SAFETY: `words` is SPIR-V validated by naga at build time and read with
        // `read_spv` (aligned, correct magic); destroyed right after pipeline creation.
        let module = unsafe { d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None) }
            .map_err(vkr("vkCreateShaderModule"))?;
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        let info = vk::ComputePipelineCreateInfo::default().stage(stage).layout(p.layout);
        // SAFETY: the stage, module and layout are alive for the call.
        let created = unsafe { d.create_compute_pipelines(vk::PipelineCache::null(), &[info], None) };
        // SAFETY: the module is only needed during pipeline creation.
        unsafe { d.destroy_shader_module(module, None) };
        p.pipeline = created.map_err(|(_, r)| GpuError::Vk { call: "vkCreateComputePipelines", result: r })?[0];
        ctx.set_name(p.pipeline, name);
        let count = sets.max(1);
        let sizes: Vec<_> =
            types.iter().map(|&ty| vk::DescriptorPoolSize::default().ty(ty).descriptor_count(count)).collect();
        // SAFETY: valid device; pool sizes cover every binding of every set.
        p.pool = unsafe {
            d.create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(count).pool_sizes(&sizes), None)
        }
        .map_err(vkr("vkCreateDescriptorPool"))?;
        let layouts = vec![p.set_layout; count as usize];
        // SAFETY: the pool was sized for `count` sets of this layout.
        p.sets = unsafe {
            d.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default().descriptor_pool(p.pool).set_layouts(&layouts),
            )
        }
        .map_err(vkr("vkAllocateDescriptorSets"))?;
        Ok(p)
    }

    /// Point bindings 0..n of set 0 at `buffers` (whole ranges).
    pub fn bind(&self, buffers: &[&Buffer<'_>]) -> Result<(), GpuError> {
        self.bind_set(0, buffers)
    }

    /// Point bindings 0..n of descriptor set `set` at `buffers` (whole ranges). The
    /// set must not be in use by a pending submission.
    pub fn bind_set(&self, set: usize, buffers: &[&Buffer<'_>]) -> Result<(), GpuError> {
        let res: Vec<Resource<'_, '_>> = buffers.iter().map(|b| Resource::Buffer(b)).collect();
        self.bind_resources(set, &res)
    }

    /// Point bindings 0..n of descriptor set `set` at buffers and storage images.
    /// The set must not be in use by a pending submission.
    pub fn bind_resources(&self, set: usize, res: &[Resource<'_, '_>]) -> Result<(), GpuError> {
        if res.len() != self.types.len() || set >= self.sets.len() {
            return Err(GpuError::Input {
                input: "bindings",
                problem: format!(
                    "pipeline has {} bindings and {} sets, got {} resources for set {set}",
                    self.types.len(),
                    self.sets.len(),
                    res.len()
                ),
            });
        }
        for (i, r) in res.iter().enumerate() {
            let fits = match r {
                Resource::Buffer(_) => {
                    matches!(self.types[i], vk::DescriptorType::STORAGE_BUFFER | vk::DescriptorType::UNIFORM_BUFFER)
                }
                Resource::Image(_) => self.types[i] == vk::DescriptorType::STORAGE_IMAGE,
                Resource::SampledView { .. } => self.types[i] == vk::DescriptorType::SAMPLED_IMAGE,
            };
            if !fits {
                return Err(GpuError::Input {
                    input: "bindings",
                    problem: format!("binding {i} is {:?}, got another kind of resource", self.types[i]),
                });
            }
        }
        let buffer_infos: Vec<[vk::DescriptorBufferInfo; 1]> = res
            .iter()
            .map(|r| match r {
                Resource::Buffer(b) => [vk::DescriptorBufferInfo::default().buffer(b.buffer).range(vk::WHOLE_SIZE)],
                Resource::Image(_) | Resource::SampledView { .. } => [vk::DescriptorBufferInfo::default()],
            })
            .collect();
        let image_infos: Vec<[vk::DescriptorImageInfo; 1]> = res
            .iter()
            .map(|r| match r {
                Resource::Image(img) => {
                    [vk::DescriptorImageInfo::default().image_view(img.view).image_layout(img.layout)]
                }
                Resource::SampledView { view, layout } => {
                    [vk::DescriptorImageInfo::default().image_view(*view).image_layout(*layout)]
                }
                Resource::Buffer(_) => [vk::DescriptorImageInfo::default()],
            })
            .collect();
        let writes: Vec<_> = res
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let w = vk::WriteDescriptorSet::default()
                    .dst_set(self.sets[set])
                    .dst_binding(i as u32)
                    .descriptor_type(self.types[i]);
                match r {
                    Resource::Buffer(_) => w.buffer_info(&buffer_infos[i]),
                    Resource::Image(_) | Resource::SampledView { .. } => w.image_info(&image_infos[i]),
                }
            })
            .collect();
        // SAFETY: the set is not in use by any pending submission (all waited on);
        // every write's info array outlives the call.
        unsafe { self.ctx.device.update_descriptor_sets(&writes, &[]) };
        Ok(())
    }

    /// Record a dispatch of `groups` workgroups with `push` constants using set 0,
    /// followed by a compute→transfer/compute barrier so results can be read next.
    pub fn record(&self, cmd: vk::CommandBuffer, push: &[u8], groups: [u32; 3]) {
        self.record_set(cmd, 0, push, groups)
    }

    /// As `record`, with descriptor set `set` (clamped to the sets allocated).
    pub fn record_set(&self, cmd: vk::CommandBuffer, set: usize, push: &[u8], groups: [u32; 3]) {
        let d = &self.ctx.device;
        let set = self.sets[set.min(self.sets.len() - 1)];
        // More bytes than the layout's push-constant range is undefined behaviour
        // (VUID-vkCmdPushConstants-size-00369): lavapipe corrupts its heap. A pass
        // whose struct outgrew its declared size fails here in tests, and never
        // writes past the range in a release build.
        debug_assert_eq!(push.len(), self.push_size as usize, "push constants vs the pipeline's declared size");
        let push = &push[..push.len().min(self.push_size as usize)];
        // SAFETY: `cmd` is recording; pipeline, layout and set are live; `push` is
        // at most the declared push-constant size (cut above; the pass structs'
        // static size assertions and the debug assertion keep them equal).
        unsafe {
            d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            d.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::COMPUTE, self.layout, 0, &[set], &[]);
            if self.push_size > 0 {
                d.cmd_push_constants(cmd, self.layout, vk::ShaderStageFlags::COMPUTE, 0, push);
            }
            d.cmd_dispatch(cmd, groups[0], groups[1], groups[2]);
            let barrier = vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_READ | vk::AccessFlags::SHADER_READ);
            d.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::DependencyFlags::empty(),
                &[barrier],
                &[],
                &[],
            );
        }
    }
}

impl Drop for ComputePipeline<'_> {
    fn drop(&mut self) {
        let d = &self.ctx.device;
        // SAFETY: no pending submission uses these (all waited on); children
        // (set via its pool) before the layouts they were made from.
        unsafe {
            d.destroy_descriptor_pool(self.pool, None);
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}
