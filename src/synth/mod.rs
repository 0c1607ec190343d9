//! CPU reference of every effect, the ground truth the GPU passes are held to:
//! `add_dof` → `add_motion_blur` → `add_noise`, the paper's order (Sec. 3.1: blur
//! before noise, so noise is never blurred). Written for clarity first.

mod dof;
pub mod layer;
mod measured;
#[cfg(test)]
pub(crate) mod measured_check;
mod motion_blur;
mod noise;
mod rng;
pub mod sequence;
pub mod training;

pub use dof::{add_defocus, add_defocus_disc, add_dof, dof_sigma_map, for_each_cascade_interval, DOF_NODE_SPACING_PX};
pub use motion_blur::{add_motion_blur, MB_MAX_SAMPLE_SPACING_PX, MB_MIN_INTERVALS};
pub use noise::{
    add_noise, correlated_sensor_noise, noise_field, noise_field_rgb, unit_band_std, white_sensor_noise, SynthesisTable,
};
pub use rng::gaussian;

use crate::image::{Flow, Plane, Rgb};
use crate::model::CameraModel;

/// Apply every present effect of `model` to `clean`, in the paper's order.
/// `depth` is needed when DoF is present and `flow` when MB is present; without
/// them that effect is skipped (logged). Output is unclipped.
pub fn apply_camera_model(
    clean: &Rgb,
    model: &CameraModel,
    depth: Option<&Plane>,
    flow: Option<&Flow>,
    seed: u64,
) -> Rgb {
    let mut img = clean.clone();
    if model.depth_of_field.present {
        match depth {
            Some(z) => img = add_dof(&img, z, &model.depth_of_field),
            None => log::warn!("depth of field is present in the model but no depth map was given: skipped"),
        }
    }
    let lambda = model.motion_blur.exposure_or_zero();
    if lambda > 0.0 {
        match flow {
            Some(f) => img = add_motion_blur(&img, f, lambda),
            None => {
                log::warn!("motion blur is present in the model but no flow was given: skipped")
            }
        }
    }
    if model.noise.present {
        img = add_noise(&img, &model.noise, seed);
    }
    img
}
