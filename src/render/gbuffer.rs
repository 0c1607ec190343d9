//! Multiview G-buffer pass (shaders/gbuffer.wgsl): draws a glTF scene into both
//! eyes at once and writes premultiplied colour + alpha, and motion (px per render
//! frame from the previous frame's camera, node transforms and, for skinned and
//! morphed meshes, deformed vertices) + linear depth.

use crate::gpu::{
    Buffer, GpuContext, GpuError, GraphicsDesc, GraphicsPipeline, Image, MultiviewTarget, Texture, VertexAttribute,
};
use crate::model::Rect;
use crate::scene::{AlphaMode, Pose, Scene, Vertex};
use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

const VS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gbuffer.vs_main.spv"));
const FS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gbuffer.fs_main.spv"));

/// G-buffer formats: premultiplied colour, and (motion x, motion y, depth m, cover).
pub const COLOUR_FORMAT: vk::Format = vk::Format::R16G16B16A16_SFLOAT;
pub const MOTION_FORMAT: vk::Format = vk::Format::R16G16B16A16_SFLOAT;

/// Uniform block of `gbuffer.wgsl` (`Frame`).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct FrameUniforms {
    pub clip_from_world: [[f32; 16]; 2],
    pub prev_clip_from_world: [[f32; 16]; 2],
    pub view_from_world: [[f32; 16]; 2],
    pub light: [f32; 4],
    pub size: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<FrameUniforms>() == 416);
const _: () = assert!(std::mem::offset_of!(FrameUniforms, light) == 384);

/// Push constants of `gbuffer.wgsl` (`Draw`): 128 bytes, the guaranteed minimum
/// `maxPushConstantsSize` (Vulkan spec, Required Limits). Transforms are affine
/// (glTF node matrices decompose into TRS, §5.25), so each is its top three rows.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DrawPush {
    world_from_object: [[f32; 4]; 3],
    prev_world_from_object: [[f32; 4]; 3],
    /// x: alpha cutoff (MASK), y: alpha mode (0 opaque, 1 mask, 2 blend),
    /// z: 1 if double-sided, w: 1 if unlit.
    material: [f32; 4],
    /// rgb: emissive (linear).
    emissive: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<DrawPush>() == 128);
const _: () = assert!(std::mem::offset_of!(DrawPush, material) == 96);

/// The top three rows of an affine matrix (row-major), as `Draw` holds them.
fn affine_rows(m: &Mat4) -> [[f32; 4]; 3] {
    let r = m.transpose().to_cols_array_2d();
    [r[0], r[1], r[2]]
}

/// A pinhole eye: intrinsics in eye-buffer pixels and its pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Eye {
    pub focal_px: f32,
    pub centre_px: [f32; 2],
    pub view_from_world: Mat4,
}

/// Vulkan clip space (x right, y down, z in [0, 1]) from a right-handed view space
/// looking down −z, for a pinhole of focal length `focal_px` and principal point
/// `centre_px` in a `width × height` buffer.
pub fn clip_from_view(focal_px: f32, centre_px: [f32; 2], width: u32, height: u32, near_m: f32, far_m: f32) -> Mat4 {
    let (w, h) = (width as f32, height as f32);
    let rows = [
        [2.0 * focal_px / w, 0.0, -(2.0 * centre_px[0] / w - 1.0), 0.0],
        [0.0, -2.0 * focal_px / h, -(2.0 * centre_px[1] / h - 1.0), 0.0],
        [0.0, 0.0, far_m / (near_m - far_m), near_m * far_m / (near_m - far_m)],
        [0.0, 0.0, -1.0, 0.0],
    ];
    Mat4::from_cols_array_2d(&rows).transpose()
}

pub const NEAR_M: f32 = 0.05;

/// How the app lights virtual content (towards the light, world space; ambient
/// fraction): one definition for the desktop renders, the XR loop and benchmarks,
/// so their frames are comparable.
pub const SCENE_LIGHT_DIR: glam::Vec3 = glam::Vec3::new(0.4, 1.0, 0.6);
pub const SCENE_AMBIENT: f32 = 0.35;
pub const FAR_M: f32 = 100.0;

/// Everything one frame of the G-buffer needs: both eyes now and one render frame
/// ago, and the scene's pose (`Scene::pose_at`) now and then.
#[derive(Clone, Debug)]
pub struct GBufferFrame {
    pub eyes: [Eye; 2],
    pub prev_eyes: [Eye; 2],
    pub pose: Pose,
    pub prev_pose: Pose,
    /// Towards the light, world space.
    pub light_dir: Vec3,
    pub ambient: f32,
}

struct GpuMesh<'a> {
    material: usize,
    /// `DrawPush::material` and `emissive` of its material.
    material_push: [[f32; 4]; 2],
    vertices: Buffer<'a>,
    indices: Buffer<'a>,
    count: u32,
    /// A deforming mesh: per frame slot, its vertices now followed by its
    /// vertices one render frame ago (binding 1 reads the second half's
    /// positions), written by `record_in`. Empty for a rigid mesh, whose
    /// previous positions are its positions.
    deformed: Vec<Buffer<'a>>,
    vertex_count: usize,
}

pub struct GBufferPass<'a> {
    // Field order = drop order: pipeline and meshes before the target and textures.
    pipeline: GraphicsPipeline<'a>,
    meshes: Vec<GpuMesh<'a>>,
    uniforms: Vec<Buffer<'a>>,
    _textures: Vec<Texture<'a>>,
    pub target: MultiviewTarget<'a>,
}

impl<'a> GBufferPass<'a> {
    /// Upload `scene` and build the pass for `width × height` eyes with
    /// `frames_in_flight` uniform buffers.
    pub fn new(
        ctx: &'a GpuContext,
        scene: &Scene,
        width: u32,
        height: u32,
        frames_in_flight: usize,
    ) -> Result<Self, GpuError> {
        let target = MultiviewTarget::new(ctx, width, height, &[COLOUR_FORMAT, MOTION_FORMAT], "g-buffer")?;
        let attributes = [
            VertexAttribute { location: 0, format: vk::Format::R32G32B32_SFLOAT, offset: 0 },
            VertexAttribute { location: 1, format: vk::Format::R32G32B32_SFLOAT, offset: 12 },
            VertexAttribute { location: 2, format: vk::Format::R32G32_SFLOAT, offset: 24 },
        ];
        // Previous-frame position (location 3) from binding 1: the same buffer for
        // a rigid mesh, the previous deformed vertices for a skinned/morphed one.
        let second = [VertexAttribute { location: 3, format: vk::Format::R32G32B32_SFLOAT, offset: 0 }];
        let frames = frames_in_flight.max(1);
        let pipeline = GraphicsPipeline::new(
            ctx,
            &target,
            &GraphicsDesc {
                vertex: VS,
                vertex_entry: c"vs_main",
                fragment: FS,
                fragment_entry: c"fs_main",
                stride: std::mem::size_of::<Vertex>() as u32,
                attributes: &attributes,
                second_binding: &second,
                push_size: std::mem::size_of::<DrawPush>() as u32,
                frame_sets: frames as u32,
                material_sets: scene.materials.len() as u32,
            },
            "g-buffer",
        )?;
        // One texture per material with the base-colour factor baked in (glTF:
        // colour = factor × texture), so the draw's push constants stay at 128 B.
        let mut textures = Vec::new();
        for (i, m) in scene.materials.iter().enumerate() {
            let (w, h, mut rgba) = match m.texture.and_then(|t| scene.textures.get(t)) {
                Some(t) => (t.width, t.height, t.rgba.clone()),
                None => (1, 1, vec![255u8; 4]),
            };
            for px in rgba.chunks_exact_mut(4) {
                for c in 0..4 {
                    let f = m.base_colour[c].clamp(0.0, 1.0);
                    px[c] = if c < 3 {
                        // The texture is sRGB-encoded, the factor linear.
                        srgb_encode(srgb_decode(px[c] as f32 / 255.0) * f)
                    } else {
                        (px[c] as f32 * f).round() as u8
                    };
                }
            }
            let tex = Texture::new(ctx, w, h, &rgba, &format!("material {i}"))?;
            // The emissive map (sRGB, glTF: emission = factor × texture); white
            // without one, so the factor alone emits.
            let (ew, eh, erg) = match m.emissive_texture.and_then(|t| scene.textures.get(t)) {
                Some(t) => (t.width, t.height, t.rgba.clone()),
                None => (1, 1, vec![255u8; 4]),
            };
            let emissive = Texture::new(ctx, ew, eh, &erg, &format!("material {i} emissive"))?;
            pipeline.bind_textures(i, &tex, &emissive)?;
            textures.push(tex);
            textures.push(emissive);
        }
        let mut meshes = Vec::new();
        for (i, m) in scene.meshes.iter().enumerate() {
            let mut deformed = Vec::new();
            if m.deform.is_some() {
                for slot in 0..frames {
                    deformed.push(Buffer::new(
                        ctx,
                        (2 * m.vertices.len().max(1) * std::mem::size_of::<Vertex>()) as u64,
                        vk::BufferUsageFlags::VERTEX_BUFFER,
                        vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                        &format!("mesh {i} deformed vertices {slot}"),
                    )?);
                }
            }
            let mat = scene.materials.get(m.material).cloned().unwrap_or_else(crate::scene::Material::fallback);
            let (cutoff, mode) = match mat.alpha {
                AlphaMode::Opaque => (0.0, 0.0),
                AlphaMode::Mask { cutoff } => (cutoff, 1.0),
                AlphaMode::Blend => (0.0, 2.0),
            };
            let e = mat.emissive.map(|c| c.clamp(0.0, 1.0e4));
            meshes.push(GpuMesh {
                material_push: [
                    [cutoff, mode, mat.double_sided as u8 as f32, mat.unlit as u8 as f32],
                    [e[0], e[1], e[2], 0.0],
                ],
                deformed,
                vertex_count: m.vertices.len(),
                material: m.material,
                vertices: ctx.upload_as(
                    bytemuck::cast_slice(&m.vertices),
                    vk::BufferUsageFlags::VERTEX_BUFFER,
                    &format!("mesh {i} vertices"),
                )?,
                indices: ctx.upload_as(
                    bytemuck::cast_slice(&m.indices),
                    vk::BufferUsageFlags::INDEX_BUFFER,
                    &format!("mesh {i} indices"),
                )?,
                count: m.indices.len() as u32,
            });
        }
        let mut uniforms = Vec::new();
        for i in 0..frames {
            let b = Buffer::new(
                ctx,
                std::mem::size_of::<FrameUniforms>() as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                &format!("g-buffer uniforms {i}"),
            )?;
            pipeline.bind_uniform(i, &b)?;
            uniforms.push(b);
        }
        Ok(Self { pipeline, meshes, uniforms, _textures: textures, target })
    }

    pub fn colour(&self) -> &Image<'a> {
        &self.target.colour[0]
    }

    pub fn motion(&self) -> &Image<'a> {
        &self.target.colour[1]
    }

    /// Write slot `slot`'s uniforms (the slot's previous frame must be complete:
    /// callers use `FrameRing::begin`, which waits for it) and record the pass.
    pub fn record(&self, cmd: vk::CommandBuffer, slot: usize, frame: &GBufferFrame) -> Result<(), GpuError> {
        self.record_in(cmd, slot, frame, Rect::full(self.target.width as usize, self.target.height as usize))
    }

    /// `record` confined to `area` (both eyes; see `MultiviewTarget::record_begin`):
    /// the clear and the rasterisation cost follow the content's screen area, not
    /// the eye buffer's. Texels outside `area` are stale; an empty `area` clears 1×1.
    pub fn record_in(
        &self,
        cmd: vk::CommandBuffer,
        slot: usize,
        frame: &GBufferFrame,
        area: Rect,
    ) -> Result<(), GpuError> {
        let (w, h) = (self.target.width, self.target.height);
        let clip = |e: &Eye| clip_from_view(e.focal_px, e.centre_px, w, h, NEAR_M, FAR_M) * e.view_from_world;
        let u = FrameUniforms {
            clip_from_world: [clip(&frame.eyes[0]).to_cols_array(), clip(&frame.eyes[1]).to_cols_array()],
            prev_clip_from_world: [
                clip(&frame.prev_eyes[0]).to_cols_array(),
                clip(&frame.prev_eyes[1]).to_cols_array(),
            ],
            view_from_world: [
                frame.eyes[0].view_from_world.to_cols_array(),
                frame.eyes[1].view_from_world.to_cols_array(),
            ],
            light: {
                let l = frame.light_dir.try_normalize().unwrap_or(Vec3::Y);
                [l.x, l.y, l.z, frame.ambient.clamp(0.0, 1.0)]
            },
            size: [w as f32, h as f32, 0.0, 0.0],
        };
        let all: Vec<f32> = bytemuck::cast_slice::<_, f32>(std::slice::from_ref(&u)).to_vec();
        if all.iter().any(|v| !v.is_finite()) {
            return Err(GpuError::Input { input: "g-buffer frame", problem: "non-finite camera matrix".into() });
        }
        let slot = slot % self.uniforms.len();
        self.uniforms[slot].write(bytemuck::bytes_of(&u))?;
        let area = [area.x.max(0) as u32, area.y.max(0) as u32, area.w.max(0) as u32, area.h.max(0) as u32];
        self.target.record_begin(cmd, &[[0.0; 4], [0.0; 4]], area);
        self.pipeline.record_bind(cmd, slot);
        if !frame.pose.is_finite() || !frame.prev_pose.is_finite() {
            return Err(GpuError::Input { input: "g-buffer frame", problem: "non-finite scene pose".into() });
        }
        for (mi, m) in self.meshes.iter().enumerate() {
            let (Some(now), Some(prev)) =
                (frame.pose.world_from_object.get(mi), frame.prev_pose.world_from_object.get(mi))
            else {
                continue;
            };
            if !is_affine(now) || !is_affine(prev) {
                return Err(GpuError::Input {
                    input: "g-buffer frame",
                    problem: format!("mesh {mi}: a projective world_from_object (glTF transforms are affine)"),
                });
            }
            let push = DrawPush {
                world_from_object: affine_rows(now),
                prev_world_from_object: affine_rows(prev),
                material: m.material_push[0],
                emissive: m.material_push[1],
            };
            match (
                m.deformed.get(slot),
                deformed_of(&frame.pose, mi, m.vertex_count),
                deformed_of(&frame.prev_pose, mi, m.vertex_count),
            ) {
                (Some(buf), Some(cur), Some(before)) => {
                    let mut bytes = Vec::with_capacity(2 * m.vertex_count * std::mem::size_of::<Vertex>());
                    bytes.extend_from_slice(bytemuck::cast_slice(cur));
                    bytes.extend_from_slice(bytemuck::cast_slice(before));
                    buf.write(&bytes)?;
                    let half = (m.vertex_count * std::mem::size_of::<Vertex>()) as u64;
                    self.pipeline.record_draw(
                        cmd,
                        m.material,
                        &[(buf, 0), (buf, half)],
                        &m.indices,
                        m.count,
                        bytemuck::bytes_of(&push),
                    );
                }
                _ => self.pipeline.record_draw(
                    cmd,
                    m.material,
                    &[(&m.vertices, 0), (&m.vertices, 0)],
                    &m.indices,
                    m.count,
                    bytemuck::bytes_of(&push),
                ),
            }
        }
        self.target.record_end(cmd);
        Ok(())
    }
}

/// Whether `m`'s bottom row is (0, 0, 0, 1) to f32 rounding.
fn is_affine(m: &Mat4) -> bool {
    let r = m.row(3);
    r.x.abs() < 1e-6 && r.y.abs() < 1e-6 && r.z.abs() < 1e-6 && (r.w - 1.0).abs() < 1e-6
}

/// Mesh `mi`'s deformed vertices in `pose`, when it has as many as the mesh.
fn deformed_of(pose: &Pose, mi: usize, count: usize) -> Option<&[Vertex]> {
    pose.deformed.get(mi).and_then(|d| d.as_deref()).map(|v| v.as_slice()).filter(|v| v.len() == count)
}

fn srgb_decode(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn srgb_encode(v: f32) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let e = if v <= 0.0031308 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
    (e * 255.0).round() as u8
}
