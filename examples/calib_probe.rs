//! Probe: the calibrator over a synthetic sequence, per tier.
use blind_augment::analysis::timing::TimedPose;
use blind_augment::analysis::{DepthMap, Frame};
use blind_augment::model::compare::*;
use blind_augment::model::DepthUnits;
use blind_augment::synth::sequence::*;
use blind_augment::worker::*;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let tier = CalibrationTier::parse(args.get(1).map(|s| s.as_str()).unwrap_or("fast")).unwrap();
    let frames: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(60);
    let w: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(320);
    let scene = motorcycle().unwrap();
    let spec = SequenceSpec::motorcycle(&scene, w, w * 3 / 4, frames, Some(frames as f64 / 60.0));
    let mut cal =
        Calibrator::new(CalibratorConfig::new(tier, 1.0 / 30.0, Some(spec.view)), Providers::for_tier(tier)).unwrap();
    let pose = |i: usize| {
        let t = spec.frame_time_s(i);
        let m = spec.path.world_from_camera(t);
        let (_, q, p) = m.to_scale_rotation_translation();
        TimedPose { t_ns: (t * 1e9).round() as i64, position_m: p, orientation: q }
    };
    cal.push_poses(&[pose(0), pose(1)]).unwrap();
    let depths: Vec<f32> = (1..10).map(|i| 2.0 + 0.4 * i as f32).collect();
    for i in 0..frames {
        cal.push_poses(&[pose(i + 2)]).unwrap();
        let f = spec.frame(&scene, i);
        let truth = f.truth.clone();
        let t0 = std::time::Instant::now();
        let ev = cal
            .push_frame(Frame {
                index: i as u64,
                t_s: f.t_s,
                image: f.image,
                depth: Some(DepthMap { depth: f.depth_m, units: DepthUnits::MetricM }),
                flow: None,
            })
            .unwrap();
        let dt = t0.elapsed().as_secs_f64();
        for e in &ev {
            match e {
                Event::Published(u) if std::env::var_os("MB").is_some() => {
                    println!(
                        "{i:3} t={:.2} λ err {:.3}: {}",
                        u.t_s,
                        exposure_error(&u.model, &truth),
                        u.model.motion_blur.diagnostics.reason
                    )
                }
                Event::Published(u) => println!(
                    "{i:3} t={:.2} λ={:?}({:.3}) noise_err={:?} dof_rmse={:?} {:?} {:.0} ms  [mb {}] [n {}] [{}]",
                    u.t_s,
                    u.model.motion_blur.exposure.map(|x| (x * 1000.0).round() / 1000.0),
                    exposure_error(&u.model, &truth),
                    noise_relative_error(&u.model.noise, &truth.noise),
                    dof_rmse_px(&u.model.depth_of_field, &truth.depth_of_field, &depths),
                    u.reason,
                    dt * 1e3,
                    u.model.motion_blur.diagnostics.method,
                    u.model.noise.diagnostics.method,
                    u.stages_s.iter().map(|(k, v)| format!("{k} {:.1}", v * 1e3)).collect::<Vec<_>>().join(", ")
                ),
                Event::Degraded { reason, .. } => println!("    degraded: {reason}"),
                other => println!("    {other:?}"),
            }
        }
    }
}
