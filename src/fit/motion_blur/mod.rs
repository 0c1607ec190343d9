//! Motion-blur exposure λ, accurate and blind.
//!
//! Accurate (paper eq. 5, L_MB(λ) = E|I − addMB(I_noMB, λ, F)|², minimised over a
//! continuous λ instead of the paper's 10-step grid): on luma (addMB is linear, so
//! luma(addMB(I)) = addMB(luma(I)) exactly), at informative pixels only, each
//! pixel's profile f(t) = I_noMB(p + tF), t ∈ [−½, ½], is sampled once at ≤ 0.25 px
//! spacing and integrated cumulatively. Then addMB at any λ is O(1) per pixel:
//! B(λ) = (C(λ/2) − C(−λ/2))/λ, with C the exact integral of the piecewise-linear
//! profile. A 21-point grid brackets the minimum and golden-section search refines
//! it to 1e-5. Standard error: Gauss–Newton, σ_r² / Σ (∂B/∂λ)².
//!
//! Informative pixels: |F| ≥ 0.05 px and a full-exposure streak that changes the
//! pixel by ≥ 1e-3 (|B(1) − f(0)|): this is exactly "texture along the flow".
//! Fewer than 64 → not identifiable. Present when λ > 3·stderr and λ ≥ 0.005
//! (a 0.1 px streak at 20 px/frame: invisible); otherwise absent where the reading
//! itself is negligible, not identifiable where it is a visible streak that the
//! standard error cannot tell from none (`exposure_status`, both tiers).
//!
//! Blind (`fit_fast`): the streak's spectral zeros along the flow where they are
//! identified, else gradient-energy isotropy with its bias risk in the standard
//! error, refined by the derivative autocorrelation's shape where the flow holds one
//! streak length — see its documentation.

mod acf_shape;
mod ends;
mod fast;
mod isotropy;
pub(crate) mod status;

pub use fast::fit_fast;

use super::isotropy_pool::{IsotropyEvidence, GRID};
use crate::image::{Flow, Plane, Rgb};
use crate::model::{flow_within_frame, Diagnostics, MotionBlur, Status};
#[cfg(test)]
pub(super) use isotropy::isotropy_evidence;
pub(crate) use status::{exposure_status, exposure_status_note, visible_speed_px};
use std::time::Instant;

const PROFILE_SPACING_PX: f32 = 0.2;
/// Most intervals in one profile, accurate and blind: past it the nodes spread
/// wider than `PROFILE_SPACING_PX` (accurate, from 204.8 px/frame) or 0.5 px
/// (blind, from 128 px/frame). Without a cap a profile's nodes, and so the fit's
/// time and memory, grew with the flow's speed: a flow of 1e5 px/frame (a flow
/// estimator's failure) took the blind fit 100 s on a 160×160 frame
/// (`tests/extremes.rs`). A streak's box mean over hundreds of pixels is read as
/// well from nodes a pixel apart.
const MAX_PROFILE_INTERVALS: [usize; 2] = [1024, 256];
/// Least flow (px per frame) of a pixel the accurate fit reads: a 0.1 px streak at
/// most, below anything λ could be read from.
pub const MIN_FLOW_PX: f32 = 0.05;
const MIN_SAMPLES: usize = 64;
/// Default pixel budget of the accurate fit. Measured at 512² (BENCHMARKS.md):
/// 2048 to 32768 samples all give a median |λ error| below 0.001; 4096 keeps a 2×
/// margin over the smallest for frames with less texture, at 6 ms instead of 19.
pub const DEFAULT_MAX_SAMPLES: usize = 4_096;

#[derive(Clone, Debug, Default)]
pub struct MbPlotData {
    /// Loss curve over λ (accurate) for the plot.
    pub lambdas: Vec<f32>,
    pub losses: Vec<f64>,
    pub estimate: Option<f32>,
    /// Blind tier, isotropy path: the frame's along/across balance by flow
    /// direction, for the worker's pooled fit (`fit::fit_fast_pooled_exposure`).
    pub isotropy: Option<IsotropyEvidence>,
}

/// One pixel's cumulative profile along its flow.
struct Profiles {
    /// Flattened node values f_j and cumulative integrals C_j (t from −½), per pixel.
    f: Vec<f32>,
    c: Vec<f32>,
    /// The same nodes on the second reference (`FitInputs::motion_deblurred_second`),
    /// empty without one.
    f2: Vec<f32>,
    c2: Vec<f32>,
    offsets: Vec<usize>,
    target: Vec<f32>,
}

impl Profiles {
    /// B(λ) for pixel i: mean of the profile over t ∈ [−λ/2, λ/2].
    #[inline]
    fn blurred(&self, i: usize, lambda: f32) -> f32 {
        let (o0, o1) = (self.offsets[i], self.offsets[i + 1]);
        Self::mean_over(&self.f[o0..o1], &self.c[o0..o1], lambda)
    }

    /// B(λ) of the second reference (the first without one).
    #[inline]
    fn blurred2(&self, i: usize, lambda: f32) -> f32 {
        if self.f2.is_empty() {
            return self.blurred(i, lambda);
        }
        let (o0, o1) = (self.offsets[i], self.offsets[i + 1]);
        Self::mean_over(&self.f2[o0..o1], &self.c2[o0..o1], lambda)
    }

    #[inline]
    fn mean_over(f: &[f32], c: &[f32], lambda: f32) -> f32 {
        Self::mean_with(f, c, &MeanArgs::new(f.len(), lambda))
    }

    /// The mean over [−λ/2, λ/2] of a profile of `args.len`'s nodes: the difference
    /// of the cumulative integral (piecewise-linear profile, m = len − 1 intervals of
    /// width h = 1/m) at ±λ/2, over λ; below λ = 1e-6 the profile's midpoint.
    #[inline]
    fn mean_with(f: &[f32], c: &[f32], args: &MeanArgs) -> f32 {
        match *args {
            MeanArgs::Point { j, a } => f[j] + (f[j + 1] - f[j]) * a,
            MeanArgs::Span { upper, lower, two_h, lambda } => {
                let cum = |(j, tau): (usize, f32)| c[j] + f[j] * tau + (f[j + 1] - f[j]) * tau * tau / two_h;
                (cum(upper) - cum(lower)) / lambda
            }
        }
    }

    /// B(λ_j) for pixel i at every node of the pooled fit's grid, λ_j = j/(GRID − 1),
    /// each node's `MeanArgs` from `taps` (they depend on the profile's length only:
    /// computed once per length, not per profile — the isotropy's grid pass calls
    /// this 4 × 4096 times per frame; 4.3 → 3.5 ms at 1280×960).
    ///
    /// The span nodes lane by lane (`GridSpans`): their taps read in one loop, then
    /// `mean_with`'s arithmetic for all of them in another — the same operations in
    /// the same order per node, so the same bits, but the three divisions per node
    /// (by 2h twice, by λ) run as vector divisions where one node at a time they ran
    /// one by one, the grid pass's largest cost.
    fn blurred_grid(&self, i: usize, out: &mut [f32; GRID], taps: &mut GridTaps) {
        let (o0, o1) = (self.offsets[i], self.offsets[i + 1]);
        let (f, c) = (&self.f[o0..o1], &self.c[o0..o1]);
        let grid = taps.of_len(f.len());
        let Some(sp) = &grid.spans else {
            for (o, args) in out.iter_mut().zip(&grid.args) {
                *o = Self::mean_with(f, c, args);
            }
            return;
        };
        out[0] = Self::mean_with(f, c, &grid.args[0]);
        // Per span node: f_j, f_{j+1} and C_j at its upper and its lower end.
        let (mut up, mut lo) = ([[0.0f32; 3]; SPANS], [[0.0f32; 3]; SPANS]);
        for k in 0..SPANS {
            let (ju, jl) = (sp.upper_j[k], sp.lower_j[k]);
            up[k] = [f[ju], f[ju + 1], c[ju]];
            lo[k] = [f[jl], f[jl + 1], c[jl]];
        }
        let two_h = sp.two_h;
        for k in 0..SPANS {
            let ([fu, fu1, cu], tu) = (up[k], sp.upper_tau[k]);
            let ([fl, fl1, cl], tl) = (lo[k], sp.lower_tau[k]);
            // `mean_with`'s `cum` at either end, written out.
            let upper = cu + fu * tu + (fu1 - fu) * tu * tu / two_h;
            let lower = cl + fl * tl + (fl1 - fl) * tl * tl / two_h;
            out[k + 1] = (upper - lower) / sp.lambda[k];
        }
    }

    /// `blurred2(i, at.lambda)` (the second reference's profile has the first's length).
    #[inline]
    fn blurred2_at(&self, i: usize, at: &mut AtLambda) -> f32 {
        if self.f2.is_empty() {
            return self.blurred_at(i, at);
        }
        let (o0, o1) = (self.offsets[i], self.offsets[i + 1]);
        let (f, c) = (&self.f2[o0..o1], &self.c2[o0..o1]);
        Self::mean_with(f, c, at.of_len(f.len()))
    }

    /// `blurred(i, at.lambda)`, its `MeanArgs` from `at` (computed once per profile
    /// length: the isotropy's root searches evaluate every sample's four profiles
    /// at each trial λ; 3.5 → 3.2 ms).
    #[inline]
    fn blurred_at(&self, i: usize, at: &mut AtLambda) -> f32 {
        let (o0, o1) = (self.offsets[i], self.offsets[i + 1]);
        let (f, c) = (&self.f[o0..o1], &self.c[o0..o1]);
        Self::mean_with(f, c, at.of_len(f.len()))
    }

    /// Number of samples (one target each; the fast tier keeps 4 profiles per sample).
    fn len(&self) -> usize {
        self.target.len()
    }

    /// E|I − B(λ)|², or with a second reference the cross loss
    /// E[(I − B₁(λ))(I − B₂(λ))]: the references' noise n₁, n₂ is independent of
    /// each other and of I's, so E[B(n₁)·B(n₂)] = 0 and the loss is the noise-free
    /// one plus I's noise variance — a constant in λ. With one reference the term
    /// E|B_λ(n₁)|² falls as the streak averages more of its noise, and pulls λ up
    /// (measured: +0.16 on 3.6 px streaks at 1280×960, BENCHMARKS.md).
    fn loss(&self, lambda: f32) -> f64 {
        let n = self.len();
        let t = &self.target;
        // The profiles' `MeanArgs` once per length (`AtLambda`): the search
        // evaluates this ~40 times over every sample.
        let mut at = AtLambda::new(lambda);
        if self.f2.is_empty() {
            (0..n).map(|i| (t[i] - self.blurred_at(i, &mut at)) as f64).map(|r| r * r).sum::<f64>() / n as f64
        } else {
            (0..n)
                .map(|i| {
                    let (b1, b2) = (self.blurred_at(i, &mut at), self.blurred2_at(i, &mut at));
                    (t[i] - b1) as f64 * (t[i] - b2) as f64
                })
                .sum::<f64>()
                / n as f64
        }
    }

    /// ∂B/∂λ of the references' mean at pixel i, by a central difference on
    /// [l0, l1] (`blurred2` is `blurred` without a second reference).
    fn slope(&self, i: usize, l0: f32, l1: f32) -> f64 {
        let mean = |l: f32| 0.5 * (self.blurred(i, l) + self.blurred2(i, l));
        ((mean(l1) - mean(l0)) / (l1 - l0)) as f64
    }

    /// Mean squared residual against the references' mean at λ (the noise of the
    /// Gauss–Newton standard error; with two references it keeps half their
    /// noise, so it errs large).
    fn residual_var(&self, lambda: f32) -> f64 {
        let n = self.len();
        (0..n)
            .map(|i| (self.target[i] - 0.5 * (self.blurred(i, lambda) + self.blurred2(i, lambda))) as f64)
            .map(|r| r * r)
            .sum::<f64>()
            / n as f64
    }
}

fn build_profiles(
    image: &Plane,
    (sharp, sharp2): (&Plane, Option<&Plane>),
    flow: &Flow,
    valid: Option<&Plane>,
    max_samples: usize,
    min_flow_px: f32,
    row_ok: &[bool],
) -> Profiles {
    let (w, h) = (image.width, image.height);
    // Cheap pre-filter: the sharp luma must change along the flow within one frame
    // interval (|∇Y·F| ≥ 2e-3, half an 8-bit step), then thin deterministically to
    // `max_samples` before the (costlier) profiles are built.
    let mut cand = vec![];
    for y in (0..h).step_by(2).filter(|&y| row_ok[y]) {
        for x in (0..w).step_by(2) {
            let i = y * w + x;
            let (fx, fy) = (flow.dx[i], flow.dy[i]);
            if fx * fx + fy * fy < min_flow_px * min_flow_px || !flow_within_frame(fx, fy, w, h) {
                continue;
            }
            // The reference must hold along the whole streak (its ends and middle).
            // Rounding by +½ and truncation (no libm call); off-frame positions
            // clamp either way.
            if let Some(v) = valid {
                let ok = |t: f32| {
                    let (xs, ys) = ((x as f32 + t * fx + 0.5) as isize, (y as f32 + t * fy + 0.5) as isize);
                    row_ok[ys.clamp(0, h as isize - 1) as usize] && v.get_clamped(xs, ys) > 0.5
                };
                if !(ok(-0.5) && ok(0.0) && ok(0.5)) {
                    continue;
                }
            }
            let (xi, yi) = (x as isize, y as isize);
            let gx = 0.5 * (sharp.get_clamped(xi + 1, yi) - sharp.get_clamped(xi - 1, yi));
            let gy = 0.5 * (sharp.get_clamped(xi, yi + 1) - sharp.get_clamped(xi, yi - 1));
            if (gx * fx + gy * fy).abs() >= 2e-3 {
                cand.push((x, y));
            }
        }
    }
    let keep = cand.len().div_ceil(max_samples).max(1);
    let mut p = Profiles { f: vec![], c: vec![], f2: vec![], c2: vec![], offsets: vec![0], target: vec![] };
    for &(x, y) in cand.iter().step_by(keep) {
        let i = y * w + x;
        let (fx, fy) = (flow.dx[i], flow.dy[i]);
        let speed = (fx * fx + fy * fy).sqrt();
        let m = ((speed / PROFILE_SPACING_PX).ceil() as usize).clamp(8, MAX_PROFILE_INTERVALS[0]);
        let start = p.f.len();
        let (xf, yf) = (x as f32, y as f32);
        let cum = append_profile(&mut p.f, &mut p.c, sharp, xf, yf, (fx, fy), m);
        // Informative: a full-exposure streak changes this pixel by ≥ 1e-3.
        if (cum - sharp.get(x, y)).abs() < 1e-3 {
            p.f.truncate(start);
            p.c.truncate(start);
            continue;
        }
        if let Some(s2) = sharp2 {
            append_profile(&mut p.f2, &mut p.c2, s2, xf, yf, (fx, fy), m);
        }
        p.offsets.push(p.f.len());
        p.target.push(image.get(x, y));
    }
    p
}

fn decide(
    method: &str,
    lambda: f32,
    stderr: f64,
    residuals: Option<(f64, f64)>,
    n: usize,
    speed_px: Option<f32>,
    started: Instant,
) -> MotionBlur {
    let status = exposure_status(lambda, stderr, speed_px);
    let present = status == Status::Present;
    let reason = format!(
        "λ = {lambda:.4} ± {stderr:.4} from {n} pixels; {}; residuals are mean squared luma errors",
        exposure_status_note(status, speed_px)
    );
    MotionBlur {
        present,
        exposure: Some(lambda.clamp(0.0, 1.0)),
        diagnostics: Diagnostics {
            status,
            reason,
            method: method.into(),
            residual_before: residuals.map(|r| r.0),
            residual_after: residuals.map(|r| r.1),
            samples_used: n as u64,
            fit_time_s: started.elapsed().as_secs_f64(),
            stderr: Some(stderr),
            stages_s: Default::default(),
        },
    }
}

/// Accurate tier: I, I_noMB and F.
pub fn fit_accurate(
    image: &Rgb,
    sharp: &Rgb,
    sharp2: Option<&Rgb>,
    flow: &Flow,
    valid: Option<&Plane>,
    opts: &super::FitOptions,
) -> (MotionBlur, Option<MbPlotData>) {
    let (max_samples, prefilter_var_px2, min_flow_px) =
        (opts.mb_max_samples, opts.mb_prefilter_var_px2, opts.mb_min_flow_px);
    let started = Instant::now();
    let mut st = super::Stages::start();
    // Only the rows the reference holds on are read (`build_profiles` keeps a pixel
    // when its streak's ends and middle are valid), and the prefilter's reach
    // around them.
    let rows: Vec<bool> = match valid {
        Some(v) => (0..v.height).map(|r| v.data[r * v.width..(r + 1) * v.width].iter().any(|&m| m > 0.5)).collect(),
        None => vec![true; image.height],
    };
    let k = crate::image::discrete_gaussian_kernel(prefilter_var_px2);
    let reach = k.len() / 2;
    let near = |r: usize| rows[r.saturating_sub(reach)..(r + reach + 1).min(rows.len())].iter().any(|&b| b);
    // Rows whose prefiltered values hold: every row the kernel reaches has valid
    // pixels (a sparse reference's band edges would otherwise blend in unset rows).
    let row_ok: Vec<bool> = (0..rows.len())
        .map(|r| rows[r.saturating_sub(reach)..(r + reach + 1).min(rows.len())].iter().all(|&b| b))
        .collect();
    let (mut y, mut y_sharp, mut y_sharp2) =
        (image.luma_rows(&near), sharp.luma_rows(&near), sharp2.map(|s| s.luma_rows(&near)));
    if prefilter_var_px2 > 0.0 {
        y = crate::image::blur_separable_rows(&y, &k, &|r| rows[r]);
        y_sharp = crate::image::blur_separable_rows(&y_sharp, &k, &|r| rows[r]);
        y_sharp2 = y_sharp2.map(|p| crate::image::blur_separable_rows(&p, &k, &|r| rows[r]));
    }
    st.lap("prefilter");
    let prof = build_profiles(&y, (&y_sharp, y_sharp2.as_ref()), flow, valid, max_samples, min_flow_px, &row_ok);
    st.lap("blur");
    let n = prof.len();
    if n < MIN_SAMPLES {
        let reason = format!(
            "only {n} pixels have flow ≥ {min_flow_px} px (and within the frame's diagonal) and texture along it (need {MIN_SAMPLES}): exposure not \
             identifiable"
        );
        let mut d = super::not_identifiable("accurate", reason, started);
        d.samples_used = n as u64;
        return (MotionBlur::absent(d), None);
    }
    let lambdas: Vec<f32> = (0..=20).map(|i| i as f32 / 20.0).collect();
    let losses: Vec<f64> = lambdas.iter().map(|&l| prof.loss(l)).collect();
    let best = (0..lambdas.len()).min_by(|&a, &b| losses[a].total_cmp(&losses[b])).unwrap_or(0);
    let lo = lambdas[best.saturating_sub(1)];
    let hi = lambdas[(best + 1).min(lambdas.len() - 1)];
    // λ to 1e-5.
    let steps = super::golden_steps((hi - lo) as f64, 1e-5);
    let mut lambda = super::golden_section(lo as f64, hi as f64, steps, |l| prof.loss(l as f32)) as f32;
    // The golden section never evaluates the bracket ends; the boundaries λ = 0 and
    // λ = 1 are legitimate answers.
    for edge in [0.0f32, 1.0] {
        if (edge - lambda).abs() < 0.05 && prof.loss(edge) <= prof.loss(lambda) {
            lambda = edge;
        }
    }
    let after = prof.loss(lambda);
    st.lap("search");
    let eps = 1e-3f32;
    let (l0, l1) = ((lambda - eps).max(0.0), (lambda + eps).min(1.0));
    let jj: f64 = (0..n).map(|i| prof.slope(i, l0, l1)).map(|j| j * j).sum();
    let res = prof.residual_var(lambda);
    let stderr = if jj > 0.0 { (res * n as f64 / (n as f64 - 1.0) / jj).sqrt() } else { 1.0 };
    st.lap("least_squares");
    let mut mb = decide("accurate", lambda, stderr, Some((losses[0], after)), n, visible_speed_px(flow), started);
    mb.diagnostics.stages_s = st.done();
    (mb, Some(MbPlotData { lambdas, losses, estimate: Some(lambda), isotropy: None }))
}

/// Append the cumulative profile of `p` from (x, y) along `dir` (t ∈ [−½, ½]).
#[cfg(test)]
fn push_profile(prof: &mut Profiles, p: &Plane, x: f32, y: f32, dir: (f32, f32)) {
    append_profile(&mut prof.f, &mut prof.c, p, x, y, dir, profile_intervals(dir));
    prof.offsets.push(prof.f.len());
}

/// `push_profile` at the four points `at` along one `dir` (the isotropy's four
/// profiles a sample), the same profiles: their nodes read together
/// (`Plane::sample_lines`: one interior test, the last nodes as one chunk), their
/// running sums as `append_profile` takes them.
fn push_profiles4(prof: &mut Profiles, p: &Plane, at: [(f32, f32); 4], dir: (f32, f32)) {
    let m = profile_intervals(dir);
    let half_step = 0.5 * (1.0 / m as f32);
    let lines = at.map(|(x, y)| profile_line(x, y, dir, m));
    let ((dx, dy), starts) = (lines[0].1, lines.map(|l| l.0));
    let start = prof.f.len();
    prof.f.resize(start + 4 * (m + 1), 0.0);
    p.sample_lines(starts, dx, dy, m + 1, &mut prof.f[start..]);
    for l in 0..4 {
        append_running_sums(&mut prof.c, &prof.f[start + l * (m + 1)..start + (l + 1) * (m + 1)], half_step);
        prof.offsets.push(start + (l + 1) * (m + 1));
    }
}

/// The intervals of `push_profile`'s profile along `dir`: nodes ≤ ½ px apart.
fn profile_intervals(dir: (f32, f32)) -> usize {
    let len = (dir.0 * dir.0 + dir.1 * dir.1).sqrt();
    ((len / 0.5).ceil() as usize).clamp(4, MAX_PROFILE_INTERVALS[1])
}

/// B(λ = 0) of the profile `push_profile(p, x, y, dir)` appends — what
/// `Profiles::blurred_at` returns for it at λ 0 — from the only two nodes that
/// value reads: the same node positions (`append_profile`'s x₀ + j·dx, which
/// `Plane::sample_line` reads as `sample_bilinear` does, bit for bit) and the same
/// interpolation (`MeanArgs::Point`), so the same bits, without the other nodes
/// or the cumulative sums (`isotropy_root`'s coarse scale asks this first).
fn profile_midpoint(p: &Plane, x: f32, y: f32, dir: (f32, f32)) -> f32 {
    let m = profile_intervals(dir);
    let ((x0, y0), (dx, dy)) = profile_line(x, y, dir, m);
    let (j, a) = MeanArgs::midpoint(m + 1);
    let node = |j: usize| p.sample_bilinear(x0 + j as f32 * dx, y0 + j as f32 * dy);
    let nodes = [node(j), node(j + 1)];
    Profiles::mean_with(&nodes, &[], &MeanArgs::Point { j: 0, a })
}

/// What `Profiles::mean_with` needs of a profile's length and λ: the interval
/// index and offset of ±λ/2 (`Span`), or of the midpoint below λ = 1e-6 (`Point`).
/// Computed here once, the same steps `mean_over` always took, so the same bits
/// whether cached (`GridTaps`, `AtLambda`) or not.
#[derive(Clone, Copy, Debug)]
enum MeanArgs {
    Point { j: usize, a: f32 },
    Span { upper: (usize, f32), lower: (usize, f32), two_h: f32, lambda: f32 },
}

impl MeanArgs {
    /// The interval holding a profile's midpoint t = 0 and the offset into it (a
    /// profile of `len` ≥ 2 nodes).
    #[inline]
    fn midpoint(len: usize) -> (usize, f32) {
        let s = 0.5 * (len - 1) as f32;
        let j = (s as usize).min(len - 2);
        (j, s - j as f32)
    }

    #[inline]
    fn new(len: usize, lambda: f32) -> Self {
        let m = (len - 1) as f32;
        if lambda < 1e-6 {
            let (j, a) = Self::midpoint(len);
            return Self::Point { j, a };
        }
        let h = 1.0 / m;
        // The interval holding t (from −½) and the offset into it; s ≥ 0, so
        // truncation is its floor, without the libm call.
        let arg = |t: f32| {
            let s = ((t + 0.5) * m).clamp(0.0, m);
            let j = (s as usize).min(len - 2);
            (j, (s - j as f32) * h)
        };
        Self::Span { upper: arg(0.5 * lambda), lower: arg(-0.5 * lambda), two_h: 2.0 * h, lambda }
    }
}

/// A value per profile length, made on first use (profile lengths are few: the
/// flow's speeds over the spacing, so a handful of distinct values per frame).
struct PerLength<T>(Vec<Option<T>>);

impl<T: Copy> PerLength<T> {
    fn get(&mut self, len: usize, make: impl FnOnce() -> T) -> &T {
        if self.0.len() <= len {
            self.0.resize(len + 1, None);
        }
        self.0[len].get_or_insert_with(make)
    }
}

/// `MeanArgs` of one λ per profile length (`Profiles::blurred_at`).
pub(super) struct AtLambda {
    lambda: f32,
    by_len: PerLength<MeanArgs>,
}

impl AtLambda {
    pub(super) fn new(lambda: f32) -> Self {
        Self { lambda, by_len: PerLength(vec![]) }
    }

    fn of_len(&mut self, len: usize) -> &MeanArgs {
        let lambda = self.lambda;
        self.by_len.get(len, || MeanArgs::new(len, lambda))
    }
}

/// `MeanArgs` of every node of the pooled fit's λ grid, λ_j = j/(GRID − 1), per
/// profile length (`Profiles::blurred_grid`).
pub(super) struct GridTaps(PerLength<GridArgs>);

/// The grid's nodes past λ 0 (`GridSpans`).
const SPANS: usize = GRID - 1;

/// One profile length's `MeanArgs` at the grid's nodes, and the nodes past λ 0
/// (λ ≥ 1/16: every one a `MeanArgs::Span`) lane by lane.
#[derive(Clone, Copy)]
struct GridArgs {
    args: [MeanArgs; GRID],
    /// `None` only if a node past λ 0 were not a span (`blurred_grid` then takes
    /// the nodes one at a time).
    spans: Option<GridSpans>,
}

/// The `MeanArgs::Span` fields of the grid's nodes 1 … GRID − 1, field by field.
#[derive(Clone, Copy)]
struct GridSpans {
    upper_j: [usize; SPANS],
    upper_tau: [f32; SPANS],
    lower_j: [usize; SPANS],
    lower_tau: [f32; SPANS],
    /// 2h, one value for a length.
    two_h: f32,
    lambda: [f32; SPANS],
}

impl GridTaps {
    pub(super) fn new() -> Self {
        Self(PerLength(vec![]))
    }

    fn of_len(&mut self, len: usize) -> &GridArgs {
        self.0.get(len, || {
            let args: [MeanArgs; GRID] = std::array::from_fn(|j| MeanArgs::new(len, j as f32 / (GRID - 1) as f32));
            let mut sp = GridSpans {
                upper_j: [0; SPANS],
                upper_tau: [0.0; SPANS],
                lower_j: [0; SPANS],
                lower_tau: [0.0; SPANS],
                two_h: 0.0,
                lambda: [0.0; SPANS],
            };
            let mut all_spans = true;
            for (k, a) in args[1..].iter().enumerate() {
                match *a {
                    MeanArgs::Span { upper, lower, two_h, lambda } => {
                        (sp.upper_j[k], sp.upper_tau[k]) = upper;
                        (sp.lower_j[k], sp.lower_tau[k]) = lower;
                        sp.lambda[k] = lambda;
                        // The same 2h at every node of a length (h = 1/(len − 1)).
                        all_spans &= k == 0 || two_h.to_bits() == sp.two_h.to_bits();
                        sp.two_h = two_h;
                    }
                    MeanArgs::Point { .. } => all_spans = false,
                }
            }
            GridArgs { args, spans: all_spans.then_some(sp) }
        })
    }
}

/// Append the m + 1 nodes f_j = p(x + t_j·dir, y + t_j·dir), t_j = j/m − ½, and
/// their cumulative trapezoid integrals C_j to `f` and `c`; returns C_m (the mean
/// over the whole streak).
fn append_profile(f: &mut Vec<f32>, c: &mut Vec<f32>, p: &Plane, x: f32, y: f32, dir: (f32, f32), m: usize) -> f32 {
    // Node j at (x, y) + (j/m − ½)·dir, stepped from the first node with one
    // reciprocal (no division per node), all m + 1 read as one line
    // (`Plane::sample_line`: the same values as a bilinear read per node).
    let half_step = 0.5 * (1.0 / m as f32);
    let ((x0, y0), (dx, dy)) = profile_line(x, y, dir, m);
    let start = f.len();
    f.resize(start + m + 1, 0.0);
    p.sample_line(x0, y0, dx, dy, &mut f[start..]);
    let nodes = &f[start..];
    append_running_sums(c, nodes, half_step)
}

/// A profile's first node (x, y) − ½·dir and its step dir/m (one reciprocal, no
/// division per node): every reader of a profile's nodes places them so.
fn profile_line(x: f32, y: f32, dir: (f32, f32), m: usize) -> ((f32, f32), (f32, f32)) {
    let inv_m = 1.0 / m as f32;
    ((x - 0.5 * dir.0, y - 0.5 * dir.1), (dir.0 * inv_m, dir.1 * inv_m))
}

/// Append the running trapezoid sums C_0 = 0, C_j = C_{j−1} + h·(f_{j−1} + f_j) of
/// `nodes` to `c`; returns the last. Written into the grown vector (pushed one at
/// a time, the sum and the length lived on the stack between pushes: a store and
/// a reload on every step of the chain; the same sums).
fn append_running_sums(c: &mut Vec<f32>, nodes: &[f32], half_step: f32) -> f32 {
    let cs = c.len();
    c.resize(cs + nodes.len(), 0.0);
    let mut cum = 0.0f32;
    for (o, k) in c[cs..].iter_mut().skip(1).zip(nodes.windows(2)) {
        cum += half_step * (k[0] + k[1]);
        *o = cum;
    }
    cum
}
