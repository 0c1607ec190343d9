//! Reading a glTF 2.0 file into a `Scene`: the container and its resources
//! (`container`), the extension policy (an extension a file *requires* and this
//! build does not implement is refused by name), the default scene's node tree, its
//! primitives, materials, textures and animations, and skins and morph targets
//! (`load_deform`). Every index and byte range in the file is checked before use
//! (see `accessor`): a malformed file is an error naming the file and what is
//! wrong, never a panic.

use super::accessor::Data;
pub(super) use super::container::Resources;
use super::container::{fetch, split_glb, GLB_MAGIC};
use super::load_deform::{reach_bound_m, read_deform, read_weight_channel, MAX_REACH_M};
use super::{
    invalid, AlphaMode, Channel, Material, Mesh, Node, Property, Scene, SceneError, Skin, TextureData, Trs, Vertex,
};
use glam::{Mat4, Quat, Vec2, Vec3};
use gltf::json;
use json::accessor::Type;
use json::validation::{Checked, Validate};
use std::collections::HashMap;
use std::sync::Arc;

/// Extensions a file may list in `extensionsRequired` and still be drawn as its
/// author meant: quantized attributes are read by `accessor` (any component type,
/// normalized or not), texture transforms are applied to the UVs at load,
/// meshopt-compressed buffer views are decoded at load (`meshopt`), WebP images
/// are decoded (the `image` crate), unlit materials skip the key light, emissive
/// strength scales the emission, a specular-glossiness material's diffuse is its
/// base colour (the G-buffer shades every surface with one diffuse key light, so
/// neither workflow's specular term is drawn), and punctual lights are ignored
/// with a note, as the G-buffer's key light stands for the room's.
pub const SUPPORTED_REQUIRED: &[&str] = &[
    "KHR_mesh_quantization",
    "KHR_texture_transform",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
    "EXT_texture_webp",
    "KHR_materials_unlit",
    "KHR_materials_emissive_strength",
    "KHR_materials_pbrSpecularGlossiness",
    "KHR_lights_punctual",
];

/// Compressed-data extensions and what each would need; refused by name when required.
const COMPRESSION: &[(&str, &str)] = &[
    ("KHR_draco_mesh_compression", "Draco-compressed meshes"),
    ("KHR_texture_basisu", "KTX2 / Basis Universal textures"),
    ("EXT_texture_avif", "AVIF textures"),
    ("MSFT_texture_dds", "DDS textures"),
];

/// Checks for what the glTF crate's own validation indexes without a bounds check
/// (a primitive's POSITION accessor), run before that validation.
fn precheck(root: &json::Root, name: &str) -> Result<(), SceneError> {
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            for (sem, acc) in &prim.attributes {
                if acc.value() >= root.accessors.len() {
                    let sem = match sem {
                        Checked::Valid(s) => s.to_string(),
                        Checked::Invalid => "an attribute".into(),
                    };
                    return Err(invalid(
                        name,
                        format!(
                            "mesh {m} primitive {p}: {sem} refers to accessor {}, and there are {}",
                            acc.value(),
                            root.accessors.len()
                        ),
                    ));
                }
            }
        }
    }
    for (i, img) in root.images.iter().enumerate() {
        // glTF 2.0 schema image.schema.json: exactly one of bufferView / uri, and
        // mimeType with bufferView.
        match (&img.buffer_view, &img.uri) {
            (Some(_), None) if img.mime_type.is_none() => {
                return Err(invalid(name, format!("image {i}: a bufferView image needs a mimeType")));
            }
            (Some(_), None) | (None, Some(_)) => {}
            _ => return Err(invalid(name, format!("image {i}: exactly one of bufferView and uri must be given"))),
        }
    }
    Ok(())
}

pub(super) fn parse(bytes: &[u8], name: &str, resources: Resources<'_>) -> Result<Scene, SceneError> {
    let (json_bytes, bin) = if bytes.starts_with(GLB_MAGIC) { split_glb(bytes, name)? } else { (bytes, None) };
    let mut value: serde_json::Value =
        serde_json::from_slice(json_bytes).map_err(|e| invalid(name, format!("not glTF 2.0 JSON: {e}")))?;
    // glTF 1.0 files (and 0.8 ones) keep their objects in maps keyed by name and
    // often write asset.version as a number: name the version rather than the
    // first type mismatch the 2.0 schema would report.
    let keyed = ["meshes", "accessors", "nodes", "materials", "buffers", "bufferViews"]
        .iter()
        .any(|k| value.get(k).is_some_and(|m| m.is_object()));
    let convert = "only glTF 2.x is read (convert it, e.g. with gltf-pipeline)";
    match value.get("asset").and_then(|a| a.get("version")) {
        Some(serde_json::Value::String(v)) if v.starts_with("2.") => {}
        Some(serde_json::Value::String(v)) if v.is_empty() => {
            return Err(invalid(name, "asset.version is empty; a glTF 2.0 file says \"2.0\""));
        }
        Some(serde_json::Value::String(v)) => return Err(invalid(name, format!("glTF {v}; {convert}"))),
        Some(serde_json::Value::Number(v)) => {
            return Err(invalid(name, format!("glTF {v} (asset.version written as a number); {convert}")));
        }
        _ if keyed => return Err(invalid(name, format!("glTF 1.0 (objects keyed by name); {convert}"))),
        _ => {}
    }
    let mut notes = Vec::new();
    normalise(&mut value, &mut notes);
    // The JSON as read: buffer-view extensions (meshopt) are read from it, the
    // typed document keeps only what the glTF crate models.
    let raw_json = value.clone();
    let mut root: json::Root =
        serde_json::from_value(value).map_err(|e| invalid(name, format!("not glTF 2.0 JSON: {e}")))?;
    if !root.asset.version.starts_with("2.") {
        return Err(invalid(name, format!("asset.version is {}; only glTF 2.x is read", root.asset.version)));
    }
    for ext in &root.extensions_required {
        if SUPPORTED_REQUIRED.contains(&ext.as_str()) {
            continue;
        }
        return Err(invalid(
            name,
            match COMPRESSION.iter().find(|(e, _)| e == ext) {
                Some((_, what)) => format!("requires {ext} ({what}), which this build does not decode"),
                None => format!("requires {ext}, which this build does not implement"),
            },
        ));
    }
    // The policy above decided on required extensions; the crate's validation
    // would refuse the ones it does not parse itself (KHR_mesh_quantization).
    let required = std::mem::take(&mut root.extensions_required);
    precheck(&root, name)?;
    let mut errors = Vec::new();
    root.validate(&root, json::Path::new, &mut |path, error| {
        let path = path().to_string();
        match error {
            // An enum value outside the spec's list: the Khronos validator warns
            // (forward compatibility) and so does this reader, where the object
            // is used (`Checked::Invalid` is refused at the read).
            json::validation::Error::Invalid => {}
            // glTF 2.0 §5.1.1: an accessor without a bufferView is all zeros
            // (sparse values may replace some); the crate calls it missing.
            json::validation::Error::Missing if path.starts_with("accessors[") && path.ends_with("].bufferView") => {}
            // §5.24.1 (mesh.primitive.attributes): a primitive without POSITION
            // is skipped by the client; its min/max checks then do not apply.
            json::validation::Error::Missing if path.ends_with("attributes[\"POSITION\"]") => {}
            _ => errors.push(format!("{path}: {error}")),
        }
    });
    root.extensions_required = required;
    if let Some(first) = errors.first() {
        let more = if errors.len() > 1 { format!(" (and {} more)", errors.len() - 1) } else { String::new() };
        return Err(invalid(name, format!("{first}{more}")));
    }

    // Buffers are resolved up front but a failure is kept, not raised: a file may
    // declare a buffer it never reads (the validator accepts that), and the error
    // is due only where data is read from it.
    let mut buffers = Vec::with_capacity(root.buffers.len());
    for (i, b) in root.buffers.iter().enumerate() {
        let what = format!("buffer {i}");
        let data = match (&b.uri, i, bin) {
            (Some(uri), _, _) => fetch(uri, &what, name, &resources).map_err(|e| match e {
                SceneError::Invalid { problem, .. } => problem,
                other => other.to_string(),
            }),
            // §4.4.3.2: the first buffer without a uri is the GLB's BIN chunk.
            (None, 0, Some(bin)) => Ok(bin.to_vec()),
            (None, _, _) => Err(format!("{what} has no data in the file: no uri, and no GLB binary chunk")),
        };
        buffers.push(data.and_then(|d| {
            if (d.len() as u64) < b.byte_length.0 {
                Err(format!("{what}: {} bytes, byteLength says {}", d.len(), b.byte_length.0))
            } else {
                Ok(d)
            }
        }));
    }
    let decoded = super::meshopt::decode_views(&raw_json, &buffers).map_err(|e| invalid(name, e))?;
    let data = Data { root: &root, buffers: &buffers, decoded: &decoded };
    let err = |e: String| invalid(name, e);

    // Nodes and their hierarchy: one parent each, no cycles (glTF 2.0 §3.5.3: the
    // node hierarchy must be a set of disjoint strict trees).
    let mut nodes = Vec::with_capacity(root.nodes.len());
    for (i, n) in root.nodes.iter().enumerate() {
        let rest = match n.matrix {
            Some(m) => {
                let (s, r, t) = Mat4::from_cols_array(&m).to_scale_rotation_translation();
                Trs { translation: t, rotation: r, scale: s }
            }
            None => Trs {
                translation: Vec3::from(n.translation.unwrap_or([0.0; 3])),
                rotation: unit_quat(n.rotation.map_or([0.0, 0.0, 0.0, 1.0], |q| q.0)).unwrap_or(Quat::NAN),
                scale: Vec3::from(n.scale.unwrap_or([1.0; 3])),
            },
        };
        if !(rest.translation.is_finite() && rest.rotation.is_finite() && rest.scale.is_finite()) {
            return Err(invalid(name, format!("node {i}: non-finite or degenerate transform")));
        }
        nodes.push(Node { parent: None, rest });
    }
    for (i, n) in root.nodes.iter().enumerate() {
        for c in n.children.iter().flatten() {
            let c = c.value();
            let child = nodes.get_mut(c).ok_or_else(|| invalid(name, format!("node {i}: child {c} does not exist")))?;
            if child.parent.is_some() || c == i {
                return Err(invalid(name, format!("node {c} has more than one parent")));
            }
            child.parent = Some(i);
        }
    }
    for i in 0..nodes.len() {
        let (mut at, mut steps) = (i, 0);
        while let Some(p) = nodes[at].parent {
            at = p;
            steps += 1;
            if steps > nodes.len() {
                return Err(invalid(name, format!("node {i} is part of a cycle in the node hierarchy")));
            }
        }
    }

    // The scene drawn: the default scene, else the first; a file without scenes
    // draws every root node (the spec lets a viewer choose; showing the content is
    // what a user loading it expects).
    let roots: Vec<usize> = match (root.scene, root.scenes.first()) {
        (Some(s), _) => root.scenes[s.value()].nodes.iter().map(|n| n.value()).collect(),
        (None, Some(s)) => {
            if root.scenes.len() > 1 {
                notes.push(format!("{} scenes and no default: drawing scene 0", root.scenes.len()));
            }
            s.nodes.iter().map(|n| n.value()).collect()
        }
        (None, None) => {
            notes.push("no scenes: drawing every root node".into());
            (0..nodes.len()).filter(|&i| nodes[i].parent.is_none()).collect()
        }
    };
    let mut drawn = vec![false; nodes.len()];
    let mut stack = roots;
    while let Some(i) = stack.pop() {
        if std::mem::replace(&mut drawn[i], true) {
            continue;
        }
        stack.extend(root.nodes[i].children.iter().flatten().map(|c| c.value()));
    }
    if root.nodes.iter().enumerate().any(|(i, n)| drawn[i] && n.camera.is_some()) {
        notes.push("cameras ignored: the view is the headset's".into());
    }
    if root.extensions_used.iter().any(|e| e == "KHR_lights_punctual") {
        notes.push("lights ignored: the G-buffer is lit by the fixed key light".into());
    }

    let mut materials = Vec::with_capacity(root.materials.len() + 1);
    let mut textures: Vec<Arc<TextureData>> = Vec::new();
    let mut image_texture: HashMap<usize, usize> = HashMap::new();
    let mut material_uv: Vec<UvSet> = Vec::new();
    let mut emissive_other_uv = 0;
    for (i, m) in root.materials.iter().enumerate() {
        let pbr = &m.pbr_metallic_roughness;
        let ext = &raw_json["materials"][i]["extensions"];
        // KHR_materials_pbrSpecularGlossiness (archived): diffuseFactor and
        // diffuseTexture take the place of the base colour (the extension's
        // README: "diffuse ... defines the reflected diffuse color").
        let spec_gloss = &ext["KHR_materials_pbrSpecularGlossiness"];
        let mut base_colour = pbr.base_color_factor.0;
        let mut base_texture = pbr.base_color_texture.clone();
        if spec_gloss.is_object() {
            base_colour = match spec_gloss.get("diffuseFactor") {
                None => [1.0; 4],
                Some(f) => serde_json::from_value(f.clone()).map_err(|e| {
                    invalid(name, format!("material {i}: KHR_materials_pbrSpecularGlossiness diffuseFactor: {e}"))
                })?,
            };
            base_texture = match spec_gloss.get("diffuseTexture") {
                None => None,
                Some(t) => Some(serde_json::from_value(t.clone()).map_err(|e| {
                    invalid(name, format!("material {i}: KHR_materials_pbrSpecularGlossiness diffuseTexture: {e}"))
                })?),
            };
            if base_texture.as_ref().is_some_and(|t: &json::texture::Info| t.index.value() >= root.textures.len()) {
                return Err(invalid(name, format!("material {i}: diffuseTexture names no texture")));
            }
        }
        if base_colour.iter().any(|c| !c.is_finite()) {
            return Err(invalid(name, format!("material {i}: non-finite baseColorFactor")));
        }
        let mut texture = None;
        let mut uv = UvSet::default();
        // A texture without a source (`allow_empty_texture`: an extension such as
        // KHR_texture_basisu supplies it) is drawn without its texture.
        let source = base_texture.as_ref().map(|info| texture_source(&root, &raw_json, info.index.value()));
        if source.is_some_and(|s| s >= root.images.len()) {
            notes.push(format!("material {i}: base-colour texture without a PNG/JPEG/WebP source; drawn untextured"));
        }
        if let Some((info, tex)) = base_texture.as_ref().zip(source.filter(|&s| s < root.images.len())) {
            texture = Some(cached_texture(tex, &mut textures, &mut image_texture, || {
                decode_image(&root, &data, tex, name, &resources)
            })?);
            uv = UvSet::from_info(info, name, i)?;
        }
        // glTF 2.0 §3.9.4: alphaCutoff applies in MASK mode only, default 0.5.
        let alpha = match m.alpha_mode {
            Checked::Valid(json::material::AlphaMode::Opaque) => AlphaMode::Opaque,
            Checked::Valid(json::material::AlphaMode::Mask) => {
                let cutoff = m.alpha_cutoff.map_or(0.5, |c| c.0);
                if !cutoff.is_finite() || cutoff < 0.0 {
                    return Err(invalid(name, format!("material {i}: alphaCutoff {cutoff} is not a number ≥ 0")));
                }
                AlphaMode::Mask { cutoff }
            }
            Checked::Valid(json::material::AlphaMode::Blend) => AlphaMode::Blend,
            Checked::Invalid => return Err(invalid(name, format!("material {i}: invalid alphaMode"))),
        };
        // KHR_materials_emissive_strength: emissiveFactor × emissiveStrength
        // (default 1, must be ≥ 0).
        let strength = match ext["KHR_materials_emissive_strength"].get("emissiveStrength") {
            None => 1.0,
            Some(v) => match v.as_f64() {
                Some(x) if x.is_finite() && x >= 0.0 => x,
                _ => {
                    return Err(invalid(name, format!("material {i}: emissiveStrength {v} is not a number ≥ 0")));
                }
            },
        };
        if m.emissive_factor.0.iter().any(|c| !c.is_finite()) {
            return Err(invalid(name, format!("material {i}: non-finite emissiveFactor")));
        }
        // The product in f64, held to f32's range (a valid huge strength must not
        // overflow to infinity; the G-buffer clamps emission far below anyway).
        let mut emissive = m.emissive_factor.0.map(|c| (c as f64 * strength).min(f32::MAX as f64) as f32);
        // KHR_materials_unlit: colour = the base colour term; the other core
        // material properties are fallbacks for viewers without the extension.
        let unlit = ext.get("KHR_materials_unlit").is_some();
        if unlit {
            emissive = [0.0; 3];
        }
        // The emissive map (glTF 2.0 §3.9.3: emission = emissiveFactor × texture),
        // read where it can emit at all. The G-buffer carries one UV set per
        // vertex, the base colour's: a map on another set or transform is noted
        // and its factor emits alone.
        let mut emissive_texture = None;
        if let Some(info) = m.emissive_texture.as_ref().filter(|_| emissive.iter().any(|&c| c > 0.0)) {
            let tex = texture_source(&root, &raw_json, info.index.value());
            let set = UvSet::from_info(info, name, i)?;
            if tex >= root.images.len() {
                notes.push(format!("material {i}: emissive texture without a PNG/JPEG/WebP source; not read"));
            } else if texture.is_some() && set != uv {
                emissive_other_uv += 1;
            } else {
                if texture.is_none() {
                    uv = set;
                }
                emissive_texture = Some(cached_texture(tex, &mut textures, &mut image_texture, || {
                    decode_image(&root, &data, tex, name, &resources)
                })?);
            }
        }
        materials.push(Material {
            base_colour,
            texture,
            alpha,
            double_sided: m.double_sided,
            emissive,
            emissive_texture,
            unlit,
        });
        material_uv.push(uv);
    }
    let default_material = materials.len();
    if emissive_other_uv > 0 {
        notes.push(format!(
            "{emissive_other_uv} emissive textures on another UV set or transform than their base colour's not read: \
             their materials emit their emissiveFactor"
        ));
    }
    materials.push(Material::fallback());
    material_uv.push(UvSet::default());

    // Skins (glTF 2.0 §5.28): joints and inverse bind matrices (identity when
    // the file gives none).
    let mut skins = Vec::with_capacity(root.skins.len());
    for (si, sk) in root.skins.iter().enumerate() {
        let what = format!("skin {si}");
        let joints: Vec<usize> = sk.joints.iter().map(|j| j.value()).collect();
        let inverse_bind: Vec<Mat4> = match sk.inverse_bind_matrices {
            Some(ix) => {
                let (v, _) =
                    data.read_f32(ix.value(), &[Type::Mat4], &format!("{what} inverseBindMatrices")).map_err(err)?;
                v.chunks_exact(16).map(Mat4::from_cols_slice).collect()
            }
            None => vec![Mat4::IDENTITY; joints.len()],
        };
        if inverse_bind.len() < joints.len() {
            return Err(invalid(
                name,
                format!("{what}: {} inverse bind matrices for {} joints", inverse_bind.len(), joints.len()),
            ));
        }
        if let Some(j) = joints.iter().find(|&&j| j >= nodes.len()) {
            return Err(invalid(name, format!("{what}: joint node {j} does not exist")));
        }
        skins.push(Skin { joints, inverse_bind });
    }

    let draco_used = root.extensions_used.iter().any(|e| e == "KHR_draco_mesh_compression");
    let mut meshes = Vec::new();
    let mut skipped_modes = Vec::new();
    let mut unskinned = false;
    for (ni, n) in root.nodes.iter().enumerate() {
        let Some(mi) = n.mesh.filter(|_| drawn[ni]).map(|m| m.value()) else { continue };
        for (pi, prim) in root.meshes[mi].primitives.iter().enumerate() {
            let what = format!("mesh {mi} primitive {pi}");
            use json::mesh::{Mode, Semantic};
            let mode = match prim.mode {
                Checked::Valid(m) => m,
                Checked::Invalid => return Err(invalid(name, format!("{what}: invalid mode"))),
            };
            if matches!(mode, Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip) {
                skipped_modes.push(format!("{mode:?}"));
                continue;
            }
            let attr = |s: Semantic| prim.attributes.get(&Checked::Valid(s)).map(|a| a.value());
            let Some(pos_ix) = attr(Semantic::Positions) else {
                skipped_modes.push("without POSITION".into());
                continue;
            };
            // KHR_draco_mesh_compression (used, not required) leaves the core
            // accessors without data: they would read as zeros.
            if draco_used && root.accessors.get(pos_ix).is_some_and(|a| a.buffer_view.is_none() && a.sparse.is_none()) {
                return Err(invalid(
                    name,
                    format!(
                        "{what}: its data is Draco-compressed (KHR_draco_mesh_compression), which this build does \
                         not decode"
                    ),
                ));
            }
            let (pos, _) = data.read_f32(pos_ix, &[Type::Vec3], &format!("{what} POSITION")).map_err(err)?;
            let positions: Vec<[f32; 3]> = pos.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            let order: Vec<u32> = match prim.indices {
                Some(ix) => data.read_indices(ix.value(), &format!("{what} indices")).map_err(err)?,
                None => (0..positions.len() as u32).collect(),
            };
            if let Some(bad) = order.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(invalid(name, format!("{what}: index {bad} ≥ {} vertices", positions.len())));
            }
            let indices = triangles(mode, &order);
            if indices.is_empty() {
                continue;
            }
            let normals: Vec<[f32; 3]> = match attr(Semantic::Normals) {
                Some(ix) => {
                    let (v, _) = data.read_f32(ix, &[Type::Vec3], &format!("{what} NORMAL")).map_err(err)?;
                    v.chunks_exact(3)
                        .map(|c| Vec3::new(c[0], c[1], c[2]).try_normalize().unwrap_or(Vec3::Z).to_array())
                        .collect()
                }
                None => vertex_normals(&positions, &indices),
            };
            let material = prim.material.map_or(default_material, |m| m.value());
            let uv_set = &material_uv[material];
            let uvs: Vec<[f32; 2]> = match attr(Semantic::TexCoords(uv_set.tex_coord)) {
                Some(ix) => {
                    let (v, _) = data.read_f32(ix, &[Type::Vec2], &format!("{what} TEXCOORD")).map_err(err)?;
                    v.chunks_exact(2).map(|c| uv_set.apply([c[0], c[1]])).collect()
                }
                None => vec![[0.0; 2]; positions.len()],
            };
            let vertices = positions
                .iter()
                .enumerate()
                .map(|(i, &p)| Vertex {
                    position: p,
                    normal: normals.get(i).copied().unwrap_or([0.0, 0.0, 1.0]),
                    uv: uvs.get(i).copied().unwrap_or([0.0; 2]),
                })
                .collect();
            let (lo, hi) = positions.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| {
                (lo.min(Vec3::from(*p)), hi.max(Vec3::from(*p)))
            });
            let deform = read_deform(&data, prim, n, &root.meshes[mi], &skins, positions.len(), &what)
                .map_err(|e| invalid(name, e))?;
            unskinned |= n.skin.is_some() && deform.as_ref().map_or(true, |d| d.skin.is_none());
            meshes.push(Mesh { node: ni, material, vertices, indices, bounds: (lo, hi), deform: deform.map(Box::new) });
        }
    }
    if !skipped_modes.is_empty() {
        skipped_modes.sort();
        skipped_modes.dedup();
        notes.push(format!("primitives not drawn: {} (only triangles with positions are)", skipped_modes.join(", ")));
    }
    if unskinned {
        notes.push("a node with a skin draws a primitive without JOINTS_0/WEIGHTS_0: drawn rigid".into());
    }
    if meshes.is_empty() {
        return Err(invalid(name, "no triangles to draw in the scene"));
    }

    let mut channels = Vec::new();
    let mut weight_channels = Vec::new();
    let mut duration_s = 0.0f32;
    for (ai, anim) in root.animations.iter().enumerate() {
        for (ci, ch) in anim.channels.iter().enumerate() {
            let what = format!("animation {ai} channel {ci}");
            let property = match ch.target.path {
                Checked::Valid(json::animation::Property::Translation) => Property::Translation,
                Checked::Valid(json::animation::Property::Rotation) => Property::Rotation,
                Checked::Valid(json::animation::Property::Scale) => Property::Scale,
                Checked::Valid(json::animation::Property::MorphTargetWeights) => {
                    let sampler = &anim.samplers[ch.sampler.value()];
                    let wc = read_weight_channel(&data, &root, ch.target.node.value(), sampler, &what)
                        .map_err(|e| invalid(name, e))?;
                    if let Some(wc) = wc {
                        duration_s = duration_s.max(*wc.times_s.last().unwrap_or(&0.0));
                        weight_channels.push(wc);
                    }
                    continue;
                }
                Checked::Invalid => continue,
            };
            let sampler = &anim.samplers[ch.sampler.value()];
            let (times_s, _) =
                data.read_f32(sampler.input.value(), &[Type::Scalar], &format!("{what} input")).map_err(err)?;
            let types: &[Type] = if property == Property::Rotation { &[Type::Vec4] } else { &[Type::Vec3] };
            let (flat, n) = data.read_f32(sampler.output.value(), types, &format!("{what} output")).map_err(err)?;
            let mut values: Vec<[f32; 4]> =
                flat.chunks_exact(n).map(|c| std::array::from_fn(|k| c.get(k).copied().unwrap_or(0.0))).collect();
            let interp = sampler.interpolation;
            let mut tangents = None;
            if interp == Checked::Valid(json::animation::Interpolation::CubicSpline) {
                // glTF 2.0 Appendix C: (in-tangent, value, out-tangent) per keyframe.
                if values.len() % 3 != 0 {
                    return Err(invalid(name, format!("{what}: CUBICSPLINE output is not (in, value, out) triples")));
                }
                tangents = Some(values.chunks_exact(3).map(|c| (c[0], c[2])).collect::<Vec<_>>());
                values = values.chunks_exact(3).map(|c| c[1]).collect();
            }
            if property == Property::Rotation {
                // A zero quaternion has no rotation to normalise to (NaN downstream).
                for q in values.iter_mut() {
                    *q = unit_quat(*q)
                        .ok_or_else(|| invalid(name, format!("{what}: a zero rotation quaternion")))?
                        .to_array();
                }
            }
            if times_s.is_empty() || values.len() != times_s.len() || times_s.windows(2).any(|w| w[1] < w[0]) {
                return Err(invalid(
                    name,
                    format!(
                        "{what}: {} keyframe times for {} values, or times not increasing",
                        times_s.len(),
                        values.len()
                    ),
                ));
            }
            duration_s = duration_s.max(*times_s.last().unwrap_or(&0.0));
            channels.push(Channel {
                node: ch.target.node.value(),
                property,
                times_s,
                values,
                step: interp == Checked::Valid(json::animation::Interpolation::Step),
                tangents,
            });
        }
    }
    let reach_m = reach_bound_m(&nodes, &meshes, &channels, &skins, &weight_channels);
    if reach_m.is_nan() || reach_m > MAX_REACH_M {
        return Err(invalid(
            name,
            format!(
                "its node transforms and mesh bounds may place vertices {reach_m:.3e} m from the origin; beyond \
                 {MAX_REACH_M:.0e} m f32 positions step by more than 6 cm and depth and motion vectors are noise"
            ),
        ));
    }
    Ok(Scene { nodes, meshes, materials, textures, channels, skins, weight_channels, duration_s, notes })
}

/// `q` scaled to unit length, or `None` for a zero (or non-finite) quaternion. It
/// is divided by its largest component first: a component above ~1.8e19 squares
/// past f32's range, and a plain normalisation then yields zeros (a rotation that
/// collapses the node, and NaN once interpolated).
fn unit_quat(q: [f32; 4]) -> Option<Quat> {
    let m = q.iter().fold(0.0f32, |m, c| m.max(c.abs()));
    if !(m.is_finite() && m > 0.0) {
        return None;
    }
    let u = Quat::from_array(q.map(|c| c / m));
    (u.length() >= 1e-6).then(|| u.normalize()).filter(|u| u.is_finite())
}

/// Brings JSON the spec allows into the shape the glTF crate's types require:
/// integers written as floats (`1.0`: JSON numbers; the validator accepts them),
/// scenes without `nodes` (optional in the schema), and animation channels
/// without a target node (optional: KHR_animation_pointer targets properties by
/// pointer), which are dropped with a note.
fn normalise(v: &mut serde_json::Value, notes: &mut Vec<String>) {
    fn integers(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Number(n) if n.is_f64() => {
                if let Some(f) = n.as_f64().filter(|f| f.fract() == 0.0 && f.abs() < 9.0e15) {
                    *v = serde_json::Value::from(f as i64);
                }
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(integers),
            serde_json::Value::Object(o) => o.values_mut().for_each(integers),
            _ => {}
        }
    }
    integers(v);
    if let Some(scenes) = v.get_mut("scenes").and_then(|s| s.as_array_mut()) {
        for s in scenes.iter_mut().filter_map(|s| s.as_object_mut()) {
            s.entry("nodes").or_insert_with(|| serde_json::Value::Array(Vec::new()));
        }
    }
    let mut dropped = 0;
    if let Some(anims) = v.get_mut("animations").and_then(|a| a.as_array_mut()) {
        for a in anims.iter_mut() {
            if let Some(chs) = a.get_mut("channels").and_then(|c| c.as_array_mut()) {
                let before = chs.len();
                chs.retain(|c| c.get("target").and_then(|t| t.get("node")).is_some());
                dropped += before - chs.len();
            }
        }
    }
    if dropped > 0 {
        notes.push(format!("{dropped} animation channels without a target node (KHR_animation_pointer) not applied"));
    }
}

/// Which UV set a material's base-colour texture reads and its
/// KHR_texture_transform, applied to the UVs at load time.
#[derive(Default, PartialEq)]
struct UvSet {
    tex_coord: u32,
    uv_from_mesh_uv: Option<glam::Affine2>,
}

impl UvSet {
    fn from_info(info: &json::texture::Info, name: &str, material: usize) -> Result<Self, SceneError> {
        let mut set = Self { tex_coord: info.tex_coord, uv_from_mesh_uv: None };
        if let Some(t) = info.extensions.as_ref().and_then(|e| e.texture_transform.as_ref()) {
            // KHR_texture_transform (README, "Overview"): uv' = T · R · S · uv with
            // the GLSL `mat3(cos, sin, 0, −sin, cos, 0, 0, 0, 1)`: column-major, so
            // its columns are (cos, sin) and (−sin, cos), a counter-clockwise
            // rotation of the UVs, as the extension's `rotation` says.
            let (o, r, s) = (Vec2::from(t.offset.0), t.rotation.0, Vec2::from(t.scale.0));
            if !(o.is_finite() && r.is_finite() && s.is_finite()) {
                return Err(invalid(name, format!("material {material}: non-finite KHR_texture_transform")));
            }
            let (sin, cos) = r.sin_cos();
            let rot = glam::Mat2::from_cols(Vec2::new(cos, sin), Vec2::new(-sin, cos));
            set.uv_from_mesh_uv = Some(glam::Affine2::from_mat2_translation(rot * glam::Mat2::from_diagonal(s), o));
            if let Some(tc) = t.tex_coord {
                set.tex_coord = tc;
            }
        }
        Ok(set)
    }

    fn apply(&self, uv: [f32; 2]) -> [f32; 2] {
        match self.uv_from_mesh_uv {
            Some(m) => m.transform_point2(Vec2::from(uv)).to_array(),
            None => uv,
        }
    }
}

/// Vertex order → triangle list (glTF 2.0 §3.7.2.1, "Topology types"): strips
/// alternate winding as the spec's `p_i = {v_i, v_{i+(1+i%2)}, v_{i+(2−i%2)}}`,
/// fans are `{v_{i+1}, v_{i+2}, v_0}`; a trailing partial triangle is dropped.
fn triangles(mode: json::mesh::Mode, order: &[u32]) -> Vec<u32> {
    use json::mesh::Mode;
    match mode {
        Mode::TriangleStrip => (0..order.len().saturating_sub(2))
            .flat_map(|i| [order[i], order[i + 1 + i % 2], order[i + 2 - i % 2]])
            .collect(),
        Mode::TriangleFan => {
            (1..order.len().saturating_sub(1)).flat_map(|i| [order[i], order[i + 1], order[0]]).collect()
        }
        _ => order.chunks_exact(3).flatten().copied().collect(),
    }
}

/// The index in `textures` of image `image`, decoded on first use.
fn cached_texture(
    image: usize,
    textures: &mut Vec<Arc<TextureData>>,
    cache: &mut HashMap<usize, usize>,
    decode: impl FnOnce() -> Result<TextureData, SceneError>,
) -> Result<usize, SceneError> {
    if let Some(&t) = cache.get(&image) {
        return Ok(t);
    }
    textures.push(Arc::new(decode()?));
    cache.insert(image, textures.len() - 1);
    Ok(textures.len() - 1)
}

/// The image a texture samples: its EXT_texture_webp source where it has one
/// (the extension's README: a client that decodes WebP uses it, the core
/// `source` being the fallback), else the core source. An index past the images
/// (no source) is returned as is for the caller to refuse or skip.
fn texture_source(root: &json::Root, raw: &serde_json::Value, texture: usize) -> usize {
    let webp = raw["textures"][texture]["extensions"]["EXT_texture_webp"]["source"].as_u64();
    match webp {
        Some(w) if (w as usize) < root.images.len() => w as usize,
        _ => root.textures[texture].source.value(),
    }
}

fn decode_image(
    root: &json::Root,
    data: &Data<'_>,
    ix: usize,
    name: &str,
    resources: &Resources<'_>,
) -> Result<TextureData, SceneError> {
    let img = root.images.get(ix).ok_or_else(|| invalid(name, format!("image {ix} does not exist")))?;
    let what = format!("image {ix}");
    let bytes: Vec<u8> = match (&img.buffer_view, &img.uri) {
        (Some(v), _) => data.view_bytes(v.value(), &what).map_err(|e| invalid(name, e))?.to_vec(),
        (None, Some(uri)) => fetch(uri, &what, name, resources)?,
        (None, None) => return Err(invalid(name, format!("{what} has neither bufferView nor uri"))),
    };
    let decoded = image::load_from_memory(&bytes)
        .map_err(|e| invalid(name, format!("{what}: {e} (PNG, JPEG and WebP are decoded)")))?
        .to_rgba8();
    Ok(TextureData { width: decoded.width(), height: decoded.height(), rgba: decoded.into_raw() })
}

/// Area-weighted vertex normals for meshes that carry none.
pub(super) fn vertex_normals(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
    let mut acc = vec![Vec3::ZERO; positions.len()];
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|i| Vec3::from(positions[tri[i] as usize]));
        let n = (b - a).cross(c - a);
        for &i in tri {
            acc[i as usize] += n;
        }
    }
    acc.into_iter().map(|n| n.try_normalize().unwrap_or(Vec3::Z).to_array()).collect()
}

#[cfg(test)]
#[path = "load_tests.rs"]
mod tests;
