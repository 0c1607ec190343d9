//! `cargo xtask assets`: generates `assets/toy.glb`, the demo's bundled glTF object,
//! from code (so its licence is this repository's and it can be regenerated): a
//! textured cube that spins about its vertical axis and bobs, with a small sphere
//! orbiting it: node transforms, a child node, a base-colour texture and two
//! animations (rotation, translation) — what the G-buffer pass must handle.

use anyhow::{Context, Result};
use serde_json::json;
use std::path::Path;

struct Bin {
    data: Vec<u8>,
    views: Vec<serde_json::Value>,
    accessors: Vec<serde_json::Value>,
}

impl Bin {
    fn align(&mut self) {
        while !self.data.len().is_multiple_of(4) {
            self.data.push(0);
        }
    }
    /// Append raw bytes as a buffer view; returns its index.
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        self.align();
        let mut v = json!({"buffer": 0, "byteOffset": self.data.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.data.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }
    fn floats(&mut self, values: &[f32], kind: &str, width: usize, target: Option<u32>, minmax: bool) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let mut a = json!({"bufferView": view, "componentType": 5126, "count": values.len() / width, "type": kind});
        if minmax {
            let lo: Vec<f32> =
                (0..width).map(|c| values.iter().skip(c).step_by(width).cloned().fold(f32::MAX, f32::min)).collect();
            let hi: Vec<f32> =
                (0..width).map(|c| values.iter().skip(c).step_by(width).cloned().fold(f32::MIN, f32::max)).collect();
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }
    fn indices(&mut self, values: &[u32]) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(34963));
        self.accessors
            .push(json!({"bufferView": view, "componentType": 5125, "count": values.len(), "type": "SCALAR"}));
        self.accessors.len() - 1
    }
}

/// Cube of half-size `s`: 24 vertices (flat faces), each face's UVs the full texture.
fn cube(s: f32) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<u32>) {
    let (mut p, mut n, mut t, mut idx) = (vec![], vec![], vec![], vec![]);
    let faces: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
        ([1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]),
        ([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
        ([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]),
        ([0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
    ];
    for (f, (nrm, u, v)) in faces.iter().enumerate() {
        for (a, b) in [(-1.0f32, -1.0f32), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            for k in 0..3 {
                p.push(s * (nrm[k] + a * u[k] + b * v[k]));
                n.push(nrm[k]);
            }
            t.push((a + 1.0) / 2.0);
            t.push((1.0 - b) / 2.0);
        }
        let o = 4 * f as u32;
        idx.extend_from_slice(&[o, o + 1, o + 2, o, o + 2, o + 3]);
    }
    (p, n, t, idx)
}

/// UV sphere of radius `r`.
fn sphere(r: f32, rings: u32, segments: u32) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<u32>) {
    let (mut p, mut n, mut t, mut idx) = (vec![], vec![], vec![], vec![]);
    for i in 0..=rings {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..=segments {
            let ph = 2.0 * std::f32::consts::PI * j as f32 / segments as f32;
            let d = [th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()];
            for dk in d {
                p.push(r * dk);
                n.push(dk);
            }
            t.push(j as f32 / segments as f32);
            t.push(i as f32 / rings as f32);
        }
    }
    let row = segments + 1;
    for i in 0..rings {
        for j in 0..segments {
            let a = i * row + j;
            idx.extend_from_slice(&[a, a + row, a + 1, a + 1, a + row, a + row + 1]);
        }
    }
    (p, n, t, idx)
}

fn texture_png() -> Result<Vec<u8>> {
    // 128² checker of warm yellow / deep blue 16-px tiles with a white frame: hard,
    // high-contrast edges at several orientations make blur and grain visible.
    let size = 128u32;
    let img = image::RgbaImage::from_fn(size, size, |x, y| {
        if x < 6 || y < 6 || x >= size - 6 || y >= size - 6 {
            return image::Rgba([245, 245, 240, 255]);
        }
        if ((x / 16) + (y / 16)) % 2 == 0 {
            image::Rgba([250, 190, 30, 255])
        } else {
            image::Rgba([25, 60, 170, 255])
        }
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).context("encoding the texture")?;
    Ok(out.into_inner())
}

pub fn generate(root: &Path) -> Result<()> {
    let mut bin = Bin { data: vec![], views: vec![], accessors: vec![] };
    let mut meshes = vec![];
    for (p, n, t, i) in [cube(0.12), sphere(0.05, 16, 24)] {
        let pos = bin.floats(&p, "VEC3", 3, Some(34962), true);
        let nrm = bin.floats(&n, "VEC3", 3, Some(34962), false);
        let uv = bin.floats(&t, "VEC2", 2, Some(34962), false);
        let ind = bin.indices(&i);
        meshes.push((pos, nrm, uv, ind));
    }
    let png = texture_png()?;
    let image_view = bin.view(&png, None);
    // Animation: 4 s loop. Spin about +y (quaternion keyframes every quarter turn,
    // slerped), a bob in y, and the moon's orbit (translation of the child).
    let times: Vec<f32> = (0..=8).map(|k| k as f32 * 0.5).collect();
    let spin: Vec<f32> = times
        .iter()
        .flat_map(|t| {
            // Angle 2π·t/4 (one turn per loop); the quaternion takes its half.
            let a = std::f32::consts::PI * t / 4.0;
            [0.0, a.sin(), 0.0, a.cos()]
        })
        .collect();
    let bob: Vec<f32> = times.iter().flat_map(|t| [0.0, 0.04 * (std::f32::consts::PI * t / 2.0).sin(), 0.0]).collect();
    let orbit: Vec<f32> = times
        .iter()
        .flat_map(|t| {
            let a = std::f32::consts::PI * t; // two orbits per loop
            [0.22 * a.cos(), 0.05, 0.22 * a.sin()]
        })
        .collect();
    let t_acc = bin.floats(&times, "SCALAR", 1, None, true);
    let spin_acc = bin.floats(&spin, "VEC4", 4, None, false);
    let bob_acc = bin.floats(&bob, "VEC3", 3, None, false);
    let orbit_acc = bin.floats(&orbit, "VEC3", 3, None, false);
    bin.align();
    let doc = json!({
        "asset": {"version": "2.0", "generator": "blind-augment xtask assets"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"name": "toy", "children": [1, 2]},
            {"name": "cube", "mesh": 0},
            {"name": "moon", "mesh": 1, "translation": [0.22, 0.05, 0.0]}
        ],
        "meshes": [
            {"name": "cube", "primitives": [{"attributes": {"POSITION": meshes[0].0, "NORMAL": meshes[0].1, "TEXCOORD_0": meshes[0].2}, "indices": meshes[0].3, "material": 0}]},
            {"name": "moon", "primitives": [{"attributes": {"POSITION": meshes[1].0, "NORMAL": meshes[1].1, "TEXCOORD_0": meshes[1].2}, "indices": meshes[1].3, "material": 1}]}
        ],
        "materials": [
            {"name": "checker", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0}},
            {"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [0.85, 0.08, 0.06, 1.0], "metallicFactor": 0.0}}
        ],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9729}],
        "images": [{"bufferView": image_view, "mimeType": "image/png"}],
        "animations": [{
            "name": "spin, bob and orbit",
            "samplers": [
                {"input": t_acc, "output": spin_acc, "interpolation": "LINEAR"},
                {"input": t_acc, "output": bob_acc, "interpolation": "LINEAR"},
                {"input": t_acc, "output": orbit_acc, "interpolation": "LINEAR"}
            ],
            "channels": [
                {"sampler": 0, "target": {"node": 1, "path": "rotation"}},
                {"sampler": 1, "target": {"node": 0, "path": "translation"}},
                {"sampler": 2, "target": {"node": 2, "path": "translation"}}
            ]
        }],
        "accessors": bin.accessors,
        "bufferViews": bin.views,
        "buffers": [{"byteLength": bin.data.len()}]
    });
    let mut js = serde_json::to_vec(&doc).context("serialising glTF JSON")?;
    while !js.len().is_multiple_of(4) {
        js.push(b' ');
    }
    // GLB container (glTF 2.0 spec §4.4): header, JSON chunk, BIN chunk.
    let total = 12 + 8 + js.len() + 8 + bin.data.len();
    let mut glb = Vec::with_capacity(total);
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(total as u32).to_le_bytes());
    glb.extend_from_slice(&(js.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&js);
    glb.extend_from_slice(&(bin.data.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin.data);
    let path = root.join("assets/toy.glb");
    std::fs::write(&path, glb).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("wrote {} ({total} bytes)", path.display());
    Ok(())
}
