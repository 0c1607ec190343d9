//! tract-onnx providers, each loaded under a documented contract for its role, so a
//! user can drop in their own export (`--onnx ROLE=PATH`) and a model that does not
//! fit is refused at load with the file and the mismatch named.
//!
//! The contracts (all tensors f32, NCHW, batch 1; RGB is the frame's own encoding
//! as the fits see it, in [0, 1]; a model does its own normalisation inside):
//!
//! | role | inputs | output | how it is run |
//! |---|---|---|---|
//! | `denoise` | `noisy` [1,3,H,W] | `clean` [1,3,H,W], same space | tiles of H×W over sample regions |
//! | `motion-deblur` | `blurred` [1,3,H,W] | `sharp` [1,3,H,W] | tiles over the whole frame |
//! | `defocus-deblur` | `blurred` [1,3,H,W] | `sharp` [1,3,H,W] | tiles over the whole frame |
//! | `depth` | `image` [1,3,H,W] | `depth` [1,1,H,W] metres, or `inverse_depth` [1,1,H,W] relative inverse depth (MiDaS/DPT/Depth-Anything), rank 3 [1,H,W] also accepted | the frame resized to H×W, the output resized back |
//! | `flow` | `frame0`, `frame1` [1,3,H,W] (previous, current) | `flow` [1,2,H,W], px of the H×W input, frame0 → frame1, x then y | both frames resized; flow rescaled to frame px per frame interval |
//!
//! H×W are fixed before optimisation (tract runs a conv net ~2.6× slower with
//! symbolic sizes, `../shared/notes/android-build.md`): a model exported with fixed
//! sizes runs at those; one with symbolic H×W at the role's default (`Contract`).

use super::{AnalysisError, DepthMap, FrameContext, Reference, Role};
use crate::image::{Flow, Plane, Rgb};
use crate::model::DepthUnits;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tract_onnx::pb;
use tract_onnx::prelude::*;

/// What a role's model must look like.
#[derive(Clone, Copy, Debug)]
pub struct Contract {
    pub role: Role,
    /// Input names, each [1, 3, H, W].
    pub inputs: &'static [&'static str],
    /// Accepted output names (one of them) and the channels each carries.
    pub outputs: &'static [(&'static str, usize)],
    /// H×W used when the model leaves them symbolic.
    pub default_hw: (usize, usize),
}

impl Contract {
    pub fn for_role(role: Role) -> Contract {
        match role {
            Role::Denoise => Contract { role, inputs: &["noisy"], outputs: &[("clean", 3)], default_hw: (128, 128) },
            Role::MotionDeblur | Role::DefocusDeblur => {
                Contract { role, inputs: &["blurred"], outputs: &[("sharp", 3)], default_hw: (256, 256) }
            }
            Role::Depth => Contract {
                role,
                inputs: &["image"],
                outputs: &[("depth", 1), ("inverse_depth", 1)],
                default_hw: (256, 256),
            },
            Role::Flow => {
                Contract { role, inputs: &["frame0", "frame1"], outputs: &[("flow", 2)], default_hw: (256, 256) }
            }
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum OnnxError {
    #[error("{path}: cannot read: {reason}")]
    Read { path: PathBuf, reason: String },
    #[error("{path}: not a readable ONNX model (truncated or corrupt?): {reason}")]
    Parse { path: PathBuf, reason: String },
    #[error("{path}: breaks the `{role}` contract: {mismatch}")]
    Contract { path: PathBuf, role: &'static str, mismatch: String },
    #[error("{path}: tract cannot prepare it at {h}×{w}: {reason}")]
    Prepare { path: PathBuf, h: usize, w: usize, reason: String },
}

type Runnable = Arc<TypedRunnableModel>;

/// A model loaded for a role: shapes fixed, optimised, ready to run.
pub struct OnnxModel {
    pub path: PathBuf,
    pub role: Role,
    /// The fixed input size.
    pub hw: (usize, usize),
    /// The output it was accepted by (e.g. `inverse_depth`).
    pub output: &'static str,
    runnable: Runnable,
}

impl std::fmt::Debug for OnnxModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxModel").field("path", &self.path).field("role", &self.role).field("hw", &self.hw).finish()
    }
}

/// Dimensions of a value: `Some(n)` fixed, `None` symbolic or missing.
fn dims(v: &pb::ValueInfoProto) -> Option<Vec<Option<i64>>> {
    use pb::tensor_shape_proto::dimension::Value;
    let pb::type_proto::Value::TensorType(t) = v.r#type.as_ref()?.value.as_ref()?;
    Some(
        t.shape
            .as_ref()?
            .dim
            .iter()
            .map(|d| match d.value {
                Some(Value::DimValue(n)) => Some(n),
                _ => None,
            })
            .collect(),
    )
}

fn elem_type(v: &pb::ValueInfoProto) -> Option<i32> {
    let pb::type_proto::Value::TensorType(t) = v.r#type.as_ref()?.value.as_ref()?;
    Some(t.elem_type)
}

/// ONNX TensorProto.DataType FLOAT.
const ONNX_FLOAT: i32 = 1;

fn show(d: &[Option<i64>]) -> String {
    let s: Vec<String> = d.iter().map(|x| x.map_or("?".into(), |n| n.to_string())).collect();
    format!("[{}]", s.join(","))
}

impl OnnxModel {
    /// Load `path` for `role`: parse, check the contract on the graph's declared
    /// inputs/outputs, fix the input shapes, optimise, and check the optimised
    /// output shape. `hw` overrides the size for models with symbolic H×W.
    pub fn load(role: Role, path: &Path, hw: Option<(usize, usize)>) -> Result<OnnxModel, OnnxError> {
        let contract = Contract::for_role(role);
        let p = path.to_path_buf();
        let broken = |mismatch: String| OnnxError::Contract { path: p.clone(), role: role.name(), mismatch };
        let bytes = std::fs::read(path).map_err(|e| OnnxError::Read { path: p.clone(), reason: e.to_string() })?;
        let onnx = tract_onnx::onnx();
        let proto = onnx
            .proto_model_for_read(&mut &bytes[..])
            .map_err(|e| OnnxError::Parse { path: p.clone(), reason: format!("{e:#}") })?;
        let graph = proto.graph.as_ref().ok_or_else(|| broken("the file holds no graph".into()))?;
        // Before IR 4, weights were listed among the inputs too.
        let inits: std::collections::HashSet<&str> = graph.initializer.iter().map(|t| t.name.as_str()).collect();
        let inputs: Vec<&pb::ValueInfoProto> =
            graph.input.iter().filter(|i| !inits.contains(i.name.as_str())).collect();
        let names: Vec<&str> = inputs.iter().map(|i| i.name.as_str()).collect();
        if names != contract.inputs {
            return Err(broken(format!("inputs are {names:?}, the contract wants {:?}", contract.inputs)));
        }
        let mut fixed_hw: Option<(usize, usize)> = None;
        for i in &inputs {
            if elem_type(i) != Some(ONNX_FLOAT) {
                return Err(broken(format!("input `{}` is not float32", i.name)));
            }
            let d = dims(i).ok_or_else(|| broken(format!("input `{}` has no tensor shape", i.name)))?;
            let ok_layout = d.len() == 4 && d[0].map_or(true, |n| n == 1) && d[1].map_or(true, |n| n == 3);
            if !ok_layout {
                return Err(broken(format!("input `{}` is {}, the contract wants [1,3,H,W]", i.name, show(&d))));
            }
            if let (Some(h), Some(w)) = (d[2], d[3]) {
                if h < 8 || w < 8 {
                    return Err(broken(format!("input `{}` is {}: H and W must be at least 8", i.name, show(&d))));
                }
                fixed_hw = Some((h as usize, w as usize));
            }
        }
        let outputs: Vec<&pb::ValueInfoProto> = graph.output.iter().collect();
        let Some((out_name, out_channels)) = (match outputs.as_slice() {
            [o] => contract.outputs.iter().find(|(n, _)| *n == o.name).copied(),
            _ => None,
        }) else {
            let got: Vec<&str> = outputs.iter().map(|o| o.name.as_str()).collect();
            let want: Vec<&str> = contract.outputs.iter().map(|o| o.0).collect();
            return Err(broken(format!("outputs are {got:?}, the contract wants one of {want:?}")));
        };
        let (h, w) = fixed_hw.or(hw).unwrap_or(contract.default_hw);
        let prepare = |reason: String| OnnxError::Prepare { path: p.clone(), h, w, reason };
        let mut model = onnx.model_for_proto_model(&proto).map_err(|e| prepare(format!("{e:#}")))?;
        for ix in 0..inputs.len() {
            model
                .set_input_fact(ix, f32::fact([1, 3, h, w]).into())
                .map_err(|e| prepare(format!("fixing input {ix}: {e:#}")))?;
        }
        let typed = model.into_optimized().map_err(|e| prepare(format!("{e:#}")))?;
        let fact = typed.output_fact(0).map_err(|e| prepare(format!("{e:#}")))?;
        let shape: Option<Vec<usize>> = fact.shape.as_concrete().map(|s| s.to_vec());
        let rank3_ok = out_channels == 1 && shape.as_deref() == Some(&[1, h, w][..]);
        if !(rank3_ok || shape.as_deref() == Some(&[1, out_channels, h, w][..])) || fact.datum_type != f32::datum_type()
        {
            return Err(broken(format!(
                "output `{out_name}` comes out as {:?} {:?} for inputs [1,3,{h},{w}], the contract wants f32 [1,{out_channels},{h},{w}]",
                fact.datum_type, shape
            )));
        }
        let runnable = typed.into_runnable().map_err(|e| prepare(format!("{e:#}")))?;
        Ok(OnnxModel { path: p, role, hw: (h, w), output: out_name, runnable })
    }

    /// Run on NCHW inputs of the fixed size; returns the output's values (NCHW).
    fn run(&self, inputs: Vec<Vec<f32>>) -> Result<Vec<f32>, AnalysisError> {
        let (h, w) = self.hw;
        let fail = |reason: String| AnalysisError::Failed { provider: self.name(), reason };
        let tensors: TVec<TValue> = inputs
            .into_iter()
            .map(|v| Tensor::from_shape(&[1, 3, h, w], &v).map(|t| t.into_tvalue()))
            .collect::<TractResult<_>>()
            .map_err(|e| fail(format!("{e:#}")))?;
        let out = self.runnable.run(tensors).map_err(|e| fail(format!("{e:#}")))?;
        let t = out.first().ok_or_else(|| fail("no output".into()))?;
        // Iterates in logical (C) order whatever the storage layout.
        let v: Vec<f32> = t.to_plain_array_view::<f32>().map_err(|e| fail(format!("{e:#}")))?.iter().copied().collect();
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(fail(format!("non-finite output at element {i}")));
        }
        Ok(v)
    }

    fn name(&self) -> String {
        format!("onnx {} ({})", self.role.name(), self.path.display())
    }
}

/// A rectangle of the frame, in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    pub x0: usize,
    pub y0: usize,
    pub width: usize,
    pub height: usize,
}

/// Tile starts covering [0, len) with tiles of `tile` whose interiors (`margin` in
/// from each side) abut; the last tile is aligned to the end.
fn tile_starts(len: usize, tile: usize, margin: usize) -> Vec<usize> {
    if len <= tile {
        return vec![0];
    }
    let step = (tile - 2 * margin).max(1);
    let mut v: Vec<usize> = (0..).map(|k| k * step).take_while(|&s| s + tile < len).collect();
    v.push(len - tile);
    v
}

/// An image-to-image model run over regions in tiles of its fixed size; pixels
/// within `margin` of a tile's edge (the network's zero padding reaches them) are
/// left to the neighbouring tile or marked invalid.
fn run_tiled(model: &OnnxModel, img: &Rgb, regions: &[Region], margin: usize) -> Result<(Rgb, Plane), AnalysisError> {
    let (th, tw) = model.hw;
    let mut out = img.clone();
    let mut valid = Plane::new(img.width, img.height, 0.0);
    for r in regions {
        if r.width < tw || r.height < th || r.x0 + r.width > img.width || r.y0 + r.height > img.height {
            return Err(AnalysisError::Failed {
                provider: model.name(),
                reason: format!(
                    "region {r:?} does not hold a {tw}×{th} tile inside the {}×{} frame",
                    img.width, img.height
                ),
            });
        }
        for ty in tile_starts(r.height, th, margin) {
            for tx in tile_starts(r.width, tw, margin) {
                let (x0, y0) = (r.x0 + tx, r.y0 + ty);
                let mut input = Vec::with_capacity(3 * th * tw);
                for c in 0..3 {
                    for y in y0..y0 + th {
                        input.extend_from_slice(&img.channels[c][y * img.width + x0..y * img.width + x0 + tw]);
                    }
                }
                let o = model.run(vec![input])?;
                for y in margin..th - margin {
                    for x in margin..tw - margin {
                        let i = (y0 + y) * img.width + x0 + x;
                        for c in 0..3 {
                            out.channels[c][i] = o[(c * th + y) * tw + x];
                        }
                        valid.data[i] = 1.0;
                    }
                }
            }
        }
    }
    Ok((out, valid))
}

/// The current frame through an image-to-image model over `regions`, as a
/// reference valid where the tiles' interiors fell; unavailable for a frame
/// smaller than one tile.
fn tiled_reference(
    model: &OnnxModel,
    ctx: &FrameContext,
    regions: &[Region],
    provider: &'static str,
) -> Result<Reference, AnalysisError> {
    let frame = &ctx.current.frame;
    let (th, tw) = model.hw;
    if frame.image.width < tw || frame.image.height < th {
        return Err(AnalysisError::unavailable(
            frame.index,
            provider,
            format!(
                "the {}×{} frame is smaller than the model's {tw}×{th} tile",
                frame.image.width, frame.image.height
            ),
        ));
    }
    let (image, valid) = run_tiled(model, &frame.image, regions, TILE_MARGIN_PX)?;
    Ok(Reference {
        image,
        valid: Some(valid),
        // The ratio is for noise *independent* of the frame's (a mean of other
        // frames). What a network leaves is its input's own noise, which shrinks the
        // residual instead; it is measured (tests/onnx.rs, BENCHMARKS.md), not
        // corrected for.
        noise_variance_ratio: 0.0,
        sources: vec![frame.index],
        second: None,
    })
}

/// Pixels the network's zero padding can reach from a tile edge: the shipped
/// denoiser's receptive field is 11 px (radius 5); 8 leaves room for user models
/// of a few more layers.
pub const TILE_MARGIN_PX: usize = 8;

/// `denoise` by a network, on sample regions rather than the whole frame: a frame
/// of at most `max_pixels` is done whole; a larger one in square regions of 2×2
/// tiles spread over it on a grid, as many as fit in `max_pixels`. Each region
/// (224 px of valid interior at the default 128-px tile) holds whole footprints of
/// every noise level, low-pass included (≤ 177 px), which is what the noise fit
/// samples.
pub struct OnnxDenoiser {
    pub model: OnnxModel,
    pub max_pixels: usize,
}

impl OnnxDenoiser {
    pub const DEFAULT_MAX_PIXELS: usize = 320 * 1024;

    pub fn new(model: OnnxModel) -> Self {
        Self { model, max_pixels: Self::DEFAULT_MAX_PIXELS }
    }

    /// Regions for a `w`×`h` frame (see the type's docs).
    pub fn regions(&self, w: usize, h: usize) -> Vec<Region> {
        let (th, tw) = self.model.hw;
        if w * h <= self.max_pixels || w < 2 * tw || h < 2 * th {
            return vec![Region { x0: 0, y0: 0, width: w, height: h }];
        }
        let (rw, rh) = (2 * tw - 2 * TILE_MARGIN_PX, 2 * th - 2 * TILE_MARGIN_PX);
        let n = (self.max_pixels / (rw * rh)).max(1);
        let cols = ((n as f64 * w as f64 / h as f64).sqrt().round() as usize).clamp(1, (w / rw).max(1));
        let rows = n.div_ceil(cols).clamp(1, (h / rh).max(1));
        let place = |k: usize, count: usize, len: usize, size: usize| {
            ((k as f64 + 0.5) * len as f64 / count as f64 - size as f64 / 2.0).clamp(0.0, (len - size) as f64) as usize
        };
        let mut v = vec![];
        for r in 0..rows {
            for c in 0..cols {
                if v.len() < n {
                    v.push(Region { x0: place(c, cols, w, rw), y0: place(r, rows, h, rh), width: rw, height: rh });
                }
            }
        }
        v
    }
}

impl super::Denoiser for OnnxDenoiser {
    fn name(&self) -> &str {
        "onnx denoise"
    }
    fn denoise(&mut self, ctx: &FrameContext) -> Result<Reference, AnalysisError> {
        let img = &ctx.current.frame.image;
        tiled_reference(&self.model, ctx, &self.regions(img.width, img.height), "onnx denoise")
    }
}

/// `motion-deblur` / `defocus-deblur` by a network, tiled over the whole frame.
pub struct OnnxDeblur {
    pub model: OnnxModel,
}

impl OnnxDeblur {
    fn reference(&self, ctx: &FrameContext) -> Result<Reference, AnalysisError> {
        let img = &ctx.current.frame.image;
        let whole = [Region { x0: 0, y0: 0, width: img.width, height: img.height }];
        tiled_reference(&self.model, ctx, &whole, "onnx deblur")
    }
}

impl super::MotionDeblurrer for OnnxDeblur {
    fn name(&self) -> &str {
        "onnx motion-deblur"
    }
    fn deblur(&mut self, ctx: &FrameContext, _flow: &Flow) -> Result<Reference, AnalysisError> {
        self.reference(ctx)
    }
}

impl super::DefocusDeblurrer for OnnxDeblur {
    fn name(&self) -> &str {
        "onnx defocus-deblur"
    }
    fn deblur(&mut self, ctx: &FrameContext, _depth: &DepthMap) -> Result<Reference, AnalysisError> {
        self.reference(ctx)
    }
}

/// Bilinear resize of a plane (pixel centres aligned).
fn resize(p: &Plane, w: usize, h: usize) -> Plane {
    let (sx, sy) = (p.width as f32 / w as f32, p.height as f32 / h as f32);
    let mut out = Plane::new(w, h, 0.0);
    for y in 0..h {
        for x in 0..w {
            out.data[y * w + x] = p.sample_bilinear((x as f32 + 0.5) * sx - 0.5, (y as f32 + 0.5) * sy - 0.5);
        }
    }
    out
}

fn resized_nchw(img: &Rgb, (h, w): (usize, usize)) -> Vec<f32> {
    (0..3).flat_map(|c| resize(&img.plane(c), w, h).data).collect()
}

/// `depth` by a network on the whole frame resized to its input size.
pub struct OnnxDepth {
    pub model: OnnxModel,
}

impl super::DepthProvider for OnnxDepth {
    fn name(&self) -> &str {
        "onnx depth"
    }
    fn depth(&mut self, ctx: &FrameContext) -> Result<DepthMap, AnalysisError> {
        let img = &ctx.current.frame.image;
        let (h, w) = self.model.hw;
        let out = self.model.run(vec![resized_nchw(img, (h, w))])?;
        let depth = resize(&Plane::from_vec(w, h, out), img.width, img.height);
        let units = if self.model.output == "depth" { DepthUnits::MetricM } else { DepthUnits::RelativeInverse };
        if units == DepthUnits::MetricM && depth.data.iter().any(|&z| z <= 0.0) {
            return Err(AnalysisError::Failed {
                provider: self.model.name(),
                reason: "metric depth output holds values ≤ 0 m".into(),
            });
        }
        Ok(DepthMap { depth, units })
    }
}

/// `flow` by a network from the previous frame to the current one, rescaled to
/// the frame's pixels and to one frame interval.
pub struct OnnxFlow {
    pub model: OnnxModel,
}

impl super::FlowProvider for OnnxFlow {
    fn name(&self) -> &str {
        "onnx flow"
    }
    fn flow(&mut self, ctx: &FrameContext) -> Result<Flow, AnalysisError> {
        let cur = &ctx.current.frame;
        let prev = ctx
            .window
            .last()
            .ok_or_else(|| AnalysisError::unavailable(cur.index, "onnx flow", "no previous frame yet"))?;
        let intervals = (cur.t_s - prev.frame.t_s) / ctx.frame_interval_s.max(1e-9);
        if !(intervals > 0.25 && intervals < 4.5) {
            return Err(AnalysisError::unavailable(
                cur.index,
                "onnx flow",
                format!("previous frame is {intervals:.2} frame intervals away"),
            ));
        }
        let (h, w) = self.model.hw;
        let out = self.model.run(vec![resized_nchw(&prev.frame.image, (h, w)), resized_nchw(&cur.image, (h, w))])?;
        let (fw, fh) = (cur.image.width, cur.image.height);
        let (sx, sy) = (fw as f32 / w as f32 / intervals as f32, fh as f32 / h as f32 / intervals as f32);
        let dx = resize(&Plane::from_vec(w, h, out[..w * h].to_vec()), fw, fh).data.iter().map(|v| v * sx).collect();
        let dy = resize(&Plane::from_vec(w, h, out[w * h..].to_vec()), fw, fh).data.iter().map(|v| v * sy).collect();
        Ok(Flow { width: fw, height: fh, dx, dy })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_with_abutting_interiors() {
        for len in [128usize, 129, 200, 240, 241, 1000] {
            let starts = tile_starts(len, 128, 8);
            assert_eq!(*starts.last().unwrap(), len.saturating_sub(128));
            // Interiors [s+8, s+120) leave no gap between 8 and len-8.
            let mut covered = vec![false; len];
            for s in &starts {
                (s + 8..s + 120).for_each(|i| covered[i] = true);
            }
            assert!(covered[8..len - 8].iter().all(|&c| c), "gap at len {len}");
        }
    }
}
