#version 450
// One axis of the Burt–Adelson reduce, twin of image::reduce (src/image/pyramid.rs):
// out[i] = Σ_k K5[k] · in[clamp(2i + k − 2)], K5 = [1 4 6 4 1]/16, taps in order,
// clamp-to-edge. axis 0 halves the width, axis 1 the height. Planar channels.
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

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.out_w || y >= p.out_h) {
        return;
    }
    for (uint c = 0u; c < p.channels; c++) {
        float acc = 0.0;
        for (int k = 0; k < 5; k++) {
            int xi = int(x);
            int yi = int(y);
            if (p.axis == 0u) {
                xi = clamp(2 * int(x) + k - 2, 0, int(p.in_w) - 1);
            } else {
                yi = clamp(2 * int(y) + k - 2, 0, int(p.in_h) - 1);
            }
            acc += k5(k) * src[c * p.in_w * p.in_h + uint(yi) * p.in_w + uint(xi)];
        }
        dst[c * p.out_w * p.out_h + y * p.out_w + x] = acc;
    }
}
