//! XR_FB_space_warp's inputs from the G-buffer (shaders/spacewarp.comp): per eye,
//! NDC motion vectors and NDC depth at the runtime's recommended motion-vector size,
//! copied into the motion-vector and depth swapchain images. The compositor then
//! synthesises every other display frame and the app renders at half the display
//! rate (the paper's demo ran at 45 Hz). Twin: synth::layer::space_warp.

use super::gbuffer::{FAR_M, NEAR_M};
use crate::gpu::{record_copy_to_external_depth, Buffer, ComputePipeline, GpuContext, GpuError, Image, Resource, EYES};
use crate::model::Rect;
use ash::vk;
use bytemuck::{Pod, Zeroable};

const SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/spacewarp.spv"));

/// Motion-vector format (XR_FB_space_warp recommends a 16-bit float RGBA).
pub const VECTOR_FORMAT: vk::Format = vk::Format::R16G16B16A16_SFLOAT;
/// Depth format of the depth swapchain this pass fills.
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Push {
    area: [i32; 4],
    eye_size: [i32; 2],
    mv_size: [i32; 2],
    near_m: f32,
    far_m: f32,
    pad: [i32; 2],
}
const _: () = assert!(std::mem::size_of::<Push>() == 48);

/// Where a frame's space-warp data go: the acquired motion-vector and depth
/// swapchain images, and the layouts they are kept in.
#[derive(Clone, Copy, Debug)]
pub struct SpaceWarpTarget {
    pub vectors: vk::Image,
    pub vectors_layout: vk::ImageLayout,
    pub depth: vk::Image,
    pub depth_layout: vk::ImageLayout,
}

pub struct SpaceWarpPass<'a> {
    ctx: &'a GpuContext,
    pipeline: ComputePipeline<'a>,
    pub vectors: Image<'a>,
    pub depth: Buffer<'a>,
    eye_size: (u32, u32),
    pub size: (u32, u32),
}

/// The near and far planes the G-buffer's projection uses (the space-warp info's
/// nearZ / farZ must match the depth written here).
pub const PLANES_M: (f32, f32) = (NEAR_M, FAR_M);

impl<'a> SpaceWarpPass<'a> {
    /// A pass reading `motion` (the G-buffer's motion image) into `width × height`
    /// outputs per eye.
    pub fn new(ctx: &'a GpuContext, motion: &Image<'_>, width: u32, height: u32) -> Result<Self, GpuError> {
        if width == 0 || height == 0 || width > motion.width || height > motion.height {
            return Err(GpuError::Input {
                input: "space-warp size",
                problem: format!("{width}×{height} must be 1…{}×{}", motion.width, motion.height),
            });
        }
        let types =
            [vk::DescriptorType::STORAGE_IMAGE, vk::DescriptorType::STORAGE_IMAGE, vk::DescriptorType::STORAGE_BUFFER];
        let pipeline =
            ComputePipeline::with_layout(ctx, SPIRV, &types, std::mem::size_of::<Push>() as u32, 1, "spacewarp")?;
        let vectors = Image::new(
            ctx,
            width,
            height,
            EYES,
            VECTOR_FORMAT,
            vk::ImageUsageFlags::STORAGE,
            vk::ImageLayout::GENERAL,
            "space-warp vectors",
        )?;
        let depth = ctx.storage_buffer(width as u64 * height as u64 * EYES as u64 * 4, "space-warp depth")?;
        pipeline.bind_resources(0, &[Resource::Image(motion), Resource::Image(&vectors), Resource::Buffer(&depth)])?;
        Ok(Self { ctx, pipeline, vectors, depth, eye_size: (motion.width, motion.height), size: (width, height) })
    }

    /// Record the conversion for the frame whose G-buffer pass wrote `area`.
    pub fn record(&self, cmd: vk::CommandBuffer, area: Rect) {
        let (w, h) = self.size;
        let push = Push {
            area: [area.x, area.y, area.w, area.h],
            eye_size: [self.eye_size.0 as i32, self.eye_size.1 as i32],
            mv_size: [w as i32, h as i32],
            near_m: PLANES_M.0,
            far_m: PLANES_M.1,
            pad: [0; 2],
        };
        self.pipeline.record(cmd, bytemuck::bytes_of(&push), [w.div_ceil(8), h.div_ceil(8), EYES]);
    }

    /// Record the conversion and the copies into `target`'s images.
    pub fn record_to(&self, cmd: vk::CommandBuffer, area: Rect, target: &SpaceWarpTarget) {
        self.record(cmd, area);
        self.vectors.record_copy_to_external(cmd, target.vectors, target.vectors_layout);
        let (w, h) = self.size;
        record_copy_to_external_depth(self.ctx, cmd, &self.depth, target.depth, target.depth_layout, [w, h, EYES]);
    }
}
