#version 450
// Test probe for the per-frame uniform block (render::EffectParams): copies the
// whole block, as the GPU sees it this frame, into record `frame` of an output
// buffer, so a test can prove every frame read exactly one published snapshot.
layout(local_size_x = 1, local_size_y = 1, local_size_z = 1) in;

// 224 bytes = 14 × uvec4 (std140 arrays of uvec4 have a 16-byte stride).
layout(std140, set = 0, binding = 0) uniform Params { uvec4 words[14]; } params;
layout(std430, set = 0, binding = 1) buffer Records { uint records[]; };

layout(push_constant) uniform Push { uint frame; } p;

void main() {
    for (uint i = 0u; i < 14u; i++) {
        uvec4 w = params.words[i];
        uint base = p.frame * 56u + i * 4u;
        records[base] = w.x;
        records[base + 1u] = w.y;
        records[base + 2u] = w.z;
        records[base + 3u] = w.w;
    }
}
