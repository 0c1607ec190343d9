#version 450
// Level 0 of the grain's joint pyramid from a luma buffer (the reference path,
// render::GrainPass): vec4 per pixel = unit white noise R, G, B (twin of
// synth::gaussian) and the content's luma. In the frame, layer_luma.comp writes the
// same vec4s straight from the layer colour.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Luma { float luma[]; };
layout(std430, set = 0, binding = 1) buffer Dst { vec4 dst[]; };

layout(push_constant) uniform Params {
    uint width;
    uint height;
    uint seed_lo;
    uint seed_hi;
} p;

#include "grain_common.glsl"

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.width || y >= p.height) {
        return;
    }
    uint i = y * p.width + x;
    dst[i] = vec4(white_rgb(x, y, p.seed_lo, p.seed_hi), luma[i]);
}
