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

/// Apply every present effect of `model` to `clean`, in the camera's order: the
/// lens's vignetting, then the paper's (DoF, motion blur, noise) with the ISP's
/// colour before the noise.
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
    if let Some(a) = model.vignetting.applied() {
        img = add_vignetting(&img, a);
    }
    if let Some(d) = model.chromatic_aberration.applied() {
        img = add_lateral_ca(&img, d.map(|v| 1.0 + v));
    }
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
    // The ISP after the optics: white balance and exposure (`model::Colour`), then
    // the noise.
    if model.colour.present {
        img = add_colour(&img, model.colour.gains_or_one());
    }
    if let Some((k, sigma)) = model.sharpening.applied() {
        img = add_sharpening(&img, k, sigma);
    }
    if model.noise.present {
        img = add_noise(&img, &model.noise, seed);
    }
    img
}

/// The lens's falloff on an encoded (sRGB) frame: each pixel decoded to linear
/// light, multiplied by V(r) (`model::Vignetting`; r from the frame's centre over
/// its half-diagonal, at pixel centres) and re-encoded, unclipped as `add_colour`.
/// The render pass's twin is `layer::vignette_gain`.
pub fn add_vignetting(img: &Rgb, log_falloff: [f32; 3]) -> Rgb {
    let (w, h) = (img.width, img.height);
    let decode = |v: f32| if v < 0.0 { v / 12.92 } else { crate::image::yuv::srgb_to_linear(v) };
    let mut out = img.clone();
    for y in 0..h {
        for x in 0..w {
            let r = crate::model::Vignetting::radius(w, h, x as f32 + 0.5, y as f32 + 0.5);
            let g = crate::model::Vignetting::gain_at(log_falloff, r);
            for ch in out.channels.iter_mut() {
                let v = &mut ch[y * w + x];
                *v = crate::image::yuv::linear_to_srgb(decode(*v) * g);
            }
        }
    }
    out
}

/// The ISP's sharpening on an encoded frame (`model::Sharpening`): every channel
/// plus `amount` times itself minus its discrete Gaussian blur of std `radius_px`
/// (borders clamped), unclipped.
pub fn add_sharpening(img: &Rgb, amount: f32, radius_px: f32) -> Rgb {
    let kernel = crate::model::kernels::discrete_gaussian_kernel(radius_px * radius_px);
    let mut out = img.clone();
    for (c, ch) in out.channels.iter_mut().enumerate() {
        let blurred =
            crate::image::blur_separable(&Plane::from_vec(img.width, img.height, img.channels[c].clone()), &kernel);
        for (v, b) in ch.iter_mut().zip(&blurred.data) {
            *v += amount * (*v - b);
        }
    }
    out
}

/// Lateral chromatic aberration on a frame: red and blue are green's image scaled
/// by `scale` = [s_R, s_B] about the frame's centre (lensfun's "linear" TCA model),
/// each resampled by Catmull–Rom at (p − c)/s + c, clamped at the borders. The
/// CPU reference `fit::chromatic` is measured against.
pub fn add_lateral_ca(img: &Rgb, scale: [f32; 2]) -> Rgb {
    let (w, h) = (img.width, img.height);
    let (cx, cy) = ((w as f32 - 1.0) * 0.5, (h as f32 - 1.0) * 0.5);
    let mut out = img.clone();
    for (k, c) in [0usize, 2].into_iter().enumerate() {
        let s = scale[k];
        if !(s.is_finite() && s > 0.0) || s == 1.0 {
            continue;
        }
        let src = Plane::from_vec(w, h, img.channels[c].clone());
        for y in 0..h {
            for x in 0..w {
                let (sx, sy) = (cx + (x as f32 - cx) / s, cy + (y as f32 - cy) / s);
                out.channels[c][y * w + x] = crate::image::sample_bicubic(&src, sx, sy);
            }
        }
    }
    out
}

/// The camera's white balance and exposure on an encoded (sRGB) frame: each value
/// decoded to linear light, multiplied by its channel's gain and re-encoded,
/// unclipped (negative values stay on the curve's linear segment, values above 1 on
/// its power law), as `apply_camera_model` leaves clipping to the caller. The
/// render pass's twin is `layer::gain_encoded` (which clips: it writes a display).
pub fn add_colour(img: &Rgb, gains: [f32; 3]) -> Rgb {
    let decode = |v: f32| if v < 0.0 { v / 12.92 } else { crate::image::yuv::srgb_to_linear(v) };
    let encode = |v: f32| if v <= 0.0031308 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
    let mut out = img.clone();
    for (ch, g) in out.channels.iter_mut().zip(gains) {
        for v in ch.iter_mut() {
            *v = encode(decode(*v) * g);
        }
    }
    out
}
