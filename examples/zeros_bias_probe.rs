//! Probe: the streak zeros' error (`fit::streak_spectrum::streak_signature`, read
//! length minus the truth, px) on box streaks of 6–16 px along x at 16 px/frame over
//! a scene of white noise smoothed by σ 0–2 px (800×700, two seeds) — the streak
//! exact (taps ½, 1 … 1, ½: the continuous box over the pixels' tent interpolant;
//! `IDEAL=1`: the ideal band-limited box, by FFT), then `DEFOCUS=σ` (Gaussian) and
//! `NOISE=std` (white) where given. What it showed (BENCHMARKS.md "The streak zeros'
//! model error"): without noise the zeros read within ±0.05 px; noise and a steep
//! scene spectrum put them 0.1–0.9 px short, the kernel's discretisation does not.
//! `cargo run --release --example zeros_bias_probe` (e.g. `NOISE=0.028 DEFOCUS=1.2`).
use blind_augment::fit::streak_spectrum::streak_signature;
use blind_augment::image::{blur_separable, blur_x, discrete_gaussian_kernel, Flow, Plane};

fn main() {
    let (w, h) = (800usize, 700usize);
    let speed = 16.0f32;
    for sigma in [0.0f32, 0.8, 1.2, 2.0] {
        for seed in [3u64, 5] {
            let noise: Vec<f32> =
                (0..w * h).map(|i| blind_augment::synth::gaussian((i % w) as u32, (i / w) as u32, 0, seed)).collect();
            let mut p = Plane::from_vec(w, h, noise.iter().map(|v| 0.35 * v).collect());
            if sigma > 0.0 {
                p = blur_separable(&p, &discrete_gaussian_kernel(sigma * sigma));
            }
            let mut row = String::new();
            for l in [6usize, 8, 12, 16] {
                // The continuous box of length l over the tent-interpolated pixels:
                // taps ½, 1 … 1, ½ over l + 1 pixels, sum l.
                let mut k = vec![1.0f32 / l as f32; l + 1];
                k[0] *= 0.5;
                k[l] *= 0.5;
                let mut b = if std::env::var("IDEAL").is_ok_and(|v| v == "1") {
                    ideal_box_x(&p, l as f32)
                } else {
                    blur_x(&p, &k)
                };
                // `NOISE=std`: white noise after the streak (and `DEFOCUS=σ` before it).
                if let Some(d) = std::env::var("DEFOCUS").ok().and_then(|v| v.parse::<f32>().ok()) {
                    b = blur_separable(&b, &discrete_gaussian_kernel(d * d));
                }
                if let Some(sd) = std::env::var("NOISE").ok().and_then(|v| v.parse::<f32>().ok()) {
                    for (i, v) in b.data.iter_mut().enumerate() {
                        *v += sd * blind_augment::synth::gaussian((i % w) as u32, (i / w) as u32, 1, seed + 100);
                    }
                }
                let flow = Flow::uniform(w, h, speed, 0.0);
                match streak_signature(&b, &flow, |_, _| true) {
                    Some(s) => {
                        row += &format!(
                            " L{l}: {:+.2}±{:.2} lobe {:.2}{}",
                            s.lambda * speed - l as f32,
                            s.stderr * speed,
                            s.side_lobe,
                            if s.identified { "" } else { " (not identified)" }
                        )
                    }
                    None => row += &format!(" L{l}: none"),
                }
            }
            println!("σ {sigma} seed {seed}:{row}");
        }
    }
}

/// Each row blurred by the ideal box of length `l` (px) along x: the row's spectrum
/// times sinc(f·l), f in cycles/px — a band-limited scene under a continuous streak.
fn ideal_box_x(p: &Plane, l: f32) -> Plane {
    use rustfft::num_complex::Complex32;
    let w = p.width;
    let mut planner = rustfft::FftPlanner::<f32>::new();
    let (fwd, inv) = (planner.plan_fft_forward(w), planner.plan_fft_inverse(w));
    let mut out = p.clone();
    for row in out.data.chunks_mut(w) {
        let mut buf: Vec<Complex32> = row.iter().map(|&v| Complex32::new(v, 0.0)).collect();
        fwd.process(&mut buf);
        for (k, c) in buf.iter_mut().enumerate() {
            let f = if k <= w / 2 { k as f32 } else { k as f32 - w as f32 } / w as f32;
            let x = std::f32::consts::PI * f * l;
            let h = if x.abs() < 1e-6 { 1.0 } else { x.sin() / x };
            *c *= h / w as f32;
        }
        inv.process(&mut buf);
        for (v, c) in row.iter_mut().zip(&buf) {
            *v = c.re;
        }
    }
    out
}
