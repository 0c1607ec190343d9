#version 450
// Composite over the background, per eye (desktop: the camera frame, opaque; the
// headset: transparent, the compositor blends the result over passthrough):
// out = bg·(1 − α) + G(C) + α·n, G the camera's colour gain times the lens's
// falloff at the pixel (colour_gain.glsl), C's red and blue resampled where the
// lens's lateral aberration moved them from (per-channel α), alpha = bg.a·(1 − α) + α, with C, α the (blurred) premultiplied virtual layer
// and n the grain field at the virtual content's luma, faded by the blurred alpha
// so the grain stops where the object does. Encoded (sRGB) space throughout: the
// camera model was fitted on encoded frames. Stored premultiplied, or straight
// (colour / alpha) where the XR layer asks for it. Twin: synth::layer::composite.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray raw_colour;
layout(rgba16f, set = 0, binding = 1) uniform readonly image2DArray dof_colour;
layout(rgba16f, set = 0, binding = 2) uniform readonly image2DArray mb_colour;
layout(rgba8, set = 0, binding = 3) uniform readonly image2DArray background;
layout(std430, set = 0, binding = 4) readonly buffer Noise { vec4 noise[]; };  // RGB + unused
layout(rgba8, set = 0, binding = 5) uniform writeonly image2DArray out_image;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // where the virtual content is; elsewhere background only
    ivec2 size;
    int use_fx;
    int use_noise;
    int noise_width;     // packed grain field, one vec4 per pixel (see layer_luma.comp)
    int row1;
    int straight_alpha;  // 1: colour divided by the output alpha (see the end of main)
    int pad1;
    vec4 gain;           // xyz: the camera's colour gains (linear light); w > 0.5: apply
    vec4 vignette;       // xyz: the lens's log-falloff terms; w: 1 / half-diagonal px (0: none)
    vec4 centre;         // the eyes' principal points: xy eye 0, zw eye 1
    vec4 chroma;         // lateral aberration: xy 1/s − 1 of red, blue; z: 1 / half-diagonal px; w > 0.5: apply
} p;

#include "colour_gain.glsl"

// The chain's last output (1: DoF, 2: MB) or raw colour at texel q inside eye
// `layer`'s rectangle; outside it nothing: the G-buffer pass only wrote the
// rectangle covering both eyes' (render area), so texels out there are stale.
vec4 chain_at(ivec2 q, int layer) {
    ivec4 r = p.rect[layer];
    if (q.x < 0 || q.y < 0 || q.x >= p.size.x || q.y >= p.size.y
        || q.x < r.x || q.y < r.y || q.x >= r.x + r.z || q.y >= r.y + r.w) {
        return vec4(0.0);
    }
    ivec3 at = ivec3(q, layer);
    return p.use_fx == 2 ? imageLoad(mb_colour, at)
           : (p.use_fx == 1 ? imageLoad(dof_colour, at) : imageLoad(raw_colour, at));
}

// Bilinear sample of the chain at continuous pixel coordinates q (texel centres at
// +½). Twin: synth::layer's `bilinear`, the same order of operations.
vec4 bilinear(vec2 q, int layer) {
    vec2 u = q - 0.5;
    vec2 f0 = floor(u);
    vec2 f = u - f0;
    ivec2 i0 = ivec2(f0);
    vec4 c00 = chain_at(i0, layer);
    vec4 c10 = chain_at(i0 + ivec2(1, 0), layer);
    vec4 c01 = chain_at(i0 + ivec2(0, 1), layer);
    vec4 c11 = chain_at(i0 + ivec2(1, 1), layer);
    vec4 top = c00 + f.x * (c10 - c00);
    vec4 bottom = c01 + f.x * (c11 - c01);
    return top + f.y * (bottom - top);
}

// Where the lens moved channel k (0 red, 1 blue) of pixel xy from: c + (xy + ½ − c)/s,
// the offset held at the camera's corner radius beyond it (model::EyeChromatic::source).
vec2 ca_source(ivec2 xy, int layer, float inv_scale_minus_one) {
    vec2 c = layer == 0 ? p.centre.xy : p.centre.zw;
    vec2 px = vec2(xy) + 0.5;
    vec2 d = px - c;
    float r = sqrt(d.x * d.x + d.y * d.y) * p.chroma.z;
    float f = inv_scale_minus_one / max(r, 1.0);
    return px + f * d;
}

void main() {
    ivec2 xy = ivec2(gl_GlobalInvocationID.xy);
    int layer = int(gl_GlobalInvocationID.z);
    if (xy.x >= p.size.x || xy.y >= p.size.y) {
        return;
    }
    ivec4 r = p.rect[layer];
    bool inside = xy.x >= r.x && xy.y >= r.y && xy.x < r.x + r.z && xy.y < r.y + r.w;
    vec4 c = chain_at(xy, layer);
    // The camera's order: optics (the lens's falloff and lateral aberration — a gain
    // per pixel and a per-channel magnification of ≤ a few pixels, so both commute
    // with the chain's blurs up to their reach over their slow variation — DoF, MB:
    // the chain) before the ISP's white balance and exposure, then its noise.
    // Falloff and colour are both linear-light gains: applied as one. With the
    // aberration, red and blue (colour and alpha) come from where the lens moved
    // them, and each channel goes "over" the background with its own alpha.
    vec4 cr = c;
    vec4 cb = c;
    if (p.chroma.w > 0.5) {
        cr = bilinear(ca_source(xy, layer, p.chroma.x), layer);
        cb = bilinear(ca_source(xy, layer, p.chroma.y), layer);
    }
    bool gain_on = pixel_gain_on(p.gain, p.vignette);
    vec3 g = gain_on ? pixel_gain(xy, layer, p.gain, p.vignette, p.centre) : vec3(1.0);
    vec4 sr = gain_on ? colour_gain(cr, g) : cr;
    vec4 sg = gain_on ? colour_gain(c, g) : c;
    vec4 sb = gain_on ? colour_gain(cb, g) : cb;
    vec3 ak = clamp(vec3(sr.a, sg.a, sb.a), 0.0, 1.0);
    vec4 bg = imageLoad(background, ivec3(xy, layer));
    vec3 rgb = bg.rgb * (1.0 - ak) + vec3(sr.r, sg.g, sb.b);
    float a = ak.g;
    if (p.use_noise != 0 && inside && a > 0.0) {
        int row = (xy.y - r.y) + (layer == 0 ? 0 : p.row1);
        int i = row * p.noise_width + (xy.x - r.x);
        rgb += a * noise[i].rgb;
    }
    float a_max = max(ak.r, max(ak.g, ak.b));
    // Premultiplied "over" alpha: 1 over an opaque background (desktop), the
    // blurred virtual alpha over a transparent one (the headset's projection layer
    // over passthrough, blended by the compositor). Premultiplied colour never
    // exceeds its alpha.
    float ao = clamp(bg.a * (1.0 - a_max) + a_max, 0.0, 1.0);
    vec3 pm = clamp(rgb, 0.0, ao);
    // Straight alpha for the headset's projection layer, submitted with
    // XR_COMPOSITION_LAYER_UNPREMULTIPLIED_ALPHA_BIT into an sRGB swapchain: the
    // compositor decodes the colour to linear light and only then multiplies by
    // alpha (OpenXR 1.1, "Composition Layer Blending"), so a blurred edge becomes
    // α·decode(c) over the passthrough. Premultiplied encoded values would be
    // decoded as decode(α·c): a dark halo on every DoF and MB edge.
    vec3 outc = p.straight_alpha != 0 ? (ao > 0.0 ? pm / ao : vec3(0.0)) : pm;
    imageStore(out_image, ivec3(xy, layer), vec4(outc, ao));
}
