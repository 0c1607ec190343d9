#version 450
// Motion blur step 2 (McGuire et al. 2012): NeighborMax, the largest TileMax vector
// among each tile and its 8 neighbours, so streaks reach across tile borders.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray tile_in;
layout(rgba16f, set = 0, binding = 1) uniform writeonly image2DArray neighbour_out;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // in tiles
    ivec2 size;          // tile grid size
    int radius;
    int step;
    float ppr_ratio;
    float exposure_ratio;
    uint frame;
    uint samples;
} p;

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    if (gl_GlobalInvocationID.x >= uint(r.z) || gl_GlobalInvocationID.y >= uint(r.w)) {
        return;
    }
    ivec2 tile = r.xy + ivec2(gl_GlobalInvocationID.xy);
    vec2 best = vec2(0.0);
    float best_len = 0.0;
    for (int j = -1; j <= 1; j++) {
        for (int i = -1; i <= 1; i++) {
            ivec2 t = tile + ivec2(i, j);
            if (t.x < r.x || t.y < r.y || t.x >= r.x + r.z || t.y >= r.y + r.w) {
                continue;
            }
            vec2 v = imageLoad(tile_in, ivec3(t, layer)).xy;
            float len = dot(v, v);
            if (len > best_len) {
                best_len = len;
                best = v;
            }
        }
    }
    imageStore(neighbour_out, ivec3(tile, layer), vec4(best, 0.0, 0.0));
}
