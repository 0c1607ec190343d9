//! The frame loop: `xrWaitFrame` paced on a display-refresh grid (halved while the
//! app submits XR_FB_space_warp data, as Quest throttles an AppSW app), and
//! `xrEndFrame` checking and recording the submitted layers (JSON report, PNG):
//! projection, XR_FB_passthrough and quad layers, composed as the spec says.

use crate::{lock, Runtime};
use openxr_sys as xr;
use serde_json::json;
use xr::Handle as _;

#[derive(Default)]
pub(crate) struct Pacing {
    /// Display time of the frame last handed out by xrWaitFrame (ns).
    pub last_display_ns: Option<i64>,
    /// The display grid's origin (first vsync).
    pub grid_origin_ns: i64,
    /// xrWaitFrame calls not yet matched by xrBeginFrame.
    pub waited: u32,
    /// Between xrBeginFrame and xrEndFrame.
    pub in_frame: bool,
    /// Display times handed out and not yet ended (xrEndFrame must name one).
    pub pending: Vec<i64>,
    /// xrEndFrame calls so far (the script's and the PNG list's frame numbers).
    pub ended: u64,
    /// Frames whose display time had to slip past the next grid slot (the app was late).
    pub missed: u64,
    /// The last submitted frame carried space-warp data: render at half rate.
    pub throttled: bool,
}

/// The session `session` names, if it is running (frame calls need that, spec 10.4).
fn running_session(rt: &mut Runtime, session: xr::Session) -> Result<&mut crate::session::Session, xr::Result> {
    let s = rt.session.as_mut().filter(|s| s.handle == session.into_raw()).ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
    if s.lost {
        return Err(xr::Result::ERROR_SESSION_LOST);
    }
    if !s.running {
        return Err(xr::Result::ERROR_SESSION_NOT_RUNNING);
    }
    Ok(s)
}

fn period_ns(hz: f32) -> i64 {
    (1e9 / hz as f64).round() as i64
}

pub(crate) unsafe extern "system" fn wait_frame(
    session: xr::Session,
    _info: *const xr::FrameWaitInfo,
    state: *mut xr::FrameState,
) -> xr::Result {
    if state.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    // Decide under the lock, sleep without it (other threads may call in meanwhile:
    // the spec allows xrWaitFrame on one thread and the rest on another).
    let (wake_ns, display_ns, period, should_render, (epoch, origin_ns), result) = {
        let mut guard = lock();
        let Some(rt) = guard.as_mut() else { return xr::Result::ERROR_HANDLE_INVALID };
        if rt.instance_lost {
            return xr::Result::ERROR_INSTANCE_LOST;
        }
        let now = rt.now_ns();
        let s = match running_session(rt, session) {
            Ok(s) => s,
            Err(r) => return r,
        };
        let display = period_ns(s.display_hz);
        let period = if s.frame.throttled { 2 * display } else { display };
        let p = &mut s.frame;
        if p.last_display_ns.is_none() {
            p.grid_origin_ns = now;
        }
        // The frame is displayed one app period after the app is woken (the budget
        // it has to render), on the display grid.
        let earliest = now + period;
        let mut target = p.last_display_ns.map_or(earliest, |l| l + period);
        if target < earliest {
            // Late: the frame slips to the next grid slot after `earliest`.
            let k = (earliest - p.grid_origin_ns + display - 1) / display;
            target = p.grid_origin_ns + k * display;
            p.missed += 1;
        }
        p.last_display_ns = Some(target);
        p.waited += 1;
        p.pending.push(target);
        let should_render = matches!(s.state, xr::SessionState::VISIBLE | xr::SessionState::FOCUSED);
        let first = s.state == xr::SessionState::READY;
        if first {
            // The frame loop is now synchronised with the runtime (spec 9.3).
            rt.set_state(xr::SessionState::SYNCHRONIZED);
        }
        let lost = rt.session.as_ref().is_some_and(|s| s.lost);
        (
            target - period,
            target,
            period,
            should_render,
            (rt.epoch, rt.origin_ns()),
            if lost { xr::Result::SESSION_LOSS_PENDING } else { xr::Result::SUCCESS },
        )
    };
    // Sleep until the wake time (XrTime is the origin + time since the epoch, see now_ns).
    let wake = epoch + std::time::Duration::from_nanos((wake_ns - origin_ns).max(0) as u64);
    let now = std::time::Instant::now();
    if wake > now {
        std::thread::sleep(wake - now);
    }
    // SAFETY: non-null caller output; `ty`/`next` are the caller's.
    unsafe {
        (*state).predicted_display_time = xr::Time::from_nanos(display_ns);
        (*state).predicted_display_period = xr::Duration::from_nanos(period);
        (*state).should_render = should_render.into();
    }
    result
}

pub(crate) unsafe extern "system" fn begin_frame(session: xr::Session, _info: *const xr::FrameBeginInfo) -> xr::Result {
    crate::with_runtime(|rt| {
        let s = match running_session(rt, session) {
            Ok(s) => s,
            Err(r) => return r,
        };
        if s.frame.waited == 0 {
            return xr::Result::ERROR_CALL_ORDER_INVALID;
        }
        s.frame.waited -= 1;
        // A second xrBeginFrame without xrEndFrame discards the previous frame.
        let discarded = std::mem::replace(&mut s.frame.in_frame, true);
        if discarded {
            xr::Result::FRAME_DISCARDED
        } else {
            xr::Result::SUCCESS
        }
    })
}

/// What one projection view submitted (for the report and the PNG writer).
pub(crate) struct SubmittedView {
    pub swapchain: u64,
    pub rect: xr::Rect2Di,
    pub array_index: u32,
    /// The swapchain's format is sRGB: sampled, its colour is decoded to linear.
    pub srgb: bool,
}

pub(crate) unsafe extern "system" fn end_frame(session: xr::Session, info: *const xr::FrameEndInfo) -> xr::Result {
    crate::with_runtime(|rt| {
        if info.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        // SAFETY: non-null frame end info of the caller.
        let info = unsafe { &*info };
        let s = match running_session(rt, session) {
            Ok(s) => s,
            Err(r) => return r,
        };
        if !s.frame.in_frame {
            return xr::Result::ERROR_CALL_ORDER_INVALID;
        }
        let t = info.display_time.as_nanos();
        let Some(i) = s.frame.pending.iter().position(|&p| p == t) else { return xr::Result::ERROR_TIME_INVALID };
        s.frame.pending.drain(..=i);
        s.frame.in_frame = false;
        let frame_no = s.frame.ended;
        s.frame.ended += 1;
        let period = if s.frame.throttled { 2 } else { 1 } * period_ns(s.display_hz);
        let missed_total = s.frame.missed;
        let state = s.state;
        if !rt.config.blend_modes.contains(&info.environment_blend_mode) {
            return xr::Result::ERROR_ENVIRONMENT_BLEND_MODE_UNSUPPORTED;
        }
        // SAFETY: `layers` holds `layer_count` pointers to layer structs.
        let layers = match unsafe { read_layers(rt, info) } {
            Ok(l) => l,
            Err(r) => return r,
        };
        let space_warp = layers.iter().any(|l| l.space_warp);
        if let Some(s) = rt.session.as_mut() {
            s.blend_mode = Some(info.environment_blend_mode);
            s.frame.throttled = space_warp;
        }
        let layer_json: Vec<_> = layers.iter().map(|l| l.json.clone()).collect();
        rt.log(json!({
            "event": "frame",
            "frame": frame_no,
            "display_time_ns": t,
            "period_ns": period,
            "missed_total": missed_total,
            "state": format!("{state:?}"),
            "blend_mode": format!("{:?}", info.environment_blend_mode),
            "layers": layer_json,
        }));
        if rt.config.png_frames.contains(&frame_no) {
            if let Err(e) = write_pngs(rt, frame_no, t, &layers, info.environment_blend_mode) {
                eprintln!("ba-xr-runtime: frame {frame_no}: writing PNG: {e}");
                return xr::Result::ERROR_RUNTIME_FAILURE;
            }
        }
        // Visible after the first submitted frame, focused right after (no system
        // UI over the app); scripted events follow.
        if state == xr::SessionState::SYNCHRONIZED && frame_no == 0 {
            rt.set_state(xr::SessionState::VISIBLE);
            rt.set_state(xr::SessionState::FOCUSED);
        }
        rt.run_script(frame_no + 1);
        xr::Result::SUCCESS
    })
}

pub(crate) struct Layer {
    pub json: serde_json::Value,
    /// A passthrough layer (drawn where it stands in the layer order).
    pub passthrough: bool,
    pub views: Vec<SubmittedView>,
    /// Blend flags of a projection layer.
    pub source_alpha: bool,
    pub unpremultiplied: bool,
    pub space_warp: bool,
    /// A quad layer's placement (its one sub-image is `views[0]`).
    pub quad: Option<Quad>,
}

/// Where a quad layer stands (spec "Quad Layer"): `pose` in the space (kind and
/// offset) at the frame's display time, `size_m` its width and height, centred on
/// the pose in its X-Y plane; drawn for the eyes in `eyes`.
pub(crate) struct Quad {
    pub space: (crate::SpaceKind, xr::Posef),
    pub pose: xr::Posef,
    pub size_m: [f32; 2],
    pub eyes: [bool; 2],
}

/// A pose the spec accepts in a layer: finite, unit quaternion ("XR_ERROR_POSE_INVALID").
fn pose_valid(p: &xr::Posef) -> bool {
    let (q, t) = (p.orientation, p.position);
    let norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
    norm.is_finite() && (norm - 1.0).abs() < 1e-3 && t.x.is_finite() && t.y.is_finite() && t.z.is_finite()
}

/// A layer's sub-image: a live swapchain with a released image, the rectangle
/// inside it, the array index among its layers (spec "Swapchain Image Management",
/// XR_ERROR_SWAPCHAIN_RECT_INVALID).
fn checked_sub_image(rt: &Runtime, sub: &xr::SwapchainSubImage) -> Result<SubmittedView, xr::Result> {
    let Some(sc) = rt.swapchains.get(&sub.swapchain.into_raw()) else {
        return Err(xr::Result::ERROR_HANDLE_INVALID);
    };
    if sc.last_released.is_none() {
        return Err(xr::Result::ERROR_LAYER_INVALID);
    }
    let r = sub.image_rect;
    // In i64: an offset plus an extent near i32::MAX must be refused, not overflow.
    if r.offset.x < 0
        || r.offset.y < 0
        || r.extent.width <= 0
        || r.extent.height <= 0
        || r.offset.x as i64 + r.extent.width as i64 > sc.width as i64
        || r.offset.y as i64 + r.extent.height as i64 > sc.height as i64
    {
        return Err(xr::Result::ERROR_SWAPCHAIN_RECT_INVALID);
    }
    if sub.image_array_index >= sc.array_size {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    Ok(SubmittedView {
        swapchain: sub.swapchain.into_raw(),
        rect: r,
        array_index: sub.image_array_index,
        srgb: sc.format == ash::vk::Format::R8G8B8A8_SRGB,
    })
}

fn fov_json(f: &xr::Fovf) -> serde_json::Value {
    json!([f.angle_left, f.angle_right, f.angle_up, f.angle_down])
}

/// Check and copy out the submitted layers (spec 10.5: layers are drawn in order,
/// each over the previous; swapchain images must have been released).
unsafe fn read_layers(rt: &Runtime, info: &xr::FrameEndInfo) -> Result<Vec<Layer>, xr::Result> {
    if info.layer_count > 16 {
        return Err(xr::Result::ERROR_LAYER_LIMIT_EXCEEDED);
    }
    let mut out = vec![];
    for i in 0..info.layer_count as usize {
        // SAFETY: `layer_count` pointers at `layers` (caller's contract).
        let base = unsafe { *info.layers.add(i) };
        if base.is_null() {
            return Err(xr::Result::ERROR_LAYER_INVALID);
        }
        // SAFETY: every layer struct begins with the base header.
        let ty = unsafe { (*base).ty };
        match ty {
            xr::StructureType::COMPOSITION_LAYER_PROJECTION => {
                // SAFETY: the type tag says what the struct is.
                let p = unsafe { &*(base as *const xr::CompositionLayerProjection) };
                if p.view_count != 2 || p.views.is_null() {
                    return Err(xr::Result::ERROR_VALIDATION_FAILURE);
                }
                if !rt.spaces.contains_key(&p.space.into_raw()) {
                    return Err(xr::Result::ERROR_HANDLE_INVALID);
                }
                let mut views = vec![];
                let mut space_warp = false;
                let mut view_json = vec![];
                for v in 0..2 {
                    // SAFETY: `view_count` views at `views`.
                    let view = unsafe { &*p.views.add(v) };
                    // "xrEndFrame ... XR_ERROR_POSE_INVALID": a projection view's
                    // pose must be a valid pose (unit quaternion, finite).
                    let q = view.pose.orientation;
                    if !pose_valid(&view.pose) {
                        return Err(xr::Result::ERROR_POSE_INVALID);
                    }
                    let sub = view.sub_image;
                    let submitted = checked_sub_image(rt, &sub)?;
                    let Some(sc) = rt.swapchains.get(&sub.swapchain.into_raw()) else {
                        return Err(xr::Result::ERROR_HANDLE_INVALID);
                    };
                    let r = sub.image_rect;
                    let mut sw = false;
                    let mut next = view.next;
                    while !next.is_null() {
                        // SAFETY: chained structs begin with a BaseInStructure header.
                        let b = unsafe { &*(next as *const xr::BaseInStructure) };
                        if b.ty == xr::StructureType::COMPOSITION_LAYER_SPACE_WARP_INFO_FB {
                            // SAFETY: the type tag says what the struct is.
                            let info = unsafe { &*(next as *const xr::CompositionLayerSpaceWarpInfoFB) };
                            // Motion vectors and depth must be released images of
                            // live swapchains, inside them (XR_FB_space_warp).
                            for sub in [info.motion_vector_sub_image, info.depth_sub_image] {
                                let Some(c) = rt.swapchains.get(&sub.swapchain.into_raw()) else {
                                    return Err(xr::Result::ERROR_HANDLE_INVALID);
                                };
                                let r = sub.image_rect;
                                if c.last_released.is_none()
                                    || sub.image_array_index >= c.array_size
                                    || r.offset.x < 0
                                    || r.offset.y < 0
                                    || (r.offset.x + r.extent.width) as u32 > c.width
                                    || (r.offset.y + r.extent.height) as u32 > c.height
                                {
                                    return Err(xr::Result::ERROR_VALIDATION_FAILURE);
                                }
                            }
                            if !(info.near_z > 0.0 && info.far_z > info.near_z) {
                                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
                            }
                            sw = true;
                        }
                        next = b.next as *const _;
                    }
                    space_warp |= sw;
                    view_json.push(json!({
                        "rect": [r.offset.x, r.offset.y, r.extent.width, r.extent.height],
                        "array_index": sub.image_array_index,
                        "swapchain_array_size": sc.array_size,
                        "format": sc.format.as_raw(),
                        "fov": fov_json(&view.fov),
                        "position": [view.pose.position.x, view.pose.position.y, view.pose.position.z],
                        "orientation": [q.x, q.y, q.z, q.w],
                        "space_warp": sw,
                    }));
                    views.push(submitted);
                }
                let f = p.layer_flags;
                let source_alpha = f.contains(xr::CompositionLayerFlags::BLEND_TEXTURE_SOURCE_ALPHA);
                let unpremultiplied = f.contains(xr::CompositionLayerFlags::UNPREMULTIPLIED_ALPHA);
                out.push(Layer {
                    json: json!({"type": "projection", "source_alpha": source_alpha, "unpremultiplied": unpremultiplied, "views": view_json}),
                    passthrough: false,
                    views,
                    source_alpha,
                    unpremultiplied,
                    space_warp,
                    quad: None,
                });
            }
            xr::StructureType::COMPOSITION_LAYER_QUAD => {
                // SAFETY: the type tag says what the struct is.
                let q = unsafe { &*(base as *const xr::CompositionLayerQuad) };
                let Some(&(_, kind, offset)) = rt.spaces.get(&q.space.into_raw()) else {
                    return Err(xr::Result::ERROR_HANDLE_INVALID);
                };
                if !pose_valid(&q.pose) {
                    return Err(xr::Result::ERROR_POSE_INVALID);
                }
                // A quad of no or non-finite extent is not a valid layer.
                if !(q.size.width > 0.0 && q.size.height > 0.0 && q.size.width.is_finite() && q.size.height.is_finite())
                {
                    return Err(xr::Result::ERROR_VALIDATION_FAILURE);
                }
                let eyes = match q.eye_visibility {
                    xr::EyeVisibility::BOTH => [true, true],
                    xr::EyeVisibility::LEFT => [true, false],
                    xr::EyeVisibility::RIGHT => [false, true],
                    _ => return Err(xr::Result::ERROR_VALIDATION_FAILURE),
                };
                let view = checked_sub_image(rt, &q.sub_image)?;
                let r = view.rect;
                let f = q.layer_flags;
                let source_alpha = f.contains(xr::CompositionLayerFlags::BLEND_TEXTURE_SOURCE_ALPHA);
                let unpremultiplied = f.contains(xr::CompositionLayerFlags::UNPREMULTIPLIED_ALPHA);
                let (p, o) = (q.pose.position, q.pose.orientation);
                out.push(Layer {
                    json: json!({
                        "type": "quad",
                        "space": format!("{kind:?}"),
                        "position": [p.x, p.y, p.z],
                        "orientation": [o.x, o.y, o.z, o.w],
                        "size_m": [q.size.width, q.size.height],
                        "rect": [r.offset.x, r.offset.y, r.extent.width, r.extent.height],
                        "eyes": eyes,
                        "source_alpha": source_alpha,
                        "unpremultiplied": unpremultiplied,
                    }),
                    passthrough: false,
                    views: vec![view],
                    source_alpha,
                    unpremultiplied,
                    space_warp: false,
                    quad: Some(Quad {
                        space: (kind, offset),
                        pose: q.pose,
                        size_m: [q.size.width, q.size.height],
                        eyes,
                    }),
                });
            }
            xr::StructureType::COMPOSITION_LAYER_PASSTHROUGH_FB => {
                // SAFETY: the type tag says what the struct is.
                let p = unsafe { &*(base as *const xr::CompositionLayerPassthroughFB) };
                let Some(&(pt, layer_running)) = rt.passthrough_layers.get(&p.layer_handle.into_raw()) else {
                    return Err(xr::Result::ERROR_HANDLE_INVALID);
                };
                let running = layer_running && rt.passthroughs.get(&pt).copied().unwrap_or(false);
                out.push(Layer {
                    json: json!({"type": "passthrough_fb", "running": running}),
                    passthrough: running,
                    views: vec![],
                    source_alpha: false,
                    unpremultiplied: false,
                    space_warp: false,
                    quad: None,
                });
            }
            other => {
                out.push(Layer {
                    json: json!({"type": format!("{other:?}")}),
                    passthrough: false,
                    views: vec![],
                    source_alpha: false,
                    unpremultiplied: false,
                    space_warp: false,
                    quad: None,
                });
            }
        }
    }
    Ok(out)
}

/// The synthetic "camera" image the test runtime shows as passthrough: a smooth
/// gradient with a coarse checker, so a blend with it is visible in a PNG. Values
/// are sRGB-encoded, as a camera image on the display.
fn passthrough_texel(x: u32, y: u32, w: u32, h: u32) -> [f32; 3] {
    let (u, v) = (x as f32 / w.max(1) as f32, y as f32 / h.max(1) as f32);
    let check = if ((x / 32) + (y / 32)).is_multiple_of(2) { 0.08 } else { 0.0 };
    [0.25 + 0.4 * u + check, 0.35 + check, 0.25 + 0.4 * v + check]
}

/// sRGB's decoding (IEC 61966-2-1), what sampling an sRGB image does.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// sRGB's encoding, for writing linear values to an 8-bit PNG.
pub fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

fn to8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Write, per eye, the projection layer as submitted (`frame_NNNN_eyeE.png`, RGBA,
/// the swapchain's bytes), the passthrough image (`frame_NNNN_eyeE_passthrough.png`,
/// where passthrough shows: a running passthrough layer, or the ALPHA_BLEND
/// environment blend mode) and what the compositor shows
/// (`frame_NNNN_eyeE_composited.png`, sRGB-encoded) — composed as OpenXR 1.1 says,
/// not as the app composes on desktop:
/// * "Swapchain Image Management": composition is in linear light; an sRGB
///   swapchain's colour is decoded when sampled, any other format read as linear;
/// * "Composition Layer Blending": layer alpha is 1 unless
///   BLEND_TEXTURE_SOURCE_ALPHA is set; UNPREMULTIPLIED_ALPHA first does
///   `LayerColor.RGB *= LayerColor.A`; then, layer by layer in submission order,
///   `CompositeColor = LayerColor + CompositeColor·(1 − LayerColor.A)`, starting
///   from zero; a passthrough layer (XR_FB_passthrough) stands in for the camera
///   image, opaque;
/// * "Environment Blend Mode": OPAQUE shows the composite's colour and ignores its
///   alpha; ALPHA_BLEND blends the composite over the real world by its alpha
///   (premultiplied, as composed).
///
/// A quad layer is written as submitted (`frame_NNNN_quadK.png`, K its place in the
/// layer list) and composed where it stands: each eye's pixel looks along its ray
/// (the eye at the display time, `session::eye_fov`) and takes the quad's nearest
/// texel where the ray meets the quad's rectangle (its image's top row at +Y).
fn write_pngs(
    rt: &Runtime,
    frame: u64,
    display_ns: i64,
    layers: &[Layer],
    blend: xr::EnvironmentBlendMode,
) -> Result<(), String> {
    let Some(dir) = &rt.config.png_dir else { return Ok(()) };
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let vk = rt.vk.as_ref().ok_or("no Vulkan state")?;
    let (w, h) = rt.config.eye_size;
    let alpha_blend = blend == xr::EnvironmentBlendMode::ALPHA_BLEND;
    let save_passthrough = |eye: usize| -> Result<(), String> {
        let mut pt = image::RgbImage::new(w, h);
        for (x, y, px) in pt.enumerate_pixels_mut() {
            *px = image::Rgb(passthrough_texel(x, y, w, h).map(to8));
        }
        let p = dir.join(format!("frame_{frame:04}_eye{eye}_passthrough.png"));
        pt.save(&p).map_err(|e| format!("{}: {e}", p.display()))
    };
    // The camera image as the compositor uses it: its 8-bit values, decoded.
    let world = |x: u32, y: u32| passthrough_texel(x, y, w, h).map(|v| srgb_to_linear(to8(v) as f32 / 255.0));
    for eye in 0..2 {
        // Linear RGBA, premultiplied.
        let mut canvas = vec![[0.0f32; 4]; (w * h) as usize];
        for (k, layer) in layers.iter().enumerate() {
            if let Some(q) = &layer.quad {
                let view = layer.views.first().ok_or("quad without its image")?;
                let sc = rt.swapchains.get(&view.swapchain).ok_or("swapchain gone")?;
                let rgba = vk.read_layer(sc, view.array_index)?;
                let r = view.rect;
                let texel = |x: u32, y: u32| -> [u8; 4] {
                    let i = (((y + r.offset.y as u32) * sc.width + x + r.offset.x as u32) * 4) as usize;
                    [rgba[i], rgba[i + 1], rgba[i + 2], rgba[i + 3]]
                };
                let (qw, qh) = (r.extent.width as u32, r.extent.height as u32);
                if eye == 0 {
                    let img = image::RgbaImage::from_fn(qw, qh, |x, y| image::Rgba(texel(x, y)));
                    let p = dir.join(format!("frame_{frame:04}_quad{k}.png"));
                    img.save(&p).map_err(|e| format!("{}: {e}", p.display()))?;
                }
                if !q.eyes[eye] {
                    continue;
                }
                let local_from_eye =
                    crate::session::head_pose(rt.config.head, display_ns).mul(&crate::session::head_from_eye(eye));
                let local_from_quad = crate::session::local_from_space(rt, q.space.0, &q.space.1, display_ns)
                    .mul(&crate::session::Pose::from_xr(&q.pose));
                let quad_from_eye = local_from_quad.inverse().mul(&local_from_eye);
                let fov = crate::session::eye_fov(eye);
                let (tl, tr, tu, td) =
                    (fov.angle_left.tan(), fov.angle_right.tan(), fov.angle_up.tan(), fov.angle_down.tan());
                let o = quad_from_eye.t;
                // "Only front face of the quad surface is visible; the back face is
                // not visible and must not be drawn by the runtime": the front faces
                // +Z, so an eye at z ≤ 0 in the quad's frame sees nothing of it.
                if o[2] <= 0.0 {
                    continue;
                }
                for (i, c) in canvas.iter_mut().enumerate() {
                    let (x, y) = (i as u32 % w, i as u32 / w);
                    let u = tl + (x as f32 + 0.5) / w as f32 * (tr - tl);
                    let v = tu - (y as f32 + 0.5) / h as f32 * (tu - td);
                    let d = quad_from_eye.rotate([u, v, -1.0]);
                    if d[2].abs() < 1e-9 {
                        continue;
                    }
                    let along = -o[2] / d[2];
                    if along <= 0.0 {
                        continue;
                    }
                    let (px, py) = (o[0] + along * d[0], o[1] + along * d[1]);
                    let (fx, fy) = (px / q.size_m[0] + 0.5, 0.5 - py / q.size_m[1]);
                    if !(0.0..1.0).contains(&fx) || !(0.0..1.0).contains(&fy) {
                        continue;
                    }
                    let t = texel(((fx * qw as f32) as u32).min(qw - 1), ((fy * qh as f32) as u32).min(qh - 1));
                    let a = if layer.source_alpha { t[3] as f32 / 255.0 } else { 1.0 };
                    for ch in 0..3 {
                        let s = t[ch] as f32 / 255.0;
                        let s = if view.srgb { srgb_to_linear(s) } else { s };
                        let s = if layer.unpremultiplied { (s * a).clamp(0.0, 1.0) } else { s };
                        c[ch] = s + c[ch] * (1.0 - a);
                    }
                    c[3] = a + c[3] * (1.0 - a);
                }
                continue;
            }
            if layer.passthrough {
                save_passthrough(eye)?;
                for (i, c) in canvas.iter_mut().enumerate() {
                    let [r, g, b] = world(i as u32 % w, i as u32 / w);
                    *c = [r, g, b, 1.0];
                }
            }
            let Some(view) = layer.views.get(eye) else { continue };
            let sc = rt.swapchains.get(&view.swapchain).ok_or("swapchain gone")?;
            let rgba = vk.read_layer(sc, view.array_index)?;
            let r = view.rect;
            let mut sub = image::RgbaImage::new(r.extent.width as u32, r.extent.height as u32);
            for y in 0..r.extent.height as u32 {
                for x in 0..r.extent.width as u32 {
                    let (sx, sy) = (x + r.offset.x as u32, y + r.offset.y as u32);
                    let i = ((sy * sc.width + sx) * 4) as usize;
                    let px = [rgba[i], rgba[i + 1], rgba[i + 2], rgba[i + 3]];
                    sub.put_pixel(x, y, image::Rgba(px));
                    if x < w && y < h {
                        let c = &mut canvas[(y * w + x) as usize];
                        // Alpha is never sRGB-encoded (Vulkan's sRGB formats decode RGB only).
                        let a = if layer.source_alpha { px[3] as f32 / 255.0 } else { 1.0 };
                        let mut colour = [0.0f32; 3];
                        for k in 0..3 {
                            let s = px[k] as f32 / 255.0;
                            let s = if view.srgb { srgb_to_linear(s) } else { s };
                            colour[k] = if layer.unpremultiplied { (s * a).clamp(0.0, 1.0) } else { s };
                        }
                        for k in 0..3 {
                            c[k] = colour[k] + c[k] * (1.0 - a);
                        }
                        c[3] = a + c[3] * (1.0 - a);
                    }
                }
            }
            let p = dir.join(format!("frame_{frame:04}_eye{eye}.png"));
            sub.save(&p).map_err(|e| format!("{}: {e}", p.display()))?;
        }
        if alpha_blend {
            save_passthrough(eye)?;
        }
        let mut out = image::RgbImage::new(w, h);
        for (i, c) in canvas.iter().enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let shown: [f32; 3] = if alpha_blend {
                let real = world(x, y);
                std::array::from_fn(|k| c[k] + real[k] * (1.0 - c[3]))
            } else {
                [c[0], c[1], c[2]]
            };
            out.put_pixel(x, y, image::Rgb(shown.map(|v| to8(linear_to_srgb(v.clamp(0.0, 1.0))))));
        }
        let p = dir.join(format!("frame_{frame:04}_eye{eye}_composited.png"));
        out.save(&p).map_err(|e| format!("{}: {e}", p.display()))?;
    }
    Ok(())
}
