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

/// lensfun's "pa" vignetting V(r) = 1 + k1·r² + k2·r⁴ + k3·r⁶ (r = 1 at the corner).
pub fn pa(k: [f32; 3], r: f32) -> f32 {
    let r2 = r * r;
    1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[2]))
}

/// A camera frame (encoded, 8-bit) darkened by the "pa" profile `k` in linear light
/// and quantised to 8 bits again.
pub fn apply_pa(img: &mut blind_augment::image::Rgb, k: [f32; 3]) {
    use blind_augment::image::yuv::{linear_to_srgb, srgb_to_linear};
    let (w, h) = (img.width, img.height);
    for ch in img.channels.iter_mut() {
        for y in 0..h {
            for x in 0..w {
                let v = &mut ch[y * w + x];
                let g = pa(k, blind_augment::model::Vignetting::radius(w, h, x as f32 + 0.5, y as f32 + 0.5));
                *v = (linear_to_srgb(srgb_to_linear(*v) * g).clamp(0.0, 1.0) * 255.0).round() / 255.0;
            }
        }
    }
}
