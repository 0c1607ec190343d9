//! The status panel end to end through the real Khronos loader on the project's
//! headless test runtime, both validation layers on (see tests/xr.rs for the
//! harness): the quad layer the app submits, the runtime's copy of its image, and
//! the runtime's composition of it.

#[path = "common/xr.rs"]
mod harness;

use blind_augment::worker::ModelChannel;
use harness::*;
use std::path::PathBuf;

/// The status panel: hidden until the left trigger shows it, then submitted every
/// frame as a quad layer in VIEW space over the projection layer, until pressed
/// again. The runtime's copy of the quad's image is the CPU drawing
/// (`panel::draw`) of exactly the lines the app reports for that frame (a buffer
/// copy: bit-exact), and those lines carry the app's status, the model's state and
/// the scene that failed to load; redrawn at ≤ 2 Hz; the quad shows in the
/// composite where it stands.
#[test]
fn status_panel_quad_shows_the_cpu_drawing_and_toggles() {
    use blind_augment::panel::{draw, PANEL_SIZE};
    let models = ModelChannel::new(model(0.4)).expect("model");
    let broken = tmp("panel-scenes").join("broken.glb");
    std::fs::write(&broken, b"glTF not really").expect("write");
    let broken = broken.display().to_string();
    let trigger = "/user/hand/left/input/trigger/value";
    let script = format!("press:/user/hand/right/input/thumbstick/click@3,press:{trigger}@10,press:{trigger}@60");
    let env = [
        ("BA_TEST_SCENES", broken.as_str()),
        ("BA_XR_SCRIPT", script.as_str()),
        ("BA_XR_PNG_DIR", "{dir}"),
        ("BA_XR_PNG_FRAMES", "5,40,70"),
    ];
    let Some(run) = run_xr("panel", &env, 80, true, &models) else { return };
    assert_clean(&run, true);
    let s = &run.summary;
    assert!(s.panel, "the panel's swapchain and VIEW space were made");
    let frames = frames_of(&run.report);
    let quads: Vec<bool> =
        frames.iter().map(|f| f["layers"].as_array().unwrap().iter().any(|l| l["type"] == "quad")).collect();
    let shown: Vec<usize> = (0..quads.len()).filter(|&k| quads[k]).collect();
    assert!(!shown.is_empty(), "no quad layer submitted");
    let (first, last) = (shown[0], *shown.last().unwrap());
    assert_eq!(shown.len(), last - first + 1, "shown from one press to the next, every frame: {shown:?}");
    assert!((10..=12).contains(&first) && (59..=61).contains(&last), "shown over frames {first}..={last}");
    // The quad is the last layer (over the projection), head-locked, 2:1.
    let quad = frames[40]["layers"].as_array().unwrap().last().unwrap().clone();
    assert_eq!(quad["type"], "quad");
    assert_eq!(quad["space"], "View");
    assert_eq!(quad["rect"], serde_json::json!([0, 0, PANEL_SIZE.0, PANEL_SIZE.1]));
    let size = quad["size_m"].as_array().unwrap();
    assert!((size[0].as_f64().unwrap() - 2.0 * size[1].as_f64().unwrap()).abs() < 1e-6);
    // The records say which lines each frame's quad shows.
    let display = |f: &serde_json::Value| f["display_time_ns"].as_i64().unwrap();
    let record_at = |k: usize| run.records.iter().find(|r| r.predicted_display_time_ns == display(frames[k]));
    for k in [5, 70] {
        assert!(record_at(k).expect("record").panel.is_none(), "frame {k}: hidden");
    }
    let lines = record_at(40).expect("record of frame 40").panel.clone().expect("frame 40 shows the panel");
    let text = lines.join("\n");
    for want in
        ["test status line", "model generation 0", "motion blur: ", "depth of field: ", "matched (A)", "broken.glb"]
    {
        assert!(text.contains(want), "{want:?} not on the panel:\n{text}");
    }
    // The composite check below reads the card's lower band (texture rows ≈ 334–
    // 499), which stays free of text while the panel has at most 8 lines.
    assert!(lines.len() <= 8, "{} lines: move the composite check's rows", lines.len());
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xr/panel");
    let submitted = image::open(dir.join("frame_0040_quad1.png")).expect("the runtime's quad PNG").to_rgba8();
    assert_eq!(submitted.dimensions(), PANEL_SIZE);
    let expected = draw(&lines, PANEL_SIZE.0, PANEL_SIZE.1);
    let differ = submitted.as_raw().iter().zip(&expected).filter(|(a, b)| a != b).count();
    assert_eq!(differ, 0, "the quad's image is not the CPU drawing of its lines ({differ} bytes differ)");
    // Composed where it stands: the card's text-free lower band lands (the geometry
    // of `xr::panel`: 0.9 m ahead, 0.15 m down, 0.5 m wide; each eye half the IPD
    // aside) on eye 0's pixels x 52..70 and eye 1's x 26..44, rows 52..56 of the 96²
    // eye. There the composite must be the card (straight alpha 215/255, colour
    // 18/20/26) over the projection layer as submitted over the passthrough image,
    // in linear light (spec "Composition Layer Blending", both layers with
    // UNPREMULTIPLIED_ALPHA), to ±1 level (the PNGs are rounded to 8 bits).
    let lin = |v: u8| {
        let v = v as f32 / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let enc = |v: f32| -> f32 {
        let v = v.clamp(0.0, 1.0);
        255.0 * if v <= 0.0031308 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 }
    };
    let (card, alpha) = ([18u8, 20, 26], 215.0 / 255.0);
    for (eye, xs) in [(0, 52..71u32), (1, 26..45u32)] {
        let png = |suffix: &str| {
            let p = dir.join(format!("frame_0040_eye{eye}{suffix}.png"));
            image::open(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display())).to_rgba8()
        };
        let (shown, layer, world) = (png("_composited"), png(""), png("_passthrough"));
        for y in 52..57u32 {
            for x in xs.clone() {
                let (got, p, w) = (shown.get_pixel(x, y).0, layer.get_pixel(x, y).0, world.get_pixel(x, y).0);
                let a_p = p[3] as f32 / 255.0;
                for c in 0..3 {
                    let under = lin(p[c]) * a_p + lin(w[c]) * (1.0 - a_p);
                    let want = enc(alpha * lin(card[c]) + (1.0 - alpha) * under);
                    assert!(
                        (got[c] as f32 - want).abs() <= 1.0,
                        "eye {eye} ({x}, {y}) channel {c}: {} composed, the card over layer {p:?} over {w:?} is {want:.1}",
                        got[c]
                    );
                }
            }
        }
    }
    // ≤ 2 Hz: at 90 Hz for ~50 frames shown, one or two redraws.
    assert!((1..=3).contains(&s.panel_redraws), "{} redraws", s.panel_redraws);
}
