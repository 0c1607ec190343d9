//! Blind defocus from the spectrum: the signature of a round aperture (a disc PSF)
//! in one frame, for the kernel-shape decision and for frames defocused uniformly.
//!
//! A disc of radius R has the transfer function 2·J₁(2πRf)/(2πRf): rings of zeros at
//! f = j₁ₖ/(2πR) (j₁ₖ = 3.832, 7.016, 10.17, …), asymptotically 1/(2R) apart. The mean
//! log power spectrum over many tiles is the scene's mean log spectrum plus
//! log|H|², so the zeros survive averaging as notches while scene structure
//! averages out; in the power cepstrum (inverse FFT of the log spectrum) the
//! periodic notches are a negative ring at quefrency ≈ 2R. A Gaussian PSF has no
//! zeros: its log spectrum is a smooth paraboloid, cepstrally concentrated at the
//! origin — but where it meets the noise floor the knee also makes a dip, so the
//! ring alone does not prove a disc. The decision takes two tests:
//!
//! 1. **ring**: the radial cepstrum's minimum over quefrencies 4 … T/2 − 4 stands out
//!    from the rest of the profile by ≥ `RING_MIN_Z` robust standard deviations
//!    (median/MAD), located to a sub-sample by a parabola;
//! 2. **notch**: at the R the ring implies, the radial log spectrum at the second zero
//!    (7.016/(2πR)) lies ≥ `NOTCH_MIN_CONTRAST` below the chord between the
//!    neighbouring sidelobe peaks (J₂ zeros 5.136 and 8.417), the chord taken in log
//!    frequency so a power-law scene spectrum (straight in log–log) gives 0 and a
//!    Gaussian's smooth fall gives ≈ 0. The first zero is not used: it sits where the
//!    scene's own spectrum bends most.
//!
//! Measured (tests/real_blur.rs: 8-bit, noise std 0.01, the two bundled
//! photographs): discs of σ 1.5–8 px on the 512² astronaut and σ 3–4.5 px on the
//! 451×300 cat give rings of z 7.0–96 and notch contrasts 0.29–2.2; Gaussians of σ
//! 1–8 px and the sharp frames give notch contrasts ≤ 0.13 (rings up to z 12.2 at
//! σ 8: the knee); the real defocused photograph z 31, contrast 0.22. The real
//! photograph clears the 0.18 threshold by a thin margin — stated, not hidden. Discs under R ≈ 2.7 px
//! (σ ≈ 1.4) put the second notch past Nyquist: undecidable, reported as Gaussian
//! (a blur that small looks nearly the same drawn either way).
//!
//! Size: 2R = dip + 0.5 (the parabola's offset of the broad cepstral dip, measured
//! 0.1–1.3 px over R 3–15 on the astronaut photo in a NumPy prototype), σ = √(R²/4 + 1/12) (the
//! pixel-sampled disc's second moment, `model::kernels::disc_radius_px`). Its
//! standard error is the split-half one: the radius from even and from odd tiles.

use crate::image::Plane;
use rustfft::num_complex::Complex32;
use rustfft::FftPlanner;

/// Ring significance (robust z of the cepstral dip) a disc needs.
pub const RING_MIN_Z: f32 = 4.0;
/// Second-notch depth below the log-frequency sidelobe chord (nats of power).
pub const NOTCH_MIN_CONTRAST: f32 = 0.18;
/// Least standard error of `sigma_px` (see `disc_signature`).
const STDERR_FLOOR_PX: f32 = 0.15;
/// Tiles averaged at most (evenly spread): the cost bound. 8 tiles of 256² cost
/// ~5.7 ms on one core at 1280×960 with the radial bins shared (12 cost 8.8 ms, and
/// ~15 ms before the transposed FFT and the halved `ln` calls; ~5.0 ms with two
/// tiles per forward transform, against 6.2 in the same run; ~2.6 ms since the three
/// cepstra share one inverse transform and the logarithms run in lanes); the real photograph
/// of tests/real_blur.rs was always read from 8, and its disc/Gaussian decisions and
/// sizes pass unchanged at 8.
const MAX_TILES: usize = 8;
/// A tile with less mean squared gradient than this (per px², luma in [0, 1]) is
/// flat: it adds only noise to the mean log spectrum.
const TILE_MIN_GRAD_SQ: f32 = 1e-5;

/// What the spectrum says about a disc PSF.
#[derive(Clone, Debug, PartialEq)]
pub struct DiscSignature {
    /// Disc radius (px) from the cepstral ring.
    pub radius_px: f32,
    /// Std of the Gaussian of the same second moment (what the model stores).
    pub sigma_px: f32,
    /// Split-half standard error of `sigma_px` (px).
    pub stderr_px: f32,
    /// Robust z of the ring.
    pub ring_z: f32,
    /// Depth of the second notch below the sidelobe chord (nats); NaN when the notch
    /// lies past Nyquist (R too small to judge).
    pub notch_contrast: f32,
    /// Tiles averaged and their size (px).
    pub tiles: usize,
    pub tile_px: usize,
    /// Both tests passed: a disc PSF of `radius_px` is present.
    pub is_disc: bool,
}

/// The symmetric Hann window of `n` samples.
pub(crate) fn hann(n: usize) -> Vec<f32> {
    (0..n).map(|i| 0.5 - 0.5 * (2.0 * std::f32::consts::PI * i as f32 / (n - 1) as f32).cos()).collect()
}

/// 2-D FFT of the `t`×`t` array `buf`, left **transposed** in `buf`: all rows in one
/// call, a cache-blocked transpose into `tmp`, all rows again, the buffers swapped. Every
/// consumer here is a radial average or a round trip through this same function, both
/// blind to the transpose, so the transpose back is skipped. (Column FFTs through a
/// strided gather cost ~0.4 ms per 256² array, more than the FFTs themselves.)
fn fft2(
    buf: &mut Vec<Complex32>,
    tmp: &mut Vec<Complex32>,
    scratch: &mut Vec<Complex32>,
    t: usize,
    fft: &std::sync::Arc<dyn rustfft::Fft<f32>>,
) {
    // One scratch buffer for every transform of the frame (grown to the largest plan).
    if scratch.len() < fft.get_inplace_scratch_len() {
        scratch.resize(fft.get_inplace_scratch_len(), Complex32::new(0.0, 0.0));
    }
    let scratch = &mut scratch[..fft.get_inplace_scratch_len()];
    fft.process_with_scratch(buf, scratch);
    const B: usize = 16;
    for by in (0..t).step_by(B) {
        for bx in (0..t).step_by(B) {
            for y in by..(by + B).min(t) {
                for x in bx..(bx + B).min(t) {
                    tmp[x * t + y] = buf[y * t + x];
                }
            }
        }
    }
    fft.process_with_scratch(tmp, scratch);
    // The result is in `tmp`: the buffers trade places (no copy back).
    std::mem::swap(buf, tmp);
}

/// `p[i] ← ln(p[i] + 1e-10)` (the floor keeps an exact zero of power finite), eight
/// lanes at a time by `wide` (Cephes' single-precision `logf`, within ~1 ulp of
/// libm's); a remainder past a multiple of 8 takes libm's.
fn ln_of(p: &mut [f32]) {
    let mut chunks = p.chunks_exact_mut(8);
    for v in &mut chunks {
        let lanes: [f32; 8] = std::array::from_fn(|k| v[k]);
        let l = (wide::f32x8::from(lanes) + wide::f32x8::splat(1e-10)).ln();
        v.copy_from_slice(&l.to_array());
    }
    for v in chunks.into_remainder() {
        *v = (*v + 1e-10).ln();
    }
}

/// Row `r` of the `t`-wide array `s` plus `l`.
fn add_row(s: &mut [f32], r: usize, l: &[f32]) {
    let t = l.len();
    for (o, v) in s[r * t..(r + 1) * t].iter_mut().zip(l) {
        *o += v;
    }
}

/// Radial bins of a `t`×`t` array in FFT layout (wrapped frequencies), bins of 1:
/// each element's rounded radius, or `t / 2` (past the last bin). Computed once (per
/// process for the tile sizes used) for the radial averages (`sqrt` + `roundf` per
/// element each time was ~2 ms at 256²; once per frame still 0.2 ms).
fn radial_bins(t: usize) -> std::borrow::Cow<'static, [u32]> {
    // The two tile sizes `disc_signature` uses are built once per process.
    static BINS: std::sync::OnceLock<[Vec<u32>; 2]> = std::sync::OnceLock::new();
    let [b128, b256] = BINS.get_or_init(|| [radial_bins_of(128), radial_bins_of(256)]);
    match t {
        128 => b128.as_slice().into(),
        256 => b256.as_slice().into(),
        _ => radial_bins_of(t).into(),
    }
}

fn radial_bins_of(t: usize) -> Vec<u32> {
    let half = t / 2;
    let mut bins = Vec::with_capacity(t * t);
    for y in 0..t {
        let fy = y.min(t - y) as f32;
        for x in 0..t {
            let fx = x.min(t - x) as f32;
            bins.push(((fx * fx + fy * fy).sqrt().round() as usize).min(half) as u32);
        }
    }
    bins
}

/// Radial average of a `t`×`t` array in FFT layout over `radial_bins(t)`.
fn radial(a: &[f32], bins: &[u32], t: usize) -> Vec<f32> {
    let half = t / 2;
    let (mut sum, mut n) = (vec![0.0f64; half + 1], vec![0u32; half + 1]);
    for (&v, &k) in a.iter().zip(bins) {
        sum[k as usize] += v as f64;
        n[k as usize] += 1;
    }
    sum[..half].iter().zip(&n).map(|(s, &c)| if c > 0 { (*s / c as f64) as f32 } else { 0.0 }).collect()
}

/// The ring: (sub-sample quefrency of the dip, robust z).
fn ring(cep: &[f32]) -> Option<(f32, f32)> {
    let (lo, hi) = (4usize, cep.len().checked_sub(4)?);
    if hi <= lo + 6 {
        return None;
    }
    let i = (lo..hi).min_by(|&a, &b| cep[a].total_cmp(&cep[b]))?;
    let b = cep[i];
    let mut others: Vec<f32> = (lo..hi).filter(|&k| k + 2 < i || k > i + 2).map(|k| cep[k]).collect();
    others.sort_by(f32::total_cmp);
    let med = others[others.len() / 2];
    let mut dev: Vec<f32> = others.iter().map(|v| (v - med).abs()).collect();
    dev.sort_by(f32::total_cmp);
    let mad = 1.4826 * dev[dev.len() / 2] + 1e-12;
    Some((refined(cep, i), (med - b) / mad))
}

/// Sub-sample position of the minimum at interior index `i`: the parabola through
/// it and its neighbours, moved at most half a sample.
fn refined(cep: &[f32], i: usize) -> f32 {
    let (a, b, c) = (cep[i - 1], cep[i], cep[i + 1]);
    let den = a - 2.0 * b + c;
    let off = if den.abs() > 1e-12 { (0.5 * (a - c) / den).clamp(-0.5, 0.5) } else { 0.0 };
    i as f32 + off
}

/// The dip of `cep` nearest in kind to `ring`'s at `dip`: its least value within
/// [dip/`NEAR`, dip·`NEAR`] (and `ring`'s own bounds), refined like `ring`'s, or None
/// where that least value lies on the window's edge (no dip there).
fn dip_near(cep: &[f32], dip: f32) -> Option<f32> {
    const NEAR: f32 = 1.3;
    let (lo, hi) = (4usize, cep.len().checked_sub(4)?);
    let a = ((dip / NEAR).floor() as usize).max(lo);
    let b = ((dip * NEAR).ceil() as usize).min(hi - 1);
    if b < a + 2 {
        return None;
    }
    let i = (a..=b).min_by(|&x, &y| cep[x].total_cmp(&cep[y]))?;
    (i != a && i != b).then(|| refined(cep, i))
}

/// Second-notch contrast at radius `r` (see module docs); NaN past Nyquist.
fn notch_contrast(spec: &[f32], t: usize, r: f32) -> f32 {
    let f = |j: f32| j / (2.0 * std::f32::consts::PI * r);
    let (p1, z2, p2) = (f(5.1356), f(7.0156), f(8.4172));
    if p2 * t as f32 >= (spec.len() - 1) as f32 {
        return f32::NAN;
    }
    let val = |fr: f32| {
        let k = fr * t as f32;
        let k0 = k.floor() as usize;
        let a = k - k0 as f32;
        spec[k0] * (1.0 - a) + spec[(k0 + 1).min(spec.len() - 1)] * a
    };
    let w = (z2.ln() - p1.ln()) / (p2.ln() - p1.ln());
    (1.0 - w) * val(p1) + w * val(p2) - val(z2)
}

fn sigma_of_dip(dip: f32) -> (f32, f32) {
    let r = 0.5 * (dip + 0.5);
    (r, (0.25 * r * r + 1.0 / 12.0).sqrt())
}

/// The disc signature of `luma` over the tiles `keep(x0, y0, size)` accepts (e.g.
/// tiles with valid depth). `None` when the frame holds too few textured tiles
/// (fewer than 2 of 128 px).
pub fn disc_signature(luma: &Plane, keep: impl Fn(usize, usize, usize) -> bool) -> Option<DiscSignature> {
    let (w, h) = (luma.width, luma.height);
    // Half-overlapping tiles; 256 px (finer quefrency, reaches R ≈ 60) when the frame
    // holds at least 4, else 128.
    let origins = |t: usize| -> Vec<(usize, usize)> {
        if w < t || h < t {
            return vec![];
        }
        let (nx, ny) = ((w - t) / (t / 2) + 1, (h - t) / (t / 2) + 1);
        (0..ny).flat_map(|j| (0..nx).map(move |i| (i * t / 2, j * t / 2))).filter(|&(x, y)| keep(x, y, t)).collect()
    };
    // A tile is textured where its mean squared gradient over every 4th pixel each
    // way (x, y ≡ 1 mod 4 from its origin; a mean, not a maximum: a sparse grid
    // estimates it as well as a dense one) reaches `TILE_MIN_GRAD_SQ`. Both tile
    // sizes' origins are multiples of `GRAD_BLOCK_PX`, so every tile is a union of
    // whole blocks whose lattice points are the tile's: each block's sum is made
    // once, on first use, and a tile adds its blocks' — a loop per tile read every
    // point of the half-overlapping tiles four times (~1.7% of the fast tier's time
    // at 1280×960, by perf). The sums are f64 over f32 terms, so the order moves the
    // mean by ~1e-16 relative: the same decision unless it sits that close to the
    // threshold.
    const GRAD_BLOCK_PX: usize = 64;
    let bw = w / GRAD_BLOCK_PX;
    let mut block_sums: Vec<Option<f64>> = vec![None; bw * (h / GRAD_BLOCK_PX)];
    let mut block_sum = |bx: usize, by: usize| -> f64 {
        *block_sums[by * bw + bx].get_or_insert_with(|| {
            let (x0, y0) = (bx * GRAD_BLOCK_PX, by * GRAD_BLOCK_PX);
            let mut g = 0.0f64;
            for y in (y0 + 1..y0 + GRAD_BLOCK_PX).step_by(4) {
                for x in (x0 + 1..x0 + GRAD_BLOCK_PX).step_by(4) {
                    let gx = 0.5 * (luma.get(x + 1, y) - luma.get(x - 1, y));
                    let gy = 0.5 * (luma.get(x, y + 1) - luma.get(x, y - 1));
                    g += (gx * gx + gy * gy) as f64;
                }
            }
            g
        })
    };
    let mut textured = |t: usize| -> Vec<(usize, usize)> {
        debug_assert_eq!(t % GRAD_BLOCK_PX, 0);
        let (nb, n) = (t / GRAD_BLOCK_PX, (t / 4) * (t / 4));
        origins(t)
            .into_iter()
            .filter(|&(x0, y0)| {
                let (bx, by) = (x0 / GRAD_BLOCK_PX, y0 / GRAD_BLOCK_PX);
                let g: f64 =
                    (by..by + nb).flat_map(|j| (bx..bx + nb).map(move |i| (i, j))).map(|(i, j)| block_sum(i, j)).sum();
                g / n as f64 >= TILE_MIN_GRAD_SQ as f64
            })
            .collect()
    };
    let (t, mut tiles) = match textured(256) {
        v if v.len() >= 4 => (256, v),
        _ => (128, textured(128)),
    };
    if tiles.len() < 2 {
        return None;
    }
    if tiles.len() > MAX_TILES {
        let n = tiles.len();
        tiles = (0..MAX_TILES).map(|i| tiles[i * n / MAX_TILES]).collect();
    }
    let win = hann(t);
    let mut planner = FftPlanner::<f32>::new();
    let fwd = planner.plan_fft_forward(t);
    let inv = planner.plan_fft_inverse(t);
    // Mean log power spectra: all tiles, even tiles, odd tiles (split half).
    let mut sums = [vec![0.0f32; t * t], vec![0.0f32; t * t]];
    let mut buf = vec![Complex32::new(0.0, 0.0); t * t];
    let (mut tmp, mut scratch) = (buf.clone(), vec![]);
    // One row of each unpacked tile's power.
    let (mut p0, mut p1) = (vec![0.0f32; t], vec![0.0f32; t]);
    // Two real tiles per complex transform: tile 2m in the real part, tile 2m + 1
    // in the imaginary part, Z = A + iB. A real tile's spectrum is Hermitian, so
    // A(f) = (Z(f) + Z̄(−f))/2 and B(f) = (Z(f) − Z̄(−f))/(2i): half the forward
    // FFTs (8 tiles: 4 transforms), the same spectra to rounding. The even tiles
    // feed the first split half, the odd the second, as before.
    // Row y of the tile at (x0, y0), as a slice (one bounds check per row).
    let row = |x0: usize, y0: usize, y: usize| &luma.data[(y0 + y) * w + x0..(y0 + y) * w + x0 + t];
    // The tile's mean in f64 over 8 lanes (one serial chain of 65 536 dependent
    // additions was ~0.7 ms of the spectrum at 256²; the lanes vectorise). The
    // reordering moves the f64 sum by ~1e-16 relative, far below the f32 the mean is
    // rounded to: the same f32 mean unless the sum sits that close to a rounding
    // boundary (20 frames' signatures identical, BENCHMARKS.md).
    let mean_of_tile = |x0: usize, y0: usize| -> f32 {
        let mut lanes = [0.0f64; 8];
        for y in 0..t {
            let r = row(x0, y0, y);
            let chunks = r.chunks_exact(8);
            for (k, &v) in chunks.remainder().iter().enumerate() {
                lanes[k] += v as f64;
            }
            for c in chunks {
                for (l, &v) in lanes.iter_mut().zip(c) {
                    *l += v as f64;
                }
            }
        }
        (lanes.iter().sum::<f64>() / (t * t) as f64) as f32
    };
    for pair in tiles.chunks(2) {
        let (x0, y0) = pair[0];
        let m0 = mean_of_tile(x0, y0);
        let second = pair.get(1).map(|&(x1, y1)| (x1, y1, mean_of_tile(x1, y1)));
        for (y, out) in buf.chunks_exact_mut(t).enumerate() {
            let a = row(x0, y0, y);
            match second {
                Some((x1, y1, m1)) => {
                    let b = row(x1, y1, y);
                    for (x, o) in out.iter_mut().enumerate() {
                        let wxy = win[x] * win[y];
                        *o = Complex32::new((a[x] - m0) * wxy, (b[x] - m1) * wxy);
                    }
                }
                None => {
                    for (x, o) in out.iter_mut().enumerate() {
                        let wxy = win[x] * win[y];
                        *o = Complex32::new((a[x] - m0) * wxy, 0.0);
                    }
                }
            }
        }
        fft2(&mut buf, &mut tmp, &mut scratch, t, &fwd);
        // Each tile's log power, row by row: the power of every element into a row
        // buffer, then its logarithms eight at a time (`add_ln`). The transform is
        // transposed (`fft2`); the point reflection −f that unpacks the two tiles is
        // the same in either layout: row r's mirror is row (t − r) mod t, reversed
        // about column 0.
        let [s0, s1] = &mut sums;
        // Rows 0 … t/2 computed; row r's logarithms also go to its mirror row
        // (their powers are the same, bit for bit: conjugation and the sum's
        // operands swapped are exact), so the rows past t/2 compute nothing.
        let mirror_add = |s: &mut [f32], r: usize, l: &[f32]| {
            let mr = (t - r) % t;
            if mr != r {
                let out = &mut s[mr * t..(mr + 1) * t];
                out[0] += l[0];
                for (o, v) in out[1..].iter_mut().zip(l[1..].iter().rev()) {
                    *o += v;
                }
            }
        };
        for r in 0..=t / 2 {
            let mr = (t - r) % t;
            let (row, mirror) = (&buf[r * t..(r + 1) * t], &buf[mr * t..(mr + 1) * t]);
            match second {
                Some(_) => {
                    // Column c's mirror is column (t − c) mod t: 0 for c = 0, then the
                    // mirror row read backwards from its end (a division per element
                    // as `% t` was ~20% of this function's own time by perf).
                    let unpack =
                        |zi: Complex32, zj: Complex32| (0.25 * (zi + zj).norm_sqr(), 0.25 * (zi - zj).norm_sqr());
                    (p0[0], p1[0]) = unpack(row[0], mirror[0].conj());
                    let cols = p0[1..].iter_mut().zip(&mut p1[1..]);
                    for ((a, b), (&zi, zm)) in cols.zip(row[1..].iter().zip(mirror[1..].iter().rev())) {
                        (*a, *b) = unpack(zi, zm.conj());
                    }
                    ln_of(&mut p0);
                    ln_of(&mut p1);
                    add_row(s0, r, &p0);
                    add_row(s1, r, &p1);
                    mirror_add(s0, r, &p0);
                    mirror_add(s1, r, &p1);
                }
                None => {
                    for (p, z) in p0.iter_mut().zip(row) {
                        *p = z.norm_sqr();
                    }
                    ln_of(&mut p0);
                    add_row(s0, r, &p0);
                    mirror_add(s0, r, &p0);
                }
            }
        }
    }
    let halves = [tiles.len().div_ceil(2), tiles.len() / 2];
    let bins = radial_bins(t);
    // The radial cepstra of the two halves' summed log spectra, from one inverse
    // transform: each sum is real and even (P(−f) = P(f)), so its cepstrum is real,
    // and Z = S₀ + iS₁ transforms to C₀ + iC₁. The inverse transform and the radial
    // average are linear, so the whole set's radial cepstrum, of (S₀ + S₁)/N, is
    // (R₀ + R₁)/N and each half's R_k/N_k: one inverse 2-D FFT instead of three,
    // the same cepstra to rounding.
    for ((b, &a), &c) in buf.iter_mut().zip(&sums[0]).zip(&sums[1]) {
        *b = Complex32::new(a, c);
    }
    // The log spectra are transposed (see `fft2`); the inverse transposes them back.
    fft2(&mut buf, &mut tmp, &mut scratch, t, &inv);
    let norm = 1.0 / (t * t) as f32;
    let cep_re: Vec<f32> = buf.iter().map(|c| c.re * norm).collect();
    let cep_im: Vec<f32> = buf.iter().map(|c| c.im * norm).collect();
    let radial_cep = [radial(&cep_re, &bins, t), radial(&cep_im, &bins, t)];
    let n_tiles = tiles.len() as f32;
    let cep_all: Vec<f32> = radial_cep[0].iter().zip(&radial_cep[1]).map(|(a, b)| (a + b) / n_tiles).collect();
    let (dip, z) = ring(&cep_all)?;
    // The radial spectrum for the notch: of all tiles only (the split halves' dips
    // are all their spread needs).
    let all: Vec<f32> = sums[0].iter().zip(&sums[1]).map(|(a, b)| (a + b) / n_tiles).collect();
    let spec = radial(&all, &bins, t);
    let (radius_px, sigma_px) = sigma_of_dip(dip);
    let notch = notch_contrast(&spec, t, radius_px);
    // Split half: each half's dip (when both halves hold tiles).
    // Floor: the dip→radius mapping's own spread (2R − dip measured 0.1–1.3 px, so
    // ±0.3 px in R, ±0.15 px in σ), which no split of the tiles reveals.
    let stderr_px = STDERR_FLOOR_PX.max(if halves[1] > 0 {
        let mean_of = |k: usize| -> Vec<f32> { radial_cep[k].iter().map(|v| v / halves[k] as f32).collect() };
        // Each half's dip near the whole set's (`dip_near`): the spread of that ring,
        // not of whatever minimum a half's noisier cepstrum has elsewhere (chelsea
        // under a σ 2 px disc: the whole set's ring at 7.6 px, z 33; one half's at
        // 7.5, the other's global minimum at 38.0, z 4.9 — ± 3.8 px for a σ read
        // within 2.3%).
        match (dip_near(&mean_of(0), dip), dip_near(&mean_of(1), dip)) {
            (Some(d0), Some(d1)) => 0.5 * (sigma_of_dip(d0).1 - sigma_of_dip(d1).1).abs(),
            _ => f32::INFINITY,
        }
    } else {
        f32::INFINITY
    });
    let is_disc = z >= RING_MIN_Z && notch >= NOTCH_MIN_CONTRAST;
    Some(DiscSignature {
        radius_px,
        sigma_px,
        stderr_px,
        ring_z: z,
        notch_contrast: notch,
        tiles: tiles.len(),
        tile_px: t,
        is_disc,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `dip_near` reads the ring near the given dip, not a deeper minimum elsewhere
    /// (which `ring` takes), to the same sub-sample refinement; a window whose least
    /// value is on its edge holds no dip.
    #[test]
    fn dip_near_reads_the_ring_near_the_whole_sets() {
        // A shallow dip at 7.25 and a deeper one at 38.
        let mut cep: Vec<f32> = (0..64).map(|k| 0.01 * ((k * 7 % 5) as f32 - 2.0) * 0.01).collect();
        for (k, v) in [(6usize, -0.5f32), (7, -1.0), (8, -0.5), (37, -1.0), (38, -2.0), (39, -1.0)] {
            cep[k] = v;
        }
        assert_eq!(ring(&cep).map(|r| r.0), Some(38.0));
        let near = dip_near(&cep, 7.6).expect("a dip near 7.6");
        assert!((near - 7.0).abs() < 1e-6, "{near}");
        // Asymmetric neighbours move it by the parabola's offset, as in `ring`.
        cep[8] = -0.8;
        let near = dip_near(&cep, 7.6).expect("a dip near 7.6");
        let (a, b, c) = (-0.5f32, -1.0f32, -0.8f32);
        assert!((near - (7.0 + 0.5 * (a - c) / (a - 2.0 * b + c))).abs() < 1e-6, "{near}");
        // A monotone stretch: the least value on the window's edge, no dip.
        let ramp: Vec<f32> = (0..64).map(|k| k as f32).collect();
        assert_eq!(dip_near(&ramp, 20.0), None);
    }
}
