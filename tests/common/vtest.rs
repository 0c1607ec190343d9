//! The temporal noise reference of the vendored real clip (OpenCV's `vtest.avi`,
//! tests/data/noise_vtest): per Laplacian level, channel and luma bin, the std of
//! (frame − temporal mean) measured by `make_reference.py` over 795 frames.

use serde::Deserialize;

#[derive(Deserialize)]
pub struct Reference {
    pub levels: Vec<RefLevel>,
}

#[derive(Deserialize)]
pub struct RefLevel {
    pub level: usize,
    pub bins: Vec<RefBin>,
}

#[derive(Deserialize)]
pub struct RefBin {
    pub luma: [f32; 2],
    #[serde(default)]
    pub std: Option<[Option<f32>; 3]>,
    #[serde(default)]
    pub relative_stderr: Option<[Option<f32>; 3]>,
}

pub fn reference() -> Reference {
    let text = std::fs::read_to_string(super::data("noise_vtest/reference.json")).expect("vendored reference");
    serde_json::from_str(&text).expect("reference.json parses")
}

/// Reference cells precise enough to judge a 20% tolerance: relative standard error
/// ≤ 5% (bins with a handful of pixels, e.g. the 4 darkest level-3 pixels, are out).
pub fn cells(r: &Reference) -> Vec<(usize, usize, [f32; 2], f32)> {
    let mut out = vec![];
    for lv in &r.levels {
        for b in &lv.bins {
            let (Some(std), Some(se)) = (&b.std, &b.relative_stderr) else { continue };
            for c in 0..3 {
                if let (Some(s), Some(e)) = (std[c], se[c]) {
                    if e <= 0.05 && s > 0.0 {
                        out.push((lv.level, c, b.luma, s));
                    }
                }
            }
        }
    }
    out
}
