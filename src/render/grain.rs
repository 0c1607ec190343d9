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

pub use crate::model::GrainTable;

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
        let luma_buf = self.ctx.upload(bytemuck::cast_slice(luma), "grain luma")?;
        let table_buf = self.ctx.upload(bytemuck::cast_slice(&table.weights), "grain table")?;
        // Transfers apart from the timed dispatches (`dispatch_and_wait` times only
        // the synthesis).
        self.ctx.submit_and_wait(|cmd| {
            self.ctx.record_copy(cmd, &luma_buf, &recorder.luma, luma_buf.size);
            self.ctx.record_copy(cmd, &table_buf, &recorder.table, table_buf.size);
        })?;
        let mut recorded = Ok(());
        self.ctx.dispatch_and_wait(|cmd| {
            // The copies above (an earlier submission) become visible to the shaders.
            crate::gpu::record_full_barrier(self.ctx, cmd);
            recorded = recorder.record(cmd, width, height, table.nodes, table.luma_range, seed);
        })?;
        recorded?;
        let bytes = self.ctx.download(recorder.field())?;
        Ok(bytemuck::cast_slice(&bytes[..3 * n * 4]).to_vec())
    }
}

/// Which grain pipeline a recorded step uses.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Step {
    Reduce,
    Expand,
    Combine,
    Init,
    Scale,
}

/// The grain synthesis recorded into a frame's command buffer (no submissions, no
/// host round trips): the same pipelines and arithmetic as `GrainPass::run`, on
/// buffers allocated once for the largest field (`max_w × max_h`) with every
/// descriptor set bound once at creation; per-frame sizes go in push constants.
/// Input: `luma` (`w × h`, filled by the caller's pass); output: `field` (planar RGB).
pub struct GrainRecorder<'a> {
    reduce: ComputePipeline<'a>,
    expand: ComputePipeline<'a>,
    combine: ComputePipeline<'a>,
    init: ComputePipeline<'a>,
    scale: ComputePipeline<'a>,
    pub luma: Buffer<'a>,
    /// Synthesis weights ([node][channel][band]); written by the caller (a copy
    /// from the frame's host-visible table) before `record`.
    pub table: Buffer<'a>,
    buffers: Vec<Buffer<'a>>,
    max: (usize, usize),
}

/// Buffer roles in `GrainRecorder::buffers`, per level.
const fn slot(kind: usize, level: usize) -> usize {
    kind * (NOISE_LEVELS + 1) + level
}
const LUMA: usize = 0; // luma pyramid (level 0 = the input `luma`, stored apart)
const GAUSS: usize = 1; // noise Gaussian pyramid (level 0 = white noise)
const BAND: usize = 2;
const RTMP_L: usize = 3;
const RTMP_N: usize = 4;
const ETMP: usize = 5;
const UP: usize = 6;
const CTMP: usize = 7;
const CUP: usize = 8;
const CUR: usize = 9;
const KINDS: usize = 10;

impl<'a> GrainRecorder<'a> {
    pub fn new(ctx: &'a GpuContext, max_w: usize, max_h: usize, table_nodes: u32) -> Result<Self, GpuError> {
        let (max_w, max_h) = (max_w.max(1), max_h.max(1));
        let sizes = level_sizes(max_w, max_h);
        let mut buffers = Vec::new();
        for kind in 0..KINDS {
            for l in 0..=NOISE_LEVELS {
                let (w, h) = sizes[l];
                let (_, h_next) = sizes[(l + 1).min(NOISE_LEVELS)];
                let (w_next, _) = sizes[(l + 1).min(NOISE_LEVELS)];
                let floats = match kind {
                    LUMA => w * h,
                    RTMP_L => w_next * h,
                    RTMP_N => 3 * w_next * h,
                    ETMP | CTMP => 3 * w * h_next.max(h),
                    _ => 3 * w * h,
                };
                buffers.push(ctx.storage_buffer((floats * 4) as u64, &format!("grain buffer {kind}/{l}"))?);
            }
        }
        let sets = |n: u32| n;
        let sb = vk_storage;
        let me = Self {
            reduce: ComputePipeline::with_layout(
                ctx,
                REDUCE,
                &sb(2),
                24,
                sets(4 * NOISE_LEVELS as u32),
                "grain reduce",
            )?,
            expand: ComputePipeline::with_layout(
                ctx,
                EXPAND,
                &sb(2),
                24,
                sets(4 * NOISE_LEVELS as u32),
                "grain expand",
            )?,
            combine: ComputePipeline::with_layout(
                ctx,
                COMBINE,
                &sb(3),
                8,
                sets(2 * NOISE_LEVELS as u32),
                "grain combine",
            )?,
            init: ComputePipeline::with_layout(ctx, INIT, &sb(1), 16, 1, "grain init")?,
            scale: ComputePipeline::with_layout(ctx, SCALE, &sb(3), 24, sets(NOISE_LEVELS as u32 + 1), "grain scale")?,
            luma: ctx.storage_buffer((max_w * max_h * 4) as u64, "grain luma")?,
            table: ctx.storage_buffer((table_nodes.max(2) as usize * 3 * BANDS * 4) as u64, "grain table")?,
            buffers,
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
            Step::Expand => &self.expand,
            Step::Combine => &self.combine,
            Step::Init => &self.init,
            Step::Scale => &self.scale,
        }
    }

    fn buf(&self, kind: usize, level: usize) -> &Buffer<'a> {
        if kind == LUMA && level == 0 {
            &self.luma
        } else {
            &self.buffers[slot(kind, level)]
        }
    }

    /// The output field (planar RGB, `w × h` of the last `record`).
    pub fn field(&self) -> &Buffer<'a> {
        self.buf(CUR, 0)
    }

    /// Every step in order: (pipeline, set index, buffers, push, groups), the
    /// dispatch sequence of `GrainPass::run` (luma pyramid, white noise, its
    /// Laplacian pyramid, band scaling, collapse into `CUR[0]`).
    fn walk(&self, w: usize, h: usize, mut emit: impl FnMut(Step, usize, &[&Buffer<'_>], Vec<u8>, [u32; 3])) {
        let sizes = level_sizes(w, h);
        let mut next = [0usize; 5];
        let mut go = |step: Step, bufs: &[&Buffer<'_>], push: Vec<u8>, g: [u32; 3]| {
            let k = step as usize;
            emit(step, next[k], bufs, push, g);
            next[k] += 1;
        };
        let pyr = |in_w: usize, in_h: usize, out_w: usize, out_h: usize, channels: u32, axis: u32| {
            bytemuck::bytes_of(&PyrParams {
                in_w: in_w as u32,
                in_h: in_h as u32,
                out_w: out_w as u32,
                out_h: out_h as u32,
                channels,
                axis,
            })
            .to_vec()
        };
        for l in 0..NOISE_LEVELS {
            let ((w0, h0), (w1, h1)) = (sizes[l], sizes[l + 1]);
            go(Step::Reduce, &[self.buf(LUMA, l), self.buf(RTMP_L, l)], pyr(w0, h0, w1, h0, 1, 0), groups(w1, h0));
            go(Step::Reduce, &[self.buf(RTMP_L, l), self.buf(LUMA, l + 1)], pyr(w1, h0, w1, h1, 1, 1), groups(w1, h1));
        }
        let init = InitParams { width: w as u32, height: h as u32, seed_lo: 0, seed_hi: 0 };
        go(Step::Init, &[self.buf(GAUSS, 0)], bytemuck::bytes_of(&init).to_vec(), groups(w, h));
        for l in 0..NOISE_LEVELS {
            let ((w0, h0), (w1, h1)) = (sizes[l], sizes[l + 1]);
            go(Step::Reduce, &[self.buf(GAUSS, l), self.buf(RTMP_N, l)], pyr(w0, h0, w1, h0, 3, 0), groups(w1, h0));
            go(Step::Reduce, &[self.buf(RTMP_N, l), self.buf(GAUSS, l + 1)], pyr(w1, h0, w1, h1, 3, 1), groups(w1, h1));
            go(Step::Expand, &[self.buf(GAUSS, l + 1), self.buf(ETMP, l)], pyr(w1, h1, w0, h1, 3, 0), groups(w0, h1));
            go(Step::Expand, &[self.buf(ETMP, l), self.buf(UP, l)], pyr(w0, h1, w0, h0, 3, 1), groups(w0, h0));
            let cp = CombineParams { count: (3 * w0 * h0) as u32, subtract: 1 };
            go(
                Step::Combine,
                &[self.buf(GAUSS, l), self.buf(UP, l), self.buf(BAND, l)],
                bytemuck::bytes_of(&cp).to_vec(),
                [(3 * w0 * h0).div_ceil(64) as u32, 1, 1],
            );
        }
        for l in 0..=NOISE_LEVELS {
            let (lw, lh) = sizes[l];
            let band = if l < NOISE_LEVELS { self.buf(BAND, l) } else { self.buf(GAUSS, NOISE_LEVELS) };
            // lo/hi/nodes are patched per frame in `record` (push bytes 12..24).
            let sp = ScaleParams { width: lw as u32, height: lh as u32, level: l as u32, nodes: 0, lo: 0.0, hi: 0.0 };
            go(Step::Scale, &[band, self.buf(LUMA, l), &self.table], bytemuck::bytes_of(&sp).to_vec(), groups(lw, lh));
        }
        for l in (0..NOISE_LEVELS).rev() {
            let ((w0, h0), (w1, h1)) = (sizes[l], sizes[l + 1]);
            let src = if l + 1 == NOISE_LEVELS { self.buf(GAUSS, NOISE_LEVELS) } else { self.buf(CUR, l + 1) };
            go(Step::Expand, &[src, self.buf(CTMP, l)], pyr(w1, h1, w0, h1, 3, 0), groups(w0, h1));
            go(Step::Expand, &[self.buf(CTMP, l), self.buf(CUP, l)], pyr(w0, h1, w0, h0, 3, 1), groups(w0, h0));
            let cp = CombineParams { count: (3 * w0 * h0) as u32, subtract: 0 };
            go(
                Step::Combine,
                &[self.buf(CUP, l), self.buf(BAND, l), self.buf(CUR, l)],
                bytemuck::bytes_of(&cp).to_vec(),
                [(3 * w0 * h0).div_ceil(64) as u32, 1, 1],
            );
        }
    }

    /// Record the synthesis of a `w × h` field (≤ the creation maximum) with the
    /// table's `nodes` over luma range `[lo, hi]` and a per-frame `seed`.
    pub fn record(
        &self,
        cmd: ash::vk::CommandBuffer,
        w: usize,
        h: usize,
        nodes: u32,
        luma_range: [f32; 2],
        seed: u64,
    ) -> Result<(), GpuError> {
        if w == 0 || h == 0 || w > self.max.0 || h > self.max.1 || nodes < 2 {
            return Err(GpuError::Input {
                input: "grain field",
                problem: format!("{w}×{h} with {nodes} nodes (max {}×{}, ≥ 2 nodes)", self.max.0, self.max.1),
            });
        }
        self.walk(w, h, |step, set, _, mut push, g| {
            match step {
                Step::Init => {
                    push[8..12].copy_from_slice(&(seed as u32).to_le_bytes());
                    push[12..16].copy_from_slice(&((seed >> 32) as u32).to_le_bytes());
                }
                Step::Scale => {
                    push[12..16].copy_from_slice(&nodes.to_le_bytes());
                    push[16..20].copy_from_slice(&luma_range[0].to_le_bytes());
                    push[20..24].copy_from_slice(&luma_range[1].to_le_bytes());
                }
                _ => {}
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
