//! Probe: the blind noise fit on video whose sensor noise is spatially correlated
//! (demosaicing, in-camera denoising, a codec's quantisation make real noise decay
//! slower than white across the pyramid's levels). Per frame of the calibration video
//! (the Motorcycle along the head path), the fit with the previous frame aligned and
//! the frame alone, each level's median error against the truth over 9 lumas × 3
//! channels, and whether the fit measured or derived the level.
//! `cargo run --release --example correlated_noise_probe -- FROM TO WIDTH`;
//! `REASON=1` prints both fits' reasons; `STRIP=rows` fits a strip of that many full rows, the next one down per frame (the
//! worker's way); `RATIOS=r1,r2,r3` the truth's level std ratios 1/0, 2/1, 3/2 (default: the vtest
//! clip's, 0.45,0.72,0.72; white noise's are about 0.24,0.44,0.49).
use blind_augment::analysis::{temporal::align, Analysed, DepthMap, Frame};
use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Neighbour, Tier};
use blind_augment::image::Plane;
use blind_augment::model::{DepthUnits, Noise, NOISE_LEVELS};
use blind_augment::synth::sequence::{motorcycle, SequenceFrame, SequenceSpec};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let from: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(55);
    let to: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(65);
    let w: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(320);
    let ratios: Vec<f32> = std::env::var("RATIOS")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .unwrap_or_else(|| vec![0.45, 0.72, 0.72]);
    let scene = motorcycle().expect("bundled scene");
    let mut spec = SequenceSpec::motorcycle(&scene, w, w * 3 / 4, 150, None);
    let ratios: [f32; NOISE_LEVELS - 1] = std::array::from_fn(|i| ratios[i.min(ratios.len() - 1)]);
    let truth =
        blind_augment::synth::correlated_sensor_noise([3e-5, 2e-5, 5e-5], [6e-4, 4e-4, 9e-4], [0.0, 1.0], ratios)
            .expect("RATIOS");
    spec.truth.noise = truth.clone();
    let analysed = |f: &SequenceFrame| Analysed {
        frame: Frame { index: f.index as u64, t_s: f.t_s, image: f.image.clone(), depth: None, flow: None },
        depth: Some(DepthMap { depth: f.depth_m.clone(), units: DepthUnits::MetricM }),
        world_from_camera: Some(f.world_from_camera),
        sparse_flow: None,
    };
    let opts = FitOptions {
        tier: Some(Tier::Fast),
        effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
        ..Default::default()
    };
    let mut prev = analysed(&spec.frame(&scene, from.saturating_sub(1)));
    let (mut with_all, mut alone_all) = (vec![vec![]; NOISE_LEVELS], vec![vec![]; NOISE_LEVELS]);
    for i in from..to {
        let fr = spec.frame(&scene, i);
        let cur = analysed(&fr);
        let a = align(&prev, &cur, &spec.view).expect("poses and depth align");
        // STRIP=rows: the worker's way at 1280×960 (`NOISE_STRIP_PX`): a strip of
        // full rows, the next one down per frame, the neighbour cropped alike.
        let h = w * 3 / 4;
        let rows: usize = std::env::var("STRIP").ok().and_then(|s| s.parse().ok()).unwrap_or(h).min(h);
        let y0 = ((i - from) * rows) % (h - rows + 1);
        let valid =
            Plane::from_vec(w, rows, a.valid[y0 * w..(y0 + rows) * w].iter().map(|&v| v as u8 as f32).collect());
        let crop = |img: &blind_augment::image::Rgb| img.crop(0, y0, w, rows).expect("strip inside the frame");
        let (image, nb) = (crop(&fr.image), crop(&a.image));
        let inp = FitInputs { neighbour: Some(Neighbour { image: &nb, valid: &valid }), ..FitInputs::new(&image) };
        let with = fit(&inp, &opts).expect("fit").model.noise;
        let alone = fit(&FitInputs::new(&image), &opts).expect("fit").model.noise;
        let (ew, ea) = (level_errors(&with, &truth), level_errors(&alone, &truth));
        for l in 0..NOISE_LEVELS {
            with_all[l].push(ew[l]);
            alone_all[l].push(ea[l]);
        }
        println!(
            "frame {i}: with the neighbour {} [{}]; alone {} [{}]",
            fmt(&ew),
            derived(&with),
            fmt(&ea),
            derived(&alone)
        );
        if std::env::var_os("REASON").is_some() {
            println!("  with: {}\n  alone: {}", with.diagnostics.reason, alone.diagnostics.reason);
        }
        prev = cur;
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let summary =
        |all: &mut Vec<Vec<f64>>| all.iter_mut().map(|v| format!("{:+.1}%", 100.0 * med(v))).collect::<Vec<_>>();
    println!("median per level, with the neighbour: {:?}", summary(&mut with_all));
    println!("median per level, the frame alone:    {:?}", summary(&mut alone_all));
}

/// Per level, the median signed relative error of the fitted std against the truth
/// over 9 lumas inside the fit's range × 3 channels.
fn level_errors(n: &Noise, t: &Noise) -> Vec<f64> {
    let [lo, hi] = n.luminance_range;
    (0..NOISE_LEVELS)
        .map(|l| {
            let mut e: Vec<f64> = (0..27)
                .map(|k| {
                    let (y, c) = (lo + (hi - lo) * ((k / 3) as f32 + 0.5) / 9.0, k % 3);
                    (n.levels[l].std(n.form, c, y) / t.levels[l].std(t.form, c, y) - 1.0) as f64
                })
                .collect();
            e.sort_by(f64::total_cmp);
            if n.present {
                e[13]
            } else {
                f64::NAN
            }
        })
        .collect()
}

fn fmt(e: &[f64]) -> String {
    e.iter().map(|v| format!("{:+.0}%", 100.0 * v)).collect::<Vec<_>>().join(" ")
}

/// The levels the fit's reason calls not identifiable (derived), as written there.
fn derived(n: &Noise) -> String {
    n.diagnostics
        .reason
        .split("levels [")
        .nth(1)
        .and_then(|t| t.split(']').next())
        .map_or("all measured".into(), |s| format!("derived {s}"))
}
