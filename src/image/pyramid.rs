//! Burt–Adelson Gaussian and Laplacian pyramids with the 5-tap binomial kernel
//! [1 4 6 4 1]/16, clamp-to-edge, any size (a level of n pixels reduces to ceil(n/2)).
//! `collapse(laplacian_pyramid(x)) == x` up to float rounding, for every size.

use super::Plane;

const K5: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];

/// Blur with K5 and keep every other sample: size ceil(w/2) × ceil(h/2).
pub fn reduce(p: &Plane) -> Plane {
    reduce_slice(&p.data, p.width, p.height)
}

/// `reduce` of a `w`×`h` row-major slice (e.g. one channel of an `Rgb`, without
/// copying it into a `Plane` first: at 1280×960 a fresh 5 MB buffer costs more in
/// page faults than the reduce itself).
pub fn reduce_slice(data: &[f32], w: usize, h: usize) -> Plane {
    reduce_slice_visiting(data, w, h, |_| {})
}

/// `reduce_slice`, calling `visit(y)` for every source row y once, in increasing
/// order (0 … h − 1), right after the reduce has read it: a caller that needs one
/// more pass over the same values (the blind noise fit's tile extremes) makes it
/// while the rows are in cache instead of reading the frame again.
pub fn reduce_slice_visiting(data: &[f32], w: usize, h: usize, mut visit: impl FnMut(usize)) -> Plane {
    debug_assert_eq!(data.len(), w * h);
    let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
    // Rows first (w2 columns per source row), then columns — but streamed: an output
    // row reads the horizontal pass of source rows 2·y2 − 2 … 2·y2 + 2 (clamped), and
    // consecutive output rows share three of them, so five filtered rows held in a
    // ring (slot = row mod 5: a window's distinct rows are ≤ 5 consecutive ones) stand
    // in for a w2×h intermediate plane — 2.4 MB written and read again per channel
    // at 1280×960 that no longer leave the cache. Each filtered row is computed once,
    // the same sums in the same order as the plane held: the same values.
    let mut ring = vec![0.0f32; 5 * w2];
    let mut held = [usize::MAX; 5];
    let mut out = Vec::with_capacity(w2 * h2);
    for y2 in 0..h2 {
        let cy = 2 * y2 as isize;
        let rows: [usize; 5] = std::array::from_fn(|k| (cy + k as isize - 2).clamp(0, h as isize - 1) as usize);
        for &r in &rows {
            if held[r % 5] != r {
                // Rows are first needed in increasing order (window y2 holds rows
                // 2·y2 − 2 … 2·y2 + 2, clamped, and the next one adds the two after them)
                // and every row is in some window: `visit` sees each row once, in order.
                reduce_row(&data[r * w..(r + 1) * w], &mut ring[(r % 5) * w2..(r % 5 + 1) * w2]);
                visit(r);
                held[r % 5] = r;
            }
        }
        let at = |k: usize| &ring[(rows[k] % 5) * w2..(rows[k] % 5 + 1) * w2];
        let (r0, r1, r2, r3, r4) = (at(0), at(1), at(2), at(3), at(4));
        // Each output starts as its first tap's product and adds the others in tap
        // order (the plane form's five passes, fused: the same operations per value).
        out.extend((0..w2).map(|x| {
            let mut v = K5[0] * r0[x];
            v += K5[1] * r1[x];
            v += K5[2] * r2[x];
            v += K5[3] * r3[x];
            v += K5[4] * r4[x];
            v
        }));
    }
    Plane::from_vec(w2, h2, out)
}

/// The horizontal pass of `reduce` on one row (`out`: ceil(w/2) values). The
/// interior (every tap inside the row) runs without clamps — the same sums in the
/// same order, 3–4× faster; only the outputs whose taps leave the row clamp.
fn reduce_row(row: &[f32], out: &mut [f32]) {
    let w = row.len();
    let w2 = out.len();
    let interior = if w >= 5 { 1..(w - 3) / 2 + 1 } else { 0..0 }; // 2·x2 − 2 ≥ 0 and 2·x2 + 2 ≤ w − 1
    let edge = |x2: usize| {
        let cx = 2 * x2 as isize;
        let mut acc = 0.0;
        for (k, wk) in K5.iter().enumerate() {
            acc += wk * row[(cx + k as isize - 2).clamp(0, w as isize - 1) as usize];
        }
        acc
    };
    // The outputs outside the interior: at most one at the left and two at the
    // right (a scan of every output for them was ~30% of the reduce by perf).
    for x2 in (0..interior.start).chain(interior.end.max(interior.start)..w2) {
        out[x2] = edge(x2);
    }
    for (o, t) in out[interior.clone()].iter_mut().zip(row[2 * interior.start.max(1) - 2..].windows(5).step_by(2)) {
        *o = K5[0] * t[0] + K5[1] * t[1] + K5[2] * t[2] + K5[3] * t[3] + K5[4] * t[4];
    }
}

/// 1-D expand of `src` (length n) to length `m`: out[x] = 2 Σ_j K5[x − 2j + 2] src[j],
/// with j clamped to the source. Each output phase's weights sum to exactly 1.
#[inline]
fn expand_taps(x: usize, n: usize) -> [(usize, f32); 3] {
    // Taps with (x - 2j + 2) in 0..=4, i.e. j in (x-2)/2 ..= (x+2)/2 with matching parity.
    let xi = x as isize;
    let mut taps = [(0usize, 0.0f32); 3];
    let mut t = 0;
    let j_lo = (xi - 2 + 1).div_euclid(2); // ceil((x-2)/2)
    let j_hi = (xi + 2).div_euclid(2);
    for j in j_lo..=j_hi {
        let k = xi - 2 * j + 2;
        if (0..5).contains(&k) && t < 3 {
            taps[t] = (j.clamp(0, n as isize - 1) as usize, 2.0 * K5[k as usize]);
            t += 1;
        }
    }
    taps
}

/// Upsample `p` to `width × height` (the size of the finer level it came from).
pub fn expand(p: &Plane, width: usize, height: usize) -> Plane {
    let (w, h) = (p.width, p.height);
    let xtaps: Vec<_> = (0..width).map(|x| expand_taps(x, w)).collect();
    // Interior output pairs (2m, 2m + 1) with m − 1 ≥ 0 and m + 1 ≤ w − 1 read
    // (¹⁄₈, ⁶⁄₈, ¹⁄₈) and (½, ½): written out, without the tap table's gathers (the
    // same products summed in the same order as `expand_taps`).
    let (e0, e2, o1) = (2.0 * K5[4], 2.0 * K5[2], 2.0 * K5[3]);
    let m_hi = (w.saturating_sub(1)).min(width.saturating_sub(1) / 2); // exclusive
    let expand_row = |row: &[f32], out: &mut [f32]| {
        // The outputs outside the written-out interior (x < 2 or x / 2 ≥ m_hi): at
        // most two at each end, visited directly (as in `reduce_row`).
        for x in (0..2.min(width)).chain((2 * m_hi).max(2)..width) {
            out[x] = xtaps[x].iter().map(|&(j, wt)| wt * row[j]).sum();
        }
        if m_hi > 1 {
            for (pair, t) in out[2..2 * m_hi].chunks_exact_mut(2).zip(row.windows(3)) {
                pair[0] = e0 * t[0] + e2 * t[1] + e0 * t[2];
                pair[1] = o1 * t[1] + o1 * t[2];
            }
        }
    };
    // Rows first, streamed as in `reduce_slice`: an output row reads the horizontal
    // pass of at most three consecutive source rows, held in a ring (slot = row
    // mod 3) instead of a width×h plane; each computed once, so the same values.
    let mut ring = vec![0.0f32; 3 * width];
    let mut held = [usize::MAX; 3];
    let mut out = Vec::with_capacity(width * height);
    for y in 0..height {
        let taps = expand_taps(y, h);
        let live = taps.iter().take_while(|t| t.1 != 0.0).count();
        for &(j, _) in &taps[..live] {
            if held[j % 3] != j {
                expand_row(&p.data[j * w..(j + 1) * w], &mut ring[(j % 3) * width..(j % 3 + 1) * width]);
                held[j % 3] = j;
            }
        }
        let src = |k: usize| (&ring[(taps[k].0 % 3) * width..(taps[k].0 % 3 + 1) * width], taps[k].1);
        // Each output is its first tap's product plus the others in tap order (the
        // plane form's passes, fused: the same operations per value).
        match live {
            3 => {
                let ((s0, w0), (s1, w1), (s2, w2)) = (src(0), src(1), src(2));
                out.extend((0..width).map(|x| {
                    let mut v = w0 * s0[x];
                    v += w1 * s1[x];
                    v += w2 * s2[x];
                    v
                }));
            }
            2 => {
                let ((s0, w0), (s1, w1)) = (src(0), src(1));
                out.extend((0..width).map(|x| {
                    let mut v = w0 * s0[x];
                    v += w1 * s1[x];
                    v
                }));
            }
            1 => {
                let (s0, w0) = src(0);
                out.extend(s0.iter().map(|sv| w0 * sv));
            }
            _ => out.resize(out.len() + width, 0.0),
        }
    }
    Plane::from_vec(width, height, out)
}

/// Whether `expand_window9`'s window at output coordinate `v` (of `out` outputs from
/// `n` source samples) lies in the interior along that axis: every output inside and
/// every tap inside the source (v − 4 ≥ 2 so that the even taps' m − 1 ≥ 0; v + 4's
/// m + 1 ≤ n − 1) — where its taps take their closed form.
#[inline]
pub fn expand_window9_interior(v: usize, out: usize, n: usize) -> bool {
    v >= 6 && v + 4 < out && (v + 4) / 2 + 1 < n
}

/// The values `expand(p, width, height)` holds in the 9×9 window centred on (x, y),
/// each coordinate clamped into the `width × height` output (row-major: `[row][col]`)
/// — the same products summed in the same order, so the same values (but for the
/// sign of an exact zero). For readers of a few windows of a large level: the blind
/// noise fit reads the level-0 band only at its flat samples' windows (~13% of a
/// 1280×960 frame), where three full-resolution expands cost 3.6 ms.
pub fn expand_window9(p: &Plane, width: usize, height: usize, x: usize, y: usize) -> [[f32; 9]; 9] {
    let mut out = [[0.0f32; 9]; 9];
    expand_window9_rows(p, width, height, x, y, |j, row| out[j] = row);
    out
}

/// `expand_window9`'s window handed to `row` one row at a time, in order (`row(j,
/// values)`), the same values: a reader that folds each row into sums as it comes
/// (the blind noise fit's level-0 band) keeps it in registers, where a returned
/// 9×9 array went through the stack and each row's wide reload waited on the
/// narrow stores that wrote it (by perf ~half of `Band0::window`'s time).
#[inline]
pub fn expand_window9_rows(
    p: &Plane,
    width: usize,
    height: usize,
    x: usize,
    y: usize,
    mut row: impl FnMut(usize, [f32; 9]),
) {
    // Interior (`expand_window9_interior`): the taps in closed form — even 2m:
    // (m−1, m, m+1) weighted (⅛, ¾, ⅛); odd 2m+1: (m, m+1) weighted (½, ½) — without
    // the tap search (3× faster per window). The same products in the same order as
    // below.
    if expand_window9_interior(x, width, p.width) && expand_window9_interior(y, height, p.height) {
        let (e0, e2, o1) = (2.0 * K5[4], 2.0 * K5[2], 2.0 * K5[3]);
        let lo = (y - 4) / 2 - ((y - 4) % 2 == 0) as usize;
        let mut horiz = [[0.0f32; 9]; 7];
        // Output column x − 4 + i reads source m = (x − 4 + i)/2 and its neighbours:
        // all within the 7 source values from b − 1 = (x − 4)/2 − 1, read as one
        // seven-value slice per row (`s[k]` is source b − 1 + k), and the window's
        // first column even or odd fixes which output reads which taps — so each
        // row's nine values take constant indices (no bounds check or parity test
        // per value; the same products in the same order).
        let b = (x - 4) / 2;
        let even_start = (x - 4) % 2 == 0;
        for (k, src) in horiz.iter_mut().enumerate().take((y + 4) / 2 + 2 - lo) {
            let row = &p.data[(lo + k) * p.width..(lo + k + 1) * p.width];
            let s = &row[b - 1..b + 6];
            let even = |q: usize| e0 * s[q] + e2 * s[q + 1] + e0 * s[q + 2];
            let odd = |q: usize| o1 * s[q] + o1 * s[q + 1];
            *src = if even_start {
                // i = 2q: m = b + q (taps s[q..q + 3]); i = 2q + 1: m = b + q (s[q + 1], s[q + 2]).
                [even(0), odd(1), even(1), odd(2), even(2), odd(3), even(3), odd(4), even(4)]
            } else {
                // i = 2q: m = b + q (s[q + 1], s[q + 2]); i = 2q + 1: m = b + q + 1 (taps s[q + 1..q + 4]).
                [odd(1), even(1), odd(2), even(2), odd(3), even(3), odd(4), even(4), odd(5)]
            };
        }
        for j in 0..9 {
            let yy = y - 4 + j;
            let m = yy / 2 - lo;
            let mut out = [0.0f32; 9];
            if yy % 2 == 0 {
                out.iter_mut().zip(&horiz[m - 1]).for_each(|(o, h)| *o = e0 * h);
                out.iter_mut().zip(&horiz[m]).for_each(|(o, h)| *o += e2 * h);
                out.iter_mut().zip(&horiz[m + 1]).for_each(|(o, h)| *o += e0 * h);
            } else {
                out.iter_mut().zip(&horiz[m]).for_each(|(o, h)| *o = o1 * h);
                out.iter_mut().zip(&horiz[m + 1]).for_each(|(o, h)| *o += o1 * h);
            }
            row(j, out);
        }
        return;
    }
    let clamp = |v: usize, k: usize, n: usize| (v as isize + k as isize - 4).clamp(0, n as isize - 1) as usize;
    let xtaps: [[(usize, f32); 3]; 9] = std::array::from_fn(|i| expand_taps(clamp(x, i, width), p.width));
    let ytaps: [[(usize, f32); 3]; 9] = std::array::from_fn(|j| expand_taps(clamp(y, j, height), p.height));
    // The horizontal pass of the source rows the window's vertical taps read (at
    // most 7 distinct rows: the window spans 9 output rows, each reading ≤ 3).
    let rows = ytaps.iter().flatten().filter(|t| t.1 != 0.0).map(|t| t.0);
    let lo = rows.clone().min().unwrap_or(0);
    let hi = rows.max().unwrap_or(0);
    let mut horiz = [[0.0f32; 9]; 9];
    for (r, src) in (lo..=hi).zip(horiz.iter_mut()) {
        let row = &p.data[r * p.width..(r + 1) * p.width];
        for (h, taps) in src.iter_mut().zip(&xtaps) {
            *h = taps.iter().map(|&(j, wt)| wt * row[j]).sum();
        }
    }
    for (j, taps) in ytaps.iter().enumerate() {
        let mut out = [0.0f32; 9];
        let mut taps = taps.iter().filter(|&&(_, wt)| wt != 0.0);
        if let Some(&(r, wt)) = taps.next() {
            out.iter_mut().zip(&horiz[r - lo]).for_each(|(o, h)| *o = wt * h);
        }
        for &(r, wt) in taps {
            out.iter_mut().zip(&horiz[r - lo]).for_each(|(o, h)| *o += wt * h);
        }
        row(j, out);
    }
}

/// Levels 0..=`levels` of the Gaussian pyramid (level 0 is the input).
pub fn gaussian_pyramid(p: &Plane, levels: usize) -> Vec<Plane> {
    gaussian_pyramid_of(p.clone(), levels)
}

/// `gaussian_pyramid` of a plane the caller gives up: level 0 is `p` itself, not a
/// copy (the blind noise fit's first reductions are 1.2 MB per channel at 1280×960).
pub fn gaussian_pyramid_of(p: Plane, levels: usize) -> Vec<Plane> {
    let mut out = Vec::with_capacity(levels + 1);
    out.push(p);
    for l in 0..levels {
        let next = reduce(&out[l]);
        out.push(next);
    }
    out
}

/// `levels` band-pass levels plus the low-pass residual.
#[derive(Clone, Debug)]
pub struct LaplacianPyramid {
    pub bands: Vec<Plane>,
    pub lowpass: Plane,
}

pub fn laplacian_pyramid(p: &Plane, levels: usize) -> LaplacianPyramid {
    let mut bands = Vec::with_capacity(levels);
    let mut cur = p.clone();
    for _ in 0..levels {
        let down = reduce(&cur);
        let up = expand(&down, cur.width, cur.height);
        for (c, u) in cur.data.iter_mut().zip(&up.data) {
            *c -= u;
        }
        bands.push(cur);
        cur = down;
    }
    LaplacianPyramid { bands, lowpass: cur }
}

impl LaplacianPyramid {
    /// Reconstruct: G_l = L_l + expand(G_{l+1}), from the low-pass up.
    pub fn collapse(&self) -> Plane {
        let mut cur = self.lowpass.clone();
        for band in self.bands.iter().rev() {
            let mut up = expand(&cur, band.width, band.height);
            for (u, b) in up.data.iter_mut().zip(&band.data) {
                *u += b;
            }
            cur = up;
        }
        cur
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook form: every tap clamped, rows then columns.
    fn reduce_reference(p: &Plane) -> Plane {
        let (w, h) = (p.width, p.height);
        let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
        let at = |x: isize, y: isize| {
            p.data[(y.clamp(0, h as isize - 1) as usize) * w + x.clamp(0, w as isize - 1) as usize]
        };
        let mut tmp = vec![0.0f32; w2 * h];
        for y in 0..h {
            for x2 in 0..w2 {
                tmp[y * w2 + x2] = (0..5).map(|k| K5[k] * at(2 * x2 as isize + k as isize - 2, y as isize)).sum();
            }
        }
        let mut out = vec![0.0f32; w2 * h2];
        for y2 in 0..h2 {
            for x2 in 0..w2 {
                out[y2 * w2 + x2] = (0..5)
                    .map(|k| {
                        K5[k] * tmp[(2 * y2 as isize + k as isize - 2).clamp(0, h as isize - 1) as usize * w2 + x2]
                    })
                    .sum();
            }
        }
        Plane::from_vec(w2, h2, out)
    }

    fn expand_reference(p: &Plane, width: usize, height: usize) -> Plane {
        let (w, h) = (p.width, p.height);
        let mut tmp = vec![0.0f32; width * h];
        for y in 0..h {
            for x in 0..width {
                tmp[y * width + x] = expand_taps(x, w).iter().map(|&(j, wt)| wt * p.data[y * w + j]).sum();
            }
        }
        let mut out = vec![0.0f32; width * height];
        for y in 0..height {
            for x in 0..width {
                out[y * width + x] = expand_taps(y, h).iter().map(|&(j, wt)| wt * tmp[j * width + x]).sum();
            }
        }
        Plane::from_vec(width, height, out)
    }

    /// The unclamped interior loops compute what the clamped reference does, for
    /// every size from 1 to 13 in each direction (interior empty, one pixel wide,
    /// odd and even) and two larger ones: reduce exactly (the same five products
    /// summed in the same order; an exact zero may differ in sign), expand within
    /// 2 ulp of values ≤ 1 (3e-7 absolute; the order of the same additions differs).
    #[test]
    fn fast_reduce_and_expand_match_the_reference() {
        let sizes = (1..14usize).flat_map(|w| (1..14usize).map(move |h| (w, h)));
        for (w, h) in sizes.chain([(37, 29), (64, 47)]) {
            let p = Plane::from_vec(w, h, (0..w * h).map(|i| ((i * 7919 % 101) as f32 / 101.0).sin()).collect());
            let (a, b) = (reduce(&p), reduce_reference(&p));
            assert_eq!((a.width, a.height), (b.width, b.height));
            for (x, y) in a.data.iter().zip(&b.data) {
                assert!(x == y, "reduce {w}×{h}: {x} vs {y}");
            }
            let (a, b) = (expand(&a, w, h), expand_reference(&b, w, h));
            for (x, y) in a.data.iter().zip(&b.data) {
                assert!((x - y).abs() <= 3e-7, "expand {w}×{h}: {x} vs {y}");
            }
        }
    }

    /// `reduce_slice_visiting` visits every source row once, in increasing order,
    /// and reduces as the plain two-pass reference does (bit for bit): every height
    /// 1–13 and two larger ones (the ring's clamped first and last windows, odd and
    /// even).
    #[test]
    fn reduce_visits_every_row_once_in_order() {
        for (w, h) in (1..14usize).map(|h| (5, h)).chain([(37, 29), (64, 48)]) {
            let data: Vec<f32> = (0..w * h).map(|i| ((i * 7919 % 101) as f32 / 101.0).cos()).collect();
            let mut seen = vec![];
            let p = reduce_slice_visiting(&data, w, h, |y| seen.push(y));
            assert_eq!(seen, (0..h).collect::<Vec<_>>(), "{w}×{h}");
            let want = reduce_reference(&Plane::from_vec(w, h, data.clone()));
            assert!(p.data.iter().zip(&want.data).all(|(a, b)| a == b), "{w}×{h}");
        }
    }

    /// `expand_window9` reads what `expand` writes, bit for bit (an exact zero may
    /// differ in sign only): every window of sizes 1–13 (odd and even, narrower
    /// than the window, the clamped border) and of 41×23 and 42×25 levels (even and
    /// odd outputs) whose windows include interior ones (the closed-form taps).
    #[test]
    fn expand_windows_are_the_expanded_values() {
        for (w, h) in (1..14usize).flat_map(|w| (1..14usize).map(move |h| (w, h))).chain([(41, 23), (42, 25)]) {
            let p = Plane::from_vec(w, h, (0..w * h).map(|i| ((i * 7919 % 101) as f32 / 101.0).sin() - 0.3).collect());
            let (ww, hh) = (2 * w - (w > 1 && w % 3 == 0) as usize, 2 * h);
            let full = expand(&p, ww, hh);
            for y in 0..hh {
                for x in 0..ww {
                    let win = expand_window9(&p, ww, hh, x, y);
                    for (j, row) in win.iter().enumerate() {
                        for (i, &v) in row.iter().enumerate() {
                            let xx = (x as isize + i as isize - 4).clamp(0, ww as isize - 1) as usize;
                            let yy = (y as isize + j as isize - 4).clamp(0, hh as isize - 1) as usize;
                            let want = full.data[yy * ww + xx];
                            assert!(
                                v.to_bits() == want.to_bits() || v == want,
                                "{w}×{h} → {ww}×{hh} at ({xx}, {yy}): {v} vs {want}"
                            );
                        }
                    }
                }
            }
        }
    }
}
