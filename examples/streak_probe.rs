//! Probe: the streak-zeros estimator (`fit::streak_spectrum`) over 42 frames with
//! and without a zero in the band — clean, noisy, defocused, the demo frame (if
//! `/tmp/demo` holds one) and two real photographs — and 33 frames of a strongly
//! oriented texture (smoothed σ 3 px along x, 1.2 px along y) streaked along and
//! across its smooth axis (and 10° off it), and 8 of the photograph at 400×300
//! (fewer lines). Figures in its module doc.
//! `cargo run --release --example streak_probe`
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::fit::streak_spectrum::streak_signature;
use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::io;
use blind_augment::synth;
fn report(name: &str, truth: f32, y: &Plane, flow: &Flow) {
    if let Ok(f) = std::env::var("ONLY") {
        if name != f {
            return;
        }
    }
    match streak_signature(y, flow, |_, _| true) {
        Some(s) => println!(
            "{name:30} truth {truth:.3}  λ {:.3} ± {:.3} (floor {:.3}) score {:.2} lobe {:.2} inside {} identified {} \
             lines {} speed {:.1}",
            s.lambda, s.stderr, s.floor_shift, s.score, s.side_lobe, s.inside, s.identified, s.lines, s.speed_px
        ),
        None => println!("{name:28} none"),
    }
}
fn main() {
    let q = |i: &Rgb| i.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
    for (w, h, speed) in [(1280usize, 960usize, 8.0f32), (640, 480, 24.0), (640, 480, 8.0)] {
        let clean = common::mirror_tile(&common::photo("astronaut.png"), w, h);
        let (depth, dof) = common::thin_lens_ramp(w, h);
        let flow = common::flow_field(w, h, speed);
        let noise = synth::white_sensor_noise([2e-5; 3], [8e-4; 3], [0.0, 1.0]);
        let noise_hi = synth::white_sensor_noise([1e-4; 3], [4e-3; 3], [0.0, 1.0]);
        for lam in [0.25f32, 0.5] {
            let mb = synth::add_motion_blur(&clean, &flow, lam);
            let tag = format!("{w}x{h}@{speed} λ{lam}");
            report(&format!("{tag} mb"), lam, &q(&mb).luma(), &flow);
            report(&format!("{tag} mbnoise"), lam, &q(&synth::add_noise(&mb, &noise, 1)).luma(), &flow);
            report(&format!("{tag} mbnoiseHI"), lam, &q(&synth::add_noise(&mb, &noise_hi, 1)).luma(), &flow);
            report(&format!("{tag} mbdof"), lam, &q(&synth::add_dof(&mb, &depth, &dof)).luma(), &flow);
            report(
                &format!("{tag} all"),
                lam,
                &q(&synth::add_noise(&synth::add_dof(&mb, &depth, &dof), &noise, 1)).luma(),
                &flow,
            );
        }
        report(&format!("{w}x{h}@{speed} clean"), 0.0, &q(&clean).luma(), &flow);
        report(&format!("{w}x{h}@{speed} cleannoise"), 0.0, &q(&synth::add_noise(&clean, &noise, 1)).luma(), &flow);
        report(&format!("{w}x{h}@{speed} dof"), 0.0, &q(&synth::add_dof(&clean, &depth, &dof)).luma(), &flow);
    }
    // Oriented texture: its own spectrum falls off along x as a streak's main lobe
    // does; the streak along x (its smooth axis) and along y (its sharp one).
    let aniso = synth::sequence::anisotropic_texture(800, 700, 3.0, 1.2, 17);
    let noise = synth::white_sensor_noise([2e-5; 3], [8e-4; 3], [0.0, 1.0]);
    let (c10, s10) = (10f32.to_radians().cos(), 10f32.to_radians().sin());
    for (axis, ax, ay) in [("x", 1.0f32, 0.0f32), ("x+10°", c10, s10), ("y", 0.0, 1.0)] {
        for (speed, sigma) in [(8.0f32, 1.5f32), (12.0, 1.2), (16.0, 1.5)] {
            let flow = Flow::uniform(aniso.width, aniso.height, speed * ax, speed * ay);
            for lam in [0.0f32, 0.2, 0.5] {
                let mut img = synth::add_motion_blur(&aniso, &flow, lam);
                let k = blind_augment::image::discrete_gaussian_kernel(sigma * sigma);
                for c in 0..3 {
                    let p = Plane::from_vec(img.width, img.height, img.channels[c].clone());
                    img.channels[c] = blind_augment::image::blur_separable(&p, &k).data;
                }
                let img = q(&synth::add_noise(&img, &noise, 1));
                report(&format!("aniso along {axis} @{speed} σ{sigma} λ{lam}"), lam, &img.luma(), &flow);
            }
        }
    }
    // Other elongations and a smaller frame (fewer lines): 12 px/frame along x, σ 1.2.
    for (sx, w, h) in [(2.0f32, 800usize, 700usize), (4.0, 800, 700), (3.0, 400, 300)] {
        let tex = synth::sequence::anisotropic_texture(w, h, sx, 1.2, 5);
        let flow = Flow::uniform(w, h, 12.0, 0.0);
        for lam in [0.0f32, 0.5] {
            let mut img = synth::add_motion_blur(&tex, &flow, lam);
            let k = blind_augment::image::discrete_gaussian_kernel(1.44);
            for c in 0..3 {
                let p = Plane::from_vec(w, h, img.channels[c].clone());
                img.channels[c] = blind_augment::image::blur_separable(&p, &k).data;
            }
            let img = q(&synth::add_noise(&img, &noise, 1));
            report(&format!("aniso {sx}/1.2 {w}x{h} @12 λ{lam}"), lam, &img.luma(), &flow);
        }
    }
    // Isotropic photograph at 400×300 (~4× fewer lines): the streaks' side lobes.
    {
        let clean = common::mirror_tile(&common::photo("astronaut.png"), 400, 300);
        let (depth, dof) = common::thin_lens_ramp(400, 300);
        for speed in [8.0f32, 24.0] {
            let flow = common::flow_field(400, 300, speed);
            let mb = synth::add_motion_blur(&clean, &flow, 0.5);
            report(&format!("400x300@{speed} λ0.5 mb"), 0.5, &q(&mb).luma(), &flow);
            report(&format!("400x300@{speed} λ0.5 mbnoise"), 0.5, &q(&synth::add_noise(&mb, &noise, 1)).luma(), &flow);
            report(&format!("400x300@{speed} λ0.5 mbdof"), 0.5, &q(&synth::add_dof(&mb, &depth, &dof)).luma(), &flow);
            report(&format!("400x300@{speed} clean"), 0.0, &q(&clean).luma(), &flow);
        }
    }
    if let (Ok((img, _)), Ok(flow)) = (
        io::load_rgb(std::path::Path::new("/tmp/demo/distorted.png")),
        io::load_flow(std::path::Path::new("/tmp/demo/flow.flo")),
    ) {
        report("demo", 0.40, &img.luma(), &flow);
    }
    for (f, deg, d) in [("motion_licenseplate_opencv.jpg", 135.0f32, 22.0f32), ("motion_text_opencv.jpg", 86.0, 31.0)] {
        let img = common::photo(f);
        let a = deg.to_radians();
        let flow = Flow::uniform(img.width, img.height, 50.0 * a.cos(), 50.0 * a.sin());
        report(f, d / 50.0, &img.luma(), &flow);
    }
}
