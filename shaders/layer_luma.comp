#version 450
// Level 0 of the grain's joint pyramid straight from the layer colour: vec4 per
// pixel = unit white noise R, G, B (twin of synth::gaussian, fresh per frame through
// the seed) and the luma of the virtual content (Rec. 601 on un-premultiplied colour, as
// image::Rgb::luma) after the camera's colour gain and the lens's falloff (the
// grain follows the colour shown). Packed: eye 0's rectangle in rows [0, row1), eye 1's in rows
// [row1, height), width = the wider rectangle. Twin: the luma step of
// synth::layer::grain_layer and render::GrainPass's grain_init.comp.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray raw_colour;
layout(rgba16f, set = 0, binding = 1) uniform readonly image2DArray dof_colour;
layout(rgba16f, set = 0, binding = 2) uniform readonly image2DArray mb_colour;
layout(std430, set = 0, binding = 3) buffer Level0 { vec4 dst[]; };

layout(push_constant) uniform Push {
    ivec4 rect[2];
    int width;           // packed width
    int row1;            // first packed row of eye 1
    int use_fx;
    int height;          // packed height (row1 + eye 1's rows)
    uint seed_lo;
    uint seed_hi;
    uint pad0;
    uint pad1;
    vec4 gain;           // the camera's colour gains, as composite.comp applies them
    vec4 vignette;       // the lens's falloff, likewise
    vec4 centre;
} p;

#include "colour_gain.glsl"

#include "grain_common.glsl"

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
        if (pixel_gain_on(p.gain, p.vignette)) {
            c = colour_gain(c, pixel_gain(at.xy, layer, p.gain, p.vignette, p.centre));
        }
        if (c.a > 1e-3) {
            vec3 u = c.rgb / c.a;
            y = 0.299 * u.r + 0.587 * u.g + 0.114 * u.b;
        }
    }
    uint py = uint(ly + (layer == 0 ? 0 : p.row1));
    uint i = py * uint(p.width) + uint(lx);
    dst[i] = vec4(white_rgb(uint(lx), py, p.seed_lo, p.seed_hi), y);
}
