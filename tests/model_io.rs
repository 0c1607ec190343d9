//! The camera-model schema (validation names the field) and the file formats
//! (round trips, bit depths, errors naming the file).

mod common;

use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::io::{self, BitDepth};
use blind_augment::model::*;

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("model_io");
    std::fs::create_dir_all(&dir).expect("tmp dir");
    dir.join(name)
}

fn sample_model() -> CameraModel {
    let mut m = CameraModel::empty(640, 480);
    m.reference.pixels_per_radian = Some(500.0);
    m.reference.frame_interval_s = Some(1.0 / 30.0);
    m.motion_blur = MotionBlur { present: true, exposure: Some(0.4), diagnostics: Diagnostics::not_fitted("x") };
    m.depth_of_field = DepthOfField {
        present: true,
        units: DepthUnits::MetricM,
        curve: Some(DofCurve::ThinLens { k: 2.0, focus_depth: 1.5, c0: 0.1 }),
        depth_range: [0.3, 5.0],
        kernel: blind_augment::model::DofKernel::Gaussian,
        diagnostics: Diagnostics::not_fitted("x"),
    };
    m
}

#[test]
fn json_round_trip_and_schema_tag() {
    let m = sample_model();
    let text = m.to_json().expect("valid");
    assert!(text.contains("\"schema\": \"blind-augment/camera-model/5\""));
    assert!(text.contains("\"form\": \"thin_lens\""));
    assert_eq!(CameraModel::from_json(&text).expect("parses"), m);
}

/// A version-1 file (no `colour`) still reads, as the current schema with the
/// colour term not fitted; an unknown schema is refused naming it; a colour gain
/// out of range or not finite is refused naming the field.
#[test]
fn version_1_files_read_and_colour_is_validated() {
    let m = sample_model();
    let mut v = serde_json::to_value(&m).expect("serialises");
    v["schema"] = serde_json::json!("blind-augment/camera-model/1");
    v.as_object_mut().expect("object").remove("colour");
    let old = CameraModel::from_json(&v.to_string()).expect("a version-1 file parses");
    assert_eq!(old.schema, blind_augment::model::SCHEMA);
    assert_eq!(old.colour.diagnostics.status, Status::NotFitted);
    assert_eq!(old.colour.gains_or_one(), [1.0; 3]);
    v["schema"] = serde_json::json!("blind-augment/camera-model/9");
    let e = CameraModel::from_json(&v.to_string()).expect_err("unknown schema").to_string();
    assert!(e.contains("schema"), "{e}");
    let mut c = sample_model();
    c.colour = blind_augment::model::Colour {
        present: true,
        illuminant: Some([1.2, 1.0, 0.7]),
        exposure: Some(0.8),
        diagnostics: Diagnostics::not_fitted("x"),
    };
    assert_eq!(CameraModel::from_json(&c.to_json().expect("valid")).expect("parses"), c);
    for (field, bad) in [("illuminant", serde_json::json!([1.0, 100.0, 1.0])), ("exposure", serde_json::json!(0.0))] {
        let mut v = serde_json::to_value(&c).expect("serialises");
        v["colour"][field] = bad;
        let e = CameraModel::from_json(&v.to_string()).expect_err("out of range").to_string();
        assert!(e.contains(&format!("colour.{field}")), "{e}");
    }
}

/// Version-2 files (no `vignetting`) read with vignetting not fitted; a vignetting
/// term round-trips, and one whose falloff leaves [0.05, 2] anywhere on the frame,
/// a non-finite coefficient or a present term without coefficients is refused,
/// naming the field.
#[test]
fn version_2_files_read_and_vignetting_is_validated() {
    let m = sample_model();
    let mut v = serde_json::to_value(&m).expect("serialises");
    v["schema"] = serde_json::json!("blind-augment/camera-model/2");
    v.as_object_mut().expect("object").remove("vignetting");
    let old = CameraModel::from_json(&v.to_string()).expect("a version-2 file parses");
    assert_eq!(old.schema, blind_augment::model::SCHEMA);
    assert_eq!(old.vignetting.diagnostics.status, Status::NotFitted);
    assert_eq!(old.vignetting.applied(), None);
    let mut c = sample_model();
    c.vignetting = blind_augment::model::Vignetting {
        present: true,
        log_falloff: Some([-0.25, -0.65, 0.34]),
        diagnostics: Diagnostics::not_fitted("x"),
    };
    assert_eq!(CameraModel::from_json(&c.to_json().expect("valid")).expect("parses"), c);
    // exp(-4) = 0.018 at the corner; exp(+1) = 2.7; present without terms.
    for bad in [serde_json::json!([-4.0, 0.0, 0.0]), serde_json::json!([1.0, 0.0, 0.0]), serde_json::Value::Null] {
        let mut v = serde_json::to_value(&c).expect("serialises");
        v["vignetting"]["log_falloff"] = bad.clone();
        let e = CameraModel::from_json(&v.to_string()).expect_err("refused").to_string();
        assert!(e.contains("vignetting"), "{bad}: {e}");
    }
    // JSON has no NaN: a model built in code is checked before it is written.
    c.vignetting.log_falloff = Some([0.0, f32::NAN, 0.0]);
    let e = c.to_json().expect_err("non-finite").to_string();
    assert!(e.contains("vignetting.log_falloff[1]"), "{e}");
}

/// Version-3 files (no `chromatic_aberration`) read with the term not fitted; the
/// term round-trips, and a scale past ±0.01 (8 px at a 1280×960 corner), a
/// non-finite one or a present term without scales is refused, naming the field.
#[test]
fn version_3_files_read_and_chromatic_aberration_is_validated() {
    let m = sample_model();
    let mut v = serde_json::to_value(&m).expect("serialises");
    v["schema"] = serde_json::json!("blind-augment/camera-model/3");
    v.as_object_mut().expect("object").remove("chromatic_aberration");
    let old = CameraModel::from_json(&v.to_string()).expect("a version-3 file parses");
    assert_eq!(old.schema, blind_augment::model::SCHEMA);
    assert_eq!(old.chromatic_aberration.diagnostics.status, Status::NotFitted);
    assert_eq!(old.chromatic_aberration.applied(), None);
    let mut c = sample_model();
    c.chromatic_aberration = blind_augment::model::ChromaticAberration {
        present: true,
        scale_minus_one: Some([0.0012, -0.0004]),
        diagnostics: Diagnostics::not_fitted("x"),
    };
    assert_eq!(CameraModel::from_json(&c.to_json().expect("valid")).expect("parses"), c);
    for bad in [serde_json::json!([0.02, 0.0]), serde_json::json!([0.0, -0.011]), serde_json::Value::Null] {
        let mut v = serde_json::to_value(&c).expect("serialises");
        v["chromatic_aberration"]["scale_minus_one"] = bad.clone();
        let e = CameraModel::from_json(&v.to_string()).expect_err("refused").to_string();
        assert!(e.contains("chromatic_aberration"), "{bad}: {e}");
    }
    c.chromatic_aberration.scale_minus_one = Some([f32::INFINITY, 0.0]);
    let e = c.to_json().expect_err("non-finite").to_string();
    assert!(e.contains("chromatic_aberration.scale_minus_one[0]"), "{e}");
}

/// Version-4 files (no `sharpening`) read with the term not fitted; the term
/// round-trips, and an amount or radius outside its range, a non-finite one or a
/// present term without both is refused, naming the field.
#[test]
fn version_4_files_read_and_sharpening_is_validated() {
    let m = sample_model();
    let mut v = serde_json::to_value(&m).expect("serialises");
    v["schema"] = serde_json::json!("blind-augment/camera-model/4");
    v.as_object_mut().expect("object").remove("sharpening");
    let old = CameraModel::from_json(&v.to_string()).expect("a version-4 file parses");
    assert_eq!(old.schema, blind_augment::model::SCHEMA);
    assert_eq!(old.sharpening.diagnostics.status, Status::NotFitted);
    assert_eq!(old.sharpening.applied(), None);
    let mut c = sample_model();
    c.sharpening = blind_augment::model::Sharpening {
        present: true,
        amount: Some(0.8),
        radius_px: Some(1.2),
        overshoot: Some(0.04),
        diagnostics: Diagnostics::not_fitted("x"),
    };
    assert_eq!(CameraModel::from_json(&c.to_json().expect("valid")).expect("parses"), c);
    assert_eq!(c.sharpening.applied(), Some((0.8, 1.2)));
    for (field, bad) in [
        ("amount", serde_json::json!(-0.1)),
        ("amount", serde_json::json!(4.5)),
        ("radius_px", serde_json::json!(0.1)),
        ("radius_px", serde_json::json!(9.0)),
        ("amount", serde_json::Value::Null),
        ("overshoot", serde_json::json!(-0.01)),
    ] {
        let mut v = serde_json::to_value(&c).expect("serialises");
        v["sharpening"][field] = bad.clone();
        let e = CameraModel::from_json(&v.to_string()).expect_err("refused").to_string();
        assert!(e.contains("sharpening"), "{field} {bad}: {e}");
    }
    c.sharpening.radius_px = Some(f32::NAN);
    let e = c.to_json().expect_err("non-finite").to_string();
    assert!(e.contains("sharpening.radius_px"), "{e}");
}

/// The DoF kernel shape round-trips; files written before it existed (no `kernel`)
/// read as the Gaussian they meant; an unknown shape is refused.
#[test]
fn dof_kernel_shape_round_trips_and_defaults_to_gaussian() {
    let mut m = sample_model();
    m.depth_of_field.kernel = DofKernel::Disc;
    let text = m.to_json().expect("valid");
    assert!(text.contains("\"kernel\": \"disc\""), "{text}");
    assert_eq!(CameraModel::from_json(&text).expect("parses"), m);
    let mut v = serde_json::to_value(&m).expect("serialises");
    v["depth_of_field"].as_object_mut().expect("object").remove("kernel");
    let old = CameraModel::from_json(&v.to_string()).expect("old file parses");
    assert_eq!(old.depth_of_field.kernel, DofKernel::Gaussian);
    v["depth_of_field"]["kernel"] = serde_json::json!("hexagon");
    assert!(CameraModel::from_json(&v.to_string()).is_err());
}

/// Each case — the JSON pointer set to the value in `good` — is refused with an
/// error naming the field.
fn refused_naming_the_field(good: &serde_json::Value, cases: Vec<(&str, serde_json::Value, &str)>) {
    for (ptr, value, field) in cases {
        let mut v = good.clone();
        *v.pointer_mut(ptr).unwrap_or_else(|| panic!("pointer {ptr}")) = value;
        let err = CameraModel::from_json(&v.to_string()).expect_err(ptr);
        assert!(err.to_string().contains(field), "{ptr}: {err}");
    }
}

/// The blind fit's level sources round-trip; files without them (written before
/// they existed, or by hand) read as none; a bad one is refused naming its field.
#[test]
fn noise_level_sources_round_trip_and_are_validated() {
    let mut m = sample_model();
    m.noise.level_sources = vec![
        LevelSource::Measured { luma: [0.1, 0.7], bins: 11, relative_stderr: 0.11 },
        LevelSource::Measured { luma: [0.1, 0.22], bins: 3, relative_stderr: 0.4 },
        LevelSource::Continued { from: 1 },
        LevelSource::Continued { from: 1 },
    ];
    let text = m.to_json().expect("valid");
    assert!(text.contains("\"measured\"") && text.contains("\"continued\""), "{text}");
    assert_eq!(CameraModel::from_json(&text).expect("parses"), m);
    let good = serde_json::to_value(&m).expect("serialises");
    let mut old = good.clone();
    old["noise"].as_object_mut().expect("object").remove("level_sources");
    assert!(CameraModel::from_json(&old.to_string()).expect("old file parses").noise.level_sources.is_empty());
    let cases: Vec<(&str, serde_json::Value, &str)> = vec![
        ("/noise/level_sources/1/measured/luma", serde_json::json!([0.5, 0.2]), "noise.level_sources[1].luma"),
        ("/noise/level_sources/1/measured/luma", serde_json::json!([0.1, 1.5]), "noise.level_sources[1].luma"),
        ("/noise/level_sources/0/measured/bins", serde_json::json!(0), "noise.level_sources[0].bins"),
        (
            "/noise/level_sources/1/measured/relative_stderr",
            serde_json::json!(-0.1),
            "noise.level_sources[1].relative_stderr",
        ),
        // Continued from itself, from a coarser level, from a continued one.
        ("/noise/level_sources/2/continued/from", serde_json::json!(2), "noise.level_sources[2].from"),
        ("/noise/level_sources/2/continued/from", serde_json::json!(3), "noise.level_sources[2].from"),
        ("/noise/level_sources/3/continued/from", serde_json::json!(2), "noise.level_sources[3].from"),
    ];
    refused_naming_the_field(&good, cases);
    let mut v = good.clone();
    v["noise"]["level_sources"].as_array_mut().expect("array").pop();
    let err = CameraModel::from_json(&v.to_string()).expect_err("3 sources");
    assert!(err.to_string().contains("noise.level_sources"), "{err}");
}

/// Each bad value is rejected with an error naming its field.
#[test]
fn validation_names_the_field() {
    let good = serde_json::to_value(sample_model()).expect("serialises");
    let cases: Vec<(&str, serde_json::Value, &str)> = vec![
        ("/motion_blur/exposure", serde_json::json!(1.5), "motion_blur.exposure"),
        ("/motion_blur/exposure", serde_json::json!(-0.1), "motion_blur.exposure"),
        ("/schema", serde_json::json!("blind-augment/camera-model/0"), "schema"),
        ("/noise/luminance_range", serde_json::json!([0.8, 0.2]), "noise.luminance_range"),
        ("/depth_of_field/curve/k", serde_json::json!(-1.0), "depth_of_field.curve.k"),
        ("/depth_of_field/curve/focus_depth", serde_json::json!(0.0), "depth_of_field.curve.focus_depth"),
        ("/depth_of_field/depth_range", serde_json::json!([5.0, 0.3]), "depth_of_field.depth_range"),
        ("/reference/frame_interval_s", serde_json::json!(0.0), "reference.frame_interval_s"),
        ("/noise/levels/2/slope/1", serde_json::json!(5.0), "noise.levels[2]"),
    ];
    refused_naming_the_field(&good, cases);
    // Three levels (the official code's layout) is not this schema.
    let mut v = good.clone();
    v["noise"]["levels"].as_array_mut().expect("array").pop();
    assert!(CameraModel::from_json(&v.to_string()).expect_err("3 levels").to_string().contains("noise.levels"));
    // NaN/Inf cannot be written in JSON; overflowing literals are parse errors.
    let text = good.to_string().replace("0.4", "1e999");
    assert!(matches!(CameraModel::from_json(&text), Err(ModelError::Parse(_))));
    // Unknown fields are typos, not extensions.
    let mut v = good.clone();
    v["motion_blur"]["exposur"] = serde_json::json!(0.2);
    assert!(CameraModel::from_json(&v.to_string()).is_err());
}

#[test]
fn evaluation_clamps_to_the_fitted_range() {
    let m = sample_model();
    let d = &m.depth_of_field;
    assert_eq!(d.sigma_px(100.0), d.sigma_px(5.0));
    assert_eq!(d.sigma_px(0.01), d.sigma_px(0.3));
    assert_eq!(d.sigma_px(f32::NAN), 0.0);
    // The thin lens stays bounded where the quadratic would explode.
    let quad = DofCurve::Quadratic { a: 1.0, b: 0.0, c: 0.0 };
    assert_eq!(quad.sigma_px(DepthUnits::MetricM, 1e6), MAX_DOF_SIGMA_PX);
}

fn gradient(w: usize, h: usize) -> Rgb {
    let mut img = Rgb::new(w, h, [0.0; 3]);
    for c in 0..3 {
        for i in 0..w * h {
            img.channels[c][i] = ((i % w) as f32 / w as f32 + c as f32 * 0.1).min(1.0);
        }
    }
    img
}

#[test]
fn image_round_trips_keep_bit_depth_and_floats() {
    let img = gradient(37, 11);
    let p16 = tmp("g16.png");
    io::save_rgb(&p16, &img, BitDepth::Sixteen).expect("write 16-bit");
    let (back, depth) = io::load_rgb(&p16).expect("read");
    assert_eq!(depth, BitDepth::Sixteen);
    for (a, b) in back.channels[0].iter().zip(&img.channels[0]) {
        assert!((a - b).abs() <= 0.5 / 65535.0 + 1e-7);
    }
    let p8 = tmp("g8.png");
    io::save_rgb(&p8, &img, BitDepth::Eight).expect("write 8-bit");
    assert_eq!(io::load_rgb(&p8).expect("read").1, BitDepth::Eight);
    // Float formats: no clipping, no quantisation.
    let hdr = img.map(|v| v * 3.0 - 1.0);
    for name in ["f.npy", "f.pfm"] {
        let p = tmp(name);
        io::save_rgb(&p, &hdr, BitDepth::Float).expect("write float");
        let (back, depth) = io::load_rgb(&p).expect("read float");
        assert_eq!(depth, BitDepth::Float);
        assert_eq!(back, hdr, "{name}");
    }
}

#[test]
fn depth_and_flow_round_trips() {
    let mut depth = Plane::new(9, 4, 2.5);
    depth.data[3] = 0.75;
    for name in ["d.pfm", "d.npy"] {
        let p = tmp(name);
        io::save_depth(&p, &depth).expect("write");
        assert_eq!(io::load_depth(&p, 1.0).expect("read"), depth);
    }
    let mut flow = Flow::uniform(9, 4, 1.5, -2.0);
    flow.dx[5] = 7.25;
    for name in ["f.flo", "f2.npy"] {
        let p = tmp(name);
        io::save_flow(&p, &flow).expect("write");
        assert_eq!(io::load_flow(&p).expect("read"), flow);
    }
    // 16-bit PNG depth: scaled, 0 is invalid (NaN).
    let png = tmp("d16.png");
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(2, 1, vec![0u16, 1500]).expect("buf").save(&png).expect("save");
    let d = io::load_depth(&png, 0.001).expect("read");
    assert!(d.data[0].is_nan() && (d.data[1] - 1.5).abs() < 1e-6);
}

#[test]
fn bad_files_are_named_with_the_problem() {
    let missing = tmp("does_not_exist.png");
    let err = io::load_rgb(&missing).expect_err("missing");
    assert!(err.to_string().contains("does_not_exist.png"), "{err}");
    let trunc = tmp("trunc.flo");
    std::fs::write(&trunc, [0u8; 6]).expect("write");
    let err = io::load_flow(&trunc).expect_err("truncated");
    assert!(err.to_string().contains("trunc.flo") && err.to_string().contains("magic"), "{err}");
    let bad_pfm = tmp("bad.pfm");
    std::fs::write(&bad_pfm, b"PF\n4 4\n-1.0\n\x00\x00").expect("write");
    let err = io::load_depth(&bad_pfm, 1.0).expect_err("truncated pfm");
    assert!(err.to_string().contains("bad.pfm"), "{err}");
    let mut nan_flow = Flow::uniform(3, 3, 0.0, 0.0);
    nan_flow.dx[4] = f32::NAN;
    let p = tmp("nan.npy");
    io::save_flow(&p, &nan_flow).expect("write");
    let err = io::load_flow(&p).expect_err("nan");
    assert!(err.to_string().contains("non-finite flow at x=1, y=1"), "{err}");
    // Middlebury's unknown-flow marker (> 1e9): longer than any frame's diagonal.
    let mut unknown = Flow::uniform(4, 3, 0.5, 0.0);
    unknown.dy[6] = 1e10;
    let p = tmp("unknown.flo");
    io::save_flow(&p, &unknown).expect("write");
    let err = io::load_flow(&p).expect_err("unknown flow").to_string();
    assert!(err.contains("unknown.flo") && err.contains("x=2, y=1") && err.contains("diagonal"), "{err}");
    unknown.dy[6] = 4.9; // within the 5 px diagonal of a 4×3 frame
    io::save_flow(&p, &unknown).expect("write");
    assert_eq!(io::load_flow(&p).expect("within the diagonal"), unknown);
    let ext = tmp("depth.txt");
    std::fs::write(&ext, "1").expect("write");
    assert!(io::load_depth(&ext, 1.0).expect_err("ext").to_string().contains("unsupported depth format"));
}
