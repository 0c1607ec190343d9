#version 450
// Depth of field on the virtual layer, vertical pass (twin: synth::layer::defocus_layer):
// spreads the horizontal pass's result with the coverage-weighted σ it carried.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray colour_in;
layout(r32f, set = 0, binding = 1) uniform readonly image2DArray sigma_in;
layout(rgba16f, set = 0, binding = 2) uniform writeonly image2DArray colour_out;

// Per workgroup (8×8 block of this dispatch): the largest source σ within reach
// (layer_dof_reach.comp); the tap loop stops where every tap is exactly zero.
layout(r32f, set = 0, binding = 3) uniform readonly image2DArray reach_in;

layout(push_constant) uniform Push {
    ivec4 rect[2];
    ivec2 size;
    int radius;
    int step;
    float ppr_ratio;
    float exposure_ratio;
    uint frame;
    uint samples;
} p;

#include "dof_tap.glsl"

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    ivec2 xy = r.xy + ivec2(gl_GlobalInvocationID.xy);
    if (gl_GlobalInvocationID.x >= uint(r.z) || gl_GlobalInvocationID.y >= uint(r.w)) {
        return;
    }
    vec4 acc = vec4(0.0);
    float h = 0.5 * float(p.step);
    float sigma_max = imageLoad(reach_in, ivec3(gl_WorkGroupID.xy, layer)).x;
    int reach = tap_reach(sigma_max, h, p.radius);
    int d0 = tap_start(reach, p.radius, p.step);
    for (int d = d0; d <= reach; d += p.step) {
        int y = xy.y + d;
        if (y < r.y || y >= r.y + r.w) {
            continue;
        }
        float k = tap(float(-d), h, imageLoad(sigma_in, ivec3(xy.x, y, layer)).x);
        if (k == 0.0) {
            continue;
        }
        acc += k * imageLoad(colour_in, ivec3(xy.x, y, layer));
    }
    imageStore(colour_out, ivec3(xy, layer), acc);
}
