#version 450
// Scale one pyramid band of the white noise by its synthesis weight at the content's
// luma (same level), twin of the band loop in synth::noise_field with
// SynthesisTable::weight: linear interpolation over `nodes` luma nodes in [lo, hi].
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) buffer Band { float band[]; };
layout(std430, set = 0, binding = 1) readonly buffer Luma { float luma[]; };
// [node][channel][band], 5 bands per channel.
layout(std430, set = 0, binding = 2) readonly buffer Table { float table[]; };

layout(push_constant) uniform Params {
    uint width;
    uint height;
    uint level;
    uint nodes;
    float lo;
    float hi;
} p;

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.width || y >= p.height) {
        return;
    }
    uint i = y * p.width + x;
    uint plane = p.width * p.height;
    float span = max(p.hi - p.lo, 1e-12);
    float t = clamp((luma[i] - p.lo) / span, 0.0, 1.0) * float(p.nodes - 1u);
    uint k = min(uint(floor(t)), p.nodes - 2u);
    float f = t - float(k);
    for (uint c = 0u; c < 3u; c++) {
        float a = table[(k * 3u + c) * 5u + p.level];
        float b = table[((k + 1u) * 3u + c) * 5u + p.level];
        band[c * plane + i] *= a + (b - a) * f;
    }
}
