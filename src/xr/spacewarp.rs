//! XR_FB_space_warp's swapchains: motion vectors (RGBA16F) and depth (D32), two
//! layers each at the runtime's recommended motion-vector size, acquired and
//! released with the colour swapchain every frame; the render core fills them
//! (render::spacewarp).
//!
//! Conventions, from the extension's text (XrCompositionLayerSpaceWarpInfoFB):
//! the motion vector is `CurrNDC − PrevNDC` of the same surface point; the render
//! core writes the G-buffer's pixel motion (current − previous, +y down) × 2 / eye
//! size, which is that difference in Vulkan's NDC (+y down; XR_EXT_frame_synthesis,
//! which supersedes this extension, names "Vulkan-style conventions" for a Vulkan
//! app). Depth is window depth over `minDepth = 0`, `maxDepth = 1` between `nearZ`
//! and `farZ` (render::spacewarp::PLANES_M). The depth swapchain "should be created
//! with XR_SWAPCHAIN_USAGE_SAMPLED_BIT | XR_SWAPCHAIN_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT":
//! the compositor samples both images, so both carry SAMPLED.

use super::{call, XrError};
use ash::vk;
use ash::vk::Handle as _;
use openxr as xr;

/// The motion-vector and depth swapchains of XR_FB_space_warp (two layers each,
/// at the runtime's recommended motion-vector size).
pub(super) struct SpaceWarpChains {
    pub vectors: xr::Swapchain<xr::Vulkan>,
    vector_images: Vec<vk::Image>,
    pub depth: xr::Swapchain<xr::Vulkan>,
    depth_images: Vec<vk::Image>,
    pub size: (u32, u32),
}

impl SpaceWarpChains {
    pub fn acquire(&mut self) -> Result<crate::render::SpaceWarpTarget, XrError> {
        let v = self.vectors.acquire_image().map_err(call("xrAcquireSwapchainImage (motion vectors)"))?;
        self.vectors.wait_image(xr::Duration::INFINITE).map_err(call("xrWaitSwapchainImage (motion vectors)"))?;
        let d = self.depth.acquire_image().map_err(call("xrAcquireSwapchainImage (depth)"))?;
        self.depth.wait_image(xr::Duration::INFINITE).map_err(call("xrWaitSwapchainImage (depth)"))?;
        Ok(crate::render::SpaceWarpTarget {
            vectors: self.vector_images[v as usize],
            vectors_layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            depth: self.depth_images[d as usize],
            depth_layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
        })
    }

    pub fn release(&mut self) -> Result<(), XrError> {
        self.vectors.release_image().map_err(call("xrReleaseSwapchainImage (motion vectors)"))?;
        self.depth.release_image().map_err(call("xrReleaseSwapchainImage (depth)"))
    }
}

/// Create the space-warp swapchains, or None (logged) when the runtime's formats
/// or sizes do not allow them: then every display frame is rendered.
pub(super) fn space_warp_swapchains(
    instance: &xr::Instance,
    system: xr::SystemId,
    session: &xr::Session<xr::Vulkan>,
    formats: &[u32],
    eye: (u32, u32),
) -> Result<Option<SpaceWarpChains>, XrError> {
    use crate::render::spacewarp::{DEPTH_FORMAT, VECTOR_FORMAT};
    let mut sw = xr::sys::SystemSpaceWarpPropertiesFB {
        ty: xr::sys::SystemSpaceWarpPropertiesFB::TYPE,
        next: std::ptr::null_mut(),
        recommended_motion_vector_image_rect_width: 0,
        recommended_motion_vector_image_rect_height: 0,
    };
    // SAFETY: `sw` is the enabled extension's properties struct, typed, next null,
    // alive for the call.
    unsafe {
        super::chained_system_properties(
            instance,
            system,
            &mut sw as *mut _ as *mut _,
            "xrGetSystemProperties (space warp)",
        )
    }?;
    let size = (sw.recommended_motion_vector_image_rect_width, sw.recommended_motion_vector_image_rect_height);
    let (vf, df) = (VECTOR_FORMAT.as_raw() as u32, DEPTH_FORMAT.as_raw() as u32);
    if size.0 == 0
        || size.1 == 0
        || size.0 > eye.0
        || size.1 > eye.1
        || !formats.contains(&vf)
        || !formats.contains(&df)
    {
        log::warn!(
            "OpenXR: XR_FB_space_warp unusable (motion vectors {}×{}, formats {formats:?}): every display frame is rendered",
            size.0,
            size.1
        );
        return Ok(None);
    }
    let create = |format: u32, usage: xr::SwapchainUsageFlags| {
        session.create_swapchain(&xr::SwapchainCreateInfo {
            create_flags: xr::SwapchainCreateFlags::EMPTY,
            usage_flags: usage | xr::SwapchainUsageFlags::SAMPLED | xr::SwapchainUsageFlags::TRANSFER_DST,
            format,
            sample_count: 1,
            width: size.0,
            height: size.1,
            face_count: 1,
            array_size: 2,
            mip_count: 1,
        })
    };
    let vectors =
        create(vf, xr::SwapchainUsageFlags::COLOR_ATTACHMENT).map_err(call("xrCreateSwapchain (motion vectors)"))?;
    let depth =
        create(df, xr::SwapchainUsageFlags::DEPTH_STENCIL_ATTACHMENT).map_err(call("xrCreateSwapchain (depth)"))?;
    let images = |s: &xr::Swapchain<xr::Vulkan>| -> Result<Vec<vk::Image>, XrError> {
        Ok(s.enumerate_images()
            .map_err(call("xrEnumerateSwapchainImages"))?
            .into_iter()
            .map(vk::Image::from_raw)
            .collect())
    };
    let (vector_images, depth_images) = (images(&vectors)?, images(&depth)?);
    log::info!(
        "OpenXR: XR_FB_space_warp on: motion vectors and depth {}×{} per eye; rendering at half the display rate",
        size.0,
        size.1
    );
    Ok(Some(SpaceWarpChains { vectors, vector_images, depth, depth_images, size }))
}
