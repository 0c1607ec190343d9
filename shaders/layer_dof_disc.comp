#version 450
// Depth of field on the virtual layer with a disc kernel (src/render/layer.rs; CPU
// twin synth::layer::disc_scatter), at full or half resolution, replacing the
// Gaussian's h/v pair when the camera model says `kernel: disc`. Scatter-as-gather
// like layer_dof_h: every covered source spreads its premultiplied colour with the
// disc of its OWN σ(Z), so silhouettes spread into transparent pixels. A disc is not
// separable: one 2-D loop, bounded per workgroup by the largest source σ within
// reach (layer_dof_reach) to the disc's own support, row by row (dof_disc.glsl).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray colour_in;
layout(r32f, set = 0, binding = 1) uniform readonly image2DArray sigma_in;
layout(rgba16f, set = 0, binding = 2) uniform writeonly image2DArray colour_out;
layout(r32f, set = 0, binding = 3) uniform readonly image2DArray reach_in;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // per eye: x, y, width, height
    ivec2 size;
    int radius;
    int step;
    float ppr_ratio;
    float exposure_ratio;
    uint frame;
    uint samples;
} p;

#include "dof_tap.glsl"
#include "dof_disc.glsl"

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
    int reach = disc_tap_reach(sigma_max, h, p.radius);
    int d0 = tap_start(reach, p.radius, p.step);
    for (int dy = d0; dy <= reach; dy += p.step) {
        int y = xy.y + dy;
        if (y < r.y || y >= r.y + r.w) {
            continue;
        }
        // Same lattice as the full loop (tap_start), so the taps visited are its
        // non-zero ones, in its order.
        int row = disc_row_reach(dy, sigma_max, h, reach);
        for (int dx = tap_start(row, p.radius, p.step); dx <= row; dx += p.step) {
            int x = xy.x + dx;
            if (x < r.x || x >= r.x + r.z) {
                continue;
            }
            float sigma = imageLoad(sigma_in, ivec3(x, y, layer)).x;
            if (sigma < 0.0) {
                continue;
            }
            float k = disc_scatter_tap(float(dx), float(dy), h, sigma);
            if (k == 0.0) {
                continue;
            }
            acc += k * imageLoad(colour_in, ivec3(x, y, layer));
        }
    }
    imageStore(colour_out, ivec3(xy, layer), acc);
}
