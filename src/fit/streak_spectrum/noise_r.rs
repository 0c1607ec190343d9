//! White pixel noise's autocorrelation through the streak lines' bilinear sampling
//! (lags 0–2): what a line of pure noise shows, for the noise floor of
//! `streak_signature_with`.

/// Samples between those `interpolated_noise_correlation` reads.
pub(super) const NOISE_R_STRIDE: usize = 4;

/// Autocorrelation at lags 0, 1, 2 of unit white pixel noise read by bilinear
/// interpolation at x₀ + j·(dx, dy), j < n. Sample j weighs pixels by tents in x
/// and y; two samples share noise only through pixels both touch, so R(m) = mean
/// over j of ov_x·ov_y, the overlaps of their 1-D weights. Lines at whole pixels
/// (axis-aligned from an integer centre) have R = (1, 0, 0): white. An oblique
/// line's samples share pixels with their neighbours (at 10° R₁/R₀ ≈ 0.25) and
/// the noise it reads falls toward Nyquist — ~3× at 10° — which a flat floor took
/// for the tail of a texture or a streak's side lobe.
pub(super) fn interpolated_noise_correlation(x0: f32, y0: f32, dx: f32, dy: f32, n: usize) -> [f64; 3] {
    // A position's pixel (as a float) and offset into it. The line's positions are
    // ≥ 0 (it lies inside the frame) and far below 2⁵²: adding and removing 2⁵² rounds
    // to the nearest integer, one less where that lies above, which is the floor —
    // the truncation `as i64` took, exactly, in float operations that vectorise
    // (`floor` is a libm call on baseline x86-64, and the saturating integer
    // conversion does not vectorise).
    const TWO_52: f64 = 4_503_599_627_370_496.0;
    let split = |a: f64| -> (f64, f64) {
        let r = (a + TWO_52) - TWO_52;
        let i = if r > a { r - 1.0 } else { r };
        (i, a - i)
    };
    // Overlap of the 1-D bilinear weights at split positions a and b: every case
    // formed and the one the pixels' difference names selected (no branch).
    let ov = |(ia, ta): (f64, f64), (ib, tb): (f64, f64)| -> f64 {
        let d = ib - ia;
        let same = (1.0 - ta) * (1.0 - tb) + ta * tb;
        let next = ta * (1.0 - tb);
        let prev = (1.0 - ta) * tb;
        if d == 0.0 {
            same
        } else if d == 1.0 {
            next
        } else if d == -1.0 {
            prev
        } else {
            0.0
        }
    };
    let pos = |j: usize| (split(x0 as f64 + j as f64 * dx as f64), split(y0 as f64 + j as f64 * dy as f64));
    // Every `NOISE_R_STRIDE`-th sample j: the pixel phases sweep slowly along a
    // line, and all of them cost ~3 ms per frame at 1280×960. Lag m pairs sample j
    // with j + m. The terms of `CHUNK` such j are formed side by side (independent:
    // they vectorise), then each lag's sum takes its own, j < n − m, in increasing
    // j: the same terms added in the same order as one loop per lag would. (A
    // chunk's j past the line's end form terms from positions off the line, even
    // outside the frame: finite, and never added.)
    const CHUNK: usize = 8;
    let (mut sum, mut count) = ([0.0f64; 3], [0usize; 3]);
    for first in (0..n).step_by(NOISE_R_STRIDE * CHUNK) {
        let mut terms = [[0.0f64; CHUNK]; 3];
        for k in 0..CHUNK {
            let j = first + k * NOISE_R_STRIDE;
            let (xa, ya) = pos(j);
            let (x1, y1) = pos(j + 1);
            let (x2, y2) = pos(j + 2);
            terms[0][k] = ov(xa, xa) * ov(ya, ya);
            terms[1][k] = ov(xa, x1) * ov(ya, y1);
            terms[2][k] = ov(xa, x2) * ov(ya, y2);
        }
        for k in 0..CHUNK {
            let j = first + k * NOISE_R_STRIDE;
            for m in 0..3 {
                if j + m < n {
                    sum[m] += terms[m][k];
                    count[m] += 1;
                }
            }
        }
    }
    std::array::from_fn(|m| sum[m] / count[m].max(1) as f64)
}
