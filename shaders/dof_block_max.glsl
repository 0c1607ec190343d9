// Shared by layer_dof_sigma.comp and layer_dof_down.comp (included; see build.rs):
// per 8×8 workgroup — one block of the scatter passes' grid — the largest σ its
// invocations wrote (−1 if none), into `tile_sigma_out` for layer_dof_reach.comp.
// Every invocation of the workgroup must call it (it holds a barrier, which is
// undefined in non-uniform control flow), so callers do not return early.
shared float block_sigma[64];

void write_block_max(float sigma, int layer) {
    block_sigma[gl_LocalInvocationIndex] = sigma;
    barrier();
    if (gl_LocalInvocationIndex == 0u) {
        float m = -1.0;
        for (int i = 0; i < 64; i++) {
            m = max(m, block_sigma[i]);
        }
        imageStore(tile_sigma_out, ivec3(gl_WorkGroupID.xy, layer), vec4(m));
    }
}
