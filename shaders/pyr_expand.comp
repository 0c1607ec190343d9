#version 450
// One axis of the Burt–Adelson expand, twin of image::expand (src/image/pyramid.rs):
// out[i] = Σ 2·K5[i − 2j + 2] · in[clamp(j)] over the (up to 3) taps of expand_taps,
// in the same order; axis 0 sums all three taps (zero weights included, like the CPU
// row pass), axis 1 skips zero weights (like the CPU column pass).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { float src[]; };
layout(std430, set = 0, binding = 1) buffer Dst { float dst[]; };

layout(push_constant) uniform Params {
    uint in_w;
    uint in_h;
    uint out_w;
    uint out_h;
    uint channels;
    uint axis;
} p;

float k5(int k) {
    if (k == 0 || k == 4) {
        return 1.0 / 16.0;
    }
    if (k == 1 || k == 3) {
        return 4.0 / 16.0;
    }
    return 6.0 / 16.0;
}

int floordiv2(int a) {
    return a >= 0 ? a / 2 : -((1 - a) / 2);
}

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.out_w || y >= p.out_h) {
        return;
    }
    int pos = p.axis == 0u ? int(x) : int(y);
    int n = p.axis == 0u ? int(p.in_w) : int(p.in_h);
    int j0 = 0;
    int j1 = 0;
    int j2 = 0;
    float w0 = 0.0;
    float w1 = 0.0;
    float w2 = 0.0;
    int t = 0;
    for (int j = floordiv2(pos - 1); j <= floordiv2(pos + 2); j++) {
        int k = pos - 2 * j + 2;
        if (k >= 0 && k < 5 && t < 3) {
            int jc = clamp(j, 0, n - 1);
            float wt = 2.0 * k5(k);
            if (t == 0) {
                j0 = jc;
                w0 = wt;
            } else if (t == 1) {
                j1 = jc;
                w1 = wt;
            } else {
                j2 = jc;
                w2 = wt;
            }
            t++;
        }
    }
    for (uint c = 0u; c < p.channels; c++) {
        uint base = c * p.in_w * p.in_h;
        float acc = 0.0;
        if (p.axis == 0u) {
            uint row = base + y * p.in_w;
            acc += w0 * src[row + uint(j0)];
            acc += w1 * src[row + uint(j1)];
            acc += w2 * src[row + uint(j2)];
        } else {
            if (w0 != 0.0) {
                acc += w0 * src[base + uint(j0) * p.in_w + x];
            }
            if (w1 != 0.0) {
                acc += w1 * src[base + uint(j1) * p.in_w + x];
            }
            if (w2 != 0.0) {
                acc += w2 * src[base + uint(j2) * p.in_w + x];
            }
        }
        dst[c * p.out_w * p.out_h + y * p.out_w + x] = acc;
    }
}
