//! `blind-augment calibrate`: the worker's calibration loop over a recorded
//! sequence (frames, optional depth, poses + intrinsics, flow), with a timeline of
//! every published model and, given the truth, its error over time; and
//! `blind-augment synth-video`: such a sequence with known truth (the bundled
//! Motorcycle photograph along a head path, distorted by a camera that changes
//! mid-sequence).

use super::{CalibrateArgs, SynthVideoArgs};
use anyhow::{bail, ensure, Context, Result};
use blind_augment::analysis::{DepthMap, Frame, Intrinsics, Role};
use blind_augment::io::poses::{format_poses_csv, read_pose_track_csv, read_poses_csv, PoseRow};
use blind_augment::io::{self, BitDepth};
use blind_augment::model::compare::{dof_rmse_px, exposure_error, noise_headline, noise_relative_error};
use blind_augment::model::CameraModel;
use blind_augment::plots::{panels_plot, Panel, Series};
use blind_augment::synth::sequence::{motorcycle, SequenceSpec};
use blind_augment::worker::{CalibrationTier, Calibrator, CalibratorConfig, Event, Providers};
use plotters::style::RGBColor;
use std::io::Write as _;
use std::path::Path;

use super::fit_cmd::{frames_bar, list_frames, sibling};

pub fn parse_intrinsics(s: &str, w: usize, h: usize) -> Result<Intrinsics> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--intrinsics `{s}`: expected fx,fy,cx,cy (numbers)"))?;
    ensure!(v.len() == 4, "--intrinsics `{s}`: expected 4 numbers fx,fy,cx,cy, got {}", v.len());
    ensure!(
        v.iter().all(|x| x.is_finite()) && v[0] > 0.0 && v[1] > 0.0,
        "--intrinsics `{s}`: need finite values with fx, fy > 0"
    );
    Ok(Intrinsics { fx: v[0], fy: v[1], cx: v[2], cy: v[3], width: w, height: h })
}

/// Each frame's number: the file names' numbers where every name is one and
/// they increase in name order (a recording keeps the camera's numbering, with
/// gaps where the live worker dropped frames: the temporal stages look for
/// frame-number neighbours), else the position.
/// Where every name is a number the frames are put in number order (names past
/// the zero padding sort wrongly by name); two names for one number fall back to
/// positions. Says which numbering it used.
pub fn frame_numbers(frames: &mut [std::path::PathBuf]) -> Vec<u64> {
    let parsed: Option<Vec<u64>> =
        frames.iter().map(|p| p.file_stem().and_then(|s| s.to_str()).and_then(|s| s.parse().ok())).collect();
    if let Some(mut n) = parsed {
        let mut order: Vec<usize> = (0..frames.len()).collect();
        order.sort_by_key(|&i| n[i]);
        let sorted: Vec<std::path::PathBuf> = order.iter().map(|&i| frames[i].clone()).collect();
        n.sort_unstable();
        if n.windows(2).all(|w| w[1] > w[0]) {
            frames.clone_from_slice(&sorted);
            if n.first() != Some(&0) || n.last() != Some(&(n.len() as u64 - 1)) {
                eprintln!(
                    "frames numbered by their names: {} to {} ({} files; the gaps are frames not recorded)",
                    n[0],
                    n[n.len() - 1],
                    n.len()
                );
            }
            return n;
        }
        eprintln!("frame names repeat a number: frames numbered by position in name order");
    }
    (0..frames.len() as u64).collect()
}

/// One line of `--timeline` / `truth.jsonl`.
#[derive(serde::Serialize, serde::Deserialize)]
struct TimelineEntry {
    frame: u64,
    t_s: f64,
    model: CameraModel,
}

fn read_truth(path: &Path) -> Result<Vec<TimelineEntry>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = vec![];
    for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let e: TimelineEntry = serde_json::from_str(line)
            .with_context(|| format!("{} line {}: not a timeline entry", path.display(), i + 1))?;
        e.model.validate().with_context(|| format!("{} line {}: model", path.display(), i + 1))?;
        out.push(e);
    }
    ensure!(!out.is_empty(), "{} holds no entries", path.display());
    Ok(out)
}

fn truth_at(truth: &[TimelineEntry], t_s: f64) -> &CameraModel {
    let i = truth.partition_point(|e| e.t_s <= t_s + 1e-9).saturating_sub(1);
    &truth[i].model
}

/// Errors of a published model against the truth at its time.
#[derive(Clone, Copy, Debug, Default)]
pub struct Errors {
    pub lambda: Option<f32>,
    pub noise: Option<f32>,
    pub dof_px: Option<f32>,
}

pub fn errors(m: &CameraModel, truth: &CameraModel) -> Errors {
    let r = truth.depth_of_field.depth_range;
    let depths: Vec<f32> = (0..16).map(|i| r[0] + (r[1] - r[0]) * (i as f32 + 0.5) / 16.0).collect();
    Errors {
        lambda: (truth.motion_blur.present || m.motion_blur.present).then(|| exposure_error(m, truth)),
        noise: noise_relative_error(&m.noise, &truth.noise),
        dof_px: dof_rmse_px(&m.depth_of_field, &truth.depth_of_field, &depths),
    }
}

pub fn run(args: CalibrateArgs) -> Result<()> {
    let tier = CalibrationTier::parse(&args.tier)
        .with_context(|| format!("--tier `{}`: expected fast, balanced or accurate", args.tier))?;
    ensure!(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0, "--fps {}: need 0 < fps ≤ 1000", args.fps);
    let mut frames = list_frames(&args.frames)?;
    let numbers = frame_numbers(&mut frames);
    let (first, _) = io::load_rgb(&frames[0]).with_context(|| format!("frame {}", frames[0].display()))?;
    let (w, h) = (first.width, first.height);
    let poses: Option<Vec<PoseRow>> = match (&args.poses, &args.intrinsics) {
        (Some(p), Some(_)) => Some(read_poses_csv(p)?),
        (Some(_), None) => bail!("--poses needs --intrinsics fx,fy,cx,cy (pixels of the frames)"),
        (None, Some(_)) => bail!("--intrinsics is only used with --poses"),
        (None, None) => None,
    };
    ensure!(!args.depth_optional || args.geometry.depth.is_some(), "--depth-optional is used with --depth");
    let intrinsics = args.intrinsics.as_deref().map(|s| parse_intrinsics(s, w, h)).transpose()?;
    let track = match (&args.pose_track, &poses) {
        (Some(p), Some(_)) => Some(read_pose_track_csv(p)?),
        (Some(_), None) => bail!("--pose-track needs --poses (the frames' times) and --intrinsics"),
        (None, _) => None,
    };
    if let Some(rows) = &poses {
        for (&i, f) in numbers.iter().zip(&frames) {
            ensure!(
                rows.iter().any(|r| r.frame == i),
                "frame {i} ({}) has no row in {}",
                f.display(),
                args.poses.as_ref().map_or(String::new(), |p| p.display().to_string())
            );
        }
    }
    let truth = args.truth.as_deref().map(read_truth).transpose()?;
    let mut providers = Providers::for_tier(tier);
    if args.geometry.flow.is_some() {
        providers = providers.with_given_flow();
    }
    for (role, path) in super::parse_onnx(&args.onnx)? {
        match role {
            Role::Depth => {
                ensure!(args.geometry.depth.is_none(), "--onnx depth=… and --depth both give depth: pick one")
            }
            Role::Flow => ensure!(args.geometry.flow.is_none(), "--onnx flow=… and --flow both give flow: pick one"),
            _ => {}
        }
        providers = providers.with_onnx(role, &path)?;
        eprintln!("{} provider: {}", role.name(), path.display());
    }
    let mut cfg = CalibratorConfig::new(tier, 1.0 / args.fps as f64, intrinsics);
    cfg.effects = super::effects(&args.only);
    cfg.colour = super::colour_wanted(&args.only);
    cfg.vignetting = super::vignetting_wanted(&args.only);
    cfg.chromatic_aberration = super::chromatic_wanted(&args.only);
    cfg.sharpening = super::sharpening_wanted(&args.only);
    cfg.fast_effort = args.fast_effort;
    let mut cal = Calibrator::new(cfg, providers)?;
    let mut timeline = match &args.timeline {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?,
        )),
        None => None,
    };
    let bar = frames_bar(frames.len());
    // Poses run ahead of camera frames on a headset (the camera pipeline's latency):
    // each frame arrives with the poses up to two frames later.
    const POSE_LEAD: u64 = 2;
    let mut pushed_rows = 0usize;
    let mut published: Vec<(u64, f64, CameraModel, f64)> = vec![];
    let mut fitted_frames: Vec<f64> = vec![];
    let (mut skipped, mut changes) = (0usize, vec![]);
    for (&i, path) in numbers.iter().zip(&frames) {
        bar.set_message(path.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default());
        let (image, _) = io::load_rgb(path).with_context(|| format!("frame {}", path.display()))?;
        ensure!(
            (image.width, image.height) == (w, h),
            "frame {} is {}×{}, earlier frames are {w}×{h}",
            path.display(),
            image.width,
            image.height
        );
        let t_s = match &poses {
            Some(rows) => {
                let t_s = rows.iter().find(|r| r.frame == i).map(|r| r.t_s).unwrap_or(i as f64 / args.fps as f64);
                // The poses known with this frame: rows up to two frames later, or
                // the pose track up to two and a half frame intervals later (the
                // track has no frame numbers; half an interval of margin for
                // frame-time jitter).
                let (upto, new): (usize, Vec<_>) = match &track {
                    Some(track) => {
                        let limit_ns = ((t_s + (POSE_LEAD as f64 + 0.5) / args.fps as f64) * 1e9).round() as i64;
                        let upto = track.partition_point(|p| p.t_ns <= limit_ns);
                        (upto, track[pushed_rows.min(upto)..upto].to_vec())
                    }
                    None => {
                        let upto = rows.partition_point(|r| r.frame <= i + POSE_LEAD);
                        (upto, rows[pushed_rows.min(upto)..upto].iter().map(|r| r.pose).collect())
                    }
                };
                if upto > pushed_rows {
                    for e in cal.push_poses(&new)? {
                        if let Event::TrackingLoss { t_s, reason } = e {
                            log::warn!("tracking loss at {t_s:.3} s: {reason}");
                            bar.println(format!("tracking loss at {t_s:.3} s: {reason}"));
                        }
                    }
                    pushed_rows = upto;
                }
                t_s
            }
            None => i as f64 / args.fps as f64,
        };
        let g = &args.geometry;
        let depth = match &g.depth {
            Some(d) => match sibling(d, path, "depth") {
                Ok(file) => {
                    Some(DepthMap { depth: io::load_depth(&file, g.depth_png_scale)?, units: g.depth_units.into() })
                }
                // A recording's frames the headset had no depth for: as live.
                Err(_) if args.depth_optional => None,
                Err(e) => return Err(e.context("(--depth-optional lets frames without a depth file go without)")),
            },
            None => None,
        };
        let flow = match &args.geometry.flow {
            Some(d) => Some(io::load_flow(&sibling(d, path, "flow")?)?),
            None => None,
        };
        let frame = Frame { index: i, t_s, image, depth, flow };
        let events = cal.push_frame(frame).with_context(|| format!("frame {}", path.display()))?;
        for e in events {
            match e {
                Event::Published(u) => {
                    fitted_frames.push(u.t_s);
                    // Where the update's time went (RUST_LOG=debug): the worker's cost
                    // per stage, as BENCHMARKS.md's breakdown reads it.
                    log::debug!(
                        "frame {} {:?} {:.1} ms: {}",
                        u.frame,
                        u.reason,
                        1e3 * u.compute_s,
                        u.stages_s.iter().map(|(k, v)| format!("{k} {:.1}", 1e3 * v)).collect::<Vec<_>>().join(", ")
                    );
                    if let Some(tl) = &mut timeline {
                        let line = serde_json::to_string(&TimelineEntry {
                            frame: u.frame,
                            t_s: u.t_s,
                            model: u.model.clone(),
                        })?;
                        writeln!(tl, "{line}").context("writing the timeline")?;
                    }
                    published.push((u.frame, u.t_s, u.model, u.compute_s));
                }
                Event::Skipped { frame, reason } => {
                    skipped += 1;
                    log::info!("frame {frame} skipped: {reason}");
                }
                Event::ChangeDetected { frame, t_s, cause } => {
                    bar.println(format!("camera change detected at frame {frame} ({t_s:.2} s): {cause}"));
                    changes.push(t_s);
                }
                Event::TrackingLoss { t_s, reason } => bar.println(format!("tracking loss at {t_s:.3} s: {reason}")),
                Event::Degraded { frame, reason } => log::debug!("frame {frame}: {reason}"),
            }
        }
        bar.inc(1);
    }
    bar.finish();
    if let Some(tl) = &mut timeline {
        tl.flush().context("writing the timeline")?;
    }
    let Some((frame, t_s, model, _)) = published.last().cloned() else {
        bail!("no camera model was published: every frame was skipped ({skipped}); see the log (RUST_LOG=info)")
    };
    std::fs::write(&args.out, model.to_json()?).with_context(|| format!("writing {}", args.out.display()))?;
    let costs: Vec<f64> = published.iter().map(|p| p.3).collect();
    let mean_ms = 1e3 * costs.iter().sum::<f64>() / costs.len() as f64;
    eprintln!(
        "wrote {} (the model published at frame {frame}, {t_s:.2} s; {} models published, {:.1} ms per update on average, tier {})",
        args.out.display(),
        published.len(),
        mean_ms,
        tier.name()
    );
    super::fit_cmd::summarize(&model);
    if let Some(truth) = &truth {
        let e = errors(&model, truth_at(truth, t_s));
        eprintln!(
            "  against the truth at {t_s:.2} s: λ error {}, noise median relative error {}, δ RMSE {}",
            e.lambda.map_or("n/a".into(), |v| format!("{v:.4}")),
            e.noise.map_or("n/a".into(), |v| format!("{:.1}%", 100.0 * v)),
            e.dof_px.map_or("n/a".into(), |v| format!("{v:.3} px"))
        );
    }
    if let Some(dir) = &args.plots {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let p = dir.join("timeline.png");
        timeline_plot(&p, &published, truth.as_deref(), &changes)?;
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

const EST: RGBColor = RGBColor(38, 110, 210);
const TRUTH: RGBColor = RGBColor(60, 60, 60);
const FIT: RGBColor = RGBColor(220, 50, 47);

fn timeline_plot(
    path: &Path,
    published: &[(u64, f64, CameraModel, f64)],
    truth: Option<&[TimelineEntry]>,
    changes: &[f64],
) -> Result<()> {
    let mid_depth = |m: &CameraModel| {
        let r = m.depth_of_field.depth_range;
        0.5 * (r[0] + r[1])
    };
    type Get = fn(&CameraModel, f32) -> Option<f64>;
    let params: [(&str, &str, Get); 3] = [
        ("exposure λ", "λ", |m, _| Some(m.motion_blur.exposure_or_zero() as f64)),
        ("noise: level-0 std (green, luma 0.5)", "std", |m, _| noise_headline(&m.noise).map(|v| v as f64)),
        ("depth of field: δ at the truth's mid depth", "δ (px)", |m, z| Some(m.depth_of_field.sigma_px(z) as f64)),
    ];
    let z_mid =
        truth.map(|t| mid_depth(&t[0].model)).or_else(|| published.first().map(|p| mid_depth(&p.2))).unwrap_or(1.0);
    let panels: Vec<Panel> = params
        .iter()
        .map(|(title, y, get)| {
            let mut series = vec![Series {
                label: "published".into(),
                points: published.iter().filter_map(|p| get(&p.2, z_mid).map(|v| (p.1, v))).collect(),
                colour: EST,
                dots: false,
            }];
            series.push(Series {
                label: "fitted at".into(),
                points: published.iter().filter_map(|p| get(&p.2, z_mid).map(|v| (p.1, v))).collect(),
                colour: FIT,
                dots: true,
            });
            if let Some(t) = truth {
                let t_end = published.last().map_or(0.0, |p| p.1);
                let mut pts: Vec<(f64, f64)> = vec![];
                for (k, e) in t.iter().enumerate() {
                    if let Some(v) = get(&e.model, z_mid) {
                        if k > 0 {
                            if let Some(&(_, prev)) = pts.last() {
                                pts.push((e.t_s, prev));
                            }
                        }
                        pts.push((e.t_s, v));
                    }
                }
                if let Some(&(_, v)) = pts.last() {
                    pts.push((t_end, v));
                }
                series.push(Series { label: "truth".into(), points: pts, colour: TRUTH, dots: false });
            }
            let title = if changes.is_empty() {
                title.to_string()
            } else {
                format!(
                    "{title} (change detected at {})",
                    changes.iter().map(|c| format!("{c:.2} s")).collect::<Vec<_>>().join(", ")
                )
            };
            Panel { title, x_desc: "video time (s)".into(), y_desc: y.to_string(), series, log_x: false }
        })
        .collect();
    panels_plot(path, &panels, 1200, 330)?;
    Ok(())
}

/// `synth-video`: a recorded sequence with known truth.
pub fn synth_video(args: SynthVideoArgs) -> Result<()> {
    let (w, h) = super::parse_size(&args.size)?;
    ensure!(args.frames >= 2, "--frames {}: at least 2", args.frames);
    let scene = motorcycle().map_err(anyhow::Error::msg)?;
    let spec = SequenceSpec::motorcycle(&scene, w, h, args.frames, args.change_at_s);
    let out = &args.out;
    for sub in ["frames", "depth", "flow"] {
        std::fs::create_dir_all(out.join(sub)).with_context(|| format!("creating {}", out.join(sub).display()))?;
    }
    let bar = indicatif::ProgressBar::new(args.frames as u64);
    let mut rows = vec![];
    let mut truth = String::new();
    // Poses cover two frames past the last one (the pose lead `calibrate` uses).
    for i in 0..args.frames + 2 {
        let t = spec.frame_time_s(i);
        let (_, q, p) = spec.path.world_from_camera(t).to_scale_rotation_translation();
        rows.push(PoseRow {
            frame: i as u64,
            t_s: t,
            pose: blind_augment::analysis::timing::TimedPose {
                t_ns: (t * 1e9).round() as i64,
                position_m: p,
                orientation: q,
            },
        });
    }
    for i in 0..args.frames {
        let f = spec.frame(&scene, i);
        let name = format!("{i:04}");
        io::save_rgb(&out.join("frames").join(format!("{name}.png")), &f.image, BitDepth::Eight)?;
        io::save_depth(&out.join("depth").join(format!("{name}.pfm")), &f.depth_m)?;
        io::save_flow(&out.join("flow").join(format!("{name}.flo")), &f.flow)?;
        if i == 0 || spec.truth_at(spec.frame_time_s(i - 1)) != &f.truth {
            truth += &serde_json::to_string(&TimelineEntry { frame: i as u64, t_s: f.t_s, model: f.truth.clone() })?;
            truth.push('\n');
        }
        bar.inc(1);
    }
    bar.finish();
    std::fs::write(out.join("poses.csv"), format_poses_csv(&rows)).context("writing poses.csv")?;
    let k = spec.view;
    std::fs::write(out.join("intrinsics.txt"), format!("{},{},{},{}\n", k.fx, k.fy, k.cx, k.cy))
        .context("writing intrinsics.txt")?;
    std::fs::write(out.join("truth.jsonl"), truth).context("writing truth.jsonl")?;
    eprintln!(
        "wrote {} frames of {w}×{h} at {} fps into {} (frames/, depth/ in metres, flow/, poses.csv, intrinsics.txt = {},{},{},{}, truth.jsonl)",
        args.frames,
        spec.fps,
        out.display(),
        k.fx,
        k.fy,
        k.cx,
        k.cy
    );
    Ok(())
}
