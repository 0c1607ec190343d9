#version 450
// Variance-matched blend between two DoF stack nodes, twin of the loop body of
// synth::add_defocus (src/synth/dof.rs): a pixel with σ0 < σ ≤ σ1 takes
// (1 − w)·S0 + w·S1 with w = (σ² − σ0²) / (σ1² − σ0²); other pixels are untouched.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Lower { float lower[]; };
layout(std430, set = 0, binding = 1) readonly buffer Upper { float upper[]; };
layout(std430, set = 0, binding = 2) readonly buffer Sigma { float sigma[]; };
layout(std430, set = 0, binding = 3) buffer Dst { float dst[]; };

layout(push_constant) uniform Params {
    uint width;
    uint height;
    float s0;
    float s1;
} p;

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.width || y >= p.height) {
        return;
    }
    uint i = y * p.width + x;
    float s = sigma[i];
    if (s > p.s0 && s <= p.s1) {
        float v0 = p.s0 * p.s0;
        float v1 = p.s1 * p.s1;
        float w = (s * s - v0) / (v1 - v0);
        uint plane = p.width * p.height;
        for (uint c = 0u; c < 3u; c++) {
            uint j = c * plane + i;
            dst[j] = (1.0 - w) * lower[j] + w * upper[j];
        }
    }
}
