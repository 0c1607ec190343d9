//! Probe: the blind exposure pooled over flow directions (`fit::pooled_exposure`).
//! `MODE=scatter`: how far sharp crops' along/across contrast r strays from one
//! second harmonic over 12 directions, each a different crop (the constant
//! `HARMONIC_SCATTER` in `src/fit/isotropy_pool.rs`). Default: λ read per frame vs pooled, on photographs
//! blurred along several directions, each frame a different crop.
//! `cargo run --release --example mb_pool_probe`
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::fit::{fit, pooled_exposure, Effects, FitInputs, FitOptions, IsotropyEvidence, Tier};
use blind_augment::image::{Flow, Rgb};
use blind_augment::synth;

fn photos() -> Vec<(&'static str, Rgb)> {
    if std::env::var_os("ANISO").is_some() {
        return vec![("aniso 3/1.2", synth::sequence::anisotropic_texture(800, 700, 3.0, 1.2, 17))];
    }
    vec![
        ("astronaut", common::photo("astronaut.png")),
        ("chelsea", common::photo("chelsea.png")),
        ("motorcycle", synth::sequence::motorcycle().expect("bundled").image),
    ]
}

/// The crop of frame `i` of `n`: a `cw × ch` window walking the photo.
fn crop_at(img: &Rgb, i: usize, n: usize, cw: usize, ch: usize) -> Rgb {
    let (mx, my) = (img.width - cw, img.height - ch);
    let t = i as f32 / n.max(1) as f32;
    // A Lissajous walk: different content per frame, covering the photo.
    let x = ((0.5 + 0.5 * (std::f32::consts::TAU * t).sin()) * mx as f32) as usize;
    let y = ((0.5 + 0.5 * (2.0 * std::f32::consts::TAU * t + 0.7).sin()) * my as f32) as usize;
    common::crop(img, x, y, cw, ch)
}

/// `SIGMA`: a uniform Gaussian defocus (px) after the streak; `NOISE`: sensor noise
/// (the tests' Poisson–Gaussian, scaled) — both what leaves the streak's zeros
/// unidentified and the single frame on its isotropy path.
fn evidence(img: &Rgb, flow: &Flow, lambda: f32) -> (String, Option<IsotropyEvidence>) {
    let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<f32>().ok()).unwrap_or(0.0);
    let mut blurred = synth::add_motion_blur(img, flow, lambda);
    let sigma = env("SIGMA");
    if sigma > 0.0 {
        let k = blind_augment::image::discrete_gaussian_kernel(sigma * sigma);
        for c in 0..3 {
            let p = blind_augment::image::Plane::from_vec(blurred.width, blurred.height, blurred.channels[c].clone());
            blurred.channels[c] = blind_augment::image::blur_separable(&p, &k).data;
        }
    }
    let noise = env("NOISE");
    if noise > 0.0 {
        blurred = common::add_sensor_noise(
            &blurred,
            [2e-5 * noise, 1.2e-5 * noise, 4e-5 * noise],
            [8e-4 * noise, 5e-4 * noise, 1.2e-3 * noise],
            7,
        );
    }
    let blurred = common::quantize8(&blurred);
    let opts = FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
        ..Default::default()
    };
    let out = fit(&FitInputs { flow: Some(flow), ..FitInputs::new(&blurred) }, &opts).expect("valid");
    let mb = out.model.motion_blur;
    let own = format!(
        "{:?} ± {:.3} {:?}",
        mb.exposure.map(|l| (l * 1000.0).round() / 1000.0),
        mb.diagnostics.stderr.unwrap_or(f64::NAN),
        mb.diagnostics.status
    );
    if std::env::var_os("REASON").is_some() {
        println!("  {}", mb.diagnostics.reason);
    }
    (own, out.plots.motion_blur.and_then(|p| p.isotropy))
}

fn main() {
    let mode = std::env::var("MODE").unwrap_or_default();
    let (cw, ch) = (300usize, 260usize);
    let speed = std::env::var("SPEED").ok().and_then(|s| s.parse().ok()).unwrap_or(8.0f32);
    if mode == "scatter" {
        // λ = 0: r of the sharp crop is the texture's own anisotropy.
        let mut all = vec![];
        for (name, img) in photos() {
            for same in [true, false] {
                let ev: Vec<IsotropyEvidence> = (0..12)
                    .filter_map(|i| {
                        let th = i as f32 * std::f32::consts::PI / 12.0;
                        let flow = Flow::uniform(cw, ch, speed * th.cos(), speed * th.sin());
                        let c = if same { crop_at(&img, 0, 1, cw, ch) } else { crop_at(&img, i, 12, cw, ch) };
                        evidence(&c, &flow, 0.0).1
                    })
                    .collect();
                let refs: Vec<&IsotropyEvidence> = ev.iter().collect();
                let rs: Vec<(f64, f64, f64)> = refs
                    .iter()
                    .flat_map(|e| e.bins.iter())
                    .filter(|b| b.samples >= 64)
                    .map(|b| {
                        let n = b.samples as f64;
                        (b.cos2 / n, b.sin2 / n, b.diff[0] / b.sum[0])
                    })
                    .collect();
                // Unweighted harmonic fit of r at λ = 0.
                let (mut ncc, mut ncs, mut nss, mut rc, mut rsn) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for &(c, s, r) in &rs {
                    ncc += c * c;
                    ncs += c * s;
                    nss += s * s;
                    rc += c * r;
                    rsn += s * r;
                }
                let det = ncc * nss - ncs * ncs;
                let (a, b) = ((nss * rc - ncs * rsn) / det, (ncc * rsn - ncs * rc) / det);
                let res: Vec<f64> = rs.iter().map(|&(c, s, r)| r - a * c - b * s).collect();
                let sd = (res.iter().map(|x| x * x).sum::<f64>() / (res.len() as f64 - 2.0)).sqrt();
                println!(
                    "{name:10} {} crops: {} bins, harmonic a {a:.3} b {b:.3}, residual sd {sd:.4}, max |res| {:.4}",
                    if same { "same" } else { "walking" },
                    rs.len(),
                    res.iter().fold(0.0f64, |m, x| m.max(x.abs()))
                );
                if !same {
                    all.extend(res);
                }
            }
        }
        let sd = (all.iter().map(|x| x * x).sum::<f64>() / all.len() as f64).sqrt();
        let mut abs: Vec<f64> = all.iter().map(|x| x.abs()).collect();
        abs.sort_by(|a, b| a.total_cmp(b));
        println!(
            "walking crops, all photos: rms {sd:.4}, p68 {:.4}, p90 {:.4}",
            abs[abs.len() * 68 / 100],
            abs[abs.len() * 9 / 10]
        );
        return;
    }
    let dir_sets: Vec<(&str, Vec<f32>)> = vec![
        ("0,90", vec![0.0, 90.0]),
        ("0,60,120", vec![0.0, 60.0, 120.0]),
        ("6 dirs", (0..6).map(|i| i as f32 * 30.0).collect()),
        ("yaw-ish 0,10,20", vec![0.0, 10.0, 20.0]),
        ("30,90,150", vec![30.0, 90.0, 150.0]),
    ];
    for (name, img) in photos() {
        for lambda in [0.0f32, 0.2, 0.5] {
            for (set, dirs) in &dir_sets {
                let mut own = vec![];
                let mut ev = vec![];
                for (i, deg) in dirs.iter().enumerate() {
                    let th = deg.to_radians();
                    let flow = Flow::uniform(cw, ch, speed * th.cos(), speed * th.sin());
                    let (o, e) = evidence(&crop_at(&img, i, dirs.len(), cw, ch), &flow, lambda);
                    own.push(o);
                    if let Some(e) = e {
                        ev.push(e);
                    }
                }
                let refs: Vec<&IsotropyEvidence> = ev.iter().collect();
                let p = pooled_exposure(&refs);
                println!(
                    "{name:10} λ {lambda} {set:16} pooled {} | per frame {}",
                    p.map_or("none".into(), |p| format!(
                        "{:.3} ± {:.3} (bins {}, rank {}, dof {}, χ² {:.2}, a {:.3} b {:.3})",
                        p.lambda, p.stderr, p.bins, p.rank, p.dof, p.chi2_per_dof, p.anisotropy[0], p.anisotropy[1]
                    )),
                    own.join("; ")
                );
            }
        }
    }
}
