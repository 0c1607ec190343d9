//! Probe: `analysis::temporal::align` at 1280×960 on two frames of the calibration video.
use blind_augment::analysis::{temporal, Analysed, DepthMap, Frame};
use blind_augment::model::DepthUnits;
use blind_augment::synth::sequence::*;

fn main() {
    let scene = motorcycle().unwrap();
    let spec = SequenceSpec::motorcycle(&scene, 1280, 960, 30, None);
    let mk = |i: usize| {
        let f = spec.frame(&scene, i);
        Analysed {
            world_from_camera: Some(spec.path.world_from_camera(f.t_s)),
            frame: Frame { index: i as u64, t_s: f.t_s, image: f.image, depth: None, flow: None },
            depth: Some(DepthMap { depth: f.depth_m, units: DepthUnits::MetricM }),
            sparse_flow: None,
        }
    };
    let (a, b) = (mk(20), mk(21));
    let n: usize = std::env::var("N").ok().and_then(|s| s.parse().ok()).unwrap_or(20);
    let mut t = vec![];
    for _ in 0..n {
        let t0 = std::time::Instant::now();
        let al = temporal::align(&a, &b, &spec.view).unwrap();
        t.push(t0.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(al);
    }
    t.sort_by(f64::total_cmp);
    println!("align 1280×960: median {:.1} ms, min {:.1} ms", t[t.len() / 2], t[0]);
}
