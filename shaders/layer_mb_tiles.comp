#version 450
// Motion blur on the virtual layer, step 1 of McGuire et al. 2012 ("A reconstruction
// filter for plausible motion blur"): TileMax, the largest half-streak vector in each
// K×K tile. Half-streak V = motion per render frame × exposure_ratio / 2, clamped to
// K px (the reconstruction's reach). Twin: synth::layer::motion_blur_layer.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray motion_in;
layout(rgba16f, set = 0, binding = 1) uniform writeonly image2DArray tile_out;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // per eye, in tiles here: x, y, width, height
    ivec2 size;          // eye-buffer size in pixels
    int radius;          // K, the tile size in pixels
    int step;
    float ppr_ratio;
    float exposure_ratio;
    uint frame;
    uint samples;
} p;

vec2 half_streak(vec4 m) {
    vec2 v = m.xy * (0.5 * p.exposure_ratio);
    float len = length(v);
    float k = float(p.radius);
    return (m.w > 0.0 && len > k) ? v * (k / len) : (m.w > 0.0 ? v : vec2(0.0));
}

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    if (gl_GlobalInvocationID.x >= uint(r.z) || gl_GlobalInvocationID.y >= uint(r.w)) {
        return;
    }
    ivec2 tile = r.xy + ivec2(gl_GlobalInvocationID.xy);
    vec2 best = vec2(0.0);
    float best_len = 0.0;
    for (int j = 0; j < p.radius; j++) {
        for (int i = 0; i < p.radius; i++) {
            ivec2 xy = tile * p.radius + ivec2(i, j);
            if (xy.x >= p.size.x || xy.y >= p.size.y) {
                continue;
            }
            vec2 v = half_streak(imageLoad(motion_in, ivec3(xy, layer)));
            float len = dot(v, v);
            if (len > best_len) {
                best_len = len;
                best = v;
            }
        }
    }
    imageStore(tile_out, ivec3(tile, layer), vec4(best, 0.0, 0.0));
}
