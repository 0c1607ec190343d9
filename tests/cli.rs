//! The `blind-augment` binary end to end: synth with known parameters, fit them
//! back (accurate and blind), plots, folders, and errors that name the file.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_blind-augment"))
}

fn dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("cli").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("tmp dir");
    d
}

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

fn run(cmd: &mut Command) -> (bool, String) {
    let out = cmd.output().expect("binary runs");
    (out.status.success(), format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)))
}

fn model(path: &Path) -> blind_augment::model::CameraModel {
    blind_augment::model::CameraModel::from_json(&std::fs::read_to_string(path).expect("json")).expect("valid")
}

/// The user's loop: write a model with known λ, synth a real photo with it, fit it
/// back with the clean reference. 16-bit input stays 16-bit.
#[test]
fn synth_then_fit_recovers_exposure() {
    let d = dir("roundtrip");
    let img = blind_augment::io::load_rgb(&data("chelsea.png")).expect("photo").0;
    let flow = blind_augment::image::Flow::uniform(img.width, img.height, 6.0, 2.0);
    blind_augment::io::save_flow(&d.join("flow.flo"), &flow).expect("flow");
    blind_augment::io::save_rgb(&d.join("clean16.png"), &img, blind_augment::io::BitDepth::Sixteen).expect("16-bit");
    let mut m = blind_augment::model::CameraModel::empty(img.width as u32, img.height as u32);
    m.motion_blur.present = true;
    m.motion_blur.exposure = Some(0.35);
    std::fs::write(d.join("truth.json"), m.to_json().expect("valid")).expect("write");
    let (ok, log) = run(bin()
        .args(["synth", "--image"])
        .arg(d.join("clean16.png"))
        .arg("--camera")
        .arg(d.join("truth.json"))
        .arg("--flow")
        .arg(d.join("flow.flo"))
        .arg("--out")
        .arg(d.join("blurred.png")));
    assert!(ok, "{log}");
    assert_eq!(
        blind_augment::io::load_rgb(&d.join("blurred.png")).expect("read").1,
        blind_augment::io::BitDepth::Sixteen
    );
    let (ok, log) = run(bin()
        .args(["fit", "--image"])
        .arg(d.join("blurred.png"))
        .arg("--motion-deblurred")
        .arg(d.join("clean16.png"))
        .arg("--flow")
        .arg(d.join("flow.flo"))
        .args(["--only", "motion-blur", "--out"])
        .arg(d.join("fit.json"))
        .arg("--plots")
        .arg(d.join("plots")));
    assert!(ok, "{log}");
    let fitted = model(&d.join("fit.json"));
    let lambda = fitted.motion_blur.exposure.expect("identifiable");
    // 16-bit quantisation only: tighter than the 0.01 of 8-bit frames.
    assert!((lambda - 0.35).abs() < 0.005, "λ {lambda}");
    assert!(d.join("plots/motion_blur.png").exists());
    assert_eq!(fitted.noise.diagnostics.status, blind_augment::model::Status::NotFitted);
}

/// Blind fit of a folder of frames, aggregated; plots for noise.
#[test]
fn fit_frames_folder_blind() {
    let d = dir("frames");
    std::fs::create_dir_all(d.join("frames")).expect("dir");
    for name in ["a.png", "b.png"] {
        std::fs::copy(data("chelsea.png"), d.join("frames").join(name)).expect("copy");
    }
    let (ok, log) = run(bin()
        .args(["--threads", "1", "fit", "--frames"])
        .arg(d.join("frames"))
        .arg("--out")
        .arg(d.join("m.json"))
        .arg("--plots")
        .arg(d.join("plots")));
    assert!(ok, "{log}");
    let m = model(&d.join("m.json"));
    assert_eq!(m.noise.diagnostics.method, "fast");
    assert!(m.noise.diagnostics.reason.contains("of 2 frames"), "{}", m.noise.diagnostics.reason);
    assert!(d.join("plots/noise.png").exists());
    // No flow, no depth: blur is not identifiable, not guessed.
    assert_eq!(m.motion_blur.diagnostics.status, blind_augment::model::Status::NotIdentifiable);
}

#[test]
fn errors_name_the_file_and_the_problem() {
    let d = dir("errors");
    let (ok, log) = run(bin().args(["fit", "--image"]).arg(d.join("nope.png")).arg("--out").arg(d.join("m.json")));
    assert!(!ok && log.contains("nope.png"), "{log}");
    std::fs::write(d.join("bad.json"), "{\"schema\": 3}").expect("write");
    let (ok, log) = run(bin()
        .args(["synth", "--image"])
        .arg(data("chelsea.png"))
        .arg("--camera")
        .arg(d.join("bad.json"))
        .arg("--out")
        .arg(d.join("o.png")));
    assert!(!ok && log.contains("bad.json"), "{log}");
    // A reference of the wrong size names the input.
    let small = d.join("small.png");
    image::RgbImage::new(10, 10).save(&small).expect("save");
    let (ok, log) = run(bin()
        .args(["fit", "--image"])
        .arg(data("chelsea.png"))
        .arg("--denoised")
        .arg(&small)
        .arg("--out")
        .arg(d.join("m.json")));
    assert!(!ok && log.contains("denoised") && log.contains("10×10"), "{log}");
    // --tier accurate without the reference says which one is missing.
    let (ok, log) = run(bin()
        .args(["fit", "--tier", "accurate", "--only", "noise", "--image"])
        .arg(data("chelsea.png"))
        .arg("--out")
        .arg(d.join("m.json")));
    assert!(!ok && log.contains("denoised"), "{log}");
}

/// The README's main command: self-contained, writes the report and images.
#[test]
fn demo_runs_without_files() {
    let d = dir("demo");
    let (ok, log) = run(bin().args(["demo", "--out"]).arg(&d));
    assert!(ok, "{log}");
    for f in [
        "report.md",
        "side_by_side.png",
        "truth.json",
        "camera_accurate.json",
        "camera_fast.json",
        "plots_accurate/depth_of_field.png",
    ] {
        assert!(d.join(f).exists(), "{f}");
    }
    let truth = model(&d.join("truth.json"));
    let acc = model(&d.join("camera_accurate.json"));
    let (t, a) = (truth.motion_blur.exposure.expect("λ"), acc.motion_blur.exposure.expect("λ"));
    assert!((t - a).abs() < 0.01, "demo λ {a} vs {t}");
    // The report's headline table puts both tiers' errors side by side: its λ row
    // must carry the errors of the written models.
    let report = std::fs::read_to_string(d.join("report.md")).expect("report");
    let fast = model(&d.join("camera_fast.json"));
    let f = fast.motion_blur.exposure_or_zero();
    // (The fast cell may go on with "(not identifiable: …)".)
    let row = format!("| motion blur | \\|λ − λ_true\\| | {:.4} | {:.4}", (a - t).abs(), (f - t).abs());
    assert!(report.contains("## Error against the truth, per tier") && report.contains(&row), "{row} in\n{report}");
    for effect in ["| depth of field | δ RMSE", "| noise | median relative error"] {
        assert!(report.contains(effect), "{effect} in\n{report}");
    }
    // Per noise level, how the fast tier read it, as its model says.
    assert_eq!(fast.noise.level_sources.len(), 4, "the fast tier's level sources");
    if let blind_augment::model::LevelSource::Measured { luma: [a, b], bins, relative_stderr } =
        fast.noise.level_sources[0]
    {
        let cell = format!("measured, {bins} luma bins over {a:.2}–{b:.2} | ±{:.1}% |", 100.0 * relative_stderr);
        assert!(report.contains("| 0 | ") && report.contains(&cell), "{cell} in\n{report}");
    } else {
        panic!("level 0 is always measured where noise is present: {:?}", fast.noise.level_sources);
    }
    // The render half needs a Vulkan device: required under REQUIRE_GPU=1 (CI).
    if std::env::var("REQUIRE_GPU").as_deref() == Ok("1") {
        for f in ["composite_side_by_side.png", "composite_zoom.png", "render/matched_007.png", "render/naive_000.png"]
        {
            assert!(d.join(f).exists(), "{f}: {log}");
        }
        let report = std::fs::read_to_string(d.join("report.md")).expect("report");
        assert!(report.contains("## Render") && !report.contains("Skipped"), "{report}");
        // The matched composite differs from the naive one (the effects ran) and
        // the naive one from the bare background (the object was drawn).
        let load = |f: &str| blind_augment::io::load_rgb(&d.join(f)).expect(f).0;
        let (naive, matched, bg) =
            (load("render/naive_004.png"), load("render/matched_004.png"), load("render/background_004.png"));
        let mad = |a: &blind_augment::image::Rgb, b: &blind_augment::image::Rgb| {
            let n = b.width * b.height;
            (0..3)
                .map(|c| {
                    (0..n)
                        .map(|i| (a.channels[c][(i / b.width) * a.width + i % b.width] - b.channels[c][i]).abs())
                        .sum::<f32>()
                })
                .sum::<f32>()
                / (3 * n) as f32
        };
        assert!(mad(&naive, &bg) > 0.002, "object not drawn");
        assert!(mad(&matched, &naive) > 0.0005, "effects changed nothing");
    }
}

/// `render` end to end on the bundled object, and its errors name the input.
#[test]
fn render_command_writes_naive_and_matched() {
    let d = dir("render");
    let bg = d.join("bg");
    std::fs::create_dir_all(&bg).expect("dir");
    let img = blind_augment::io::load_rgb(&data("chelsea.png")).expect("photo").0;
    for k in 0..2 {
        blind_augment::io::save_rgb(&bg.join(format!("f{k}.png")), &img, blind_augment::io::BitDepth::Eight)
            .expect("bg");
    }
    let mut m = blind_augment::model::CameraModel::empty(img.width as u32, img.height as u32);
    m.reference.frame_interval_s = Some(1.0 / 30.0);
    m.noise = blind_augment::synth::white_sensor_noise([1e-4; 3], [1e-3; 3], [0.0, 1.0]);
    std::fs::write(d.join("camera.json"), m.to_json().expect("json")).expect("write");
    let glb = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("assets/toy.glb");
    let (ok, log) = run(bin()
        .args(["render", "--scene"])
        .arg(d.join("missing.glb"))
        .arg("--background")
        .arg(&bg)
        .arg("--camera")
        .arg(d.join("camera.json"))
        .arg("--out")
        .arg(d.join("out")));
    assert!(!ok && log.contains("missing.glb"), "{log}");
    if std::env::var("REQUIRE_GPU").as_deref() != Ok("1") {
        eprintln!("render_command: the rendering half needs REQUIRE_GPU=1 (a Vulkan device)");
        return;
    }
    let (ok, log) = run(bin()
        .args(["render", "--scene"])
        .arg(&glb)
        .arg("--background")
        .arg(&bg)
        .arg("--camera")
        .arg(d.join("camera.json"))
        .arg("--out")
        .arg(d.join("out"))
        .args(["--eye-size", "160x120", "--focal-px", "300"]));
    assert!(ok, "{log}");
    for k in 0..2 {
        for kind in ["naive", "matched"] {
            let f = d.join("out").join(format!("{kind}_{k:03}.png"));
            let (img, _) = blind_augment::io::load_rgb(&f).expect("output");
            // Both eyes side by side with a 4-px gap.
            assert_eq!((img.width, img.height), (2 * 160 + 4, 120), "{}", f.display());
        }
    }
    let (ok, log) = run(bin()
        .args(["render", "--scene"])
        .arg(&glb)
        .arg("--background")
        .arg(&bg)
        .arg("--camera")
        .arg(d.join("camera.json"))
        .arg("--out")
        .arg(d.join("out2"))
        .args(["--eye-size", "160by120"]));
    assert!(!ok && log.contains("--eye-size"), "{log}");
}
