//! Blind motion-blur exposure from the zeros a streak leaves in the spectrum along
//! the flow: texture anisotropy and isotropic blur cannot move them.
//!
//! A box streak of length L = λ|F| px along u = F/|F| multiplies every 1-D spectrum
//! taken along u by sinc²(π f L): zeros at f = k/L cycles/px. Lines sampled along
//! the local flow direction carry that factor whatever the scene (the line's power
//! spectrum is the 2-D spectrum integrated over the across-flow frequency, and the
//! streak's transfer function depends on the along-flow frequency only), while the
//! scene's own spectrum is smooth in log frequency. Defocus multiplies in a smooth
//! Gaussian (or a disc, whose zeros are radial and do not line up along u) — it
//! lowers the zeros' contrast but does not move them. So:
//!
//! 1. at centres on a grid over the frame (flow ≥ 3 px/frame, both lines inside the
//!    frame and the valid mask) sample luma on a line of `LINE_PX` px along u **and**
//!    one across it (along v); remove the mean, Hann-window, FFT, normalise each
//!    line's power to sum 1 (bright or high-contrast lines do not dominate); leave
//!    out a pair whose two spectra are both about flat (`FLAT_LINE_TILT`): noise
//!    over a flat area, which holds nothing a streak could shape but weighed as much
//!    as a textured line;
//! 2. put each line's spectrum on the **exposure axis** φ = f·|F| (cycles per frame of
//!    motion): there the zeros lie at φ = k/λ for every line whatever its speed, so
//!    lines with different flow magnitudes average without smearing the zeros;
//! 3. take the log ratio of the along-flow to the across-flow mean power (the latter
//!    smoothed over ±`ACROSS_SMOOTH_BINS`). What both directions share cancels:
//!    defocus, the scene's fall-off, and — the reason for the ratio — the knee where
//!    a blurred spectrum meets the noise floor, which on the along-flow spectrum
//!    alone looks like a first zero (measured: sharp and σ 1 px frames with no
//!    streak matched a template at correlation 0.78–0.81 without the ratio,
//!    ≤ 0.38 with it);
//! 4. regress out the remaining trend (1, ln φ, ln² φ: texture anisotropy that varies
//!    smoothly with frequency) and correlate the residual with the same-detrended
//!    template. The template is the ratio a streak leaves **over a noise floor**:
//!    along / across = (S·sinc² + N) / (S + N) = (1 − r)·sinc²(πφλ) + r, with
//!    r(φ) = N / across(φ) and N the least smoothed along-flow power in the upper
//!    3/4 of the band (white noise is flat on the exposure axis and is all a zero
//!    leaves). Without it the template's deep zeros met a noise-filled ratio that
//!    only falls to the floor and stays: noise read streaks 27–35% long (astronaut
//!    1280×960, λ 0.5 + noise: 0.673 ± 0.041; the demo frame 0.509 for 0.40);
//! 5. λ is the best template over a grid reaching from `BELOW_BAND` × `lambda_min`
//!    (`lambda_min`: first zero at 80% of the band) to `ABOVE_FULL`, refined by a
//!    parabola; a best outside [lambda_min, 1] is a fall-off at an end of the band
//!    (a streak too short for a zero in it, defocus, interpolation), not a zero.
//!
//! 6. a zero is a dip with power coming back after it: the best template is taken
//!    only where the along-flow power over its first side lobe stands
//!    e^`MIN_SIDE_LOBE` above the noise floor — the floor in the shape white pixel
//!    noise takes through the lines' bilinear sampling (`interpolated_noise_
//!    correlation`: an oblique line low-passes it ~3× toward Nyquist). Without the
//!    gate a texture smoother along the flow than across it (σ 3 / 1.2 px, along or
//!    10° off its smooth axis) read λ 0.43–0.92 *identified* at correlation 0.97–1.00
//!    for truths 0, 0.2 and 0.5: its ratio falls smoothly to the floor and the
//!    template put its zero at the knee.
//!
//! 7. and the dip must be the along-flow power's: the ratio also dips where the
//!    across-flow spectrum peaks (a text line's letter pitch), so the along-flow
//!    power's own detrended ln must dip at the zero (`MIN_ALONG_DIP`) and the
//!    across-flow peak may supply at most `MAX_ACROSS_SHARE` of the ratio's dip.
//!    Without them 31 px streaks across text lines read 3.4–5.5 px (± 0.15) and
//!    sharp photographs (coffee, rocket) 19–20 px streaks, all identified; a sharp
//!    scanned page's 17.5 px and a 31 px streak at 45° to text lines read as 4.4
//!    px still pass (docs/blind-motion-blur.md "Zeros of the ratio that are not zeros of the
//!    streak").
//!
//! Standard error: the spread of λ over `SUBSETS` interleaved subsets of lines /
//! √subsets, in quadrature with the λ shift when the noise floor is doubled and
//! halved, floored at the grid step. The match is trusted (`identified`) when the
//! best lies inside [lambda_min, 1], the correlation is ≥ `MIN_SCORE` and the
//! relative standard error is ≤ `MAX_RELATIVE_STDERR`. Measured (42 frames —
//! astronaut 1280×960 at ~7 px/frame and 640×480 at 8 and 24 px/frame; λ 0, 0.25, 0.5; clean, noisy, defocused, both; the demo frame;
//! two real photographs): the 9 it identifies read within 9% (1280×960 λ 0.5:
//! 0.493 ± 0.010, under defocus 0.486 ± 0.012; 640×480 at 24 px/frame λ 0.25:
//! 0.248, λ 0.5 + noise 0.486 ± 0.023; the license-plate photograph −2.5%), and it
//! identifies no frame without a zero in the band. Without the floor and the grid's
//! reach it identifies 14, 7 of them 16–∞% off (the clean and the defocused
//! 1280×960 frames at λ 0.35 with correlation 0.53–0.61; 1.8 px streaks at 0.35;
//! noise +35%). Noisy short streaks read 0.295 ± 0.036 for 0.25 — not
//! identified, the isotropy estimator of `motion_blur::fit_fast` takes over, with
//! its stated band.
//! A page of text is often not identified: its line pitch puts its own periodic
//! structure along the flow, its letter pitch across it.
//!
//! A streak shorter than ~3 px puts its first zero near or past Nyquist: not
//! identifiable here (the isotropy estimator of `motion_blur::fit_fast` takes over).

use crate::image::{Flow, Plane};
use rustfft::num_complex::Complex32;
use rustfft::FftPlanner;

mod noise_r;
use noise_r::interpolated_noise_correlation;
#[cfg(test)]
use noise_r::NOISE_R_STRIDE;

/// Samples per line (1 px apart). 128 resolves a first zero at 1/L ≥ 3 bins for
/// L ≤ 42 px.
pub const LINE_PX: usize = 128;
/// Least grid step between line centres (px); larger frames take a coarser grid
/// so that about `TARGET_CENTRES` lines are read (lines 128 px long overlap
/// heavily at 16 px, so more add little).
const GRID_PX: usize = 16;
const TARGET_CENTRES: usize = 1200;
/// Least flow (px/frame) a line needs, as in the isotropy estimator.
const MIN_SPEED_PX: f32 = 3.0;
/// Least correlation between the detrended log spectrum ratio and the template.
/// Set on the pure-sinc template (640×480 astronaut, 8-bit, λ 0 and 0.2: streak-free
/// ratios correlated ≤ 0.38, streaks 0.37–0.93). With the noise-floor template a
/// streak-free frame can correlate up to 0.95, but its best lies outside
/// [lambda_min, 1] (every such frame of the 42 above); the streaks
/// it identifies correlate 0.64–0.96, the text page's best 0.38.
pub const MIN_SCORE: f32 = 0.45;
/// Interleaved subsets must agree: relative standard error at most this.
pub const MAX_RELATIVE_STDERR: f32 = 0.1;
/// The across-flow log spectrum is smoothed over ±this many bins before it is
/// subtracted: it is there to cancel what both directions share (defocus, the
/// noise floor's knee, the scene's fall-off), not to add its own fine structure.
const ACROSS_SMOOTH_BINS: usize = 3;
/// Dip depth the template allows (noise floor, window leakage): ln(sinc² + ε).
const TEMPLATE_FLOOR: f32 = 0.02;
const SUBSETS: usize = 4;
/// λ grid step of the search.
const LAMBDA_STEP: f32 = 0.0025;
/// The subsets' and the noise-floor variants' searches step this many times
/// coarser (they measure a spread).
const AUX_STEPS: usize = 4;
/// The main search refines this many of its coarse pass's best local maxima.
const REFINED_PEAKS: usize = 3;
/// The search grid reaches below the least λ with a zero in the band (to this
/// fraction of it) and beyond a full-frame exposure (to this λ), so that a best
/// template at either end of [lambda_min, 1] is seen as an edge, not a zero.
/// Measured: without the lower reach, a frame with no streak or with one too short
/// for a zero in the band (clean, defocused, or λ 0.25 at 7 px/frame) matched the
/// template whose zero sits at the band's edge, at correlation 0.53–0.89.
const BELOW_BAND: f32 = 0.7;
const ABOVE_FULL: f32 = 1.3;
/// Least ln ratio of the along-flow power over the best template's first side lobe
/// to the noise floor. A zero is a dip with power coming back after it; where the
/// along-flow spectrum only falls to the floor (a texture smoother along the flow
/// than across it, a streak whose side lobes defocus and noise bury), the template
/// still matches — its zero placed at the knee, its side lobes filled by the floor —
/// at correlation up to 1.00. Measured (the floor shaped by the lines' sampling):
/// an oriented texture along its smooth axis or 10° off it 0.03–0.13 (read λ
/// 0.37–0.92 for 0, 0.2, 0.5), the streaks identified 0.21 (noisy) to 5.3 (the
/// license plate); the oriented texture over four seeds, up to 20° off — its wrong
/// reads up to 0.17 (20° off, 12 px/frame, λ 0
/// read 0.49), the photograph's right reads from 0.05 (noisy) up. The two overlap:
/// 0.2 identifies none of the wrong reads and loses right ones whose lobe lies in
/// the noise (their zeros were only the knee, as the texture's are; the isotropy
/// fallback and the worker's pool answer them).
pub const MIN_SIDE_LOBE: f32 = 0.2;
/// Least depth of the along-flow power's own dip at the first zero: the mean of
/// its detrended ln (1, ln φ, ln² φ, as the ratio) over φλ ∈ [0.85, 1.15] must lie
/// this far below 0. The template is matched to the along/across *ratio*, and a
/// ratio also dips where the across-flow spectrum peaks; a streak's zero is in the
/// along-flow power. Measured (`benches/streak_gates/probe.py`: nine photographs
/// and four text pages, box streaks 0–31 px at 0°/45°/90°, clean and with 3 DN
/// noise, 50 px/frame; docs/blind-motion-blur.md "Zeros of the ratio that are not zeros of the
/// streak"): right reads' dips 0.23 (31 px under noise) to 2.2; six of the eleven
/// wrong identifications −0.32 to 0.20 (the sharp coffee cup and rocket read as
/// 19–20 px streaks: 0.20, 0.12; a 16 px streak on text under noise read 40.6 px:
/// −0.10). A threshold where the two meet, not a separation.
pub const MIN_ALONG_DIP: f32 = 0.2;
/// Largest share of the ratio's dip at the first zero that the across-flow
/// spectrum's own peak may supply (its detrended ln there over the ratio's dip). A
/// text line's letter pitch (3–6 px) is a peak across the flow, and the ratio dips
/// there whatever the along-flow power does: 31 px streaks across text lines read
/// 3.4–5.5 px ± 0.15 (shares 0.66–1.0). Measured as for `MIN_ALONG_DIP`: right
/// reads' shares up to 0.57 (a brick wall, 16 px at 45°).
pub const MAX_ACROSS_SHARE: f32 = 0.6;

/// A line pair counts only where at least one of its two lines holds texture: its
/// mean normalised power over the band's lowest sixteenth (periods ≥ 16 px) at
/// least this many times its mean over the band's upper half (periods 2–4 px).
/// White noise gives ~1 there (up to ~2–3 where an oblique line's bilinear
/// sampling low-passes it, `interpolated_noise_correlation`), a 1/f² texture ~400,
/// a streak more. With the per-line normalisation a pair of pure-noise lines over a
/// flat area weighs as much as a textured one. Measured (`benches/streak_gates/
/// probe.py`, docs/blind-motion-blur.md "Lines with no texture along the flow"): on the
/// held-out set (144 frames with 0 and 2 DN of noise) the rule cuts the wrong
/// identifications from 6 to 2 (the colour wheel at 120° with 12 px and at 30°
/// with 6 px, the silhouette's two: gone; the moon's sky and the colour wheel with no
/// streak remain), 47 right reads with and without it; on the tuning-like set (300
/// frames) the same 185 right reads and 2 wrong ones. Stricter tilts (10, 30, 100)
/// also drop lines with weak texture, and each made a new wrong read in one set or
/// the other; dropping a pair where only its along-flow line is flat made new wrong
/// reads of 2.6 px on a 24 px streak.
const FLAT_LINE_TILT: f32 = 4.0;

/// Whether a normalised spectrum (bins 1 … n/2) is about flat (`FLAT_LINE_TILT`).
fn flat(p: &[f32]) -> bool {
    let (low, high) = (&p[..(p.len() / 8).max(1)], &p[p.len() / 2..]);
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len().max(1) as f32;
    mean(low) < FLAT_LINE_TILT * mean(high)
}

/// What the spectrum along the flow says about the streak.
#[derive(Clone, Debug, PartialEq)]
pub struct StreakSignature {
    pub lambda: f32,
    pub stderr: f32,
    /// Correlation of the best template with the detrended log spectrum.
    pub score: f32,
    /// Best correlation among templates ≥ 25% away in λ (the main search's
    /// evaluated templates: its coarse grid outside the refined peaks, so a flank
    /// of the best peak reads a few hundredths lower than on the full grid).
    pub runner_up: f32,
    pub lines: usize,
    /// Median flow speed of the lines (px/frame).
    pub speed_px: f32,
    /// Least λ the band can show (first zero inside the band).
    pub lambda_min: f32,
    /// The best template lies in [lambda_min, 1] (see `match_template`).
    pub inside: bool,
    /// Half the λ shift when the noise-floor estimate is doubled and halved (in
    /// `stderr`, in quadrature with the subsets' spread).
    pub floor_shift: f32,
    /// ln of the along-flow power over the best template's first side lobe, over
    /// the noise floor (see `MIN_SIDE_LOBE`; NaN where the lobe lies past the band).
    pub side_lobe: f32,
    /// Depth of the along-flow power's own dip at the first zero (see
    /// `MIN_ALONG_DIP`; detrended ln, positive = a dip).
    pub along_dip: f32,
    /// Share of the ratio's dip at the first zero that is the across-flow
    /// spectrum's peak (see `MAX_ACROSS_SHARE`; +∞ where the ratio does not dip).
    pub across_share: f32,
    pub identified: bool,
}

/// Mean normalised power on the exposure axis, for a subset of lines.
struct Spectrum {
    /// Bin centres φ (cycles per frame of motion) and mean power per bin.
    phi: Vec<f32>,
    power: Vec<f64>,
    across: Vec<f64>,
    /// White pixel noise's power per bin through the lines' bilinear sampling (up
    /// to one factor: the noise variance), on the same scale as `power`: only for
    /// the spectrum of every line (its search alone reads the side lobe).
    noise: Option<Vec<f64>>,
    weight: Vec<f64>,
}

/// One line pair: its flow speed, the normalised power spectra along and across
/// the flow (bins 1 … n/2), and white pixel noise's autocorrelation at lags 0–2
/// after the along line's bilinear sampling, over the line's total power.
struct Line {
    speed: f32,
    along: Vec<f32>,
    across: Vec<f32>,
    noise_r: [f64; 3],
}

/// Estimate λ from the streak's spectral zeros on luma `y` with `flow` (px/frame);
/// `valid(x, y)` says which pixels may be sampled. `None` when no line qualifies.
/// About `TARGET_CENTRES` lines (full effort; `streak_signature_with` takes another
/// count).
pub fn streak_signature(y: &Plane, flow: &Flow, valid: impl Fn(usize, usize) -> bool) -> Option<StreakSignature> {
    streak_signature_with(y, flow, valid, TARGET_CENTRES)
}

/// Line centres at `effort` (`FitOptions::fast_effort`): `TARGET_CENTRES` scaled.
pub fn target_centres(effort: f32) -> usize {
    crate::fit::scaled_count(TARGET_CENTRES, effort)
}

/// `streak_signature` over about `centres` line centres (the grid step never below
/// `GRID_PX`, so small frames read the same lines at any count).
pub fn streak_signature_with(
    y: &Plane,
    flow: &Flow,
    valid: impl Fn(usize, usize) -> bool,
    centres: usize,
) -> Option<StreakSignature> {
    let (w, h) = (y.width, y.height);
    let n = LINE_PX;
    let half = (n / 2) as f32;
    let win = super::defocus_spectrum::hann(n);
    let fft = FftPlanner::<f32>::new().plan_fft_forward(n);
    let mut buf = vec![Complex32::new(0.0, 0.0); n];
    // A centre's two lines' samples (`Plane::sample_line`): along and across.
    let (mut along, mut across) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut scratch = vec![Complex32::new(0.0, 0.0); fft.get_inplace_scratch_len()];
    // Per line pair: speed, normalised power at bins k = 1 … n/2, noise correlation.
    // Per line pair, its centre's raster index: the pairs are read column by
    // column and then put back in raster order (see below).
    let mut lines: Vec<(usize, Line)> = vec![];
    // (start's pixel phase x, y; direction x, y) → noise correlation.
    type NoiseKey = (f32, f32, f32, f32);
    let mut noise_r_cache: Option<(NoiseKey, [f64; 3])> = None;
    let inside = |x: f32, yy: f32| x >= 0.0 && yy >= 0.0 && x <= (w - 1) as f32 && yy <= (h - 1) as f32;
    let grid = (((w * h) as f32 / centres.max(1) as f32).sqrt().ceil() as usize).max(GRID_PX);
    // Centres column by column: a line with a vertical component crosses ~128
    // frame rows, one cache line or two each, and the next centre down the column
    // crosses three quarters of the same rows at the same columns, so it finds them
    // cached (in raster order the next centre is 32 px along the row, in other cache
    // lines, and those rows come back only a grid row later). The subsets, the
    // sums and the median read the pairs in raster order, as before.
    for cx in (grid / 2..w).step_by(grid) {
        for cy in (grid / 2..h).step_by(grid) {
            let i = cy * w + cx;
            let (fx, fy) = (flow.dx[i], flow.dy[i]);
            let speed = (fx * fx + fy * fy).sqrt();
            // A flow past the frame's diagonal displaces nothing still in the frame.
            let too_far = !crate::model::flow_within_frame(fx, fy, w, h);
            if !speed.is_finite() || speed < MIN_SPEED_PX || too_far || !valid(cx, cy) {
                continue;
            }
            // A line of n samples through the centre along (dx, dy): its start, when
            // both ends lie inside the frame and the valid mask.
            let start = |dx: f32, dy: f32| -> Option<(f32, f32)> {
                let (x0, y0) = (cx as f32 - half * dx, cy as f32 - half * dy);
                let (x1, y1) = (x0 + (n - 1) as f32 * dx, y0 + (n - 1) as f32 * dy);
                let ok = inside(x0, y0)
                    && inside(x1, y1)
                    && valid(x0 as usize, y0 as usize)
                    && valid(x1 as usize, y1 as usize);
                ok.then_some((x0, y0))
            };
            let (ux, uy) = (fx / speed, fy / speed);
            let (vx, vy) = (-uy, ux);
            let (Some((x0, y0)), Some((a0, b0))) = (start(ux, uy), start(vx, vy)) else {
                continue;
            };
            y.sample_line(x0, y0, ux, uy, &mut along);
            y.sample_line(a0, b0, vx, vy, &mut across);
            // Each line's mean in sample order, the two side by side: two independent
            // chains of dependent additions (one line's alone, each step waited on the
            // last: ~0.4 ms of the fit's 3 780 lines).
            let sums = along.iter().zip(&across).fold((0.0f32, 0.0f32), |(a, b), (&u, &v)| (a + u, b + v));
            let mut spectrum = |samples: &[f32], sum: f32| -> Option<(Vec<f32>, f32)> {
                // The windowed deviations from the mean, written once.
                let mean = sum / n as f32;
                for ((b, &v), &wj) in buf.iter_mut().zip(samples).zip(&win) {
                    *b = Complex32::new((v - mean) * wj, 0.0);
                }
                fft.process_with_scratch(&mut buf, &mut scratch);
                let p: Vec<f32> = buf[1..=n / 2].iter().map(|c| c.norm_sqr()).collect();
                let total: f32 = p.iter().sum();
                (total > 1e-12).then(|| (p.into_iter().map(|v| v / total).collect(), total))
            };
            let (Some((pu, total)), Some((pv, _))) = (spectrum(&along, sums.0), spectrum(&across, sums.1)) else {
                continue;
            };
            if flat(&pu) && flat(&pv) {
                continue;
            }
            // A uniform flow gives every line the same direction and pixel phase
            // (integer centres): one computation serves them all.
            let key = (x0.fract(), y0.fract(), ux, uy);
            let r = match noise_r_cache {
                Some((k, r)) if k == key => r,
                _ => {
                    let r = interpolated_noise_correlation(x0, y0, ux, uy, n);
                    noise_r_cache = Some((key, r));
                    r
                }
            };
            lines.push((i, Line { speed, along: pu, across: pv, noise_r: r.map(|v| v / total as f64) }));
        }
    }
    lines.sort_unstable_by_key(|&(i, _)| i);
    let lines: Vec<Line> = lines.into_iter().map(|(_, l)| l).collect();
    if lines.len() < 16 {
        return None;
    }
    let mut speeds: Vec<f32> = lines.iter().map(|l| l.speed).collect();
    speeds.sort_by(f32::total_cmp);
    let speed_med = speeds[speeds.len() / 2];
    // Exposure-axis grid: one bin per native bin at the median speed, up to the
    // Nyquist of the median line.
    let dphi = speed_med / n as f32;
    let bins = n / 2;
    let cosines: Vec<[f64; 2]> = (1..=bins)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            [a.cos(), (2.0 * a).cos()]
        })
        .collect();
    let accumulate = |subset: usize, of: usize| -> Spectrum {
        let with_noise = of == 1;
        let mut power = vec![0.0f64; bins];
        let mut across = vec![0.0f64; bins];
        let mut noise = vec![0.0f64; if with_noise { bins } else { 0 }];
        let mut weight = vec![0.0f64; bins];
        // Each line's splat positions g(k), all its bins' in one pass before the
        // scattered sums (two divisions each: computed in the sums' loop they were
        // scalar, ~1/3 of the accumulation by perf; here they vectorise), the same
        // operations per value.
        let mut gs = vec![0.0f32; bins];
        for Line { speed, along: p, across: q, noise_r } in lines.iter().skip(subset).step_by(of) {
            let speed = *speed;
            for (k, g) in gs.iter_mut().enumerate() {
                // Native bin k+1 sits at φ = (k+1)/n · speed; splat linearly.
                *g = (k + 1) as f32 * speed / n as f32 / dphi - 1.0;
            }
            for (k, ((&v, &vq), &g)) in p.iter().zip(q).zip(&gs).enumerate() {
                // The line's white-noise power at native bin k+1, in its normalised
                // units: R₀ + 2R₁cos 2πf + 2R₂cos 4πf over its total power.
                let vn = if with_noise {
                    let [c1, c2] = cosines[k];
                    noise_r[0] + 2.0 * noise_r[1] * c1 + 2.0 * noise_r[2] * c2
                } else {
                    0.0
                };
                if g < 0.0 {
                    continue;
                }
                // g ≥ 0: truncation is its floor, bit for bit (`floorf` is a libm
                // call on baseline x86-64).
                let g0 = g as usize;
                let a = (g - g0 as f32) as f64;
                if g0 < bins {
                    power[g0] += (1.0 - a) * v as f64;
                    across[g0] += (1.0 - a) * vq as f64;
                    if with_noise {
                        noise[g0] += (1.0 - a) * vn;
                    }
                    weight[g0] += 1.0 - a;
                }
                if g0 + 1 < bins {
                    power[g0 + 1] += a * v as f64;
                    across[g0 + 1] += a * vq as f64;
                    if with_noise {
                        noise[g0 + 1] += a * vn;
                    }
                    weight[g0 + 1] += a;
                }
            }
        }
        let phi = (0..bins).map(|b| (b + 1) as f32 * dphi).collect();
        Spectrum { phi, power, across, noise: with_noise.then_some(noise), weight }
    };
    // Least λ: the first zero φ = 1/λ at or below 80% of the band's top.
    let phi_top = bins as f32 * dphi;
    let lambda_min = (1.0 / (0.8 * phi_top)).max(LAMBDA_STEP);
    let whole = accumulate(0, 1);
    let table = SincTable::new(&whole.phi, lambda_min);
    let best = match_template(&whole, &table, 1.0, 1, true)?;
    // The spread terms search a grid `AUX_STEPS`× coarser (parabola-refined): they
    // gauge a spread, not the answer.
    let aux = AUX_STEPS;
    // The noise floor is an estimate: the λ shift when it is doubled and halved.
    let floor_shift =
        match (match_template(&whole, &table, 2.0, aux, false), match_template(&whole, &table, 0.5, aux, false)) {
            (Some(a), Some(b)) => 0.5 * (a.lambda - b.lambda).abs(),
            _ => f32::INFINITY,
        };
    let parts: Vec<f32> = (0..SUBSETS)
        .filter_map(|k| match_template(&accumulate(k, SUBSETS), &table, 1.0, aux, false).map(|r| r.lambda))
        .collect();
    let stderr = if parts.len() >= 2 {
        let m = parts.iter().sum::<f32>() / parts.len() as f32;
        let var = parts.iter().map(|p| (p - m).powi(2)).sum::<f32>() / (parts.len() - 1) as f32;
        (var / parts.len() as f32 + floor_shift * floor_shift).sqrt().max(LAMBDA_STEP)
    } else {
        f32::INFINITY
    };
    let TemplateMatch { lambda, score, runner_up, inside, side_lobe, along_dip, across_share } = best;
    let identified = inside
        && score >= MIN_SCORE
        && stderr <= MAX_RELATIVE_STDERR * lambda
        && side_lobe >= MIN_SIDE_LOBE
        && along_dip >= MIN_ALONG_DIP
        && across_share <= MAX_ACROSS_SHARE;
    Some(StreakSignature {
        lambda,
        stderr,
        score,
        runner_up,
        lines: lines.len(),
        speed_px: speed_med,
        lambda_min,
        inside,
        floor_shift,
        side_lobe,
        along_dip,
        across_share,
        identified,
    })
}

/// The best template's answer for one spectrum.
struct TemplateMatch {
    lambda: f32,
    /// Correlation of the best template with the detrended observation.
    score: f32,
    /// Best correlation among templates ≥ 25% away in λ.
    runner_up: f32,
    /// The best λ lies in [lambda_min, 1]: a zero inside the band, an exposure no
    /// longer than the frame.
    inside: bool,
    /// ln of the mean along-flow power over the first side lobe's span, over the
    /// noise floor (NaN where that span lies outside the band).
    side_lobe: f32,
    along_dip: f32,
    across_share: f32,
}

/// sinc²(πφλ) on the search's λ grid (λ_k = `BELOW_BAND`·lambda_min + k·`LAMBDA_STEP`
/// up to `ABOVE_FULL`) for every bin φ of the exposure axis. Every search of one
/// signature (the main one, the noise-floor variants, the subsets: one axis, one
/// grid or every `AUX_STEPS`-th point of it) reads it, so the ~26 000 sines are
/// taken once, by the angle-addition recurrence along λ (f64: its rounding after
/// ~500 steps is ~1e-13), instead of ~47 000 `sin` calls per signature.
struct SincTable {
    /// The least λ with a zero in the band; the grid starts at `BELOW_BAND` of it.
    lambda_min: f32,
    lo: f32,
    steps: usize,
    bins: usize,
    sinc2: Vec<f64>,
}

impl SincTable {
    fn new(phi: &[f32], lambda_min: f32) -> Self {
        let lo = BELOW_BAND * lambda_min;
        let steps = ((ABOVE_FULL - lo) / LAMBDA_STEP).floor() as usize + 1;
        let bins = phi.len();
        let mut sinc2 = vec![0.0f64; steps * bins];
        for (b, &f) in phi.iter().enumerate() {
            let a = std::f64::consts::PI * f as f64;
            let (x0, dx) = (a * lo as f64, a * LAMBDA_STEP as f64);
            let ((mut sn, mut cs), (sd, cd)) = (x0.sin_cos(), dx.sin_cos());
            for k in 0..steps {
                let x = x0 + k as f64 * dx;
                let sinc = if x.abs() < 1e-9 { 1.0 } else { sn / x };
                sinc2[k * bins + b] = sinc * sinc;
                (sn, cs) = (sn * cd + cs * sd, cs * cd - sn * sd);
            }
        }
        Self { lambda_min, lo, steps, bins, sinc2 }
    }

    fn lambda(&self, k: usize) -> f32 {
        self.lo + k as f32 * LAMBDA_STEP
    }
}

/// Best λ by correlation of the detrended log power ratio with the detrended
/// template ln((1 − r)·(sinc²(πφλ) + ε) + r), r(φ) the noise floor's share of the
/// across-flow power (its floor estimate × `floor_scale`). The grid runs from
/// `BELOW_BAND`·`lambda_min` to `ABOVE_FULL`: a best outside [lambda_min, 1] is a
/// main-lobe fall-off or a pattern that wants ever more zeros, not a located zero.
fn match_template(
    s: &Spectrum,
    table: &SincTable,
    floor_scale: f64,
    stride: usize,
    refine: bool,
) -> Option<TemplateMatch> {
    // Bins with data, above the lowest two native bins (window leakage from DC).
    let idx: Vec<usize> =
        (2..s.phi.len()).filter(|&b| s.weight[b] > 0.0 && s.power[b] > 0.0 && s.across[b] > 0.0).collect();
    if idx.len() < 16 {
        return None;
    }
    let smooth = |v: &[f64], i: usize| -> f64 {
        let lo = i.saturating_sub(ACROSS_SMOOTH_BINS);
        let hi = (i + ACROSS_SMOOTH_BINS + 1).min(v.len());
        v[lo..hi].iter().sum::<f64>() / (hi - lo) as f64
    };
    let lphi: Vec<f64> = idx.iter().map(|&b| (s.phi[b] as f64).ln()).collect();
    let lacross: Vec<f64> = idx.iter().map(|&b| (s.across[b] / s.weight[b]).ln()).collect();
    let along: Vec<f64> = idx.iter().map(|&b| s.power[b] / s.weight[b]).collect();
    // The across-flow reference, smoothed (see `ACROSS_SMOOTH_BINS`), in ln power.
    let lref: Vec<f64> = (0..idx.len()).map(|i| smooth(&lacross, i)).collect();
    let obs: Vec<f64> = along.iter().zip(&lref).map(|(a, r)| a.ln() - r).collect();
    // Noise floor (normalised power per bin): white noise is flat on the exposure
    // axis and is all that is left of the along-flow power at a streak's zeros, so
    // the least smoothed along-flow power over the upper 3/4 of the band. Without a
    // streak or noise it is the scene's power at the band's top, which flattens the
    // template there — conservative. Its uncertainty is carried by the caller (the
    // λ shift when it is doubled and halved).
    let floor = (idx.len() / 4..idx.len()).map(|i| smooth(&along, i)).fold(f64::INFINITY, f64::min) * floor_scale;
    // Detrending basis (1, ln φ, ln² φ) and its normal matrix, inverted once: a
    // singular system (too few distinct frequencies) leaves the data undetrended.
    let rows: Vec<[f64; 3]> = lphi.iter().map(|&l| [1.0, l, l * l]).collect();
    let mut ata = [[0.0f64; 3]; 3];
    for b in &rows {
        for r in 0..3 {
            for c in 0..3 {
                ata[r][c] += b[r] * b[c];
            }
        }
    }
    let m = glam::DMat3::from_cols_array_2d(&ata);
    let inv = (m.determinant().abs() > 1e-12).then(|| m.inverse());
    let project = |v: &[f64]| -> glam::DVec3 {
        let mut atb = glam::DVec3::ZERO;
        for (b, &x) in rows.iter().zip(v) {
            atb += glam::DVec3::from(*b) * x;
        }
        atb
    };
    // The residual of a per-bin series after the basis (itself where the system is
    // singular).
    let detrend = |v: &[f64]| -> Vec<f64> {
        match inv {
            Some(inv) => {
                let coef = inv * project(v);
                v.iter().zip(&rows).map(|(&x, b)| x - coef.dot(glam::DVec3::from(*b))).collect()
            }
            None => v.to_vec(),
        }
    };
    let r_obs = detrend(&obs);
    let n_obs = r_obs.iter().map(|v| v * v).sum::<f64>().sqrt();
    if n_obs.is_nan() || n_obs <= 0.0 {
        return None;
    }
    // The noise floor's share of the across-flow power per bin.
    let share: Vec<f64> = lref.iter().map(|&lr| (floor / lr.exp()).min(1.0)).collect();
    let mut t = vec![0.0f64; idx.len()];
    // Correlation of the observation with the template a transfer function `row`
    // (per bin of the exposure axis) leaves over the noise floor.
    let mut correlate = |row: &[f64]| -> f64 {
        for ((ti, &b), &r) in t.iter_mut().zip(&idx).zip(&share) {
            // Along / across = (S·H + N) / (S + N) with the scene's power S the same
            // both ways: (1 − r)·H + r, r = N / (S + N).
            *ti = ((1.0 - r) * (row[b] + TEMPLATE_FLOOR as f64) + r).ln();
        }
        // r_obs is orthogonal to the basis, so ⟨r_obs, detrended t⟩ = ⟨r_obs, t⟩, and
        // |detrended t|² = |t|² − atbᵀ(AᵀA)⁻¹atb: no residual vector per template.
        let dot = r_obs.iter().zip(&t).map(|(a, b)| a * b).sum::<f64>();
        let tt = t.iter().map(|v| v * v).sum::<f64>();
        let proj = inv.map_or(0.0, |inv| {
            let atb = project(&t);
            atb.dot(inv * atb)
        });
        let n_t2 = tt - proj;
        if n_t2.is_nan() || n_t2 <= 1e-12 * tt.max(1e-300) {
            return -1.0;
        }
        dot / (n_obs * n_t2.sqrt())
    };
    // The template at grid point k (λ_{k·stride} of the table).
    let mut score_of =
        |k: usize| -> f64 { correlate(&table.sinc2[k * stride * table.bins..(k * stride + 1) * table.bins]) };
    let lambda_min = table.lambda_min;
    let step = LAMBDA_STEP * stride as f32;
    let steps = (table.steps - 1) / stride + 1;
    let at = |k: usize| table.lambda(k * stride);
    // `refine`: every `AUX_STEPS`-th template first, then the step's own grid
    // within ±`AUX_STEPS` of that pass's `REFINED_PEAKS` best local maxima. The
    // correlation's peaks span several coarse steps (the aux searches are read at
    // that step), so the best template is the full grid's; the coarse pass was
    // three quarters of the search's ~420 templates of 60 sines and logarithms.
    let every = if refine { AUX_STEPS } else { 1 };
    let mut scores: Vec<Option<f64>> = vec![None; steps];
    for k in (0..steps).step_by(every) {
        scores[k] = Some(score_of(k));
    }
    let evaluated = |scores: &[Option<f64>]| -> Vec<(usize, f64)> {
        scores.iter().enumerate().filter_map(|(k, s)| s.map(|s| (k, s))).collect()
    };
    let far = |k: usize, from: f32| (at(k) / from - 1.0).abs() >= 0.25;
    if every > 1 {
        let coarse = evaluated(&scores);
        let mut peaks: Vec<(usize, f64)> = (0..coarse.len())
            .filter(|&i| {
                let s = coarse[i].1;
                (i == 0 || coarse[i - 1].1 <= s) && (i + 1 == coarse.len() || coarse[i + 1].1 <= s)
            })
            .map(|i| coarse[i])
            .collect();
        peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
        for &(k, _) in peaks.iter().take(REFINED_PEAKS) {
            for j in k.saturating_sub(every - 1)..(k + every).min(steps) {
                if scores[j].is_none() {
                    scores[j] = Some(score_of(j));
                }
            }
        }
    }
    let grid = evaluated(&scores);
    let &(kbest, sbest) = grid.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    let lbest = at(kbest);
    let runner_up = grid.iter().filter(|&&(k, _)| far(k, lbest)).map(|g| g.1).fold(-1.0f64, f64::max);
    // Parabola through the best and its neighbours (both evaluated: a refined
    // window reaches the coarse points on either side).
    let mut lambda = lbest;
    let neighbour = |k: Option<usize>| k.and_then(|k| scores.get(k).copied().flatten());
    if let (Some(a), Some(c)) = (neighbour(kbest.checked_sub(1)), neighbour(Some(kbest + 1))) {
        let b = sbest;
        let den = a - 2.0 * b + c;
        if den < 0.0 {
            lambda += (0.5 * (a - c) / den).clamp(-0.5, 0.5) as f32 * step;
        }
    }
    // The first side lobe (sinc² ≥ 0.03 over φλ ∈ [1.25, 1.65], peak 0.047 at 1.43):
    // its mean along-flow power over the noise floor, ln. See `MIN_SIDE_LOBE`.
    let side_lobe = s.noise.as_ref().map_or(f64::NAN, |noise_power| {
        // The floor here has the shape of white pixel noise read through the lines'
        // bilinear sampling (`Spectrum::noise`), at the least smoothed ratio of the
        // along-flow power to that shape over the upper 3/4 of the band: a flat
        // floor at the band's top sits below an oblique line's noise at mid-band.
        let shape: Vec<f64> = idx.iter().map(|&b| noise_power[b] / s.weight[b]).collect();
        let level = (idx.len() / 4..idx.len())
            .map(|i| smooth(&along, i) / smooth(&shape, i))
            .filter(|v| v.is_finite())
            .fold(f64::INFINITY, f64::min);
        let (a, b) = (1.25 / lambda as f64, 1.65 / lambda as f64);
        let (mut power, mut noise, mut count) = (0.0f64, 0.0f64, 0usize);
        for (i, &k) in idx.iter().enumerate() {
            if (a..=b).contains(&(s.phi[k] as f64)) {
                power += along[i];
                noise += level * shape[i];
                count += 1;
            }
        }
        if count == 0 || noise <= 0.0 {
            f64::NAN
        } else {
            (power / noise).ln()
        }
    });
    // Where the ratio's dip at the first zero comes from (`MIN_ALONG_DIP`,
    // `MAX_ACROSS_SHARE`): the ratio is ln along − ln across (smoothed), and
    // detrending is linear, so the along-flow power's own detrended ln is the
    // ratio's residual plus the across-flow reference's.
    let r_ref = detrend(&lref);
    let (mut ratio_sum, mut across_sum, mut count) = (0.0f64, 0.0f64, 0usize);
    let at_zero = |i: usize| s.phi[idx[i]] as f64 * lambda as f64;
    for i in 0..idx.len() {
        if (0.85..=1.15).contains(&at_zero(i)) {
            ratio_sum += r_obs[i];
            across_sum += r_ref[i];
            count += 1;
        }
    }
    // Fast flow puts few bins at low φ (φ steps by speed / LINE_PX: 0.39 cycles per
    // frame at 50 px/frame, so a full-frame streak's zero at φ = 1 has no bin within
    // ±15%): then the bin nearest to the zero, if within ±30% (sinc² ≤ 0.14 there,
    // still the zero's trough against the main lobe).
    if count == 0 {
        let nearest = (0..idx.len()).min_by(|&a, &b| (at_zero(a) - 1.0).abs().total_cmp(&(at_zero(b) - 1.0).abs()));
        if let Some(i) = nearest.filter(|&i| (0.7..=1.3).contains(&at_zero(i))) {
            ratio_sum = r_obs[i];
            across_sum = r_ref[i];
            count = 1;
        }
    }
    let (along_dip, across_share) = if count == 0 {
        (f64::NAN, f64::INFINITY)
    } else {
        let (ratio, across) = (ratio_sum / count as f64, across_sum / count as f64);
        (-(ratio + across), if ratio < 0.0 { across / -ratio } else { f64::INFINITY })
    };
    Some(TemplateMatch {
        lambda,
        score: sbest as f32,
        runner_up: runner_up as f32,
        inside: lbest >= lambda_min && lbest <= 1.0,
        side_lobe: side_lobe as f32,
        along_dip: along_dip as f32,
        across_share: across_share as f32,
    })
}

#[cfg(test)]
mod tests;
