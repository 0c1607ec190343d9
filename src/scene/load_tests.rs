//! Unit tests of the glTF reader: values computed from the spec's definitions.

use super::*;
use base64::Engine as _;

#[test]
fn strips_and_fans_follow_the_spec_formulas() {
    use json::mesh::Mode;
    let order = [10, 11, 12, 13, 14];
    // glTF 2.0 §3.7.2.1: strip p_i = {v_i, v_{i+(1+i%2)}, v_{i+(2−i%2)}}.
    assert_eq!(triangles(Mode::TriangleStrip, &order), vec![10, 11, 12, 11, 13, 12, 12, 13, 14]);
    // fan p_i = {v_{i+1}, v_{i+2}, v_0}.
    assert_eq!(triangles(Mode::TriangleFan, &order), vec![11, 12, 10, 12, 13, 10, 13, 14, 10]);
    // A trailing partial triangle is dropped, not read past the end.
    assert_eq!(triangles(Mode::Triangles, &order), vec![10, 11, 12]);
    assert!(triangles(Mode::TriangleStrip, &order[..2]).is_empty());
    assert!(triangles(Mode::TriangleFan, &[]).is_empty());
}

/// A hand-written document: KHR_mesh_quantization positions (normalized i16,
/// interleaved with u8 texture coordinates at a 12-byte stride), one vertex
/// replaced by a sparse accessor, a triangle strip, and a KHR_texture_transform.
/// Every value is computed here from the spec's definitions.
#[test]
fn quantized_sparse_interleaved_strip_with_texture_transform() {
    let mut bin = Vec::new();
    let verts: [([i16; 3], [u8; 2]); 4] =
        [([0, 0, 0], [0, 0]), ([32767, 0, 0], [255, 0]), ([0, 32767, 0], [0, 255]), ([-32767, -32767, 0], [255, 255])];
    for (p, uv) in verts {
        for c in p {
            bin.extend_from_slice(&c.to_le_bytes());
        }
        bin.extend_from_slice(&[0, 0]); // padding to 8
        bin.extend_from_slice(&uv);
        bin.extend_from_slice(&[0, 0]); // padding to 12
    }
    let sparse_at = bin.len();
    bin.extend_from_slice(&2u16.to_le_bytes()); // sparse index: vertex 2
    bin.extend_from_slice(&[0, 0]);
    for c in [0i16, 16384, 0] {
        bin.extend_from_slice(&c.to_le_bytes()); // sparse value (normalized i16)
    }
    let b64 = base64::engine::general_purpose::STANDARD.encode(&bin);
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_mesh_quantization", "KHR_texture_transform"],
        "extensionsRequired": ["KHR_mesh_quantization", "KHR_texture_transform"],
        "buffers": [{"byteLength": bin.len(), "uri": format!("data:application/octet-stream;base64,{b64}")}],
        "bufferViews": [
            {"buffer": 0, "byteLength": 48, "byteStride": 12},
            {"buffer": 0, "byteOffset": sparse_at, "byteLength": 4},
            {"buffer": 0, "byteOffset": sparse_at + 4, "byteLength": 6}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5122, "normalized": true, "count": 4, "type": "VEC3",
             "min": [-1, -1, 0], "max": [1, 1, 0],
             "sparse": {"count": 1, "indices": {"bufferView": 1, "componentType": 5123},
                        "values": {"bufferView": 2}}},
            {"bufferView": 0, "byteOffset": 8, "componentType": 5121, "normalized": true, "count": 4, "type": "VEC2"}
        ],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "extensions": {
            "KHR_texture_transform": {"offset": [0.5, 0.0], "rotation": std::f32::consts::FRAC_PI_2, "scale": [2.0, 1.0]}}}}}],
        "textures": [{"source": 0}],
        "images": [{"uri": "data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8DwHwAFBQIAX8jx0gAAAABJRU5ErkJggg=="}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "mode": 5, "material": 0}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0
    });
    let scene = parse(&serde_json::to_vec(&doc).unwrap(), "quantized.gltf", Resources::Embedded).expect("loads");
    let m = &scene.meshes[0];
    let p: Vec<[f32; 3]> = m.vertices.iter().map(|v| v.position).collect();
    // Normalized i16: c / 32767, clamped at −1 (KHR_mesh_quantization, glTF §3.11).
    assert_eq!(p[0], [0.0, 0.0, 0.0]);
    assert_eq!(p[1], [1.0, 0.0, 0.0]);
    assert!((p[2][1] - 16384.0 / 32767.0).abs() < 1e-7, "sparse value replaces vertex 2: {:?}", p[2]);
    assert_eq!(p[3], [-1.0, -1.0, 0.0]);
    // Strip of 4 vertices (§3.7.2.1): (0, 1, 2), (1, 3, 2).
    assert_eq!(m.indices, vec![0, 1, 2, 1, 3, 2]);
    // Tolerance 1e-6: f32 rounding of sin/cos(π/2) and of the products.
    // uv' = T·R·S·uv, R the extension's column-major mat3 (cos, sin | −sin, cos)
    // at π/2, S = (2, 1), T = (0.5, 0):
    // vertex 1, uv (1, 0) [u8 255 normalized] → S (2, 0) → R (0, 2) → T (0.5, 2).
    let uv1 = m.vertices[1].uv;
    assert!((uv1[0] - 0.5).abs() < 1e-6 && (uv1[1] - 2.0).abs() < 1e-6, "{uv1:?}");
    // vertex 2, uv (0, 1) → S (0, 1) → R (−1, 0) → T (−0.5, 0).
    let uv2 = m.vertices[2].uv;
    assert!((uv2[0] + 0.5).abs() < 1e-6 && uv2[1].abs() < 1e-6, "{uv2:?}");
    assert_eq!(scene.textures.len(), 1);
}

/// A JSON chunk whose length is not a multiple of 4 (trimesh writes such GLBs;
/// §4.4.3 asks for padding): the BIN chunk follows it directly.
#[test]
fn glb_with_an_unpadded_json_chunk_splits() {
    let json = b"{\"a\":1}"; // 7 bytes
    let bin = [1u8, 2, 3, 4];
    let mut glb = Vec::new();
    let total = 12 + 8 + json.len() + 8 + bin.len();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(total as u32).to_le_bytes());
    glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(json);
    glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin);
    let (j, b) = split_glb(&glb, "unpadded.glb").expect("splits");
    assert_eq!((j, b), (&json[..], Some(&bin[..])));
}

#[test]
fn required_extensions_not_implemented_are_refused_by_name() {
    for (ext, says) in [
        (
            "KHR_draco_mesh_compression",
            "requires KHR_draco_mesh_compression (Draco-compressed meshes), which this build does not decode",
        ),
        ("EXT_texture_avif", "requires EXT_texture_avif (AVIF textures), which this build does not decode"),
        ("KHR_texture_basisu", "KTX2"),
        ("KHR_materials_foo", "requires KHR_materials_foo, which this build does not implement"),
    ] {
        let doc =
            serde_json::json!({"asset": {"version": "2.0"}, "extensionsRequired": [ext], "extensionsUsed": [ext]});
        let err = parse(&serde_json::to_vec(&doc).unwrap(), "x.gltf", Resources::Embedded).expect_err(ext);
        assert!(err.to_string().contains(says), "{err}");
    }
}

/// CUBICSPLINE by glTF 2.0 Appendix C: keyframes 0 → 1 at t 0 → 1, out-tangent 2
/// at the first, in-tangent 0 at the second: at s = ½ the Hermite sum is
/// h01·1 + td·h10·2 = 0.5 + 0.125·2 = 0.75; at s = ¼, 0.15625 + 0.140625·2 = 0.4375.
/// Before, the tangents were dropped and the curve read linear (0.5, 0.25).
#[test]
fn cubic_spline_translation_follows_the_hermite_formula() {
    let floats: Vec<f32> = [
        vec![0.0, 1.0],                                    // times
        vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0], // k0: in, value, out
        vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0], // k1: in, value, out
    ]
    .concat();
    let tri: Vec<f32> = vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let bytes: Vec<u8> = floats.iter().chain(&tri).flat_map(|f| f.to_le_bytes()).collect();
    let b64 = base64::engine::general_purpose::STANDARD.encode(&bytes);
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": bytes.len(), "uri": format!("data:application/octet-stream;base64,{b64}")}],
        "bufferViews": [
            {"buffer": 0, "byteLength": 8},
            {"buffer": 0, "byteOffset": 8, "byteLength": 72},
            {"buffer": 0, "byteOffset": 80, "byteLength": 36}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]},
            {"bufferView": 1, "componentType": 5126, "count": 6, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 2}}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "animations": [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
                        "samplers": [{"input": 0, "output": 1, "interpolation": "CUBICSPLINE"}]}]
    });
    let scene = parse(&serde_json::to_vec(&doc).unwrap(), "spline.gltf", Resources::Embedded).expect("loads");
    // Tolerance 1e-6: f32 arithmetic on values of order 1.
    for (t, want) in [(0.5, 0.75f32), (0.25, 0.4375), (0.0, 0.0)] {
        let x = scene.local_at(t)[0].translation.x;
        assert!((x - want).abs() < 1e-6, "t {t}: {x}, Hermite gives {want}");
    }
}

/// A skinned triangle whose skin has two joints; joint `bad` has an inverse bind
/// matrix translating by 1e18 m (as tinygltf's `unassigned-skeleton.gltf` has for
/// a joint no vertex weights). Every vertex is weighted to joint `used`.
fn skinned_triangle(used: u16, bad: usize) -> Vec<u8> {
    let mut bin: Vec<u8> = Vec::new();
    for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        bin.extend(p.iter().flat_map(|c| c.to_le_bytes()));
    }
    for _ in 0..3 {
        bin.extend([used, 0, 0, 0].iter().flat_map(|j| j.to_le_bytes()));
    }
    for _ in 0..3 {
        bin.extend([1.0f32, 0.0, 0.0, 0.0].iter().flat_map(|w| w.to_le_bytes()));
    }
    for k in 0..2 {
        let mut m = Mat4::IDENTITY.to_cols_array();
        if k == bad {
            m[12] = 1e18;
        }
        bin.extend(m.iter().flat_map(|c| c.to_le_bytes()));
    }
    let b64 = base64::engine::general_purpose::STANDARD.encode(&bin);
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0, 1, 2]}],
        "nodes": [{"mesh": 0, "skin": 0}, {}, {}],
        "skins": [{"joints": [1, 2], "inverseBindMatrices": 3}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 1, "WEIGHTS_0": 2}}]}],
        "buffers": [{"byteLength": bin.len(), "uri": format!("data:application/octet-stream;base64,{b64}")}],
        "bufferViews": [
            {"buffer": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 24},
            {"buffer": 0, "byteOffset": 60, "byteLength": 48},
            {"buffer": 0, "byteOffset": 108, "byteLength": 128}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "VEC4"},
            {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC4"},
            {"bufferView": 3, "componentType": 5126, "count": 2, "type": "MAT4"}
        ]
    });
    serde_json::to_vec(&doc).unwrap()
}

/// The reach check covers the joints a skin's vertices use, and only those: a
/// wild matrix on an unused joint moves no vertex; on the used one it is refused.
#[test]
fn skin_reach_counts_only_the_joints_vertices_use() {
    let scene = parse(&skinned_triangle(0, 1), "unused.gltf", Resources::Embedded).expect("unused wild joint");
    let pose = scene.pose_at(0.0, Mat4::IDENTITY);
    assert!(pose.is_finite());
    assert_eq!(pose.deformed[0].as_ref().unwrap()[1].position, [1.0, 0.0, 0.0]);
    let err = parse(&skinned_triangle(0, 0), "used.gltf", Resources::Embedded).expect_err("used wild joint");
    assert!(err.to_string().contains("from the origin"), "{err}");
}

/// glTF 1.0-era files are named as such, whatever their asset.version looks like
/// (a number in collada2gltf's output, absent, or empty), not reported by the
/// first type mismatch of the 2.0 schema ("invalid type: map, expected a sequence").
#[test]
fn old_and_versionless_files_are_named() {
    for (doc, says) in [
        (serde_json::json!({"asset": {"version": 1}, "meshes": {}}), "glTF 1 (asset.version written as a number)"),
        (serde_json::json!({"asset": {"version": 0.8}}), "glTF 0.8"),
        (serde_json::json!({"asset": {"version": "1.0"}}), "glTF 1.0; only glTF 2.x"),
        (serde_json::json!({"asset": {}, "meshes": {"box": {}}}), "glTF 1.0 (objects keyed by name)"),
        (serde_json::json!({"asset": {"version": ""}}), "asset.version is empty"),
    ] {
        let err = parse(&serde_json::to_vec(&doc).unwrap(), "old.gltf", Resources::Embedded).expect_err("refused");
        assert!(err.to_string().contains(says), "{doc}: {err}");
    }
}
