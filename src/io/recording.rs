//! Recordings of what the calibration worker takes, written in exactly
//! `blind-augment calibrate`'s input layout, so a sequence seen live on the
//! headset (or by `blind-augment xr --camera-frames`) replays on the desktop:
//!
//! ```text
//! frames/NNNNNN.png     each frame the worker took, 16-bit RGB, named by its camera
//!                       frame number (gaps: frames the worker dropped while busy)
//! depth/NNNNNN.npy      the depth delivered with it (float32 H×W; units in the manifest)
//! poses.csv             world_from_camera at each frame's time (io::poses's format),
//!                       interpolated on the pose track the worker received
//! pose_track.csv        every pose the worker received: t_s,tx,ty,tz,qx,qy,qz,qw
//!                       (`calibrate --pose-track`: the replay's calibrator gets
//!                       the live one's track, not one pose per recorded frame)
//! intrinsics.txt        fx,fy,cx,cy of the frames
//! timeline.jsonl        every model published while recording: {"frame","t_s","model"}
//! manifest.json         device, app version, camera, stream size, clock, why it stopped,
//!                       and the `calibrate` command that replays it
//! ```
//!
//! Frames are written on a thread of the recording's own; the worker hands them
//! over through a short queue and waits only when the disk falls that far behind
//! (the frame loop never waits: it only swaps the tap in the worker's slot).
//! Before every frame the free space of the recording's file system is read
//! (statvfs); under `RecordLimits::min_free_bytes` the recording stops and says
//! so, keeping everything written until then consistent.

use super::poses::{format_pose_track_csv, format_poses_csv, PoseRow};
use crate::analysis::timing::{PoseTrack, TimedPose};
use crate::analysis::{Frame, Intrinsics};
use crate::model::{CameraModel, DepthUnits};
use crate::worker::{Tap, Worker};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

/// What the manifest says about where the frames came from.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct RecordingInfo {
    /// e.g. "Oculus Quest 3 (eureka)", "desktop".
    pub device: String,
    pub app_version: String,
    /// The camera's id (Camera2) or the folder the frames came from.
    pub camera_id: String,
    /// The camera stream's size (px).
    pub stream_size: (u32, u32),
    /// What frame times are measured on (e.g. "REALTIME → XrTime", "file rate").
    pub timestamps: String,
    /// The nominal frame interval (s): `calibrate --fps` is its inverse.
    pub frame_interval_s: f64,
    pub intrinsics: Option<Intrinsics>,
    /// The calibration tier running live.
    pub tier: String,
}

/// When a recording stops by itself.
#[derive(Clone, Copy, Debug)]
pub struct RecordLimits {
    /// Video time from the first recorded frame (s).
    pub max_s: f64,
    /// Stop when the file system holds less than this (bytes).
    pub min_free_bytes: u64,
}

impl Default for RecordLimits {
    fn default() -> Self {
        // 10 s of a 30 Hz camera the worker takes a third of: ~100 frames of
        // ~4 MB (1280×960, 16-bit PNG). 512 MiB left for the system and the user.
        Self { max_s: 10.0, min_free_bytes: 512 << 20 }
    }
}

/// Why a recording ended.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// The worker stopped feeding it (stopped by the user, or the app ended).
    Stopped,
    /// `RecordLimits::max_s` of video recorded.
    Duration,
    /// The file system had less than `RecordLimits::min_free_bytes` free.
    LowStorage { free_bytes: u64 },
    /// A write failed; what was written before stays.
    WriteError { message: String },
}

/// `manifest.json`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Manifest {
    /// This layout's version.
    pub format: u32,
    #[serde(flatten)]
    pub info: RecordingInfo,
    pub frames: u64,
    /// Camera frame numbers of the first and last recorded frame.
    pub first_frame: Option<u64>,
    pub last_frame: Option<u64>,
    pub first_t_s: Option<f64>,
    pub last_t_s: Option<f64>,
    pub frames_with_depth: u64,
    pub depth_units: Option<DepthUnits>,
    pub poses_received: u64,
    /// poses.csv was written (every frame lies within the pose track).
    pub poses_csv: bool,
    pub models_published: u64,
    pub stopped: StopReason,
    /// Notes: frames without poses, a depth unit change, …
    pub notes: Vec<String>,
    /// The command that replays the recording from inside its folder.
    pub calibrate: String,
}

pub const MANIFEST_FORMAT: u32 = 1;

#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    #[error("recording folder {path}: {problem}")]
    Folder { path: PathBuf, problem: String },
    #[error("recording {path}: the writer thread could not start: {source}")]
    Thread { path: PathBuf, source: std::io::Error },
    #[error("recording {path}: the writer thread panicked")]
    Panicked { path: PathBuf },
}

enum Item {
    Frame(Box<Frame>),
    Poses(Vec<TimedPose>),
    Model { frame: u64, t_s: f64, model: Box<CameraModel> },
}

/// Frames the worker may hand over before it waits for the disk.
const QUEUE: usize = 4;

/// The worker's side of a recording: forwards what it takes. Dropping it (the
/// worker replaced or removed the tap, or stopped) ends the recording.
pub struct RecordingTap {
    tx: SyncSender<Item>,
    /// The writer has stopped (a limit, storage, an error): nothing more is copied.
    closed: bool,
}

impl RecordingTap {
    fn send(&mut self, item: Item) {
        // A send fails only once the writer has stopped and dropped its end: the
        // recording is over and the rest is not wanted.
        if !self.closed && self.tx.send(item).is_err() {
            self.closed = true;
        }
    }
}

impl Tap for RecordingTap {
    fn taken(&mut self, frame: Option<&Frame>, poses: &[TimedPose]) {
        if !poses.is_empty() && !self.closed {
            self.send(Item::Poses(poses.to_vec()));
        }
        if let Some(f) = frame.filter(|_| !self.closed) {
            self.send(Item::Frame(Box::new(f.clone())));
        }
    }

    fn published(&mut self, frame: u64, t_s: f64, _generation: u64, model: &CameraModel) {
        if !self.closed {
            self.send(Item::Model { frame, t_s, model: Box::new(model.clone()) });
        }
    }
}

/// The owner's side: where it is written, and the writer to join.
pub struct Recording {
    dir: PathBuf,
    handle: Option<JoinHandle<Manifest>>,
}

impl Recording {
    /// Create `dir` (it must not hold a recording already) and start the writer.
    /// Install the returned tap with `Worker::set_tap`.
    pub fn start(
        dir: &Path,
        info: RecordingInfo,
        limits: RecordLimits,
    ) -> Result<(Recording, RecordingTap), RecordingError> {
        let folder = |problem: String| RecordingError::Folder { path: dir.to_path_buf(), problem };
        if !(limits.max_s > 0.0 && limits.max_s.is_finite()) {
            return Err(folder(format!("duration {} s: need a finite duration > 0", limits.max_s)));
        }
        if dir.join("manifest.json").exists() || dir.join("frames").exists() {
            return Err(folder("already holds a recording (manifest.json or frames/): choose a new folder".into()));
        }
        for sub in ["frames", "depth"] {
            std::fs::create_dir_all(dir.join(sub)).map_err(|e| folder(format!("cannot create {sub}/: {e}")))?;
        }
        let (tx, rx) = sync_channel(QUEUE);
        let writer = Writer::new(dir.to_path_buf(), info, limits);
        let handle = std::thread::Builder::new()
            .name("recording".into())
            .spawn(move || writer.run(rx))
            .map_err(|source| RecordingError::Thread { path: dir.to_path_buf(), source })?;
        Ok((Recording { dir: dir.to_path_buf(), handle: Some(handle) }, RecordingTap { tx, closed: false }))
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The writer has stopped (its tap was dropped, or a limit was reached):
    /// `finish` will not wait for more input.
    pub fn is_finished(&self) -> bool {
        self.handle.as_ref().map_or(true, |h| h.is_finished())
    }

    /// Wait for the writer (drop the tap first: remove it from the worker, or stop
    /// the worker) and return the manifest it wrote.
    pub fn finish(mut self) -> Result<Manifest, RecordingError> {
        match self.handle.take().map(|h| h.join()) {
            Some(Ok(m)) => Ok(m),
            _ => Err(RecordingError::Panicked { path: self.dir.clone() }),
        }
    }
}

/// Recordings started and stopped by the controller's record button: each a
/// new folder `recordings/rec-<unix milliseconds>` in the app's external files
/// folder (`adb pull`, or `cargo xtask pull-recording`), in `calibrate`'s input
/// layout. The headset app runs it on its camera thread; it never touches the
/// frame loop.
pub struct Recorder {
    root: Option<std::path::PathBuf>,
    info: RecordingInfo,
    current: Option<Recording>,
}

impl Recorder {
    pub fn new(root: Option<std::path::PathBuf>, info: RecordingInfo) -> Self {
        Self { root, info, current: None }
    }

    /// Act on `presses` record-button presses; end a recording that stopped by
    /// itself (duration, low storage).
    pub fn poll(&mut self, presses: u32, worker: &Worker) {
        if self.current.as_ref().is_some_and(|r| r.is_finished()) {
            self.stop(worker);
        }
        for _ in 0..presses {
            if self.current.is_some() {
                self.stop(worker);
            } else {
                self.start(worker);
            }
        }
    }

    pub fn start(&mut self, worker: &Worker) {
        self.start_with(worker, RecordLimits::default());
    }

    /// Start a recording that stops by itself at `limits` (an intent's duration).
    pub fn start_with(&mut self, worker: &Worker, limits: RecordLimits) {
        let Some(root) = &self.root else {
            log::warn!("recording: the app has no external files folder");
            return;
        };
        // Milliseconds: a stop and a new start within one second get two folders.
        let ms = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis());
        let dir = root.join(format!("rec-{ms}"));
        match Recording::start(&dir, self.info.clone(), limits) {
            Ok((rec, tap)) => {
                worker.set_tap(Some(Box::new(tap)));
                log::info!("recording into {}", dir.display());
                self.current = Some(rec);
            }
            Err(e) => log::warn!("recording not started: {e}"),
        }
    }

    pub fn stop(&mut self, worker: &Worker) {
        let Some(rec) = self.current.take() else { return };
        worker.set_tap(None);
        let dir = rec.dir().to_path_buf();
        // The worker drops the tap at its next turn; the writer then finishes.
        match rec.finish() {
            Ok(m) => log::info!(
                "recording {}: {} frames, {} models, stopped: {:?}",
                dir.display(),
                m.frames,
                m.models_published,
                m.stopped
            ),
            Err(e) => log::warn!("recording: {e}"),
        }
    }
}

impl Recorder {
    /// The recording in progress, if any.
    pub fn current(&self) -> Option<&Path> {
        self.current.as_ref().map(|r| r.dir())
    }
}

/// Free bytes for an unprivileged user on the file system holding `dir`.
fn free_bytes(dir: &Path) -> Option<u64> {
    let s = rustix::fs::statvfs(dir).ok()?;
    Some(s.f_bavail.saturating_mul(s.f_frsize))
}

struct Writer {
    dir: PathBuf,
    info: RecordingInfo,
    limits: RecordLimits,
    /// (camera frame number, t_s) of every recorded frame.
    frames: Vec<(u64, f64)>,
    poses: Vec<TimedPose>,
    depth_units: Option<DepthUnits>,
    frames_with_depth: u64,
    models: u64,
    timeline: Option<std::io::BufWriter<std::fs::File>>,
    notes: Vec<String>,
    stopped: Option<StopReason>,
}

impl Writer {
    fn new(dir: PathBuf, info: RecordingInfo, limits: RecordLimits) -> Self {
        Self {
            dir,
            info,
            limits,
            frames: vec![],
            poses: vec![],
            depth_units: None,
            frames_with_depth: 0,
            models: 0,
            timeline: None,
            notes: vec![],
            stopped: None,
        }
    }

    fn run(mut self, rx: Receiver<Item>) -> Manifest {
        // Until the tap is dropped, or a stop: then the receiver goes at once (the
        // tap's sends fail without waiting) and the files are closed now, not at
        // the user's next press.
        for item in rx {
            let r = match item {
                Item::Poses(p) => {
                    self.poses.extend(p);
                    Ok(())
                }
                Item::Frame(f) => self.frame(&f),
                Item::Model { frame, t_s, model } => self.model(frame, t_s, &model),
            };
            if let Err(message) = r {
                log::warn!("recording {}: {message}: stopped", self.dir.display());
                self.stopped = Some(StopReason::WriteError { message });
            }
            if self.stopped.is_some() {
                break;
            }
        }
        self.close()
    }

    fn frame(&mut self, f: &Frame) -> Result<(), String> {
        if let Some(&(_, t0)) = self.frames.first() {
            if f.t_s - t0 > self.limits.max_s {
                self.stopped = Some(StopReason::Duration);
                return Ok(());
            }
        }
        if let Some(free) = free_bytes(&self.dir) {
            if free < self.limits.min_free_bytes {
                log::warn!("recording {}: {free} bytes free: stopped", self.dir.display());
                self.stopped = Some(StopReason::LowStorage { free_bytes: free });
                return Ok(());
            }
        }
        if self.frames.last().is_some_and(|&(i, t)| f.index <= i || f.t_s <= t) {
            self.notes.push(format!("frame {} at {:.6} s does not follow the previous one: left out", f.index, f.t_s));
            return Ok(());
        }
        let name = format!("{:06}", f.index);
        let path = self.dir.join("frames").join(format!("{name}.png"));
        write_png16(&path, &f.image)?;
        if let Some(d) = &f.depth {
            match self.depth_units {
                Some(u) if u != d.units => self
                    .notes
                    .push(format!("frame {}: depth in {:?}, earlier frames in {u:?}: not kept", f.index, d.units)),
                _ => {
                    self.depth_units = Some(d.units);
                    let p = self.dir.join("depth").join(format!("{name}.npy"));
                    super::save_depth(&p, &d.depth).map_err(|e| e.to_string())?;
                    self.frames_with_depth += 1;
                }
            }
        }
        self.frames.push((f.index, f.t_s));
        Ok(())
    }

    fn model(&mut self, frame: u64, t_s: f64, model: &CameraModel) -> Result<(), String> {
        if self.frames.is_empty() {
            // Published from frames taken before the recording started.
            return Ok(());
        }
        if self.timeline.is_none() {
            let p = self.dir.join("timeline.jsonl");
            let f = std::fs::File::create(&p).map_err(|e| format!("{}: {e}", p.display()))?;
            self.timeline = Some(std::io::BufWriter::new(f));
        }
        let line = serde_json::json!({ "frame": frame, "t_s": t_s, "model": model });
        if let Some(tl) = self.timeline.as_mut() {
            writeln!(tl, "{line}").map_err(|e| format!("timeline.jsonl: {e}"))?;
        }
        self.models += 1;
        Ok(())
    }

    /// poses.csv (one row per frame, when the track covers every frame),
    /// pose_track.csv, intrinsics.txt, manifest.json.
    fn close(mut self) -> Manifest {
        let stopped = self.stopped.take().unwrap_or(StopReason::Stopped);
        let mut notes = std::mem::take(&mut self.notes);
        if let Some(tl) = self.timeline.as_mut() {
            if let Err(e) = tl.flush() {
                notes.push(format!("timeline.jsonl: {e}"));
            }
        }
        self.poses.sort_by_key(|p| p.t_ns);
        self.poses.dedup_by_key(|p| p.t_ns);
        let mut poses_csv = false;
        if !self.frames.is_empty() && !self.poses.is_empty() {
            match PoseTrack::new(self.poses.clone()) {
                Ok(track) => {
                    let rows: Vec<PoseRow> = self
                        .frames
                        .iter()
                        .filter_map(|&(frame, t_s)| {
                            track.at((t_s * 1e9).round() as i64).map(|pose| PoseRow { frame, t_s, pose })
                        })
                        .collect();
                    if rows.len() == self.frames.len() {
                        poses_csv = write_note(&self.dir.join("poses.csv"), &format_poses_csv(&rows), &mut notes);
                    } else {
                        notes.push(format!(
                            "poses.csv not written: {} of {} frames lie outside the pose track ({:.3}–{:.3} s)",
                            self.frames.len() - rows.len(),
                            self.frames.len(),
                            self.poses[0].t_ns as f64 * 1e-9,
                            self.poses[self.poses.len() - 1].t_ns as f64 * 1e-9
                        ));
                    }
                }
                Err(e) => notes.push(format!("poses.csv not written: {e}")),
            }
        }
        let track_csv = !self.poses.is_empty()
            && write_note(&self.dir.join("pose_track.csv"), &format_pose_track_csv(&self.poses), &mut notes);
        if let Some(k) = &self.info.intrinsics {
            write_note(&self.dir.join("intrinsics.txt"), &format!("{},{},{},{}\n", k.fx, k.fy, k.cx, k.cy), &mut notes);
        }
        let mut calibrate = format!(
            "blind-augment calibrate --frames frames --fps {} --tier {}",
            1.0 / self.info.frame_interval_s,
            self.info.tier
        );
        if self.frames_with_depth > 0 {
            let units = match self.depth_units {
                Some(DepthUnits::RelativeInverse) => "relative-inverse",
                _ => "metric-m",
            };
            calibrate += &format!(" --depth depth --depth-units {units}");
            // The headset's depth is not there for every frame: those go without,
            // as they did live.
            if self.frames_with_depth < self.frames.len() as u64 {
                calibrate += " --depth-optional";
            }
        }
        if let (true, Some(k)) = (poses_csv, &self.info.intrinsics) {
            calibrate += &format!(" --poses poses.csv --intrinsics {},{},{},{}", k.fx, k.fy, k.cx, k.cy);
            if track_csv {
                calibrate += " --pose-track pose_track.csv";
            }
        }
        calibrate += " --out model.json --timeline replay.jsonl";
        let m = Manifest {
            format: MANIFEST_FORMAT,
            info: self.info.clone(),
            frames: self.frames.len() as u64,
            first_frame: self.frames.first().map(|f| f.0),
            last_frame: self.frames.last().map(|f| f.0),
            first_t_s: self.frames.first().map(|f| f.1),
            last_t_s: self.frames.last().map(|f| f.1),
            frames_with_depth: self.frames_with_depth,
            depth_units: self.depth_units,
            poses_received: self.poses.len() as u64,
            poses_csv,
            models_published: self.models,
            stopped,
            notes,
            calibrate,
        };
        let path = self.dir.join("manifest.json");
        match serde_json::to_string_pretty(&m) {
            Ok(text) => {
                if let Err(e) = std::fs::write(&path, text) {
                    log::error!("recording {}: manifest.json not written: {e}", self.dir.display());
                }
            }
            Err(e) => log::error!("recording {}: manifest: {e}", self.dir.display()),
        }
        m
    }
}

fn write_note(path: &Path, text: &str, notes: &mut Vec<String>) -> bool {
    match std::fs::write(path, text) {
        Ok(()) => true,
        Err(e) => {
            notes.push(format!("{}: {e}", path.display()));
            false
        }
    }
}

/// 16-bit RGB PNG with fast compression: the worker's frames are floats (YUV
/// converted), which 8 bits would requantise; 16 bits keep them to 1/65535,
/// far below any camera's noise.
fn write_png16(path: &Path, img: &crate::image::Rgb) -> Result<(), String> {
    use image::ImageEncoder as _;
    let mut buf: Vec<u8> = Vec::with_capacity(img.len() * 6);
    for i in 0..img.len() {
        for c in 0..3 {
            let v = (img.channels[c][i].clamp(0.0, 1.0) * 65535.0).round() as u16;
            buf.extend_from_slice(&v.to_ne_bytes());
        }
    }
    let file = std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let enc = image::codecs::png::PngEncoder::new_with_quality(
        std::io::BufWriter::new(file),
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Sub,
    );
    enc.write_image(&buf, img.width as u32, img.height as u32, image::ExtendedColorType::Rgb16)
        .map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::DepthMap;
    use crate::image::{Plane, Rgb};
    use glam::{Quat, Vec3};

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ba_recording_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn info() -> RecordingInfo {
        RecordingInfo {
            device: "test".into(),
            app_version: "0".into(),
            camera_id: "50".into(),
            stream_size: (8, 6),
            timestamps: "test clock".into(),
            frame_interval_s: 0.1,
            intrinsics: Some(Intrinsics { fx: 10.0, fy: 10.0, cx: 4.0, cy: 3.0, width: 8, height: 6 }),
            tier: "fast".into(),
        }
    }

    fn frame(index: u64, depth: bool) -> Frame {
        let mut image = Rgb::new(8, 6, [0.0; 3]);
        for (i, v) in image.channels[1].iter_mut().enumerate() {
            *v = (i as f32 * 0.0173 + index as f32 * 0.01) % 1.0;
        }
        Frame {
            index,
            t_s: index as f64 * 0.1,
            image,
            depth: depth.then(|| DepthMap { depth: Plane::new(8, 6, 1.5), units: DepthUnits::MetricM }),
            flow: None,
        }
    }

    fn pose(t_s: f64) -> TimedPose {
        TimedPose {
            t_ns: (t_s * 1e9).round() as i64,
            position_m: Vec3::new(t_s as f32, 0.0, 0.0),
            orientation: Quat::from_rotation_y(t_s as f32),
        }
    }

    /// Frames with a gap (a frame the worker dropped), poses between frames, a
    /// model: everything lands in calibrate's layout and reads back.
    #[test]
    fn a_recording_round_trips_in_calibrates_layout() {
        let d = dir("round_trip");
        let (rec, mut tap) = Recording::start(&d, info(), RecordLimits { max_s: 100.0, min_free_bytes: 0 }).unwrap();
        let track: Vec<TimedPose> = (0..=12).map(|k| pose(k as f64 * 0.05)).collect();
        tap.taken(None, &track[..4]);
        tap.taken(Some(&frame(0, true)), &track[4..6]);
        tap.published(0, 0.0, 1, &CameraModel::empty(8, 6));
        tap.taken(Some(&frame(2, true)), &track[6..]);
        drop(tap);
        let m = rec.finish().unwrap();
        assert_eq!((m.frames, m.frames_with_depth, m.models_published), (2, 2, 1));
        assert_eq!((m.first_frame, m.last_frame, m.stopped.clone()), (Some(0), Some(2), StopReason::Stopped));
        assert!(m.poses_csv, "{:?}", m.notes);
        let (img, bits) = crate::io::load_rgb(&d.join("frames/000002.png")).unwrap();
        assert_eq!(bits, crate::io::BitDepth::Sixteen);
        let want = frame(2, false).image;
        // 16-bit PNG: within half a step of 1/65535.
        let worst = img.channels[1].iter().zip(&want.channels[1]).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert!(worst <= 0.5 / 65535.0 + 1e-7, "worst {worst}");
        let depth = crate::io::load_depth(&d.join("depth/000000.npy"), 1.0).unwrap();
        assert!(depth.data.iter().all(|&z| z == 1.5));
        let rows = crate::io::poses::read_poses_csv(&d.join("poses.csv")).unwrap();
        assert_eq!(rows.iter().map(|r| r.frame).collect::<Vec<_>>(), vec![0, 2]);
        // Frame 2 at 0.2 s is a knot of the track: its pose exactly.
        assert!((rows[1].pose.position_m.x - 0.2).abs() < 1e-6);
        let track_csv = std::fs::read_to_string(d.join("pose_track.csv")).unwrap();
        assert_eq!(track_csv.lines().count(), 1 + 13);
        assert_eq!(std::fs::read_to_string(d.join("intrinsics.txt")).unwrap().trim(), "10,10,4,3");
        let tl = std::fs::read_to_string(d.join("timeline.jsonl")).unwrap();
        let v: serde_json::Value = serde_json::from_str(tl.lines().next().unwrap()).unwrap();
        assert_eq!(v["frame"], 0);
        CameraModel::from_json(&v["model"].to_string()).unwrap();
        let read: Manifest = serde_json::from_str(&std::fs::read_to_string(d.join("manifest.json")).unwrap()).unwrap();
        assert_eq!(read.frames, 2);
        assert!(read.calibrate.contains("--poses poses.csv --intrinsics 10,10,4,3"), "{}", read.calibrate);
        assert!(read.calibrate.contains("--depth depth --depth-units metric-m"), "{}", read.calibrate);
        // A second recording into the same folder is refused, naming it.
        let again = Recording::start(&d, info(), RecordLimits::default());
        assert!(matches!(again, Err(RecordingError::Folder { .. })));
        let _ = std::fs::remove_dir_all(&d);
    }

    /// The record button's logic against a running worker: a press starts a
    /// recording of what the worker takes, the next press stops it and writes the
    /// manifest; a second recording goes to a new folder.
    #[test]
    fn the_record_button_records_what_the_worker_takes() {
        use crate::worker::{CalibrationTier, Calibrator, CalibratorConfig, ModelChannel, Providers};
        let root = dir("button");
        let channel = ModelChannel::new(CameraModel::empty(8, 6)).unwrap();
        let cfg = CalibratorConfig::new(CalibrationTier::Fast, 0.1, None);
        let worker =
            Worker::spawn(Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast)).unwrap(), channel).unwrap();
        let mut r = Recorder::new(Some(root.clone()), info());
        r.poll(1, &worker);
        let first = r.current().expect("recording").to_path_buf();
        for i in 0..3 {
            worker.submit(frame(i, false), &[pose(i as f64 * 0.1)]);
            assert!(worker.wait_idle(std::time::Duration::from_secs(30)));
        }
        r.poll(1, &worker);
        assert!(r.current().is_none());
        let m: Manifest = serde_json::from_str(&std::fs::read_to_string(first.join("manifest.json")).unwrap()).unwrap();
        assert_eq!((m.frames, m.stopped), (3, StopReason::Stopped));
        std::thread::sleep(std::time::Duration::from_millis(2));
        r.poll(1, &worker);
        let second = r.current().expect("a second recording").to_path_buf();
        assert_ne!(first, second);
        r.stop(&worker);
        drop(worker);
        let _ = std::fs::remove_dir_all(&root);
    }

    /// Too little free space: nothing is written, the manifest says why, and the
    /// tap never blocks the worker afterwards (the writer drains its queue).
    #[test]
    fn low_storage_stops_cleanly() {
        let d = dir("low_storage");
        let (rec, mut tap) =
            Recording::start(&d, info(), RecordLimits { max_s: 100.0, min_free_bytes: u64::MAX }).unwrap();
        for i in 0..(3 * QUEUE as u64) {
            tap.taken(Some(&frame(i, false)), &[pose(i as f64 * 0.1)]);
        }
        drop(tap);
        let m = rec.finish().unwrap();
        assert!(matches!(m.stopped, StopReason::LowStorage { .. }), "{:?}", m.stopped);
        assert_eq!(m.frames, 0);
        assert_eq!(std::fs::read_dir(d.join("frames")).unwrap().count(), 0);
        assert!(d.join("manifest.json").exists());
        let _ = std::fs::remove_dir_all(&d);
    }

    /// The duration limit counts video time from the first recorded frame, and
    /// ends the recording then: the manifest is written without waiting for the
    /// tap to go, and the tap stops copying frames.
    #[test]
    fn the_duration_limit_ends_the_recording() {
        let d = dir("duration");
        let (rec, mut tap) = Recording::start(&d, info(), RecordLimits { max_s: 0.25, min_free_bytes: 0 }).unwrap();
        for i in 0..6 {
            tap.taken(Some(&frame(i, i % 2 == 0)), &[]);
        }
        let until = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while !rec.is_finished() && std::time::Instant::now() < until {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        assert!(rec.is_finished(), "finished while the tap is still installed");
        assert!(d.join("manifest.json").exists());
        for i in 6..(3 * QUEUE as u64) {
            tap.taken(Some(&frame(i, false)), &[]);
        }
        assert!(tap.closed, "the tap learnt that the writer stopped");
        drop(tap);
        let m = rec.finish().unwrap();
        assert_eq!(m.stopped, StopReason::Duration);
        assert_eq!(m.frames, 3, "0, 0.1, 0.2 s are within 0.25 s of the first");
        assert!(!m.poses_csv, "no poses were received");
        assert!(!m.calibrate.contains("--poses"));
        assert_eq!(m.frames_with_depth, 2);
        assert!(m.calibrate.contains("--depth depth --depth-units metric-m --depth-optional"), "{}", m.calibrate);
        let bad = Recording::start(&dir("bad"), info(), RecordLimits { max_s: f64::NAN, min_free_bytes: 0 });
        assert!(matches!(bad, Err(RecordingError::Folder { .. })));
        let _ = std::fs::remove_dir_all(&d);
    }
}
