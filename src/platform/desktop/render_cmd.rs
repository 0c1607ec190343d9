//! `blind-augment render`: the stereo composite of a glTF object over a background
//! sequence, naive and matched to a camera model, on the desktop render core
//! (offscreen multiview target; lavapipe or any Vulkan device). A camera path (a
//! lateral head sway) and the object's own animation drive the motion.

use super::RenderArgs;
use anyhow::{bail, Context, Result};
use blind_augment::gpu::{GpuContext, GpuOptions};
use blind_augment::image::Rgb;
use blind_augment::io::{self, BitDepth};
use blind_augment::model::CameraModel;
use blind_augment::render::layer::LayerSettings;
use blind_augment::render::{Eye, FrameInput, GBufferFrame, StereoRenderer};
use blind_augment::scene::Scene;
use blind_augment::worker::Snapshot;
use glam::{Mat4, Vec3};
use std::path::Path;
use std::time::Instant;

/// Interpupillary distance of the stereo pair (m).
pub const IPD_M: f32 = 0.064;

/// How the sequence moves: the head (world_from_head at time t) and where the
/// object stands.
pub struct Motion {
    pub head: Box<dyn Fn(f32) -> Mat4>,
    pub world_from_scene: Mat4,
}

/// Timings of one render run.
#[derive(Default, Debug, Clone)]
pub struct RenderStats {
    pub frames: usize,
    pub naive_ms: f64,
    pub matched_ms: f64,
    pub device: String,
    /// Largest DoF reach (eye px) the matched frames used (from the content's depth).
    pub dof_radius_px: i32,
    /// The model generation each frame was rendered with (live: as published).
    pub generations: Vec<u64>,
}

/// Where each frame's camera model comes from.
pub enum ModelSource<'a> {
    /// One model for every frame.
    Fixed(&'a CameraModel),
    /// The newest snapshot the calibration worker has published, read once per frame.
    Live(&'a blind_augment::worker::ModelChannel),
}

pub struct RenderedFrame {
    pub naive: Rgb,
    pub matched: Rgb,
}

/// Bilinear resample of `img` to `w × h` (both eyes' background on desktop).
pub fn resample(img: &Rgb, w: usize, h: usize) -> Rgb {
    if img.width == w && img.height == h {
        return img.clone();
    }
    let mut out = Rgb::new(w, h, [0.0; 3]);
    let (sx, sy) = (img.width as f32 / w as f32, img.height as f32 / h as f32);
    for c in 0..3 {
        let plane = img.plane(c);
        for y in 0..h {
            for x in 0..w {
                out.channels[c][y * w + x] =
                    plane.sample_bilinear((x as f32 + 0.5) * sx - 0.5, (y as f32 + 0.5) * sy - 0.5);
            }
        }
    }
    out
}

fn to_rgba8(img: &Rgb) -> Vec<u8> {
    (0..img.width * img.height)
        .flat_map(|i| {
            let px = |c: usize| (img.channels[c][i].clamp(0.0, 1.0) * 255.0).round() as u8;
            [px(0), px(1), px(2), 255]
        })
        .collect()
}

fn from_rgba8(bytes: &[u8], w: usize, h: usize) -> Rgb {
    let mut out = Rgb::new(w, h, [0.0; 3]);
    for i in 0..w * h {
        for c in 0..3 {
            out.channels[c][i] = bytes[4 * i + c] as f32 / 255.0;
        }
    }
    out
}

fn eyes(world_from_head: Mat4, focal_px: f32, w: u32, h: u32) -> [Eye; 2] {
    std::array::from_fn(|e| {
        let offset = if e == 0 { -IPD_M / 2.0 } else { IPD_M / 2.0 };
        let world_from_eye = world_from_head * Mat4::from_translation(Vec3::new(offset, 0.0, 0.0));
        Eye { focal_px, centre_px: [w as f32 / 2.0, h as f32 / 2.0], view_from_world: world_from_eye.inverse() }
    })
}

/// Render every background frame (camera frames `interval_s` apart) naive and
/// matched. `camera_focal_px`: the background camera's focal length in its pixels;
/// the eye buffer sees the same field of view at `eye` size. Returns both eyes'
/// composites per frame (eyes side by side).
#[allow(clippy::too_many_arguments)]
pub fn render_sequence(
    scene: &Scene,
    backgrounds: &[Rgb],
    source: ModelSource,
    eye: (u32, u32),
    camera_focal_px: f32,
    motion: &Motion,
    settings: LayerSettings,
    progress: &dyn Fn(usize),
) -> Result<(Vec<RenderedFrame>, RenderStats)> {
    let Some(first) = backgrounds.first() else { bail!("no background frames") };
    let (w, h) = eye;
    anyhow::ensure!(w >= 8 && h >= 8 && w <= 8192 && h <= 8192, "eye size {w}×{h} must be 8…8192 px per side");
    let eye_focal_px = camera_focal_px * w as f32 / first.width as f32;
    // The camera's pixels per radian at the centre is its focal length in pixels.
    let with_focal = |m: &CameraModel| {
        let mut m = m.clone();
        m.reference.pixels_per_radian.get_or_insert(camera_focal_px);
        m
    };
    let mut fixed: Option<std::sync::Arc<Snapshot>> = None;
    let interval_s = match &source {
        ModelSource::Fixed(m) => m.reference.frame_interval_s,
        ModelSource::Live(c) => c.latest().model.reference.frame_interval_s,
    }
    .unwrap_or(1.0 / 30.0);
    let ctx = GpuContext::new(&GpuOptions::default()).context("no Vulkan device (install mesa-vulkan-drivers)")?;
    let mut renderer =
        StereoRenderer::new(&ctx, scene, w, h, settings, Some(eye_focal_px)).context("building the stereo renderer")?;
    let mut stats = RenderStats { device: ctx.device_name().to_string(), ..Default::default() };
    let mut out = Vec::new();
    for (k, bg) in backgrounds.iter().enumerate() {
        // One snapshot for the whole frame (both renders): a live model published
        // mid-frame is picked up by the next frame.
        let snapshot = match &source {
            ModelSource::Fixed(m) => {
                fixed.get_or_insert_with(|| std::sync::Arc::new(Snapshot::new(1, with_focal(m)))).clone()
            }
            ModelSource::Live(c) => {
                let latest = c.latest();
                if latest.model.reference.pixels_per_radian.is_some() {
                    latest
                } else {
                    std::sync::Arc::new(Snapshot::new(latest.generation, with_focal(&latest.model)))
                }
            }
        };
        stats.generations.push(snapshot.generation);
        let t = k as f32 * interval_s;
        let t_prev = t - settings.render_interval_s;
        let bg_eye = to_rgba8(&resample(bg, w as usize, h as usize));
        let both: Vec<u8> = bg_eye.iter().chain(bg_eye.iter()).copied().collect();
        renderer.set_background(&both).context("uploading the background")?;
        let frame = GBufferFrame {
            eyes: eyes((motion.head)(t), eye_focal_px, w, h),
            prev_eyes: eyes((motion.head)(t_prev), eye_focal_px, w, h),
            pose: scene.pose_at(t as f64, motion.world_from_scene),
            prev_pose: scene.pose_at(t_prev as f64, motion.world_from_scene),
            light_dir: blind_augment::render::gbuffer::SCENE_LIGHT_DIR,
            ambient: blind_augment::render::gbuffer::SCENE_AMBIENT,
        };
        let now = frame.pose.world_corners(scene);
        let before = frame.prev_pose.world_corners(scene);
        let input = FrameInput { gbuffer: &frame, corners_now: &now, corners_prev: &before };
        let mut images = [Rgb::new(1, 1, [0.0; 3]), Rgb::new(1, 1, [0.0; 3])];
        for (i, matched) in [false, true].into_iter().enumerate() {
            let start = Instant::now();
            let fx = renderer.render(&snapshot, &input, matched).context("rendering")?;
            if fx.dof {
                stats.dof_radius_px = stats.dof_radius_px.max(fx.dof_radius_px);
            }
            renderer.finish().context("waiting for the GPU")?;
            let ms = start.elapsed().as_secs_f64() * 1e3;
            if matched {
                stats.matched_ms += ms;
            } else {
                stats.naive_ms += ms;
            }
            let bytes = renderer.read_output().context("reading the composite back")?;
            let n = (w * h * 4) as usize;
            let left = from_rgba8(&bytes[..n], w as usize, h as usize);
            let right = from_rgba8(&bytes[n..2 * n], w as usize, h as usize);
            images[i] = side_by_side(&[&left, &right], 4);
        }
        let [naive, matched] = images;
        out.push(RenderedFrame { naive, matched });
        progress(k);
    }
    let msgs = ctx.take_messages();
    if !msgs.is_empty() {
        log::warn!("Vulkan reported: {msgs:?}");
    }
    stats.frames = backgrounds.len();
    Ok((out, stats))
}

/// Panels left to right with a white gap.
pub fn side_by_side(panels: &[&Rgb], gap: usize) -> Rgb {
    let h = panels.iter().map(|p| p.height).max().unwrap_or(0);
    let total = panels.iter().map(|p| p.width).sum::<usize>() + gap * panels.len().saturating_sub(1);
    let mut out = Rgb::new(total, h, [1.0; 3]);
    let mut x0 = 0;
    for p in panels {
        for c in 0..3 {
            for y in 0..p.height {
                let dst = y * total + x0;
                out.channels[c][dst..dst + p.width].copy_from_slice(&p.channels[c][y * p.width..(y + 1) * p.width]);
            }
        }
        x0 += p.width + gap;
    }
    out
}

/// The default camera path: a lateral head sway (±`amplitude_m`, one period per
/// `period_s`), eyes at the origin looking down −z.
pub fn sway(amplitude_m: f32, period_s: f32) -> Box<dyn Fn(f32) -> Mat4> {
    Box::new(move |t| {
        Mat4::from_translation(Vec3::new(amplitude_m * (std::f32::consts::TAU * t / period_s).sin(), 0.0, 0.0))
    })
}

pub fn write_frames(out: &Path, frames: &[RenderedFrame]) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for (k, f) in frames.iter().enumerate() {
        io::save_rgb(&out.join(format!("naive_{k:03}.png")), &f.naive, BitDepth::Eight)?;
        io::save_rgb(&out.join(format!("matched_{k:03}.png")), &f.matched, BitDepth::Eight)?;
    }
    Ok(())
}

pub fn run(args: RenderArgs) -> Result<()> {
    let scene = Scene::load(&args.scene)?;
    for note in &scene.notes {
        log::warn!("{}: {note}", args.scene.display());
    }
    let text = std::fs::read_to_string(&args.camera).with_context(|| format!("reading {}", args.camera.display()))?;
    let model = CameraModel::from_json(&text).with_context(|| format!("camera model {}", args.camera.display()))?;
    let mut paths: Vec<_> = std::fs::read_dir(&args.background)
        .with_context(|| format!("reading {}", args.background.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
        })
        .collect();
    paths.sort();
    anyhow::ensure!(!paths.is_empty(), "{} holds no PNG/JPEG frames", args.background.display());
    let mut frames = Vec::new();
    for p in &paths {
        let (img, _) = io::load_rgb(p)?;
        if let Some(f) = frames.first().map(|f: &Rgb| (f.width, f.height)) {
            anyhow::ensure!(
                f == (img.width, img.height),
                "{} is {}×{}, the first frame {}×{}",
                p.display(),
                img.width,
                img.height,
                f.0,
                f.1
            );
        }
        frames.push(img);
    }
    let (bw, bh) = (frames[0].width, frames[0].height);
    let eye = match &args.eye_size {
        Some(s) => parse_size(s)?,
        None => (bw as u32, bh as u32),
    };
    let focal = match (args.focal_px, model.reference.pixels_per_radian) {
        (Some(f), _) | (None, Some(f)) if f.is_finite() && f > 0.0 => f,
        _ => {
            log::warn!("no --focal-px and no pixels_per_radian in the model: assuming a 60° horizontal field of view");
            bw as f32 / 2.0 / (30.0f32.to_radians()).tan()
        }
    };
    anyhow::ensure!(args.object_depth_m > 0.1 && args.object_depth_m.is_finite(), "--object-depth-m must be > 0.1 m");
    let motion = Motion {
        head: sway(0.04, 8.0 / 30.0 * 2.0),
        world_from_scene: Mat4::from_translation(Vec3::new(0.0, 0.0, -args.object_depth_m)),
    };
    let bar = indicatif::ProgressBar::new(frames.len() as u64);
    let (rendered, stats) = render_sequence(
        &scene,
        &frames,
        ModelSource::Fixed(&model),
        eye,
        focal,
        &motion,
        LayerSettings::default(),
        &|_| bar.inc(1),
    )?;
    bar.finish_and_clear();
    write_frames(&args.out, &rendered)?;
    eprintln!(
        "rendered {} frames at {}×{} per eye on {}: naive {:.1} ms/frame, matched {:.1} ms/frame (wall, incl. readback); wrote {}",
        stats.frames,
        eye.0,
        eye.1,
        stats.device,
        stats.naive_ms / stats.frames as f64,
        stats.matched_ms / stats.frames as f64,
        args.out.display()
    );
    Ok(())
}

pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (a, b) = s.split_once(['x', '×']).with_context(|| format!("--eye-size {s}: expected WxH"))?;
    let w: u32 = a.trim().parse().with_context(|| format!("--eye-size {s}: width"))?;
    let h: u32 = b.trim().parse().with_context(|| format!("--eye-size {s}: height"))?;
    Ok((w, h))
}
