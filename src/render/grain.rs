//! Grain compute passes, twin of `synth::noise_field`: the paper's Laplacian-pyramid
//! noise synthesis on the GPU, fused into few dispatches. Level 0 of a *joint*
//! pyramid holds unit white noise (3 planes) and the content's luma (plane 4) —
//! written by `grain_init.comp` from a luma buffer, or in the frame by
//! `layer_luma.comp` straight from the layer colour; `pyr_reduce` builds both
//! Gaussian pyramids at once (one 4-plane dispatch per axis and level); the collapse
//! runs coarse to fine, one `grain_synth` dispatch per level computing
//! C_l = E(C_{l+1}) + w_l(luma_l)·(G_l − E(G_{l+1})) (band, scale and collapse in one
//! pass), from `grain_top`'s C_L = w_L(luma_L)·G_L. Weights from
//! `synth::SynthesisTable`, passed in as plain data; fresh noise per frame comes from
//! the seed. 14 dispatches for 4 levels where the unfused chain took 46, and every
//! buffer holds one vec4 per pixel so a tap is one load, not one per channel.

use crate::gpu::{Buffer, ComputePipeline, GpuContext, GpuError};
use crate::model::NOISE_LEVELS;
use bytemuck::{Pod, Zeroable};

const REDUCE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/grain_reduce.spv"));
const INIT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/grain_init.spv"));
const TOP: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/grain_top.spv"));
const SYNTH: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/grain_synth.spv"));
const BANDS: usize = NOISE_LEVELS + 1;
/// Floats per pixel of every grain buffer: one vec4 (joint pyramid: noise R, G, B
/// and luma; collapse and field: R, G, B and an unused 0), interleaved so a shader
/// reads a pixel's channels in one load.
pub const GRAIN_TEXEL_FLOATS: usize = 4;

pub use crate::model::GrainTable;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct PyrParams {
    in_w: u32,
    in_h: u32,
    out_w: u32,
    out_h: u32,
    axis: u32,
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
struct TopParams {
    width: u32,
    height: u32,
    level: u32,
    nodes: u32,
    lo: f32,
    hi: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct SynthParams {
    w0: u32,
    h0: u32,
    w1: u32,
    h1: u32,
    level: u32,
    nodes: u32,
    lo: f32,
    hi: f32,
}

const _: () = assert!(std::mem::size_of::<PyrParams>() == 20);
const _: () = assert!(std::mem::size_of::<InitParams>() == 16);
const _: () = assert!(std::mem::size_of::<TopParams>() == 24);
const _: () = assert!(std::mem::offset_of!(TopParams, nodes) == 12);
const _: () = assert!(std::mem::size_of::<SynthParams>() == 32);
const _: () = assert!(std::mem::offset_of!(SynthParams, nodes) == 20);

/// Whole-image grain with its own submissions: `GrainRecorder`'s dispatch sequence
/// (the one the frame records) on a recorder sized for each call, for the twin test
/// and the reference benchmark.
pub struct GrainPass<'a> {
    ctx: &'a GpuContext,
}

/// 2-D workgroup counts for 8×8 groups.
fn groups(w: usize, h: usize) -> [u32; 3] {
    [(w as u32).div_ceil(8), (h as u32).div_ceil(8), 1]
}

impl<'a> GrainPass<'a> {
    pub fn new(ctx: &'a GpuContext) -> Result<Self, GpuError> {
        Ok(Self { ctx })
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
        let recorder = GrainRecorder::new(self.ctx, width, height, table.nodes)?;
        let init = ComputePipeline::with_layout(self.ctx, INIT, &vk_storage(2), 16, 1, "grain init")?;
        let luma_buf = self.ctx.upload(bytemuck::cast_slice(luma), "grain luma")?;
        init.bind(&[&luma_buf, recorder.level0()])?;
        let table_buf = self.ctx.upload(bytemuck::cast_slice(&table.weights), "grain table")?;
        // Transfers apart from the timed dispatches (`dispatch_and_wait` times only
        // the synthesis).
        self.ctx.submit_and_wait(|cmd| {
            self.ctx.record_copy(cmd, &table_buf, &recorder.table, table_buf.size);
        })?;
        let mut recorded = Ok(());
        self.ctx.dispatch_and_wait(|cmd| {
            // The copy above (an earlier submission) becomes visible to the shaders.
            crate::gpu::record_full_barrier(self.ctx, cmd);
            let ip = InitParams {
                width: width as u32,
                height: height as u32,
                seed_lo: seed as u32,
                seed_hi: (seed >> 32) as u32,
            };
            init.record(cmd, bytemuck::bytes_of(&ip), groups(width, height));
            recorded = recorder.record(cmd, width, height, table.nodes, table.luma_range);
        })?;
        recorded?;
        let bytes = self.ctx.download(recorder.field())?;
        let texels: &[[f32; GRAIN_TEXEL_FLOATS]] = bytemuck::cast_slice(&bytes[..GRAIN_TEXEL_FLOATS * n * 4]);
        Ok(planar_rgb(texels))
    }
}

/// Which grain pipeline a recorded step uses.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Step {
    Reduce,
    Top,
    Synth,
}

/// The grain synthesis recorded into a frame's command buffer (no submissions, no
/// host round trips), on buffers allocated once for the largest field
/// (`max_w × max_h`) with every descriptor set bound once at creation; per-frame
/// sizes go in push constants. Input: `level0()` (`w × h` vec4s: unit white noise
/// R, G, B and luma, filled by the caller's pass before `record`); output: `field()`
/// (`w × h` vec4s: R, G, B, 0).
pub struct GrainRecorder<'a> {
    reduce: ComputePipeline<'a>,
    top: ComputePipeline<'a>,
    synth: ComputePipeline<'a>,
    /// Synthesis weights ([node][channel][band]); written by the caller (a copy
    /// from the frame's host-visible table) before `record`.
    pub table: Buffer<'a>,
    /// Joint Gaussian pyramid (noise + luma), levels 0..=L.
    joint: Vec<Buffer<'a>>,
    /// Row-reduced intermediates, levels 0..L.
    rows: Vec<Buffer<'a>>,
    /// Collapse C_l, levels 0..=L (C_0 is the field).
    collapse: Vec<Buffer<'a>>,
    max: (usize, usize),
}

impl<'a> GrainRecorder<'a> {
    pub fn new(ctx: &'a GpuContext, max_w: usize, max_h: usize, table_nodes: u32) -> Result<Self, GpuError> {
        let (max_w, max_h) = (max_w.max(1), max_h.max(1));
        let sizes = level_sizes(max_w, max_h);
        let bytes = |floats: usize| (floats * 4) as u64;
        let mut joint = Vec::new();
        let mut rows = Vec::new();
        let mut collapse = Vec::new();
        for (l, &(w, h)) in sizes.iter().enumerate() {
            joint.push(ctx.storage_buffer(bytes(GRAIN_TEXEL_FLOATS * w * h), &format!("grain joint pyramid {l}"))?);
            collapse.push(ctx.storage_buffer(bytes(GRAIN_TEXEL_FLOATS * w * h), &format!("grain collapse {l}"))?);
            if l < NOISE_LEVELS {
                let w_next = sizes[l + 1].0;
                rows.push(ctx.storage_buffer(bytes(GRAIN_TEXEL_FLOATS * w_next * h), &format!("grain rows {l}"))?);
            }
        }
        let levels = NOISE_LEVELS as u32;
        let me = Self {
            reduce: ComputePipeline::with_layout(ctx, REDUCE, &vk_storage(2), 20, 2 * levels, "grain reduce")?,
            top: ComputePipeline::with_layout(ctx, TOP, &vk_storage(3), 24, 1, "grain top")?,
            synth: ComputePipeline::with_layout(ctx, SYNTH, &vk_storage(5), 32, levels, "grain synth")?,
            table: ctx.storage_buffer((table_nodes.max(2) as usize * 3 * BANDS * 4) as u64, "grain table")?,
            joint,
            rows,
            collapse,
            max: (max_w, max_h),
        };
        // Bind every step's set once (same walk as `record`, binding instead of
        // recording).
        let mut err = Ok(());
        me.walk(max_w, max_h, |step, set, bufs, _, _| {
            if err.is_ok() {
                err = me.pipeline(step).bind_set(set, bufs);
            }
        });
        err?;
        Ok(me)
    }

    fn pipeline(&self, step: Step) -> &ComputePipeline<'a> {
        match step {
            Step::Reduce => &self.reduce,
            Step::Top => &self.top,
            Step::Synth => &self.synth,
        }
    }

    /// Level 0 of the joint pyramid (`w × h` vec4s: noise R, G, B, luma),
    /// for the caller's pass that fills it.
    pub fn level0(&self) -> &Buffer<'a> {
        &self.joint[0]
    }

    /// The output field (`w × h` vec4s R, G, B, 0 of the last `record`).
    pub fn field(&self) -> &Buffer<'a> {
        &self.collapse[0]
    }

    /// Every step in order: (pipeline, set index, buffers, push, groups): the joint
    /// pyramid (reduce rows then columns, per level), the coarsest level's scale,
    /// then the fused band/scale/collapse per level, coarse to fine, into `C_0`.
    fn walk(&self, w: usize, h: usize, mut emit: impl FnMut(Step, usize, &[&Buffer<'_>], Vec<u8>, [u32; 3])) {
        let sizes = level_sizes(w, h);
        let mut next = [0usize; 3];
        let mut go = |step: Step, bufs: &[&Buffer<'_>], push: Vec<u8>, g: [u32; 3]| {
            let k = step as usize;
            emit(step, next[k], bufs, push, g);
            next[k] += 1;
        };
        let pyr = |in_w: usize, in_h: usize, out_w: usize, out_h: usize, axis: u32| {
            bytemuck::bytes_of(&PyrParams {
                in_w: in_w as u32,
                in_h: in_h as u32,
                out_w: out_w as u32,
                out_h: out_h as u32,
                axis,
            })
            .to_vec()
        };
        for l in 0..NOISE_LEVELS {
            let ((w0, h0), (w1, h1)) = (sizes[l], sizes[l + 1]);
            go(Step::Reduce, &[&self.joint[l], &self.rows[l]], pyr(w0, h0, w1, h0, 0), groups(w1, h0));
            go(Step::Reduce, &[&self.rows[l], &self.joint[l + 1]], pyr(w1, h0, w1, h1, 1), groups(w1, h1));
        }
        let (tw, th) = sizes[NOISE_LEVELS];
        // nodes/lo/hi are patched per frame in `record`.
        let tp =
            TopParams { width: tw as u32, height: th as u32, level: NOISE_LEVELS as u32, nodes: 0, lo: 0.0, hi: 0.0 };
        go(
            Step::Top,
            &[&self.joint[NOISE_LEVELS], &self.table, &self.collapse[NOISE_LEVELS]],
            bytemuck::bytes_of(&tp).to_vec(),
            groups(tw, th),
        );
        for l in (0..NOISE_LEVELS).rev() {
            let ((w0, h0), (w1, h1)) = (sizes[l], sizes[l + 1]);
            let sp = SynthParams {
                w0: w0 as u32,
                h0: h0 as u32,
                w1: w1 as u32,
                h1: h1 as u32,
                level: l as u32,
                nodes: 0,
                lo: 0.0,
                hi: 0.0,
            };
            go(
                Step::Synth,
                &[&self.joint[l], &self.joint[l + 1], &self.collapse[l + 1], &self.table, &self.collapse[l]],
                bytemuck::bytes_of(&sp).to_vec(),
                groups(w0.div_ceil(2), h0.div_ceil(2)), // one invocation per 2×2 output quad
            );
        }
    }

    /// Record the synthesis of a `w × h` field (≤ the creation maximum; `level0()`
    /// already filled) with the table's `nodes` over luma range `[lo, hi]`.
    pub fn record(
        &self,
        cmd: ash::vk::CommandBuffer,
        w: usize,
        h: usize,
        nodes: u32,
        luma_range: [f32; 2],
    ) -> Result<(), GpuError> {
        if w == 0 || h == 0 || w > self.max.0 || h > self.max.1 || nodes < 2 {
            return Err(GpuError::Input {
                input: "grain field",
                problem: format!("{w}×{h} with {nodes} nodes (max {}×{}, ≥ 2 nodes)", self.max.0, self.max.1),
            });
        }
        let patch = |push: &mut [u8], at: usize| {
            push[at..at + 4].copy_from_slice(&nodes.to_le_bytes());
            push[at + 4..at + 8].copy_from_slice(&luma_range[0].to_le_bytes());
            push[at + 8..at + 12].copy_from_slice(&luma_range[1].to_le_bytes());
        };
        self.walk(w, h, |step, set, _, mut push, g| {
            match step {
                Step::Top => patch(&mut push, std::mem::offset_of!(TopParams, nodes)),
                Step::Synth => patch(&mut push, std::mem::offset_of!(SynthParams, nodes)),
                Step::Reduce => {}
            }
            self.pipeline(step).record_set(cmd, set, &push, g);
        });
        Ok(())
    }
}

fn vk_storage(n: usize) -> Vec<ash::vk::DescriptorType> {
    vec![ash::vk::DescriptorType::STORAGE_BUFFER; n]
}

/// Pyramid level sizes, finest first (`image::reduce` halves rounding up).
fn level_sizes(w: usize, h: usize) -> Vec<(usize, usize)> {
    let mut sizes = vec![(w, h)];
    for _ in 0..NOISE_LEVELS {
        let &(a, b) = sizes.last().unwrap_or(&(w, h));
        sizes.push((a.div_ceil(2), b.div_ceil(2)));
    }
    sizes
}

/// Planar R, G, B planes (the CPU's `Rgb` layout) from the field's vec4 texels.
pub fn planar_rgb(texels: &[[f32; GRAIN_TEXEL_FLOATS]]) -> Vec<f32> {
    (0..3).flat_map(|c| texels.iter().map(move |t| t[c])).collect()
}
