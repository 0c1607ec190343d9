use blind_augment::analysis::timing::*;
use blind_augment::analysis::*;
use blind_augment::fit::*;
use blind_augment::model::DepthUnits;
use blind_augment::synth;
use blind_augment::synth::sequence::*;
use std::sync::Arc;
fn main() {
    let scene = motorcycle().unwrap();
    let w: usize = std::env::var("W").ok().and_then(|s| s.parse().ok()).unwrap_or(320);
    let frames: Vec<usize> = std::env::var("FRAMES")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or(vec![18, 20, 24]);
    let sparse = std::env::var_os("SPARSE").is_some();
    let spec = SequenceSpec::motorcycle(&scene, w, w * 3 / 4, 60, None);
    let npx = w * w * 3 / 4;
    let poses: Vec<TimedPose> = (0..40)
        .map(|i| {
            let t = spec.frame_time_s(i);
            let (_, q, p) = spec.path.world_from_camera(t).to_scale_rotation_translation();
            TimedPose { t_ns: (t * 1e9).round() as i64, position_m: p, orientation: q }
        })
        .collect();
    let track = PoseTrack::new(poses).unwrap();
    let an = |i: usize| {
        let f = spec.frame(&scene, i);
        let a = Analysed {
            frame: Frame {
                index: i as u64,
                t_s: f.t_s,
                image: f.image.clone(),
                depth: Some(DepthMap { depth: f.depth_m.clone(), units: DepthUnits::MetricM }),
                flow: None,
            },
            depth: Some(DepthMap { depth: f.depth_m.clone(), units: DepthUnits::MetricM }),
            world_from_camera: Some(f.world_from_camera),
            sparse_flow: None,
        };
        (a, f)
    };
    let mut held = vec![];
    for i in 8..12 {
        let (mut a, _) = an(i);
        let ctx = FrameContext {
            current: &a.clone(),
            window: &[],
            poses: Some(&track),
            intrinsics: Some(&spec.view),
            frame_interval_s: 1.0 / 30.0,
        };
        a.sparse_flow = PoseDepthFlow::sparse(&ctx).ok();
        held.push(Arc::new(a));
    }
    let opts = FitOptions {
        tier: Some(Tier::Accurate),
        effects: Effects { noise: false, motion_blur: true, depth_of_field: false },
        mb_prefilter_var_px2: std::env::var("PRE").ok().and_then(|s| s.parse().ok()).unwrap_or(0.0),
        // `WORKER=1`: the worker's sample cap and shortest flow.
        mb_max_samples: if std::env::var_os("WORKER").is_some() { 2048 } else { FitOptions::default().mb_max_samples },
        mb_min_flow_px: if std::env::var_os("WORKER").is_some() { 4.0 } else { FitOptions::default().mb_min_flow_px },
        ..Default::default()
    };
    for i in frames {
        let (a, f) = an(i);
        let ctx = FrameContext {
            current: &a,
            window: &held,
            poses: Some(&track),
            intrinsics: Some(&spec.view),
            frame_interval_s: 1.0 / 30.0,
        };
        let pf = PoseDepthFlow.flow(&ctx).unwrap();
        let ferr = pf.dx.iter().zip(&f.flow.dx).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        let fmag = f.flow.dx.iter().map(|a| a.abs()).fold(0.0f32, f32::max);
        // `REPS=n`: the fastest of n runs of the flow, one band alignment and the reference.
        let reps: usize = std::env::var("REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(0);
        let best = |f: &mut dyn FnMut()| {
            (0..reps)
                .map(|_| {
                    let t = std::time::Instant::now();
                    f();
                    t.elapsed().as_secs_f64() * 1e3
                })
                .fold(f64::INFINITY, f64::min)
        };
        if reps > 0 {
            let t_flow = best(&mut || drop(PoseDepthFlow.flow(&ctx)));
            let t_align =
                best(&mut || drop(blind_augment::analysis::temporal::align_bands(&held[0], &a, &spec.view, 6)));
            let t_ref = best(&mut || drop(TemporalMotionDeblur::sparse().deblur(&ctx, &pf)));
            eprintln!("best of {reps}: flow {t_flow:.1} ms, one band alignment {t_align:.1} ms, sparse reference {t_ref:.1} ms");
        }
        let t0 = std::time::Instant::now();
        let r = if sparse { TemporalMotionDeblur::sparse() } else { TemporalMotionDeblur::default() }
            .deblur(&ctx, &pf)
            .unwrap();
        let t_ref = t0.elapsed().as_secs_f64() * 1e3;
        let t0 = std::time::Instant::now();
        let o = fit(
            &FitInputs {
                motion_deblurred: Some(&r.image),
                motion_deblurred_second: r.second.as_ref(),
                flow: Some(&pf),
                reference_valid: r.valid.as_ref(),
                ..FitInputs::new(&f.image)
            },
            &opts,
        );
        eprintln!(
            "reference {t_ref:.1} ms, fit {:.1} ms {:?}",
            t0.elapsed().as_secs_f64() * 1e3,
            o.map(|o| o.model.motion_blur.diagnostics.stages_s)
        );
        let mut only_dof = f.truth.clone();
        only_dof.motion_blur.present = false;
        only_dof.noise.present = false;
        let sharp = synth::apply_camera_model(&f.clean, &only_dof, Some(&f.depth_m), Some(&f.flow), 0);
        let valid_frac = r.valid.as_ref().unwrap().data.iter().filter(|v| **v > 0.5).count() as f32 / npx as f32;
        let l = |s: &blind_augment::image::Rgb,
                 fl: &blind_augment::image::Flow,
                 v: Option<&blind_augment::image::Plane>| {
            let second = if std::ptr::eq(s, &r.image) { r.second.as_ref() } else { None };
            fit(
                &FitInputs {
                    motion_deblurred: Some(s),
                    motion_deblurred_second: second,
                    flow: Some(fl),
                    reference_valid: v,
                    ..FitInputs::new(&f.image)
                },
                &opts,
            )
            .unwrap()
            .model
            .motion_blur
            .exposure
        };
        // reference error vs true sharp in valid region
        let mut e2 = 0.0;
        let mut n = 0.0;
        for k in 0..npx {
            if r.valid.as_ref().unwrap().data[k] > 0.5 {
                e2 += (r.image.channels[1][k] - sharp.channels[1][k]).powi(2);
                n += 1.0;
            }
        }
        println!(
            "frame {i}: λ {:?} flow err max {ferr:.3} of {fmag:.2}; ref rms err {:.4} valid {valid_frac:.2} sources {:?}",
            f.truth.motion_blur.exposure,
            (e2 / n as f32).sqrt(),
            r.sources
        );
        println!("  truth flow+true ref {:?}; pose flow+true ref {:?}; truth flow + temporal ref {:?}; pose flow+temporal {:?}", l(&sharp, &f.flow, None), l(&sharp, &pf, None), l(&r.image, &f.flow, r.valid.as_ref()), l(&r.image, &pf, r.valid.as_ref()));
    }
}
