#version 450
// Motion blur, GPU twin of synth::add_motion_blur (src/synth/motion_blur.rs):
// out(p) = (1/λ) ∫_{-λ/2}^{λ/2} I(p + t·F(p)) dt, trapezoid rule with nodes at most
// `max_spacing_px` apart (and at least `min_intervals`), bilinear clamp-to-edge reads.
// The arithmetic follows the CPU twin's order so the two agree to float rounding.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

// Planar RGB (R plane, then G, then B), row-major.
layout(std430, set = 0, binding = 0) readonly buffer Src { float src[]; };
// Per-pixel flow (x, y) in pixels per frame interval.
layout(std430, set = 0, binding = 1) readonly buffer Flow { vec2 flow[]; };
layout(std430, set = 0, binding = 2) buffer Dst { float dst[]; };

layout(push_constant) uniform Params {
    uint width;
    uint height;
    float exposure;
    float max_spacing_px;
    uint min_intervals;
} p;

float fetch(uint c, int x, int y) {
    int xc = clamp(x, 0, int(p.width) - 1);
    int yc = clamp(y, 0, int(p.height) - 1);
    return src[c * p.width * p.height + uint(yc) * p.width + uint(xc)];
}

float bilinear(uint c, float x, float y) {
    float xf = floor(x);
    float yf = floor(y);
    float fx = x - xf;
    float fy = y - yf;
    int x0 = int(xf);
    int y0 = int(yf);
    float a = fetch(c, x0, y0);
    float b = fetch(c, x0 + 1, y0);
    float cc = fetch(c, x0, y0 + 1);
    float d = fetch(c, x0 + 1, y0 + 1);
    float top = a + (b - a) * fx;
    float bottom = cc + (d - cc) * fx;
    return top + (bottom - top) * fy;
}

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.width || y >= p.height) {
        return;
    }
    uint i = y * p.width + x;
    uint plane = p.width * p.height;
    vec2 f = flow[i];
    float streak_px = p.exposure * sqrt(f.x * f.x + f.y * f.y);
    if (streak_px < 1e-6) {
        dst[i] = src[i];
        dst[plane + i] = src[plane + i];
        dst[2u * plane + i] = src[2u * plane + i];
        return;
    }
    uint intervals = max(uint(ceil(streak_px / p.max_spacing_px)), p.min_intervals);
    vec3 acc = vec3(0.0);
    for (uint k = 0u; k <= intervals; k++) {
        float t = p.exposure * (float(k) / float(intervals) - 0.5);
        float wt = (k == 0u || k == intervals) ? 0.5 : 1.0;
        float sx = float(x) + t * f.x;
        float sy = float(y) + t * f.y;
        acc += wt * vec3(bilinear(0u, sx, sy), bilinear(1u, sx, sy), bilinear(2u, sx, sy));
    }
    acc /= float(intervals);
    dst[i] = acc.x;
    dst[plane + i] = acc.y;
    dst[2u * plane + i] = acc.z;
}
