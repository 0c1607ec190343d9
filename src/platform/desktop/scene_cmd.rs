//! `blind-augment scene`: what the renderer would draw of each glTF file, or why
//! the file is refused — the check to run before rendering or pushing a scene to
//! the headset.

use anyhow::{bail, Result};
use blind_augment::scene::Scene;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct SceneArgs {
    /// glTF 2.0 files (`.glb`, `.gltf`).
    #[arg(required_unless_present = "extensions")]
    files: Vec<PathBuf>,
    /// Print the extensions a file may list in `extensionsRequired` and still be
    /// drawn by this build, one per line.
    #[arg(long)]
    extensions: bool,
}

/// One line per file, tab-separated: the path, `ok` or `refused`, then what is
/// drawn (meshes and how many deform, triangles, textures, animation channels and
/// length) and the notes, or the reason.
pub fn run(args: SceneArgs) -> Result<()> {
    if args.extensions {
        for e in blind_augment::scene::SUPPORTED_REQUIRED {
            println!("{e}");
        }
    }
    let mut refused = 0;
    for path in &args.files {
        match Scene::load(path) {
            Ok(s) => {
                let triangles: usize = s.meshes.iter().map(|m| m.indices.len() / 3).sum();
                let skinned = s.meshes.iter().filter(|m| m.deform.as_ref().is_some_and(|d| d.skin.is_some())).count();
                let morphed =
                    s.meshes.iter().filter(|m| m.deform.as_ref().is_some_and(|d| !d.targets.is_empty())).count();
                let mut line = format!(
                    "{}\tok\t{} meshes ({skinned} skinned, {morphed} morphed), {triangles} triangles, {} textures, {} \
                     animation channels ({:.2} s)",
                    path.display(),
                    s.meshes.len(),
                    s.textures.len(),
                    s.channels.len() + s.weight_channels.len(),
                    s.duration_s
                );
                for n in &s.notes {
                    line.push_str("; ");
                    line.push_str(n);
                }
                println!("{line}");
            }
            Err(e) => {
                refused += 1;
                println!("{}\trefused\t{e}", path.display());
            }
        }
    }
    if refused > 0 {
        bail!("{refused} of {} files refused", args.files.len());
    }
    Ok(())
}
