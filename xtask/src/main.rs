//! Project automation in Rust (`cargo xtask <command>`), so developers need nothing
//! but cargo: `bench` runs every benchmark (fit speed, speed/accuracy trade, GPU
//! passes) and keeps the raw output for BENCHMARKS.md; `assets` regenerates the
//! bundled glTF object. CI is `.ci/run` alone, the
//! one definition of the checks.

mod assets;

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."))
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
    let dir = root().join("target/bench");
    std::fs::create_dir_all(&dir).context("creating target/bench")?;
    let quality = cargo(&["bench", "--bench", "quality"])?;
    std::fs::write(dir.join("quality.md"), quality).context("writing target/bench/quality.md")?;
    let fit = cargo(&["bench", "--bench", "fit"])?;
    std::fs::write(dir.join("fit.txt"), fit).context("writing target/bench/fit.txt")?;
    let gpu = cargo(&["bench", "--bench", "gpu"])?;
    std::fs::write(dir.join("gpu.md"), gpu).context("writing target/bench/gpu.md")?;
    let frame = cargo(&["bench", "--bench", "frame"])?;
    std::fs::write(dir.join("frame.md"), frame).context("writing target/bench/frame.md")?;
    eprintln!("raw results in {}; copy the figures into BENCHMARKS.md", dir.display());
    Ok(())
}

fn main() -> Result<()> {
    match std::env::args().nth(1).as_deref() {
        Some("bench") => bench(),
        Some("assets") => assets::generate(&root()),
        other => bail!("usage: cargo xtask bench | assets (got {other:?})"),
    }
}
