//! Plain data shared by the renderer and its CPU twins: the per-eye pixel
//! rectangles effect work is bounded by, the MB tile grid over them, and the grain
//! synthesis table a snapshot carries to the GPU.

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
