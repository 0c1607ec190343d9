//! The production effect chain on the virtual layer, recorded into one frame's
//! command buffer after the G-buffer pass: DoF (separable scatter, `layer_dof_h/v`,
//! or the 2-D disc scatter `layer_dof_disc` when the model's kernel is a disc)
//! → MB (McGuire 2012 tile-max / neighbour-max reconstruction, `layer_mb_*`) →
//! the ISP's sharpening (an unsharp mask, `layer_sharpen`, two separable passes) →
//! grain (the paper's Laplacian synthesis at the content's luma, `GrainRecorder`)
//! → composite over the background with the blurred alpha (`composite.comp`).
//! CPU twins: `synth::layer`.
//!
//! Work is bounded by per-eye screen rectangles (the projected bounds of the virtual
//! content, dilated by the blur reach): every dispatch covers the rectangles only,
//! so effect cost follows the content's screen area, not the eye buffer. Effects
//! absent in the camera model are not dispatched at all. Within the rectangles the
//! DoF taps follow the σ actually present: each 8×8 workgroup of the scatter passes
//! stops its loop at 4σ of the largest source within reach (`layer_dof_reach`),
//! beyond which every tap is exactly zero.

use super::grain::GrainRecorder;
use super::params::EffectParams;
pub use super::sharpen::Sharpen;
use super::sharpen::SharpenPush;
use crate::gpu::{Buffer, ComputePipeline, GpuContext, GpuError, Image, QueryPool, Resource, EYES};
use crate::model::{half_rect, tile_rect, EyeChromatic, EyeGain, EyeVignette, Rect};
use crate::model::{CameraModel, DepthUnits, MAX_DOF_SIGMA_PX};
use ash::vk;
use bytemuck::{Pod, Zeroable};

const DOF_SIGMA: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_dof_sigma.spv"));
const DOF_DOWN: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_dof_down.spv"));
const DOF_UP: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_dof_up.spv"));
const DOF_H: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_dof_h.spv"));
const DOF_V: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_dof_v.spv"));
const DOF_DISC: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_dof_disc.spv"));
const DOF_REACH: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_dof_reach.spv"));
const MB_TILES: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_mb_tiles.spv"));
const MB_NEIGHBOUR: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_mb_neighbour.spv"));
const MB_GATHER: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_mb_gather.spv"));
const LUMA: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_luma.spv"));
const COMPOSITE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/composite.spv"));
const SHARPEN: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layer_sharpen.spv"));

/// Timestamp slots of a profiled frame: frame start, G-buffer done, then each stage.
pub const STAMP_START: u32 = 0;
pub const STAMP_GBUFFER: u32 = 1;
pub const STAMP_DOF: u32 = 2;
pub const STAMP_MB: u32 = 3;
pub const STAMP_GRAIN: u32 = 4;
pub const STAMP_COMPOSITE: u32 = 5;
pub const STAMPS: u32 = 6;

/// Largest DoF gather radius in eye pixels (σ ≤ radius / 3 is spread fully).
pub const MAX_DOF_RADIUS_PX: i32 = 48;

/// Push constants shared by the DoF and MB passes (`Push` in their shaders).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LayerPush {
    pub rect: [[i32; 4]; 2],
    pub size: [i32; 2],
    pub radius: i32,
    pub step: i32,
    pub ppr_ratio: f32,
    pub exposure_ratio: f32,
    pub frame: u32,
    pub samples: u32,
    /// MB taps per pixel of the neighbourhood's full streak (0: always `samples`).
    pub taps_per_px: f32,
}
const _: () = assert!(std::mem::size_of::<LayerPush>() == 68);
const _: () = assert!(std::mem::offset_of!(LayerPush, taps_per_px) == 64);
const _: () = assert!(std::mem::offset_of!(LayerPush, size) == 32);
const _: () = assert!(std::mem::offset_of!(LayerPush, ppr_ratio) == 48);

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct LumaPush {
    rect: [[i32; 4]; 2],
    width: i32,
    row1: i32,
    /// Source: 0 raw colour, 1 DoF output, 2 MB output.
    use_fx: i32,
    /// Packed height (eye 0's rows + eye 1's).
    height: i32,
    seed: [u32; 2],
    pad: [u32; 2],
    /// xyz: the camera's colour gains (`FrameEffects::colour_gain`); w: 1 to apply.
    gain: [f32; 4],
    /// xyz: the lens's log-falloff terms (`FrameEffects::vignette`); w: 1 / the
    /// camera's half-diagonal in eye pixels, 0 = no vignetting.
    vignette: [f32; 4],
    /// The eyes' principal points (px): xy eye 0, zw eye 1.
    centre: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<LumaPush>() == 112);
const _: () = assert!(std::mem::offset_of!(LumaPush, vignette) == 80);
const _: () = assert!(std::mem::offset_of!(LumaPush, seed) == 48);
const _: () = assert!(std::mem::offset_of!(LumaPush, gain) == 64);

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct CompositePush {
    rect: [[i32; 4]; 2],
    size: [i32; 2],
    use_fx: i32,
    use_noise: i32,
    noise_width: i32,
    row1: i32,
    straight_alpha: i32,
    pad: i32,
    /// As `LumaPush::gain`, `vignette` and `centre`.
    gain: [f32; 4],
    vignette: [f32; 4],
    centre: [f32; 4],
    /// Lateral aberration (`FrameEffects::chromatic`): xy 1/s − 1 of red and blue;
    /// z: 1 / the camera's half-diagonal in eye pixels; w: 1 to apply.
    chroma: [f32; 4],
}
// 128 B: Vulkan's guaranteed maxPushConstantsSize.
const _: () = assert!(std::mem::size_of::<CompositePush>() == 128);
const _: () = assert!(std::mem::offset_of!(CompositePush, chroma) == 112);
const _: () = assert!(std::mem::offset_of!(CompositePush, vignette) == 80);
const _: () = assert!(std::mem::offset_of!(CompositePush, straight_alpha) == 56);
const _: () = assert!(std::mem::offset_of!(CompositePush, gain) == 64);

/// Quality settings: the speed/accuracy knobs measured in BENCHMARKS.md.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayerSettings {
    /// DoF tap spacing in px: 1 = every pixel, 2 = every other (¼ of the taps in 2-D).
    pub dof_step_px: i32,
    /// DoF at half resolution (2×2 down, scatter with σ/2, bilinear up): ≈ 8× fewer
    /// taps, sharp content softened.
    pub dof_half_res: bool,
    /// Most MB taps per pixel (McGuire's S).
    pub mb_samples: u32,
    /// MB taps per pixel of streak length: a pixel takes
    /// clamp(⌈2·|neighbourhood half-streak|·this⌉, 2, `mb_samples`) taps, so short
    /// streaks (slow heads) stop paying for the longest one's taps. 0 (default) =
    /// always `mb_samples`.
    pub mb_taps_per_px: f32,
    /// MB tile size K (px): also the longest half-streak reconstructed.
    pub mb_tile_px: i32,
    /// Display frame interval: motion vectors are per render frame.
    pub render_interval_s: f32,
    /// Synthesise grain (the paper's pyramid; off = no noise even if present).
    pub grain: bool,
    /// Apply the camera's white balance and exposure (`model::Colour`; off = the
    /// authored colours even where the model has them).
    pub colour: bool,
    /// Apply the lens's vignetting (`model::Vignetting`; off = none even where the
    /// model has it).
    pub vignetting: bool,
    /// Apply the lens's lateral chromatic aberration (`model::ChromaticAberration`;
    /// off = none even where the model has it).
    pub chromatic_aberration: bool,
    /// Apply the ISP's sharpening (`model::Sharpening`; off = none even where the
    /// model has it).
    pub sharpening: bool,
    /// Store the composite with straight (unpremultiplied) alpha: the colour divided
    /// by the output alpha. The headset's projection layer uses it with
    /// XR_COMPOSITION_LAYER_UNPREMULTIPLIED_ALPHA_BIT, so the compositor, which
    /// decodes an sRGB swapchain to linear light before blending, gets α·decode(c)
    /// at a blurred edge. Off (premultiplied): the desktop's own composites.
    pub straight_alpha: bool,
}

impl Default for LayerSettings {
    fn default() -> Self {
        Self {
            // Chosen from BENCHMARKS.md's settings table: half resolution costs ⅙ of
            // full resolution at p99 1.5 8-bit steps from the exact scatter.
            dof_step_px: 1,
            dof_half_res: true,
            // Fixed 12 MB taps: the streak-proportional rule (1 or 2 taps per px) is
            // cheaper but measurably noisier (BENCHMARKS.md settings table).
            mb_samples: 12,
            mb_taps_per_px: 0.0,
            mb_tile_px: 16,
            render_interval_s: 1.0 / 45.0,
            grain: true,
            colour: true,
            vignetting: true,
            chromatic_aberration: true,
            sharpening: true,
            straight_alpha: false,
        }
    }
}

/// What one frame's effect chain does, derived from a model snapshot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameEffects {
    pub dof: bool,
    /// The model's DoF kernel is a disc: one 2-D scatter (`layer_dof_disc`) instead
    /// of the Gaussian's h/v pair.
    pub dof_disc: bool,
    pub motion_blur: bool,
    pub noise: bool,
    /// The camera's per-channel colour gain (linear light) where the model has one
    /// and the settings apply it; `None`: the authored colours, at no cost.
    pub colour_gain: Option<[f32; 3]>,
    /// The lens's falloff where the model has it and the settings apply it: its
    /// log terms and 1 / the camera's half-diagonal in eye pixels. `None`: no cost.
    pub vignette: Option<([f32; 3], f32)>,
    /// The lens's lateral aberration where the model has it and the settings apply
    /// it: [1/s_R − 1, 1/s_B − 1] and 1 / the camera's half-diagonal in eye pixels.
    /// `None`: no cost.
    pub chromatic: Option<([f32; 2], f32)>,
    /// The ISP's unsharp mask where the model has it and the settings apply it (its
    /// σ scaled to eye pixels). `None`: no cost.
    pub sharpening: Option<Sharpen>,
    /// Each eye's principal point in its buffer (px), where the passthrough
    /// camera's optical axis lands: `gbuffer::Eye::centre_px` (the XR view's
    /// asymmetric frustum; `StereoRenderer::render_to` sets it). `None`: the
    /// buffer's centre (the desktop, whose background is the camera frame).
    pub eye_centres_px: Option<[[f32; 2]; 2]>,
    /// Eye-buffer / camera `pixels_per_radian`.
    pub ppr_ratio: f32,
    /// Exposure time over the render frame interval (λ · camera interval / render
    /// interval): motion per render frame × this = the streak.
    pub exposure_ratio: f32,
    pub dof_radius_px: i32,
    pub rects: [Rect; 2],
    pub frame: u32,
}

impl FrameEffects {
    /// Effects of `model` for eye buffers with `eye_pixels_per_radian`. The ratio
    /// falls back to 1 when the model does not know its camera's (desktop: the
    /// background is the eye's view). `content_depth_m`: the view depths the
    /// virtual content spans this frame (near, far); the DoF reach is the largest
    /// blur over that span instead of over the model's whole fitted range — only what
    /// the scene requires (a model fitted down to 0.3 m would otherwise make every
    /// frame pay the reach of a 0.3 m blur). Rects start empty (see `dilate_rects`).
    pub fn from_model(
        model: &CameraModel,
        eye_pixels_per_radian: Option<f32>,
        content_depth_m: Option<[f32; 2]>,
        settings: &LayerSettings,
    ) -> Self {
        let ppr_ratio = match (eye_pixels_per_radian, model.reference.pixels_per_radian) {
            (Some(e), Some(c)) if e.is_finite() && c.is_finite() && e > 0.0 && c > 0.0 => e / c,
            _ => 1.0,
        };
        let dof_model = &model.depth_of_field;
        let dof = dof_model.present && dof_model.curve.is_some() && dof_model.units == DepthUnits::MetricM;
        if dof_model.present && dof_model.units != DepthUnits::MetricM {
            log::warn!("DoF model is in relative inverse depth: no metric scale for virtual depths, DoF skipped");
        }
        let step = settings.dof_step_px.clamp(1, 4);
        let dof_radius_px = if dof {
            let [mut lo, mut hi] = dof_model.depth_range;
            if let Some([near, far]) = content_depth_m {
                if near.is_finite() && far.is_finite() && near <= far {
                    // `sigma_px` clamps depths to the fitted range, so content
                    // outside it takes the range's end blur, as the shader does.
                    (lo, hi) = (near, far);
                }
            }
            let sigma_max = (0..=64)
                .map(|i| dof_model.sigma_px(lo + (hi - lo) * i as f32 / 64.0))
                .fold(0.0f32, f32::max)
                .min(MAX_DOF_SIGMA_PX)
                * ppr_ratio;
            let r = ((3.0 * sigma_max).ceil() as i32).clamp(step, MAX_DOF_RADIUS_PX);
            (r + step - 1) / step * step
        } else {
            0
        };
        let lambda = model.motion_blur.exposure_or_zero();
        let exposure_ratio = match model.reference.frame_interval_s {
            Some(t) if t > 0.0 && settings.render_interval_s > 0.0 => lambda * t / settings.render_interval_s,
            _ => 0.0,
        };
        // The camera's half-diagonal (px) in eye pixels: the ratio of the two pixels
        // per radian.
        let inv_half_diag_eye_px =
            1.0 / (0.5 * (model.reference.width as f32).hypot(model.reference.height as f32) * ppr_ratio);
        let inv_half_diag_eye_px = Some(inv_half_diag_eye_px).filter(|v| v.is_finite() && *v > 0.0);
        if lambda > 0.0 && exposure_ratio == 0.0 {
            log::warn!("motion blur present but the camera frame interval is unknown: MB skipped");
        }
        Self {
            dof: dof && dof_radius_px > 0,
            dof_disc: dof_model.kernel == crate::model::DofKernel::Disc,
            motion_blur: exposure_ratio > 0.0 && exposure_ratio.is_finite(),
            noise: model.noise.present && settings.grain,
            // Validated models hold gains in [1/64, 64]; identity gains are skipped.
            colour_gain: (model.colour.present && settings.colour)
                .then(|| model.colour.gains_or_one())
                .filter(|g| g.iter().all(|v| v.is_finite() && *v > 0.0) && *g != [1.0; 3]),
            vignette: model.vignetting.applied().filter(|_| settings.vignetting).zip(inv_half_diag_eye_px),
            // Validated scales are within 1 ± 0.01; a scale of exactly 1 costs nothing.
            chromatic: model
                .chromatic_aberration
                .applied()
                .filter(|_| settings.chromatic_aberration)
                .map(|d| d.map(|v| 1.0 / (1.0 + v) - 1.0))
                .filter(|d| d.iter().all(|v| v.is_finite()) && *d != [0.0; 2])
                .zip(inv_half_diag_eye_px),
            // σ is in the camera's pixels: the eye buffer's are `ppr_ratio` of them.
            sharpening: model
                .sharpening
                .applied()
                .filter(|_| settings.sharpening)
                .and_then(|(k, sigma)| Sharpen::new(k, sigma * ppr_ratio)),
            eye_centres_px: None,
            ppr_ratio,
            exposure_ratio: if exposure_ratio.is_finite() { exposure_ratio } else { 0.0 },
            dof_radius_px,
            rects: [Rect::default(); 2],
            frame: 0,
        }
    }

    /// The per-pixel gain of eye `eye` in a `width × height` buffer (the composite's
    /// colour times vignetting; `synth::layer::composite`'s argument).
    pub fn eye_gain(&self, eye: usize, width: u32, height: u32) -> EyeGain {
        let centres = self.eye_centres_px.unwrap_or([[width as f32 * 0.5, height as f32 * 0.5]; 2]);
        EyeGain {
            colour: self.colour_gain,
            vignette: self.vignette.map(|(log_falloff, inv_half_diag_px)| EyeVignette {
                log_falloff,
                centre_px: centres[eye.min(1)],
                inv_half_diag_px,
            }),
            chromatic: self.chromatic.map(|(inv_scale_minus_one, inv_half_diag_px)| EyeChromatic {
                inv_scale_minus_one,
                centre_px: centres[eye.min(1)],
                inv_half_diag_px,
            }),
        }
    }

    /// How far effects reach beyond the content's bounds (px).
    pub fn margin_px(&self, settings: &LayerSettings) -> i32 {
        let mut m = 1;
        if self.dof {
            m += self.dof_radius_px;
        }
        if self.motion_blur {
            m += settings.mb_tile_px;
        }
        // Red and blue land up to |1/s − 1| · the camera's half-diagonal (eye px)
        // from where green does: the fringe must stay inside the rectangles.
        if let Some((d, inv)) = self.chromatic {
            let shift = d[0].abs().max(d[1].abs()) / inv;
            m += (shift.ceil() as i32).clamp(0, MAX_CHROMATIC_MARGIN_PX);
        }
        // The mask's halo spreads as far as its blur reaches.
        if let Some(sh) = self.sharpening {
            m += sh.radius_px;
        }
        m
    }
}

/// Most the aberration widens the rectangles (px): 0.01 (the validated bound) of a
/// Quest-class eye buffer's half-diagonal is ~15 px.
const MAX_CHROMATIC_MARGIN_PX: i32 = 32;

/// Eye `eye`'s principal point (px) as the composite applies it.
fn self_centre(fx: &FrameEffects, eye: usize, width: u32, height: u32) -> [f32; 2] {
    let g = fx.eye_gain(eye, width, height);
    g.vignette.map(|v| v.centre_px).or(g.chromatic.map(|c| c.centre_px)).unwrap_or([0.0; 2])
}

pub struct LayerEffects<'a> {
    ctx: &'a GpuContext,
    width: u32,
    height: u32,
    settings: LayerSettings,
    dof_h: ComputePipeline<'a>,
    dof_v: ComputePipeline<'a>,
    dof_disc: ComputePipeline<'a>,
    mb_tiles: ComputePipeline<'a>,
    mb_neighbour: ComputePipeline<'a>,
    mb_gather: ComputePipeline<'a>,
    luma: ComputePipeline<'a>,
    composite: ComputePipeline<'a>,
    sharpen: ComputePipeline<'a>,
    grain: GrainRecorder<'a>,
    dof_sigma: ComputePipeline<'a>,
    dof_reach: ComputePipeline<'a>,
    dof_down: ComputePipeline<'a>,
    dof_up: ComputePipeline<'a>,
    /// The frame's parameters, copied from the slot's uniform buffer at the start
    /// of the chain (one fixed binding for every pass; queue order + barrier keep
    /// the previous frame's reads before the copy).
    params: Buffer<'a>,
    pub dof_tmp: Image<'a>,
    sigma_tmp: Image<'a>,
    sigma_full: Image<'a>,
    /// Per 8×8 block of the scatter passes' grid: largest σ in it, then (reach)
    /// the largest within the pass radius — the per-workgroup tap-loop bound.
    dof_tile_sigma: Image<'a>,
    dof_reach_sigma: Image<'a>,
    colour_half: Image<'a>,
    sigma_half: Image<'a>,
    dof_half: Image<'a>,
    pub dof_out: Image<'a>,
    tiles: Image<'a>,
    neighbour: Image<'a>,
    pub mb_out: Image<'a>,
}

fn storage_image<'c>(
    ctx: &'c GpuContext,
    w: u32,
    h: u32,
    format: vk::Format,
    name: &str,
) -> Result<Image<'c>, GpuError> {
    Image::new(ctx, w, h, EYES, format, vk::ImageUsageFlags::STORAGE, vk::ImageLayout::GENERAL, name)
}

fn groups(w: i32, h: i32) -> [u32; 3] {
    [(w.max(0) as u32).div_ceil(8), (h.max(0) as u32).div_ceil(8), EYES]
}

impl<'a> LayerEffects<'a> {
    /// Build the chain for G-buffer images `colour`/`motion`, compositing over
    /// `background` (RGBA8, 2 layers) into `output` (RGBA8 storage, 2 layers).
    /// `grain_nodes`: size of the synthesis tables that will be used.
    pub fn new(
        ctx: &'a GpuContext,
        colour: &Image<'a>,
        motion: &Image<'a>,
        background: &Image<'a>,
        output: &Image<'a>,
        settings: LayerSettings,
        grain_nodes: u32,
    ) -> Result<Self, GpuError> {
        let (w, h) = (colour.width, colour.height);
        for (name, img) in [("motion", motion), ("background", background), ("output", output)] {
            if img.width != w || img.height != h || img.layers != EYES {
                return Err(GpuError::Input {
                    input: "layer images",
                    problem: format!("{name} is {}×{}×{}, colour is {w}×{h}×{EYES}", img.width, img.height, img.layers),
                });
            }
        }
        if settings.mb_tile_px < 4
            || settings.mb_samples == 0
            || !(1..=4).contains(&settings.dof_step_px)
            || !(settings.mb_taps_per_px >= 0.0 && settings.mb_taps_per_px <= 64.0)
        {
            return Err(GpuError::Input {
                input: "layer settings",
                problem: format!("{settings:?}: tile ≥ 4 px, ≥ 1 MB sample, 0–64 MB taps per px, DoF step 1–4"),
            });
        }
        let f16 = vk::Format::R16G16B16A16_SFLOAT;
        let (tw, th) = (w.div_ceil(settings.mb_tile_px as u32), h.div_ceil(settings.mb_tile_px as u32));
        let st = vk::DescriptorType::STORAGE_IMAGE;
        let sb = vk::DescriptorType::STORAGE_BUFFER;
        let ub = vk::DescriptorType::UNIFORM_BUFFER;
        let push = std::mem::size_of::<LayerPush>() as u32;
        let me = Self {
            ctx,
            width: w,
            height: h,
            settings,
            // Set 0: full resolution, set 1: half resolution.
            dof_h: ComputePipeline::with_layout(ctx, DOF_H, &[st, st, st, st, st], push, 2, "layer dof h")?,
            dof_v: ComputePipeline::with_layout(ctx, DOF_V, &[st, st, st, st], push, 2, "layer dof v")?,
            dof_disc: ComputePipeline::with_layout(ctx, DOF_DISC, &[st, st, st, st], push, 2, "layer dof disc")?,
            dof_sigma: ComputePipeline::with_layout(ctx, DOF_SIGMA, &[ub, st, st, st], push, 1, "layer dof sigma")?,
            dof_reach: ComputePipeline::with_layout(ctx, DOF_REACH, &[st, st], push, 1, "layer dof reach")?,
            dof_down: ComputePipeline::with_layout(
                ctx,
                DOF_DOWN,
                &[ub, st, st, st, st, st],
                push,
                1,
                "layer dof down",
            )?,
            dof_up: ComputePipeline::with_layout(ctx, DOF_UP, &[st, st], push, 1, "layer dof up")?,
            mb_tiles: ComputePipeline::with_layout(ctx, MB_TILES, &[st, st], push, 1, "layer mb tiles")?,
            mb_neighbour: ComputePipeline::with_layout(ctx, MB_NEIGHBOUR, &[st, st], push, 1, "layer mb neighbour")?,
            mb_gather: ComputePipeline::with_layout(ctx, MB_GATHER, &[st, st, st, st, st], push, 1, "layer mb gather")?,
            luma: ComputePipeline::with_layout(
                ctx,
                LUMA,
                &[st, st, st, sb],
                size_of::<LumaPush>() as u32,
                1,
                "layer luma",
            )?,
            composite: ComputePipeline::with_layout(
                ctx,
                COMPOSITE,
                &[st, st, st, st, sb, st],
                size_of::<CompositePush>() as u32,
                1,
                "composite",
            )?,
            sharpen: ComputePipeline::with_layout(
                ctx,
                SHARPEN,
                &[st, st, st, st],
                size_of::<SharpenPush>() as u32,
                1,
                "layer sharpen",
            )?,
            // Both eyes' rectangles stacked: at most the full eye, twice as tall.
            grain: GrainRecorder::new(ctx, w as usize, 2 * h as usize, grain_nodes)?,
            params: crate::gpu::Buffer::new(
                ctx,
                std::mem::size_of::<EffectParams>() as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
                vk::MemoryPropertyFlags::DEVICE_LOCAL,
                "layer effect params",
            )?,
            dof_tmp: storage_image(ctx, w, h, f16, "dof horizontal")?,
            sigma_tmp: storage_image(ctx, w, h, vk::Format::R32_SFLOAT, "dof sigma")?,
            sigma_full: storage_image(ctx, w, h, vk::Format::R32_SFLOAT, "dof source sigma")?,
            dof_tile_sigma: storage_image(ctx, w.div_ceil(8), h.div_ceil(8), vk::Format::R32_SFLOAT, "dof tile sigma")?,
            dof_reach_sigma: storage_image(ctx, w.div_ceil(8), h.div_ceil(8), vk::Format::R32_SFLOAT, "dof reach")?,
            colour_half: storage_image(ctx, w.div_ceil(2), h.div_ceil(2), f16, "dof half colour")?,
            sigma_half: storage_image(ctx, w.div_ceil(2), h.div_ceil(2), vk::Format::R32_SFLOAT, "dof half sigma")?,
            dof_half: storage_image(ctx, w.div_ceil(2), h.div_ceil(2), f16, "dof half out")?,
            dof_out: storage_image(ctx, w, h, f16, "dof out")?,
            tiles: storage_image(ctx, tw, th, f16, "mb tile max")?,
            neighbour: storage_image(ctx, tw, th, f16, "mb neighbour max")?,
            mb_out: storage_image(ctx, w, h, f16, "mb out")?,
        };
        use Resource::{Buffer as B, Image as I};
        me.dof_sigma.bind_resources(0, &[B(&me.params), I(motion), I(&me.sigma_full), I(&me.dof_tile_sigma)])?;
        me.dof_reach.bind_resources(0, &[I(&me.dof_tile_sigma), I(&me.dof_reach_sigma)])?;
        me.dof_h.bind_resources(
            0,
            &[I(colour), I(&me.sigma_full), I(&me.dof_tmp), I(&me.sigma_tmp), I(&me.dof_reach_sigma)],
        )?;
        me.dof_v.bind_resources(0, &[I(&me.dof_tmp), I(&me.sigma_tmp), I(&me.dof_out), I(&me.dof_reach_sigma)])?;
        me.dof_disc.bind_resources(0, &[I(colour), I(&me.sigma_full), I(&me.dof_out), I(&me.dof_reach_sigma)])?;
        me.dof_down.bind_resources(
            0,
            &[B(&me.params), I(colour), I(motion), I(&me.colour_half), I(&me.sigma_half), I(&me.dof_tile_sigma)],
        )?;
        me.dof_h.bind_resources(
            1,
            &[I(&me.colour_half), I(&me.sigma_half), I(&me.dof_tmp), I(&me.sigma_tmp), I(&me.dof_reach_sigma)],
        )?;
        me.dof_v.bind_resources(1, &[I(&me.dof_tmp), I(&me.sigma_tmp), I(&me.dof_half), I(&me.dof_reach_sigma)])?;
        me.dof_disc
            .bind_resources(1, &[I(&me.colour_half), I(&me.sigma_half), I(&me.dof_half), I(&me.dof_reach_sigma)])?;
        me.dof_up.bind_resources(0, &[I(&me.dof_half), I(&me.dof_out)])?;
        me.mb_tiles.bind_resources(0, &[I(motion), I(&me.tiles)])?;
        me.mb_neighbour.bind_resources(0, &[I(&me.tiles), I(&me.neighbour)])?;
        me.mb_gather.bind_resources(0, &[I(colour), I(&me.dof_out), I(motion), I(&me.neighbour), I(&me.mb_out)])?;
        me.luma.bind_resources(0, &[I(colour), I(&me.dof_out), I(&me.mb_out), B(me.grain.level0())])?;
        // The DoF's horizontal buffer is free once the chain is past DoF: the
        // mask's horizontal blur goes there.
        me.sharpen.bind_resources(0, &[I(colour), I(&me.dof_out), I(&me.mb_out), I(&me.dof_tmp)])?;
        me.composite.bind_resources(
            0,
            &[I(colour), I(&me.dof_out), I(&me.mb_out), I(background), B(me.grain.field()), I(output)],
        )?;
        Ok(me)
    }

    /// The last recorded grain field (vec4 R, G, B, 0 per pixel, eyes stacked as in
    /// `layer_luma`; `grain::planar_rgb` converts).
    pub fn grain_field(&self) -> &Buffer<'a> {
        self.grain.field()
    }

    pub fn settings(&self) -> &LayerSettings {
        &self.settings
    }

    /// Record the chain. `params`: the frame slot's uniform (EffectParams of the
    /// snapshot in use); `grain_table`: host-visible synthesis weights for the
    /// same snapshot (`nodes` × 3 × 5 floats) with its luma range.
    pub fn record(
        &self,
        cmd: vk::CommandBuffer,
        params: &Buffer<'_>,
        fx: &FrameEffects,
        grain_table: Option<(&Buffer<'_>, u32, [f32; 2])>,
    ) -> Result<(), GpuError> {
        self.record_profiled(cmd, params, fx, grain_table, None)
    }

    /// `record`, writing timestamps into `profile` (when given) after each stage:
    /// [`STAMP_DOF`], [`STAMP_MB`], [`STAMP_GRAIN`] and [`STAMP_COMPOSITE`]
    /// (skipped stages repeat the previous stamp, so their time reads as zero).
    pub fn record_profiled(
        &self,
        cmd: vk::CommandBuffer,
        params: &Buffer<'_>,
        fx: &FrameEffects,
        grain_table: Option<(&Buffer<'_>, u32, [f32; 2])>,
        profile: Option<&QueryPool<'_>>,
    ) -> Result<(), GpuError> {
        let stamp = |i: u32| {
            if let Some(q) = profile {
                q.record_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, i);
            }
        };
        let full = Rect::full(self.width as usize, self.height as usize);
        let clip = |r: Rect| {
            let x0 = r.x.clamp(0, full.w);
            let y0 = r.y.clamp(0, full.h);
            let x1 = (r.x + r.w).clamp(0, full.w);
            let y1 = (r.y + r.h).clamp(0, full.h);
            Rect { x: x0, y: y0, w: x1 - x0, h: y1 - y0 }
        };
        let rects = [clip(fx.rects[0]), clip(fx.rects[1])];
        let any = rects.iter().any(|r| r.area() > 0);
        let to4 = |r: Rect| [r.x, r.y, r.w, r.h];
        // Previous commands (last frame's effect reads, the G-buffer pass) complete
        // before this frame's copies and writes: one barrier at the chain's start.
        crate::gpu::record_full_barrier(self.ctx, cmd);
        self.ctx.record_copy(cmd, params, &self.params, std::mem::size_of::<EffectParams>() as u64);
        let noise_table = match (fx.noise && any, grain_table) {
            (true, Some((table, nodes, range))) => {
                self.ctx.record_copy(cmd, table, &self.grain.table, self.grain.table.size);
                Some((nodes, range))
            }
            _ => None,
        };
        crate::gpu::record_full_barrier(self.ctx, cmd);
        let mut push = LayerPush {
            rect: [to4(rects[0]), to4(rects[1])],
            size: [self.width as i32, self.height as i32],
            radius: fx.dof_radius_px,
            step: self.settings.dof_step_px,
            ppr_ratio: fx.ppr_ratio,
            exposure_ratio: fx.exposure_ratio,
            frame: fx.frame,
            samples: self.settings.mb_samples,
            taps_per_px: self.settings.mb_taps_per_px,
        };
        let gw = rects[0].w.max(rects[1].w);
        let gh = rects[0].h.max(rects[1].h);
        let mut source = 0; // 0: G-buffer colour, 1: DoF output, 2: MB output
        if any && fx.dof {
            if self.settings.dof_half_res {
                // σ per pixel is computed inside the down step (no full-res σ image).
                let step = self.settings.dof_step_px;
                let hr = rects.map(half_rect);
                let mut hp = push;
                hp.rect = [to4(hr[0]), to4(hr[1])];
                hp.radius = ((fx.dof_radius_px + 1) / 2 + step - 1) / step * step;
                let (hgw, hgh) = (hr[0].w.max(hr[1].w), hr[0].h.max(hr[1].h));
                self.dof_down.record(cmd, bytemuck::bytes_of(&push), groups(hgw, hgh));
                // One invocation per 8×8 block of the scatter grid.
                self.dof_reach.record(cmd, bytemuck::bytes_of(&hp), groups((hgw + 7) / 8, (hgh + 7) / 8));
                if fx.dof_disc {
                    self.dof_disc.record_set(cmd, 1, bytemuck::bytes_of(&hp), groups(hgw, hgh));
                } else {
                    self.dof_h.record_set(cmd, 1, bytemuck::bytes_of(&hp), groups(hgw, hgh));
                    self.dof_v.record_set(cmd, 1, bytemuck::bytes_of(&hp), groups(hgw, hgh));
                }
                self.dof_up.record(cmd, bytemuck::bytes_of(&push), groups(gw, gh));
            } else {
                self.dof_sigma.record(cmd, bytemuck::bytes_of(&push), groups(gw, gh));
                self.dof_reach.record(cmd, bytemuck::bytes_of(&push), groups((gw + 7) / 8, (gh + 7) / 8));
                if fx.dof_disc {
                    self.dof_disc.record(cmd, bytemuck::bytes_of(&push), groups(gw, gh));
                } else {
                    self.dof_h.record(cmd, bytemuck::bytes_of(&push), groups(gw, gh));
                    self.dof_v.record(cmd, bytemuck::bytes_of(&push), groups(gw, gh));
                }
            }
            source = 1;
        }
        stamp(STAMP_DOF);
        if any && fx.motion_blur {
            let k = self.settings.mb_tile_px;
            let trs = rects.map(|r| tile_rect(r, k, self.width as usize, self.height as usize));
            let mut tp = push;
            tp.rect = [to4(trs[0]), to4(trs[1])];
            tp.radius = k;
            let (tgw, tgh) = (trs[0].w.max(trs[1].w), trs[0].h.max(trs[1].h));
            self.mb_tiles.record(cmd, bytemuck::bytes_of(&tp), groups(tgw, tgh));
            tp.size = [(self.width as i32 + k - 1) / k, (self.height as i32 + k - 1) / k];
            self.mb_neighbour.record(cmd, bytemuck::bytes_of(&tp), groups(tgw, tgh));
            push.radius = k;
            push.step = (source == 1) as i32;
            self.mb_gather.record(cmd, bytemuck::bytes_of(&push), groups(gw, gh));
            source = 2;
        }
        if let (true, Some(sh)) = (any, fx.sharpening) {
            let mut w = [[0.0f32; 4]; 4];
            for (i, v) in sh.taps.iter().enumerate() {
                w[i / 4][i % 4] = *v;
            }
            let mut sp = SharpenPush {
                rect: [to4(rects[0]), to4(rects[1])],
                size: [self.width as i32, self.height as i32],
                source,
                pass: 0,
                radius: sh.radius_px,
                amount: sh.amount,
                pad: [0; 2],
                w,
            };
            self.sharpen.record(cmd, bytemuck::bytes_of(&sp), groups(gw, gh));
            sp.pass = 1;
            self.sharpen.record(cmd, bytemuck::bytes_of(&sp), groups(gw, gh));
            // Raw colour is never written: the masked layer is in the DoF output.
            source = source.max(1);
        }
        stamp(STAMP_MB);
        let gain4 = fx.colour_gain.map_or([1.0, 1.0, 1.0, 0.0], |g| [g[0], g[1], g[2], 1.0]);
        let vignette4 = fx.vignette.map_or([0.0; 4], |(a, inv)| [a[0], a[1], a[2], inv]);
        let [c0, c1] = [0, 1].map(|e| self_centre(fx, e, self.width, self.height));
        let centre4 = [c0[0], c0[1], c1[0], c1[1]];
        let mut cp = CompositePush {
            rect: [to4(rects[0]), to4(rects[1])],
            size: [self.width as i32, self.height as i32],
            use_fx: source,
            straight_alpha: self.settings.straight_alpha as i32,
            gain: gain4,
            vignette: vignette4,
            centre: centre4,
            chroma: fx.chromatic.map_or([0.0; 4], |(d, inv)| [d[0], d[1], inv, 1.0]),
            ..Default::default()
        };
        if let Some((nodes, range)) = noise_table {
            let nw = gw.max(1);
            let nh = (rects[0].h + rects[1].h).max(1);
            let seed = (fx.frame as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x5eed;
            // Luma of the chain's output (0: raw colour, 1: DoF, 2: MB) and the
            // frame's white noise: level 0 of the grain's joint pyramid.
            let lp = LumaPush {
                rect: [to4(rects[0]), to4(rects[1])],
                width: nw,
                row1: rects[0].h,
                use_fx: source,
                height: nh,
                seed: [seed as u32, (seed >> 32) as u32],
                pad: [0; 2],
                gain: gain4,
                vignette: vignette4,
                centre: centre4,
            };
            self.luma.record(
                cmd,
                bytemuck::bytes_of(&lp),
                [(nw as u32).div_ceil(8), (rects[0].h.max(rects[1].h) as u32).div_ceil(8), EYES],
            );
            self.grain.record(cmd, nw as usize, nh as usize, nodes, range)?;
            cp.use_noise = 1;
            cp.noise_width = nw;
            cp.row1 = rects[0].h;
        }
        stamp(STAMP_GRAIN);
        self.composite.record(cmd, bytemuck::bytes_of(&cp), groups(self.width as i32, self.height as i32));
        stamp(STAMP_COMPOSITE);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Diagnostics, DofCurve};

    fn thin_lens() -> CameraModel {
        let mut m = CameraModel::empty(1280, 960);
        m.depth_of_field = crate::model::DepthOfField {
            present: true,
            units: DepthUnits::MetricM,
            curve: Some(DofCurve::ThinLens { k: 23.04, focus_depth: 3.143, c0: 0.2 }),
            depth_range: [0.3, 10.0],
            kernel: crate::model::DofKernel::Gaussian,
            diagnostics: Diagnostics::not_fitted("test"),
        };
        m
    }

    /// The DoF reach follows the content's depth span: 3·max σ over it (eye px,
    /// ratio 1, rounded up), not over the model's whole fitted range — whose near end
    /// (0.3 m) hits the σ clamp (10 px → reach 30).
    #[test]
    fn dof_reach_follows_the_content_depth() {
        let m = thin_lens();
        let s = LayerSettings::default();
        let whole = FrameEffects::from_model(&m, None, None, &s);
        assert_eq!(whole.dof_radius_px, 30);
        // Content at 2.9–3.4 m around the 3.143 m focus: σ ≤ 23.04·|1/2.9 − 1/3.143| + 0.2 = 0.81.
        let near_focus = FrameEffects::from_model(&m, None, Some([2.9, 3.4]), &s);
        let sigma_max = m.depth_of_field.sigma_px(2.9).max(m.depth_of_field.sigma_px(3.4));
        assert_eq!(near_focus.dof_radius_px, (3.0 * sigma_max).ceil() as i32);
        assert!(near_focus.dof_radius_px <= 3);
        // Invalid spans fall back to the whole range.
        for bad in [[f32::NAN, 3.0], [3.0, 2.0]] {
            assert_eq!(FrameEffects::from_model(&m, None, Some(bad), &s).dof_radius_px, 30);
        }
    }

    /// The aberration widens the rectangles by its largest shift in eye pixels
    /// (rounded up), so the fringe outside the content is composited: 1280×960
    /// reference (half-diagonal 800 px), eye pixels twice as fine, red 1.002 →
    /// |1/s − 1|·1600 = 3.19 → 4 px more; absent or switched off: no margin.
    #[test]
    fn chromatic_aberration_widens_the_margin() {
        let mut m = CameraModel::empty(1280, 960);
        m.reference.pixels_per_radian = Some(1000.0);
        let s = LayerSettings::default();
        let base = FrameEffects::from_model(&m, Some(2000.0), None, &s).margin_px(&s);
        m.chromatic_aberration = crate::model::ChromaticAberration {
            present: true,
            scale_minus_one: Some([0.002, -0.001]),
            diagnostics: Diagnostics::not_fitted("test"),
        };
        let fx = FrameEffects::from_model(&m, Some(2000.0), None, &s);
        let (d, inv) = fx.chromatic.expect("applied");
        assert!((d[0] - (1.0 / 1.002 - 1.0)).abs() < 1e-7 && (inv - 1.0 / 1600.0).abs() < 1e-9, "{d:?} {inv}");
        assert_eq!(fx.margin_px(&s), base + 4);
        let off = LayerSettings { chromatic_aberration: false, ..s };
        assert_eq!(FrameEffects::from_model(&m, Some(2000.0), None, &off).margin_px(&off), base);
    }

    /// The mask's σ is in camera pixels: at twice the camera's pixels per radian a
    /// σ of 1.5 px is 3 eye px, whose taps (cut at 15 px, w₀ + 2Σwᵢ = 1) widen the
    /// margin by their reach; off in the settings, nothing.
    #[test]
    fn sharpening_scales_to_eye_pixels_and_widens_the_margin() {
        let mut m = CameraModel::empty(1280, 960);
        m.reference.pixels_per_radian = Some(1000.0);
        let s = LayerSettings::default();
        let base = FrameEffects::from_model(&m, Some(2000.0), None, &s).margin_px(&s);
        m.sharpening = crate::model::Sharpening {
            present: true,
            amount: Some(1.0),
            radius_px: Some(1.5),
            overshoot: None,
            diagnostics: Diagnostics::not_fitted("test"),
        };
        let fx = FrameEffects::from_model(&m, Some(2000.0), None, &s);
        let sh = fx.sharpening.expect("applied");
        assert_eq!(sh.radius_px, 15, "σ 3 eye px reaches past the 15-px cut");
        let sum = sh.taps[0] + 2.0 * sh.taps[1..].iter().sum::<f32>();
        assert!((sum - 1.0).abs() < 1e-6, "{sum}");
        let var: f32 = 2.0 * sh.taps.iter().enumerate().map(|(i, w)| (i * i) as f32 * w).sum::<f32>();
        assert!((var - 9.0).abs() < 0.05, "variance {var} for σ 3 px");
        assert_eq!(fx.margin_px(&s), base + 15);
        let off = LayerSettings { sharpening: false, ..s };
        assert_eq!(FrameEffects::from_model(&m, Some(2000.0), None, &off).sharpening, None);
    }
}
