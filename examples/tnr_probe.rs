//! Probe: what the worker publishes for noise when the camera's noise is correlated
//! from frame to frame, as an ISP's motion-compensated temporal noise reduction
//! makes it: the calibration video rendered without noise, then noise n_t = ρ·n_{t−1}
//! (aligned into this frame by pose and depth) + √(1 − ρ²)·e_t, e_t the camera's
//! own (white, signal-dependent) field, fresh where the alignment fails — the same
//! std per frame, correlation ρ between consecutive frames. Median relative error of
//! the noise published over the last second, per tier and ρ. Difference-based
//! fits read σ·√(1 − ρ) for a neighbour one frame back.
//! With `LAGS=1`, also the blind noise fit against the frame 1 and 3 back (each
//! aligned): the median ratio of their level-0 stds, the signature a detector of
//! temporally correlated noise would read (1 for independent noise; √((1 − ρ³)/(1 − ρ))
//! for ρ per frame).
//! With `COPY=p`, a codec's skipped blocks beside ρ: each 8×8 block of the previous
//! frame's noise (aligned) is copied whole with chance p (the DivX clip copies 72% of
//! its pixels between frames), the rest follows ρ (`tests/common::CorrelatedNoise`).
//! `EVENTS=1` prints the worker's events. `W=px` renders the video that wide (4:3;
//! default 320) and `TIER=fast|accurate` runs one tier only.
//! `cargo run --release --example tnr_probe [FRAMES] [ρ,ρ,…]` (default 45 and 0,0.5,0.8).
#[path = "../tests/common/mod.rs"]
mod common;
use blind_augment::analysis::{temporal, Analysed, DepthMap};
use blind_augment::model::compare::noise_relative_error;
use blind_augment::model::DepthUnits;
use blind_augment::synth::sequence::SequenceSpec;
use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, Event, Providers};
use common::calibration::{drive_edited, scene, CorrelatedNoise};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let frames: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(45);
    let rhos: Vec<f32> =
        args.get(2).map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect()).unwrap_or(vec![0.0, 0.5, 0.8]);
    let copy: Option<f32> = std::env::var("COPY").ok().and_then(|s| s.parse().ok());
    let w: usize = std::env::var("W").ok().and_then(|s| s.parse().ok()).unwrap_or(320);
    let only = std::env::var("TIER").ok();
    let tiers = [CalibrationTier::Fast, CalibrationTier::Accurate];
    for tier in tiers.into_iter().filter(|t| only.as_deref().map_or(true, |o| format!("{t:?}").eq_ignore_ascii_case(o)))
    {
        for &rho in &rhos {
            let mut spec = SequenceSpec::motorcycle(scene(), w, w * 3 / 4, frames, None);
            let mut camera = CorrelatedNoise::new(&mut spec, rho, copy);
            let truth = camera.truth().clone();
            let view = spec.view;
            let mut cal =
                Calibrator::new(CalibratorConfig::new(tier, 1.0 / 30.0, Some(view)), Providers::for_tier(tier))
                    .unwrap();
            let lags = std::env::var_os("LAGS").is_some() && tier == CalibrationTier::Fast;
            let mut held: std::collections::VecDeque<Analysed> = Default::default();
            let mut ratios = vec![];
            let mut errs = vec![];
            let path = spec.path;
            drive_edited(
                &mut cal,
                &spec,
                scene(),
                |f| {
                    camera.apply(f);
                    if lags {
                        let depth = f.depth.clone().expect("the sequence's depth");
                        held.push_back(Analysed {
                            frame: blind_augment::analysis::Frame { depth: None, flow: None, ..f.clone() },
                            depth: Some(DepthMap { depth: depth.depth, units: DepthUnits::MetricM }),
                            world_from_camera: Some(path.world_from_camera(f.t_s)),
                            sparse_flow: None,
                        });
                        while held.len() > 4 {
                            held.pop_front();
                        }
                        if held.len() == 4 {
                            let std0 = |lag: usize| -> Option<f32> {
                                let cur = &held[3];
                                let a = temporal::align(&held[3 - lag], cur, &view)?;
                                let valid = blind_augment::image::Plane::from_vec(
                                    a.image.width,
                                    a.image.height,
                                    a.valid.iter().map(|&v| v as u8 as f32).collect(),
                                );
                                let nb = blind_augment::fit::Neighbour { image: &a.image, valid: &valid };
                                let n = blind_augment::fit::fit_noise_fast(&cur.frame.image, Some(&nb), 10_000).0;
                                n.present.then(|| n.levels[0].std(n.form, 1, n.clamp_luma(0.5)))
                            };
                            if let (Some(a), Some(b)) = (std0(1), std0(3)) {
                                ratios.push(b / a);
                            }
                        }
                    }
                },
                |sf, e| {
                    if std::env::var_os("EVENTS").is_some() && !matches!(e, Event::Published(_)) {
                        eprintln!("{:.2} s: {e:?}", sf.t_s);
                    }
                    if let Event::Published(u) = e {
                        if sf.t_s >= spec.frame_time_s(frames) - 1.0 {
                            if let Some(err) = noise_relative_error(&u.model.noise, &truth) {
                                errs.push(err);
                            }
                        }
                    }
                },
            );
            errs.sort_by(f32::total_cmp);
            let median = errs.get(errs.len() / 2).copied();
            println!("{tier:?} ρ {rho}: {} publications in the last second, median noise error {median:?}", errs.len());
            match cal.noise_correlation() {
                Some(c) => println!("  lag probes: {:?}, ρ {:.3} ({})", c.status, c.rho, c.reason),
                None => println!("  lag probes: none"),
            }
            if !ratios.is_empty() {
                ratios.sort_by(f32::total_cmp);
                let q = |p: f32| ratios[((ratios.len() - 1) as f32 * p).round() as usize];
                println!(
                    "  level-0 std, lag 3 over lag 1: {} frames, min {:.2}, p10 {:.2}, median {:.2}, p90 {:.2}, max {:.2}",
                    ratios.len(),
                    q(0.0),
                    q(0.1),
                    q(0.5),
                    q(0.9),
                    q(1.0)
                );
            }
        }
    }
}
