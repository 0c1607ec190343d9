//! The per-frame uniform block: every effect parameter of one `CameraModel`
//! snapshot, packed for the GPU (std140-compatible: all members 4-byte scalars in
//! 16-byte groups). Built from a validated model, so nothing non-finite reaches a
//! shader; absent effects are flagged off and their parameters zeroed.

use crate::model::{CameraModel, DofCurve, NoiseForm, NOISE_LEVELS};
use bytemuck::{Pod, Zeroable};

pub const FLAG_NOISE: u32 = 1;
pub const FLAG_MOTION_BLUR: u32 = 2;
pub const FLAG_DEPTH_OF_FIELD: u32 = 4;

/// DoF curve forms in `dof_form`.
pub const DOF_NONE: u32 = 0;
pub const DOF_QUADRATIC: u32 = 1;
pub const DOF_THIN_LENS: u32 = 2;
pub const DOF_CONSTANT: u32 = 3;

#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct EffectParams {
    /// Snapshot generation (which published model this frame used).
    pub generation: u32,
    pub flags: u32,
    /// λ (0 when MB is absent).
    pub exposure: f32,
    /// Camera frame interval in seconds (0 when unknown).
    pub frame_interval_s: f32,
    pub dof_form: u32,
    /// 0: metric depth in m, 1: relative inverse depth.
    pub dof_units: u32,
    pub dof_depth_range: [f32; 2],
    /// quadratic: a, b, c; thin lens: k, u(Z_f) (inverse depth of focus), c0;
    /// constant: c.
    pub dof_coeffs: [f32; 4],
    /// 0: linear std, 1: affine variance.
    pub noise_form: u32,
    pub noise_has_lowpass: u32,
    pub noise_luma_range: [f32; 2],
    /// Per band (4 band-pass levels, then the low-pass): R, G, B, pad.
    pub noise_slope: [[f32; 4]; NOISE_LEVELS + 1],
    pub noise_intercept: [[f32; 4]; NOISE_LEVELS + 1],
}

const _: () = assert!(std::mem::size_of::<EffectParams>() == 224);
const _: () = assert!(std::mem::size_of::<EffectParams>() % 16 == 0);
const _: () = assert!(std::mem::offset_of!(EffectParams, dof_form) == 16);
const _: () = assert!(std::mem::offset_of!(EffectParams, dof_coeffs) == 32);
const _: () = assert!(std::mem::offset_of!(EffectParams, noise_form) == 48);
const _: () = assert!(std::mem::offset_of!(EffectParams, noise_slope) == 64);
const _: () = assert!(std::mem::offset_of!(EffectParams, noise_intercept) == 144);

impl EffectParams {
    /// Pack a (validated) model. `generation` identifies the snapshot.
    pub fn from_model(model: &CameraModel, generation: u32) -> Self {
        let mut p = EffectParams::zeroed();
        p.generation = generation;
        p.frame_interval_s = model.reference.frame_interval_s.unwrap_or(0.0);
        let mb = model.motion_blur.exposure_or_zero();
        if mb > 0.0 {
            p.flags |= FLAG_MOTION_BLUR;
            p.exposure = mb;
        }
        let dof = &model.depth_of_field;
        if let (true, Some(curve)) = (dof.present, dof.curve) {
            p.flags |= FLAG_DEPTH_OF_FIELD;
            p.dof_units = (dof.units == crate::model::DepthUnits::RelativeInverse) as u32;
            p.dof_depth_range = dof.depth_range;
            (p.dof_form, p.dof_coeffs) = match curve {
                DofCurve::Quadratic { a, b, c } => (DOF_QUADRATIC, [a, b, c, 0.0]),
                DofCurve::ThinLens { k, focus_depth, c0 } => {
                    (DOF_THIN_LENS, [k, dof.units.inverse_depth(focus_depth), c0, 0.0])
                }
                DofCurve::Constant { c } => (DOF_CONSTANT, [c, 0.0, 0.0, 0.0]),
            };
        }
        let noise = &model.noise;
        if noise.present {
            p.flags |= FLAG_NOISE;
            p.noise_form = (noise.form == NoiseForm::AffineVariance) as u32;
            p.noise_luma_range = noise.luminance_range;
            for (l, level) in noise.levels.iter().chain(noise.lowpass.iter()).enumerate().take(NOISE_LEVELS + 1) {
                p.noise_slope[l] = [level.slope[0], level.slope[1], level.slope[2], 0.0];
                p.noise_intercept[l] = [level.intercept[0], level.intercept[1], level.intercept[2], 0.0];
            }
            p.noise_has_lowpass = noise.lowpass.is_some() as u32;
        }
        p
    }
}
