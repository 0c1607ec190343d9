//! White balance against measured illuminants, and the colour fit's known answers
//! and cost. Three parts, Markdown on stdout for BENCHMARKS.md:
//! 1. Real photographs with a colour checker's illuminant (`BENCH_COLOUR`, the
//!    manifest `cargo xtask bench-quality MIRRORS` writes: Cube+, NUS 8-camera,
//!    INTEL-TAU, Gehler–Shi, SimpleCube++): every member of the general grey-world
//!    family (`fit::colour::GreyFamily`) on each, the angular error per split, the
//!    chosen `ESTIMATOR` per camera, and whether its stated error covers the truth.
//!    The split is by camera (`xtask/src/colour_corpus.rs`).
//! 2. Known answers: the project's vendored photographs (their cameras' own white
//!    balance taken as neutral) rendered under CIE illuminants without white
//!    balance, 8-bit sRGB; `fit_colour` against the applied cast.
//! 3. `fit_colour`'s cost on a 1280×960 frame (the headset's camera size).

use blind_augment::fit::colour::{
    angular_error_deg, fit_colour, illuminant, GreyFamily, LinearFrame, CONTENT_FLOOR_DEG, ESTIMATOR, WORK_SIDE_PX,
};
use blind_augment::image::{Rgb, LUMA_WEIGHTS};
use blind_augment::io::load_rgb;
use std::path::Path;
use std::time::Instant;

struct Photo {
    id: String,
    held_out: bool,
    camera: String,
    frame: LinearFrame,
    truth: [f64; 3],
}

fn members() -> Vec<GreyFamily> {
    let mut v = vec![];
    for order in [0u8, 1] {
        for p in [1.0f32, 2.0, 4.0, 6.0, 8.0, 12.0, f32::INFINITY] {
            v.push(GreyFamily { order, p });
        }
    }
    v
}

fn read_npy_f32(path: &Path) -> Result<(Vec<u64>, Vec<f64>), String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let npy = npyz::NpyFile::new(&bytes[..]).map_err(|e| format!("{}: {e}", path.display()))?;
    let shape = npy.shape().to_vec();
    let data: Vec<f64> = match npy.dtype().descr().trim_matches('\'') {
        "<f4" => npy.into_vec::<f32>().map_err(|e| e.to_string())?.into_iter().map(f64::from).collect(),
        "<f8" => npy.into_vec::<f64>().map_err(|e| e.to_string())?,
        d => return Err(format!("{}: dtype {d}", path.display())),
    };
    Ok((shape, data))
}

fn load(line: &str) -> Result<Option<Photo>, String> {
    if line.starts_with('#') || line.trim().is_empty() {
        return Ok(None);
    }
    let f: Vec<&str> = line.split('\t').collect();
    let [id, split, camera, kind, image, truth] = f[..] else { return Err(format!("bad manifest row: {line}")) };
    let frame = if kind == "npy" {
        let (shape, data) = read_npy_f32(Path::new(image))?;
        let [h, w, 3] = shape[..] else { return Err(format!("{image}: shape {shape:?}")) };
        let (h, w) = (h as usize, w as usize);
        // Thumbnails scaled so their maximum is 1: what reaches 0.98 may be clipped.
        LinearFrame::downsample(
            w,
            h,
            WORK_SIDE_PX,
            |c, x, y| data[(y * w + x) * 3 + c] as f32,
            |x, y| (0..3).any(|c| data[(y * w + x) * 3 + c] >= 0.98),
        )
    } else if let Some(levels) = kind.strip_prefix("png16:") {
        let (black, sat): (f32, f32) = match levels.split_once(':') {
            Some((b, s)) => (b.parse().map_err(|_| kind.to_string())?, s.parse().map_err(|_| kind.to_string())?),
            None => return Err(format!("bad kind {kind}")),
        };
        let img = image::open(image).map_err(|e| format!("{image}: {e}"))?.into_rgb16();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let px = img.into_raw();
        LinearFrame::downsample(
            w,
            h,
            WORK_SIDE_PX,
            |c, x, y| ((px[(y * w + x) * 3 + c] as f32 - black) / (sat - black)).max(0.0),
            |x, y| (0..3).any(|c| px[(y * w + x) * 3 + c] as f32 >= sat),
        )
    } else {
        return Err(format!("unknown kind {kind}"));
    };
    let truth: Vec<f64> = if truth.ends_with(".npy") {
        read_npy_f32(Path::new(truth))?.1
    } else {
        truth
            .split(',')
            .map(|v| v.parse::<f64>().map_err(|_| format!("bad truth {truth}")))
            .collect::<Result<_, _>>()?
    };
    let [r, g, b] = truth[..] else { return Err(format!("{id}: truth {truth:?}")) };
    Ok(Some(Photo { id: id.into(), held_out: split == "held-out", camera: camera.into(), frame, truth: [r, g, b] }))
}

fn stats(v: &mut [f64]) -> (f64, f64, f64, f64) {
    v.sort_by(|a, b| a.total_cmp(b));
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (q(0.5), mean, q(0.9), *v.last().unwrap_or(&f64::NAN))
}

fn real_photographs(manifest: &Path) {
    let text = std::fs::read_to_string(manifest).expect("BENCH_COLOUR manifest");
    let mut photos = vec![];
    let mut skipped = 0usize;
    for line in text.lines() {
        match load(line) {
            Ok(Some(p)) => photos.push(p),
            Ok(None) => {}
            Err(e) => {
                eprintln!("skipped: {e}");
                skipped += 1;
            }
        }
    }
    let started = Instant::now();
    let ms = members();
    // errors[m][i]: member m on photo i (NaN: not identifiable).
    let errors: Vec<Vec<f64>> = ms
        .iter()
        .map(|&m| {
            photos
                .iter()
                .map(|p| illuminant(&p.frame, m).map_or(f64::NAN, |e| angular_error_deg(e.rgb, p.truth)))
                .collect()
        })
        .collect();
    let tuning = photos.iter().filter(|p| !p.held_out).count();
    println!(
        "{} photographs ({} tuning, {} held out; {skipped} unreadable), {} cameras; {:.1} s",
        photos.len(),
        tuning,
        photos.len() - tuning,
        {
            let mut c: Vec<&str> = photos.iter().map(|p| p.camera.as_str()).collect();
            c.sort();
            c.dedup();
            c.len()
        },
        started.elapsed().as_secs_f64()
    );
    println!();
    println!("| estimator | tuning: median / mean / p90 / worst | held-out: median / mean / p90 / worst | not identifiable |");
    println!("|---|---|---|---|");
    for (m, errs) in ms.iter().zip(&errors) {
        let mut cells = vec![];
        for held in [false, true] {
            let mut v: Vec<f64> = errs
                .iter()
                .zip(&photos)
                .filter(|(e, p)| p.held_out == held && e.is_finite())
                .map(|(e, _)| *e)
                .collect();
            let (md, mean, p90, worst) = stats(&mut v);
            cells.push(format!("{md:.2}° / {mean:.2}° / {p90:.2}° / {worst:.1}°"));
        }
        let ni = errs.iter().filter(|e| !e.is_finite()).count();
        let mark = if *m == ESTIMATOR { " **(used)**" } else { "" };
        println!("| {}{mark} | {} | {} | {ni} |", m.name(), cells[0], cells[1]);
    }
    // The chosen one per camera, and its stated error's coverage.
    let k = ms.iter().position(|m| *m == ESTIMATOR).expect("ESTIMATOR is a member");
    println!();
    println!(
        "`{}` per camera; covered: error within 1σ / 2σ of the stated error (jackknife ⊕ {CONTENT_FLOOR_DEG}° floor):",
        ESTIMATOR.name()
    );
    println!();
    println!("| camera | split | photos | median | p90 | covered 1σ / 2σ |");
    println!("|---|---|---|---|---|---|");
    let mut cams: Vec<(&str, bool)> = photos.iter().map(|p| (p.camera.as_str(), p.held_out)).collect();
    cams.sort();
    cams.dedup();
    for (cam, held) in cams {
        let idx: Vec<usize> = (0..photos.len()).filter(|&i| photos[i].camera == cam).collect();
        let mut v: Vec<f64> = idx.iter().map(|&i| errors[k][i]).filter(|e| e.is_finite()).collect();
        let covered = |z: f64| {
            idx.iter()
                .filter(|&&i| {
                    illuminant(&photos[i].frame, ESTIMATOR)
                        .is_some_and(|e| errors[k][i] <= z * e.jackknife_deg.hypot(CONTENT_FLOOR_DEG))
                })
                .count()
        };
        let n = v.len();
        let (md, _, p90, _) = stats(&mut v);
        println!(
            "| {cam} | {} | {n} | {md:.2}° | {p90:.2}° | {:.0}% / {:.0}% |",
            if held { "held-out" } else { "tuning" },
            100.0 * covered(1.0) as f64 / idx.len() as f64,
            100.0 * covered(2.0) as f64 / idx.len() as f64
        );
    }
    // The floor that makes the stated error a one-sigma one on the tuning split
    // (68% of the errors within it), by bisection: what `CONTENT_FLOOR_DEG` is
    // set from.
    let jk: Vec<(f64, f64)> = photos
        .iter()
        .zip(&errors[k])
        .filter(|(p, e)| !p.held_out && e.is_finite())
        .filter_map(|(p, e)| illuminant(&p.frame, ESTIMATOR).map(|x| (*e, x.jackknife_deg)))
        .collect();
    let cover = |f: f64, z: f64| jk.iter().filter(|(e, j)| *e <= z * j.hypot(f)).count() as f64 / jk.len() as f64;
    let (mut lo, mut hi) = (0.0f64, 20.0f64);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if cover(mid, 1.0) < 0.68 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    println!();
    println!(
        "Floor for a one-sigma stated error on the tuning split: {hi:.2}° (used {CONTENT_FLOOR_DEG}°: within 1σ {:.0}%, 2σ {:.0}% of tuning photos).",
        100.0 * cover(CONTENT_FLOOR_DEG, 1.0),
        100.0 * cover(CONTENT_FLOOR_DEG, 2.0)
    );
    if std::env::var_os("BENCH_COLOUR_WORST").is_some() {
        let mut worst: Vec<(f64, &str)> =
            errors[k].iter().zip(&photos).filter(|(_, p)| !p.held_out).map(|(e, p)| (*e, p.id.as_str())).collect();
        worst.sort_by(|a, b| b.0.total_cmp(&a.0));
        for (e, id) in worst.iter().take(10) {
            eprintln!("{id}: {e:.2}°");
        }
    }
}

/// CIE illuminants as chromaticities (CIE 15:2004, tables T.1 and T.8): what a
/// camera sees when its white balance does not correct them.
const ILLUMINANTS: [(&str, f64, f64); 7] = [
    ("A (tungsten, 2856 K)", 0.44757, 0.40745),
    ("F11 (TL84 fluorescent)", 0.38052, 0.37713),
    ("F2 (cool white fluorescent)", 0.37208, 0.37529),
    ("D50", 0.34567, 0.35850),
    ("D65 (none)", 0.31271, 0.32902),
    ("D75", 0.29902, 0.31485),
    ("LED-B5 (6500 K LED)", 0.3118, 0.3236),
];

/// The illuminant's colour in linear sRGB, relative to D65 (sRGB's white), luma 1.
fn cast_of(x: f64, y: f64) -> [f64; 3] {
    let xyz = [x / y, 1.0, (1.0 - x - y) / y];
    let m = [[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]];
    let lin = |v: [f64; 3]| -> [f64; 3] { std::array::from_fn(|r| (0..3).map(|c| m[r][c] * v[c]).sum()) };
    let d65 = lin([0.31271 / 0.32902, 1.0, (1.0 - 0.31271 - 0.32902) / 0.32902]);
    let rgb = lin(xyz);
    let g: [f64; 3] = std::array::from_fn(|c| rgb[c] / d65[c]);
    let l: f64 = (0..3).map(|c| LUMA_WEIGHTS[c] as f64 * g[c]).sum();
    g.map(|v| v / l)
}

fn encode(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    let e = if v <= 0.0031308 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
    (e * 255.0).round() / 255.0
}

fn known_answers() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let photos = [
        "assets/motorcycle_left_333x497.png",
        "tests/data/astronaut.png",
        "tests/data/chelsea.png",
        "tests/data/rocket.jpg",
        "tests/data/noise_vtest/mean.png",
        "tests/data/scenes/middlebury2005-Art/view1.png",
        "tests/data/scenes/middlebury2006-Aloe/view1.png",
        "tests/data/scenes/tum-rgbd/TUM_color.png",
    ];
    println!();
    println!("| illuminant | cast from neutral | photos | median / worst error (modelled) | median / worst (estimate) | present / not identifiable |");
    println!("|---|---|---|---|---|---|");
    let mut all = vec![];
    let mut own = vec![];
    for (name, x, y) in ILLUMINANTS {
        let cast = cast_of(x, y);
        let (mut modelled, mut raw, mut present, mut unknown) = (vec![], vec![], 0, 0);
        for p in photos {
            let Ok((img, _)) = load_rgb(&root.join(p)) else {
                eprintln!("skipped {p}");
                continue;
            };
            let mut out = Rgb::new(img.width, img.height, [0.0; 3]);
            for ((o, i), g) in out.channels.iter_mut().zip(&img.channels).zip(cast) {
                for (o, v) in o.iter_mut().zip(i) {
                    *o = encode(blind_augment::image::yuv::srgb_to_linear(*v) * g as f32);
                }
            }
            let fit = fit_colour(&out);
            present += fit.present as usize;
            // Not identifiable: no illuminant, counted apart (never as neutral).
            match fit.illuminant {
                Some(i) => {
                    let m = angular_error_deg(i.map(f64::from), cast);
                    modelled.push(m);
                    all.push(m);
                }
                None => unknown += 1,
            }
            if let Some(e) = illuminant(&LinearFrame::from_encoded(&out, WORK_SIDE_PX), ESTIMATOR) {
                raw.push(angular_error_deg(e.rgb, cast));
                if name.starts_with("D65") {
                    own.push(format!("{} {:.1}°", p.rsplit('/').next().unwrap_or(p), angular_error_deg(e.rgb, cast)));
                }
            }
        }
        let n = modelled.len() + unknown;
        let (m_md, _, _, m_w) = stats(&mut modelled);
        let (r_md, _, _, r_w) = stats(&mut raw);
        println!(
            "| {name} | {:.1}° | {n} | {m_md:.2}° / {m_w:.2}° | {r_md:.2}° / {r_w:.2}° | {present} / {unknown} |",
            angular_error_deg(cast, [1.0; 3])
        );
    }
    let (md, _, p90, w) = stats(&mut all);
    println!();
    println!("Each photograph's own reading under D65 (its colours against grey): {}.", own.join(", "));
    println!();
    println!(
        "All {} identifiable: median {md:.2}°, p90 {p90:.2}°, worst {w:.2}° (the modelled illuminant against the cast).",
        all.len()
    );
}

fn cost() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (img, _) = load_rgb(&root.join("tests/data/astronaut.png")).expect("astronaut");
    let (w, h) = (1280usize, 960usize);
    let mut big = Rgb::new(w, h, [0.0; 3]);
    for c in 0..3 {
        for y in 0..h {
            for x in 0..w {
                big.channels[c][y * w + x] = img.channels[c][(y * img.height / h) * img.width + x * img.width / w];
            }
        }
    }
    let mut t: Vec<f64> = (0..31)
        .map(|_| {
            let s = Instant::now();
            std::hint::black_box(fit_colour(&big));
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    let (md, _, p90, _) = stats(&mut t);
    println!();
    println!("`fit_colour` at 1280×960, one thread: median {md:.2} ms, p90 {p90:.2} ms (31 runs).");
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    match std::env::var_os("BENCH_COLOUR") {
        Some(m) => real_photographs(Path::new(&m)),
        None => eprintln!("BENCH_COLOUR not set: no real photographs (run `cargo xtask bench-quality MIRRORS`)"),
    }
    known_answers();
    cost();
}
