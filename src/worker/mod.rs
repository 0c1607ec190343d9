//! The calibration worker: camera frames in, validated camera-model snapshots out,
//! never blocking the frame loop.
//! * `channel`: the lock-free hand-off of immutable snapshots to the renderer;
//! * `calibrator`: the calibration loop itself (analysis → fit → aggregation →
//!   change detection), plain code that `calibrate` runs over recordings;
//! * `thread`: that loop on a low-priority thread fed through a latest-frame slot.

pub mod calibrator;
mod channel;
pub mod thread;

pub use calibrator::{
    CalibError, CalibrationTier, Calibrator, CalibratorConfig, Event, Phase, Providers, Update, UpdateReason,
};
pub use channel::{ModelChannel, Snapshot};
pub use thread::{Published, Tap, Worker, WorkerStats, WorkerStatus};
