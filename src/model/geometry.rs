//! Plain data shared by the renderer and its CPU twins: the per-eye pixel
//! rectangles effect work is bounded by, the MB tile grid over them, the grain
//! synthesis table a snapshot carries to the GPU, and the per-pixel gain (colour
//! and vignetting) the composite applies.

/// A pixel rectangle (the screen bounds effect work is limited to).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Rect {
    pub x: i32,
    pub y: i32,
    pub w: i32,
    pub h: i32,
}

impl Rect {
    pub fn full(width: usize, height: usize) -> Self {
        Rect { x: 0, y: 0, w: width as i32, h: height as i32 }
    }
    pub fn contains(&self, x: i32, y: i32) -> bool {
        x >= self.x && y >= self.y && x < self.x + self.w && y < self.y + self.h
    }
    pub fn area(&self) -> usize {
        (self.w.max(0) as usize) * (self.h.max(0) as usize)
    }
}

/// The one rectangle a multiview pass may be confined to so that it covers every
/// rectangle in `rects`: their union, widened outward to multiples of `align_px`
/// (so that whole tiles and 2×2 half-resolution blocks over any of them lie
/// inside) and clipped to `width × height`. Empty when every rectangle is.
pub fn covering_rect(rects: &[Rect], align_px: i32, width: usize, height: usize) -> Rect {
    let align = align_px.max(1);
    let (mut x0, mut y0, mut x1, mut y1) = (i32::MAX, i32::MAX, i32::MIN, i32::MIN);
    for r in rects.iter().filter(|r| r.area() > 0) {
        x0 = x0.min(r.x);
        y0 = y0.min(r.y);
        x1 = x1.max(r.x + r.w);
        y1 = y1.max(r.y + r.h);
    }
    if x0 > x1 {
        return Rect::default();
    }
    let down = |v: i32| v.div_euclid(align) * align;
    let up = |v: i32| (v + align - 1).div_euclid(align) * align;
    let (x0, y0) = (down(x0).max(0), down(y0).max(0));
    let (x1, y1) = (up(x1).min(width as i32), up(y1).min(height as i32));
    Rect { x: x0, y: y0, w: (x1 - x0).max(0), h: (y1 - y0).max(0) }
}

/// Tiles (of `tile_px`) covering `rect`, as (x0, y0, w, h) in tile units.
pub fn tile_rect(rect: Rect, tile_px: i32, width: usize, height: usize) -> Rect {
    if rect.area() == 0 {
        return Rect::default();
    }
    let x0 = rect.x / tile_px;
    let y0 = rect.y / tile_px;
    let x1 = ((rect.x + rect.w - 1) / tile_px).min((width as i32 - 1) / tile_px);
    let y1 = ((rect.y + rect.h - 1) / tile_px).min((height as i32 - 1) / tile_px);
    Rect { x: x0, y: y0, w: x1 - x0 + 1, h: y1 - y0 + 1 }
}

/// The half-resolution rectangle covering full-resolution `rect`.
pub fn half_rect(rect: Rect) -> Rect {
    if rect.area() == 0 {
        return Rect::default();
    }
    let (x0, y0) = (rect.x.div_euclid(2), rect.y.div_euclid(2));
    let (x1, y1) = ((rect.x + rect.w + 1).div_euclid(2), (rect.y + rect.h + 1).div_euclid(2));
    Rect { x: x0, y: y0, w: x1 - x0, h: y1 - y0 }
}

/// Grain synthesis weights of one noise model, as the GPU reads them:
/// [node][channel][band] with `nodes` luma nodes over `luma_range` (computed from
/// the model by `synth::SynthesisTable`; carried by each `worker::Snapshot`).
#[derive(Clone, Debug, PartialEq)]
pub struct GrainTable {
    pub luma_range: [f32; 2],
    pub nodes: u32,
    pub weights: Vec<f32>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covering_rect_holds_every_rect_and_its_tiles() {
        let a = Rect { x: 37, y: 5, w: 100, h: 41 };
        let b = Rect { x: 60, y: 90, w: 13, h: 7 };
        let c = covering_rect(&[a, b, Rect::default()], 16, 300, 200);
        assert_eq!(c, Rect { x: 32, y: 0, w: 112, h: 112 });
        // Every tile of 16 over a or b, and every 2×2 block, lies inside.
        for r in [a, b] {
            let t = tile_rect(r, 16, 300, 200);
            assert!(c.contains(t.x * 16, t.y * 16) && c.contains((t.x + t.w) * 16 - 1, (t.y + t.h) * 16 - 1));
            let hr = half_rect(r);
            assert!(c.contains(hr.x * 2, hr.y * 2) && c.contains((hr.x + hr.w) * 2 - 1, (hr.y + hr.h) * 2 - 1));
        }
        // Clipped to the target; empty in, empty out.
        assert_eq!(
            covering_rect(&[Rect { x: 290, y: 190, w: 10, h: 10 }], 16, 300, 200),
            Rect { x: 288, y: 176, w: 12, h: 24 }
        );
        assert_eq!(covering_rect(&[Rect::default(), Rect::default()], 16, 300, 200), Rect::default());
    }
}

/// The lens's falloff as one eye buffer sees it (`model::Vignetting` mapped into
/// the eye's pixels): r = |p − `centre_px`| · `inv_half_diag_px`, held at 1 past
/// the camera's corner (the fitted and validated range).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeVignette {
    pub log_falloff: [f32; 3],
    pub centre_px: [f32; 2],
    pub inv_half_diag_px: f32,
}

impl EyeVignette {
    /// V at the centre of pixel (x, y) (`shaders/colour_gain.glsl`'s
    /// `vignette_gain`, the same f32 arithmetic).
    pub fn gain_at(&self, x: usize, y: usize) -> f32 {
        let dx = (x as f32 + 0.5 - self.centre_px[0]) * self.inv_half_diag_px;
        let dy = (y as f32 + 0.5 - self.centre_px[1]) * self.inv_half_diag_px;
        let r2 = (dx * dx + dy * dy).min(1.0);
        let a = self.log_falloff;
        (r2 * (a[0] + r2 * (a[1] + r2 * a[2]))).exp()
    }
}

/// The lens's lateral chromatic aberration as one eye buffer sees it
/// (`model::ChromaticAberration` about the eye's principal point): red and blue are
/// read at c + (p − c)/s, i.e. p + `inv_scale_minus_one`·d with d = p − c, d held
/// at the camera's corner radius beyond it (as `EyeVignette`; a ratio of scales is
/// the same in any pixel unit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeChromatic {
    /// [1/s_R − 1, 1/s_B − 1].
    pub inv_scale_minus_one: [f32; 2],
    pub centre_px: [f32; 2],
    pub inv_half_diag_px: f32,
}

impl EyeChromatic {
    /// Where channel `k` (0 red, 1 blue) of the pixel with centre (x + ½, y + ½) is
    /// read, in continuous pixel coordinates (`shaders/composite.comp`'s
    /// `ca_source`, the same f32 arithmetic).
    pub fn source(&self, k: usize, x: usize, y: usize) -> [f32; 2] {
        let px = [x as f32 + 0.5, y as f32 + 0.5];
        let d = [px[0] - self.centre_px[0], px[1] - self.centre_px[1]];
        let r = (d[0] * d[0] + d[1] * d[1]).sqrt() * self.inv_half_diag_px;
        let f = self.inv_scale_minus_one[k] / r.max(1.0);
        [px[0] + f * d[0], px[1] + f * d[1]]
    }
}

/// What the composite applies per pixel of one eye beyond the effect chain: the
/// linear-light gain (the camera's colour gains, `model::Colour`, times the lens's
/// falloff at the pixel) and the lens's lateral chromatic aberration.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EyeGain {
    pub colour: Option<[f32; 3]>,
    pub vignette: Option<EyeVignette>,
    pub chromatic: Option<EyeChromatic>,
}

impl EyeGain {
    /// The gain at pixel (x, y); `None` where neither term applies (the authored
    /// colour passes untouched).
    pub fn at(&self, x: usize, y: usize) -> Option<[f32; 3]> {
        if self.colour.is_none() && self.vignette.is_none() {
            return None;
        }
        let v = self.vignette.map_or(1.0, |v| v.gain_at(x, y));
        Some(self.colour.unwrap_or([1.0; 3]).map(|g| g * v))
    }
}
