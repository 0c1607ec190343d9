//! Lateral chromatic aberration read blindly from one frame: a lens that focuses red
//! and blue at other magnifications than green images channel c as green's image
//! scaled by s_c about the optical centre (lensfun's "linear" TCA model, r_c = s_c·r;
//! its "poly3" profiles are this term plus small cubic ones). Near an edge in an
//! achromatic-enough scene channel c is locally an affine copy of green, so for
//! small shifts
//!
//!   C(p) ≈ a·G(p) + b − a·(s_c − 1)·r·∂_r G(p),
//!
//! r the pixel's distance from the centre and ∂_r the derivative along the radius:
//! a least-squares fit of C on (G, r·∂_r G, 1) over a small window reads s_c − 1 as
//! −coefficient / a (the fringe's sign and size, whatever the edge's colours). Each
//! window gives one reading with its own variance; the frame's estimate is their
//! inverse-variance mean under Tukey's biweight, its error a jackknife over 4×4
//! tiles (edges in one region share a texture's bias). The same linearisation is
//! what registration by optical flow does per channel (Lucas–Kanade), restricted to
//! the one parameter a radial magnification has.
//!
//! Readings come only from windows where green has a strong edge whose normal is
//! mostly radial (a tangential edge does not move under a radial scale) and outside
//! the frame's central quarter (the shift grows with r). Measured by
//! `tests/chromatic.rs` and `benches/chromatic.rs` (BENCHMARKS.md "Lateral
//! chromatic aberration"). The worker reads a few hundred windows per frame at a
//! slow cadence and pools the frames' estimates (`pool`) into the model's term,
//! present / absent / not identifiable. The tile jackknife's σ (0.001–0.009 px on
//! the test photographs) understates the error (up to 0.02 px there): `pool` floors
//! it.

use crate::image::Rgb;
use crate::model::{ChromaticAberration, Diagnostics, Status, MAX_CHROMATIC_SCALE_DEVIATION};

/// Window half-side (px): 5×5 windows.
const HALF: usize = 2;
/// Candidate grid step (px).
const STEP: usize = 3;
/// Readings start this far out (fraction of the half-diagonal).
const MIN_RADIUS: f32 = 0.25;
/// Green's radial derivative at a candidate: at least this (encoded units per px) ...
const MIN_RADIAL_GRADIENT: f32 = 0.02;
/// ... and at least this share of the gradient's magnitude.
const MIN_RADIAL_SHARE: f32 = 0.7;
/// Gain of C against G a window must show (an edge in both channels, same sense).
const GAIN_RANGE: [f64; 2] = [0.2, 5.0];
/// Tukey biweight cut-off in standardised residuals.
const TUKEY_C: f64 = 4.685;
/// Fewest readings for an estimate.
pub const MIN_READINGS: usize = 50;
/// Most windows read (a grid-ordered subsample beyond). The trade, at 1280×960 on
/// one thread and on lensfun's profiles (`benches/chromatic.rs`): 1 000 windows
/// 13.5 ms, corner-shift error p90 ≤ 0.017 px; 3 000 windows 40 ms, p90 ≤ 0.011 px.
const MAX_WINDOWS: usize = 1000;

/// One channel's estimate: s − 1 and its one-sigma error (jackknife over tiles).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScaleEstimate {
    pub scale_minus_one: f64,
    pub stderr: f64,
    pub readings: usize,
}

/// Gauss–Newton passes at most: each resamples the channel by the scale read so far
/// and reads what is left (the linearisation holds for shifts well under an edge's
/// width); they stop once a pass moves the corner by ≤ 0.005 px. With 3 000
/// windows one pass read a 0.6 px red shift on the rocket photograph as 0.99 px (its
/// own aberration ~0.1); three left the greyscale rocket at 0.65–0.68 px, six at
/// 0.58–0.59 (`tests/chromatic.rs`).
const PASSES: usize = 6;

/// s_R − 1 and s_B − 1 of `image` (encoded, any size), each `None` where the frame
/// has under `MIN_READINGS` usable edges.
pub fn estimate(image: &Rgb) -> [Option<ScaleEstimate>; 2] {
    estimate_with(image, MAX_WINDOWS)
}

/// `estimate` reading at most `max_windows` windows (the worker's per-frame budget).
pub fn estimate_with(image: &Rgb, max_windows: usize) -> [Option<ScaleEstimate>; 2] {
    estimate_from(image, max_windows, [0.0; 2])
}

/// `estimate_with` starting the Gauss–Newton passes at `start` = [s_R − 1, s_B − 1]
/// (the worker's newest reading of each channel: a lens does not change, so the
/// first pass usually converges and the frame costs one pass instead of three to
/// six).
pub fn estimate_from(image: &Rgb, max_windows: usize, start: [f64; 2]) -> [Option<ScaleEstimate>; 2] {
    let max_windows = max_windows.max(MIN_READINGS);
    let start = start.map(|v| if v.is_finite() && v.abs() <= MAX_CHROMATIC_SCALE_DEVIATION as f64 { v } else { 0.0 });
    let (w, h) = (image.width, image.height);
    let g = &image.channels[1];
    let (cx, cy) = ((w as f32 - 1.0) * 0.5, (h as f32 - 1.0) * 0.5);
    let half_diag = cx.hypot(cy).max(1.0);
    let m = HALF + 1;
    if w <= 2 * m + 1 || h <= 2 * m + 1 {
        return [None, None];
    }
    let at = |c: &[f32], x: usize, y: usize| c[y * w + x];
    // Green's radial derivative at (x, y) (central differences), its gradient's
    // magnitude and the radius.
    let radial = |x: usize, y: usize| -> (f32, f32, f32) {
        let gx = 0.5 * (at(g, x + 1, y) - at(g, x - 1, y));
        let gy = 0.5 * (at(g, x, y + 1) - at(g, x, y - 1));
        let (dx, dy) = (x as f32 - cx, y as f32 - cy);
        let rad = dx.hypot(dy).max(1e-6);
        ((gx * dx + gy * dy) / rad, gx.hypot(gy), rad)
    };
    // Candidate windows: strong, mostly radial green edges away from the centre.
    let mut centres: Vec<(usize, usize, u8)> = vec![];
    let min_r2 = (MIN_RADIUS * half_diag).powi(2);
    let min_g2 = MIN_RADIAL_GRADIENT * MIN_RADIAL_GRADIENT;
    for y in (m..h - m).step_by(STEP) {
        for x in (m..w - m).step_by(STEP) {
            // Cheap rejections first (inside the central quarter; a gradient under
            // the radial threshold in any direction): most of the grid.
            let (dx, dy) = (x as f32 - cx, y as f32 - cy);
            let gx = 0.5 * (at(g, x + 1, y) - at(g, x - 1, y));
            let gy = 0.5 * (at(g, x, y + 1) - at(g, x, y - 1));
            if dx * dx + dy * dy < min_r2 || gx * gx + gy * gy < min_g2 {
                continue;
            }
            let (gr, mag, rad) = radial(x, y);
            if rad >= MIN_RADIUS * half_diag && gr.abs() >= MIN_RADIAL_GRADIENT && gr.abs() >= MIN_RADIAL_SHARE * mag {
                centres.push((x, y, ((4 * y / h).min(3) * 4 + (4 * x / w).min(3)) as u8));
            }
        }
    }
    if centres.len() > max_windows {
        let step = centres.len().div_ceil(max_windows);
        centres = centres.into_iter().step_by(step).collect();
    }
    // Each window's green and r·∂_r G, once (the passes resample only C).
    const N: usize = (2 * HALF + 1) * (2 * HALF + 1);
    let windows: Vec<([f32; N], [f32; N])> = centres
        .iter()
        .map(|&(x, y, _)| {
            let mut gv = [0.0f32; N];
            let mut dv = [0.0f32; N];
            for (i, (wx, wy)) in
                (y - HALF..=y + HALF).flat_map(|wy| (x - HALF..=x + HALF).map(move |wx| (wx, wy))).enumerate()
            {
                let (gr, _, rad) = radial(wx, wy);
                gv[i] = at(g, wx, wy);
                dv[i] = rad * gr;
            }
            (gv, dv)
        })
        .collect();
    [0usize, 2].map(|c| {
        let plane = &image.channels[c];
        let mut scale = 1.0 + start[c / 2];
        for pass in 0..PASSES {
            let s = scale as f32;
            let readings: Vec<Reading> = centres
                .iter()
                .zip(&windows)
                .map(|(&(x, y, tile), (gv, dv))| {
                    // The channel with the scale read so far undone: C(c + s·(p − c)).
                    let mut cv = [0.0f32; N];
                    for (i, (wx, wy)) in
                        (y - HALF..=y + HALF).flat_map(|wy| (x - HALF..=x + HALF).map(move |wx| (wx, wy))).enumerate()
                    {
                        cv[i] = crate::image::sample_bicubic_slice(
                            plane,
                            w,
                            h,
                            cx + s * (wx as f32 - cx),
                            cy + s * (wy as f32 - cy),
                        );
                    }
                    window_reading(&cv, gv, dv, tile)
                })
                .filter(|r| r.var.is_finite())
                .collect();
            let m = combine_mean(&readings)?;
            scale *= 1.0 + m;
            // The error from the last pass's readings (their jackknife over tiles).
            if m.abs() * half_diag as f64 <= 0.005 || pass + 1 == PASSES {
                let stderr = jackknife(&readings)?;
                return Some(ScaleEstimate { scale_minus_one: scale - 1.0, stderr, readings: readings.len() });
            }
        }
        None
    })
}

/// Floor of a frame's corner-shift σ (px): the tile jackknife states 0.001–0.009
/// px where the errors on greyscale photographs reach 0.02 (`tests/chromatic.rs`),
/// so no frame, and no pool of frames of one scene (their texture biases are
/// shared), is taken as surer than this.
pub const STDERR_FLOOR_PX: f64 = 0.01;
/// A corner shift under this (reference-frame px) is not modelled: a tenth of a
/// pixel's fringe is under one 8-bit step on all but the hardest edges. lensfun's
/// profiles at 1280×960 shift the corner by 0.1 px at the median
/// (`benches/chromatic.rs`).
pub const MIN_VISIBLE_SHIFT_PX: f64 = 0.1;
/// Present beyond this many σ (and `MIN_VISIBLE_SHIFT_PX`).
pub const PRESENT_SIGMAS: f64 = 3.0;
/// Fewest frames with an estimate for a reading.
pub const MIN_FRAMES: usize = 3;

/// The term from frames' estimates (`estimate_with`, oldest first) of a frame whose
/// half-diagonal is `half_diag_px`: per channel the inverse-variance mean (each σ
/// floored at `STDERR_FLOOR_PX`), its σ inflated by the frames' excess scatter
/// (Birge ratio) and floored again. Present where a channel's corner shift is over
/// `PRESENT_SIGMAS`·σ and `MIN_VISIBLE_SHIFT_PX`; absent where both are under
/// `MIN_VISIBLE_SHIFT_PX` at 2σ (the scales read kept, not applied); not
/// identifiable otherwise, under `MIN_FRAMES` frames with edges, or outside the
/// model's range.
pub fn pool(frames: &[[Option<ScaleEstimate>; 2]], half_diag_px: f64) -> ChromaticAberration {
    let started = std::time::Instant::now();
    let floor = STDERR_FLOOR_PX / half_diag_px.max(1.0);
    let channel = |k: usize| -> Option<(f64, f64, usize)> {
        let e: Vec<(f64, f64)> = frames
            .iter()
            .filter_map(|f| f[k])
            .filter(|e| e.scale_minus_one.is_finite() && e.stderr.is_finite())
            .map(|e| (e.scale_minus_one, e.stderr.max(floor)))
            .collect();
        if e.len() < MIN_FRAMES {
            return None;
        }
        let sw: f64 = e.iter().map(|(_, s)| 1.0 / (s * s)).sum();
        let m = e.iter().map(|(v, s)| v / (s * s)).sum::<f64>() / sw;
        let chi2 = e.iter().map(|(v, s)| ((v - m) / s).powi(2)).sum::<f64>();
        let birge = (chi2 / (e.len() - 1) as f64).max(1.0).sqrt();
        Some((m, (birge / sw.sqrt()).max(floor), e.len()))
    };
    let (r, b) = (channel(0), channel(1));
    let samples = r.map_or(0, |c| c.2).max(b.map_or(0, |c| c.2)) as u64;
    let diag = |status, reason: String, stderr: Option<f64>| Diagnostics {
        status,
        reason,
        method: "video".into(),
        residual_before: None,
        residual_after: None,
        samples_used: samples,
        fit_time_s: started.elapsed().as_secs_f64(),
        stderr,
        stages_s: Default::default(),
    };
    let (Some(r), Some(b)) = (r, b) else {
        return ChromaticAberration::absent(diag(
            Status::NotIdentifiable,
            format!("under {MIN_FRAMES} frames with enough strong radial edges in red and blue"),
            None,
        ));
    };
    // Corner shifts (px) and their σ.
    let shift = [r, b].map(|(m, s, _)| (m * half_diag_px, s * half_diag_px));
    let stderr_px = shift[0].1.max(shift[1].1);
    let values = [r.0 as f32, b.0 as f32];
    let reason = format!(
        "corner shift red {:+.3} ± {:.3} px, blue {:+.3} ± {:.3} px (1σ, {} and {} frames)",
        shift[0].0, shift[0].1, shift[1].0, shift[1].1, r.2, b.2
    );
    if values.iter().any(|v| !(v.is_finite() && v.abs() <= MAX_CHROMATIC_SCALE_DEVIATION)) {
        return ChromaticAberration::absent(diag(
            Status::NotIdentifiable,
            format!("{reason}: outside the model's range"),
            Some(stderr_px),
        ));
    }
    let seen = |(d, s): (f64, f64)| d.abs() > PRESENT_SIGMAS * s && d.abs() >= MIN_VISIBLE_SHIFT_PX;
    if shift.iter().any(|c| seen(*c)) {
        return ChromaticAberration {
            present: true,
            scale_minus_one: Some(values),
            diagnostics: diag(Status::Present, reason, Some(stderr_px)),
        };
    }
    // Absent only on evidence: both fringes below the visible level at 2σ.
    if shift.iter().all(|(d, s)| d.abs() + 2.0 * s <= MIN_VISIBLE_SHIFT_PX) {
        let mut c = ChromaticAberration::absent(diag(Status::Absent, reason, Some(stderr_px)));
        c.scale_minus_one = Some(values);
        return c;
    }
    ChromaticAberration::absent(diag(
        Status::NotIdentifiable,
        format!(
            "{reason}: neither over {PRESENT_SIGMAS}σ and {MIN_VISIBLE_SHIFT_PX} px nor under \
             {MIN_VISIBLE_SHIFT_PX} px at 2σ"
        ),
        Some(stderr_px),
    ))
}

/// One window's reading of s − 1, its variance and its tile.
#[derive(Clone, Copy, Debug)]
struct Reading {
    value: f64,
    var: f64,
    tile: u8,
}

impl Reading {
    const NONE: Reading = Reading { value: 0.0, var: f64::INFINITY, tile: 0 };
}

/// The least-squares reading of one channel's window values `cv` against green's
/// `gv` and r·∂_r G `dv`.
fn window_reading(cv: &[f32], gv: &[f32], dv: &[f32], tile: u8) -> Reading {
    // Normal equations of C ~ [G, r·∂_r G, 1].
    let mut n = [[0.0f64; 3]; 3];
    let mut v = [0.0f64; 3];
    let mut yy = 0.0f64;
    let count = cv.len() as f64;
    for ((&t, &gi), &di) in cv.iter().zip(gv).zip(dv) {
        let row = [gi as f64, di as f64, 1.0];
        let t = t as f64;
        if !(row.iter().all(|v| v.is_finite()) && t.is_finite()) {
            return Reading::NONE;
        }
        for i in 0..3 {
            v[i] += row[i] * t;
            for j in 0..3 {
                n[i][j] += row[i] * row[j];
            }
        }
        yy += t * t;
    }
    let Some(inv) = invert3(n) else { return Reading::NONE };
    let coef: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| inv[i][j] * v[j]).sum());
    let a = coef[0];
    if !(GAIN_RANGE[0]..=GAIN_RANGE[1]).contains(&a) {
        return Reading::NONE;
    }
    // Residual variance: yᵀy − coefᵀ·Xᵀy over n − 3.
    let rss = (yy - (0..3).map(|i| coef[i] * v[i]).sum::<f64>()).max(0.0);
    // An 8-bit step's variance as the floor: a noise-free window is not exact.
    let s2 = (rss / (count - 3.0)).max(1.0 / (12.0 * 255.0 * 255.0));
    let value = -coef[1] / a;
    let var = s2 * inv[1][1] / (a * a);
    if value.is_finite() && var.is_finite() && var > 0.0 {
        Reading { value, var, tile }
    } else {
        Reading::NONE
    }
}

fn invert3(m: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let scale = m[0][0].abs() * m[1][1].abs() * m[2][2].abs();
    if !(det.is_finite() && det.abs() > 1e-12 * scale.max(1e-300)) {
        return None;
    }
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    // inverse[i][j] = cofactor[j][i] / det (the cyclic form carries the signs).
    Some(std::array::from_fn(|i| std::array::from_fn(|j| c(j, i) / det)))
}

/// Tukey-weighted inverse-variance mean of the readings (`None` under
/// `MIN_READINGS`).
fn combine_mean(readings: &[Reading]) -> Option<f64> {
    if readings.len() < MIN_READINGS {
        return None;
    }
    weighted_mean(&readings.iter().collect::<Vec<_>>())
}

/// Jackknife over the 16 tiles of `combine_mean`: leave out each tile that holds
/// readings (an empty tile's "leave-out" is the whole estimate again and would
/// shrink the spread).
fn jackknife(readings: &[Reading]) -> Option<f64> {
    let loo: Vec<f64> = (0..16u8)
        .filter(|t| readings.iter().any(|r| r.tile == *t))
        .filter_map(|t| weighted_mean(&readings.iter().filter(|r| r.tile != t).collect::<Vec<_>>()))
        .collect();
    let k = loo.len() as f64;
    if k < 2.0 {
        return None;
    }
    let mean = loo.iter().sum::<f64>() / k;
    Some(((k - 1.0) / k * loo.iter().map(|v| (v - mean).powi(2)).sum::<f64>()).sqrt())
}

/// From the weighted median, Tukey iterations on standardised residuals (each
/// reading's own σ times a common scale from their MAD).
fn weighted_mean(rs: &[&Reading]) -> Option<f64> {
    if rs.is_empty() {
        return None;
    }
    let mut sorted: Vec<(f64, f64)> = rs.iter().map(|r| (r.value, 1.0 / r.var)).collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = sorted.iter().map(|s| s.1).sum();
    let mut acc = 0.0;
    let mut m = sorted[sorted.len() / 2].0;
    for s in &sorted {
        acc += s.1;
        if acc >= 0.5 * total {
            m = s.0;
            break;
        }
    }
    for _ in 0..10 {
        let mut z: Vec<f64> = rs.iter().map(|r| ((r.value - m) / r.var.sqrt()).abs()).collect();
        let mid = z.len() / 2;
        let scale = (1.4826 * *z.select_nth_unstable_by(mid, f64::total_cmp).1).max(1e-9);
        let (mut sw, mut swx) = (0.0, 0.0);
        for r in rs {
            let u = (r.value - m) / (r.var.sqrt() * scale * TUKEY_C);
            if u.abs() < 1.0 {
                let wt = (1.0 - u * u).powi(2) / r.var;
                sw += wt;
                swx += wt * r.value;
            }
        }
        if sw <= 0.0 {
            return None;
        }
        m = swx / sw;
    }
    m.is_finite().then_some(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(values_px: &[f64], stderr_px: f64, half_diag_px: f64) -> Vec<[Option<ScaleEstimate>; 2]> {
        values_px
            .iter()
            .map(|v| {
                let e = ScaleEstimate {
                    scale_minus_one: v / half_diag_px,
                    stderr: stderr_px / half_diag_px,
                    readings: 200,
                };
                [Some(e), Some(ScaleEstimate { scale_minus_one: -e.scale_minus_one, ..e })]
            })
            .collect()
    }

    /// The three states from frames' estimates at an 800 px half-diagonal: a 0.16 px
    /// fringe read consistently is present (its scales kept exactly: the mean of
    /// equal values); 0.01 px is absent (0.01 + 2·0.01 floor ≤ 0.1); two frames, or
    /// frames scattering 0 / 0.2 px (Birge-inflated σ 0.038 px: the scatter's
    /// standard error), or a reading past the
    /// model's range are not identifiable.
    #[test]
    fn pooled_frames_give_the_three_states() {
        let hd = 800.0;
        let c = pool(&frames(&[0.16; 8], 0.002, hd), hd);
        assert_eq!(c.diagnostics.status, Status::Present, "{}", c.diagnostics.reason);
        let s = c.applied().expect("applied");
        assert!((s[0] as f64 * hd - 0.16).abs() < 1e-4 && (s[1] as f64 * hd + 0.16).abs() < 1e-4, "{s:?}");
        // The floor, not the frames' own 0.002 px, is the stated σ.
        assert!((c.diagnostics.stderr.unwrap() - STDERR_FLOOR_PX).abs() < 1e-9);

        let c = pool(&frames(&[0.01; 8], 0.002, hd), hd);
        assert_eq!(c.diagnostics.status, Status::Absent, "{}", c.diagnostics.reason);
        assert!(!c.present && c.scale_minus_one.is_some() && c.applied().is_none());

        let c = pool(&frames(&[0.16; 2], 0.002, hd), hd);
        assert_eq!(c.diagnostics.status, Status::NotIdentifiable);
        assert!(c.scale_minus_one.is_none());

        let c = pool(&frames(&[0.0, 0.2, 0.0, 0.2, 0.0, 0.2, 0.0, 0.2], 0.002, hd), hd);
        assert_eq!(c.diagnostics.status, Status::NotIdentifiable, "{}", c.diagnostics.reason);
        // The scatter's standard error: 0.107 px / √8.
        assert!((c.diagnostics.stderr.unwrap() - 0.107 / 8f64.sqrt()).abs() < 0.002, "{:?}", c.diagnostics.stderr);

        let c = pool(&frames(&[0.02 * hd; 8], 0.002, hd), hd);
        assert_eq!(c.diagnostics.status, Status::NotIdentifiable, "{}", c.diagnostics.reason);
        assert!(c.scale_minus_one.is_none());
    }
}
