//! `cargo xtask gltf-corpus MIRRORS`: the glTF loader over public glTF files made
//! by other projects. MIRRORS holds bare git mirrors as `owner+name/repo` (what the
//! project's `fetch` tool brings); every `.gltf`/`.glb` of each project listed in
//! `CORPUS` is extracted with its folder (external buffers and images) and checked
//! with `blind-augment scene`; the outcome per project and per file is written to
//! `docs/gltf-corpus.md`. Nothing is vendored: the page names each project's
//! commit and licence.

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// (owner/name, licence of the repository; models inside may carry their own).
const CORPUS: &[(&str, &str)] = &[
    ("KhronosGroup/glTF-Validator", "Apache-2.0"),
    ("assimp/assimp", "BSD-3-Clause (test models: per-model notices)"),
    ("syoyo/tinygltf", "MIT (models: Khronos sample licences)"),
    ("mikedh/trimesh", "MIT"),
    ("bevyengine/bevy", "MIT OR Apache-2.0 (assets: per-asset licences)"),
    ("donmccurdy/glTF-Transform", "MIT"),
    ("CesiumGS/gltf-pipeline", "Apache-2.0"),
    ("google/draco", "Apache-2.0"),
    ("qt/qt3d", "LGPL-3.0 / GPL"),
];

pub(crate) fn git(dir: &Path, args: &[&str]) -> Result<Vec<u8>> {
    let out = Command::new("git").arg("--git-dir").arg(dir).args(args).output().context("running git")?;
    if !out.status.success() {
        bail!("git {} in {}: {}", args.join(" "), dir.display(), String::from_utf8_lossy(&out.stderr));
    }
    Ok(out.stdout)
}

fn gltf_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            gltf_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "gltf" || e == "glb") {
            out.push(p);
        }
    }
}

/// The reason's kind, for the summary: what a reader of the page would group by.
fn kind(reason: &str) -> &'static str {
    if reason.contains("which this build does not") {
        "requires an extension not implemented"
    } else if reason.contains("no triangles to draw") {
        "nothing to draw (no triangles in the scene)"
    } else if reason.contains("PNG and JPEG are decoded") {
        "image format not decoded"
    } else if reason.contains("No such file") || reason.contains("cannot read") {
        "a referenced file is missing"
    } else if reason.contains("only glTF 2") {
        "glTF 1.0"
    } else if reason.contains("not glTF 2.0 JSON") {
        "not glTF 2.0 JSON (the reason names the value)"
    } else {
        "malformed (named in the reason)"
    }
}

/// Writes `HEAD:path` of each of `paths` under `dest` through one
/// `git cat-file --batch`; blobs the mirror lacks are skipped and returned.
pub(crate) fn extract(git_dir: &Path, paths: &[&str], dest: &Path) -> Result<Vec<String>> {
    use std::io::{BufRead as _, Read as _, Write as _};
    let mut child = Command::new("git")
        .arg("--git-dir")
        .arg(git_dir)
        .args(["cat-file", "--batch"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .context("running git cat-file")?;
    let mut stdin = child.stdin.take().context("git stdin")?;
    let list: String = paths.iter().map(|p| format!("HEAD:{p}\n")).collect();
    let writer = std::thread::spawn(move || stdin.write_all(list.as_bytes()));
    let mut out = std::io::BufReader::new(child.stdout.take().context("git stdout")?);
    let mut missing = Vec::new();
    for p in paths {
        let mut header = String::new();
        out.read_line(&mut header)?;
        let fields: Vec<&str> = header.split_whitespace().collect();
        let Some(size) = fields.get(2).filter(|_| fields.get(1) == Some(&"blob")).and_then(|s| s.parse::<usize>().ok())
        else {
            missing.push(p.to_string());
            continue;
        };
        let mut blob = vec![0u8; size + 1];
        out.read_exact(&mut blob)?;
        blob.pop();
        let path = dest.join(p);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)?;
        }
        std::fs::write(&path, blob)?;
    }
    writer.join().map_err(|_| anyhow::anyhow!("git writer thread"))??;
    child.wait()?;
    Ok(missing)
}

pub fn run(root: &Path, target: &Path, mirrors: &Path) -> Result<()> {
    let bin = target.join("debug/blind-augment");
    crate::cargo(&["build", "--bin", "blind-augment"])?;
    let work = target.join("gltf-corpus");
    let _ = std::fs::remove_dir_all(&work);
    let mut page = String::from(
        "# glTF files made elsewhere\n\nWhat `blind-augment scene` (the loader `render`, `xr` and the headset use) makes \
         of every `.gltf` and `.glb` in these projects' repositories. Regenerate: `cargo xtask gltf-corpus MIRRORS` \
         (bare git mirrors as `owner+name/repo`). The Khronos validator's own test files are mostly broken \
         on purpose or hold no mesh; `tests/gltf_files.rs` holds the loader to the validator's report on each.\n\n| project | commit | licence | files | drawn | refused |\n|---|---|---|---|---|---|\n",
    );
    let mut rows = String::new();
    let mut reasons: BTreeMap<(&str, &str), usize> = BTreeMap::new();
    for (repo, licence) in CORPUS {
        let git_dir = mirrors.join(repo.replace('/', "+")).join("repo");
        if !git_dir.exists() {
            eprintln!("{repo}: no mirror at {}; skipped", git_dir.display());
            continue;
        }
        let commit = String::from_utf8(git(&git_dir, &["rev-parse", "HEAD"])?)?.trim().to_string();
        let names = String::from_utf8(git(&git_dir, &["ls-tree", "-r", "--name-only", "HEAD"])?)?;
        let mut dirs: Vec<String> = names
            .lines()
            .filter(|n| n.ends_with(".gltf") || n.ends_with(".glb"))
            .map(|n| n.rsplit_once('/').map_or(".".to_string(), |(d, _)| d.to_string()))
            .collect();
        dirs.sort();
        dirs.dedup();
        let dest = work.join(repo.replace('/', "+"));
        std::fs::create_dir_all(&dest)?;
        // Every file in the folders holding a glTF file (its buffers and images),
        // read blob by blob: a mirror may lack its largest blobs, and those files
        // are then missing here too (the loader names them).
        let wanted: Vec<&str> = names
            .lines()
            .filter(|n| {
                let dir = n.rsplit_once('/').map_or(".", |(d, _)| d);
                dirs.binary_search_by(|d| d.as_str().cmp(dir)).is_ok()
            })
            .collect();
        let missing = extract(&git_dir, &wanted, &dest)?;
        let mut files = Vec::new();
        gltf_files(&dest, &mut files);
        let (mut ok, mut refused) = (0, 0);
        for chunk in files.chunks(100) {
            let out = Command::new(&bin).arg("scene").args(chunk).output().context("running blind-augment scene")?;
            for line in String::from_utf8_lossy(&out.stdout).lines() {
                let mut parts = line.splitn(3, '\t');
                let (Some(path), Some(outcome), Some(detail)) = (parts.next(), parts.next(), parts.next()) else {
                    continue;
                };
                let rel = Path::new(path).strip_prefix(&dest).unwrap_or(Path::new(path)).display().to_string();
                let detail = detail.replace(&format!("{}/", dest.display()), "").replace('|', "\\|");
                if outcome == "ok" {
                    ok += 1;
                } else {
                    refused += 1;
                    let k = if missing.iter().any(|m| detail.contains(m.as_str())) {
                        "a file the mirror lacks (its largest blobs are not brought)"
                    } else {
                        kind(&detail)
                    };
                    *reasons.entry((repo, k)).or_default() += 1;
                }
                rows.push_str(&format!("| {repo} | `{rel}` | {outcome} | {detail} |\n"));
            }
            if out.stdout.is_empty() {
                bail!("blind-augment scene gave no output: {}", String::from_utf8_lossy(&out.stderr));
            }
        }
        eprintln!("{repo}: {} files, {ok} drawn, {refused} refused", files.len());
        page.push_str(&format!(
            "| {repo} | `{}` | {licence} | {} | {ok} | {refused} |\n",
            &commit[..12.min(commit.len())],
            files.len()
        ));
    }
    page.push_str("\n## Refusals by kind\n\n| project | kind | files |\n|---|---|---|\n");
    for ((repo, k), n) in &reasons {
        page.push_str(&format!("| {repo} | {k} | {n} |\n"));
    }
    page.push_str("\n## Every file\n\n| project | file | outcome | drawn, or the reason |\n|---|---|---|---|\n");
    page.push_str(&rows);
    let out = root.join("docs/gltf-corpus.md");
    std::fs::create_dir_all(root.join("docs"))?;
    std::fs::write(&out, page).with_context(|| format!("writing {}", out.display()))?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
