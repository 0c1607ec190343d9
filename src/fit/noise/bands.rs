//! The blind noise fit's per-channel pyramids, the frame's level-0 band and binning
//! luma read window by window where its samples measure them (never built as
//! planes), and its separable window sums.

use super::*;

/// One channel's Gaussian pyramid G[1..=levels] (`.0[l]` is G[l + 1]; G[0] is
/// `data` itself, not copied) and its band-pass levels 0..levels, by the clamp-free
/// interior `reduce`/`expand`. Without `band0` the level-0 band is left empty (0×0):
/// the frame's own is read window by window (`Band0`), never as a plane.
pub(super) fn channel_pyramids(
    data: &[f32],
    w: usize,
    h: usize,
    levels: usize,
    band0: bool,
    visit: impl FnMut(usize),
) -> (Vec<Plane>, Vec<Plane>) {
    let g = crate::image::gaussian_pyramid_of(crate::image::reduce_slice_visiting(data, w, h, visit), levels);
    let bands = (0..levels)
        .map(|l| {
            if l == 0 && !band0 {
                return Plane::from_vec(0, 0, vec![]);
            }
            let (fine, fw, fh) =
                if l == 0 { (data, w, h) } else { (&g[l - 1].data[..], g[l - 1].width, g[l - 1].height) };
            let mut b = crate::image::expand(&g[l], fw, fh);
            for (v, gv) in b.data.iter_mut().zip(fine) {
                *v = gv - *v;
            }
            b
        })
        .collect();
    (g, bands)
}

/// The frame's level-0 band per channel, I_c − expand(G_c[1]), read only in the 9×9
/// windows of the flat samples that measure it (~13% of a 1280×960 frame's pixels
/// at the default grid): three full-resolution expands were 3.6 ms of the fit's
/// 7.4 ms of pyramids. `expand_window9` computes what `expand` would have written,
/// so every window holds the values the plane held.
pub(super) struct Band0<'a> {
    pub(super) fine: [&'a [f32]; 3],
    pub(super) g1: [&'a Plane; 3],
    pub(super) width: usize,
    pub(super) height: usize,
}

impl Band0<'_> {
    /// The band of channel `c` in the 9×9 window at (x, y), coordinates clamped into
    /// the frame (as `Plane::get_clamped` reads a border window).
    pub(super) fn window(&self, c: usize, x: usize, y: usize) -> [[f32; 9]; 9] {
        let mut e = crate::image::expand_window9(self.g1[c], self.width, self.height, x, y);
        if self.interior(x, y) {
            // No clamps: each window row is a slice of the frame's row (the same
            // subtraction per value; the clamped indices below cost ~1 ms a fit).
            for (j, er) in e.iter_mut().enumerate() {
                let start = (y + j - 4) * self.width + x - 4;
                for (v, &f) in er.iter_mut().zip(&self.fine[c][start..start + 9]) {
                    *v = f - *v;
                }
            }
            return e;
        }
        let (w, h) = (self.width as isize, self.height as isize);
        std::array::from_fn(|j| {
            let yy = (y as isize + j as isize - 4).clamp(0, h - 1) as usize;
            std::array::from_fn(|i| {
                let xx = (x as isize + i as isize - 4).clamp(0, w - 1) as usize;
                self.fine[c][yy * self.width + xx] - e[j][i]
            })
        })
    }

    /// `win.mean_sq_window(&self.window(c, x, y), self.interior(x, y))`, the same
    /// value: inside the frame each band row is folded into the column sums as
    /// `expand_window9_rows` hands it over (the same subtraction, square and sum per
    /// value, in the same order), never stored as a window.
    pub(super) fn mean_sq(&self, win: &SepWindow, c: usize, x: usize, y: usize) -> f32 {
        if !self.interior(x, y) {
            return win.mean_sq_window(&self.window(c, x, y), false);
        }
        expanded_mean_sq(win, self.g1[c], (self.width, self.height), x, y, Some(self.fine[c]))
    }

    /// Whether the window at (x, y) lies inside the frame (`SepWindow::interior`).
    pub(super) fn interior(&self, x: usize, y: usize) -> bool {
        x >= 4 && y >= 4 && x + 4 < self.width && y + 4 < self.height
    }
}

/// The blind tier's window sums in separable form: per window column, a weighted
/// sum down its 9 rows (9 independent accumulators, which the compiler keeps in
/// vector lanes), then the columns' weighted sum — Σ_i w_i Σ_j w_j f(v_ji), the
/// window of `window(l)` (its outer product) up to float rounding. Why: the 2-D
/// serial sums are 81 dependent additions per sample, bound by the adder's latency
/// (by perf ~60% of the blind noise fit's sample search at 1280×960). The accurate
/// tier keeps the serial sums: on a flat frame its regression relies on their exact
/// cancellation (tests/extremes.rs::flat_textureless_frame; a reordered sum there
/// lost the noise, see BENCHMARKS.md). Border samples take the clamped 2-D sums.
pub(super) struct SepWindow {
    w1: [f32; 9],
    w2: [[f32; 9]; 9],
}

impl SepWindow {
    pub(super) fn new(level: usize) -> Self {
        Self { w1: window_1d(level), w2: window(level) }
    }

    #[inline]
    pub(super) fn interior(p: &Plane, x: usize, y: usize) -> bool {
        x >= 4 && y >= 4 && x + 4 < p.width && y + 4 < p.height
    }

    /// Σ_i w_i c_i: the column sums' weighted sum, as a pairwise tree (four
    /// dependent additions instead of nine in a chain).
    #[inline]
    pub(super) fn across(&self, c: &[f32; 9]) -> f32 {
        let p: [f32; 9] = std::array::from_fn(|i| c[i] * self.w1[i]);
        ((p[0] + p[1]) + (p[2] + p[3])) + ((p[4] + p[5]) + (p[6] + p[7])) + p[8]
    }

    /// Window mean of `p` at (x, y) (every grid point's binning luma; the mean of
    /// squares, `mean_sq`, only for the flat samples that report it).
    #[inline]
    pub(super) fn mean(&self, p: &Plane, x: usize, y: usize) -> f32 {
        self.plane_sum_of(p, x, y, |v| v)
    }

    /// Window mean of the squares of `p` at (x, y).
    #[inline]
    pub(super) fn mean_sq(&self, p: &Plane, x: usize, y: usize) -> f32 {
        self.plane_sum_of(p, x, y, |v| v * v)
    }

    /// The window's weighted sum of f(value) on a plane for `mean` / `mean_sq`:
    /// separable inside, the clamped serial 2-D sum (`window_sum`) at borders.
    #[inline]
    fn plane_sum_of(&self, p: &Plane, x: usize, y: usize, f: impl Fn(f32) -> f32) -> f32 {
        if !Self::interior(p, x, y) {
            return window_sum(p, x, y, &self.w2, f);
        }
        let mut c = [0.0f32; 9];
        for (j, &wj) in self.w1.iter().enumerate() {
            let start = (y + j - 4) * p.width + x - 4;
            for (a, &v) in c.iter_mut().zip(&p.data[start..start + 9]) {
                *a += wj * f(v);
            }
        }
        self.across(&c)
    }

    /// `mean(p, x, y)` where `v` is p's window at (x, y) (clamped at the border, as
    /// `local_mean` reads it): the same sums in the same order.
    #[inline]
    pub(super) fn mean_window(&self, v: &[[f32; 9]; 9], interior: bool) -> f32 {
        self.window_sum_of(v, interior, |x| x)
    }

    /// `mean_sq` of a plane whose window at (x, y) is `v` (`interior`: the window
    /// lies inside the plane): the same sums in the same order, border windows by
    /// `local_mean_sq`'s serial 2-D sum.
    #[inline]
    pub(super) fn mean_sq_window(&self, v: &[[f32; 9]; 9], interior: bool) -> f32 {
        self.window_sum_of(v, interior, |x| x * x)
    }

    /// The window's weighted sum of f(value) for `mean_window` / `mean_sq_window`:
    /// separable inside (as `mean`), the serial 2-D sum of `window_sum` at borders.
    #[inline]
    fn window_sum_of(&self, v: &[[f32; 9]; 9], interior: bool, f: impl Fn(f32) -> f32) -> f32 {
        if !interior {
            let mut acc = 0.0;
            for (wr, vr) in self.w2.iter().zip(v) {
                for (wt, &x) in wr.iter().zip(vr) {
                    acc += wt * f(x);
                }
            }
            return acc;
        }
        let mut c = [0.0f32; 9];
        for (&wj, row) in self.w1.iter().zip(v) {
            for (a, &x) in c.iter_mut().zip(row) {
                *a += wj * f(x);
            }
        }
        self.across(&c)
    }

    /// `mean_prod(p, q, x, y)` where `v` is p's window at (x, y) (see
    /// `mean_sq_window`; border windows by `local_mean_prod`'s serial sum).
    #[inline]
    pub(super) fn mean_prod_window(&self, v: &[[f32; 9]; 9], interior: bool, q: &Plane, x: usize, y: usize) -> f32 {
        if !interior {
            let mut acc = 0.0;
            for (j, (wr, vr)) in self.w2.iter().zip(v).enumerate() {
                let yy = y as isize + j as isize - 4;
                for (i, (wt, &a)) in wr.iter().zip(vr).enumerate() {
                    acc += wt * a * q.get_clamped(x as isize + i as isize - 4, yy);
                }
            }
            return acc;
        }
        let mut c = [0.0f32; 9];
        for (j, (&wj, row)) in self.w1.iter().zip(v).enumerate() {
            let start = (y + j - 4) * q.width + x - 4;
            for ((a, &u), &b) in c.iter_mut().zip(row).zip(&q.data[start..start + 9]) {
                *a += wj * (u * b);
            }
        }
        self.across(&c)
    }
}

/// `win.mean_sq_window` of the window (x, y) — inside the `width × height` frame —
/// of `expand(coarse)`, or with `fine` of the band `fine − expand(coarse)`: each row
/// folded into the column sums as `expand_window9_rows` hands it over (the same
/// subtraction, square and sums per value, in the same order), never stored as a
/// window.
#[inline]
fn expanded_mean_sq(
    win: &SepWindow,
    coarse: &Plane,
    (width, height): (usize, usize),
    x: usize,
    y: usize,
    fine: Option<&[f32]>,
) -> f32 {
    let mut sums = [0.0f32; 9];
    crate::image::expand_window9_rows(coarse, width, height, x, y, |j, e| {
        let wj = win.w1[j];
        match fine {
            Some(fine) => {
                let start = (y + j - 4) * width + x - 4;
                for ((a, &f), e) in sums.iter_mut().zip(&fine[start..start + 9]).zip(e) {
                    let v = f - e;
                    *a += wj * (v * v);
                }
            }
            None => {
                for (a, e) in sums.iter_mut().zip(e) {
                    *a += wj * (e * e);
                }
            }
        }
    });
    win.across(&sums)
}

/// The 1-D window weights `w` over outputs v − 4 … v + 4 of `expand`, moved onto the
/// coarse samples those outputs read (even output 2m: m − 1, m, m + 1 weighted ⅛, ¾,
/// ⅛; odd 2m + 1: m, m + 1 weighted ½, ½): the first coarse index, the weights, and
/// how many coarse samples carry weight (7 from an even first output, else 6).
/// Needs v ≥ 6 (the even taps' m − 1 ≥ 0).
fn expand_mean_weights(v: usize, w: &[f32; 9]) -> AxisWeights {
    let even_first = (v - 4) % 2 == 0;
    let lo = (v - 4) / 2 - even_first as usize;
    let mut a = [0.0f32; 7];
    for (j, &wj) in w.iter().enumerate() {
        let out = v - 4 + j;
        let m = out / 2 - lo;
        if out % 2 == 0 {
            a[m - 1] += wj * 0.125;
            a[m] += wj * 0.75;
            a[m + 1] += wj * 0.125;
        } else {
            a[m] += wj * 0.5;
            a[m + 1] += wj * 0.5;
        }
    }
    (lo, a, if even_first { 7 } else { 6 })
}

/// `expand_mean_weights`' first coarse index, weights and their count.
pub(super) type AxisWeights = (usize, [f32; 7], usize);

/// The smoothed luma a level's samples are binned by: a plane of the level's size,
/// or (level 0) `expand(coarse)` to `width × height` read only in the windows the
/// samples take (`expand_window9`: the values `expand` writes), which spares a
/// frame-size plane written and read back (4.9 MB at 1280×960).
pub(super) enum Binning<'a> {
    Plane(&'a Plane),
    Expanded { coarse: &'a Plane, width: usize, height: usize },
}

impl Binning<'_> {
    pub(super) fn size(&self) -> (usize, usize) {
        match self {
            Binning::Plane(p) => (p.width, p.height),
            Binning::Expanded { width, height, .. } => (*width, *height),
        }
    }

    /// The expanded plane's 1-D window weights moved onto the coarse samples at
    /// column (`axis` 0) or row (1) `v` (`expand_mean_weights`), where that axis's
    /// window reads the coarse plane without clamps; `None` otherwise, and for a
    /// plane. A grid's samples share their rows' and columns': computed once each
    /// (twice per sample was ~2% of the blind noise fit).
    #[inline]
    pub(super) fn axis_weights(&self, win: &SepWindow, axis: usize, v: usize) -> Option<AxisWeights> {
        match self {
            Binning::Plane(_) => None,
            Binning::Expanded { coarse, width, height } => {
                let (out, n) = if axis == 0 { (*width, coarse.width) } else { (*height, coarse.height) };
                crate::image::expand_window9_interior(v, out, n).then(|| expand_mean_weights(v, &win.w1))
            }
        }
    }

    /// `win.mean` of the plane at (x, y), given `axis_weights(win, 0, x)` and
    /// `axis_weights(win, 1, y)`.
    #[inline]
    pub(super) fn mean_with(
        &self,
        win: &SepWindow,
        x: usize,
        y: usize,
        wx: Option<&AxisWeights>,
        wy: Option<&AxisWeights>,
    ) -> f32 {
        match self {
            Binning::Plane(p) => win.mean(p, x, y),
            Binning::Expanded { coarse, width, height } => {
                // The window mean is linear in the coarse values: Σ_r a_r Σ_c b_c G[r][c]
                // with a, b the window's 1-D weights pushed through `expand`'s taps (7
                // coarse rows and columns, 49 products instead of the expanded window's
                // ~250 operations); the window's values by `expand_window9` only at the
                // borders. The same mean to rounding (the sums regrouped).
                if let (Some(&(cx, bx, nx)), Some(&(cy, ay, ny))) = (wx, wy) {
                    let mut acc = 0.0f32;
                    for (r, &a) in ay[..ny].iter().enumerate() {
                        let start = (cy + r) * coarse.width + cx;
                        let row = &coarse.data[start..start + nx];
                        let s: f32 = row.iter().zip(&bx[..nx]).map(|(g, b)| g * b).sum();
                        acc += a * s;
                    }
                    return acc;
                }
                let v = crate::image::expand_window9(coarse, *width, *height, x, y);
                win.mean_window(&v, Self::interior(*width, *height, x, y))
            }
        }
    }

    /// `win.mean_sq` of the plane at (x, y).
    #[inline]
    pub(super) fn mean_sq(&self, win: &SepWindow, x: usize, y: usize) -> f32 {
        match self {
            Binning::Plane(p) => win.mean_sq(p, x, y),
            Binning::Expanded { coarse, width, height } => {
                if Self::interior(*width, *height, x, y) {
                    return expanded_mean_sq(win, coarse, (*width, *height), x, y, None);
                }
                let v = crate::image::expand_window9(coarse, *width, *height, x, y);
                win.mean_sq_window(&v, false)
            }
        }
    }

    pub(super) fn interior(width: usize, height: usize, x: usize, y: usize) -> bool {
        x >= 4 && y >= 4 && x + 4 < width && y + 4 < height
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Level 0's binning mean read from the half-resolution luma — through the
    /// coarse weights inside, the expanded window at the borders — is the window
    /// mean of the plane `expand` writes, at every pixel of odd and even sizes, to
    /// 1e-6 of the values' scale (f32 sums of ~50 products regrouped: a few ulps).
    #[test]
    fn expanded_binning_mean_is_the_expanded_planes() {
        let coarse = Plane::from_vec(40, 30, (0..1200).map(|i| ((i * 37) % 101) as f32 / 101.0 - 0.2).collect());
        let win = SepWindow::new(0);
        for (w, h) in [(80, 60), (79, 59)] {
            let full = crate::image::expand(&coarse, w, h);
            let read = Binning::Expanded { coarse: &coarse, width: w, height: h };
            for y in 0..h {
                for x in 0..w {
                    let (wx, wy) = (read.axis_weights(&win, 0, x), read.axis_weights(&win, 1, y));
                    let (want, got) = (win.mean(&full, x, y), read.mean_with(&win, x, y, wx.as_ref(), wy.as_ref()));
                    assert!((got - want).abs() <= 1e-6, "{w}×{h} at ({x}, {y}): {got} vs {want}");
                }
            }
        }
    }

    /// The row-folded window sums of squares are the stored windows' bit for bit, at
    /// every pixel (interior and border) of odd and even sizes, at every level's
    /// window: level 0's band (`Band0::mean_sq`) and the expanded binning luma
    /// (`Binning::mean_sq`, whose plane form `expand` writes).
    #[test]
    fn row_folded_squares_are_the_windows_own() {
        let coarse = Plane::from_vec(40, 30, (0..1200).map(|i| ((i * 37) % 101) as f32 / 101.0 - 0.2).collect());
        for (w, h) in [(80, 60), (79, 59)] {
            let fine: Vec<f32> = (0..w * h).map(|i| ((i * 53) % 97) as f32 / 97.0 - 0.3).collect();
            let band0 = Band0 { fine: [&fine; 3], g1: [&coarse; 3], width: w, height: h };
            let full = crate::image::expand(&coarse, w, h);
            let read = Binning::Expanded { coarse: &coarse, width: w, height: h };
            for level in 0..4 {
                let win = SepWindow::new(level);
                for y in 0..h {
                    for x in 0..w {
                        let want = win.mean_sq_window(&band0.window(1, x, y), band0.interior(x, y));
                        let got = band0.mean_sq(&win, 1, x, y);
                        assert_eq!(got.to_bits(), want.to_bits(), "band {w}×{h} L{level} at ({x}, {y})");
                        let (want, got) = (win.mean_sq(&full, x, y), read.mean_sq(&win, x, y));
                        assert_eq!(got.to_bits(), want.to_bits(), "luma {w}×{h} L{level} at ({x}, {y})");
                    }
                }
            }
        }
    }
}
