// Multiview G-buffer pass for glTF content (src/render/gbuffer.rs). One draw covers
// both eyes: `view_index` (VK_KHR_multiview) selects the eye's matrices.
// Outputs (two rgba16f layers per eye):
//   0: premultiplied colour, sRGB-encoded (the camera model is fitted on encoded
//      frames, so the effects and the composite run in that space), alpha;
//   1: screen motion (px per render frame, +x right, +y down) from the previous
//      frame's camera, object transforms and vertices, linear view depth in metres, and 1
//      where a surface was drawn.
// WGSL, not GLSL: naga's GLSL front end has no gl_ViewIndex.

struct Frame {
    clip_from_world: array<mat4x4<f32>, 2>,
    prev_clip_from_world: array<mat4x4<f32>, 2>,
    view_from_world: array<mat4x4<f32>, 2>,
    // xyz: direction towards the light (world, unit); w: ambient share.
    light: vec4<f32>,
    // x, y: eye-buffer size in pixels.
    size: vec4<f32>,
}

// Affine transforms as their top three rows (row-major); the material's alpha
// handling (glTF 2.0 §3.9.4) and emission.
struct Draw {
    world_from_object: array<vec4<f32>, 3>,
    prev_world_from_object: array<vec4<f32>, 3>,
    // x: alpha cutoff (MASK), y: mode (0 OPAQUE, 1 MASK, 2 BLEND), z: 1 if double-sided,
    // w: 1 if unlit (KHR_materials_unlit).
    material: vec4<f32>,
    // rgb: emissive factor (linear), times the emissive map.
    emissive: vec4<f32>,
}

fn affine(rows: array<vec4<f32>, 3>, p: vec3<f32>) -> vec4<f32> {
    let h = vec4<f32>(p, 1.0);
    return vec4<f32>(dot(rows[0], h), dot(rows[1], h), dot(rows[2], h), 1.0);
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(0) var base_colour: texture_2d<f32>;
@group(1) @binding(1) var base_sampler: sampler;
// The emissive map (white when the material has none), sampled like the base colour.
@group(1) @binding(2) var emissive_map: texture_2d<f32>;
var<push_constant> draw: Draw;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal_world: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) cur_clip: vec4<f32>,
    @location(3) prev_clip: vec4<f32>,
    @location(4) depth_m: f32,
}

@vertex
fn vs_main(
    @builtin(view_index) view: i32,
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    // The vertex one render frame ago (binding 1): `position` again for a rigid
    // mesh, the previous skinned/morphed vertex for a deforming one.
    @location(3) prev_position: vec3<f32>,
) -> VsOut {
    let world = affine(draw.world_from_object, position);
    let prev_world = affine(draw.prev_world_from_object, prev_position);
    var out: VsOut;
    out.cur_clip = frame.clip_from_world[view] * world;
    out.prev_clip = frame.prev_clip_from_world[view] * prev_world;
    out.clip = out.cur_clip;
    // Normals: the upper 3×3 (uniform scale assumed; renormalised per fragment).
    let r = draw.world_from_object;
    out.normal_world = vec3<f32>(dot(r[0].xyz, normal), dot(r[1].xyz, normal), dot(r[2].xyz, normal));
    out.uv = uv;
    out.depth_m = -(frame.view_from_world[view] * world).z;
    return out;
}

struct FsOut {
    @location(0) colour: vec4<f32>,
    @location(1) motion: vec4<f32>,
}

fn srgb_encode(c: vec3<f32>) -> vec3<f32> {
    let x = clamp(c, vec3<f32>(0.0), vec3<f32>(1.0));
    let lo = x * 12.92;
    let hi = 1.055 * pow(x, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(hi, lo, x <= vec3<f32>(0.0031308));
}

@fragment
fn fs_main(in: VsOut, @builtin(front_facing) front: bool) -> FsOut {
    let texel = textureSample(base_colour, base_sampler, in.uv);
    let emission = draw.emissive.rgb * textureSample(emissive_map, base_sampler, in.uv).rgb;
    // Single-sided materials show their front faces only (glTF 2.0 §3.9.6).
    if (!front && draw.material.z < 0.5) {
        discard;
    }
    var n = normalize(in.normal_world);
    if (!front) {
        n = -n;
    }
    // §3.9.4: OPAQUE ignores alpha; MASK draws, fully opaque, where alpha ≥ the
    // cutoff and nothing elsewhere; BLEND's alpha is the coverage the composite
    // blends the passthrough by (nothing drawn at zero alpha, so no depth or
    // motion is written for an invisible surface).
    var alpha = clamp(texel.a, 0.0, 1.0);
    let mode = draw.material.y;
    if (mode < 0.5) {
        alpha = 1.0;
    } else if (mode < 1.5) {
        if (alpha < draw.material.x) {
            discard;
        }
        alpha = 1.0;
    } else if (alpha < 0.5 / 255.0) {
        discard;
    }
    let ambient = frame.light.w;
    var shade = ambient + (1.0 - ambient) * max(dot(n, frame.light.xyz), 0.0);
    // KHR_materials_unlit: the base colour as authored, whatever the light.
    if (draw.material.w > 0.5) {
        shade = 1.0;
    }
    let lit = texel.rgb * shade + emission;
    var out: FsOut;
    out.colour = vec4<f32>(srgb_encode(lit) * alpha, alpha);
    // NDC → pixels: x_px = (ndc.x + 1) / 2 · width (Vulkan NDC +y is down, as rows).
    let cur = in.cur_clip.xy / in.cur_clip.w;
    let prev = in.prev_clip.xy / max(in.prev_clip.w, 1e-6);
    let motion_px = (cur - prev) * 0.5 * frame.size.xy;
    out.motion = vec4<f32>(motion_px, in.depth_m, 1.0);
    return out;
}
