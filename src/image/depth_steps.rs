//! Pixels near a depth discontinuity: where a depth-reprojected image is not to be
//! trusted (parallax, disocclusion, and blur that straddles the step).

use super::Plane;

/// Clear `mask` on the rows `row` accepts within `reach` px (Chebyshev) of a depth
/// discontinuity of `depth`: a relative step of more than `step` between
/// 4-neighbours (non-finite depths are no step). Separable box dilation by running
/// counts over only the rows within `reach` of an accepted one: O(those pixels).
/// A mask of another size than `depth` is left as it is.
pub fn clear_near_depth_steps(mask: &mut Plane, depth: &Plane, reach: usize, step: f32, row: &dyn Fn(usize) -> bool) {
    let (w, h) = (depth.width, depth.height);
    if (mask.width, mask.height) != (w, h) {
        return;
    }
    let z = &depth.data;
    let is_step = |a: f32, b: f32| a.is_finite() && b.is_finite() && (a - b).abs() > step * a.min(b);
    // Only rows within `reach` of an accepted row are read (a sixth of 1280×960 in
    // the fast tier's sparse reference: every row's steps cost 2.3 ms per update).
    let needed: Vec<bool> = (0..h).map(|y| (y.saturating_sub(reach)..(y + reach + 1).min(h)).any(row)).collect();
    // Steps dilated along rows: `near_x[i]` counts the steps within `reach` in the row.
    let mut near_x = vec![0u32; w * h];
    let mut steps = vec![0u32; w + 1];
    for y in (0..h).filter(|&y| needed[y]) {
        for x in 0..w {
            let i = y * w + x;
            let e = (x + 1 < w && is_step(z[i], z[i + 1]))
                || (x > 0 && is_step(z[i], z[i - 1]))
                || (y + 1 < h && is_step(z[i], z[i + w]))
                || (y > 0 && is_step(z[i], z[i - w]));
            steps[x + 1] = steps[x] + u32::from(e);
        }
        for x in 0..w {
            let (lo, hi) = (x.saturating_sub(reach), (x + reach + 1).min(w));
            near_x[y * w + x] = steps[hi] - steps[lo];
        }
    }
    for y in (0..h).filter(|&y| row(y)) {
        let (lo, hi) = (y.saturating_sub(reach), (y + reach + 1).min(h));
        for x in 0..w {
            if (lo..hi).any(|yy| near_x[yy * w + x] > 0) {
                mask.data[y * w + x] = 0.0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A depth step clears the mask within `reach` px of it, on the accepted rows
    /// only, and nothing else; a 1%-per-row depth ramp is no step.
    #[test]
    fn depth_steps_clear_the_mask_around_them() {
        let (w, h) = (40usize, 30usize);
        // Two planes, 2 m and 3 m, split between x = 19 and 20, each ramping 1% per row.
        let z: Vec<f32> =
            (0..w * h).map(|i| (if i % w < 20 { 2.0 } else { 3.0 }) * (1.0 + 0.01 * (i / w) as f32)).collect();
        let depth = Plane::from_vec(w, h, z);
        let every_third = |y: usize| y % 3 == 1;
        for row in [&(|_| true) as &dyn Fn(usize) -> bool, &every_third] {
            let mut mask = Plane::new(w, h, 1.0);
            clear_near_depth_steps(&mut mask, &depth, 3, 0.03, row);
            for y in 0..h {
                for x in 0..w {
                    // Step pixels x = 19, 20; within 3 px: 16..=23.
                    let cleared = row(y) && (16..=23).contains(&x);
                    assert_eq!(mask.data[y * w + x] == 0.0, cleared, "({x}, {y})");
                }
            }
        }
    }
}
