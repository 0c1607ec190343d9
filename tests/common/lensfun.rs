//! lensfun's lens database (`data/db/*.xml`, extracted by `cargo xtask bench-quality`)
//! read for the benches that apply its measured profiles: each calibration line with
//! the name of the lens it belongs to.

/// A numeric attribute (`name="…"`) of an XML element's line.
pub fn attr(line: &str, name: &str) -> Option<f32> {
    let at = line.find(&format!(" {name}=\""))? + name.len() + 3;
    line[at..].split('"').next()?.parse().ok()
}

/// (lens model, element line) of every `<tag …>` calibration line inside a `<lens>`
/// of the XML files under `dir`, in the files' sorted order.
pub fn entries(dir: &str, tag: &str) -> Vec<(String, String)> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{dir}: {e}"))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "xml"))
        .collect();
    files.sort();
    let open = format!("<{tag}");
    let mut out = vec![];
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap_or_default();
        let (mut lens, mut in_lens) = (String::new(), false);
        for line in text.lines().map(str::trim) {
            if line.starts_with("<lens>") {
                in_lens = true;
                lens.clear();
            } else if in_lens && lens.is_empty() && line.starts_with("<model>") {
                lens = line.trim_start_matches("<model>").trim_end_matches("</model>").to_string();
            } else if line.starts_with("</lens>") {
                in_lens = false;
            } else if in_lens && line.starts_with(&open) {
                out.push((lens.clone(), line.to_string()));
            }
        }
    }
    out
}
