//! Robust fits of the DoF depth model δ(Z) to per-pixel (Z, σ) estimates.
//!
//! Both forms are fitted by iteratively reweighted least squares with Huber
//! weights (scale = 1.4826·MAD, k = 1.345: 95% efficiency on Gaussian residuals,
//! bounded influence of the outliers that depth edges and textureless leftovers
//! produce):
//! * quadratic δ = aZ² + bZ + c (the paper's; linear in its coefficients);
//! * thin lens δ = k·|u − u_f| + c0 with u the inverse depth: for each candidate
//!   focus u_f the model is linear in (k, c0); u_f is found by a grid over the
//!   sample range and golden-section refinement.
//!
//! The form with the lower mean Huber loss wins; the thin lens wins ties within 1%
//! because it stays bounded outside the fitted range. A curve whose variation over
//! the range is below 3 standard errors (or 0.05 px) is replaced by a constant.

use crate::model::{DepthUnits, DofCurve};

const HUBER_K: f64 = 1.345;

#[derive(Clone, Debug)]
pub struct CurveFit {
    pub curve: DofCurve,
    /// Mean Huber loss of the chosen form (px²).
    pub loss: f64,
    /// Robust residual scale (px).
    pub scale: f64,
    /// Approximate RMS standard error of the curve over the samples: scale·√(p/N).
    pub stderr_px: f64,
    pub quadratic: Option<DofCurve>,
    pub thin_lens: Option<DofCurve>,
}

/// Median by linear-time selection (the IRLS loops call this hundreds of times).
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let n = v.len();
    let (_, &mut upper, _) = v.select_nth_unstable_by(n / 2, |a, b| a.total_cmp(b));
    if n % 2 == 1 {
        upper
    } else {
        let lower = v[..n / 2].iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

/// `median` of `|r|` over `res`, selected on the values' bit patterns in `buf`:
/// non-negative floats (NaN included, its sign cleared like every value's) order as
/// their bits do, and `total_cmp` orders them the same way, so the value is
/// `median`'s, bit for bit (integer comparisons select ~30% faster, and the IRLS
/// loops select hundreds of times per frame).
fn median_abs(res: &[f64], buf: &mut Vec<u64>) -> f64 {
    buf.clear();
    buf.extend(res.iter().map(|r| r.abs().to_bits()));
    let n = buf.len();
    if n == 0 {
        return 0.0;
    }
    let (_, &mut upper, _) = buf.select_nth_unstable(n / 2);
    let upper = f64::from_bits(upper);
    if n % 2 == 1 {
        upper
    } else {
        let lower = buf[..n / 2].iter().map(|&b| f64::from_bits(b)).fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

fn robust_scale(res: &[f64]) -> f64 {
    robust_scale_in(res, &mut vec![])
}

/// `robust_scale` with the selection buffer supplied (`median_abs`).
fn robust_scale_in(res: &[f64], buf: &mut Vec<u64>) -> f64 {
    (1.4826 * median_abs(res, buf)).max(1e-6)
}

fn huber_loss(res: &[f64], scale: f64) -> f64 {
    let k = HUBER_K * scale;
    res.iter().map(|&r| if r.abs() <= k { 0.5 * r * r } else { k * (r.abs() - 0.5 * k) }).sum::<f64>()
        / res.len().max(1) as f64
}

/// What `irls` returns: the coefficients, the residuals and their robust scale
/// (`robust_scale` of the residuals, which the last step computed for its weights).
struct Irls<const P: usize> {
    beta: [f64; P],
    res: Vec<f64>,
    scale: f64,
}

/// IRLS for y ≈ X β with Huber weights, X given row by row through `row(i)`
/// (P ≤ 3 columns; normal equations accumulated in place, solved by Cholesky).
/// None if singular.
fn irls<const P: usize>(n: usize, row: impl Fn(usize) -> [f64; P], y: &[f64], iters: usize) -> Option<Irls<P>> {
    let mut beta = [0.0f64; P];
    let mut res = vec![0.0f64; n];
    let mut buf = Vec::with_capacity(n);
    // The scale of the zero residuals is only ever returned by a fit of no steps
    // (each step selects its own from its residuals).
    let mut scale = if iters == 0 { robust_scale_in(&res, &mut buf) } else { 0.0 };
    // 1/scale of the previous step's residuals, whose Huber weights this step's
    // normal equations take; None on the first step (every weight 1).
    let mut inv_scale: Option<f64> = None;
    // The Huber weights of the previous step's residuals (every weight 1 on the
    // first step).
    let mut weights = vec![1.0f64; n];
    for _ in 0..iters {
        let mut xtwx = nalgebra::SMatrix::<f64, P, P>::zeros();
        let mut xtwy = nalgebra::SVector::<f64, P>::zeros();
        // The weights in a pass of their own, the quotient taken for every sample
        // and kept where |r| is past the corner: a select, not a branch, so the pass
        // runs four samples to a vector division. Taken inside the sums' loop (a
        // branch on each sample's side of the corner, mispredicted where residuals
        // straddle it, and a scalar division) the thin lens's focus search takes
        // 1.61 ms at the bench frame's 2 845 edges, this pass 1.43 (the defocus
        // fit's least squares 1.8 against 1.6 ms, same-moment). The same weights
        // (the same expression), the same sums in the same order.
        if let Some(inv) = inv_scale {
            for (w, r) in weights.iter_mut().zip(&res) {
                // |r|/scale as a product with the reciprocal (one division per step
                // for it, not one per sample).
                let a = r.abs() * inv;
                let q = HUBER_K / a;
                *w = if a <= HUBER_K { 1.0 } else { q };
            }
        }
        for i in 0..n {
            let (r, w) = (row(i), weights[i]);
            for a in 0..P {
                xtwy[a] += w * r[a] * y[i];
                for b in 0..P {
                    xtwx[(a, b)] += w * r[a] * r[b];
                }
            }
        }
        // Tiny ridge: keeps a degenerate design (all samples at one depth) solvable;
        // the flatness test then turns it into a constant.
        for d in 0..P {
            xtwx[(d, d)] += 1e-9 * (1.0 + xtwx[(d, d)]);
        }
        let sol = xtwx.cholesky()?.solve(&xtwy);
        beta.copy_from_slice(sol.as_slice());
        for i in 0..n {
            let r = row(i);
            res[i] = y[i] - (0..P).map(|a| r[a] * beta[a]).sum::<f64>();
        }
        scale = robust_scale_in(&res, &mut buf);
        inv_scale = Some(1.0 / scale);
    }
    beta.iter().all(|b| b.is_finite()).then_some(Irls { beta, res, scale })
}

fn fit_quadratic(z: &[f64], s: &[f64]) -> Option<(DofCurve, Vec<f64>)> {
    // Centre and scale Z for conditioning, then map back to raw coefficients.
    let zm = z.iter().sum::<f64>() / z.len() as f64;
    let zs = (z.iter().map(|v| (v - zm).powi(2)).sum::<f64>() / z.len() as f64).sqrt().max(1e-9);
    let Irls { beta: b, res, .. } = irls(
        z.len(),
        |i| {
            let t = (z[i] - zm) / zs;
            [t * t, t, 1.0]
        },
        s,
        15,
    )?;
    // δ = b0 t² + b1 t + b2 with t = (Z − zm)/zs.
    let a = b[0] / (zs * zs);
    let bb = b[1] / zs - 2.0 * b[0] * zm / (zs * zs);
    let c = b[0] * zm * zm / (zs * zs) - b[1] * zm / zs + b[2];
    let curve = DofCurve::Quadratic { a: a as f32, b: bb as f32, c: c as f32 };
    let ok = [a, bb, c].iter().all(|v| v.is_finite());
    ok.then_some((curve, res))
}

fn fit_thin_lens_at(u: &[f64], s: &[f64], uf: f64, iters: usize) -> Option<Irls<2>> {
    irls(u.len(), |i| [(u[i] - uf).abs(), 1.0], s, iters)
}

/// The focus search's loss at a focus `uf`: the mean Huber loss of the thin lens
/// fitted there with `iters` IRLS steps, ∞ where that fit fails or its slope is
/// negative.
fn thin_lens_loss(u: &[f64], s: &[f64], uf: f64, iters: usize) -> f64 {
    match fit_thin_lens_at(u, s, uf, iters) {
        Some(Irls { beta: [k, _], res, scale }) if k >= 0.0 => huber_loss(&res, scale),
        _ => f64::INFINITY,
    }
}

/// Foci the focus grid fits at once (`thin_lens_losses`).
const LANES: usize = 4;

/// `thin_lens_loss` at `LANES` foci at once, bit for bit: each lane runs `irls`'s
/// steps on its own focus — the same operations in the same order, its sums over
/// the samples in their order — but one pass over the samples serves all lanes,
/// their sums side by side in vectors. One focus at a time, the step's six sums are
/// chains of dependent additions, one link per sample: the grid's 33 fits were
/// 0.9 ms of the bench frame's 1.4 ms focus search (the defocus fit's least
/// squares 1.7 → 1.5 ms, same-moment; the lanes' selections of the scale remain
/// one by one).
fn thin_lens_losses(u: &[f64], y: &[f64], uf: [f64; LANES], iters: usize) -> [f64; LANES] {
    let n = u.len();
    // Per lane: its residuals (lane by lane, for the scale's selection), its
    // weights (sample by sample, lanes side by side, for the sums), its coefficients,
    // scale and 1/scale, and whether its fit still stands.
    let mut res = vec![vec![0.0f64; n]; LANES];
    let mut weights = vec![1.0f64; n * LANES];
    let mut beta = [[0.0f64; 2]; LANES];
    let mut scale = [0.0f64; LANES];
    let mut inv_scale: Option<[f64; LANES]> = None;
    let mut alive = [true; LANES];
    let mut buf = Vec::with_capacity(n);
    for _ in 0..iters {
        if let Some(inv) = inv_scale {
            for (l, r) in res.iter().enumerate() {
                for (i, &r) in r.iter().enumerate() {
                    let a = r.abs() * inv[l];
                    let q = HUBER_K / a;
                    weights[i * LANES + l] = if a <= HUBER_K { 1.0 } else { q };
                }
            }
        }
        // `irls`'s sums for P = 2, row [|u − u_f|, 1]: xtwy[a] += w·r[a]·y,
        // xtwx[a][b] += w·r[a]·r[b], in that order, per lane.
        let (mut y0, mut y1) = ([0.0f64; LANES], [0.0f64; LANES]);
        let (mut x00, mut x01, mut x10, mut x11) = ([0.0f64; LANES], [0.0f64; LANES], [0.0f64; LANES], [0.0f64; LANES]);
        for (i, (&ui, &yi)) in u.iter().zip(y).enumerate() {
            let w = &weights[i * LANES..(i + 1) * LANES];
            for l in 0..LANES {
                let r = [(ui - uf[l]).abs(), 1.0];
                y0[l] += w[l] * r[0] * yi;
                x00[l] += w[l] * r[0] * r[0];
                x01[l] += w[l] * r[0] * r[1];
                y1[l] += w[l] * r[1] * yi;
                x10[l] += w[l] * r[1] * r[0];
                x11[l] += w[l] * r[1] * r[1];
            }
        }
        let mut inv = [0.0f64; LANES];
        for l in 0..LANES {
            if !alive[l] {
                continue;
            }
            let mut xtwx = nalgebra::SMatrix::<f64, 2, 2>::new(x00[l], x01[l], x10[l], x11[l]);
            let xtwy = nalgebra::SVector::<f64, 2>::new(y0[l], y1[l]);
            for d in 0..2 {
                xtwx[(d, d)] += 1e-9 * (1.0 + xtwx[(d, d)]);
            }
            let Some(ch) = xtwx.cholesky() else {
                alive[l] = false;
                continue;
            };
            let sol = ch.solve(&xtwy);
            beta[l].copy_from_slice(sol.as_slice());
            for (ri, (&ui, &yi)) in res[l].iter_mut().zip(u.iter().zip(y)) {
                let r = [(ui - uf[l]).abs(), 1.0];
                *ri = yi - (0..2).map(|a| r[a] * beta[l][a]).sum::<f64>();
            }
            scale[l] = robust_scale_in(&res[l], &mut buf);
            inv[l] = 1.0 / scale[l];
        }
        inv_scale = Some(inv);
    }
    std::array::from_fn(|l| {
        let fitted = alive[l] && beta[l].iter().all(|b| b.is_finite()) && beta[l][0] >= 0.0;
        if fitted {
            huber_loss(&res[l], scale[l])
        } else {
            f64::INFINITY
        }
    })
}

fn fit_thin_lens(u: &[f64], s: &[f64], units: DepthUnits) -> Option<(DofCurve, Vec<f64>)> {
    let lo = u.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = u.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    // The focus search runs on at most 2048 evenly spread samples with 6 IRLS steps;
    // the final fit uses all samples and 15 steps.
    let step = u.len().div_ceil(2048);
    let (us, ss): (Vec<f64>, Vec<f64>) = (0..u.len()).step_by(step).map(|i| (u[i], s[i])).unzip();
    const SEARCH_STEPS: usize = 6;
    let loss_at = |uf: f64| thin_lens_loss(&us, &ss, uf, SEARCH_STEPS);
    // Grid (the focus may lie just outside the sampled range), then golden section.
    let span = hi - lo;
    let n = 32;
    let grid: Vec<f64> = (0..=n).map(|i| lo - 0.1 * span + 1.2 * span * i as f64 / n as f64).collect();
    // `LANES` foci at a time (`thin_lens_losses`), the remainder one by one: the
    // same losses as `loss_at`'s.
    let mut losses = Vec::with_capacity(grid.len());
    let mut quads = grid.chunks_exact(LANES);
    for q in &mut quads {
        losses.extend(thin_lens_losses(&us, &ss, std::array::from_fn(|l| q[l]), SEARCH_STEPS));
    }
    losses.extend(quads.remainder().iter().map(|&g| loss_at(g)));
    let best = (0..grid.len()).min_by(|&a, &b| losses[a].total_cmp(&losses[b]))?;
    let (a, b) = (grid[best.saturating_sub(1)], grid[(best + 1).min(n)]);
    // 14 steps shrink the two-grid-cell bracket (15% of the samples' inverse-depth
    // span) by 0.618^14 ≈ 1.2e-3, to ~2e-4 of the span: the focus then moves δ by
    // about k·span·2e-4 px, a thousandth of the curve's own range — 25 steps (to
    // 6e-6) cost 11 more IRLS fits for nothing a test or the renderer can see.
    let uf = super::golden_section(a, b, 14, loss_at);
    let Irls { beta: [k, c0], res, .. } = fit_thin_lens_at(u, s, uf, 15)?;
    if k.is_nan() || k < 0.0 {
        return None;
    }
    // Back from inverse depth to the depth value of the focal plane.
    let focus_depth = match units {
        DepthUnits::MetricM => {
            if uf <= 0.0 {
                return None; // focused "beyond infinity": not a thin lens
            }
            1.0 / uf
        }
        DepthUnits::RelativeInverse => uf,
    };
    let curve = DofCurve::ThinLens { k: k as f32, focus_depth: focus_depth as f32, c0: c0 as f32 };
    [k, focus_depth, c0].iter().all(|v| v.is_finite()).then_some((curve, res))
}

/// Fit δ(Z) to samples `(depth, sigma_px)` over `depth_range`. None if too few.
pub fn fit_dof_curve(depth: &[f32], sigma_px: &[f32], units: DepthUnits, depth_range: [f32; 2]) -> Option<CurveFit> {
    if depth.len() < 8 {
        return None;
    }
    let z: Vec<f64> = depth.iter().map(|&v| v as f64).collect();
    let s: Vec<f64> = sigma_px.iter().map(|&v| v as f64).collect();
    let u: Vec<f64> = depth.iter().map(|&v| units.inverse_depth(v) as f64).collect();
    let quad = fit_quadratic(&z, &s);
    let thin = fit_thin_lens(&u, &s, units);
    let score = |r: &Option<(DofCurve, Vec<f64>)>| r.as_ref().map(|(_, res)| huber_loss(res, robust_scale(res)));
    let (lq, lt) = (score(&quad), score(&thin));
    let pick_thin = match (lq, lt) {
        (Some(q), Some(t)) => t <= q * 1.01,
        (None, Some(_)) => true,
        _ => false,
    };
    let (curve, res) = if pick_thin { thin.clone()? } else { quad.clone()? };
    let scale = robust_scale(&res);
    let loss = huber_loss(&res, scale);
    let stderr_px = scale * (3.0 / z.len() as f64).sqrt();
    // Flatness: variation of the curve over the range vs its uncertainty.
    let evals: Vec<f32> = (0..=64)
        .map(|i| {
            let zz = depth_range[0] + (depth_range[1] - depth_range[0]) * i as f32 / 64.0;
            curve.sigma_px(units, zz)
        })
        .collect();
    let (mn, mx) = evals.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let curve = if ((mx - mn) as f64) < (3.0 * stderr_px).max(0.05) {
        let mut sv = s.clone();
        DofCurve::Constant { c: (median(&mut sv) as f32).clamp(0.0, crate::model::MAX_DOF_SIGMA_PX) }
    } else {
        curve
    };
    Some(CurveFit { curve, loss, scale, stderr_px, quadratic: quad.map(|(c, _)| c), thin_lens: thin.map(|(c, _)| c) })
}

/// The fitted curve's standard error as the RMS over `range` (65 depths, even in
/// Z) of its prediction standard error, from a cluster-robust (sandwich)
/// covariance of its linear parameters: bread Σ wᵢ xᵢxᵢᵀ, meat Σ_g (Σ_{i∈g} wᵢrᵢxᵢ)(…)ᵀ
/// over the samples' clusters `cluster[i]` (Huber weights wᵢ at `scale`), times
/// G/(G − 1). Why: samples of one edge or one patch of texture share their errors,
/// so scale·√(p/N) counts them as independent; and the prediction's variance grows
/// where the range lies beyond the samples' depths (leverage). The thin lens is
/// linear at its fitted focus (the focus's own uncertainty is left out).
/// With the number of clusters holding samples; None with fewer than 4 or a
/// singular design.
pub fn cluster_stderr(
    curve: &DofCurve,
    z: &[f32],
    s: &[f32],
    cluster: &[u32],
    scale: f64,
    units: DepthUnits,
    range: [f32; 2],
) -> Option<(f64, usize)> {
    let n = z.len().min(s.len()).min(cluster.len());
    let grid: Vec<f64> = (0..=64).map(|i| (range[0] + (range[1] - range[0]) * i as f32 / 64.0) as f64).collect();
    match *curve {
        DofCurve::Quadratic { a, b, c } => {
            let zm = z[..n].iter().map(|&v| v as f64).sum::<f64>() / n.max(1) as f64;
            let zs = (z[..n].iter().map(|&v| (v as f64 - zm).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt().max(1e-9);
            let x = |zz: f64| {
                let t = (zz - zm) / zs;
                [t * t, t, 1.0]
            };
            let f = |zz: f64| (a as f64 * zz + b as f64) * zz + c as f64;
            sandwich(
                n,
                |i| x(z[i] as f64),
                |i| s[i] as f64 - f(z[i] as f64),
                cluster,
                scale,
                grid.iter().map(|&g| x(g)),
            )
        }
        DofCurve::ThinLens { k, focus_depth, c0 } => {
            let uf = units.inverse_depth(focus_depth) as f64;
            let x = |zz: f32| [(units.inverse_depth(zz) as f64 - uf).abs(), 1.0];
            let f = |zz: f32| k as f64 * x(zz)[0] + c0 as f64;
            sandwich(n, |i| x(z[i]), |i| s[i] as f64 - f(z[i]), cluster, scale, grid.iter().map(|&g| x(g as f32)))
        }
        DofCurve::Constant { c } => {
            sandwich(n, |_| [1.0], |i| s[i] as f64 - c as f64, cluster, scale, grid.iter().map(|_| [1.0]))
        }
    }
}

fn sandwich<const P: usize>(
    n: usize,
    row: impl Fn(usize) -> [f64; P],
    res: impl Fn(usize) -> f64,
    cluster: &[u32],
    scale: f64,
    at: impl Iterator<Item = [f64; P]>,
) -> Option<(f64, usize)> {
    let groups = cluster[..n].iter().map(|&c| c as usize + 1).max().unwrap_or(0);
    let mut score = vec![[0.0f64; P]; groups];
    let mut bread = nalgebra::SMatrix::<f64, P, P>::zeros();
    let k = HUBER_K * scale.max(1e-6);
    for i in 0..n {
        let (x, r) = (row(i), res(i));
        if !r.is_finite() {
            continue;
        }
        let w = if r.abs() <= k { 1.0 } else { k / r.abs() };
        for a in 0..P {
            score[cluster[i] as usize][a] += w * r * x[a];
            for b in 0..P {
                bread[(a, b)] += w * x[a] * x[b];
            }
        }
    }
    let mut meat = nalgebra::SMatrix::<f64, P, P>::zeros();
    let mut g = 0usize;
    for sc in score.iter().filter(|sc| sc.iter().any(|&v| v != 0.0)) {
        g += 1;
        let v = nalgebra::SVector::<f64, P>::from_column_slice(sc);
        meat += v * v.transpose();
    }
    if g < 4 {
        return None;
    }
    let inv = bread.try_inverse()?;
    let cov = inv * meat * inv * (g as f64 / (g - 1) as f64);
    let (mut sum, mut m) = (0.0f64, 0usize);
    for x in at {
        let v = nalgebra::SVector::<f64, P>::from_column_slice(&x);
        sum += (v.transpose() * cov * v)[(0, 0)].max(0.0);
        m += 1;
    }
    let out = (sum / m.max(1) as f64).sqrt();
    out.is_finite().then_some((out, g))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The focus grid's lanes are `thin_lens_loss` at each focus, bit for bit
    /// (exact: the same steps per lane, the grid's choice must not move): foci
    /// inside, at the edge of and beyond the samples, one whose fit slopes the
    /// wrong way (∞), on thin-lens samples with outliers, and on samples at one
    /// depth (the ridge's degenerate design).
    #[test]
    fn focus_lanes_are_the_single_focus_losses() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let u: Vec<f64> = (0..700).map(|_| 0.2 + 1.6 * rnd()).collect();
        let s: Vec<f64> = u
            .iter()
            .enumerate()
            .map(|(i, &ui)| 3.0 * (ui - 0.9).abs() + 0.4 + 0.2 * (rnd() - 0.5) + if i % 17 == 0 { 4.0 } else { 0.0 })
            .collect();
        let flat_u = vec![0.7f64; 300];
        let flat_s: Vec<f64> = (0..300).map(|_| 1.0 + rnd()).collect();
        let falling: Vec<f64> = u.iter().map(|&ui| 5.0 - 2.0 * ui).collect();
        let mut infinite = 0;
        for (uu, ss) in [(&u, &s), (&flat_u, &flat_s), (&u, &falling)] {
            for foci in [[0.9, 0.2, 1.8, 2.5], [0.0, 0.7, 0.905, -1.0]] {
                for iters in [1, 6] {
                    let lanes = thin_lens_losses(uu, ss, foci, iters);
                    for (l, &f) in foci.iter().enumerate() {
                        let one = thin_lens_loss(uu, ss, f, iters);
                        assert_eq!(
                            lanes[l].to_bits(),
                            one.to_bits(),
                            "focus {f}, {iters} steps: {} for {one}",
                            lanes[l]
                        );
                        infinite += one.is_infinite() as usize;
                    }
                }
            }
        }
        assert!(infinite > 0, "no lane's fit sloped the wrong way");
    }

    /// Samples that share their errors are counted once: every sample repeated four
    /// times reads the same standard error as the set once, when each copy shares
    /// its original's cluster (to the G/(G − 1) factor, the same G) — and half of
    /// it (1/√4) when every copy is taken as independent.
    /// Tolerance 1e-9 relative for the equality (float sums in another order), 1%
    /// for the half (G/(G − 1) of 40 vs 160 clusters).
    #[test]
    fn shared_errors_are_counted_once() {
        let units = DepthUnits::MetricM;
        let z: Vec<f32> = (0..40).map(|i| 0.8 + 0.07 * i as f32).collect();
        let noise = |i: usize| ((i * 37 % 11) as f32 - 5.0) * 0.03;
        let s: Vec<f32> = z.iter().enumerate().map(|(i, &z)| 0.2 * z * z - 0.5 * z + 1.0 + noise(i)).collect();
        let curve = fit_dof_curve(&z, &s, units, [0.8, 3.53]).expect("fits").curve;
        let range = [0.8, 3.53];
        let own: Vec<u32> = (0..40).collect();
        let (once, g) = cluster_stderr(&curve, &z, &s, &own, 0.1, units, range).expect("40 clusters");
        assert_eq!(g, 40);
        let rep = |v: &[f32]| v.iter().flat_map(|&x| [x; 4]).collect::<Vec<f32>>();
        let (z4, s4) = (rep(&z), rep(&s));
        let shared: Vec<u32> = (0..160).map(|i| i / 4).collect();
        let (same, _) = cluster_stderr(&curve, &z4, &s4, &shared, 0.1, units, range).expect("40 clusters");
        assert!((same / once - 1.0).abs() < 1e-9, "{same} vs {once}");
        let apart: Vec<u32> = (0..160).collect();
        let (half, _) = cluster_stderr(&curve, &z4, &s4, &apart, 0.1, units, range).expect("160 clusters");
        assert!((half / (0.5 * once) - 1.0).abs() < 0.01, "{half} vs {}", 0.5 * once);
    }

    /// Beyond the samples' depths the prediction's error grows (leverage): the same
    /// fit read over twice its span reads a larger standard error, for each form.
    /// Fewer than four clusters give none.
    #[test]
    fn extrapolation_widens_and_few_clusters_give_none() {
        let units = DepthUnits::MetricM;
        let z: Vec<f32> = (0..60).map(|i| 1.5 + 0.02 * i as f32).collect();
        let s: Vec<f32> = z
            .iter()
            .enumerate()
            .map(|(i, &z)| 1.5 * (1.0 / z - 0.5).abs() + 0.3 + ((i % 5) as f32 - 2.0) * 0.02)
            .collect();
        let cells: Vec<u32> = (0..60).map(|i| i / 6).collect();
        for curve in [
            DofCurve::Quadratic { a: 0.1, b: -0.2, c: 0.5 },
            DofCurve::ThinLens { k: 1.5, focus_depth: 2.0, c0: 0.3 },
            DofCurve::Constant { c: 0.4 },
        ] {
            let (inside, _) = cluster_stderr(&curve, &z, &s, &cells, 0.05, units, [1.5, 2.68]).expect("10 clusters");
            let (beyond, _) = cluster_stderr(&curve, &z, &s, &cells, 0.05, units, [0.9, 3.3]).expect("10 clusters");
            assert!(inside > 0.0 && inside.is_finite(), "{curve:?}: {inside}");
            match curve {
                // A constant has no leverage: the same error anywhere.
                DofCurve::Constant { .. } => assert!((beyond / inside - 1.0).abs() < 1e-9, "{inside} vs {beyond}"),
                _ => assert!(beyond > 1.5 * inside, "{curve:?}: {inside} → {beyond}"),
            }
            let three: Vec<u32> = (0..60).map(|i| i % 3).collect();
            assert!(cluster_stderr(&curve, &z, &s, &three, 0.05, units, [1.5, 2.68]).is_none());
        }
    }
}
