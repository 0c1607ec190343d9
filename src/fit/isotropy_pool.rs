//! Blind motion-blur exposure pooled over flow directions: the isotropy estimator's
//! along/across balance of several frames (or of one frame whose flow turns across
//! it), fitted jointly with the texture's own anisotropy.
//!
//! Why it can separate them: a sharp texture's gradient energy along a unit
//! direction u = (cos θ, sin θ) is uᵀJu, J its structure tensor, so the along/across
//! contrast of the isotropy estimator, r = (C − D)/(C + D), is exactly a second
//! harmonic of the flow direction, r(θ) = a·cos 2θ + b·sin 2θ (a = (J₁₁ − J₂₂)/tr J,
//! b = 2J₁₂/tr J). The streak turns with the flow, the texture does not: at the true
//! λ every direction's r lies on one harmonic, at a wrong λ the streak's share (r
//! rises with λ in every direction alike) does not. Directions 90° apart constrain λ
//! once (their harmonic terms cancel), three or more distinct directions K − 2 times.
//! One frame with uniform flow gives one direction: not identifiable here (the
//! single-frame estimator's prior band stands).
//!
//! Evidence per frame (`IsotropyEvidence`): samples binned by flow direction (mod
//! 180°), per bin the sums of C − D and C + D on a λ grid and their second moments
//! (each bin's sampling variance by the delta method). The pooled fit
//! (`fit_fast_pooled_exposure`) sums the frames' bins per direction (only different
//! directions are independent looks at the texture), then minimises over λ the
//! weighted residual of the bins' r(λ) about their best harmonic; weights
//! 1/(sampling variance + `HARMONIC_SCATTER`²), the scatter measured on photographs
//! (see `HARMONIC_SCATTER`). The standard error is the half-width of the
//! profile-likelihood interval (Δχ² = 1, scaled by χ²/dof where the residual
//! exceeds the modelled scatter): r is flat in λ near 0, where a Gauss–Newton
//! slope would claim nothing or too much.

use super::motion_blur::status::{exposure_status, exposure_status_note, MAX_ISOTROPY_HALF_BAND};
use crate::model::{Diagnostics, MotionBlur, Status};
use std::time::Instant;

/// λ grid of the evidence: λ_j = j / (GRID − 1). The sums are smooth in λ (each is
/// a sum over thousands of box means): a root of the cubic interpolation between
/// nodes 1/16 apart lies within 0.006 of the exact root (mean 0.0003; 194 frames of
/// photographs blurred along several flow directions), far inside the pooled λ's
/// standard error.
pub const GRID: usize = 17;
/// Direction bins over 180° (15° each): a turning flow spreads one frame's samples
/// over a few bins, each its own direction.
pub const DIRECTION_BINS: usize = 12;
/// Least samples a bin needs to enter the pooled fit: its sums are ratios of
/// heavy-tailed gradient energies.
const MIN_BIN_SAMPLES: usize = 64;
/// How far a bin's r(λ*) strays from the harmonic shared by all bins when the bins
/// see different content (different frames, different parts of the frame): the
/// standard deviation of r about its best second harmonic over directions, each
/// direction a different crop of a sharp photograph (astronaut, chelsea,
/// Motorcycle, 300×260 crops at 12 directions: rms 0.048, p90 0.079; one crop at
/// every direction: 0.003–0.009, the structure tensor's exact harmonic up to
/// sampling). Rounded up to 0.05.
const HARMONIC_SCATTER: f64 = 0.05;
/// Above this standard error the pooled λ is reported not identifiable: the single
/// frame's rule (a 90% band wider than half of [0, 1]) as a standard error.
const MAX_STDERR: f64 = MAX_ISOTROPY_HALF_BAND / 1.645;

/// One direction bin's sums over its samples at each grid λ: Δ = C − D and
/// S = C + D per sample (the sample's squared central differences along and across
/// its flow on the across-blurred frame).
#[derive(Clone, Debug)]
pub struct DirectionSums {
    pub samples: usize,
    /// Σ cos 2θ, Σ sin 2θ over the bin's samples (θ the flow's direction).
    pub cos2: f64,
    pub sin2: f64,
    /// Σ |F| over the bin's samples (px/frame): the streak length a λ means here.
    pub speed: f64,
    pub diff: [f64; GRID],
    pub sum: [f64; GRID],
    pub diff_sq: [f64; GRID],
    pub diff_sum: [f64; GRID],
    pub sum_sq: [f64; GRID],
}

impl Default for DirectionSums {
    fn default() -> Self {
        DirectionSums {
            samples: 0,
            cos2: 0.0,
            sin2: 0.0,
            speed: 0.0,
            diff: [0.0; GRID],
            sum: [0.0; GRID],
            diff_sq: [0.0; GRID],
            diff_sum: [0.0; GRID],
            sum_sq: [0.0; GRID],
        }
    }
}

/// One frame's isotropy evidence by flow direction (`DIRECTION_BINS` bins).
#[derive(Clone, Debug)]
pub struct IsotropyEvidence {
    pub bins: Vec<DirectionSums>,
}

impl Default for IsotropyEvidence {
    fn default() -> Self {
        IsotropyEvidence { bins: vec![DirectionSums::default(); DIRECTION_BINS] }
    }
}

impl IsotropyEvidence {
    /// Add one sample with flow (fx, fy) (non-zero) whose along/across energies at
    /// the grid's λs are `c[j]`, `d[j]`.
    pub(super) fn add(&mut self, fx: f32, fy: f32, c: &[f64; GRID], d: &[f64; GRID]) {
        let (fx, fy) = (fx as f64, fy as f64);
        let n2 = fx * fx + fy * fy;
        let (cos2, sin2) = ((fx * fx - fy * fy) / n2, 2.0 * fx * fy / n2);
        // 2θ ∈ (−π, π] → bin; a direction and its opposite share one.
        let t = (sin2.atan2(cos2) + std::f64::consts::PI) / std::f64::consts::TAU;
        let k = ((t * DIRECTION_BINS as f64) as usize).min(DIRECTION_BINS - 1);
        let b = &mut self.bins[k];
        b.samples += 1;
        b.cos2 += cos2;
        b.sin2 += sin2;
        b.speed += n2.sqrt();
        for j in 0..GRID {
            let (dl, s) = (c[j] - d[j], c[j] + d[j]);
            b.diff[j] += dl;
            b.sum[j] += s;
            b.diff_sq[j] += dl * dl;
            b.diff_sum[j] += dl * s;
            b.sum_sq[j] += s * s;
        }
    }

    /// Samples in bins the pooled fit reads.
    fn usable_samples(&self) -> usize {
        self.bins.iter().filter(|b| b.samples >= MIN_BIN_SAMPLES).map(|b| b.samples).sum()
    }

    /// The fastest mean flow speed (px/frame) of the bins the pooled fit reads (a
    /// streak's length per unit λ where it is longest; `None` without such a bin).
    fn fastest_bin_speed(&self) -> Option<f32> {
        self.bins
            .iter()
            .filter(|b| b.samples >= MIN_BIN_SAMPLES)
            .map(|b| (b.speed / b.samples as f64) as f32)
            .filter(|s| s.is_finite())
            .reduce(f32::max)
    }
}

/// Cubic (Catmull–Rom) interpolation of grid values at λ ∈ [0, 1]; one-sided
/// differences at the ends.
pub(super) fn interp(v: &[f64; GRID], lambda: f64) -> f64 {
    let m = (GRID - 1) as f64;
    let s = (lambda.clamp(0.0, 1.0) * m).min(m - 1e-9);
    let j = s as usize;
    let t = s - j as f64;
    let slope = |i: usize| -> f64 {
        if i == 0 {
            v[1] - v[0]
        } else if i == GRID - 1 {
            v[GRID - 1] - v[GRID - 2]
        } else {
            0.5 * (v[i + 1] - v[i - 1])
        }
    };
    let (p0, p1, m0, m1) = (v[j], v[j + 1], slope(j), slope(j + 1));
    let (t2, t3) = (t * t, t * t * t);
    (2.0 * t3 - 3.0 * t2 + 1.0) * p0 + (t3 - 2.0 * t2 + t) * m0 + (-2.0 * t3 + 3.0 * t2) * p1 + (t3 - t2) * m1
}

/// One bin as an observation: its direction (mean cos 2θ, sin 2θ) and r(λ) with
/// its sampling variance.
struct Observation<'a> {
    c: f64,
    s: f64,
    bin: &'a DirectionSums,
}

impl Observation<'_> {
    /// r(λ) = ΣΔ / ΣS and its delta-method variance Σ(Δᵢ − r·Sᵢ)² / (ΣS)².
    fn r(&self, lambda: f64) -> (f64, f64) {
        let b = self.bin;
        let (sd, ss) = (interp(&b.diff, lambda), interp(&b.sum, lambda));
        if ss <= 0.0 {
            return (0.0, f64::INFINITY);
        }
        let r = sd / ss;
        let (d2, ds, s2) = (interp(&b.diff_sq, lambda), interp(&b.diff_sum, lambda), interp(&b.sum_sq, lambda));
        let var = ((d2 - 2.0 * r * ds + r * r * s2) / (ss * ss)).max(0.0);
        (r, var)
    }
}

/// Weighted least squares of y on the harmonic columns (c, s): the residual sum of
/// squares, the fitted (a, b) and the columns' rank (a 2×2 normal matrix whose
/// smaller eigenvalue is below 1e-6 of its trace has rank 1: directions 0° and 90°
/// only, or one direction).
fn harmonic_fit(obs: &[Observation], y: &[f64], w: &[f64]) -> (f64, [f64; 2], usize) {
    let (mut ncc, mut ncs, mut nss, mut rc, mut rs) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (k, o) in obs.iter().enumerate() {
        ncc += w[k] * o.c * o.c;
        ncs += w[k] * o.c * o.s;
        nss += w[k] * o.s * o.s;
        rc += w[k] * o.c * y[k];
        rs += w[k] * o.s * y[k];
    }
    let tr = ncc + nss;
    let det = ncc * nss - ncs * ncs;
    let disc = (0.25 * (ncc - nss).powi(2) + ncs * ncs).sqrt();
    let small = 0.5 * tr - disc;
    let (ab, rank) = if tr <= 0.0 {
        ([0.0, 0.0], 0)
    } else if small <= 1e-6 * tr {
        // Rank 1: project on the large eigenvector e (N e = (tr − small) e).
        let big = tr - small;
        let e = if ncs.abs() > 1e-12 * tr {
            let (x, y) = (ncs, big - ncc);
            let n = (x * x + y * y).sqrt();
            [x / n, y / n]
        } else if ncc >= nss {
            [1.0, 0.0]
        } else {
            [0.0, 1.0]
        };
        let coef = (e[0] * rc + e[1] * rs) / big;
        ([coef * e[0], coef * e[1]], 1)
    } else {
        ([(nss * rc - ncs * rs) / det, (ncc * rs - ncs * rc) / det], 2)
    };
    let rss = obs.iter().enumerate().map(|(k, o)| w[k] * (y[k] - ab[0] * o.c - ab[1] * o.s).powi(2)).sum();
    (rss, ab, rank)
}

/// What the pooled fit found, for the probe and the tests.
#[derive(Clone, Debug)]
pub struct PooledExposure {
    pub lambda: f64,
    pub stderr: f64,
    /// Bins that entered, their distinct directions' rank (0–2) and the residual's
    /// degrees of freedom (bins − rank − 1).
    pub bins: usize,
    pub rank: usize,
    pub dof: usize,
    /// χ² per degree of freedom at λ (1 when the scatter is as modelled; NaN
    /// without a degree of freedom).
    pub chi2_per_dof: f64,
    /// The texture's harmonic (a, b) at λ: r = a·cos 2θ + b·sin 2θ.
    pub anisotropy: [f64; 2],
}

/// The frames' evidence summed per direction bin. Successive frames of a turning
/// head share much of their content, so only different directions count as
/// independent looks at the texture's harmonic (a bin per frame would let 30 frames
/// of two directions claim 15 times the evidence).
fn merge(frames: &[&IsotropyEvidence]) -> IsotropyEvidence {
    let mut merged = IsotropyEvidence::default();
    for f in frames {
        for (m, b) in merged.bins.iter_mut().zip(&f.bins) {
            m.samples += b.samples;
            m.cos2 += b.cos2;
            m.sin2 += b.sin2;
            m.speed += b.speed;
            for j in 0..GRID {
                m.diff[j] += b.diff[j];
                m.sum[j] += b.sum[j];
                m.diff_sq[j] += b.diff_sq[j];
                m.diff_sum[j] += b.diff_sum[j];
                m.sum_sq[j] += b.sum_sq[j];
            }
        }
    }
    merged
}

/// The joint fit of λ and the texture's anisotropy over every usable bin of
/// `frames`; `None` when no direction constrains λ (fewer bins than the harmonic
/// has parameters + 1, or no information left once it is profiled out).
pub fn pooled_exposure(frames: &[&IsotropyEvidence]) -> Option<PooledExposure> {
    let merged = merge(frames);
    let obs: Vec<Observation> = merged
        .bins
        .iter()
        .filter(|b| b.samples >= MIN_BIN_SAMPLES)
        .map(|b| Observation { c: b.cos2 / b.samples as f64, s: b.sin2 / b.samples as f64, bin: b })
        .collect();
    let kk = obs.len();
    if kk < 2 {
        return None;
    }
    let scatter2 = HARMONIC_SCATTER * HARMONIC_SCATTER;
    let eval = |lambda: f64| -> (f64, [f64; 2], usize, Vec<f64>, Vec<f64>) {
        let (mut y, mut w) = (Vec::with_capacity(kk), Vec::with_capacity(kk));
        for o in &obs {
            let (r, v) = o.r(lambda);
            y.push(r);
            w.push(1.0 / (v + scatter2));
        }
        let (rss, ab, rank) = harmonic_fit(&obs, &y, &w);
        (rss, ab, rank, y, w)
    };
    // A fine scan (the residual may have several dips where bins are few), then a
    // parabola through the best node and its neighbours.
    const SCAN: usize = 200;
    let rss: Vec<f64> = (0..=SCAN).map(|i| eval(i as f64 / SCAN as f64).0).collect();
    let best = (0..=SCAN).min_by(|&a, &b| rss[a].total_cmp(&rss[b]))?;
    let mut lambda = best as f64 / SCAN as f64;
    if best > 0 && best < SCAN {
        let (a, b, c) = (rss[best - 1], rss[best], rss[best + 1]);
        let den = a - 2.0 * b + c;
        if den > 0.0 {
            lambda += (0.5 * (a - c) / den).clamp(-0.5, 0.5) / SCAN as f64;
        }
    }
    let (rss_at, ab, rank, _, _) = eval(lambda);
    if kk <= rank {
        return None;
    }
    // The interval where the residual stays within one unit of χ² of its least
    // (scaled by χ²/dof where the scatter exceeds the modelled one): a profile
    // likelihood interval, honest where the Gauss–Newton slope is not — r is flat in
    // λ near 0 (a short box lowers gradient energy by ~L²), and at the ends of [0, 1].
    let dof = kk - rank - 1;
    let chi2_per_dof = if dof > 0 { rss_at / dof as f64 } else { f64::NAN };
    let inflate = if dof > 0 { chi2_per_dof.max(1.0) } else { 1.0 };
    let limit = rss_at.min(rss[best]) + inflate;
    let node = |i: usize| i as f64 / SCAN as f64;
    // The crossing between nodes i (inside) and o (outside), linear in the residual.
    let cross =
        |i: usize, o: usize| node(i) + (node(o) - node(i)) * ((limit - rss[i]) / (rss[o] - rss[i])).clamp(0.0, 1.0);
    let mut i = best;
    while i > 0 && rss[i - 1] <= limit {
        i -= 1;
    }
    let lo = if i == 0 { 0.0 } else { cross(i, i - 1) };
    let mut i = best;
    while i < SCAN && rss[i + 1] <= limit {
        i += 1;
    }
    let hi = if i == SCAN { 1.0 } else { cross(i, i + 1) };
    let stderr = (lambda - lo).max(hi - lambda).max(0.5 / SCAN as f64);
    Some(PooledExposure { lambda, stderr, bins: kk, rank, dof, chi2_per_dof, anisotropy: ab })
}

/// The pooled blind exposure as a motion-blur model: present / absent / not
/// identifiable by the single-frame rule (`motion_blur::exposure_status`, at the
/// fastest usable bin's mean speed), not identifiable too where no direction
/// constrains λ or its standard error exceeds `MAX_STDERR`.
pub fn fit_fast_pooled_exposure(frames: &[&IsotropyEvidence]) -> MotionBlur {
    let started = Instant::now();
    let merged = merge(frames);
    let (samples, speed) = (merged.usable_samples(), merged.fastest_bin_speed());
    let Some(p) = pooled_exposure(frames) else {
        let mut d = super::not_identifiable(
            "fast (pooled)",
            format!(
                "{} frames' isotropy evidence holds too few flow directions to separate the streak from the \
                 texture's own anisotropy",
                frames.len()
            ),
            started,
        );
        d.samples_used = samples as u64;
        return MotionBlur::absent(d);
    };
    let lambda = p.lambda.clamp(0.0, 1.0) as f32;
    let what = format!(
        "λ = {lambda:.4} ± {:.4} by gradient-energy isotropy pooled over {} frames ({} direction bins, rank {}, \
         {} residual degrees of freedom, χ²/dof {:.2}), fitted jointly with the texture's anisotropy (a {:.3}, b \
         {:.3})",
        p.stderr,
        frames.len(),
        p.bins,
        p.rank,
        p.dof,
        p.chi2_per_dof,
        p.anisotropy[0],
        p.anisotropy[1]
    );
    if p.stderr > MAX_STDERR {
        let mut d = super::not_identifiable(
            "fast (pooled)",
            format!("{what}: the directions constrain λ too weakly, not identifiable"),
            started,
        );
        d.samples_used = samples as u64;
        d.stderr = Some(p.stderr);
        return MotionBlur::absent(d);
    }
    let status = exposure_status(lambda, p.stderr, speed);
    MotionBlur {
        present: status == Status::Present,
        exposure: Some(lambda),
        diagnostics: Diagnostics {
            status,
            reason: format!("{what}; {}", exposure_status_note(status, speed)),
            method: "fast (pooled)".into(),
            residual_before: None,
            residual_after: None,
            samples_used: samples as u64,
            fit_time_s: started.elapsed().as_secs_f64(),
            stderr: Some(p.stderr),
            stages_s: Default::default(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Flow;
    use crate::synth::sequence::anisotropic_texture;

    /// Frames of the anisotropic texture (a new draw each) streaked by λ along the
    /// given directions (degrees), 12 px/frame; each frame's own isotropy root and
    /// evidence.
    fn frames(lambda: f32, dirs_deg: &[f32]) -> Vec<(f32, IsotropyEvidence)> {
        let (w, h) = (256, 256);
        dirs_deg
            .iter()
            .enumerate()
            .map(|(i, deg)| {
                let th = deg.to_radians();
                let flow = Flow::uniform(w, h, 12.0 * th.cos(), 12.0 * th.sin());
                let frame =
                    crate::synth::add_motion_blur(&anisotropic_texture(w, h, 3.0, 1.2, 40 + i as u64), &flow, lambda);
                super::super::motion_blur::isotropy_evidence(&frame.luma(), &flow).expect("textured frame")
            })
            .collect()
    }

    /// The texture biases every single frame's root by its direction (measured: λ
    /// 0.5 read as 0.99 along x, 0.19 and 0.0 along 60° and 120°; 0.52, 0.0, 0.51
    /// along 45°, 90°, 135°), the pooled fit recovers it (measured 0.536 ± 0.039
    /// over 0/60/120°, 0.515 ± 0.034 over four directions) and the texture's
    /// harmonic (a ≈ −0.37: less energy along x). Tolerance: 2 standard errors or
    /// 0.05, whichever is larger — the pooled fit's own stated precision.
    #[test]
    fn pooled_fit_separates_the_streak_from_the_texture_anisotropy() {
        for dirs in [&[0.0f32, 60.0, 120.0][..], &[0.0, 45.0, 90.0, 135.0]] {
            let f = frames(0.5, dirs);
            let own: Vec<f32> = f.iter().map(|(l, _)| *l).collect();
            let worst = own.iter().map(|l| (l - 0.5).abs()).fold(0.0f32, f32::max);
            let ev: Vec<&IsotropyEvidence> = f.iter().map(|(_, e)| e).collect();
            let p = pooled_exposure(&ev).expect("three or more directions constrain λ");
            println!("{dirs:?}: frames {own:?}, pooled {p:?}");
            assert!(worst > 0.15, "the texture must bias single frames for this test to mean anything: {own:?}");
            let tol = (2.0 * p.stderr).max(0.05);
            assert!((p.lambda - 0.5).abs() <= tol, "pooled {} ± {} for 0.5", p.lambda, p.stderr);
            assert!(p.stderr < 0.1, "three directions of a strong texture pin λ: ± {}", p.stderr);
            assert!(p.anisotropy[0] < -0.2, "less gradient energy along x: a = {}", p.anisotropy[0]);
            let mb = fit_fast_pooled_exposure(&ev);
            assert_eq!(mb.diagnostics.status, Status::Present, "{}", mb.diagnostics.reason);
        }
    }

    /// One flow direction cannot tell a streak from a texture (the harmonic absorbs
    /// any r): none, and the model says not identifiable; two directions 45° apart
    /// neither (the two harmonic terms fit any two values).
    #[test]
    fn too_few_directions_are_not_identifiable() {
        for dirs in [&[0.0f32, 0.0, 0.0][..], &[0.0, 45.0]] {
            let f = frames(0.5, dirs);
            let ev: Vec<&IsotropyEvidence> = f.iter().map(|(_, e)| e).collect();
            let mb = fit_fast_pooled_exposure(&ev);
            println!("{dirs:?}: {:?} {}", mb.exposure, mb.diagnostics.reason);
            assert_eq!(mb.diagnostics.status, Status::NotIdentifiable, "{dirs:?}: {}", mb.diagnostics.reason);
            assert!(mb.exposure.is_none());
        }
        assert!(pooled_exposure(&[]).is_none());
    }

    /// The pooled status's speed: each usable bin's mean |F|, the fastest of them,
    /// through `add` and `merge`; bins under `MIN_BIN_SAMPLES` do not count.
    #[test]
    fn fastest_bin_speed_is_the_fastest_usable_bins_mean() {
        let (c, d) = ([1.0f64; GRID], [1.0f64; GRID]);
        let mut a = IsotropyEvidence::default();
        for i in 0..MIN_BIN_SAMPLES {
            // Along x at 3 and 7 px/frame alternately: mean 5.
            a.add(if i % 2 == 0 { 3.0 } else { 7.0 }, 0.0, &c, &d);
        }
        // A faster direction with too few samples to be read.
        for _ in 0..MIN_BIN_SAMPLES - 1 {
            a.add(0.0, 40.0, &c, &d);
        }
        assert_eq!(a.fastest_bin_speed(), Some(5.0));
        let mut b = IsotropyEvidence::default();
        b.add(0.0, 40.0, &c, &d);
        let merged = merge(&[&a, &b]);
        assert_eq!(merged.fastest_bin_speed(), Some(40.0));
        assert_eq!(IsotropyEvidence::default().fastest_bin_speed(), None);
    }
}
