//! Training pairs for the project's own denoiser (`cargo xtask train-models`): clean
//! crops of real photographs and the same crops with noise synthesised by this
//! crate's noise model (`synth::noise`), so the network learns to remove exactly the
//! kind of noise the camera model describes — white Poisson–Gaussian sensor noise
//! and its spatially correlated variants (demosaicing, in-camera denoising boost or
//! cut individual pyramid levels), with and without 8-bit quantisation.
//!
//! Deterministic: everything derives from `seed`, so the trained model can be
//! reproduced bit-for-bit from the committed photographs.

use super::noise::{add_noise, white_sensor_noise};
use crate::image::{Plane, Rgb};
use crate::model::{Noise, NOISE_LEVELS};

/// Patch pairs in NCHW order (what PyTorch and the ONNX contract use).
#[derive(Clone, Debug)]
pub struct PatchPairs {
    pub count: usize,
    pub patch_px: usize,
    pub clean: Vec<f32>,
    pub noisy: Vec<f32>,
}

/// Small deterministic generator (SplitMix64): the pairs must not depend on a
/// crate's RNG algorithm changing between versions.
pub(crate) struct SplitMix(pub(crate) u64);

impl SplitMix {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [lo, hi).
    pub(crate) fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * ((self.next_u64() >> 40) as f32 / (1u64 << 24) as f32)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

/// A random camera noise model of the family the fit describes: white
/// Poisson–Gaussian (level-0 std between ~0.3/255 and ~20/255 over the luma range,
/// channels differing by up to ±30%), with each coarser level scaled by up to ×2 or
/// ÷2 (correlated noise). Noise-free with probability 0.1, so the network learns to
/// leave clean content alone.
pub fn random_noise_model(rng_seed: u64) -> Noise {
    let mut rng = SplitMix(rng_seed);
    let a0 = 10f32.powf(rng.uniform(-6.0, -3.5));
    let b0 = 10f32.powf(rng.uniform(-5.0, -2.5));
    let tint = |rng: &mut SplitMix| -> [f32; 3] { std::array::from_fn(|_| rng.uniform(0.7, 1.3)) };
    let (ta, tb) = (tint(&mut rng), tint(&mut rng));
    let mut noise =
        white_sensor_noise(std::array::from_fn(|c| a0 * ta[c]), std::array::from_fn(|c| b0 * tb[c]), [0.0, 1.0]);
    for l in 1..NOISE_LEVELS {
        let s = 10f32.powf(rng.uniform(-0.3, 0.3));
        let level = &mut noise.levels[l];
        level.intercept.iter_mut().chain(level.slope.iter_mut()).for_each(|v| *v *= s * s);
    }
    if rng.uniform(0.0, 1.0) < 0.1 {
        noise.present = false;
    }
    noise
}

/// `count` pairs of `patch_px`² crops from `photos` (uniformly chosen; random
/// position, flip, transpose and brightness gain 0.3–1.1), noise added by
/// `random_noise_model`; half of the noisy crops quantised to 8 bits as PNG frames
/// are. The clean crop is the target (unquantised). Noise is synthesised over the
/// crop plus a 16-px border, then cut, so pyramid borders do not shape it.
pub fn denoise_pairs(photos: &[Rgb], count: usize, patch_px: usize, seed: u64) -> PatchPairs {
    let mut rng = SplitMix(seed);
    let per = 3 * patch_px * patch_px;
    let mut out =
        PatchPairs { count, patch_px, clean: Vec::with_capacity(count * per), noisy: Vec::with_capacity(count * per) };
    let border = 16usize;
    let big = patch_px + 2 * border;
    let usable: Vec<&Rgb> = photos.iter().filter(|p| p.width >= big && p.height >= big).collect();
    for _ in 0..count {
        if usable.is_empty() {
            break;
        }
        let photo = usable[rng.below(usable.len())];
        let (x0, y0) = (rng.below(photo.width - big + 1), rng.below(photo.height - big + 1));
        let (flip, transpose) = (rng.below(2) == 1, rng.below(2) == 1);
        let gain = rng.uniform(0.3, 1.1);
        let crop = Rgb::from_planes(std::array::from_fn(|c| {
            let mut p = Plane::new(big, big, 0.0);
            for y in 0..big {
                for x in 0..big {
                    let (mut sx, sy) = if transpose { (y, x) } else { (x, y) };
                    if flip {
                        sx = big - 1 - sx;
                    }
                    p.data[y * big + x] = gain * photo.channels[c][(y0 + sy) * photo.width + x0 + sx];
                }
            }
            p
        }));
        let noise = random_noise_model(rng.next_u64());
        let mut noisy = add_noise(&crop, &noise, rng.next_u64());
        if rng.below(2) == 1 {
            noisy = noisy.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
        }
        for (dst, src) in [(&mut out.clean, &crop), (&mut out.noisy, &noisy)] {
            for c in 0..3 {
                for y in border..border + patch_px {
                    dst.extend_from_slice(&src.channels[c][y * big + border..y * big + border + patch_px]);
                }
            }
        }
    }
    out.count = out.clean.len() / per;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Same seed, same pairs; noisy differs from clean by a plausible amount.
    #[test]
    fn deterministic_and_noisy() {
        let photo = Rgb::from_planes(std::array::from_fn(|c| {
            Plane::from_vec(120, 100, (0..12000).map(|i| ((i * (c + 3)) % 97) as f32 / 97.0).collect())
        }));
        let a = denoise_pairs(std::slice::from_ref(&photo), 6, 32, 7);
        let b = denoise_pairs(std::slice::from_ref(&photo), 6, 32, 7);
        assert_eq!(a.count, 6);
        assert_eq!(a.clean, b.clean);
        assert_eq!(a.noisy, b.noisy);
        assert_eq!(a.clean.len(), 6 * 3 * 32 * 32);
        let rms =
            (a.clean.iter().zip(&a.noisy).map(|(x, y)| (x - y).powi(2)).sum::<f32>() / a.clean.len() as f32).sqrt();
        // Level-0 std between ~0.3/255 and ~0.08 by construction (some pairs clean).
        assert!(rms > 1e-4 && rms < 0.1, "rms {rms}");
        // A photo too small for the crop yields no pairs rather than a panic.
        assert_eq!(denoise_pairs(&[Rgb::new(20, 20, [0.5; 3])], 4, 32, 1).count, 0);
    }
}
