//! The blind exposure's second single-frame reading where the streak's zeros are not
//! identified: the *shape* of the derivative autocorrelation along the flow matched to
//! the one across it (docs/blind-motion-blur.md "The derivative autocorrelation's shape, shipped").
//!
//! Gradient-energy isotropy (`isotropy.rs`) balances one number per direction: blur
//! the frame across the flow by a candidate box L and take the L at which the
//! gradient energies along and across agree — the derivative autocorrelation at lag
//! 0. A sharp scene that is isotropic has the same derivative autocorrelation along
//! any direction at *every* lag, so after the same box across the flow the whole
//! function along u = F/|F| must match the one along v up to one amplitude:
//! ru_L(t) ≈ a·rv_L(t), t = 0…`MAX_LAG_PX` (fewer for a slow flow's short
//! streaks). The L that matches best is the streak.
//! A texture's anisotropy moves the lag-0 balance (a page of text: −46%); it moves
//! the shape less (the same page: −17%), and where isotropy and the shape disagree
//! neither is trusted more than their difference (`fit_fast`).
//!
//! Computed exactly, for every L at once, from one 2-D FFT: over a crop of the frame
//! sampled along (u, v), with du, dv its differences,
//! ru_L(t) = Σ_s r_L(s)·A_u(t, s) and rv_L(t) = Σ_s r_L(s)·A_v(0, t + s), where A is
//! the 2-D autocorrelation of du (dv) and r_L the box's own autocorrelation: the box
//! across commutes with the differences, so no candidate is ever blurred. White
//! pixel noise's share (σ² by Immerkær's estimate) is subtracted from both: noise is
//! isotropic, but the box across averages it along u and not along v.
//!
//! From a shape length of 20 px the along-flow curve's own dip near it (`along_dip`)
//! refines it: a box of L makes that curve dip at lag L whatever the texture's
//! anisotropy (the real text page: shape 25.8 px, dip 31.0, stated 31).
//!
//! Assumes one streak length over the crop: the flow's direction within ±10° (axial
//! spread) and its speed within ±25% of the median over the crop — the largest
//! centred one that holds it (`CROP_SCALES`); otherwise not read.

mod lags;

use crate::image::{Flow, Plane};
#[cfg(test)]
use lags::fft_size;
use lags::{autocorrelations, box_kernel, immerkaer_sigma, kernel_autocorrelation, NoiseTable, AV_OFFSET};

/// Lags of the two autocorrelations matched (px).
const MAX_LAG_PX: usize = 80;
/// Longest streak the shape is read for (px): the box's own autocorrelation spans
/// ±that across the flow, and the lags must hold its whole profile.
const MAX_LENGTH_PX: usize = 60;
/// The crop's largest side along and across the flow (px), a speed/accuracy setting:
/// the FFT is O(N log N) in the crop's area. Measured (BENCHMARKS.md): 640×480 read
/// 36 / 48 probe / held-out frames within 15% in 9–14 ms at 1280×960, this size 35 /
/// 50 in 4.7–6.4 ms, 384×288 29 / 48.
const MAX_CROP: (usize, usize) = (512, 384);
/// The crop's least side: two lag windows must fit in it.
const MIN_CROP_PX: usize = 2 * MAX_LAG_PX;
/// Flow below this (px per frame) is not read (as `isotropy.rs`).
const MIN_SPEED_PX: f32 = 3.0;
/// Least mean resultant length of the doubled flow angles: a spread of ~±10°.
const MIN_AXIAL_COHERENCE: f32 = 0.94;
/// Least ratio of the crop's across-flow derivative energy to white noise's: noise
/// alone gives ~1 (Immerkær's σ is exact on it, and texture only raises it); a
/// texture at 1.2× under σ 0.02 still reads a 12 px streak at 30°
/// (`white_noise_is_subtracted`; its along-flow energy was 1.07× the noise's).
const MIN_ENERGY_OVER_NOISE: f64 = 1.1;
/// The flow's 10th and 90th speed percentiles within this factor of the median.
const MAX_SPEED_SPREAD: f32 = 1.25;
/// A reading of no streak must be resolved: the match at a `ZERO_PROBE_PX` streak
/// (or the longest candidate, if shorter) must be worse than at none by this
/// factor. Smooth shading matches every length about equally: on the box-streak
/// evaluation frames (640×480, 50 px/frame) the colour wheel's residual rose
/// 0–1.3% from 0 to 4 px (without this rule it read its 6, 12 and 24 px streaks as
/// 0 px, *absent*), the 30 other frames read at 0 px by 21% or more (the rendered
/// page at 90° the least).
const MIN_ZERO_RISE: f64 = 1.1;
const ZERO_PROBE_PX: usize = 4;

/// What the shape reads.
#[derive(Clone, Debug)]
pub(super) struct AcfShape {
    /// Exposure: the streak length over the median flow speed.
    pub(super) lambda: f32,
    pub(super) length_px: f32,
    pub(super) speed_px: f32,
    /// Relative residual |ru − a·rv|² / |ru|² at the best length, and at L = 0.
    pub(super) residual: f64,
    pub(super) residual_sharp: f64,
    /// The crop's size along × across the flow (px).
    pub(super) crop: (usize, usize),
    /// The along-flow dip near the shape's length, where one is read.
    pub(super) dip: Option<Dip>,
}

/// The streak length from the autocorrelations' shape on `y` under `flow`, or why it
/// is not read.
#[cfg(test)]
pub(super) fn acf_shape(y: &Plane, flow: &Flow) -> Result<AcfShape, Refusal> {
    acf_read(y, flow).shape
}

/// How many candidate lengths (1 px apart) the shape reads past a full-frame
/// streak's, so that a best length at the full frame is a located minimum and one
/// past it is seen as such (`Refusal::PastFullFrame`), not as "the search's end". A best
/// past it is no exposure (λ ≤ 1): the frame is smoother along the flow than any
/// streak makes it. Measured (an oriented texture σ 3 / 1.2 px at 8 px/frame, 0–20°
/// off its smooth axis, no streak or λ 0.5): the best lies at 7.8–8.5 px — that
/// texture's smoothness along the flow is a full-frame streak's; with candidates
/// ending at ⌊speed⌋ (7 px for 7.99 px/frame at 10°) the shape is refused, and
/// isotropy's unbracketed root answers λ 1.000 *present* (`fit_fast` refuses where
/// both end there). Two, not more: the motion-blur fit's cost on the bench frame
/// rises ~0.35 ms with candidates to 1.5× the full frame, for nothing those two do
/// not show (and they are read only where the best within the full frame is the
/// full frame).
const PAST_FULL_FRAME_PX: usize = 2;

/// Why the shape gives no length. One kind is told apart because a caller branches
/// on it (`ends::both_at_full_frame`); the words are for the fit's reason.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Refusal {
    /// The best length lies past a full-frame streak (`PAST_FULL_FRAME_PX`): the frame
    /// is smoother along the flow than any exposure makes it.
    PastFullFrame(String),
    /// Any other reason: incoherent flow, no texture above the noise, a match that
    /// does not depend on the length, a best at the search's end.
    Other(String),
}

impl Refusal {
    /// The reason in words.
    pub(super) fn why(&self) -> &str {
        match self {
            Refusal::PastFullFrame(why) | Refusal::Other(why) => why,
        }
    }
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.why())
    }
}

impl From<String> for Refusal {
    fn from(why: String) -> Self {
        Refusal::Other(why)
    }
}

impl From<&str> for Refusal {
    fn from(why: &str) -> Self {
        Refusal::Other(why.into())
    }
}

/// What one look at the autocorrelations gives: the shape's reading (or why not),
/// and the frame's own (L = 0) derivative autocorrelations along and across the
/// flow, noise removed, lags 0…max_lag, wherever they were computed — also where
/// the shape's minimum is refused (the zeros' check in `fit_fast` reads them).
pub(super) struct AcfRead {
    pub(super) shape: Result<AcfShape, Refusal>,
    pub(super) sharp: Option<(Vec<f64>, Vec<f64>)>,
}

pub(super) fn acf_read(y: &Plane, flow: &Flow) -> AcfRead {
    let mut sharp = None;
    let shape = read(y, flow, &mut sharp, None);
    AcfRead { shape, sharp }
}

/// The fewest lags `sharp_curves` computes: its crop (6.4 × 4.8 lag windows) is then
/// at least 256×192 px, ~50 000 pairs per lag.
const MIN_CHECK_LAGS: usize = 40;

/// Only the frame's own (L = 0) derivative autocorrelations along and across the
/// flow, noise removed, to the lags a dip near `length_px` needs (and at least
/// `MIN_CHECK_LAGS`), over a crop proportioned to them: the zeros' check at a
/// fraction of the shape's cost (a 20 px streak: a 256×192 crop, not 512×384).
pub(super) fn sharp_curves(y: &Plane, flow: &Flow, length_px: f32) -> Result<(Vec<f64>, Vec<f64>), String> {
    let lags = ((length_px as f64 * DIP_WINDOW).ceil() as usize + 2).max(MIN_CHECK_LAGS);
    let mut sharp = None;
    let why = read(y, flow, &mut sharp, Some(lags)).err();
    sharp.ok_or_else(|| why.map(|r| r.why().to_string()).unwrap_or_default())
}

/// What the autocorrelations say about a streak of a given length (`check_length`).
pub(super) struct LengthCheck {
    /// A dip near the length, where read.
    pub(super) dip: Option<Dip>,
    /// Why the length is not a streak's — no dip near it and no shape above half
    /// of it — or `None`.
    pub(super) contradiction: Option<String>,
    /// The full look, where it ran (the fallback reads its shape).
    pub(super) shape: Option<Result<AcfShape, Refusal>>,
    /// For the fit's reason: "; the derivative autocorrelation …".
    pub(super) note: String,
}

/// Whether the autocorrelations support a streak of `length_px` (from
/// `min_length` px; the zeros' check in `fit_fast`): a dip near it (`along_dip`),
/// or else a shape length above half of it. The frame's own curves come first over
/// a crop sized to the dip (`sharp_curves`, 1–2 ms); only where they show no dip
/// does the full look run (its dip and its shape). Stage times go to `st`.
pub(super) fn check_length(
    y: &Plane,
    flow: &Flow,
    length_px: f32,
    min_length: f32,
    st: &mut crate::fit::Stages,
) -> LengthCheck {
    let dip_of = |(along, across): &(Vec<f64>, Vec<f64>)| along_dip(along, across, length_px as f64, min_length as f64);
    let dip_note = |d: &Dip| {
        format!(
            "; the derivative autocorrelation dips along the flow at {:.1} px ({:.3} against {:.3} across)",
            d.lag_px, d.along, d.across
        )
    };
    let quick = sharp_curves(y, flow, length_px).ok().and_then(|c| dip_of(&c));
    st.lap("search.acf_check");
    if let Some(d) = quick {
        return LengthCheck { dip: Some(d), contradiction: None, shape: None, note: dip_note(&d) };
    }
    let read = acf_read(y, flow);
    st.lap("search.acf_shape");
    let mut check = LengthCheck { dip: None, contradiction: None, shape: None, note: String::new() };
    if let Some(curves) = &read.sharp {
        let dip = dip_of(curves);
        let shape_px = read.shape.as_ref().map_or(0.0, |sh| sh.length_px);
        let shape_note = match &read.shape {
            Ok(sh) => format!("its shape reads {:.1} px", sh.length_px),
            Err(why) => format!("its shape is not read ({why})"),
        };
        check.note = match &dip {
            Some(d) => format!("{}, {shape_note}", dip_note(d)),
            None => format!("; the derivative autocorrelation has no dip along the flow near it, {shape_note}"),
        };
        if dip.is_none() && shape_px < 0.5 * length_px {
            check.contradiction = Some(format!("no dip along the flow near it, and {shape_note}"));
        }
        check.dip = dip;
    }
    check.shape = Some(read.shape);
    check
}

/// The shape's reading; with `curves_only` = Some(lags) only the L = 0 curves to
/// that many lags (into `sharp`), and no shape.
fn read(
    y: &Plane,
    flow: &Flow,
    sharp: &mut Option<(Vec<f64>, Vec<f64>)>,
    curves_only: Option<usize>,
) -> Result<AcfShape, Refusal> {
    let (w, h) = (y.width, y.height);
    if flow.width != w || flow.height != h {
        return Err("flow and frame differ in size".into());
    }
    let (theta, speed, (cw, ch)) = coherent_crop(flow)?;
    let l_max = if curves_only.is_some() { 0 } else { (MAX_LENGTH_PX as f32).min(speed).floor() as usize };
    if l_max < 2 && curves_only.is_none() {
        return Err(Refusal::Other(format!("flow of {speed:.1} px/frame: no streak length to read")));
    }
    // A slow flow's streaks are short: lags to twice the longest candidate (and a
    // texture's scale) hold the streak's signature, and a crop proportioned to them
    // costs a fraction (the FFT is O(N log N) in its area): 6.4 × 4.8 lag windows,
    // 512×384 at the full 80 px.
    let max_lag = curves_only.unwrap_or(2 * l_max + 24).min(MAX_LAG_PX);
    let (cw, ch) = (cw.min(32 * max_lag / 5), ch.min(24 * max_lag / 5));
    let (ux, uy) = axis(theta);
    let (vx, vy) = (-uy, ux);
    // The crop, rows along u, stepping along v, from a whole pixel: a flow along an
    // axis then samples pixels, not their bilinear means (which low-pass the noise
    // along one axis only).
    let (a0, b0) = (-0.5 * (cw - 1) as f32, -0.5 * (ch - 1) as f32);
    let (cx, cy) = (0.5 * (w - 1) as f32, 0.5 * (h - 1) as f32);
    let (ox, oy) = ((cx + a0 * ux + b0 * vx).round(), (cy + a0 * uy + b0 * vy).round());
    let mut crop = vec![0.0f32; cw * ch];
    for (j, row) in crop.chunks_exact_mut(cw).enumerate() {
        let b = j as f32;
        y.sample_line(ox + b * vx, oy + b * vy, ux, uy, row);
    }
    let sigma = immerkaer_sigma(y);
    let noise = NoiseTable::new((ox, oy), (ux, uy), (cw, ch));
    // The candidates reach `PAST_FULL_FRAME_PX` past a full-frame streak (within the
    // lags' `MAX_LENGTH_PX`).
    let l_ext = if curves_only.is_some() { l_max } else { (l_max + PAST_FULL_FRAME_PX).min(MAX_LENGTH_PX) };
    let (au, av) = autocorrelations(&crop, cw, ch, max_lag, l_ext);
    // Per candidate length: the relative residual of the best amplitude.
    let (a_len, b_len) = (cw - 1, ch - 1);
    // The two autocorrelations after a box of `len` across the flow, noise removed.
    let curves = |len: usize| -> ([f64; MAX_LAG_PX + 1], [f64; MAX_LAG_PX + 1]) {
        let k = box_kernel(len as f64);
        let rk = kernel_autocorrelation(&k);
        let c = (rk.len() - 1) / 2;
        let rb = |s: isize| -> f64 {
            let i = s + c as isize;
            if i >= 0 && (i as usize) < rk.len() {
                rk[i as usize]
            } else {
                0.0
            }
        };
        let mut ru = [0.0f64; MAX_LAG_PX + 1];
        let mut rv = [0.0f64; MAX_LAG_PX + 1];
        let dot = |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).map(|(x, y)| x * y).sum() };
        for t in 0..=max_lag {
            // Σ_s r(s)·A_u(t, s) and Σ_s r(s)·A_v(t + s), s = −c…c: contiguous dots.
            let su = dot(&rk, &au.row(t)[MAX_LENGTH_PX - c..=MAX_LENGTH_PX + c]);
            let sv = dot(&rk, &av[t + AV_OFFSET - c..=t + AV_OFFSET + c]);
            // Means over the pairs each lag has (the crop is finite).
            ru[t] = su / (b_len * (a_len - t)) as f64;
            rv[t] = sv / (a_len * (b_len - t)) as f64;
            // White pixel noise's share, through the crop's bilinear sampling (for a
            // flow along an axis: 2s₂σ², −s₂σ² at lag 1 along u, the box's
            // autocorrelation differenced twice along v): non-zero within
            // `NoiseTable::REACH` of lag 0 only.
            let tt = t as isize;
            let reach = NoiseTable::REACH;
            let nu: f64 = (-reach..=reach).map(|s| rb(s) * noise.du(tt, s)).sum();
            let nv: f64 = (-tt - reach..=-tt + reach).map(|s| rb(s) * noise.dv(tt + s)).sum();
            ru[t] -= sigma * sigma * nu;
            rv[t] -= sigma * sigma * nv;
        }
        (ru, rv)
    };
    let residual_at = |len: usize| -> f64 {
        let (ru, rv) = curves(len);
        let uv: f64 = ru.iter().zip(&rv).map(|(a, b)| a * b).sum();
        let vv: f64 = rv.iter().map(|v| v * v).sum();
        let uu: f64 = ru.iter().map(|v| v * v).sum();
        if vv <= 0.0 || uu <= 0.0 || !uv.is_finite() {
            return 1.0;
        }
        let amp = uv / vv;
        ru.iter().zip(&rv).map(|(a, b)| (a - amp * b).powi(2)).sum::<f64>() / uu
    };
    // The frame's own curves are kept before the texture test: a frame with no
    // texture above the noise shows no streak's dip either (the zeros' check).
    let (ru0, rv0) = curves(0);
    *sharp = Some((ru0[..=max_lag].to_vec(), rv0[..=max_lag].to_vec()));
    if curves_only.is_some() {
        return Err("the frame's own curves only".into());
    }
    // Texture above the noise: the across-flow derivative's mean energy (a streak
    // lowers the along-flow one, not this) at least `MIN_ENERGY_OVER_NOISE` × white
    // noise's. Without it every residual is noise's and the shape says nothing.
    let energy_u = au.row(0)[MAX_LENGTH_PX] / (a_len * b_len) as f64;
    let energy_v = av[AV_OFFSET] / (a_len * b_len) as f64;
    let (noise_u, noise_v) = (sigma * sigma * noise.du(0, 0), sigma * sigma * noise.dv(0));
    if energy_v <= MIN_ENERGY_OVER_NOISE * noise_v || !(energy_u > 0.0 && energy_v > 0.0) {
        return Err(Refusal::Other(format!(
            "no texture above the noise in the crop (derivative energy {energy_u:.2e} / {energy_v:.2e} along / \
             across, noise's {noise_u:.2e} / {noise_v:.2e})"
        )));
    }
    let mut residuals: Vec<f64> = (0..=l_max).map(residual_at).collect();
    let argmin = |r: &[f64]| (0..r.len()).min_by(|&a, &b| r[a].total_cmp(&r[b])).unwrap_or(0);
    let mut best = argmin(&residuals);
    // The candidates past the full frame only where the best is the full frame: a
    // minimum inside it is located as before (and the extra lengths cost ~0.3 ms).
    if best == l_max && l_ext > l_max {
        residuals.extend((l_max + 1..=l_ext).map(residual_at));
        best = argmin(&residuals);
    }
    // No streak is a reading only where a short one would fit measurably worse.
    let probe = ZERO_PROBE_PX.min(l_max);
    // (A NaN residual is no rise either.)
    let rises = residuals[probe] >= MIN_ZERO_RISE * residuals[0];
    if best == 0 && !rises {
        return Err(Refusal::Other(format!(
            "the match barely depends on the length (a {probe} px streak fits within {:.1}% of none, under \
             {:.0}%): the shape does not tell a streak from none",
            100.0 * (residuals[probe] / residuals[0].max(f64::MIN_POSITIVE) - 1.0),
            100.0 * (MIN_ZERO_RISE - 1.0)
        )));
    }
    // A minimum at the search's top end is no balance: the match may improve past
    // it (the lags' `MAX_LENGTH_PX`, or a full-frame streak). Measured: a colour
    // wheel with no streak read 50 px (λ 1) at 50 px/frame.
    if best == l_ext && (l_ext as f32) > speed {
        return Err(Refusal::PastFullFrame(format!(
            "the best length, at least {l_ext} px, lies past a full-frame streak ({speed:.1} px/frame)"
        )));
    }
    if best == l_ext {
        return Err(Refusal::Other(format!("the best length lies at the search's end ({l_ext} px)")));
    }
    // Parabola through the best and its neighbours.
    let mut length = best as f64;
    if best > 0 && best < l_ext {
        let (a, b, c) = (residuals[best - 1], residuals[best], residuals[best + 1]);
        let den = a - 2.0 * b + c;
        if den > 0.0 {
            length += (0.5 * (a - c) / den).clamp(-0.5, 0.5);
        }
    }
    let length_px = length as f32;
    if length_px > speed {
        return Err(Refusal::PastFullFrame(format!(
            "the best length, {length_px:.1} px, lies past a full-frame streak ({speed:.1} px/frame)"
        )));
    }
    Ok(AcfShape {
        lambda: (length_px / speed).clamp(0.0, 1.0),
        length_px,
        speed_px: speed,
        residual: residuals[best],
        residual_sharp: residuals[0],
        crop: (cw, ch),
        dip: along_dip(&ru0[..=max_lag], &rv0[..=max_lag], length, MIN_DIP_LENGTH_PX),
    })
}

/// The dip's search window around the shape's length: [L / w, L·w].
const DIP_WINDOW: f64 = 1.4;
/// The shortest shape length whose dip is read. Below it the sharp texture's own
/// autocorrelation is not narrow against L and drags the dip long (the 2R(t) term
/// falls across it): measured on the box-streak tuning and held-out frames, dips
/// read 12 px streaks at 12.3–16.3 px where the shape read 11.0–14.0, and one 16 px
/// streak at 21.7 (shape 16.3); from shape lengths of 20 px every dip read as close
/// as the shape or closer (24 px streaks 24.0–26.1, 31 px 30.8–32.9).
pub(super) const MIN_DIP_LENGTH_PX: f64 = 20.0;
/// The longest streak whose dip the lags can show: its window ends at
/// ⌈`DIP_WINDOW`·L⌉, within the `MAX_LAG_PX` (tested).
pub(super) const MAX_DIP_LENGTH_PX: f32 = 57.0;
/// Shorter lags hold a sharp texture's own negative lobe (a stroke's two edges).
const MIN_DIP_LAG: usize = 4;
/// How far the along-flow autocorrelation (normalised) must dip below the across-flow
/// one at the same lag: the dip is the streak's, not the texture's.
const MIN_DIP_EXCESS: f64 = 0.05;

/// Where a streak's along-flow derivative autocorrelation dips (Yitzhaky & Kopeika
/// 1997). After a box of L along the flow the derivative is (s(x) − s(x − L))/L, so
/// its autocorrelation is (2R(t) − R(t − L) − R(t + L))/L² with R the sharp frame's
/// own: a minimum at t = L wherever R is narrower than L, whatever the texture's
/// anisotropy (which moves the shape's amplitude match, not this lag). Read within
/// [L/`DIP_WINDOW`, L·`DIP_WINDOW`] of the shape's length, as an interior minimum
/// below zero and below the across-flow autocorrelation at the same lag by
/// `MIN_DIP_EXCESS`, for lengths from `min_length` (the shape's refinement:
/// `MIN_DIP_LENGTH_PX`).
pub(super) fn along_dip(ru: &[f64], rv: &[f64], length: f64, min_length: f64) -> Option<Dip> {
    let max_lag = ru.len().min(rv.len()).checked_sub(1)?;
    if !(ru[0] > 0.0 && rv[0] > 0.0 && length >= min_length) {
        return None;
    }
    let lo = ((length / DIP_WINDOW).floor() as usize).max(MIN_DIP_LAG);
    let hi = ((length * DIP_WINDOW).ceil() as usize).min(max_lag);
    if lo + 2 > hi {
        return None;
    }
    let nu = |t: usize| ru[t] / ru[0];
    let nv = |t: usize| rv[t] / rv[0];
    let t = (lo..=hi).min_by(|&a, &b| nu(a).total_cmp(&nu(b)))?;
    // Below zero — a streak's dip is (2R(L) − R(0) − R(2L))/L², negative for any
    // R narrower than L; curves of noise alone, normalised by a lag 0 that the
    // noise's subtraction left near 0, read anything — and below the across-flow
    // curve by the margin (both false for NaN too).
    let below = nu(t) < 0.0 && nv(t) - MIN_DIP_EXCESS - nu(t) > 0.0;
    if t == lo || t == hi || !below {
        return None;
    }
    let (a, b, c) = (nu(t - 1), nu(t), nu(t + 1));
    let den = a - 2.0 * b + c;
    let shift = if den > 0.0 { (0.5 * (a - c) / den).clamp(-0.5, 0.5) } else { 0.0 };
    Some(Dip { lag_px: (t as f64 + shift) as f32, along: nu(t), across: nv(t) })
}

/// The along-flow derivative autocorrelation's dip (normalised to lag 0).
#[derive(Clone, Copy, Debug)]
pub(super) struct Dip {
    pub(super) lag_px: f32,
    pub(super) along: f64,
    pub(super) across: f64,
}

/// (cos θ, sin θ), through f64: LLVM fuses an f32 pair into `sincosf`, which the
/// Quest build's API 29 libm does not export (`cargo xtask apk` fails to link).
fn axis(theta: f32) -> (f32, f32) {
    let (s, c) = (theta as f64).sin_cos();
    (c as f32, s as f32)
}

/// What the flow holds over a set of positions.
struct FlowStats {
    /// Axial mean direction (radians, image axes) and mean resultant length of the
    /// doubled angles (a streak has an axis, not a sign).
    theta: f32,
    coherence: f32,
    /// 10th, 50th and 90th speed percentiles (px/frame).
    speeds: [f32; 3],
}

impl FlowStats {
    /// The flow at the pixels nearest to `positions` (frame coordinates), where it
    /// is finite and at least `MIN_SPEED_PX`.
    fn over(flow: &Flow, positions: impl Iterator<Item = (f32, f32)>) -> Result<Self, String> {
        let (w, h) = (flow.width, flow.height);
        let (mut c2, mut s2) = (0.0f64, 0.0f64);
        let mut speeds = vec![];
        for (x, y) in positions {
            let (xi, yi) = (x.round(), y.round());
            if !(xi >= 0.0 && yi >= 0.0 && (xi as usize) < w && (yi as usize) < h) {
                continue;
            }
            let i = yi as usize * w + xi as usize;
            let (fx, fy) = (flow.dx[i], flow.dy[i]);
            let sp = (fx * fx + fy * fy).sqrt();
            if !sp.is_finite() || sp < MIN_SPEED_PX {
                continue;
            }
            let (c, s) = (fx / sp, fy / sp);
            c2 += (c * c - s * s) as f64;
            s2 += (2.0 * c * s) as f64;
            speeds.push(sp);
        }
        let n = speeds.len();
        if n < 64 {
            return Err(format!("only {n} flow samples ≥ {MIN_SPEED_PX} px/frame"));
        }
        speeds.sort_by(f32::total_cmp);
        Ok(Self {
            theta: 0.5 * (s2.atan2(c2) as f32),
            coherence: ((c2 * c2 + s2 * s2).sqrt() / n as f64) as f32,
            speeds: [speeds[n / 10], speeds[n / 2], speeds[(9 * n) / 10]],
        })
    }

    /// The median speed where the flow holds one streak length, else why not.
    fn one_length(&self) -> Result<f32, String> {
        if self.coherence < MIN_AXIAL_COHERENCE {
            return Err(format!(
                "the flow's direction varies (axial coherence {:.2} < {MIN_AXIAL_COHERENCE})",
                self.coherence
            ));
        }
        let [p10, med, p90] = self.speeds;
        if p90 > MAX_SPEED_SPREAD * med || p10 * MAX_SPEED_SPREAD < med {
            return Err(format!("the flow's speed varies ({p10:.1}–{p90:.1} px/frame around {med:.1})"));
        }
        Ok(med)
    }
}

/// Crop scales tried, largest first: a flow that turns or speeds up toward the
/// frame's edges (a wide-angle head turn: ~2× the centre's speed at a 90° field of
/// view's corners) may hold one length over the centre.
const CROP_SCALES: [f32; 3] = [1.0, 0.75, 0.5];

/// The flow's direction and median speed over the largest centred crop (along ×
/// across it, px) that holds one streak length, or why none does.
/// The median flow speed over the crop the shape would read (px/frame), or why the
/// shape is not read there: a cheap first look (the flow alone) before the FFT.
pub(super) fn crop_speed(flow: &Flow) -> Result<f32, String> {
    coherent_crop(flow).map(|(_, speed, _)| speed)
}

fn coherent_crop(flow: &Flow) -> Result<(f32, f32, (usize, usize)), String> {
    let (w, h) = (flow.width, flow.height);
    let step = ((w * h) as f64 / 4096.0).sqrt().max(1.0) as usize;
    let grid = (step / 2..h).step_by(step).flat_map(|y| (step / 2..w).step_by(step).map(move |x| (x as f32, y as f32)));
    // The whole frame's direction orients the first crop.
    let mut theta = FlowStats::over(flow, grid)?.theta;
    let (cx, cy) = (0.5 * (w - 1) as f32, 0.5 * (h - 1) as f32);
    // 32 × 24 positions over a crop's footprint.
    let footprint = |theta: f32, (cw, ch): (usize, usize)| {
        let (ux, uy) = axis(theta);
        (0..24).flat_map(move |j| {
            (0..32).map(move |i| {
                let a = (i as f32 / 31.0 - 0.5) * cw as f32;
                let b = (j as f32 / 23.0 - 0.5) * ch as f32;
                (cx + a * ux - b * uy, cy + a * uy + b * ux)
            })
        })
    };
    let mut why = String::new();
    for scale in CROP_SCALES {
        let size = |theta: f32| {
            let (c, s) = axis(theta);
            let (cw, ch) = crop_size(w, h, c.abs(), s.abs());
            ((cw as f32 * scale) as usize, (ch as f32 * scale) as usize)
        };
        let mut dims = size(theta);
        if dims.0 < MIN_CROP_PX || dims.1 < MIN_CROP_PX {
            if why.is_empty() {
                why =
                    format!("the frame holds only a {}×{} px crop along the flow (need {MIN_CROP_PX})", dims.0, dims.1);
            }
            break;
        }
        let mut stats = FlowStats::over(flow, footprint(theta, dims))?;
        // Orient the crop along its own flow (once: the footprint barely moves).
        let turn = (stats.theta - theta).sin().abs();
        if turn > 2f32.to_radians().sin() {
            theta = stats.theta;
            dims = size(theta);
            stats = FlowStats::over(flow, footprint(theta, dims))?;
        }
        match stats.one_length() {
            Ok(speed) => return Ok((theta, speed, dims)),
            Err(e) => why = format!("{e} over a {}×{} px crop", dims.0, dims.1),
        }
    }
    Err(why)
}

/// The largest crop (along × across the flow, px) centred in a `w`×`h` frame whose
/// corners stay a pixel inside it (bilinear taps), for |cos θ| = `c`, |sin θ| = `s`:
/// the best of the frame's aspect both ways and a square, then capped at `MAX_CROP`.
fn crop_size(w: usize, h: usize, c: f32, s: f32) -> (usize, usize) {
    let (hw, hh) = (0.5 * w as f32 - 2.0, 0.5 * h as f32 - 2.0);
    let mut best = (0usize, 0usize);
    for aspect in [w as f32 / h as f32, h as f32 / w as f32, 1.0] {
        // Half-extents along x and y of a crop `aspect·q` × `q`.
        let q = (hw / (0.5 * (c * aspect + s))).min(hh / (0.5 * (s * aspect + c)));
        let (cw, ch) = ((aspect * q).floor().max(0.0) as usize, q.floor().max(0.0) as usize);
        let (cw, ch) = (cw.min(MAX_CROP.0), ch.min(MAX_CROP.1));
        if cw * ch > best.0 * best.1 {
            best = (cw, ch);
        }
    }
    best
}

#[cfg(test)]
mod tests;
