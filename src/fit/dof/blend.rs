//! The DoF stack's blend weight → variance map, corrected for the frame's own
//! spectrum: a blend of two stack nodes is not a Gaussian, and read as one it
//! overstates σ between the nodes.
//!
//! Between nodes S_k = H_{t_k} S and S_{k+1} (H_t: the discrete Gaussian of variance
//! t), the per-pixel search fits I ≈ (1 − w) S_k + w S_{k+1}. A mixture of two
//! Gaussian transfer functions lies above the Gaussian of the mixture's variance at
//! every frequency (e^{−ta} is convex in t), so the least-squares w of a frame
//! blurred by exactly H_t exceeds the variance-linear (t − t_k)/(t_{k+1} − t_k), and
//! σ read through the linear map comes out long: measured on the astronaut and
//! chelsea photographs blurred by exact discrete Gaussians, +0.03…+0.05 px between
//! the default 0.5 px nodes (0 on them): δ biased upward.
//!
//! The least-squares w of a frame blurred by H_t is, over the frame,
//! w*(t) = ⟨H_t S − S_k, S_{k+1} − S_k⟩ / |S_{k+1} − S_k|², and because discrete
//! Gaussians compose (H_a H_b = H_{a+b}, and are symmetric) every inner product is
//! one function of the summed variances: ⟨H_a S, H_b S⟩ = g(a + b). The stack the
//! fit builds anyway samples g at T = 2t_k (each node's energy) and t_k + t_{k+1}
//! (neighbours' product); g in between is interpolated (a cubic in ln T on ln g:
//! natural images' power-law spectra make ln g nearly linear in ln T; checked on
//! 1/ρ² and 1/ρ³ spectra, w* within 0.004 of the exact value). The map is exact at
//! the nodes by construction (w*(t_k) = 0, w*(t_{k+1}) = 1 use sampled T only).

/// Table points per stack interval (w* is smooth and monotone in t).
const TABLE: usize = 16;

/// Samples (T, g(T)) of g(T) = ⟨S − m, H_T (S − m)⟩ per pixel, T increasing. The
/// fit sums them over its samples' patches: the identity g(a + b) = ⟨H_a S, H_b S⟩
/// is exact over a whole plane (Parseval) and holds in expectation over a subset.
#[derive(Default)]
pub(super) struct Gram {
    pts: Vec<(f64, f64)>,
}

impl Gram {
    /// The sample at T (full-resolution px²), after every smaller T.
    pub(super) fn push(&mut self, t: f32, g: f64) {
        self.pts.push((t as f64, g));
    }

    /// g(T) by Lagrange interpolation of ln g through the (up to) four samples
    /// nearest T — in ln T where all of them and T are positive, else in T. `None`
    /// where a sample is not positive (a constant frame) or too few exist.
    fn at(&self, t: f64) -> Option<f64> {
        let n = self.pts.len();
        if n < 2 || self.pts.iter().any(|p| !(p.1 > 0.0 && p.1.is_finite())) {
            return None;
        }
        let k = n.min(4);
        let i = self.pts.partition_point(|p| p.0 < t);
        let start = i.saturating_sub(k / 2).min(n - k);
        let win = &self.pts[start..start + k];
        let log_x = t > 0.0 && win.iter().all(|p| p.0 > 0.0);
        let x = |v: f64| if log_x { v.ln() } else { v };
        let xq = x(t);
        let mut y = 0.0;
        for (a, pa) in win.iter().enumerate() {
            let mut l = 1.0;
            for (b, pb) in win.iter().enumerate() {
                if a != b {
                    let d = x(pa.0) - x(pb.0);
                    if d == 0.0 {
                        return None;
                    }
                    l *= (xq - x(pb.0)) / d;
                }
            }
            y += l * pa.1.ln();
        }
        let g = y.exp();
        g.is_finite().then_some(g)
    }
}

/// One stack interval's map between the blend weight w and the variance t it
/// reads: w at `TABLE` + 1 variances evenly spaced over [t0, t1], nondecreasing
/// from 0 to 1 (the variance-linear map where the frame gives no usable spectrum).
pub(super) struct BlendMap {
    t0: f32,
    t1: f32,
    w: [f32; TABLE + 1],
}

impl BlendMap {
    pub(super) fn new(gram: &Gram, t0: f32, t1: f32) -> Self {
        let linear = Self { t0, t1, w: std::array::from_fn(|i| i as f32 / TABLE as f32) };
        let (a, b) = (t0 as f64, t1 as f64);
        let g = |t: f64| gram.at(t);
        let (Some(g_aa), Some(g_ab), Some(g_bb)) = (g(2.0 * a), g(a + b), g(2.0 * b)) else { return linear };
        let den = g_bb - 2.0 * g_ab + g_aa;
        if !(den > 0.0 && den.is_finite()) || b <= a {
            return linear;
        }
        let mut w = [0.0f32; TABLE + 1];
        for (i, wi) in w.iter_mut().enumerate().take(TABLE).skip(1) {
            let t = a + (b - a) * i as f64 / TABLE as f64;
            let (Some(gb), Some(ga)) = (g(t + b), g(t + a)) else { return linear };
            let v = (gb - ga - g_ab + g_aa) / den;
            if !v.is_finite() {
                return linear;
            }
            *wi = v as f32;
        }
        w[TABLE] = 1.0;
        // Monotone and inside [0, 1] whatever the interpolation did.
        let mut run = 0.0f32;
        for wi in w.iter_mut() {
            run = run.max(wi.clamp(0.0, 1.0));
            *wi = run;
        }
        Self { t0, t1, w }
    }

    /// The variance a blend weight `wgt` ∈ [0, 1] reads.
    pub(super) fn variance(&self, wgt: f32) -> f32 {
        let wgt = wgt.clamp(0.0, 1.0);
        let i = self.w.partition_point(|&v| v < wgt).clamp(1, TABLE);
        let (lo, hi) = (self.w[i - 1], self.w[i]);
        let f = if hi > lo { (wgt - lo) / (hi - lo) } else { 0.0 };
        self.t0 + (self.t1 - self.t0) * ((i - 1) as f32 + f) / TABLE as f32
    }

    /// The blend weight that reads variance `t` (clamped into the interval).
    pub(super) fn weight(&self, t: f32) -> f32 {
        if self.t1 <= self.t0 {
            return 0.0;
        }
        let u = ((t - self.t0) / (self.t1 - self.t0)).clamp(0.0, 1.0) * TABLE as f32;
        let i = (u.floor() as usize).min(TABLE - 1);
        let f = u - i as f32;
        self.w[i] + f * (self.w[i + 1] - self.w[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{blur_separable, discrete_gaussian_kernel, Plane};

    fn test_plane() -> Plane {
        // A deterministic texture with a power-law-ish spectrum: sums of sines.
        let (w, h) = (96, 80);
        let mut d = vec![0.0f32; w * h];
        for (k, f) in [0.05f32, 0.11, 0.23, 0.41, 0.73, 1.3, 2.1, 2.9].iter().enumerate() {
            let amp = 1.0 / (1.0 + k as f32);
            for y in 0..h {
                for x in 0..w {
                    d[y * w + x] += amp * (f * x as f32 + 0.7 * f * y as f32 + k as f32).sin();
                }
            }
        }
        Plane::from_vec(w, h, d)
    }

    /// The map is the variance-linear one's inverse where no spectrum is known,
    /// `variance` and `weight` are inverses, and the ends are the nodes.
    #[test]
    fn map_ends_and_inverse() {
        let flat = Gram::default();
        let m = BlendMap::new(&flat, 1.0, 2.25);
        assert_eq!(m.variance(0.0), 1.0);
        assert_eq!(m.variance(1.0), 2.25);
        assert!((m.variance(0.5) - 1.625).abs() < 1e-6);
        let p = test_plane();
        let m = p.data.iter().map(|&v| v as f64).sum::<f64>() / p.data.len() as f64;
        let dot = |a: &Plane, b: &Plane| {
            a.data.iter().zip(&b.data).map(|(&x, &y)| (x as f64 - m) * (y as f64 - m)).sum::<f64>()
                / a.data.len() as f64
        };
        let mut g = Gram::default();
        let nodes = [0.0f32, 0.5, 1.0, 1.5, 2.0];
        let mut prev = p.clone();
        g.push(0.0, dot(&prev, &prev));
        for k in 0..4 {
            let next = blur_separable(&prev, &discrete_gaussian_kernel(nodes[k + 1].powi(2) - nodes[k].powi(2)));
            g.push(nodes[k].powi(2) + nodes[k + 1].powi(2), dot(&prev, &next));
            g.push(2.0 * nodes[k + 1].powi(2), dot(&next, &next));
            prev = next;
        }
        let m = BlendMap::new(&g, 1.0, 2.25);
        assert_eq!(m.variance(0.0), 1.0);
        assert_eq!(m.variance(1.0), 2.25);
        for t in [1.1f32, 1.4, 1.8, 2.2] {
            let back = m.variance(m.weight(t));
            assert!((back - t).abs() < 1e-4, "{t} → {back}");
            // A blend of two Gaussians carries more high frequency than the
            // Gaussian of its variance: the matching weight exceeds the linear one.
            assert!(m.weight(t) > (t - 1.0) / 1.25, "{t}: {}", m.weight(t));
        }
    }
}
