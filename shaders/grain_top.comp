#version 450
// Coarsest level of the collapse: C_L = w_L(luma_L) · G_L, the low-pass of the white
// noise scaled by its synthesis weight at the content's luma of that level (twin of
// the low-pass step of synth::noise_field). Source: the joint pyramid's level L
// (vec4: noise R, G, B, luma); destination: vec4 (R, G, B, 0).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { vec4 src[]; };
layout(std430, set = 0, binding = 1) readonly buffer Table { float table[]; };
layout(std430, set = 0, binding = 2) buffer Dst { vec4 dst[]; };

layout(push_constant) uniform Params {
    uint width;
    uint height;
    uint level;
    uint nodes;
    float lo;
    float hi;
} p;

#include "grain_weight.glsl"

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.width || y >= p.height) {
        return;
    }
    uint i = y * p.width + x;
    vec4 g = src[i];
    dst[i] = vec4(g.rgb * grain_weights(p.level, g.w), 0.0);
}
