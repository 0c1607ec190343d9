//! Desktop parity of the headset's live calibration: `blind-augment xr
//! --camera-frames` feeds a synthesised sequence to the calibration worker as the
//! camera would, through the real OpenXR loader and the test runtime, records what
//! the worker takes, and `calibrate` on the recording reproduces the models
//! published live.

#[path = "common/xr.rs"]
mod harness;

use blind_augment::io::recording::{Manifest, StopReason};
use blind_augment::model::CameraModel;
use harness::*;
use std::path::Path;

fn cli() -> std::process::Command {
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_blind-augment"));
    for v in VARS {
        cmd.env_remove(v);
    }
    cmd
}

fn run(cmd: &mut std::process::Command) -> (bool, String) {
    let out = cmd.output().expect("binary runs");
    (out.status.success(), format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)))
}

/// (frame, model as JSON) per line; each model must load (validated).
fn timeline(path: &Path) -> Vec<(u64, serde_json::Value)> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).expect("timeline line");
            CameraModel::from_json(&v["model"].to_string()).expect("timeline model");
            (v["frame"].as_u64().expect("frame number"), v["model"].clone())
        })
        .collect()
}

/// synth-video → `xr --camera-frames … --record` (live worker, real time, frames
/// skipped while it is busy: at 640×480 on two cores about half) → `calibrate` on
/// the recording as its manifest says: the same frames publish the same models.
#[test]
fn a_desktop_recording_replays_the_live_calibration() {
    let Some(manifest) = manifest() else { return };
    let _guard = serial();
    let dir = tmp("recording");
    let seq = dir.join("seq");
    let (ok, text) = run(cli().args(["synth-video", "--out"]).arg(&seq).args(["--frames", "36", "--size", "640x480"]));
    assert!(ok, "{text}");
    let k = std::fs::read_to_string(seq.join("intrinsics.txt")).expect("intrinsics");
    let rec = dir.join("rec");
    let (ok, text) = run(cli()
        .args(["xr", "--camera-frames"])
        .arg(seq.join("frames"))
        .arg("--poses")
        .arg(seq.join("poses.csv"))
        .args(["--intrinsics", k.trim(), "--depth"])
        .arg(seq.join("depth"))
        .args(["--tier", "fast", "--record-s", "100", "--record-min-free-mib", "0", "--panel", "--record"])
        .arg(&rec)
        .env("XR_RUNTIME_JSON", &manifest)
        .env("BA_XR_EYE_SIZE", "64x64"));
    if !ok && !required() && text.contains("Vulkan") {
        eprintln!("skipping: {text}");
        return;
    }
    assert!(ok, "{text}");
    assert!(text.contains("ended: Exited"), "the loop ended when the frames did:\n{text}");
    assert!(text.contains("camera frames: 36 offered"), "{text}");
    // The status panel (shown from the start) carried the feed's and the model's
    // state as the frames went by.
    let panel: Vec<&str> = text.lines().filter_map(|l| l.strip_prefix("  | ")).collect();
    for want in ["fast tier · camera ", "recording into rec", "model generation ", "motion blur: "] {
        assert!(panel.iter().any(|l| l.contains(want)), "{want:?} not on the panel's last drawing: {panel:#?}");
    }
    let m: Manifest =
        serde_json::from_str(&std::fs::read_to_string(rec.join("manifest.json")).expect("manifest")).expect("manifest");
    assert_eq!(m.stopped, StopReason::Stopped);
    // The low-priority worker takes the first frame and then whichever frames come
    // while it is idle: how many depends on the CPU it gets (on a quiet two-core
    // machine about half; with two other jobs busy on both cores its first fit
    // outlasted the 1.2 s feed and it took that frame alone). What must hold
    // whatever it took: the replay below reproduces it.
    assert!(m.frames >= 1, "the worker took no frame");
    assert_eq!(m.frames_with_depth, m.frames);
    assert!(m.poses_csv, "{:?}", m.notes);
    assert!(m.models_published >= 1, "{m:?}");
    // Replay exactly as the manifest says, from inside the recording.
    let args: Vec<&str> = m.calibrate.split_whitespace().skip(1).collect();
    let (ok, text) = run(cli().args(&args).current_dir(&rec));
    assert!(ok, "{} → {text}", m.calibrate);
    let live = timeline(&rec.join("timeline.jsonl"));
    let replay = timeline(&rec.join("replay.jsonl"));
    let frames = |t: &[(u64, serde_json::Value)]| t.iter().map(|e| e.0).collect::<Vec<_>>();
    // The same frames reach the calibrator in the same order with the same content
    // and the same pose track (pose_track.csv), so the same frames publish the
    // same models. Tolerance: 1e-4 relative (+1e-7 absolute) on every number —
    // the live timeline is written from f64 copies of f32 values, the replay's
    // from f32, and the two run on different thread pools (summation order);
    // anything the inputs change moves λ by 1e-3 or more (one pose per recorded
    // frame instead of the track: 0.007).
    assert_eq!(frames(&live), frames(&replay), "frames publishing live vs replayed");
    for ((f, a), (_, b)) in live.iter().zip(&replay) {
        same(a, b, &format!("frame {f}"));
    }
    eprintln!("{} frames recorded of 36 offered; {} models replayed equal", m.frames, live.len());
}

/// Every field of two models equal: strings exactly, numbers within 1e-4
/// relative + 1e-7; wall times and the free-text reasons (they quote times) left out.
fn same(a: &serde_json::Value, b: &serde_json::Value, at: &str) {
    use serde_json::Value as V;
    match (a, b) {
        (V::Object(x), V::Object(y)) => {
            let keys = |o: &serde_json::Map<String, V>| {
                o.keys()
                    .filter(|k| !["fit_time_s", "stages_s", "reason"].contains(&k.as_str()))
                    .cloned()
                    .collect::<Vec<_>>()
            };
            let (mut kx, mut ky) = (keys(x), keys(y));
            kx.sort();
            ky.sort();
            assert_eq!(kx, ky, "{at}: fields");
            for k in kx {
                same(&x[&k], &y[&k], &format!("{at}.{k}"));
            }
        }
        (V::Array(x), V::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}: lengths");
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                same(p, q, &format!("{at}[{i}]"));
            }
        }
        (V::Number(x), V::Number(y)) => {
            let (x, y) = (x.as_f64().expect("number"), y.as_f64().expect("number"));
            assert!((x - y).abs() <= 1e-4 * x.abs().max(y.abs()) + 1e-7, "{at}: live {x}, replayed {y}");
        }
        _ => assert_eq!(a, b, "{at}"),
    }
}

/// `--record` without `--camera-frames`, and a recording folder that already
/// holds one, are refused by name before the loop starts.
#[test]
fn recording_arguments_are_checked() {
    let dir = tmp("recording_args");
    let (ok, text) = run(cli().args(["xr", "--record"]).arg(dir.join("r")));
    assert!(!ok);
    assert!(text.contains("--camera-frames"), "{text}");
    let seq = dir.join("seq");
    let (ok, text) = run(cli().args(["synth-video", "--out"]).arg(&seq).args(["--frames", "3", "--size", "64x48"]));
    assert!(ok, "{text}");
    let busy = dir.join("busy");
    std::fs::create_dir_all(busy.join("frames")).expect("dir");
    let (ok, text) = run(cli().args(["xr", "--camera-frames"]).arg(seq.join("frames")).arg("--record").arg(&busy));
    assert!(!ok);
    assert!(text.contains("already holds a recording"), "{text}");
    assert!(!text.contains("panicked"), "{text}");
}
