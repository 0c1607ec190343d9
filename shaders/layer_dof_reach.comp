#version 450
// Depth of field, reach per tile (src/render/layer.rs): for each 8×8 block of the
// scatter passes' workgroup grid, the largest source σ any of its pixels can
// receive from — the max of the block σ maxima (layer_dof_sigma / layer_dof_down)
// over every block within the pass radius, ⌈radius / 8⌉ blocks each way. The
// horizontal pass's sources lie within the radius along the row; the vertical
// pass's are horizontal-pass outputs whose σ is a weighted mean of sources within
// the radius along their rows, so the square neighbourhood bounds both. A tap
// beyond 4σ + h of its source is exactly zero (layer_dof_h.comp `tap`), so a
// workgroup may stop its loop at ⌈4·reach + h⌉ without changing a single sum: the
// result is bit-identical to the full-radius loop, and the twin needs no change.
// The bound is uniform per workgroup, the one kind of loop cut every
// implementation honours (a SIMD CPU rasteriser runs divergent lanes masked).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(r32f, set = 0, binding = 0) uniform readonly image2DArray tile_sigma_in;
layout(r32f, set = 0, binding = 1) uniform writeonly image2DArray reach_out;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // the scatter passes' rectangles (half resolution there)
    ivec2 size;
    int radius;          // the scatter passes' radius
    int step;
    float ppr_ratio;
    float exposure_ratio;
    uint frame;
    uint samples;
} p;

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    ivec2 tiles = (r.zw + 7) / 8;
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (t.x >= tiles.x || t.y >= tiles.y) {
        return;
    }
    int n = (p.radius + 7) / 8;
    ivec2 lo = max(t - n, ivec2(0));
    ivec2 hi = min(t + n, tiles - 1);
    float m = -1.0;
    for (int y = lo.y; y <= hi.y; y++) {
        for (int x = lo.x; x <= hi.x; x++) {
            m = max(m, imageLoad(tile_sigma_in, ivec3(x, y, layer)).x);
        }
    }
    imageStore(reach_out, ivec3(t, layer), vec4(m));
}
