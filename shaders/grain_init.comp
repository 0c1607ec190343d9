#version 450
// Unit white noise per pixel and channel, twin of synth::gaussian (src/synth/rng.rs):
// PCG hash of (x, y, channel, seed), Box–Muller cosine branch. Same u32 arithmetic;
// ln/cos may differ from the CPU's libm in the last bits.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) buffer Dst { float dst[]; };

layout(push_constant) uniform Params {
    uint width;
    uint height;
    uint seed_lo;
    uint seed_hi;
} p;

uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

float gaussian(uint x, uint y, uint c) {
    uint s = p.seed_lo ^ pcg_hash(p.seed_hi);
    uint h1 = pcg_hash(x ^ pcg_hash(y ^ pcg_hash(c ^ pcg_hash(s))));
    uint h2 = pcg_hash(h1 ^ 0x9e3779b9u);
    float u1 = (float(h1 >> 8u) + 1.0) * (1.0 / 16777216.0);
    float u2 = float(h2 >> 8u) * (1.0 / 16777216.0);
    return sqrt(-2.0 * log(u1)) * cos(6.2831855 * u2);
}

void main() {
    uint x = gl_GlobalInvocationID.x;
    uint y = gl_GlobalInvocationID.y;
    if (x >= p.width || y >= p.height) {
        return;
    }
    uint plane = p.width * p.height;
    for (uint c = 0u; c < 3u; c++) {
        dst[c * plane + y * p.width + x] = gaussian(x, y, c);
    }
}
