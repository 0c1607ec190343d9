//! Probe: how much a surface point's defocus changes between a rest frame (the
//! motion-blur references' source) and the frames of the head turn that follows, on
//! the calibration video with the demo's camera (`tests/common::demo_camera`): per
//! frame, over the pixels the rest frame sees, |Δ(1/Z)| and δ(Z_now)² − δ(Z_rest)²
//! (px², the variance a Gaussian-equivalent defocus adds) — what the temporal
//! motion-blur fit takes for streak variance (a streak of L px has L²/12).
//! `cargo run --release --example defocus_change_probe [REST]` (default rest frame 10).
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::synth::sequence::*;

fn main() {
    let rest: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(10);
    let scene = motorcycle().expect("bundled scene");
    let mut spec = SequenceSpec::motorcycle(&scene, 320, 240, 40, None);
    common::demo_camera(&mut spec);
    let (k, dof) = (spec.view, spec.truth.depth_of_field.clone());
    let src = spec.frame(&scene, rest);
    for i in [14usize, 18, 20, 24, 26, 28, 29] {
        let dst = spec.frame(&scene, i);
        let src_from_dst = src.world_from_camera.inverse() * dst.world_from_camera;
        let (mut inv_z, mut var, mut signed) = (vec![], vec![], vec![]);
        for y in 0..k.height {
            for x in 0..k.width {
                let z = dst.depth_m.data[y * k.width + x];
                let p = glam::Vec3::new((x as f32 - k.cx) / k.fx * z, (y as f32 - k.cy) / k.fy * z, z);
                let q = src_from_dst.transform_point3(p);
                let (u, v) = (k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy);
                if q.z <= 0.0 || u < 2.0 || v < 2.0 || u > k.width as f32 - 3.0 || v > k.height as f32 - 3.0 {
                    continue;
                }
                inv_z.push((1.0 / q.z - 1.0 / z).abs());
                let d = dof.sigma_px(z).powi(2) - dof.sigma_px(q.z).powi(2);
                var.push(d.abs());
                signed.push(d);
            }
        }
        inv_z.sort_by(f32::total_cmp);
        signed.sort_by(f32::total_cmp);
        var.sort_by(f32::total_cmp);
        let n = var.len();
        let share = |t: f32| var.iter().filter(|v| **v <= t).count() as f32 / n as f32;
        println!(
            "frame {i}: {n} px seen at rest; |Δ(1/Z)| median {:.4} /m; δ_now² − δ_rest² median {:+.3} px², |·| median {:.3}, p90 {:.3}; share ≤ 0.01 / 0.02 / 0.05 px²: {:.2} / {:.2} / {:.2}",
            inv_z[n / 2],
            signed[n / 2],
            var[n / 2],
            var[n * 9 / 10],
            share(0.01),
            share(0.02),
            share(0.05)
        );
    }
}
