//! Desktop CLI: `fit`, `synth`, `demo`, `render`, `xr`, `calibrate`, `synth-video`. Parses arguments,
//! loads files, calls the library, writes results. Errors carry the file and the
//! problem (anyhow context).

mod calibrate_cmd;
mod camera_feed;
mod demo;
mod fit_cmd;
mod render_cmd;
mod scene_cmd;
mod xr_cmd;

use anyhow::{Context, Result};
use blind_augment::fit::{Effects, Tier};
use blind_augment::model::DepthUnits;
use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "blind-augment",
    version,
    about = "Blindly fit a camera's noise, motion blur and depth of field, and apply them"
)]
struct Cli {
    /// Worker threads (default: all cores). 1 = single-threaded.
    #[arg(long, global = true)]
    threads: Option<usize>,
    #[command(subcommand)]
    cmd: Command,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum TierArg {
    Fast,
    Accurate,
}

#[derive(Clone, Copy, ValueEnum, PartialEq)]
pub enum EffectArg {
    Noise,
    MotionBlur,
    DepthOfField,
    /// White balance and exposure (`model::Colour`).
    Colour,
    /// The lens's falloff (`model::Vignetting`; `calibrate` with poses and metric
    /// depth only: it needs the same surfaces seen at two image radii).
    Vignetting,
    /// The lens's lateral chromatic aberration (`model::ChromaticAberration`;
    /// `calibrate` only: it pools several frames' fringes).
    ChromaticAberration,
    /// The ISP's edge sharpening (`model::Sharpening`; `fit` reads one frame's
    /// straight edges, `calibrate` pools 8 s of frames).
    Sharpening,
}

/// Whether `--only` asks for the sharpening term (all effects without it).
pub fn sharpening_wanted(only: &Option<Vec<EffectArg>>) -> bool {
    only.as_ref().map_or(true, |l| l.contains(&EffectArg::Sharpening))
}

/// Whether `--only` asks for the aberration term (all effects without it).
pub fn chromatic_wanted(only: &Option<Vec<EffectArg>>) -> bool {
    only.as_ref().map_or(true, |l| l.contains(&EffectArg::ChromaticAberration))
}

/// Whether `--only` asks for the vignetting term (all effects without it).
pub fn vignetting_wanted(only: &Option<Vec<EffectArg>>) -> bool {
    only.as_ref().map_or(true, |l| l.contains(&EffectArg::Vignetting))
}

/// Whether `--only` asks for the colour term (all effects without it).
pub fn colour_wanted(only: &Option<Vec<EffectArg>>) -> bool {
    only.as_ref().map_or(true, |l| l.contains(&EffectArg::Colour))
}

#[derive(Clone, Copy, ValueEnum)]
pub enum DepthUnitsArg {
    /// Metric depth in metres.
    MetricM,
    /// Relative inverse depth (disparity, MiDaS/DPT output): larger = nearer.
    RelativeInverse,
}

impl From<DepthUnitsArg> for DepthUnits {
    fn from(d: DepthUnitsArg) -> Self {
        match d {
            DepthUnitsArg::MetricM => DepthUnits::MetricM,
            DepthUnitsArg::RelativeInverse => DepthUnits::RelativeInverse,
        }
    }
}

/// `--onnx ROLE=PATH` flags, parsed: each role at most once.
pub fn parse_onnx(flags: &[String]) -> anyhow::Result<Vec<(blind_augment::analysis::Role, PathBuf)>> {
    use blind_augment::analysis::Role;
    let mut out: Vec<(Role, PathBuf)> = vec![];
    for f in flags {
        let (role, path) = f.split_once('=').with_context(|| format!("--onnx `{f}`: expected ROLE=PATH"))?;
        let names: Vec<&str> = Role::ALL.iter().map(|r| r.name()).collect();
        let role = Role::parse(role.trim())
            .with_context(|| format!("--onnx `{f}`: unknown role `{role}` (roles: {})", names.join(", ")))?;
        anyhow::ensure!(!path.is_empty(), "--onnx `{f}`: the path is empty");
        anyhow::ensure!(out.iter().all(|(r, _)| *r != role), "--onnx: role `{}` given twice", role.name());
        out.push((role, PathBuf::from(path)));
    }
    Ok(out)
}

#[derive(clap::Args, Clone)]
pub struct DepthArgs {
    /// Depth map: PFM, 16-bit PNG or .npy (H×W). Non-finite or ≤ 0 values are invalid.
    #[arg(long)]
    depth: Option<PathBuf>,
    /// How to read depth values.
    #[arg(long, value_enum, default_value = "metric-m")]
    depth_units: DepthUnitsArg,
    /// Scale applied to 16-bit PNG depth values (0.001: millimetres to metres).
    #[arg(long, default_value_t = 0.001)]
    depth_png_scale: f32,
    /// Flow: Middlebury .flo or .npy (H×W×2, x then y), pixels per frame interval.
    #[arg(long)]
    flow: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct FitArgs {
    /// The frame to fit (PNG/JPEG 8/16-bit, PFM, .npy).
    #[arg(long, required_unless_present = "frames")]
    image: Option<PathBuf>,
    /// Fit every image in this folder and aggregate robustly (references, depth and
    /// flow must then be folders holding files with the same stems).
    #[arg(long, conflicts_with = "image")]
    frames: Option<PathBuf>,
    /// I with noise removed (enables the accurate noise fit).
    #[arg(long)]
    denoised: Option<PathBuf>,
    /// I with motion blur removed (enables the accurate exposure fit).
    #[arg(long)]
    motion_deblurred: Option<PathBuf>,
    /// I with defocus removed (enables the accurate δ(Z) fit).
    #[arg(long)]
    defocus_deblurred: Option<PathBuf>,
    #[command(flatten)]
    geometry: DepthArgs,
    /// Effects to fit (comma-separated); the others are written as not fitted.
    #[arg(long, value_enum, value_delimiter = ',')]
    only: Option<Vec<EffectArg>>,
    /// Force a tier; by default accurate where a reference is given, fast elsewhere.
    #[arg(long, value_enum)]
    tier: Option<TierArg>,
    /// Fast tier: the share of the blind exposure and defocus fits' sample counts
    /// read, 0.25–1 (speed for accuracy: BENCHMARKS.md "The fast tier's effort").
    #[arg(long, default_value_t = 1.0)]
    fast_effort: f32,
    /// Replace a role's provider by an ONNX model (repeatable): ROLE is denoise,
    /// depth, flow, motion-deblur or defocus-deblur; the model must meet the role's
    /// contract (docs/calibration.md, "Your own networks").
    #[arg(long = "onnx", value_name = "ROLE=PATH")]
    onnx: Vec<String>,
    /// Output camera model (JSON).
    #[arg(long)]
    out: PathBuf,
    /// Write PNG plots of the fits into this folder.
    #[arg(long)]
    plots: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct SynthArgs {
    /// Clean image to distort.
    #[arg(long)]
    image: PathBuf,
    /// Camera model (JSON) to apply.
    #[arg(long)]
    camera: PathBuf,
    #[command(flatten)]
    geometry: DepthArgs,
    /// Noise seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output: PNG/JPEG (16-bit input stays 16-bit), or .npy/.pfm float32 (no clipping).
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
}

#[derive(clap::Args)]
pub struct RenderArgs {
    /// glTF 2.0 scene: `.glb`, or `.gltf` with its buffers and images beside it or in `data:` URIs.
    #[arg(long)]
    scene: PathBuf,
    /// Folder of background frames (PNG/JPEG, sorted by name; camera frames).
    #[arg(long)]
    background: PathBuf,
    /// Camera model (JSON) to match.
    #[arg(long)]
    camera: PathBuf,
    /// Output folder: naive_NNN.png and matched_NNN.png (left | right eye).
    #[arg(long)]
    out: PathBuf,
    /// Eye-buffer size per eye, WxH (default: the background's size).
    #[arg(long)]
    eye_size: Option<String>,
    /// The background camera's focal length in its pixels (default: the model's
    /// pixels_per_radian).
    #[arg(long)]
    focal_px: Option<f32>,
    /// Distance from the eyes to the object (m).
    #[arg(long, default_value_t = 1.5)]
    object_depth_m: f32,
}

#[derive(clap::Args)]
pub struct XrArgs {
    /// Request exit after this many rendered frames (default: run until the
    /// runtime ends the session).
    #[arg(long)]
    frames: Option<u64>,
    /// Camera model JSON (default: a placeholder Quest 3-like model until
    /// calibration publishes one).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// glTF 2.0 scene, `.glb` or `.gltf` (default: the bundled assets/toy.glb).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// A folder of more glTF scenes the next-scene button cycles through after
    /// the first (each loaded when asked for; one that fails is named and skipped).
    #[arg(long)]
    scenes: Option<PathBuf>,
    /// Distance from the start head pose to the object (m).
    #[arg(long, default_value_t = 1.5)]
    object_depth_m: f32,
    /// Display refresh rate to request (XR_FB_display_refresh_rate), Hz.
    #[arg(long, default_value_t = 90.0)]
    display_hz: f32,
    /// Enable the OpenXR core validation layer and the Vulkan validation layer
    /// (where installed); any Vulkan validation message fails the run.
    #[arg(long)]
    validation: bool,
    /// Show the status panel from the start (the left trigger toggles it).
    #[arg(long)]
    panel: bool,
    /// Camera frames for live calibration (`calibrate`'s input layout: a recording
    /// or `synth-video`'s output), fed to the calibration worker in real time at
    /// their own times as the headset's camera would; the loop renders with the
    /// models it publishes and exits when the frames end (unless --frames ends it
    /// first).
    #[arg(long)]
    camera_frames: Option<PathBuf>,
    /// With --camera-frames: poses.csv (world_from_camera per frame) …
    #[arg(long, requires = "camera_frames")]
    poses: Option<PathBuf>,
    /// … and the frames' pinhole intrinsics fx,fy,cx,cy (px).
    #[arg(long, requires = "camera_frames")]
    intrinsics: Option<String>,
    /// With --camera-frames: depth and flow folders named like the frames.
    #[command(flatten)]
    geometry: DepthArgs,
    /// The camera's frame rate where --poses gives no times (and the nominal frame
    /// interval).
    #[arg(long, default_value_t = 30.0)]
    camera_fps: f32,
    /// Live calibration tier: fast (the headset's), balanced or accurate.
    #[arg(long, default_value = "fast")]
    tier: String,
    /// Record what the calibration worker takes into this new folder (frames,
    /// depth, poses, intrinsics, the published models, manifest.json), in
    /// `calibrate`'s input layout.
    #[arg(long, requires = "camera_frames")]
    record: Option<PathBuf>,
    /// Stop recording after this much video (s).
    #[arg(long, default_value_t = 10.0)]
    record_s: f64,
    /// Stop recording when the disk has less than this free (MiB).
    #[arg(long, default_value_t = 512)]
    record_min_free_mib: u64,
}

#[derive(clap::Args)]
pub struct CalibrateArgs {
    /// Folder of frames (PNG/JPEG/PFM/.npy), in name order. Frame numbers: where
    /// every file name is a number (`000123.png`, as recordings and synth-video
    /// write them) that number, gaps kept; else the position in name order. A
    /// frame numbered n is row `frame = n` of --poses.
    #[arg(long)]
    frames: PathBuf,
    /// --depth and --flow: folders of files named like the frames (depth: PFM,
    /// 16-bit PNG scaled by --depth-png-scale, .npy, read as --depth-units; flow
    /// instead of flow from poses and depth).
    #[command(flatten)]
    geometry: DepthArgs,
    /// poses.csv: `frame,t_s,tx,ty,tz,qx,qy,qz,qw`, world_from_camera, camera in
    /// OpenCV axes (x right, y down, z forward), metres, t_s = middle of exposure.
    #[arg(long)]
    poses: Option<PathBuf>,
    /// Pinhole intrinsics in pixels of the frames: fx,fy,cx,cy (with --poses).
    #[arg(long)]
    intrinsics: Option<String>,
    /// With --depth: a frame without a depth file goes without depth (a
    /// recording's frames the headset had no depth for) instead of an error.
    #[arg(long)]
    depth_optional: bool,
    /// Every pose tracked, `t_s,tx,ty,tz,qx,qy,qz,qw` (a recording's
    /// pose_track.csv): the calibrator gets these instead of --poses' rows, each
    /// once the frame 2.5 frame intervals before it is read; --poses still gives
    /// the frames' times.
    #[arg(long)]
    pose_track: Option<PathBuf>,
    /// fast (the frame alone, every frame) | balanced | accurate (video as its own
    /// reference).
    #[arg(long, default_value = "accurate")]
    tier: String,
    /// The blind fits' share of their sample counts, 0.25–1 (speed for accuracy:
    /// BENCHMARKS.md "The fast tier's effort").
    #[arg(long, default_value_t = 1.0)]
    fast_effort: f32,
    /// Replace a role's provider by an ONNX model (repeatable): ROLE is denoise,
    /// depth, flow, motion-deblur or defocus-deblur; the model must meet the role's
    /// contract (docs/calibration.md, "Your own networks").
    #[arg(long = "onnx", value_name = "ROLE=PATH")]
    onnx: Vec<String>,
    /// Frame rate when --poses does not give times (and the nominal frame interval).
    #[arg(long, default_value_t = 30.0)]
    fps: f32,
    /// Effects to calibrate (comma-separated).
    #[arg(long, value_enum, value_delimiter = ',')]
    only: Option<Vec<EffectArg>>,
    /// The last published camera model (JSON).
    #[arg(long)]
    out: PathBuf,
    /// Every published model, one JSON object per line: {"frame", "t_s", "model"}.
    #[arg(long)]
    timeline: Option<PathBuf>,
    /// timeline.png: each parameter over video time, the frames fitted, the truth.
    #[arg(long)]
    plots: Option<PathBuf>,
    /// Known truth (a timeline file, as `synth-video` writes): errors are reported.
    #[arg(long)]
    truth: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct SynthVideoArgs {
    /// Output folder (frames/, depth/, flow/, poses.csv, intrinsics.txt, truth.jsonl).
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = 90)]
    frames: usize,
    /// Frame size WxH (the field of view is the same at every size).
    #[arg(long, default_value = "320x240")]
    size: String,
    /// The camera changes (exposure halves, gain ×1.5) at this video time (s).
    #[arg(long)]
    change_at_s: Option<f64>,
}

#[derive(Subcommand)]
enum Command {
    /// Fit a camera model to a frame (or a folder of frames).
    Fit(FitArgs),
    /// Apply a camera model to a clean image (DoF → MB → noise).
    Synth(SynthArgs),
    /// Self-contained demo on an embedded photograph with known distortions:
    /// distorts, fits (accurate and fast tiers), writes plots and a report.
    Demo(DemoArgs),
    /// Render a glTF object over a background sequence, naive and matched to a
    /// camera model (stereo, Vulkan).
    Render(RenderArgs),
    /// Run the OpenXR frame loop on the active runtime (a headset's, or on desktop
    /// the test runtime: XR_RUNTIME_JSON from `cargo xtask xr-runtime`).
    Xr(XrArgs),
    /// Calibrate from a recorded sequence with the worker's loop (frames, depth,
    /// poses): the last model, a timeline of every published one, plots.
    Calibrate(CalibrateArgs),
    /// Write a recorded sequence with known truth (the bundled photograph along a
    /// head path; an optional mid-sequence camera change).
    SynthVideo(SynthVideoArgs),
    /// Check glTF files: what each would draw, or why it is refused.
    Scene(scene_cmd::SceneArgs),
}

pub fn parse_size(s: &str) -> Result<(usize, usize)> {
    let (w, h) = render_cmd::parse_size(s)?;
    Ok((w as usize, h as usize))
}

pub fn effects(only: &Option<Vec<EffectArg>>) -> Effects {
    match only {
        None => Effects::ALL,
        Some(list) => Effects {
            noise: list.contains(&EffectArg::Noise),
            motion_blur: list.contains(&EffectArg::MotionBlur),
            depth_of_field: list.contains(&EffectArg::DepthOfField),
        },
    }
}

pub fn tier(t: Option<TierArg>) -> Option<Tier> {
    t.map(|t| match t {
        TierArg::Fast => Tier::Fast,
        TierArg::Accurate => Tier::Accurate,
    })
}

fn synth(args: SynthArgs) -> Result<()> {
    let (img, depth_bits) = blind_augment::io::load_rgb(&args.image)?;
    let text = std::fs::read_to_string(&args.camera).with_context(|| format!("reading {}", args.camera.display()))?;
    let model = blind_augment::model::CameraModel::from_json(&text)
        .with_context(|| format!("camera model {}", args.camera.display()))?;
    let g = &args.geometry;
    let depth = g.depth.as_ref().map(|p| blind_augment::io::load_depth(p, g.depth_png_scale)).transpose()?;
    let flow = g.flow.as_ref().map(|p| blind_augment::io::load_flow(p)).transpose()?;
    for (name, w, h) in [
        ("depth", depth.as_ref().map(|d| d.width), depth.as_ref().map(|d| d.height)),
        ("flow", flow.as_ref().map(|f| f.width), flow.as_ref().map(|f| f.height)),
    ] {
        if let (Some(w), Some(h)) = (w, h) {
            anyhow::ensure!(
                w == img.width && h == img.height,
                "{name} is {w}×{h} but {} is {}×{}",
                args.image.display(),
                img.width,
                img.height
            );
        }
    }
    if model.depth_of_field.present && depth.is_none() {
        anyhow::bail!("the camera model has depth of field but no --depth was given");
    }
    if model.motion_blur.present && flow.is_none() {
        anyhow::bail!("the camera model has motion blur but no --flow was given");
    }
    let out = blind_augment::synth::apply_camera_model(&img, &model, depth.as_ref(), flow.as_ref(), args.seed);
    blind_augment::io::save_rgb(&args.out, &out, depth_bits)?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

pub fn main() -> std::process::ExitCode {
    // The library reports its fallbacks through `log` (e.g. "OpenXR: no passthrough
    // …"): warnings and errors on stderr unless RUST_LOG says otherwise.
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    // Before any frame-sized allocation (see `blind_augment::alloc`).
    let kept = blind_augment::alloc::keep_freed_blocks();
    if let blind_augment::alloc::AllocTuning::Refused(param) = kept {
        eprintln!("warning: the C allocator refused {param}: fits will page-fault their planes afresh each call");
    }
    let cli = Cli::parse();
    // `fit`: one fit per process, so its first touches are most of its memory
    // traffic: huge pages, one arena (before the thread pool starts; see
    // `blind_augment::alloc::huge_heap_one_arena`). Not `calibrate`: over a
    // sequence it is warm after the first updates, and measured no faster.
    if matches!(cli.cmd, Command::Fit(_)) && kept == blind_augment::alloc::AllocTuning::Applied {
        if let blind_augment::alloc::AllocTuning::Refused(what) = blind_augment::alloc::huge_heap_one_arena() {
            log::info!("the C allocator refused {what}: first touches stay in 4 KiB pages");
        }
    }
    if let Some(n) = cli.threads {
        if let Err(e) = rayon::ThreadPoolBuilder::new().num_threads(n.max(1)).build_global() {
            eprintln!("error: cannot set up {n} threads: {e}");
            return std::process::ExitCode::FAILURE;
        }
    }
    let res = match cli.cmd {
        Command::Fit(a) => fit_cmd::run(a),
        Command::Synth(a) => synth(a),
        Command::Demo(a) => demo::run(a),
        Command::Render(a) => render_cmd::run(a),
        Command::Xr(a) => xr_cmd::run(a),
        Command::Calibrate(a) => calibrate_cmd::run(a),
        Command::SynthVideo(a) => calibrate_cmd::synth_video(a),
        Command::Scene(a) => scene_cmd::run(a),
    };
    match res {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
