//! `cargo xtask gltf-corpus MIRRORS`: the glTF loader over public glTF files made
//! by other projects. MIRRORS holds bare git mirrors as `owner+name/repo` (what the
//! project's `fetch` tool brings); every `.gltf`/`.glb` of each project listed in
//! `CORPUS` is extracted with its folder (external buffers and images) and checked
//! with `blind-augment scene`; the outcome per project and per file is written to
//! `docs/gltf-corpus.md`. Nothing is vendored: the page names each project's
//! commit and licence. With `--validator DIR` (a folder where
//! `npm install gltf-validator` was run) every file is also put to the Khronos
//! glTF Validator (`xtask/js/gltf-validate.js`), and the page counts the files the
//! validator accepts, that require only extensions this build implements, and that
//! the loader still refuses: the outside check that such files all render.

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
    } else if reason.contains("PNG, JPEG and WebP are decoded") {
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

/// The Khronos validator's verdict on one file.
struct Verdict {
    errors: i64,
    codes: Vec<String>,
    required: Vec<String>,
}

/// Runs `xtask/js/gltf-validate.js` under node on `files` (NODE_PATH = `modules`).
fn validate(root: &Path, modules: &Path, files: &[PathBuf]) -> Result<BTreeMap<PathBuf, Verdict>> {
    let mut verdicts = BTreeMap::new();
    for chunk in files.chunks(100) {
        let out = Command::new("node")
            .env("NODE_PATH", modules)
            .arg(root.join("xtask/js/gltf-validate.js"))
            .args(chunk)
            .output()
            .context("running node (the Khronos validator needs Node.js)")?;
        if !out.status.success() {
            bail!("gltf-validate.js failed: {}", String::from_utf8_lossy(&out.stderr));
        }
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let v: serde_json::Value = serde_json::from_str(line).with_context(|| format!("validator line {line}"))?;
            let strings = |k: &str| -> Vec<String> {
                v[k].as_array()
                    .map(|a| a.iter().filter_map(|x| x.as_str().map(String::from)).collect())
                    .unwrap_or_default()
            };
            let file = PathBuf::from(v["file"].as_str().context("validator line without file")?);
            verdicts.insert(
                file,
                Verdict {
                    errors: v["errors"].as_i64().unwrap_or(-1),
                    codes: strings("codes"),
                    required: strings("required"),
                },
            );
        }
    }
    Ok(verdicts)
}

pub fn run(root: &Path, target: &Path, mirrors: &Path, validator: Option<&Path>) -> Result<()> {
    let bin = target.join("debug/blind-augment");
    crate::cargo(&["build", "--bin", "blind-augment"])?;
    let work = target.join("gltf-corpus");
    let _ = std::fs::remove_dir_all(&work);
    let mut page = String::from(
        "# glTF files made elsewhere\n\nWhat `blind-augment scene` (the loader `render`, `xr` and the headset use) makes \
         of every `.gltf` and `.glb` in these projects' repositories, beside the Khronos glTF Validator's verdict \
         on each. Regenerate: `cargo xtask gltf-corpus MIRRORS --validator DIR` (bare git mirrors as \
         `owner+name/repo`; DIR: a folder where `npm install gltf-validator` was run). The Khronos validator's own test files are mostly broken \
         on purpose or hold no mesh; `tests/gltf_files.rs` holds the loader to the validator's report on each.\n\n| project | commit | licence | files | drawn | refused |\n|---|---|---|---|---|---|\n",
    );
    let supported: Vec<String> = if validator.is_some() {
        let out =
            Command::new(&bin).args(["scene", "--extensions"]).output().context("blind-augment scene --extensions")?;
        String::from_utf8(out.stdout)?.lines().map(String::from).collect()
    } else {
        Vec::new()
    };
    let mut rows = String::new();
    // (project, validator-accepted files using only implemented required
    // extensions, of those drawn, those with no triangles in their scene, the
    // other refused ones' names).
    let mut checked: Vec<(&str, usize, usize, usize, Vec<String>)> = Vec::new();
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
        let verdicts = match validator {
            Some(modules) => Some(validate(root, modules, &files)?),
            None => None,
        };
        let mut accepted = (0, 0, 0, Vec::new());
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
                let verdict = verdicts.as_ref().and_then(|v| v.get(Path::new(path)));
                let verdict_cell = match verdict {
                    None => String::new(),
                    Some(v) if v.errors == 0 => "valid".to_string(),
                    Some(v) if v.errors < 0 => "not read".to_string(),
                    Some(v) => format!("{} errors ({})", v.errors, v.codes.join(", ")),
                };
                if verdict.is_some_and(|v| v.errors == 0 && v.required.iter().all(|e| supported.contains(e))) {
                    accepted.0 += 1;
                    if outcome == "ok" {
                        accepted.1 += 1;
                    } else if detail.contains("no triangles to draw") {
                        accepted.2 += 1;
                    } else {
                        accepted.3.push(rel.clone());
                    }
                }
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
                if validator.is_some() {
                    rows.push_str(&format!("| {repo} | `{rel}` | {verdict_cell} | {outcome} | {detail} |\n"));
                } else {
                    rows.push_str(&format!("| {repo} | `{rel}` | {outcome} | {detail} |\n"));
                }
            }
            if out.stdout.is_empty() {
                bail!("blind-augment scene gave no output: {}", String::from_utf8_lossy(&out.stderr));
            }
        }
        eprintln!("{repo}: {} files, {ok} drawn, {refused} refused", files.len());
        checked.push((repo, accepted.0, accepted.1, accepted.2, accepted.3));
        page.push_str(&format!(
            "| {repo} | `{}` | {licence} | {} | {ok} | {refused} |\n",
            &commit[..12.min(commit.len())],
            files.len()
        ));
    }
    if validator.is_some() {
        page.push_str(
            "\n## Files the Khronos validator accepts\n\nFiles with no validator error (its npm package, \
             `--validator DIR`) whose `extensionsRequired` this build implements: each is drawn, or has no \
             triangles in its scene (points, lines, or meshes no scene node places: the validator's own test \
             files mostly), or is listed as refused (its reason in the table of every file below).\n\n| project | accepted | drawn | no triangles | refused |\n\
             |---|---|---|---|---|\n",
        );
        for (repo, n, drawn, empty, refused) in &checked {
            let names: Vec<String> = refused.iter().map(|r| format!("`{r}`")).collect();
            page.push_str(&format!(
                "| {repo} | {n} | {drawn} | {empty} | {} |\n",
                if names.is_empty() { "0".to_string() } else { names.join(", ") }
            ));
        }
    }
    page.push_str(
        "\nDraco meshes (KHR_draco_mesh_compression) and KTX2 / Basis Universal textures (KHR_texture_basisu) \
         are refused by name. The Rust crates that decode them either bind the C++ reference decoders, which \
         need the Android NDK to cross-build for the headset, or are pre-releases: the pure-Rust \
         `draco-oxide-decoder` 0.1.0-alpha.12 decoded every Draco file of this corpus and matched Draco's own \
         uncompressed Box, but panicked on 7 of about 500 corrupted Draco streams of the loader's mutation test \
         (an assertion on the stream's wrap range; one on the octahedral normal transform), and the APK aborts \
         on a panic.\n",
    );
    page.push_str("\n## Refusals by kind\n\n| project | kind | files |\n|---|---|---|\n");
    for ((repo, k), n) in &reasons {
        page.push_str(&format!("| {repo} | {k} | {n} |\n"));
    }
    if validator.is_some() {
        page.push_str(
            "\n## Every file\n\n| project | file | Khronos validator | outcome | drawn, or the reason |\n|---|---|---|---|---|\n",
        );
    } else {
        page.push_str("\n## Every file\n\n| project | file | outcome | drawn, or the reason |\n|---|---|---|---|\n");
    }
    page.push_str(&rows);
    let out = root.join("docs/gltf-corpus.md");
    std::fs::create_dir_all(root.join("docs"))?;
    std::fs::write(&out, page).with_context(|| format!("writing {}", out.display()))?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
