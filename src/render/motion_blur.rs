//! Motion-blur compute pass (`shaders/motion_blur.comp`), twin of
//! `synth::add_motion_blur`: per-pixel exposure-window gather along the flow.
//! This is the reference-matching gather; the renderer's tile-max/neighbour-max
//! reconstruction for moving silhouettes builds on it (next step of the render core).

use crate::gpu::{ComputePipeline, GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

const SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/motion_blur.spv"));
const WORKGROUP: u32 = 8;

/// Push constants, laid out as `Params` in the shader (std430 scalars, 20 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct MotionBlurParams {
    pub width: u32,
    pub height: u32,
    pub exposure: f32,
    pub max_spacing_px: f32,
    pub min_intervals: u32,
}

const _: () = assert!(std::mem::size_of::<MotionBlurParams>() == 20);
const _: () = assert!(std::mem::offset_of!(MotionBlurParams, exposure) == 8);
const _: () = assert!(std::mem::offset_of!(MotionBlurParams, min_intervals) == 16);

pub struct MotionBlurPass<'a> {
    ctx: &'a GpuContext,
    pipeline: ComputePipeline<'a>,
}

impl<'a> MotionBlurPass<'a> {
    pub fn new(ctx: &'a GpuContext) -> Result<Self, GpuError> {
        Ok(Self { ctx, pipeline: ComputePipeline::new(ctx, SPIRV, 3, 20, "motion_blur")? })
    }

    /// Blur `rgb` (planar R, G, B of `width × height`) along `flow_xy` (interleaved
    /// x, y in px per frame) with exposure λ. Inputs are validated here so that no
    /// NaN/Inf or out-of-range value reaches the GPU.
    pub fn run(
        &self,
        width: usize,
        height: usize,
        rgb: &[f32],
        flow_xy: &[f32],
        exposure: f32,
    ) -> Result<Vec<f32>, GpuError> {
        let n = width * height;
        if n == 0 || rgb.len() != 3 * n || flow_xy.len() != 2 * n {
            return Err(GpuError::Input {
                input: "image/flow",
                problem: format!(
                    "{width}×{height} needs {} colour and {} flow values, got {} and {}",
                    3 * n,
                    2 * n,
                    rgb.len(),
                    flow_xy.len()
                ),
            });
        }
        if let Some(i) = flow_xy.iter().position(|v| !v.is_finite()) {
            return Err(GpuError::Input { input: "flow", problem: format!("non-finite value at pixel {}", i / 2) });
        }
        // The shader takes a tap every `MB_MAX_SAMPLE_SPACING_PX` along the streak:
        // a flow past the frame's diagonal (`model::flow_within_frame`) would hold
        // one invocation for millions of taps.
        if let Some(i) =
            flow_xy.chunks_exact(2).position(|v| !crate::model::flow_within_frame(v[0], v[1], width, height))
        {
            return Err(GpuError::Input {
                input: "flow",
                problem: format!(
                    "({}, {}) px/frame at pixel {i} is longer than the {width}×{height} frame's diagonal",
                    flow_xy[2 * i],
                    flow_xy[2 * i + 1]
                ),
            });
        }
        if !exposure.is_finite() || !(0.0..=1.0).contains(&exposure) {
            return Err(GpuError::Input { input: "exposure", problem: format!("must be in [0, 1], got {exposure}") });
        }
        let params = MotionBlurParams {
            width: width as u32,
            height: height as u32,
            exposure,
            max_spacing_px: crate::model::MB_MAX_SAMPLE_SPACING_PX,
            min_intervals: crate::model::MB_MIN_INTERVALS,
        };
        let src = self.ctx.upload(bytemuck::cast_slice(rgb), "motion_blur src")?;
        let flow = self.ctx.upload(bytemuck::cast_slice(flow_xy), "motion_blur flow")?;
        let dst = self.ctx.storage_buffer((rgb.len() * 4) as u64, "motion_blur dst")?;
        self.pipeline.bind(&[&src, &flow, &dst])?;
        let groups = [(width as u32).div_ceil(WORKGROUP), (height as u32).div_ceil(WORKGROUP), 1];
        self.ctx.dispatch_and_wait(|cmd| self.pipeline.record(cmd, bytemuck::bytes_of(&params), groups))?;
        let bytes = self.ctx.download(&dst)?;
        Ok(bytemuck::cast_slice(&bytes[..rgb.len() * 4]).to_vec())
    }
}
