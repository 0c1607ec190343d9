//! Vignetting on known answers made elsewhere: real lenses' measured falloff
//! (lensfun's "pa" profiles, V = 1 + k1·r² + k2·r⁴ + k3·r⁶, r = 1 at the frame's
//! corner) applied to the real scenes of `benches/scenes.rs` (photographs with
//! measured depth from several public datasets, re-rendered along a head path with
//! rests and a mid-run camera change), and the same runs without it. Run:
//! `cargo xtask bench-quality MIRRORS` (extracts the scenes and lensfun's database,
//! sets `BENCH_SCENES` and `BENCH_LENSFUN`); prints Markdown for BENCHMARKS.md.
//!
//! Lenses are split like the scenes: a lens is held out by a hash of its name (a
//! third of them), a tuning scene gets a tuning lens and a held-out scene a held-out
//! one. Per run, over the publications from `FROM_S` (the window's first pairs):
//! * curve error: max over r ∈ [0, 1] of |V̂(r) − V(r)| over the corner falloff
//!   1 − V(1) (the "within 10%"), median over the present publications, and
//!   the same without the division (|ΔV|, in the linear light's fraction: what a
//!   small falloff's relative error amounts to);
//! * present: the share of publications with the falloff present (the rest not
//!   identifiable or absent);
//! * false present: on the run without vignetting, the share published present, and
//!   absent (the rest not identifiable: a faint falloff not told from none).
//!
//! Also, without video: how far the model's three log terms can follow each profile
//! at all (the best least-squares fit of ln V over the frame's pixels).

#[path = "../tests/common/mod.rs"]
mod common;

use blind_augment::model::Vignetting;
use blind_augment::synth::sequence::SequenceSpec;
use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, Event, Providers};
use common::calibration::{frame, pose};
use common::lensfun::{apply_pa, attr, entries, pa};
use common::scenes::{load, name_hash, spec_for, Entry, FPS, HEIGHT, WIDTH};
use common::summary;

/// Frames per run: 10 s at 30 fps. A lens does not change, so the runs are longer
/// than `benches/scenes.rs`'s: these head paths turn by 3° at most and rest 1.5 s
/// between turns, so the window's first six informative frame pairs take seconds.
const FRAMES: usize = 300;
/// Publications from this time on are scored.
const FROM_S: f64 = 6.0;

/// One lensfun profile.
#[derive(Clone, Debug)]
struct Profile {
    lens: String,
    focal_mm: f32,
    aperture: f32,
    k: [f32; 3],
}

impl Profile {
    fn v(&self, r: f32) -> f32 {
        pa(self.k, r)
    }
    fn held_out(&self) -> bool {
        name_hash(&self.lens) % 3 == 0
    }
}

/// Every "pa" vignetting entry of the database's XML files under `dir` whose falloff
/// the model can hold (V in [0.05, 2] and non-increasing on [0, 1]: a real lens's
/// falloff; a handful of entries rise towards the corner), one per distinct
/// (lens, focal length, aperture) — the nearest-focus distance only.
fn profiles(dir: &str) -> Vec<Profile> {
    let mut out: Vec<Profile> = vec![];
    for (lens, line) in entries(dir, "vignetting") {
        if !line.contains("model=\"pa\"") {
            continue;
        }
        let (Some(focal_mm), Some(aperture), Some(k1), Some(k2), Some(k3)) =
            (attr(&line, "focal"), attr(&line, "aperture"), attr(&line, "k1"), attr(&line, "k2"), attr(&line, "k3"))
        else {
            continue;
        };
        let p = Profile { lens, focal_mm, aperture, k: [k1, k2, k3] };
        let vs: Vec<f32> = (0..=64).map(|i| p.v(i as f32 / 64.0)).collect();
        let ok = vs.iter().all(|v| (0.05..=2.0).contains(v)) && vs.windows(2).all(|w| w[1] <= w[0] + 1e-4);
        let dup = out.iter().any(|q| q.lens == p.lens && q.focal_mm == p.focal_mm && q.aperture == p.aperture);
        if ok && !dup {
            out.push(p);
        }
    }
    out
}

/// Frame pixels' normalised radii (every 4th pixel), for the fits without video.
fn frame_radii() -> Vec<f32> {
    let mut r = vec![];
    for y in (0..HEIGHT).step_by(4) {
        for x in (0..WIDTH).step_by(4) {
            r.push(Vignetting::radius(WIDTH, HEIGHT, x as f32 + 0.5, y as f32 + 0.5));
        }
    }
    r
}

/// The best fit of ln V by a1·r² + a2·r⁴ + a3·r⁶ (the first `terms` of them) over
/// the frame's pixels: its curve error (as the runs' metric).
#[allow(clippy::needless_range_loop)] // elimination over a 3×3 block reads clearest by index
fn representable(p: &Profile, radii: &[f32], terms: usize) -> f32 {
    let mut a = [[0.0f64; 3]; 3];
    let mut b = [0.0f64; 3];
    for &r in radii {
        let r2 = (r * r) as f64;
        let x = [r2, r2 * r2, r2 * r2 * r2];
        let y = (p.v(r) as f64).ln();
        for i in 0..terms {
            b[i] += x[i] * y;
            for j in 0..terms {
                a[i][j] += x[i] * x[j];
            }
        }
    }
    // Gaussian elimination on the leading `terms`×`terms` block.
    let n = terms;
    for c in 0..n {
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for k in c..n {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0f64; 3];
    for c in (0..n).rev() {
        let s: f64 = (c + 1..n).map(|k| a[c][k] * x[k]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    curve_error(p, [x[0] as f32, x[1] as f32, x[2] as f32])
}

fn curve_error(p: &Profile, a: [f32; 3]) -> f32 {
    let corner = (1.0 - p.v(1.0)).max(1e-6);
    (0..=50).map(|i| i as f32 / 50.0).map(|r| (Vignetting::gain_at(a, r) - p.v(r)).abs()).fold(0.0, f32::max) / corner
}

struct Run {
    absent: f32,
    curve_err: Option<f32>,
    abs_err: Option<f32>,
    present: f32,
    first_present_s: Option<f64>,
}

/// The scene's run with `lens` applied (None: without vignetting).
fn run(e: &Entry, spec: &SequenceSpec, lens: Option<&Profile>) -> Run {
    let mut cfg = CalibratorConfig::new(CalibrationTier::Fast, 1.0 / FPS as f64, Some(spec.view));
    // The other effects' fits do not read or change the vignetting term: off, so a
    // run costs its frames' rendering and the vignetting fit.
    cfg.effects = blind_augment::fit::Effects { noise: false, motion_blur: false, depth_of_field: false };
    cfg.colour = false;
    let mut cal = Calibrator::new(cfg, Providers::for_tier(CalibrationTier::Fast)).expect("valid config");
    // `BENCH_VIGNETTING_TRACE=1`: each tuning scene's publications to stderr.
    let trace = std::env::var_os("BENCH_VIGNETTING_TRACE").is_some();
    cal.push_poses(&[pose(spec, 0), pose(spec, 1)]).expect("poses");
    let (mut errs, mut abs, mut scored, mut present, mut absent, mut first) = (vec![], vec![], 0, 0, 0, None);
    for i in 0..spec.frames {
        cal.push_poses(&[pose(spec, i + 2)]).expect("poses");
        let mut fr = frame(&spec.frame(&e.scene, i));
        if let Some(p) = lens {
            apply_pa(&mut fr.image, p.k);
        }
        for ev in cal.push_frame(fr).unwrap_or_default() {
            let Event::Published(u) = ev else { continue };
            let v = &u.model.vignetting;
            if trace && !e.held_out {
                eprintln!("  {:.2} {:?} {:?} {}", u.t_s, v.diagnostics.status, v.log_falloff, v.diagnostics.reason);
            }
            if v.present && first.is_none() {
                first = Some(u.t_s);
            }
            if u.t_s < FROM_S {
                continue;
            }
            scored += 1;
            absent += (v.diagnostics.status == blind_augment::model::Status::Absent) as usize;
            if let (true, Some(a), Some(p)) = (v.present, v.log_falloff, lens) {
                present += 1;
                errs.push(curve_error(p, a));
                abs.push(curve_error(p, a) * (1.0 - p.v(1.0)).max(1e-6));
            } else if v.present {
                present += 1;
            }
        }
    }
    errs.sort_by(f32::total_cmp);
    abs.sort_by(f32::total_cmp);
    Run {
        absent: absent as f32 / scored.max(1) as f32,
        curve_err: (!errs.is_empty()).then(|| errs[errs.len() / 2]),
        abs_err: (!abs.is_empty()).then(|| abs[abs.len() / 2]),
        present: present as f32 / scored.max(1) as f32,
        first_present_s: first,
    }
}

/// Median / p10 / lowest: for shares where lower is worse.
fn stats_low(v: &[f32]) -> String {
    if v.is_empty() {
        return "— / — / —".into();
    }
    let mut v = v.to_vec();
    v.sort_by(f32::total_cmp);
    let q = |p: f32| v[((v.len() - 1) as f32 * p).round() as usize];
    format!("{:.2} / {:.2} / {:.2}", q(0.5), q(0.1), v[0])
}

fn main() {
    let (Some(manifest), Some(lensfun)) = (std::env::var_os("BENCH_SCENES"), std::env::var_os("BENCH_LENSFUN")) else {
        eprintln!("BENCH_SCENES or BENCH_LENSFUN is not set: run `cargo xtask bench-quality MIRRORS`");
        return;
    };
    let all = profiles(&lensfun.to_string_lossy());
    let (held, tuning): (Vec<&Profile>, Vec<&Profile>) = all.iter().partition(|p| p.held_out());
    let radii = frame_radii();
    println!("### Vignetting on measured lenses\n");
    println!(
        "{} lensfun \"pa\" profiles (distinct lens, focal length, aperture; {} held out by lens name).\n",
        all.len(),
        held.len()
    );
    println!("The model's log-polynomial against every profile, without video (best fit over a 320×240 frame; curve error as below):\n");
    println!("| terms | median / p90 / worst curve error |\n|---|---|");
    for terms in [2, 3] {
        let e: Vec<f32> = all.iter().map(|p| representable(p, &radii, terms)).collect();
        println!("| {terms} | {} |", summary(&e));
    }
    let corners: Vec<f32> = all.iter().map(|p| 1.0 - p.v(1.0)).collect();
    println!("\nThe profiles' corner falloff 1 − V(1): median / p90 / largest {}.\n", summary(&corners));
    let mut entries = load(&manifest.to_string_lossy());
    // One tuning scene by name (`BENCH_VIGNETTING_ONLY=Books`); never a held-out one.
    if let Ok(only) = std::env::var("BENCH_VIGNETTING_ONLY") {
        entries.retain(|e| !e.held_out && e.id.contains(only.as_str()));
    }
    println!(
        "{} scenes ({} held out), {WIDTH}×{HEIGHT} at {FPS} fps, {FRAMES} frames along `benches/scenes.rs`'s head paths (its camera change at 2.75 s included); publications from {FROM_S} s scored.\n",
        entries.len(),
        entries.iter().filter(|e| e.held_out).count()
    );
    println!("Tuning scenes:\n");
    println!("| scene | lens | corner falloff | curve error | \\|ΔV\\| | present | first present (s) | without it: present / absent |\n|---|---|---|---|---|---|---|---|");
    let mut rows: Vec<(bool, Run, Run)> = vec![];
    for e in &entries {
        let pool = if e.held_out { &held } else { &tuning };
        if pool.is_empty() {
            continue;
        }
        let lens = pool[e.k % pool.len()];
        let mut spec = spec_for(&e.scene, e.k);
        spec.frames = FRAMES;
        let with = run(e, &spec, Some(lens));
        let without = run(e, &spec, None);
        eprintln!(
            "{}: {} {} mm f/{}: curve error {:?}, present {:.2}",
            e.id, lens.lens, lens.focal_mm, lens.aperture, with.curve_err, with.present
        );
        if !e.held_out {
            println!(
                "| {} | {} {} mm f/{} | {:.3} | {} | {} | {:.2} | {} | {:.2} / {:.2} |",
                e.id,
                lens.lens.replace('|', "/"),
                lens.focal_mm,
                lens.aperture,
                1.0 - lens.v(1.0),
                with.curve_err.map_or("—".into(), |v| format!("{v:.3}")),
                with.abs_err.map_or("—".into(), |v| format!("{v:.3}")),
                with.present,
                with.first_present_s.map_or("—".into(), |t| format!("{t:.2}")),
                without.present,
                without.absent,
            );
        }
        rows.push((e.held_out, with, without));
    }
    println!("\nPer split: median / p90 / worst of the runs' values.\n");
    println!("| split | runs | curve error | \\|ΔV\\| | present (median / p10 / lowest) | false present | absent without it (median / p10 / lowest) | runs never present | first present (s) |\n|---|---|---|---|---|---|---|---|---|");
    for split in [false, true] {
        let rs: Vec<&(bool, Run, Run)> = rows.iter().filter(|r| r.0 == split).collect();
        let err: Vec<f32> = rs.iter().filter_map(|r| r.1.curve_err).collect();
        let pres: Vec<f32> = rs.iter().map(|r| r.1.present).collect();
        let fals: Vec<f32> = rs.iter().map(|r| r.2.present).collect();
        let abs_without: Vec<f32> = rs.iter().map(|r| r.2.absent).collect();
        let abs: Vec<f32> = rs.iter().filter_map(|r| r.1.abs_err).collect();
        let first: Vec<f32> = rs.iter().filter_map(|r| r.1.first_present_s.map(|t| t as f32)).collect();
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            if split { "held-out" } else { "tuning" },
            rs.len(),
            summary(&err),
            summary(&abs),
            stats_low(&pres),
            summary(&fals),
            stats_low(&abs_without),
            rs.iter().filter(|r| r.1.first_present_s.is_none()).count(),
            summary(&first)
        );
    }
}
