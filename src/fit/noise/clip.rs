//! Which noise samples to leave out: pixels clipped at a channel's extreme (a
//! repeated white or black level) and pixels where an aligned reference does not
//! hold, as per-tile counts read over each sample's footprint.

use super::*;

/// Clipped pixels: a channel is clipped at its maximum (minimum) when that exact
/// value repeats in at least 0.05% of the pixels (and 2) and is bright, ≥ 0.6
/// (dark, ≤ 0.1). This finds 8-bit 255s, 16-bit 65535s and float frames clipped at
/// any white level, while unclipped float frames (over- and undershoot included)
/// have no repeated extreme and lose nothing.
pub(super) fn clip_mask(img: &Rgb, block: usize, valid: Option<&Plane>) -> ClipMask {
    clip_mask_of(img, &clip_limits(img), block, valid, &[0, 1, 2])
}

/// Per channel, the clipped low and high values (see `clip_mask`), if any.
pub(super) type ClipLimits = [(Option<f32>, Option<f32>); 3];

/// The clipped extremes of every channel (`channel_clip_limits`; the accurate
/// tier's — the blind tier reads them from tile extremes, `blind_clip_masks`).
pub(super) fn clip_limits(img: &Rgb) -> ClipLimits {
    let min_count = clip_min_count(img.len());
    std::array::from_fn(|c| channel_clip_limits(&img.channels[c], min_count))
}

/// How often a channel's extreme must repeat to be a clip level (`clip_mask`):
/// 0.05% of the pixels, and at least 2.
pub(super) fn clip_min_count(pixels: usize) -> usize {
    (pixels / 2000).max(2)
}

/// A channel's clip levels from its extremes and their counts (`clip_mask`): the
/// minimum when dark (≤ 0.1), the maximum when bright (≥ 0.6), each repeated at
/// least `min_count` times.
pub(super) fn clip_levels(lo: (f32, usize), hi: (f32, usize), min_count: usize) -> (Option<f32>, Option<f32>) {
    ((lo.0 <= 0.1 && lo.1 >= min_count).then_some(lo.0), (hi.0 >= 0.6 && hi.1 >= min_count).then_some(hi.0))
}

/// One channel's `clip_limits`, in one pass over 8 independent lanes: per lane the
/// extremes and how often each was seen (a new extreme restarts its count), then
/// the lanes merged (the channel's extreme counts in every lane that reached it).
/// Measured both ways, in different surroundings: while the blocking scan before it
/// read every row (the frame cached), a lane-wise single pass was 2× slower than a
/// pass for the extremes and another counting them; with blocking on half the rows
/// the passes are bound by memory (three 4.9 MB planes at 1280×960), and one pass
/// read 3.7 ms against 4.4 ms for two (the `search.clipping` stage, the fit bench's
/// frame). The lanes compare with `<`/`>`: the fit's input is checked finite first.
pub(super) fn channel_clip_limits(ch: &[f32], min_count: usize) -> (Option<f32>, Option<f32>) {
    const LANES: usize = 8;
    let (mut lo, mut hi) = ([f32::INFINITY; LANES], [f32::NEG_INFINITY; LANES]);
    let (mut nlo, mut nhi) = ([0u32; LANES], [0u32; LANES]);
    let mut see = |i: usize, v: f32| {
        nlo[i] = if v < lo[i] { 1 } else { nlo[i] + (v == lo[i]) as u32 };
        lo[i] = if v < lo[i] { v } else { lo[i] };
        nhi[i] = if v > hi[i] { 1 } else { nhi[i] + (v == hi[i]) as u32 };
        hi[i] = if v > hi[i] { v } else { hi[i] };
    };
    let chunks = ch.chunks_exact(LANES);
    let tail = chunks.remainder();
    for k in chunks {
        for (i, &v) in k.iter().enumerate() {
            see(i, v);
        }
    }
    for (i, &v) in tail.iter().enumerate() {
        see(i, v);
    }
    let merge = |ext: &[f32; LANES], n: &[u32; LANES], better: fn(f32, f32) -> f32| {
        let e = ext.iter().copied().fold(ext[0], better);
        let count: usize = ext.iter().zip(n).filter(|(x, _)| **x == e).map(|(_, &c)| c as usize).sum();
        (e, count)
    };
    clip_levels(merge(&lo, &nlo, f32::min), merge(&hi, &nhi, f32::max), min_count)
}

/// `clip_mask` counting clipped values in `channels` only (the blind tier measures
/// each channel where that channel is unclipped: on the vtest clip the dark grass's
/// blue channel sits at 0 in 8% of the pixels, which would otherwise take the green
/// and red noise of the whole lawn with it).
pub(super) fn clip_mask_of(
    img: &Rgb,
    limits: &ClipLimits,
    block: usize,
    valid: Option<&Plane>,
    channels: &[usize],
) -> ClipMask {
    // Pixels where the reference does not hold: a sample is kept while they are at
    // most `MAX_INVALID_FRACTION` of its footprint (the residual is zero there, so
    // they lower its variance by at most that fraction). Excluding every footprint
    // that touches one would empty the coarse levels, whose windows are ~70 px wide.
    let holds = |x: f32| x > 0.5; // NaN: does not hold
    let invalid = valid.filter(|v| v.data.iter().any(|x| !holds(*x))).map(|v| {
        IntegralImage::new(&Plane::from_vec(
            v.width,
            v.height,
            v.data.iter().map(|x| if holds(*x) { 0.0 } else { 1.0 }).collect(),
        ))
    });
    let channels: Vec<usize> =
        channels.iter().copied().filter(|&c| limits[c].0.is_some() || limits[c].1.is_some()).collect();
    if channels.is_empty() {
        return ClipMask { clipped: None, invalid };
    }
    // Mark block×block tiles holding any clipped pixel; footprint tests then run on
    // the tile grid (conservative by up to one tile). The accurate tier uses 1 (exact),
    // the blind tier 8 (a 1/64-size table; it can afford to lose border samples).
    let (bw, bh) = (img.width.div_ceil(block), img.height.div_ceil(block));
    let mut blocks = Plane::new(bw, bh, 0.0);
    for &c in &channels {
        let (lo, hi) = limits[c];
        let (lo, hi) = (lo.unwrap_or(f32::NAN), hi.unwrap_or(f32::NAN)); // NaN equals nothing
        for (y, row) in img.channels[c].chunks_exact(img.width).enumerate() {
            // Whole tiles at once (no early exit: a branch-free fold vectorises).
            for (bx, tile) in row.chunks(block).enumerate() {
                if tile.iter().fold(false, |a, &v| a | (v == lo) | (v == hi)) {
                    blocks.data[(y / block) * bw + bx] = 1.0;
                }
            }
        }
    }
    ClipMask { clipped: Some((IntegralImage::new(&blocks), block_shift(block))), invalid }
}

/// Largest share of a noise sample's footprint where the reference may not hold.
pub(super) const MAX_INVALID_FRACTION: f64 = 0.02;

/// Clipped-tile counts over boxes (and log2 of the tile size; `None` when the frame
/// has no clipping at all), and the invalid-reference pixel counts (`None`: valid
/// everywhere).
pub(super) struct ClipMask {
    clipped: Option<(IntegralImage, u32)>,
    invalid: Option<IntegralImage>,
}

/// log2 of a tile size (1 for the accurate tier, 8 for the blind one): `touches`
/// runs for every channel at every grid point of every level, and three integer
/// divisions by a run-time tile size per call were most of its cost.
fn block_shift(block: usize) -> u32 {
    assert!(block.is_power_of_two(), "clip tiles are a power of two px (got {block})");
    block.trailing_zeros()
}

impl ClipMask {
    /// Whether any clipped pixel may lie within `r` of (x, y) (level-0 pixels):
    /// the box is widened to whole tiles, so the test errs on the safe side.
    ///
    /// `coarse`: for footprints so wide (level 3 and the low-pass: ~100–180 px) that
    /// one clipped pixel anywhere near would empty them on a small frame (the
    /// accurate tier passes it from level 3, the blind tier from level 2);
    /// there a footprint may hold up to `MAX_INVALID_FRACTION` clipped pixels (they
    /// carry no noise: the variance is diluted by at most that fraction).
    pub(super) fn touches(&self, x: usize, y: usize, r: usize, coarse: bool) -> bool {
        let span = |c: usize, r: usize, n: usize| ((c + r + 1).min(n) - c.saturating_sub(r)) as f64;
        let clipped = match &self.clipped {
            None => false,
            Some((ii, shift)) => {
                let (bx, by) = ((x >> shift).min(ii.width() - 1), (y >> shift).min(ii.height() - 1));
                let rb = (r + (1 << shift) - 1) >> shift; // r.div_ceil(block)
                let count = ii.box_sum(bx, by, rb);
                if coarse {
                    count > MAX_INVALID_FRACTION * span(bx, rb, ii.width()) * span(by, rb, ii.height())
                } else {
                    count > 0.0
                }
            }
        };
        clipped
            || self.invalid.as_ref().is_some_and(|ii| {
                let (cx, cy) = (x.min(ii.width() - 1), y.min(ii.height() - 1));
                let area = span(cx, r, ii.width()) * span(cy, r, ii.height());
                ii.box_sum(cx, cy, r) > MAX_INVALID_FRACTION * area
            })
    }
}

/// Every `block`×`block` tile's lowest and highest value of one channel, band by
/// band of `block` rows (`rows_read`: fed as the rows arrive, e.g. by the blind
/// noise fit's first reduce, `reduce_slice_visiting`, while they are in cache).
#[cfg_attr(test, derive(Debug, PartialEq))]
pub(super) struct TileExtremes {
    block: usize,
    width: usize,
    height: usize,
    bands_done: usize,
    lo: Vec<f32>,
    hi: Vec<f32>,
}

impl TileExtremes {
    pub(super) fn new(width: usize, height: usize, block: usize) -> Self {
        let tiles = width.div_ceil(block) * height.div_ceil(block);
        Self { block, width, height, bands_done: 0, lo: Vec::with_capacity(tiles), hi: Vec::with_capacity(tiles) }
    }

    /// Rows 0 … `y` of channel `ch` are now available: every band they complete is
    /// read. Called with increasing `y` (any steps); a band is read once.
    /// Out of line (a call per band of rows): inlined into the pyramid's reduce, its
    /// tile lanes stayed vectorised or not with changes elsewhere in the noise fit
    /// (measured: 2.95 → 9.52 M instructions a fit, the pyramids +0.8 ms, after an
    /// unrelated edit to `blind.rs`).
    #[inline(never)]
    pub(super) fn rows_read(&mut self, ch: &[f32], y: usize) {
        let (block, w) = (self.block, self.width);
        while self.bands_done * block < self.height && ((self.bands_done + 1) * block).min(self.height) <= y + 1 {
            let by = self.bands_done;
            let band = &ch[by * block * w..((by + 1) * block).min(self.height) * w];
            // A whole tile of the fit's width (`LANES` columns) down the band: its
            // extremes held in that many lanes through its rows (one load, one min and
            // one max per value, which vectorise) and folded across the lanes once
            // per tile; other widths and a partial last tile value by value.
            // `if` selects, not `f32::min`: the input is finite (checked by `fit`).
            const LANES: usize = 8;
            for x0 in (0..w).step_by(block) {
                let x1 = (x0 + block).min(w);
                let (lo, hi) = if x1 - x0 == LANES {
                    // Plain index loops over fixed-size arrays: written with slice
                    // iterators (`chunks_exact`, `skip`, `from_fn`, `fold`) the lanes
                    // vectorised or not with how the crate's other code was split
                    // into codegen units (rows_read 6% → 15% of the noise fit after
                    // an edit to `blind.rs`, perf).
                    let lanes_at = |i: usize| band.get(i..).and_then(|s| s.first_chunk::<LANES>()).copied();
                    let rows = band.len() / w;
                    let first = lanes_at(x0).unwrap_or([0.0; LANES]);
                    let (mut lo, mut hi) = (first, first);
                    for r in 1..rows {
                        let v = lanes_at(r * w + x0).unwrap_or(first);
                        for k in 0..LANES {
                            lo[k] = if v[k] < lo[k] { v[k] } else { lo[k] };
                            hi[k] = if v[k] > hi[k] { v[k] } else { hi[k] };
                        }
                    }
                    let (mut l, mut u) = (f32::INFINITY, f32::NEG_INFINITY);
                    for k in 0..LANES {
                        l = l.min(lo[k]);
                        u = u.max(hi[k]);
                    }
                    (l, u)
                } else {
                    band.chunks_exact(w)
                        .flat_map(|row| &row[x0..x1])
                        .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, u), &v| {
                            (if v < l { v } else { l }, if v > u { v } else { u })
                        })
                };
                self.lo.push(lo);
                self.hi.push(hi);
            }
            self.bands_done += 1;
        }
    }
}

/// The blind tier's clip limits and per-channel tile masks (`clip_limits` and
/// `clip_mask_of(img, limits, block, None, &[c])` for each channel c, exactly) from
/// one pass per channel: every tile's lowest and highest value. A channel's extreme
/// is the extreme of its tiles' extremes; only tiles that reach it are read again
/// to count it (a frame clipped over a fifth of its area reads a fifth again), and
/// a tile holds a clipped pixel exactly when its extreme is the clip level.
#[cfg(test)]
pub(super) fn blind_clip_masks(img: &Rgb, block: usize) -> (ClipLimits, [ClipMask; 3]) {
    let tiles: Vec<TileExtremes> = (0..3)
        .map(|c| {
            let mut t = TileExtremes::new(img.width, img.height, block);
            t.rows_read(&img.channels[c], img.height.saturating_sub(1));
            t
        })
        .collect();
    blind_clip_masks_from(img, &tiles)
}

/// `blind_clip_masks` from the channels' tile extremes (`TileExtremes`, one per
/// channel in order, every row read).
pub(super) fn blind_clip_masks_from(img: &Rgb, tiles: &[TileExtremes]) -> (ClipLimits, [ClipMask; 3]) {
    let (w, h) = (img.width, img.height);
    let min_count = clip_min_count(img.len());
    let per_channel = |c: usize| -> ((Option<f32>, Option<f32>), ClipMask) {
        let (ch, t) = (&img.channels[c], &tiles[c]);
        debug_assert_eq!(t.lo.len(), w.div_ceil(t.block) * h.div_ceil(t.block), "every band read");
        let block = t.block;
        let (bw, bh) = (w.div_ceil(block), h.div_ceil(block));
        let (tlo, thi) = (&t.lo, &t.hi);
        // How often `e` occurs in the tiles whose extreme it is, up to `min_count`
        // (so at most `min_count` tiles are read again, whatever the frame).
        let count = |tiles: &[f32], e: f32| {
            let mut n = 0usize;
            for (t, _) in tiles.iter().enumerate().filter(|(_, &v)| v == e) {
                let (bx, by) = (t % bw, t / bw);
                for y in by * block..((by + 1) * block).min(h) {
                    n += ch[y * w + bx * block..y * w + ((bx + 1) * block).min(w)].iter().filter(|&&v| v == e).count();
                }
                if n >= min_count {
                    break;
                }
            }
            n
        };
        let lo = tlo.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = thi.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let (lo, hi) = clip_levels((lo, count(tlo, lo)), (hi, count(thi, hi)), min_count);
        if lo.is_none() && hi.is_none() {
            return ((lo, hi), ClipMask { clipped: None, invalid: None });
        }
        let blocks: Vec<f32> =
            tlo.iter().zip(thi).map(|(&a, &b)| (Some(a) == lo || Some(b) == hi) as u8 as f32).collect();
        let ii = IntegralImage::new(&Plane::from_vec(bw, bh, blocks));
        ((lo, hi), ClipMask { clipped: Some((ii, block_shift(block))), invalid: None })
    };
    let [(l0, m0), (l1, m1), (l2, m2)] = std::array::from_fn(per_channel);
    ([l0, l1, l2], [m0, m1, m2])
}
