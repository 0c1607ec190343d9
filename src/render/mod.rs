//! Effect passes on the GPU, one file per pass, each the twin of a `synth` function
//! and held to it by a lavapipe test (tests/gpu_effects.rs). Depends on `gpu` and
//! `model` only: inputs are plain planar slices, not `image` types.

pub mod dof;
pub mod grain;
pub mod motion_blur;

pub use dof::DofPass;
pub use grain::{GrainPass, GrainTable};
pub use motion_blur::MotionBlurPass;
