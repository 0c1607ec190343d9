//! Probe: the blur the motion-blur reference (rest frame 10 aligned by pose and
//! depth) carries beyond the current frame's own, both rendered with the demo's
//! camera and no motion blur or noise: per 12-px tile, the Gaussian variance (px²
//! per axis; > 0: the frame is blurrier) that best matches one to the other, against
//! the thin lens's δ(Z)² − δ(Z_rest)² with and without the reprojection's
//! magnification. `NODOF=1`: without depth of field (the alignment's own blur);
//! `REACH=px`: only tiles that far from a depth step.
//! `cargo run --release --example reference_blur_probe [FRAME]` (default 28).
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::analysis::*;
use blind_augment::image::*;
use blind_augment::model::DepthUnits;
use blind_augment::synth::sequence::*;
/// Measured Δv, then the thin lens's: plain, × (Z_rest/Z)², × (Z/Z_rest)² (tile means).
type Tile = (f32, f32, f32, f32);

fn an(f: &SequenceFrame, img: Rgb) -> Analysed {
    Analysed {
        frame: Frame { index: f.index as u64, t_s: f.t_s, image: img, depth: None, flow: None },
        depth: Some(DepthMap { depth: f.depth_m.clone(), units: DepthUnits::MetricM }),
        world_from_camera: Some(f.world_from_camera),
        sparse_flow: None,
    }
}
fn main() {
    let scene = motorcycle().unwrap();
    let mut spec = SequenceSpec::motorcycle(&scene, 320, 240, 40, None);
    common::demo_camera(&mut spec);
    let k = spec.view;
    let dof = spec.truth.depth_of_field.clone();
    let mut only_dof = spec.truth.clone();
    only_dof.motion_blur.present = false;
    only_dof.noise.present = false;
    if std::env::var_os("NODOF").is_some() {
        only_dof.depth_of_field.present = false;
    }
    let rest = 10usize;
    let fs = spec.frame(&scene, rest);
    let sharp_s = blind_augment::synth::apply_camera_model(&fs.clean, &only_dof, Some(&fs.depth_m), Some(&fs.flow), 0);
    let cur: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(28);
    let fc = spec.frame(&scene, cur);
    let sharp_c = blind_augment::synth::apply_camera_model(&fc.clean, &only_dof, Some(&fc.depth_m), Some(&fc.flow), 0);
    let a = temporal::align(&an(&fs, sharp_s.clone()), &an(&fc, sharp_c.clone()), &k).unwrap();
    let (w, h) = (320usize, 240usize);
    let src_from_dst = fs.world_from_camera.inverse() * fc.world_from_camera;
    let (r, c) = (a.image.luma(), sharp_c.luma());
    // Blur stack of both for v in 0..1.2 step 0.05 (px² per axis)
    let vs: Vec<f32> = (0..=24).map(|i| i as f32 * 0.05).collect();
    let stack = |p: &Plane| -> Vec<Plane> {
        vs.iter().map(|&v| if v == 0.0 { p.clone() } else { blur_separable(p, &discrete_gaussian_kernel(v)) }).collect()
    };
    let (rs, cs) = (stack(&r), stack(&c));
    // REACH=px: tiles farther than this from a depth step (3% between neighbours)
    // of the current frame only (default 0: every tile).
    let reach: usize = std::env::var("REACH").ok().and_then(|s| s.parse().ok()).unwrap_or(0);
    let mut clear = Plane::new(w, h, 1.0);
    if reach > 0 {
        clear_near_depth_steps(&mut clear, &fc.depth_m, reach, 0.03, &|_| true);
    }
    let t = 12usize;
    let mut rows = vec![];
    for ty in (8..h - 8 - t).step_by(t) {
        for tx in (8..w - 8 - t).step_by(t) {
            let idx: Vec<usize> = (ty..ty + t).flat_map(|y| (tx..tx + t).map(move |x| y * w + x)).collect();
            if !idx.iter().all(|&i| a.valid[i] && clear.data[i] > 0.5) {
                continue;
            }
            // texture: gradient energy
            let g: f32 = idx
                .iter()
                .map(|&i| (c.data[i + 1] - c.data[i - 1]).powi(2) + (c.data[i + w] - c.data[i - w]).powi(2))
                .sum::<f32>()
                / idx.len() as f32;
            if g < 1e-3 {
                continue;
            }
            let err = |p: &Plane, q: &Plane| idx.iter().map(|&i| (p.data[i] - q.data[i]).powi(2)).sum::<f32>();
            // signed v: >0 blur r (current blurrier), <0 blur c
            let mut best = (0.0f32, f32::INFINITY);
            for (j, &v) in vs.iter().enumerate() {
                let e1 = err(&rs[j], &cs[0]);
                if e1 < best.1 {
                    best = (v, e1);
                }
                let e2 = err(&rs[0], &cs[j]);
                if e2 < best.1 {
                    best = (-v, e2);
                }
            }
            // predictions (tile means)
            let (mut p0, mut pp, mut pm) = (0.0f32, 0.0f32, 0.0f32);
            for &i in &idx {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let z = fc.depth_m.data[i];
                let p = glam::Vec3::new((x - k.cx) / k.fx * z, (y - k.cy) / k.fy * z, z);
                let zs = src_from_dst.transform_point3(p).z;
                let (dc, ds) = (dof.sigma_px(z).powi(2), dof.sigma_px(zs).powi(2));
                p0 += dc - ds;
                pp += dc - ds * (zs / z).powi(2);
                pm += dc - ds * (z / zs).powi(2);
            }
            let n = idx.len() as f32;
            rows.push((best.0, p0 / n, pp / n, pm / n));
        }
    }
    let corr = |f: &dyn Fn(&Tile) -> f32| {
        let n = rows.len() as f32;
        let (mx, my) = (rows.iter().map(|r| r.0).sum::<f32>() / n, rows.iter().map(f).sum::<f32>() / n);
        let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
        for r in &rows {
            let (dx, dy) = (r.0 - mx, f(r) - my);
            sxy += dx * dy;
            sxx += dx * dx;
            syy += dy * dy;
        }
        let rmse = (rows.iter().map(|r| (r.0 - f(r)).powi(2)).sum::<f32>() / n).sqrt();
        (sxy / (sxx * syy).sqrt(), sxy / syy, rmse)
    };
    println!("frame {cur}: {} tiles; measured Δv median {:.3}", rows.len(), {
        let mut v: Vec<f32> = rows.iter().map(|r| r.0).collect();
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    });
    println!("  none   : corr {:.2} slope {:.2} rmse {:.3}", corr(&|r| r.1).0, corr(&|r| r.1).1, corr(&|r| r.1).2);
    println!("  (zs/z)²: corr {:.2} slope {:.2} rmse {:.3}", corr(&|r| r.2).0, corr(&|r| r.2).1, corr(&|r| r.2).2);
    println!("  (z/zs)²: corr {:.2} slope {:.2} rmse {:.3}", corr(&|r| r.3).0, corr(&|r| r.3).1, corr(&|r| r.3).2);
    let med = |f: &dyn Fn(&Tile) -> f32| {
        let mut v: Vec<f32> = rows.iter().map(f).collect();
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "  predicted medians: none {:.3}, (zs/z)² {:.3}, (z/zs)² {:.3}",
        med(&|r| r.1),
        med(&|r| r.2),
        med(&|r| r.3)
    );
    println!("  zero   : rmse {:.3}", (rows.iter().map(|r| r.0 * r.0).sum::<f32>() / rows.len() as f32).sqrt());
}
