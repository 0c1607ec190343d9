//! White balance on real photographs with a measured illuminant: extracts the
//! colour-constancy corpora from bare git mirrors into `target/bench-colour/`,
//! writes `manifest.tsv` and runs `cargo bench --bench colour` on it (Markdown to
//! `target/bench/colour.md`). Part of `cargo xtask bench-quality MIRRORS`;
//! `--colour-only` runs it alone.
//!
//! Sources (research-use data, not vendored; each row names its camera):
//! * `shuwei666/DMCC-Cross-sensor-color-constancy`: 64×64 linear raw thumbnails
//!   (black level subtracted, max scaled to 1, the colour checker zeroed) with the
//!   checker's illuminant, of Cube+ (Canon 550D), the NUS 8-camera set and
//!   INTEL-TAU (three cameras);
//! * `shuwei666/Color-Constancy-PCC`: Gehler–Shi's 568 in the same form;
//! * `Hal0809/DL-IllumExtractor`: six SimpleCube++ frames at 648×432 (16-bit raw,
//!   black level 2048), the only ones here at more than thumbnail size.
//!
//! The split is by camera and fixed here: `HELD_OUT` cameras are never looked at
//! while choosing or tuning the estimator (only their aggregate is reported).

use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;

const DMCC: &str = "shuwei666/DMCC-Cross-sensor-color-constancy";
const PCC: &str = "shuwei666/Color-Constancy-PCC";
const SIMPLE_CUBE: &str = "Hal0809/DL-IllumExtractor";
/// Held-out cameras: three of NUS's eight, one of INTEL-TAU's three and all of
/// Gehler–Shi (a fourth independent source).
const HELD_OUT: [&str; 5] = ["NUS-Fuji", "NUS-Olympus", "NUS-Panasonic", "TAU_N_D810", "GehlerShi"];

fn mirror(mirrors: &Path, repo: &str) -> Option<std::path::PathBuf> {
    let g = mirrors.join(repo.replace('/', "+")).join("repo");
    if g.exists() {
        Some(g)
    } else {
        eprintln!("colour: no mirror of {repo} at {}", g.display());
        None
    }
}

/// Rows `(camera, image path, label path)` of a DMCC-layout tree under `root`
/// (`<set>/numpy_data/*.npy` beside `<set>/numpy_labels/*.npy`).
fn npy_pairs(git_dir: &Path, root: &str) -> Result<Vec<(String, String, String)>> {
    let listing =
        String::from_utf8(crate::gltf_corpus::git(git_dir, &["ls-tree", "-r", "--name-only", "HEAD", root])?)?;
    let mut rows = vec![];
    for p in listing.lines().filter(|p| p.contains("/numpy_data/") && p.ends_with(".npy")) {
        let set = p.trim_start_matches(root).trim_start_matches('/').split('/').next().unwrap_or("").to_string();
        rows.push((set, p.to_string(), p.replace("/numpy_data/", "/numpy_labels/")));
    }
    Ok(rows)
}

pub fn run_colour(target: &Path, mirrors: &Path) -> Result<Option<String>> {
    let dir = target.join("bench-colour");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut manifest = String::from("# id\tsplit\tcamera\tkind\timage\ttruth\n");
    let mut rows = 0usize;
    let split = |camera: &str| if HELD_OUT.contains(&camera) { "held-out" } else { "tuning" };
    for (repo, root, rename) in [(DMCC, "dataset", None), (PCC, "dataset/CC2018", Some("GehlerShi"))] {
        let Some(git_dir) = mirror(mirrors, repo) else { continue };
        let pairs = npy_pairs(&git_dir, root)?;
        let paths: Vec<&str> = pairs.iter().flat_map(|(_, a, b)| [a.as_str(), b.as_str()]).collect();
        let dest = dir.join(repo.replace('/', "+"));
        let missing = crate::gltf_corpus::extract(&git_dir, &paths, &dest)?;
        for (set, img, label) in &pairs {
            if missing.iter().any(|m| m == img || m == label) {
                continue;
            }
            let camera = rename.unwrap_or(set);
            let id = format!("{camera}/{}", Path::new(img).file_stem().and_then(|s| s.to_str()).unwrap_or("?"));
            writeln!(
                manifest,
                "{id}\t{}\t{camera}\tnpy\t{}\t{}",
                split(camera),
                dest.join(img).display(),
                dest.join(label).display()
            )?;
            rows += 1;
        }
    }
    if let Some(git_dir) = mirror(mirrors, SIMPLE_CUBE) {
        let dest = dir.join("simplecube");
        for part in ["train", "test"] {
            let gt = String::from_utf8(crate::gltf_corpus::git(
                &git_dir,
                &["show", &format!("HEAD:data/SimpleCube++/{part}/gt.csv")],
            )?)?;
            let listing = String::from_utf8(crate::gltf_corpus::git(
                &git_dir,
                &["ls-tree", "-r", "--name-only", "HEAD", &format!("data/SimpleCube++/{part}/PNG")],
            )?)?;
            let pngs: Vec<&str> = listing.lines().filter(|p| p.ends_with(".png")).collect();
            let missing = crate::gltf_corpus::extract(&git_dir, &pngs, &dest)?;
            for png in pngs.iter().filter(|p| !missing.iter().any(|m| m == *p)) {
                let stem = Path::new(png).file_stem().and_then(|s| s.to_str()).unwrap_or("?");
                let Some(line) = gt.lines().find(|l| l.split(',').next() == Some(stem)) else { continue };
                let truth: Vec<&str> = line.split(',').skip(1).collect();
                // SimpleCube++: Canon 550D/600D raw, black level 2048, saturation
                // below 16 384 (the dataset's readme); the checker zeroed.
                writeln!(
                    manifest,
                    "SimpleCube++/{stem}\ttuning\tSimpleCube++\tpng16:2048:15000\t{}\t{}",
                    dest.join(png).display(),
                    truth.join(",")
                )?;
                rows += 1;
            }
        }
    }
    if rows == 0 {
        eprintln!("skipped white balance on real photographs: no colour-constancy mirror");
        return Ok(None);
    }
    std::fs::write(dir.join("manifest.tsv"), &manifest).context("writing manifest.tsv")?;
    eprintln!("{rows} photographs in {}", dir.display());
    std::env::set_var("BENCH_COLOUR", dir.join("manifest.tsv"));
    Ok(Some(crate::cargo(&["bench", "--bench", "colour"])?))
}
