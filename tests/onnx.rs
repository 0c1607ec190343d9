//! The ONNX providers (`analysis::onnx`): the shipped, project-trained denoiser is
//! loaded and checked (CI never trains); what it is worth to the noise fit is
//! measured against the single-frame blind fit; contract-breaking, truncated and
//! corrupt files are refused by name; the depth and flow runners are held to
//! exact answers with small graphs built here; the drop-in path (`--onnx`) runs
//! end to end through `fit` and `calibrate`.

#[path = "common/mod.rs"]
mod common;

use blind_augment::analysis::onnx::{OnnxDenoiser, OnnxDepth, OnnxError, OnnxFlow, OnnxModel};
use blind_augment::analysis::{Analysed, Denoiser, DepthProvider, FlowProvider, Frame, FrameContext, Role};
use blind_augment::fit::{fit, FitInputs, FitOptions, Tier};
use blind_augment::image::{Plane, Rgb};
use blind_augment::model::{DepthUnits, Noise};
use blind_augment::synth::white_sensor_noise;
use prost::Message;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tract_onnx::pb;

fn shipped() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/models/denoise.onnx")
}

fn tmp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("onnx");
    std::fs::create_dir_all(&d).expect("tmp dir");
    d.join(name)
}

fn analysed(index: u64, t_s: f64, image: Rgb) -> Analysed {
    Analysed {
        frame: Frame { index, t_s, image, depth: None, flow: None },
        depth: None,
        world_from_camera: None,
        sparse_flow: None,
    }
}

fn ctx<'a>(a: &'a Analysed, window: &'a [Arc<Analysed>]) -> FrameContext<'a> {
    FrameContext { current: a, window, poses: None, intrinsics: None, frame_interval_s: 1.0 / 30.0 }
}

/// The test noise: white Poisson–Gaussian, level-0 std ≈ 0.01 at mid grey.
fn noise() -> Noise {
    white_sensor_noise([4e-5, 3e-5, 6e-5], [4e-4, 3e-4, 6e-4], [0.0, 1.0])
}

fn psnr(a: &Rgb, b: &Rgb, valid: &Plane) -> f64 {
    let (mut se, mut n) = (0.0f64, 0usize);
    for c in 0..3 {
        for i in 0..a.len() {
            if valid.data[i] > 0.5 {
                se += (a.channels[c][i] as f64 - b.channels[c][i] as f64).powi(2);
                n += 1;
            }
        }
    }
    10.0 * (1.0 / (se / n.max(1) as f64)).log10()
}

/// The committed model loads under the `denoise` contract at the size its record
/// (`denoise.json`, written by `cargo xtask train-models`) states.
#[test]
fn shipped_denoiser_meets_its_contract() {
    let m = OnnxModel::load(Role::Denoise, &shipped(), None).expect("shipped denoiser loads");
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(shipped().with_extension("json")).expect("denoise.json"))
            .expect("denoise.json parses");
    assert_eq!(record["role"], "denoise");
    assert_eq!(record["input"]["name"], "noisy");
    assert_eq!(record["output"]["name"], "clean");
    let shape: Vec<usize> = serde_json::from_value(record["input"]["shape"].clone()).expect("shape");
    assert_eq!(shape, vec![1, 3, m.hw.0, m.hw.1]);
    assert_eq!(m.output, "clean");
}

/// On a photograph it never saw (the cat; trained on the Motorcycle and the
/// astronaut), with the project's noise model: the denoised frame is closer to
/// the clean one. Training measured +3.6 dB on 64-px validation crops of this
/// photograph; 2 dB leaves room for the whole-frame tiling and 8-bit-free input.
#[test]
fn shipped_denoiser_denoises_a_held_out_photograph() {
    let clean = common::photo("chelsea.png");
    let noisy = blind_augment::synth::add_noise(&clean, &noise(), 11);
    let mut d = OnnxDenoiser::new(OnnxModel::load(Role::Denoise, &shipped(), None).expect("loads"));
    let a = analysed(0, 0.0, noisy.clone());
    let r = d.denoise(&ctx(&a, &[])).expect("denoises");
    let valid = r.valid.clone().expect("network references say where they hold");
    let covered = valid.data.iter().filter(|&&v| v > 0.5).count() as f64 / valid.data.len() as f64;
    // A 451×300 frame is done whole (≤ max_pixels); only the 8-px tile margin at the
    // frame border is left out: (435·284)/(451·300) = 0.913.
    assert!(covered > 0.9, "covered {covered}");
    let (before, after) = (psnr(&noisy, &clean, &valid), psnr(&r.image, &clean, &valid));
    eprintln!("chelsea: PSNR {before:.2} dB noisy → {after:.2} dB denoised");
    assert!(after > before + 2.0, "PSNR {before:.2} → {after:.2}");
}

/// Larger frames are denoised in sample regions, not whole: at 1280×960 the
/// regions stay within the pixel budget and each holds a low-pass footprint.
#[test]
fn large_frames_are_denoised_in_regions() {
    let d = OnnxDenoiser::new(OnnxModel::load(Role::Denoise, &shipped(), None).expect("loads"));
    let regions = d.regions(1280, 960);
    let px: usize = regions.iter().map(|r| r.width * r.height).sum();
    assert!(regions.len() >= 4 && px <= d.max_pixels, "{} regions, {px} px", regions.len());
    for r in &regions {
        assert!(r.x0 + r.width <= 1280 && r.y0 + r.height <= 960);
        // Low-pass footprint: 2·(5·16 + 8) + 1 = 177 px, inside the valid interior.
        assert!(r.width - 16 >= 177 && r.height - 16 >= 177, "{r:?}");
    }
}

/// Per-level relative error of the level-0..3 stds (median over R/G/B and luma
/// 0.2…0.8), as `model::compare` states the headline.
fn level_errors(fit: &Noise, truth: &Noise) -> Vec<f32> {
    (0..4)
        .map(|l| {
            let mut e: Vec<f32> = vec![];
            for c in 0..3 {
                for y in [0.2f32, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8] {
                    let yf = y.clamp(fit.luminance_range[0], fit.luminance_range[1]);
                    let (sf, st) = (fit.levels[l].std(fit.form, c, yf), truth.levels[l].std(truth.form, c, y));
                    e.push((sf / st - 1.0).abs());
                }
            }
            e.sort_by(f32::total_cmp);
            e[e.len() / 2]
        })
        .collect()
}

/// What the network is worth to the noise fit, measured on one frame of each
/// photograph (the 8-bit quantisation a PNG frame has included) against the
/// single-frame blind fit — the comparison BENCHMARKS.md reports. Measured: level
/// 0 off by 22–28% (blind: 12%), levels 1–3 by 47–80% (blind: 12%; temporal
/// references in the worker: 2–6%): the 5-layer network leaves about half of the
/// noise variance in its output (`val_median_residual_variance_ratio` 0.47), and
/// with an 11-px receptive field none of the coarse levels' noise. So the worker
/// keeps the temporal reference for the accurate tier; the network path is there
/// for stronger drop-in denoisers. Asserted, as a regression bound on the
/// plumbing (a channel-order or tiling bug reads ~100% off): level 0 within 35%
/// on both photographs, levels 1–3 within 90%.
#[test]
fn network_reference_in_the_noise_fit() {
    let truth = noise();
    let mut d = OnnxDenoiser::new(OnnxModel::load(Role::Denoise, &shipped(), None).expect("loads"));
    let (mut net0, mut blind0) = (vec![], vec![]);
    for name in ["chelsea.png", "astronaut.png"] {
        let clean = common::photo(name);
        let noisy =
            blind_augment::synth::add_noise(&clean, &truth, 5).map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
        let a = analysed(0, 0.0, noisy.clone());
        let r = d.denoise(&ctx(&a, &[])).expect("denoises");
        let only_noise = blind_augment::fit::Effects { noise: true, motion_blur: false, depth_of_field: false };
        let mut inp = FitInputs::new(&noisy);
        inp.denoised = Some(&r.image);
        inp.reference_valid = r.valid.as_ref();
        let net = fit(&inp, &FitOptions { tier: Some(Tier::Accurate), effects: only_noise, ..Default::default() })
            .expect("fit with the network's reference");
        let blind = fit(
            &FitInputs::new(&noisy),
            &FitOptions { tier: Some(Tier::Fast), effects: only_noise, ..Default::default() },
        )
        .expect("blind fit");
        let (en, eb) = (level_errors(&net.model.noise, &truth), level_errors(&blind.model.noise, &truth));
        eprintln!("{name}: per-level error, network reference {en:.3?}, blind {eb:.3?}");
        net0.push(en[0]);
        blind0.push(eb[0]);
        assert!(en[1..].iter().all(|&e| e < 0.9), "{name}: network levels 1–3 {en:?}");
    }
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    assert!(net0.iter().all(|&e| e < 0.35), "network level-0 errors {net0:?}");
    eprintln!("level 0 mean error: network {:.3}, blind {:.3}", mean(&net0), mean(&blind0));
}

// ---- contract enforcement ----------------------------------------------------

fn expect_contract_error(r: Result<OnnxModel, OnnxError>, path: &Path, needle: &str) {
    match r {
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains(&path.display().to_string()), "error does not name the file: {msg}");
            assert!(msg.contains(needle), "error does not say `{needle}`: {msg}");
        }
        Ok(m) => panic!("{} was accepted as {:?}", path.display(), m.role),
    }
}

#[test]
fn a_model_loaded_for_the_wrong_role_is_refused() {
    let p = shipped();
    expect_contract_error(OnnxModel::load(Role::Depth, &p, None), &p, "inputs are [\"noisy\"]");
    expect_contract_error(OnnxModel::load(Role::Flow, &p, None), &p, "the contract wants [\"frame0\", \"frame1\"]");
    expect_contract_error(OnnxModel::load(Role::MotionDeblur, &p, None), &p, "`motion-deblur` contract");
}

#[test]
fn truncated_missing_and_corrupt_files_are_refused() {
    let bytes = std::fs::read(shipped()).expect("shipped model");
    let cut = tmp("truncated.onnx");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
    expect_contract_error(OnnxModel::load(Role::Denoise, &cut, None), &cut, "not a readable ONNX model");
    let junk = tmp("junk.onnx");
    std::fs::write(&junk, b"this is not protobuf at all \xff\xfe").expect("write");
    expect_contract_error(OnnxModel::load(Role::Denoise, &junk, None), &junk, "not a readable ONNX model");
    let missing = tmp("missing.onnx");
    expect_contract_error(OnnxModel::load(Role::Denoise, &missing, None), &missing, "cannot read");
}

/// The shipped graph, edited: each edit breaks one clause of the contract.
#[test]
fn each_contract_clause_is_checked() {
    let proto = pb::ModelProto::decode(&std::fs::read(shipped()).expect("read")[..]).expect("decodes");
    let write = |name: &str, edit: &dyn Fn(&mut pb::GraphProto)| -> PathBuf {
        let mut m = proto.clone();
        edit(m.graph.as_mut().expect("graph"));
        let p = tmp(name);
        std::fs::write(&p, m.encode_to_vec()).expect("write");
        p
    };
    let set_dim = |v: &mut pb::ValueInfoProto, axis: usize, n: i64| {
        if let Some(pb::type_proto::Value::TensorType(t)) = v.r#type.as_mut().and_then(|t| t.value.as_mut()) {
            t.shape.as_mut().expect("shape").dim[axis].value =
                Some(pb::tensor_shape_proto::dimension::Value::DimValue(n));
        }
    };
    let p = write("renamed_output.onnx", &|g| g.output[0].name = "denoised".into());
    expect_contract_error(OnnxModel::load(Role::Denoise, &p, None), &p, "outputs are [\"denoised\"]");
    let p = write("four_channels.onnx", &|g| set_dim(&mut g.input[0], 1, 4));
    expect_contract_error(OnnxModel::load(Role::Denoise, &p, None), &p, "the contract wants [1,3,H,W]");
    let p = write("batch_two.onnx", &|g| set_dim(&mut g.input[0], 0, 2));
    expect_contract_error(OnnxModel::load(Role::Denoise, &p, None), &p, "[2,3,128,128]");
    let p = write("int_input.onnx", &|g| {
        if let Some(pb::type_proto::Value::TensorType(t)) = g.input[0].r#type.as_mut().and_then(|t| t.value.as_mut()) {
            t.elem_type = 7; // INT64
        }
    });
    expect_contract_error(OnnxModel::load(Role::Denoise, &p, None), &p, "not float32");
    let p = write("no_graph_outputs.onnx", &|g| g.output.clear());
    expect_contract_error(OnnxModel::load(Role::Denoise, &p, None), &p, "outputs are []");
}

// ---- depth and flow runners, on graphs with known answers ----------------------

fn tensor(name: &str, dims: &[i64], vals: &[f32]) -> pb::TensorProto {
    pb::TensorProto {
        name: name.into(),
        dims: dims.to_vec(),
        data_type: 1,
        float_data: vals.to_vec(),
        ..Default::default()
    }
}

fn value(name: &str, dims: &[i64]) -> pb::ValueInfoProto {
    use pb::tensor_shape_proto::{dimension::Value, Dimension};
    pb::ValueInfoProto {
        name: name.into(),
        r#type: Some(pb::TypeProto {
            value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                elem_type: 1,
                shape: Some(pb::TensorShapeProto {
                    dim: dims
                        .iter()
                        .map(|&d| Dimension { value: Some(Value::DimValue(d)), ..Default::default() })
                        .collect(),
                }),
            })),
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// A one-node graph: a 1×1 convolution (weights [out, in, 1, 1], bias) of the
/// inputs, concatenated along channels when there are two.
fn conv_model(inputs: &[&str], output: &str, hw: i64, weights: &[f32], bias: &[f32]) -> Vec<u8> {
    let out_c = bias.len() as i64;
    let in_c = 3 * inputs.len() as i64;
    let mut nodes = vec![];
    let conv_in = if inputs.len() > 1 {
        nodes.push(pb::NodeProto {
            op_type: "Concat".into(),
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec!["cat".into()],
            attribute: vec![pb::AttributeProto { name: "axis".into(), r#type: 2, i: 1, ..Default::default() }],
            ..Default::default()
        });
        "cat".to_string()
    } else {
        inputs[0].to_string()
    };
    nodes.push(pb::NodeProto {
        op_type: "Conv".into(),
        input: vec![conv_in, "w".into(), "b".into()],
        output: vec![output.into()],
        ..Default::default()
    });
    let graph = pb::GraphProto {
        name: "test".into(),
        node: nodes,
        initializer: vec![tensor("w", &[out_c, in_c, 1, 1], weights), tensor("b", &[out_c], bias)],
        input: inputs.iter().map(|n| value(n, &[1, 3, hw, hw])).collect(),
        output: vec![value(output, &[1, out_c, hw, hw])],
        ..Default::default()
    };
    pb::ModelProto {
        ir_version: 8,
        opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 17 }],
        graph: Some(graph),
        ..Default::default()
    }
    .encode_to_vec()
}

/// Depth `depth` = 1 + R + 2G (metres) at 32×32, run on a 96×64 frame whose colour
/// is a smooth ramp: the runner resizes in and out, so the result is the formula
/// up to bilinear resampling of a linear ramp (exact away from the border; 1e-4).
#[test]
fn depth_runner_resizes_and_keeps_units() {
    let p = tmp("depth.onnx");
    std::fs::write(&p, conv_model(&["image"], "depth", 32, &[1.0, 2.0, 0.0], &[1.0])).expect("write");
    let mut d = OnnxDepth { model: OnnxModel::load(Role::Depth, &p, None).expect("loads") };
    let (w, h) = (96usize, 64usize);
    let img = Rgb::from_planes([
        Plane::from_vec(w, h, (0..w * h).map(|i| (i % w) as f32 / w as f32).collect()),
        Plane::from_vec(w, h, (0..w * h).map(|i| (i / w) as f32 / h as f32).collect()),
        Plane::new(w, h, 0.3),
    ]);
    let a = analysed(0, 0.0, img.clone());
    let out = d.depth(&ctx(&a, &[])).expect("depth");
    assert_eq!(out.units, DepthUnits::MetricM);
    for y in 8..h - 8 {
        for x in 8..w - 8 {
            let i = y * w + x;
            let want = 1.0 + img.channels[0][i] + 2.0 * img.channels[1][i];
            assert!((out.depth.data[i] - want).abs() < 1e-4, "({x},{y}): {} vs {want}", out.depth.data[i]);
        }
    }
    // Relative inverse depth is recognised by the output's name.
    let p = tmp("inverse_depth.onnx");
    std::fs::write(&p, conv_model(&["image"], "inverse_depth", 32, &[0.0, 0.0, 1.0], &[0.0])).expect("write");
    let mut d = OnnxDepth { model: OnnxModel::load(Role::Depth, &p, None).expect("loads") };
    assert_eq!(d.depth(&ctx(&a, &[])).expect("depth").units, DepthUnits::RelativeInverse);
    // Metric depth ≤ 0 is a failure of the model, not a depth.
    let p = tmp("negative_depth.onnx");
    std::fs::write(&p, conv_model(&["image"], "depth", 32, &[0.0, 0.0, 0.0], &[-1.0])).expect("write");
    let mut d = OnnxDepth { model: OnnxModel::load(Role::Depth, &p, None).expect("loads") };
    let e = d.depth(&ctx(&a, &[])).expect_err("negative metric depth refused").to_string();
    assert!(e.contains("≤ 0 m") && e.contains("negative_depth.onnx"), "{e}");
}

/// Flow = (4, −2) px of a 32×32 input between frame0 and frame1 (the bias), frames
/// 2 intervals apart, a 128×96 frame: the runner reports (4·128/32/2, −2·96/32/2)
/// = (8, −3) px per frame interval everywhere (exact: constants survive resizing).
#[test]
fn flow_runner_rescales_to_frame_pixels_per_interval() {
    let p = tmp("flow.onnx");
    std::fs::write(&p, conv_model(&["frame0", "frame1"], "flow", 32, &[0.0; 12], &[4.0, -2.0])).expect("write");
    let mut f = OnnxFlow { model: OnnxModel::load(Role::Flow, &p, None).expect("loads") };
    let img = Rgb::new(128, 96, [0.5; 3]);
    let prev = Arc::new(analysed(0, 0.0, img.clone()));
    let cur = analysed(2, 2.0 / 30.0, img);
    let window = [prev];
    let flow = f.flow(&ctx(&cur, &window)).expect("flow");
    assert!(flow.dx.iter().all(|&v| (v - 8.0).abs() < 1e-5) && flow.dy.iter().all(|&v| (v + 3.0).abs() < 1e-5));
    // No previous frame: unavailable (the worker falls back to Lucas–Kanade).
    let e = f.flow(&ctx(&cur, &[])).expect_err("needs a previous frame").to_string();
    assert!(e.contains("no previous frame"), "{e}");
}

// ---- the drop-in path through the CLI ------------------------------------------

fn bin(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_blind-augment")).args(args).output().expect("the binary runs")
}

#[test]
fn cli_fit_and_calibrate_take_onnx_models() {
    let dir = tmp("cli");
    let _ = std::fs::remove_dir_all(&dir);
    let d = dir.display().to_string();
    let out = bin(&["synth-video", "--out", &d, "--frames", "24", "--size", "320x240"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let model = shipped().display().to_string();
    let onnx = format!("denoise={model}");
    let frame = format!("{d}/frames/{}", {
        let mut v: Vec<_> =
            std::fs::read_dir(dir.join("frames")).expect("frames").flatten().map(|e| e.file_name()).collect();
        v.sort();
        v[10].to_string_lossy().to_string()
    });
    let cam = format!("{d}/fit.json");
    let out = bin(&["fit", "--image", &frame, "--only", "noise", "--onnx", &onnx, "--out", &cam]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("denoise provider"), "{err}");
    let m =
        blind_augment::model::CameraModel::from_json(&std::fs::read_to_string(&cam).expect("written")).expect("valid");
    // The network's reference turns on the accurate noise fit.
    assert!(m.noise.present && m.noise.diagnostics.method == "accurate", "{:?}", m.noise.diagnostics);

    let cal = format!("{d}/cal.json");
    let out = bin(&[
        "calibrate",
        "--frames",
        &format!("{d}/frames"),
        "--depth",
        &format!("{d}/depth"),
        "--poses",
        &format!("{d}/poses.csv"),
        "--intrinsics",
        std::fs::read_to_string(dir.join("intrinsics.txt")).expect("intrinsics").trim(),
        "--onnx",
        &onnx,
        "--only",
        "noise",
        "--out",
        &cal,
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let m =
        blind_augment::model::CameraModel::from_json(&std::fs::read_to_string(&cal).expect("written")).expect("valid");
    assert!(m.noise.present, "{:?}", m.noise.diagnostics);

    // Bad flags: each refused with the flag and the problem named.
    for (args, needle) in [
        (vec!["--onnx", "sharpen=x.onnx"], "unknown role `sharpen`"),
        (vec!["--onnx", "denoise"], "expected ROLE=PATH"),
        (vec!["--onnx", &onnx, "--onnx", &onnx], "given twice"),
        (vec!["--onnx", "flow=x.onnx"], "needs consecutive frames"),
        (vec!["--onnx", "depth=/nonexistent.onnx"], "/nonexistent.onnx: cannot read"),
        (vec!["--onnx", &format!("depth={model}")], "breaks the `depth` contract"),
    ] {
        let mut a = vec!["fit", "--image", &frame, "--out", &cam];
        a.extend(args.iter().copied());
        let out = bin(&a);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(needle), "{a:?}: {err}");
    }
}
