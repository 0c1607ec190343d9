// Synthesis weights of `level` for channels R, G, B at luma y, twin of
// synth::SynthesisTable::weight: linear interpolation over p.nodes luma nodes in
// [p.lo, p.hi]; needs `table` ([node][channel][band], 5 bands) and push constants
// `nodes`, `lo`, `hi` declared before the include. The node lookup is shared by
// the three channels.
vec3 grain_weights(uint level, float y) {
    float span = max(p.hi - p.lo, 1e-12);
    float t = clamp((y - p.lo) / span, 0.0, 1.0) * float(p.nodes - 1u);
    uint k = min(uint(floor(t)), p.nodes - 2u);
    float f = t - float(k);
    uint a0 = k * 15u + level;
    uint b0 = a0 + 15u;
    vec3 a = vec3(table[a0], table[a0 + 5u], table[a0 + 10u]);
    vec3 b = vec3(table[b0], table[b0 + 5u], table[b0 + 10u]);
    return a + (b - a) * f;
}
