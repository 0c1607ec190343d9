//! Kernels that define the effects on the pixel grid, shared by the CPU reference
//! (`synth`) and the GPU passes (`render`): Lindeberg's discrete Gaussian
//! T(n; t) = e^{-t} I_n(t), the meaning of "a blur of variance t px²" here.

/// Kernel taps for variance `variance_px2` (σ² in px²), centred, odd length,
/// truncated where the tail mass is below ~1e-6 and renormalised to sum 1.
pub fn discrete_gaussian_kernel(variance_px2: f32) -> Vec<f32> {
    let t = variance_px2.max(0.0) as f64;
    if t < 1e-12 {
        return vec![1.0];
    }
    // Radius 5σ + 2: the two-sided tail beyond it is below 1e-6, so the truncated,
    // renormalised kernel keeps its variance to ~1e-5 relative.
    let r = (5.0 * t.sqrt() + 2.0).ceil() as usize;
    // Miller's backward recurrence for I_n(t): I_{n-1} = (2n/t) I_n + I_{n+1}, started
    // well above r so the start values' error has decayed; normalising the kernel to
    // sum 1 fixes the unknown scale (Σ_n e^{-t} I_n(t) = 1 over all n).
    let start = r + 20 + (2.0 * t).ceil() as usize;
    let mut vals = vec![0.0f64; start + 2];
    vals[start] = 1e-300;
    for n in (1..=start).rev() {
        vals[n - 1] = (2.0 * n as f64 / t) * vals[n] + vals[n + 1];
        if vals[n - 1] > 1e250 {
            // Rescale to stay inside f64 range; only ratios matter.
            for v in vals.iter_mut().skip(n - 1) {
                *v *= 1e-250;
            }
        }
    }
    let mut k: Vec<f64> = (0..=2 * r).map(|i| vals[(i as isize - r as isize).unsigned_abs()]).collect();
    let s: f64 = k.iter().sum();
    for v in &mut k {
        *v /= s;
    }
    k.into_iter().map(|v| v as f32).collect()
}
