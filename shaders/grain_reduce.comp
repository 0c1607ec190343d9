#version 450
// One axis of the Burt–Adelson reduce on the grain's joint pyramid (vec4 per pixel:
// noise R, G, B and luma, reduced together), twin of image::reduce
// (src/image/pyramid.rs): out[i] = Σ_k K5[k] · in[clamp(2i + k − 2)],
// K5 = [1 4 6 4 1]/16, taps in order, clamp-to-edge. axis 0 halves the width, axis
// 1 the height. Interleaved vec4s: one load per tap instead of one per channel.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { vec4 src[]; };
layout(std430, set = 0, binding = 1) buffer Dst { vec4 dst[]; };

layout(push_constant) uniform Params {
    uint in_w;
    uint in_h;
    uint out_w;
    uint out_h;
    uint axis;
} p;

void main() {
    int x = int(gl_GlobalInvocationID.x);
    int y = int(gl_GlobalInvocationID.y);
    if (x >= int(p.out_w) || y >= int(p.out_h)) {
        return;
    }
    int iw = int(p.in_w);
    // Taps along the axis: base index of the line, stride between samples, centre.
    int centre = p.axis == 0u ? 2 * x : 2 * y;
    int n = p.axis == 0u ? iw : int(p.in_h);
    int base = p.axis == 0u ? y * iw : x;
    int stride = p.axis == 0u ? 1 : iw;
    vec4 acc = vec4(0.0);
    acc += (1.0 / 16.0) * src[base + clamp(centre - 2, 0, n - 1) * stride];
    acc += (4.0 / 16.0) * src[base + clamp(centre - 1, 0, n - 1) * stride];
    acc += (6.0 / 16.0) * src[base + clamp(centre, 0, n - 1) * stride];
    acc += (4.0 / 16.0) * src[base + clamp(centre + 1, 0, n - 1) * stride];
    acc += (1.0 / 16.0) * src[base + clamp(centre + 2, 0, n - 1) * stride];
    dst[y * int(p.out_w) + x] = acc;
}
