#version 450
// The ISP's sharpening on the virtual layer (src/render/layer.rs; CPU twin
// synth::layer::sharpen): an unsharp mask out = L + k·(L − G ∗ L) on the chain's
// output L (premultiplied colour and alpha, nothing outside the eye's rectangle), G
// separable with the one-sided taps w (model::kernels::sharpening_taps). Pass 0: the
// horizontal blur of L into tmp; pass 1: the vertical blur of tmp and the mask,
// written into the DoF output (in place where L is it: each invocation reads L at
// its own pixel only) or the MB output (in place). The camera applies it after
// its optics and white balance (model::Sharpening); the per-pixel gain and the
// lens's aberration vary slowly over the kernel's reach, so it commutes with them.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, set = 0, binding = 0) uniform readonly image2DArray raw_colour;
layout(rgba16f, set = 0, binding = 1) uniform image2DArray dof_colour;
layout(rgba16f, set = 0, binding = 2) uniform image2DArray mb_colour;
layout(rgba16f, set = 0, binding = 3) uniform image2DArray tmp;

layout(push_constant) uniform Push {
    ivec4 rect[2];       // per eye: x, y, width, height
    ivec2 size;
    int source;          // the chain's output: 0 raw colour, 1 DoF, 2 MB
    int pass;            // 0: horizontal blur, 1: vertical blur and mask
    int radius;          // last non-zero tap
    float amount;        // k
    int pad0;
    int pad1;
    vec4 w[4];           // taps 0..15
} p;

bool in_rect(ivec2 q, int layer) {
    ivec4 r = p.rect[layer];
    return q.x >= r.x && q.y >= r.y && q.x < r.x + r.z && q.y < r.y + r.w;
}

vec4 source_at(ivec2 q, int layer) {
    if (!in_rect(q, layer)) {
        return vec4(0.0);
    }
    ivec3 at = ivec3(q, layer);
    return p.source == 2 ? imageLoad(mb_colour, at)
           : (p.source == 1 ? imageLoad(dof_colour, at) : imageLoad(raw_colour, at));
}

float tap(int i) {
    int a = abs(i);
    return p.w[a >> 2][a & 3];
}

void main() {
    int layer = int(gl_GlobalInvocationID.z);
    ivec4 r = p.rect[layer];
    ivec2 xy = r.xy + ivec2(gl_GlobalInvocationID.xy);
    if (gl_GlobalInvocationID.x >= uint(r.z) || gl_GlobalInvocationID.y >= uint(r.w)) {
        return;
    }
    vec4 acc = vec4(0.0);
    if (p.pass == 0) {
        for (int i = -p.radius; i <= p.radius; i++) {
            acc += tap(i) * source_at(xy + ivec2(i, 0), layer);
        }
        imageStore(tmp, ivec3(xy, layer), acc);
        return;
    }
    for (int i = -p.radius; i <= p.radius; i++) {
        ivec2 q = xy + ivec2(0, i);
        acc += tap(i) * (in_rect(q, layer) ? imageLoad(tmp, ivec3(q, layer)) : vec4(0.0));
    }
    vec4 l = source_at(xy, layer);
    vec4 o = l + p.amount * (l - acc);
    if (p.source == 2) {
        imageStore(mb_colour, ivec3(xy, layer), o);
    } else {
        imageStore(dof_colour, ivec3(xy, layer), o);
    }
}
