//! Isotropy's root at an end of [0, 1] where the texture put it, not a balance:
//! the blind exposure's refusals there (`fit_fast`). Each returns the first part of
//! the reason (the caller adds the streak zeros' note) where the frame is not
//! identifiable, else `None`.

use super::acf_shape::{AcfShape, Refusal};

/// A shape length within this of the flow's speed reads a full-frame streak: half
/// the shape's 1 px grid of candidate lengths.
const FULL_FRAME_MARGIN_PX: f32 = 0.5;

/// The root at 0 because the texture itself carries more gradient energy along the
/// flow (a streak can only lower it): an isotropic scene without blur and an
/// anisotropic one with blur look alike here. Also where even the prior's most
/// along-heavy texture (C/D = 1 + `TEXTURE_ANISOTROPY_90`) puts the root at 0
/// (`band` [0, 0]): the frame's along excess lies beyond the prior, so the prior's
/// band says nothing about λ.
pub(super) fn root_at_zero(
    lambda: f32,
    along_excess: f64,
    along_excess_se: f64,
    band: Option<[f32; 2]>,
) -> Option<String> {
    let beyond_prior = band.is_some_and(|b| b[1] == 0.0);
    (lambda == 0.0 && ((along_excess > 0.02 && along_excess > 3.0 * along_excess_se) || beyond_prior)).then(|| {
        format!(
            "the frame has {:.1}% (± {:.1}%) more gradient energy along the flow than across before any streak — \
             anisotropic texture, so gradient-energy isotropy cannot separate it from motion blur",
            100.0 * along_excess,
            100.0 * along_excess_se
        )
    })
}

/// The other end: the root is not bracketed below a full-frame exposure and the
/// frame still holds clearly less gradient energy along the flow than across after
/// a full-frame streak is undone — its texture is smoother along the flow than any
/// exposure explains, and λ = 1 is the search's end, not a balance (the prior's
/// band, cut at 1, then looked narrow). Measured: texture smoothed σ 3 px along the
/// flow and 1.2 px across read λ 1.000 ± 0.036 *present* for truths 0, 0.2 and 0.5
/// (8 px/frame, σ 1.5 px defocus, noise).
pub(super) fn root_at_one(lambda: f32, top_excess: f64, top_excess_se: f64) -> Option<String> {
    (lambda >= 1.0 && top_excess < -0.02 && top_excess < -3.0 * top_excess_se).then(|| {
        format!(
            "even a full-frame streak leaves the frame {:.1}% (± {:.1}%) short of gradient energy along the flow — \
             texture smoother along the flow than across, so gradient-energy isotropy cannot separate it from \
             motion blur",
            -100.0 * top_excess,
            100.0 * top_excess_se
        )
    })
}

/// Isotropy's root not bracketed below a full-frame exposure (the λ = 1 it reads is
/// the search's end, within `root_at_one`'s error), and the autocorrelation shape's
/// best length at a full-frame streak or past it: both searches end at λ = 1. A
/// texture smoother along the flow than across, by as much as a full-frame streak
/// makes, reads the same, and one frame cannot tell the two. Returns what the shape
/// read. Measured: an oriented texture (σ 3 / 1.2 px) 0–20° off its smooth axis
/// at 8 px/frame reads λ 1.000 ± 0.05–0.13 *present* without this refusal on 5 of
/// its 36 frames (truths 0 and 0.5), all refused with it; the price, an isotropic
/// texture at λ 1 whose zeros heavy defocus (σ 2–2.5 px) fills: 3 of its 72 frames,
/// which read 1.000 ± 0.06–0.07, are refused too (docs/blind-motion-blur.md "λ = 1 where both
/// searches end"). With isotropy's root inside [0, 1] a shape refused past the full
/// frame leaves isotropy's answer, as every refusal of the shape does.
pub(super) fn both_at_full_frame(lambda: f32, shape: &Result<AcfShape, Refusal>) -> Option<String> {
    if lambda < 1.0 {
        return None;
    }
    match shape {
        Ok(sh) => (sh.length_px >= sh.speed_px - FULL_FRAME_MARGIN_PX).then(|| {
            format!("its best length, {:.1} px, is a full-frame streak's ({:.1} px/frame)", sh.length_px, sh.speed_px)
        }),
        Err(Refusal::PastFullFrame(why)) => Some(why.clone()),
        Err(Refusal::Other(_)) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(length_px: f32, speed_px: f32) -> AcfShape {
        AcfShape {
            lambda: (length_px / speed_px).min(1.0),
            length_px,
            speed_px,
            residual: 0.01,
            residual_sharp: 0.5,
            crop: (256, 192),
            dip: None,
        }
    }

    /// The refusal's kind decides, not its words: the same words as any other
    /// refusal leave isotropy's answer; a located length within half a pixel of the
    /// full frame refuses, one below it does not; and below λ = 1 nothing refuses.
    #[test]
    fn both_at_full_frame_branches_on_the_refusal_kind() {
        let words = "the best length, 8.2 px, lies past a full-frame streak (8.0 px/frame)".to_string();
        let past = Err(Refusal::PastFullFrame(words.clone()));
        assert_eq!(both_at_full_frame(1.0, &past), Some(words.clone()));
        assert_eq!(both_at_full_frame(0.99, &past), None);
        assert_eq!(both_at_full_frame(1.0, &Err(Refusal::Other(words))), None);
        assert!(both_at_full_frame(1.0, &Ok(shape(7.6, 8.0))).is_some());
        assert_eq!(both_at_full_frame(1.0, &Ok(shape(7.4, 8.0))), None);
        assert_eq!(both_at_full_frame(0.9, &Ok(shape(8.0, 8.0))), None);
    }
}
