//! `cargo xtask train-models`: trains the project's own ONNX models (no registry
//! reachable here ships depth, flow or denoise weights) and exports them into
//! `assets/models/`, where they are committed. Steps:
//!
//! 1. a Python venv under `target/train-models/venv` (git-ignored; never in CI) with
//!    pinned PyTorch, onnx and NumPy from PyPI (CPU; ~2 minutes the first time);
//! 2. training data made by the project's own `synth` from the bundled real
//!    photographs (`examples/train_data.rs`), seeded;
//! 3. training and export per model (`xtask/train/*.py`), seeded, fixed input
//!    shapes; metrics written next to the model.
//!
//! CI never trains: the tests load the shipped models and check their contract and
//! what they do (`tests/onnx.rs`).

use anyhow::{bail, Context, Result};
use std::path::Path;
use std::process::Command;

/// Pinned so a re-run reproduces the shipped model (torch 2.15 needs onnx for the
/// TorchScript exporter, `dynamo=False`).
const PIP_PACKAGES: &[&str] = &["torch==2.15.0", "onnx==1.23.2", "numpy==2.4.6"];
const SEED: &str = "20261123";
const TRAIN_PAIRS: &str = "4000";

fn run(cmd: &mut Command, what: &str) -> Result<()> {
    eprintln!("$ {what}");
    let status = cmd.status().with_context(|| format!("starting {what}"))?;
    if !status.success() {
        bail!("{what} failed with {status}");
    }
    Ok(())
}

pub fn train(root: &Path) -> Result<()> {
    let work = root.join("target/train-models");
    let venv = work.join("venv");
    let python = venv.join("bin/python");
    if !python.exists() {
        run(
            Command::new("python3").arg("-m").arg("venv").arg(&venv),
            "python3 -m venv target/train-models/venv (Debian: apt install python3-venv)",
        )?;
    }
    let mut pip = Command::new(&python);
    pip.args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check"]).args(PIP_PACKAGES);
    run(&mut pip, &format!("pip install {}", PIP_PACKAGES.join(" ")))?;

    let data = work.join("data");
    let data_s = data.to_str().context("target path is not UTF-8")?;
    super::cargo(&["run", "--release", "--example", "train_data", "--", data_s, TRAIN_PAIRS, SEED])?;

    let models = root.join("assets/models");
    std::fs::create_dir_all(&models).context("creating assets/models")?;
    let script = root.join("xtask/train/denoise.py");
    let mut train = Command::new(&python);
    train
        .arg(&script)
        .arg(&data)
        .arg(models.join("denoise.onnx"))
        .arg(models.join("denoise.json"))
        .args(["--seed", SEED])
        .current_dir(root);
    run(&mut train, "python xtask/train/denoise.py (about 10 minutes on 2 cores)")?;
    eprintln!("wrote assets/models/denoise.onnx and denoise.json; check them with: cargo test --test onnx");
    Ok(())
}
