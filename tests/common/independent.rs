//! A second forward model, written without `synth`: the kind of addDoF / addMB /
//! addNoise another implementation would use, so the accurate fits
//! are held to frames they did not make themselves.
//!
//! How it differs from `synth`, on purpose:
//! * defocus: a blend of whole-image Gaussian *layers* σ_j = j·`step` — each a
//!   *sampled* continuous Gaussian truncated at 4σ (scipy's `gaussian_filter`,
//!   OpenCV's float default), reflect-101 borders — blended per pixel linearly in σ
//!   (synth: cascaded discrete Gaussians, variance-matched blend, clamp borders);
//! * motion blur: midpoint rule with Catmull–Rom bicubic reads (synth: trapezoid,
//!   bilinear);
//! * noise: photon counts drawn from a true Poisson law on each channel's own value,
//!   white-balance gains after it, Gaussian read noise, added after the blur and
//!   quantised to 8 bits (synth: Gaussian bands per Laplacian level, std by luma).
//!
//! Nothing here is tuned to the fits; the parameters are the physical ones.

use blind_augment::image::{Flow, Plane, Rgb};

/// SplitMix64: a different generator from `synth::rng`.
pub struct SplitMix(pub u64);

impl SplitMix {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1).
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller, one of the pair).
    pub fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// Poisson(μ): Knuth's product method below 30, Hörmann's PTRS above
    /// ("The transformed rejection method for generating Poisson random
    /// variables", 1993) — exact at every mean, unlike a normal approximation.
    pub fn poisson(&mut self, mu: f64) -> u64 {
        if mu <= 0.0 {
            return 0;
        }
        if mu < 30.0 {
            let l = (-mu).exp();
            let (mut k, mut p) = (0u64, 1.0f64);
            loop {
                p *= self.uniform();
                if p <= l {
                    return k;
                }
                k += 1;
            }
        }
        let slam = mu.sqrt();
        let loglam = mu.ln();
        let b = 0.931 + 2.53 * slam;
        let a = -0.059 + 0.02483 * b;
        let inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
        let vr = 0.9277 - 3.6224 / (b - 2.0);
        loop {
            let u = self.uniform() - 0.5;
            let v = self.uniform();
            let us = 0.5 - u.abs();
            let k = ((2.0 * a / us + b) * u + mu + 0.43).floor();
            if us >= 0.07 && v <= vr {
                return k as u64;
            }
            if k < 0.0 || (us < 0.013 && v > us) {
                continue;
            }
            let lhs = (v * inv_alpha / (a / (us * us) + b)).ln();
            let rhs = -mu + k * loglam - ln_factorial(k);
            if lhs <= rhs {
                return k as u64;
            }
        }
    }
}

/// ln k! (Stirling series past 10; exact below).
fn ln_factorial(k: f64) -> f64 {
    if k < 10.0 {
        return (1..=k as u64).map(|i| (i as f64).ln()).sum();
    }
    let k1 = k + 1.0;
    (k1 - 0.5) * k1.ln() - k1 + 0.5 * std::f64::consts::TAU.ln() + 1.0 / (12.0 * k1) - 1.0 / (360.0 * k1.powi(3))
}

/// Sampled Gaussian, truncated at 4σ, normalised (σ = 0: identity).
pub fn sampled_gaussian(sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let r = (4.0 * sigma).ceil() as isize;
    let mut k: Vec<f32> = (-r..=r).map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp()).collect();
    let s: f32 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

/// Reflect-101 index (… 2 1 | 0 1 2 … n−1 | n−2 …).
fn reflect101(i: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let mut j = i.rem_euclid(period);
    if j >= n {
        j = period - j;
    }
    j as usize
}

/// Separable blur of `src` (w×h) with kernel `k`, output rows `y0..y1` only.
fn blur_rows(src: &[f32], w: usize, h: usize, k: &[f32], y0: usize, y1: usize) -> Vec<f32> {
    let r = (k.len() / 2) as isize;
    let (t0, t1) = ((y0 as isize - r).max(0) as usize, ((y1 as isize + r) as usize).min(h));
    // Horizontal pass over the rows the vertical pass reads (reflected rows map
    // into 0..h; compute every row that can be read).
    let need: Vec<usize> = (0..h).filter(|&y| (t0..t1).contains(&y) || y < r as usize || y + r as usize >= h).collect();
    let mut tmp = vec![0.0f32; w * h];
    for &y in &need {
        for x in 0..w {
            let mut acc = 0.0;
            for (t, &kv) in k.iter().enumerate() {
                acc += kv * src[y * w + reflect101(x as isize + t as isize - r, w)];
            }
            tmp[y * w + x] = acc;
        }
    }
    let mut out = vec![0.0f32; w * (y1 - y0)];
    for y in y0..y1 {
        for x in 0..w {
            let mut acc = 0.0;
            for (t, &kv) in k.iter().enumerate() {
                acc += kv * tmp[reflect101(y as isize + t as isize - r, h) * w + x];
            }
            out[(y - y0) * w + x] = acc;
        }
    }
    out
}

/// Defocus as a blend of Gaussian layers every `step_px`: pixel p with σ(p) between
/// layers j and j+1 takes (1 − t)·L_j + t·L_{j+1}, t = (σ − σ_j)/step (the two
/// weights sum to 1; σ on a layer reads that layer alone).
pub fn layered_defocus(sharp: &Rgb, sigma_px: &[f32], step_px: f32) -> Rgb {
    let (w, h) = (sharp.width, sharp.height);
    let max_sigma = sigma_px.iter().cloned().fold(0.0f32, f32::max);
    let layers = (max_sigma / step_px).ceil() as usize + 1;
    let mut out = Rgb::new(w, h, [0.0; 3]);
    for j in 0..layers {
        let sj = j as f32 * step_px;
        let weight = |s: f32| (1.0 - (s - sj).abs() / step_px).max(0.0);
        // Only the rows holding a pixel that reads layer j are blurred.
        let rows: Vec<usize> = (0..h).filter(|&y| (0..w).any(|x| weight(sigma_px[y * w + x]) > 0.0)).collect();
        let (Some(&y0), Some(&y1)) = (rows.first(), rows.last()) else { continue };
        let k = sampled_gaussian(sj);
        for c in 0..3 {
            let layer = blur_rows(&sharp.channels[c], w, h, &k, y0, y1 + 1);
            for y in y0..=y1 {
                for x in 0..w {
                    let i = y * w + x;
                    let wt = weight(sigma_px[i]);
                    if wt > 0.0 {
                        out.channels[c][i] += wt * layer[(y - y0) * w + x];
                    }
                }
            }
        }
    }
    out
}

/// Catmull–Rom cubic weights for fractional offset t ∈ [0, 1).
fn catmull_rom(t: f32) -> [f32; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2)]
}

fn bicubic(p: &[f32], w: usize, h: usize, x: f32, y: f32) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (wx, wy) = (catmull_rom(x - fx), catmull_rom(y - fy));
    let mut acc = 0.0;
    for (j, wyj) in wy.iter().enumerate() {
        let yy = (fy as isize + j as isize - 1).clamp(0, h as isize - 1) as usize;
        for (i, wxi) in wx.iter().enumerate() {
            let xx = (fx as isize + i as isize - 1).clamp(0, w as isize - 1) as usize;
            acc += wyj * wxi * p[yy * w + xx];
        }
    }
    acc
}

/// Motion blur: the mean of `4·streak + 4` midpoint samples of the bicubic image
/// over the exposure window t ∈ [−λ/2, λ/2] of the frame interval along F(p).
pub fn cubic_motion_blur(sharp: &Rgb, flow: &Flow, lambda: f32) -> Rgb {
    let (w, h) = (sharp.width, sharp.height);
    let mut out = sharp.clone();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (fx, fy) = (flow.dx[i], flow.dy[i]);
            let streak = lambda * (fx * fx + fy * fy).sqrt();
            if streak <= 0.0 {
                continue;
            }
            let n = (4.0 * streak).ceil() as usize + 4;
            for c in 0..3 {
                let mut acc = 0.0;
                for k in 0..n {
                    let t = lambda * ((k as f32 + 0.5) / n as f32 - 0.5);
                    acc += bicubic(&sharp.channels[c], w, h, x as f32 + t * fx, y as f32 + t * fy);
                }
                out.channels[c][i] = acc / n as f32;
            }
        }
    }
    out
}

/// A sensor: `full_well_e` electrons at value 1 on every channel, white-balance
/// gains applied after the photon count, Gaussian read noise (std in output units).
#[derive(Clone, Copy, Debug)]
pub struct Sensor {
    pub full_well_e: f64,
    pub wb_gain: [f64; 3],
    pub read_std: [f64; 3],
}

impl Sensor {
    /// The noise std of channel c at output value v: photons v/g·N at gain g·v/(v/g·N)
    /// → var = g·v/N + read².
    pub fn std_at(&self, c: usize, v: f64) -> f64 {
        (self.wb_gain[c] * v.max(0.0) / self.full_well_e + self.read_std[c].powi(2)).sqrt()
    }

    /// Noise added to `img` (values in [0, 1]), then 8-bit quantisation.
    pub fn expose(&self, img: &Rgb, seed: u64) -> Rgb {
        let mut rng = SplitMix(seed);
        let mut out = img.clone();
        for c in 0..3 {
            let g = self.wb_gain[c];
            for v in out.channels[c].iter_mut() {
                let photons = (v.max(0.0) as f64 / g * self.full_well_e).max(0.0);
                let counted = rng.poisson(photons) as f64 / self.full_well_e * g;
                let read = self.read_std[c] * rng.normal();
                *v = (((counted + read).clamp(0.0, 1.0) * 255.0).round() / 255.0) as f32;
            }
        }
        out
    }
}

/// σ map of a per-depth function over a depth plane (0 where depth is invalid).
pub fn sigma_map(depth: &Plane, f: impl Fn(f32) -> f32) -> Vec<f32> {
    depth.data.iter().map(|&z| if z.is_finite() && z > 0.0 { f(z).max(0.0) } else { 0.0 }).collect()
}
