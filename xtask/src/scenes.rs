//! `cargo xtask bench-quality MIRRORS`: calibration on real scenes made elsewhere.
//! Extracts the photographs and their measured depth or disparity from bare git
//! mirrors (`owner+name/repo`, what the project's `fetch` tool brings) into
//! `target/bench-scenes/`, writes `manifest.tsv` (how to read each one's depth), and
//! runs `cargo bench --bench scenes` on them; its Markdown goes to
//! `target/bench/scenes.md`. Each scene names its repository; three tuning scenes
//! are also vendored for the CI subset (`tests/real_scenes.rs`).
//! With a mirror of the PolyU real-world noisy image dataset it first runs `cargo
//! bench --bench real_noise` on its crops (`target/bench/real_noise.md`);
//! `--noise-only` stops there. Before it (not with `--noise-only`), white balance
//! on real photographs with a measured illuminant (`colour_corpus`,
//! `target/bench/colour.md`); `--colour-only` stops after that.
//!
//! The split is fixed here: the `held-out` scenes are never looked at while tuning an
//! estimator (only their aggregate is read, to report it).

use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;

/// How a scene's depth file is read (the bench decodes it; `manifest.tsv` column 6).
/// Middlebury: Z = f·B / (d + doffs) with d = value / `div` px (0: unknown).
#[derive(Clone, Copy)]
enum Depth {
    /// (div, baseline m, disparity offset px at this size, `None`: `dmin.txt` / div).
    Disparity(f32, f32, Option<f32>),
    /// TUM RGB-D: metres = value / 5000 (0: unknown).
    Tum,
    /// SUN RGB-D: the value's bits rotated right by 3, then millimetres.
    Sun,
    /// NYU Depth v2 raw Kinect (little-endian in the PGM): metres = 351.3 / (1092.5 −
    /// value), 2047 none (the NYU toolbox's conversion, as Open3D's
    /// `CreateRGBDImageFromNYUFormat` applies it).
    Nyu,
}

struct SceneDef {
    id: &'static str,
    repo: &'static str,
    image: &'static str,
    depth: &'static str,
    /// Disparity scenes only: the `dmin.txt` holding the crop's disparity offset.
    dmin: Option<&'static str>,
    read: Depth,
    focal_px: f32,
    held_out: bool,
}

/// Middlebury 2005/2006 "third size": f = 3740 / 3 px, B = 160 mm (the datasets'
/// pages). 2006 mirrors carry no `dmin.txt`: its offset is taken as 2005's
/// Laundry/Reindeer value, 230 full-size px (an assumption: it sets the metric scale
/// of the depth, which the sequence's parallax and the truth's δ(Z) then share).
const MB_F_THIRD: f32 = 3740.0 / 3.0;
const MB_B: f32 = 0.16;
const DMIN_2006_THIRD: f32 = 230.0 / 3.0;

macro_rules! mb2006 {
    ($name:literal, $held:expr) => {
        SceneDef {
            id: concat!("middlebury2006-", $name),
            repo: "ibergonzani/patch-match-stereo",
            image: concat!("dataset/", $name, "/view1.png"),
            depth: concat!("dataset/", $name, "/disp1.png"),
            dmin: None,
            read: Depth::Disparity(3.0, MB_B, Some(DMIN_2006_THIRD)),
            focal_px: MB_F_THIRD,
            held_out: $held,
        }
    };
}

macro_rules! mb2005 {
    ($name:literal, $held:expr) => {
        SceneDef {
            id: concat!("middlebury2005-", $name),
            repo: "PRiME-project/PRiMEStereoMatch",
            image: concat!("data/", $name, "/view1.png"),
            depth: concat!("data/", $name, "/disp1.png"),
            dmin: Some(concat!("data/", $name, "/dmin.txt")),
            read: Depth::Disparity(3.0, MB_B, None),
            focal_px: MB_F_THIRD,
            held_out: $held,
        }
    };
}

/// Middlebury 2003 quarter size (disparity = value / 4). Its calibration is not
/// published with the mirror: f and B as 2005's at quarter size, the offset as 2006's
/// (the same assumption).
macro_rules! mb2003 {
    ($name:literal, $img:literal, $disp:literal, $held:expr) => {
        SceneDef {
            id: concat!("middlebury2003-", $name),
            repo: "PRiME-project/PRiMEStereoMatch",
            image: concat!("data/", $name, "/", $img),
            depth: concat!("data/", $name, "/", $disp),
            dmin: None,
            read: Depth::Disparity(4.0, MB_B, Some(230.0 / 4.0)),
            focal_px: 3740.0 / 4.0,
            held_out: $held,
        }
    };
}

/// Every third scene of each source (by name) is held out, and SUN RGB-D whole.
const SCENES: &[SceneDef] = &[
    mb2006!("Aloe", false),
    mb2006!("Baby1", false),
    mb2006!("Baby2", true),
    mb2006!("Baby3", false),
    mb2006!("Bowling1", false),
    mb2006!("Bowling2", true),
    mb2006!("Cloth1", false),
    mb2006!("Cloth2", false),
    mb2006!("Cloth3", true),
    mb2006!("Cloth4", false),
    mb2006!("Flowerpots", false),
    mb2006!("Lampshade1", true),
    mb2006!("Lampshade2", false),
    mb2006!("Midd1", false),
    mb2006!("Midd2", true),
    mb2006!("Monopoly", false),
    mb2006!("Plastic", false),
    mb2006!("Rocks1", true),
    mb2006!("Rocks2", false),
    mb2006!("Wood1", false),
    mb2006!("Wood2", true),
    mb2005!("Art", false),
    mb2005!("Books", false),
    mb2005!("Dolls", true),
    mb2005!("Laundry", false),
    mb2005!("Moebius", false),
    mb2005!("Reindeer", true),
    mb2003!("Cones", "im2.png", "disp2.png", false),
    mb2003!("Teddy", "im2.png", "disp2.png", true),
    SceneDef {
        id: "tum-rgbd",
        repo: "mikiec84/Open3D",
        image: "examples/TestData/RGBD/other_formats/TUM_color.png",
        depth: "examples/TestData/RGBD/other_formats/TUM_depth.png",
        dmin: None,
        read: Depth::Tum,
        // The Kinect's default intrinsics in the TUM RGB-D tools.
        focal_px: 525.0,
        held_out: false,
    },
    SceneDef {
        id: "nyu-depth-v2",
        repo: "mikiec84/Open3D",
        image: "examples/TestData/RGBD/other_formats/NYU_color.ppm",
        depth: "examples/TestData/RGBD/other_formats/NYU_depth.pgm",
        dmin: None,
        read: Depth::Nyu,
        // NYU Depth v2 toolbox's fx_rgb.
        focal_px: 518.86,
        held_out: false,
    },
    SceneDef {
        id: "sun-rgbd",
        repo: "mikiec84/Open3D",
        image: "examples/TestData/RGBD/other_formats/SUN_color.jpg",
        depth: "examples/TestData/RGBD/other_formats/SUN_depth.png",
        dmin: None,
        read: Depth::Sun,
        // SUN RGB-D's Kinect v1 scenes, about 520 px (an assumption: no
        // intrinsics file beside this frame).
        focal_px: 520.0,
        held_out: true,
    },
];

pub fn run(
    target: &Path,
    mirrors: &Path,
    quick: bool,
    noise_only: bool,
    colour_only: bool,
    vignetting_only: bool,
) -> Result<()> {
    let bench = target.join("bench");
    std::fs::create_dir_all(&bench)?;
    if !noise_only && !vignetting_only {
        if let Some(out) = crate::colour_corpus::run_colour(target, mirrors)? {
            std::fs::write(bench.join("colour.md"), out).context("writing target/bench/colour.md")?;
            eprintln!("results in {}", bench.join("colour.md").display());
        }
    }
    if colour_only {
        return Ok(());
    }
    if !vignetting_only {
        if let Some(out) = run_real_noise(target, mirrors)? {
            std::fs::write(bench.join("real_noise.md"), out).context("writing target/bench/real_noise.md")?;
            eprintln!("results in {}", bench.join("real_noise.md").display());
        }
    }
    if noise_only {
        return Ok(());
    }
    let dir = target.join("bench-scenes");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut manifest = String::from("# id\tsplit\tsource\timage\tdepth\tread\tfocal_px\n");
    let mut skipped = vec![];
    for s in SCENES {
        let git_dir = mirrors.join(s.repo.replace('/', "+")).join("repo");
        if !git_dir.exists() {
            skipped.push(format!("{} (no mirror of {} at {})", s.id, s.repo, git_dir.display()));
            continue;
        }
        let dest = dir.join(s.id);
        let mut paths = vec![s.image, s.depth];
        paths.extend(s.dmin);
        let missing = crate::gltf_corpus::extract(&git_dir, &paths, &dest)?;
        if !missing.is_empty() {
            skipped.push(format!("{} ({} lacks {})", s.id, s.repo, missing.join(", ")));
            continue;
        }
        let read = match s.read {
            Depth::Disparity(div, b, offset) => {
                let offset = match (offset, s.dmin) {
                    (Some(o), _) => o,
                    (None, Some(f)) => {
                        let text = std::fs::read_to_string(dest.join(f))?;
                        let dmin: f32 =
                            text.trim().parse().with_context(|| format!("{}: dmin.txt says {text:?}", s.id))?;
                        dmin / div
                    }
                    (None, None) => anyhow::bail!("{}: no disparity offset", s.id),
                };
                format!("disparity:{div}:{b}:{offset}")
            }
            Depth::Tum => "tum".into(),
            Depth::Sun => "sun".into(),
            Depth::Nyu => "nyu".into(),
        };
        let commit = String::from_utf8(crate::gltf_corpus::git(&git_dir, &["rev-parse", "HEAD"])?)?;
        writeln!(
            manifest,
            "{}\t{}\t{}@{}\t{}\t{}\t{read}\t{}",
            s.id,
            if s.held_out { "held-out" } else { "tuning" },
            s.repo,
            &commit.trim()[..12.min(commit.trim().len())],
            dest.join(s.image).display(),
            dest.join(s.depth).display(),
            s.focal_px
        )?;
    }
    for s in &skipped {
        eprintln!("skipped: {s}");
    }
    std::fs::write(dir.join("manifest.tsv"), &manifest).context("writing manifest.tsv")?;
    eprintln!("{} scenes in {}", manifest.lines().count() - 1, dir.display());
    // The bench reads the manifest and the bundled Motorcycle (Middlebury 2014).
    std::env::set_var("BENCH_SCENES", dir.join("manifest.tsv"));
    if quick {
        std::env::set_var("BENCH_SCENES_QUICK", "1");
    }
    if let Some(out) = run_vignetting(target, mirrors)? {
        std::fs::write(bench.join("vignetting.md"), out).context("writing target/bench/vignetting.md")?;
        eprintln!("results in {}", bench.join("vignetting.md").display());
    }
    if vignetting_only {
        return Ok(());
    }
    let out = crate::cargo(&["bench", "--bench", "scenes"])?;
    std::fs::write(bench.join("scenes.md"), out).context("writing target/bench/scenes.md")?;
    eprintln!("results in {}", bench.join("scenes.md").display());
    Ok(())
}

/// The lens database with measured vignetting profiles (lensfun's `data/db`).
const LENSFUN_REPO: &str = "lensfun/lensfun";

/// Extracts lensfun's database XML into `target/bench-lensfun/` and runs `cargo
/// bench --bench chromatic`, then `--bench vignetting` on the scenes already in
/// `BENCH_SCENES`; `None` without the mirror.
fn run_vignetting(target: &Path, mirrors: &Path) -> Result<Option<String>> {
    let git_dir = mirrors.join(LENSFUN_REPO.replace('/', "+")).join("repo");
    if !git_dir.exists() {
        eprintln!("skipped vignetting: no mirror of {LENSFUN_REPO} at {}", git_dir.display());
        return Ok(None);
    }
    let dir = target.join("bench-lensfun");
    let _ = std::fs::remove_dir_all(&dir);
    let listing =
        String::from_utf8(crate::gltf_corpus::git(&git_dir, &["ls-tree", "-r", "--name-only", "HEAD", "data/db"])?)?;
    let files: Vec<&str> = listing.lines().filter(|p| p.ends_with(".xml")).collect();
    let missing = crate::gltf_corpus::extract(&git_dir, &files, &dir)?;
    if !missing.is_empty() {
        eprintln!("lensfun: {} files missing from the mirror", missing.len());
    }
    let commit = String::from_utf8(crate::gltf_corpus::git(&git_dir, &["rev-parse", "HEAD"])?)?;
    eprintln!("lensfun {} ({} files) in {}", &commit.trim()[..12.min(commit.trim().len())], files.len(), dir.display());
    std::env::set_var("BENCH_LENSFUN", dir.join("data/db"));
    // Lateral chromatic aberration on the same database's TCA profiles (the vendored
    // photographs; seconds), then vignetting on the scenes.
    let mut out = crate::cargo(&["bench", "--bench", "chromatic"])?;
    out += "\n";
    out += &crate::cargo(&["bench", "--bench", "vignetting"])?;
    Ok(Some(out))
}

/// The PolyU real-world noisy image dataset's held-out scenes (camera_ISO_scene, as
/// its crops are named): every third of the 29 in sorted order, fixed here. Their
/// crops are only ever reported in aggregate.
const REAL_NOISE_HELD_OUT: &[&str] = &[
    "Canon5D2_3200_plug",
    "Canon5D2_6400_circuit",
    "Canon600D_1600_book",
    "Canon80D_12800_printer",
    "Canon80D_800_GO",
    "NikonD800_4000_flower",
    "NikonD800_6400_photo",
    "NikonD800_6400_wall",
    "Sony_3200_door",
];

/// The repository of real camera noise with a multi-shot reference (Xu et al. 2018).
const REAL_NOISE_REPO: &str = "csjunxu/PolyU-Real-World-Noisy-Images-Dataset";

/// Extracts the PolyU crops (each `*_real.JPG` shot with its `*_mean.JPG`) into
/// `target/bench-real-noise/`, writes `manifest.tsv` and runs `cargo bench --bench
/// real_noise`; `None` without the mirror.
pub fn run_real_noise(target: &Path, mirrors: &Path) -> Result<Option<String>> {
    let git_dir = mirrors.join(REAL_NOISE_REPO.replace('/', "+")).join("repo");
    if !git_dir.exists() {
        eprintln!("skipped real camera noise: no mirror of {REAL_NOISE_REPO} at {}", git_dir.display());
        return Ok(None);
    }
    let dir = target.join("bench-real-noise");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let listing = String::from_utf8(crate::gltf_corpus::git(
        &git_dir,
        &["ls-tree", "-r", "--name-only", "HEAD", "CroppedImages"],
    )?)?;
    let shots: Vec<&str> = listing.lines().filter(|p| p.ends_with("_real.JPG")).collect();
    let mut paths = vec![];
    for s in &shots {
        paths.push(s.to_string());
        paths.push(s.replace("_real.JPG", "_mean.JPG"));
    }
    let refs: Vec<&str> = paths.iter().map(|s| s.as_str()).collect();
    let missing = crate::gltf_corpus::extract(&git_dir, &refs, &dir)?;
    let mut manifest = String::from("# id\tsplit\tshot\tmean\n");
    let mut held = 0;
    for s in &shots {
        let mean = s.replace("_real.JPG", "_mean.JPG");
        if missing.iter().any(|m| m == s || *m == mean) {
            eprintln!("skipped {s}: not in the mirror");
            continue;
        }
        // Canon5D2_5_160_3200_chair_11_real.JPG: camera, aperture, shutter, ISO, scene, crop.
        let name = s.trim_start_matches("CroppedImages/").trim_end_matches("_real.JPG");
        let f: Vec<&str> = name.split('_').collect();
        let scene = match f[..] {
            [camera, _, _, iso, scene, ..] => format!("{camera}_{iso}_{scene}"),
            _ => anyhow::bail!("{s}: not named camera_aperture_shutter_ISO_scene_crop"),
        };
        let held_out = REAL_NOISE_HELD_OUT.contains(&scene.as_str());
        held += held_out as usize;
        writeln!(
            manifest,
            "{name}\t{}\t{}\t{}",
            if held_out { "held-out" } else { "tuning" },
            dir.join(s).display(),
            dir.join(&mean).display()
        )?;
    }
    std::fs::write(dir.join("manifest.tsv"), &manifest).context("writing manifest.tsv")?;
    eprintln!("{} crops ({held} held out) in {}", manifest.lines().count() - 1, dir.display());
    std::env::set_var("BENCH_REAL_NOISE", dir.join("manifest.tsv"));
    Ok(Some(crate::cargo(&["bench", "--bench", "real_noise"])?))
}
