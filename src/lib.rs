//! blind-augment: blind estimation of a camera's noise, motion blur and depth of
//! field (Prakash et al., "Blind Augmentation", TVCG 2025) and their CPU reference
//! synthesis. See ARCHITECTURE.md for the module map and invariants.
// The CPU core has no `unsafe`; only `gpu` and `xr` opt out, per module.
#![deny(unsafe_code)]
// Numeric kernels index several parallel arrays (channels, levels, samples) with one
// index; iterator zips of four slices read worse than the index they replace.
#![allow(clippy::needless_range_loop)]

pub mod analysis;
pub mod fit;
pub mod gpu;
pub mod image;
pub mod io;
pub mod model;
pub mod panel;
pub mod plots;
pub mod render;
pub mod scene;
pub mod synth;
pub mod worker;
pub mod xr;

/// Process-wide allocator setup (binaries and benchmarks call it first).
#[path = "platform/alloc.rs"]
pub mod alloc;
/// The Quest app's entry point (the cdylib `cargo xtask apk` packages).
#[cfg(target_os = "android")]
#[path = "platform/android.rs"]
mod android;
/// The passthrough camera (Camera2 NDK + AImageReader) the app's worker is fed from.
#[cfg(target_os = "android")]
#[path = "platform/android_camera.rs"]
mod android_camera;
// Links the pure-Rust unwinder's _Unwind_* (no NDK libunwind; see Cargo.toml).
#[cfg(target_os = "android")]
extern crate unwinding;
