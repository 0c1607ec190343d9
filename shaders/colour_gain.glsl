// The camera's white balance and exposure on the virtual colour (model::Colour):
// encoded (sRGB) straight colour decoded to linear light, multiplied per channel,
// re-encoded and clamped to [0, 1]. Twin: synth::layer::gain_encoded.
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
