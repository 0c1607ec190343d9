//! Burt–Adelson Gaussian and Laplacian pyramids with the 5-tap binomial kernel
//! [1 4 6 4 1]/16, clamp-to-edge, any size (a level of n pixels reduces to ceil(n/2)).
//! `collapse(laplacian_pyramid(x)) == x` up to float rounding, for every size.

use super::Plane;

const K5: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];

/// Blur with K5 and keep every other sample: size ceil(w/2) × ceil(h/2).
pub fn reduce(p: &Plane) -> Plane {
    let (w, h) = (p.width, p.height);
    let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
    // Rows first: w2 columns at full height.
    let mut tmp = vec![0.0f32; w2 * h];
    for y in 0..h {
        let row = &p.data[y * w..(y + 1) * w];
        for x2 in 0..w2 {
            let cx = 2 * x2 as isize;
            let mut acc = 0.0;
            for (k, wk) in K5.iter().enumerate() {
                let xi = (cx + k as isize - 2).clamp(0, w as isize - 1) as usize;
                acc += wk * row[xi];
            }
            tmp[y * w2 + x2] = acc;
        }
    }
    let mut out = vec![0.0f32; w2 * h2];
    for y2 in 0..h2 {
        let cy = 2 * y2 as isize;
        let o = &mut out[y2 * w2..(y2 + 1) * w2];
        for (k, wk) in K5.iter().enumerate() {
            let yi = (cy + k as isize - 2).clamp(0, h as isize - 1) as usize;
            let src = &tmp[yi * w2..(yi + 1) * w2];
            for (ov, sv) in o.iter_mut().zip(src) {
                *ov += wk * sv;
            }
        }
    }
    Plane::from_vec(w2, h2, out)
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
    let mut tmp = vec![0.0f32; width * h];
    for y in 0..h {
        let row = &p.data[y * w..(y + 1) * w];
        for (x, taps) in xtaps.iter().enumerate() {
            tmp[y * width + x] = taps.iter().map(|&(j, wt)| wt * row[j]).sum();
        }
    }
    let mut out = vec![0.0f32; width * height];
    for y in 0..height {
        let o = &mut out[y * width..(y + 1) * width];
        for (j, wt) in expand_taps(y, h) {
            if wt == 0.0 {
                continue;
            }
            let src = &tmp[j * width..(j + 1) * width];
            for (ov, sv) in o.iter_mut().zip(src) {
                *ov += wt * sv;
            }
        }
    }
    Plane::from_vec(width, height, out)
}

/// Levels 0..=`levels` of the Gaussian pyramid (level 0 is the input).
pub fn gaussian_pyramid(p: &Plane, levels: usize) -> Vec<Plane> {
    let mut out = Vec::with_capacity(levels + 1);
    out.push(p.clone());
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
