//! Probe: the blind noise fit per frame of the calibration video, alone or with the previous frame aligned (`NB=1`), its error against the truth and (`TIME=1`) its stage times. `cargo run --release --example noise_neighbour -- FROM TO WIDTH`.
use blind_augment::fit::{fit, Effects, FitInputs, FitOptions, Tier};
use blind_augment::model::compare::*;
use blind_augment::synth::sequence::*;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let from: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(110);
    let to: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(150);
    let w: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(320);
    let scene = motorcycle().unwrap();
    let spec = SequenceSpec::motorcycle(&scene, w, w * 3 / 4, 150, Some(2.5));
    // JPEG=q: every frame through a JPEG encoder at quality q (an intra-only codec:
    // its noise is independent from frame to frame).
    let jpeg: Option<u8> = std::env::var("JPEG").ok().and_then(|s| s.parse().ok());
    // SAVE=dir: every rendered frame written there (8-bit PNG, frame_NNN.png);
    // LOAD=dir: frames read from there instead (e.g. after a video codec).
    let frame_image = |f: &SequenceFrame, jpeg: Option<u8>| {
        let name = format!("frame_{:03}.png", f.index);
        if let Ok(dir) = std::env::var("SAVE") {
            let path = std::path::Path::new(&dir).join(&name);
            blind_augment::io::save_rgb(&path, &f.image, blind_augment::io::BitDepth::Eight).unwrap();
        }
        if let Ok(dir) = std::env::var("LOAD") {
            return blind_augment::io::load_rgb(&std::path::Path::new(&dir).join(&name)).unwrap().0;
        }
        jpeg.map_or_else(|| f.image.clone(), |q| jpeg_round_trip(&f.image, q))
    };
    let an = |f: &SequenceFrame| blind_augment::analysis::Analysed {
        frame: blind_augment::analysis::Frame {
            index: f.index as u64,
            t_s: f.t_s,
            image: frame_image(f, jpeg),
            depth: None,
            flow: None,
        },
        depth: Some(blind_augment::analysis::DepthMap {
            depth: f.depth_m.clone(),
            units: blind_augment::model::DepthUnits::MetricM,
        }),
        world_from_camera: Some(f.world_from_camera),
        sparse_flow: None,
    };
    let use_nb = std::env::var("NB").is_ok();
    // LAG=k: the neighbour is the frame k before (default 1).
    let lag: usize = std::env::var("LAG").ok().and_then(|s| s.parse().ok()).unwrap_or(1);
    for i in from..to {
        let prev = (i >= lag).then(|| an(&spec.frame(&scene, i - lag)));
        let f = spec.frame(&scene, i);
        let cur = an(&f);
        let ta = std::time::Instant::now();
        let al = prev
            .as_ref()
            .filter(|_| use_nb)
            .and_then(|p| blind_augment::analysis::temporal::align(p, &cur, &spec.view));
        if std::env::var("TIME").is_ok() {
            eprintln!("align {:.1} ms", ta.elapsed().as_secs_f64() * 1e3);
        }
        let valid = al.as_ref().map(|a| {
            blind_augment::image::Plane::from_vec(
                f.image.width,
                f.image.height,
                a.valid.iter().map(|&v| v as u8 as f32).collect(),
            )
        });
        let mut inp = FitInputs::new(&cur.frame.image);
        if let (Some(a), Some(v)) = (al.as_ref(), valid.as_ref()) {
            inp.neighbour = Some(blind_augment::fit::Neighbour { image: &a.image, valid: v });
        }
        let t0 = std::time::Instant::now();
        let mut o = fit(
            &inp,
            &FitOptions {
                tier: Some(Tier::Fast),
                effects: Effects { noise: true, motion_blur: false, depth_of_field: false },
                ..Default::default()
            },
        )
        .unwrap();
        // RAW=1: the neighbour read whatever the frame (`fit` reads a frame with a
        // codec's block grid alone).
        if std::env::var_os("RAW").is_some() {
            let per_level = FitOptions::default().noise_fast_samples_per_level;
            o.model.noise = blind_augment::fit::fit_noise_fast(&cur.frame.image, inp.neighbour.as_ref(), per_level).0;
        }
        if std::env::var("TIME").is_ok() {
            eprintln!("fit {:.1} ms {:?}", t0.elapsed().as_secs_f64() * 1e3, o.model.noise.diagnostics.stages_s);
        }
        let n = &o.model.noise;
        let t = &f.truth.noise;
        let s = |m: &blind_augment::model::Noise, l: usize| {
            m.levels
                .get(l)
                .map(|lv| lv.std(m.form, 1, 0.5f32.clamp(m.luminance_range[0], m.luminance_range[1])))
                .unwrap_or(f32::NAN)
        };
        if std::env::var("DUMP").is_ok() {
            dump(&o);
            truth_at(t);
        }
        println!("{i} err={:?} present={} form={:?}/{:?} range={:?} std@.5 L0..3 fit [{:.4} {:.4} {:.4} {:.4}] truth [{:.4} {:.4} {:.4} {:.4}] {}", noise_relative_error(n, t), n.present, n.form, n.intensity, n.luminance_range, s(n,0), s(n,1), s(n,2), s(n,3), s(t,0), s(t,1), s(t,2), s(t,3), &n.diagnostics.reason.chars().take(150).collect::<String>());
    }
}
#[allow(dead_code)]
fn dump(o: &blind_augment::fit::FitOutput) {
    if let Some(p) = &o.plots.noise {
        for (l, (y, s)) in p.levels.iter().enumerate() {
            let pts: Vec<String> = y.iter().zip(&s[1]).map(|(a, b)| format!("{:.2}:{:.4}", a, b)).collect();
            println!("   L{l}: {}", pts.join(" "));
        }
    }
    for l in 0..4 {
        let lv = &o.model.noise.levels[l];
        println!("   L{l} slope {:?} icpt {:?}", lv.slope, lv.intercept);
    }
}
#[allow(dead_code)]
fn truth_at(t: &blind_augment::model::Noise) {
    let v: Vec<String> = [0.1f32, 0.17, 0.22, 0.28, 0.34, 0.4, 0.47, 0.53, 0.59]
        .iter()
        .map(|&y| format!("{y:.2}:{:.4}", t.levels[0].std(t.form, 1, y)))
        .collect();
    println!(
        "   truth L0 {}  form {:?} L1/L0 {:.3}",
        v.join(" "),
        t.form,
        t.levels[1].std(t.form, 1, 0.4) / t.levels[0].std(t.form, 1, 0.4)
    );
}

/// `img` encoded as 8-bit JPEG at `quality` and decoded.
fn jpeg_round_trip(img: &blind_augment::image::Rgb, quality: u8) -> blind_augment::image::Rgb {
    let (w, h) = (img.width, img.height);
    let mut bytes = Vec::with_capacity(w * h * 3);
    for i in 0..w * h {
        for c in 0..3 {
            bytes.push((img.channels[c][i].clamp(0.0, 1.0) * 255.0).round() as u8);
        }
    }
    let mut out = vec![];
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
        .encode(&bytes, w as u32, h as u32, image::ExtendedColorType::Rgb8)
        .unwrap();
    let dec = image::load_from_memory(&out).unwrap().to_rgb8();
    let mut r = blind_augment::image::Rgb::new(w, h, [0.0; 3]);
    for (i, p) in dec.pixels().enumerate() {
        for c in 0..3 {
            r.channels[c][i] = p.0[c] as f32 / 255.0;
        }
    }
    r
}
