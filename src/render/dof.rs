//! Depth-of-field compute passes (`shaders/dof_blur.comp`, `shaders/dof_blend.comp`),
//! twin of `synth::add_defocus`: the cascaded discrete-Gaussian stack with nodes
//! every `model::DOF_NODE_SPACING_PX`, each pixel blended between the two nodes
//! around its σ with variance-matched weights. One submission per stack interval
//! (blur x, blur y, blend), because each needs its own bindings.

use crate::gpu::{Buffer, ComputePipeline, GpuContext, GpuError};
use crate::model::{kernels::discrete_gaussian_kernel, DOF_NODE_SPACING_PX, MAX_DOF_SIGMA_PX};
use bytemuck::{Pod, Zeroable};

const BLUR_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/dof_blur.spv"));
const BLEND_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/dof_blend.spv"));
const WORKGROUP: u32 = 8;

/// Push constants of `dof_blur.comp`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct BlurParams {
    pub width: u32,
    pub height: u32,
    pub radius: u32,
    pub axis: u32,
    pub kernel_offset: u32,
}

/// Push constants of `dof_blend.comp`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct BlendParams {
    pub width: u32,
    pub height: u32,
    pub s0: f32,
    pub s1: f32,
}

const _: () = assert!(std::mem::size_of::<BlurParams>() == 20);
const _: () = assert!(std::mem::size_of::<BlendParams>() == 16);
const _: () = assert!(std::mem::offset_of!(BlendParams, s0) == 8);

pub struct DofPass<'a> {
    ctx: &'a GpuContext,
    blur_x: ComputePipeline<'a>,
    blur_y: ComputePipeline<'a>,
    blend: ComputePipeline<'a>,
    /// The discrete-Gaussian kernel of every stack interval up to MAX_DOF_SIGMA_PX,
    /// concatenated; they depend only on the interval, so they are built once here
    /// rather than on every run.
    kernels: Buffer<'a>,
    /// (offset, radius) of interval k's taps in `kernels`.
    kernel_spans: Vec<(u32, u32)>,
}

impl<'a> DofPass<'a> {
    pub fn new(ctx: &'a GpuContext) -> Result<Self, GpuError> {
        let intervals = (MAX_DOF_SIGMA_PX / DOF_NODE_SPACING_PX).ceil() as usize;
        let mut taps = Vec::new();
        let mut kernel_spans = Vec::with_capacity(intervals);
        for k in 0..intervals {
            // The same f32 arithmetic as synth::for_each_cascade_interval.
            let (s0, s1) = (k as f32 * DOF_NODE_SPACING_PX, (k + 1) as f32 * DOF_NODE_SPACING_PX);
            let kernel = discrete_gaussian_kernel(s1 * s1 - s0 * s0);
            kernel_spans.push((taps.len() as u32, (kernel.len() / 2) as u32));
            taps.extend_from_slice(&kernel);
        }
        Ok(Self {
            ctx,
            blur_x: ComputePipeline::new(ctx, BLUR_SPIRV, 3, 20, "dof_blur_x")?,
            blur_y: ComputePipeline::new(ctx, BLUR_SPIRV, 3, 20, "dof_blur_y")?,
            blend: ComputePipeline::new(ctx, BLEND_SPIRV, 4, 16, "dof_blend")?,
            kernels: ctx.upload(bytemuck::cast_slice(&taps), "dof kernels")?,
            kernel_spans,
        })
    }

    /// Blur `rgb` (planar R, G, B of `width × height`) with per-pixel std `sigma_px`.
    /// σ is sanitised exactly as the CPU twin does (non-finite → 0, clamped to
    /// [0, MAX_DOF_SIGMA_PX]) before upload.
    pub fn run(&self, width: usize, height: usize, rgb: &[f32], sigma_px: &[f32]) -> Result<Vec<f32>, GpuError> {
        let n = width * height;
        if n == 0 || rgb.len() != 3 * n || sigma_px.len() != n {
            return Err(GpuError::Input {
                input: "image/sigma",
                problem: format!(
                    "{width}×{height} needs {} colour and {n} σ values, got {} and {}",
                    3 * n,
                    rgb.len(),
                    sigma_px.len()
                ),
            });
        }
        let sigma: Vec<f32> =
            sigma_px.iter().map(|&s| if s.is_finite() { s.clamp(0.0, MAX_DOF_SIGMA_PX) } else { 0.0 }).collect();
        let max_sigma = sigma.iter().cloned().fold(0.0f32, f32::max);
        if max_sigma == 0.0 {
            return Ok(rgb.to_vec());
        }
        let bytes = (rgb.len() * 4) as u64;
        let mut prev = self.ctx.upload(bytemuck::cast_slice(rgb), "dof stack lower")?;
        let mut next = self.ctx.storage_buffer(bytes, "dof stack upper")?;
        let tmp = self.ctx.storage_buffer(bytes, "dof blur tmp")?;
        let sigma_buf = self.ctx.upload(bytemuck::cast_slice(&sigma), "dof sigma")?;
        // σ = 0 pixels keep the exact input: start the output as a copy.
        let out = self.ctx.storage_buffer(bytes, "dof out")?;
        self.ctx.submit_and_wait(|cmd| self.ctx.record_copy(cmd, &prev, &out, bytes))?;
        let groups = [(width as u32).div_ceil(WORKGROUP), (height as u32).div_ceil(WORKGROUP), 1];
        let intervals = (max_sigma / DOF_NODE_SPACING_PX).ceil().max(1.0) as usize;
        for k in 0..intervals {
            let (s0, s1) = (k as f32 * DOF_NODE_SPACING_PX, (k + 1) as f32 * DOF_NODE_SPACING_PX);
            let (kernel_offset, radius) = self.kernel_spans[k];
            self.blur_x.bind(&[&prev, &tmp, &self.kernels])?;
            self.blur_y.bind(&[&tmp, &next, &self.kernels])?;
            self.blend.bind(&[&prev, &next, &sigma_buf, &out])?;
            let (w, h) = (width as u32, height as u32);
            let px = BlurParams { width: w, height: h, radius, axis: 0, kernel_offset };
            let py = BlurParams { width: w, height: h, radius, axis: 1, kernel_offset };
            let pb = BlendParams { width: w, height: h, s0, s1 };
            self.ctx.dispatch_and_wait(|cmd| {
                self.blur_x.record(cmd, bytemuck::bytes_of(&px), groups);
                self.blur_y.record(cmd, bytemuck::bytes_of(&py), groups);
                self.blend.record(cmd, bytemuck::bytes_of(&pb), groups);
            })?;
            std::mem::swap(&mut prev, &mut next);
        }
        let data = self.ctx.download(&out)?;
        Ok(bytemuck::cast_slice(&data[..rgb.len() * 4]).to_vec())
    }
}
