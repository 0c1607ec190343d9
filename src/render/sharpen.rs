//! The ISP's sharpening on the virtual layer (`model::Sharpening`): the mask one
//! frame applies and the push block of `layer_sharpen.comp`, whose two passes
//! `layer::LayerEffects` records after DoF and MB. CPU twin: `synth::layer::sharpen`.

use bytemuck::{Pod, Zeroable};

/// The unsharp mask one frame applies to the chain's output:
/// out = L + amount·(L − G ∗ L), G the separable kernel `taps` (one-sided,
/// `model::kernels::sharpening_taps`), reaching `radius_px`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sharpen {
    pub amount: f32,
    pub taps: [f32; crate::model::kernels::SHARPENING_TAPS],
    pub radius_px: i32,
}

impl Sharpen {
    /// The mask for amount k and σ in eye pixels; `None` where it does nothing.
    pub fn new(amount: f32, sigma_eye_px: f32) -> Option<Self> {
        if !(amount.is_finite() && amount > 0.0 && sigma_eye_px.is_finite() && sigma_eye_px > 0.0) {
            return None;
        }
        let taps = crate::model::kernels::sharpening_taps(sigma_eye_px);
        let radius_px = taps.iter().rposition(|&w| w > 0.0).unwrap_or(0) as i32;
        (radius_px > 0).then_some(Self { amount, taps, radius_px })
    }
}

/// `layer_sharpen.comp`'s push block.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(super) struct SharpenPush {
    pub(super) rect: [[i32; 4]; 2],
    pub(super) size: [i32; 2],
    pub(super) source: i32,
    pub(super) pass: i32,
    pub(super) radius: i32,
    pub(super) amount: f32,
    pub(super) pad: [i32; 2],
    pub(super) w: [[f32; 4]; 4],
}

const _: () = assert!(std::mem::size_of::<SharpenPush>() == 128);
const _: () = assert!(std::mem::offset_of!(SharpenPush, amount) == 52);
const _: () = assert!(std::mem::offset_of!(SharpenPush, w) == 64);
