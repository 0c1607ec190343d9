//! Lateral chromatic aberration on known answers made elsewhere: real lenses'
//! measured transverse chromatic aberration (lensfun's TCA profiles: "poly3"'s
//! linear terms vr, vb — its cubic terms are 1–2 orders smaller — and "linear"'s kr,
//! kb) applied to the vendored photographs at the corner shifts a 1280×960 camera
//! would show ((v − 1)·800 px), 8-bit quantised with noise σ 0.01; `fit::chromatic`
//! on each. Greyscale copies have no aberration of their own (the truth is the
//! applied one); on the colour photographs the applied shift is read as the
//! difference from the photograph read without it. Run: `cargo xtask bench-quality
//! MIRRORS --vignetting-only` (extracts lensfun's database, sets `BENCH_LENSFUN`);
//! prints Markdown for BENCHMARKS.md.
//!
//! Lenses are split as in `benches/vignetting.rs` (a third held out by a hash of the
//! lens name); 40 profiles of each split, evenly through the database's order.

#[path = "../tests/common/mod.rs"]
mod common;

use blind_augment::fit::chromatic::estimate;
use blind_augment::image::Rgb;
use blind_augment::synth::add_lateral_ca;
use common::lensfun::{attr, entries};
use common::scenes::name_hash;
use common::{grey, summary};

/// A 1280×960 frame's half-diagonal (px): the corner shifts the profiles are shown at.
const HALF_DIAG_1280_PX: f32 = 800.0;
const PER_SPLIT: usize = 40;
const PHOTOS: [&str; 3] = ["astronaut.png", "chelsea.png", "rocket.jpg"];

struct Tca {
    lens: String,
    focal_mm: f32,
    v: [f32; 2],
}

fn profiles(dir: &str) -> Vec<Tca> {
    let mut out: Vec<Tca> = vec![];
    for (lens, line) in entries(dir, "tca") {
        let v = if line.contains("model=\"poly3\"") {
            attr(&line, "vr").zip(attr(&line, "vb"))
        } else if line.contains("model=\"linear\"") {
            attr(&line, "kr").zip(attr(&line, "kb"))
        } else {
            None
        };
        let (Some((vr, vb)), Some(focal_mm)) = (v, attr(&line, "focal")) else { continue };
        let dup = out.iter().any(|q| q.lens == lens && q.focal_mm == focal_mm);
        if (vr - 1.0).abs() <= 0.01 && (vb - 1.0).abs() <= 0.01 && !dup {
            out.push(Tca { lens, focal_mm, v: [vr, vb] });
        }
    }
    out
}

fn camera(img: &Rgb) -> Rgb {
    let mut out = img.clone();
    for (c, ch) in out.channels.iter_mut().enumerate() {
        for (i, v) in ch.iter_mut().enumerate() {
            let (x, y) = ((i % img.width) as u32, (i / img.width) as u32);
            *v = ((*v + 0.01 * blind_augment::synth::gaussian(x, y, c as u32, 5)).clamp(0.0, 1.0) * 255.0).round()
                / 255.0;
        }
    }
    out
}

fn main() {
    let Some(dir) = std::env::var_os("BENCH_LENSFUN") else {
        eprintln!("BENCH_LENSFUN is not set: run `cargo xtask bench-quality MIRRORS --vignetting-only`");
        return;
    };
    let all = profiles(&dir.to_string_lossy());
    let pick = |held: bool| -> Vec<&Tca> {
        let pool: Vec<&Tca> = all.iter().filter(|p| (name_hash(&p.lens) % 3 == 0) == held).collect();
        let step = (pool.len() / PER_SPLIT).max(1);
        pool.into_iter().step_by(step).take(PER_SPLIT).collect()
    };
    let shifts: Vec<f32> = all.iter().flat_map(|p| p.v.map(|v| ((v - 1.0) * HALF_DIAG_1280_PX).abs())).collect();
    println!("### Lateral chromatic aberration on measured lenses\n");
    println!(
        "{} lensfun TCA profiles (lens, focal length); their corner shifts at 1280×960, |v − 1|·800 px, median / p90 / largest: {}. {PER_SPLIT} per split, on {} photographs (greyscale copy and colour), σ 0.01, 8-bit.\n",
        all.len(),
        summary(&shifts),
        PHOTOS.len()
    );
    println!("| split | scene | readings | \\|error\\| of the corner shift (px) | relative error where the shift ≥ 0.2 px |\n|---|---|---|---|---|");
    let photos: Vec<(String, Rgb)> = PHOTOS.iter().map(|n| (n.to_string(), common::photo(n))).collect();
    for held in [false, true] {
        let lenses = pick(held);
        for colour in [false, true] {
            let (mut abs, mut rel) = (vec![], vec![]);
            for (_, photo) in &photos {
                let base = if colour { photo.clone() } else { grey(photo) };
                let half_diag = 0.5 * (base.width as f32 - 1.0).hypot(base.height as f32 - 1.0);
                let own = estimate(&camera(&base));
                for p in &lenses {
                    let want = p.v.map(|v| (v - 1.0) * HALF_DIAG_1280_PX);
                    let scale = want.map(|s| 1.0 + s / half_diag);
                    let got = estimate(&camera(&add_lateral_ca(&base, scale)));
                    for k in 0..2 {
                        let (Some(g), Some(o)) = (got[k], own[k]) else { continue };
                        let read = ((g.scale_minus_one - if colour { o.scale_minus_one } else { 0.0 })
                            * half_diag as f64) as f32;
                        let e = (read - want[k]).abs();
                        abs.push(e);
                        if want[k].abs() >= 0.2 {
                            rel.push(e / want[k].abs());
                        }
                    }
                }
            }
            println!(
                "| {} | {} | {} | {} | {} |",
                if held { "held-out" } else { "tuning" },
                if colour { "colour, minus its own" } else { "greyscale" },
                abs.len(),
                summary(&abs),
                summary(&rel)
            );
        }
    }
}
