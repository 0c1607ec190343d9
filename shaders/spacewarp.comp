#version 450
// XR_FB_space_warp inputs from the G-buffer, per eye at the motion-vector
// resolution: each output texel takes the G-buffer texel under its centre
// (nearest). Motion vectors in NDC units per render frame (the G-buffer's pixel
// motion × 2 / eye size; x right, y down as Vulkan's NDC), z = 0 (no depth motion
// is tracked); depth as the projection's NDC depth, f·(d − n) / ((f − n)·d) for view
// depth d (0 at the near plane, 1 at the far). Texels outside the rectangle the
// G-buffer pass wrote this frame, or uncovered, are empty: motion 0, depth 1 (far).
// Twin: synth::layer::space_warp.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray motion;
layout(rgba16f, set = 0, binding = 1) uniform writeonly image2DArray vectors;
layout(std430, set = 0, binding = 2) buffer Depth { float depth[]; };

layout(push_constant) uniform Push {
    ivec4 area;          // the G-buffer pass's rectangle (both eyes): x, y, w, h
    ivec2 eye_size;      // G-buffer size
    ivec2 mv_size;       // output size
    float near_m;
    float far_m;
    int pad0;
    int pad1;
} p;

void main() {
    ivec2 xy = ivec2(gl_GlobalInvocationID.xy);
    int layer = int(gl_GlobalInvocationID.z);
    if (xy.x >= p.mv_size.x || xy.y >= p.mv_size.y) {
        return;
    }
    ivec2 src = ivec2((vec2(xy) + 0.5) * vec2(p.eye_size) / vec2(p.mv_size));
    src = clamp(src, ivec2(0), p.eye_size - 1);
    bool inside = src.x >= p.area.x && src.y >= p.area.y && src.x < p.area.x + p.area.z && src.y < p.area.y + p.area.w;
    vec4 m = inside ? imageLoad(motion, ivec3(src, layer)) : vec4(0.0);
    vec4 v = vec4(0.0);
    float d = 1.0;
    if (m.w > 0.5 && m.z > 0.0) {
        v = vec4(m.xy * 2.0 / vec2(p.eye_size), 0.0, 0.0);
        d = clamp(p.far_m * (m.z - p.near_m) / ((p.far_m - p.near_m) * m.z), 0.0, 1.0);
    }
    imageStore(vectors, ivec3(xy, layer), v);
    depth[(layer * p.mv_size.y + xy.y) * p.mv_size.x + xy.x] = d;
}
