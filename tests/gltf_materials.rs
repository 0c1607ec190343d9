//! The material properties the matched effects see, through the G-buffer on
//! lavapipe: alpha modes (glTF 2.0 §3.9.4: OPAQUE ignores alpha, MASK draws fully
//! opaque where alpha ≥ the cutoff and nothing elsewhere, BLEND's alpha is the
//! coverage the composite blends by), single- and double-sided faces (§3.9.6),
//! and the emissive factor; the material extensions read: KHR_materials_unlit,
//! KHR_materials_emissive_strength, KHR_materials_pbrSpecularGlossiness (its
//! diffuse as the base colour), and KHR_lights_punctual required but ignored.

mod common;

use base64::Engine;
use blind_augment::gpu::FrameRing;
use blind_augment::render::{Eye, GBufferFrame, GBufferPass};
use blind_augment::scene::{AlphaMode, Scene};
use glam::{Mat4, Vec3};
use serde_json::json;

const W: u32 = 64;
const H: u32 = 48;

/// A 1 m quad in the z = 0 plane with one material; `facing_camera` winds it
/// counter-clockwise seen from +z (glTF's front face, §3.7.2.1), else clockwise.
fn quad(material: serde_json::Value, facing_camera: bool) -> Vec<u8> {
    quad_requiring(material, facing_camera, &[])
}

/// `quad` with these extensions listed as used and required.
fn quad_requiring(material: serde_json::Value, facing_camera: bool, required: &[&str]) -> Vec<u8> {
    let p: [[f32; 3]; 4] = [[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]];
    let idx: [u16; 6] = if facing_camera { [0, 1, 2, 0, 2, 3] } else { [0, 2, 1, 0, 3, 2] };
    let mut bin: Vec<u8> = bytemuck::cast_slice(&p).to_vec();
    bin.extend_from_slice(bytemuck::cast_slice(&idx));
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin));
    let mut doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [material],
        "buffers": [{"uri": uri, "byteLength": bin.len()}],
        "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-0.5, -0.5, 0.0], "max": [0.5, 0.5, 0.0]},
            {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ]
    });
    if !required.is_empty() {
        doc["extensionsUsed"] = json!(required);
        doc["extensionsRequired"] = json!(required);
    }
    serde_json::to_vec(&doc).expect("json")
}

/// The centre pixel's (premultiplied colour, coverage written to the motion
/// target's w) with the quad 2 m ahead, both eyes; `None` if the pixel differs
/// between the eyes (it should not: the quad spans the centre of both).
fn centre(ctx: &blind_augment::gpu::GpuContext, scene: &Scene) -> ([f32; 4], f32) {
    centre_lit(ctx, scene, Vec3::Z, 1.0)
}

/// `centre` with the key light from `light_dir` and this ambient share.
fn centre_lit(ctx: &blind_augment::gpu::GpuContext, scene: &Scene, light_dir: Vec3, ambient: f32) -> ([f32; 4], f32) {
    let pass = GBufferPass::new(ctx, scene, W, H, 1).expect("pass");
    let mut ring = FrameRing::new(ctx, 1, 256).expect("ring");
    let eye = Eye {
        focal_px: 40.0,
        centre_px: [W as f32 / 2.0, H as f32 / 2.0],
        view_from_world: Mat4::from_translation(Vec3::new(0.0, 0.0, 2.0)).inverse(),
    };
    let frame = GBufferFrame {
        eyes: [eye, eye],
        prev_eyes: [eye, eye],
        pose: scene.pose_at(0.0, Mat4::IDENTITY),
        prev_pose: scene.pose_at(0.0, Mat4::IDENTITY),
        light_dir,
        ambient,
    };
    let (slot, cmd) = ring.begin().expect("begin");
    pass.record(cmd, slot, &frame).expect("record");
    ring.submit(slot).expect("submit");
    ring.wait_all().expect("wait");
    let f16 = |b: Vec<u8>| -> Vec<f32> {
        b.chunks_exact(2).map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32()).collect()
    };
    let colour = f16(pass.colour().download().expect("colour"));
    let motion = f16(pass.motion().download().expect("motion"));
    let at = 4 * ((H / 2) * W + W / 2) as usize;
    let n = (W * H) as usize * 4;
    assert_eq!(colour[at..at + 4], colour[n + at..n + at + 4], "eyes differ");
    ([colour[at], colour[at + 1], colour[at + 2], colour[at + 3]], motion[at + 3])
}

fn load(material: serde_json::Value, facing_camera: bool) -> Scene {
    Scene::from_glb(&quad(material, facing_camera), "quad.gltf").expect("quad loads")
}

/// Alpha 0.3 under each mode. Tolerance 2e-3: f16 storage of values ≤ 1 (step ≤ 4.9e-4)
/// and 8-bit texels of the baked base colour (0.3 → 77/255 = 0.302).
#[test]
fn alpha_modes_cover_as_the_spec_says() {
    let Some(ctx) = common::gpu_context("alpha_modes_cover_as_the_spec_says") else { return };
    let grey = |mode: &str, cutoff: Option<f32>| {
        let mut m = json!({"pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 0.3]}, "alphaMode": mode});
        if let Some(c) = cutoff {
            m["alphaCutoff"] = json!(c);
        }
        m
    };
    let opaque = load(grey("OPAQUE", None), true);
    assert_eq!(opaque.materials[0].alpha, AlphaMode::Opaque);
    let (c, cover) = centre(&ctx, &opaque);
    assert!((c[3] - 1.0).abs() < 2e-3 && cover == 1.0, "OPAQUE ignores alpha: {c:?}, cover {cover}");

    let (c, cover) = centre(&ctx, &load(grey("MASK", None), true));
    assert!(c[3] == 0.0 && cover == 0.0, "MASK at the default cutoff 0.5 hides alpha 0.3: {c:?}, cover {cover}");
    let (c, cover) = centre(&ctx, &load(grey("MASK", Some(0.2)), true));
    assert!((c[3] - 1.0).abs() < 2e-3 && cover == 1.0, "MASK at cutoff 0.2 draws alpha 0.3 opaque: {c:?}");

    let (c, cover) = centre(&ctx, &load(grey("BLEND", None), true));
    assert!((c[3] - 0.302).abs() < 2e-3 && cover == 1.0, "BLEND's alpha is its coverage: {c:?}");
    // Premultiplied: white lit at ambient 1 is white, times alpha.
    assert!((c[0] - c[3]).abs() < 2e-3, "premultiplied colour {c:?}");
    let msgs = ctx.take_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}

/// A single-sided quad seen from behind is not drawn; double-sided it is.
#[test]
fn back_faces_drawn_only_when_double_sided() {
    let Some(ctx) = common::gpu_context("back_faces_drawn_only_when_double_sided") else { return };
    let (_, cover) = centre(&ctx, &load(json!({}), true));
    assert_eq!(cover, 1.0, "a single-sided quad facing the camera is drawn");
    let (_, cover) = centre(&ctx, &load(json!({}), false));
    assert_eq!(cover, 0.0, "a single-sided quad facing away is culled");
    let (_, cover) = centre(&ctx, &load(json!({"doubleSided": true}), false));
    assert_eq!(cover, 1.0, "a double-sided quad facing away is drawn");
}

/// Emission adds to the lit colour: black base colour, emissive (0.5, 0, 0) →
/// sRGB-encoded red 0.7354, green and blue 0. Tolerance 2e-3 (f16 storage).
#[test]
fn emissive_factor_adds_light() {
    let Some(ctx) = common::gpu_context("emissive_factor_adds_light") else { return };
    let m =
        json!({"pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]}, "emissiveFactor": [0.5, 0.0, 0.0]});
    let (c, _) = centre(&ctx, &load(m, true));
    assert!((c[0] - 0.7354).abs() < 2e-3 && c[1].abs() < 2e-3 && c[2].abs() < 2e-3, "{c:?}");
}

/// KHR_materials_unlit: the base colour as it is, whatever the light, without
/// the emissive fallback. Grey 0.5
/// lit edge-on with no ambient is black; unlit it is sRGB 0.7354. Tolerance
/// 2e-3 (f16 storage, 8-bit texels of the baked base colour: 0.5 → 128/255).
#[test]
fn unlit_materials_ignore_the_light() {
    let Some(ctx) = common::gpu_context("unlit_materials_ignore_the_light") else { return };
    let grey = json!({"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0]}});
    let (lit, _) = centre_lit(&ctx, &load(grey.clone(), true), Vec3::X, 0.0);
    assert!(lit[0] < 2e-3, "lit edge-on without ambient is black: {lit:?}");
    let mut unlit = grey;
    unlit["extensions"] = json!({"KHR_materials_unlit": {}});
    // An emissive factor is a fallback for viewers without the extension (its
    // README: colour = the base colour term): not added.
    unlit["emissiveFactor"] = json!([0.5, 0.0, 0.0]);
    let scene = Scene::from_glb(&quad_requiring(unlit, true, &["KHR_materials_unlit"]), "unlit.gltf")
        .expect("a file requiring KHR_materials_unlit loads");
    assert!(scene.materials[0].unlit);
    let (c, _) = centre_lit(&ctx, &scene, Vec3::X, 0.0);
    // 128/255 = 0.50196 encodes to 0.7372.
    assert!((c[0] - 0.7372).abs() < 2e-3 && (c[2] - 0.7372).abs() < 2e-3, "unlit grey: {c:?}");
}

/// KHR_materials_emissive_strength scales the emissive factor: (0.1, 0, 0) × 5
/// emits 0.5 → sRGB red 0.7354 (tolerance 2e-3, f16 storage).
#[test]
fn emissive_strength_scales_emission() {
    let Some(ctx) = common::gpu_context("emissive_strength_scales_emission") else { return };
    let m = json!({
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]},
        "emissiveFactor": [0.1, 0.0, 0.0],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 5.0}}
    });
    let (c, _) = centre(&ctx, &load(m, true));
    assert!((c[0] - 0.7354).abs() < 2e-3 && c[1].abs() < 2e-3, "{c:?}");
    // A valid strength beyond f32's range loads (the product is held to f32).
    let huge = json!({
        "emissiveFactor": [0.0, 1.0, 0.0],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 1e39}}
    });
    let scene = Scene::from_glb(&quad(huge, true), "huge.gltf").expect("a huge strength is valid");
    assert_eq!(scene.materials[0].emissive, [0.0, f32::MAX, 0.0]);
    let bad = json!({"extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": -1.0}}});
    let Err(err) = Scene::from_glb(&quad(bad, true), "bad.gltf") else { panic!("a negative strength is refused") };
    assert!(err.to_string().contains("emissiveStrength"), "{err}");
}

/// KHR_materials_pbrSpecularGlossiness (archived, still exported): its diffuse
/// factor is drawn as the base colour. Diffuse red 0.5 at ambient 1 → sRGB
/// 0.7372 (8-bit texel 128/255; tolerance 2e-3).
#[test]
fn specular_glossiness_diffuse_is_the_base_colour() {
    let Some(ctx) = common::gpu_context("specular_glossiness_diffuse_is_the_base_colour") else { return };
    let m = json!({"extensions": {"KHR_materials_pbrSpecularGlossiness": {"diffuseFactor": [0.5, 0.0, 0.0, 1.0]}}});
    let scene = Scene::from_glb(&quad_requiring(m, true, &["KHR_materials_pbrSpecularGlossiness"]), "sg.gltf")
        .expect("a file requiring KHR_materials_pbrSpecularGlossiness loads");
    let (c, _) = centre(&ctx, &scene);
    assert!((c[0] - 0.7372).abs() < 2e-3 && c[1].abs() < 2e-3, "{c:?}");
}

/// KHR_lights_punctual required: the lights are ignored with a note (the
/// G-buffer is lit by its key light), the geometry drawn.
#[test]
fn required_punctual_lights_are_ignored_with_a_note() {
    let scene = Scene::from_glb(&quad_requiring(json!({}), true, &["KHR_lights_punctual"]), "lights.gltf")
        .expect("a file requiring KHR_lights_punctual loads");
    assert!(scene.notes.iter().any(|n| n.contains("lights ignored")), "{:?}", scene.notes);
}

/// `quad` with one 1×1 PNG image (RGBA `texel`) as texture 0.
fn quad_with_texture(material: serde_json::Value, texel: [u8; 4]) -> Vec<u8> {
    let mut png = Vec::new();
    image::RgbaImage::from_pixel(1, 1, image::Rgba(texel))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("png");
    let mut doc: serde_json::Value = serde_json::from_slice(&quad(material, true)).expect("json");
    let uri = format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(&png));
    doc["images"] = json!([{"uri": uri}]);
    doc["textures"] = json!([{"source": 0}]);
    serde_json::to_vec(&doc).expect("json")
}

/// The emissive map multiplies the emissive factor (glTF 2.0 §3.9.3): factor 0.5
/// grey × a red map emits red 0.5 → sRGB 0.7354, green and blue 0 (a factor alone
/// would emit grey). Tolerance 2e-3 (f16 storage). A map on another UV set than
/// the base colour's is not read, and the file says so.
#[test]
fn emissive_texture_multiplies_the_factor() {
    let Some(ctx) = common::gpu_context("emissive_texture_multiplies_the_factor") else { return };
    let m = json!({
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]},
        "emissiveFactor": [0.5, 0.5, 0.5],
        "emissiveTexture": {"index": 0}
    });
    let scene = Scene::from_glb(&quad_with_texture(m, [255, 0, 0, 255]), "emissive.gltf").expect("loads");
    assert!(scene.materials[0].emissive_texture.is_some());
    let (c, _) = centre(&ctx, &scene);
    assert!((c[0] - 0.7354).abs() < 2e-3 && c[1].abs() < 2e-3 && c[2].abs() < 2e-3, "{c:?}");
    let other = json!({
        "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}},
        "emissiveFactor": [1.0, 1.0, 1.0],
        "emissiveTexture": {"index": 0, "texCoord": 1}
    });
    let scene = Scene::from_glb(&quad_with_texture(other, [255, 0, 0, 255]), "other.gltf").expect("loads");
    assert!(scene.materials[0].emissive_texture.is_none());
    assert!(scene.notes.iter().any(|n| n.contains("emissive textures on another UV set")), "{:?}", scene.notes);
}
