//! Depth of field δ(Z), blind: the frame and its depth alone.
//!
//! Zhuo & Sim 2011: at edges (gradient-magnitude maxima along the gradient, ≥ 0.03
//! per px), re-blur with σ0 = 3 px; for a Gaussian-blurred step the gradient ratio
//! R = |∇I| / |∇(I ∗ G_σ0)| gives σ = σ0/√(R² − 1). Three guards keep the ratio to
//! what it assumes, one step seen through noise: both gradients are averaged over 5
//! pixels along the edge (`EDGE_TANGENT_TAPS`; noise at the gradient maximum read δ
//! −45% on a noisy 2 px test frame); edges are selected on the nearly noise-free
//! re-blurred gradient (`EDGE_MIN_REBLUR_GRAD`; the frame's own threshold picked
//! noise-raised gradients); only isolated edges count (`isolated`: a thin bar's two
//! edges cancel in the re-blur and read δ low — on a texture of known blur RMSE
//! 0.24 px before, 0.056 px after, `tests/fast_path.rs`). The central difference
//! and pixel sampling bias the formula at small σ, so the raw value is mapped
//! through a table from a 1-D simulation of ideally sampled blurred steps (sub-pixel
//! phases averaged): an estimator calibration, not a camera calibration.
//! The re-blurred image is built at half resolution (`reblur_half`: the pyramid's
//! reduce, variance 1 px², then the remaining 8 px² at half resolution — the
//! σ0 = 3 px blur is band-limited far below the half-resolution Nyquist) and its
//! gradient read by bilinear interpolation; the table simulates exactly that
//! pipeline, so the approximation is calibrated out. A full-resolution blur of
//! 25 taps per pass cost 11 ms of the fast tier at 1280×960; this costs ~2 ms.
//!
//! Kernel shape (blind): `defocus_spectrum::disc_signature` looks for a round
//! aperture's disc in the frame's mean log spectrum over tiles with valid depth. A
//! disc sets `DofKernel::Disc` and maps the edge ratios through a table simulated
//! with the disc's edge-spread function instead of erf; when the frame holds one
//! depth (inverse depth's 5–95% spread ≤ 2%), the δ(Z) curve is the constant σ of
//! the disc radius itself, with the split-half standard error — edge ratios on a
//! uniformly defocused page of text are biased by its thin strokes (they read
//! 1.96 px for the 2.79 px of tests/real_blur.rs).

use super::*;

#[cfg(test)]
#[path = "blind_tables.rs"]
mod tables;

/// Raw Zhuo–Sim estimate → true σ for each kernel shape, from a 1-D simulation
/// (see module docs; `tables::measure_zhuo_sim_table`), stored in `measured.rs`: simulated
/// on first use it cost a fresh process ~5 ms (`crate::synth::measured_check`).
fn zhuo_sim_table(kernel: DofKernel) -> &'static [(f32, f32)] {
    match kernel {
        DofKernel::Gaussian => &super::measured::ZHUO_SIM_GAUSSIAN,
        DofKernel::Disc => &super::measured::ZHUO_SIM_DISC,
    }
}

/// The Zhuo–Sim re-blur (Gaussian of std `ZS_SIGMA0`) of the frame at half resolution,
/// from `half` = `reduce(y)` (binomial, variance 1 px², the even pixels; shared with
/// the exposure fit): a discrete Gaussian of the remaining (σ0² − 1)/4 half px².
fn reblur_half(half: &Plane) -> Plane {
    blur_separable(half, &discrete_gaussian_kernel((ZS_SIGMA0 * ZS_SIGMA0 - 1.0) / 4.0))
}

/// The re-blurred half-resolution frame (`reblur_half`) with its central differences
/// per full-resolution px, 0.25·(next − previous), at every interior pixel: made once,
/// row by row (contiguous: they vectorise; each row zeroed in cache, not a frame-size
/// memset ahead), for the edge scan's ~100 000 re-blurred gradient taps, which read 16
/// values and formed four differences each (the same differences).
struct Reblurred {
    half: Plane,
    gx: Vec<f32>,
    gy: Vec<f32>,
}

impl Reblurred {
    fn new(half: Plane) -> Self {
        let (w, h, d) = (half.width, half.height, &half.data);
        let (mut gx, mut gy) = (Vec::with_capacity(w * h), Vec::with_capacity(w * h));
        for y in 0..h {
            gx.resize((y + 1) * w, 0.0);
            gy.resize((y + 1) * w, 0.0);
            if w >= 3 && y >= 1 && y + 1 < h {
                let (up, row, down) = (&d[(y - 1) * w..y * w], &d[y * w..(y + 1) * w], &d[(y + 1) * w..(y + 2) * w]);
                let (ox, oy) = (&mut gx[y * w..(y + 1) * w], &mut gy[y * w..(y + 1) * w]);
                for x in 1..w - 1 {
                    ox[x] = 0.25 * (row[x + 1] - row[x - 1]);
                    oy[x] = 0.25 * (down[x] - up[x]);
                }
            }
        }
        Self { half, gx, gy }
    }

    /// Gradient (per full-resolution px) of the re-blurred image at full-resolution
    /// pixel (x, y): central differences of its bilinear interpolation (full-resolution
    /// pixel x sits at half-resolution x/2).
    #[inline]
    fn grad(&self, x: usize, y: usize) -> (f32, f32) {
        let half = &self.half;
        // Bilinear weights at (x/2, y/2) over the half-resolution central differences.
        let (hx, hy) = (0.5 * x as f32, 0.5 * y as f32);
        // x/2 ≥ 0: its integer part is the truncation (`floorf` is a libm call on
        // baseline x86-64), bit for bit.
        let (x0, y0) = ((x / 2) as isize, (y / 2) as isize);
        let (fx, fy) = (hx - x0 as f32, hy - y0 as f32);
        let lerp =
            |a: f32, b: f32, c: f32, d: f32| (1.0 - fy) * ((1.0 - fx) * a + fx * b) + fy * ((1.0 - fx) * c + fx * d);
        // Interior: every tap (x0 − 1 … x0 + 2, y0 − 1 … y0 + 2) inside, no clamps, the
        // differences read from the planes.
        let (hw, hh) = (half.width as isize, half.height as isize);
        if x0 >= 1 && y0 >= 1 && x0 + 2 < hw && y0 + 2 < hh {
            let w = half.width;
            let i = y0 as usize * w + x0 as usize;
            let (gx, gy) = (&self.gx, &self.gy);
            return (
                lerp(gx[i], gx[i + 1], gx[i + w], gx[i + w + 1]),
                lerp(gy[i], gy[i + 1], gy[i + w], gy[i + w + 1]),
            );
        }
        let g = |i: isize, j: isize| {
            (
                0.25 * (half.get_clamped(i + 1, j) - half.get_clamped(i - 1, j)),
                0.25 * (half.get_clamped(i, j + 1) - half.get_clamped(i, j - 1)),
            )
        };
        let (a, b, c, d) = (g(x0, y0), g(x0 + 1, y0), g(x0, y0 + 1), g(x0 + 1, y0 + 1));
        (lerp(a.0, b.0, c.0, d.0), lerp(a.1, b.1, c.1, d.1))
    }
}

const ZS_SIGMA0: f32 = 3.0;

/// Least gradient magnitude (per px) of an edge sample, on the pixel's own central
/// difference and again on the average along the edge.
const EDGE_MIN_GRAD: f32 = 0.03;

/// Each edge sample's gradients (frame and re-blurred) are the mean of 2k + 1
/// pixels along the edge's tangent (rounded to one of 8 directions, so every tap
/// is a pixel and nothing is interpolated). A straight edge's gradient is the same
/// along its tangent, so the mean keeps the edge profile the table was simulated
/// for while dividing the noise variance by 2k + 1. Why it matters: the ratio
/// takes the frame's gradient at its maximum, where noise adds to it — on the
/// calibration video at 1280×960 (noise std ≈ 0.02, edges blurred 1.4–2.9 px)
/// single-pixel ratios read δ up to 0.7 px (25%) low, and noise maxima in flat
/// regions (|∇n| of white noise exceeds 0.03 in ~10% of pixels there) entered as
/// sharp edges. k = 2 measured (BENCHMARKS.md): the noisy and the noise-free
/// frames then read within 0.16 px of each other; k = 4 read curved edges wider
/// (+0.2–0.3 px on noise-free frames).
const EDGE_TANGENT_TAPS: isize = 2;

/// Most edge samples (one per edge) the fast tier's curve fit takes (see
/// `fit_fast`): a bound on its cost for frames denser than the camera's. Measured
/// at 1280×960 (edges found by `fit_fast`'s scan): 2 676 edges on a sharp
/// textured frame (the astronaut photograph mirror-tiled), 1 089–1 113 on
/// `synth-video` frames, so the cap binds only on larger or denser frames.
const FAST_MAX_EDGE_SAMPLES: usize = 8192;

/// Least re-blurred gradient magnitude (per px, averaged along the edge like the
/// frame's) of an edge sample. The frame's own gradient threshold selects edges
/// whose gradient noise happened to push them over it, and those read δ low (a
/// larger frame gradient, a larger ratio); the re-blurred gradient is nearly
/// noise-free, so selecting on it does not bias the ratio, and at 0.04 the frame's
/// threshold does not bind (the frame's gradient is the re-blurred one × R > 1).
/// Blurry edges have the lowest gradients, so they felt it most: on the
/// procedural texture at 1280×960 with the video's noise, δ 2.7 px read for 2.87
/// at the near end, 2.81 with this threshold (noise-free: 2.82–2.85).
const EDGE_MIN_REBLUR_GRAD: f32 = 0.04;

/// How far along the normal another edge biases the re-blur ratio: the re-blurred
/// gradient at the edge weighs a neighbour at distance d by exp(−d²/2σ0²) — 0.14
/// at 2σ0 = 6 px, 0.07 at 7 px.
const INTERFERENCE_REACH_PX: f32 = 7.0;
/// Largest share of the edge's own gradient the profile along its normal may show
/// again within the reach (a rise past its running minimum, or a gradient of the
/// opposite sign: a neighbouring edge).
const INTERFERENCE_MAX_FRACTION: f32 = 0.2;

/// An edge candidate of the scan (`fit_fast`) on its scanned row: column, rounded
/// gradient direction, tangent-summed frame gradient, its mean magnitude, and the
/// frame-to-re-blurred gradient ratio once read.
#[derive(Clone, Copy)]
struct Edge {
    px: usize,
    s: (isize, isize),
    g: (f32, f32),
    m: f32,
    r: f32,
}

/// Fewest edges a reduced-effort scan (`FitOptions::fast_effort` < 1: a share of
/// the rows) must find before its samples are used alone (see `fit_fast`): below
/// it the other rows are read too, which makes the full scan. Full-effort scans
/// find ~2 300–3 000 edges on textured 1280×960 frames, 37–256 on edge-poor ones,
/// so a half-effort scan of a textured frame keeps over 1 000 and an edge-poor one
/// is read whole.
const EFFORT_MIN_EDGES: usize = 600;

/// Whether the edge at `c` (gradient direction rounded to `s`, unit `normal`,
/// tangent-averaged magnitude `peak`) is alone within `INTERFERENCE_REACH_PX`
/// along its normal: the gradient projected on the normal (averaged along the
/// tangent like the edge itself) falls off on both sides without rising again or
/// changing sign by more than `INTERFERENCE_MAX_FRACTION` of the peak. Zhuo–Sim's
/// ratio assumes one step: a thin line's two edges cancel in the re-blur and read
/// δ low, a staircase's add and read it high. Near the border the walk stops
/// (nothing seen is nothing against).
fn isolated(g: &GradRows, c: (isize, isize), s: (isize, isize), normal: (f32, f32), peak: f32) -> bool {
    let (w, h) = (g.w as isize, g.h as isize);
    let step = ((s.0 * s.0 + s.1 * s.1) as f32).sqrt();
    let reach = (INTERFERENCE_REACH_PX / step).ceil() as isize;
    let lim = INTERFERENCE_MAX_FRACTION * peak;
    let (t, k) = ((-s.1, s.0), EDGE_TANGENT_TAPS);
    let taps = (2 * k + 1) as f32;
    for dir in [-1isize, 1] {
        let mut low = peak;
        for d in 1..=reach {
            let (cx, cy) = (c.0 + dir * d * s.0, c.1 + dir * d * s.1);
            let (ax, ay, bx, by) = (cx - k * t.0, cy - k * t.1, cx + k * t.0, cy + k * t.1);
            if ax.min(bx) < 1 || ay.min(by) < 1 || ax.max(bx) >= w - 1 || ay.max(by) >= h - 1 {
                break;
            }
            let mut p = 0.0;
            for j in -k..=k {
                let (qx, qy) = ((cx + j * t.0) as usize, (cy + j * t.1) as usize);
                let (gx, gy) = g.at(qx, qy);
                p += gx * normal.0 + gy * normal.1;
            }
            p /= taps;
            if p < -lim || p > low + lim {
                return false;
            }
            low = low.min(p);
        }
    }
    true
}

/// Rows the edge scan reads around its scanned row py: the non-maximum suppression
/// py ± 1, the tangent mean py ± `EDGE_TANGENT_TAPS`, and `isolated`'s walk along
/// the normal, ⌈`INTERFERENCE_REACH_PX`⌉ steps of a rounded direction (≥ 1 px in y
/// when it moves in y) and the tangent taps around each.
const GRAD_ROWS_REACH: usize = INTERFERENCE_REACH_PX as usize + EDGE_TANGENT_TAPS as usize;
/// Rows `GradRows` holds: a power of two (the slot is the row's low bits) with room
/// for every row within `GRAD_ROWS_REACH` of the scanned one.
const GRAD_ROWS: usize = (2 * GRAD_ROWS_REACH + 1).next_power_of_two();
const _: () = assert!(
    INTERFERENCE_REACH_PX == GRAD_ROWS_REACH as f32 - EDGE_TANGENT_TAPS as f32 && GRAD_ROWS > 2 * GRAD_ROWS_REACH
);

/// The frame's central-difference gradients (per px) and their squared magnitudes
/// for the rows around the edge scan's row, each row computed once over its whole
/// width (contiguous: it vectorises) and kept in a ring of `GRAD_ROWS` rows. The
/// scan's three readers — the threshold and non-maximum suppression, the tangent
/// mean, `isolated`'s walk — would otherwise each take a scalar central difference
/// per tap (four reads and bounds checks; on the bench frame 84 101 suppression
/// taps, 32 702 × 5 tangent taps and at most 5 693 × 2 × 7 × 5 walk taps, a bound),
/// the same value `at` reads (the same two subtractions and products).
/// Columns 0 and w − 1 and rows outside [1, h − 2] are never computed: every reader
/// stays inside them.
struct GradRows {
    w: usize,
    h: usize,
    /// gx and gy per pixel, row slot by row slot (two planes, not pairs: the
    /// row's loop then stores whole lanes).
    gx: Vec<f32>,
    gy: Vec<f32>,
    /// gx² + gy² per pixel.
    m2: Vec<f32>,
    /// The frame row each slot holds (`usize::MAX`: none).
    held: [usize; GRAD_ROWS],
}

impl GradRows {
    fn new(w: usize, h: usize) -> Self {
        let plane = || vec![0.0; GRAD_ROWS * w];
        Self { w, h, gx: plane(), gy: plane(), m2: plane(), held: [usize::MAX; GRAD_ROWS] }
    }

    /// Make rows py − `GRAD_ROWS_REACH` … py + `GRAD_ROWS_REACH` (those in [1, h − 2])
    /// of frame `y` available.
    fn hold_around(&mut self, y: &Plane, py: usize) {
        let w = self.w;
        for yy in py.saturating_sub(GRAD_ROWS_REACH).max(1)..(py + GRAD_ROWS_REACH + 1).min(self.h - 1) {
            let slot = yy % GRAD_ROWS;
            if self.held[slot] == yy {
                continue;
            }
            let (up, row, down) =
                (&y.data[(yy - 1) * w..yy * w], &y.data[yy * w..(yy + 1) * w], &y.data[(yy + 1) * w..(yy + 2) * w]);
            let span = slot * w..(slot + 1) * w;
            let (ox, oy, m2) = (&mut self.gx[span.clone()], &mut self.gy[span.clone()], &mut self.m2[span]);
            // Columns 1 … w − 2 as zipped slices (indexed, the bounds checks kept the
            // loop near scalar: 3.3 instructions a pixel over every row of the frame,
            // 2.0 zipped, by callgrind).
            // (Under 3 columns there is no interior column: nothing to compute.)
            let inner = 1..w.max(2) - 1;
            let outs = ox[inner.clone()].iter_mut().zip(&mut oy[inner.clone()]).zip(&mut m2[inner.clone()]);
            let across = row.iter().zip(row.get(2..).unwrap_or_default());
            let vertical = up[inner.clone()].iter().zip(&down[inner]);
            for (((ox, oy), m2), ((&left, &right), (&u, &d))) in outs.zip(across.zip(vertical)) {
                let (gx, gy) = (0.5 * (right - left), 0.5 * (d - u));
                *ox = gx;
                *oy = gy;
                *m2 = gx * gx + gy * gy;
            }
            self.held[slot] = yy;
        }
    }

    /// Squared gradient magnitudes of held row `yy`.
    #[inline]
    fn m2_row(&self, yy: usize) -> &[f32] {
        let slot = yy % GRAD_ROWS;
        debug_assert_eq!(self.held[slot], yy);
        &self.m2[slot * self.w..(slot + 1) * self.w]
    }

    /// Central-difference gradient at (x, yy), yy a held row and 1 ≤ x ≤ w − 2.
    #[inline]
    fn at(&self, x: usize, yy: usize) -> (f32, f32) {
        let slot = yy % GRAD_ROWS;
        debug_assert_eq!(self.held[slot], yy);
        let i = slot * self.w + x;
        (self.gx[i], self.gy[i])
    }
}

fn calibrate(raw: f32, kernel: DofKernel) -> f32 {
    let t = zhuo_sim_table(kernel);
    // Below σ ≈ 0.25 px the raw value dips under its σ = 0 value (the central
    // difference cannot resolve such blur): anything up to t[0] reads 0, and above
    // it the raw value rises with σ from `i0` on (asserted by
    // `zhuo_sim_tables_are_monotone`): a binary search there, then linear
    // interpolation raw → σ between the neighbouring entries.
    if raw.is_nan() || raw <= t[0].0 {
        return 0.0;
    }
    let i0 = t.iter().position(|e| e.0 > t[0].0).unwrap_or(t.len());
    let i = i0 + t[i0..].partition_point(|e| e.0 < raw);
    if i >= t.len() {
        return t[t.len() - 1].1;
    }
    let ((r0, s0), (r1, s1)) = (t[i - 1], t[i]);
    s0 + (s1 - s0) * (raw - r0) / (r1 - r0).max(1e-9)
}

/// Fast tier: the frame and Z (Zhuo & Sim 2011 edge re-blur ratio).
pub fn fit_fast(
    luma: &crate::fit::SharedLuma,
    depth: &Plane,
    units: DepthUnits,
    opts: &crate::fit::FitOptions,
) -> (DepthOfField, Option<DofPlotData>) {
    let started = Instant::now();
    let mut st = crate::fit::Stages::start();
    // The frame's luma (shared with the motion-blur fit: whichever runs first pays).
    let y = luma.full();
    st.lap("luma");
    // Kernel shape (and a uniformly defocused frame's blur) from the spectrum, over
    // tiles whose depth is valid.
    let tile_ok = |x0: usize, y0: usize, t: usize| {
        (y0..y0 + t).step_by(8).all(|yy| (x0..x0 + t).step_by(8).all(|x| valid_depth(depth.get(x, yy), units)))
    };
    // (All 8 tiles at any `fast_effort`: fewer read Gaussian blur as a disc — on 3–4
    // of 24 thin-lens and quadratic frames at 4–6 tiles, 10 at 2; BENCHMARKS.md "The
    // fast tier's effort".)
    let spectrum = crate::fit::defocus_spectrum::disc_signature(y, tile_ok);
    st.lap("search.spectrum");
    let kernel = match &spectrum {
        Some(s) if s.is_disc => DofKernel::Disc,
        _ => DofKernel::Gaussian,
    };
    let shape_note = match &spectrum {
        Some(s) => format!(
            "kernel {} (spectrum over {} tiles of {} px: cepstral ring z {:.1} at R {:.2} px, second-notch contrast {:.3}; \
             a disc needs z ≥ {} and contrast ≥ {})",
            if s.is_disc { "disc" } else { "gaussian" },
            s.tiles,
            s.tile_px,
            s.ring_z,
            s.radius_px,
            s.notch_contrast,
            crate::fit::defocus_spectrum::RING_MIN_Z,
            crate::fit::defocus_spectrum::NOTCH_MIN_CONTRAST
        ),
        None => "kernel gaussian (too few textured tiles with valid depth for the spectrum)".into(),
    };
    // One depth across the frame: the spectrum's disc is the answer (edge ratios are
    // biased by thin strokes and texture; the ring measures the aperture itself).
    // (`constant_depth` reads 77 000 depths at 1280×960: only where a disc was seen.)
    // The spectrum comes first so that such a frame skips the re-blur and the edge
    // scan (~7 ms at 1280×960) whose samples it would not use.
    let disc = spectrum.as_ref().filter(|s| s.is_disc);
    if let Some((s, range)) = disc.and_then(|s| Some((s, constant_depth(depth, units)?))) {
        let c = s.sigma_px.min(opts.dof_max_sigma_px);
        // As `finish`: invisible is absent, visible within 3 standard errors of none
        // is not identifiable (it does not vote "absent" in the worker's window).
        let status = if c < 0.1 {
            Status::Absent
        } else if c > 3.0 * s.stderr_px {
            Status::Present
        } else {
            Status::NotIdentifiable
        };
        let present = status == Status::Present;
        let dof = DepthOfField {
            present,
            units,
            curve: Some(DofCurve::Constant { c }),
            depth_range: range,
            kernel,
            diagnostics: Diagnostics {
                status,
                reason: format!(
                    "one depth across the frame: constant δ {c:.3} px from the disc radius ({} px, second moment), \
                     ± {:.3} px (split-half spread of the ring, at least the radius mapping's own); \
                     {shape_note}; edge ratios not read (biased by thin strokes and texture where the disc \
                     measures the aperture)",
                    s.radius_px, s.stderr_px
                ),
                method: "fast".into(),
                residual_before: None,
                residual_after: None,
                samples_used: s.tiles as u64,
                fit_time_s: started.elapsed().as_secs_f64(),
                stderr: Some(s.stderr_px as f64),
                stages_s: st.done(),
            },
        };
        return (dof, None);
    }
    let re = Reblurred::new(reblur_half(luma.half()));
    st.lap("blur");
    let (w, h) = (y.width, y.height);
    // Every other row and column above 400k pixels: edges are lines, so a quarter of
    // their pixels still gives thousands of samples, at a quarter of the scan. A
    // lower effort reads its share of those rows (every 2nd at effort 0.5, every 4th
    // at 0.25) — unless that finds fewer than `EFFORT_MIN_EDGES` edges: then the
    // other rows are read too, which is the full scan (an edge-poor frame, the
    // rocket's sky at 37–256 edges, lost its curve on 2 of 6 frames to a coarser
    // scan without this guard; BENCHMARKS.md "The fast tier's effort").
    let full_step = if w * h > 400_000 { 2 } else { 1 };
    let row_share = (1.0 / opts.fast_effort.max(crate::fit::MIN_FAST_EFFORT)).round().max(1.0) as usize;
    // The rows of the full step's lattice whose index `i` satisfies `rows(i)`, every
    // `step`-th column: per sample its depth, σ and frame row (raster order).
    let scan = |rows: &dyn Fn(usize) -> bool| -> (Vec<f32>, Vec<f32>, Vec<(usize, usize)>) {
        let step = full_step;
        let (mut zs, mut sig, mut at) = (vec![], vec![], vec![]);
        // Central-difference gradients and their squared magnitudes of the rows
        // around py, each row computed over its whole width at once (contiguous, so it
        // vectorises; the per-pixel scalar path took 7.8 ms of 22 at 1280×960):
        // ~70% of the scanned pixels fail the edge threshold on them, the non-maximum
        // suppression reads its neighbours from them, and the tangent mean and the
        // isolation walk their taps (`GradRows`).
        let mut grads = GradRows::new(w, h);
        let min_sq = EDGE_MIN_GRAD * EDGE_MIN_GRAD;
        // A row's scanned positions over the threshold (at most every position).
        let mut above = vec![0usize; w / step + 1];
        // Those of them that are gradient maxima with a valid depth, with their
        // rounded gradient direction.
        let mut maxima = vec![(0usize, 0isize, 0isize); w / step + 1];
        // Those whose tangent-averaged gradients pass the thresholds (compacted in
        // place: the frame's, then the re-blurred frame's with its ratio).
        let mut edges = vec![Edge { px: 0, s: (0, 0), g: (0.0, 0.0), m: 0.0, r: 0.0 }; w / step + 1];
        for (_, py) in (2..h.saturating_sub(2)).step_by(step).enumerate().filter(|&(i, _)| rows(i)) {
            grads.hold_around(y, py);
            let m2 = [grads.m2_row(py - 1), grads.m2_row(py), grads.m2_row(py + 1)];
            // The row's positions over the threshold, gathered without a branch per
            // position (~28% pass on the bench frame: an unpredictable branch).
            let mut n_above = 0;
            for px in (2..w.saturating_sub(2)).step_by(step) {
                above[n_above] = px;
                n_above += (m2[1][px] >= min_sq) as usize;
            }
            // Non-maximum suppression along the (rounded) gradient direction, on
            // squared magnitudes (the square root is monotone), and the depth's
            // validity, for every position over the threshold — again gathered without
            // a branch (~39% survive on the bench frame: a branch per test mispredicted
            // for a good share of the scan's time). The direction is the unit
            // gradient's components rounded (ties away from zero, as `round`): each
            // compared against half the magnitude instead of divided by it (m > 0 past
            // the threshold; ×0.5 is exact, so only a quotient within rounding of ±0.5
            // could round otherwise). Survivors keep their raster order.
            let mut n_max = 0;
            for &px in &above[..n_above] {
                let m_sq = m2[1][px];
                let (gx, gy) = grads.at(px, py);
                let half_m = 0.5 * m_sq.sqrt();
                let unit = |g: f32| (g >= half_m) as isize - (g <= -half_m) as isize;
                let (sx, sy) = (unit(gx), unit(gy));
                let xi = px as isize;
                let (ahead, behind) = (&m2[(1 + sy) as usize], &m2[(1 - sy) as usize]);
                // (Every value is finite: `>=` is the scalar test's `!(<)`.)
                let is_max = (m_sq >= ahead[(xi + sx) as usize]) & (m_sq >= behind[(xi - sx) as usize]);
                maxima[n_max] = (px, sx, sy);
                n_max += (is_max & valid_depth(depth.get(px, py), units)) as usize;
            }
            // The gradients averaged along the edge (its rounded tangent, ±
            // `EDGE_TANGENT_TAPS` px; see the constant), and the edge threshold applied
            // again to the average — the survivors gathered without a branch again
            // (~66% pass), as are those of the re-blurred frame's threshold next.
            let k = EDGE_TANGENT_TAPS;
            let taps = (2 * k + 1) as f32;
            let mut n_edges = 0;
            for &(px, sx, sy) in &maxima[..n_max] {
                let (xi, yi) = (px as isize, py as isize);
                let (tx, ty) = (-sy, sx);
                let inside = |t: isize| {
                    let (x, yy) = (xi + t * tx, yi + t * ty);
                    x >= 2 && yy >= 2 && x < w as isize - 2 && yy < h as isize - 2
                };
                if !inside(-k) || !inside(k) {
                    continue;
                }
                let mut g = (0.0f32, 0.0f32);
                for t in -k..=k {
                    let (a, b) = grads.at((xi + t * tx) as usize, (yi + t * ty) as usize);
                    g = (g.0 + a, g.1 + b);
                }
                let m = (g.0 * g.0 + g.1 * g.1).sqrt() / taps;
                edges[n_edges] = Edge { px, s: (sx, sy), g, m, r: 0.0 };
                n_edges += (m >= EDGE_MIN_GRAD) as usize;
            }
            // The re-blurred frame's mean (bilinear, 16 reads per tap) only for edges
            // that passed the frame's threshold.
            let mut n_ratio = 0;
            for i in 0..n_edges {
                let e = edges[i];
                let (xi, yi, (tx, ty)) = (e.px as isize, py as isize, (-e.s.1, e.s.0));
                let mut gr = (0.0f32, 0.0f32);
                for t in -k..=k {
                    let (c, d) = re.grad((xi + t * tx) as usize, (yi + t * ty) as usize);
                    gr = (gr.0 + c, gr.1 + d);
                }
                let mr = (gr.0 * gr.0 + gr.1 * gr.1).sqrt() / taps;
                let r = e.m / mr;
                edges[n_ratio] = Edge { r, ..e };
                // (m > 0 and mr finite: r is never NaN, so `>` is `!(<=)`.)
                n_ratio += ((mr >= EDGE_MIN_REBLUR_GRAD) & (r > 1.0)) as usize;
            }
            for &Edge { px, s, g, m, r } in &edges[..n_ratio] {
                let normal = (g.0 / (m * taps), g.1 / (m * taps));
                if !isolated(&grads, (px as isize, py as isize), s, normal, m) {
                    continue;
                }
                sig.push(ZS_SIGMA0 / (r * r - 1.0).sqrt());
                zs.push(depth.get(px, py));
                at.push((py, px));
            }
        }
        (zs, sig, at)
    };
    let (mut zs, mut sig, mut at) = scan(&|i| i % row_share == 0);
    let mut scan_note = String::new();
    if row_share > 1 {
        scan_note = format!(
            "; edge scan on one row in {row_share} of its {full_step}-px lattice (effort {})",
            opts.fast_effort
        );
        if sig.len() < EFFORT_MIN_EDGES {
            // The rows left out, merged in frame-row order: the full scan's samples in
            // its order, exactly (each row's samples depend on that row alone).
            let (z2, s2, at2) = scan(&|i| i % row_share != 0);
            scan_note += &format!(
                " found {} edges, under {EFFORT_MIN_EDGES}: the other rows were read too ({} edges in all)",
                sig.len(),
                sig.len() + s2.len()
            );
            // Rows are disjoint between the passes and a stable sort keeps each row's
            // own order.
            let mut all: Vec<((usize, usize), f32, f32)> =
                at.iter().zip(&zs).zip(&sig).map(|((&r, &z), &s)| (r, z, s)).collect();
            all.extend(at2.iter().zip(&z2).zip(&s2).map(|((&r, &z), &s)| (r, z, s)));
            all.sort_by_key(|t| t.0 .0);
            at = all.iter().map(|t| t.0).collect();
            (zs, sig) = all.into_iter().map(|(_, z, s)| (z, s)).unzip();
        }
    }
    st.lap("search.edges");
    // Beyond `FAST_MAX_EDGE_SAMPLES` edges the robust curve fit (linear in the
    // samples) would cost more than the rest of the fit while its standard error
    // falls only as 1/√n: every k-th edge in raster order (spread over the frame and
    // its depths) is kept, and the reported standard error is that of the kept ones.
    let keep = sig.len().div_ceil(FAST_MAX_EDGE_SAMPLES).max(1);
    let zs: Vec<f32> = zs.into_iter().step_by(keep).collect();
    let at: Vec<(usize, usize)> = at.into_iter().step_by(keep).collect();
    let sig: Vec<f32> =
        sig.into_iter().step_by(keep).map(|raw| calibrate(raw, kernel).min(opts.dof_max_sigma_px)).collect();
    let cells = super::Cells::new(w, h);
    let cell: Vec<u32> = at.into_iter().map(|(py, px)| cells.of(px, py)).collect();
    let (mut dof, plot) = finish("fast", zs, sig, cell, units, frame_depth_span(depth, units), started, st, |_| None);
    if dof.curve.is_some() {
        dof.kernel = kernel;
        dof.diagnostics.reason = format!("{}; {shape_note}", dof.diagnostics.reason);
    }
    dof.diagnostics.reason += &scan_note;
    (dof, plot)
}

/// Most edge samples a pooled fit takes (`fit_fast_pooled`): one frame's
/// (`FAST_MAX_EDGE_SAMPLES`), so pooling costs one more curve fit however many
/// frames the pool holds (at 1280×960: 9.3 ms for the 11 000 samples of ten
/// `synth-video` frames, about 1 100 edges each).
pub const POOLED_MAX_EDGE_SAMPLES: usize = FAST_MAX_EDGE_SAMPLES;

/// One δ(Z) curve fitted on the edge samples of several blind fits (`fit_fast`'s
/// plot data) of one fixed-focus camera: every frame gives an equal share of at
/// most `POOLED_MAX_EDGE_SAMPLES` (every k-th of its samples), the evaluation
/// range bounds extrapolation by the union of the frames' depths. Why: one frame's
/// curve follows the depths its view holds textured — on the calibration video
/// views differ by 0.2–0.4 px RMSE — while the camera's δ(Z) is one curve; the
/// union of views pins it over the depths all of them saw.
/// `kernel` is the kernel the samples' σ were calibrated for (`fit_fast` maps
/// each edge ratio through that kernel's table): callers pool frames of one
/// kernel. Below `MIN_SAMPLES` in all: absent, status not identifiable.
pub fn fit_fast_pooled(
    frames: &[&DofPlotData],
    units: DepthUnits,
    kernel: DofKernel,
) -> (DepthOfField, Option<DofPlotData>) {
    let started = Instant::now();
    let mut st = crate::fit::Stages::start();
    let share = POOLED_MAX_EDGE_SAMPLES / frames.len().max(1);
    let (mut z, mut s, mut cell) = (vec![], vec![], vec![]);
    let mut span: Option<[f32; 2]> = None;
    // Each frame's cells apart (a cell of one view is not the same patch of scene
    // in the next); a frame without cells gives each sample its own.
    let mut offset = 0u32;
    for f in frames {
        let n = f.depth.len().min(f.sigma_px.len());
        let keep = n.div_ceil(share.max(1)).max(1);
        z.extend(f.depth[..n].iter().step_by(keep));
        s.extend(f.sigma_px[..n].iter().step_by(keep));
        let own: Vec<u32> = if f.cell.len() >= n { f.cell[..n].to_vec() } else { (0..n as u32).collect() };
        let next = offset + own.iter().max().map_or(0, |&c| c + 1);
        cell.extend(own.into_iter().step_by(keep).map(|c| offset + c));
        offset = next;
        if let Some([lo, hi]) = f.frame_depth_span {
            span = Some(span.map_or([lo, hi], |[a, b]| [a.min(lo), b.max(hi)]));
        }
    }
    st.lap("pool");
    let method = format!("fast (edges pooled over {} frames)", frames.len());
    let (mut dof, plot) = finish(&method, z, s, cell, units, span, started, st, |_| None);
    if dof.curve.is_some() {
        dof.kernel = kernel;
    }
    (dof, plot)
}

/// The depth range when the frame holds one depth (inverse depth's 5–95% spread
/// within 2% of its median, over every 4th pixel), else `None`.
fn constant_depth(depth: &Plane, units: DepthUnits) -> Option<[f32; 2]> {
    let mut z = valid_depths(depth, units, 4);
    if z.len() < MIN_SAMPLES {
        return None;
    }
    let n = z.len();
    let mut at = |k: usize| *z.select_nth_unstable_by(k, f32::total_cmp).1;
    let (lo, mid, hi) = (at(n / 20), at(n / 2), at(n - 1 - n / 20));
    let (first, last) = (at(0), at(n - 1));
    let (ul, um, uh) = (units.inverse_depth(lo), units.inverse_depth(mid), units.inverse_depth(hi));
    ((uh - ul).abs() <= 0.02 * um.abs().max(1e-6)).then_some([first, last])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `GradRows` holds, for every scanned row, every row within `GRAD_ROWS_REACH`
    /// of it, each the plain central difference bit for bit (a stale slot would
    /// hand the scan another row's gradients): scanned at steps 1, 2 and 4, on a
    /// frame taller than the ring, and on one shorter than the reach.
    #[test]
    fn grad_rows_hold_every_row_the_scan_reads() {
        for (w, h) in [(13usize, 71usize), (9, 6)] {
            let p = Plane::from_vec(w, h, (0..w * h).map(|i| ((i * 37) % 23) as f32 * 0.043 - 0.3).collect());
            for step in [1usize, 2, 4] {
                let mut g = GradRows::new(w, h);
                for py in (2..h - 2).step_by(step) {
                    g.hold_around(&p, py);
                    for yy in py.saturating_sub(GRAD_ROWS_REACH).max(1)..(py + GRAD_ROWS_REACH + 1).min(h - 1) {
                        for x in 1..w - 1 {
                            let gx = 0.5 * (p.get(x + 1, yy) - p.get(x - 1, yy));
                            let gy = 0.5 * (p.get(x, yy + 1) - p.get(x, yy - 1));
                            let (ax, ay) = g.at(x, yy);
                            assert_eq!(
                                (ax.to_bits(), ay.to_bits()),
                                (gx.to_bits(), gy.to_bits()),
                                "{w}×{h} ({x}, {yy})"
                            );
                            assert_eq!(g.m2_row(yy)[x].to_bits(), (gx * gx + gy * gy).to_bits());
                        }
                    }
                }
            }
        }
    }

    /// `calibrate`'s binary search needs the raw Zhuo–Sim value to rise strictly
    /// with σ from the first entry above the σ = 0 value on (below it, σ < 0.3 px,
    /// the raw value dips: unresolvable, read as 0); the mapping then inverts the
    /// table there (to 1e-3 px: float rounding of the interpolation).
    #[test]
    fn zhuo_sim_tables_are_monotone() {
        for kernel in [DofKernel::Gaussian, DofKernel::Disc] {
            let t = zhuo_sim_table(kernel);
            let i0 = t.iter().position(|e| e.0 > t[0].0).expect("the raw value rises");
            assert!(t[i0].1 <= 0.5, "{kernel:?}: resolvable only from σ {}", t[i0].1);
            for w in t[i0..].windows(2) {
                assert!(w[1].0 > w[0].0, "{kernel:?}: raw {} at σ {} then {} at σ {}", w[0].0, w[0].1, w[1].0, w[1].1);
            }
            for &(raw, sigma) in &t[i0..] {
                assert!((calibrate(raw, kernel) - sigma).abs() < 1e-3, "{kernel:?} σ {sigma}");
            }
            assert_eq!(calibrate(t[0].0, kernel), 0.0);
        }
    }
}

#[cfg(test)]
mod pooled_tests {
    use super::*;

    /// Edge samples of a thin lens (k = 4 px per m⁻¹, focus 2.5 m, c0 0.3 px) at the
    /// depths `z`, with a deterministic ±0.3 px scatter (a robust fit's noise).
    fn frame(z: Vec<f32>, span: [f32; 2]) -> DofPlotData {
        let truth = |z: f32| 4.0 * (1.0 / z - 1.0 / 2.5).abs() + 0.3;
        let sigma_px =
            z.iter().enumerate().map(|(i, &z)| truth(z) + 0.3 * ((i * 7919) % 13) as f32 / 6.0 - 0.3).collect();
        DofPlotData { depth: z, sigma_px, quadratic: None, thin_lens: None, frame_depth_span: Some(span), cell: vec![] }
    }

    /// Two views of one camera, one seeing only near depths (1–2 m, ten times the
    /// samples), one only far (3–6 m): the pooled curve follows the camera over
    /// both (RMSE ≤ 0.1 px: the samples' scatter averaged over thousands, plus the
    /// thin lens's focus search on a grid), each view gets an equal share of the
    /// sample budget (the near view alone would not pin the far side), and the
    /// evaluation range is the union of the views' depths.
    #[test]
    fn pooled_views_pin_the_curve_over_their_union() {
        let near = frame((0..20_000).map(|i| 1.0 + (i % 1000) as f32 / 1000.0).collect(), [1.0, 2.0]);
        let far = frame((0..2_000).map(|i| 3.0 + 3.0 * (i % 500) as f32 / 500.0).collect(), [3.0, 6.0]);
        let (dof, plot) = fit_fast_pooled(&[&near, &far], DepthUnits::MetricM, DofKernel::Gaussian);
        assert!(dof.present, "{}", dof.diagnostics.reason);
        assert_eq!(dof.depth_range, [1.0, 6.0]);
        let plot = plot.expect("plot data");
        let from_far = plot.depth.iter().filter(|&&z| z >= 3.0).count();
        assert!(from_far >= 2_000 && plot.depth.len() <= POOLED_MAX_EDGE_SAMPLES, "{from_far} of {}", plot.depth.len());
        let truth = |z: f32| 4.0 * (1.0 / z - 1.0 / 2.5).abs() + 0.3;
        let zs: Vec<f32> = (0..50).map(|i| 1.0 + 5.0 * i as f32 / 49.0).collect();
        let rmse = (zs.iter().map(|&z| (dof.sigma_px(z) - truth(z)).powi(2)).sum::<f32>() / zs.len() as f32).sqrt();
        assert!(rmse <= 0.1, "pooled RMSE {rmse} px: {}", dof.diagnostics.reason);
        assert!(dof.diagnostics.method.contains("2 frames"), "{}", dof.diagnostics.method);
    }

    /// No samples at all: absent and not identifiable, never a curve.
    #[test]
    fn an_empty_pool_is_not_identifiable() {
        let (dof, plot) = fit_fast_pooled(&[], DepthUnits::MetricM, DofKernel::Gaussian);
        assert!(!dof.present && dof.curve.is_none() && plot.is_none());
        assert_eq!(dof.diagnostics.status, Status::NotIdentifiable);
    }
}
