#version 450
// Depth of field, step 1 (src/render/layer.rs; twin synth::layer::dof_sigma_plane):
// each covered pixel's own blur σ in eye pixels from its depth through the fitted
// δ(Z), once per pixel (the scatter passes read it per tap); −1 where uncovered.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std140, set = 0, binding = 0) uniform Effect {
    uvec4 head;          // generation, flags, exposure (bits), frame_interval (bits)
    uvec4 dof;           // form, units, range lo (bits), range hi (bits)
    vec4 dof_coeffs;
} e;
layout(rgba16f, set = 0, binding = 1) uniform readonly image2DArray motion_in;
layout(r32f, set = 0, binding = 2) uniform writeonly image2DArray sigma_out;
// Per 8×8 block (= the scatter passes' workgroups): the largest σ written in it (−1
// if none), for layer_dof_reach.comp.
layout(r32f, set = 0, binding = 3) uniform writeonly image2DArray tile_sigma_out;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // per eye: x, y, width, height
    ivec2 size;
    int radius;
    int step;
    float ppr_ratio;     // eye-buffer pixels per camera pixel
    float exposure_ratio;
    uint frame;
    uint samples;
} p;


#include "dof_sigma.glsl"

#include "dof_block_max.glsl"

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    ivec2 xy = r.xy + ivec2(gl_GlobalInvocationID.xy);
    float sigma = -1.0;
    // No early return: every invocation reaches write_block_max's barrier.
    if (gl_GlobalInvocationID.x < uint(r.z) && gl_GlobalInvocationID.y < uint(r.w)) {
        vec4 m = imageLoad(motion_in, ivec3(xy, layer));
        sigma = m.w > 0.0 ? sigma_eye(m.z) : -1.0;
        imageStore(sigma_out, ivec3(xy, layer), vec4(sigma));
    }
    write_block_max(sigma, layer);
}
