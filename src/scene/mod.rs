//! glTF 2.0 scenes as plain data for the G-buffer pass: triangle meshes (position,
//! normal, UV), base-colour materials and textures, the node hierarchy and its
//! animations (translation / rotation / scale channels), evaluated at any time.
//! Reads self-contained `.glb` files (buffers and images embedded).

use glam::{Mat4, Quat, Vec3};
use std::sync::Arc;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("glTF `{input}`: {problem}")]
    Invalid { input: String, problem: String },
}

fn invalid(input: &str, problem: impl Into<String>) -> SceneError {
    SceneError::Invalid { input: input.to_string(), problem: problem.into() }
}

/// Interleaved vertex as the G-buffer's vertex shader reads it (locations 0, 1, 2).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub uv: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<Vertex>() == 32);
const _: () = assert!(std::mem::offset_of!(Vertex, normal) == 12);
const _: () = assert!(std::mem::offset_of!(Vertex, uv) == 24);

/// One glTF primitive, drawn with its node's transform.
#[derive(Clone, Debug)]
pub struct Mesh {
    pub node: usize,
    pub material: usize,
    pub vertices: Vec<Vertex>,
    pub indices: Vec<u32>,
    /// Object-space bounds (min, max).
    pub bounds: (Vec3, Vec3),
}

#[derive(Clone, Debug)]
pub struct Material {
    /// Linear RGBA factor (glTF baseColorFactor).
    pub base_colour: [f32; 4],
    /// Index into `Scene::textures` (sRGB RGBA8).
    pub texture: Option<usize>,
}

#[derive(Clone, Debug)]
pub struct TextureData {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Trs {
    pub fn matrix(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

#[derive(Clone, Debug)]
pub struct Node {
    pub parent: Option<usize>,
    pub rest: Trs,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Property {
    Translation,
    Rotation,
    Scale,
}

/// One animation channel: keyframe times (s) and values (xyz or quaternion xyzw).
#[derive(Clone, Debug)]
pub struct Channel {
    pub node: usize,
    pub property: Property,
    pub times_s: Vec<f32>,
    pub values: Vec<[f32; 4]>,
    /// STEP interpolation (else linear; CUBICSPLINE is read as linear between its
    /// keyframe values, its tangents ignored).
    pub step: bool,
}

#[derive(Clone, Debug)]
pub struct Scene {
    pub nodes: Vec<Node>,
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub textures: Vec<Arc<TextureData>>,
    pub channels: Vec<Channel>,
    /// Longest animation (s); animations loop with this period.
    pub duration_s: f32,
}

impl Scene {
    /// Parse a self-contained binary glTF (`.glb`). `name` names the input in errors.
    pub fn from_glb(bytes: &[u8], name: &str) -> Result<Self, SceneError> {
        let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| invalid(name, e.to_string()))?;
        let blob = gltf.blob.as_deref();
        let buffer_data = |b: gltf::Buffer<'_>| -> Option<&[u8]> {
            match b.source() {
                gltf::buffer::Source::Bin => blob,
                gltf::buffer::Source::Uri(_) => None,
            }
        };
        for b in gltf.buffers() {
            if buffer_data(b.clone()).is_none() {
                return Err(invalid(name, format!("buffer {} is external or missing; embed it (.glb)", b.index())));
            }
        }
        let mut textures = Vec::new();
        let mut image_to_texture = std::collections::HashMap::new();
        for img in gltf.images() {
            let gltf::image::Source::View { view, .. } = img.source() else {
                return Err(invalid(name, format!("image {} is an external file; embed it (.glb)", img.index())));
            };
            let data = buffer_data(view.buffer()).unwrap_or(&[]);
            let slice = data
                .get(view.offset()..view.offset() + view.length())
                .ok_or_else(|| invalid(name, format!("image {} lies outside its buffer", img.index())))?;
            let decoded = image::load_from_memory(slice)
                .map_err(|e| invalid(name, format!("image {}: {e}", img.index())))?
                .to_rgba8();
            image_to_texture.insert(img.index(), textures.len());
            textures.push(Arc::new(TextureData {
                width: decoded.width(),
                height: decoded.height(),
                rgba: decoded.into_raw(),
            }));
        }
        let mut materials: Vec<Material> = gltf
            .materials()
            .map(|m| {
                let pbr = m.pbr_metallic_roughness();
                Material {
                    base_colour: pbr.base_color_factor(),
                    texture: pbr
                        .base_color_texture()
                        .and_then(|t| image_to_texture.get(&t.texture().source().index()).copied()),
                }
            })
            .collect();
        let default_material = materials.len();
        materials.push(Material { base_colour: [0.8, 0.8, 0.8, 1.0], texture: None });

        let mut nodes: Vec<Node> = gltf
            .nodes()
            .map(|n| {
                let (t, r, s) = n.transform().decomposed();
                Node {
                    parent: None,
                    rest: Trs { translation: Vec3::from(t), rotation: Quat::from_array(r), scale: Vec3::from(s) },
                }
            })
            .collect();
        for n in gltf.nodes() {
            for c in n.children() {
                nodes[c.index()].parent = Some(n.index());
            }
        }
        let mut meshes = Vec::new();
        for n in gltf.nodes() {
            let Some(mesh) = n.mesh() else { continue };
            for prim in mesh.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    return Err(invalid(name, format!("mesh {}: only triangle primitives are drawn", mesh.index())));
                }
                let reader = prim.reader(buffer_data);
                let positions: Vec<[f32; 3]> = reader
                    .read_positions()
                    .ok_or_else(|| invalid(name, format!("mesh {} has a primitive without positions", mesh.index())))?
                    .collect();
                let indices: Vec<u32> = match reader.read_indices() {
                    Some(i) => i.into_u32().collect(),
                    None => (0..positions.len() as u32).collect(),
                };
                if let Some(bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
                    return Err(invalid(
                        name,
                        format!("mesh {}: index {bad} ≥ {} vertices", mesh.index(), positions.len()),
                    ));
                }
                if positions.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(invalid(name, format!("mesh {}: non-finite vertex position", mesh.index())));
                }
                let normals: Vec<[f32; 3]> = match reader.read_normals() {
                    Some(n) => n.collect(),
                    None => vertex_normals(&positions, &indices),
                };
                let uvs: Vec<[f32; 2]> = match reader.read_tex_coords(0) {
                    Some(t) => t.into_f32().collect(),
                    None => vec![[0.0; 2]; positions.len()],
                };
                // A NaN here would become a NaN fragment in the G-buffer and spread
                // through every blur: refuse it at load time.
                if normals.iter().flatten().chain(uvs.iter().flatten()).any(|v| !v.is_finite()) {
                    return Err(invalid(
                        name,
                        format!("mesh {}: non-finite normal or texture coordinate", mesh.index()),
                    ));
                }
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
                meshes.push(Mesh {
                    node: n.index(),
                    material: prim.material().index().unwrap_or(default_material),
                    vertices,
                    indices,
                    bounds: (lo, hi),
                });
            }
        }
        if meshes.is_empty() {
            return Err(invalid(name, "no triangle meshes"));
        }
        let mut channels = Vec::new();
        let mut duration_s = 0.0f32;
        for anim in gltf.animations() {
            for ch in anim.channels() {
                let reader = ch.reader(buffer_data);
                let times_s: Vec<f32> = reader.read_inputs().map(|i| i.collect()).unwrap_or_default();
                use gltf::animation::util::ReadOutputs;
                let (property, mut values): (Property, Vec<[f32; 4]>) = match reader.read_outputs() {
                    Some(ReadOutputs::Translations(t)) => {
                        (Property::Translation, t.map(|v| [v[0], v[1], v[2], 0.0]).collect())
                    }
                    Some(ReadOutputs::Scales(s)) => (Property::Scale, s.map(|v| [v[0], v[1], v[2], 0.0]).collect()),
                    Some(ReadOutputs::Rotations(r)) => (Property::Rotation, r.into_f32().collect()),
                    _ => continue, // morph weights: not drawn
                };
                let interp = ch.sampler().interpolation();
                if interp == gltf::animation::Interpolation::CubicSpline {
                    // (in-tangent, value, out-tangent) triples: keep the values.
                    values = values.chunks(3).filter_map(|c| c.get(1).copied()).collect();
                }
                if times_s.is_empty()
                    || values.len() != times_s.len()
                    || times_s.windows(2).any(|w| w[1] < w[0])
                    || times_s.iter().chain(values.iter().flatten()).any(|v| !v.is_finite())
                {
                    return Err(invalid(
                        name,
                        format!("animation {} channel {}: bad keyframes", anim.index(), ch.index()),
                    ));
                }
                duration_s = duration_s.max(*times_s.last().unwrap_or(&0.0));
                channels.push(Channel {
                    node: ch.target().node().index(),
                    property,
                    times_s,
                    values,
                    step: interp == gltf::animation::Interpolation::Step,
                });
            }
        }
        Ok(Self { nodes, meshes, materials, textures, channels, duration_s })
    }

    /// Local transforms at time `t_s` (animations loop over `duration_s`). The
    /// time is f64 and wrapped into the animation before it becomes f32: an
    /// f32 clock of a long-running session steps in whole milliseconds (7.8 ms
    /// after a day), and motion vectors and motion blur would jump with it.
    pub fn local_at(&self, t_s: f64) -> Vec<Trs> {
        let mut local: Vec<Trs> = self.nodes.iter().map(|n| n.rest).collect();
        let t = if self.duration_s > 0.0 { t_s.rem_euclid(self.duration_s as f64) as f32 } else { 0.0 };
        for ch in &self.channels {
            let Some(trs) = local.get_mut(ch.node) else { continue };
            let v = sample(ch, t);
            match ch.property {
                Property::Translation => trs.translation = Vec3::new(v[0], v[1], v[2]),
                Property::Scale => trs.scale = Vec3::new(v[0], v[1], v[2]),
                Property::Rotation => trs.rotation = Quat::from_array(v).normalize(),
            }
        }
        local
    }

    /// `world_from_node` for every node at time `t_s`, with `world_from_scene`
    /// placing the whole scene.
    pub fn world_from_nodes(&self, t_s: f64, world_from_scene: Mat4) -> Vec<Mat4> {
        let local = self.local_at(t_s);
        let mut world: Vec<Option<Mat4>> = vec![None; self.nodes.len()];
        fn resolve(
            i: usize,
            nodes: &[Node],
            local: &[Trs],
            world: &mut [Option<Mat4>],
            root: Mat4,
            depth: usize,
        ) -> Mat4 {
            if let Some(m) = world[i] {
                return m;
            }
            // A malformed cyclic hierarchy stops at the depth guard instead of recursing forever.
            let parent = match nodes[i].parent {
                Some(p) if depth < nodes.len() => resolve(p, nodes, local, world, root, depth + 1),
                _ => root,
            };
            let m = parent * local[i].matrix();
            world[i] = Some(m);
            m
        }
        (0..self.nodes.len()).map(|i| resolve(i, &self.nodes, &local, &mut world, world_from_scene, 0)).collect()
    }

    /// World-space corners of every mesh's bounds at time `t_s`.
    pub fn world_corners(&self, t_s: f64, world_from_scene: Mat4) -> Vec<Vec3> {
        let world = self.world_from_nodes(t_s, world_from_scene);
        let mut out = Vec::with_capacity(self.meshes.len() * 8);
        for m in &self.meshes {
            let (lo, hi) = m.bounds;
            let w = world.get(m.node).copied().unwrap_or(Mat4::IDENTITY);
            for k in 0..8 {
                let c = Vec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                );
                out.push(w.transform_point3(c));
            }
        }
        out
    }
}

fn sample(ch: &Channel, t: f32) -> [f32; 4] {
    let n = ch.times_s.len();
    let k = ch.times_s.partition_point(|&x| x <= t);
    if k == 0 {
        return ch.values[0];
    }
    if k >= n {
        return ch.values[n - 1];
    }
    let (t0, t1) = (ch.times_s[k - 1], ch.times_s[k]);
    let (a, b) = (ch.values[k - 1], ch.values[k]);
    if ch.step || t1 <= t0 {
        return a;
    }
    let f = (t - t0) / (t1 - t0);
    if ch.property == Property::Rotation {
        // glTF spec, Appendix "Interpolation": spherical linear for rotations.
        Quat::from_array(a).normalize().slerp(Quat::from_array(b).normalize(), f).to_array()
    } else {
        std::array::from_fn(|i| a[i] + (b[i] - a[i]) * f)
    }
}

/// Area-weighted vertex normals for meshes that carry none.
fn vertex_normals(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
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
