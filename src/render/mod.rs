//! Effect passes on the GPU, one file per pass, each the twin of a `synth` function
//! and held to it by a lavapipe test (tests/gpu_effects.rs). Depends on `gpu` and
//! `model` only: inputs are plain planar slices, not `image` types.

pub mod dof;
pub mod gbuffer;
pub mod grain;
pub mod layer;
pub mod motion_blur;
pub mod params;
pub mod sharpen;
pub mod spacewarp;
pub mod stereo;

pub use dof::DofPass;
pub use gbuffer::{Eye, GBufferFrame, GBufferPass};
pub use grain::{planar_rgb, GrainPass, GrainRecorder, GrainTable, GRAIN_TEXEL_FLOATS};
pub use layer::{FrameEffects, LayerEffects, LayerSettings};
pub use motion_blur::MotionBlurPass;
pub use params::EffectParams;
pub use spacewarp::{SpaceWarpPass, SpaceWarpTarget};
pub use stereo::{Enabled, ExternalTarget, FrameInput, StereoRenderer};

/// SPIR-V of the uniform-block probe used by the hot-swap test.
pub const PARAMS_PROBE_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/params_probe.spv"));
