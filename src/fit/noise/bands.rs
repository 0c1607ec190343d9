//! The blind noise fit's per-channel pyramids, and the frame's level-0 band read
//! window by window where its flat samples measure it (never built as a plane).

use super::*;

/// One channel's Gaussian pyramid G[1..=levels] (`.0[l]` is G[l + 1]; G[0] is
/// `data` itself, not copied) and its band-pass levels 0..levels, by the clamp-free
/// interior `reduce`/`expand`. Without `band0` the level-0 band is left empty (0×0):
/// the frame's own is read window by window (`Band0`), never as a plane.
pub(super) fn channel_pyramids(
    data: &[f32],
    w: usize,
    h: usize,
    levels: usize,
    band0: bool,
) -> (Vec<Plane>, Vec<Plane>) {
    let g = crate::image::gaussian_pyramid_of(crate::image::reduce_slice(data, w, h), levels);
    let bands = (0..levels)
        .map(|l| {
            if l == 0 && !band0 {
                return Plane::from_vec(0, 0, vec![]);
            }
            let (fine, fw, fh) =
                if l == 0 { (data, w, h) } else { (&g[l - 1].data[..], g[l - 1].width, g[l - 1].height) };
            let mut b = crate::image::expand(&g[l], fw, fh);
            for (v, gv) in b.data.iter_mut().zip(fine) {
                *v = gv - *v;
            }
            b
        })
        .collect();
    (g, bands)
}

/// The frame's level-0 band per channel, I_c − expand(G_c[1]), read only in the 9×9
/// windows of the flat samples that measure it (~13% of a 1280×960 frame's pixels
/// at the default grid): three full-resolution expands were 3.6 ms of the fit's
/// 7.4 ms of pyramids. `expand_window9` computes what `expand` would have written,
/// so every window holds the values the plane held.
pub(super) struct Band0<'a> {
    pub(super) fine: [&'a [f32]; 3],
    pub(super) g1: [&'a Plane; 3],
    pub(super) width: usize,
    pub(super) height: usize,
}

impl Band0<'_> {
    /// The band of channel `c` in the 9×9 window at (x, y), coordinates clamped into
    /// the frame (as `Plane::get_clamped` reads a border window).
    pub(super) fn window(&self, c: usize, x: usize, y: usize) -> [[f32; 9]; 9] {
        let mut e = crate::image::expand_window9(self.g1[c], self.width, self.height, x, y);
        if self.interior(x, y) {
            // No clamps: each window row is a slice of the frame's row (the same
            // subtraction per value; the clamped indices below cost ~1 ms a fit).
            for (j, er) in e.iter_mut().enumerate() {
                let start = (y + j - 4) * self.width + x - 4;
                for (v, &f) in er.iter_mut().zip(&self.fine[c][start..start + 9]) {
                    *v = f - *v;
                }
            }
            return e;
        }
        let (w, h) = (self.width as isize, self.height as isize);
        std::array::from_fn(|j| {
            let yy = (y as isize + j as isize - 4).clamp(0, h - 1) as usize;
            std::array::from_fn(|i| {
                let xx = (x as isize + i as isize - 4).clamp(0, w - 1) as usize;
                self.fine[c][yy * self.width + xx] - e[j][i]
            })
        })
    }

    /// Whether the window at (x, y) lies inside the frame (`SepWindow::interior`).
    pub(super) fn interior(&self, x: usize, y: usize) -> bool {
        x >= 4 && y >= 4 && x + 4 < self.width && y + 4 < self.height
    }
}
