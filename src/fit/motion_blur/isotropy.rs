//! The blind exposure's isotropy estimator: the root of the along/across gradient
//! energy balance over sampled profiles, its subsets' spread, the texture prior's
//! band and the evidence per flow direction the worker pools (`fit_fast`'s fallback
//! where the streak zeros are not identified; its method is documented there).

use super::{profile_intervals, profile_midpoint, push_profiles4, AtLambda, GridTaps, Profiles, MIN_SAMPLES};
use crate::fit::isotropy_pool::{interp, IsotropyEvidence, GRID};
use crate::image::{Flow, Plane};

/// Blind tier: pixels (each with 4 profiles) and interleaved subsets for the
/// standard error. `FitOptions::fast_effort` scales the pixels (`fast_samples`).
const FAST_SAMPLES: usize = 4096;
const FAST_SUBSETS: usize = 4;
/// How far a sharp natural scene's gradient-energy ratio along vs across a
/// direction, C(0)/D(0) − 1 over the isotropy estimator's own pixel selection,
/// strays from 1 — the 90th percentile of |·|, measured on the astronaut, chelsea
/// and Motorcycle photographs at 12 directions each (36 values: median 0.052, 68th
/// percentile 0.097, 90th 0.21, largest 0.29 — the astronaut). The isotropy root
/// assumes 0; the λ range [root at 1 − this, root at 1 + this] is its ~90% band.
pub(super) const TEXTURE_ANISOTROPY_90: f64 = 0.21;
/// The isotropy's pixels at `effort`: `FAST_SAMPLES` scaled, never below 4 subsets
/// of `MIN_SAMPLES` (the root needs `MIN_SAMPLES` in all).
pub(super) fn fast_samples(effort: f32) -> usize {
    crate::fit::scaled_count(FAST_SAMPLES, effort).max(FAST_SUBSETS * MIN_SAMPLES)
}

/// The isotropy root on plane `p` at `scale` (1: the frame; 2: its reduction, whose
/// pixel (x, y) sits at frame pixel (2x, 2y)); `Err(samples)` below `MIN_SAMPLES`.
/// Samples are frame pixels with flow ≥ 3 px/frame (and within the frame's
/// diagonal, `model::flow_within_frame`) and a gradient, picked by
/// gradient *magnitude* only, so the selection prefers no direction (`candidates`),
/// or the given `pixels` (the coarse scale takes the fine root's, `IsotropyRoot::pixels`).
/// `stats`: also the subsets' spread, the along-flow excess and the prior's band
/// (the frame's scale); without, the root alone (the coarse scale's root is only
/// compared with the fine one: its subsets' roots and excess were computed and never
/// read) and the other fields 0 / `None`.
pub(super) fn isotropy_root(
    p: &Plane,
    flow: &Flow,
    scale: usize,
    stats: bool,
    pixels: Option<&[Sample]>,
    max_samples: usize,
) -> Result<IsotropyRoot, usize> {
    let chosen = match pixels {
        Some(px) => px.to_vec(),
        None => candidates(p, flow, scale, max_samples),
    };
    // The root alone (the coarse scale) starts from g(0) = C(0) − D(0) and is λ 0
    // where that is ≥ 0 (below). g(0) reads each profile's midpoint only, which
    // `profile_midpoint` gives bit for bit without building the profile, summed in
    // the same order as `imbalance` sums: the same g(0), so the same answer, and on
    // a frame whose coarse root is 0 none of the profiles (the bench frame's coarse
    // stage 1.4 → 0.6 ms, most of what is left the half-scale luma's reduction).
    // Elsewhere the search below starts from this g(0).
    let mut g0 = None;
    if !stats {
        if chosen.len() < MIN_SAMPLES {
            return Err(chosen.len());
        }
        let (mut c, mut d) = (0.0f64, 0.0f64);
        for &sample in &chosen {
            let Geometry { x, y: yy, u, v, dir } = geometry(sample, scale);
            let b = |(ox, oy): (f32, f32)| profile_midpoint(p, x + ox, yy + oy, dir);
            let (b0, b1, b2, b3) = (b(u), b((-u.0, -u.1)), b(v), b((-v.0, -v.1)));
            c += (0.5 * (b0 - b1) as f64).powi(2);
            d += (0.5 * (b2 - b3) as f64).powi(2);
        }
        if c - d >= 0.0 {
            return Ok(IsotropyRoot::alone(0.0, chosen));
        }
        g0 = Some(c - d);
    }
    // Per sample: profiles along v (length |F|/scale) at p+u, p−u, p+v, p−v. The
    // node vectors sized for all of them first (grown by doubling, their copies
    // were ~0.5% of the fit's instructions).
    let nodes: usize = chosen.iter().map(|&s| 4 * (profile_intervals(geometry(s, scale).dir) + 1)).sum();
    let mut prof = Profiles {
        f: Vec::with_capacity(nodes),
        c: Vec::with_capacity(nodes),
        f2: vec![],
        c2: vec![],
        offsets: Vec::with_capacity(4 * chosen.len() + 1),
        target: Vec::with_capacity(chosen.len()),
    };
    prof.offsets.push(0);
    // Each sample's flow, for the direction bins of the evidence, and its squared
    // central differences along the two diagonals (u ± v)/√2 (`stats` only).
    let mut flows = vec![];
    let mut oblique: Vec<(f64, f64)> = vec![];
    for &sample in &chosen {
        let Geometry { x, y: yy, u: (ux, uy), v: (vx, vy), dir } = geometry(sample, scale);
        if stats {
            let (_, _, fx, fy) = sample;
            flows.push((fx, fy));
            let diff = |(dx, dy): (f32, f32)| {
                let (dx, dy) = (dx * std::f32::consts::FRAC_1_SQRT_2, dy * std::f32::consts::FRAC_1_SQRT_2);
                (0.5 * (p.sample_bilinear(x + dx, yy + dy) - p.sample_bilinear(x - dx, yy - dy)) as f64).powi(2)
            };
            oblique.push((diff((ux + vx, uy + vy)), diff((ux - vx, uy - vy))));
        }
        let at = [(ux, uy), (-ux, -uy), (vx, vy), (-vx, -vy)].map(|(ox, oy)| (x + ox, yy + oy));
        push_profiles4(&mut prof, p, at, dir);
        prof.target.push(0.0);
    }
    let n = prof.len();
    if n < MIN_SAMPLES {
        return Err(n);
    }
    // C − D at λ over the samples of one interleaved subset (`subset` of `of`; 0 of
    // 1: every sample). C/D rises with λ: the extra box along v lowers D.
    let imbalance = |lambda: f32, subset: usize, of: usize| -> f64 {
        let (mut c, mut d) = (0.0f64, 0.0f64);
        let mut at = AtLambda::new(lambda);
        for s in (subset..n).step_by(of) {
            let mut b = |k: usize| prof.blurred_at(4 * s + k, &mut at);
            let (b0, b1, b2, b3) = (b(0), b(1), b(2), b(3));
            c += (0.5 * (b0 - b1) as f64).powi(2);
            d += (0.5 * (b2 - b3) as f64).powi(2);
        }
        c - d
    };
    let g = |lambda: f32| imbalance(lambda, 0, 1);
    // Illinois regula falsi on [lo, hi] with g(lo) < 0 ≤ g(hi) given: C − kD is
    // smooth and monotone in λ, so it closes the bracket in a few evaluations where
    // bisection needs one per halving; each evaluation is a pass over every
    // sample's four profiles, the isotropy stage's cost.
    let refine = |g: &dyn Fn(f32) -> f64, (mut lo, mut f_lo): (f32, f64), (mut hi, mut f_hi): (f32, f64), tol: f32| {
        let mut side = 0i8;
        // Bisection would need log2(1/tol) steps; the cap only guards the arithmetic.
        for _ in 0..64 {
            if hi - lo < tol {
                break;
            }
            let mut mid = ((lo as f64 * f_hi - hi as f64 * f_lo) / (f_hi - f_lo)) as f32;
            if !(mid > lo && mid < hi) {
                mid = 0.5 * (lo + hi);
            }
            let f_mid = g(mid);
            if f_mid < 0.0 {
                (lo, f_lo) = (mid, f_mid);
                if side == -1 {
                    f_hi *= 0.5;
                }
                side = -1;
            } else {
                (hi, f_hi) = (mid, f_mid);
                if side == 1 {
                    f_lo *= 0.5;
                }
                side = 1;
            }
        }
        0.5 * (lo + hi)
    };
    // λ to 6e-5 (2^-14), far below the estimator's spread.
    const ROOT_TOL: f32 = 1.0 / 16384.0;
    if !stats {
        // The coarse scale's root alone: from the ends of [0, 1].
        let f0 = g0.unwrap_or_else(|| g(0.0));
        let lambda = if f0 >= 0.0 {
            0.0
        } else {
            let f1 = g(1.0);
            if f1 < 0.0 {
                1.0
            } else {
                refine(&g, (0.0, f0), (1.0, f1), ROOT_TOL)
            }
        };
        return Ok(IsotropyRoot::alone(lambda, chosen));
    }
    // One pass: every sample's C and D at the grid's λs (`isotropy_pool::GRID`),
    // summed per interleaved subset (the root's spread) and per flow direction (the
    // pooled fit's evidence). The grid brackets the frame's and the subsets' roots,
    // which exact evaluations then refine; the prior's band is read off the grid
    // (cubic interpolation: within 0.006 of exact roots, mean 0.0003, over 194
    // frames of photographs blurred along several flow directions — inside a bound
    // of 1/256 on a bias). The stage costs ~0.7 ms more than root searches from
    // [0, 1] alone (8.7–9.7 against 8.0–8.4 ms at 1280×960, same-moment A/B,
    // BENCHMARKS.md).
    let mut sub = vec![[[0.0f64; GRID]; 2]; FAST_SUBSETS];
    let mut evidence = IsotropyEvidence::default();
    let (mut c, mut d) = ([0.0f64; GRID], [0.0f64; GRID]);
    let mut b = [[0.0f32; GRID]; 4];
    let mut taps = GridTaps::new();
    for (s, &(fx, fy)) in flows.iter().enumerate() {
        for (k, bk) in b.iter_mut().enumerate() {
            prof.blurred_grid(4 * s + k, bk, &mut taps);
        }
        for j in 0..GRID {
            c[j] = (0.5 * (b[0][j] - b[1][j]) as f64).powi(2);
            d[j] = (0.5 * (b[2][j] - b[3][j]) as f64).powi(2);
        }
        let acc = &mut sub[s % FAST_SUBSETS];
        for j in 0..GRID {
            acc[0][j] += c[j];
            acc[1][j] += d[j];
        }
        evidence.add(fx, fy, &c, &d);
    }
    let mut total = [[0.0f64; GRID]; 2];
    for acc in &sub {
        for j in 0..GRID {
            total[0][j] += acc[0][j];
            total[1][j] += acc[1][j];
        }
    }
    let node = |j: usize| j as f32 / (GRID - 1) as f32;
    // The first node where C − kD ≥ 0: `Err(0)` at λ 0, `Err(1)` past λ 1, else the
    // bracket's upper node.
    let bracket = |cd: &[[f64; GRID]; 2], k: f64| -> Result<usize, f32> {
        match (0..GRID).find(|&j| cd[0][j] - k * cd[1][j] >= 0.0) {
            Some(0) => Err(0.0),
            Some(j) => Ok(j),
            None => Err(1.0),
        }
    };
    // The root of the interpolated C − kD, by bisection in its bracket.
    let grid_root = |cd: &[[f64; GRID]; 2], k: f64, tol: f32| -> f32 {
        let j = match bracket(cd, k) {
            Ok(j) => j,
            Err(end) => return end,
        };
        let gi = |l: f32| interp(&cd[0], l as f64) - k * interp(&cd[1], l as f64);
        let (mut lo, mut hi) = (node(j - 1), node(j));
        while hi - lo >= tol {
            let mid = 0.5 * (lo + hi);
            if gi(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    // A root of C − D refined by exact evaluations inside its grid bracket.
    let exact_root = |cd: &[[f64; GRID]; 2], g: &dyn Fn(f32) -> f64, tol: f32| match bracket(cd, 1.0) {
        Err(end) => end,
        Ok(j) => {
            let at = |j: usize| (node(j), cd[0][j] - cd[1][j]);
            refine(g, at(j - 1), at(j), tol)
        }
    };
    let lambda = exact_root(&total, &g, ROOT_TOL);
    let k = FAST_SUBSETS as f64;
    let mean_se = |parts: &[f64]| -> (f64, f64) {
        let mean = parts.iter().sum::<f64>() / k;
        (mean, (parts.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / (k - 1.0)).sqrt() / k.sqrt())
    };
    // (P − Q)/(P + Q) per subset, P and Q the diagonals' gradient energies.
    let contrast: Vec<f64> = (0..FAST_SUBSETS)
        .map(|j| {
            let (pp, qq) = oblique.iter().skip(j).step_by(FAST_SUBSETS).fold((0.0, 0.0), |a, o| (a.0 + o.0, a.1 + o.1));
            if pp + qq > 0.0 {
                (pp - qq) / (pp + qq)
            } else {
                0.0
            }
        })
        .collect();
    let (oblique_contrast, oblique_contrast_se) = mean_se(&contrast);
    // The texture prior's band: where the root would sit if the sharp scene's
    // along/across energy ratio were 1 ∓ `TEXTURE_ANISOTROPY_90` instead of 1 — on
    // the frame's scale only (the coarse root only checks the fine one), to 1/256
    // (a bound on a bias, not a measurement) — or as far as the anisotropy the frame
    // shows on its diagonals, where that is more (`anisotropy_ratios`).
    let [k_lo, k_hi] = anisotropy_ratios(oblique_contrast, oblique_contrast_se);
    let band = Some([grid_root(&total, k_lo, 1.0 / 256.0), grid_root(&total, k_hi, 1.0 / 256.0)]);
    // The subsets' roots to 1/1024, exact: their spread (~0.005 and up) is what is
    // read, and interpolation errors differ between subsets (they doubled the text
    // photograph's spread, 0.0045 → 0.0076).
    let parts: Vec<f64> = (0..FAST_SUBSETS)
        .map(|j| exact_root(&sub[j], &|l| imbalance(l, j, FAST_SUBSETS), 1.0 / 1024.0) as f64)
        .collect();
    // C(0)/D(0) − 1 per subset (the grid's first node is λ = 0).
    let excess: Vec<f64> =
        sub.iter().map(|cd| if cd[1][0] > 0.0 { (cd[0][0] - cd[1][0]) / cd[1][0] } else { 0.0 }).collect();
    let (along_excess, along_excess_se) = mean_se(&excess);
    // The same at the grid's last node, λ = 1.
    let top: Vec<f64> = sub
        .iter()
        .map(|cd| if cd[1][GRID - 1] > 0.0 { (cd[0][GRID - 1] - cd[1][GRID - 1]) / cd[1][GRID - 1] } else { 0.0 })
        .collect();
    let (top_excess, top_excess_se) = mean_se(&top);
    Ok(IsotropyRoot {
        lambda,
        spread: mean_se(&parts).1,
        n,
        along_excess,
        along_excess_se,
        top_excess,
        top_excess_se,
        oblique_contrast,
        oblique_contrast_se,
        band,
        evidence: Some(evidence),
        pixels: chosen,
    })
}

/// The along/across energy ratios C/D of the sharp texture that bound the
/// isotropy root's band: 1 ∓ `TEXTURE_ANISOTROPY_90` (natural scenes), widened to
/// the anisotropy the frame itself proves on its diagonals.
///
/// A texture's directional gradient energy is uᵀJu, a second harmonic
/// m·(1 + A·cos 2(θ − θ₀)) of the direction θ (J its structure tensor): its
/// along/across contrast (C − D)/(C + D) is a = A·cos 2θ₀ and its diagonals'
/// (P − Q)/(P + Q) is b = A·sin 2θ₀ (θ₀ from the flow). A streak along the flow is
/// mirror-symmetric about it and moves P and Q alike, so b is the texture's; a is
/// what the isotropy root confounds with the streak. One frame proves A ≥ |b|: the
/// along/across contrast may be as large, a ratio (1 ∓ |b|)/(1 ± |b|), and the
/// band reaches that far where it is wider than the prior (|b| less two standard
/// errors: sampling alone never widens it).
///
/// The bound, not more: under a heavy-tailed prior on (a, b) — over four
/// photographs at 12 directions |b| has median 0.028 and 90th percentile 0.176,
/// a Cauchy's ratio — the 90% half-width of a given b is 2.06·|b|, but that
/// refused 19 of the 144 held-out box-streak frames (15 of them read right; the
/// bound: 3) for 6 more oriented-texture frames (BENCHMARKS.md "Oriented texture
/// at an angle to the flow"). Measured: an oriented texture (σ 3 / 1.2 px) 20° and
/// 30° off the flow, where |b| reads 0.25–0.36 and 0.32–0.48, read *present* and
/// missed the truth on 20 of 24 frames without the bound (λ 0.37–1.0 for none), on
/// 1 with it; at 10° (|b|
/// 0.14–0.19) and along the axis (b = 0) one frame cannot tell.
pub(super) fn anisotropy_ratios(oblique_contrast: f64, oblique_contrast_se: f64) -> [f64; 2] {
    let a = (oblique_contrast.abs() - 2.0 * oblique_contrast_se).clamp(0.0, 0.9);
    [(1.0 - TEXTURE_ANISOTROPY_90).min((1.0 - a) / (1.0 + a)), (1.0 + TEXTURE_ANISOTROPY_90).max((1.0 + a) / (1.0 - a))]
}

/// The reason's account of the band: the anisotropy it allows — the natural
/// prior's, or what the diagonals prove (`anisotropy_ratios`) where that is more —
/// and the λ range that puts the root in.
pub(super) fn band_note(oblique_contrast: f64, oblique_contrast_se: f64, band: [f32; 2]) -> String {
    let [k_lo, k_hi] = anisotropy_ratios(oblique_contrast, oblique_contrast_se);
    let allowed = if k_hi > 1.0 + TEXTURE_ANISOTROPY_90 {
        format!(
            "the frame's own texture anisotropy (its diagonals' gradient-energy contrast {oblique_contrast:.3} ± \
             {oblique_contrast_se:.3}, beyond natural scenes': along/across ratios {k_lo:.2}–{k_hi:.2})"
        )
    } else {
        format!(
            "a natural texture anisotropy (±{:.0}%, 90% of scenes; the diagonals' contrast {oblique_contrast:.3} ± \
             {oblique_contrast_se:.3} shows no more)",
            100.0 * TEXTURE_ANISOTROPY_90
        )
    };
    format!("{allowed} would put it anywhere in [{:.3}, {:.3}]", band[0], band[1])
}

/// The isotropy samples at `scale`: frame pixels with flow ≥ 3 px/frame and a
/// gradient on `p`, thinned evenly to at most `max_samples` (`FAST_SAMPLES` at
/// full effort; see `isotropy_root`).
fn candidates(p: &Plane, flow: &Flow, scale: usize, max_samples: usize) -> Vec<Sample> {
    let (w, h) = (flow.width, flow.height);
    let mut cand = vec![];
    // Every other pixel of the scale, coarser on large frames: only `max_samples`
    // are kept, so scanning ~8× that many positions (not 300 000 at 1280×960) leaves
    // the selection as even and as magnitude-only as before, at a ninth of the scan.
    let positions = (w / (2 * scale)).max(1) * (h / (2 * scale)).max(1);
    let thin = ((positions as f64 / (8 * max_samples) as f64).sqrt().floor() as usize).max(1);
    let step = 2 * scale * thin;
    for py in (2 * scale..h.saturating_sub(2 * scale)).step_by(step) {
        for px in (2 * scale..w.saturating_sub(2 * scale)).step_by(step) {
            let (qx, qy) = (px / scale, py / scale);
            if qx + 1 >= p.width || qy + 1 >= p.height || qx == 0 || qy == 0 {
                continue;
            }
            let i = py * w + px;
            let (fx, fy) = (flow.dx[i], flow.dy[i]);
            // Flow below 3 px/frame: the ±1 px derivative cannot resolve the box.
            let speed_sq = fx * fx + fy * fy;
            if speed_sq.is_nan() || speed_sq < 9.0 || !crate::model::flow_within_frame(fx, fy, w, h) {
                continue;
            }
            let gx = 0.5 * (p.get(qx + 1, qy) - p.get(qx - 1, qy));
            let gy = 0.5 * (p.get(qx, qy + 1) - p.get(qx, qy - 1));
            if gx * gx + gy * gy >= 1e-4 {
                cand.push((px, py, fx, fy));
            }
        }
    }
    let keep = cand.len().div_ceil(max_samples).max(1);
    cand.into_iter().step_by(keep).collect()
}

/// The isotropy root and its direction evidence on plane `p` (the frame's scale),
/// for the pooled fit's tests.
#[cfg(test)]
pub(in crate::fit) fn isotropy_evidence(p: &Plane, flow: &Flow) -> Option<(f32, IsotropyEvidence)> {
    isotropy_root(p, flow, 1, true, None, FAST_SAMPLES).ok().and_then(|r| Some((r.lambda, r.evidence?)))
}

/// What `isotropy_root` measured.
#[derive(Clone, Debug)]
pub(super) struct IsotropyRoot {
    pub(super) lambda: f32,
    /// Spread of the root over interleaved subsets / √subsets.
    pub(super) spread: f64,
    pub(super) n: usize,
    /// C(0)/D(0) − 1 (mean over subsets) and its standard error. A streak only
    /// lowers C, so a clearly positive excess proves texture with more gradient
    /// energy along the flow than across: isotropy is violated.
    pub(super) along_excess: f64,
    pub(super) along_excess_se: f64,
    /// C(1)/D(1) − 1 (mean over subsets) and its standard error: what is left of the
    /// along-flow deficit after a full-frame streak is undone. Clearly negative: the
    /// texture is smoother along the flow than any exposure explains.
    pub(super) top_excess: f64,
    pub(super) top_excess_se: f64,
    /// (P − Q)/(P + Q), P and Q the gradient energies along the diagonals
    /// (u + v)/√2 and (u − v)/√2 (mean over subsets), and its standard error. A
    /// streak along u is mirror-symmetric about u, so it moves P and Q alike:
    /// on an isotropic scene this is 0 at any exposure, and a clearly non-zero one
    /// is the texture's own anisotropy, at an angle to the flow.
    pub(super) oblique_contrast: f64,
    pub(super) oblique_contrast_se: f64,
    /// The roots at the C/D ratios of `anisotropy_ratios` (1 ∓ `TEXTURE_ANISOTROPY_90`,
    /// or wider where the diagonals prove more): the λ range the texture's anisotropy
    /// leaves open (~90% for natural scenes); with `stats` only (`None` at the coarse scale).
    pub(super) band: Option<[f32; 2]>,
    /// The samples' C and D on the pooled fit's λ grid by flow direction (with
    /// `stats` only).
    pub(super) evidence: Option<IsotropyEvidence>,
    /// The sample pixels (frame coordinates) the root was taken over: the coarse
    /// scale's root is taken over the same ones.
    pub(super) pixels: Vec<Sample>,
}

impl IsotropyRoot {
    /// The root alone over `pixels` (the coarse scale: no statistics).
    fn alone(lambda: f32, pixels: Vec<Sample>) -> Self {
        Self {
            lambda,
            spread: 0.0,
            n: pixels.len(),
            along_excess: 0.0,
            along_excess_se: 0.0,
            top_excess: 0.0,
            top_excess_se: 0.0,
            oblique_contrast: 0.0,
            oblique_contrast_se: 0.0,
            band: None,
            evidence: None,
            pixels,
        }
    }
}

/// A sample on the plane of `scale` (`geometry`).
struct Geometry {
    /// Its pixel on that plane.
    x: f32,
    y: f32,
    /// The flow's unit direction u and its normal v.
    u: (f32, f32),
    v: (f32, f32),
    /// Its profiles' extent: the flow's length on that plane, along v.
    dir: (f32, f32),
}

fn geometry((px, py, fx, fy): Sample, scale: usize) -> Geometry {
    let s = scale as f32;
    let speed = (fx * fx + fy * fy).sqrt() / s;
    let (ux, uy) = (fx / (speed * s), fy / (speed * s));
    let (vx, vy) = (-uy, ux);
    let (x, y) = ((px / scale) as f32, (py / scale) as f32);
    Geometry { x, y, u: (ux, uy), v: (vx, vy), dir: (vx * speed, vy * speed) }
}

/// An isotropy sample: its frame pixel and the flow there, read once by the
/// candidate scan. Reading the flow again at each chosen pixel (the profiles, the
/// coarse scale), after the scan has left those cache lines, costs a miss on each
/// of the two 4.9 MB flow planes per sample, ~43% of `isotropy_root`'s own time in
/// a `perf` profile of the bench frame.
pub(super) type Sample = (usize, usize, f32, f32);

#[cfg(test)]
mod tests {
    use super::super::push_profile;
    use super::*;
    use crate::image::Rgb;

    /// The band's ratios: the prior's where the diagonals show no more than natural
    /// anisotropy or only sampling; (1 ∓ a)/(1 ± a) beyond, a = |b| less two
    /// standard errors; the same for either sign of b; bounded where a nears 1.
    #[test]
    fn anisotropy_ratios_widen_only_beyond_the_prior_and_sampling() {
        let prior = [1.0 - TEXTURE_ANISOTROPY_90, 1.0 + TEXTURE_ANISOTROPY_90];
        assert_eq!(anisotropy_ratios(0.0, 0.0), prior);
        // b 0.08: (1 + b)/(1 − b) = 1.17, inside the prior's 1.21.
        assert_eq!(anisotropy_ratios(0.08, 0.0), prior);
        // b 0.3 but ± 0.15: sampling alone, not a texture.
        assert_eq!(anisotropy_ratios(0.3, 0.15), prior);
        // b 0.2 ± 0.01: a = 0.18.
        let a = 0.18;
        let [lo, hi] = anisotropy_ratios(0.2, 0.01);
        assert!((lo - (1.0 - a) / (1.0 + a)).abs() < 1e-12 && (hi - (1.0 + a) / (1.0 - a)).abs() < 1e-12, "{lo} {hi}");
        assert_eq!(anisotropy_ratios(-0.2, 0.01), [lo, hi]);
        let [lo, hi] = anisotropy_ratios(0.999, 0.0);
        assert!((lo - 0.1 / 1.9).abs() < 1e-12 && (hi - 19.0).abs() < 1e-9, "{lo} {hi}");
    }

    /// `push_profiles4` appends what four `push_profile` calls append (nodes, running
    /// sums, offsets), bit for bit: inside, near and across the plane's edge, at
    /// interval counts whose node counts leave tails of 1–16 nodes.
    #[test]
    fn four_profiles_at_once_are_four_profiles() {
        let (w, h) = (61usize, 47usize);
        let p = Plane::from_vec(w, h, (0..w * h).map(|i| ((i * 37) % 101) as f32 * 0.013 - 0.4).collect());
        let empty = || Profiles { f: vec![], c: vec![], f2: vec![], c2: vec![], offsets: vec![0], target: vec![] };
        for (x, y) in [(30.0f32, 20.0f32), (1.2, 3.7), (59.5, 45.9), (30.3, 46.5)] {
            for dir in [(3.1f32, 0.4f32), (-0.7, 5.9), (0.0, 0.2), (8.0, -1.0), (2.0, 2.0), (-4.6, -7.3), (20.0, 3.0)] {
                let at = [(x + 1.0, y), (x - 1.0, y), (x, y + 1.0), (x, y - 1.0)];
                let (mut one, mut four) = (empty(), empty());
                for &(px, py) in &at {
                    push_profile(&mut one, &p, px, py, dir);
                }
                push_profiles4(&mut four, &p, at, dir);
                let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&four.f), bits(&one.f), "({x}, {y}) along {dir:?}");
                assert_eq!(bits(&four.c), bits(&one.c), "({x}, {y}) along {dir:?}");
                assert_eq!(four.offsets, one.offsets, "({x}, {y}) along {dir:?}");
            }
        }
    }

    /// `profile_midpoint` (the coarse root's g(0) without the profiles) is the built
    /// profile's B(λ 0), and `blurred_grid` (lane-wise) is `blurred` at each grid
    /// node, bit for bit (exact: the early answer and the grid must be what the
    /// profiles give one node at a time): in the interior, where nodes leave the plane (clamped reads),
    /// at odd and even interval counts, the shortest profile (4 intervals) and past
    /// the interval cap.
    #[test]
    fn midpoint_and_grid_pass_are_the_profiles_own_values() {
        use crate::fit::motion_blur::profile_intervals;
        let (w, h) = (61usize, 47usize);
        let p = Plane::from_vec(w, h, (0..w * h).map(|i| ((i * 37) % 101) as f32 * 0.013 - 0.4).collect());
        let mut prof = Profiles { f: vec![], c: vec![], f2: vec![], c2: vec![], offsets: vec![0], target: vec![] };
        let mut want = vec![];
        let mut intervals = std::collections::BTreeSet::new();
        for (x, y) in [(30.0f32, 20.0f32), (1.2, 3.7), (59.5, 45.9), (-3.0, 10.0), (30.3, 46.5)] {
            for dir in
                [(3.1f32, 0.4f32), (-0.7, 5.9), (0.0, 0.2), (130.0, -20.0), (2.0, 2.0), (0.25, 1.75), (-4.6, -1.3)]
            {
                push_profile(&mut prof, &p, x, y, dir);
                want.push(profile_midpoint(&p, x, y, dir));
                intervals.insert(profile_intervals(dir));
            }
        }
        assert!(intervals.contains(&4) && intervals.contains(&256), "{intervals:?}");
        assert!(intervals.iter().any(|m| m % 2 == 1) && intervals.iter().any(|m| m % 2 == 0), "{intervals:?}");
        let mut at = AtLambda::new(0.0);
        for (i, v) in want.iter().enumerate() {
            assert_eq!(prof.blurred_at(i, &mut at).to_bits(), v.to_bits(), "profile {i}");
        }
        // The grid pass's lane-wise means are `blurred`'s at every node, bit for bit
        // (exact: the same operations per node), on the same profiles.
        let mut taps = GridTaps::new();
        let mut grid = [0.0f32; GRID];
        for i in 0..want.len() {
            prof.blurred_grid(i, &mut grid, &mut taps);
            for (j, g) in grid.iter().enumerate() {
                let one = prof.blurred(i, j as f32 / (GRID - 1) as f32);
                assert_eq!(g.to_bits(), one.to_bits(), "profile {i}, node {j}: {g} for {one}");
            }
        }
    }

    /// The diagonals' contrast is the texture's: on an isotropic texture it stays
    /// within sampling of 0 under any streak along the flow (the streak is
    /// mirror-symmetric about it), and on an oriented one it grows with the angle
    /// between the texture's axis and the flow (A·sin 2θ₀), a streak or not.
    /// Tolerance on the isotropic texture: 3 standard errors and 0.02, the one
    /// 480×400 realisation's own anisotropy (read: |r| ≤ 0.052 ± 0.019 over nine
    /// cases); the oriented one read 0.25 / 0.46 / 0.60 / 0.67 at 10–45°, 0.21–0.49
    /// under the streak.
    #[test]
    fn the_diagonals_contrast_is_the_textures_not_the_streaks() {
        let (w, h) = (480usize, 400usize);
        let read = |tex: &Rgb, deg: f32, lambda: f32| {
            let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
            let flow = Flow::uniform(w, h, 12.0 * c, 12.0 * s);
            let img = crate::synth::add_motion_blur(tex, &flow, lambda);
            let r = isotropy_root(&img.luma(), &flow, 1, true, None, FAST_SAMPLES).expect("textured");
            (r.oblique_contrast, r.oblique_contrast_se)
        };
        let round = crate::synth::sequence::anisotropic_texture(w, h, 2.0, 2.0, 7);
        for deg in [0.0f32, 30.0, 75.0] {
            for lambda in [0.0f32, 0.5, 1.0] {
                let (r, se) = read(&round, deg, lambda);
                assert!(r.abs() <= 3.0 * se + 0.02, "isotropic texture, {deg}°, λ {lambda}: {r:.4} ± {se:.4}");
            }
        }
        // σ 3 px along x, 1.2 across: the flow `deg` off its smooth axis.
        let oriented = crate::synth::sequence::anisotropic_texture(w, h, 3.0, 1.2, 7);
        let mut last = 0.0;
        for deg in [10.0f32, 20.0, 30.0, 45.0] {
            let (r, se) = read(&oriented, deg, 0.0);
            assert!(r > last + 3.0 * se, "oriented texture {deg}° off: {r:.4} ± {se:.4} after {last:.4}");
            last = r;
            let (r_blurred, _) = read(&oriented, deg, 0.5);
            assert!(r_blurred > 0.1, "oriented texture {deg}° off under a streak: {r_blurred:.4}");
        }
    }
}
