//! CPU image operations shared by `synth` and `fit`: planar float images, luma,
//! Burt–Adelson pyramids, discrete-Gaussian blurs, bilinear and bicubic sampling; camera
//! YUV_420_888 frames to RGB (`yuv`).
//!
//! Conventions: values are linear floats (nominally [0,1] for colour), row-major,
//! `(x, y)` with `x` along a row. Borders are clamp-to-edge everywhere, so every
//! operation is defined for any size down to 1×1.

mod blur;
mod depth_steps;
mod pyramid;
mod sample;
pub mod yuv;

pub use blur::{blur_separable, blur_separable_rows, blur_x, discrete_gaussian_kernel};
pub use depth_steps::clear_near_depth_steps;
pub use pyramid::{
    expand, expand_window9, expand_window9_interior, expand_window9_rows, gaussian_pyramid, gaussian_pyramid_of,
    laplacian_pyramid, reduce, reduce_slice, reduce_slice_visiting, LaplacianPyramid,
};
pub use sample::{bicubic_interior, cubic_weights, sample_bicubic, sample_bicubic_rgb_interior, sample_bicubic_slice};

/// One channel of floats.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl Plane {
    pub fn new(width: usize, height: usize, fill: f32) -> Self {
        Self { width, height, data: vec![fill; width * height] }
    }

    pub fn from_vec(width: usize, height: usize, data: Vec<f32>) -> Self {
        debug_assert_eq!(data.len(), width * height);
        Self { width, height, data }
    }

    /// The `w`×`h` rectangle at (`x0`, `y0`), copied (None where it does not fit).
    pub fn crop(&self, x0: usize, y0: usize, w: usize, h: usize) -> Option<Plane> {
        crop_slice(&self.data, self.width, self.height, x0, y0, w, h).map(|d| Self::from_vec(w, h, d))
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Clamp-to-edge read with signed coordinates.
    #[inline]
    pub fn get_clamped(&self, x: isize, y: isize) -> f32 {
        let xc = x.clamp(0, self.width as isize - 1) as usize;
        let yc = y.clamp(0, self.height as isize - 1) as usize;
        self.data[yc * self.width + xc]
    }

    /// Bilinear sample at continuous pixel coordinates (pixel centres at integers),
    /// clamp-to-edge outside the image.
    #[inline]
    pub fn sample_bilinear(&self, x: f32, y: f32) -> f32 {
        // Interior fast path (all four taps inside): truncation is the floor of a
        // non-negative value and needs no libm call (`floorf` is one on baseline
        // x86-64: 2% of the fast tier by perf), and no tap needs a clamp. Same
        // arithmetic as below, so the same bits. NaN fails the test and takes the
        // clamped path.
        if self.bilinear_interior(x, y) {
            return self.sample_bilinear_inside(x, y);
        }
        self.sample_bilinear_clamped(x, y)
    }

    /// Whether all four bilinear taps of (x, y) lie inside the plane (NaN: no). The
    /// region is a box, so a segment whose two ends pass lies inside (`sample_line`).
    #[inline]
    fn bilinear_interior(&self, x: f32, y: f32) -> bool {
        x >= 0.0 && y >= 0.0 && x < self.width.saturating_sub(1) as f32 && y < self.height.saturating_sub(1) as f32
    }

    /// `sample_bilinear` at a point `bilinear_interior` accepted.
    #[inline(always)]
    fn sample_bilinear_inside(&self, x: f32, y: f32) -> f32 {
        let (x0, y0) = (x as usize, y as usize);
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let i = y0 * self.width + x0;
        // One bounds check for the four taps (the interior test keeps them inside;
        // the slice proves it to the compiler).
        let q = &self.data[i..i + self.width + 2];
        let (a, b) = (q[0], q[1]);
        let (c, d) = (q[self.width], q[self.width + 1]);
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        top + (bottom - top) * fy
    }

    /// `out[j] = sample_bilinear(x0 + j·dx, y0 + j·dy)`, the same values, for the
    /// straight lines the motion-blur profiles and the streak spectrum read: where
    /// both ends lie in the interior every node does (the interior is a box, and
    /// x0 + j·dx is monotone in j under rounding too), so one test serves the whole
    /// line and the taps inline into one loop (per-node calls spilled the loop's
    /// state to the stack: ~9 ns a node with the frame in cache, 4 × 4 096 profiles
    /// a frame).
    pub fn sample_line(&self, x0: f32, y0: f32, dx: f32, dy: f32, out: &mut [f32]) {
        let Some(last) = out.len().checked_sub(1) else {
            return;
        };
        let (x1, y1) = (x0 + last as f32 * dx, y0 + last as f32 * dy);
        if self.bilinear_interior(x0, y0) && self.bilinear_interior(x1, y1) {
            // (Planes of 2²³ values or more, whose tap indices would not be exact in
            // an f32, take one node at a time.)
            if self.data.len() >= 1 << 23 {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = self.sample_bilinear_inside(x0 + j as f32 * dx, y0 + j as f32 * dy);
                }
                return;
            }
            // `sample_bilinear_inside` per node in chunks of 16, then one of 8, then
            // single nodes (`line_chunks`): each chunk in three loops — positions,
            // weights and tap indices (lane-wise), the four taps' reads (the only
            // scalar part), and the two-way interpolation (lane-wise). The same
            // operations per node in the same order, so the same values; one node
            // per iteration would do every step in scalar registers. The lengths are
            // constants, so each loop unrolls whole, without zeroed scratch or
            // per-chunk length tests: chunks of a run-time length up to 32 take
            // 62 / 119 / 208 ns for lines of 17 / 33 / 65 nodes, these 51 / 85 /
            // 154 ns (9 nodes: 45 against 44 ns).
            let n16 = out.len() / 16 * 16;
            let (sixteens, rest) = out.split_at_mut(n16);
            line_chunks::<16>(&self.data, self.width, (x0, y0, dx, dy), sixteens, 0);
            line_chunks::<8>(&self.data, self.width, (x0, y0, dx, dy), rest, n16);
        } else {
            for (j, o) in out.iter_mut().enumerate() {
                *o = self.sample_bilinear(x0 + j as f32 * dx, y0 + j as f32 * dy);
            }
        }
    }

    /// `sample_line` along `L` parallel lines of `n` nodes each — line l from
    /// `starts[l]`, every line with the step (dx, dy) — into `out[l·n..(l + 1)·n]`:
    /// the same values. Each line's whole chunks of 16 nodes as `sample_line`
    /// reads them; the nodes after them gathered across the lines into chunks of
    /// 4 (the isotropy's four 17-node profiles a sample: their last nodes one chunk
    /// instead of four single nodes), with one interior test for all the lines.
    pub fn sample_lines<const L: usize>(&self, starts: [(f32, f32); L], dx: f32, dy: f32, n: usize, out: &mut [f32]) {
        let Some(last) = n.checked_sub(1) else {
            return;
        };
        let inside = starts.iter().all(|&(x0, y0)| {
            self.bilinear_interior(x0, y0) && self.bilinear_interior(x0 + last as f32 * dx, y0 + last as f32 * dy)
        });
        let first_taps = self.data.get(..self.width + 2);
        let (true, Some(first_taps), true) = (inside, first_taps, self.data.len() < 1 << 23) else {
            for (&(x0, y0), o) in starts.iter().zip(out.chunks_exact_mut(n)) {
                self.sample_line(x0, y0, dx, dy, o);
            }
            return;
        };
        let n16 = n / 16 * 16;
        for (&(x0, y0), o) in starts.iter().zip(out.chunks_exact_mut(n)) {
            line_chunks::<16>(&self.data, self.width, (x0, y0, dx, dy), &mut o[..n16], 0);
        }
        // The tails, line by line: node j of line l at (x0 + j·dx, y0 + j·dy), as
        // `line_chunks` places it; (line, node) pairs four to a chunk.
        let mut quad = [(0usize, 0.0f32, 0.0f32); 4];
        let mut held = 0;
        for (l, &(x0, y0)) in starts.iter().enumerate() {
            for j in n16..n {
                let jf = j as f32;
                quad[held] = (l * n + j, x0 + jf * dx, y0 + jf * dy);
                held += 1;
                if held == 4 {
                    let v = bilinear_chunk(&self.data, self.width, first_taps, &quad.map(|t| t.1), &quad.map(|t| t.2));
                    for (t, v) in quad.iter().zip(v) {
                        out[t.0] = v;
                    }
                    held = 0;
                }
            }
        }
        for &(at, x, y) in &quad[..held] {
            out[at] = bilinear_chunk(&self.data, self.width, first_taps, &[x], &[y])[0];
        }
    }

    /// `sample_bilinear` where a tap leaves the image (kept out of line so that the
    /// interior path inlines into the profile and line loops that call it).
    #[cold]
    #[inline(never)]
    fn sample_bilinear_clamped(&self, x: f32, y: f32) -> f32 {
        let xf = x.floor();
        let yf = y.floor();
        let fx = x - xf;
        let fy = y - yf;
        let x0 = xf as isize;
        let y0 = yf as isize;
        let a = self.get_clamped(x0, y0);
        let b = self.get_clamped(x0 + 1, y0);
        let c = self.get_clamped(x0, y0 + 1);
        let d = self.get_clamped(x0 + 1, y0 + 1);
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        top + (bottom - top) * fy
    }
}

/// `Plane::sample_line`'s nodes `first..first + out.len()` of the line (x0, y0) +
/// j·(dx, dy) on the row-major plane `data` of width `w`, in chunks of `C` and
/// then one node at a time; both ends in the interior and the plane under 2²³
/// values (`sample_line` checks both); each chunk's nodes by `bilinear_chunk`.
#[inline(always)]
fn line_chunks<const C: usize>(
    data: &[f32],
    w: usize,
    (x0, y0, dx, dy): (f32, f32, f32, f32),
    out: &mut [f32],
    first: usize,
) {
    let Some(first_taps) = data.get(..w + 2) else {
        return;
    };
    let mut c0 = first;
    let mut chunks = out.chunks_exact_mut(C);
    for chunk in &mut chunks {
        let (mut xs, mut ys) = ([0.0f32; C], [0.0f32; C]);
        for k in 0..C {
            let j = (c0 + k) as f32;
            (xs[k], ys[k]) = (x0 + j * dx, y0 + j * dy);
        }
        chunk.copy_from_slice(&bilinear_chunk(data, w, first_taps, &xs, &ys));
        c0 += C;
    }
    for (k, o) in chunks.into_remainder().iter_mut().enumerate() {
        let j = (c0 + k) as f32;
        *o = bilinear_chunk(data, w, first_taps, &[x0 + j * dx], &[y0 + j * dy])[0];
    }
}

/// The bilinear values at the `C` interior points (xs[k], ys[k]) of the row-major
/// plane `data` of width `w` (< 2²³ values; `first_taps` its first w + 2), each as
/// `sample_bilinear_inside` computes it — in three loops: weights and tap indices
/// (lane-wise), the four taps' reads (the only scalar part), the two-way
/// interpolation (lane-wise).
///
/// The integer parts without float-to-integer conversions (saturating `as`
/// casts, which stayed scalar with two fix-ups each: ~22% of the lines' time):
/// inside, 0 ≤ x < 2²², where adding and subtracting 2²³ rounds x to an integer
/// exactly and one comparison makes it the floor, which for x ≥ 0 is the
/// truncation `as` took, so fx and fy are the same floats. The index ⌊y⌋·w + ⌊x⌋
/// < 2²³ is then exact in an f32 too, and read from the bits of itself plus 2²³.
#[inline(always)]
fn bilinear_chunk<const C: usize>(
    data: &[f32],
    w: usize,
    first_taps: &[f32],
    xs: &[f32; C],
    ys: &[f32; C],
) -> [f32; C] {
    const TWO_23: f32 = 8_388_608.0;
    let floor_inside = |v: f32| {
        let r = (v + TWO_23) - TWO_23;
        r - if r > v { 1.0 } else { 0.0 }
    };
    let wf = w as f32;
    let base = TWO_23.to_bits();
    let (mut fx, mut fy, mut at) = ([0.0f32; C], [0.0f32; C], [0u32; C]);
    for k in 0..C {
        let (x, y) = (xs[k], ys[k]);
        let (xf, yf) = (floor_inside(x), floor_inside(y));
        fx[k] = x - xf;
        fy[k] = y - yf;
        at[k] = (yf * wf + xf + TWO_23).to_bits() - base;
    }
    let (mut a, mut b, mut c, mut d) = ([0.0f32; C], [0.0f32; C], [0.0f32; C], [0.0f32; C]);
    for k in 0..C {
        let i = at[k] as usize;
        // (Never the fallback: the interior test put every node's taps inside.
        // Without a panic path the loop unrolls and the taps stay in registers.)
        debug_assert!(i + w + 2 <= data.len(), "point ({}, {}) outside the plane", xs[k], ys[k]);
        let q = data.get(i..i + w + 2).unwrap_or(first_taps);
        (a[k], b[k], c[k], d[k]) = (q[0], q[1], q[w], q[w + 1]);
    }
    let mut out = [0.0f32; C];
    for k in 0..C {
        let top = a[k] + (b[k] - a[k]) * fx[k];
        let bottom = c[k] + (d[k] - c[k]) * fx[k];
        out[k] = top + (bottom - top) * fy[k];
    }
    out
}

/// The `w`×`h` rectangle at (`x0`, `y0`) of a row-major `width`×`height` image.
fn crop_slice<T: Copy>(
    data: &[T],
    width: usize,
    height: usize,
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
) -> Option<Vec<T>> {
    if x0 + w > width || y0 + h > height || data.len() != width * height {
        return None;
    }
    let mut out = Vec::with_capacity(w * h);
    for y in y0..y0 + h {
        out.extend_from_slice(&data[y * width + x0..y * width + x0 + w]);
    }
    Some(out)
}

/// Three planar colour channels (R, G, B) of equal size.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgb {
    pub width: usize,
    pub height: usize,
    pub channels: [Vec<f32>; 3],
}

/// Rec. 601 luma weights, as the paper's "Y channel of YCbCr".
pub const LUMA_WEIGHTS: [f32; 3] = [0.299, 0.587, 0.114];

impl Rgb {
    pub fn new(width: usize, height: usize, fill: [f32; 3]) -> Self {
        let n = width * height;
        Self { width, height, channels: [vec![fill[0]; n], vec![fill[1]; n], vec![fill[2]; n]] }
    }

    pub fn len(&self) -> usize {
        self.width * self.height
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn plane(&self, c: usize) -> Plane {
        Plane::from_vec(self.width, self.height, self.channels[c].clone())
    }

    pub fn from_planes(planes: [Plane; 3]) -> Self {
        let [r, g, b] = planes;
        Self { width: r.width, height: r.height, channels: [r.data, g.data, b.data] }
    }

    /// The `w`×`h` rectangle at (`x0`, `y0`), copied (None where it does not fit).
    pub fn crop(&self, x0: usize, y0: usize, w: usize, h: usize) -> Option<Rgb> {
        let channels = [0, 1, 2].map(|c| crop_slice(&self.channels[c], self.width, self.height, x0, y0, w, h));
        let [r, g, b] = channels;
        Some(Self { width: w, height: h, channels: [r?, g?, b?] })
    }

    /// `luma` on the rows where `row(y)`, 0 elsewhere (a fit that reads a few bands
    /// of a frame pays for those: `fit::motion_blur`).
    pub fn luma_rows(&self, row: &dyn Fn(usize) -> bool) -> Plane {
        let w = self.width;
        let mut out = Plane::new(w, self.height, 0.0);
        let [r, g, b] = &self.channels;
        for y in (0..self.height).filter(|&y| row(y)) {
            let span = y * w..(y + 1) * w;
            for (o, ((r, g), b)) in
                out.data[span.clone()].iter_mut().zip(r[span.clone()].iter().zip(&g[span.clone()]).zip(&b[span]))
            {
                *o = LUMA_WEIGHTS[0] * r + LUMA_WEIGHTS[1] * g + LUMA_WEIGHTS[2] * b;
            }
        }
        out
    }

    /// `luma()` and whether every value of it is finite, in one pass: each block of
    /// luma is scanned as it is written, while in cache. Luma's weights are all
    /// positive, so a non-finite value in any channel makes that pixel's luma
    /// non-finite (±∞ stays infinite or meets −∞ as NaN; NaN stays NaN): a finite
    /// luma is a finite frame, read at a third of the channels' bytes (the converse
    /// fails only where finite values near f32::MAX overflow).
    pub fn luma_checked(&self) -> (Plane, bool) {
        const BLOCK: usize = 4096;
        let [r, g, b] = &self.channels;
        let mut data = Vec::with_capacity(r.len().min(g.len()).min(b.len()));
        let mut finite = true;
        for ((r, g), b) in r.chunks(BLOCK).zip(g.chunks(BLOCK)).zip(b.chunks(BLOCK)) {
            let start = data.len();
            data.extend(
                r.iter()
                    .zip(g)
                    .zip(b)
                    .map(|((r, g), b)| LUMA_WEIGHTS[0] * r + LUMA_WEIGHTS[1] * g + LUMA_WEIGHTS[2] * b),
            );
            finite &= data[start..].iter().fold(true, |acc, v| acc & v.is_finite());
        }
        (Plane::from_vec(self.width, self.height, data), finite)
    }

    /// Rec. 601 luma Y = 0.299 R + 0.587 G + 0.114 B.
    /// (`luma_checked`'s plane: one definition of the sum; its finiteness scan runs
    /// on blocks still in cache.)
    pub fn luma(&self) -> Plane {
        self.luma_checked().0
    }

    /// First non-finite value as `(x, y, channel)`, if any.
    pub fn first_non_finite(&self) -> Option<(usize, usize, usize)> {
        // The three channels' blocks in one pass (three streams at once), and the
        // first one found in channel order, as before, only if any block holds one.
        const BLOCK: usize = 1024;
        let [r, g, b] = &self.channels;
        let all_finite = r.chunks(BLOCK).zip(g.chunks(BLOCK)).zip(b.chunks(BLOCK)).all(|((r, g), b)| {
            r.iter().zip(g).zip(b).fold(true, |acc, ((&x, &y), &z)| acc & x.is_finite() & y.is_finite() & z.is_finite())
        });
        if all_finite && r.len() == g.len() && g.len() == b.len() {
            return None;
        }
        for (c, ch) in self.channels.iter().enumerate() {
            if let Some(i) = first_non_finite(ch) {
                return Some((i % self.width.max(1), i / self.width.max(1), c));
            }
        }
        None
    }

    /// Per-pixel map over all channels.
    pub fn map(&self, f: impl Fn(f32) -> f32) -> Rgb {
        let ch = |c: &Vec<f32>| c.iter().map(|&v| f(v)).collect::<Vec<_>>();
        Rgb {
            width: self.width,
            height: self.height,
            channels: [ch(&self.channels[0]), ch(&self.channels[1]), ch(&self.channels[2])],
        }
    }
}

/// Per-pixel optical flow in pixels per frame interval (x then y).
#[derive(Clone, Debug, PartialEq)]
pub struct Flow {
    pub width: usize,
    pub height: usize,
    pub dx: Vec<f32>,
    pub dy: Vec<f32>,
}

impl Flow {
    pub fn uniform(width: usize, height: usize, dx: f32, dy: f32) -> Self {
        Self { width, height, dx: vec![dx; width * height], dy: vec![dy; width * height] }
    }
}

/// Central-difference luma gradient squared magnitude, clamp-to-edge.
pub fn gradient_sq(p: &Plane) -> Plane {
    let mut out = Plane::new(p.width, p.height, 0.0);
    for y in 0..p.height {
        for x in 0..p.width {
            let (xi, yi) = (x as isize, y as isize);
            let gx = 0.5 * (p.get_clamped(xi + 1, yi) - p.get_clamped(xi - 1, yi));
            let gy = 0.5 * (p.get_clamped(xi, yi + 1) - p.get_clamped(xi, yi - 1));
            out.data[y * p.width + x] = gx * gx + gy * gy;
        }
    }
    out
}

/// Summed-area table with one row/column of zero padding, for O(1) box counts.
pub struct IntegralImage {
    width: usize,
    height: usize,
    sums: Vec<f64>,
}

impl IntegralImage {
    pub fn new(p: &Plane) -> Self {
        let (w, h) = (p.width, p.height);
        let mut sums = vec![0.0f64; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0.0f64;
            for x in 0..w {
                row += p.get(x, y) as f64;
                sums[(y + 1) * (w + 1) + x + 1] = sums[y * (w + 1) + x + 1] + row;
            }
        }
        Self { width: w, height: h, sums }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// Sum over the box of half-size `r` centred on `(x, y)`, clipped to the image.
    pub fn box_sum(&self, x: usize, y: usize, r: usize) -> f64 {
        let x0 = x.saturating_sub(r);
        let y0 = y.saturating_sub(r);
        let x1 = (x + r + 1).min(self.width);
        let y1 = (y + r + 1).min(self.height);
        let w = self.width + 1;
        self.sums[y1 * w + x1] - self.sums[y0 * w + x1] - self.sums[y1 * w + x0] + self.sums[y0 * w + x0]
    }
}

/// Index of the first non-finite value. Every frame the fit sees is scanned, so the
/// common all-finite case runs branch-free over blocks (a short-circuiting scan does
/// not vectorise: 0.36 ms per 1280×960 plane on this machine, 0.17 ms this way,
/// measured side by side); the position is looked for only in a block that holds one.
pub fn first_non_finite(v: &[f32]) -> Option<usize> {
    const BLOCK: usize = 1024;
    v.chunks(BLOCK).enumerate().find_map(|(b, chunk)| {
        if chunk.iter().fold(true, |acc, &x| acc & x.is_finite()) {
            None
        } else {
            chunk.iter().position(|x| !x.is_finite()).map(|i| b * BLOCK + i)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The interior fast path of `sample_bilinear` is the clamped formula, bit for
    /// bit (it only skips the floor call and the clamps): checked at points all
    /// over a 7×5 plane, on and near its last row and column, and outside it.
    #[test]
    fn bilinear_interior_path_is_the_clamped_formula() {
        let p = Plane::from_vec(7, 5, (0..35).map(|i| ((i * 37) % 11) as f32 * 0.173 - 0.4).collect());
        let clamped = |x: f32, y: f32| {
            let (xf, yf) = (x.floor(), y.floor());
            let (fx, fy, x0, y0) = (x - xf, y - yf, xf as isize, yf as isize);
            let (a, b) = (p.get_clamped(x0, y0), p.get_clamped(x0 + 1, y0));
            let (c, d) = (p.get_clamped(x0, y0 + 1), p.get_clamped(x0 + 1, y0 + 1));
            let top = a + (b - a) * fx;
            top + (c + (d - c) * fx - top) * fy
        };
        for j in -8..=48 {
            for i in -8..=68 {
                let (x, y) = (i as f32 * 0.1013, j as f32 * 0.1007);
                assert_eq!(p.sample_bilinear(x, y).to_bits(), clamped(x, y).to_bits(), "at ({x}, {y})");
            }
        }
        for (x, y) in [(5.999_999, 3.999_999), (6.0, 4.0), (0.0, 0.0), (-0.0, 2.5)] {
            assert_eq!(p.sample_bilinear(x, y).to_bits(), clamped(x, y).to_bits(), "at ({x}, {y})");
        }
    }

    /// `luma_checked` is the per-pixel weighted sum in channel order bit for bit,
    /// finite exactly where every luma value is, on sizes below, at and past its
    /// block length.
    #[test]
    fn checked_luma_is_the_luma() {
        for (w, h) in [(1, 1), (64, 64), (100, 41)] {
            let mut img = Rgb::new(w, h, [0.0; 3]);
            for (c, ch) in img.channels.iter_mut().enumerate() {
                for (i, v) in ch.iter_mut().enumerate() {
                    *v = ((i * 31 + c * 7) % 113) as f32 / 50.0 - 0.9;
                }
            }
            let (l, finite) = img.luma_checked();
            let bits = |p: &Plane| p.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            let [r, g, b] = &img.channels;
            let want: Vec<u32> = (0..w * h)
                .map(|i| (LUMA_WEIGHTS[0] * r[i] + LUMA_WEIGHTS[1] * g[i] + LUMA_WEIGHTS[2] * b[i]).to_bits())
                .collect();
            assert_eq!(bits(&l), want, "{w}×{h}");
            assert!(finite, "{w}×{h}");
            img.channels[1][w * h - 1] = f32::NAN;
            assert!(!img.luma_checked().1, "{w}×{h}: NaN in the last pixel");
        }
    }

    /// `first_non_finite` finds what a plain scan finds: NaN, +∞ and −∞ first, last,
    /// at a block's edges and in a short last block, in lengths around the block
    /// size, and nothing in finite data holding the extremes (±f32::MAX,
    /// subnormals, −0).
    #[test]
    fn first_non_finite_is_the_plain_scan() {
        for n in [0usize, 1, 15, 16, 17, 1023, 1024, 1025, 3000] {
            let mut v: Vec<f32> = (0..n).map(|i| [0.25, f32::MAX, -f32::MAX, 1e-40, -0.0][i % 5]).collect();
            assert_eq!(first_non_finite(&v), None, "finite, length {n}");
            for at in [0, 15, 16, 1023, 1024, 2047, 2999].into_iter().filter(|&i| i < n).chain(n.checked_sub(1)) {
                for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
                    let keep = v[at];
                    v[at] = bad;
                    assert_eq!(first_non_finite(&v), v.iter().position(|x| !x.is_finite()), "{bad} at {at} of {n}");
                    v[at] = keep;
                }
            }
        }
    }

    /// `sample_line` writes what `sample_bilinear` reads at every node, bit for bit:
    /// lines inside the plane (the one-test path), lines leaving it through either
    /// end or crossing it, lines along the last row and column (the interior's open
    /// edge), zero steps, NaN, and lengths 0–40.
    #[test]
    fn sample_line_is_bilinear_per_node() {
        let p = Plane::from_vec(23, 17, (0..23 * 17).map(|i| ((i * 53) % 29) as f32 * 0.071 - 0.5).collect());
        let lines: [(f32, f32, f32, f32); 11] = [
            (1.3, 2.7, 0.37, 0.21),        // inside
            (2.0, 1.0, 0.5, 0.25),         // on whole and half pixels (the floor's ties)
            (0.0, 0.0, 0.499_999_97, 0.3), // just below half pixels, from the corner
            (20.9, 14.2, -0.41, -0.33),    // inside, backwards
            (-2.0, 3.0, 0.5, 0.1),         // enters
            (10.0, 8.0, 0.9, 0.6),         // leaves
            (-1.0, -1.0, 1.0, 0.9),        // crosses
            (0.0, 15.999, 0.5, 0.0),       // along the last row's open edge
            (22.0, 0.5, 0.0, 0.4),         // on the last column (outside the interior)
            (5.5, 5.5, 0.0, 0.0),          // one point, repeated
            (f32::NAN, 3.0, 0.2, 0.2),     // NaN
        ];
        for (x0, y0, dx, dy) in lines {
            // Every split of `sample_line`'s chunks: singles, one of 8, 16s, and each mixed.
            for n in [0usize, 1, 2, 7, 8, 9, 15, 16, 17, 24, 25, 31, 32, 40] {
                let mut out = vec![0.0f32; n];
                p.sample_line(x0, y0, dx, dy, &mut out);
                for (j, v) in out.iter().enumerate() {
                    let want = p.sample_bilinear(x0 + j as f32 * dx, y0 + j as f32 * dy);
                    assert_eq!(v.to_bits(), want.to_bits(), "line ({x0}, {y0}) + j·({dx}, {dy}), n {n}, node {j}");
                }
            }
        }
    }

    /// `sample_lines` is `sample_line` per line, bit for bit: four parallel lines
    /// inside, one leaving the plane (every line then read alone), every split of
    /// the tails into chunks of 4 and single nodes (lengths 0–40).
    #[test]
    fn parallel_lines_are_their_own_lines() {
        let p = Plane::from_vec(41, 37, (0..41 * 37).map(|i| ((i * 53) % 29) as f32 * 0.071 - 0.5).collect());
        type Lines = ([(f32, f32); 4], f32, f32);
        let cases: [Lines; 3] = [
            ([(3.3, 4.1), (5.7, 2.2), (4.0, 6.0), (2.5, 3.5)], 0.37, 0.21),
            ([(20.9, 30.2), (22.1, 31.0), (19.4, 29.9), (21.0, 28.5)], -0.41, -0.33),
            ([(3.3, 4.1), (-2.0, 3.0), (4.0, 6.0), (2.5, 3.5)], 0.5, 0.1),
        ];
        for (starts, dx, dy) in cases {
            for n in [0usize, 1, 2, 3, 15, 16, 17, 18, 19, 20, 31, 32, 33, 40] {
                let mut got = vec![0.0f32; 4 * n];
                p.sample_lines(starts, dx, dy, n, &mut got);
                for (l, &(x0, y0)) in starts.iter().enumerate() {
                    let mut want = vec![0.0f32; n];
                    p.sample_line(x0, y0, dx, dy, &mut want);
                    let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&got[l * n..(l + 1) * n]), bits(&want), "line {l}, n {n}");
                }
            }
        }
    }

    /// A crop holds the rectangle's pixels in order; one that does not fit is None.
    #[test]
    fn crop_copies_the_rectangle_and_refuses_one_outside() {
        let p = Plane::from_vec(4, 3, (0..12).map(|v| v as f32).collect());
        assert_eq!(p.crop(1, 1, 2, 2).map(|c| c.data), Some(vec![5.0, 6.0, 9.0, 10.0]));
        assert_eq!(p.crop(0, 0, 4, 3), Some(p.clone()));
        assert!(p.crop(3, 0, 2, 1).is_none() && p.crop(0, 2, 1, 2).is_none());
        let img = Rgb::from_planes([p.clone(), p.clone(), p]);
        let c = img.crop(0, 2, 4, 1).expect("fits");
        assert_eq!((c.width, c.height, c.channels[2].clone()), (4, 1, vec![8.0, 9.0, 10.0, 11.0]));
    }
}
