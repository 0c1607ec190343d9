//! Probe: the streak zeros' side-lobe gate (`streak_spectrum::MIN_SIDE_LOBE`)
//! across seeds — an oriented texture (σ 3/1.2 px; four texture and noise seeds;
//! flow 0°, 5°, 10°, 20° off its smooth axis; 8/12/16 px/frame; λ 0 and 0.5) and
//! the astronaut (λ 0.5; clean, defocused, three noise seeds; 1280×960 to 400×300).
//! Prints every read and the largest lobe among the texture's wrong reads inside
//! the band against the least among the photograph's right reads that pass the
//! other gates: where the threshold sits between them.
//! `cargo run --release --example side_lobe_probe`
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::fit::streak_spectrum::streak_signature;
use blind_augment::image::{Flow, Plane};
use blind_augment::synth;
fn main() {
    let q = |i: &blind_augment::image::Rgb| i.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
    let noise = synth::white_sensor_noise([2e-5; 3], [8e-4; 3], [0.0, 1.0]);
    let mut max_tex: f32 = -9.0;
    let mut min_gen: f32 = 9.0;
    for seed in [3u64, 5, 11, 23] {
        let tex = synth::sequence::anisotropic_texture(800, 700, 3.0, 1.2, seed);
        for deg in [0.0f32, 5.0, 10.0, 20.0] {
            let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
            for (speed, sigma) in [(8.0f32, 1.5f32), (12.0, 1.2), (16.0, 1.5)] {
                let flow = Flow::uniform(800, 700, speed * c, speed * s);
                for lam in [0.0f32, 0.5] {
                    let mut img = synth::add_motion_blur(&tex, &flow, lam);
                    let k = blind_augment::image::discrete_gaussian_kernel(sigma * sigma);
                    for ch in 0..3 {
                        let p = Plane::from_vec(800, 700, img.channels[ch].clone());
                        img.channels[ch] = blind_augment::image::blur_separable(&p, &k).data;
                    }
                    let img = q(&synth::add_noise(&img, &noise, seed));
                    if let Some(sg) = streak_signature(&img.luma(), &flow, |_, _| true) {
                        let ok_read = (sg.lambda / lam.max(1e-3) - 1.0).abs() <= 0.15;
                        println!(
                            "tex seed {seed} {deg}° @{speed} λ{lam}: λ {:.3} ± {:.3} in {} lobe {:.2} id {} {}",
                            sg.lambda,
                            sg.stderr,
                            sg.inside,
                            sg.side_lobe,
                            sg.identified,
                            if ok_read { "(right)" } else { "" }
                        );
                        if sg.inside && !ok_read && sg.side_lobe.is_finite() {
                            max_tex = max_tex.max(sg.side_lobe);
                        }
                    }
                }
            }
        }
    }
    for seed in [3u64, 5, 11] {
        for (w, h, speed) in [(1280usize, 960usize, 8.0f32), (640, 480, 24.0), (400, 300, 8.0), (400, 300, 24.0)] {
            let clean = common::mirror_tile(&common::photo("astronaut.png"), w, h);
            let (depth, dof) = common::thin_lens_ramp(w, h);
            let flow = common::flow_field(w, h, speed);
            let mb = synth::add_motion_blur(&clean, &flow, 0.5);
            for (name, img) in [
                ("mb", mb.clone()),
                ("mbdof", synth::add_dof(&mb, &depth, &dof)),
                ("mbnoise", synth::add_noise(&mb, &noise, seed)),
            ] {
                if let Some(sg) = streak_signature(&q(&img).luma(), &flow, |_, _| true) {
                    let right = (sg.lambda / 0.5 - 1.0).abs() <= 0.1;
                    println!(
                        "photo seed {seed} {w}x{h}@{speed} {name}: λ {:.3} ± {:.3} lobe {:.2} id {} {}",
                        sg.lambda,
                        sg.stderr,
                        sg.side_lobe,
                        sg.identified,
                        if right { "(right)" } else { "" }
                    );
                    if right
                        && sg.inside
                        && sg.side_lobe.is_finite()
                        && sg.stderr <= 0.1 * sg.lambda
                        && sg.score >= 0.45
                    {
                        min_gen = min_gen.min(sg.side_lobe);
                    }
                }
            }
        }
    }
    println!("max lobe of wrong texture reads (inside): {max_tex:.3}; min lobe of right photo reads passing the other gates: {min_gen:.3}");
}
