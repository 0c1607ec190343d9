//! Calibration on real scenes made elsewhere, the subset CI runs: three tuning-split
//! scenes of `cargo xtask bench-quality` from three public sources, vendored in
//! `tests/data/scenes/` (photograph and measured depth; `tests/data/ATTRIBUTION.md`),
//! each re-rendered along a head path with rests and turns by a known camera that
//! changes mid-run (`common::scenes::spec_for`: λ ×2 and noise std ×1.6 at 2.75 s),
//! run through the worker and held against the truth over the publications outside
//! the settling seconds (`common::scenes::run`). The held-out split is never vendored.

mod common;

use blind_augment::worker::CalibrationTier;
use common::scenes::{entry, run, spec_for, Entry, RunResult};

/// The vendored scenes: id, source, photograph, depth, its encoding, focal length
/// (px of the photograph), as `xtask/src/scenes.rs` lists them.
fn scenes() -> Vec<Entry> {
    let dir = |f: &str| common::data(&format!("scenes/{f}")).to_string_lossy().into_owned();
    [
        (
            "middlebury2006-Aloe",
            "ibergonzani/patch-match-stereo@d5717d5",
            "middlebury2006-Aloe/view1.png",
            "middlebury2006-Aloe/disp1.png",
            // Third size: d = value / 3, f = 3740 / 3 px, B = 160 mm, offset 230 / 3 px.
            "disparity:3:0.16:76.666664",
            3740.0f32 / 3.0,
        ),
        (
            "middlebury2005-Art",
            "PRiME-project/PRiMEStereoMatch@3a28bb6",
            "middlebury2005-Art/view1.png",
            "middlebury2005-Art/disp1.png",
            // Its dmin.txt: 200 full-size px.
            "disparity:3:0.16:66.666664",
            3740.0 / 3.0,
        ),
        ("tum-rgbd", "mikiec84/Open3D@879b6fc", "tum-rgbd/TUM_color.png", "tum-rgbd/TUM_depth.png", "tum", 525.0),
    ]
    .into_iter()
    .map(|(id, source, image, depth, read, focal)| {
        entry(id, false, source, &dir(image), &dir(depth), read, focal).unwrap_or_else(|e| panic!("{id}: {e}"))
    })
    .collect()
}

/// Per scene and tier, the targets for the held-out split, held here on the
/// tuning subset (measured values in brackets, VM, 2026-12-07):
/// * λ: the fast tier within 0.05 (0.004 / 0.011 / 0.012); the accurate tier each
///   within 0.02, its p90 target, and their median within 0.01 (0.002 / 0.013 /
///   0.004; with one λ fit per 0.25 s instead of one per moving update, Art 0.040);
/// * noise (median relative error of the published level stds): fast within 15%
///   (3.9 / 1.5 / 2.0%), accurate within 3% (1.6 / 1.1 / 1.6%);
/// * the change followed within 1 s of the first frame that can show it (0.03–0.07 s);
/// * motion blur never dropped after it is first published (no flicker over rests).
#[test]
fn real_scenes_calibrate_within_stated_tolerances() {
    let entries = scenes();
    // The scenes in parallel (each run is one worker on one thread of its own).
    let results: Vec<Vec<(CalibrationTier, RunResult)>> = std::thread::scope(|s| {
        let handles: Vec<_> = entries
            .iter()
            .map(|e| {
                s.spawn(move || {
                    let spec = spec_for(&e.scene, e.k);
                    [CalibrationTier::Fast, CalibrationTier::Accurate]
                        .into_iter()
                        .map(|tier| (tier, run(e, &spec, tier)))
                        .collect()
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("scene run")).collect()
    });
    let mut accurate_lambda = vec![];
    for (e, runs) in entries.iter().zip(&results) {
        for (tier, r) in runs {
            eprintln!(
                "{} {tier:?}: λ error {:?}, noise {:?}, follow {:?} s, drops {}, {:.1} s",
                e.id, r.lambda_err, r.noise_err, r.follow_s, r.drops, r.secs
            );
            let (lambda_max, noise_max) = match tier {
                CalibrationTier::Fast => (0.05, 0.15),
                _ => (0.02, 0.03),
            };
            let lambda = r.lambda_err.unwrap_or_else(|| panic!("{} {tier:?}: no λ published", e.id));
            assert!(lambda <= lambda_max, "{} {tier:?}: λ error {lambda:.4} > {lambda_max}", e.id);
            let noise = r.noise_err.unwrap_or_else(|| panic!("{} {tier:?}: no noise published", e.id));
            assert!(noise <= noise_max, "{} {tier:?}: noise error {noise:.4} > {noise_max}", e.id);
            let follow = r.follow_s.unwrap_or_else(|| panic!("{} {tier:?}: the change is not followed", e.id));
            assert!(follow <= 1.0, "{} {tier:?}: the change followed after {follow:.2} s", e.id);
            assert_eq!(r.drops, 0, "{} {tier:?}: motion blur dropped after it was published", e.id);
            if *tier == CalibrationTier::Accurate {
                accurate_lambda.push(lambda);
            }
        }
    }
    accurate_lambda.sort_by(f32::total_cmp);
    let median = accurate_lambda[accurate_lambda.len() / 2];
    assert!(median <= 0.01, "accurate λ error median {median:.4} over {accurate_lambda:?}");
}
