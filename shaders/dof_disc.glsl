// Included by layer_dof_disc.comp (after dof_tap.glsl): the disc kernel's tap, twin
// of model::kernels::{disc_radius_px, disc_cell_area, disc_tap} and
// synth::layer::disc_scatter_tap. A cell's area inside the disc in closed form,
// so the kernel's mass is πR² exactly without summing it.

const float DISC_MIN_SIGMA_PX = 1.0;

float disc_radius_px(float sigma) {
    return 2.0 * sqrt(max(sigma * sigma - 1.0 / 12.0, 0.0));
}

// ∫₀ˣ √(R² − t²) dt, 0 ≤ x ≤ R.
float quarter_circle_integral(float x, float r) {
    x = clamp(x, 0.0, r);
    return 0.5 * (x * sqrt(max(r * r - x * x, 0.0)) + r * r * asin(clamp(x / r, -1.0, 1.0)));
}

// Disc ∩ [x0, x1]×[y0, y1] in the first quadrant.
float disc_area_quadrant(float x0, float x1, float y0, float y1, float r) {
    if (x0 * x0 + y0 * y0 >= r * r) {
        return 0.0;
    }
    float xa = (y1 < r) ? sqrt(r * r - y1 * y1) : 0.0;
    float xb = sqrt(max(r * r - y0 * y0, 0.0));
    float full = max(min(x1, xa) - x0, 0.0) * (y1 - y0);
    float lo = clamp(xa, x0, x1);
    float hi = clamp(xb, x0, x1);
    return full + (quarter_circle_integral(hi, r) - quarter_circle_integral(lo, r)) - y0 * (hi - lo);
}

float disc_cell_area(float dx, float dy, float h, float r) {
    float ax = abs(dx);
    float ay = abs(dy);
    float nx = max(ax - h, 0.0);
    float ny = max(ay - h, 0.0);
    if (nx * nx + ny * ny >= r * r) {
        return 0.0;
    }
    float fx = ax + h;
    float fy = ay + h;
    if (fx * fx + fy * fy <= r * r) {
        return 4.0 * h * h;
    }
    // A cell straddling an axis is its two halves on one side (symmetry).
    vec3 sx = (ax < h) ? vec3(0.0, h - ax, h + ax) : vec3(ax - h, ax + h, 0.0);
    vec3 sy = (ay < h) ? vec3(0.0, h - ay, h + ay) : vec3(ay - h, ay + h, 0.0);
    float area = 0.0;
    for (int i = 0; i < 2; i++) {
        float xl = (i == 0) ? sx.x : 0.0;
        float xh = (i == 0) ? sx.y : sx.z;
        for (int j = 0; j < 2; j++) {
            float yl = (j == 0) ? sy.x : 0.0;
            float yh = (j == 0) ? sy.y : sy.z;
            if (xh > xl && yh > yl) {
                area += disc_area_quadrant(xl, xh, yl, yh, r);
            }
        }
    }
    return area;
}

// Below DISC_MIN_SIGMA_PX the separable Gaussian's product of 1-D taps.
float disc_scatter_tap(float dx, float dy, float h, float sigma) {
    if (sigma < DISC_MIN_SIGMA_PX) {
        return tap(dx, h, sigma) * tap(dy, h, sigma);
    }
    float r = disc_radius_px(sigma);
    return disc_cell_area(dx, dy, h, r) / (3.14159265 * r * r);
}

// The disc loop's bounds, per workgroup (uniform, like tap_reach; σ_max from
// layer_dof_reach.comp). A disc tap is zero once the cell's nearest point lies at R
// or beyond (disc_cell_area), R = disc_radius_px(σ) ≤ 2σ, so per coordinate beyond
// R + h; a Gaussian product below DISC_MIN_SIGMA_PX is zero beyond 4σ + h per
// coordinate (`tap`). The Gaussian's 4σ_max + h square (tap_reach) holds about four
// times the disc's taps. +1 absorbs float rounding of the bound.
int disc_tap_reach(float sigma_max, float h, int radius) {
    float g = 4.0 * min(sigma_max, DISC_MIN_SIGMA_PX);
    return clamp(int(ceil(max(2.0 * sigma_max, g) + h)) + 1, 0, radius);
}

// Row dy's half-width inside that square: a disc's non-zero cells satisfy
// (|dx| − h)₊² + (|dy| − h)₊² < R² ≤ (2σ_max)², i.e. |dx| < h + √((2σ_max)² − ny²);
// the sub-DISC_MIN Gaussians fill the 4σ + h square. Cutting the square to the
// circle skips another ~21% of the taps, all of them exactly zero, so the sums
// are bit-identical to the full loop's (the twin needs no change).
int disc_row_reach(int dy, float sigma_max, float h, int reach) {
    float rmax = 2.0 * sigma_max;
    float ny = max(abs(float(dy)) - h, 0.0);
    float span = h + sqrt(max(rmax * rmax - ny * ny, 0.0));
    float g = 4.0 * min(sigma_max, DISC_MIN_SIGMA_PX);
    if (ny <= g) {
        span = max(span, g + h);
    }
    return clamp(int(ceil(span)) + 1, 0, reach);
}
