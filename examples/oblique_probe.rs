//! Probe: the blind exposure on one frame of oriented texture whose axis lies at
//! an angle to the flow, and on natural photographs at every flow direction —
//! what the fast fit reads (λ ± its standard error, status, the path that
//! answered) next to the diagonals' gradient-energy contrast
//! (`isotropy::IsotropyRoot::oblique_contrast`), which a streak along the flow
//! leaves at 0 on an isotropic scene.
//! `cargo run --release --example oblique_probe` (`SET=texture` or `SET=photos`
//! for one set; `LINES=1` prints every frame, `REASON=1` its reason too).
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Tier};
use blind_augment::image::{Flow, Rgb};
use blind_augment::model::Status;
use blind_augment::synth;

struct Read {
    lambda: f32,
    stderr: f64,
    status: Status,
    oblique: f64,
    oblique_se: f64,
    path: &'static str,
    reason: String,
}

fn read(img: &Rgb, flow: &Flow) -> Read {
    let opts = FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
        ..Default::default()
    };
    let out = fit(&FitInputs { flow: Some(flow), ..FitInputs::new(img) }, &opts).expect("fit");
    let mb = &out.model.motion_blur;
    let r = &mb.diagnostics.reason;
    // "diagonals' gradient-energy contrast x ± y" or "diagonals' contrast x ± y" in
    // the isotropy path's reason.
    let (oblique, oblique_se) = r
        .split("diagonals' gradient-energy contrast ")
        .nth(1)
        .or_else(|| r.split("diagonals' contrast ").nth(1))
        .and_then(|t| {
            let mut it = t.split(" ± ");
            let v = it.next()?.parse().ok()?;
            let se: String = it.next()?.chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
            Some((v, se.parse().ok()?))
        })
        .unwrap_or((f64::NAN, f64::NAN));
    let path = if r.starts_with("λ") && r.contains("autocorrelation along") {
        "shape"
    } else if r.contains("by gradient-energy isotropy") {
        "isotropy"
    } else if r.contains("from the streak's spectral zeros") {
        "zeros"
    } else if mb.diagnostics.status == Status::NotIdentifiable {
        "refused"
    } else {
        "other"
    };
    Read {
        lambda: mb.exposure.unwrap_or(f32::NAN),
        stderr: mb.diagnostics.stderr.unwrap_or(f64::NAN),
        status: mb.diagnostics.status,
        oblique,
        oblique_se,
        path,
        reason: r.clone(),
    }
}

/// One line per frame (with `LINES=1`) and a tally per group.
struct Tally {
    name: String,
    n: usize,
    covered: usize,
    present_wrong: usize,
    refused: usize,
    rows: Vec<String>,
}

impl Tally {
    fn new(name: String) -> Self {
        Tally { name, n: 0, covered: 0, present_wrong: 0, refused: 0, rows: vec![] }
    }
    fn add(&mut self, label: String, truth: f32, r: &Read) {
        self.n += 1;
        let covered = r.lambda.is_finite() && ((r.lambda - truth).abs() as f64) <= 2.0 * r.stderr;
        let answered = r.status != Status::NotIdentifiable;
        self.covered += (covered || !answered) as usize;
        self.refused += (!answered) as usize;
        // A present reading whose error does not hold the truth: the failure that
        // renders a streak the camera did not make (or the wrong one).
        self.present_wrong += (r.status == Status::Present && !covered) as usize;
        self.rows.push(format!(
            "{label}: truth {truth:.2} read {:.3} ± {:.3} {:?} by {} | oblique {:+.3} ± {:.3}",
            r.lambda, r.stderr, r.status, r.path, r.oblique, r.oblique_se
        ));
        if std::env::var("REASON").is_ok_and(|v| v == "1") {
            self.rows.push(format!("    {}", r.reason));
        }
    }
    fn print(&self) {
        if std::env::var("LINES").is_ok_and(|v| v == "1") {
            for row in &self.rows {
                println!("  {row}");
            }
        }
        println!(
            "{}: {} frames, present and not covered {}, not identifiable {}, covered or refused {}",
            self.name, self.n, self.present_wrong, self.refused, self.covered
        );
    }
}

fn main() {
    let set = std::env::var("SET").unwrap_or_default();
    if set.is_empty() || set == "texture" {
        // The oriented texture (σ 3 px along x, 1.2 across: its smooth axis is x),
        // flow at `deg` off that axis.
        // `DEGS=0,10`: those angles only.
        let degs: Vec<f32> = match std::env::var("DEGS") {
            Ok(v) => v.split(',').filter_map(|d| d.trim().parse().ok()).collect(),
            Err(_) => vec![0.0, 10.0, 20.0, 30.0, 45.0, 60.0, 90.0],
        };
        for deg in degs {
            let mut t = Tally::new(format!("texture {deg}° off its smooth axis"));
            for seed in [3u64, 5] {
                let tex = synth::sequence::anisotropic_texture(800, 700, 3.0, 1.2, seed);
                let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
                for speed in [8.0f32, 16.0] {
                    let flow = Flow::uniform(800, 700, speed * c, speed * s);
                    for lam in [0.0f32, 0.25, 0.5] {
                        let img = common::defocus_noise_8bit(&synth::add_motion_blur(&tex, &flow, lam), 1.2, seed);
                        t.add(format!("seed {seed} @{speed}"), lam, &read(&img, &flow));
                    }
                }
            }
            t.print();
        }
    }
    if set == "iso" {
        // An isotropic texture (σ 1.2 px both ways) at long exposures: what a real
        // full-frame streak reads, next to the oriented texture's λ = 1 end.
        // `DEFOCUS=σ` (px, default 1.2): heavier defocus fills the zeros.
        let defocus: f32 = std::env::var("DEFOCUS").ok().and_then(|v| v.parse().ok()).unwrap_or(1.2);
        let mut t = Tally::new(format!("isotropic texture, long exposures, defocus σ {defocus} px"));
        for seed in [3u64, 5] {
            let tex = synth::sequence::anisotropic_texture(800, 700, 1.2, 1.2, seed);
            for deg in [0.0f32, 30.0] {
                let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
                for speed in [8.0f32, 16.0] {
                    let flow = Flow::uniform(800, 700, speed * c, speed * s);
                    for lam in [0.75f32, 0.9, 1.0] {
                        let img = common::defocus_noise_8bit(&synth::add_motion_blur(&tex, &flow, lam), defocus, seed);
                        t.add(format!("seed {seed} {deg}° @{speed}"), lam, &read(&img, &flow));
                    }
                }
            }
        }
        t.print();
    }
    if set.is_empty() || set == "photos" {
        let photos = [
            ("astronaut", common::photo("astronaut.png")),
            ("chelsea", common::photo("chelsea.png")),
            ("rocket", common::photo("rocket.jpg")),
            ("motorcycle", common::asset_photo("motorcycle_left_333x497.png")),
        ];
        for (name, photo) in photos {
            let clean = common::mirror_tile(&photo, 800, 600);
            let mut t = Tally::new(format!("{name} at 12 directions"));
            for deg in (0..12).map(|k| 15.0 * k as f32) {
                let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
                for speed in [8.0f32, 16.0] {
                    let flow = Flow::uniform(800, 600, speed * c, speed * s);
                    for lam in [0.0f32, 0.5] {
                        let img = common::defocus_noise_8bit(&synth::add_motion_blur(&clean, &flow, lam), 0.8, 7);
                        t.add(format!("{deg}° @{speed}"), lam, &read(&img, &flow));
                    }
                }
            }
            t.print();
        }
    }
}
