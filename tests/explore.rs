mod common;
use blind_augment::fit::{fit, FitInputs, FitOptions};
use blind_augment::model::*;
use blind_augment::synth::*;
use common::*;

#[test]
fn explore() {
    let img = photo("astronaut.png");
    let (w, h) = (img.width, img.height);
    // MB
    for &(scale, lam) in &[
        (8.0f32, 0.0f32),
        (8.0, 0.1),
        (8.0, 0.5),
        (8.0, 1.0),
        (1.5, 0.3),
        (1.5, 0.9),
    ] {
        let flow = flow_field(w, h, scale);
        let blurred = quantize8(&add_motion_blur(&img, &flow, lam));
        let t = std::time::Instant::now();
        let out = fit(
            &FitInputs {
                image: &blurred,
                denoised: None,
                motion_deblurred: Some(&img),
                defocus_deblurred: None,
                depth: None,
                depth_units: DepthUnits::MetricM,
                flow: Some(&flow),
            },
            &FitOptions {
                effects: blind_augment::fit::Effects {
                    noise: false,
                    motion_blur: true,
                    depth_of_field: false,
                },
                ..Default::default()
            },
        )
        .unwrap();
        println!(
            "MB scale {scale} λ {lam}: got {:?} present {} {:?} in {:?}",
            out.model.motion_blur.exposure,
            out.model.motion_blur.present,
            out.model.motion_blur.diagnostics.stderr,
            t.elapsed()
        );
        let fast = fit(
            &FitInputs {
                image: &blurred,
                denoised: None,
                motion_deblurred: None,
                defocus_deblurred: None,
                depth: None,
                depth_units: DepthUnits::MetricM,
                flow: Some(&flow),
            },
            &FitOptions {
                effects: blind_augment::fit::Effects {
                    noise: false,
                    motion_blur: true,
                    depth_of_field: false,
                },
                ..Default::default()
            },
        )
        .unwrap();
        println!(
            "   fast: {:?} {}",
            fast.model.motion_blur.exposure, fast.model.motion_blur.diagnostics.reason
        );
    }
    // DoF
    let depth = depth_ramp(w, h, 0.5, 4.0);
    for truth in [
        DofCurve::ThinLens {
            k: 3.0,
            focus_depth: 1.2,
            c0: 0.3,
        },
        DofCurve::Quadratic {
            a: 0.3,
            b: -1.0,
            c: 1.5,
        },
    ] {
        let dof = DepthOfField {
            present: true,
            units: DepthUnits::MetricM,
            curve: Some(truth),
            depth_range: [0.5, 4.0],
            diagnostics: Diagnostics::not_fitted(""),
        };
        let t = std::time::Instant::now();
        let blurred = quantize8(&add_dof(&img, &depth, &dof));
        println!("synth dof {:?}", t.elapsed());
        let t = std::time::Instant::now();
        let out = fit(
            &FitInputs {
                image: &blurred,
                denoised: None,
                motion_deblurred: None,
                defocus_deblurred: Some(&img),
                depth: Some(&depth),
                depth_units: DepthUnits::MetricM,
                flow: None,
            },
            &FitOptions {
                effects: blind_augment::fit::Effects {
                    noise: false,
                    motion_blur: false,
                    depth_of_field: true,
                },
                ..Default::default()
            },
        )
        .unwrap();
        let el = t.elapsed();
        let m = &out.model.depth_of_field;
        let r = m.depth_range;
        let rmse = ((0..=100)
            .map(|i| {
                let z = r[0] + (r[1] - r[0]) * i as f32 / 100.0;
                (m.sigma_px(z) - dof.sigma_px(z)).powi(2) as f64
            })
            .sum::<f64>()
            / 101.0)
            .sqrt();
        println!(
            "DoF truth {truth:?} got {:?} range {:?} rmse {rmse:.4} in {el:?} n={}",
            m.curve, r, m.diagnostics.samples_used
        );
        let fast = fit(
            &FitInputs {
                image: &blurred,
                denoised: None,
                motion_deblurred: None,
                defocus_deblurred: None,
                depth: Some(&depth),
                depth_units: DepthUnits::MetricM,
                flow: None,
            },
            &FitOptions {
                effects: blind_augment::fit::Effects {
                    noise: false,
                    motion_blur: false,
                    depth_of_field: true,
                },
                ..Default::default()
            },
        )
        .unwrap();
        let m = &fast.model.depth_of_field;
        let rmse = ((0..=100)
            .map(|i| {
                let z = r[0] + (r[1] - r[0]) * i as f32 / 100.0;
                (m.sigma_px(z) - dof.sigma_px(z)).powi(2) as f64
            })
            .sum::<f64>()
            / 101.0)
            .sqrt();
        println!(
            "   fast {:?} rmse {rmse:.3} n={}",
            m.curve, m.diagnostics.samples_used
        );
    }
    // Noise
    let a = [2e-5f32, 1e-5, 4e-5];
    let b = [8e-4f32, 5e-4, 1.2e-3];
    let noisy = add_sensor_noise(&img, a, b, 3);
    let t = std::time::Instant::now();
    let out = fit(
        &FitInputs {
            image: &noisy,
            denoised: Some(&img),
            motion_deblurred: None,
            defocus_deblurred: None,
            depth: None,
            depth_units: DepthUnits::MetricM,
            flow: None,
        },
        &FitOptions {
            effects: blind_augment::fit::Effects {
                noise: true,
                motion_blur: false,
                depth_of_field: false,
            },
            ..Default::default()
        },
    )
    .unwrap();
    println!("noise fit {:?}: {:?}", t.elapsed(), out.model.noise);
    let fast = fit(
        &FitInputs {
            image: &noisy,
            denoised: None,
            motion_deblurred: None,
            defocus_deblurred: None,
            depth: None,
            depth_units: DepthUnits::MetricM,
            flow: None,
        },
        &FitOptions {
            effects: blind_augment::fit::Effects {
                noise: true,
                motion_blur: false,
                depth_of_field: false,
            },
            ..Default::default()
        },
    )
    .unwrap();
    let unit = unit_band_std();
    for (name, nm) in [("acc", &out.model.noise), ("fast", &fast.model.noise)] {
        println!("{name} form {:?} range {:?}", nm.form, nm.luminance_range);
        for (l, lev) in nm.levels.iter().enumerate() {
            for y in [0.2f32, 0.5, 0.8] {
                let got: Vec<f32> = (0..3).map(|c| lev.std(nm.form, c, y)).collect();
                let tru: Vec<f32> = (0..3).map(|c| (a[c] + b[c] * y).sqrt() * unit[l]).collect();
                println!("  l{l} y{y}: got {got:?} true {tru:?}");
            }
        }
        let mut errs = vec![];
        for yi in 0..9 {
            let y = nm.luminance_range[0]
                + (nm.luminance_range[1] - nm.luminance_range[0]) * (yi as f32 + 0.5) / 9.0;
            let flat = blind_augment::image::Rgb::new(256, 256, [y, y, y]);
            let field = noise_field(&flat.luma(), nm, 99);
            for c in 0..3 {
                let s = (field.channels[c]
                    .iter()
                    .map(|v| (*v as f64).powi(2))
                    .sum::<f64>()
                    / field.channels[c].len() as f64)
                    .sqrt();
                let truth = ((a[c] + b[c] * y) as f64).sqrt();
                errs.push((s / truth - 1.0).abs());
            }
        }
        println!(
            "{name} noise median rel err {:.4} max {:.4}",
            median(errs.clone()),
            errs.iter().cloned().fold(0.0, f64::max)
        );
    }
}
