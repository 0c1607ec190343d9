//! Separable blurs with Lindeberg's discrete Gaussian kernel T(n; t) = e^{-t} I_n(t).
//!
//! Why not a sampled Gaussian: a sampled, renormalised Gaussian of std 0.25 px has a
//! variance of ~7e-4 px² instead of 0.0625 px², so small blurs would vanish and a
//! cascade of them would not add up. The discrete Gaussian has *exactly* variance t
//! for every t ≥ 0, is the identity at t = 0, and obeys the semigroup law
//! T(t1) * T(t2) = T(t1 + t2), so blurring in increments is exact (Lindeberg 1990).

use super::Plane;

pub use crate::model::kernels::discrete_gaussian_kernel;

/// Convolve rows then columns with the same centred kernel, clamp-to-edge.
///
/// Both passes accumulate one tap at a time over a contiguous row
/// (`out[x] += w_k · src[x + k]`), which the compiler vectorises; a per-pixel dot
/// product would be a float reduction it may not reorder.
pub fn blur_separable(p: &Plane, kernel: &[f32]) -> Plane {
    blur_separable_rows(p, kernel, &|_| true)
}

/// `blur_separable` on the rows where `row(y)` only (the others are 0): the
/// horizontal pass runs on those rows and the kernel's reach around them, so a fit
/// that reads a few bands of a frame pays for those bands (the fast tier's
/// motion-blur reference, `analysis::temporal::align_bands`).
pub fn blur_separable_rows(p: &Plane, kernel: &[f32], row: &dyn Fn(usize) -> bool) -> Plane {
    let (w, h) = (p.width, p.height);
    if kernel.len() <= 1 {
        let mut out = p.clone();
        for y in (0..h).filter(|&y| !row(y)) {
            out.data[y * w..(y + 1) * w].fill(0.0);
        }
        return out;
    }
    let r = kernel.len() / 2;
    let wanted: Vec<bool> = (0..h).map(row).collect();
    // Rows the vertical pass reads: within r of a wanted row (clamped at the edges).
    let mut reach = vec![false; h];
    for y in (0..h).filter(|&y| wanted[y]) {
        for k in 0..kernel.len() {
            reach[(y as isize + k as isize - r as isize).clamp(0, h as isize - 1) as usize] = true;
        }
    }
    let tmp = blur_x_rows(p, kernel, &reach);
    // Grown row by row (each row zeroed while in cache, then written), not zeroed
    // whole first: a frame-size memset ahead of the writes was ~3% of the blind
    // fit's instructions over its blurs.
    let mut out = Vec::with_capacity(w * h);
    let mut src: Vec<&[f32]> = Vec::with_capacity(kernel.len());
    for y in 0..h {
        out.resize((y + 1) * w, 0.0);
        if !wanted[y] {
            continue;
        }
        src.clear();
        src.extend((0..kernel.len()).map(|k| {
            let yi = (y as isize + k as isize - r as isize).clamp(0, h as isize - 1) as usize;
            &tmp[yi * w..(yi + 1) * w]
        }));
        taps_into(&mut out[y * w..(y + 1) * w], kernel, |k, x| &src[k][x..]);
    }
    Plane::from_vec(w, h, out)
}

/// `out[x] = Σ_k kernel[k] · tap(k, x0)[x − x0]`, summed from 0 in tap order (so
/// the same value as adding one tap's product at a time into a zeroed row), over
/// blocks of `LANES` outputs held in registers through all the taps: the row is
/// written once instead of loaded and stored once per tap (`tap(k, x0)` is the
/// k-th source row from column x0 on).
///
/// 32 lanes: four AVX2 vectors, four independent chains of additions. With 16
/// (two chains) each tap's addition waited on the previous one's (~3 cycles a tap):
/// the blind DoF fit's re-blur of the 640×480 half frame (21 taps) took 0.70 ms,
/// 0.60 with 32 or 64 lanes (24 runs each); 32 leaves SSE2's 16
/// registers room (8 accumulators), NEON's 32 as well.
#[inline]
fn taps_into<'a>(out: &mut [f32], kernel: &[f32], tap: impl Fn(usize, usize) -> &'a [f32]) {
    const LANES: usize = 32;
    let mut x0 = 0;
    let w = out.len();
    while x0 + LANES <= w {
        let mut acc = [0.0f32; LANES];
        for (k, &wk) in kernel.iter().enumerate() {
            let s = &tap(k, x0)[..LANES];
            for (a, &v) in acc.iter_mut().zip(s) {
                *a += wk * v;
            }
        }
        out[x0..x0 + LANES].copy_from_slice(&acc);
        x0 += LANES;
    }
    if x0 < w {
        let n = w - x0;
        let mut acc = [0.0f32; LANES];
        for (k, &wk) in kernel.iter().enumerate() {
            let s = &tap(k, x0)[..n];
            for (a, &v) in acc.iter_mut().zip(s) {
                *a += wk * v;
            }
        }
        out[x0..].copy_from_slice(&acc[..n]);
    }
}

/// The horizontal pass alone (clamp-to-edge): an anisotropic blur is this with one
/// kernel after `blur_separable` with another.
pub fn blur_x(p: &Plane, kernel: &[f32]) -> Plane {
    Plane::from_vec(p.width, p.height, blur_x_rows(p, kernel, &vec![true; p.height]))
}

/// The horizontal pass on the rows where `rows[y]` (the others 0), over a padded
/// row (`taps_into`).
fn blur_x_rows(p: &Plane, kernel: &[f32], rows: &[bool]) -> Vec<f32> {
    let (w, h) = (p.width, p.height);
    let r = kernel.len() / 2;
    if w == 0 {
        return vec![];
    }
    // Grown row by row (as `blur_separable_rows`' output).
    let mut tmp = Vec::with_capacity(w * h);
    let mut padded = vec![0.0f32; w + 2 * r];
    for y in 0..h {
        tmp.resize((y + 1) * w, 0.0);
        if !rows[y] {
            continue;
        }
        let row = &p.data[y * w..(y + 1) * w];
        // Clamp-to-edge padding: the row itself, its end values repeated r times.
        padded[..r].fill(row[0]);
        padded[r..r + w].copy_from_slice(row);
        padded[r + w..].fill(row[w - 1]);
        let padded = &padded[..];
        taps_into(&mut tmp[y * w..(y + 1) * w], kernel, |k, x| &padded[k + x..]);
    }
    tmp
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moments(k: &[f32]) -> (f64, f64) {
        let r = (k.len() / 2) as f64;
        let sum: f64 = k.iter().map(|&v| v as f64).sum();
        let var: f64 = k.iter().enumerate().map(|(i, &v)| v as f64 * (i as f64 - r).powi(2)).sum();
        (sum, var)
    }

    /// Variance must equal t to 1e-5 relative (f32 taps): this is what makes the
    /// DoF cascade exact.
    #[test]
    fn discrete_gaussian_has_exact_variance() {
        for &t in &[0.0625f32, 0.25, 1.0, 4.0, 25.0, 100.0] {
            let (sum, var) = moments(&discrete_gaussian_kernel(t));
            assert!((sum - 1.0).abs() < 1e-5, "t={t} sum={sum}");
            assert!((var - t as f64).abs() < 1e-4 * t as f64 + 1e-6, "t={t} var={var}");
        }
        assert_eq!(discrete_gaussian_kernel(0.0), vec![1.0]);
    }

    /// Semigroup: T(a) * T(b) = T(a + b) tap by tap, to 1e-6 absolute.
    #[test]
    fn discrete_gaussian_semigroup() {
        let a = discrete_gaussian_kernel(0.7);
        let b = discrete_gaussian_kernel(2.3);
        let c = discrete_gaussian_kernel(3.0);
        let mut conv = vec![0.0f32; a.len() + b.len() - 1];
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                conv[i + j] += x * y;
            }
        }
        let off = (conv.len() - c.len()) / 2;
        for (i, v) in c.iter().enumerate() {
            assert!((conv[i + off] - v).abs() < 1e-6);
        }
    }

    /// The separable blur is the clamp-to-edge convolution summed tap by tap in
    /// order from 0 (rows, then columns), bit for bit, for sizes below, at and
    /// between multiples of `taps_into`'s lane count, with an odd and a long kernel.
    #[test]
    fn blur_is_the_in_order_tap_sum() {
        let naive = |p: &Plane, k: &[f32]| -> Plane {
            let (w, h, r) = (p.width as isize, p.height as isize, (k.len() / 2) as isize);
            let at = |x: isize, y: isize, q: &[f32]| q[(y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize];
            let mut tmp = vec![0.0f32; p.data.len()];
            for y in 0..h {
                for x in 0..w {
                    let mut a = 0.0f32;
                    for (i, &wk) in k.iter().enumerate() {
                        a += wk * at(x + i as isize - r, y, &p.data);
                    }
                    tmp[(y * w + x) as usize] = a;
                }
            }
            let mut out = vec![0.0f32; p.data.len()];
            for y in 0..h {
                for x in 0..w {
                    let mut a = 0.0f32;
                    for (i, &wk) in k.iter().enumerate() {
                        a += wk * at(x, y + i as isize - r, &tmp);
                    }
                    out[(y * w + x) as usize] = a;
                }
            }
            Plane::from_vec(p.width, p.height, out)
        };
        for (w, h) in [(1, 3), (15, 4), (32, 5), (33, 7), (70, 6), (129, 3)] {
            let p = Plane::from_vec(w, h, (0..w * h).map(|i| ((i * 7919) % 101) as f32 / 100.0 - 0.3).collect());
            for t in [0.5f32, 2.0, 9.0] {
                let k = discrete_gaussian_kernel(t);
                let (got, want) = (blur_separable(&p, &k), naive(&p, &k));
                let bits = |q: &Plane| q.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "{w}×{h}, t {t}");
            }
        }
    }

    /// The row-restricted blur equals the full blur on its rows (bit for bit: the
    /// same taps in the same order) and is 0 elsewhere, edges included.
    #[test]
    fn row_restricted_blur_matches_the_full_blur_on_its_rows() {
        let (w, h) = (37, 53);
        let p = Plane::from_vec(w, h, (0..w * h).map(|i| ((i * 7919) % 101) as f32 / 100.0).collect());
        let k = discrete_gaussian_kernel(2.0);
        let full = blur_separable(&p, &k);
        let pick = |y: usize| (y / 8) % 3 == 1 || y == 0 || y == h - 1;
        let part = blur_separable_rows(&p, &k, &pick);
        for y in 0..h {
            for x in 0..w {
                let want = if pick(y) { full.get(x, y) } else { 0.0 };
                assert_eq!(part.get(x, y), want, "({x}, {y})");
            }
        }
    }
}
