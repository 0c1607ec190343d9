//! XR_META_environment_depth: the headset's depth of the room (Quest 3: stereo
//! depth from its tracking cameras, one low-resolution image per eye) for the
//! calibration worker — δ(Z) needs metric depth and pose + depth flow needs depth
//! (`analysis::reproject` puts it into the passthrough camera). Not for rendering.
//!
//! Per frame, between xrBeginFrame and xrEndFrame (spec: at most one acquire per
//! frame, the image usable until the next xrEndFrame): collect a finished read-back,
//! and when one is due and none is in flight, acquire the newest depth image and
//! queue its read-back (`gpu::DepthReadback`, polled on later frames: the frame loop
//! never waits on it). Teardown (`Drop`): the read-back waited for, the provider
//! stopped, the swapchain destroyed, then the provider (spec: the swapchain is the
//! provider's child) — all before the session, which `xr::run` drops after this.
//!
//! Conventions, as read from the extension and Meta's samples (none verified on a
//! headset here — docs/xr.md lists them): D16 values are window depth d ∈ [0, 1] of an
//! OpenGL-style projection (z_ndc = 2d − 1) with near plane `nearZ` and far plane
//! `farZ`, infinite when `farZ < nearZ` or infinite (spec: XrEnvironmentDepthImageMETA);
//! the view poses are in the acquire's space at the depth's own capture; the images
//! are kept in SHADER_READ_ONLY_OPTIMAL; their first row is the top of the view.
//! The extension: "The view is never flipped horizontally nor vertically"
//! (XrEnvironmentDepthImageViewMETA::fov), and under Vulkan an image's origin is
//! its top-left corner (XR_KHR_vulkan_enable2, "Swapchain Images"). Meta's GLES
//! samples sample with uv = ndc·0.5 + 0.5 (t = 0, the first row, at ndc y = −1):
//! the same image under GL's bottom-left origin; where the spec and a GL sample
//! could be read apart, the spec is followed. `ROWS_BOTTOM_UP` holds the choice.
#![allow(unsafe_code)]

use super::{call, XrError};
use crate::analysis::reproject::DepthView;
use crate::gpu::{DepthReadback, GpuContext};
use ash::vk;
use ash::vk::Handle as _;
use glam::{Mat4, Quat, Vec3};
use openxr as xr;
use openxr::sys::Handle as _;
use std::time::{Duration, Instant};

/// Whether the depth images' first row is the bottom of the view (see the module doc).
pub const ROWS_BOTTOM_UP: bool = false;

/// Layout the runtime keeps the depth images in while the app may read them.
const IMAGE_LAYOUT: vk::ImageLayout = vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL;

/// One environment-depth image pair, ready for `analysis::reproject`.
#[derive(Clone, Debug)]
pub struct EnvironmentDepth {
    /// Predicted display time of the frame that acquired it (XrTime, ns).
    pub acquired_at_ns: i64,
    /// Left and right eye: NDC depth rows top-down, `world_from_view` in the frame
    /// loop's LOCAL space (the space head poses are in), OpenXR view axes.
    pub views: [DepthView; 2],
}

/// Build the two `DepthView`s from read-back values (layer-major, rows as stored)
/// and the acquire's metadata.
pub fn depth_views(
    values: &[f32],
    (width, height): (u32, u32),
    near_z: f32,
    far_z: f32,
    views: &[xr::sys::EnvironmentDepthImageViewMETA; 2],
) -> Result<[DepthView; 2], String> {
    let (w, h) = (width as usize, height as usize);
    if values.len() != 2 * w * h {
        return Err(format!("{} depth values for two {w}×{h} layers", values.len()));
    }
    // Spec: "When farZ is less than nearZ, an infinite projection matrix is used."
    let far_m = if far_z < near_z || far_z.is_infinite() { f32::INFINITY } else { far_z };
    if !(near_z.is_finite() && near_z > 0.0) || far_m.is_nan() || far_m <= near_z {
        return Err(format!("near {near_z} m / far {far_z} m"));
    }
    let view = |e: usize| -> Result<DepthView, String> {
        let v = &views[e];
        let q = v.pose.orientation;
        let p = v.pose.position;
        let rot = Quat::from_xyzw(q.x, q.y, q.z, q.w);
        if !(rot.is_finite() && (rot.length() - 1.0).abs() < 1e-3) {
            return Err(format!("view {e}: orientation {rot:?} is not a unit quaternion"));
        }
        let world_from_view = Mat4::from_rotation_translation(rot.normalize(), Vec3::new(p.x, p.y, p.z));
        let f = v.fov;
        let fov_tan = [f.angle_left.tan(), f.angle_right.tan(), f.angle_up.tan(), f.angle_down.tan()];
        let layer = &values[e * w * h..(e + 1) * w * h];
        let ndc_depth: Vec<f32> =
            if ROWS_BOTTOM_UP { layer.chunks_exact(w).rev().flatten().copied().collect() } else { layer.to_vec() };
        let dv = DepthView { width: w, height: h, ndc_depth, near_m: near_z, far_m, fov_tan, world_from_view };
        Ok(dv)
    };
    Ok([view(0)?, view(1)?])
}

/// What an acquire told about the image being read back.
struct Acquired {
    at_ns: i64,
    near_z: f32,
    far_z: f32,
    views: [xr::sys::EnvironmentDepthImageViewMETA; 2],
}

/// What setting the extension up came to.
pub(super) enum Setup<'a> {
    Ready(Box<EnvDepth<'a>>),
    /// The system has no environment depth.
    Unsupported,
    /// Not permitted (Quest: the spatial-data permission `com.oculus.permission.
    /// USE_SCENE` not granted yet): worth trying again once the user may have.
    NotPermitted,
}

/// The provider, its swapchain and the read-back of its images.
pub(super) struct EnvDepth<'a> {
    fp: xr::raw::EnvironmentDepthMETA,
    provider: xr::sys::EnvironmentDepthProviderMETA,
    swapchain: xr::sys::EnvironmentDepthSwapchainMETA,
    readback: Option<DepthReadback<'a>>,
    pending: Option<Acquired>,
    interval: Duration,
    last_acquire: Option<Instant>,
    /// Acquires that returned XR_ENVIRONMENT_DEPTH_NOT_AVAILABLE_META (no depth yet).
    pub not_available: u64,
    /// Read-backs completed.
    pub reads: u64,
}

impl<'a> EnvDepth<'a> {
    /// Create and start the provider (see `Setup` for why it may not be).
    pub fn set_up(
        instance: &xr::Instance,
        system: xr::SystemId,
        session: &xr::Session<xr::Vulkan>,
        ctx: &'a GpuContext,
        hz: f32,
    ) -> Result<Setup<'a>, XrError> {
        let Some(fp) = instance.exts().meta_environment_depth else {
            return Err(XrError::MissingExtension("XR_META_environment_depth"));
        };
        let mut props = xr::sys::SystemEnvironmentDepthPropertiesMETA {
            ty: xr::sys::SystemEnvironmentDepthPropertiesMETA::TYPE,
            next: std::ptr::null_mut(),
            supports_environment_depth: xr::sys::FALSE,
            supports_hand_removal: xr::sys::FALSE,
        };
        // SAFETY: `props` is the enabled extension's properties struct, typed, next
        // null, alive for the call.
        unsafe {
            super::chained_system_properties(
                instance,
                system,
                &mut props as *mut _ as *mut _,
                "xrGetSystemProperties (environment depth)",
            )
        }?;
        if props.supports_environment_depth != xr::sys::TRUE {
            return Ok(Setup::Unsupported);
        }
        let mut provider = xr::sys::EnvironmentDepthProviderMETA::NULL;
        let info = xr::sys::EnvironmentDepthProviderCreateInfoMETA {
            ty: xr::sys::EnvironmentDepthProviderCreateInfoMETA::TYPE,
            next: std::ptr::null(),
            create_flags: xr::sys::EnvironmentDepthProviderCreateFlagsMETA::EMPTY,
        };
        // SAFETY: a live session of this instance; `info` and `provider` outlive the call.
        let r = unsafe { (fp.create_environment_depth_provider)(session.as_raw(), &info, &mut provider) };
        if r == xr::sys::Result::ERROR_NOT_PERMITTED_PASSTHROUGH_FB {
            return Ok(Setup::NotPermitted);
        }
        if r.into_raw() < 0 {
            return Err(call("xrCreateEnvironmentDepthProviderMETA")(r));
        }
        // From here on `Drop` destroys what exists.
        let mut me = Self {
            fp,
            provider,
            swapchain: xr::sys::EnvironmentDepthSwapchainMETA::NULL,
            readback: None,
            pending: None,
            interval: Duration::from_secs_f32(1.0 / hz.clamp(0.1, 90.0)),
            last_acquire: None,
            not_available: 0,
            reads: 0,
        };
        if props.supports_hand_removal == xr::sys::TRUE {
            // Hands move: their depth would read as scene motion in pose + depth flow.
            let set = xr::sys::EnvironmentDepthHandRemovalSetInfoMETA {
                ty: xr::sys::EnvironmentDepthHandRemovalSetInfoMETA::TYPE,
                next: std::ptr::null(),
                enabled: xr::sys::TRUE,
            };
            // SAFETY: a live provider; `set` outlives the call.
            let r = unsafe { (fp.set_environment_depth_hand_removal)(provider, &set) };
            if r.into_raw() < 0 {
                log::warn!("OpenXR: environment depth hand removal refused ({r:?}): hands stay in the depth");
            }
        }
        let sc_info = xr::sys::EnvironmentDepthSwapchainCreateInfoMETA {
            ty: xr::sys::EnvironmentDepthSwapchainCreateInfoMETA::TYPE,
            next: std::ptr::null(),
            create_flags: xr::sys::EnvironmentDepthSwapchainCreateFlagsMETA::EMPTY,
        };
        // SAFETY: a live provider; `sc_info` and the output outlive the call.
        let r = unsafe { (fp.create_environment_depth_swapchain)(provider, &sc_info, &mut me.swapchain) };
        if r.into_raw() < 0 {
            return Err(call("xrCreateEnvironmentDepthSwapchainMETA")(r));
        }
        let mut state = xr::sys::EnvironmentDepthSwapchainStateMETA {
            ty: xr::sys::EnvironmentDepthSwapchainStateMETA::TYPE,
            next: std::ptr::null_mut(),
            width: 0,
            height: 0,
        };
        // SAFETY: a live swapchain; `state` outlives the call.
        let r = unsafe { (fp.get_environment_depth_swapchain_state)(me.swapchain, &mut state) };
        if r.into_raw() < 0 {
            return Err(call("xrGetEnvironmentDepthSwapchainStateMETA")(r));
        }
        let mut count = 0u32;
        // SAFETY: capacity 0 with a null array: the count query of the two-call idiom.
        let r = unsafe {
            (fp.enumerate_environment_depth_swapchain_images)(me.swapchain, 0, &mut count, std::ptr::null_mut())
        };
        if r.into_raw() < 0 {
            return Err(call("xrEnumerateEnvironmentDepthSwapchainImagesMETA")(r));
        }
        let blank = xr::sys::SwapchainImageVulkanKHR {
            ty: xr::sys::SwapchainImageVulkanKHR::TYPE,
            next: std::ptr::null_mut(),
            image: 0,
        };
        let mut images = vec![blank; count as usize];
        // SAFETY: `images` holds `count` Vulkan image structs (the session is Vulkan),
        // each with its type set, as the call requires.
        let r = unsafe {
            (fp.enumerate_environment_depth_swapchain_images)(
                me.swapchain,
                count,
                &mut count,
                images.as_mut_ptr() as *mut xr::sys::SwapchainImageBaseHeader,
            )
        };
        if r.into_raw() < 0 {
            return Err(call("xrEnumerateEnvironmentDepthSwapchainImagesMETA")(r));
        }
        images.truncate(count as usize);
        let vk_images: Vec<vk::Image> = images.iter().map(|i| vk::Image::from_raw(i.image)).collect();
        me.readback =
            Some(DepthReadback::new(ctx, &vk_images, vk::Format::D16_UNORM, state.width, state.height, IMAGE_LAYOUT)?);
        // SAFETY: a live, stopped provider.
        let r = unsafe { (fp.start_environment_depth_provider)(provider) };
        if r.into_raw() < 0 {
            return Err(call("xrStartEnvironmentDepthProviderMETA")(r));
        }
        log::info!(
            "OpenXR: environment depth on: {}×{} per eye, {} images, read back at ≤ {hz} Hz",
            state.width,
            state.height,
            vk_images.len()
        );
        Ok(Setup::Ready(Box::new(me)))
    }

    /// Call once per frame between xrBeginFrame and xrEndFrame: the depth read back
    /// since the last call, if any; a new acquire and read-back when due.
    pub fn on_frame(&mut self, space: &xr::Space, display_time: xr::Time) -> Result<Option<EnvironmentDepth>, XrError> {
        let Some(readback) = self.readback.as_mut() else { return Ok(None) };
        let mut out = None;
        if let Some(values) = readback.poll()? {
            self.reads += 1;
            if let Some(a) = self.pending.take() {
                let views = depth_views(&values, readback.size(), a.near_z, a.far_z, &a.views)
                    .map_err(XrError::EnvironmentDepth)?;
                out = Some(EnvironmentDepth { acquired_at_ns: a.at_ns, views });
            }
        }
        if readback.busy() || self.last_acquire.is_some_and(|t| t.elapsed() < self.interval) {
            return Ok(out);
        }
        let info = xr::sys::EnvironmentDepthImageAcquireInfoMETA {
            ty: xr::sys::EnvironmentDepthImageAcquireInfoMETA::TYPE,
            next: std::ptr::null(),
            space: space.as_raw(),
            display_time,
        };
        let blank_view = xr::sys::EnvironmentDepthImageViewMETA {
            ty: xr::sys::EnvironmentDepthImageViewMETA::TYPE,
            next: std::ptr::null(),
            fov: xr::Fovf::default(),
            pose: xr::Posef::IDENTITY,
        };
        let mut image = xr::sys::EnvironmentDepthImageMETA {
            ty: xr::sys::EnvironmentDepthImageMETA::TYPE,
            next: std::ptr::null(),
            swapchain_index: 0,
            near_z: 0.0,
            far_z: 0.0,
            views: [blank_view; 2],
        };
        // SAFETY: a live, started provider, called between xrBeginFrame and
        // xrEndFrame at most once (the caller's contract); `info` and `image` (its
        // view structs typed) outlive the call.
        let r = unsafe { (self.fp.acquire_environment_depth_image)(self.provider, &info, &mut image) };
        self.last_acquire = Some(Instant::now());
        if r == xr::sys::Result::ENVIRONMENT_DEPTH_NOT_AVAILABLE_META {
            self.not_available += 1;
            return Ok(out);
        }
        if r.into_raw() < 0 {
            return Err(call("xrAcquireEnvironmentDepthImageMETA")(r));
        }
        readback.start(image.swapchain_index as usize)?;
        self.pending = Some(Acquired {
            at_ns: display_time.as_nanos(),
            near_z: image.near_z,
            far_z: image.far_z,
            views: image.views,
        });
        Ok(out)
    }
}

impl Drop for EnvDepth<'_> {
    fn drop(&mut self) {
        // The read-back first: it reads the swapchain's images.
        drop(self.readback.take());
        // SAFETY: live handles of this extension (or NULL, skipped); the swapchain
        // (the provider's child) before the provider; nothing reads the images now.
        unsafe {
            if self.swapchain != xr::sys::EnvironmentDepthSwapchainMETA::NULL {
                let _ = (self.fp.stop_environment_depth_provider)(self.provider);
                let _ = (self.fp.destroy_environment_depth_swapchain)(self.swapchain);
            }
            let _ = (self.fp.destroy_environment_depth_provider)(self.provider);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(x: f32) -> xr::sys::EnvironmentDepthImageViewMETA {
        xr::sys::EnvironmentDepthImageViewMETA {
            ty: xr::sys::EnvironmentDepthImageViewMETA::TYPE,
            next: std::ptr::null(),
            fov: xr::Fovf { angle_left: -0.8, angle_right: 0.7, angle_up: 0.6, angle_down: -0.9 },
            pose: xr::Posef {
                orientation: xr::Quaternionf { x: 0.0, y: 0.0, z: 0.0, w: 1.0 },
                position: xr::Vector3f { x, y: 1.0, z: 0.0 },
            },
        }
    }

    /// Layers split, rows kept in storage order (the spec never flips them), far < near
    /// read as an infinite far plane, tangents of the fov angles, the pose as given.
    #[test]
    fn views_from_values() {
        let (w, h) = (3u32, 2u32);
        let values: Vec<f32> = (0..12).map(|i| i as f32 / 100.0).collect();
        let v = depth_views(&values, (w, h), 0.1, 0.0, &[view(-0.03), view(0.03)]).unwrap();
        assert_eq!(v[0].ndc_depth, vec![0.0, 0.01, 0.02, 0.03, 0.04, 0.05]);
        assert_eq!(v[1].ndc_depth, vec![0.06, 0.07, 0.08, 0.09, 0.10, 0.11]);
        assert!(v[0].far_m.is_infinite() && v[0].near_m == 0.1);
        assert!((v[0].fov_tan[0] - (-0.8f32).tan()).abs() < 1e-6 && (v[0].fov_tan[3] - (-0.9f32).tan()).abs() < 1e-6);
        assert_eq!(v[1].world_from_view.w_axis.truncate(), Vec3::new(0.03, 1.0, 0.0));
        let finite = depth_views(&values, (w, h), 0.1, 20.0, &[view(0.0), view(0.0)]).unwrap();
        assert_eq!(finite[0].far_m, 20.0);
    }

    #[test]
    fn bad_metadata_is_an_error() {
        let values = vec![0.5; 12];
        assert!(depth_views(&values[..11], (3, 2), 0.1, 0.0, &[view(0.0), view(0.0)]).is_err());
        assert!(depth_views(&values, (3, 2), f32::NAN, 0.0, &[view(0.0), view(0.0)]).is_err());
        assert!(depth_views(&values, (3, 2), 0.0, 10.0, &[view(0.0), view(0.0)]).is_err());
        let mut bad = view(0.0);
        bad.pose.orientation.w = 2.0;
        assert!(depth_views(&values, (3, 2), 0.1, 0.0, &[bad, view(0.0)]).is_err());
    }
}
