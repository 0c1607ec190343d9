//! The hand-off between the calibration thread and the frame loop: immutable
//! `CameraModel` snapshots, published lock-free. The worker calls `publish` whenever
//! a refit lands; the frame loop calls `latest` once per frame and uses that one
//! snapshot for the whole frame, so a frame can never see half of one model and half
//! of another, and never blocks on the worker. (The calibration thread itself —
//! frames in, fits out, at low priority — builds on this.)

use crate::model::{CameraModel, GrainTable, ModelError};
use arc_swap::ArcSwap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// One published model and its generation (1, 2, ... in publication order), with
/// what the renderer derives from it once (the grain synthesis table, computed on
/// the publishing thread, never in the frame loop).
#[derive(Debug)]
pub struct Snapshot {
    pub generation: u64,
    pub model: CameraModel,
    /// Synthesis weights of `model.noise` (None when noise is absent).
    pub grain: Option<GrainTable>,
}

impl Snapshot {
    pub fn new(generation: u64, model: CameraModel) -> Self {
        let grain = model.noise.present.then(|| {
            let t = crate::synth::SynthesisTable::new(&model.noise);
            GrainTable { luma_range: t.luma_range(), nodes: t.nodes() as u32, weights: t.weights_flat() }
        });
        Self { generation, model, grain }
    }
}

/// Cloneable handle shared by the publisher (worker) and the reader (frame loop).
#[derive(Clone)]
pub struct ModelChannel {
    current: Arc<ArcSwap<Snapshot>>,
    generations: Arc<AtomicU64>,
}

impl ModelChannel {
    /// Start with `initial` as generation 0 (validated: nothing invalid is ever published).
    pub fn new(initial: CameraModel) -> Result<Self, ModelError> {
        initial.validate()?;
        Ok(Self {
            current: Arc::new(ArcSwap::from_pointee(Snapshot::new(0, initial))),
            generations: Arc::new(AtomicU64::new(0)),
        })
    }

    /// Validate and publish `model`; returns its generation. Readers see it from
    /// their next `latest` on.
    pub fn publish(&self, model: CameraModel) -> Result<u64, ModelError> {
        model.validate()?;
        let generation = self.generations.fetch_add(1, Ordering::SeqCst) + 1;
        self.current.store(Arc::new(Snapshot::new(generation, model)));
        Ok(generation)
    }

    /// The newest snapshot (lock-free; the Arc keeps it alive while in use).
    pub fn latest(&self) -> Arc<Snapshot> {
        self.current.load_full()
    }
}
