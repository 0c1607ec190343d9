#version 450
// Half-resolution DoF, down step (twin: synth::layer::defocus_layer_half): per 2×2
// block inside the full-resolution rectangle, the box average of the premultiplied
// colour and the alpha-weighted σ/2 of its covered pixels (−1 if none). Each pixel's
// σ comes from its depth here (as layer_dof_sigma.comp computes it for the
// full-resolution path): no full-resolution σ image is written and read back.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std140, set = 0, binding = 0) uniform Effect {
    uvec4 head;          // generation, flags, exposure (bits), frame_interval (bits)
    uvec4 dof;           // form, units, range lo (bits), range hi (bits)
    vec4 dof_coeffs;
} e;
layout(rgba16f, set = 0, binding = 1) uniform readonly image2DArray colour_in;
layout(rgba16f, set = 0, binding = 2) uniform readonly image2DArray motion_in;
layout(rgba16f, set = 0, binding = 3) uniform writeonly image2DArray colour_out;
layout(r32f, set = 0, binding = 4) uniform writeonly image2DArray sigma_out;
// Per 8×8 block of this dispatch (= the scatter passes' workgroups, whose rectangle
// is the half-resolution one): the largest σ written in it (−1 if none), for
// layer_dof_reach.comp.
layout(r32f, set = 0, binding = 5) uniform writeonly image2DArray tile_sigma_out;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // full-resolution rectangles
    ivec2 size;
    int radius;
    int step;
    float ppr_ratio;
    float exposure_ratio;
    uint frame;
    uint samples;
} p;

#include "dof_sigma.glsl"

#include "dof_block_max.glsl"

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    ivec2 h0 = r.xy / 2;
    ivec2 h1 = (r.xy + r.zw + 1) / 2;
    ivec2 hxy = h0 + ivec2(gl_GlobalInvocationID.xy);
    float sigma_half = -1.0;
    // No early return: every invocation reaches write_block_max's barrier.
    if (r.z > 0 && r.w > 0 && hxy.x < h1.x && hxy.y < h1.y) {
        vec4 c = vec4(0.0);
        float sw = 0.0;
        float ss = 0.0;
        for (int k = 0; k < 4; k++) {
            ivec2 xy = 2 * hxy + ivec2(k & 1, k >> 1);
            if (xy.x < r.x || xy.y < r.y || xy.x >= r.x + r.z || xy.y >= r.y + r.w) {
                continue;
            }
            vec4 px = imageLoad(colour_in, ivec3(xy, layer));
            c += 0.25 * px;
            vec4 m = imageLoad(motion_in, ivec3(xy, layer));
            if (m.w > 0.0) {
                float sg = sigma_eye(m.z);
                float wt = max(px.a, 1e-3);
                sw += wt;
                ss += wt * 0.5 * sg;
            }
        }
        sigma_half = sw > 0.0 ? ss / sw : -1.0;
        imageStore(colour_out, ivec3(hxy, layer), c);
        imageStore(sigma_out, ivec3(hxy, layer), vec4(sigma_half));
    }
    write_block_max(sigma_half, layer);
}
