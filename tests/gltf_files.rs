//! glTF files the project did not make: the Khronos glTF-Validator's test assets
//! (tests/data/gltf_validator, Apache-2.0, with the validator's own report for
//! each), `.gltf` with external and `data:` resources, and a mutation test over
//! thousands of damaged files. Never a panic; every refusal names the file; a
//! file the validator accepts is refused only for a stated limitation.

use blind_augment::scene::{Scene, SceneError};
use std::path::{Path, PathBuf};

const TOY: &[u8] = include_bytes!("../assets/toy.glb");

fn validator_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gltf_validator")
}

fn fixtures(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).expect("fixture folder").flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            fixtures(&p, out);
        } else if p.extension().is_some_and(|e| e == "gltf" || e == "glb") {
            out.push(p);
        }
    }
}

/// The validator's error count for a fixture, from its `.report.json`.
fn validator_errors(path: &Path) -> u64 {
    let report = PathBuf::from(format!("{}.report.json", path.display()));
    let text = std::fs::read_to_string(&report).expect("every fixture has its validator report");
    let v: serde_json::Value = serde_json::from_str(&text).expect("report is JSON");
    v["issues"]["numErrors"].as_u64().expect("numErrors")
}

/// Reasons a valid file may be refused: limitations this build states, not
/// claims that the file is wrong.
const LIMITATIONS: &[&str] = &[
    "no triangles to draw",
    "which this build does not",
    "(PNG, JPEG and WebP are decoded)",
    "is a URL",
    "has no data in the file",
];

#[test]
fn validator_assets_never_panic_and_refusals_name_the_file() {
    let mut files = Vec::new();
    fixtures(&validator_dir(), &mut files);
    // 372 files at the vendored commit; a missing folder must not pass silently.
    assert!(files.len() > 300, "only {} validator fixtures found", files.len());
    let (mut loaded_valid, mut refused_valid, mut loaded_invalid, mut refused_invalid) = (0, 0, 0, 0);
    let mut wrongly_refused = Vec::new();
    for path in &files {
        let errors = validator_errors(path);
        match Scene::load(path) {
            Ok(scene) => {
                check_drawable(&scene, path);
                if errors == 0 {
                    loaded_valid += 1
                } else {
                    loaded_invalid += 1
                }
            }
            Err(e @ SceneError::Unanticipated { .. }) => panic!("{}: the reader panicked: {e}", path.display()),
            Err(e) => {
                let msg = e.to_string();
                assert!(msg.contains(&path.display().to_string()), "error does not name the file: {msg}");
                if errors == 0 {
                    refused_valid += 1;
                    if !LIMITATIONS.iter().any(|l| msg.contains(l)) {
                        wrongly_refused.push(msg);
                    }
                } else {
                    refused_invalid += 1;
                }
            }
        }
    }
    println!(
        "validator-accepted: {loaded_valid} loaded, {refused_valid} refused for a stated limitation; \
         validator-rejected: {refused_invalid} refused, {loaded_invalid} loaded (their errors lie in what is not drawn)"
    );
    assert!(
        wrongly_refused.is_empty(),
        "files the validator accepts, refused as malformed:\n{}",
        wrongly_refused.join("\n")
    );
}

/// The two files that panicked the previous reader, refused with their reason.
#[test]
fn the_files_that_panicked_are_refused_with_a_reason() {
    for (rel, reason) in [
        ("base/image/empty_object.gltf", "exactly one of bufferView and uri"),
        ("base/mesh/unresolved_positions.gltf", "POSITION refers to accessor 0, and there are 0"),
    ] {
        let path = validator_dir().join(rel);
        let err = Scene::load(&path).expect_err(rel).to_string();
        assert!(err.contains(reason), "{rel}: {err}");
    }
}

/// What the renderer relies on: something to draw, finite vertices, indices in range.
fn check_drawable(scene: &Scene, what: &dyn std::fmt::Debug) {
    assert!(!scene.meshes.is_empty(), "{what:?}: loaded with nothing to draw");
    for m in &scene.meshes {
        assert!(m.indices.len() % 3 == 0 && !m.indices.is_empty(), "{what:?}: not a triangle list");
        assert!(m.indices.iter().all(|&i| (i as usize) < m.vertices.len()), "{what:?}: index out of range");
        let floats = m.vertices.iter().flat_map(|v| v.position.iter().chain(&v.normal).chain(&v.uv));
        assert!(floats.into_iter().all(|x| x.is_finite()), "{what:?}: non-finite vertex");
        assert!(m.material < scene.materials.len(), "{what:?}: material out of range");
        assert!(m.node < scene.nodes.len(), "{what:?}: node out of range");
    }
    for t in &scene.textures {
        assert_eq!(t.rgba.len(), (t.width * t.height * 4) as usize, "{what:?}: texture size");
    }
    let world = scene.world_from_nodes(0.7, glam::Mat4::IDENTITY);
    assert!(world.iter().all(|m| m.is_finite()), "{what:?}: non-finite node transform");
}

/// (JSON chunk, BIN chunk) of a GLB.
fn split(glb: &[u8]) -> (serde_json::Value, Vec<u8>) {
    let len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let json = serde_json::from_slice(&glb[20..20 + len]).unwrap();
    let bin_at = 20 + len;
    let bin_len = u32::from_le_bytes(glb[bin_at..bin_at + 4].try_into().unwrap()) as usize;
    (json, glb[bin_at + 8..bin_at + 8 + bin_len].to_vec())
}

fn glb(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(json).unwrap();
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while b.len() % 4 != 0 {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

fn assert_same(a: &Scene, b: &Scene) {
    assert_eq!(a.meshes.len(), b.meshes.len());
    for (x, y) in a.meshes.iter().zip(&b.meshes) {
        assert_eq!(x.vertices, y.vertices);
        assert_eq!(x.indices, y.indices);
        assert_eq!(x.material, y.material);
    }
    assert_eq!(a.textures.len(), b.textures.len());
    for (x, y) in a.textures.iter().zip(&b.textures) {
        assert_eq!((x.width, x.height), (y.width, y.height));
        assert!(x.rgba == y.rgba);
    }
    assert_eq!(a.channels.len(), b.channels.len());
}

/// The bundled `.glb` rewritten as a `.gltf` with its buffer and its images as
/// files beside it (names with spaces, percent-encoded as a URI must be), and
/// again with everything in `data:` URIs: all three load to the same scene.
#[test]
fn gltf_with_external_files_and_data_uris_loads_like_the_glb() {
    use base64::Engine as _;
    let reference = Scene::from_glb(TOY, "toy.glb").expect("bundled asset");
    let (mut json, bin) = split(TOY);
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("gltf_external");
    std::fs::create_dir_all(&dir).unwrap();

    let mut external = json.clone();
    external["buffers"][0]["uri"] = "toy data.bin".replace(' ', "%20").into();
    std::fs::write(dir.join("toy data.bin"), &bin).unwrap();
    for (i, img) in external["images"].as_array_mut().unwrap().iter_mut().enumerate() {
        let view = &json["bufferViews"][img["bufferView"].as_u64().unwrap() as usize];
        let (off, len) =
            (view["byteOffset"].as_u64().unwrap_or(0) as usize, view["byteLength"].as_u64().unwrap() as usize);
        let file = format!("texture {i}.png");
        std::fs::write(dir.join(&file), &bin[off..off + len]).unwrap();
        *img = serde_json::json!({ "uri": file.replace(' ', "%20") });
    }
    let gltf_path = dir.join("toy.gltf");
    std::fs::write(&gltf_path, serde_json::to_vec_pretty(&external).unwrap()).unwrap();
    let loaded = Scene::load(&gltf_path).expect("external .gltf");
    assert_same(&reference, &loaded);

    // Without its folder, the same JSON is refused by name.
    let err = Scene::from_glb(&serde_json::to_vec(&external).unwrap(), "bare.gltf").expect_err("external");
    let err = err.to_string();
    assert!(err.contains("external file `texture%200.png`") && err.contains("from its folder"), "{err}");
    // A missing file is named with its path.
    std::fs::remove_file(dir.join("texture 0.png")).unwrap();
    let err = Scene::load(&gltf_path).expect_err("missing image").to_string();
    assert!(err.contains("texture 0.png"), "{err}");

    let b64 = base64::engine::general_purpose::STANDARD.encode(&bin);
    json["buffers"][0]["uri"] = format!("data:application/octet-stream;base64,{b64}").into();
    let data_uri = Scene::from_glb(&serde_json::to_vec(&json).unwrap(), "toy-data-uri.gltf").expect("data URIs");
    assert_same(&reference, &data_uri);
}

/// Minimal xorshift: the mutation test's cases are the same on every run.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn numeric_leaves(v: &serde_json::Value, path: &mut Vec<String>, out: &mut Vec<(Vec<String>, bool)>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                path.push(k.clone());
                numeric_leaves(x, path, out);
                path.pop();
            }
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                path.push(i.to_string());
                numeric_leaves(x, path, out);
                path.pop();
            }
        }
        serde_json::Value::Number(_) => out.push((path.clone(), true)),
        serde_json::Value::String(_) => out.push((path.clone(), false)),
        _ => {}
    }
}

fn at<'a>(v: &'a mut serde_json::Value, path: &[String]) -> &'a mut serde_json::Value {
    path.iter().fold(v, |v, k| match v {
        serde_json::Value::Array(a) => &mut a[k.parse::<usize>().unwrap()],
        other => &mut other[k.as_str()],
    })
}

/// Damaged files: truncations, container lengths, every number and string of the
/// JSON replaced by hostile values, cyclic and shared nodes, NaN / Inf / huge
/// words in the binary data, random byte flips. The reader must refuse each with
/// a reason or load something drawable; a panic (caught as `Unanticipated`) fails.
#[test]
fn mutated_files_are_refused_or_drawable_never_a_panic() {
    let (json, bin) = split(TOY);
    let mut cases: Vec<(String, Vec<u8>)> = Vec::new();
    for cut in (0..TOY.len()).step_by(97).chain([11, 12, 19, 20, 21]) {
        cases.push((format!("truncated at {cut}"), TOY[..cut].to_vec()));
    }
    let json_len = u32::from_le_bytes(TOY[12..16].try_into().unwrap()) as usize;
    for (word_at, name) in [(8, "total length"), (12, "JSON length"), (20 + json_len, "BIN length")] {
        for v in [0u32, 1, 11, 12, 0x7FFF_FFFF, u32::MAX, TOY.len() as u32 + 1] {
            let mut m = TOY.to_vec();
            m[word_at..word_at + 4].copy_from_slice(&v.to_le_bytes());
            cases.push((format!("{name} = {v}"), m));
        }
    }
    let mut leaves = Vec::new();
    numeric_leaves(&json, &mut Vec::new(), &mut leaves);
    for (path, numeric) in &leaves {
        let hostile: Vec<serde_json::Value> = if *numeric {
            vec![(-1).into(), 0.into(), 4_294_967_295u64.into(), 1e300.into(), 0.5.into(), "7".into()]
        } else {
            vec!["SCALAR".into(), "".into(), "data:,".into(), "../../../../etc/passwd".into(), 3.into()]
        };
        for h in hostile {
            let mut j = json.clone();
            *at(&mut j, path) = h.clone();
            cases.push((format!("{} = {h}", path.join(".")), glb(&j, &bin)));
        }
    }
    for (what, children) in [
        ("node 0 its own child", vec![(0usize, vec![0u64])]),
        ("nodes 0 and 1 each other's child", vec![(0, vec![1]), (1, vec![0])]),
        ("node 2 shared by nodes 0 and 1", vec![(0, vec![2]), (1, vec![2])]),
        ("child 99", vec![(0, vec![99])]),
    ] {
        let mut j = json.clone();
        for (n, c) in children {
            j["nodes"][n]["children"] = c.into();
        }
        cases.push((what.to_string(), glb(&j, &bin)));
    }
    for word in (0..bin.len() / 4).step_by(7) {
        for (name, v) in [("NaN", 0x7FC0_0000u32), ("+Inf", 0x7F80_0000), ("0xFFFFFFFF", u32::MAX)] {
            let mut b = bin.clone();
            b[word * 4..word * 4 + 4].copy_from_slice(&v.to_le_bytes());
            cases.push((format!("BIN word {word} = {name}"), glb(&json, &b)));
        }
    }
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for k in 0..1500 {
        let mut m = TOY.to_vec();
        for _ in 0..1 + rng.below(8) {
            let i = rng.below(m.len());
            m[i] ^= 1 << rng.below(8);
        }
        cases.push((format!("random flips #{k}"), m));
    }
    let (mut refused, mut loaded) = (0, 0);
    for (what, bytes) in &cases {
        let name = format!("mutant ({what})");
        match Scene::from_glb(bytes, &name) {
            Ok(scene) => {
                check_drawable(&scene, what);
                loaded += 1;
            }
            Err(e @ SceneError::Unanticipated { .. }) => panic!("{what}: the reader panicked: {e}"),
            Err(e) => {
                assert!(e.to_string().contains(&name), "{what}: error does not name the input: {e}");
                refused += 1;
            }
        }
    }
    println!("{} mutants: {refused} refused with a reason, {loaded} loaded and drawable", cases.len());
    assert!(refused > cases.len() / 4, "most damage must be noticed ({refused} of {})", cases.len());
}

/// A `.gltf` whose files come from a reader (the headset's APK assets): the same
/// scene as the `.glb`, and a file the reader lacks named in the error.
#[test]
fn gltf_resources_from_a_reader_load_like_the_glb() {
    let reference = Scene::from_glb(TOY, "toy.glb").expect("bundled asset");
    let (mut json, bin) = split(TOY);
    json["buffers"][0]["uri"] = "data%20file.bin".into();
    let store = std::collections::HashMap::from([("data file.bin".to_string(), bin)]);
    let read = |rel: &str| store.get(rel).cloned().ok_or_else(|| format!("{rel} is not in the store"));
    let doc = serde_json::to_vec(&json).unwrap();
    let loaded = Scene::from_bytes_with(&doc, "assets/toy.gltf", &read).expect("reader");
    assert_same(&reference, &loaded);
    json["buffers"][0]["uri"] = "other.bin".into();
    let err = Scene::from_bytes_with(&serde_json::to_vec(&json).unwrap(), "assets/toy.gltf", &read)
        .expect_err("missing")
        .to_string();
    assert!(err.contains("other.bin is not in the store"), "{err}");
}

fn sample_dir(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gltf_samples").join(rel)
}

/// Positions' (min, max) over every mesh of `scene`, in object space.
fn position_range(scene: &Scene) -> ([f32; 3], [f32; 3]) {
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for v in scene.meshes.iter().flat_map(|m| &m.vertices) {
        for k in 0..3 {
            lo[k] = lo[k].min(v.position[k]);
            hi[k] = hi[k].max(v.position[k]);
        }
    }
    (lo, hi)
}

/// Positions and triangles equal; normals checked against the geometry instead
/// (`outward_cube_normals`): the sample's fallback buffer holds its normals still
/// octahedral-encoded (x, y, and z = 1 before the filter), as read (−0.71, 0, 0.71)
/// on the x = 0 face.
fn assert_same_geometry(a: &Scene, b: &Scene) {
    assert_eq!(a.meshes.len(), b.meshes.len());
    for (x, y) in a.meshes.iter().zip(&b.meshes) {
        let p = |m: &blind_augment::scene::Mesh| m.vertices.iter().map(|v| v.position).collect::<Vec<_>>();
        assert_eq!(p(x), p(y));
        // meshoptimizer's index codec keeps each triangle and its winding but may
        // start it at another vertex: compare triangles rotated to their least index.
        let tris = |m: &blind_augment::scene::Mesh| -> Vec<[u32; 3]> {
            m.indices
                .chunks_exact(3)
                .map(|t| {
                    let r = (0..3).min_by_key(|&i| t[i]).unwrap();
                    [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
                })
                .collect()
        };
        assert_eq!(tris(x), tris(y));
    }
}

/// The sample's normals against its geometry, to 1/127 (the filter's 8-bit
/// output): every normal unit and on the front side of each triangle that uses
/// its vertex (glTF winding: counter-clockwise seen from the front); the first
/// mesh, a cube quantized to 0…16383, has the outward axis of each face (n = −x on
/// the x = 0 face, +x on x = 16383, …).
fn outward_cube_normals(scene: &Scene) {
    for m in &scene.meshes {
        for t in m.indices.chunks_exact(3) {
            let p = |i: u32| glam::Vec3::from(m.vertices[i as usize].position);
            let face = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).normalize();
            for &i in t {
                let n = glam::Vec3::from(m.vertices[i as usize].normal);
                assert!((n.length() - 1.0).abs() < 1.0 / 127.0, "normal {n} not unit");
                assert!(n.dot(face) > 0.0, "normal {n} behind its triangle {t:?} (face normal {face})");
            }
        }
    }
    for v in &scene.meshes[0].vertices {
        let n = v.normal;
        let k = (0..3).max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs())).unwrap();
        for j in 0..3 {
            let want = if j == k { n[k].signum() } else { 0.0 };
            assert!((n[j] - want).abs() < 1.0 / 127.0, "normal {n:?} at {:?}", v.position);
        }
        assert_eq!(v.position[k], if n[k] > 0.0 { 16383.0 } else { 0.0 }, "normal {n:?} at {:?}", v.position);
    }
}

/// EXT_meshopt_compression (gltf-pipeline's test file, made by gltfpack: positions
/// in u16, octahedral-filtered normals in i8, triangle indices): the decoded
/// positions and indices equal the file's own uncompressed fallback buffer's, the
/// normals point out of the cube faces, and the file still loads with the fallback
/// buffer gone (as a file that requires the extension ships). The positions span
/// the accessor's declared min/max (0…16383), which the encoder wrote.
#[test]
fn meshopt_views_decode_to_the_files_own_fallback() {
    let dir = sample_dir("meshopt-fallback");
    let text = std::fs::read(dir.join("meshopt-fallback.gltf")).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&text).unwrap();
    let read = |rel: &str| std::fs::read(dir.join(rel)).map_err(|e| format!("{rel}: {e}"));
    let decoded = Scene::from_bytes_with(&text, "meshopt-fallback.gltf", &read).expect("decodes");
    // The same document reading the fallback: the extension stripped from the views.
    let mut plain = json.clone();
    for v in plain["bufferViews"].as_array_mut().unwrap() {
        v.as_object_mut().unwrap().remove("extensions");
    }
    let fallback = Scene::from_bytes_with(&serde_json::to_vec(&plain).unwrap(), "fallback.gltf", &read).expect("plain");
    assert_same_geometry(&fallback, &decoded);
    outward_cube_normals(&decoded);
    assert_eq!(decoded.meshes.iter().map(|m| m.indices.len() / 3).sum::<usize>(), 60);
    // Without the fallback buffer (no uri), and the extension required.
    let mut bare = json.clone();
    bare["buffers"][1].as_object_mut().unwrap().remove("uri");
    bare["extensionsRequired"] = serde_json::json!(["KHR_mesh_quantization", "EXT_meshopt_compression"]);
    let alone = Scene::from_bytes_with(&serde_json::to_vec(&bare).unwrap(), "bare.gltf", &read).expect("no fallback");
    assert_same(&decoded, &alone);
    assert_eq!(position_range(&alone), ([0.0; 3], [16383.0; 3]));
    // A damaged stream is refused naming the view, never a panic.
    let mut bytes = std::fs::read(dir.join("meshopt-fallback.bin")).unwrap();
    bytes[0] ^= 0xff;
    let broken = |rel: &str| if rel == "meshopt-fallback.bin" { Ok(bytes.clone()) } else { read(rel) };
    let err = Scene::from_bytes_with(&serde_json::to_vec(&bare).unwrap(), "broken.gltf", &broken)
        .expect_err("damaged header")
        .to_string();
    assert!(err.contains("broken.gltf") && err.contains("buffer view 0"), "{err}");
}

/// KHR_meshopt_compression (the ratified name; same codecs) from gltf-pipeline,
/// required and without a fallback, and EXT_meshopt_compression in a `.glb`
/// written by glTF-Transform: both load, their geometry equals what the
/// uncompressed data gives (the EXT sample's fallback positions and indices, normals
/// out of the faces; the Box's declared bounds).
#[test]
fn meshopt_files_from_two_packers_load() {
    let dir = sample_dir("meshopt-no-fallback-khr");
    let khr = Scene::load(&dir.join("meshopt-no-fallback.gltf")).expect("KHR_meshopt_compression");
    let ext_dir = sample_dir("meshopt-fallback");
    let read = |rel: &str| std::fs::read(ext_dir.join(rel)).map_err(|e| format!("{rel}: {e}"));
    let mut plain: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ext_dir.join("meshopt-fallback.gltf")).unwrap()).unwrap();
    for v in plain["bufferViews"].as_array_mut().unwrap() {
        v.as_object_mut().unwrap().remove("extensions");
    }
    let fallback = Scene::from_bytes_with(&serde_json::to_vec(&plain).unwrap(), "fallback.gltf", &read).expect("plain");
    assert_same_geometry(&fallback, &khr);
    outward_cube_normals(&khr);

    let bytes = std::fs::read(sample_dir("BoxMeshopt/BoxMeshopt.glb")).unwrap();
    let (json, _) = split(&bytes);
    let boxed = Scene::from_glb(&bytes, "BoxMeshopt.glb").expect("glTF-Transform's meshopt box");
    check_drawable(&boxed, &"BoxMeshopt.glb");
    let pos =
        &json["accessors"][json["meshes"][0]["primitives"][0]["attributes"]["POSITION"].as_u64().unwrap() as usize];
    let f = |k: &str| -> [f32; 3] { std::array::from_fn(|i| pos[k][i].as_f64().unwrap() as f32) };
    assert!(pos.get("normalized").map_or(true, |n| n == false), "raw positions expected: {pos}");
    assert_eq!(position_range(&boxed), (f("min"), f("max")));
}

/// `check_drawable`, and the poses over the animation finite (what reaches the GPU
/// each frame: node matrices and skinned / morphed vertices).
fn check_poses(scene: &Scene, what: &dyn std::fmt::Debug) {
    check_drawable(scene, what);
    for k in 0..8 {
        let t = scene.duration_s as f64 * k as f64 / 7.0;
        let pose = scene.pose_at(t, glam::Mat4::IDENTITY);
        assert!(pose.is_finite(), "{what:?}: non-finite pose at {t} s");
        for (m, d) in scene.meshes.iter().zip(&pose.deformed) {
            if let Some(d) = d {
                assert_eq!(d.len(), m.vertices.len(), "{what:?}: deformed vertex count");
            }
        }
    }
}

/// A sample as one self-contained `.gltf`: its buffers as `data:` URIs.
fn embedded(rel: &str) -> (serde_json::Value, Vec<Vec<u8>>) {
    use base64::Engine as _;
    let path = sample_dir(rel);
    let bytes = std::fs::read(&path).unwrap();
    let (mut json, glb_bin) = if bytes.starts_with(b"glTF") {
        let (j, b) = split(&bytes);
        (j, Some(b))
    } else {
        (serde_json::from_slice::<serde_json::Value>(&bytes).unwrap(), None)
    };
    let mut buffers = Vec::new();
    for (i, b) in json["buffers"].as_array().unwrap().iter().enumerate() {
        buffers.push(match b.get("uri").and_then(|u| u.as_str()) {
            Some(uri) if uri.starts_with("data:") => {
                base64::engine::general_purpose::STANDARD.decode(uri.split_once(',').unwrap().1).unwrap()
            }
            Some(uri) => std::fs::read(path.parent().unwrap().join(uri)).unwrap(),
            None if i == 0 => glb_bin.clone().unwrap(),
            None => Vec::new(),
        });
    }
    (json.take(), buffers)
}

fn with_buffers(json: &serde_json::Value, buffers: &[Vec<u8>]) -> Vec<u8> {
    use base64::Engine as _;
    let mut j = json.clone();
    for (i, b) in buffers.iter().enumerate() {
        if !b.is_empty() {
            j["buffers"][i]["uri"] =
                format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(b))
                    .into();
        }
    }
    serde_json::to_vec(&j).unwrap()
}

/// The mutation test over the files that exercise skins, morph targets and
/// meshopt decoding (Khronos SimpleSkin, SimpleMorph, AnimatedMorphCube;
/// glTF-Transform's BoxMeshopt): every JSON number and string replaced by hostile
/// values, NaN / Inf / huge words and random bit flips in the buffers. Each is
/// refused with a reason naming the input, or loads with finite poses over its
/// whole animation; a panic fails.
#[test]
fn mutated_skins_morphs_and_meshopt_never_panic() {
    let mut cases: Vec<(String, Vec<u8>)> = Vec::new();
    let mut rng = Rng(0xD1B5_4A32_D192_ED03);
    for rel in [
        "SimpleSkin/simple_skin.gltf",
        "SimpleMorph/SimpleMorph.gltf",
        "AnimatedMorphCube/AnimatedMorphCube.gltf",
        "BoxMeshopt/BoxMeshopt.glb",
    ] {
        let (json, buffers) = embedded(rel);
        let seed = with_buffers(&json, &buffers);
        Scene::from_glb(&seed, rel).unwrap_or_else(|e| panic!("{rel}: the unmutated seed must load: {e}"));
        let mut leaves = Vec::new();
        numeric_leaves(&json, &mut Vec::new(), &mut leaves);
        for (path, numeric) in &leaves {
            if path.iter().any(|p| p == "uri") {
                continue;
            }
            let hostile: Vec<serde_json::Value> = if *numeric {
                vec![(-1).into(), 0.into(), 4_294_967_295u64.into(), 1e300.into(), 0.5.into()]
            } else {
                vec!["SCALAR".into(), "".into(), 3.into()]
            };
            for h in hostile {
                let mut j = json.clone();
                *at(&mut j, path) = h.clone();
                cases.push((format!("{rel}: {} = {h}", path.join(".")), with_buffers(&j, &buffers)));
            }
        }
        for (bi, b) in buffers.iter().enumerate() {
            for word in (0..b.len() / 4).step_by(3) {
                for (name, v) in [("NaN", 0x7FC0_0000u32), ("+Inf", 0x7F80_0000), ("0xFFFFFFFF", u32::MAX)] {
                    let mut bs = buffers.clone();
                    bs[bi][word * 4..word * 4 + 4].copy_from_slice(&v.to_le_bytes());
                    cases.push((format!("{rel}: buffer {bi} word {word} = {name}"), with_buffers(&json, &bs)));
                }
            }
            for k in 0..150 {
                let mut bs = buffers.clone();
                for _ in 0..1 + rng.below(4) {
                    if bs[bi].is_empty() {
                        break;
                    }
                    let i = rng.below(bs[bi].len());
                    bs[bi][i] ^= 1 << rng.below(8);
                }
                cases.push((format!("{rel}: buffer {bi} random flips #{k}"), with_buffers(&json, &bs)));
            }
        }
    }
    let (mut refused, mut loaded) = (0, 0);
    for (what, bytes) in &cases {
        let name = format!("mutant ({what})");
        match Scene::from_glb(bytes, &name) {
            Ok(scene) => {
                check_poses(&scene, what);
                loaded += 1;
            }
            Err(e @ SceneError::Unanticipated { .. }) => panic!("{what}: the reader panicked: {e}"),
            Err(e) => {
                assert!(e.to_string().contains(&name), "{what}: error does not name the input: {e}");
                refused += 1;
            }
        }
    }
    println!("{} mutants: {refused} refused with a reason, {loaded} loaded with finite poses", cases.len());
    assert!(refused > 0 && loaded > 0, "{refused} refused, {loaded} loaded");
}

/// EXT_texture_webp (gltf-pipeline's test box): the file requiring it loads with
/// its WebP texture decoded, and the file offering a PNG fallback samples the WebP
/// (the extension's README: a client that decodes WebP uses it). The WebP is the
/// PNG re-encoded lossily: same size, and the mean absolute difference over RGB is
/// below 4/255 (lossy WebP at its default quality keeps PSNR above ~35 dB, a mean
/// error of a few levels; a wrong or garbled decode differs by tens of levels).
#[test]
fn webp_textures_decode() {
    let dir = sample_dir("webp-box");
    let required = Scene::load(&dir.join("box-textured-separate.gltf")).expect("EXT_texture_webp required");
    let fallback = Scene::load(&dir.join("box-textured-with-fallback.gltf")).expect("EXT_texture_webp used");
    let png = image::open(dir.join("cesium logo.png")).expect("png").to_rgba8();
    for scene in [&required, &fallback] {
        assert_eq!(scene.textures.len(), 1);
        let t = &scene.textures[scene.materials[0].texture.expect("textured")];
        assert_eq!((t.width, t.height), png.dimensions());
        let diff: f64 = t
            .rgba
            .chunks_exact(4)
            .zip(png.as_raw().chunks_exact(4))
            .map(|(a, b)| (0..3).map(|k| (a[k] as f64 - b[k] as f64).abs()).sum::<f64>())
            .sum::<f64>()
            / (3 * t.rgba.len() / 4) as f64;
        assert!(diff < 4.0, "mean |WebP − PNG| = {diff:.2} levels");
    }
    // The fallback file samples the WebP, not its PNG: its texels are the
    // required file's, which differ from the PNG's (lossy).
    let texels = |s: &Scene| s.textures[s.materials[0].texture.expect("textured")].rgba.clone();
    assert_eq!(texels(&fallback), texels(&required));
    assert_ne!(texels(&required), png.into_raw(), "the WebP decodes to other texels than the PNG");
}
