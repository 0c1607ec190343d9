//! Compression blocking, blind: the 8-px grid a block-transform codec leaves in a
//! frame, which the fast noise fit reports (its fine levels then hold codec
//! artefacts as well as sensor noise).

use super::*;

/// The frame's compression blocking alone, as the blind fit detects it (its
/// structure measure, the luma's band 2, built here): for callers that hold a
/// reference from other frames and must know whether the stream's codec copies
/// noise between them (`worker::Calibrator`).
pub fn compression_blocking(img: &Rgb) -> Option<crate::model::Blocking> {
    let bands = crate::image::laplacian_pyramid(&img.luma(), 3).bands;
    detect_blocking(img, None, &bands[2], 4)
}

/// Periodic block-grid discontinuities of a block-transform codec (JPEG, MPEG-4,
/// H.264 at 8 px): the mean absolute luma step across each column (row) phase mod 8,
/// over the flatter half of the frame (where blocking shows and texture does not
/// mask it). Blocking is reported when one phase exceeds the median of the other
/// seven by `BLOCKING_RATIO` in both directions; unblocked frames measured here stay
/// below 1.05 (the astronaut, the cat, synthetic noise), the vtest clip's DivX
/// frames reach ~1.3 (tests/real_noise.rs). `luma`: the frame's luma where the
/// caller holds it (read instead of made row by row from the three channels; the
/// same values, `Rgb::luma`'s sum).
pub(super) fn detect_blocking(
    img: &Rgb,
    luma: Option<&Plane>,
    structure: &Plane,
    scale: usize,
) -> Option<crate::model::Blocking> {
    const PERIOD: usize = 8;
    let (w, h) = (img.width, img.height);
    if w < 4 * PERIOD || h < 4 * PERIOD {
        return None;
    }
    // Flat pixels: structure magnitude below its median (structure is a signed band
    // at 1/scale resolution).
    // The median selected on the magnitudes' bit patterns: non-negative floats
    // (NaN included, its sign cleared like every value's) order as their bits do,
    // and `total_cmp` orders them the same way, so the value is `percentile`'s, bit
    // for bit, by integer comparisons.
    let mut s: Vec<u32> = structure.data.iter().map(|v| v.abs().to_bits()).collect();
    let med = match s.len().checked_sub(1) {
        Some(last) => {
            let k = (last as f64 * 0.5).round() as usize;
            f32::from_bits(*s.select_nth_unstable(k).1)
        }
        None => 0.0,
    };
    // Row by row, the luma computed on the fly (two rows live, no full-frame plane),
    // the flat mask as 0/1 weights and the phase sums over 8-px chunks: branch-free,
    // so the 8 phases vectorise.
    let lw = crate::image::LUMA_WEIGHTS;
    let luma_row = |y: usize, out: &mut [f32]| {
        let i = y * w;
        for (x, o) in out.iter_mut().enumerate() {
            *o = lw[0] * img.channels[0][i + x] + lw[1] * img.channels[1][i + x] + lw[2] * img.channels[2][i + x];
        }
    };
    let (mut cur_buf, mut next_buf, mut flat) = (vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]);
    if luma.is_none() {
        luma_row(0, &mut cur_buf);
    }
    let (mut col, mut ncol, mut row, mut nrow) =
        ([0.0f64; PERIOD], [0.0f64; PERIOD], [0.0f64; PERIOD], [0.0f64; PERIOD]);
    // Above 400k pixels every other band of `PERIOD` rows: each band still holds
    // every row phase and the column sums half the frame's flat pixels (~150 000 at
    // 1280×960), far more than the boundary/interior contrast needs (unblocked
    // frames < 1.05, the vtest clip's ~1.3); the scan was 3 ms of the blind tier.
    let band_stride = if w * h > 400_000 { 2 } else { 1 };
    let mut have = 0usize; // the row whose luma `cur` holds
    let mut flat_row: Option<usize> = None; // the structure row `flat` was built from
    for y in 0..h - 1 {
        if (y / PERIOD) % band_stride != 0 {
            continue;
        }
        if luma.is_none() {
            if have != y {
                luma_row(y, &mut cur_buf);
            }
            luma_row(y + 1, &mut next_buf);
            have = y + 1;
        }
        let (cur, next): (&[f32], &[f32]) = match luma {
            Some(l) => (&l.data[y * w..(y + 1) * w], &l.data[(y + 1) * w..(y + 2) * w]),
            None => (&cur_buf, &next_buf),
        };
        // The mask changes only with the structure row (every `scale` frame rows):
        // rebuilt then, one structure value spread over its `scale` columns.
        let sy = (y / scale).min(structure.height - 1);
        if flat_row != Some(sy) {
            let srow = &structure.data[sy * structure.width..(sy + 1) * structure.width];
            for (xs, f) in flat.chunks_mut(scale).enumerate() {
                let m = (srow[xs.min(structure.width - 1)].abs() <= med) as u8 as f32;
                f.fill(m);
            }
            // The last column has no right neighbour: its horizontal step is left out.
            flat[w - 1] = 0.0;
            flat_row = Some(sy);
        }
        let (mut c, mut nc, mut r) = ([0.0f32; PERIOD], [0.0f32; PERIOD], [0.0f32; PERIOD]);
        let n = (w - 1) / PERIOD * PERIOD;
        // In chunks of one period (fixed-length slices: no bounds check per pixel,
        // the phases in lanes; each phase's sum in the same order as before).
        let chunks = flat[..n]
            .chunks_exact(PERIOD)
            .zip(cur[..n].chunks_exact(PERIOD))
            .zip(cur[1..n + 1].chunks_exact(PERIOD).zip(next[..n].chunks_exact(PERIOD)));
        for ((m, here), (right, below)) in chunks {
            for k in 0..PERIOD {
                c[k] += m[k] * (right[k] - here[k]).abs();
                r[k] += m[k] * (below[k] - here[k]).abs();
                nc[k] += m[k];
            }
        }
        for x in n..w - 1 {
            let m = flat[x];
            c[x % PERIOD] += m * (cur[x + 1] - cur[x]).abs();
            r[x % PERIOD] += m * (next[x] - cur[x]).abs();
            nc[x % PERIOD] += m;
        }
        let (rs, rn): (f32, f32) = (r.iter().sum(), nc.iter().sum());
        for k in 0..PERIOD {
            col[k] += c[k] as f64;
            ncol[k] += nc[k] as f64;
        }
        row[y % PERIOD] += rs as f64;
        nrow[y % PERIOD] += rn as f64;
        if luma.is_none() {
            std::mem::swap(&mut cur_buf, &mut next_buf);
        }
    }
    let peak = |sum: &[f64; PERIOD], n: &[f64; PERIOD]| -> Option<(usize, f32)> {
        let m: Vec<f64> = (0..PERIOD).map(|i| sum[i] / n[i].max(1.0)).collect();
        let k = (0..PERIOD).max_by(|&a, &b| m[a].total_cmp(&m[b]))?;
        let mut rest: Vec<f32> = (0..PERIOD).filter(|&i| i != k).map(|i| m[i] as f32).collect();
        let base = percentile(&mut rest, 0.5) as f64;
        (base > 0.0).then(|| (k, (m[k] / base) as f32))
    };
    let (px, rx) = peak(&col, &ncol)?;
    let (py, ry) = peak(&row, &nrow)?;
    let strength = rx.min(ry);
    (strength >= BLOCKING_RATIO).then_some(crate::model::Blocking {
        period_px: PERIOD as u32,
        phase_px: [px as u32, py as u32],
        strength,
    })
}

/// Smallest boundary/interior step ratio reported as blocking (see `detect_blocking`).
const BLOCKING_RATIO: f32 = 1.15;
