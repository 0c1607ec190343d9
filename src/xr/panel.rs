//! The status panel as a quad composition layer (OpenXR 1.0, "Quad Layer":
//! XrCompositionLayerQuad): a head-locked card below the line of sight, in the VIEW
//! reference space, showing `panel::draw`'s CPU drawing of the calibration's status.
//! Redrawn at most twice a second (`REDRAW`), and only while shown; each drawing is
//! copied into its own swapchain by `gpu::ImageUpload` with a fence the frame loop
//! never waits on (a copy still executing postpones the next redraw by a frame).
//!
//! Teardown: the upload (waits for a copy in flight) before the swapchain, both
//! before the VIEW space and the session (fields in that order).
#![allow(unsafe_code)]

use super::scenes::SceneCycle;
use super::{call, Toggles, XrError};
use crate::gpu::{GpuContext, ImageUpload};
use crate::panel::PANEL_SIZE;
use ash::vk;
use ash::vk::Handle as _;
use openxr as xr;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The "≤ 2 Hz": text that changes faster cannot be read anyway, and each
/// redraw costs a CPU drawing (≈ 1–3 ms) on the frame loop's thread.
const REDRAW: Duration = Duration::from_millis(500);
/// Where the card sits in VIEW space: 0.9 m ahead, 0.15 m below the eyes (about
/// 9.5° down: read with a glance, clear of the object ahead at eye height), 0.5 m
/// wide (the texture's 2:1 aspect).
const POSITION_M: [f32; 3] = [0.0, -0.15, -0.9];
const WIDTH_M: f32 = 0.5;

/// The panel's lines for this frame: the scene and the effect switches, the app's
/// lines (camera, calibration, recording), the snapshot's model (`age_s` since
/// its generation was first seen), the newest scene errors (a file that failed
/// to load is named, then skipped).
pub(super) fn frame_lines(
    cycle: &SceneCycle,
    toggles: Toggles,
    status: Option<&dyn Fn() -> Vec<String>>,
    snapshot: &crate::worker::Snapshot,
    age_s: Option<f64>,
) -> Vec<String> {
    let mut lines = vec![
        format!(
            "blind-augment · scene {}: {}",
            cycle.current(),
            cycle.current_name().unwrap_or_else(|| "the bundled one".into())
        ),
        effects_line(toggles),
    ];
    if let Some(status) = status {
        lines.extend(status());
    }
    lines.extend(crate::panel::model_lines(&snapshot.model, snapshot.generation, age_s));
    let errors = &cycle.errors;
    lines.extend(errors[errors.len().saturating_sub(2)..].iter().map(|e| format!("!{e}")));
    lines
}

/// What A, B, X and Y switch now.
fn effects_line(t: Toggles) -> String {
    if !t.matched {
        return "naive (A)".into();
    }
    let on = |b: bool| if b { "on" } else { "off" };
    format!(
        "matched (A) · noise {} (B) · blur {} (X) · focus {} (Y)",
        on(t.effects.noise),
        on(t.effects.motion_blur),
        on(t.effects.dof)
    )
}

pub(super) struct Panel<'a> {
    upload: ImageUpload<'a>,
    swapchain: xr::Swapchain<xr::Vulkan>,
    images: Vec<vk::Image>,
    view_space: xr::Space,
    size: (u32, u32),
    pub shown: bool,
    /// The lines the last released image shows (None: nothing drawn yet), and when
    /// they were drawn.
    drawn: Option<(Instant, Arc<[String]>)>,
    pub redraws: u64,
}

impl<'a> Panel<'a> {
    /// The panel's swapchain (`format`: the projection swapchain's, sRGB first) and
    /// the VIEW space it is placed in.
    pub fn new(
        ctx: &'a GpuContext,
        session: &xr::Session<xr::Vulkan>,
        format: u32,
        shown: bool,
    ) -> Result<Self, XrError> {
        let (w, h) = PANEL_SIZE;
        let upload = ImageUpload::new(ctx, w, h)?;
        let swapchain = session
            .create_swapchain(&xr::SwapchainCreateInfo {
                create_flags: xr::SwapchainCreateFlags::EMPTY,
                // Written by copies only; COLOR_ATTACHMENT because the layout the
                // runtime hands images over in is COLOR_ATTACHMENT_OPTIMAL.
                usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT | xr::SwapchainUsageFlags::TRANSFER_DST,
                format,
                sample_count: 1,
                width: w,
                height: h,
                face_count: 1,
                array_size: 1,
                mip_count: 1,
            })
            .map_err(call("xrCreateSwapchain (panel)"))?;
        let images = swapchain
            .enumerate_images()
            .map_err(call("xrEnumerateSwapchainImages (panel)"))?
            .into_iter()
            .map(vk::Image::from_raw)
            .collect();
        let view_space = session
            .create_reference_space(xr::ReferenceSpaceType::VIEW, xr::Posef::IDENTITY)
            .map_err(call("xrCreateReferenceSpace (VIEW)"))?;
        Ok(Self { upload, swapchain, images, view_space, size: (w, h), shown, drawn: None, redraws: 0 })
    }

    /// Redraw when shown and due (≤ 2 Hz) and the previous copy has finished:
    /// `lines` is called only then. Between xrBeginFrame and xrEndFrame.
    pub fn update(&mut self, now: Instant, lines: impl FnOnce() -> Vec<String>) -> Result<(), XrError> {
        if !self.shown || self.drawn.as_ref().is_some_and(|(t, _)| now.saturating_duration_since(*t) < REDRAW) {
            return Ok(());
        }
        if self.upload.busy()? {
            return Ok(());
        }
        let lines: Arc<[String]> = lines().into();
        let rgba = crate::panel::draw(&lines, self.size.0, self.size.1);
        let index = self.swapchain.acquire_image().map_err(call("xrAcquireSwapchainImage (panel)"))?;
        self.swapchain.wait_image(xr::Duration::INFINITE).map_err(call("xrWaitSwapchainImage (panel)"))?;
        let copied = self.upload.start(&rgba, self.images[index as usize], 0);
        // Released even after a failed copy: no swapchain may stay acquired. The
        // copy was submitted to the session's queue before the release (XR_KHR_
        // vulkan_enable2: the runtime then orders its reads after it).
        self.swapchain.release_image().map_err(call("xrReleaseSwapchainImage (panel)"))?;
        copied?;
        self.drawn = Some((now, lines));
        self.redraws += 1;
        Ok(())
    }

    /// The lines the submitted card shows, if it is submitted this frame.
    pub fn showing(&self) -> Option<Arc<[String]>> {
        self.drawn.as_ref().filter(|_| self.shown).map(|(_, l)| l.clone())
    }

    /// The quad layer to submit this frame: shown and drawn at least once (a layer
    /// may only name a swapchain with a released image, spec "Swapchain Image
    /// Management").
    pub fn layer(&self) -> Option<xr::sys::CompositionLayerQuad> {
        if !self.shown || self.drawn.is_none() {
            return None;
        }
        let (w, h) = self.size;
        Some(xr::sys::CompositionLayerQuad {
            ty: xr::sys::CompositionLayerQuad::TYPE,
            next: std::ptr::null(),
            // The card's alpha is straight (`panel::draw`), like the projection
            // layer's (`layers::projection_flags`).
            layer_flags: xr::CompositionLayerFlags::BLEND_TEXTURE_SOURCE_ALPHA
                | xr::CompositionLayerFlags::UNPREMULTIPLIED_ALPHA,
            space: self.view_space.as_raw(),
            eye_visibility: xr::EyeVisibility::BOTH,
            sub_image: xr::sys::SwapchainSubImage {
                swapchain: self.swapchain.as_raw(),
                image_rect: xr::Rect2Di {
                    offset: xr::Offset2Di { x: 0, y: 0 },
                    extent: xr::Extent2Di { width: w as i32, height: h as i32 },
                },
                image_array_index: 0,
            },
            // "Quad Layer": the quad lies in the pose's X-Y plane facing +Z, so the
            // identity orientation faces the eyes from −Z.
            pose: xr::Posef {
                orientation: xr::Quaternionf::IDENTITY,
                position: xr::Vector3f { x: POSITION_M[0], y: POSITION_M[1], z: POSITION_M[2] },
            },
            size: xr::Extent2Df { width: WIDTH_M, height: WIDTH_M * h as f32 / w as f32 },
        })
    }
}
