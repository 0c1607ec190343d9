// Shared by layer_dof_sigma.comp and layer_dof_down.comp (needs the Effect uniform
// `e` and the push constant `ppr_ratio`).
// δ(Z) of model::DofCurve::sigma_px with the depth clamp of DepthOfField::sigma_px,
// in camera pixels, then in eye pixels. Metric depth only (the renderer's depth).
float sigma_eye(float z) {
    // Absent, or relative-inverse units (no metric scale for virtual depths).
    if ((e.head.y & 4u) == 0u || e.dof.y != 0u) {
        return 0.0;
    }
    float lo = uintBitsToFloat(e.dof.z);
    float hi = uintBitsToFloat(e.dof.w);
    z = clamp(z, lo, hi);
    float d = 0.0;
    if (e.dof.x == 1u) {
        d = (e.dof_coeffs.x * z + e.dof_coeffs.y) * z + e.dof_coeffs.z;
    } else if (e.dof.x == 2u) {
        d = e.dof_coeffs.x * abs(1.0 / z - e.dof_coeffs.y) + e.dof_coeffs.z;
    } else if (e.dof.x == 3u) {
        d = e.dof_coeffs.x;
    }
    return clamp(d, 0.0, 10.0) * p.ppr_ratio;
}
