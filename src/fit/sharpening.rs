//! The ISP's sharpening read blindly from a frame's straight edges, by the
//! slanted-edge method of ISO 12233 (the edge located row by row from its
//! derivative's centroid, a line fitted through the centroids, every pixel near it a
//! sample of the edge profile at its own distance t from the line), fitted with the
//! unsharp mask's exact profile on the pixel grid.
//!
//! An edge of blur σ_e sampled at pixel centres is v(p) = Φ(t_p/σ_e); the mask
//! out = v + k·(v − G ∗ v) (`model::Sharpening`) blurs it with the discrete Gaussian
//! of variance σ² on the pixel grid, which along a line's normal n = (c, −s·c)
//! (slope s, c = 1/√(1 + s²)) is a distribution of variance σ² but not Gaussian: its
//! even cumulants are κ₄ = σ²·c⁴(1 + s⁴), κ₆ = σ²·c⁶(1 + s⁶) (each axis's discrete
//! Gaussian is a difference of two Poisson variables, all even cumulants σ²). So
//! G ∗ v at distance t is the distribution function of N(0, σ_e²) plus that one, by
//! Edgeworth's series to the third term (S² = σ_e² + σ², z = t/S):
//!
//!   Φ(z) − φ(z)·[κ₄/(24S⁴)·He₃(z) + κ₆/(720S⁶)·He₅(z) + κ₄²/(1152S⁸)·He₇(z)]
//!
//! (at σ ≤ 1 px a Gaussian of the same variance misses up to half the halo). Each
//! edge's samples y = α + β·(T₀ + k·T₁), T₀ = v, T₁ = v − G ∗ v, leave a residual
//! SSR_e(k, σ, σ_e); with every edge's noise variance unknown the frame's profile
//! log-likelihood is −½·Σ_e n_e·ln min_σe SSR_e, so frames add their tables and the
//! camera's (k, σ) minimise the sum (`SharpeningCosts`, `decide`). Every blur before
//! the mask (optics, pixel area, demosaicing) is in σ_e, free per edge.
//!
//! To first order a mask of small σ only narrows an edge (σ_e'² ≈ σ_e² − k·σ²), so
//! k, σ and σ_e trade against each other, and a real edge's blur is not Gaussian:
//! what the frame fixes is the halo. The headline is therefore model-free: the
//! edges' profiles, each scaled to its fit's far levels, pooled in 0.25-px bins of t,
//! and their overshoot past the bright level (a blur by any non-negative kernel
//! leaves a step monotone, so any overshoot is the ISP's), its error a jackknife
//! over groups of edges; the mask's (k, σ) is kept for rendering and must agree
//! (k > 0) for *present*. Measured by `tests/sharpening.rs` (docs/accuracy.md
//! "Sharpening").

use crate::image::Rgb;
use crate::model::{Diagnostics, Sharpening, Status, SHARPENING_AMOUNT_RANGE, SHARPENING_RADIUS_RANGE_PX};

/// Edge cells (px): an edge is read over `CELL` pixels along it.
const CELL: usize = 16;
/// Samples at |t| ≤ `REACH_PX` from the line: the halo of σ ≤ 3 px on an edge of
/// σ_e ≤ 1.5 px is within 2S ≈ 6.7 px.
const REACH_PX: f64 = 7.0;
/// The derivative's centroid is taken over ±`CENTROID_HALF` px of the line.
const CENTROID_HALF: i64 = 5;
/// A cell's gradients must agree on one direction: coherence ((λ₁ − λ₂)/(λ₁ + λ₂))²
/// of its structure tensor at least this.
const MIN_COHERENCE: f64 = 0.8;
/// The centroids' RMS distance from their line (px) at most this: a curved or
/// broken edge is not one step.
const MAX_LINE_RMS_PX: f64 = 0.35;
/// The step (encoded units) at least this, its two sides' samples past
/// `PLATEAU_FROM_PX` left by its best fit with an RMS under `PLATEAU_FLATNESS` of the
/// step: texture or another edge beside it would read as a halo.
const MIN_STEP: f64 = 0.06;
const PLATEAU_FROM_PX: f64 = 4.5;
const PLATEAU_FLATNESS: f64 = 0.06;
/// Before any fit, either side's raw std past `PLATEAU_FROM_PX` over this share of
/// the step drops the edge: a mask's halo tail there stays under a few per cent of it.
const PREFILTER_ROUGHNESS: f64 = 0.15;
/// No sample may be clipped: a clipped side loses its overshoot.
const CLIP: [f32; 2] = [0.01, 0.99];
/// Fewest edges (over all frames pooled) for a reading.
pub const MIN_EDGES: usize = 20;
/// Edge blur grid σ_e (px).
const EDGE_SIGMA_STEPS: usize = 19;
fn edge_sigma(i: usize) -> f64 {
    0.4 + 0.1 * i as f64
}
/// Mask radius grid σ (px).
pub const RADII: [f64; 8] = [0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0];
/// Amount grid: −0.5 (a blurring ISP; read as none) to 4 in steps of 0.025.
const AMOUNT_STEPS: usize = 181;
fn amount(i: usize) -> f64 {
    -0.5 + 0.025 * i as f64
}
/// Jackknife groups.
const GROUPS: usize = 8;
/// Bin width (px) of the pooled, model-free edge profile.
const ESF_BIN_PX: f64 = 0.25;
const ESF_BINS: usize = (2.0 * REACH_PX / ESF_BIN_PX) as usize;
/// An overshoot under this share of the step is not modelled: 1.5% of a 0.5 step is
/// 2 of 255 levels on the edge's brightest pixel.
pub const MIN_VISIBLE_OVERSHOOT: f64 = 0.015;
/// Present beyond this many σ (and `MIN_VISIBLE_OVERSHOOT`).
pub const PRESENT_SIGMAS: f64 = 3.0;
/// Floor of the overshoot's σ: the jackknife over one scene's edges does not see
/// the bias its texture shares.
pub const STDERR_FLOOR: f64 = 0.003;

/// The summed profile log-likelihood tables of one or more frames: n_e·ln SSR per
/// (radius, amount), per jackknife group (their sum is the whole table). Frames
/// add (`add`).
#[derive(Clone, Debug, PartialEq)]
pub struct SharpeningCosts {
    groups: Vec<Vec<f64>>,
    /// Per group, the edges' profiles normalised to their fits' far levels (0 dark,
    /// 1 bright), summed per `ESF_BIN_PX` bin of t: (sum, count).
    esf: Vec<Vec<(f64, f64)>>,
    /// Edges read.
    pub edges: usize,
    /// Sum of the edges' best σ_e (px), for their mean.
    edge_sigma_sum: f64,
}

impl Default for SharpeningCosts {
    fn default() -> Self {
        let n = RADII.len() * AMOUNT_STEPS;
        Self {
            groups: vec![vec![0.0; n]; GROUPS],
            esf: vec![vec![(0.0, 0.0); ESF_BINS]; GROUPS],
            edges: 0,
            edge_sigma_sum: 0.0,
        }
    }
}

impl SharpeningCosts {
    /// Pool another frame's tables (frames' noise independent: log-likelihoods add).
    pub fn add(&mut self, other: &SharpeningCosts) {
        for (g, o) in self.groups.iter_mut().zip(&other.groups) {
            for (a, b) in g.iter_mut().zip(o) {
                *a += b;
            }
        }
        for (g, o) in self.esf.iter_mut().zip(&other.esf) {
            for (a, b) in g.iter_mut().zip(o) {
                a.0 += b.0;
                a.1 += b.1;
            }
        }
        self.edges += other.edges;
        self.edge_sigma_sum += other.edge_sigma_sum;
    }

    /// The overshoot of the pooled profile of the groups `keep` says: the bins'
    /// largest mean at 0 ≤ t < `PLATEAU_FROM_PX` over the bright level 1 (each
    /// edge's far level from its fit, which its plateau's many samples fix; the
    /// samples past `PLATEAU_FROM_PX` still hold the tail of a wide halo). A
    /// non-negative blur of a step is monotone: any overshoot is the ISP's.
    fn observed_overshoot(&self, keep: impl Fn(usize) -> bool) -> f64 {
        let mut bins = vec![(0.0, 0.0); ESF_BINS];
        for (_, esf) in self.esf.iter().enumerate().filter(|(g, _)| keep(*g)) {
            for (a, b) in bins.iter_mut().zip(esf) {
                a.0 += b.0;
                a.1 += b.1;
            }
        }
        let t_of = |i: usize| (i as f64 + 0.5) * ESF_BIN_PX - REACH_PX;
        let peak = bins
            .iter()
            .enumerate()
            .filter(|&(i, &(_, count))| count > 0.0 && (0.0..PLATEAU_FROM_PX).contains(&t_of(i)))
            .map(|(_, &(sum, count))| sum / count)
            .fold(f64::NEG_INFINITY, f64::max);
        peak - 1.0
    }

    /// Mean best edge blur σ_e (px) of the edges read, `None` without edges.
    pub fn mean_edge_sigma_px(&self) -> Option<f64> {
        (self.edges > 0).then(|| self.edge_sigma_sum / self.edges as f64)
    }
}

/// One frame's reading before `decide`: its tables over at most `max_edges` edges
/// (the strongest cells first; an edge whose best blur is the grid's top, 2.2 px,
/// left out).
pub fn frame_costs(image: &Rgb, max_edges: usize) -> SharpeningCosts {
    let grey = grey(image);
    let edges = find_edges(&grey, image.width, image.height, max_edges);
    let mut costs = SharpeningCosts::default();
    for e in &edges {
        let (table, sigma_e, (r, k)) = edge_table(e);
        // An edge blurrier than the grid's top would pull k down to fit its width.
        if sigma_e >= edge_sigma(EDGE_SIGMA_STEPS - 1) - 1e-9 {
            continue;
        }
        let (rms, levels) = plateau_residual(e, sigma_e, RADII[r], k);
        let step = levels[1] - levels[0];
        if !(step > 0.0 && rms <= PLATEAU_FLATNESS * step) {
            continue;
        }
        let g = costs.edges % GROUPS;
        for &(t, y) in &e.samples {
            let b = ((t as f64 + REACH_PX) / ESF_BIN_PX).floor() as usize;
            if let Some(bin) = costs.esf[g].get_mut(b) {
                bin.0 += (y as f64 - levels[0]) / step;
                bin.1 += 1.0;
            }
        }
        let n = e.samples.len() as f64;
        // Floor: noiseless synthetic edges would otherwise put ln 0 in the sum.
        let floor = n * 1e-9;
        for (j, ssr) in table.iter().enumerate() {
            let c = n * (ssr + floor).ln();
            costs.groups[g][j] += c;
        }
        costs.edges += 1;
        costs.edge_sigma_sum += sigma_e;
    }
    costs
}

/// The term from pooled tables: (k, σ) at the minimum (k refined by a parabola
/// through its grid neighbours), the pooled profile's model-free overshoot and its
/// jackknife σ over groups of edges (floored at `STDERR_FLOOR`). Present where the
/// overshoot is over `PRESENT_SIGMAS`·σ and `MIN_VISIBLE_OVERSHOOT` and the mask's
/// fit has k > 0; absent where the overshoot is under `MIN_VISIBLE_OVERSHOOT` at 2σ
/// (the reading kept, not applied); not identifiable otherwise, under `MIN_EDGES`
/// edges, or where k ends at the grid's top (a fit the edges' shape, not a mask,
/// drove there).
pub fn decide(costs: &SharpeningCosts, method: &str, started: std::time::Instant) -> Sharpening {
    let diag = |status, reason: String, stderr: Option<f64>| Diagnostics {
        status,
        reason,
        method: method.into(),
        residual_before: None,
        residual_after: None,
        samples_used: costs.edges as u64,
        fit_time_s: started.elapsed().as_secs_f64(),
        stderr,
        stages_s: Default::default(),
    };
    if costs.edges < MIN_EDGES {
        return Sharpening::absent(diag(
            Status::NotIdentifiable,
            format!("{} isolated straight edges, under {MIN_EDGES}", costs.edges),
            None,
        ));
    }
    let total: Vec<f64> = (0..costs.groups[0].len()).map(|j| costs.groups.iter().map(|g| g[j]).sum()).collect();
    let (k, radius) = minimum(&total);
    let observed = costs.observed_overshoot(|_| true);
    let jack: Vec<f64> = (0..GROUPS).map(|g| costs.observed_overshoot(|h| h != g)).collect();
    let mean = jack.iter().sum::<f64>() / GROUPS as f64;
    let var = (GROUPS - 1) as f64 / GROUPS as f64 * jack.iter().map(|o| (o - mean).powi(2)).sum::<f64>();
    let stderr = var.sqrt().max(STDERR_FLOOR);
    let edge_sigma = costs.mean_edge_sigma_px().unwrap_or(f64::NAN);
    let reason = format!(
        "overshoot {:.1}% ± {:.1}% of the step (1σ; {} edges, their blur {edge_sigma:.2} px); unsharp mask \
         k {k:.2}, σ {radius:.2} px",
        100.0 * observed,
        100.0 * stderr,
        costs.edges
    );
    if !(observed.is_finite() && stderr.is_finite()) {
        return Sharpening::absent(diag(Status::NotIdentifiable, format!("{reason}: not finite"), None));
    }
    let amount_k = k.clamp(SHARPENING_AMOUNT_RANGE[0] as f64, SHARPENING_AMOUNT_RANGE[1] as f64) as f32;
    let radius_px = radius.clamp(SHARPENING_RADIUS_RANGE_PX[0] as f64, SHARPENING_RADIUS_RANGE_PX[1] as f64) as f32;
    let with_values = |mut s: Sharpening| {
        s.amount = Some(amount_k);
        s.radius_px = Some(radius_px);
        s.overshoot = Some(observed.clamp(0.0, 1.0) as f32);
        s
    };
    if k >= amount(AMOUNT_STEPS - 1) - 0.05 {
        return Sharpening::absent(diag(
            Status::NotIdentifiable,
            format!("{reason}: the mask's fit ends at the grid's top (edges the model does not describe)"),
            Some(stderr),
        ));
    }
    if observed > PRESENT_SIGMAS * stderr && observed >= MIN_VISIBLE_OVERSHOOT && k > 0.0 {
        return with_values(Sharpening {
            present: true,
            ..Sharpening::absent(diag(Status::Present, reason, Some(stderr)))
        });
    }
    if observed + 2.0 * stderr <= MIN_VISIBLE_OVERSHOOT {
        return with_values(Sharpening::absent(diag(Status::Absent, reason, Some(stderr))));
    }
    Sharpening::absent(diag(
        Status::NotIdentifiable,
        format!(
            "{reason}: neither over {PRESENT_SIGMAS}σ and {:.1}% (with k > 0) nor under {:.1}% at 2σ",
            100.0 * MIN_VISIBLE_OVERSHOOT,
            100.0 * MIN_VISIBLE_OVERSHOOT
        ),
        Some(stderr),
    ))
}

/// One frame's term (`frame_costs` then `decide`), method "fast".
pub fn estimate(image: &Rgb, max_edges: usize) -> Sharpening {
    let started = std::time::Instant::now();
    decide(&frame_costs(image, max_edges), "fast", started)
}

/// (k, σ) at a table's minimum, k refined by a parabola through its neighbours.
fn minimum(table: &[f64]) -> (f64, f64) {
    let (best, _) = table
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .fold((0usize, f64::INFINITY), |(bi, bv), (i, &v)| if v < bv { (i, v) } else { (bi, bv) });
    let (r, a) = (best / AMOUNT_STEPS, best % AMOUNT_STEPS);
    let mut k = amount(a);
    if a > 0 && a + 1 < AMOUNT_STEPS {
        let (l, m, h) = (table[best - 1], table[best], table[best + 1]);
        let curv = l - 2.0 * m + h;
        if curv > 0.0 {
            k += 0.025 * (0.5 * (l - h) / curv).clamp(-0.5, 0.5);
        }
    }
    (k, RADII[r])
}

fn grey(image: &Rgb) -> Vec<f32> {
    let [r, g, b] = &image.channels;
    r.iter().zip(g).zip(b).map(|((r, g), b)| (r + g + b) / 3.0).collect()
}

/// One edge's samples: (t px, value), t positive on the bright side, and the
/// projected mask's cumulant factors c⁴(1 + s⁴), c⁶(1 + s⁶).
struct Edge {
    samples: Vec<(f32, f32)>,
    kappa4: f64,
    kappa6: f64,
}

/// Straight isolated edges in `CELL`-pixel cells, strongest first, at most
/// `max_edges` of them.
fn find_edges(grey: &[f32], w: usize, h: usize, max_edges: usize) -> Vec<Edge> {
    let at = |x: i64, y: i64| grey[y as usize * w + x as usize] as f64;
    let mut cells = Vec::new();
    let margin = 2;
    let mut cy = margin;
    while cy + CELL + margin <= h {
        let mut cx = margin;
        while cx + CELL + margin <= w {
            let (mut jxx, mut jxy, mut jyy) = (0.0, 0.0, 0.0);
            let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
            for y in cy..cy + CELL {
                for x in cx..cx + CELL {
                    let (xi, yi) = (x as i64, y as i64);
                    let gx = 0.5 * (at(xi + 1, yi) - at(xi - 1, yi));
                    let gy = 0.5 * (at(xi, yi + 1) - at(xi, yi - 1));
                    jxx += gx * gx;
                    jxy += gx * gy;
                    jyy += gy * gy;
                    let m = gx * gx + gy * gy;
                    sx += m * x as f64;
                    sy += m * y as f64;
                    sw += m;
                }
            }
            let tr = jxx + jyy;
            let det_root = ((jxx - jyy).powi(2) + 4.0 * jxy * jxy).sqrt();
            let (l1, l2) = (0.5 * (tr + det_root), 0.5 * (tr - det_root));
            let coherence = if tr > 0.0 { ((l1 - l2) / (l1 + l2)).powi(2) } else { 0.0 };
            // Mean squared gradient along the normal over (MIN_STEP / 4 px)²: at
            // least a step of MIN_STEP crossing the cell within a few pixels.
            let strong = l1 / (CELL * CELL) as f64 > (MIN_STEP / 4.0).powi(2) / 4.0;
            if coherence >= MIN_COHERENCE && strong && sw > 0.0 {
                // Normal: the eigenvector of λ₁.
                let (nx, ny) = if jxy.abs() > 1e-12 {
                    let (vx, vy) = (l1 - jyy, jxy);
                    let n = (vx * vx + vy * vy).sqrt();
                    (vx / n, vy / n)
                } else if jxx >= jyy {
                    (1.0, 0.0)
                } else {
                    (0.0, 1.0)
                };
                cells.push((l1, cx, cy, nx, ny, sx / sw, sy / sw));
            }
            cx += CELL;
        }
        cy += CELL;
    }
    cells.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut edges = Vec::new();
    for &(_, cx, cy, nx, ny, mx, my) in &cells {
        if edges.len() >= max_edges {
            break;
        }
        // Across axis a, along axis b: x/y for a near-vertical edge, else swapped.
        let vertical = nx.abs() >= ny.abs();
        let (na, nb, ma, mb, b0) = if vertical { (nx, ny, mx, my, cy) } else { (ny, nx, my, mx, cx) };
        let (wa, hb) = if vertical { (w, h) } else { (h, w) };
        let value = |a: i64, b: i64| if vertical { at(a, b) } else { at(b, a) };
        if let Some(e) = read_edge(value, wa as i64, hb as i64, b0 as i64, ma, mb, -nb / na) {
            edges.push(e);
        }
    }
    edges
}

/// The edge in rows b0..b0+CELL of the along axis (an axis-swapped view `value`
/// of size `wa` × `hb`), starting from the line a = ma + slope·(b − mb).
fn read_edge(value: impl Fn(i64, i64) -> f64, wa: i64, hb: i64, b0: i64, ma: f64, mb: f64, slope: f64) -> Option<Edge> {
    let bs: Vec<i64> = (b0..b0 + CELL as i64).collect();
    let (mut a0, mut s, b_mid) =
        (ma + slope * ((b0 as f64 + CELL as f64 / 2.0 - 0.5) - mb), slope, b0 as f64 + CELL as f64 / 2.0 - 0.5);
    if s.is_nan() || s.abs() > 1.05 {
        return None;
    }
    // Two passes of ISO 12233's centroid line fit.
    for _ in 0..2 {
        let mut pts = Vec::with_capacity(CELL);
        for &b in &bs {
            let ac = (a0 + s * (b as f64 - b_mid)).round() as i64;
            if ac - CENTROID_HALF - 1 < 0 || ac + CENTROID_HALF + 1 >= wa || b < 0 || b >= hb {
                return None;
            }
            let d: Vec<(f64, f64)> = (ac - CENTROID_HALF..=ac + CENTROID_HALF)
                .map(|a| (a as f64, value(a + 1, b) - value(a - 1, b)))
                .collect();
            let sum: f64 = d.iter().map(|(_, v)| v).sum();
            if sum.abs() < 1e-6 {
                return None;
            }
            pts.push((b as f64 - b_mid, d.iter().map(|(a, v)| a * v).sum::<f64>() / sum));
        }
        let n = pts.len() as f64;
        let (sb, sa) = pts.iter().fold((0.0, 0.0), |(x, y), (b, a)| (x + b, y + a));
        let (mb_, ma_) = (sb / n, sa / n);
        let sbb: f64 = pts.iter().map(|(b, _)| (b - mb_).powi(2)).sum();
        let sab: f64 = pts.iter().map(|(b, a)| (b - mb_) * (a - ma_)).sum();
        s = sab / sbb;
        a0 = ma_ - s * mb_;
        let rms = (pts.iter().map(|(b, a)| (a - a0 - s * b).powi(2)).sum::<f64>() / n).sqrt();
        if !(rms <= MAX_LINE_RMS_PX && s.abs() <= 1.05) {
            return None;
        }
    }
    let c = 1.0 / (1.0 + s * s).sqrt();
    let reach_a = (REACH_PX / c).ceil() as i64 + 1;
    let mut samples = Vec::with_capacity(CELL * (2 * reach_a as usize + 1));
    for &b in &bs {
        let line = a0 + s * (b as f64 - b_mid);
        let ac = line.round() as i64;
        if ac - reach_a < 0 || ac + reach_a >= wa {
            return None;
        }
        for a in ac - reach_a..=ac + reach_a {
            let t = (a as f64 - line) * c;
            if t.abs() <= REACH_PX {
                let v = value(a, b) as f32;
                if !(CLIP[0]..=CLIP[1]).contains(&v) {
                    return None;
                }
                samples.push((t as f32, v));
            }
        }
    }
    // Orientation and step: the two sides past PLATEAU_FROM_PX.
    let side = |sign: f32| {
        let v: Vec<f64> =
            samples.iter().filter(|(t, _)| sign * t >= PLATEAU_FROM_PX as f32).map(|&(_, v)| v as f64).collect();
        let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt();
        (m, sd, v.len())
    };
    let (hi, lo) = (side(1.0), side(-1.0));
    if hi.2 < CELL || lo.2 < CELL {
        return None;
    }
    let step = hi.0 - lo.0;
    // The isolation test proper needs the fit (`plateau_residual`); sides this
    // rough fail it whatever the fit, so they are not fitted.
    if step.abs() < MIN_STEP || hi.1.max(lo.1) > PREFILTER_ROUGHNESS * step.abs() {
        return None;
    }
    if step < 0.0 {
        for p in &mut samples {
            p.0 = -p.0;
        }
    }
    Some(Edge { samples, kappa4: c.powi(4) * (1.0 + s.powi(4)), kappa6: c.powi(6) * (1.0 + s.powi(6)) })
}

/// Bin width (px) of the profile's samples: a template evaluated at a bin's mean t
/// is off by its curvature times the bin's t variance (≤ 1/768 px²), far under the
/// noise.
const BIN_PX: f64 = 0.125;

/// The edge's min over σ_e of its residual per (radius, amount), and the σ_e of its
/// overall best fit. Samples are pooled in `BIN_PX` bins of t (count, mean t, mean
/// y); the residual is the bins' within-bin sum of squares plus their weighted
/// misfit.
fn edge_table(e: &Edge) -> (Vec<f64>, f64, (usize, f64)) {
    let mut bins: std::collections::BTreeMap<i64, (f64, f64, f64, f64)> = Default::default();
    for &(t, y) in &e.samples {
        let b = bins.entry((t as f64 / BIN_PX).floor() as i64).or_default();
        *b = (b.0 + 1.0, b.1 + t as f64, b.2 + y as f64, b.3 + (y as f64).powi(2));
    }
    // (weight, t, y) per bin and the within-bin sum of squares.
    let within: f64 = bins.values().map(|b| b.3 - b.2 * b.2 / b.0).sum::<f64>().max(0.0);
    let bins: Vec<(f64, f64, f64)> = bins.values().map(|b| (b.0, b.1 / b.0, b.2 / b.0)).collect();
    let n: f64 = bins.iter().map(|b| b.0).sum();
    let (sy, syy) = bins.iter().fold((0.0, 0.0), |(a, c), &(w, _, y)| (a + w * y, c + w * y * y));
    let cyy = syy - sy * sy / n;
    // Φ(t/σ_e) per σ_e and bin: independent of the radius.
    let table_n = normal_table();
    let t0: Vec<Vec<f64>> = (0..EDGE_SIGMA_STEPS)
        .map(|ei| bins.iter().map(|&(_, t, _)| table_n.at(t / edge_sigma(ei)).0).collect())
        .collect();
    let mut table = vec![f64::INFINITY; RADII.len() * AMOUNT_STEPS];
    let mut best = (f64::INFINITY, 0.0, (0usize, 0.0f64));
    for (r, &radius) in RADII.iter().enumerate() {
        for (ei, t0) in t0.iter().enumerate() {
            let se = edge_sigma(ei);
            let mask = MaskBlur::new(e, se, radius);
            let (mut s0, mut s1, mut s00, mut s01, mut s11, mut sy0, mut sy1) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            for (&(w, t, y), &v0) in bins.iter().zip(t0) {
                let v1 = v0 - mask.at(t, table_n);
                s0 += w * v0;
                s1 += w * v1;
                s00 += w * v0 * v0;
                s01 += w * v0 * v1;
                s11 += w * v1 * v1;
                sy0 += w * y * v0;
                sy1 += w * y * v1;
            }
            for a in 0..AMOUNT_STEPS {
                let k = amount(a);
                let st = s0 + k * s1;
                let stt = s00 + 2.0 * k * s01 + k * k * s11;
                let syt = sy0 + k * sy1;
                let ctt = stt - st * st / n;
                let cyt = syt - sy * st / n;
                // A fit with the step reversed (β ≤ 0) explains nothing.
                let ssr = within + if ctt > 1e-12 && cyt > 0.0 { (cyy - cyt * cyt / ctt).max(0.0) } else { cyy };
                let slot = &mut table[r * AMOUNT_STEPS + a];
                if ssr < *slot {
                    *slot = ssr;
                }
                if ssr < best.0 {
                    best = (ssr, se, (r, k));
                }
            }
        }
    }
    (table, best.1, best.2)
}

/// G ∗ v of an edge of blur σ_e under the mask of radius σ, at distance t: the
/// Edgeworth series of the module's doc, its coefficients fixed per (edge, σ_e, σ).
struct MaskBlur {
    big_s: f64,
    c4: f64,
    c6: f64,
    c44: f64,
}

impl MaskBlur {
    fn new(e: &Edge, edge_sigma_px: f64, radius_px: f64) -> Self {
        let var_m = radius_px * radius_px;
        let (k4, k6) = (var_m * e.kappa4, var_m * e.kappa6);
        let big_s = (edge_sigma_px * edge_sigma_px + var_m).sqrt();
        Self {
            big_s,
            c4: k4 / (24.0 * big_s.powi(4)),
            c6: k6 / (720.0 * big_s.powi(6)),
            c44: k4 * k4 / (1152.0 * big_s.powi(8)),
        }
    }

    #[inline]
    fn at(&self, t: f64, table: &NormalTable) -> f64 {
        let z = t / self.big_s;
        let z2 = z * z;
        let he3 = z * (z2 - 3.0);
        let he5 = z * (z2 * (z2 - 10.0) + 15.0);
        let he7 = z * (z2 * (z2 * (z2 - 21.0) + 105.0) - 105.0);
        let (cdf, pdf) = table.at(z);
        cdf - pdf * (self.c4 * he3 + self.c6 * he5 + self.c44 * he7)
    }
}

/// The mask's profile T₀ + k·T₁ of an edge at distance t (`edge_table`'s template).
fn template(e: &Edge, t: f64, edge_sigma_px: f64, radius_px: f64, k: f64) -> f64 {
    let table = normal_table();
    let v0 = table.at(t / edge_sigma_px).0;
    v0 + k * (v0 - MaskBlur::new(e, edge_sigma_px, radius_px).at(t, table))
}

/// RMS residual of the edge's best fit (α + β·template) over its samples past
/// `PLATEAU_FROM_PX`: what the mask cannot explain there is texture or another
/// edge.
/// Also the fit's dark and bright levels α + β·T(∓∞) = (α, α + β).
fn plateau_residual(e: &Edge, edge_sigma_px: f64, radius_px: f64, k: f64) -> (f64, [f64; 2]) {
    let pts: Vec<(f64, f64, f64)> = e
        .samples
        .iter()
        .map(|&(t, y)| (t as f64, template(e, t as f64, edge_sigma_px, radius_px, k), y as f64))
        .collect();
    let n = pts.len() as f64;
    let (mt, my) = pts.iter().fold((0.0, 0.0), |(a, b), p| (a + p.1 / n, b + p.2 / n));
    let ctt: f64 = pts.iter().map(|p| (p.1 - mt).powi(2)).sum();
    let cty: f64 = pts.iter().map(|p| (p.1 - mt) * (p.2 - my)).sum();
    let beta = if ctt > 0.0 { cty / ctt } else { 0.0 };
    let far: Vec<f64> =
        pts.iter().filter(|p| p.0.abs() >= PLATEAU_FROM_PX).map(|p| p.2 - (my + beta * (p.1 - mt))).collect();
    let alpha = my - beta * mt;
    ((far.iter().map(|r| r * r).sum::<f64>() / far.len().max(1) as f64).sqrt(), [alpha, alpha + beta])
}

fn phi_cdf(x: f64) -> f64 {
    0.5 * (1.0 + libm::erf(x * std::f64::consts::FRAC_1_SQRT_2))
}

/// Φ and φ tabulated on [−8, 8] every 1/512, read with linear interpolation: off by
/// at most h²/8·max|Φ''| ≈ 1.2e-7 and h²/8·max|φ''| ≈ 1.9e-7, under a thousandth of
/// an 8-bit step, at a fraction of erf's and exp's cost in the fits' inner loop.
struct NormalTable {
    cdf: Vec<f64>,
    pdf: Vec<f64>,
}

const TABLE_PER_UNIT: f64 = 512.0;
const TABLE_REACH: f64 = 8.0;

fn normal_table() -> &'static NormalTable {
    static T: std::sync::OnceLock<NormalTable> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        let n = (2.0 * TABLE_REACH * TABLE_PER_UNIT) as usize + 2;
        let x = |i: usize| i as f64 / TABLE_PER_UNIT - TABLE_REACH;
        NormalTable {
            cdf: (0..n).map(|i| phi_cdf(x(i))).collect(),
            pdf: (0..n).map(|i| (-0.5 * x(i) * x(i)).exp() * 0.398_942_280_401_432_7).collect(),
        }
    })
}

impl NormalTable {
    /// (Φ(x), φ(x)).
    #[inline]
    fn at(&self, x: f64) -> (f64, f64) {
        let u = ((x.clamp(-TABLE_REACH, TABLE_REACH) + TABLE_REACH) * TABLE_PER_UNIT).min(self.cdf.len() as f64 - 2.0);
        let i = u as usize;
        let f = u - i as f64;
        (self.cdf[i] + f * (self.cdf[i + 1] - self.cdf[i]), self.pdf[i] + f * (self.pdf[i + 1] - self.pdf[i]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Straight parallel bands at `angle_rad`, 20 px wide, between 0.25 and 0.65:
    /// each edge point-sampled from Φ(t/σ_e).
    fn bands_frame(w: usize, h: usize, angle_rad: f64, edge_sigma_px: f64) -> Rgb {
        let (c, s) = (angle_rad.cos(), angle_rad.sin());
        let data: Vec<f32> = (0..w * h)
            .map(|i| {
                let t = (i % w) as f64 * c + (i / w) as f64 * s + 0.37;
                // A rise at u = 0, a fall at u = 20; the next edges are ≥ 10 px away.
                let u = (t + 10.0).rem_euclid(40.0) - 10.0;
                (0.25 + 0.4 * (phi_cdf(u / edge_sigma_px) - phi_cdf((u - 20.0) / edge_sigma_px))) as f32
            })
            .collect();
        Rgb { width: w, height: h, channels: [data.clone(), data.clone(), data] }
    }

    fn with_noise(img: &Rgb, sigma: f32, seed: u64) -> Rgb {
        let mut rng = seed;
        let mut next = || {
            // xorshift64* then Box-Muller.
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut out = img.clone();
        let n: Vec<f32> = (0..img.width * img.height)
            .map(|_| {
                let (u, v) = (next().max(1e-12), next());
                ((-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()) as f32 * sigma
            })
            .collect();
        for ch in &mut out.channels {
            for (v, e) in ch.iter_mut().zip(&n) {
                *v = ((*v + e) * 255.0).round() / 255.0;
            }
        }
        out
    }

    /// Synthetic straight edges sharpened by the discrete mask (`synth::add_sharpening`)
    /// read their overshoot within 10% (the target is 20%; noise σ 0.005 and 8-bit
    /// steps on ~200 edges leave a few per cent), without the mask read absent, and a
    /// flat frame is not identifiable.
    #[test]
    fn edges_give_the_overshoot_and_the_three_states() {
        let angles = [0.13, 0.52, 0.93, 1.31, 1.9, 2.6];
        let read = |edge_sigma: f64, k: f64, radius: f64, seed: u64| {
            let started = std::time::Instant::now();
            let mut costs = SharpeningCosts::default();
            for (i, &angle) in angles.iter().enumerate() {
                let clean = bands_frame(256, 192, angle, edge_sigma);
                let frame = if k > 0.0 { crate::synth::add_sharpening(&clean, k as f32, radius as f32) } else { clean };
                costs.add(&frame_costs(&with_noise(&frame, 0.005, seed + i as u64), 400));
            }
            decide(&costs, "fast", started)
        };
        for (edge_sigma, k, radius) in [(1.0, 1.0, 1.0), (1.3, 0.6, 1.5), (0.8, 1.5, 0.75)] {
            let s = read(edge_sigma, k, radius, 7);
            let truth = Sharpening::overshoot(k, radius, edge_sigma);
            let got = s.overshoot.unwrap_or(0.0) as f64;
            let fitted =
                Sharpening::overshoot(s.amount.unwrap_or(0.0) as f64, s.radius_px.unwrap_or(1.0) as f64, edge_sigma);
            assert!((fitted / truth - 1.0).abs() <= 0.05, "the mask's fit: {fitted} for {truth}");
            eprintln!("k {k} σ {radius} σ_e {edge_sigma}: overshoot {got:.4} for {truth:.4}; {}", s.diagnostics.reason);
            assert_eq!(s.diagnostics.status, Status::Present, "{}", s.diagnostics.reason);
            assert!((got / truth - 1.0).abs() <= 0.10, "k {k} σ {radius}: {got} for {truth}: {}", s.diagnostics.reason);
            let none = read(edge_sigma, 0.0, 1.0, 17);
            eprintln!("none σ_e {edge_sigma}: {}", none.diagnostics.reason);
            assert_eq!(none.diagnostics.status, Status::Absent, "{}", none.diagnostics.reason);
        }
        let flat = Rgb { width: 256, height: 256, channels: [vec![0.5; 65536], vec![0.5; 65536], vec![0.5; 65536]] };
        assert_eq!(estimate(&flat, 400).diagnostics.status, Status::NotIdentifiable);
    }
}
