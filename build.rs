//! Compiles every `shaders/*.comp` (GLSL 450 compute) and `shaders/*.wgsl` (graphics
//! stages; one SPIR-V file per entry point, `{stem}.{entry}.spv`) to SPIR-V in OUT_DIR
//! with naga, validating each module, so shader errors are build errors with the file
//! named. GLSL files may pull shared code from `shaders/*.glsl` with a line
//! `#include "name.glsl"` (resolved here: naga's GLSL front end has no includes).

use std::path::Path;

fn main() {
    let dir = Path::new("shaders");
    println!("cargo:rerun-if-changed=shaders");
    let out = std::env::var("OUT_DIR").expect("cargo sets OUT_DIR");
    let mut entries: Vec<_> = std::fs::read_dir(dir).expect("shaders/ exists").flatten().map(|e| e.path()).collect();
    entries.sort();
    for path in entries.iter().filter(|p| p.extension().is_some_and(|e| e == "wgsl")) {
        println!("cargo:rerun-if-changed={}", path.display());
        let source = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let module = naga::front::wgsl::parse_str(&source)
            .unwrap_or_else(|e| panic!("{}: WGSL errors: {}", path.display(), e.emit_to_string(&source)));
        let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: invalid shader: {e:?}", path.display()));
        let stem = path.file_stem().and_then(|s| s.to_str()).expect("utf-8 shader name");
        for ep in &module.entry_points {
            let options = naga::back::spv::Options {
                lang_version: (1, 3),
                flags: naga::back::spv::WriterFlags::empty(),
                ..Default::default()
            };
            let pipeline = naga::back::spv::PipelineOptions { shader_stage: ep.stage, entry_point: ep.name.clone() };
            let words = naga::back::spv::write_vec(&module, &info, &options, Some(&pipeline))
                .unwrap_or_else(|e| panic!("{}: SPIR-V generation failed: {e:?}", path.display()));
            let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
            std::fs::write(Path::new(&out).join(format!("{stem}.{}.spv", ep.name)), bytes).expect("write SPIR-V");
        }
    }
    for path in entries.into_iter().filter(|p| p.extension().is_some_and(|e| e == "comp")) {
        println!("cargo:rerun-if-changed={}", path.display());
        let source = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let source = resolve_includes(dir, &path, &source);
        let module = naga::front::glsl::Frontend::default()
            .parse(&naga::front::glsl::Options::from(naga::ShaderStage::Compute), &source)
            .unwrap_or_else(|e| panic!("{}: GLSL parse errors: {e:?}", path.display()));
        let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: invalid shader: {e:?}", path.display()));
        let options = naga::back::spv::Options {
            lang_version: (1, 0),
            flags: naga::back::spv::WriterFlags::empty(),
            ..Default::default()
        };
        let pipeline =
            naga::back::spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: "main".into() };
        let words = naga::back::spv::write_vec(&module, &info, &options, Some(&pipeline))
            .unwrap_or_else(|e| panic!("{}: SPIR-V generation failed: {e:?}", path.display()));
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let name = path.file_stem().and_then(|s| s.to_str()).expect("utf-8 shader name");
        std::fs::write(Path::new(&out).join(format!("{name}.spv")), bytes).expect("write SPIR-V");
    }
}

/// Replace each `#include "name.glsl"` line with that file from `dir` (one level:
/// included files do not include others, which keeps line numbers easy to follow).
fn resolve_includes(dir: &Path, path: &Path, source: &str) -> String {
    let mut out = String::with_capacity(source.len());
    for line in source.lines() {
        let trimmed = line.trim();
        if let Some(rest) = trimmed.strip_prefix("#include") {
            let name = rest.trim().trim_matches('"');
            let inc = dir.join(name);
            let text = std::fs::read_to_string(&inc)
                .unwrap_or_else(|e| panic!("{}: #include {}: {e}", path.display(), inc.display()));
            out.push_str(&text);
        } else {
            out.push_str(line);
        }
        out.push('\n');
    }
    out
}
