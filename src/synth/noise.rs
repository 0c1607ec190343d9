//! addNoise: Laplacian-pyramid noise synthesis, as in the paper's supplement.
//!
//! 1. white N(0,1) noise per channel (counter-based, seeded);
//! 2. its Laplacian pyramid (4 band-pass levels + low-pass);
//! 3. each level normalised to local std 1 (eq. 8);
//! 4. multiplied by the model's std at that level, from the content's luma at that
//!    level's resolution (Gaussian pyramid of Y);
//! 5. collapsed and added.
//!
//! Step 3: the white field is stationary by construction, so its local std at level
//! l is the same constant c_l everywhere; we divide by c_l (`unit_band_std`)
//! instead of by a 9×9 local estimate of it. The estimate only adds sampling error:
//! at level 3 the window (σ = 0.5 px) sees about three samples, and dividing by
//! such an estimate reshapes the distribution. With the exact constant, scaling
//! every level by the same s reproduces s·N exactly, so white noise of std s
//! round-trips through fit → synth.

use super::rng::gaussian;
use crate::image::{gaussian_pyramid, laplacian_pyramid, Plane, Rgb};
use crate::model::{Noise, NOISE_LEVELS};
use rayon::prelude::*;
use std::sync::OnceLock;

/// Std of each band (levels 0..4, then the low-pass) of the Laplacian pyramid of
/// unit white noise, measured once on a 768×768×3 field (interior and borders
/// pooled; relative standard error ≤ 0.5% at the coarsest band, ≤ 0.1% at level 0).
pub fn unit_band_std() -> &'static [f32; NOISE_LEVELS + 1] {
    static C: OnceLock<[f32; NOISE_LEVELS + 1]> = OnceLock::new();
    C.get_or_init(|| {
        let n = 768usize;
        let mut sums = [0.0f64; NOISE_LEVELS + 1];
        let mut counts = [0usize; NOISE_LEVELS + 1];
        for c in 0..3u32 {
            let data = (0..n * n).map(|i| gaussian((i % n) as u32, (i / n) as u32, c, 0x5eed_c0de)).collect();
            let pyr = laplacian_pyramid(&Plane::from_vec(n, n, data), NOISE_LEVELS);
            for (l, band) in pyr.bands.iter().chain(std::iter::once(&pyr.lowpass)).enumerate() {
                sums[l] += band.data.iter().map(|&v| (v as f64).powi(2)).sum::<f64>();
                counts[l] += band.data.len();
            }
        }
        let mut out = [0.0f32; NOISE_LEVELS + 1];
        for l in 0..=NOISE_LEVELS {
            out[l] = (sums[l] / counts[l] as f64).sqrt() as f32;
        }
        out
    })
}

/// The synthesised noise field (no content added) for content with luma `luma`.
pub fn noise_field(luma: &Plane, noise: &Noise, seed: u64) -> Rgb {
    let (w, h) = (luma.width, luma.height);
    if !noise.present {
        return Rgb::new(w, h, [0.0; 3]);
    }
    let unit = unit_band_std();
    let ypyr = gaussian_pyramid(luma, NOISE_LEVELS);
    let planes: Vec<Plane> = (0..3usize)
        .into_par_iter()
        .map(|c| {
            let white = (0..w * h).map(|i| gaussian((i % w) as u32, (i / w) as u32, c as u32, seed)).collect();
            let mut pyr = laplacian_pyramid(&Plane::from_vec(w, h, white), NOISE_LEVELS);
            for (l, band) in pyr.bands.iter_mut().enumerate() {
                let level = &noise.levels[l];
                let y = &ypyr[l];
                for (v, &yl) in band.data.iter_mut().zip(&y.data) {
                    *v *= level.std(noise.form, c, noise.clamp_luma(yl)) / unit[l];
                }
            }
            match &noise.lowpass {
                Some(level) => {
                    let y = &ypyr[NOISE_LEVELS];
                    for (v, &yl) in pyr.lowpass.data.iter_mut().zip(&y.data) {
                        *v *= level.std(noise.form, c, noise.clamp_luma(yl)) / unit[NOISE_LEVELS];
                    }
                }
                // Zero-mean noise with no low-pass model: drop the residual.
                None => pyr.lowpass.data.iter_mut().for_each(|v| *v = 0.0),
            }
            pyr.collapse()
        })
        .collect();
    let [r, g, b]: [Plane; 3] = planes.try_into().unwrap_or_else(|_| unreachable!("three channels mapped"));
    Rgb::from_planes([r, g, b])
}

/// addNoise(I, σ): `clean` plus synthesised noise; unclipped (an 8-bit writer clips).
pub fn add_noise(clean: &Rgb, noise: &Noise, seed: u64) -> Rgb {
    if !noise.present {
        return clean.clone();
    }
    let field = noise_field(&clean.luma(), noise, seed);
    let mut out = clean.clone();
    for c in 0..3 {
        for (o, n) in out.channels[c].iter_mut().zip(&field.channels[c]) {
            *o += n;
        }
    }
    out
}
