//! `blind-augment xr --camera-frames DIR`: a recorded or synthesised sequence (in
//! `calibrate`'s input layout) fed to the calibration worker as the headset's
//! camera feeds it — in real time at the frames' own times, a frame made only when
//! the worker would take it, poses running two frames ahead — while the frame
//! loop renders with the models it publishes; `--record` records what the worker
//! takes, as the headset app does (`io::recording`).

use super::calibrate_cmd::{frame_numbers, parse_intrinsics};
use super::fit_cmd::{list_frames, sibling};
use super::XrArgs;
use anyhow::{ensure, Context, Result};
use blind_augment::analysis::{DepthMap, Frame};
use blind_augment::io::poses::{read_poses_csv, PoseRow};
use blind_augment::io::recording::{Manifest, RecordLimits, Recording, RecordingInfo};
use blind_augment::io::{self};
use blind_augment::panel::CalibrationStatus;
use blind_augment::worker::{
    CalibrationTier, Calibrator, CalibratorConfig, ModelChannel, Providers, Worker, WorkerStats,
};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Poses reach the worker this many frames ahead of their frame (`calibrate`'s
/// lead: a headset's camera pipeline delivers frames after the head poses).
const POSE_LEAD: u64 = 2;

/// A sequence ready to feed.
pub struct CameraFeed {
    frames: Vec<PathBuf>,
    numbers: Vec<u64>,
    poses: Option<Vec<PoseRow>>,
    fps: f64,
    depth: Option<(PathBuf, blind_augment::model::DepthUnits, f32)>,
    flow: Option<PathBuf>,
    worker: Worker,
    recording: Option<Recording>,
    tier: CalibrationTier,
    /// The status panel's camera and calibration lines, refreshed as frames are fed.
    pub status: Arc<Mutex<Vec<String>>>,
}

/// How often the feed refreshes its status lines (the panel redraws at ≤ 2 Hz).
const STATUS_EVERY: Duration = Duration::from_millis(250);

/// What a feed did.
pub struct FeedSummary {
    pub offered: u64,
    /// Frames not made because the worker was busy (a headset's camera frames
    /// arrive regardless; the producer skips them).
    pub skipped: u64,
    pub stats: WorkerStats,
    pub recording: Option<Manifest>,
}

impl CameraFeed {
    /// Check the sequence and start the worker (and the recording) on `models`.
    pub fn open(args: &XrArgs, dir: &std::path::Path, models: &ModelChannel) -> Result<CameraFeed> {
        let tier = CalibrationTier::parse(&args.tier)
            .with_context(|| format!("--tier `{}`: expected fast, balanced or accurate", args.tier))?;
        ensure!(
            args.camera_fps.is_finite() && args.camera_fps > 0.0 && args.camera_fps <= 1000.0,
            "--camera-fps {}: need 0 < fps ≤ 1000",
            args.camera_fps
        );
        let mut frames = list_frames(dir)?;
        let numbers = frame_numbers(&mut frames);
        let (first, _) = io::load_rgb(&frames[0]).with_context(|| format!("frame {}", frames[0].display()))?;
        let (w, h) = (first.width, first.height);
        let poses = match (&args.poses, &args.intrinsics) {
            (Some(p), Some(_)) => Some(read_poses_csv(p)?),
            (Some(_), None) => anyhow::bail!("--poses needs --intrinsics fx,fy,cx,cy (pixels of the frames)"),
            (None, Some(_)) => anyhow::bail!("--intrinsics is only used with --poses"),
            (None, None) => None,
        };
        if let Some(rows) = &poses {
            for (&n, f) in numbers.iter().zip(&frames) {
                ensure!(rows.iter().any(|r| r.frame == n), "frame {n} ({}) has no row in --poses", f.display());
            }
        }
        let intrinsics = args.intrinsics.as_deref().map(|s| parse_intrinsics(s, w, h)).transpose()?;
        let g = &args.geometry;
        let mut providers = Providers::for_tier(tier);
        if g.flow.is_some() {
            providers = providers.with_given_flow();
        }
        let fps = args.camera_fps as f64;
        let cfg = CalibratorConfig::new(tier, 1.0 / fps, intrinsics);
        let calibrator = Calibrator::new(cfg, providers)?;
        let worker = Worker::spawn(calibrator, models.clone()).context("starting the calibration thread")?;
        let recording = match &args.record {
            Some(out) => {
                let info = RecordingInfo {
                    device: format!("desktop ({})", std::env::consts::ARCH),
                    app_version: env!("CARGO_PKG_VERSION").into(),
                    camera_id: dir.display().to_string(),
                    stream_size: (w as u32, h as u32),
                    timestamps: if poses.is_some() {
                        "poses.csv t_s".into()
                    } else {
                        format!("frame number / {fps} fps")
                    },
                    frame_interval_s: 1.0 / fps,
                    intrinsics,
                    tier: tier.name().into(),
                };
                let limits = RecordLimits {
                    max_s: args.record_s,
                    min_free_bytes: args.record_min_free_mib.saturating_mul(1 << 20),
                };
                let (rec, tap) = Recording::start(out, info, limits)?;
                worker.set_tap(Some(Box::new(tap)));
                Some(rec)
            }
            None => None,
        };
        Ok(CameraFeed {
            frames,
            numbers,
            poses,
            fps,
            depth: g.depth.clone().map(|d| (d, g.depth_units.into(), g.depth_png_scale)),
            flow: g.flow.clone(),
            worker,
            recording,
            tier,
            status: Arc::new(Mutex::new(vec![format!("{} tier · waiting for the first camera frame", tier.name())])),
        })
    }

    fn t_s(&self, n: u64) -> f64 {
        self.poses.as_ref().and_then(|rows| rows.iter().find(|r| r.frame == n)).map_or(n as f64 / self.fps, |r| r.t_s)
    }

    fn frame(&self, k: usize, t_s: f64) -> Result<Frame> {
        let path = &self.frames[k];
        let (image, _) = io::load_rgb(path).with_context(|| format!("frame {}", path.display()))?;
        let depth = match &self.depth {
            Some((d, units, scale)) => {
                Some(DepthMap { depth: io::load_depth(&sibling(d, path, "depth")?, *scale)?, units: *units })
            }
            None => None,
        };
        let flow = match &self.flow {
            Some(d) => Some(io::load_flow(&sibling(d, path, "flow")?)?),
            None => None,
        };
        Ok(Frame { index: self.numbers[k], t_s, image, depth, flow })
    }

    /// Feed every frame at its time (from the start of the call) until `stop`,
    /// wait for the worker's last fit, then stop the worker and finish the
    /// recording. `done` is set when the frames have ended (the frame loop's exit).
    pub fn run(self, stop: &AtomicBool, done: &AtomicBool) -> Result<FeedSummary> {
        let start = Instant::now();
        let t0 = self.t_s(self.numbers[0]);
        let (mut offered, mut skipped, mut pushed_rows) = (0u64, 0u64, 0usize);
        let mut failure = None;
        let mut panel = CalibrationStatus::new(self.tier.name());
        let mut refreshed: Option<Instant> = None;
        for k in 0..self.frames.len() {
            if refreshed.map_or(true, |t| t.elapsed() >= STATUS_EVERY) {
                let now = Instant::now();
                refreshed = Some(now);
                let lines = panel.lines(now, offered, &self.worker.status(), self.recording.as_ref().map(|r| r.dir()));
                *self.status.lock().unwrap_or_else(|e| e.into_inner()) = lines;
            }
            let n = self.numbers[k];
            let t_s = self.t_s(n);
            let due = start + Duration::from_secs_f64((t_s - t0).max(0.0));
            while !stop.load(Ordering::SeqCst) && Instant::now() < due {
                std::thread::sleep((due - Instant::now()).min(Duration::from_millis(20)));
            }
            if stop.load(Ordering::SeqCst) {
                break;
            }
            let new: Vec<_> = match &self.poses {
                Some(rows) => {
                    let upto = rows.partition_point(|r| r.frame <= n + POSE_LEAD);
                    let v = rows[pushed_rows.min(upto)..upto].iter().map(|r| r.pose).collect();
                    pushed_rows = pushed_rows.max(upto);
                    v
                }
                None => vec![],
            };
            offered += 1;
            if !self.worker.wants_frame() {
                skipped += 1;
                self.worker.submit_poses(&new);
                continue;
            }
            match self.frame(k, t_s) {
                Ok(f) => self.worker.submit(f, &new),
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
        // The last frame's fit (its status shown), then the frame loop may end.
        self.worker.wait_idle(Duration::from_secs(120));
        let lines =
            panel.lines(Instant::now(), offered, &self.worker.status(), self.recording.as_ref().map(|r| r.dir()));
        *self.status.lock().unwrap_or_else(|e| e.into_inner()) = lines;
        done.store(true, Ordering::SeqCst);
        let stats = self.worker.stop();
        let recording = self.recording.map(|r| r.finish()).transpose()?;
        if let Some(e) = failure {
            return Err(e);
        }
        Ok(FeedSummary { offered, skipped, stats, recording })
    }
}
