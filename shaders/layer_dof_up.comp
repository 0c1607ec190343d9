#version 450
// Half-resolution DoF, up step (twin: synth::layer::defocus_layer_half): bilinear
// upsample of the half-resolution result to the full-resolution rectangle, reads
// clamped to the half rectangle.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray half_in;
layout(rgba16f, set = 0, binding = 1) uniform writeonly image2DArray colour_out;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // full-resolution rectangles
    ivec2 size;
    int radius;
    int step;
    float ppr_ratio;
    float exposure_ratio;
    uint frame;
    uint samples;
} p;

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    ivec2 xy = r.xy + ivec2(gl_GlobalInvocationID.xy);
    if (gl_GlobalInvocationID.x >= uint(r.z) || gl_GlobalInvocationID.y >= uint(r.w)) {
        return;
    }
    ivec2 h0 = r.xy / 2;
    ivec2 h1 = (r.xy + r.zw + 1) / 2 - 1;
    vec2 f = vec2(xy) * 0.5 - 0.25;
    vec2 fl = floor(f);
    vec2 a = f - fl;
    ivec2 i0 = ivec2(fl);
    ivec2 p00 = clamp(i0, h0, h1);
    ivec2 p11 = clamp(i0 + ivec2(1), h0, h1);
    vec4 c00 = imageLoad(half_in, ivec3(p00.x, p00.y, layer));
    vec4 c10 = imageLoad(half_in, ivec3(p11.x, p00.y, layer));
    vec4 c01 = imageLoad(half_in, ivec3(p00.x, p11.y, layer));
    vec4 c11 = imageLoad(half_in, ivec3(p11.x, p11.y, layer));
    vec4 top = c00 + (c10 - c00) * a.x;
    vec4 bottom = c01 + (c11 - c01) * a.x;
    imageStore(colour_out, ivec3(xy, layer), top + (bottom - top) * a.y);
}
