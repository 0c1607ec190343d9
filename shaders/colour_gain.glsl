// The camera's white balance and exposure (model::Colour) and the lens's falloff
// (model::Vignetting) on the virtual colour: encoded (sRGB) straight colour
// decoded to linear light, multiplied per channel, re-encoded and clamped to
// [0, 1]. Twins: synth::layer::gain_encoded, model::EyeGain::at.
float srgb_decode(float v) {
    return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

float srgb_encode(float v) {
    return v <= 0.0031308 ? v * 12.92 : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

// Premultiplied colour c (alpha c.a) with the gain applied; unchanged where alpha
// is ≤ 1e-3 (its straight colour is not defined there, as in layer_luma).
vec4 colour_gain(vec4 c, vec3 gain) {
    if (c.a <= 1e-3) {
        return c;
    }
    vec3 u = clamp(c.rgb / c.a, 0.0, 1.0);
    vec3 g = vec3(srgb_encode(clamp(srgb_decode(u.r) * gain.r, 0.0, 1.0)),
                  srgb_encode(clamp(srgb_decode(u.g) * gain.g, 0.0, 1.0)),
                  srgb_encode(clamp(srgb_decode(u.b) * gain.b, 0.0, 1.0)));
    return vec4(g * c.a, c.a);
}

// The lens's falloff V(r) at pixel xy of eye `layer` (model::EyeVignette::gain_at):
// r = |xy + ½ − the eye's principal point| · vig.w, held at 1 past the camera's
// corner; log V = r²·(a1 + r²·(a2 + r²·a3)) with vig.xyz = a. 1 where vig.w ≤ 0.
float vignette_gain(ivec2 xy, int layer, vec4 vig, vec4 centre) {
    if (vig.w <= 0.0) {
        return 1.0;
    }
    vec2 c = layer == 0 ? centre.xy : centre.zw;
    vec2 d = (vec2(xy) + 0.5 - c) * vig.w;
    float r2 = min(d.x * d.x + d.y * d.y, 1.0);
    return exp(r2 * (vig.x + r2 * (vig.y + r2 * vig.z)));
}

// Whether the composite's per-pixel gain applies (colour or vignetting), and its
// value at xy of eye `layer`.
bool pixel_gain_on(vec4 gain, vec4 vig) {
    return gain.w > 0.5 || vig.w > 0.0;
}

vec3 pixel_gain(ivec2 xy, int layer, vec4 gain, vec4 vig, vec4 centre) {
    vec3 g = gain.w > 0.5 ? gain.xyz : vec3(1.0);
    return g * vignette_gain(xy, layer, vig, centre);
}
