// XR_META_environment_depth's depth images (VK_FORMAT_D16_UNORM, two array layers:
// left and right eye) read into a buffer of floats, layer-major then row-major as
// stored (row 0 is the image's first row; src/xr/env_depth.rs orders the rows).
// Texel fetches, no sampler and no filtering: the values stay the NDC depths the
// runtime wrote (a D16 texel is k/65535 exactly). Read by src/gpu/depth_readback.rs.

@group(0) @binding(0) var depth: texture_depth_2d_array;

struct Values {
    v: array<f32>,
}
@group(0) @binding(1) var<storage, read_write> dst: Values;

struct Push {
    width: u32,
    height: u32,
}
var<push_constant> p: Push;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= p.width || id.y >= p.height || id.z >= 2u) {
        return;
    }
    let d = textureLoad(depth, vec2<i32>(id.xy), i32(id.z), 0);
    dst.v[(id.z * p.height + id.y) * p.width + id.x] = d;
}
