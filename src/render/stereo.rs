//! The stereo renderer: per frame, takes one camera-model snapshot, writes its
//! parameters into the frame slot's uniform buffer, records the G-buffer pass and
//! the effect chain into the slot's command buffer, and submits without waiting
//! (2 frames in flight). On desktop the target is an offscreen RGBA8 image pair over
//! a background image pair; on the headset it is the swapchain image array.

use super::gbuffer::{clip_from_view, Eye, GBufferFrame, GBufferPass, FAR_M, NEAR_M};
use super::layer::{FrameEffects, LayerEffects, LayerSettings};
use super::params::EffectParams;
use super::spacewarp::{SpaceWarpPass, SpaceWarpTarget};
use crate::gpu::{Buffer, FrameRing, GpuContext, GpuError, Image, QueryPool, Statistics, EYES};
use crate::model::{covering_rect, Rect, GRAIN_TABLE_NODES};
use crate::scene::Scene;
use crate::worker::Snapshot;
use ash::vk;
use glam::Vec3;

pub const FRAMES_IN_FLIGHT: usize = 2;

/// Which of the matched effects a frame may apply: all for a matched frame, none
/// for a naive one, or any mix (the headset's per-effect toggles). An effect the
/// camera model lacks stays off whatever this says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Enabled {
    pub noise: bool,
    pub motion_blur: bool,
    pub dof: bool,
}

impl Enabled {
    /// Every effect (`true`) or none (`false`).
    pub fn matched(on: bool) -> Self {
        Self { noise: on, motion_blur: on, dof: on }
    }
}

/// An image outside the renderer that receives each frame's composite (the
/// OpenXR swapchain image array: same size, two layers, RGBA8), and the layout it
/// is kept in.
#[derive(Clone, Copy, Debug)]
pub struct ExternalTarget {
    pub image: vk::Image,
    pub layout: vk::ImageLayout,
}

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
    /// XR_FB_space_warp's conversion (binds the G-buffer's motion image).
    space_warp: Option<SpaceWarpPass<'a>>,
    gbuffer: GBufferPass<'a>,
    pub background: Image<'a>,
    pub output: Image<'a>,
    ring: FrameRing<'a>,
    tables: Vec<Buffer<'a>>,
    settings: LayerSettings,
    eye_pixels_per_radian: Option<f32>,
    frame: u32,
    pub last_effects: Option<FrameEffects>,
    /// Where the last frame's G-buffer pass wrote (see `render`); stale outside.
    gbuffer_area: Rect,
    profile: Option<Profile<'a>>,
}

impl Drop for StereoRenderer<'_> {
    fn drop(&mut self) {
        // Frames may still be in flight (an error returned mid-loop): wait for them
        // before the fields below free the images and buffers they use (the
        // fields drop after this body; VUID-vkDestroyImage-image-01000).
        let _ = self.ring.wait_all();
    }
}

/// Per-frame GPU profile (benchmarks): timestamps per stage and pipeline
/// statistics for the G-buffer pass (query 0) and the effect chain (query 1).
struct Profile<'a> {
    stamps: QueryPool<'a>,
    stats: Option<QueryPool<'a>>,
}

/// What one profiled frame cost on the GPU.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameProfile {
    pub gbuffer_ms: f64,
    pub dof_ms: f64,
    pub mb_ms: f64,
    pub grain_ms: f64,
    pub composite_ms: f64,
    pub gbuffer_stats: Statistics,
    pub effects_stats: Statistics,
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
        let rgba8 = |name: &str| {
            let usage = vk::ImageUsageFlags::STORAGE;
            Image::new(ctx, width, height, EYES, vk::Format::R8G8B8A8_UNORM, usage, vk::ImageLayout::GENERAL, name)
        };
        let background = rgba8("background")?;
        let output = rgba8("output")?;
        let nodes = GRAIN_TABLE_NODES as u32;
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
            space_warp: None,
            gbuffer,
            background,
            output,
            ring,
            tables,
            settings,
            eye_pixels_per_radian,
            frame: 0,
            last_effects: None,
            gbuffer_area: Rect::default(),
            profile: None,
        })
    }

    /// Turn per-frame GPU profiling on (timestamps; pipeline statistics where the
    /// device has them). Each `render` then waits for its frame; read the result
    /// with `last_profile`.
    pub fn enable_profiling(&mut self) -> Result<(), GpuError> {
        let stamps = QueryPool::timestamps(self.ctx, super::layer::STAMPS)?;
        let stats = if self.ctx.has_pipeline_statistics() { Some(QueryPool::statistics(self.ctx, 2)?) } else { None };
        self.profile = Some(Profile { stamps, stats });
        Ok(())
    }

    /// The profile of the last rendered frame (waits for it).
    pub fn last_profile(&self) -> Result<Option<FrameProfile>, GpuError> {
        let Some(p) = &self.profile else { return Ok(None) };
        self.finish()?;
        let t = p.stamps.timestamps_ms()?;
        let stats = match &p.stats {
            Some(s) => s.statistics_results()?,
            None => vec![Statistics::default(); 2],
        };
        use super::layer::*;
        let d = |a: u32, b: u32| t[b as usize] - t[a as usize];
        Ok(Some(FrameProfile {
            gbuffer_ms: d(STAMP_START, STAMP_GBUFFER),
            dof_ms: d(STAMP_GBUFFER, STAMP_DOF),
            mb_ms: d(STAMP_DOF, STAMP_MB),
            grain_ms: d(STAMP_MB, STAMP_GRAIN),
            composite_ms: d(STAMP_GRAIN, STAMP_COMPOSITE),
            gbuffer_stats: stats[0],
            effects_stats: stats[1],
        }))
    }

    pub fn size(&self) -> (u32, u32) {
        (self.gbuffer.target.width, self.gbuffer.target.height)
    }

    pub fn gbuffer(&self) -> &GBufferPass<'a> {
        &self.gbuffer
    }

    /// The rectangle (both eyes) the last frame's G-buffer pass wrote; texels
    /// outside it are left from earlier frames (or undefined) and mean nothing.
    pub fn gbuffer_area(&self) -> Rect {
        self.gbuffer_area
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

    /// View depth range (m, the clip w) of the content's `corners`, both eyes, now
    /// and one frame before: every point of the content lies within its bounding
    /// box, and depth is affine, so the corners bound it. None when a corner is
    /// behind the near plane or not finite.
    pub fn content_depth_m(&self, eyes: &[Eye; 2], prev: &[Eye; 2], now: &[Vec3], before: &[Vec3]) -> Option<[f32; 2]> {
        let (w, h) = self.size();
        let (mut near, mut far) = (f32::MAX, f32::MIN);
        for e in 0..2 {
            for (eye, pts) in [(&eyes[e], now), (&prev[e], before)] {
                let m = clip_from_view(eye.focal_px, eye.centre_px, w, h, NEAR_M, FAR_M) * eye.view_from_world;
                for p in pts {
                    let z = (m * p.extend(1.0)).w;
                    if !z.is_finite() || z <= NEAR_M {
                        return None;
                    }
                    near = near.min(z);
                    far = far.max(z);
                }
            }
        }
        (near <= far).then_some([near, far])
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
        self.render_to(snapshot, input, Enabled::matched(matched), None, None)
    }

    /// The render frame interval (s) motion vectors are measured over: the
    /// predicted display period under OpenXR, which changes with the refresh rate
    /// and with space-warp throttling.
    /// The eyes' focal length (px per radian at the centre): what the model's
    /// pixel-sized effects are scaled by. The XR loop sets it from each frame's
    /// views (the field of view is known only once views are located).
    pub fn set_eye_pixels_per_radian(&mut self, px_per_rad: f32) {
        self.eye_pixels_per_radian = Some(px_per_rad).filter(|v| v.is_finite() && *v > 0.0);
    }

    pub fn set_render_interval_s(&mut self, interval_s: f32) {
        if interval_s.is_finite() && interval_s > 0.0 {
            self.settings.render_interval_s = interval_s;
        }
    }

    /// Produce XR_FB_space_warp's motion vectors and depth (`width × height` per
    /// eye) with every frame from now on (see `render_to`).
    pub fn enable_space_warp(&mut self, width: u32, height: u32) -> Result<(), GpuError> {
        self.ring.wait_all()?;
        self.space_warp = Some(SpaceWarpPass::new(self.ctx, self.gbuffer.motion(), width, height)?);
        Ok(())
    }

    /// As `render`, then copy the composite into `target` and, when space warp is
    /// enabled and `space_warp` given, the frame's motion vectors and depth into
    /// its images, in the same submission.
    pub fn render_to(
        &mut self,
        snapshot: &Snapshot,
        input: &FrameInput<'_>,
        enabled: Enabled,
        target: Option<ExternalTarget>,
        space_warp: Option<SpaceWarpTarget>,
    ) -> Result<FrameEffects, GpuError> {
        let model = &snapshot.model;
        let g = input.gbuffer;
        let depth = self.content_depth_m(&g.eyes, &g.prev_eyes, input.corners_now, input.corners_prev);
        let mut fx = FrameEffects::from_model(model, self.eye_pixels_per_radian, depth, &self.settings);
        fx.dof &= enabled.dof;
        fx.motion_blur &= enabled.motion_blur;
        fx.noise &= enabled.noise;
        // The lens's falloff is about the passthrough camera's optical axis, which
        // lands on each eye's principal point (the view's asymmetric frustum).
        fx.eye_centres_px = Some([g.eyes[0].centre_px, g.eyes[1].centre_px]);
        fx.frame = self.frame;
        self.frame = self.frame.wrapping_add(1);
        fx.rects =
            self.rects(&g.eyes, &g.prev_eyes, input.corners_now, input.corners_prev, fx.margin_px(&self.settings));
        if self.profile.is_some() {
            // A profiled frame must not overlap the previous one's queries (waited
            // before `begin`, which unsignals the new slot's fence).
            self.ring.wait_all()?;
        }
        let (slot, cmd) = self.ring.begin()?;
        // The slot's previous frame is complete (begin waited): its buffers may be rewritten.
        let params = EffectParams::from_model(model, snapshot.generation as u32);
        self.ring.slot(slot).uniform.write(bytemuck::bytes_of(&params))?;
        // The snapshot's grain table (computed when it was published).
        let table = match (&snapshot.grain, fx.noise) {
            (Some(t), true) if t.nodes as usize == GRAIN_TABLE_NODES => {
                self.tables[slot].write(bytemuck::cast_slice(&t.weights))?;
                Some((&self.tables[slot], t.nodes, t.luma_range))
            }
            _ => None,
        };
        if let Some(p) = &self.profile {
            p.stamps.record_reset(cmd);
            if let Some(s) = &p.stats {
                s.record_reset(cmd);
            }
            crate::gpu::record_full_barrier(self.ctx, cmd);
            p.stamps.record_timestamp(cmd, vk::PipelineStageFlags::TOP_OF_PIPE, super::layer::STAMP_START);
        }
        let stats = self.profile.as_ref().and_then(|p| p.stats.as_ref());
        let stamps = self.profile.as_ref().map(|p| &p.stamps);
        if let Some(s) = stats {
            s.record_begin(cmd, 0);
        }
        // The G-buffer pass is confined to the rectangle covering both eyes' work
        // rectangles (one render area per multiview pass), widened to whole MB
        // tiles and 2×2 DoF blocks: every texel the effects read is written this
        // frame, and the clear and raster cost follow the content's screen area.
        // Outside it the G-buffer is stale; the composite treats it as empty.
        let tile = self.settings.mb_tile_px.max(1);
        let (w, h) = self.size();
        let area = covering_rect(&fx.rects, if tile % 2 == 0 { tile } else { 2 * tile }, w as usize, h as usize);
        self.gbuffer_area = area;
        let recorded = self.gbuffer.record_in(cmd, slot, g, area);
        if let Some(s) = stats {
            s.record_end(cmd, 0);
        }
        if let Some(q) = stamps {
            q.record_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, super::layer::STAMP_GBUFFER);
        }
        if let Some(s) = stats {
            s.record_begin(cmd, 1);
        }
        let recorded =
            recorded.and_then(|_| self.effects.record_profiled(cmd, &self.ring.slot(slot).uniform, &fx, table, stamps));
        if let Some(s) = stats {
            s.record_end(cmd, 1);
        }
        if let (Ok(()), Some(t)) = (&recorded, target) {
            self.output.record_copy_to_external(cmd, t.image, t.layout);
        }
        if let (Ok(()), Some(pass)) = (&recorded, &self.space_warp) {
            match space_warp {
                Some(t) => pass.record_to(cmd, area, &t),
                None => pass.record(cmd, area),
            }
        }
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
