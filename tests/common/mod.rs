//! Shared helpers for the integration tests: vendored photographs, synthetic depth
//! and flow with known structure, the true noise generator.
#![allow(dead_code)]

pub mod calibration;
pub mod independent;
pub mod lensfun;
pub mod scenes;
pub mod vtest;

use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::io;
use std::path::PathBuf;

pub fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

pub fn photo(name: &str) -> Rgb {
    io::load_rgb(&data(name)).expect("vendored test photo").0
}

/// A photograph shipped in `assets/` (the Motorcycle view).
pub fn asset_photo(name: &str) -> Rgb {
    io::load_rgb(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("assets").join(name)).expect("asset photo").0
}

/// Crop (x0, y0, w, h).
pub fn crop(img: &Rgb, x0: usize, y0: usize, w: usize, h: usize) -> Rgb {
    let mut out = Rgb::new(w, h, [0.0; 3]);
    for c in 0..3 {
        for y in 0..h {
            for x in 0..w {
                out.channels[c][y * w + x] = img.channels[c][(y0 + y) * img.width + x0 + x];
            }
        }
    }
    out
}

/// `src` mirror-tiled to `w × h` (real texture at any frame size, e.g. 1280×960).
pub fn mirror_tile(src: &Rgb, w: usize, h: usize) -> Rgb {
    let m = |i: usize, n: usize| {
        let p = i % (2 * n);
        if p < n {
            p
        } else {
            2 * n - 1 - p
        }
    };
    let mut out = Rgb::new(w, h, [0.0; 3]);
    for c in 0..3 {
        for y in 0..h {
            for x in 0..w {
                out.channels[c][y * w + x] = src.channels[c][m(y, src.height) * src.width + m(x, src.width)];
            }
        }
    }
    out
}

/// 8-bit quantisation, as a PNG round trip does.
/// The image with every channel its luma (Rec. 601): a scene with no colour and
/// no chromatic aberration of its own.
pub fn grey(img: &Rgb) -> Rgb {
    let mut out = img.clone();
    for i in 0..img.width * img.height {
        let y: f32 = (0..3).map(|c| blind_augment::image::LUMA_WEIGHTS[c] * img.channels[c][i]).sum();
        (0..3).for_each(|c| out.channels[c][i] = y);
    }
    out
}

pub fn quantize8(img: &Rgb) -> Rgb {
    img.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0)
}

/// A smooth metric depth map from `near_m` to `far_m`: a tilted plane with a bump,
/// so every depth in the range is populated.
pub fn depth_ramp(w: usize, h: usize, near_m: f32, far_m: f32) -> Plane {
    let mut d = Plane::new(w, h, 0.0);
    for y in 0..h {
        for x in 0..w {
            let u = (x as f32 + 0.5) / w as f32;
            let v = (y as f32 + 0.5) / h as f32;
            let t = (0.7 * v + 0.3 * u + 0.08 * (6.0 * u).sin() * (4.0 * v).cos()).clamp(0.0, 1.0);
            d.data[y * w + x] = near_m + (far_m - near_m) * t;
        }
    }
    d
}

/// The motion-blur-under-defocus scene's depth and lens: a plain ramp 0.5–4 m
/// (70% down the frame, 30% across) through a thin lens (k 3, focus 1.2 m, c0 0.3:
/// σ up to 3.8 px at the near end).
pub fn thin_lens_ramp(w: usize, h: usize) -> (Plane, blind_augment::model::DepthOfField) {
    use blind_augment::model::*;
    let depth = Plane::from_vec(
        w,
        h,
        (0..w * h).map(|i| 0.5 + 3.5 * (0.7 * (i / w) as f32 / h as f32 + 0.3 * (i % w) as f32 / w as f32)).collect(),
    );
    let dof = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::ThinLens { k: 3.0, focus_depth: 1.2, c0: 0.3 }),
        depth_range: [0.5, 4.0],
        kernel: DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("truth"),
    };
    (depth, dof)
}

/// A smooth flow field in px/frame with magnitude around `scale` and varying
/// direction (a rotation plus a translation, like head motion).
pub fn flow_field(w: usize, h: usize, scale: f32) -> Flow {
    let mut f = Flow::uniform(w, h, 0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            let u = x as f32 / w as f32 - 0.5;
            let v = y as f32 / h as f32 - 0.5;
            let i = y * w + x;
            f.dx[i] = scale * (0.8 - 0.9 * v);
            f.dy[i] = scale * (0.3 + 0.9 * u);
        }
    }
    f
}

/// Poisson–Gaussian sensor noise: std_c(Y) = sqrt(a_c + b_c·Y), white, seeded.
pub fn add_sensor_noise(clean: &Rgb, a: [f32; 3], b: [f32; 3], seed: u64) -> Rgb {
    let y = clean.luma();
    let mut out = clean.clone();
    for c in 0..3 {
        for i in 0..clean.len() {
            let s = (a[c] + b[c] * y.data[i]).max(0.0).sqrt();
            let n =
                blind_augment::synth::gaussian((i % clean.width) as u32, (i / clean.width) as u32, c as u32 + 10, seed);
            out.channels[c][i] += s * n;
        }
    }
    out
}

/// Fit options for the blind (fast) exposure alone: the motion-blur tests' fit.
pub fn fast_exposure_only() -> blind_augment::fit::FitOptions {
    use blind_augment::fit::{Effects, FitOptions, Tier};
    FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
        ..Default::default()
    }
}

/// A camera over a synthetic frame: Gaussian defocus of `sigma_px` per channel, the
/// bench's white sensor noise (seeded) and 8-bit quantisation.
pub fn defocus_noise_8bit(img: &Rgb, sigma_px: f32, seed: u64) -> Rgb {
    let noise = blind_augment::synth::white_sensor_noise([2e-5; 3], [8e-4; 3], [0.0, 1.0]);
    let k = blind_augment::image::discrete_gaussian_kernel(sigma_px * sigma_px);
    let mut out = img.clone();
    for ch in 0..3 {
        let p = Plane::from_vec(img.width, img.height, img.channels[ch].clone());
        out.channels[ch] = blind_augment::image::blur_separable(&p, &k).data;
    }
    quantize8(&blind_augment::synth::add_noise(&out, &noise, seed))
}

pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

/// A Vulkan context for a GPU test (validation layer on when installed), or `None`
/// with a message when there is no device — unless REQUIRE_GPU=1 (set by .ci/run),
/// where a missing device, or a missing validation layer, fails the test.
pub fn gpu_context(test: &str) -> Option<blind_augment::gpu::GpuContext> {
    let opts =
        blind_augment::gpu::GpuOptions { validation: true, prefer_device: std::env::var("BLIND_AUGMENT_DEVICE").ok() };
    let required = std::env::var("REQUIRE_GPU").as_deref() == Ok("1");
    match blind_augment::gpu::GpuContext::new(&opts) {
        Ok(ctx) => {
            let layer = if ctx.validation_enabled() { "on" } else { "not installed" };
            eprintln!("{test}: running on {} (validation layer {layer})", ctx.device_name());
            assert!(
                !required || ctx.validation_enabled(),
                "{test}: REQUIRE_GPU=1 expects the validation layer (vulkan-validationlayers)"
            );
            Some(ctx)
        }
        Err(e) if required => panic!("{test}: REQUIRE_GPU=1 but no Vulkan device: {e}"),
        Err(e) => {
            eprintln!("{test}: SKIPPED, no Vulkan device ({e}); set REQUIRE_GPU=1 to make this a failure");
            None
        }
    }
}

/// Std of the noise `synth` adds to a flat grey of luma y, per channel, over 256²
/// pixels (std error of the estimate ≈ 0.14%).
pub fn synth_flat_std(noise: &blind_augment::model::Noise, y: f32) -> [f64; 3] {
    let field = blind_augment::synth::noise_field(&Plane::new(256, 256, y), noise, 77);
    std::array::from_fn(|c| {
        let v = &field.channels[c];
        (v.iter().map(|x| (*x as f64).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
    })
}

/// Relative errors of synth's flat-grey std against `truth(c, y)` at 9 lumas
/// spread over the fitted range.
pub fn noise_errors(noise: &blind_augment::model::Noise, truth: impl Fn(usize, f32) -> f64) -> Vec<f64> {
    let [lo, hi] = noise.luminance_range;
    let mut errs = vec![];
    for k in 0..9 {
        let y = lo + (hi - lo) * (k as f32 + 0.5) / 9.0;
        for (c, s) in synth_flat_std(noise, y).into_iter().enumerate() {
            errs.push(s / truth(c, y) - 1.0);
        }
    }
    errs
}

/// `blind-augment demo`'s camera (src/platform/desktop/demo.rs `truth_model`: its
/// noise, λ 0.4, its thin-lens δ(Z) focused at disparity 30 of the Middlebury
/// Motorcycle at quarter size) on a calibration sequence: the camera whose live
/// video showed the worker's noise spikes and false changes (BENCHMARKS.md "The
/// worker's noise at a burst's start and after a reset").
pub fn demo_camera(spec: &mut blind_augment::synth::sequence::SequenceSpec) {
    spec.truth.noise = blind_augment::synth::white_sensor_noise([2e-5, 1.2e-5, 4e-5], [8e-4, 5e-4, 1.2e-3], [0.0, 1.0]);
    spec.truth.motion_blur.exposure = Some(0.4);
    let (focal_px, baseline_m, doffs_px) = (3979.911f32 / 4.0, 0.193001f32, 124.343f32 / 4.0);
    spec.truth.depth_of_field.curve = Some(blind_augment::model::DofCurve::ThinLens {
        k: 0.12 * focal_px * baseline_m,
        focus_depth: focal_px * baseline_m / (30.0 + doffs_px),
        c0: 0.2,
    });
}

/// A frame of a synthetic sequence as the worker's analysis hands it over: its image,
/// its true metric depth and pose (no flow), for `analysis::temporal::align`.
pub fn analysed(f: &blind_augment::synth::sequence::SequenceFrame) -> blind_augment::analysis::Analysed {
    use blind_augment::analysis::{Analysed, DepthMap, Frame};
    Analysed {
        frame: Frame { index: f.index as u64, t_s: f.t_s, image: f.image.clone(), depth: None, flow: None },
        depth: Some(DepthMap { depth: f.depth_m.clone(), units: blind_augment::model::DepthUnits::MetricM }),
        world_from_camera: Some(f.world_from_camera),
        sparse_flow: None,
    }
}

/// "median / p90 / worst" of `v` (worst = largest), to three decimals.
pub fn summary(v: &[f32]) -> String {
    if v.is_empty() {
        return "— / — / —".into();
    }
    let mut v = v.to_vec();
    v.sort_by(f32::total_cmp);
    let q = |p: f32| v[((v.len() - 1) as f32 * p).round() as usize];
    format!("{:.3} / {:.3} / {:.3}", q(0.5), q(0.9), v[v.len() - 1])
}
