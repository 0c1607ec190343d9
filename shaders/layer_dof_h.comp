#version 450
// Depth of field on the virtual layer, horizontal pass (src/render/layer.rs; CPU
// twin synth::layer::separable_scatter), at full or half resolution. Scatter-as-gather: every covered source pixel
// spreads its premultiplied colour with a Gaussian of its OWN blur σ(Z) — a gather
// with the receiving pixel's σ (the paper's addDoF) cannot spread a silhouette into
// the transparent pixels around it, which is what blurs the alpha edge. Kernel taps
// are the Gaussian integrated over each tap's span (exact mass, a delta at σ = 0).
// Separable: this pass also writes the coverage-weighted mean σ of what it gathered,
// which the vertical pass spreads with (exact for constant σ).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray colour_in;
layout(r32f, set = 0, binding = 1) uniform readonly image2DArray sigma_in;
layout(rgba16f, set = 0, binding = 2) uniform writeonly image2DArray colour_out;
layout(r32f, set = 0, binding = 3) uniform writeonly image2DArray sigma_out;

// Per workgroup (8×8 block of this dispatch): the largest source σ within reach
// (layer_dof_reach.comp); the tap loop stops where every tap is exactly zero.
layout(r32f, set = 0, binding = 4) uniform readonly image2DArray reach_in;

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

#include "dof_tap.glsl"

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    ivec2 xy = r.xy + ivec2(gl_GlobalInvocationID.xy);
    if (gl_GlobalInvocationID.x >= uint(r.z) || gl_GlobalInvocationID.y >= uint(r.w)) {
        return;
    }
    vec4 acc = vec4(0.0);
    float s_acc = 0.0;
    float w_acc = 0.0;
    float h = 0.5 * float(p.step);
    float sigma_max = imageLoad(reach_in, ivec3(gl_WorkGroupID.xy, layer)).x;
    int reach = tap_reach(sigma_max, h, p.radius);
    int d0 = tap_start(reach, p.radius, p.step);
    for (int d = d0; d <= reach; d += p.step) {
        int x = xy.x + d;
        if (x < r.x || x >= r.x + r.z) {
            continue;
        }
        float sigma = imageLoad(sigma_in, ivec3(x, xy.y, layer)).x;
        if (sigma < 0.0) {
            continue;
        }
        float k = tap(float(-d), h, sigma);
        if (k == 0.0) {
            continue;
        }
        vec4 c = imageLoad(colour_in, ivec3(x, xy.y, layer));
        acc += k * c;
        float wk = k * c.a;
        s_acc += wk * sigma;
        w_acc += wk;
    }
    imageStore(colour_out, ivec3(xy, layer), acc);
    imageStore(sigma_out, ivec3(xy, layer), vec4(w_acc > 1e-6 ? s_acc / w_acc : 0.0));
}
