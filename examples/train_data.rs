//! Writes the denoiser's training and validation pairs (`synth::training`) as .npy
//! files for `cargo xtask train-models`: train on the bundled Motorcycle and the
//! astronaut test photograph, validate on the held-out cat (chelsea.png).
//!
//! Usage: `cargo run --release --example train_data -- OUT_DIR [TRAIN_COUNT] [SEED]`

use anyhow::{Context, Result};
use blind_augment::io;
use blind_augment::synth::training::denoise_pairs;
use std::path::{Path, PathBuf};

/// Training crops are 64 px: the network is fully convolutional (receptive field
/// 11 px), so it is exported at another fixed size (`assets/models/README.md`).
const PATCH_PX: usize = 64;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().context("usage: train_data OUT_DIR [TRAIN_COUNT] [SEED]")?);
    let count: usize = args.next().map_or(Ok(4000), |s| s.parse()).context("TRAIN_COUNT")?;
    let seed: u64 = args.next().map_or(Ok(20261123), |s| s.parse()).context("SEED")?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let load = |p: &str| -> Result<_> { Ok(io::load_rgb(&root.join(p)).with_context(|| format!("loading {p}"))?.0) };
    let train = [load("assets/motorcycle_left_333x497.png")?, load("tests/data/astronaut.png")?];
    let val = [load("tests/data/chelsea.png")?];
    for (name, photos, n, s) in [("train", &train[..], count, seed), ("val", &val[..], count / 8, seed ^ 0xfeed)] {
        let pairs = denoise_pairs(photos, n, PATCH_PX, s);
        let shape = [pairs.count as u64, 3, PATCH_PX as u64, PATCH_PX as u64];
        for (kind, data) in [("clean", &pairs.clean), ("noisy", &pairs.noisy)] {
            let path = out.join(format!("{name}_{kind}.npy"));
            io::write_npy(&path, &shape, data).with_context(|| format!("writing {}", path.display()))?;
        }
        println!("{name}: {} pairs of {PATCH_PX}x{PATCH_PX}", pairs.count);
    }
    Ok(())
}
