#version 450
// Elementwise a − b (Laplacian band: level minus expanded coarser level) or a + b
// (collapse: expanded coarser level plus band), twins of the loops in
// image::laplacian_pyramid and LaplacianPyramid::collapse.
layout(local_size_x = 64, local_size_y = 1, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer A { float a[]; };
layout(std430, set = 0, binding = 1) readonly buffer B { float b[]; };
layout(std430, set = 0, binding = 2) buffer Dst { float dst[]; };

layout(push_constant) uniform Params {
    uint count;
    uint subtract;
} p;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= p.count) {
        return;
    }
    dst[i] = p.subtract != 0u ? a[i] - b[i] : a[i] + b[i];
}
