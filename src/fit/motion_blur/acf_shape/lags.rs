//! The shape's lag sums: the crop's derivative autocorrelations along and across the
//! flow by one 2-D FFT, white pixel noise's covariance through the crop's bilinear
//! sampling, and the candidate box's own autocorrelation (`super::read` combines them).

use super::{MAX_LAG_PX, MAX_LENGTH_PX};
use crate::image::Plane;
use rustfft::num_complex::Complex32;
use rustfft::FftPlanner;

/// Immerkær's white-noise σ on the frame's pixels (every eighth row triple: an
/// estimate, at an eighth of the pass): the mean |Laplacian difference| · √(π/2)/6.
pub(super) fn immerkaer_sigma(p: &Plane) -> f64 {
    let (w, h) = (p.width, p.height);
    let (mut sum, mut count) = (0.0f64, 0usize);
    // A row's |differences| first, over zipped slices (they vectorise), then summed
    // in order: the serial f64 sum is the estimate's definition, and computed inside
    // it the differences (indexed, bounds-checked) doubled its time.
    let mut row_abs = vec![0.0f32; w.saturating_sub(2)];
    for y in (1..h - 1).step_by(8) {
        let (a, b, c) = (&p.data[(y - 1) * w..y * w], &p.data[y * w..(y + 1) * w], &p.data[(y + 1) * w..(y + 2) * w]);
        for (o, ((ta, tb), tc)) in row_abs.iter_mut().zip(a.windows(3).zip(b.windows(3)).zip(c.windows(3))) {
            let v = ta[0] - 2.0 * ta[1] + ta[2] - 2.0 * (tb[0] - 2.0 * tb[1] + tb[2]) + tc[0] - 2.0 * tc[1] + tc[2];
            *o = v.abs();
        }
        for &v in &row_abs {
            sum += v as f64;
        }
        count += w - 2;
    }
    if count == 0 {
        return 0.0;
    }
    (std::f64::consts::FRAC_PI_2).sqrt() / 6.0 * sum / count as f64
}

/// Unit white pixel noise's covariance between crop samples (t, s) apart (along u,
/// across), averaged over the crop: bilinear sampling mixes up to four pixels per
/// sample, so at an oblique flow the crop's noise is correlated (an axis-aligned
/// crop: 1 at (0, 0), 0 elsewhere).
pub(super) struct NoiseTable {
    cov: [[f64; 2 * NoiseTable::SPAN as usize + 1]; 2 * NoiseTable::SPAN as usize + 1],
}

impl NoiseTable {
    /// Offsets with a covariance: two bilinear footprints overlap within 2 px.
    pub(super) const SPAN: isize = 2;
    /// Lags of the differences' covariance that can be non-zero.
    pub(super) const REACH: isize = NoiseTable::SPAN + 1;

    pub(super) fn new(origin: (f32, f32), u: (f32, f32), size: (usize, usize)) -> Self {
        let v = (-u.1, u.0);
        let taps = |x: f32, y: f32| -> [((i64, i64), f64); 4] {
            let (xf, yf) = (x.floor(), y.floor());
            let (fx, fy) = ((x - xf) as f64, (y - yf) as f64);
            let (xi, yi) = (xf as i64, yf as i64);
            [
                ((xi, yi), (1.0 - fx) * (1.0 - fy)),
                ((xi + 1, yi), fx * (1.0 - fy)),
                ((xi, yi + 1), (1.0 - fx) * fy),
                ((xi + 1, yi + 1), fx * fy),
            ]
        };
        let n = 2 * Self::SPAN as usize + 1;
        let mut cov = [[0.0f64; 2 * Self::SPAN as usize + 1]; 2 * Self::SPAN as usize + 1];
        // A 16×16 grid of crop positions: the fractional phases a rotation visits.
        let mut count = 0usize;
        for gj in 0..16 {
            for gi in 0..16 {
                let (i, j) = ((gi * size.0 / 16) as f32, (gj * size.1 / 16) as f32);
                let p = taps(origin.0 + i * u.0 + j * v.0, origin.1 + i * u.1 + j * v.1);
                for (ti, row) in cov.iter_mut().enumerate() {
                    for (si, c) in row.iter_mut().enumerate() {
                        let (t, s) = (ti as f32 - Self::SPAN as f32, si as f32 - Self::SPAN as f32);
                        let (ii, jj) = (i + t, j + s);
                        let q = taps(origin.0 + ii * u.0 + jj * v.0, origin.1 + ii * u.1 + jj * v.1);
                        for (pp, wp) in p {
                            for (qq, wq) in q {
                                if pp == qq {
                                    *c += wp * wq;
                                }
                            }
                        }
                    }
                }
                count += 1;
            }
        }
        for row in cov.iter_mut().take(n) {
            for c in row.iter_mut() {
                *c /= count as f64;
            }
        }
        Self { cov }
    }

    fn at(&self, t: isize, s: isize) -> f64 {
        if t.abs() > Self::SPAN || s.abs() > Self::SPAN {
            return 0.0;
        }
        self.cov[(t + Self::SPAN) as usize][(s + Self::SPAN) as usize]
    }

    /// Covariance of du at lag (t along u, s across).
    pub(super) fn du(&self, t: isize, s: isize) -> f64 {
        2.0 * self.at(t, s) - self.at(t + 1, s) - self.at(t - 1, s)
    }

    /// Covariance of dv at lag t along v.
    pub(super) fn dv(&self, t: isize) -> f64 {
        2.0 * self.at(0, t) - self.at(0, t + 1) - self.at(0, t - 1)
    }
}

/// A box of `length` px (fractional ends: the outer taps carry the fraction), odd
/// length, unit sum — as OpenCV's `motion_kernel` and the probe draw it.
pub(super) fn box_kernel(length: f64) -> Vec<f64> {
    if length < 1.0 {
        return vec![1.0];
    }
    let mut n = length.ceil() as usize;
    n += usize::from(n % 2 == 0);
    let mut k = vec![1.0; n];
    let cut = (n as f64 - length) / 2.0;
    k[0] -= cut;
    k[n - 1] -= cut;
    let sum: f64 = k.iter().sum();
    k.iter().map(|v| v / sum).collect()
}

/// r(s) = Σ_j k_j k_{j+s}, s = −(n−1)…n−1 (index s + n − 1).
pub(super) fn kernel_autocorrelation(k: &[f64]) -> Vec<f64> {
    let n = k.len();
    (0..2 * n - 1)
        .map(|i| {
            let s = i as isize - (n as isize - 1);
            (0..n)
                .filter_map(|j| {
                    let jj = j as isize + s;
                    (jj >= 0 && (jj as usize) < n).then(|| k[j] * k[jj as usize])
                })
                .sum()
        })
        .collect()
}

/// Index offset of lag 0 in `autocorrelations`' second result.
pub(super) const AV_OFFSET: usize = MAX_LAG_PX + MAX_LENGTH_PX;

/// A_u(t, s), t = 0…`MAX_LAG_PX`, s = −`MAX_LENGTH_PX`…`MAX_LENGTH_PX`, raw sums.
pub(super) struct LagTable {
    data: Vec<f64>,
}

impl LagTable {
    pub(super) const ROW: usize = 2 * MAX_LENGTH_PX + 1;
    /// A_u(t, s) for s = −`MAX_LENGTH_PX`…`MAX_LENGTH_PX` (index s + `MAX_LENGTH_PX`).
    pub(super) fn row(&self, t: usize) -> &[f64] {
        &self.data[t * Self::ROW..(t + 1) * Self::ROW]
    }
}

/// The smallest m ≥ n of the form 2^a·3^b·5^c (fast FFT sizes).
pub(super) fn fft_size(n: usize) -> usize {
    (n..)
        .find(|&m| {
            let mut r = m;
            for p in [2, 3, 5] {
                while r % p == 0 {
                    r /= p;
                }
            }
            r == 1
        })
        .unwrap_or(n)
}

/// The raw autocorrelation sums of du (along u at lags 0…`MAX_LAG_PX`, across at
/// ±`MAX_LENGTH_PX`) and of dv along v (lags ±`AV_OFFSET`, index + `AV_OFFSET`), by
/// one zero-padded 2-D FFT of du + i·dv (two real transforms in one complex one).
pub(super) fn autocorrelations(
    crop: &[f32],
    cw: usize,
    ch: usize,
    max_lag: usize,
    l_max: usize,
) -> (LagTable, Vec<f64>) {
    let (a, b) = (cw - 1, ch - 1);
    // Zero padding wide enough that no lag read wraps around: u lags to `max_lag`,
    // v lags to `max_lag` + the box's reach `l_max` (entries past those are read
    // by no candidate).
    let nu = fft_size(a + max_lag + 1);
    let nv = fft_size(b + max_lag + l_max + 1);
    let mut planner = FftPlanner::<f32>::new();
    let (fu, fv) = (planner.plan_fft_forward(nu), planner.plan_fft_forward(nv));
    let (iu, iv) = (planner.plan_fft_inverse(nu), planner.plan_fft_inverse(nv));
    let zero = Complex32::new(0.0, 0.0);
    // One scratch for every transform; each `process_with_scratch` call transforms
    // every row of its buffer (rustfft's batching).
    let scratch_len = [&fu, &fv, &iu, &iv].iter().map(|f| f.get_inplace_scratch_len()).max().unwrap_or(0);
    let mut scratch = vec![zero; scratch_len];
    // The b data rows along u (the padding rows are zero and stay zero), `BLOCK` at
    // a time: transformed, then written transposed (rows: u frequency, along v) so
    // that the v transforms run on contiguous rows (a strided column gather cost
    // more than the FFTs, `defocus_spectrum::fft2`) — one frame-sized buffer, not two.
    const BLOCK: usize = 16;
    let mut zt = vec![zero; nu * nv];
    let mut rows = vec![zero; BLOCK * nu];
    for y0 in (0..b).step_by(BLOCK) {
        let n = BLOCK.min(b - y0);
        let block = &mut rows[..n * nu];
        for (j, row) in block.chunks_exact_mut(nu).enumerate() {
            let y = y0 + j;
            let (r0, r1) = (&crop[y * cw..(y + 1) * cw], &crop[(y + 1) * cw..(y + 2) * cw]);
            for x in 0..a {
                row[x] = Complex32::new(r0[x + 1] - r0[x], r1[x] - r0[x]);
            }
            row[a..].fill(zero);
        }
        fu.process_with_scratch(block, &mut scratch);
        for bx in (0..nu).step_by(BLOCK) {
            for j in 0..n {
                for x in bx..(bx + BLOCK).min(nu) {
                    zt[x * nv + y0 + j] = block[j * nu + x];
                }
            }
        }
    }
    drop(rows);
    fv.process_with_scratch(&mut zt, &mut scratch);
    // Split the two spectra in place, each pair k, −k once: Du(k) = (Z(k) + Z*(−k))/2,
    // Dv(k) = (Z(k) − Z*(−k))/(2i); |Du|² stays (as a real number) for the inverse,
    // |Dv|² is summed over the u frequencies (`pv_marginal`).
    let mut pv_marginal = vec![0.0f64; nv];
    for ku in 0..nu {
        let mu = (nu - ku) % nu;
        for kv in 0..nv {
            let mv = (nv - kv) % nv;
            let (i, m) = (ku * nv + kv, mu * nv + mv);
            if i > m {
                continue;
            }
            let (p, q) = (zt[i], zt[m]);
            let qc = q.conj();
            // At −k the same pair, conjugated: |Du(−k)|² = |Du(k)|², |Dv(−k)|² = |Dv(k)|².
            let (du_k, dv_k) = (0.25 * (p + qc).norm_sqr(), 0.25 * (p - qc).norm_sqr());
            zt[i] = Complex32::new(du_k, 0.0);
            pv_marginal[kv] += dv_k as f64;
            if m != i {
                zt[m] = Complex32::new(du_k, 0.0);
                pv_marginal[mv] += dv_k as f64;
            }
        }
    }
    let mut pu = zt;
    // A_u: inverse along v (every u frequency's row), the lags ±MAX_LENGTH_PX kept,
    // then inverse along u.
    iv.process_with_scratch(&mut pu, &mut scratch);
    let row_len = LagTable::ROW;
    let mut g = vec![zero; row_len * nu];
    for ku in 0..nu {
        let row = &pu[ku * nv..(ku + 1) * nv];
        for (r, s) in (-(MAX_LENGTH_PX as isize)..=MAX_LENGTH_PX as isize).enumerate() {
            g[r * nu + ku] = row[s.rem_euclid(nv as isize) as usize];
        }
    }
    drop(pu);
    iu.process_with_scratch(&mut g, &mut scratch);
    let norm = 1.0 / (nu * nv) as f64;
    let mut data = vec![0.0f64; (MAX_LAG_PX + 1) * row_len];
    for (r, line) in g.chunks_exact(nu).enumerate() {
        for t in 0..=MAX_LAG_PX {
            data[t * row_len + r] = line[t].re as f64 * norm;
        }
    }
    // A_v(0, t'): the marginal over the u frequencies, inverse along v.
    let mut m: Vec<Complex32> = pv_marginal.iter().map(|&v| Complex32::new(v as f32, 0.0)).collect();
    iv.process_with_scratch(&mut m, &mut scratch);
    let av = (-(AV_OFFSET as isize)..=AV_OFFSET as isize)
        .map(|t| m[t.rem_euclid(nv as isize) as usize].re as f64 * norm)
        .collect();
    (LagTable { data }, av)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The two-pass σ (differences per row, then the in-order sum) is the per-pixel
    /// in-order sum's, bit for bit, on frames of several sizes.
    #[test]
    fn immerkaer_sigma_is_the_in_order_sum() {
        let reference = |p: &Plane| -> f64 {
            let (w, h) = (p.width, p.height);
            let (mut sum, mut count) = (0.0f64, 0usize);
            for y in (1..h - 1).step_by(8) {
                let at = |x: usize, y: usize| p.data[y * w + x];
                for x in 1..w - 1 {
                    let v = at(x - 1, y - 1) - 2.0 * at(x, y - 1) + at(x + 1, y - 1)
                        - 2.0 * (at(x - 1, y) - 2.0 * at(x, y) + at(x + 1, y))
                        + at(x - 1, y + 1)
                        - 2.0 * at(x, y + 1)
                        + at(x + 1, y + 1);
                    sum += v.abs() as f64;
                }
                count += w - 2;
            }
            (std::f64::consts::FRAC_PI_2).sqrt() / 6.0 * sum / count as f64
        };
        for (w, h) in [(3, 3), (17, 10), (64, 33), (101, 57)] {
            let p = Plane::from_vec(w, h, (0..w * h).map(|i| ((i * 7919) % 211) as f32 / 97.0 - 1.1).collect());
            assert_eq!(immerkaer_sigma(&p).to_bits(), reference(&p).to_bits(), "{w}×{h}");
        }
    }
}
