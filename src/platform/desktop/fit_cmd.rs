//! `blind-augment fit`: one frame, or a folder of frames aggregated robustly.

use super::FitArgs;
use anyhow::{Context, Result};
use blind_augment::analysis::onnx::{OnnxDeblur, OnnxDenoiser, OnnxDepth, OnnxModel};
use blind_augment::analysis::{
    Analysed, DefocusDeblurrer, Denoiser, DepthMap, DepthProvider, Frame, FrameContext, MotionDeblurrer, Reference,
    Role,
};
use blind_augment::fit::{aggregate_models, fit, FitInputs, FitOptions, FitOutput};
use blind_augment::image::{Flow, Plane, Rgb};
use blind_augment::io;
use blind_augment::model::DepthUnits;
use std::path::{Path, PathBuf};

const IMAGE_EXTS: [&str; 5] = ["png", "jpg", "jpeg", "pfm", "npy"];

struct Loaded {
    image: Rgb,
    denoised: Option<Rgb>,
    motion_deblurred: Option<Rgb>,
    defocus_deblurred: Option<Rgb>,
    depth: Option<Plane>,
    depth_units: DepthUnits,
    flow: Option<Flow>,
}

fn load_opt_rgb(p: &Option<PathBuf>) -> Result<Option<Rgb>> {
    Ok(match p {
        Some(p) => Some(io::load_rgb(p)?.0),
        None => None,
    })
}

/// The images in `dir`, in name order (an error when there are none).
pub fn list_frames(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut frames: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading frames folder {}", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| IMAGE_EXTS.contains(&e.to_ascii_lowercase().as_str()))
        })
        .collect();
    frames.sort();
    anyhow::ensure!(!frames.is_empty(), "frames folder {} holds no images ({})", dir.display(), IMAGE_EXTS.join(", "));
    Ok(frames)
}

/// The progress bar of a run over `n` frames.
pub fn frames_bar(n: usize) -> indicatif::ProgressBar {
    indicatif::ProgressBar::new(n as u64).with_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames {msg} [{elapsed_precise}]")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    )
}

/// In folder mode, the file in `dir` with the same stem as `frame` (any extension).
pub fn sibling(dir: &Path, frame: &Path, what: &str) -> Result<PathBuf> {
    let stem = frame.file_stem().context("frame without a file name")?;
    let entries = std::fs::read_dir(dir).with_context(|| format!("reading {what} folder {}", dir.display()))?;
    for e in entries.flatten() {
        let p = e.path();
        if p.file_stem() == Some(stem) {
            return Ok(p);
        }
    }
    anyhow::bail!("{what} folder {} has no file named like {}", dir.display(), frame.display())
}

/// Networks given by `--onnx` (flow needs consecutive frames: `calibrate` runs it).
#[derive(Default)]
struct Networks {
    denoise: Option<OnnxDenoiser>,
    motion_deblur: Option<OnnxDeblur>,
    defocus_deblur: Option<OnnxDeblur>,
    depth: Option<OnnxDepth>,
}

impl Networks {
    fn load(args: &FitArgs) -> Result<Networks> {
        let mut n = Networks::default();
        for (role, path) in super::parse_onnx(&args.onnx)? {
            let given = match role {
                Role::Denoise => args.denoised.is_some(),
                Role::MotionDeblur => args.motion_deblurred.is_some(),
                Role::DefocusDeblur => args.defocus_deblurred.is_some(),
                Role::Depth => args.geometry.depth.is_some(),
                Role::Flow => anyhow::bail!(
                    "--onnx flow=…: a flow network needs consecutive frames; use `calibrate`, or give --flow"
                ),
            };
            anyhow::ensure!(!given, "--onnx {}=… and a file for the same role are both given: pick one", role.name());
            let model = OnnxModel::load(role, &path, None)?;
            eprintln!("{} provider: {}", role.name(), path.display());
            match role {
                Role::Denoise => n.denoise = Some(OnnxDenoiser::new(model)),
                Role::MotionDeblur => n.motion_deblur = Some(OnnxDeblur { model }),
                Role::DefocusDeblur => n.defocus_deblur = Some(OnnxDeblur { model }),
                Role::Depth => n.depth = Some(OnnxDepth { model }),
                Role::Flow => {}
            }
        }
        Ok(n)
    }

    /// Fill the references, and depth, the files did not give; the pixels where the
    /// network references hold (their valid masks, multiplied).
    fn complete(&mut self, inp: &mut Loaded) -> Result<Option<Plane>> {
        let frame = Frame { index: 0, t_s: 0.0, image: inp.image.clone(), depth: None, flow: None };
        let current = Analysed { frame, depth: None, world_from_camera: None, sparse_flow: None };
        let ctx = FrameContext { current: &current, window: &[], poses: None, intrinsics: None, frame_interval_s: 1.0 };
        let mut valid: Option<Plane> = None;
        let mut keep = |r: Reference| {
            if let Some(v) = r.valid {
                valid = Some(match valid.take() {
                    Some(mut a) => {
                        a.data.iter_mut().zip(&v.data).for_each(|(a, b)| *a *= b);
                        a
                    }
                    None => v,
                });
            }
            r.image
        };
        if let Some(d) = self.depth.as_mut() {
            let map = d.depth(&ctx)?;
            anyhow::ensure!(
                map.units == inp.depth_units,
                "--onnx depth gives {:?} depth but --depth-units says {:?}",
                map.units,
                inp.depth_units
            );
            inp.depth = Some(map.depth);
        }
        if let Some(d) = self.denoise.as_mut() {
            inp.denoised = Some(keep(d.denoise(&ctx)?));
        }
        if let Some(d) = self.motion_deblur.as_mut() {
            let flow = inp.flow.clone().context("--onnx motion-deblur=… needs --flow")?;
            inp.motion_deblurred = Some(keep(MotionDeblurrer::deblur(d, &ctx, &flow)?));
        }
        if let Some(d) = self.defocus_deblur.as_mut() {
            let depth = DepthMap {
                depth: inp.depth.clone().context("--onnx defocus-deblur=… needs depth")?,
                units: inp.depth_units,
            };
            inp.defocus_deblurred = Some(keep(DefocusDeblurrer::deblur(d, &ctx, &depth)?));
        }
        Ok(valid)
    }
}

fn run_one(inp: &mut Loaded, nets: &mut Networks, opts: &FitOptions) -> Result<FitOutput> {
    let valid = nets.complete(inp)?;
    let fi = FitInputs {
        denoised: inp.denoised.as_ref(),
        motion_deblurred: inp.motion_deblurred.as_ref(),
        defocus_deblurred: inp.defocus_deblurred.as_ref(),
        depth: inp.depth.as_ref(),
        depth_units: inp.depth_units,
        flow: inp.flow.as_ref(),
        reference_valid: valid.as_ref(),
        ..FitInputs::new(&inp.image)
    };
    Ok(fit(&fi, opts)?)
}

pub fn run(args: FitArgs) -> Result<()> {
    let opts = FitOptions {
        tier: super::tier(args.tier),
        effects: super::effects(&args.only),
        colour: super::colour_wanted(&args.only),
        sharpening: super::sharpening_wanted(&args.only),
        fast_effort: args.fast_effort,
        ..Default::default()
    };
    let g = &args.geometry;
    let mut nets = Networks::load(&args)?;
    let output = if let Some(dir) = &args.frames {
        let frames = list_frames(dir)?;
        let bar = frames_bar(frames.len());
        let mut models = vec![];
        let mut last = None;
        for frame in &frames {
            bar.set_message(frame.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default());
            let load = |d: &Option<PathBuf>, what: &str| -> Result<Option<Rgb>> {
                match d {
                    Some(d) => Ok(Some(io::load_rgb(&sibling(d, frame, what)?)?.0)),
                    None => Ok(None),
                }
            };
            let mut inp = Loaded {
                image: io::load_rgb(frame)?.0,
                denoised: load(&args.denoised, "denoised")?,
                motion_deblurred: load(&args.motion_deblurred, "motion-deblurred")?,
                defocus_deblurred: load(&args.defocus_deblurred, "defocus-deblurred")?,
                depth: match &g.depth {
                    Some(d) => Some(io::load_depth(&sibling(d, frame, "depth")?, g.depth_png_scale)?),
                    None => None,
                },
                depth_units: g.depth_units.into(),
                flow: match &g.flow {
                    Some(d) => Some(io::load_flow(&sibling(d, frame, "flow")?)?),
                    None => None,
                },
            };
            let out = run_one(&mut inp, &mut nets, &opts).with_context(|| format!("fitting {}", frame.display()))?;
            models.push(out.model.clone());
            last = Some(out);
            bar.inc(1);
        }
        bar.finish();
        let model = aggregate_models(&models)?;
        FitOutput { model, plots: last.map(|o| o.plots).unwrap_or_default() }
    } else {
        let image = args.image.as_ref().context("--image or --frames is required")?;
        let mut inp = Loaded {
            image: io::load_rgb(image)?.0,
            denoised: load_opt_rgb(&args.denoised)?,
            motion_deblurred: load_opt_rgb(&args.motion_deblurred)?,
            defocus_deblurred: load_opt_rgb(&args.defocus_deblurred)?,
            depth: g.depth.as_ref().map(|p| io::load_depth(p, g.depth_png_scale)).transpose()?,
            depth_units: g.depth_units.into(),
            flow: g.flow.as_ref().map(|p| io::load_flow(p)).transpose()?,
        };
        run_one(&mut inp, &mut nets, &opts).with_context(|| format!("fitting {}", image.display()))?
    };
    let json = output.model.to_json()?;
    std::fs::write(&args.out, json).with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("wrote {}", args.out.display());
    summarize(&output.model);
    if let Some(dir) = &args.plots {
        write_plots(dir, &output)?;
    }
    Ok(())
}

pub fn summarize(m: &blind_augment::model::CameraModel) {
    let d = &m.noise.diagnostics;
    eprintln!("  noise:          {:<17} {} ({:.1} ms)", d.status_str(), d.reason, d.fit_time_s * 1e3);
    let d = &m.motion_blur.diagnostics;
    eprintln!("  motion blur:    {:<17} {} ({:.1} ms)", d.status_str(), d.reason, d.fit_time_s * 1e3);
    let d = &m.depth_of_field.diagnostics;
    eprintln!("  depth of field: {:<17} {} ({:.1} ms)", d.status_str(), d.reason, d.fit_time_s * 1e3);
    let c = &m.colour;
    let gains = c.gains_or_one();
    eprintln!(
        "  colour:         {:<17} gains R, G, B {:.3}, {:.3}, {:.3}; {} ({:.1} ms)",
        c.diagnostics.status_str(),
        gains[0],
        gains[1],
        gains[2],
        c.diagnostics.reason,
        c.diagnostics.fit_time_s * 1e3
    );
    let v = &m.vignetting;
    let corner = v.applied().map_or(1.0, |a| blind_augment::model::Vignetting::gain_at(a, 1.0));
    eprintln!(
        "  vignetting:     {:<17} corner V {:.3}; {} ({:.1} ms)",
        v.diagnostics.status_str(),
        corner,
        v.diagnostics.reason,
        v.diagnostics.fit_time_s * 1e3
    );
    let c = &m.chromatic_aberration;
    let d = &c.diagnostics;
    eprintln!("  aberration:     {:<17} {} ({:.1} ms)", d.status_str(), d.reason, d.fit_time_s * 1e3);
    let d = &m.sharpening.diagnostics;
    eprintln!("  sharpening:     {:<17} {} ({:.1} ms)", d.status_str(), d.reason, d.fit_time_s * 1e3);
}

pub fn write_plots(dir: &Path, out: &FitOutput) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    if let Some(d) = &out.plots.noise {
        let p = dir.join("noise.png");
        blind_augment::plots::noise_plot(&p, d, &out.model.noise)?;
        eprintln!("wrote {}", p.display());
    }
    if let Some(d) = &out.plots.depth_of_field {
        let p = dir.join("depth_of_field.png");
        blind_augment::plots::dof_plot(&p, d, &out.model.depth_of_field)?;
        eprintln!("wrote {}", p.display());
    }
    if let Some(d) = &out.plots.motion_blur {
        let p = dir.join("motion_blur.png");
        blind_augment::plots::mb_plot(&p, d)?;
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}
