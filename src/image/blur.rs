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
    if kernel.len() <= 1 {
        return p.clone();
    }
    let (w, h) = (p.width, p.height);
    let r = kernel.len() / 2;
    let mut tmp = vec![0.0f32; w * h];
    let mut padded = vec![0.0f32; w + 2 * r];
    for y in 0..h {
        let row = &p.data[y * w..(y + 1) * w];
        for (i, v) in padded.iter_mut().enumerate() {
            *v = row[(i as isize - r as isize).clamp(0, w as isize - 1) as usize];
        }
        let out = &mut tmp[y * w..(y + 1) * w];
        for (k, &wk) in kernel.iter().enumerate() {
            for (o, &v) in out.iter_mut().zip(&padded[k..k + w]) {
                *o += wk * v;
            }
        }
    }
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        let o = &mut out[y * w..(y + 1) * w];
        for (k, &wk) in kernel.iter().enumerate() {
            let yi = (y as isize + k as isize - r as isize).clamp(0, h as isize - 1) as usize;
            for (ov, &sv) in o.iter_mut().zip(&tmp[yi * w..(yi + 1) * w]) {
                *ov += wk * sv;
            }
        }
    }
    Plane::from_vec(w, h, out)
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
}
