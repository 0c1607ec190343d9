//! The composition layers one rendered frame submits: the projection layer (both
//! eyes of the multiview swapchain, with XR_FB_space_warp's motion vectors and depth
//! chained per view), under it XR_FB_passthrough's layer, and over it the status
//! panel's quad when shown. Raw `openxr::sys`
//! structs: openxr 0.22's builders can neither chain the space-warp info nor build
//! XrCompositionLayerPassthroughFB.
#![allow(unsafe_code)]

use super::spacewarp::SpaceWarpChains;
use openxr as xr;

/// How the projection layer's alpha is to be read by the compositor.
///
/// OpenXR 1.1, "Composition Layer Blending": with
/// XR_COMPOSITION_LAYER_BLEND_TEXTURE_SOURCE_ALPHA_BIT the layer's alpha is used,
/// and `CompositeColor = LayerColor + CompositeColor·(1 − LayerColor.A)`; with
/// XR_COMPOSITION_LAYER_UNPREMULTIPLIED_ALPHA_BIT the runtime first does
/// `LayerColor.RGB *= LayerColor.A`. "Swapchain Image Management": composition
/// happens in linear light, an sRGB swapchain is decoded when the runtime samples
/// it. The renderer therefore stores straight colour (`LayerSettings::straight_alpha`)
/// and the layer sets both bits, so an edge at α lands as α·decode(c) — as Meta's
/// XrPassthrough sample submits its projection layer over passthrough. Without
/// passthrough the renderer composes over opaque black (α = 1 everywhere) and the
/// layer is submitted opaque.
pub(super) fn projection_flags(see_through: bool) -> xr::CompositionLayerFlags {
    if see_through {
        xr::CompositionLayerFlags::BLEND_TEXTURE_SOURCE_ALPHA | xr::CompositionLayerFlags::UNPREMULTIPLIED_ALPHA
    } else {
        xr::CompositionLayerFlags::EMPTY
    }
}

/// What one frame submits besides the display time and blend mode.
pub(super) struct Submission<'s> {
    pub space: &'s xr::Space,
    /// Each eye's pose and the field of view it was rendered with.
    pub poses: [xr::Posef; 2],
    pub fovs: [[f32; 4]; 2],
    pub swapchain: xr::sys::Swapchain,
    pub size: (u32, u32),
    pub space_warp: Option<&'s SpaceWarpChains>,
    pub passthrough_layer: Option<xr::sys::PassthroughLayerFB>,
    pub flags: xr::CompositionLayerFlags,
    /// The status panel (`panel::Panel::layer`), drawn over everything.
    pub quad: Option<xr::sys::CompositionLayerQuad>,
}

fn full((w, h): (u32, u32)) -> xr::Rect2Di {
    xr::Rect2Di { offset: xr::Offset2Di { x: 0, y: 0 }, extent: xr::Extent2Di { width: w as i32, height: h as i32 } }
}

fn sub_image(chain: xr::sys::Swapchain, size: (u32, u32), eye: usize) -> xr::sys::SwapchainSubImage {
    xr::sys::SwapchainSubImage { swapchain: chain, image_rect: full(size), image_array_index: eye as u32 }
}

/// Submit `sub` with xrEndFrame: the passthrough layer first (painter's order,
/// spec "Compositing"), then the projection layer, then the panel's quad.
pub(super) fn end_frame(
    stream: &mut xr::FrameStream<xr::Vulkan>,
    display_time: xr::Time,
    blend_mode: xr::EnvironmentBlendMode,
    sub: &Submission<'_>,
) -> Result<(), xr::sys::Result> {
    // Per eye: the space-warp info (motion vectors and depth of this frame; the
    // LOCAL space does not move between frames, so its delta pose is identity:
    // XR_FB_space_warp, appSpaceDeltaPose "should be identity when there is no
    // XrCompositionLayerProjection::space transformation in application").
    let warp_info: Vec<xr::sys::CompositionLayerSpaceWarpInfoFB> = match sub.space_warp {
        Some(sw) => (0..2)
            .map(|e| xr::sys::CompositionLayerSpaceWarpInfoFB {
                ty: xr::sys::CompositionLayerSpaceWarpInfoFB::TYPE,
                next: std::ptr::null(),
                layer_flags: xr::sys::CompositionLayerSpaceWarpInfoFlagsFB::EMPTY,
                motion_vector_sub_image: sub_image(sw.vectors.as_raw(), sw.size, e),
                app_space_delta_pose: xr::Posef::IDENTITY,
                depth_sub_image: sub_image(sw.depth.as_raw(), sw.size, e),
                min_depth: 0.0,
                max_depth: 1.0,
                near_z: crate::render::spacewarp::PLANES_M.0,
                far_z: crate::render::spacewarp::PLANES_M.1,
            })
            .collect(),
        None => vec![],
    };
    let proj_views: Vec<xr::sys::CompositionLayerProjectionView> = (0..2)
        .map(|e| {
            let f = sub.fovs[e];
            xr::sys::CompositionLayerProjectionView {
                ty: xr::sys::CompositionLayerProjectionView::TYPE,
                next: warp_info.get(e).map_or(std::ptr::null(), |i| i as *const _ as *const _),
                pose: sub.poses[e],
                fov: xr::Fovf { angle_left: f[0], angle_right: f[1], angle_up: f[2], angle_down: f[3] },
                sub_image: sub_image(sub.swapchain, sub.size, e),
            }
        })
        .collect();
    let projection = xr::sys::CompositionLayerProjection {
        ty: xr::sys::CompositionLayerProjection::TYPE,
        next: std::ptr::null(),
        layer_flags: sub.flags,
        space: sub.space.as_raw(),
        view_count: 2,
        views: proj_views.as_ptr(),
    };
    let passthrough = sub.passthrough_layer.map(|layer| xr::sys::CompositionLayerPassthroughFB {
        ty: xr::sys::CompositionLayerPassthroughFB::TYPE,
        next: std::ptr::null(),
        flags: xr::CompositionLayerFlags::EMPTY,
        // XR_FB_passthrough: "space must be XR_NULL_HANDLE".
        space: <xr::sys::Space as xr::sys::Handle>::NULL,
        layer_handle: layer,
    });
    // SAFETY: CompositionLayerBase is repr(transparent) over the layer header every
    // layer struct begins with (spec "Composition Layer Types"); the structs, the
    // views and the space-warp infos they point to live on this stack frame (the
    // quad in `sub`, borrowed for this call), past the xrEndFrame call that reads them.
    let layers: Vec<&xr::CompositionLayerBase<'_, xr::Vulkan>> = unsafe {
        passthrough
            .as_ref()
            .map(|p| {
                &*(p as *const xr::sys::CompositionLayerPassthroughFB
                    as *const xr::CompositionLayerBase<'_, xr::Vulkan>)
            })
            .into_iter()
            .chain([&*(&projection as *const xr::sys::CompositionLayerProjection
                as *const xr::CompositionLayerBase<'_, xr::Vulkan>)])
            .chain(sub.quad.as_ref().map(|q| {
                &*(q as *const xr::sys::CompositionLayerQuad as *const xr::CompositionLayerBase<'_, xr::Vulkan>)
            }))
            .collect()
    };
    stream.end(display_time, blend_mode, &layers)
}
