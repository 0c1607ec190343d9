//! addNoise: Laplacian-pyramid noise synthesis, as in the paper's supplement.
//!
//! 1. white N(0,1) noise per channel (counter-based, seeded);
//! 2. its Laplacian pyramid (4 band-pass levels + low-pass);
//! 3. each level normalised to local std 1 (eq. 8);
//! 4. multiplied by the model's std at that level, from the content's luma at that
//!    level's resolution (Gaussian pyramid of Y);
//! 5. collapsed and added.
//!
//! Step 4 is calibrated (`SynthesisTable`): because the pyramid is overcomplete,
//! re-analysing noise made from independently weighted bands leaks energy between
//! levels (measured: for demosaic-like correlated noise, level 1 came back 26% low
//! and the total std 5% low). The weights are solved so that the analysis of the
//! synthesised noise reproduces the model on flat content; for white noise they
//! reduce to the plain model std / c_l.
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
use crate::model::{Noise, NoiseIntensity, NOISE_LEVELS};
use rayon::prelude::*;

/// Std of each band (levels 0..4, then the low-pass) of the Laplacian pyramid of
/// unit white noise, measured on a 768×768×3 field (interior and borders pooled;
/// relative standard error ≤ 0.5% at the coarsest band, ≤ 0.1% at level 0). The
/// measurement (`measure_unit_band_std`) is stored in `measured.rs`: computed on
/// first use it cost every fresh process ~50 ms (the fits and the grain table read
/// it); `measured::tests` holds the stored values to a fresh measurement.
pub fn unit_band_std() -> &'static [f32; NOISE_LEVELS + 1] {
    &super::measured::UNIT_BAND_STD
}

#[cfg(test)]
pub(super) fn measure_unit_band_std() -> [f32; NOISE_LEVELS + 1] {
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
}

pub(super) const BANDS: usize = NOISE_LEVELS + 1;

/// Cross-level energy transfer of the pyramid, M[m][l][l'] = mean over pixels of
/// A_m(E_l)·A_m(E_l'), where E_l is the image collapsed from band l alone of the
/// Laplacian pyramid of unit white noise and A_m is band m of its re-analysis.
/// The Laplacian pyramid is overcomplete: a band re-weighted on its own is not the
/// band of any image, so re-analysing synthesised noise leaks energy between
/// neighbouring levels. Analysis is linear, so for band weights w the variance of
/// analysed band m is Σ_{l,l'} w_l w_l' M[m][l][l']. Measured on 512×512×3
/// (`measure_transfer`), stored in `measured.rs` like `unit_band_std`.
fn transfer() -> &'static [[[f64; BANDS]; BANDS]; BANDS] {
    &super::measured::TRANSFER
}

#[cfg(test)]
pub(super) fn measure_transfer() -> [[[f64; BANDS]; BANDS]; BANDS] {
    let n = 512usize;
    let mut m = [[[0.0f64; BANDS]; BANDS]; BANDS];
    let mut count = [0usize; BANDS];
    for c in 0..3u32 {
        let data = (0..n * n).map(|i| gaussian((i % n) as u32, (i / n) as u32, c, 0x7a5f)).collect();
        let pyr = laplacian_pyramid(&Plane::from_vec(n, n, data), NOISE_LEVELS);
        // Analysed bands of each single-band image.
        let analysed: Vec<Vec<Plane>> = (0..BANDS)
            .map(|l| {
                let mut only = pyr.clone();
                for (k, b) in only.bands.iter_mut().enumerate() {
                    if k != l {
                        b.data.iter_mut().for_each(|v| *v = 0.0);
                    }
                }
                if l != NOISE_LEVELS {
                    only.lowpass.data.iter_mut().for_each(|v| *v = 0.0);
                }
                let a = laplacian_pyramid(&only.collapse(), NOISE_LEVELS);
                let mut v = a.bands;
                v.push(a.lowpass);
                v
            })
            .collect();
        for mm in 0..BANDS {
            count[mm] += analysed[0][mm].data.len();
            for l in 0..BANDS {
                for l2 in 0..BANDS {
                    let dot: f64 = analysed[l][mm]
                        .data
                        .iter()
                        .zip(&analysed[l2][mm].data)
                        .map(|(a, b)| *a as f64 * *b as f64)
                        .sum();
                    m[mm][l][l2] += dot;
                }
            }
        }
    }
    for mm in 0..BANDS {
        for l in 0..BANDS {
            for l2 in 0..BANDS {
                m[mm][l][l2] /= count[mm] as f64;
            }
        }
    }
    m
}

/// Band weights (multipliers of the raw white-noise bands) whose analysed per-band
/// stds equal `target` (bands without a target get weight 0 and are not matched).
/// Fixed point w_m ← w_m·√(target_m² / predicted_m), from the naive w = target/c.
fn solve_weights(target: &[Option<f64>; BANDS]) -> [f64; BANDS] {
    let m = transfer();
    let unit = unit_band_std();
    let mut w: [f64; BANDS] = std::array::from_fn(|l| target[l].map_or(0.0, |t| t / unit[l] as f64));
    for _ in 0..60 {
        let mut change = 0.0f64;
        for mm in 0..BANDS {
            let Some(t) = target[mm] else { continue };
            let mut pred = 0.0;
            for l in 0..BANDS {
                for l2 in 0..BANDS {
                    pred += w[l] * w[l2] * m[mm][l][l2];
                }
            }
            if pred > 1e-30 && t > 0.0 {
                let f = (t * t / pred).sqrt().clamp(0.5, 2.0);
                w[mm] *= f;
                change = change.max((f - 1.0).abs());
            } else {
                w[mm] = 0.0;
            }
        }
        if change < 1e-7 {
            break;
        }
    }
    w
}

/// Per-channel band weights on a luma grid over the model's range, so that the
/// Laplacian analysis of the synthesised noise on flat content reproduces the
/// model's per-level stds exactly, white or not. 33 nodes, linear in luma.
pub struct SynthesisTable {
    luma_lo: f32,
    luma_hi: f32,
    /// [node][channel][band]
    weights: Vec<[[f32; BANDS]; 3]>,
}

const TABLE_NODES: usize = crate::model::GRAIN_TABLE_NODES;

impl SynthesisTable {
    pub fn new(noise: &Noise) -> Self {
        let [lo, hi] = noise.luminance_range;
        let weights = (0..TABLE_NODES)
            .map(|k| {
                let y = lo + (hi - lo) * k as f32 / (TABLE_NODES - 1) as f32;
                std::array::from_fn(|c| {
                    let target: [Option<f64>; BANDS] = std::array::from_fn(|l| {
                        if l < NOISE_LEVELS {
                            Some(noise.levels[l].std(noise.form, c, y) as f64)
                        } else {
                            noise.lowpass.map(|lp| lp.std(noise.form, c, y) as f64)
                        }
                    });
                    solve_weights(&target).map(|v| v as f32)
                })
            })
            .collect();
        Self { luma_lo: lo, luma_hi: hi, weights }
    }

    /// Luma range covered by the nodes.
    pub fn luma_range(&self) -> [f32; 2] {
        [self.luma_lo, self.luma_hi]
    }

    /// Number of luma nodes.
    /// Luma nodes of every table (fixed), for sizing GPU buffers up front.
    pub fn node_count() -> usize {
        TABLE_NODES
    }

    pub fn nodes(&self) -> usize {
        self.weights.len()
    }

    /// The weights flattened as [node][channel][band] (5 bands), e.g. for a GPU buffer.
    pub fn weights_flat(&self) -> Vec<f32> {
        self.weights.iter().flat_map(|n| n.iter().flat_map(|c| c.iter().copied())).collect()
    }

    /// Weight of `band` for channel `c` at luma `y` (clamped to the range).
    #[inline]
    pub fn weight(&self, c: usize, band: usize, y: f32) -> f32 {
        let span = (self.luma_hi - self.luma_lo).max(1e-12);
        let t = ((y - self.luma_lo) / span).clamp(0.0, 1.0) * (TABLE_NODES - 1) as f32;
        let k = (t.floor() as usize).min(TABLE_NODES - 2);
        let f = t - k as f32;
        let (a, b) = (self.weights[k][c][band], self.weights[k + 1][c][band]);
        a + (b - a) * f
    }
}

/// The synthesised noise field (no content added) for content with luma `luma`,
/// every channel's maps read at luma (the GPU grain pass's twin). For a model with
/// `NoiseIntensity::Channel` this is exact on neutral content (R = G = B = Y);
/// `noise_field_rgb` reads each channel at its own value.
pub fn noise_field(luma: &Plane, noise: &Noise, seed: u64) -> Rgb {
    let ypyr = gaussian_pyramid(luma, NOISE_LEVELS);
    field_at(luma.width, luma.height, [&ypyr, &ypyr, &ypyr], noise, seed)
}

/// The synthesised noise field for `content`, each channel's maps read at the
/// model's intensity: luma, or that channel's own value.
pub fn noise_field_rgb(content: &Rgb, noise: &Noise, seed: u64) -> Rgb {
    match noise.intensity {
        NoiseIntensity::Luma => noise_field(&content.luma(), noise, seed),
        NoiseIntensity::Channel => {
            let pyr: Vec<Vec<Plane>> =
                (0..3).map(|c| crate::image::gaussian_pyramid_of(content.plane(c), NOISE_LEVELS)).collect();
            field_at(content.width, content.height, [&pyr[0], &pyr[1], &pyr[2]], noise, seed)
        }
    }
}

/// Band l of channel c's white noise weighted at `intensity[c]`'s level l.
fn field_at(w: usize, h: usize, intensity: [&Vec<Plane>; 3], noise: &Noise, seed: u64) -> Rgb {
    if !noise.present {
        return Rgb::new(w, h, [0.0; 3]);
    }
    let table = SynthesisTable::new(noise);
    let planes: Vec<Plane> = (0..3usize)
        .into_par_iter()
        .map(|c| {
            let ypyr = intensity[c];
            let white = (0..w * h).map(|i| gaussian((i % w) as u32, (i / w) as u32, c as u32, seed)).collect();
            let mut pyr = laplacian_pyramid(&Plane::from_vec(w, h, white), NOISE_LEVELS);
            for (l, band) in pyr.bands.iter_mut().chain(std::iter::once(&mut pyr.lowpass)).enumerate() {
                for (v, &yl) in band.data.iter_mut().zip(&ypyr[l].data) {
                    *v *= table.weight(c, l, yl);
                }
            }
            pyr.collapse()
        })
        .collect();
    let mut it = planes.into_iter();
    let mut next = || it.next().unwrap_or_else(|| Plane::new(w, h, 0.0));
    Rgb::from_planes([next(), next(), next()])
}

/// The camera-model noise entry of white Poisson–Gaussian sensor noise with
/// std_c(Y) = √(a_c + b_c·Y): band l of white noise carries the fraction c_l of its
/// std (`unit_band_std`), so level l's affine variance is (a + bY)·c_l², low-pass
/// included. Used as ground truth by the demo, tests and benchmarks.
pub fn white_sensor_noise(a: [f32; 3], b: [f32; 3], luminance_range: [f32; 2]) -> Noise {
    let unit = unit_band_std();
    let level = |l: usize| crate::model::NoiseLevel {
        slope: std::array::from_fn(|c| b[c] * unit[l] * unit[l]),
        intercept: std::array::from_fn(|c| a[c] * unit[l] * unit[l]),
    };
    Noise {
        present: true,
        form: crate::model::NoiseForm::AffineVariance,
        intensity: NoiseIntensity::Luma,
        levels: (0..NOISE_LEVELS).map(level).collect(),
        lowpass: Some(level(NOISE_LEVELS)),
        luminance_range,
        bins: vec![],
        level_sources: vec![],
        blocking: None,
        diagnostics: crate::model::Diagnostics::not_fitted("white Poisson–Gaussian sensor noise"),
    }
}

/// Real camera noise decays slower than white across the pyramid: demosaicing, an
/// ISP's denoiser and a codec's quantisation correlate it between neighbouring
/// pixels. Level std ratios (level l + 1 over level l) measured here: white noise
/// 0.24 / 0.44 / 0.49 (`unit_band_std`), white noise low-passed by a Gaussian of std
/// 0.7 px (a demosaic's reach) 0.58 / 0.53 / 0.51, the vtest clip's DivX noise
/// 0.40–0.51 / 0.69–0.74 over its static pixels.
///
/// `white_sensor_noise`'s level 0 (std_c(Y) = √(a_c + b_c·Y)·c_0) with each coarser
/// level's std `level_ratios[l]` times the finer one's (the low-pass's by the last
/// ratio): the ground truth of correlated sensor noise for tests and probes. An
/// error names a ratio that is not finite and positive.
pub fn correlated_sensor_noise(
    a: [f32; 3],
    b: [f32; 3],
    luminance_range: [f32; 2],
    level_ratios: [f32; NOISE_LEVELS - 1],
) -> Result<Noise, String> {
    if let Some((i, r)) = level_ratios.iter().enumerate().find(|(_, r)| !(r.is_finite() && **r > 0.0)) {
        return Err(format!("level ratio {i} (level {} over level {i}) must be finite and > 0, got {r}", i + 1));
    }
    let mut noise = white_sensor_noise(a, b, luminance_range);
    let unit = unit_band_std();
    // Level l's std relative to level 0: the product of the ratios up to it, against
    // white noise's c_l / c_0 (the variance scales by the square).
    let mut std_rel = 1.0f32;
    for l in 1..=NOISE_LEVELS {
        std_rel *= level_ratios[(l - 1).min(NOISE_LEVELS - 2)];
        let k = (std_rel * unit[0] / unit[l]).powi(2);
        let level = if l < NOISE_LEVELS { noise.levels.get_mut(l) } else { noise.lowpass.as_mut() };
        if let Some(level) = level {
            level.slope.iter_mut().chain(level.intercept.iter_mut()).for_each(|v| *v *= k);
        }
    }
    noise.diagnostics = crate::model::Diagnostics::not_fitted(&format!(
        "correlated Poisson–Gaussian sensor noise (level std ratios {level_ratios:?})"
    ));
    Ok(noise)
}

/// addNoise(I, σ): `clean` plus synthesised noise; unclipped (an 8-bit writer clips).
pub fn add_noise(clean: &Rgb, noise: &Noise, seed: u64) -> Rgb {
    if !noise.present {
        return clean.clone();
    }
    let field = noise_field_rgb(clean, noise, seed);
    let mut out = clean.clone();
    for c in 0..3 {
        for (o, n) in out.channels[c].iter_mut().zip(&field.channels[c]) {
            *o += n;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::measured_check::{check, Table};

    /// The stored white-noise tables equal a fresh measurement (tolerance in
    /// `measured_check::check`).
    #[test]
    fn measured_tables_synth() {
        let unit = measure_unit_band_std();
        let m = measure_transfer();
        let flat = |v: &[[[f64; BANDS]; BANDS]; BANDS]| -> Vec<f64> { v.iter().flatten().flatten().copied().collect() };
        check(
            "src/synth/measured.rs",
            "White-noise tables of the Laplacian-pyramid noise synthesis (`noise.rs`), measured once.",
            &[
                Table {
                    name: "UNIT_BAND_STD",
                    ty: "[f32; crate::model::NOISE_LEVELS + 1]",
                    doc: "/// `noise::measure_unit_band_std`: band stds of unit white noise, levels 0..4 then the low-pass.",
                    stored: unit_band_std().iter().map(|&v| v as f64).collect(),
                    fresh: unit.iter().map(|&v| v as f64).collect(),
                    literal: format!("{unit:?}"),
                },
                Table {
                    name: "TRANSFER",
                    ty: "[[[f64; crate::model::NOISE_LEVELS + 1]; crate::model::NOISE_LEVELS + 1]; crate::model::NOISE_LEVELS + 1]",
                    doc: "/// `noise::measure_transfer`: M[m][l][l'], the pyramid's cross-level energy transfer.",
                    stored: flat(transfer()),
                    fresh: flat(&m),
                    literal: format!("{m:?}"),
                },
            ],
        );
    }
}
