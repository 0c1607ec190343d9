// Shared by the grain shaders (textually included by build.rs).
// Unit white noise per pixel and channel, twin of synth::gaussian (src/synth/rng.rs):
// PCG hash of (x, y, channel, seed), Box–Muller cosine branch. Same u32 arithmetic;
// ln/cos may differ from the CPU's libm in the last bits.
uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

float gaussian(uint x, uint y, uint c, uint seed_lo, uint seed_hi) {
    uint s = seed_lo ^ pcg_hash(seed_hi);
    uint h1 = pcg_hash(x ^ pcg_hash(y ^ pcg_hash(c ^ pcg_hash(s))));
    uint h2 = pcg_hash(h1 ^ 0x9e3779b9u);
    float u1 = (float(h1 >> 8u) + 1.0) * (1.0 / 16777216.0);
    float u2 = float(h2 >> 8u) * (1.0 / 16777216.0);
    return sqrt(-2.0 * log(u1)) * cos(6.2831855 * u2);
}

vec3 white_rgb(uint x, uint y, uint seed_lo, uint seed_hi) {
    return vec3(gaussian(x, y, 0u, seed_lo, seed_hi), gaussian(x, y, 1u, seed_lo, seed_hi),
                gaussian(x, y, 2u, seed_lo, seed_hi));
}
