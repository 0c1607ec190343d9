//! Project automation in Rust (`cargo xtask <command>`), so developers need nothing
//! but cargo: `bench` runs every benchmark (fit speed, speed/accuracy trade, GPU
//! passes) and keeps the raw output for BENCHMARKS.md; `assets` regenerates the
//! bundled glTF object; `xr-runtime` builds the headless OpenXR test runtime and
//! prints its manifest's path (for `XR_RUNTIME_JSON`); `apk` builds, signs and
//! checks the Quest APK without the NDK (apk.rs), `install` puts it on a headset;
//! `train-models` trains the shipped ONNX models (models.rs); `gltf-corpus` runs the
//! glTF loader over other projects' files (gltf_corpus.rs). CI is `.ci/run` alone, the
//! one definition of the checks.

mod apk;
mod assets;
mod colour_corpus;
mod gltf_corpus;
mod models;
mod scenes;

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."))
}

/// Where cargo puts what it builds: `CARGO_TARGET_DIR` when set (a relative one is
/// read from the directory the builds run in, the workspace root: see `cargo`),
/// else `<workspace>/target`.
fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR").filter(|v| !v.is_empty()) {
        Some(dir) => {
            let dir = PathBuf::from(dir);
            if dir.is_absolute() {
                dir
            } else {
                root().join(dir)
            }
        }
        None => root().join("target"),
    }
}

fn cargo(args: &[&str]) -> Result<String> {
    eprintln!("$ cargo {}", args.join(" "));
    let out = Command::new(env!("CARGO"))
        .args(args)
        .current_dir(root())
        .stderr(std::process::Stdio::inherit())
        .output()
        .with_context(|| format!("running cargo {}", args.join(" ")))?;
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    print!("{stdout}");
    if !out.status.success() {
        bail!("cargo {} failed with {}", args.join(" "), out.status);
    }
    Ok(stdout)
}

fn bench() -> Result<()> {
    let dir = target_dir().join("bench");
    std::fs::create_dir_all(&dir).context("creating target/bench")?;
    let quality = cargo(&["bench", "--bench", "quality"])?;
    std::fs::write(dir.join("quality.md"), quality).context("writing target/bench/quality.md")?;
    let fit = cargo(&["bench", "--bench", "fit"])?;
    std::fs::write(dir.join("fit.txt"), fit).context("writing target/bench/fit.txt")?;
    let gpu = cargo(&["bench", "--bench", "gpu"])?;
    std::fs::write(dir.join("gpu.md"), gpu).context("writing target/bench/gpu.md")?;
    let frame = cargo(&["bench", "--bench", "frame"])?;
    std::fs::write(dir.join("frame.md"), frame).context("writing target/bench/frame.md")?;
    // Live calibration per tier (also writes benches/results/calibration_pareto.png).
    let calibration = cargo(&["bench", "--bench", "calibration"])?;
    std::fs::write(dir.join("calibration.md"), calibration).context("writing target/bench/calibration.md")?;
    std::fs::write(dir.join("xr.txt"), xr_bench()?).context("writing target/bench/xr.txt")?;
    eprintln!("raw results in {}; copy the figures into BENCHMARKS.md", dir.display());
    Ok(())
}

/// Build `tests/xr-runtime` and write its loader manifest next to the library
/// (the Khronos loader reads `library_path` from it; an absolute path, so the
/// manifest works from any directory). Prints the manifest's path on stdout.
fn xr_runtime(release: bool) -> Result<()> {
    let mut args = vec!["build", "-p", "ba-xr-runtime"];
    if release {
        args.push("--release");
    }
    cargo(&args)?;
    let dir = target_dir().join(if release { "release" } else { "debug" });
    let lib = dir.join("libba_xr_runtime.so");
    anyhow::ensure!(lib.exists(), "{} was not built", lib.display());
    let template = std::fs::read_to_string(root().join("tests/xr-runtime/runtime.json.in"))
        .context("reading tests/xr-runtime/runtime.json.in")?;
    let lib_json = serde_json::to_string(&lib.display().to_string()).context("encoding the library path")?;
    let manifest = dir.join("ba_xr_runtime.json");
    std::fs::write(&manifest, template.replace("\"@LIB@\"", &lib_json))
        .with_context(|| format!("writing {}", manifest.display()))?;
    println!("{}", manifest.display());
    eprintln!("use it with: export XR_RUNTIME_JSON={}", manifest.display());
    Ok(())
}

/// CPU time per XR frame and the share of the loop spent in xrWaitFrame: the
/// release binary's `xr` command on the release test runtime (90 Hz display,
/// passthrough by ALPHA_BLEND; without and with space warp), at a small eye buffer (the loop's own cost) and at
/// Quest 3's recommended eye size (the loop with the render core's GPU work; on
/// lavapipe that work runs on the same CPU cores).
fn xr_bench() -> Result<String> {
    xr_runtime(true)?;
    cargo(&["build", "--release", "--bin", "blind-augment"])?;
    let manifest = target_dir().join("release/ba_xr_runtime.json");
    let bin = target_dir().join("release/blind-augment");
    let mut out = String::new();
    for (eye, extensions) in [
        ("256x256", "passthrough,refresh_rate"),
        ("256x256", "passthrough,refresh_rate,space_warp"),
        ("1680x1760", "passthrough,refresh_rate"),
        ("1680x1760", "passthrough,refresh_rate,space_warp"),
    ] {
        eprintln!("$ blind-augment xr --frames 300 (eye {eye}, runtime offers {extensions})");
        let run = Command::new(&bin)
            .args(["xr", "--frames", "300"])
            .env("XR_RUNTIME_JSON", &manifest)
            .env("BA_XR_EYE_SIZE", eye)
            .env("BA_XR_BLEND_MODES", "opaque,alpha_blend")
            .env("BA_XR_EXTENSIONS", extensions)
            .output()
            .context("running blind-augment xr")?;
        let text = String::from_utf8_lossy(&run.stdout);
        if !run.status.success() {
            bail!("blind-augment xr failed at {eye}: {}{}", text, String::from_utf8_lossy(&run.stderr));
        }
        out.push_str(&format!("## eye {eye}, runtime offers {extensions}, 300 frames\n{text}\n"));
    }
    print!("{out}");
    Ok(out)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("bench") => bench(),
        Some("assets") => assets::generate(&root()),
        Some("xr-runtime") => xr_runtime(args.iter().any(|a| a == "--release")),
        Some("bench-xr") => xr_bench().map(|_| ()),
        Some("apk") => apk::apk(&root(), args.iter().any(|a| a == "--release")).map(|_| ()),
        Some("install") => apk::install(&root(), args.iter().any(|a| a == "--release")),
        Some("pull-recording") => apk::pull_recording(&root(), args.get(1).map(Path::new)),
        Some("train-models") => models::train(&root()),
        Some("gltf-corpus") => match args.get(1) {
            Some(dir) => {
                let validator = args.iter().position(|a| a == "--validator").and_then(|i| args.get(i + 1));
                gltf_corpus::run(&root(), &target_dir(), Path::new(dir), validator.map(Path::new))
            }
            None => bail!(
                "usage: cargo xtask gltf-corpus MIRRORS [--validator NODE_MODULES] (bare git mirrors as \
                 owner+name/repo; NODE_MODULES: where `npm install gltf-validator` was run)"
            ),
        },
        Some("bench-quality") => match args.get(1).filter(|a| !a.starts_with("--")) {
            Some(dir) => scenes::run(
                &target_dir(),
                Path::new(dir),
                args.iter().any(|a| a == "--quick"),
                args.iter().any(|a| a == "--noise-only"),
                args.iter().any(|a| a == "--colour-only"),
                args.iter().any(|a| a == "--vignetting-only"),
            ),
            None => bail!("usage: cargo xtask bench-quality MIRRORS [--quick] [--noise-only] [--colour-only] [--vignetting-only] (bare git mirrors as owner+name/repo)"),
        },
        other => bail!("usage: cargo xtask bench | bench-xr | assets | xr-runtime [--release] | apk [--release] | install [--release] | pull-recording [DEST] | train-models | gltf-corpus MIRRORS [--validator DIR] | bench-quality MIRRORS [--quick] [--noise-only] [--colour-only] [--vignetting-only] (got {other:?}; `bench-xr` runs the XR part of bench alone)"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Builds land where cargo puts them: CARGO_TARGET_DIR when set (a relative one
    /// from the workspace root, where `cargo` runs the builds), else `target/`.
    #[test]
    fn target_dir_follows_cargo_target_dir() {
        // SAFETY (set_var): the only test in this binary reading the variable.
        let before = std::env::var_os("CARGO_TARGET_DIR");
        std::env::set_var("CARGO_TARGET_DIR", "/tmp/elsewhere");
        assert_eq!(target_dir(), PathBuf::from("/tmp/elsewhere"));
        std::env::set_var("CARGO_TARGET_DIR", "build/out");
        assert_eq!(target_dir(), root().join("build/out"));
        std::env::remove_var("CARGO_TARGET_DIR");
        assert_eq!(target_dir(), root().join("target"));
        if let Some(v) = before {
            std::env::set_var("CARGO_TARGET_DIR", v);
        }
    }
}
