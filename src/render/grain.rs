//! Grain compute passes, twin of `synth::noise_field`: the paper's Laplacian-pyramid
//! noise synthesis on the GPU — counter-based white noise (`grain_init.comp`), its
//! 4-level Laplacian pyramid (`pyr_reduce`, `pyr_expand`, `pyr_combine`), each band
//! scaled by the synthesis weight at the content's luma of that level
//! (`grain_scale.comp`, weights from `synth::SynthesisTable`, passed in as plain
//! data), and the collapse. Fresh noise per frame comes from the seed.

use crate::gpu::{Buffer, ComputePipeline, GpuContext, GpuError};
use crate::model::NOISE_LEVELS;
use bytemuck::{Pod, Zeroable};

const REDUCE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/pyr_reduce.spv"));
const EXPAND: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/pyr_expand.spv"));
const COMBINE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/pyr_combine.spv"));
const INIT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/grain_init.spv"));
const SCALE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/grain_scale.spv"));
const BANDS: usize = NOISE_LEVELS + 1;

/// Synthesis weights per luma node, channel and band ([node][channel][band]).
#[derive(Clone, Debug)]
pub struct GrainTable {
    pub luma_range: [f32; 2],
    pub nodes: u32,
    pub weights: Vec<f32>,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct PyrParams {
    in_w: u32,
    in_h: u32,
    out_w: u32,
    out_h: u32,
    channels: u32,
    axis: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct CombineParams {
    count: u32,
    subtract: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct InitParams {
    width: u32,
    height: u32,
    seed_lo: u32,
    seed_hi: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ScaleParams {
    width: u32,
    height: u32,
    level: u32,
    nodes: u32,
    lo: f32,
    hi: f32,
}

const _: () = assert!(std::mem::size_of::<PyrParams>() == 24);
const _: () = assert!(std::mem::size_of::<CombineParams>() == 8);
const _: () = assert!(std::mem::size_of::<InitParams>() == 16);
const _: () = assert!(std::mem::size_of::<ScaleParams>() == 24);
const _: () = assert!(std::mem::offset_of!(ScaleParams, lo) == 16);

pub struct GrainPass<'a> {
    ctx: &'a GpuContext,
    reduce: ComputePipeline<'a>,
    expand: ComputePipeline<'a>,
    combine: ComputePipeline<'a>,
    init: ComputePipeline<'a>,
    scale: ComputePipeline<'a>,
}

/// 2-D workgroup counts for 8×8 groups.
fn groups(w: usize, h: usize) -> [u32; 3] {
    [(w as u32).div_ceil(8), (h as u32).div_ceil(8), 1]
}

impl<'a> GrainPass<'a> {
    pub fn new(ctx: &'a GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            ctx,
            reduce: ComputePipeline::new(ctx, REDUCE, 2, 24, "pyr_reduce")?,
            expand: ComputePipeline::new(ctx, EXPAND, 2, 24, "pyr_expand")?,
            combine: ComputePipeline::new(ctx, COMBINE, 3, 8, "pyr_combine")?,
            init: ComputePipeline::new(ctx, INIT, 1, 16, "grain_init")?,
            scale: ComputePipeline::new(ctx, SCALE, 3, 24, "grain_scale")?,
        })
    }

    /// Bind, record one dispatch, submit and wait (each dispatch has its own bindings).
    fn dispatch(
        &self,
        p: &ComputePipeline<'_>,
        bufs: &[&Buffer<'_>],
        push: &[u8],
        g: [u32; 3],
    ) -> Result<(), GpuError> {
        p.bind(bufs)?;
        self.ctx.dispatch_and_wait(|cmd| p.record(cmd, push, g))
    }

    /// Separable reduce of a `channels`-plane buffer of `w × h`.
    fn reduce(&self, src: &Buffer<'_>, w: usize, h: usize, channels: usize) -> Result<Buffer<'a>, GpuError> {
        let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
        let tmp = self.ctx.storage_buffer((channels * w2 * h * 4) as u64, "reduce tmp")?;
        let out = self.ctx.storage_buffer((channels * w2 * h2 * 4) as u64, "reduce out")?;
        let c = channels as u32;
        let px = PyrParams { in_w: w as u32, in_h: h as u32, out_w: w2 as u32, out_h: h as u32, channels: c, axis: 0 };
        self.dispatch(&self.reduce, &[src, &tmp], bytemuck::bytes_of(&px), groups(w2, h))?;
        let py =
            PyrParams { in_w: w2 as u32, in_h: h as u32, out_w: w2 as u32, out_h: h2 as u32, channels: c, axis: 1 };
        self.dispatch(&self.reduce, &[&tmp, &out], bytemuck::bytes_of(&py), groups(w2, h2))?;
        Ok(out)
    }

    /// Separable expand of a 3-plane buffer of `w × h` to `width × height`.
    fn expand(
        &self,
        src: &Buffer<'_>,
        w: usize,
        h: usize,
        width: usize,
        height: usize,
    ) -> Result<Buffer<'a>, GpuError> {
        let tmp = self.ctx.storage_buffer((3 * width * h * 4) as u64, "expand tmp")?;
        let out = self.ctx.storage_buffer((3 * width * height * 4) as u64, "expand out")?;
        let px =
            PyrParams { in_w: w as u32, in_h: h as u32, out_w: width as u32, out_h: h as u32, channels: 3, axis: 0 };
        self.dispatch(&self.expand, &[src, &tmp], bytemuck::bytes_of(&px), groups(width, h))?;
        let py = PyrParams {
            in_w: width as u32,
            in_h: h as u32,
            out_w: width as u32,
            out_h: height as u32,
            channels: 3,
            axis: 1,
        };
        self.dispatch(&self.expand, &[&tmp, &out], bytemuck::bytes_of(&py), groups(width, height))?;
        Ok(out)
    }

    fn combine(&self, a: &Buffer<'_>, b: &Buffer<'_>, count: usize, subtract: bool) -> Result<Buffer<'a>, GpuError> {
        let out = self.ctx.storage_buffer((count * 4) as u64, "combine out")?;
        let params = CombineParams { count: count as u32, subtract: subtract as u32 };
        self.dispatch(&self.combine, &[a, b, &out], bytemuck::bytes_of(&params), [(count as u32).div_ceil(64), 1, 1])?;
        Ok(out)
    }

    /// Noise field (planar R, G, B) for content of luma `luma` (`width × height`).
    pub fn run(
        &self,
        width: usize,
        height: usize,
        luma: &[f32],
        table: &GrainTable,
        seed: u64,
    ) -> Result<Vec<f32>, GpuError> {
        let n = width * height;
        if n == 0 || luma.len() != n {
            return Err(GpuError::Input {
                input: "luma",
                problem: format!("{width}×{height} needs {n} values, got {}", luma.len()),
            });
        }
        if let Some(i) = luma.iter().position(|v| !v.is_finite()) {
            return Err(GpuError::Input { input: "luma", problem: format!("non-finite value at pixel {i}") });
        }
        let [lo, hi] = table.luma_range;
        if table.nodes < 2
            || table.weights.len() != table.nodes as usize * 3 * BANDS
            || !lo.is_finite()
            || !hi.is_finite()
            || table.weights.iter().any(|w| !w.is_finite() || *w < 0.0)
        {
            return Err(GpuError::Input {
                input: "grain table",
                problem: "needs ≥ 2 nodes of 3×5 finite, non-negative weights and a finite luma range".into(),
            });
        }
        // Level sizes, finest first.
        let mut sizes = vec![(width, height)];
        for _ in 0..NOISE_LEVELS {
            let &(w, h) = sizes.last().unwrap_or(&(width, height));
            sizes.push((w.div_ceil(2), h.div_ceil(2)));
        }
        // Luma Gaussian pyramid (1 channel).
        let mut lumas = vec![self.ctx.upload(bytemuck::cast_slice(luma), "grain luma 0")?];
        for l in 0..NOISE_LEVELS {
            let (w, h) = sizes[l];
            let next = self.reduce(&lumas[l], w, h, 1)?;
            lumas.push(next);
        }
        // White noise and its Laplacian pyramid (3 channels).
        let white = self.ctx.storage_buffer((3 * n * 4) as u64, "grain white")?;
        let ip = InitParams {
            width: width as u32,
            height: height as u32,
            seed_lo: seed as u32,
            seed_hi: (seed >> 32) as u32,
        };
        self.dispatch(&self.init, &[&white], bytemuck::bytes_of(&ip), groups(width, height))?;
        let mut gauss = vec![white];
        let mut bands = vec![];
        for l in 0..NOISE_LEVELS {
            let (w, h) = sizes[l];
            let (w2, h2) = sizes[l + 1];
            let down = self.reduce(&gauss[l], w, h, 3)?;
            let up = self.expand(&down, w2, h2, w, h)?;
            bands.push(self.combine(&gauss[l], &up, 3 * w * h, true)?);
            gauss.push(down);
        }
        let table_buf = self.ctx.upload(bytemuck::cast_slice(&table.weights), "grain table")?;
        let lowpass = gauss.pop().ok_or(GpuError::Input { input: "pyramid", problem: "empty".into() })?;
        for (l, band) in bands.iter().chain(std::iter::once(&lowpass)).enumerate() {
            let (w, h) = sizes[l];
            let sp = ScaleParams { width: w as u32, height: h as u32, level: l as u32, nodes: table.nodes, lo, hi };
            self.dispatch(&self.scale, &[band, &lumas[l], &table_buf], bytemuck::bytes_of(&sp), groups(w, h))?;
        }
        // Collapse from the low-pass up.
        let mut cur = lowpass;
        for l in (0..NOISE_LEVELS).rev() {
            let (w, h) = sizes[l];
            let (w2, h2) = sizes[l + 1];
            let up = self.expand(&cur, w2, h2, w, h)?;
            cur = self.combine(&up, &bands[l], 3 * w * h, false)?;
        }
        let bytes = self.ctx.download(&cur)?;
        Ok(bytemuck::cast_slice(&bytes[..3 * n * 4]).to_vec())
    }
}
