//! Probe: the blind DoF fit on single frames of the calibration video, against the
//! truth's δ(Z), with and without the video's other effects and its added defocus.
use blind_augment::fit::{self, Effects, FitInputs, FitOptions, Tier};
use blind_augment::model::DepthUnits;
use blind_augment::synth::sequence::*;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let w: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(320);
    let scene = motorcycle().unwrap();
    let spec = SequenceSpec::motorcycle(&scene, w, w * 3 / 4, 150, None);
    let truth = spec.truth.clone();
    let r = truth.depth_of_field.depth_range;
    let depths: Vec<f32> = (0..8).map(|i| r[0] + (r[1] - r[0]) * (i as f32 + 0.5) / 8.0).collect();
    println!("depths {:?}", depths.iter().map(|z| (z * 100.0).round() / 100.0).collect::<Vec<_>>());
    println!(
        "truth  {:?}",
        depths.iter().map(|&z| (truth.depth_of_field.sigma_px(z) * 100.0).round() / 100.0).collect::<Vec<_>>()
    );
    let floor = spec.source_pixel_blur_px(&scene);
    println!(
        "truth ⊕ the photograph's pixel ({floor:.2} px) {:?}",
        depths
            .iter()
            .map(|&z| (truth.depth_of_field.sigma_px(z).hypot(floor) * 100.0).round() / 100.0)
            .collect::<Vec<_>>()
    );
    let cases = std::env::var("CASES").unwrap_or("all,dof only,none".into());
    for case in cases.split(',') {
        for i in [10usize, 40, 70, 100] {
            let mut s = spec.clone();
            match case {
                "dof only" => {
                    s.truth.noise.present = false;
                    s.truth.motion_blur.exposure = Some(0.0);
                }
                "dof+noise" => s.truth.motion_blur.exposure = Some(0.0),
                "dof+mb" => s.truth.noise.present = false,
                "none" => {
                    s.truth.noise.present = false;
                    s.truth.motion_blur.exposure = Some(0.0);
                    s.truth.depth_of_field.present = false;
                }
                _ => {}
            }
            let f = s.frame(&scene, i);
            let inp =
                FitInputs { depth: Some(&f.depth_m), depth_units: DepthUnits::MetricM, ..FitInputs::new(&f.image) };
            let opts = FitOptions {
                tier: Some(Tier::Fast),
                effects: Effects { noise: false, motion_blur: false, depth_of_field: true },
                ..Default::default()
            };
            let o = fit::fit(&inp, &opts).unwrap();
            let d = &o.model.depth_of_field;
            println!(
                "{case:9} frame {i:3}: {:?}  [{}]",
                depths.iter().map(|&z| (d.sigma_px(z) * 100.0).round() / 100.0).collect::<Vec<_>>(),
                d.diagnostics.reason.chars().take(160).collect::<String>()
            );
        }
    }
}
