//! The blind (fast) tier's exposure: the frame and its flow only — the streak's
//! spectral zeros where they are identified, else gradient-energy isotropy with its
//! bias risk, refined by the derivative autocorrelation's shape (`fit_fast`).

use super::isotropy::{fast_samples, isotropy_root, IsotropyRoot};
use super::status::MAX_ISOTROPY_HALF_BAND;
use super::{acf_shape, decide, ends, exposure_status_note, isotropy, visible_speed_px, MbPlotData, MIN_SAMPLES};
use crate::image::Flow;
use crate::model::MotionBlur;
use std::time::Instant;

/// Fast tier: frame and flow only. The first of two estimators that can answer wins;
/// the second is then refined by a third:
///
/// 1. **Streak zeros** (`streak_spectrum`): the box streak's spectral zeros along the
///    flow, read against the across-flow spectrum. Neither texture anisotropy nor
///    defocus moves them, so where they are identified (correlation ≥
///    `streak_spectrum::MIN_SCORE`, interleaved subsets agreeing within 10%) λ is
///    theirs. Streaks under ~3 px (first zero past Nyquist), heavy defocus or noise
///    that fills the zeros leave them unidentified. From `CONFIRM_MIN_LENGTH_PX`
///    they must also be supported by the derivative autocorrelation (a dip along
///    the flow near the length, or a shape above half of it): noise on flat
///    content had its zeros read as 19–21 px streaks that were not there. Their
///    standard error carries the template's model error (`ZEROS_MODEL_ERROR`: the
///    zeros read ~2% short on most scenes) in quadrature with their spread.
/// 2. **Gradient-energy isotropy** otherwise. Assume the sharp scene is
///    statistically isotropic around the sampled pixels. A box streak of length
///    L* = λ*|F| along u = F/|F| leaves the frame I. Blur I once more, by a box of
///    length L along the perpendicular v, and compare the directional gradient
///    energies C(L) = E[(∂_u B_v(L) I)²] and D(L) = E[(∂_v B_v(L) I)²]. By isotropy
///    they are equal exactly when both axes carry the same box, i.e. at L = L*, at
///    every scale. λ is the root of C − D on [0, 1] (bracketed on a λ grid, refined by
///    regula falsi), with L = λ|F| per
///    pixel. Anisotropic texture biases it (measured: a text page −48%, and an
///    isotropic defocus that weakens the streak's signal lets a 14% texture
///    anisotropy drive λ to 0 — BENCHMARKS.md). The **bias risk** enters the
///    standard error twice over, the larger counting: (a) the root is taken at two
///    scales over the same pixels (±1 px on the frame and ±1 px on its
///    half-resolution reduction); an isotropic scene gives both the same root, an
///    anisotropic one biases them by different amounts; (b) a prior on natural
///    scenes' anisotropy (`TEXTURE_ANISOTROPY_90`, measured): the roots of C/D =
///    1 ∓ that bound a ~90% band for λ, wide where the streak changes the balance
///    little (short streaks, defocus, noise) — wider than half of [0, 1] is *not
///    identifiable* unless the shape's dip answers (3.). Where the frame's
///    diagonals show more anisotropy than the prior allows (a texture oriented at
///    an angle to the flow; a streak along the flow leaves them balanced), the band
///    reaches what they prove (`isotropy::anisotropy_ratios`). The bias
///    term is added in quadrature to the spread of the root over `FAST_SUBSETS`
///    interleaved subsets / √subsets.
/// 3. **The derivative autocorrelation's shape** (`acf_shape`), where isotropy
///    answers and the flow holds one streak length (direction within ~±10°, speed
///    within ±25%) over a centred crop of the frame: the same box across the flow,
///    but the whole autocorrelation of the derivative along u matched to the one
///    along v (lags 0–80 px, one free amplitude, white noise's share subtracted),
///    not their lag-0 values. Its λ is
///    reported; half its difference from the isotropy root enters the standard error
///    in quadrature with isotropy's. Measured on the frames this path answers
///    (box streaks at 640×480, 50 px/frame, BENCHMARKS.md): median error 10% / 7%
///    where isotropy alone had 36% / 22% (probe / held-out sets); the real text page
///    25.8 px for 31 (isotropy: 16.8). From a shape length of 20 px the along-flow
///    curve's dip near it (`acf_shape::along_dip`) is reported instead, its error
///    half its difference from the shape's: medians 2.3% / 3.7%, the text page 31.0.
///
/// Every isotropy answer (and with `evidence_always` a zeros answer too) returns
/// the frame's along/across balance per flow direction (`MbPlotData::isotropy`):
/// the worker pools it over the directions a head turns in, where the texture's
/// anisotropy and the streak separate (`fit::pooled_exposure`).
/// The shortest streak the zeros read that the derivative autocorrelations check
/// (`fit_fast`): below it the dip's window, [L/1.4, 1.4·L], reaches the sharp
/// texture's own negative lobe at a few px.
const CONFIRM_MIN_LENGTH_PX: f32 = 10.0;
/// The streak zeros' model error, relative to λ (one standard error), joined in
/// quadrature to their sampling and noise-floor spread. The template is sinc² over
/// a flat noise floor; the measured spectra are Hann-windowed (the window's main
/// lobe carries a falling scene spectrum's power into the zero: the zero reads at a
/// higher frequency, the streak shorter) and their floor is not the template's (a
/// streak along the flow also lowers the across-flow power it is set against, so the
/// template's floor sits too high and places the zero late). Measured on 111 zeros
/// answers (70 box streaks of 6–31 px at 50 px/frame on photographs; 20 of 6–16 px
/// on an isotropic texture under defocus and noise; 21 of 8 px on four
/// photographs): relative error median −1.7%, |error| 68th percentile 2.5%, 90th
/// 6.2%; on a noise-free synthetic line field with an exact box ±0.05 px, so the
/// error is the scene's and the noise's, not the estimator's arithmetic. Without it the zeros claimed ± 0.003–0.02 where they
/// missed by 2–4%: on the isotropic texture 16 of 20 answers held the truth outside
/// two standard errors.
const ZEROS_MODEL_ERROR: f64 = 0.025;

/// `effort` (`FitOptions::fast_effort`, in [`MIN_FAST_EFFORT`](crate::fit::MIN_FAST_EFFORT), 1]) scales the
/// isotropy's pixels and the streak's lines (BENCHMARKS.md: what each effort costs
/// in accuracy).
pub fn fit_fast(
    luma: &crate::fit::SharedLuma,
    flow: &Flow,
    evidence_always: bool,
    effort: f32,
) -> (MotionBlur, Option<MbPlotData>) {
    let started = Instant::now();
    let y = luma.full();
    let mut st = crate::fit::Stages::start();
    let samples = fast_samples(effort);
    let speed = visible_speed_px(flow);
    let centres = crate::fit::streak_spectrum::target_centres(effort);
    let streak = crate::fit::streak_spectrum::streak_signature_with(y, flow, |_, _| true, centres);
    st.lap("search.spectrum");
    // The autocorrelations, where read for the zeros' check below, serve the
    // fallback too (one FFT per frame).
    let mut shape_read: Option<Result<acf_shape::AcfShape, acf_shape::Refusal>> = None;
    let mut contradiction: Option<String> = None;
    let mut check_note = String::new();
    // The dip's lag and the flow's speed where the check read one (for the error).
    let mut check_dip: Option<(f32, f32)> = None;
    if let Some(sig) = streak.as_ref().filter(|s| s.identified) {
        let lambda = sig.lambda.clamp(0.0, 1.0);
        // A streak of L ≥ `CONFIRM_MIN_LENGTH_PX` leaves the along-flow derivative
        // autocorrelation a dip at lag L (`acf_shape::along_dip`) and the shape a
        // length near L. Where neither shows (no dip near L *and* the shape under
        // half of it), the zeros are noise's, not a streak's — measured: the two
        // wrong identifications of the held-out set (flat content under 2 DN of
        // noise, no streak: the moon's sky 19.2 px, a colour wheel on black 21.5 px)
        // have no dip and a shape of 0 px, while of the 102 right identifications from
        // 10 px on both sets 97 show a dip and 4 a shape within 25% (one has neither:
        // a colour wheel's 24 px streak read 20.8 px, which this check leaves not
        // identifiable).
        if let Ok(speed) = acf_shape::crop_speed(flow) {
            let len = lambda * speed;
            // Past `acf_shape::MAX_DIP_LENGTH_PX` no dip can show within the lags (and
            // the shape's candidates end at 60 px): such zeros go unchecked. (Synth's
            // 57–90 px streaks on two photographs were not identified by the zeros.)
            if (CONFIRM_MIN_LENGTH_PX..=acf_shape::MAX_DIP_LENGTH_PX).contains(&len) {
                let check = acf_shape::check_length(y, flow, len, CONFIRM_MIN_LENGTH_PX, &mut st);
                check_note = check.note;
                check_dip = check.dip.map(|d| (d.lag_px, speed));
                contradiction = check.contradiction.map(|why| {
                    format!(
                        "identified at {len:.1} px (correlation {:.2}) but contradicted by the derivative \
                         autocorrelation: {why}",
                        sig.score
                    )
                });
                shape_read = check.shape;
            }
        }
    }
    if let Some(sig) = streak.as_ref().filter(|s| s.identified && contradiction.is_none()) {
        let lambda = sig.lambda.clamp(0.0, 1.0);
        // Long streaks read short by their zeros (31 px box streaks: 27.7–30.7 px, 24
        // px: 21.2–23.5, at a stated ± 0.13–1.7 px — the truth outside two standard
        // errors on most; docs/blind-motion-blur.md "The zeros' error at long streaks"), where the
        // dip read 30.8–31.9 / 23.9–24.4: from `acf_shape::MIN_DIP_LENGTH_PX` half
        // the two lengths' difference joins the zeros' standard error.
        let (stderr, widened) = match check_dip {
            Some((dip_px, speed)) if lambda * speed >= acf_shape::MIN_DIP_LENGTH_PX as f32 => (
                (sig.stderr as f64).hypot(0.5 * ((dip_px / speed) - lambda).abs() as f64),
                format!(" (the zeros alone ± {:.4}, half their difference from the dip's in quadrature)", sig.stderr),
            ),
            _ => (sig.stderr as f64, String::new()),
        };
        let model = ZEROS_MODEL_ERROR * lambda as f64;
        let stderr = stderr.hypot(model);
        let mut mb = decide("fast", lambda, stderr, None, sig.lines, speed, started);
        mb.diagnostics.reason = format!(
            "λ = {lambda:.4} ± {stderr:.4}{widened} (the template's model error ± {model:.4} in quadrature) from \
             the streak's spectral zeros along the flow ({} lines, \
             correlation {:.2}, \
             next best {:.2}, first side lobe e^{:.2} × the noise floor, along-flow dip {:.2} (ln) at the zero, \
             {:.0}% of the ratio's dip across-flow texture{check_note}); {}",
            sig.lines,
            sig.score,
            sig.runner_up,
            sig.side_lobe,
            sig.along_dip,
            100.0 * sig.across_share.max(0.0),
            exposure_status_note(mb.diagnostics.status, speed)
        );
        // The pooled fit's evidence where asked (`FitOptions::mb_isotropy_evidence`).
        let plot = evidence_always.then(|| {
            let isotropy = isotropy_root(y, flow, 1, true, None, samples).ok().and_then(|r| r.evidence);
            st.lap("search.isotropy");
            MbPlotData { isotropy, ..Default::default() }
        });
        mb.diagnostics.stages_s = st.done();
        return (mb, plot);
    }
    let fine = isotropy_root(y, flow, 1, true, None, samples);
    st.lap("search.isotropy");
    let IsotropyRoot {
        lambda,
        spread,
        n,
        along_excess,
        along_excess_se,
        top_excess,
        top_excess_se,
        oblique_contrast,
        oblique_contrast_se,
        band,
        evidence,
        pixels,
    } = match fine {
        Ok(root) => root,
        Err(n) => {
            let reason = format!(
                "only {n} textured pixels with flow ≥ 3 px/frame and within the frame's diagonal (need {MIN_SAMPLES}), and no streak zeros along the \
             flow: exposure not identifiable blindly"
            );
            let mut d = crate::fit::not_identifiable("fast", reason, started);
            d.samples_used = n as u64;
            d.stages_s = st.done();
            return (MotionBlur::absent(d), None);
        }
    };
    // Every answer of the isotropy path carries the frame's evidence for pooling:
    // the frames this path cannot answer alone are the ones pooling is for.
    let plot = Some(MbPlotData { isotropy: evidence, ..Default::default() });
    let streak_note = match &streak {
        Some(_) if contradiction.is_some() => contradiction.clone().unwrap_or_default(),
        Some(s) if !s.inside => format!(
            "not identified (the best template, λ {:.3}, lies outside [{:.3}, 1]: a fall-off, not a zero in the band)",
            s.lambda, s.lambda_min
        ),
        Some(s) => format!(
            "not identified (correlation {:.2}, λ {:.3} ± {:.3}, side lobe e^{:.2}, along-flow dip {:.2}, across \
             share {:.2})",
            s.score, s.lambda, s.stderr, s.side_lobe, s.along_dip, s.across_share
        ),
        None => "not measurable (no line along the flow fits the frame)".into(),
    };
    // Isotropy's root at an end of [0, 1] where the texture, not a balance, put it
    // (`ends`): not identifiable.
    let at_end = ends::root_at_zero(lambda, along_excess, along_excess_se, band)
        .or_else(|| ends::root_at_one(lambda, top_excess, top_excess_se));
    if let Some(why) = at_end {
        let reason = format!("{why}; streak zeros {streak_note}: exposure not identifiable blindly");
        let mut d = crate::fit::not_identifiable("fast", reason, started);
        d.samples_used = n as u64;
        d.stages_s = st.done();
        return (MotionBlur::absent(d), plot);
    }
    let band = band.unwrap_or([lambda; 2]);
    let half_band = 0.5 * (band[1] - band[0]) as f64;
    let prior = isotropy::band_note(oblique_contrast, oblique_contrast_se, band);
    // Isotropy's band wider than half of [0, 1]: isotropy cannot answer, nor can
    // the autocorrelation shape it gauges — except through the shape's dip along
    // the flow, the reading a texture's anisotropy moves least (`acf_shape::along_dip`,
    // from `acf_shape::MIN_DIP_LENGTH_PX`), whose error then carries the wide band
    // as well (below). Measured (box streaks at 640×480, 50 px/frame): a text
    // photograph's 24 px streak 30° off the flow read 24.0 ± 8.7 px by its dip where
    // the diagonals' anisotropy had widened the band past half of [0, 1].
    if half_band > MAX_ISOTROPY_HALF_BAND {
        let shape = shape_read.take().unwrap_or_else(|| acf_shape::acf_read(y, flow).shape);
        st.lap("search.acf_shape");
        if !matches!(&shape, Ok(sh) if sh.dip.is_some()) {
            let reason = format!(
                "gradient-energy isotropy reads λ = {lambda:.4} from {n} pixels, but {prior}: the streak changes the \
                 along/across balance less than the scene's own texture may, and the derivative autocorrelation \
                 shows no dip along the flow, so exposure is not identifiable blindly here; streak zeros {streak_note}"
            );
            let mut d = crate::fit::not_identifiable("fast", reason, started);
            d.samples_used = n as u64;
            d.stderr = Some(half_band / 1.645);
            d.stages_s = st.done();
            return (MotionBlur::absent(d), plot);
        }
        shape_read = Some(shape);
    }
    // The second scale only where its answer is used (the bias risk of a root).
    // Over the fine root's own pixels: the disagreement then compares one set of
    // pixels at two scales, without a second sampling's scatter (and without a
    // second candidate scan).
    let coarse = isotropy_root(luma.half(), flow, 2, false, Some(&pixels), samples);
    st.lap("search.isotropy_coarse");
    let bias = coarse.ok().map_or(0.0, |c| (c.lambda as f64 - lambda as f64).abs());
    // The two-scale disagreement and the prior band (a 90% band: half-width / 1.645
    // is its σ) both gauge the texture's bias: the larger counts, in quadrature
    // with the sampling spread.
    let iso_stderr = (spread * spread + bias.max(half_band / 1.645).powi(2)).sqrt();
    let iso_detail = format!(
        "from {n} pixels (subset spread {spread:.4}, two-scale disagreement {bias:.4}; {prior}: the bias risk of \
         anisotropic texture)"
    );
    // The autocorrelations' shape: on the 51 + 73 probe and held-out frames this path
    // answers, median error 10% / 6% against isotropy's 36% / 22% (BENCHMARKS.md). It
    // has biases of its own (smooth shading read as no streak, a text page's line
    // pitch), so the two readings' difference enters the standard error: half of it,
    // in quadrature with isotropy's bias risk.
    let shape = shape_read.unwrap_or_else(|| acf_shape::acf_read(y, flow).shape);
    st.lap("search.acf_shape");
    // Both searches end at λ = 1 (`ends::both_at_full_frame`): not identifiable.
    if let Some(why) = ends::both_at_full_frame(lambda, &shape) {
        let reason = format!(
            "gradient-energy isotropy's root is not bracketed below a full-frame exposure ({iso_detail}), and the \
             derivative autocorrelation's shape ends there too ({why}): λ = 1 is where both searches end, not a \
             balance — a texture smoother along the flow than across by as much as a full-frame streak makes reads \
             the same, and one frame cannot tell them apart; streak zeros {streak_note}: exposure not identifiable \
             blindly"
        );
        let mut d = crate::fit::not_identifiable("fast", reason, started);
        d.samples_used = n as u64;
        d.stderr = Some(iso_stderr);
        d.stages_s = st.done();
        return (MotionBlur::absent(d), plot);
    }
    let (lambda, stderr, how) = match shape {
        Ok(sh) => {
            // The dip, where read, is the reading a texture's anisotropy moves least
            // (`acf_shape::along_dip`): its bias gauge is its difference from the
            // shape's length (the same autocorrelations read two ways), not from
            // isotropy's (which that anisotropy moves most: the real text page's
            // isotropy read 16.8 px for 31, its shape 25.8, its dip 31.0).
            let (got, other, dip) = match sh.dip {
                Some(d) => (
                    (d.lag_px / sh.speed_px).clamp(0.0, 1.0),
                    sh.lambda,
                    format!(
                        " and its dip along the flow at {:.1} px ({:.3} against {:.3} across)",
                        d.lag_px, d.along, d.across
                    ),
                ),
                None => (sh.lambda, lambda, String::new()),
            };
            let stderr = iso_stderr.hypot(0.5 * (got - other) as f64);
            let gauge = if sh.dip.is_some() {
                "half the dip's difference from the shape's length is in the error"
            } else {
                "half the two readings' difference is in the error"
            };
            let how = format!(
                "λ = {got:.4} ± {stderr:.4} from the shape of the derivative autocorrelation along the flow against \
                 across it{dip} (streak {:.1} px by the shape at {:.1} px/frame over a {}×{} px crop, residual {:.3} \
                 against {:.3} sharp); gradient-energy isotropy reads λ = {lambda:.4} ± {iso_stderr:.4} \
                 {iso_detail}; {gauge}",
                sh.length_px, sh.speed_px, sh.crop.0, sh.crop.1, sh.residual, sh.residual_sharp
            );
            (got, stderr, how)
        }
        Err(why) => (
            lambda,
            iso_stderr,
            format!(
                "λ = {lambda:.4} ± {iso_stderr:.4} by gradient-energy isotropy {iso_detail}; autocorrelation shape \
                 not read: {why}"
            ),
        ),
    };
    let mut mb = decide("fast", lambda, stderr, None, n, speed, started);
    mb.diagnostics.reason =
        format!("{how}; streak zeros {streak_note}; {}", exposure_status_note(mb.diagnostics.status, speed));
    mb.diagnostics.stages_s = st.done();
    (mb, plot)
}
