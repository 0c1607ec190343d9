#version 450
// Luma of the virtual content for the grain (Rec. 601 on un-premultiplied colour,
// as image::Rgb::luma), packed for GrainPass: eye 0's rectangle in rows
// [0, h0), eye 1's in rows [h0, h0 + h1), width = the wider rectangle.
// Twin: the luma step of synth::layer::grain_layer.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray raw_colour;
layout(rgba16f, set = 0, binding = 1) uniform readonly image2DArray dof_colour;
layout(rgba16f, set = 0, binding = 2) uniform readonly image2DArray mb_colour;
layout(std430, set = 0, binding = 3) buffer Luma { float luma[]; };

layout(push_constant) uniform Push {
    ivec4 rect[2];
    int width;           // packed width
    int row1;            // first packed row of eye 1
    int use_fx;
    int pad1;
} p;

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    int lx = int(gl_GlobalInvocationID.x);
    int ly = int(gl_GlobalInvocationID.y);
    if (lx >= p.width || ly >= (layer == 0 ? p.row1 : p.rect[1].w)) {
        return;
    }
    float y = 0.0;
    if (lx < r.z && ly < r.w) {
        ivec3 at = ivec3(r.x + lx, r.y + ly, layer);
        vec4 c = p.use_fx == 2 ? imageLoad(mb_colour, at)
                 : (p.use_fx == 1 ? imageLoad(dof_colour, at) : imageLoad(raw_colour, at));
        if (c.a > 1e-3) {
            vec3 u = c.rgb / c.a;
            y = 0.299 * u.r + 0.587 * u.g + 0.114 * u.b;
        }
    }
    luma[(ly + (layer == 0 ? 0 : p.row1)) * p.width + lx] = y;
}
