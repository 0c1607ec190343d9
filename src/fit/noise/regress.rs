//! The per-level regressions of the noise fits: variance on luma by weighted least
//! squares (`ols`, reweighted by `precision_weights`), std on luma by Gauss–Newton
//! (`fit_linear_std`), and the likelihood that chooses between the two forms
//! (`neg2_log_likelihood`).

/// OLS of v on (1, y): returns (intercept, slope, ssr, covariance[2][2]).
pub(super) fn ols(y: &[f32], v: &[f32], wts: Option<&[f32]>) -> Option<(f64, f64, f64, [[f64; 2]; 2])> {
    let n = y.len();
    if n == 0 {
        return None;
    }
    let (mut sw, mut sy, mut syy, mut sv, mut syv) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
    for i in 0..n {
        let w = wts.map_or(1.0, |w| w[i] as f64);
        let (yi, vi) = (y[i] as f64, v[i] as f64);
        sw += w;
        sy += w * yi;
        syy += w * yi * yi;
        sv += w * vi;
        syv += w * yi * vi;
    }
    let det = sw * syy - sy * sy;
    // Fewer than 4 points, or all at one luma: a constant is all the data can say.
    let (a, b) = if n >= 4 && det.abs() > 1e-12 * sw * sw {
        let b = (sw * syv - sy * sv) / det;
        ((sv - b * sy) / sw, b)
    } else {
        (sv / sw, 0.0)
    };
    let ssr: f64 = (0..n).map(|i| wts.map_or(1.0, |w| w[i] as f64) * (v[i] as f64 - a - b * y[i] as f64).powi(2)).sum();
    // Weighted LS: Cov(β) = (Σ w r² / (n − 2)) · (XᵀWX)⁻¹, for weights of any scale.
    let s2 = ssr / (n as f64 - 2.0).max(1.0);
    let cov = if n >= 4 && det.abs() > 1e-12 * sw * sw {
        [[s2 * syy / det, -s2 * sy / det], [-s2 * sy / det, s2 * sw / det]]
    } else {
        [[s2 / sw, 0.0], [0.0, 0.0]]
    };
    Some((a, b, ssr, cov))
}

/// Gauss–Newton for v ≈ B((a + b·Y)²) = a² + 2ab·m1 + b²·m2 (m1 = B(Y),
/// m2 = B(Y²): the window pools the squared std, so this is exact where
/// (a + b·B(Y))² would be biased up by b²·Var_B(Y)). Started from OLS of √v on m1.
///
/// The normal equations JᵀWJ and JᵀWr are polynomials in (a, b) whose coefficients
/// are nine weighted sums over the samples (`GnSums`), so each iteration is O(1)
/// after one pass: the per-sample iterations this replaced were ~7% of a fresh
/// process's accurate noise fit at 512² (perf). The residual sum of squares is
/// summed per sample, once, at the solution (no cancellation).
pub(super) fn fit_linear_std(m1: &[f32], m2: &[f32], v: &[f32], wts: Option<&[f32]>) -> Option<(f64, f64, f64)> {
    let sq: Vec<f32> = v.iter().map(|&x| x.max(0.0).sqrt()).collect();
    let (mut a, mut b, _, _) = ols(m1, &sq, wts)?;
    let w = |i: usize| wts.map_or(1.0, |w| w[i] as f64);
    let pred = |a: f64, b: f64, i: usize| a * a + 2.0 * a * b * m1[i] as f64 + b * b * m2[i] as f64;
    let mut g = GnSums::default();
    for i in 0..v.len() {
        let (wi, p, q, vi) = (w(i), m1[i] as f64, m2[i] as f64, v[i] as f64);
        g.s1 += wi;
        g.m1 += wi * p;
        g.m2 += wi * q;
        g.m11 += wi * p * p;
        g.m12 += wi * p * q;
        g.m22 += wi * q * q;
        g.v += wi * vi;
        g.v1 += wi * vi * p;
        g.v2 += wi * vi * q;
    }
    for _ in 0..30 {
        let (jtj, jtr) = g.normal_equations(a, b);
        let det = jtj[0][0] * jtj[1][1] - jtj[0][1] * jtj[1][0];
        if det.abs() < 1e-30 {
            break;
        }
        let da = (jtj[1][1] * jtr[0] - jtj[0][1] * jtr[1]) / det;
        let db = (jtj[0][0] * jtr[1] - jtj[1][0] * jtr[0]) / det;
        a += da;
        b += db;
        if da.abs() + db.abs() < 1e-12 {
            break;
        }
    }
    let ssr = (0..v.len()).map(|i| w(i) * (v[i] as f64 - pred(a, b, i)).powi(2)).sum();
    (a.is_finite() && b.is_finite()).then_some((a, b, ssr))
}

/// Weighted sums of 1, m1, m2, m1², m1·m2, m2², v, v·m1, v·m2 (`fit_linear_std`).
#[derive(Default)]
struct GnSums {
    s1: f64,
    m1: f64,
    m2: f64,
    m11: f64,
    m12: f64,
    m22: f64,
    v: f64,
    v1: f64,
    v2: f64,
}

impl GnSums {
    /// (JᵀWJ, JᵀWr) at (a, b) for r = v − (a² + 2ab·m1 + b²·m2), J = ∂pred/∂(a, b) =
    /// (2(a + b·m1), 2(a·m1 + b·m2)), expanded over the sums.
    fn normal_equations(&self, a: f64, b: f64) -> ([[f64; 2]; 2], [f64; 2]) {
        let g = self;
        let (aa, ab, bb) = (a * a, a * b, b * b);
        let j00 = 4.0 * (aa * g.s1 + 2.0 * ab * g.m1 + bb * g.m11);
        let j01 = 4.0 * (aa * g.m1 + ab * (g.m2 + g.m11) + bb * g.m12);
        let j11 = 4.0 * (aa * g.m11 + 2.0 * ab * g.m12 + bb * g.m22);
        // Σw·(a + b·m1)·r and Σw·(a·m1 + b·m2)·r, r's terms v, −a², −2ab·m1, −b²·m2.
        let r0 = a * (g.v - aa * g.s1 - 2.0 * ab * g.m1 - bb * g.m2)
            + b * (g.v1 - aa * g.m1 - 2.0 * ab * g.m11 - bb * g.m12);
        let r1 = a * (g.v1 - aa * g.m1 - 2.0 * ab * g.m11 - bb * g.m12)
            + b * (g.v2 - aa * g.m2 - 2.0 * ab * g.m12 - bb * g.m22);
        ([[j00, j01], [j01, j11]], [2.0 * r0, 2.0 * r1])
    }
}

/// Weights 1/pred² (times the optional base weights): the sampling variance of a
/// local-variance estimate grows like σ⁴, so unweighted least squares would let the
/// bright end dictate the dark end. Predictions are floored at 1e-3 of their
/// maximum so a line through zero cannot produce infinite weights.
pub(super) fn precision_weights(pred: &[f64], base: Option<&[f32]>) -> Vec<f32> {
    let floor = pred.iter().cloned().fold(0.0f64, f64::max) * 1e-3 + 1e-30;
    pred.iter().enumerate().map(|(i, &p)| (base.map_or(1.0, |b| b[i] as f64) / p.max(floor).powi(2)) as f32).collect()
}

/// −2·log-likelihood (up to a constant) of variance samples `v` under predictions
/// `pred` with sampling std ∝ pred: Σ ln pred² + n·ln(mean((v − pred)²/pred²)).
pub(super) fn neg2_log_likelihood(v: &[f32], pred: &[f64]) -> f64 {
    let floor = pred.iter().cloned().fold(0.0f64, f64::max) * 1e-3 + 1e-30;
    let n = v.len() as f64;
    let (mut logs, mut rel) = (0.0f64, 0.0f64);
    for (&vi, &p) in v.iter().zip(pred) {
        let p = p.max(floor);
        logs += 2.0 * p.ln();
        rel += (vi as f64 - p).powi(2) / (p * p);
    }
    logs + n * (rel / n).max(1e-300).ln()
}
