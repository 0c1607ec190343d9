//! Noise, blind (the fast tier, `fit_fast`): every band-pass level measured on the
//! frame alone at its flattest samples per luma bin, with the clip tiles, codec
//! blocking and (with an aligned neighbour exposure) the difference bands it reads.
//! The shared regression, windows and clip masks are in `noise/mod.rs`.

use super::bands::{channel_pyramids, AxisWeights, Band0, Binning, SepWindow};
use super::blocking::detect_blocking;
use super::sources::luma_span;
use super::*;

const BLIND_FLAT_FRACTION: f64 = 0.2;
/// Default of `FitOptions::noise_fast_samples_per_level`. Measured over 27 frames of
/// known noise and the real DivX clip (the table is in BENCHMARKS.md, "Fast tier
/// speed at 1280×960", the noise grid as a measured setting): level 0's error is the
/// same from 40 000 down to 5 000 (median 10–11%: texture in the flattest samples,
/// not sampling), the clip's level 0 inside its range 18.4% at 20 000 and 16.8%
/// here; the noise fit at 1280×960 takes 15.4 ms instead of 18.5. 10 000, not
/// 5 000: at 5 000 level 2 was measured on none of the 27 frames (6 here, 4 at
/// 20 000) and derived instead, which on real correlated noise is what costs most.
pub const DEFAULT_FAST_SAMPLES_PER_LEVEL: usize = 10_000;
/// Fewest grid points per level `FitOptions::noise_fast_samples_per_level` takes:
/// every luma bin could then still hold `BLIND_MIN_PER_BIN` samples.
pub const MIN_FAST_SAMPLES_PER_LEVEL: usize = BLIND_BINS * BLIND_MIN_PER_BIN;
/// The blind tier's finest level-0 grid: only 20% of its samples are kept (the
/// flattest), so it samples denser than the accurate tier.
const BLIND_STRIDE_PX: usize = 4;
/// Side of the clip scan's tiles (`TileExtremes`): a sample's footprint is widened
/// to whole tiles, so small tiles lose few samples near a clipped pixel.
const CLIP_TILE_PX: usize = 8;
const BLIND_BINS: usize = 16;
const BLIND_MIN_PER_BIN: usize = 24;
/// Largest std ratio of a level to the next finer one that still reads as noise.
/// Measured: white noise 0.25 (level 1/0), 0.45, 0.50; the vtest clip's codec noise
/// 0.50, 0.65, 0.67 (temporal reference); the flattest samples of textured frames
/// 1.1–3 (the astronaut's level 2 over level 1, the vtest frame's levels 1–3).
const MAX_LEVEL_STD_RATIO: f32 = 0.8;
/// How many levels coarser than the measured band the frame's structure is read
/// that chooses the flat samples: two for the frame alone (band l+2 holds little
/// level-l noise, so choosing on it does not pick low noise); one from level 1 on
/// with an aligned neighbour, whose difference cancels texture only where the two
/// exposures agree — what it leaves lives at the texture's scales. Measured
/// (BENCHMARKS.md "Correlated noise on video"),
/// levels 2 / 3, l+2 → l+1: white noise at 640×480 +8.5 / +23.0% → +6.9 / +14.4%,
/// in the worker's strips at 1280×960 +4.5 / +18.1% → +4.7 / +8.8%; correlated noise
/// within ±3% either way; a neighbour differing only in its noise within ±2.3%.
const NEIGHBOUR_STRUCTURE_OFFSET: usize = 1;
/// The frame alone's (see `NEIGHBOUR_STRUCTURE_OFFSET`).
const STRUCTURE_OFFSET: usize = 2;
/// Fewest flat samples a bin is measured on (a median of fewer scatters by > 25% at level 3).
const BLIND_MIN_FLAT: usize = 12;
/// The texture a natural scene leaves in its flattest samples, as a level-0 band std
/// (0–1 pixel values), and the share of the noise's variance by which that texture
/// grows as noise blurs the flat set's selection: the frame-alone fit's bias model,
/// read² = (1 + k²)·noise² + T² (`texture_bias`). Fitted on 36 frames of known added
/// noise (the astronaut, chelsea, the Motorcycle view and the vtest clip's temporal
/// mean, three strengths, three seeds) so that 2 standard errors hold the level-0
/// error at mid luma on 90% of them; on 63 frames of 7 held-out natural scenes it
/// held 60 (BENCHMARKS.md, "The blind noise's texture floor"). No frame statistic
/// measured separates texture from noise (the level-1 band at the flat samples
/// misreads grass as noise and the real clip's road as texture), so this is a
/// prior: pure textures (grass, gravel, brick) exceed it by +15…+695%.
const TEXTURE_FLOOR_STD: f32 = 0.006;
const TEXTURE_FLOOR_RELATIVE: f32 = 0.26;

/// Share of white noise's level-`l` band variance that survives a Catmull–Rom
/// bicubic resampling at a sub-pixel offset (what `analysis::temporal::align` does
/// to the neighbour frame), averaged over offsets on a 4×4 grid of phases: the
/// bicubic kernel low-passes, most at level 0. Measured on a 256² field
/// (`measure_bicubic_noise_transmission`), stored in `measured.rs` (see
/// `crate::synth::measured_check` for why).
fn bicubic_noise_transmission(level: usize) -> f32 {
    super::measured::BICUBIC_NOISE_TRANSMISSION[level.min(NOISE_LEVELS - 1)]
}

#[cfg(test)]
pub(super) fn measure_bicubic_noise_transmission() -> [f32; NOISE_LEVELS] {
    let n = 256usize;
    let data = (0..n * n).map(|i| crate::synth::gaussian((i % n) as u32, (i / n) as u32, 7, 0x5eed)).collect();
    let field = Plane::from_vec(n, n, data);
    let var_of = |p: &Plane| -> [f64; NOISE_LEVELS] {
        let pyr = laplacian_pyramid(p, NOISE_LEVELS);
        std::array::from_fn(|l| {
            // The inner half: away from the clamped borders.
            let b = &pyr.bands[l];
            let (x0, y0) = (b.width / 4, b.height / 4);
            let mut acc = 0.0f64;
            let mut m = 0usize;
            for y in y0..b.height - y0 {
                for x in x0..b.width - x0 {
                    acc += (b.get(x, y) as f64).powi(2);
                    m += 1;
                }
            }
            acc / m.max(1) as f64
        })
    };
    let base = var_of(&field);
    let mut sum = [0.0f64; NOISE_LEVELS];
    let phases = [0.125f32, 0.375, 0.625, 0.875];
    for &u in &phases {
        for &v in &phases {
            let mut shifted = Plane::new(n, n, 0.0);
            for y in 0..n {
                for x in 0..n {
                    shifted.data[y * n + x] = crate::image::sample_bicubic(&field, x as f32 + u, y as f32 + v);
                }
            }
            let s = var_of(&shifted);
            for l in 0..NOISE_LEVELS {
                sum[l] += s[l] / base[l] / (phases.len() * phases.len()) as f64;
            }
        }
    }
    sum.map(|k| k as f32)
}

/// The relative bias a frame-alone reading `std` (level-0 band std) may carry by the
/// texture-floor model (`TEXTURE_FLOOR_STD`): std over the noise's
/// √((std² − T²)/(1 + k²)), less one; 1 (the noise could be half the reading or
/// less) where the reading lies within the floor. Non-finite or non-positive
/// readings: 1.
pub(super) fn texture_bias(std: f32) -> f32 {
    // f64: a reading's square stays finite whatever a (validated, finite) frame holds.
    let (s, t, k) = (std as f64, TEXTURE_FLOOR_STD as f64, TEXTURE_FLOOR_RELATIVE as f64);
    let noise_sq = (s * s - t * t) / (1.0 + k * k);
    if !(s.is_finite() && s > 0.0) || noise_sq <= 0.25 * s * s {
        return 1.0;
    }
    (s / noise_sq.sqrt() - 1.0) as f32
}

/// One luma bin's blind measurement at one level.
#[derive(Clone)]
struct BinMeasure {
    y: f32,
    y2: f32,
    var: [f32; 3],
    n: usize,
    /// Relative standard error of the bin's std (mean over channels).
    rel_se: f32,
}

/// The method a blind noise fit names when it read an aligned neighbour: the
/// worker prefers such fits to the frame-alone ones (`Calibrator::aggregate`),
/// which take the flattest texture for noise (+57% on the calibration video's
/// first frame, against 2–3% with the neighbour).
pub const FAST_WITH_NEIGHBOUR: &str = "fast (aligned neighbour)";
/// The method of a blind noise fit of the frame alone.
pub const FAST_ALONE: &str = "fast";

/// Fast tier: the frame alone.
///
/// Every band-pass level is measured on the frame itself (real noise is shaped by
/// demosaicing, in-camera denoising, sharpening and compression, so coarse levels do
/// not follow from level 0 by white-noise ratios — on the vtest clip level 1 holds
/// 0.45–0.50× level 0's std where white noise holds 0.24× (`UNIT_BAND_STD`), and
/// level 3 1.6× the white prediction). At level l, per luma bin (16 bins of the smoothed luma), the flat
/// samples are the `BLIND_FLAT_FRACTION` with the least luma energy two levels
/// coarser (band l+2: structure that spans the level-l window, and nearly
/// uncorrelated with level-l noise, so selecting on it does not bias the level-l
/// variance the way picking the lowest variances would); their median local
/// variance, calibrated by `white_noise_median_to_mean(l)`, is the bin's value.
/// With an aligned `neighbour` the noise is read off the difference (texture
/// cancels), and from level 1 on the flat samples are chosen one level coarser
/// instead (band l+1; see `NEIGHBOUR_STRUCTURE_OFFSET`).
/// Binning by luma means dark bins are measured on dark samples: shadows are never
/// judged flat or textured by the bright parts' standard. The bins' lower envelope
/// is the noise (`trim_textured`: the line no bin undercuts by more than 30% that
/// keeps the most bins within a factor 1.2 of its variance); bins outside that band
/// are texture and dropped. The low-pass is not identifiable from one frame (it is
/// the image itself) and is left out.
pub fn fit_fast(
    image: &Rgb,
    neighbour: Option<&crate::fit::Neighbour>,
    samples_per_level: usize,
) -> (Noise, NoisePlotData) {
    fit_fast_with_luma(image, neighbour, samples_per_level, None)
}

/// `fit_fast` given the frame's shared luma where a blind exposure or defocus fit
/// of the same `fit::fit` call builds it anyway (`fit::fit_noise` builds it just
/// before): the blocking scan reads it instead of making its rows from the three
/// channels — the same values.
pub(in crate::fit) fn fit_fast_with_luma(
    image: &Rgb,
    neighbour: Option<&crate::fit::Neighbour>,
    samples_per_level: usize,
    luma: Option<&crate::fit::SharedLuma>,
) -> (Noise, NoisePlotData) {
    let started = Instant::now();
    let mut st = crate::fit::Stages::start();
    // With an aligned neighbour (another exposure of the same scene): the band-pass
    // levels of D = I − I' per channel (0 where the alignment does not hold; samples
    // whose footprint holds more than `MAX_INVALID_FRACTION` of such pixels are
    // skipped), so that each flat sample reads B(b·b_D) = B(b²) − B(b·b'): the two
    // exposures' noise is independent, their texture the same, so the product with
    // the neighbour's band cancels the texture and keeps the noise (see `fit_fast`).
    let (fw, fh) = (image.width, image.height);
    let neighbour = neighbour.filter(|n| (n.image.width, n.image.height) == (fw, fh));
    let cross: Option<Vec<Vec<Plane>>> = neighbour.map(|n| {
        (0..3)
            .into_par_iter()
            .map(|c| {
                let d: Vec<f32> = image.channels[c]
                    .iter()
                    .zip(&n.image.channels[c])
                    .zip(&n.valid.data)
                    .map(|((a, b), v)| if *v > 0.5 { a - b } else { 0.0 })
                    .collect();
                channel_pyramids(&d, fw, fh, NOISE_LEVELS, true, |_| {}).1
            })
            .collect()
    });
    st.lap("blur.neighbour");
    // One Gaussian pyramid per channel, levels 0..=L+2, and its band-pass levels
    // 0..L+2. Everything the fit reads of the luma follows by linearity (luma is a
    // fixed weighted sum of the channels, and reduce/expand are linear), so no luma
    // pyramid is built: G_Y[l] = Σ w_c G_c[l]; the smoothed luma used for binning
    // level l (I's own luma carries the noise) is expand(G_Y[l+1]) = Σ w_c (G_c[l] −
    // band_c[l]); level l's structure measure is the luma band l+2 = Σ w_c band_c[l+2].
    // Level 0 is the frame's own channel (borrowed, not copied).
    // The first reduce hands the clip scan (`TileExtremes`) each band of rows it
    // has just read, while they are in cache.
    type Pyramids = (Vec<Plane>, Vec<Plane>);
    let (pyr, tiles): (Vec<Pyramids>, Vec<TileExtremes>) = (0..3)
        .into_par_iter()
        .map(|c| {
            let ch = &image.channels[c][..];
            let mut t = TileExtremes::new(fw, fh, CLIP_TILE_PX);
            let p = channel_pyramids(ch, fw, fh, NOISE_LEVELS + 2, false, |y| t.rows_read(ch, y));
            (p, t)
        })
        .unzip();
    st.lap("blur.pyramids");
    // One pass (the three weighted terms summed in channel order, as three passes
    // accumulating into the output summed them).
    let luma_of = |c: [&[f32]; 3], like: &Plane| -> Plane {
        let w = crate::image::LUMA_WEIGHTS;
        let out = c[0].iter().zip(c[1]).zip(c[2]).map(|((a, b), d)| w[0] * a + w[1] * b + w[2] * d).collect();
        Plane::from_vec(like.width, like.height, out)
    };
    // pyr[c].0[l] is G_c[l + 1].
    let gauss = |l: usize| -> [&[f32]; 3] {
        std::array::from_fn(|c| if l == 0 { &image.channels[c][..] } else { &pyr[c].0[l - 1].data[..] })
    };
    let band = |l: usize| -> [&Plane; 3] { std::array::from_fn(|c| &pyr[c].1[l]) };
    // expand(G_Y[l+1]) from the coarse luma (reduce is linear): one plane expanded
    // instead of six level-l planes read (`blur.luma` 2.3 → 1.6 ms at 1280×960, the
    // same values to rounding).
    // Level 0's is not expanded to the frame's size: its samples read it window by
    // window from the half-resolution luma (`Binning::Expanded`).
    let smooth: Vec<Plane> = (0..NOISE_LEVELS)
        .into_par_iter()
        .map(|l| {
            let coarse = luma_of(gauss(l + 1), &pyr[0].0[l]);
            if l == 0 {
                return coarse;
            }
            crate::image::expand(&coarse, pyr[0].0[l - 1].width, pyr[0].0[l - 1].height)
        })
        .collect();
    // The luma bands 2..NOISE_LEVELS + 2: level l's structure is band l + the offset
    // (`STRUCTURE_OFFSET`, or `NEIGHBOUR_STRUCTURE_OFFSET` from level 1 with a
    // neighbour: the same planes, one level finer).
    let structure: Vec<Plane> = (STRUCTURE_OFFSET..NOISE_LEVELS + STRUCTURE_OFFSET)
        .into_par_iter()
        .map(|k| luma_of(band(k).map(|b| &b.data[..]), &pyr[0].1[k]))
        .collect();
    const _: () = assert!(NEIGHBOUR_STRUCTURE_OFFSET + 1 >= STRUCTURE_OFFSET);
    let band0 = Band0 {
        fine: std::array::from_fn(|c| &image.channels[c][..]),
        g1: std::array::from_fn(|c| &pyr[c].0[0]),
        width: fw,
        height: fh,
    };
    let bands: Vec<&[Plane]> = pyr.iter().map(|(_, b)| &b[..NOISE_LEVELS]).collect();
    st.lap("blur.luma");
    let luma = luma.map(|l| l.full()).filter(|l| (l.width, l.height) == (fw, fh));
    let blocking = detect_blocking(image, luma, &structure[0], 4);
    st.lap("search.blocking");
    // About `samples_per_level` grid points per level whatever the frame size
    // (`level_stride`).
    let stride0 = ((image.len() as f64 / samples_per_level.max(1) as f64).sqrt() as f32).max(BLIND_STRIDE_PX as f32);
    let (limits, clip) = blind_clip_masks_from(image, &tiles);
    // Where the neighbour's alignment fails: one table for all channels.
    let misaligned = neighbour.map(|n| clip_mask_of(image, &limits, CLIP_TILE_PX, Some(n.valid), &[]));
    st.lap("search.clipping");
    // Levels with fewer than 3 usable bins (tiny or fully textured frames) cannot be
    // fitted on their own: they follow the finest measured level by white-noise band
    // ratios, and the reason says so.
    // Levels are measured finest first. A level stops being identifiable where the
    // frame's flattest samples are texture rather than noise: with fewer than 3 flat
    // bins, or when its median std over the bins it shares with the finer level
    // exceeds `MAX_LEVEL_STD_RATIO` times that level's (camera noise falls toward
    // coarse levels, texture does not). It and every coarser level then follow the
    // finest measured level by the white-noise band ratios (see below); the reason
    // names them. Coarser levels are then not sampled at all:
    // nothing would read them (levels 2–3 hold ~60% of the grid points at 1280×960,
    // and over 27 frames of known noise level 2 was measured on 6, level 3 on
    // none).
    let (mut points, mut measured_levels, mut derived): (Vec<LevelPoints>, Vec<usize>, Vec<usize>) =
        (vec![], vec![], vec![]);
    let mut prev: Option<Vec<BinMeasure>> = None;
    // Per measured level, its bins' median relative standard error (`sources`).
    let mut bin_rel_se: Vec<f32> = vec![];
    let mut level0_untrimmed = false;
    // Level 0's bins, every one measured (the per-bin confidence reports them all).
    let mut measured0: Vec<BinMeasure> = vec![];
    for l in 0..NOISE_LEVELS {
        if !derived.is_empty() {
            derived.push(l);
            continue;
        }
        let cross = cross.as_deref().zip(misaligned.as_ref());
        let offset = if cross.is_some() && l >= 1 { NEIGHBOUR_STRUCTURE_OFFSET } else { STRUCTURE_OFFSET };
        let structure = &structure[l + offset - STRUCTURE_OFFSET];
        let binning = if l == 0 {
            Binning::Expanded { coarse: &smooth[0], width: fw, height: fh }
        } else {
            Binning::Plane(&smooth[l])
        };
        let all = measure_level(l, (&bands, &band0), cross, &binning, (structure, offset), &clip, stride0);
        // A level whose bins no line explains (fewer than 3 agree) is texture, not
        // noise: measured on the calibration video (Motorcycle, 320×240), keeping
        // every bin there let levels 1–3 read 5–20× the truth on 1 frame in 5.
        // Level 0 keeps its bins (its samples are the most numerous, and without
        // it there is no map at all); the reason says it was not trimmed.
        let (bins, untrimmed) = match trim_textured(&all) {
            Some(b) => (b, false),
            None if l == 0 => (all.iter().collect(), true),
            None => (vec![], true),
        };
        if untrimmed && l == 0 {
            level0_untrimmed = true;
        }
        let grows = prev.as_ref().is_some_and(|p| {
            let p: Vec<&BinMeasure> = p.iter().collect();
            median_std_ratio(&bins, &p).map_or(true, |r| r > MAX_LEVEL_STD_RATIO)
        });
        // Level 0 may stand on fewer than 3 bins (a narrow-luma frame); coarser ones not.
        let too_few = bins.is_empty() || (l > 0 && bins.len() < 3);
        if grows || too_few {
            derived.push(l);
        } else {
            measured_levels.push(l);
            points.push(LevelPoints {
                y: bins.iter().map(|b| b.y).collect(),
                y2: bins.iter().map(|b| b.y2).collect(),
                own: None,
                var: std::array::from_fn(|c| bins.iter().map(|b| b.var[c]).collect()),
                weights: Some(bins.iter().map(|b| b.n as f32).collect()),
            });
            let mut se: Vec<f32> = bins.iter().map(|b| b.rel_se).collect();
            bin_rel_se.push(percentile(&mut se, 0.5));
            prev = Some(bins.into_iter().cloned().collect());
        }
        if l == 0 {
            measured0 = all;
        }
    }
    st.lap("search.samples");
    let fitted =
        if measured_levels.first() == Some(&0) { fit_levels(&points, NoiseIntensity::Luma, true) } else { None };
    let fitted = fitted.map(|LevelFit { form, intensity, levels: lv, covs, rel_res, nll }| {
        let unit = crate::synth::unit_band_std();
        let last = lv.len() - 1;
        // Beyond the finest measured levels: white noise's per-level ratios, not
        // scaled by how much slower than white the two finest measured levels decay
        // (correlated noise decays slower): measured, that excess was only ever
        // texture. Over 27 frames of known white noise such a scaling fired on the 12
        // with two or more levels measured — a level 1 or 2 read high by texture
        // (+6…+232%) — and compounded it (chelsea's strongest noise: level 3 +423%
        // where level 2 read +232%; levels 2–3 median 36.8 / 40.6% with it, 25.4 /
        // 25.4% without), and the real clip's fit measures one level only, so it
        // never reached correlated noise.
        let levels = (0..NOISE_LEVELS)
            .map(|l| match measured_levels.iter().position(|&m| m == l) {
                Some(i) => lv[i],
                None => {
                    let from = measured_levels[last];
                    let r: f32 = unit[l] / unit[from];
                    let k = if form == NoiseForm::LinearStd { r } else { r * r };
                    NoiseLevel { slope: lv[last].slope.map(|v| v * k), intercept: lv[last].intercept.map(|v| v * k) }
                }
            })
            .collect();
        LevelFit { form, intensity, levels, covs, rel_res, nll }
    });
    // The luma range is what level 0's used bins cover: no value outside it.
    let y0 = points.first().map(|p| p.y.clone()).unwrap_or_default();
    let range = luma_span(&y0).unwrap_or([0.0, 1.0]);
    let samples: Vec<LevelSamples> = points
        .iter()
        .map(|p| LevelSamples { y: p.y.clone(), y2: p.y2.clone(), own: None, var: p.var.clone() })
        .collect();
    let covs = fitted.as_ref().map(|f| f.covs.clone()).unwrap_or_default();
    st.lap("least_squares");
    let samples_used: usize = points.iter().flat_map(|p| p.weights.iter().flatten()).map(|&w| w as usize).sum();
    let method = if neighbour.is_some() { FAST_WITH_NEIGHBOUR } else { FAST_ALONE };
    let mut noise = finish(method, started, fitted, &samples, range, false);
    noise.diagnostics.samples_used = samples_used as u64;
    noise.diagnostics.stages_s = st.done();
    // Confidence per luma bin (level 0): every measured bin, whether the fit used it.
    let used0: Vec<f32> = points.first().map(|p| p.y.clone()).unwrap_or_default();
    // Frame alone: texture in the flattest samples reads as noise, by an amount no
    // statistic of one frame separated (`TEXTURE_FLOOR_STD`); each bin's confidence
    // and the model's standard error carry the floor model's bias in quadrature with
    // their sampling error. With an aligned neighbour the texture cancels (2–3% on
    // the calibration video): sampling alone.
    let floor = |std: f32| if neighbour.is_none() { texture_bias(std) } else { 0.0 };
    noise.bins = measured0
        .iter()
        .map(|b| {
            let std = b.var.map(|v| v.max(0.0).sqrt());
            crate::model::NoiseBin {
                luma: b.y,
                samples: b.n as u32,
                std,
                relative_stderr: b.rel_se.hypot(floor(std.iter().sum::<f32>() / 3.0)),
                used: used0.contains(&b.y),
            }
        })
        .collect();
    let ym = 0.5 * (noise.luminance_range[0] + noise.luminance_range[1]);
    let std_mid = (0..3).map(|c| noise.levels[0].std(noise.form, c, ym)).sum::<f32>() / 3.0;
    if measured_levels.first() == Some(&0) && covs.len() == points.len() {
        let (bias, with_neighbour) = (floor(std_mid), neighbour.is_some());
        noise.level_sources =
            super::sources::level_sources(&noise, &measured_levels, &points, &covs, &bin_rel_se, bias, with_neighbour);
    }
    // Presence was decided on the sampling error alone (`noise::finish`); the
    // texture term widens only the stated error. Texture in the flattest samples
    // adds variance, so it can read a noiseless textured frame as noisy (the known
    // failure: +21% on a real textured photograph) but never hides noise that is
    // there: a "present" whose stated error exceeds a third is a bias bound, not
    // doubt about presence.
    if noise.present && neighbour.is_none() {
        let bias = floor(std_mid) as f64;
        let sampling = noise.diagnostics.stderr.unwrap_or(1.0);
        noise.diagnostics.stderr = Some(sampling.hypot(bias));
        noise.diagnostics.reason += &format!(
            "; standard error ±{:.1}%: sampling ±{:.1}%, and texture in the flattest samples ±{:.1}% \
             (a natural scene's floor: {TEXTURE_FLOOR_STD} in level-0 std, {:.0}% of the noise's; a pure texture exceeds it)",
            100.0 * sampling.hypot(bias),
            100.0 * sampling,
            100.0 * bias,
            100.0 * TEXTURE_FLOOR_RELATIVE
        );
    }
    if noise.present && level0_untrimmed {
        noise.diagnostics.reason +=
            "; level 0's luma bins agree with no common line (3 or more within 1.2× in variance): \
             all were used, texture may be counted as noise";
    }
    if noise.present && !derived.is_empty() {
        noise.diagnostics.reason += &format!(
            "; levels {derived:?} not identifiable from this frame (texture exceeds the noise there, or too few flat luma bins): \
             they continue the finest measured level by white-noise band ratios"
        );
    }
    if noise.present {
        noise.diagnostics.reason += &super::sources::partial_level_notes(&noise);
    }
    if let Some(b) = blocking {
        noise.diagnostics.reason += &format!(
            "; compression blocking: {} px grid at phase ({}, {}), boundary steps {:.2}× the interior's — the fine levels hold codec artefacts, not only sensor noise",
            b.period_px, b.phase_px[0], b.phase_px[1], b.strength
        );
    }
    noise.blocking = blocking;
    (noise, plot_data(&points))
}

/// Median over the luma bins two levels share of the coarse level's std over the
/// fine level's (channel-pooled); `None` when they share no bin.
fn median_std_ratio(coarse: &[&BinMeasure], fine: &[&BinMeasure]) -> Option<f32> {
    let std = |b: &BinMeasure| (b.var.iter().sum::<f32>() / 3.0).max(0.0).sqrt();
    let mut r: Vec<f32> = coarse
        .iter()
        .filter_map(|c| {
            let bin = (c.y * BLIND_BINS as f32) as usize;
            fine.iter().find(|f| (f.y * BLIND_BINS as f32) as usize == bin).map(|f| std(c) / std(f).max(1e-12))
        })
        .collect();
    (!r.is_empty()).then(|| percentile(&mut r, 0.5))
}

/// The blind tier's sample stride at level `l`: about `n` samples per level
/// (`stride0` = √(pixels / n), at least `BLIND_STRIDE_PX`; n =
/// `FitOptions::noise_fast_samples_per_level`), the level-0 stride rounded down and
/// coarser ones to the nearest (n = 10 000 at 1280×960: 11, 6, 3, 1; at 20 000: 7,
/// 4, 2, 1) — halving an integer stride instead gave level 2 of a 1280×960 frame
/// 77 000 samples at stride 1, 4× the others and 40% of the search.
fn level_stride(stride0: f32, l: usize) -> usize {
    if l == 0 {
        stride0 as usize
    } else {
        ((stride0 / (1u32 << l) as f32).round() as usize).max(1)
    }
}

/// Per-bin measurements of level `l` (see `fit_fast`).
fn measure_level(
    l: usize,
    (bands, band0): (&[&[Plane]], &Band0),
    cross: Option<(&[Vec<Plane>], &ClipMask)>,
    luma: &Binning,
    (structure, offset): (&Plane, usize),
    clip: &[ClipMask; 3],
    stride0: f32,
) -> Vec<BinMeasure> {
    let scale = 1usize << l;
    let stride = level_stride(stride0, l);
    let win = SepWindow::new(l);
    // The structure energy (window mean of the squared structure band) of every
    // structure pixel, by one separable blur: at the coarse levels many samples
    // share a structure pixel, and 18 taps per pixel beat 81 per sample.
    let energy = {
        let sq = Plane::from_vec(structure.width, structure.height, structure.data.iter().map(|v| v * v).collect());
        crate::image::blur_separable(&sq, &window_1d((l + offset).min(3)))
    };
    // Footprint of the measured band in level-0 pixels (as in `collect_samples`); clipping
    // under the structure band only makes a sample look textured, it biases nothing.
    let radius = 5 * scale + 8;
    let (w, h) = luma.size();
    // (x, y, B(Y), structure, unclipped-channel bits). B(Y²) is read only for the
    // flat samples that report it (`BinMeasure::y2`, ~20% of them): its window sums
    // for every grid point were ~0.4 ms of the fit at 1280×960.
    type Sample = (usize, usize, f32, f32, u8);
    let mut pts: Vec<Sample> = vec![];
    let xs: Vec<(usize, Option<AxisWeights>)> = grid(w, stride).map(|x| (x, luma.axis_weights(&win, 0, x))).collect();
    for y in grid(h, stride) {
        let wy = luma.axis_weights(&win, 1, y);
        for &(x, ref wx) in &xs {
            let ok = (0..3).fold(0u8, |m, c| m | ((!clip[c].touches(x * scale, y * scale, radius, l >= 2) as u8) << c));
            if ok == 0 || cross.is_some_and(|(_, bad)| bad.touches(x * scale, y * scale, radius, l >= 2)) {
                continue;
            }
            let s = energy.get((x >> offset).min(energy.width - 1), (y >> offset).min(energy.height - 1));
            pts.push((x, y, luma.mean_with(&win, x, y, wx.as_ref(), wy.as_ref()), s, ok));
        }
    }
    let m2m = white_noise_median_to_mean(l);
    let mut out = vec![];
    // The samples of luma bin b, [b/16, (b + 1)/16), in grid order: one pass over
    // them all (a filter per bin read every sample 16 times). BLIND_BINS is a power
    // of two, so ⌊16·y⌋ is exact and the bins are the comparisons' bins.
    const _: () = assert!(BLIND_BINS.is_power_of_two());
    let mut bins: Vec<Vec<&Sample>> = vec![vec![]; BLIND_BINS];
    for p in &pts {
        // y ≥ 0 (NaN fails): truncation is the floor, without a libm call.
        if p.2 >= 0.0 {
            let b = (p.2 * BLIND_BINS as f32) as usize;
            if b < BLIND_BINS {
                bins[b].push(p);
            }
        }
    }
    for bin in bins {
        let bin = sorted_stably_by(&bin, |p| p.3);
        // Each channel's flat set: the flattest fraction of the bin's samples where
        // that channel is unclipped; the bin counts when every channel has one.
        let flats: [Vec<_>; 3] = std::array::from_fn(|c| {
            let mut mine: Vec<_> = bin.iter().filter(|p| p.4 & (1 << c) != 0).copied().collect();
            let k = (mine.len() as f64 * BLIND_FLAT_FRACTION).ceil() as usize;
            if mine.len() < BLIND_MIN_PER_BIN || k < BLIND_MIN_FLAT {
                vec![]
            } else {
                mine.truncate(k);
                mine
            }
        });
        if flats.iter().any(|f| f.is_empty()) {
            continue;
        }
        let flat = &flats[1];
        let n = flat.len() as f32;
        let mut var = [0.0f32; 3];
        let mut rel_se = 0.0f32;
        for c in 0..3 {
            let n = flats[c].len() as f32;
            // With a neighbour — level 0: B(b·b_D), first order in a texture mismatch
            // between the exposures but free of the alignment's low-pass; coarser
            // levels: B(b_D²) / (1 + κ_l), the texture mismatch entering squared, κ_l
            // the alignment's noise transmission (≈ 1 there). Measured on the
            // calibration video (BENCHMARKS.md): the product at every level reads
            // levels 1–3 2–5× high while the head turns (the exposures' motion blur
            // differs, and texture dwarfs the noise there).
            if let Some((cross, _)) = cross.filter(|_| l == 0) {
                let v: Vec<f32> = flats[c]
                    .iter()
                    .map(|p| {
                        let b = band0.window(c, p.0, p.1);
                        win.mean_prod_window(&b, band0.interior(p.0, p.1), &cross[c][0], p.0, p.1)
                    })
                    .collect();
                let (mean, se) = mean_se(&v);
                var[c] = mean;
                rel_se += if mean > 0.0 { se / (2.0 * mean) / 3.0 } else { 1.0 / 3.0 };
                continue;
            }
            let (plane, gain) = match cross {
                Some((d, _)) => (Some(&d[c][l]), 1.0 + bicubic_noise_transmission(l)),
                None if l == 0 => (None, 1.0),
                None => (Some(&bands[c][l]), 1.0),
            };
            let mut v = map_in_raster_order(&flats[c], |p| match plane {
                Some(plane) => win.mean_sq(plane, p.0, p.1),
                None => band0.mean_sq(&win, c, p.0, p.1),
            });
            let med = percentile(&mut v, 0.5);
            let iqr = percentile(&mut v, 0.75) - percentile(&mut v, 0.25);
            var[c] = med / m2m / gain;
            // SE of a median: 1.2533·sd/√n with sd from the IQR; half of it in std terms.
            rel_se += if med > 0.0 { 1.2533 * iqr / 1.349 / n.sqrt() / (2.0 * med) / 3.0 } else { 1.0 / 3.0 };
        }
        out.push(BinMeasure {
            y: flat.iter().map(|p| p.2).sum::<f32>() / n,
            y2: map_in_raster_order(flat, |p| luma.mean_sq(&win, p.0, p.1)).iter().sum::<f32>() / n,
            var,
            n: flat.len(),
            rel_se,
        });
    }
    out
}

/// `items` ordered by `key` as a stable `sort_by(total_cmp)` orders them (ties
/// keep their order), the same order: each item's key mapped to an integer that
/// orders as `total_cmp` does, packed above its index (below 2³²), and the packed
/// integers sorted (an unstable sort of distinct integers has one result). The
/// stable sort of references compared through them took 0.33 ms of the noise fit's
/// bins at 1280×960 (three levels, ~17 600 samples).
pub(super) fn sorted_stably_by<'a, T>(items: &[&'a T], key: impl Fn(&T) -> f32) -> Vec<&'a T> {
    let packed = |(i, t): (usize, &&T)| {
        // `f32::total_cmp`'s key: negative values' magnitude bits flipped, then the
        // sign bit flipped so that the signed order reads as unsigned.
        let bits = key(t).to_bits() as i32;
        let ordered = (bits ^ (((bits >> 31) as u32) >> 1) as i32) as u32 ^ 0x8000_0000;
        (u64::from(ordered) << 32) | i as u64
    };
    let mut keys: Vec<u64> = items.iter().enumerate().map(packed).collect();
    keys.sort_unstable();
    keys.iter().map(|&k| items[(k & 0xffff_ffff) as usize]).collect()
}

/// `pts.iter().map(f).collect()` — the same values in the same slots, so every
/// order statistic and sum taken of them after is the same — with `f` called in the
/// samples' raster order. A bin's flat samples are ordered by their structure, which
/// scatters them over the frame, and each reads 9×9 windows of full-size planes (the
/// three channels and the level's coarser Gaussian): in raster order neighbouring
/// windows share rows and cache lines.
pub(super) fn map_in_raster_order<T>(
    pts: &[&(usize, usize, f32, f32, T)],
    mut f: impl FnMut(&(usize, usize, f32, f32, T)) -> f32,
) -> Vec<f32> {
    let mut order: Vec<u32> = (0..pts.len() as u32).collect();
    order.sort_unstable_by_key(|&i| (pts[i as usize].1, pts[i as usize].0));
    let mut out = vec![0.0f32; pts.len()];
    for i in order {
        out[i as usize] = f(pts[i as usize]);
    }
    out
}

/// One-sided robust line: texture leaking into a bin only raises it, so the noise is
/// the *lower envelope* of the bins. Every line through two bins (channel-pooled
/// variance) is scored by the bins it explains — within [1/1.2, 1.2]× — and rejected
/// outright when a bin lies below 0.7× it (noise cannot be lower than itself); the
/// best line's inliers are kept (ties: the lower line). A plain refit-and-trim loop
/// fails on real frames whose dark half is all texture (the vtest lawn: its bins
/// pull the first line up so far that the flat road's bins look like outliers).
/// Fewer than 4 bins are kept as they are; `None` when no line explains 3 of 4 or
/// more (the bins scatter: texture, not a noise map).
fn trim_textured(bins: &[BinMeasure]) -> Option<Vec<&BinMeasure>> {
    if bins.len() < 4 {
        return Some(bins.iter().collect());
    }
    let v: Vec<f64> = bins.iter().map(|b| b.var.iter().map(|&x| x as f64).sum::<f64>() / 3.0).collect();
    let y: Vec<f64> = bins.iter().map(|b| b.y as f64).collect();
    let mut best: Option<(usize, f64, Vec<bool>)> = None;
    for i in 0..bins.len() {
        for j in i..bins.len() {
            // j == i: the flat line through one bin.
            let slope = if j == i || (y[j] - y[i]).abs() < 1e-6 { 0.0 } else { (v[j] - v[i]) / (y[j] - y[i]) };
            let line = |k: usize| v[i] + slope * (y[k] - y[i]);
            if (0..bins.len()).any(|k| line(k) <= 0.0 || v[k] < 0.7 * line(k)) {
                continue;
            }
            let inl: Vec<bool> = (0..bins.len()).map(|k| v[k] <= 1.2 * line(k) && v[k] >= line(k) / 1.2).collect();
            let count = inl.iter().filter(|&&x| x).count();
            let level: f64 = (0..bins.len()).map(line).sum();
            let better = match &best {
                None => true,
                Some((c, l, _)) => count > *c || (count == *c && level < *l),
            };
            if better {
                best = Some((count, level, inl));
            }
        }
    }
    match best {
        Some((count, _, inl)) if count >= 3 => Some(bins.iter().zip(inl).filter(|(_, k)| *k).map(|(b, _)| b).collect()),
        _ => None,
    }
}
