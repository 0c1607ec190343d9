//! Real camera noise against a multi-shot reference: the PolyU real-world noisy
//! image dataset (Xu et al., "Real-world Noisy Image Denoising: A New Benchmark",
//! 2018: 100 crops of 512² from 40 static scenes, five cameras, ISO 800–12800, each
//! one in-camera JPEG shot beside the mean of ~500 shots of the same scene).
//! Per crop: the noise N = shot − mean; each tier's fit (fast: the shot alone;
//! accurate: the shot with the mean as I_noNoise) synthesises grain on the mean
//! (`synth::noise_field`), and both are measured the same way, per channel and
//! luma bin of the mean (8 bins; clipped pixels out): the per-pixel std, and the
//! std of each band-pass level of the Laplacian pyramid. Error: synthesised ÷ real
//! − 1. Run: `cargo xtask bench-quality MIRRORS` (sets `BENCH_REAL_NOISE` to the
//! extracted crops' manifest); prints Markdown for BENCHMARKS.md.
//!
//! The split is by scene (crops of one scene share its camera, ISO and texture):
//! the held-out scenes are listed in `xtask/src/scenes.rs` and are only ever
//! reported in aggregate.

#[path = "../tests/common/mod.rs"]
mod common;

use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Tier};
use blind_augment::image::{gaussian_pyramid, laplacian_pyramid, Plane, Rgb};
use blind_augment::io::load_rgb;
use blind_augment::model::{Noise, Status, NOISE_LEVELS};
use blind_augment::synth::noise_field;
use std::path::Path;

const BINS: usize = 8;
/// Fewest level-0 pixels a (bin, channel) cell is measured on; a level-l band's
/// cells need a 4^l-th of it (at least 16): the std of n Gaussian samples scatters
/// by 1/√(2n), 2.2% at 1024.
const MIN_PIXELS: usize = 1024;

struct Crop {
    id: String,
    held_out: bool,
    shot: Rgb,
    mean: Rgb,
}

/// Per (bin, channel): the errors of one crop; `pixel` the per-pixel std's, `levels[l]`
/// the band-pass level l's.
struct CropErrors {
    pixel: Vec<f64>,
    levels: [Vec<f64>; NOISE_LEVELS],
    status: Status,
}

/// Pixels clipped in either image (any channel at 0 or 255 of 8 bits): their noise
/// is cut, not the sensor's.
fn clip_mask(a: &Rgb, b: &Rgb) -> Plane {
    let data = (0..a.len())
        .map(|i| {
            let clipped = (0..3).any(|c| {
                [a.channels[c][i], b.channels[c][i]].iter().any(|&v| !(0.5 / 255.0..=254.5 / 255.0).contains(&v))
            });
            if clipped {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    Plane::from_vec(a.width, a.height, data)
}

/// Max-pool a mask by 2 (a coarse pixel is clipped if any of its 2×2 is).
fn pool(m: &Plane, w: usize, h: usize) -> Plane {
    let data = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let mut v = 0.0f32;
            for dy in 0..2 {
                for dx in 0..2 {
                    let (sx, sy) = ((2 * x + dx).min(m.width - 1), (2 * y + dy).min(m.height - 1));
                    v = v.max(m.get(sx, sy));
                }
            }
            v
        })
        .collect();
    Plane::from_vec(w, h, data)
}

/// Per channel and luma bin: the std of `field`'s channel over the unclipped
/// pixels whose `luma` falls in the bin; `None` below `min_n` pixels.
fn binned_std(field: &[Plane; 3], luma: &Plane, clipped: &Plane, min_n: usize) -> [[Option<f64>; 3]; BINS] {
    std::array::from_fn(|b| {
        std::array::from_fn(|c| {
            let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0usize);
            for i in 0..luma.data.len() {
                let y = luma.data[i];
                if clipped.data[i] > 0.5 || ((y * BINS as f32) as usize).min(BINS - 1) != b {
                    continue;
                }
                let v = field[c].data[i] as f64;
                s += v;
                s2 += v * v;
                n += 1;
            }
            (n >= min_n).then(|| {
                let m = s / n as f64;
                (s2 / n as f64 - m * m).max(0.0).sqrt()
            })
        })
    })
}

/// The per-pixel and per-level stds of a noise field, binned by the mean's luma.
struct Measure {
    pixel: [[Option<f64>; 3]; BINS],
    levels: Vec<[[Option<f64>; 3]; BINS]>,
}

fn measure(noise: &Rgb, mean: &Rgb, clipped: &Plane) -> Measure {
    let luma = gaussian_pyramid(&mean.luma(), NOISE_LEVELS);
    let planes: [Plane; 3] = std::array::from_fn(|c| noise.plane(c));
    let pixel = binned_std(&planes, &luma[0], clipped, MIN_PIXELS);
    let bands: Vec<Vec<Plane>> = planes.iter().map(|p| laplacian_pyramid(p, NOISE_LEVELS).bands).collect();
    let mut mask = clipped.clone();
    let mut levels = vec![];
    for l in 0..NOISE_LEVELS {
        if l > 0 {
            mask = pool(&mask, luma[l].width, luma[l].height);
        }
        let b: [Plane; 3] = std::array::from_fn(|c| bands[c][l].clone());
        levels.push(binned_std(&b, &luma[l], &mask, (MIN_PIXELS >> (2 * l)).max(16)));
    }
    Measure { pixel, levels }
}

fn errors(model: &Noise, truth: &Measure, crop: &Crop, clipped: &Plane) -> CropErrors {
    let mut out = CropErrors { status: model.diagnostics.status, pixel: vec![], levels: Default::default() };
    let field = noise_field(&crop.mean.luma(), model, 7);
    let got = measure(&field, &crop.mean, clipped);
    let push = |v: &mut Vec<f64>, g: &[[Option<f64>; 3]; BINS], t: &[[Option<f64>; 3]; BINS]| {
        for b in 0..BINS {
            for c in 0..3 {
                if let (Some(g), Some(t)) = (g[b][c], t[b][c]) {
                    if t > 0.0 {
                        v.push(g / t - 1.0);
                    }
                }
            }
        }
    };
    push(&mut out.pixel, &got.pixel, &truth.pixel);
    for l in 0..NOISE_LEVELS {
        push(&mut out.levels[l], &got.levels[l], &truth.levels[l]);
    }
    out
}

fn load(path: &str) -> Result<Rgb, String> {
    load_rgb(Path::new(path)).map(|(i, _)| i).map_err(|e| format!("{path}: {e}"))
}

fn read_manifest(path: &str) -> Result<Vec<Crop>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut out = vec![];
    for line in text.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
        let f: Vec<&str> = line.split('\t').collect();
        let [id, split, shot, mean] = f[..] else {
            return Err(format!("{path}: a line needs id, split, shot, mean: {line:?}"));
        };
        let (shot, mean) = (load(shot)?, load(mean)?);
        if (shot.width, shot.height) != (mean.width, mean.height) {
            return Err(format!("{id}: shot and mean differ in size"));
        }
        out.push(Crop { id: id.into(), held_out: split == "held-out", shot, mean });
    }
    Ok(out)
}

fn pct(mut v: Vec<f64>, q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let Ok(manifest) = std::env::var("BENCH_REAL_NOISE") else {
        eprintln!("BENCH_REAL_NOISE is not set: run `cargo xtask bench-quality MIRRORS`");
        return;
    };
    let crops = match read_manifest(&manifest) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let trace = std::env::var("BENCH_REAL_NOISE_TRACE").is_ok();
    // While tuning: the tuning split only (the held-out crops are not even fitted).
    let tuning_only = std::env::var("BENCH_REAL_NOISE_TUNING").is_ok();
    // results[tier][split] = the crops' errors.
    let tiers = [("fast", Tier::Fast), ("accurate", Tier::Accurate)];
    let mut results: Vec<[Vec<CropErrors>; 2]> = (0..tiers.len()).map(|_| [vec![], vec![]]).collect();
    for (i, crop) in crops.iter().enumerate() {
        if tuning_only && crop.held_out {
            continue;
        }
        eprint!("\r{}/{} {}        ", i + 1, crops.len(), crop.id);
        let clipped = clip_mask(&crop.shot, &crop.mean);
        let noise = Rgb {
            width: crop.shot.width,
            height: crop.shot.height,
            channels: std::array::from_fn(|c| {
                crop.shot.channels[c].iter().zip(&crop.mean.channels[c]).map(|(a, b)| a - b).collect()
            }),
        };
        let truth = measure(&noise, &crop.mean, &clipped);
        if trace && !crop.held_out {
            // The truth's own shape: level stds over level 0's (green, median over
            // bins), and how much of the mean's structure the difference holds per
            // level (correlation of the luma bands).
            let med = |l: usize| {
                common::median(
                    (0..BINS).filter_map(|b| Some(truth.levels[l][b][1]? / truth.levels[0][b][1]?)).collect(),
                )
            };
            let nb = laplacian_pyramid(&noise.luma(), NOISE_LEVELS).bands;
            let mb = laplacian_pyramid(&crop.mean.luma(), NOISE_LEVELS).bands;
            let corr: Vec<String> = (0..NOISE_LEVELS)
                .map(|l| {
                    let (mut ab, mut aa, mut bb) = (0.0f64, 0.0f64, 0.0f64);
                    for (a, b) in nb[l].data.iter().zip(&mb[l].data) {
                        ab += (*a as f64) * (*b as f64);
                        aa += (*a as f64).powi(2);
                        bb += (*b as f64).powi(2);
                    }
                    format!("{:+.2}", ab / (aa * bb).sqrt())
                })
                .collect();
            // The truth on the flattest fifth of each luma bin (structure energy of
            // the mean's luma band two levels coarser), per level, over the truth on
            // every pixel of the bin (green, median over bins).
            let mpyr = laplacian_pyramid(&crop.mean.luma(), NOISE_LEVELS + 2).bands;
            let lpyr = gaussian_pyramid(&crop.mean.luma(), NOISE_LEVELS);
            let npyr = laplacian_pyramid(&noise.plane(1), NOISE_LEVELS).bands;
            let flat_ratio: Vec<String> = (0..NOISE_LEVELS)
                .map(|l| {
                    let st = &mpyr[l + 2];
                    let (w, h) = (npyr[l].width, npyr[l].height);
                    let energy = |x: usize, y: usize| {
                        let (cx, cy) = (x >> 2, y >> 2);
                        let mut e = 0.0f32;
                        for dy in 0..3 {
                            for dx in 0..3 {
                                let (sx, sy) = (
                                    (cx + dx).saturating_sub(1).min(st.width - 1),
                                    (cy + dy).saturating_sub(1).min(st.height - 1),
                                );
                                e += st.get(sx, sy).powi(2);
                            }
                        }
                        e
                    };
                    let mut per_bin: Vec<Vec<(f32, f32)>> = vec![vec![]; BINS];
                    for y in 0..h {
                        for x in 0..w {
                            let b = ((lpyr[l].get(x, y) * BINS as f32) as usize).min(BINS - 1);
                            per_bin[b].push((energy(x, y), npyr[l].get(x, y)));
                        }
                    }
                    let r: Vec<f64> = per_bin
                        .into_iter()
                        .filter(|v| v.len() >= (MIN_PIXELS >> (2 * l)).max(16) * 5)
                        .map(|mut v| {
                            let all = (v.iter().map(|p| (p.1 as f64).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
                            v.sort_by(|a, b| a.0.total_cmp(&b.0));
                            let k = v.len() / 5;
                            let flat = (v[..k].iter().map(|p| (p.1 as f64).powi(2)).sum::<f64>() / k as f64).sqrt();
                            flat / all
                        })
                        .collect();
                    format!("{:.2}", common::median(r))
                })
                .collect();
            eprintln!("\n{} truth on the flattest fifth over all: {}", crop.id, flat_ratio.join(" "));
            eprintln!(
                "\n{} truth: level ratios 1 {:.2} 2 {:.2} 3 {:.2}; corr with the mean's bands {}",
                crop.id,
                med(1),
                med(2),
                med(3),
                corr.join(" ")
            );
        }
        for (t, (name, tier)) in tiers.iter().enumerate() {
            let mut inputs = FitInputs::new(&crop.shot);
            if *tier == Tier::Accurate {
                inputs.denoised = Some(&crop.mean);
            }
            let opts = FitOptions {
                tier: Some(*tier),
                effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
                ..FitOptions::default()
            };
            let model = match fit(&inputs, &opts) {
                Ok(r) => r.model.noise,
                Err(e) => {
                    eprintln!("\n{}: {name} fit failed: {e}", crop.id);
                    continue;
                }
            };
            let e = errors(&model, &truth, crop, &clipped);
            if trace && !crop.held_out {
                let m = |v: &[f64]| 100.0 * common::median(v.to_vec());
                eprintln!(
                    "\n{} {name}: pixel {:+.0}%, levels {:+.0} {:+.0} {:+.0} {:+.0}% ({})",
                    crop.id,
                    m(&e.pixel),
                    m(&e.levels[0]),
                    m(&e.levels[1]),
                    m(&e.levels[2]),
                    m(&e.levels[3]),
                    model.diagnostics.reason
                );
            }
            results[t][crop.held_out as usize].push(e);
        }
    }
    eprintln!();
    println!("| tier | split | crops | absent / not identifiable | per-pixel std: median \\|err\\| / p90 / signed median | level 0 | level 1 | level 2 | level 3 |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for (t, (name, _)) in tiers.iter().enumerate() {
        for (s, split) in ["tuning", "held-out"].iter().enumerate() {
            let r = &results[t][s];
            let all =
                |f: &dyn Fn(&CropErrors) -> &Vec<f64>| -> Vec<f64> { r.iter().flat_map(|e| f(e).clone()).collect() };
            let abs = |v: &[f64]| v.iter().map(|e| e.abs()).collect::<Vec<_>>();
            let pixel = all(&|e| &e.pixel);
            let lv: Vec<String> = (0..NOISE_LEVELS)
                .map(|l| {
                    let v = all(&|e| &e.levels[l]);
                    format!("{:.0}% / {:+.0}%", 100.0 * pct(abs(&v), 0.5), 100.0 * pct(v.clone(), 0.5))
                })
                .collect();
            println!(
                "| {name} | {split} | {} | {} / {} | {:.0}% / {:.0}% / {:+.0}% | {} |",
                r.len(),
                r.iter().filter(|e| e.status == Status::Absent).count(),
                r.iter().filter(|e| e.status == Status::NotIdentifiable).count(),
                100.0 * pct(abs(&pixel), 0.5),
                100.0 * pct(abs(&pixel), 0.9),
                100.0 * pct(pixel.clone(), 0.5),
                lv.join(" | ")
            );
        }
    }
    println!();
    println!(
        "Cells: (crop, luma bin, channel) with ≥ {MIN_PIXELS} unclipped pixels (a level-l band: a 4^l-th, ≥ 16); \
         levels as median |err| / signed median; a fit without noise present synthesises none (−100%)."
    );
}
