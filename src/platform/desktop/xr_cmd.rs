//! `blind-augment xr`: the OpenXR frame loop on the active runtime (a headset's,
//! or the project's headless test runtime on desktop) with the bundled or a given
//! scene and camera model, and a frame-timing summary.

use super::XrArgs;
use anyhow::{Context, Result};
use blind_augment::model::CameraModel;
use blind_augment::render::LayerSettings;
use blind_augment::scene::Scene;
use blind_augment::worker::ModelChannel;
use blind_augment::xr::{self, default_camera, EndReason, XrOptions, XrSummary};
use glam::{Mat4, Vec3};
use std::sync::atomic::{AtomicBool, Ordering};

use super::camera_feed::CameraFeed;

const TOY: &[u8] = include_bytes!("../../../assets/toy.glb");

fn percentile(v: &[f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * p).round() as usize]
}

/// The summary as printed (also what BENCHMARKS.md quotes).
pub fn format_summary(s: &XrSummary) -> String {
    let ms = |v: f64| v * 1e3;
    let total: f64 = s.cpu_s.iter().sum::<f64>() + s.wait_s.iter().sum::<f64>();
    let wait: f64 = s.wait_s.iter().sum();
    let period_ms = percentile(&s.periods_ns.iter().map(|&p| p as f64).collect::<Vec<_>>(), 0.5) * 1e-6;
    format!(
        "runtime: {}\nsystem: {} on {}\neye: {}×{} (format {}), blend {:?}, passthrough {}, space warp {}, display {}\n\
         frames: {} rendered, {} submitted empty (not visible, or no view tracked yet), {} untracked (the last tracked views shown), \
         {} after a skipped display slot (from predicted display times)\n\
         CPU per frame (outside xrWaitFrame): median {:.2} ms, p95 {:.2} ms, max {:.2} ms\n\
         waiting in xrWaitFrame: {:.0}% of the loop; predicted display period {:.2} ms\n\
         session states: {}\nended: {:?}",
        s.runtime,
        s.system,
        s.device,
        s.eye_size.0,
        s.eye_size.1,
        s.swapchain_format,
        s.blend_mode,
        if s.passthrough { "on" } else { "off" },
        if s.space_warp { "on (app at half the display rate)" } else { "off" },
        s.display_hz.map_or("runtime default".into(), |h| format!("{h} Hz")),
        s.frames_rendered,
        s.frames_empty,
        s.frames_untracked,
        s.missed_frames,
        ms(percentile(&s.cpu_s, 0.5)),
        ms(percentile(&s.cpu_s, 0.95)),
        ms(percentile(&s.cpu_s, 1.0)),
        if total > 0.0 { 100.0 * wait / total } else { 0.0 },
        period_ms,
        s.states.iter().map(|st| format!("{st:?}")).collect::<Vec<_>>().join(" → "),
        s.end,
    )
}

pub fn run(args: XrArgs) -> Result<()> {
    let scene = match &args.scene {
        Some(p) => {
            let scene = Scene::load(p)?;
            for note in &scene.notes {
                log::warn!("{}: {note}", p.display());
            }
            scene
        }
        None => Scene::from_glb(TOY, "assets/toy.glb")?,
    };
    let model = match &args.camera {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            CameraModel::from_json(&text).with_context(|| format!("camera model {}", p.display()))?
        }
        None => {
            log::info!("no --camera: the default camera model until calibration publishes one");
            default_camera()
        }
    };
    anyhow::ensure!(args.object_depth_m > 0.1 && args.object_depth_m.is_finite(), "--object-depth-m must be > 0.1 m");
    let more_scenes = match &args.scenes {
        Some(dir) => {
            anyhow::ensure!(dir.is_dir(), "--scenes {}: not a folder", dir.display());
            let v = xr::scenes_in(dir);
            anyhow::ensure!(!v.is_empty(), "--scenes {}: no .glb or .gltf files", dir.display());
            v
        }
        None => vec![],
    };
    let models = ModelChannel::new(model).context("camera model")?;
    let feed = match &args.camera_frames {
        Some(dir) => Some(CameraFeed::open(&args, dir, &models)?),
        None => {
            anyhow::ensure!(
                args.geometry.depth.is_none() && args.geometry.flow.is_none(),
                "--depth and --flow are read with --camera-frames"
            );
            None
        }
    };
    // The feed ends the loop when its frames end (`frames_done`); the loop's end
    // stops the feed (`loop_done`).
    let (frames_done, loop_done) = (AtomicBool::new(false), AtomicBool::new(false));
    // The panel's camera and calibration lines: the feed's, else what stands in.
    let status_lines = feed.as_ref().map(|f| f.status.clone());
    let status = || match &status_lines {
        Some(lines) => lines.lock().unwrap_or_else(|e| e.into_inner()).clone(),
        None => vec![format!(
            "no camera: {} (--camera-frames feeds the calibration)",
            if args.camera.is_some() { "the model given by --camera" } else { "the default model" }
        )],
    };
    // The lines the panel showed last (printed at the end: what a user saw).
    let mut panel_lines: Option<std::sync::Arc<[String]>> = None;
    let mut on_frame = |r: &xr::FrameRecord| {
        if r.panel.is_some() {
            panel_lines.clone_from(&r.panel);
        }
    };
    let (summary, fed) = std::thread::scope(|s| {
        let feeding = feed.map(|f| s.spawn(|| f.run(&loop_done, &frames_done)));
        let summary = xr::run(XrOptions {
            frames: args.frames,
            validation: args.validation,
            core_validation: args.validation,
            scene: &scene,
            more_scenes: &more_scenes,
            local_from_scene: Mat4::from_translation(Vec3::new(0.0, 0.0, -args.object_depth_m)),
            models: &models,
            settings: LayerSettings::default(),
            display_hz: args.display_hz,
            // The desktop app's calibration takes no headset depth (depth comes
            // with the frames).
            env_depth_hz: 0.0,
            on_frame: Some(&mut on_frame),
            stop: feeding.as_ref().map(|_| &frames_done),
            panel: args.panel,
            status: Some(&status),
            platform: &(),
        });
        loop_done.store(true, Ordering::SeqCst);
        let fed = feeding.map(|h| h.join().unwrap_or_else(|_| Err(anyhow::anyhow!("the camera feed panicked"))));
        (summary, fed)
    });
    let summary = summary?;
    if let Some(fed) = fed {
        let f = fed?;
        let s = &f.stats;
        println!(
            "camera frames: {} offered, {} skipped while the worker was busy, {} fitted, {} models published, {} errors; newest model generation {}",
            f.offered,
            f.skipped,
            s.processed,
            s.published.len(),
            s.errors.len(),
            models.latest().generation
        );
        if let (Some(m), Some(dir)) = (&f.recording, &args.record) {
            println!(
                "recording {}: {} frames ({} with depth), {} poses, {} models, stopped: {:?}{}\n  replay: cd {} && {}",
                dir.display(),
                m.frames,
                m.frames_with_depth,
                m.poses_received,
                m.models_published,
                m.stopped,
                if m.notes.is_empty() { String::new() } else { format!("; notes: {}", m.notes.join("; ")) },
                dir.display(),
                m.calibrate
            );
        }
    }
    println!("{}", format_summary(&summary));
    for (frame, index) in &summary.scene_changes {
        let name =
            if *index == 0 { "the starting scene".to_string() } else { more_scenes[index - 1].display().to_string() };
        println!("frame {frame}: scene {index} ({name})");
    }
    for e in &summary.scene_errors {
        println!("scene skipped: {e}");
    }
    if !summary.panel {
        println!("status panel: unavailable (see the log)");
    } else if let Some(lines) = &panel_lines {
        println!("status panel: {} redraws; last shown:", summary.panel_redraws);
        for l in lines.iter() {
            println!("  | {}", l.strip_prefix('!').unwrap_or(l));
        }
    }
    if !summary.vulkan_messages.is_empty() {
        anyhow::bail!(
            "Vulkan validation reported {} message(s): {:?}",
            summary.vulkan_messages.len(),
            summary.vulkan_messages
        );
    }
    match summary.end {
        EndReason::Exited | EndReason::Stopped => Ok(()),
        EndReason::SessionLost => anyhow::bail!("the OpenXR session was lost (the runtime reported LOSS_PENDING)"),
        EndReason::InstanceLost => anyhow::bail!("the OpenXR instance was lost (XrEventDataInstanceLossPending)"),
    }
}
