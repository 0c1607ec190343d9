#version 450
// One level of the grain collapse, fused: C_l = E(C_{l+1}) + w_l(luma_l) · (G_l − E(G_{l+1}))
// — band l of the white noise's Laplacian pyramid (level minus expanded coarser
// level), scaled by its synthesis weight at the content's luma of that level, added
// to the expanded coarser collapse. Twin of the band, scale and collapse loops of
// synth::noise_field (image::laplacian_pyramid, LaplacianPyramid::collapse) with the
// same arithmetic in the same order: the 2-D expand is image::expand's row pass
// (x taps in order) then its column pass (y taps in order), on the fly. One
// dispatch per level instead of five (expand ×2, combine, scale, expand ×2,
// combine); vec4s carry the three channels (and the luma) in one load.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

// Joint pyramid level l (noise R, G, B = G_l; w = luma_l), w0 × h0.
layout(std430, set = 0, binding = 0) readonly buffer Fine { vec4 fine[]; };
// Joint pyramid level l + 1 (rgb used), w1 × h1.
layout(std430, set = 0, binding = 1) readonly buffer Coarse { vec4 coarse[]; };
// Collapse of levels ≥ l + 1 (rgb), w1 × h1.
layout(std430, set = 0, binding = 2) readonly buffer Below { vec4 below[]; };
layout(std430, set = 0, binding = 3) readonly buffer Table { float table[]; };
layout(std430, set = 0, binding = 4) buffer Dst { vec4 dst[]; };

layout(push_constant) uniform Params {
    uint w0;
    uint h0;
    uint w1;
    uint h1;
    uint level;
    uint nodes;
    float lo;
    float hi;
} p;

#include "grain_weight.glsl"

// Taps of image::expand: output 2m takes coarse m − 1, m, m + 1 with 2·K5 = 1/8, 3/4,
// 1/8; output 2m + 1 takes m, m + 1 with 1/2, 1/2; indices clamped to the edge. So
// one invocation per 2×2 output quad (2m + {0, 1}, 2n + {0, 1}) loads the 3×3 coarse
// neighbourhood once — 9 loads per field for 4 outputs instead of 9 per output —
// and runs straight-line code (no per-lane parity branches).
vec3 even_row(vec3 a, vec3 b, vec3 c) {
    return 0.125 * a + 0.75 * b + 0.125 * c;
}

vec3 odd_row(vec3 b, vec3 c) {
    return 0.5 * b + 0.5 * c;
}

void store(int x, int y, vec3 eg, vec3 ec) {
    if (x >= int(p.w0) || y >= int(p.h0)) {
        return;
    }
    int i = y * int(p.w0) + x;
    vec4 g = fine[i];
    vec3 band = g.rgb - eg;
    band *= grain_weights(p.level, g.w);
    dst[i] = vec4(ec + band, 0.0);
}

void main() {
    int m = int(gl_GlobalInvocationID.x);
    int n = int(gl_GlobalInvocationID.y);
    if (2 * m >= int(p.w0) || 2 * n >= int(p.h0)) {
        return;
    }
    int w1 = int(p.w1);
    ivec3 jx = clamp(ivec3(m - 1, m, m + 1), ivec3(0), ivec3(w1 - 1));
    ivec3 jy = clamp(ivec3(n - 1, n, n + 1), ivec3(0), ivec3(int(p.h1) - 1)) * w1;
    // Row pass (x) at the three coarse rows, even and odd output columns, both fields.
    vec3 a0 = coarse[jy.x + jx.x].rgb, a1 = coarse[jy.x + jx.y].rgb, a2 = coarse[jy.x + jx.z].rgb;
    vec3 b0 = coarse[jy.y + jx.x].rgb, b1 = coarse[jy.y + jx.y].rgb, b2 = coarse[jy.y + jx.z].rgb;
    vec3 c0 = coarse[jy.z + jx.x].rgb, c1 = coarse[jy.z + jx.y].rgb, c2 = coarse[jy.z + jx.z].rgb;
    vec3 ge0 = even_row(a0, a1, a2), ge1 = even_row(b0, b1, b2), ge2 = even_row(c0, c1, c2);
    vec3 go0 = odd_row(a1, a2), go1 = odd_row(b1, b2), go2 = odd_row(c1, c2);
    a0 = below[jy.x + jx.x].rgb; a1 = below[jy.x + jx.y].rgb; a2 = below[jy.x + jx.z].rgb;
    b0 = below[jy.y + jx.x].rgb; b1 = below[jy.y + jx.y].rgb; b2 = below[jy.y + jx.z].rgb;
    c0 = below[jy.z + jx.x].rgb; c1 = below[jy.z + jx.y].rgb; c2 = below[jy.z + jx.z].rgb;
    vec3 ce0 = even_row(a0, a1, a2), ce1 = even_row(b0, b1, b2), ce2 = even_row(c0, c1, c2);
    vec3 co0 = odd_row(a1, a2), co1 = odd_row(b1, b2), co2 = odd_row(c1, c2);
    // Column pass (y) and the band/scale/collapse for each output of the quad.
    store(2 * m, 2 * n, even_row(ge0, ge1, ge2), even_row(ce0, ce1, ce2));
    store(2 * m + 1, 2 * n, even_row(go0, go1, go2), even_row(co0, co1, co2));
    store(2 * m, 2 * n + 1, odd_row(ge1, ge2), odd_row(ce1, ce2));
    store(2 * m + 1, 2 * n + 1, odd_row(go1, go2), odd_row(co1, co2));
}
