//! White-noise tables of the noise fits, measured once.
//!
//! Generated: `UPDATE_TABLES=1 cargo test --lib measured_tables`. Do not edit.

/// `measure_white_noise_median_to_mean`: median / mean of white noise's local band variances.
#[rustfmt::skip]
pub(crate) static WHITE_NOISE_MEDIAN_TO_MEAN: [f32; crate::model::NOISE_LEVELS] = [0.98979825, 0.9715189, 0.9004941, 0.6745308];

/// `blind::measure_bicubic_noise_transmission`: band variance kept by a bicubic sub-pixel shift.
#[rustfmt::skip]
pub(crate) static BICUBIC_NOISE_TRANSMISSION: [f32; crate::model::NOISE_LEVELS] = [0.6265805, 0.97120386, 0.99252176, 1.0005237];
