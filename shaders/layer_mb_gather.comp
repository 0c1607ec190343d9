#version 450
// Motion blur step 3 (McGuire et al. 2012, Algorithm 1): per pixel, `samples` taps
// along the neighbourhood's dominant half-streak, each weighted by depth-ordered
// cone/cylinder coverage tests, so a moving object's streak spreads over what lies
// behind it (including the transparent pixels around it: the blurred alpha edge) and
// a static foreground stays sharp. Tap count follows the streak length
// (LayerSettings::mb_taps_per_px), capped at `samples`. Per-pixel jitter from an integer hash (identical
// on the CPU twin, synth::layer::motion_blur_layer), fresh each frame.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray colour_a;
layout(rgba16f, set = 0, binding = 1) uniform readonly image2DArray colour_b;
layout(rgba16f, set = 0, binding = 2) uniform readonly image2DArray motion_in;
layout(rgba16f, set = 0, binding = 3) uniform readonly image2DArray neighbour_in;
layout(rgba16f, set = 0, binding = 4) uniform writeonly image2DArray colour_out;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // in pixels
    ivec2 size;
    int radius;          // K (tile size)
    int step;            // 1: read colour_b (DoF output), 0: colour_a (G-buffer)
    float ppr_ratio;
    float exposure_ratio;
    uint frame;
    uint samples;
    float taps_per_px;   // 0: always `samples`
} p;

const float SOFT_Z_M = 0.05;   // depth softness of the ordering tests (metres)
const float EMPTY_Z_M = 1.0e4; // depth of uncovered pixels: behind everything

uint hash(uint x) {
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

vec4 colour(ivec2 xy, int layer) {
    return p.step == 1 ? imageLoad(colour_b, ivec3(xy, layer)) : imageLoad(colour_a, ivec3(xy, layer));
}

vec2 half_streak(vec4 m) {
    vec2 v = m.xy * (0.5 * p.exposure_ratio);
    float len = length(v);
    float k = float(p.radius);
    return (m.w > 0.0 && len > k) ? v * (k / len) : (m.w > 0.0 ? v : vec2(0.0));
}

float closer(float za, float zb) {
    return clamp(1.0 - (za - zb) / SOFT_Z_M, 0.0, 1.0);
}

float cone(float dist, float vlen) {
    return clamp(1.0 - dist / vlen, 0.0, 1.0);
}

float cylinder(float dist, float vlen) {
    return 1.0 - smoothstep(0.95 * vlen, 1.05 * vlen, dist);
}

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    ivec2 x = r.xy + ivec2(gl_GlobalInvocationID.xy);
    if (gl_GlobalInvocationID.x >= uint(r.z) || gl_GlobalInvocationID.y >= uint(r.w)) {
        return;
    }
    vec2 vn = imageLoad(neighbour_in, ivec3(x / p.radius, layer)).xy;
    vec4 cx = colour(x, layer);
    if (length(vn) < 0.5) {
        imageStore(colour_out, ivec3(x, layer), cx);
        return;
    }
    vec4 mx = imageLoad(motion_in, ivec3(x, layer));
    float zx = mx.w > 0.0 ? mx.z : EMPTY_Z_M;
    float vx = max(length(half_streak(mx)), 0.5);
    float weight = 1.0 / vx;
    vec4 sum = cx * weight;
    uint h = hash(uint(x.x) * 1973u + uint(x.y) * 9277u + uint(layer) * 26699u + p.frame * 7919u);
    float j = float(h & 0xffffu) / 65536.0 - 0.5;
    // Taps ∝ the neighbourhood's full streak (2·|vn| px), at least 2, at most
    // `samples`: uniform per tile, so lanes stay together.
    uint n = max(p.samples, 1u);
    if (p.taps_per_px > 0.0) {
        n = clamp(uint(ceil(2.0 * length(vn) * p.taps_per_px)), min(2u, n), n);
    }
    for (uint i = 0u; i < n; i++) {
        float t = mix(-1.0, 1.0, (float(i) + j + 1.0) / (float(n) + 1.0));
        ivec2 y = x + ivec2(floor(vn * t + 0.5));
        if (y.x < r.x || y.y < r.y || y.x >= r.x + r.z || y.y >= r.y + r.w || y == x) {
            continue;
        }
        vec4 my = imageLoad(motion_in, ivec3(y, layer));
        float zy = my.w > 0.0 ? my.z : EMPTY_Z_M;
        float vy = max(length(half_streak(my)), 0.5);
        float dist = length(vec2(y - x));
        float f = closer(zy, zx);
        float b = closer(zx, zy);
        float a = f * cone(dist, vy) + b * cone(dist, vx) + cylinder(dist, vy) * cylinder(dist, vx) * 2.0;
        weight += a;
        sum += a * colour(y, layer);
    }
    imageStore(colour_out, ivec3(x, layer), sum / weight);
}
