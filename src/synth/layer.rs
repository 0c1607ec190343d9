//! CPU twins of the renderer's production passes on the virtual layer
//! (`render::layer`): premultiplied colour + alpha with per-pixel motion and depth,
//! as the G-buffer pass writes it. Each function follows its shader's arithmetic
//! so the GPU is held to it (tests/gpu_layer.rs); `defocus_layer_exact` is the
//! unapproximated reference the quality settings are measured against.

use crate::image::LUMA_WEIGHTS;
use crate::model::kernels::{disc_tap, DISC_MIN_SIGMA_PX};
pub use crate::model::{half_rect, tile_rect, Rect};
use crate::model::{DepthOfField, DepthUnits, DofKernel, EyeGain, MAX_DOF_SIGMA_PX};

/// One eye of the virtual layer: premultiplied RGBA and (motion x, motion y in px
/// per render frame, depth in m, coverage) per pixel, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    pub width: usize,
    pub height: usize,
    pub colour: Vec<[f32; 4]>,
    pub motion: Vec<[f32; 4]>,
}

/// erf, Abramowitz & Stegun 7.1.26 (|error| ≤ 1.5e-7), as in the shaders (the
/// published constants verbatim, hence more digits than f32 holds).
#[allow(clippy::excessive_precision)]
pub fn erf_as(x: f32) -> f32 {
    let s = if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    };
    let a = x.abs();
    let t = 1.0 / (1.0 + 0.3275911 * a);
    let y = 1.0
        - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t + 0.254829592)
            * t
            * (-a * a).exp();
    s * y
}

/// Mass of N(0, σ²) over [d − h, d + h] (a delta for σ → 0); 0 beyond 4σ (tail
/// < 6.4e-5 of the mass), as the shaders cut it to skip far taps.
pub fn tap(d: f32, h: f32, sigma: f32) -> f32 {
    if d.abs() - h > 4.0 * sigma {
        return 0.0;
    }
    if sigma < 1e-4 {
        return if d.abs() < h { 1.0 } else { 0.0 };
    }
    let k = std::f32::consts::FRAC_1_SQRT_2 / sigma;
    0.5 * (erf_as((d + h) * k) - erf_as((d - h) * k))
}

/// Blur σ in eye pixels at metric depth `z_m`: the model's δ(Z) (camera pixels)
/// times the eye/camera `pixels_per_radian` ratio. Relative-inverse models have no
/// metric scale for virtual depths: no DoF (the renderer skips it and says so).
pub fn sigma_eye_px(dof: &DepthOfField, z_m: f32, ppr_ratio: f32) -> f32 {
    if !dof.present || dof.units != DepthUnits::MetricM {
        return 0.0;
    }
    dof.sigma_px(z_m).clamp(0.0, MAX_DOF_SIGMA_PX) * ppr_ratio
}

/// Per-pixel source blur σ in eye pixels (`layer_dof_sigma.comp`); −1 marks
/// uncovered pixels (they scatter nothing).
pub fn dof_sigma_plane(layer: &Layer, dof: &DepthOfField, ppr_ratio: f32, rect: Rect) -> Vec<f32> {
    let mut out = vec![-1.0f32; layer.colour.len()];
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let i = y as usize * layer.width + x as usize;
            let m = layer.motion[i];
            if m[3] > 0.0 {
                out[i] = sigma_eye_px(dof, m[2], ppr_ratio);
            }
        }
    }
    out
}

/// Separable scatter-as-gather over `rect` of a `width`-wide image (zero outside
/// `rect`): a horizontal pass spreading each source pixel (σ ≥ 0) with its own σ and
/// carrying the coverage-weighted σ, then a vertical pass with that σ
/// (`layer_dof_h/v.comp`). `radius` is a multiple of `step` (taps every `step` px,
/// each the Gaussian's mass over its span). Pixels outside `rect` keep `colour`.
pub fn separable_scatter(
    colour: &[[f32; 4]],
    sigma: &[f32],
    width: usize,
    radius: i32,
    step: i32,
    rect: Rect,
) -> Vec<[f32; 4]> {
    let (w, step) = (width as i32, step.max(1));
    let h = 0.5 * step as f32;
    let idx = |x: i32, y: i32| (y * w + x) as usize;
    let mut hc = vec![[0.0f32; 4]; colour.len()];
    let mut hs = vec![0.0f32; colour.len()];
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let (mut acc, mut s_acc, mut w_acc) = ([0.0f32; 4], 0.0f32, 0.0f32);
            let mut d = -radius;
            while d <= radius {
                let (sx, off) = (x + d, d);
                d += step;
                if sx < rect.x || sx >= rect.x + rect.w {
                    continue;
                }
                let sg = sigma[idx(sx, y)];
                if sg < 0.0 {
                    continue;
                }
                let k = tap(-(off as f32), h, sg);
                let c = colour[idx(sx, y)];
                for i in 0..4 {
                    acc[i] += k * c[i];
                }
                let wk = k * c[3];
                s_acc += wk * sg;
                w_acc += wk;
            }
            hc[idx(x, y)] = acc;
            hs[idx(x, y)] = if w_acc > 1e-6 { s_acc / w_acc } else { 0.0 };
        }
    }
    let mut out = colour.to_vec();
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let mut acc = [0.0f32; 4];
            let mut d = -radius;
            while d <= radius {
                let (sy, off) = (y + d, d);
                d += step;
                if sy < rect.y || sy >= rect.y + rect.h {
                    continue;
                }
                let c = hc[idx(x, sy)];
                if c == [0.0; 4] {
                    continue;
                }
                let k = tap(-(off as f32), h, hs[idx(x, sy)]);
                for i in 0..4 {
                    acc[i] += k * c[i];
                }
            }
            out[idx(x, y)] = acc;
        }
    }
    out
}

/// Tap of the disc scatter (`shaders/dof_disc.glsl`): a source of std `sigma`
/// spreads its disc (`kernels::disc_tap`, cells of half-size `h`) or, below
/// `DISC_MIN_SIGMA_PX`, the separable Gaussian's product of 1-D taps.
pub fn disc_scatter_tap(dx: f32, dy: f32, h: f32, sigma: f32) -> f32 {
    if sigma < DISC_MIN_SIGMA_PX {
        return tap(dx, h, sigma) * tap(dy, h, sigma);
    }
    disc_tap(dx, dy, h, sigma)
}

/// 2-D scatter-as-gather of a disc kernel over `rect` (`layer_dof_disc.comp`): each
/// source pixel (σ ≥ 0) spreads its own disc over the receivers within `radius`
/// (taps every `step` px). A disc is not separable, so one 2-D pass replaces the
/// Gaussian's two 1-D passes. Pixels outside `rect` keep `colour`.
pub fn disc_scatter(
    colour: &[[f32; 4]],
    sigma: &[f32],
    width: usize,
    radius: i32,
    step: i32,
    rect: Rect,
) -> Vec<[f32; 4]> {
    let (w, step) = (width as i32, step.max(1));
    let h = 0.5 * step as f32;
    let idx = |x: i32, y: i32| (y * w + x) as usize;
    let mut out = colour.to_vec();
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let mut acc = [0.0f32; 4];
            let mut dy = -radius;
            while dy <= radius {
                let sy = y + dy;
                let ody = dy;
                dy += step;
                if sy < rect.y || sy >= rect.y + rect.h {
                    continue;
                }
                let mut dx = -radius;
                while dx <= radius {
                    let sx = x + dx;
                    let odx = dx;
                    dx += step;
                    if sx < rect.x || sx >= rect.x + rect.w {
                        continue;
                    }
                    let sg = sigma[idx(sx, sy)];
                    if sg < 0.0 {
                        continue;
                    }
                    let k = disc_scatter_tap(odx as f32, ody as f32, h, sg);
                    if k == 0.0 {
                        continue;
                    }
                    let c = colour[idx(sx, sy)];
                    for i in 0..4 {
                        acc[i] += k * c[i];
                    }
                }
            }
            out[idx(x, y)] = acc;
        }
    }
    out
}

/// The scatter of the model's kernel shape.
fn scatter(
    kernel: DofKernel,
    colour: &[[f32; 4]],
    sigma: &[f32],
    width: usize,
    radius: i32,
    step: i32,
    rect: Rect,
) -> Vec<[f32; 4]> {
    match kernel {
        DofKernel::Gaussian => separable_scatter(colour, sigma, width, radius, step, rect),
        DofKernel::Disc => disc_scatter(colour, sigma, width, radius, step, rect),
    }
}

/// Full-resolution defocus of one eye over `rect`: σ plane, then the scatter of the
/// model's kernel shape. Pixels outside `rect` keep their input.
pub fn defocus_layer(
    layer: &Layer,
    dof: &DepthOfField,
    ppr_ratio: f32,
    radius: i32,
    step: i32,
    rect: Rect,
) -> Vec<[f32; 4]> {
    let sigma = dof_sigma_plane(layer, dof, ppr_ratio, rect);
    scatter(dof.kernel, &layer.colour, &sigma, layer.width, radius, step, rect)
}

/// Half-resolution defocus (`layer_dof_down.comp` → the kernel's scatter at half
/// resolution with σ/2 and radius `radius_half` → `layer_dof_up.comp`): 2×2 box
/// average of the premultiplied colour and the alpha-weighted σ/2 of the covered
/// pixels, the scatter, then a bilinear upsample (clamped to the half rectangle).
/// ≈ 8× fewer taps; sharp (σ ≲ 1 px) content is softened by the 2×2 average.
pub fn defocus_layer_half(
    layer: &Layer,
    dof: &DepthOfField,
    ppr_ratio: f32,
    radius_half: i32,
    step: i32,
    rect: Rect,
) -> Vec<[f32; 4]> {
    let sigma_full = dof_sigma_plane(layer, dof, ppr_ratio, rect);
    let (w, h) = (layer.width, layer.height);
    let (hw, hh) = (w.div_ceil(2), h.div_ceil(2));
    let hr = half_rect(rect);
    let mut colour = vec![[0.0f32; 4]; hw * hh];
    let mut sigma = vec![-1.0f32; hw * hh];
    for hy in hr.y..hr.y + hr.h {
        for hx in hr.x..hr.x + hr.w {
            let (mut c, mut sw, mut ss) = ([0.0f32; 4], 0.0f32, 0.0f32);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (x, y) = (2 * hx + dx, 2 * hy + dy);
                if !rect.contains(x, y) {
                    continue;
                }
                let i = y as usize * w + x as usize;
                let p = layer.colour[i];
                for k in 0..4 {
                    c[k] += 0.25 * p[k];
                }
                let sg = sigma_full[i];
                if sg >= 0.0 {
                    let wt = p[3].max(1e-3);
                    sw += wt;
                    ss += wt * 0.5 * sg;
                }
            }
            let j = hy as usize * hw + hx as usize;
            colour[j] = c;
            sigma[j] = if sw > 0.0 { ss / sw } else { -1.0 };
        }
    }
    let blurred = scatter(dof.kernel, &colour, &sigma, hw, radius_half, step, hr);
    let mut out = layer.colour.clone();
    let fetch = |x: i32, y: i32| {
        let xc = x.clamp(hr.x, hr.x + hr.w - 1);
        let yc = y.clamp(hr.y, hr.y + hr.h - 1);
        blurred[yc as usize * hw + xc as usize]
    };
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let (fx, fy) = (x as f32 * 0.5 - 0.25, y as f32 * 0.5 - 0.25);
            let (x0, y0) = (fx.floor(), fy.floor());
            let (ax, ay) = (fx - x0, fy - y0);
            let (x0, y0) = (x0 as i32, y0 as i32);
            let (a, b, c, d) = (fetch(x0, y0), fetch(x0 + 1, y0), fetch(x0, y0 + 1), fetch(x0 + 1, y0 + 1));
            out[y as usize * w + x as usize] = std::array::from_fn(|k| {
                let top = a[k] + (b[k] - a[k]) * ax;
                let bottom = c[k] + (d[k] - c[k]) * ax;
                top + (bottom - top) * ay
            });
        }
    }
    out
}

/// The unapproximated reference: every covered pixel scatters a 2-D Gaussian of its
/// own σ (pixel-integrated, 4σ reach) — or its disc — over the whole eye. The production pass's
/// quality settings are measured against this.
pub fn defocus_layer_exact(layer: &Layer, dof: &DepthOfField, ppr_ratio: f32) -> Vec<[f32; 4]> {
    let (w, h) = (layer.width as i32, layer.height as i32);
    let mut out = vec![[0.0f32; 4]; layer.colour.len()];
    for sy in 0..h {
        for sx in 0..w {
            let i = (sy * w + sx) as usize;
            let m = layer.motion[i];
            if m[3] <= 0.0 {
                continue;
            }
            let sigma = sigma_eye_px(dof, m[2], ppr_ratio);
            let r = (4.0 * sigma).ceil() as i32;
            let c = layer.colour[i];
            let kx: Vec<f32> = (-r..=r).map(|d| tap(d as f32, 0.5, sigma)).collect();
            let disc = dof.kernel == DofKernel::Disc && sigma >= DISC_MIN_SIGMA_PX;
            for dy in -r..=r {
                let y = sy + dy;
                if y < 0 || y >= h {
                    continue;
                }
                let ky = kx[(dy + r) as usize];
                for dx in -r..=r {
                    let x = sx + dx;
                    if x < 0 || x >= w {
                        continue;
                    }
                    let k = if disc { disc_tap(dx as f32, dy as f32, 0.5, sigma) } else { ky * kx[(dx + r) as usize] };
                    let o = &mut out[(y * w + x) as usize];
                    for ch in 0..4 {
                        o[ch] += k * c[ch];
                    }
                }
            }
        }
    }
    out
}

/// Depth softness of the MB ordering tests and the depth of uncovered pixels.
pub const MB_SOFT_Z_M: f32 = 0.05;
pub const MB_EMPTY_Z_M: f32 = 1.0e4;

fn half_streak(m: [f32; 4], exposure_ratio: f32, tile_px: i32) -> [f32; 2] {
    if m[3] <= 0.0 {
        return [0.0; 2];
    }
    let v = [m[0] * (0.5 * exposure_ratio), m[1] * (0.5 * exposure_ratio)];
    let len = (v[0] * v[0] + v[1] * v[1]).sqrt();
    let k = tile_px as f32;
    if len > k {
        [v[0] * (k / len), v[1] * (k / len)]
    } else {
        v
    }
}

/// Integer hash for the per-pixel jitter (lowbias32), as in `layer_mb_gather.comp`.
pub fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846ca68b);
    x ^= x >> 16;
    x
}

/// McGuire et al. 2012 reconstruction over `rect` of one eye (`layer_mb_*.comp`):
/// TileMax → NeighborMax → up to `samples` jittered taps (∝ the streak with
/// `taps_per_px` > 0) along the neighbourhood's
/// half-streak with depth-ordered cone/cylinder weights. `colour` is the input layer
/// (after DoF), `motion` the G-buffer's. Pixels outside `rect` keep their input.
#[allow(clippy::too_many_arguments)]
pub fn motion_blur_layer(
    colour: &[[f32; 4]],
    motion: &[[f32; 4]],
    width: usize,
    height: usize,
    exposure_ratio: f32,
    tile_px: i32,
    samples: u32,
    taps_per_px: f32,
    frame: u32,
    eye: u32,
    rect: Rect,
) -> Vec<[f32; 4]> {
    let w = width as i32;
    let idx = |x: i32, y: i32| (y * w + x) as usize;
    let tr = tile_rect(rect, tile_px, width, height);
    let (tw, th) = ((width as i32 + tile_px - 1) / tile_px, (height as i32 + tile_px - 1) / tile_px);
    let mut tile_max = vec![[0.0f32; 2]; (tw * th) as usize];
    for ty in tr.y..tr.y + tr.h {
        for tx in tr.x..tr.x + tr.w {
            let (mut best, mut best_len) = ([0.0f32; 2], 0.0f32);
            for j in 0..tile_px {
                for i in 0..tile_px {
                    let (x, y) = (tx * tile_px + i, ty * tile_px + j);
                    if x >= w || y >= height as i32 {
                        continue;
                    }
                    let v = half_streak(motion[idx(x, y)], exposure_ratio, tile_px);
                    let l = v[0] * v[0] + v[1] * v[1];
                    if l > best_len {
                        best_len = l;
                        best = v;
                    }
                }
            }
            tile_max[(ty * tw + tx) as usize] = best;
        }
    }
    let mut neighbour = vec![[0.0f32; 2]; (tw * th) as usize];
    for ty in tr.y..tr.y + tr.h {
        for tx in tr.x..tr.x + tr.w {
            let (mut best, mut best_len) = ([0.0f32; 2], 0.0f32);
            for j in -1..=1 {
                for i in -1..=1 {
                    let (x, y) = (tx + i, ty + j);
                    if !tr.contains(x, y) {
                        continue;
                    }
                    let v = tile_max[(y * tw + x) as usize];
                    let l = v[0] * v[0] + v[1] * v[1];
                    if l > best_len {
                        best_len = l;
                        best = v;
                    }
                }
            }
            neighbour[(ty * tw + tx) as usize] = best;
        }
    }
    let closer = |za: f32, zb: f32| (1.0 - (za - zb) / MB_SOFT_Z_M).clamp(0.0, 1.0);
    let cone = |dist: f32, vlen: f32| (1.0 - dist / vlen).clamp(0.0, 1.0);
    let smoothstep = |e0: f32, e1: f32, x: f32| {
        let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    let cylinder = |dist: f32, vlen: f32| 1.0 - smoothstep(0.95 * vlen, 1.05 * vlen, dist);
    let mut out = colour.to_vec();
    let max_n = samples.max(1);
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let vn = neighbour[((y / tile_px) * tw + x / tile_px) as usize];
            let cx = colour[idx(x, y)];
            let vn_len = (vn[0] * vn[0] + vn[1] * vn[1]).sqrt();
            if vn_len < 0.5 {
                continue;
            }
            // Taps ∝ the neighbourhood's full streak, as layer_mb_gather.comp.
            let n = if taps_per_px > 0.0 {
                ((2.0 * vn_len * taps_per_px).ceil() as u32).clamp(2.min(max_n), max_n)
            } else {
                max_n
            };
            let mx = motion[idx(x, y)];
            let zx = if mx[3] > 0.0 { mx[2] } else { MB_EMPTY_Z_M };
            let hx = half_streak(mx, exposure_ratio, tile_px);
            let vx = (hx[0] * hx[0] + hx[1] * hx[1]).sqrt().max(0.5);
            let mut weight = 1.0 / vx;
            let mut sum = cx.map(|c| c * weight);
            let h = hash32(
                (x as u32)
                    .wrapping_mul(1973)
                    .wrapping_add((y as u32).wrapping_mul(9277))
                    .wrapping_add(eye.wrapping_mul(26699))
                    .wrapping_add(frame.wrapping_mul(7919)),
            );
            let j = (h & 0xffff) as f32 / 65536.0 - 0.5;
            for i in 0..n {
                let a = (i as f32 + j + 1.0) / (n as f32 + 1.0);
                // GLSL mix(-1, 1, a) = -1·(1 − a) + 1·a, written out in the same order.
                let t = -(1.0 - a) + a;
                let sx = x + (vn[0] * t + 0.5).floor() as i32;
                let sy = y + (vn[1] * t + 0.5).floor() as i32;
                if !rect.contains(sx, sy) || (sx == x && sy == y) {
                    continue;
                }
                let my = motion[idx(sx, sy)];
                let zy = if my[3] > 0.0 { my[2] } else { MB_EMPTY_Z_M };
                let hy = half_streak(my, exposure_ratio, tile_px);
                let vy = (hy[0] * hy[0] + hy[1] * hy[1]).sqrt().max(0.5);
                let dist = (((sx - x) * (sx - x) + (sy - y) * (sy - y)) as f32).sqrt();
                let f = closer(zy, zx);
                let b = closer(zx, zy);
                let wgt = f * cone(dist, vy) + b * cone(dist, vx) + cylinder(dist, vy) * cylinder(dist, vx) * 2.0;
                weight += wgt;
                let cy = colour[idx(sx, sy)];
                for ch in 0..4 {
                    sum[ch] += wgt * cy[ch];
                }
            }
            out[idx(x, y)] = sum.map(|s| s / weight);
        }
    }
    out
}

/// The ISP's unsharp mask on the chain's output `layer` (premultiplied colour and
/// alpha, `width` wide), inside `rect` (nothing outside it):
/// out = L + amount·(L − G ∗ L), G separable with the one-sided `taps` (offsets
/// 0..=`radius`, `model::kernels::sharpening_taps`), the horizontal pass first and
/// the sums in the order of `layer_sharpen.comp`. Pixels outside `rect` keep their
/// value. Twin of `render::layer`'s sharpening passes.
pub fn sharpen(layer: &[[f32; 4]], width: usize, rect: Rect, taps: &[f32], radius: i32, amount: f32) -> Vec<[f32; 4]> {
    let height = layer.len() / width.max(1);
    let inside =
        |x: i32, y: i32| x >= 0 && y >= 0 && (x as usize) < width && (y as usize) < height && rect.contains(x, y);
    let at = |v: &[[f32; 4]], x: i32, y: i32| if inside(x, y) { v[y as usize * width + x as usize] } else { [0.0; 4] };
    let tap = |i: i32| taps.get(i.unsigned_abs() as usize).copied().unwrap_or(0.0);
    let mut tmp = vec![[0.0f32; 4]; layer.len()];
    for (i, t) in tmp.iter_mut().enumerate() {
        let (x, y) = ((i % width) as i32, (i / width) as i32);
        if inside(x, y) {
            let mut acc = [0.0f32; 4];
            for d in -radius..=radius {
                let v = at(layer, x + d, y);
                for c in 0..4 {
                    acc[c] += tap(d) * v[c];
                }
            }
            *t = acc;
        }
    }
    let mut out = layer.to_vec();
    for (i, o) in out.iter_mut().enumerate() {
        let (x, y) = ((i % width) as i32, (i / width) as i32);
        if inside(x, y) {
            let mut acc = [0.0f32; 4];
            for d in -radius..=radius {
                let v = at(&tmp, x, y + d);
                for c in 0..4 {
                    acc[c] += tap(d) * v[c];
                }
            }
            let l = layer[i];
            *o = std::array::from_fn(|c| l[c] + amount * (l[c] - acc[c]));
        }
    }
    out
}

/// The camera's colour gain (`model::Colour::gains_or_one`, linear light) on one
/// premultiplied encoded (sRGB) pixel: its straight colour decoded, multiplied,
/// re-encoded and clamped to [0, 1]; unchanged where alpha ≤ 1e-3
/// (`shaders/colour_gain.glsl`).
pub fn gain_encoded(c: [f32; 4], gain: [f32; 3]) -> [f32; 4] {
    if c[3] <= 1e-3 {
        return c;
    }
    let encode = |v: f32| if v <= 0.0031308 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
    let g: [f32; 3] = std::array::from_fn(|k| {
        let u = (c[k] / c[3]).clamp(0.0, 1.0);
        encode((crate::image::yuv::srgb_to_linear(u) * gain[k]).clamp(0.0, 1.0)) * c[3]
    });
    [g[0], g[1], g[2], c[3]]
}

/// Luma (Rec. 601) of the un-premultiplied virtual colour over `rect`, row-major
/// `rect.w × rect.h` (`layer_luma.comp`), after the per-pixel `gain` (the camera's
/// colour and the lens's falloff) where it applies; 0 where alpha ≤ 1e-3.
pub fn layer_luma(colour: &[[f32; 4]], width: usize, rect: Rect, gain: &EyeGain) -> Vec<f32> {
    let mut out = Vec::with_capacity(rect.area());
    for y in rect.y..rect.y + rect.h {
        for x in rect.x..rect.x + rect.w {
            let c = colour[y as usize * width + x as usize];
            let c = gain.at(x as usize, y as usize).map_or(c, |g| gain_encoded(c, g));
            out.push(if c[3] > 1e-3 { (0..3).map(|i| LUMA_WEIGHTS[i] * c[i] / c[3]).sum() } else { 0.0 });
        }
    }
    out
}

/// `composite.comp` for one eye: out = bg·(1 − α) + G(C) + α·n (G: the per-pixel
/// `gain` — the camera's colour times the lens's falloff — where it applies,
/// `gain_encoded`; n: planar RGB grain
/// of `rect`'s size, or none), alpha = bg.a·(1 − α) + α (premultiplied "over"),
/// colour clamped to [0, alpha]; the virtual layer is `fx` (or
/// `raw`) inside `rect` and empty outside it. `straight_alpha`: the colour is
/// stored divided by the output alpha (0 where that is 0), as the headset's
/// projection layer submits it (`LayerSettings::straight_alpha`). With
/// `gain.chromatic`, red and blue (colour and alpha) are the layer bilinearly
/// sampled where the lens moved them from (`EyeChromatic::source`) and each
/// channel goes "over" with its own alpha; the grain follows green's alpha and the
/// output alpha is the largest channel's.
#[allow(clippy::too_many_arguments)]
pub fn composite(
    background: &[[f32; 4]],
    raw: &[[f32; 4]],
    fx: Option<&[[f32; 4]]>,
    noise: Option<&[f32]>,
    width: usize,
    rect: Rect,
    straight_alpha: bool,
    gain: &EyeGain,
) -> Vec<[f32; 4]> {
    let plane = rect.area();
    let height = background.len() / width.max(1);
    let layer = fx.unwrap_or(raw);
    // The chain's output at texel (x, y): nothing outside the rectangle (the GPU's
    // G-buffer is only written inside the rectangles, so its composite reads
    // nothing there) or the buffer.
    let chain = |x: i32, y: i32| -> [f32; 4] {
        if x < 0 || y < 0 || x >= width as i32 || y >= height as i32 || !rect.contains(x, y) {
            [0.0; 4]
        } else {
            layer[y as usize * width + x as usize]
        }
    };
    (0..background.len())
        .map(|i| {
            let (x, y) = ((i % width) as i32, (i / width) as i32);
            let inside = rect.contains(x, y);
            let c = chain(x, y);
            // Each channel's sample: green's (and every channel's without
            // aberration) at the pixel, red's and blue's where the lens moved them from.
            let samples: [[f32; 4]; 3] = match gain.chromatic {
                None => [c; 3],
                Some(ca) => {
                    let at = |k: usize| {
                        let [qx, qy] = ca.source(k, x as usize, y as usize);
                        bilinear(&chain, qx, qy)
                    };
                    [at(0), c, at(1)]
                }
            };
            let g = gain.at(x as usize, y as usize);
            let mut rgb = [0.0f32; 3];
            let mut a_max = 0.0f32;
            for k in 0..3 {
                let s = g.map_or(samples[k], |g| gain_encoded(samples[k], g));
                let a_k = s[3].clamp(0.0, 1.0);
                a_max = a_max.max(a_k);
                rgb[k] = background[i][k] * (1.0 - a_k) + s[k];
            }
            let a = c[3].clamp(0.0, 1.0);
            if let (Some(n), true, true) = (noise, inside, a > 0.0) {
                let j = ((y - rect.y) * rect.w + (x - rect.x)) as usize;
                for k in 0..3 {
                    rgb[k] += a * n[k * plane + j];
                }
            }
            // Premultiplied "over": opaque over an opaque background; the virtual
            // alpha over a transparent one (the headset's passthrough layer).
            let ao = (background[i][3] * (1.0 - a_max) + a_max).clamp(0.0, 1.0);
            let pm = rgb.map(|v| v.clamp(0.0, ao));
            let out = if !straight_alpha {
                pm
            } else if ao > 0.0 {
                pm.map(|v| v / ao)
            } else {
                [0.0; 3]
            };
            [out[0], out[1], out[2], ao]
        })
        .collect()
}

/// Bilinear sample of `texel` at continuous pixel coordinates (qx, qy) (texel
/// centres at +½), in `composite.comp`'s `bilinear` order of operations.
fn bilinear(texel: &impl Fn(i32, i32) -> [f32; 4], qx: f32, qy: f32) -> [f32; 4] {
    let (ux, uy) = (qx - 0.5, qy - 0.5);
    let (x0, y0) = (ux.floor(), uy.floor());
    let (fx, fy) = (ux - x0, uy - y0);
    let (x0, y0) = (x0 as i32, y0 as i32);
    let (c00, c10, c01, c11) = (texel(x0, y0), texel(x0 + 1, y0), texel(x0, y0 + 1), texel(x0 + 1, y0 + 1));
    std::array::from_fn(|k| {
        let top = c00[k] + fx * (c10[k] - c00[k]);
        let bottom = c01[k] + fx * (c11[k] - c01[k]);
        top + fy * (bottom - top)
    })
}

/// `spacewarp.comp` for one eye: XR_FB_space_warp's motion vectors (NDC per render
/// frame; the G-buffer's pixel motion × 2 / eye size, z = 0) and NDC depth
/// (f·(d − n) / ((f − n)·d), clamped to [0, 1]) at `mv_w × mv_h`, each texel from the
/// G-buffer texel under its centre. `motion`: the eye's G-buffer motion texels
/// (x, y px; view depth m; coverage), `eye_w` wide; outside `area` (where the
/// G-buffer pass wrote) or uncovered: vector 0, depth 1.
#[allow(clippy::too_many_arguments)]
pub fn space_warp(
    motion: &[[f32; 4]],
    eye_w: usize,
    eye_h: usize,
    area: Rect,
    mv_w: usize,
    mv_h: usize,
    near_m: f32,
    far_m: f32,
) -> (Vec<[f32; 4]>, Vec<f32>) {
    let mut vectors = Vec::with_capacity(mv_w * mv_h);
    let mut depth = Vec::with_capacity(mv_w * mv_h);
    for y in 0..mv_h {
        for x in 0..mv_w {
            // The texel centre's source pixel, as the shader computes it in f32.
            let sx = (((x as f32 + 0.5) * eye_w as f32 / mv_w as f32) as usize).min(eye_w - 1);
            let sy = (((y as f32 + 0.5) * eye_h as f32 / mv_h as f32) as usize).min(eye_h - 1);
            let m = if area.contains(sx as i32, sy as i32) { motion[sy * eye_w + sx] } else { [0.0; 4] };
            if m[3] > 0.5 && m[2] > 0.0 {
                vectors.push([m[0] * 2.0 / eye_w as f32, m[1] * 2.0 / eye_h as f32, 0.0, 0.0]);
                depth.push((far_m * (m[2] - near_m) / ((far_m - near_m) * m[2])).clamp(0.0, 1.0));
            } else {
                vectors.push([0.0; 4]);
                depth.push(1.0);
            }
        }
    }
    (vectors, depth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Rgb;

    /// The render pass's colour gain (`gain_encoded`, on premultiplied layer colour)
    /// and the camera's (`synth::add_colour`, on a frame) are one operation where
    /// nothing clips: an opaque pixel agrees to 1e-6 (f32 rounding of the same
    /// formulas), a half-transparent one after un-premultiplying; clipped values
    /// stay at 1 in the pass (it writes a display), above it in the frame's twin.
    #[test]
    fn the_layer_gain_is_the_frames_colour_gain() {
        let gains = [1.3f32, 0.9, 0.55];
        let values = [0.0f32, 0.02, 0.1, 0.35, 0.6, 0.8];
        let frame = Rgb { width: values.len(), height: 1, channels: std::array::from_fn(|_| values.to_vec()) };
        let graded = crate::synth::add_colour(&frame, gains);
        for (i, &v) in values.iter().enumerate() {
            for a in [1.0f32, 0.5] {
                let out = gain_encoded([v * a, v * a, v * a, a], gains);
                for c in 0..3 {
                    let expect = graded.channels[c][i].min(1.0);
                    assert!(
                        (out[c] / a - expect).abs() < 1e-6,
                        "value {v}, alpha {a}, channel {c}: {} vs {expect}",
                        out[c] / a
                    );
                }
                assert_eq!(out[3], a);
            }
        }
        // Transparent pixels pass through; the luma reads the gained colour.
        assert_eq!(gain_encoded([0.0; 4], gains), [0.0; 4]);
        let layer = [[0.5f32, 0.5, 0.5, 1.0]];
        let rect = Rect { x: 0, y: 0, w: 1, h: 1 };
        // One stop down: the luma the grain is read at falls with the colour shown.
        let down = [0.5f32; 3];
        let plain = layer_luma(&layer, 1, rect, &EyeGain::default())[0];
        let graded_luma = layer_luma(&layer, 1, rect, &EyeGain { colour: Some(down), ..Default::default() })[0];
        let g = gain_encoded(layer[0], down);
        let expect: f32 = (0..3).map(|c| crate::image::LUMA_WEIGHTS[c] * g[c]).sum();
        assert!((graded_luma - expect).abs() < 1e-6, "{graded_luma} vs {expect}");
        assert!(plain - graded_luma > 0.1, "one stop down moved the luma from {plain} to {graded_luma}");
    }
}
