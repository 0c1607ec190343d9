#version 450
// One axis of the separable discrete-Gaussian blur used by the DoF stack, twin of
// image::blur_separable (src/image/blur.rs): taps accumulated in order k = 0..2r,
// out = Σ_k w_k · in[clamp(i + k − r)], clamp-to-edge, planar RGB.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { float src[]; };
layout(std430, set = 0, binding = 1) buffer Dst { float dst[]; };
// Every stack interval's kernel, concatenated (uploaded once per pass object).
layout(std430, set = 0, binding = 2) readonly buffer Kernel { float weights[]; };

layout(push_constant) uniform Params {
    uint width;
    uint height;
    uint radius;
    uint axis; // 0: along x (rows), 1: along y (columns)
    uint kernel_offset; // this interval's taps start here in `weights`
} p;

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.width || y >= p.height) {
        return;
    }
    uint plane = p.width * p.height;
    int r = int(p.radius);
    for (uint c = 0u; c < 3u; c++) {
        float acc = 0.0;
        for (int k = 0; k <= 2 * r; k++) {
            int xi = int(x);
            int yi = int(y);
            if (p.axis == 0u) {
                xi = clamp(int(x) + k - r, 0, int(p.width) - 1);
            } else {
                yi = clamp(int(y) + k - r, 0, int(p.height) - 1);
            }
            acc += weights[p.kernel_offset + uint(k)] * src[c * plane + uint(yi) * p.width + uint(xi)];
        }
        dst[c * plane + y * p.width + x] = acc;
    }
}
