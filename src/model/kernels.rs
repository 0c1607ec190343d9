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

/// Smallest σ drawn as a disc (`DofKernel::Disc`). Below it the disc is under
/// 4 px across and the pixel lattice moves its second moment by up to 17% (measured
/// over radii 0.8–2); such a blur is the Gaussian of the same σ instead, which
/// differs from the disc only above ~0.3 cycles/px, where both have removed most of
/// the contrast. From σ = 1 px (radius 1.91) on the drawn disc's per-axis variance
/// is within 3.2% of σ² (within 1.1% from radius 3, 0.5% from radius 4).
pub const DISC_MIN_SIGMA_PX: f32 = 1.0;

/// Radius (px) of the uniform disc whose pixel-area-sampled kernel has per-axis
/// variance σ²: the continuous disc has R²/4, and integrating it over unit pixels
/// adds the box's 1/12, so R = 2·√(σ² − 1/12).
pub fn disc_radius_px(sigma_px: f32) -> f32 {
    2.0 * (sigma_px * sigma_px - 1.0 / 12.0).max(0.0).sqrt()
}

/// ∫₀ˣ √(R² − t²) dt for 0 ≤ x ≤ R (area under a quarter circle).
fn quarter_circle_integral(x: f32, r: f32) -> f32 {
    let x = x.clamp(0.0, r);
    0.5 * (x * (r * r - x * x).max(0.0).sqrt() + r * r * (x / r).clamp(-1.0, 1.0).asin())
}

/// Area of the disc of radius `r` (centred at the origin) inside [x0, x1]×[y0, y1],
/// first quadrant (0 ≤ x0 ≤ x1, 0 ≤ y0 ≤ y1). Closed form: full columns up to where
/// the circle leaves the top edge, then the circle's integral down to where it
/// leaves the bottom edge.
fn disc_area_quadrant(x0: f32, x1: f32, y0: f32, y1: f32, r: f32) -> f32 {
    if x0 * x0 + y0 * y0 >= r * r {
        return 0.0;
    }
    let xa = if y1 < r { (r * r - y1 * y1).sqrt() } else { 0.0 };
    let xb = (r * r - y0 * y0).max(0.0).sqrt();
    let full = (x1.min(xa) - x0).max(0.0) * (y1 - y0);
    let lo = xa.clamp(x0, x1);
    let hi = xb.clamp(x0, x1);
    full + (quarter_circle_integral(hi, r) - quarter_circle_integral(lo, r)) - y0 * (hi - lo)
}

/// Area of the disc of radius `r` inside the square cell of half-size `h` centred at
/// offset (dx, dy) px from the disc's centre. The cells tile the plane, so the areas
/// sum to πr² exactly: the kernel's mass is known without summing it (what a
/// scatter needs). Cells entirely inside (area 4h²) or outside (0) skip the
/// arithmetic.
pub fn disc_cell_area(dx: f32, dy: f32, h: f32, r: f32) -> f32 {
    let (ax, ay) = (dx.abs(), dy.abs());
    // Nearest and farthest points of the cell from the centre.
    let (nx, ny) = ((ax - h).max(0.0), (ay - h).max(0.0));
    if nx * nx + ny * ny >= r * r {
        return 0.0;
    }
    let (fx, fy) = (ax + h, ay + h);
    if fx * fx + fy * fy <= r * r {
        return 4.0 * h * h;
    }
    // By symmetry, a cell straddling an axis is twice its half on one side.
    let span = |a: f32| if a < h { (0.0, h - a, h + a) } else { (a - h, a + h, 0.0) };
    let (x0, x1, xs) = span(ax);
    let (y0, y1, ys) = span(ay);
    let mut area = 0.0;
    for (xl, xh) in [(x0, x1), (0.0, xs)] {
        for (yl, yh) in [(y0, y1), (0.0, ys)] {
            if xh > xl && yh > yl {
                area += disc_area_quadrant(xl, xh, yl, yh, r);
            }
        }
    }
    area
}

/// Weight of the disc kernel of std `sigma_px` at offset (dx, dy) for cells of
/// half-size `h` (0.5: pixels): cell area / πR², the disc's mass 1 exactly. Callers
/// take the Gaussian below `DISC_MIN_SIGMA_PX`.
pub fn disc_tap(dx: f32, dy: f32, h: f32, sigma_px: f32) -> f32 {
    let r = disc_radius_px(sigma_px);
    disc_cell_area(dx, dy, h, r) / (std::f32::consts::PI * r * r)
}

/// One-sided taps of the sharpening's blur as the renderer applies it
/// (`render::layer`, its twin `synth::layer::sharpen`): the discrete Gaussian of
/// variance σ² (`discrete_gaussian_kernel`), cut at `SHARPENING_TAPS` − 1 px and
/// renormalised so w₀ + 2·Σ wᵢ = 1 (the cut drops under 2·10⁻⁴ of the mass up to σ 4
/// px). Entry i is the weight of offsets ±i; the rest are 0.
pub fn sharpening_taps(sigma_px: f32) -> [f32; SHARPENING_TAPS] {
    let k = discrete_gaussian_kernel(sigma_px * sigma_px);
    let r = k.len() / 2;
    let mut w = [0.0f32; SHARPENING_TAPS];
    for (i, v) in w.iter_mut().enumerate().take(r.min(SHARPENING_TAPS - 1) + 1) {
        *v = k[r + i];
    }
    let sum = w[0] + 2.0 * w[1..].iter().sum::<f32>();
    if sum > 0.0 {
        for v in &mut w {
            *v /= sum;
        }
    }
    w
}

/// Taps of `sharpening_taps` (offsets 0..=15 px): what fits the pass's push block.
pub const SHARPENING_TAPS: usize = 16;

#[cfg(test)]
mod tests {
    use super::*;

    /// The disc kernel's mass is 1 and its per-axis variance σ² (lattice effect
    /// bounded as documented on `DISC_MIN_SIGMA_PX`), for pixels and for coarser
    /// cells (mass only: a cell of half-size h adds h²/3, not 1/12).
    #[test]
    fn disc_kernel_mass_and_second_moment() {
        for &sigma in &[1.0f32, 1.3, 2.0, 2.75, 4.0, 7.5, 10.0, 30.0] {
            let r = disc_radius_px(sigma).ceil() as i32 + 2;
            let (mut m, mut v) = (0.0f64, 0.0f64);
            for dy in -r..=r {
                for dx in -r..=r {
                    let w = disc_tap(dx as f32, dy as f32, 0.5, sigma) as f64;
                    m += w;
                    v += w * (dx * dx) as f64;
                }
            }
            // f32 closed forms: mass to 1e-4 relative.
            assert!((m - 1.0).abs() < 1e-4, "σ {sigma}: mass {m}");
            let rel = (v / m / (sigma * sigma) as f64 - 1.0).abs();
            let bound = if disc_radius_px(sigma) >= 4.0 { 0.006 } else { 0.033 };
            assert!(rel < bound, "σ {sigma}: variance off by {rel}");
            // Cells of 2 px: mass still 1.
            let m2: f64 = (-r..=r)
                .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
                .filter(|(dx, dy)| dx % 2 == 0 && dy % 2 == 0)
                .map(|(dx, dy)| disc_tap(dx as f32, dy as f32, 1.0, sigma) as f64)
                .sum();
            assert!((m2 - 1.0).abs() < 1e-4, "σ {sigma}: 2-px cells mass {m2}");
        }
    }

    /// A cell's area agrees with a 400×400 point count (tolerance: the count's
    /// discretisation, ≤ perimeter/400 per unit area ≈ 1%).
    #[test]
    fn disc_cell_area_matches_point_count() {
        for &(dx, dy, r) in
            &[(0.0f32, 0.0f32, 0.7f32), (3.0, 0.0, 3.2), (2.0, 2.0, 3.0), (0.0, 5.0, 5.3), (4.0, 1.0, 4.4)]
        {
            let n = 400;
            let mut inside = 0u32;
            for j in 0..n {
                for i in 0..n {
                    let x = dx - 0.5 + (i as f32 + 0.5) / n as f32;
                    let y = dy - 0.5 + (j as f32 + 0.5) / n as f32;
                    inside += (x * x + y * y <= r * r) as u32;
                }
            }
            let count = inside as f32 / (n * n) as f32;
            let a = disc_cell_area(dx, dy, 0.5, r);
            assert!((a - count).abs() < 0.01, "({dx}, {dy}) r {r}: area {a}, count {count}");
        }
    }
}
