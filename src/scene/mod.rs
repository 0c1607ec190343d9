//! glTF 2.0 scenes as plain data for the G-buffer pass: triangle meshes (position,
//! normal, UV), base-colour materials and textures, the node hierarchy, skins and
//! morph targets, and their animations (translation / rotation / scale / weights
//! channels), evaluated at any time into a `Pose`: node matrices and the deformed
//! vertices of skinned and morphed meshes (the G-buffer's motion vectors compare
//! two poses vertex by vertex, so a waving hand streaks as the camera would blur it).
//! Reads `.glb` and `.gltf` (external files beside it, `data:` URIs); `load` says
//! how, `accessor` reads the data with every range checked.

mod accessor;
mod container;
mod load;
mod load_deform;
mod meshopt;

pub use load::SUPPORTED_REQUIRED;

use glam::{Mat4, Quat, Vec3};
use std::sync::Arc;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("glTF `{input}`: {problem}")]
    Invalid { input: String, problem: String },
    /// The reader panicked: a malformed input it did not anticipate. Kept as an
    /// error so the app never goes down on a user's file; the fuzz test over
    /// mutated files holds that no input reaches it.
    #[error("glTF `{input}`: malformed in a way the reader did not anticipate ({detail}); please report this file")]
    Unanticipated { input: String, detail: String },
}

/// Runs a parse, turning a panic inside it (from the glTF crate or this reader)
/// into `SceneError::Unanticipated`.
fn guarded(name: &str, parse: impl FnOnce() -> Result<Scene, SceneError>) -> Result<Scene, SceneError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(parse)).unwrap_or_else(|payload| {
        let detail = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "panic".into());
        Err(SceneError::Unanticipated { input: name.to_string(), detail })
    })
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
    /// Object-space bounds (min, max) of the undeformed vertices.
    pub bounds: (Vec3, Vec3),
    /// Skin and morph targets, when the primitive has either.
    pub deform: Option<Box<Deform>>,
}

/// What moves a mesh's vertices, not only its node: glTF 2.0 §3.7.3 (skins) and
/// §3.7.2.2 (morph targets).
#[derive(Clone, Debug, Default)]
pub struct Deform {
    /// Index into `Scene::skins`; the vertices then follow the joints and the
    /// mesh node's own transform is ignored (§3.7.3.3).
    pub skin: Option<usize>,
    /// JOINTS_0 (indices into the skin's joints) and WEIGHTS_0, one per vertex,
    /// weights normalised to sum 1 at load. Only the first set: four influences.
    pub joints: Vec<[u16; 4]>,
    pub weights: Vec<[f32; 4]>,
    /// Morph targets: per target, per vertex, position and normal displacements.
    pub targets: Vec<MorphTarget>,
    /// Target weights when no animation drives them (the node's `weights`, else
    /// the mesh's, else zeros).
    pub default_weights: Vec<f32>,
}

#[derive(Clone, Debug, Default)]
pub struct MorphTarget {
    pub positions: Vec<[f32; 3]>,
    /// Empty where the target moves no normals.
    pub normals: Vec<[f32; 3]>,
}

/// A skin: its joint nodes and their inverse bind matrices (glTF 2.0 §5.28).
#[derive(Clone, Debug)]
pub struct Skin {
    pub joints: Vec<usize>,
    pub inverse_bind: Vec<Mat4>,
}

/// A morph-weights animation channel (path `weights`): `count` weights per keyframe.
#[derive(Clone, Debug)]
pub struct WeightChannel {
    pub node: usize,
    pub count: usize,
    pub times_s: Vec<f32>,
    /// keyframes × count.
    pub values: Vec<f32>,
    pub step: bool,
    /// CUBICSPLINE: keyframes × count in-tangents and out-tangents (Appendix C).
    pub tangents: Option<(Vec<f32>, Vec<f32>)>,
}

/// The scene at one instant: every node's `world_from_node` and, for each mesh
/// that deforms, its vertices (world space for skinned meshes, object space for
/// morphed ones). Two poses a frame apart give the G-buffer its motion vectors.
#[derive(Clone, Debug, Default)]
pub struct Pose {
    pub world_from_nodes: Vec<Mat4>,
    /// Per mesh: `Some` for a deforming mesh (same length and order as its
    /// `Mesh::vertices`), `None` for a rigid one.
    pub deformed: Vec<Option<Arc<Vec<Vertex>>>>,
    /// Per mesh: world from the space its drawn vertices are in (identity for a
    /// skinned mesh, its node's matrix otherwise).
    pub world_from_object: Vec<Mat4>,
}

#[derive(Clone, Debug)]
pub struct Material {
    /// Linear RGBA factor (glTF baseColorFactor).
    pub base_colour: [f32; 4],
    /// Index into `Scene::textures` (sRGB RGBA8).
    pub texture: Option<usize>,
    pub alpha: AlphaMode,
    /// Back faces drawn (lit with the flipped normal); else culled (glTF 2.0 §3.9.6).
    pub double_sided: bool,
    /// Linear RGB added to the lit colour (glTF emissiveFactor, times
    /// KHR_materials_emissive_strength), times `emissive_texture` where set.
    pub emissive: [f32; 3],
    /// Index into `Scene::textures` (sRGB RGBA8) of the emissive map, sampled at
    /// the same UVs as the base colour.
    pub emissive_texture: Option<usize>,
    /// KHR_materials_unlit: drawn as its base colour, without the key light.
    pub unlit: bool,
}

impl Material {
    /// glTF's default material (§3.9.1): white, opaque, single-sided; drawn grey
    /// here so unlit geometry stays visible over passthrough.
    pub fn fallback() -> Self {
        Self {
            base_colour: [0.8, 0.8, 0.8, 1.0],
            texture: None,
            alpha: AlphaMode::Opaque,
            double_sided: false,
            emissive: [0.0; 3],
            emissive_texture: None,
            unlit: false,
        }
    }
}

/// How a material's alpha covers (glTF 2.0 §3.9.4, `alphaMode`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlphaMode {
    /// Alpha ignored: fully opaque.
    Opaque,
    /// Drawn where alpha ≥ the cutoff, fully opaque there; nothing elsewhere.
    Mask { cutoff: f32 },
    /// Alpha is coverage: the composite blends the surface into the passthrough
    /// by it. The G-buffer keeps the nearest surface (no sorting of layered
    /// transparent surfaces).
    Blend,
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
    /// STEP interpolation (else linear, or cubic with `tangents`).
    pub step: bool,
    /// CUBICSPLINE: each keyframe's (in-tangent, out-tangent), in value units per
    /// second (glTF 2.0 Appendix C).
    pub tangents: Option<Vec<([f32; 4], [f32; 4])>>,
}

#[derive(Clone, Debug)]
pub struct Scene {
    pub nodes: Vec<Node>,
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub textures: Vec<Arc<TextureData>>,
    pub channels: Vec<Channel>,
    pub skins: Vec<Skin>,
    pub weight_channels: Vec<WeightChannel>,
    /// Longest animation (s); animations loop with this period.
    pub duration_s: f32,
    /// What of the file is not drawn, and why (cameras, lights, line primitives, …).
    pub notes: Vec<String>,
}

impl Scene {
    /// Load a `.glb` or `.gltf` file; a `.gltf`'s external buffers and images are
    /// read from its folder.
    pub fn load(path: &std::path::Path) -> Result<Self, SceneError> {
        let name = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|e| invalid(&name, format!("cannot read: {e}")))?;
        let dir = path.parent().unwrap_or(std::path::Path::new("."));
        guarded(&name, || load::parse(&bytes, &name, load::Resources::Folder(dir)))
    }

    /// Parse a `.glb` or `.gltf` whose external files (relative URIs,
    /// percent-decoded) `read` supplies: the headset reads a bundled scene's
    /// buffers and images from the APK's assets this way.
    pub fn from_bytes_with(
        bytes: &[u8],
        name: &str,
        read: &dyn Fn(&str) -> Result<Vec<u8>, String>,
    ) -> Result<Self, SceneError> {
        guarded(name, || load::parse(bytes, name, load::Resources::Reader(read)))
    }

    /// Parse a self-contained glTF (`.glb`, or `.gltf` whose resources are all
    /// `data:` URIs). `name` names the input in errors.
    pub fn from_glb(bytes: &[u8], name: &str) -> Result<Self, SceneError> {
        guarded(name, || load::parse(bytes, name, load::Resources::Embedded))
    }

    /// Local transforms at time `t_s` (animations loop over `duration_s`). The
    /// time is f64 and wrapped into the animation before it becomes f32: an
    /// f32 clock of a long-running session steps in whole milliseconds (7.8 ms
    /// after a day), and motion vectors and motion blur would jump with it.
    pub fn local_at(&self, t_s: f64) -> Vec<Trs> {
        let mut local: Vec<Trs> = self.nodes.iter().map(|n| n.rest).collect();
        let t = self.animation_time(t_s);
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

    /// Time within the looping animation (s), wrapped in f64 first.
    fn animation_time(&self, t_s: f64) -> f32 {
        if self.duration_s > 0.0 {
            t_s.rem_euclid(self.duration_s as f64) as f32
        } else {
            0.0
        }
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

    /// Morph weights of every mesh at time `t_s`: its node's weights channel where
    /// one drives it, else its defaults. Empty for meshes without targets.
    fn mesh_weights_at(&self, t_s: f64) -> Vec<Vec<f32>> {
        let t = self.animation_time(t_s);
        self.meshes
            .iter()
            .map(|m| {
                let Some(d) = m.deform.as_ref().filter(|d| !d.targets.is_empty()) else { return Vec::new() };
                let mut w = d.default_weights.clone();
                w.resize(d.targets.len(), 0.0);
                if let Some(ch) = self.weight_channels.iter().rev().find(|c| c.node == m.node) {
                    for (k, v) in sample_weights(ch, t).into_iter().enumerate().take(w.len()) {
                        w[k] = v;
                    }
                }
                w
            })
            .collect()
    }

    /// The scene at time `t_s`, placed by `world_from_scene`: node matrices and
    /// the deformed meshes' vertices (linear blend skinning, glTF 2.0 §3.7.3.3:
    /// `Σ wᵢ · world_from_jointᵢ · inverse_bindᵢ` applied to the morphed vertex,
    /// §3.7.2.2: `p + Σ wₖ · Δpₖ`).
    pub fn pose_at(&self, t_s: f64, world_from_scene: Mat4) -> Pose {
        let world_from_nodes = self.world_from_nodes(t_s, world_from_scene);
        let weights = self.mesh_weights_at(t_s);
        let mut deformed = Vec::with_capacity(self.meshes.len());
        let mut world_from_object = Vec::with_capacity(self.meshes.len());
        for (mi, m) in self.meshes.iter().enumerate() {
            let node = world_from_nodes.get(m.node).copied().unwrap_or(Mat4::IDENTITY);
            let Some(d) = &m.deform else {
                deformed.push(None);
                world_from_object.push(node);
                continue;
            };
            let mut verts = m.vertices.clone();
            let w = &weights[mi];
            if w.iter().any(|&x| x != 0.0) {
                for (vi, v) in verts.iter_mut().enumerate() {
                    let (mut p, mut n) = (Vec3::from(v.position), Vec3::from(v.normal));
                    let mut moved_normal = false;
                    for (t, &wk) in d.targets.iter().zip(w) {
                        if wk == 0.0 {
                            continue;
                        }
                        if let Some(dp) = t.positions.get(vi) {
                            p += wk * Vec3::from(*dp);
                        }
                        if let Some(dn) = t.normals.get(vi) {
                            n += wk * Vec3::from(*dn);
                            moved_normal = true;
                        }
                    }
                    v.position = p.to_array();
                    if moved_normal {
                        v.normal = n.try_normalize().unwrap_or(Vec3::Z).to_array();
                    }
                }
            }
            let skin = d.skin.and_then(|s| self.skins.get(s));
            match skin {
                Some(skin) => {
                    let joint: Vec<Mat4> = skin
                        .joints
                        .iter()
                        .zip(&skin.inverse_bind)
                        .map(|(&j, ibm)| world_from_nodes.get(j).copied().unwrap_or(world_from_scene) * *ibm)
                        .collect();
                    for (vi, v) in verts.iter_mut().enumerate() {
                        let (js, ws) = (d.joints.get(vi).copied().unwrap_or_default(), d.weights.get(vi).copied());
                        let ws = ws.unwrap_or([1.0, 0.0, 0.0, 0.0]);
                        let mut m4 = Mat4::ZERO;
                        for k in 0..4 {
                            if ws[k] != 0.0 {
                                m4 += joint.get(js[k] as usize).copied().unwrap_or(Mat4::IDENTITY) * ws[k];
                            }
                        }
                        v.position = m4.transform_point3(Vec3::from(v.position)).to_array();
                        // Normals by the blended upper 3×3, as the G-buffer treats
                        // node matrices (uniform scale assumed), renormalised.
                        v.normal =
                            m4.transform_vector3(Vec3::from(v.normal)).try_normalize().unwrap_or(Vec3::Z).to_array();
                    }
                    world_from_object.push(Mat4::IDENTITY);
                }
                None => world_from_object.push(node),
            }
            deformed.push(Some(Arc::new(verts)));
        }
        Pose { world_from_nodes, deformed, world_from_object }
    }

    /// World-space corners of every mesh's bounds at time `t_s` (a deformed
    /// mesh's bounds are its deformed vertices').
    pub fn world_corners(&self, t_s: f64, world_from_scene: Mat4) -> Vec<Vec3> {
        self.pose_at(t_s, world_from_scene).world_corners(self)
    }
}

impl Pose {
    /// World-space corners of every mesh's bounds in this pose.
    pub fn world_corners(&self, scene: &Scene) -> Vec<Vec3> {
        let mut out = Vec::with_capacity(scene.meshes.len() * 8);
        for (mi, m) in scene.meshes.iter().enumerate() {
            let (lo, hi) = match self.deformed.get(mi).and_then(|d| d.as_ref()) {
                Some(v) => bounds(v),
                None => m.bounds,
            };
            let w = self.world_from_object.get(mi).copied().unwrap_or(Mat4::IDENTITY);
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

    /// Whether every matrix and deformed vertex is finite (what reaches the GPU).
    pub fn is_finite(&self) -> bool {
        self.world_from_object.iter().all(|m| m.is_finite())
            && self
                .deformed
                .iter()
                .flatten()
                .all(|v| v.iter().all(|x| x.position.iter().chain(&x.normal).all(|c| c.is_finite())))
    }
}

/// Bounds (min, max) of vertices' positions.
pub(crate) fn bounds(vertices: &[Vertex]) -> (Vec3, Vec3) {
    vertices.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), v| {
        (lo.min(Vec3::from(v.position)), hi.max(Vec3::from(v.position)))
    })
}

/// One weights channel at time `t` (glTF 2.0 Appendix C; weights interpolate
/// component-wise, as translations do).
fn sample_weights(ch: &WeightChannel, t: f32) -> Vec<f32> {
    let (n, c) = (ch.times_s.len(), ch.count);
    let key = |k: usize| &ch.values[k * c..(k + 1) * c];
    let k = ch.times_s.partition_point(|&x| x <= t);
    if k == 0 {
        return key(0).to_vec();
    }
    if k >= n {
        return key(n - 1).to_vec();
    }
    let (t0, t1) = (ch.times_s[k - 1], ch.times_s[k]);
    let (a, b) = (key(k - 1), key(k));
    if ch.step || t1 <= t0 {
        return a.to_vec();
    }
    let f = (t - t0) / (t1 - t0);
    if let Some((ins, outs)) = &ch.tangents {
        let (b0, a1) = (&outs[(k - 1) * c..k * c], &ins[k * c..(k + 1) * c]);
        let td = t1 - t0;
        let (s2, s3) = (f * f, f * f * f);
        let (h00, h10, h01, h11) = (2.0 * s3 - 3.0 * s2 + 1.0, s3 - 2.0 * s2 + f, -2.0 * s3 + 3.0 * s2, s3 - s2);
        return (0..c).map(|i| h00 * a[i] + td * h10 * b0[i] + h01 * b[i] + td * h11 * a1[i]).collect();
    }
    (0..c).map(|i| a[i] + (b[i] - a[i]) * f).collect()
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
    if let Some(tg) = &ch.tangents {
        // glTF 2.0 Appendix C, cubic Hermite spline: with s = f, td = t1 − t0,
        // v = (2s³ − 3s² + 1)·v0 + td·(s³ − 2s² + s)·b0 + (−2s³ + 3s²)·v1 + td·(s³ − s²)·a1,
        // b0 the out-tangent of keyframe k − 1, a1 the in-tangent of keyframe k;
        // rotations are normalised after (the spec's note on quaternions).
        let (b0, a1) = (tg[k - 1].1, tg[k].0);
        let td = t1 - t0;
        let (s2, s3) = (f * f, f * f * f);
        let (h00, h10, h01, h11) = (2.0 * s3 - 3.0 * s2 + 1.0, s3 - 2.0 * s2 + f, -2.0 * s3 + 3.0 * s2, s3 - s2);
        let v: [f32; 4] = std::array::from_fn(|i| h00 * a[i] + td * h10 * b0[i] + h01 * b[i] + td * h11 * a1[i]);
        return if ch.property == Property::Rotation {
            let q = Quat::from_array(v);
            if q.length() > 1e-6 {
                q.normalize().to_array()
            } else {
                a
            }
        } else {
            v
        };
    }
    if ch.property == Property::Rotation {
        // glTF spec, Appendix "Interpolation": spherical linear for rotations.
        Quat::from_array(a).normalize().slerp(Quat::from_array(b).normalize(), f).to_array()
    } else {
        std::array::from_fn(|i| a[i] + (b[i] - a[i]) * f)
    }
}
