//! Blind depth of field pooled over views: the edge samples of the blind DoF fits
//! of frames taken with the head at rest, one δ(Z) curve on all of them
//! (`fit::fit_fast_pooled`). A fixed-focus camera has one δ(Z); each view sees a
//! different slice of depths.

use super::*;

/// One blind DoF fit's edge samples, kept for the pooled fit (`Calibrator::pool_dof`).
#[derive(Debug)]
pub(super) struct PooledEdges {
    t_s: f64,
    units: crate::model::DepthUnits,
    kernel: crate::model::DofKernel,
    edges: fit::DofPlotData,
}

/// How long a blind DoF fit's edge samples stay in the pool (s of video), and the
/// most frames it holds. A fixed-focus camera's δ(Z) only changes with a detected
/// change (which empties the pool from then back), so the pool may reach past the
/// aggregation window: 3 s of a head looking around are several views.
const DOF_POOL_S: f64 = 3.0;
const DOF_POOL_FRAMES: usize = 32;
/// Most motion (px per frame interval, over the sparse grid) of a frame whose
/// edges enter the DoF pool. Motion blur widens every edge across the flow's
/// direction: on the calibration video at 1280×960 (λ = 0.5, turns of 7–37
/// px/frame) mid-turn frames read δ 0.4–1 px high. At 1 px/frame the streak (≤ 1
/// px, variance ≤ 1/12 px²) moves a 2 px edge by ≤ 0.02 px. Frames without a
/// sparse flow (no pose or depth) count as at rest: nothing says otherwise.
const DOF_POOL_MAX_MOTION_PX: f32 = 1.0;

/// Whether `a`'s edges may enter the DoF pool (`DOF_POOL_MAX_MOTION_PX`).
pub(super) fn dof_still(a: &Analysed) -> bool {
    a.max_motion_px().map_or(true, |m| m <= DOF_POOL_MAX_MOTION_PX)
}

impl Calibrator {
    /// The pooled blind δ(Z) (`fit::fit_fast_pooled`) replaces this frame's own: one
    /// curve on the edge samples of every blind fit of the last `DOF_POOL_S` taken
    /// with the head at rest (`dof_still`), with this frame's depth units and kernel
    /// (older or other entries dropped; at most `DOF_POOL_FRAMES`). `edges`: this
    /// frame's samples, if it is at rest. With the pool empty and the frame moving,
    /// the frame's own curve stands. The pooled fit's time counts with the DoF fit's.
    pub(super) fn pool_dof(&mut self, t_s: f64, edges: Option<fit::DofPlotData>, model: &mut CameraModel) {
        // A frame whose own fit found no curve says nothing of the kernel: the
        // pool's newest entry does (else one failed frame would empty a disc pool).
        let own_curve = model.depth_of_field.curve.is_some();
        let (units, kernel) = match self.dof_pool.back().filter(|_| !own_curve) {
            Some(p) => (p.units, p.kernel),
            None => (model.depth_of_field.units, model.depth_of_field.kernel),
        };
        if let Some(edges) = edges.filter(|_| own_curve) {
            self.dof_pool.push_back(PooledEdges { t_s, units, kernel, edges });
        }
        self.dof_pool.retain(|p| t_s - p.t_s <= DOF_POOL_S && p.units == units && p.kernel == kernel);
        while self.dof_pool.len() > DOF_POOL_FRAMES {
            self.dof_pool.pop_front();
        }
        // One frame in the pool: the frame's own fit when it is that frame.
        if self.dof_pool.is_empty() || (self.dof_pool.len() == 1 && self.dof_pool[0].t_s == t_s) {
            return;
        }
        let frames: Vec<&fit::DofPlotData> = self.dof_pool.iter().map(|p| &p.edges).collect();
        let (mut pooled, _) = fit::fit_fast_pooled(&frames, units, kernel);
        if pooled.curve.is_some() {
            let own = &model.depth_of_field.diagnostics;
            pooled.diagnostics.fit_time_s += own.fit_time_s;
            pooled.diagnostics.reason = format!("{}; this frame alone: {}", pooled.diagnostics.reason, own.reason);
            model.depth_of_field = pooled;
        }
    }

    /// Drop the pooled edges of frames before `since_s` (a detected camera change).
    pub(super) fn forget_dof_before(&mut self, since_s: f64) {
        self.dof_pool.retain(|p| p.t_s >= since_s);
    }
}
