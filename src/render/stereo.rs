//! The stereo renderer: per frame, takes one camera-model snapshot, writes its
//! parameters into the frame slot's uniform buffer, records the G-buffer pass and
//! the effect chain into the slot's command buffer, and submits without waiting
//! (2 frames in flight). On desktop the target is an offscreen RGBA8 image pair over
//! a background image pair; on the headset it is the swapchain image array.

use super::gbuffer::{clip_from_view, Eye, GBufferFrame, GBufferPass, FAR_M, NEAR_M};
use super::layer::{FrameEffects, LayerEffects, LayerSettings};
use super::params::EffectParams;
use crate::gpu::{Buffer, FrameRing, GpuContext, GpuError, Image, EYES};
use crate::scene::Scene;
use crate::synth::layer::Rect;
use crate::synth::SynthesisTable;
use crate::worker::Snapshot;
use ash::vk;
use glam::Vec3;

pub const FRAMES_IN_FLIGHT: usize = 2;

/// One frame's content: the G-buffer inputs and the world-space corners of the
/// virtual content's bounds now and one render frame ago (for the work rectangles).
pub struct FrameInput<'f> {
    pub gbuffer: &'f GBufferFrame,
    pub corners_now: &'f [Vec3],
    pub corners_prev: &'f [Vec3],
}

pub struct StereoRenderer<'a> {
    ctx: &'a GpuContext,
    // Drop order: the chain (borrows nothing but the context, but binds the images
    // below) first, then the G-buffer, then the images it binds.
    effects: LayerEffects<'a>,
    gbuffer: GBufferPass<'a>,
    pub background: Image<'a>,
    pub output: Image<'a>,
    ring: FrameRing<'a>,
    tables: Vec<Buffer<'a>>,
    table_cache: Option<(u64, SynthesisTable)>,
    settings: LayerSettings,
    eye_pixels_per_radian: Option<f32>,
    frame: u32,
    pub last_effects: Option<FrameEffects>,
}

impl<'a> StereoRenderer<'a> {
    pub fn new(
        ctx: &'a GpuContext,
        scene: &Scene,
        width: u32,
        height: u32,
        settings: LayerSettings,
        eye_pixels_per_radian: Option<f32>,
    ) -> Result<Self, GpuError> {
        let gbuffer = GBufferPass::new(ctx, scene, width, height, FRAMES_IN_FLIGHT)?;
        let usage = vk::ImageUsageFlags::STORAGE;
        let background = Image::new(
            ctx,
            width,
            height,
            EYES,
            vk::Format::R8G8B8A8_UNORM,
            usage,
            vk::ImageLayout::GENERAL,
            "background",
        )?;
        let output = Image::new(
            ctx,
            width,
            height,
            EYES,
            vk::Format::R8G8B8A8_UNORM,
            usage,
            vk::ImageLayout::GENERAL,
            "output",
        )?;
        let nodes = crate::synth::SynthesisTable::node_count() as u32;
        let effects =
            LayerEffects::new(ctx, gbuffer.colour(), gbuffer.motion(), &background, &output, settings, nodes)?;
        let ring = FrameRing::new(ctx, FRAMES_IN_FLIGHT, std::mem::size_of::<EffectParams>() as u64)?;
        let mut tables = Vec::new();
        for i in 0..FRAMES_IN_FLIGHT {
            tables.push(Buffer::new(
                ctx,
                (nodes as usize * 3 * (crate::model::NOISE_LEVELS + 1) * 4) as u64,
                vk::BufferUsageFlags::TRANSFER_SRC,
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                &format!("grain table {i}"),
            )?);
        }
        Ok(Self {
            ctx,
            effects,
            gbuffer,
            background,
            output,
            ring,
            tables,
            table_cache: None,
            settings,
            eye_pixels_per_radian,
            frame: 0,
            last_effects: None,
        })
    }

    pub fn size(&self) -> (u32, u32) {
        (self.gbuffer.target.width, self.gbuffer.target.height)
    }

    pub fn gbuffer(&self) -> &GBufferPass<'a> {
        &self.gbuffer
    }

    pub fn effects(&self) -> &LayerEffects<'a> {
        &self.effects
    }

    /// Per-eye pixel rectangle holding the projected `corners` (now and previous),
    /// dilated by `margin`; the whole eye when a corner is behind the near plane.
    pub fn rects(&self, eyes: &[Eye; 2], prev: &[Eye; 2], now: &[Vec3], before: &[Vec3], margin: i32) -> [Rect; 2] {
        let (w, h) = self.size();
        std::array::from_fn(|e| {
            let (mut x0, mut y0, mut x1, mut y1) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
            for (eye, pts) in [(&eyes[e], now), (&prev[e], before)] {
                let m = clip_from_view(eye.focal_px, eye.centre_px, w, h, NEAR_M, FAR_M) * eye.view_from_world;
                for p in pts {
                    let c = m * p.extend(1.0);
                    if !c.is_finite() || c.w <= NEAR_M {
                        return Rect::full(w as usize, h as usize);
                    }
                    let (px, py) = ((c.x / c.w + 1.0) * 0.5 * w as f32, (c.y / c.w + 1.0) * 0.5 * h as f32);
                    x0 = x0.min(px);
                    y0 = y0.min(py);
                    x1 = x1.max(px);
                    y1 = y1.max(py);
                }
            }
            if x0 > x1 {
                return Rect::default();
            }
            let bx0 = (x0.floor() as i64 - margin as i64).clamp(0, w as i64) as i32;
            let by0 = (y0.floor() as i64 - margin as i64).clamp(0, h as i64) as i32;
            let bx1 = (x1.ceil() as i64 + margin as i64).clamp(0, w as i64) as i32;
            let by1 = (y1.ceil() as i64 + margin as i64).clamp(0, h as i64) as i32;
            Rect { x: bx0, y: by0, w: (bx1 - bx0).max(0), h: (by1 - by0).max(0) }
        })
    }

    /// Replace both eyes' background with RGBA8 texels (`w × h × 2`, eye-major).
    pub fn set_background(&self, rgba: &[u8]) -> Result<(), GpuError> {
        self.ring.wait_all()?;
        self.background.upload(rgba)
    }

    /// Render one frame with `snapshot`'s effects (`matched`) or none (naive), and
    /// submit it. Returns the effects used.
    pub fn render(
        &mut self,
        snapshot: &Snapshot,
        input: &FrameInput<'_>,
        matched: bool,
    ) -> Result<FrameEffects, GpuError> {
        let model = &snapshot.model;
        let mut fx = FrameEffects::from_model(model, self.eye_pixels_per_radian, &self.settings);
        if !matched {
            fx.dof = false;
            fx.motion_blur = false;
            fx.noise = false;
        }
        fx.frame = self.frame;
        self.frame = self.frame.wrapping_add(1);
        let g = input.gbuffer;
        fx.rects =
            self.rects(&g.eyes, &g.prev_eyes, input.corners_now, input.corners_prev, fx.margin_px(&self.settings));
        // The grain table depends on the noise model only: rebuilt when the
        // snapshot changes (a ~ms CPU job; the worker could precompute it).
        if fx.noise && self.table_cache.as_ref().map(|c| c.0) != Some(snapshot.generation) {
            self.table_cache = Some((snapshot.generation, SynthesisTable::new(&model.noise)));
        }
        let (slot, cmd) = self.ring.begin()?;
        // The slot's previous frame is complete (begin waited): its buffers may be rewritten.
        let params = EffectParams::from_model(model, snapshot.generation as u32);
        self.ring.slot(slot).uniform.write(bytemuck::bytes_of(&params))?;
        let table = match (&self.table_cache, fx.noise) {
            (Some((_, t)), true) => {
                let flat = t.weights_flat();
                self.tables[slot].write(bytemuck::cast_slice(&flat))?;
                Some((&self.tables[slot], t.nodes() as u32, t.luma_range()))
            }
            _ => None,
        };
        let recorded = self
            .gbuffer
            .record(cmd, slot, g)
            .and_then(|_| self.effects.record(cmd, &self.ring.slot(slot).uniform, &fx, table));
        // Submit even after a recording error so the slot's fence is signalled again.
        let submitted = self.ring.submit(slot);
        recorded?;
        submitted?;
        self.last_effects = Some(fx);
        Ok(fx)
    }

    /// Wait for all frames in flight.
    pub fn finish(&self) -> Result<(), GpuError> {
        self.ring.wait_all()
    }

    /// Both eyes' composite (RGBA8, eye-major) after waiting for the GPU.
    pub fn read_output(&self) -> Result<Vec<u8>, GpuError> {
        self.finish()?;
        self.output.download()
    }

    pub fn context(&self) -> &'a GpuContext {
        self.ctx
    }
}
