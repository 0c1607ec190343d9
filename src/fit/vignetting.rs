//! Vignetting fitted blindly from video: a static surface seen in two frames at two
//! image radii is darkened by V(r) differently in each, so the log-ratio of its two
//! renderings is log V(r_cur) − log V(r_src) plus the frames' exposure change. With
//! log V(r) = a1·r² + a2·r⁴ (`model::Vignetting`) that is linear in (a1, a2) with one
//! intercept per frame pair: a least-squares problem over the pairs a moving head
//! gives, the surfaces matched by pose and depth (the worker's `analysis::temporal`).
//! One frame cannot separate falloff from the scene's own shading; video can
//! (Goldman & Chen, "Vignette and exposure calibration and compensation", ICCV 2005,
//! fit the same quantities from overlapping panorama frames).
//!
//! Samples: box means of linear luma (sRGB decoded) on a grid, kept where the box is
//! flat in both frames (an edge moved by a sub-pixel misalignment or by a
//! different motion blur would read as falloff), neither clipped nor dark. What
//! survives the gate (specular highlights, moving objects, depth errors) is taken
//! out by Tukey's biweight on the residuals. The error is a jackknife over the pairs.

use crate::image::{Rgb, LUMA_WEIGHTS};
use crate::model::{Diagnostics, Status, Vignetting};

/// Sample grid: this many points along the frame's longer side (32 px apart at
/// 1280×960, about 1 100 points where a box fits), each the centre of a box as wide
/// as the spacing, read at 9×9 (5×5 at 320×240) of its pixels.
pub const GRID_ALONG_LONG_SIDE: usize = 40;
/// Fewest frame pairs, each with `MIN_ROWS_PER_PAIR` samples, for a fit: the
/// jackknife over pairs needs several to say anything.
pub const MIN_PAIRS: usize = 6;
pub const MIN_ROWS_PER_PAIR: usize = 30;
/// One-sigma uncertainty of the corner falloff above which the term is not
/// identifiable (the head has not shown the same surfaces at different radii).
pub const MAX_STDERR: f64 = 0.025;
/// Smallest corner falloff |1 − V(1)| worth modelling: 3% of linear light, about
/// twice the luminance difference a viewer tells apart side by side (Weber ~1–2%),
/// about three 8-bit steps at mid grey. At 2% a tuning scene's own structure
/// (Middlebury's Monopoly, no vignetting applied) read 2.2 ± 0.8% and was
/// published present (`benches/vignetting.rs`).
pub const MIN_VISIBLE_FALLOFF: f64 = 0.03;
/// Standard errors the corner falloff must exceed to be present: 3, as the
/// jackknife over frame pairs that share surfaces understates the spread a little.
pub const PRESENT_SIGMAS: f64 = 3.0;
/// A sample box is flat where its halves' means differ by at most this fraction of
/// its mean, horizontally and vertically, in both frames. At 0.06 (with boxes half
/// the spacing) the motorcycle sequence at 320×240 kept 1–5% of its grid, the
/// halves' noise alone failing it; Tukey's weights take what the looser gate lets
/// through.
const FLATNESS: f32 = 0.15;
/// Box means below this linear luma carry too little signal (quantisation, noise
/// floor); any encoded value above `CLIP` may be clipped.
const MIN_LINEAR: f32 = 0.01;
const CLIP: f32 = 0.97;
/// Tukey biweight cut-off in robust standard deviations (95% efficiency at the
/// normal).
const TUKEY_C: f64 = 4.685;

/// Terms of log V (`model::Vignetting::log_falloff`).
const P: usize = 3;
/// One matched sample: [r_cur² − r_src², r_cur⁴ − r_src⁴, r_cur⁶ − r_src⁶,
/// ln Y_cur − ln Y_src].
pub type Row = [f32; P + 1];

/// Box geometry of the grid for a `w`×`h` frame: (spacing, box half-side) in px.
fn grid(w: usize, h: usize) -> (usize, usize) {
    let spacing = (w.max(h) / GRID_ALONG_LONG_SIDE).max(4);
    (spacing, (spacing / 2).max(2))
}

fn radius(w: usize, h: usize, x: f32, y: f32) -> f32 {
    Vignetting::radius(w, h, x, y)
}

/// Grid points (pixel centres) of a `w`×`h` frame where a sample box fits.
pub fn sample_points(w: usize, h: usize) -> Vec<[f32; 2]> {
    let (spacing, half) = grid(w, h);
    let margin = half + 2;
    if w <= 2 * margin || h <= 2 * margin {
        return Vec::new();
    }
    let xs = (margin..w - margin).step_by(spacing);
    let ys: Vec<usize> = (margin..h - margin).step_by(spacing).collect();
    xs.flat_map(|x| ys.iter().map(move |&y| [x as f32 + 0.5, y as f32 + 0.5])).collect()
}

/// Mean linear luma of the box centred on pixel (x, y), read at every
/// max(2, half/4)-th pixel (9×9 taps at 1280×960, 5×5 at 320×240); `None` where it
/// leaves the frame, is clipped or dark, or is not flat (`FLATNESS`).
fn box_mean(img: &Rgb, x: f32, y: f32, half: usize, lut: &[f32]) -> Option<f32> {
    let (w, h) = (img.width as isize, img.height as isize);
    let (cx, cy) = (x.floor() as isize, y.floor() as isize);
    let hf = half as isize;
    let step = (half / 4).max(2);
    if !(x.is_finite() && y.is_finite()) || cx - hf < 0 || cy - hf < 0 || cx + hf >= w || cy + hf >= h {
        return None;
    }
    // Sums and tap counts over the left/right and top/bottom halves (the centre
    // row/column in none).
    let (mut sums, mut counts) = ([0.0f32; 4], [0usize; 4]);
    let (mut all, mut n) = (0.0f32, 0usize);
    let [cr, cg, cb] = &img.channels;
    for dy in (-hf..=hf).step_by(step) {
        let row = ((cy + dy) * w) as usize;
        for dx in (-hf..=hf).step_by(step) {
            let i = row + (cx + dx) as usize;
            let (er, eg, eb) = (cr[i], cg[i], cb[i]);
            if !(er <= CLIP && eg <= CLIP && eb <= CLIP) {
                return None; // clipped, or NaN
            }
            let d = |v: f32| super::colour::srgb_decode_with(lut, v);
            let yl = LUMA_WEIGHTS[0] * d(er) + LUMA_WEIGHTS[1] * d(eg) + LUMA_WEIGHTS[2] * d(eb);
            all += yl;
            n += 1;
            for (k, on) in [dx < 0, dx > 0, dy < 0, dy > 0].into_iter().enumerate() {
                if on {
                    sums[k] += yl;
                    counts[k] += 1;
                }
            }
        }
    }
    let mean = all / n.max(1) as f32;
    let m: [f32; 4] = std::array::from_fn(|k| sums[k] / counts[k].max(1) as f32);
    let flat = (m[0] - m[1]).abs() <= FLATNESS * mean && (m[2] - m[3]).abs() <= FLATNESS * mean;
    (mean >= MIN_LINEAR && flat).then_some(mean)
}

/// Rows of one frame pair: `matches` pairs a point of `cur` with where the same
/// surface is in `src` (both pixel positions, same frame size). Points whose box
/// is not flat, clipped or dark in either frame are left out.
pub fn pair_rows(cur: &Rgb, src: &Rgb, matches: &[([f32; 2], [f32; 2])]) -> Vec<Row> {
    let (w, h) = (cur.width, cur.height);
    if (src.width, src.height) != (w, h) {
        return Vec::new();
    }
    let (_, half) = grid(w, h);
    let lut = super::colour::srgb_lut();
    matches
        .iter()
        .filter_map(|&([xc, yc], [xs, ys])| {
            let yc_l = box_mean(cur, xc, yc, half, lut)?;
            let ys_l = box_mean(src, xs, ys, half, lut)?;
            let (rc, rs) = (radius(w, h, xc, yc).powi(2), radius(w, h, xs, ys).powi(2));
            Some([rc - rs, rc * rc - rs * rs, rc * rc * rc - rs * rs * rs, yc_l.ln() - ys_l.ln()])
        })
        .collect()
}

/// Normal equations (XᵀWX, XᵀWy) of the falloff's terms.
type Normal = ([[f64; P]; P], [f64; P]);

/// Weighted per-pair centred normal equations, each pair's intercept eliminated.
fn pair_normal(rows: &[Row], weights: &[f64]) -> Normal {
    let mut out = ([[0.0f64; P]; P], [0.0f64; P]);
    let sw: f64 = weights.iter().sum();
    if sw <= 0.0 {
        return out;
    }
    let mut m = [0.0f64; P + 1];
    for (r, &wt) in rows.iter().zip(weights) {
        for k in 0..=P {
            m[k] += wt * r[k] as f64;
        }
    }
    m.iter_mut().for_each(|v| *v /= sw);
    for (r, &wt) in rows.iter().zip(weights) {
        let x: [f64; P] = std::array::from_fn(|k| r[k] as f64 - m[k]);
        let y = r[P] as f64 - m[P];
        for i in 0..P {
            out.1[i] += wt * x[i] * y;
            for j in 0..P {
                out.0[i][j] += wt * x[i] * x[j];
            }
        }
    }
    out
}

/// Solve the normal equations (Gaussian elimination with partial pivoting);
/// `None` where they are singular to working precision (the samples do not span the
/// terms).
fn solve(n: &Normal) -> Option<[f64; P]> {
    let (mut a, mut b) = *n;
    let scale = (0..P).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    for c in 0..P {
        let piv = (c..P).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[piv][c].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(c, piv);
        b.swap(c, piv);
        for r in c + 1..P {
            let f = a[r][c] / a[c][c];
            for k in c..P {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0f64; P];
    for c in (0..P).rev() {
        let s: f64 = (c + 1..P).map(|k| a[c][k] * x[k]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn add(acc: &mut Normal, n: &Normal, sign: f64) {
    for i in 0..P {
        acc.1[i] += sign * n.1[i];
        for j in 0..P {
            acc.0[i][j] += sign * n.0[i][j];
        }
    }
}

/// Residuals of every row of `pairs` under `a` (each pair's intercept its weighted
/// mean residual).
fn residuals(pairs: &[&[Row]], weights: &[Vec<f64>], a: [f64; P]) -> Vec<Vec<f64>> {
    pairs
        .iter()
        .zip(weights)
        .map(|(rows, w)| {
            let raw: Vec<f64> =
                rows.iter().map(|r| r[P] as f64 - (0..P).map(|k| a[k] * r[k] as f64).sum::<f64>()).collect();
            let sw: f64 = w.iter().sum();
            let c = if sw > 0.0 { raw.iter().zip(w).map(|(e, w)| e * w).sum::<f64>() / sw } else { 0.0 };
            raw.into_iter().map(|e| e - c).collect()
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Fit the vignetting term from frame pairs' rows (`pair_rows`), oldest first.
pub fn fit_vignetting(pairs: &[&[Row]]) -> Vignetting {
    let started = std::time::Instant::now();
    let diag = |status, reason: String, stderr: Option<f64>, before: Option<f64>, after: Option<f64>, samples: u64| {
        Diagnostics {
            status,
            reason,
            method: "video".into(),
            residual_before: before,
            residual_after: after,
            samples_used: samples,
            fit_time_s: started.elapsed().as_secs_f64(),
            stderr,
            stages_s: Default::default(),
        }
    };
    let usable: Vec<&[Row]> = pairs
        .iter()
        .copied()
        .filter(|p| p.len() >= MIN_ROWS_PER_PAIR && p.iter().all(|r| r.iter().all(|v| v.is_finite())))
        .collect();
    if usable.len() < MIN_PAIRS {
        return Vignetting::absent(diag(
            Status::NotIdentifiable,
            format!(
                "{} frame pairs with ≥ {MIN_ROWS_PER_PAIR} flat matched samples (need {MIN_PAIRS}): \
                 not enough of the same surfaces seen twice",
                usable.len()
            ),
            None,
            None,
            None,
            0,
        ));
    }
    // Iteratively reweighted least squares, Tukey's biweight on residuals scaled by
    // their MAD (recomputed each pass), from ordinary least squares.
    let mut weights: Vec<Vec<f64>> = usable.iter().map(|p| vec![1.0; p.len()]).collect();
    let mad = |res: &[Vec<f64>]| 1.4826 * median(res.iter().flatten().map(|e| e.abs()).collect());
    let before = mad(&residuals(&usable, &weights, [0.0; P]));
    let mut a = [0.0f64; P];
    let mut normals = Vec::new();
    for _ in 0..8 {
        normals = usable.iter().zip(&weights).map(|(p, w)| pair_normal(p, w)).collect::<Vec<_>>();
        let mut acc = ([[0.0; P]; P], [0.0; P]);
        normals.iter().for_each(|n| add(&mut acc, n, 1.0));
        let Some(next) = solve(&acc) else {
            return Vignetting::absent(diag(
                Status::NotIdentifiable,
                "the matched samples span too few radii to separate the falloff's terms".into(),
                None,
                Some(before),
                None,
                0,
            ));
        };
        a = next;
        let res = residuals(&usable, &weights, a);
        let s = mad(&res).max(1e-6);
        for (w, r) in weights.iter_mut().zip(&res) {
            for (w, e) in w.iter_mut().zip(r) {
                let u = e / (TUKEY_C * s);
                *w = if u.abs() < 1.0 { (1.0 - u * u).powi(2) } else { 0.0 };
            }
        }
    }
    let res = residuals(&usable, &weights, a);
    let after = mad(&res);
    let used = weights.iter().flatten().filter(|w| **w > 0.0).count() as u64;
    // Corner falloff f = 1 − exp(Σ a) and its jackknife over the pairs (each pair's
    // normal equations left out in turn, weights held).
    let corner = |a: [f64; P]| 1.0 - a.iter().sum::<f64>().exp();
    let f = corner(a);
    let mut total = ([[0.0; P]; P], [0.0; P]);
    normals.iter().for_each(|n| add(&mut total, n, 1.0));
    let loo: Vec<f64> = normals
        .iter()
        .filter_map(|n| {
            let mut t = total;
            add(&mut t, n, -1.0);
            solve(&t).map(corner)
        })
        .collect();
    let m = loo.len() as f64;
    let stderr = if loo.len() + 1 >= usable.len() && m >= 2.0 {
        let mean = loo.iter().sum::<f64>() / m;
        ((m - 1.0) / m * loo.iter().map(|v| (v - mean).powi(2)).sum::<f64>()).sqrt()
    } else {
        f64::INFINITY
    };
    let n_pairs = usable.len();
    let values = a.map(|v| v as f32);
    let in_range = crate::model::CameraModel {
        vignetting: Vignetting { present: true, log_falloff: Some(values), diagnostics: Diagnostics::not_fitted("") },
        ..crate::model::CameraModel::empty(1, 1)
    }
    .validate()
    .is_ok();
    if !(stderr.is_finite() && stderr <= MAX_STDERR && in_range) {
        return Vignetting::absent(diag(
            Status::NotIdentifiable,
            format!(
                "corner falloff {:.3} ± {:.3} over {n_pairs} frame pairs: the same surfaces have not been seen at \
                 radii far enough apart{}",
                f,
                stderr,
                if in_range { "" } else { " (and the fit is outside the model's range)" }
            ),
            stderr.is_finite().then_some(stderr),
            Some(before),
            Some(after),
            used,
        ));
    }
    let reason = format!("corner falloff {f:.3} ± {stderr:.3} (1σ, jackknife over {n_pairs} frame pairs)");
    let diagnostics = |status| diag(status, reason.clone(), Some(stderr), Some(before), Some(after), used);
    if f.abs() > PRESENT_SIGMAS * stderr && f.abs() >= MIN_VISIBLE_FALLOFF {
        return Vignetting { present: true, log_falloff: Some(values), diagnostics: diagnostics(Status::Present) };
    }
    // Absent only on evidence: the falloff below the visible level at 2σ. Between
    // the two the frames cannot tell a faint falloff from none.
    let status = if f.abs() + 2.0 * stderr <= MIN_VISIBLE_FALLOFF { Status::Absent } else { Status::NotIdentifiable };
    let mut v = Vignetting::absent(diagnostics(status));
    if status == Status::NotIdentifiable {
        v.diagnostics.reason += &format!(
            ": neither over {PRESENT_SIGMAS}σ and {MIN_VISIBLE_FALLOFF} nor under {MIN_VISIBLE_FALLOFF} at 2σ"
        );
    }
    // The terms read are kept (not applied) where absent: the evidence for it.
    if status == Status::Absent {
        v.log_falloff = Some(values);
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// xorshift64*: uniform and normal draws for the synthetic rows.
    struct Rng(u64);
    impl Rng {
        fn new(seed: u64) -> Self {
            Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
        }
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u1, u2) = (1.0 - self.uniform(), self.uniform());
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        }
    }

    /// Rows of `pairs` pairs for a true falloff `a`: random radii, an exposure
    /// change per pair, Gaussian noise `sigma` on the log-ratio and a fraction
    /// `outliers` of gross errors.
    fn rows(a: [f64; P], pairs: usize, sigma: f64, outliers: f64, seed: u64) -> Vec<Vec<Row>> {
        let mut rng = Rng::new(seed);
        (0..pairs)
            .map(|p| {
                let exposure = 0.1 * (p as f64 * 0.7).sin();
                (0..400)
                    .map(|_| {
                        let (rc, rs) = (rng.uniform(), rng.uniform());
                        let lv = |r: f64| a[0] * r * r + a[1] * r.powi(4) + a[2] * r.powi(6);
                        let mut y = lv(rc) - lv(rs) + exposure + sigma * rng.normal();
                        if (rng.uniform()) < outliers {
                            y += 0.5 + rng.uniform();
                        }
                        let (c2, s2) = (rc * rc, rs * rs);
                        [(c2 - s2) as f32, (c2 * c2 - s2 * s2) as f32, (c2.powi(3) - s2.powi(3)) as f32, y as f32]
                    })
                    .collect()
            })
            .collect()
    }

    fn fit(rows: &[Vec<Row>]) -> Vignetting {
        let refs: Vec<&[Row]> = rows.iter().map(|r| r.as_slice()).collect();
        fit_vignetting(&refs)
    }

    /// A lensfun-like falloff (corner 0.6) read through noise and 10% gross
    /// outliers: the corner within 0.01 (the jackknife's σ here is ~0.003; 0.01 is
    /// three of them and a tenth of the 10% on a 0.4 falloff).
    #[test]
    fn a_falloff_is_read_through_noise_and_outliers() {
        let a = [-0.35, -0.16, 0.0];
        let v = fit(&rows(a, 12, 0.03, 0.1, 7));
        assert!(v.present, "{:?}", v.diagnostics);
        let got = Vignetting::gain_at(v.log_falloff.unwrap(), 1.0);
        let want = a.iter().sum::<f64>().exp() as f32;
        assert!((got - want).abs() < 0.01, "corner {got} for {want}: {}", v.diagnostics.reason);
        assert!(v.diagnostics.stderr.unwrap() < 0.01);
    }

    /// No falloff: absent, and its bound says so.
    #[test]
    fn a_flat_lens_is_absent() {
        let v = fit(&rows([0.0; P], 12, 0.03, 0.05, 8));
        assert_eq!(v.diagnostics.status, Status::Absent, "{}", v.diagnostics.reason);
        assert!(!v.present);
    }

    /// Too few pairs, or every sample at the same radius in both frames (a head
    /// that does not move): not identifiable, never absent.
    #[test]
    fn a_still_head_is_not_identifiable() {
        let v = fit(&rows([-0.4, 0.0, 0.0], 3, 0.03, 0.0, 9));
        assert_eq!(v.diagnostics.status, Status::NotIdentifiable);
        let still: Vec<Vec<Row>> = rows([-0.4, 0.0, 0.0], 12, 0.03, 0.0, 10)
            .into_iter()
            .map(|p| p.into_iter().map(|r| [0.0, 0.0, 0.0, r[P]]).collect())
            .collect();
        let v = fit(&still);
        assert_eq!(v.diagnostics.status, Status::NotIdentifiable, "{}", v.diagnostics.reason);
        assert!(v.log_falloff.is_none());
    }

    /// Non-finite rows never reach the coefficients.
    #[test]
    fn non_finite_rows_are_refused() {
        let mut r = rows([-0.3, 0.0, 0.0], 12, 0.02, 0.0, 11);
        r.iter_mut().for_each(|p| p[0][P] = f32::NAN);
        let v = fit(&r);
        assert_eq!(v.diagnostics.status, Status::NotIdentifiable);
    }

    /// Box means: a frame with a radial falloff applied, matched to itself shifted,
    /// gives rows whose log-ratios are the falloff's difference.
    #[test]
    fn pair_rows_read_the_falloff_of_a_flat_surface() {
        let (w, h) = (160, 120);
        let a = [-0.5f32, 0.0, 0.0];
        let make = |shift: f32| {
            let mut img = Rgb::new(w, h, [0.0; 3]);
            for y in 0..h {
                for x in 0..w {
                    let r = radius(w, h, x as f32 + 0.5 + shift, y as f32 + 0.5);
                    let lin = 0.3 * Vignetting::gain_at(a, r);
                    let e = crate::image::yuv::linear_to_srgb(lin);
                    for c in 0..3 {
                        img.channels[c][y * w + x] = e;
                    }
                }
            }
            img
        };
        // The surface is uniform; the "source" frame sees point p at p + 20 px.
        let (cur, src) = (make(0.0), make(0.0));
        let matches: Vec<_> = sample_points(w, h)
            .into_iter()
            .filter(|p| p[0] + 20.0 < w as f32 - 8.0)
            .map(|p| (p, [p[0] + 20.0, p[1]]))
            .collect();
        let rows = pair_rows(&cur, &src, &matches);
        assert!(rows.len() > 50, "{} rows", rows.len());
        for r in rows {
            let want = a[0] * r[0];
            assert!((r[P] - want).abs() < 0.02, "log ratio {} for {want}", r[P]);
        }
    }
}
