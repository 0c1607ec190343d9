//! Analysis providers: what the calibration worker needs besides the frames. So far
//! the headset-native parts that run without a device: camera timing on the
//! headset's clock and head poses at any time (timing.rs), and the headset's
//! depth reprojected into the passthrough camera (reproject.rs). The tract-onnx
//! and classical providers come with live calibration.

pub mod reproject;
pub mod timing;
