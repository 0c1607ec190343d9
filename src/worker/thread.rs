//! The calibrator on its own thread at background priority (nice 19 on desktop
//! Linux and Android: `setpriority` per thread, through `thread-priority`; its
//! data-parallel fits on a pool of its own whose threads are lowered too), fed
//! through a latest-frame slot: `submit` replaces a frame the worker has not
//! taken yet (counted as dropped), so a slow fit never queues frames without
//! bound and the submitting thread (camera callback, frame loop) only ever holds
//! the slot's lock for a swap. Poses are never dropped (they are small and the
//! track needs them all); their queue is bounded at `MAX_QUEUED_POSES`, oldest
//! first out. Models go out through `ModelChannel::publish` (validated, lock-free
//! for the reader). A `Tap` (a recording) sees what the worker takes and
//! publishes, on the worker's thread: it is installed through the slot, so the
//! frame loop that starts or stops one holds the slot's lock only for a swap.

use super::calibrator::{Calibrator, Event, Phase};
use super::ModelChannel;
use crate::analysis::timing::TimedPose;
use crate::analysis::Frame;
use crate::model::CameraModel;
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

const MAX_QUEUED_POSES: usize = 4096;
/// Poses a new tap starts with: about 1.4 s of a 90 Hz head track.
const RECENT_POSES: usize = 128;

/// What sees the worker's input and output on its own thread: a recording
/// (`io::recording`). Called before each frame is fitted and after each model
/// is published; a slow tap slows the worker (never the frame loop).
pub trait Tap: Send {
    /// A frame the worker took (None: poses arrived alone), with the poses taken
    /// with it, before it is fitted.
    fn taken(&mut self, frame: Option<&Frame>, poses: &[TimedPose]);
    /// A model the worker published, with the frame and time it belongs to.
    fn published(&mut self, frame: u64, t_s: f64, generation: u64, model: &CameraModel);
}

#[derive(Default)]
struct Slot {
    frame: Option<Frame>,
    poses: Vec<TimedPose>,
    submitted: u64,
    dropped: u64,
    busy: bool,
    stop: bool,
    /// A tap to install (Some(None): remove the current one) at the worker's next
    /// turn.
    tap_change: Option<Option<Box<dyn Tap>>>,
    /// Restart the calibration (`Calibrator::restart`) at the worker's next turn.
    restart: bool,
    /// What the worker has done so far (`Worker::status`), updated after each turn.
    progress: WorkerStatus,
}

struct Shared {
    slot: Mutex<Slot>,
    wake: Condvar,
    idle: Condvar,
}

/// One published model as the worker saw it.
#[derive(Clone, Debug)]
pub struct Published {
    pub frame: u64,
    pub t_s: f64,
    pub generation: u64,
    pub compute_s: f64,
    /// Wall time since the worker started.
    pub at_s: f64,
}

/// What the worker did, returned by `stop`.
#[derive(Clone, Debug, Default)]
pub struct WorkerStats {
    pub submitted: u64,
    pub dropped: u64,
    pub processed: u64,
    pub published: Vec<Published>,
    /// Frames refused (bad input) and provider problems, as logged.
    pub errors: Vec<String>,
    /// Why the thread's priority could not be lowered (None: it was).
    pub priority_error: Option<String>,
    /// Restarts asked for (`Worker::restart`).
    pub restarts: u64,
}

/// What the worker has done so far, read while it runs (`Worker::status`: the
/// headset's status panel).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WorkerStatus {
    /// Frames handed over, and those replaced before the worker took them.
    pub submitted: u64,
    pub dropped: u64,
    /// Frames fitted, models published, frames and models refused.
    pub processed: u64,
    pub published: u64,
    pub errors: u64,
    pub restarts: u64,
    pub phase: Phase,
}

pub struct Worker {
    shared: Arc<Shared>,
    handle: Option<JoinHandle<WorkerStats>>,
}

fn lock(m: &Mutex<Slot>) -> std::sync::MutexGuard<'_, Slot> {
    // A panic on the worker thread poisons the lock; the slot's data stay valid
    // (plain values), so carry on rather than propagate the panic.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Worker {
    /// Start `calibrator` on a background thread publishing into `channel`.
    pub fn spawn(mut calibrator: Calibrator, channel: ModelChannel) -> std::io::Result<Worker> {
        let shared = Arc::new(Shared { slot: Mutex::new(Slot::default()), wake: Condvar::new(), idle: Condvar::new() });
        let s = shared.clone();
        let handle = std::thread::Builder::new().name("calibration".into()).spawn(move || {
            let started = Instant::now();
            let mut stats = WorkerStats {
                priority_error: thread_priority::set_current_thread_priority(thread_priority::ThreadPriority::Min)
                    .err()
                    .map(|e| format!("{e:?}")),
                ..Default::default()
            };
            if let Some(e) = &stats.priority_error {
                log::warn!("calibration thread: could not lower its priority ({e}); running at normal priority");
            }
            // The fits are data-parallel (rayon). Run on the global pool they would
            // execute on its threads at normal priority, whatever this thread's; so
            // the calibrator gets its own pool whose threads lower themselves too.
            let pool = rayon::ThreadPoolBuilder::new()
                .thread_name(|i| format!("calibration-{i}"))
                .start_handler(|_| {
                    if let Err(e) = thread_priority::set_current_thread_priority(thread_priority::ThreadPriority::Min) {
                        log::warn!("calibration pool thread: could not lower its priority ({e:?})");
                    }
                })
                .build();
            let pool = match pool {
                Ok(p) => Some(p),
                Err(e) => {
                    log::warn!("calibration: no background thread pool ({e}); fits run on the shared pool");
                    None
                }
            };
            let mut tap: Option<Box<dyn Tap>> = None;
            // The newest poses taken: a new tap gets them first, so frames taken
            // right after it is installed (a camera frame lags the head poses by
            // its pipeline's latency) lie within the poses it has.
            let mut recent: std::collections::VecDeque<TimedPose> = std::collections::VecDeque::new();
            loop {
                let (frame, poses, change, restart) = {
                    let mut slot = lock(&s.slot);
                    slot.busy = false;
                    slot.progress = WorkerStatus {
                        processed: stats.processed,
                        published: stats.published.len() as u64,
                        errors: stats.errors.len() as u64,
                        restarts: stats.restarts,
                        phase: calibrator.phase(),
                        ..slot.progress
                    };
                    s.idle.notify_all();
                    while slot.frame.is_none() && !slot.stop && slot.tap_change.is_none() && !slot.restart {
                        slot = s.wake.wait(slot).unwrap_or_else(|p| p.into_inner());
                    }
                    if slot.stop {
                        stats.submitted = slot.submitted;
                        stats.dropped = slot.dropped;
                        break;
                    }
                    slot.busy = true;
                    let restart = std::mem::take(&mut slot.restart);
                    (slot.frame.take(), std::mem::take(&mut slot.poses), slot.tap_change.take(), restart)
                };
                if restart {
                    calibrator.restart();
                    stats.restarts += 1;
                    log::info!("calibration: restarted (start-up burst on the next frame)");
                }
                // The old tap is dropped here, on this thread: a recording's writer
                // learns that its input ended.
                if let Some(t) = change {
                    tap = t;
                    if let Some(t) = tap.as_mut() {
                        if !recent.is_empty() {
                            t.taken(None, recent.make_contiguous());
                        }
                    }
                }
                recent.extend(poses.iter().copied());
                let excess = recent.len().saturating_sub(RECENT_POSES);
                recent.drain(..excess);
                if let Some(t) = tap.as_mut() {
                    if frame.is_some() || !poses.is_empty() {
                        t.taken(frame.as_ref(), &poses);
                    }
                }
                match calibrator.push_poses(&poses) {
                    Ok(events) => log_events(&events, &mut stats),
                    Err(e) => {
                        log::warn!("calibration: poses refused: {e}");
                        stats.errors.push(e.to_string());
                    }
                }
                let Some(frame) = frame else { continue };
                let index = frame.index;
                let result = match &pool {
                    Some(p) => p.install(|| calibrator.push_frame(frame)),
                    None => calibrator.push_frame(frame),
                };
                match result {
                    Ok(events) => {
                        stats.processed += 1;
                        for e in &events {
                            if let Event::Published(u) = e {
                                match channel.publish(u.model.clone()) {
                                    Ok(generation) => {
                                        if let Some(t) = tap.as_mut() {
                                            t.published(u.frame, u.t_s, generation, &u.model);
                                        }
                                        stats.published.push(Published {
                                            frame: u.frame,
                                            t_s: u.t_s,
                                            generation,
                                            compute_s: u.compute_s,
                                            at_s: started.elapsed().as_secs_f64(),
                                        })
                                    }
                                    Err(e) => {
                                        log::error!(
                                            "calibration: model of frame {} refused by validation: {e}",
                                            u.frame
                                        );
                                        stats.errors.push(e.to_string());
                                    }
                                }
                            }
                        }
                        log_events(&events, &mut stats);
                    }
                    Err(e) => {
                        log::warn!("calibration: frame {index} skipped: {e}");
                        stats.errors.push(e.to_string());
                    }
                }
            }
            stats
        })?;
        Ok(Worker { shared, handle: Some(handle) })
    }

    /// Hand over the newest frame and the poses known since the last call. Never
    /// waits for the worker: a frame it has not taken yet is replaced (dropped).
    pub fn submit(&self, frame: Frame, poses: &[TimedPose]) {
        let mut slot = lock(&self.shared.slot);
        slot.submitted += 1;
        if slot.frame.replace(frame).is_some() {
            slot.dropped += 1;
        }
        slot.poses.extend_from_slice(poses);
        let excess = slot.poses.len().saturating_sub(MAX_QUEUED_POSES);
        slot.poses.drain(..excess);
        drop(slot);
        self.shared.wake.notify_one();
    }

    /// Poses alone (the frame loop's head poses between camera frames); bounded
    /// like those `submit` carries.
    pub fn submit_poses(&self, poses: &[TimedPose]) {
        let mut slot = lock(&self.shared.slot);
        slot.poses.extend_from_slice(poses);
        let excess = slot.poses.len().saturating_sub(MAX_QUEUED_POSES);
        slot.poses.drain(..excess);
    }

    /// Install a tap (a recording) or, with None, remove the current one; the
    /// worker makes the change at its next turn (after the fit in progress) and
    /// drops the tap it replaces on its own thread. Never waits for the worker.
    pub fn set_tap(&self, tap: Option<Box<dyn Tap>>) {
        lock(&self.shared.slot).tap_change = Some(tap);
        self.shared.wake.notify_one();
    }

    /// Restart the calibration from scratch at the worker's next turn (after the
    /// fit in progress); never waits for the worker.
    pub fn restart(&self) {
        lock(&self.shared.slot).restart = true;
        self.shared.wake.notify_one();
    }

    /// What the worker has done so far (as of the end of its last turn) and the
    /// frames handed over; holds the slot's lock only to copy it.
    pub fn status(&self) -> WorkerStatus {
        let slot = lock(&self.shared.slot);
        WorkerStatus { submitted: slot.submitted, dropped: slot.dropped, ..slot.progress }
    }

    /// Whether the worker would take a frame now (none waiting, no fit running):
    /// a producer whose frames cost something to make (YUV → RGB) makes them only
    /// then, instead of making frames the slot would drop.
    pub fn wants_frame(&self) -> bool {
        let slot = lock(&self.shared.slot);
        slot.frame.is_none() && !slot.busy && !slot.stop
    }

    /// Wait until the worker has taken and finished every submitted frame (tests,
    /// recordings); false on timeout.
    pub fn wait_idle(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        let mut slot = lock(&self.shared.slot);
        while slot.frame.is_some() || slot.busy {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            slot = self.shared.idle.wait_timeout(slot, left).map(|r| r.0).unwrap_or_else(|p| p.into_inner().0);
        }
        true
    }

    /// Stop after the current fit and return what the worker did.
    pub fn stop(mut self) -> WorkerStats {
        self.shutdown()
    }

    fn shutdown(&mut self) -> WorkerStats {
        lock(&self.shared.slot).stop = true;
        self.shared.wake.notify_all();
        match self.handle.take().map(|h| h.join()) {
            Some(Ok(stats)) => stats,
            Some(Err(_)) => {
                WorkerStats { errors: vec!["the calibration thread panicked".into()], ..Default::default() }
            }
            None => WorkerStats::default(),
        }
    }
}

impl Drop for Worker {
    /// The thread must not outlive the channel's users unnoticed: stop and join.
    fn drop(&mut self) {
        if self.handle.is_some() {
            self.shutdown();
        }
    }
}

fn log_events(events: &[Event], stats: &mut WorkerStats) {
    for e in events {
        match e {
            Event::Published(u) => {
                log::debug!("calibration: published the model of frame {} ({:?})", u.frame, u.reason)
            }
            Event::Degraded { frame, reason } => log::debug!("calibration: frame {frame}: {reason}"),
            Event::Skipped { frame, reason } => {
                log::info!("calibration: frame {frame} skipped: {reason}");
                stats.errors.push(format!("frame {frame}: {reason}"));
            }
            Event::ChangeDetected { frame, cause, .. } => {
                log::info!("calibration: camera change at frame {frame}: {cause}")
            }
            Event::TrackingLoss { t_s, reason } => log::warn!("calibration: tracking loss at {t_s:.3} s: {reason}"),
        }
    }
}
