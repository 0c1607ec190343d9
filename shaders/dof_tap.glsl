// Shared by layer_dof_h.comp and layer_dof_v.comp (included; see build.rs): the
// scatter's tap mass and the per-workgroup tap-loop bound.

// erf, Abramowitz & Stegun 7.1.26 (|error| ≤ 1.5e-7); the CPU twin uses the same.
float erf_as(float x) {
    float s = sign(x);
    float a = abs(x);
    float t = 1.0 / (1.0 + 0.3275911 * a);
    float y = 1.0 - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t + 0.254829592) * t * exp(-a * a);
    return s * y;
}

// Mass of N(0, σ²) over [d − h, d + h]; 0 beyond 4σ (the tail there is < 6.4e-5
// of the mass; cutting it skips the two erf and the colour read of far taps of
// small-σ sources).
float tap(float d, float h, float sigma) {
    if (abs(d) - h > 4.0 * sigma) {
        return 0.0;
    }
    if (sigma < 1e-4) {
        return (abs(d) < h) ? 1.0 : 0.0;
    }
    float k = 0.70710678 / sigma;
    return 0.5 * (erf_as((d + h) * k) - erf_as((d - h) * k));
}

// Where this workgroup's tap loop may stop: taps beyond 4·σ_max + h are zero
// (`tap`), σ_max being the largest source σ within reach of the workgroup
// (layer_dof_reach.comp); +1 absorbs float rounding of the bound. Same for every
// invocation of the workgroup, so the loop bound stays uniform.
int tap_reach(float sigma_max, float h, int radius) {
    return clamp(int(ceil(4.0 * sigma_max + h)) + 1, 0, radius);
}

// First tap of the cut loop: the full loop's lattice point −radius + k·step nearest
// inside −reach, so the taps visited are the full loop's non-zero ones, in order.
int tap_start(int reach, int radius, int step) {
    return -radius + (radius - reach + step - 1) / step * step;
}
