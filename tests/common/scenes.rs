//! Calibration on real scenes made elsewhere, shared by `benches/scenes.rs` (every
//! scene the mirrors give, per split) and `tests/real_scenes.rs` (the vendored
//! tuning subset CI runs): how a scene's depth is read, the run's camera and head
//! path, and one run of the worker against the truth.

use super::calibration::{frame, pose};
use blind_augment::image::Plane;
use blind_augment::model::compare::noise_relative_error;
use blind_augment::model::*;
use blind_augment::synth::sequence::{decode_rgb, scene_from_depth, HeadPath, Scene, SequenceSpec};
use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, Event, Providers};
use std::time::Instant;

pub const WIDTH: usize = 320;
pub const HEIGHT: usize = 240;
pub const FPS: f32 = 30.0;
pub const FRAMES: usize = 165;
pub const CHANGE_S: f64 = 2.75;
pub const SETTLE_S: f64 = 1.0;

pub struct Entry {
    /// Picks the run's camera (`spec_for`): from the scene's name, so a scene's run
    /// does not change when others join the list.
    pub k: usize,
    pub id: String,
    pub held_out: bool,
    pub source: String,
    pub scene: Scene,
}

/// Depth in metres (NaN where unknown or beyond `dmax_m`) from a 16- or 8-bit
/// depth/disparity image read as the manifest's `read` says.
pub fn read_depth(path: &str, read: &str, focal_px: f32, dmax_m: f32) -> Result<Plane, String> {
    let decoded = image::open(path).map_err(|e| format!("{path}: {e}"))?;
    let eight_bit = matches!(decoded.color(), image::ColorType::L8 | image::ColorType::Rgb8 | image::ColorType::Rgba8);
    let img = decoded.to_luma16();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let raw = img.into_raw();
    let f: Box<dyn Fn(u16) -> f32> = match read.split(':').collect::<Vec<_>>().as_slice() {
        ["disparity", div, b, off] => {
            let p = |s: &str| s.parse::<f32>().map_err(|e| format!("{read}: {e}"));
            let (div, b, off) = (p(div)?, p(b)?, p(off)?);
            // Middlebury: Z = f·B / (d + offset), d = value / div; 0 is unknown.
            // 8-bit PNGs come back ×257 as 16-bit.
            Box::new(move |v: u16| {
                let v = if eight_bit { (v / 257) as f32 } else { v as f32 };
                if v == 0.0 {
                    f32::NAN
                } else {
                    focal_px * b / (v / div + off)
                }
            })
        }
        ["tum"] => Box::new(|v: u16| if v == 0 { f32::NAN } else { v as f32 / 5000.0 }),
        ["sun"] => Box::new(|v: u16| {
            let r = v.rotate_right(3);
            if r == 0 {
                f32::NAN
            } else {
                r as f32 / 1000.0
            }
        }),
        // The frame's 16-bit PGM holds the Kinect's raw values little-endian
        // (PGM is big-endian: Open3D's loader swaps the bytes too); 2047 is none.
        ["nyu"] => Box::new(|v: u16| {
            let v = v.swap_bytes();
            if v >= 2047 {
                return f32::NAN;
            }
            let z = 351.3 / (1092.5 - v as f32);
            if z > 0.0 {
                z
            } else {
                f32::NAN
            }
        }),
        _ => return Err(format!("{path}: unknown depth encoding {read:?}")),
    };
    let data: Vec<f32> = raw.into_iter().map(&f).map(|z| if z > 0.0 && z <= dmax_m { z } else { f32::NAN }).collect();
    Ok(Plane::from_vec(w, h, data))
}

/// FNV-1a of the scene's name.
pub fn name_hash(id: &str) -> usize {
    id.bytes().fold(0x811c_9dc5u32, |h, b| (h ^ b as u32).wrapping_mul(0x0100_0193)) as usize
}

/// A scene from its photograph and depth file (`read_depth`'s encoding `read`,
/// focal length in the photograph's pixels), depth beyond 20 m unknown.
pub fn entry(
    id: &str,
    held_out: bool,
    source: &str,
    image: &str,
    depth: &str,
    read: &str,
    focal_px: f32,
) -> Result<Entry, String> {
    let img = std::fs::read(image).map_err(|e| format!("{image}: {e}")).and_then(|b| decode_rgb(&b))?;
    let z = read_depth(depth, read, focal_px, 20.0)?;
    let scene = scene_from_depth(img, z, focal_px)?;
    Ok(Entry { k: name_hash(id), id: id.into(), held_out, source: source.into(), scene })
}

/// The scenes of a bench manifest (`cargo xtask bench-quality` writes it: id, split,
/// source, image, depth, read, focal_px per line), after the bundled Motorcycle
/// (a tuning scene); lines that do not load are named and skipped.
pub fn load(manifest: &str) -> Vec<Entry> {
    let text = std::fs::read_to_string(manifest).unwrap_or_else(|e| panic!("{manifest}: {e}"));
    let mut out = vec![];
    match blind_augment::synth::sequence::motorcycle() {
        Ok(scene) => out.push(Entry {
            k: name_hash("middlebury2014-motorcycle"),
            id: "middlebury2014-motorcycle".into(),
            held_out: false,
            source: "bundled (assets/)".into(),
            scene,
        }),
        Err(e) => eprintln!("bundled Motorcycle: {e}"),
    }
    for line in text.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
        let c: Vec<&str> = line.split('\t').collect();
        let [id, split, source, image, depth, read, focal] = c[..] else {
            eprintln!("manifest line {line:?}: not 7 columns; skipped");
            continue;
        };
        let focal: f32 = focal.parse().unwrap_or(f32::NAN);
        match entry(id, split == "held-out", source, image, depth, read, focal) {
            Ok(e) => out.push(e),
            Err(e) => eprintln!("{id}: {e}; skipped"),
        }
    }
    out
}

/// The run's camera: λ and noise before and after the change vary with the scene's
/// index across a headset camera's range; δ(Z) a thin lens focused at the scene's
/// median depth reaching ~1.5 px at its depth extremes.
pub fn spec_for(scene: &Scene, k: usize) -> SequenceSpec {
    let f = scene.intrinsics.fx;
    let view = blind_augment::analysis::reproject::Intrinsics {
        fx: f,
        fy: f,
        cx: WIDTH as f32 / 2.0,
        cy: HEIGHT as f32 / 2.0,
        width: WIDTH,
        height: HEIGHT,
    };
    // Keep the view inside the photograph: yaw and pitch shift it by about f·angle.
    let margin_x = (scene.intrinsics.width.saturating_sub(WIDTH)) as f32 / 2.0;
    let margin_y = (scene.intrinsics.height.saturating_sub(HEIGHT)) as f32 / 2.0;
    let path = HeadPath {
        yaw_amplitude_rad: (0.7 * margin_x / f).min(0.05),
        pitch_amplitude_rad: (0.5 * margin_y / f).min(0.02),
        sway_m: 0.01,
        move_s: [0.5, 0.8, 1.2][k % 3],
        hold_s: 1.5,
    };
    let lambda = [0.2f32, 0.3, 0.4][k % 3];
    let gain = [1.0f32, 1.6, 0.6][(k / 3) % 3];
    let mut truth = CameraModel::empty(WIDTH as u32, HEIGHT as u32);
    truth.reference.frame_interval_s = Some(1.0 / FPS);
    truth.reference.pixels_per_radian = Some(f);
    let g2 = gain * gain;
    truth.noise = blind_augment::synth::white_sensor_noise(
        [3e-5 * g2, 2e-5 * g2, 5e-5 * g2],
        [6e-4 * g2, 4e-4 * g2, 9e-4 * g2],
        [0.0, 1.0],
    );
    truth.motion_blur =
        MotionBlur { present: true, exposure: Some(lambda), diagnostics: Diagnostics::not_fitted("ground truth") };
    let mut z: Vec<f32> = scene.depth_m.data.clone();
    z.sort_by(f32::total_cmp);
    let (lo, mid, hi) = (z[z.len() / 100], z[z.len() / 2], z[z.len() * 99 / 100]);
    let span = (1.0 / lo - 1.0 / mid).abs().max((1.0 / mid - 1.0 / hi).abs()).max(1e-3);
    truth.depth_of_field = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::ThinLens { k: 1.2 / span, focus_depth: mid, c0: 0.3 }),
        depth_range: [z[0], z[z.len() - 1]],
        kernel: DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("ground truth"),
    };
    let mut after = truth.clone();
    after.motion_blur.exposure = Some(2.0 * lambda);
    let a = 1.6f32 * 1.6 * g2;
    after.noise = blind_augment::synth::white_sensor_noise(
        [3e-5 * a, 2e-5 * a, 5e-5 * a],
        [6e-4 * a, 4e-4 * a, 9e-4 * a],
        [0.0, 1.0],
    );
    SequenceSpec { frames: FRAMES, fps: FPS, view, path, truth, change: Some((CHANGE_S, after)), seed: 11 + k as u64 }
}

/// The current frame's own sharp rendering as the motion-blur reference
/// (`BENCH_SCENES_TRUTH_SHARP`).
struct TruthSharp(std::sync::Arc<std::sync::Mutex<Option<blind_augment::image::Rgb>>>);

impl blind_augment::analysis::MotionDeblurrer for TruthSharp {
    fn name(&self) -> &str {
        "truth sharp"
    }
    fn deblur(
        &mut self,
        ctx: &blind_augment::analysis::FrameContext,
        _flow: &blind_augment::image::Flow,
    ) -> Result<blind_augment::analysis::Reference, blind_augment::analysis::AnalysisError> {
        let image =
            self.0.lock().expect("slot").clone().ok_or(blind_augment::analysis::AnalysisError::Unavailable {
                frame: ctx.current.frame.index,
                provider: "truth sharp",
                reason: "no rendering".into(),
            })?;
        let noisy = std::env::var("BENCH_SCENES_TRUTH_SHARP").ok().as_deref() == Some("noisy");
        Ok(blind_augment::analysis::Reference {
            second: (!noisy).then(|| image.clone()),
            image,
            valid: None,
            noise_variance_ratio: 0.0,
            sources: vec![ctx.current.frame.index],
        })
    }
}

pub struct RunResult {
    /// Per publication outside the settling windows, the published δ(Z) (px) at
    /// `dof_depths`.
    pub dof_sigma_px: Vec<Vec<f32>>,
    /// The truth's δ(Z) at `dof_depths` (constant over the run).
    pub truth_sigma_px: Vec<f32>,
    pub lambda_err: Option<f32>,
    pub noise_err: Option<f32>,
    pub follow_s: Option<f64>,
    pub drops: usize,
    pub secs: f64,
}

/// The depths δ(Z) is compared at: the 16 quantiles (1/32, 3/32, …) of the
/// scene's measured depth, so a depth counts as often as the scene shows it.
pub fn dof_depths(scene: &Scene) -> Vec<f32> {
    let mut z: Vec<f32> = scene.depth_m.data.iter().copied().filter(|z| z.is_finite() && *z > 0.0).collect();
    z.sort_by(f32::total_cmp);
    if z.is_empty() {
        return vec![];
    }
    (0..16).map(|i| z[((z.len() - 1) as f32 * (i as f32 + 0.5) / 16.0) as usize]).collect()
}

/// The same sequence without the applied defocus (its δ(Z) absent, λ and noise
/// as before): what the blind δ(Z) reads there is the scene's own softness (the
/// photograph's focus, its pixel, the re-rendering's resampling).
pub fn without_defocus(spec: &SequenceSpec) -> SequenceSpec {
    let mut s = spec.clone();
    let absent = |d: &mut DepthOfField| *d = DepthOfField::absent(d.units, Diagnostics::not_fitted("ground truth"));
    absent(&mut s.truth.depth_of_field);
    if let Some((_, after)) = &mut s.change {
        absent(&mut after.depth_of_field);
    }
    s
}

/// 90th percentile of a flow's speed (px/frame; 0 for an empty flow).
fn p90_speed_px(flow: &blind_augment::image::Flow) -> f32 {
    let mut sp: Vec<f32> = flow.dx.iter().zip(&flow.dy).map(|(a, b)| a.hypot(*b)).collect();
    sp.sort_by(f32::total_cmp);
    sp.get(sp.len() * 9 / 10).copied().unwrap_or(0.0)
}

fn median(mut v: Vec<f32>) -> Option<f32> {
    v.sort_by(f32::total_cmp);
    v.get(v.len() / 2).copied()
}

pub fn run(entry: &Entry, spec: &SequenceSpec, tier: CalibrationTier) -> RunResult {
    let t0 = Instant::now();
    let trace = std::env::var_os("BENCH_SCENES_TRACE").is_some();
    let mut cfg = CalibratorConfig::new(tier, 1.0 / FPS as f64, Some(spec.view));
    // `BENCH_SCENES_EXPOSURE_MEMORY_S=S`: the exposure memory tried at another length.
    if let Some(s) = std::env::var("BENCH_SCENES_EXPOSURE_MEMORY_S").ok().and_then(|s| s.parse().ok()) {
        cfg.exposure_memory_s = s;
    }
    // `BENCH_SCENES_TRUTH_FLOW=1`: the frames carry the truth flow and the worker
    // reads it instead of the pose + depth flow (the references still come from
    // poses and depth): separates the flow's part of a λ error from the references'.
    let truth_flow = std::env::var_os("BENCH_SCENES_TRUTH_FLOW").is_some();
    let mut providers = Providers::for_tier(tier);
    if truth_flow {
        providers.flow = Box::new(blind_augment::analysis::GivenFlow);
    }
    // `BENCH_SCENES_TRUTH_SHARP=1`: the motion-blur reference is the frame's own
    // camera without motion blur and noise (its defocus kept): separates the
    // references' part of a λ error from the fit's.
    let truth_sharp = std::env::var_os("BENCH_SCENES_TRUTH_SHARP").is_some();
    let sharp_slot: std::sync::Arc<std::sync::Mutex<Option<blind_augment::image::Rgb>>> = Default::default();
    if truth_sharp {
        providers.motion_deblur = Some(Box::new(TruthSharp(sharp_slot.clone())));
    }
    let mut cal = Calibrator::new(cfg, providers).expect("valid config");
    cal.push_poses(&[pose(spec, 0), pose(spec, 1)]).expect("poses");
    let mut published: Vec<(f64, CameraModel, CameraModel)> = vec![];
    let depths = dof_depths(&entry.scene);
    // The first frame after the change whose streak λ can be read (truth flow ≥
    // 4 px/frame at its 90th percentile, the temporal fit's shortest flow): a change
    // during a rest cannot show in λ before it.
    let mut moving_after_change: Option<f64> = None;
    for i in 0..spec.frames {
        cal.push_poses(&[pose(spec, i + 2)]).expect("poses");
        let f = spec.frame(&entry.scene, i);
        if f.t_s >= CHANGE_S && moving_after_change.is_none() && p90_speed_px(&f.flow) >= 4.0 {
            moving_after_change = Some(f.t_s);
        }
        if truth_sharp {
            let mut m = f.truth.clone();
            m.motion_blur = MotionBlur::absent(Diagnostics::not_fitted("reference"));
            if std::env::var("BENCH_SCENES_TRUTH_SHARP").ok().as_deref() != Some("noisy") {
                m.noise = Noise::absent(Diagnostics::not_fitted("reference"));
            }
            let r =
                blind_augment::synth::apply_camera_model(&f.clean, &m, Some(&f.depth_m), Some(&f.flow), 977 + i as u64);
            *sharp_slot.lock().expect("slot") = Some(r.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0));
        }
        // `BENCH_SCENES_DUMP=DIR`: a tuning scene's frames 0, 45, 90 and 135 as PNG (what
        // the worker saw), named by scene, frame and whether defocus was applied.
        if let (Some(dir), false) = (std::env::var_os("BENCH_SCENES_DUMP"), entry.held_out) {
            if i % 45 == 0 {
                let dof = if spec.truth.depth_of_field.present { "dof" } else { "free" };
                let path = std::path::Path::new(&dir).join(format!("{}-{dof}-{i:03}.png", entry.id));
                if let Err(e) = blind_augment::io::save_rgb(&path, &f.image, blind_augment::io::BitDepth::Eight) {
                    eprintln!("{}: {e}", path.display());
                }
            }
        }
        let mut input = frame(&f);
        if truth_flow {
            input.flow = Some(f.flow.clone());
        }
        for e in cal.push_frame(input).expect("valid frame") {
            if let Event::Published(u) = e {
                if trace && !entry.held_out {
                    let mb = &u.model.motion_blur;
                    eprintln!(
                        "t {:.2} frame t {:.2} truth flow p90 {:.2} px, frames {:?}: λ {:?} (truth {:?}) {:?} noise err {:?} | {}",
                        u.t_s,
                        f.t_s,
                        p90_speed_px(&f.flow),
                        u.frames_used,
                        mb.exposure,
                        f.truth.motion_blur.exposure,
                        mb.diagnostics.status,
                        noise_relative_error(&u.model.noise, &f.truth.noise),
                        mb.diagnostics.reason
                    );
                    // δ(Z) at the scene's depth quantiles 1/32, 15/32, 31/32 against the
                    // truth's there (px).
                    let dof = &u.model.depth_of_field;
                    let at = |d: &DepthOfField| [0, 7, 15].map(|i| depths.get(i).map_or(0.0, |&z| d.sigma_px(z)));
                    eprintln!(
                        "    δ {:.2?} (truth {:.2?}) {:?} | {}",
                        at(dof),
                        at(&f.truth.depth_of_field),
                        dof.diagnostics.status,
                        dof.diagnostics.reason
                    );
                }
                published.push((u.t_s, u.model, f.truth.clone()));
            }
        }
    }
    let settled = |t: f64| t >= SETTLE_S && !(CHANGE_S..CHANGE_S + SETTLE_S).contains(&t);
    let dof_sigma_px = published
        .iter()
        .filter(|p| settled(p.0))
        .map(|(_, m, _)| depths.iter().map(|&z| m.depth_of_field.sigma_px(z)).collect())
        .collect();
    let truth_sigma_px = depths.iter().map(|&z| spec.truth.depth_of_field.sigma_px(z)).collect();
    let lambda = published
        .iter()
        .filter(|p| settled(p.0))
        .filter_map(|(_, m, tr)| Some((m.motion_blur.exposure? - tr.motion_blur.exposure?).abs()))
        .collect();
    let noise =
        published.iter().filter(|p| settled(p.0)).filter_map(|(_, m, tr)| noise_relative_error(&m.noise, &tr.noise));
    let after = spec.change.as_ref().and_then(|(_, a)| a.motion_blur.exposure).unwrap_or(0.0);
    let from = moving_after_change.unwrap_or(CHANGE_S);
    let follow_s = published
        .iter()
        .filter(|p| p.0 >= CHANGE_S)
        .find(|(_, m, _)| m.motion_blur.exposure.is_some_and(|l| (l - after).abs() <= (0.1 * after).max(0.05)))
        .map(|p| (p.0 - from).max(0.0));
    let first = published.iter().position(|p| p.1.motion_blur.present);
    let drops = first.map_or(0, |i| published[i..].iter().filter(|p| !p.1.motion_blur.present).count());
    RunResult {
        dof_sigma_px,
        truth_sigma_px,
        lambda_err: median(lambda),
        noise_err: median(noise.collect()),
        follow_s,
        drops,
        secs: t0.elapsed().as_secs_f64(),
    }
}
