//! A glTF file's skins, morph targets and `weights` animation channels, read and
//! checked at load (every index in range for the per-frame evaluation), and the
//! bound on how far any vertex can reach that decides whether a scene is drawable.

use super::accessor::Data;
use super::{Channel, Deform, Mesh, MorphTarget, Node, Property, Skin, WeightChannel};
use glam::Vec3;
use gltf::json;
use json::accessor::Type;
use json::validation::Checked;
use std::collections::HashMap;

/// A primitive's skin and morph targets (`None` when it has neither): JOINTS_0 /
/// WEIGHTS_0 when its node has a skin (glTF 2.0 §3.7.3), every target's POSITION
/// and NORMAL displacements (§3.7.2.2; TANGENT is not used by the G-buffer), and
/// the default weights (node's, else mesh's). Every index is checked here so the
/// per-frame evaluation reads in range.
pub(super) fn read_deform(
    data: &Data,
    prim: &json::mesh::Primitive,
    node: &json::Node,
    mesh: &json::Mesh,
    skins: &[Skin],
    vertex_count: usize,
    what: &str,
) -> Result<Option<Deform>, String> {
    use json::mesh::Semantic;
    let attr = |s: Semantic| prim.attributes.get(&Checked::Valid(s)).map(|a| a.value());
    let mut d = Deform::default();
    if let (Some(si), Some(jix), Some(wix)) = (node.skin, attr(Semantic::Joints(0)), attr(Semantic::Weights(0))) {
        let skin = skins.get(si.value()).ok_or_else(|| format!("{what}: skin {} does not exist", si.value()))?;
        let (j, _) = data.read_f32(jix, &[Type::Vec4], &format!("{what} JOINTS_0"))?;
        let (w, _) = data.read_f32(wix, &[Type::Vec4], &format!("{what} WEIGHTS_0"))?;
        if j.len() != vertex_count * 4 || w.len() != vertex_count * 4 {
            return Err(format!("{what}: JOINTS_0 / WEIGHTS_0 count differs from POSITION's {vertex_count}"));
        }
        for (vi, (jc, wc)) in j.chunks_exact(4).zip(w.chunks_exact(4)).enumerate() {
            let mut ws = [wc[0], wc[1], wc[2], wc[3]];
            if ws.iter().any(|&x| x < 0.0) {
                return Err(format!("{what}: vertex {vi} has a negative skin weight"));
            }
            let mut js = [0u16; 4];
            for k in 0..4 {
                // An unused influence (weight 0) may name any joint (§3.7.3.3).
                if ws[k] == 0.0 {
                    continue;
                }
                if jc[k] < 0.0 || jc[k] as usize >= skin.joints.len() || jc[k].fract() != 0.0 {
                    return Err(format!(
                        "{what}: vertex {vi} names joint {} of a skin with {}",
                        jc[k],
                        skin.joints.len()
                    ));
                }
                js[k] = jc[k] as u16;
            }
            // §3.7.3.3: the weights sum to 1; quantized weights drift from it.
            let sum: f32 = ws.iter().sum();
            if sum > 1e-6 {
                ws.iter_mut().for_each(|x| *x /= sum);
            } else {
                ws = [1.0, 0.0, 0.0, 0.0];
            }
            d.joints.push(js);
            d.weights.push(ws);
        }
        d.skin = Some(si.value());
    }
    for (ti, t) in prim.targets.iter().flatten().enumerate() {
        let mut target = MorphTarget::default();
        let read = |ix: Option<json::Index<json::Accessor>>, which: &str| -> Result<Vec<[f32; 3]>, String> {
            let Some(ix) = ix else { return Ok(Vec::new()) };
            let (v, _) = data.read_f32(ix.value(), &[Type::Vec3], &format!("{what} target {ti} {which}"))?;
            if v.len() != vertex_count * 3 {
                return Err(format!("{what}: target {ti} {which} count differs from POSITION's {vertex_count}"));
            }
            Ok(v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
        };
        target.positions = read(t.positions, "POSITION")?;
        target.normals = read(t.normals, "NORMAL")?;
        d.targets.push(target);
    }
    if !d.targets.is_empty() {
        let defaults = node.weights.as_ref().or(mesh.weights.as_ref());
        d.default_weights = defaults.cloned().unwrap_or_default();
        d.default_weights.resize(d.targets.len(), 0.0);
        if d.default_weights.iter().any(|w| !w.is_finite()) {
            return Err(format!("{what}: non-finite morph weight"));
        }
    }
    Ok((d.skin.is_some() || !d.targets.is_empty()).then_some(d))
}

/// A `weights` animation channel: `count` weights per keyframe, where `count` is
/// the number of morph targets of the node's mesh (glTF 2.0 §3.11). `None` for a
/// node without a morphed mesh (nothing to drive).
pub(super) fn read_weight_channel(
    data: &Data,
    root: &json::Root,
    node: usize,
    sampler: &json::animation::Sampler,
    what: &str,
) -> Result<Option<WeightChannel>, String> {
    let count = root
        .nodes
        .get(node)
        .and_then(|n| n.mesh)
        .and_then(|m| root.meshes.get(m.value()))
        .and_then(|m| m.primitives.first())
        .map_or(0, |p| p.targets.as_ref().map_or(0, |t| t.len()));
    if count == 0 {
        return Ok(None);
    }
    let (times_s, _) = data.read_f32(sampler.input.value(), &[Type::Scalar], &format!("{what} input"))?;
    let (flat, _) = data.read_f32(sampler.output.value(), &[Type::Scalar], &format!("{what} output"))?;
    let cubic = sampler.interpolation == Checked::Valid(json::animation::Interpolation::CubicSpline);
    let per_key = if cubic { 3 * count } else { count };
    if times_s.is_empty() || flat.len() != times_s.len() * per_key || times_s.windows(2).any(|w| w[1] < w[0]) {
        return Err(format!(
            "{what}: {} weights for {} keyframe times and {count} morph targets, or times not increasing",
            flat.len(),
            times_s.len()
        ));
    }
    let (values, tangents) = if cubic {
        // Appendix C: per keyframe `count` in-tangents, `count` values, `count` out-tangents.
        let (mut ins, mut vals, mut outs) = (Vec::new(), Vec::new(), Vec::new());
        for k in flat.chunks_exact(3 * count) {
            ins.extend_from_slice(&k[..count]);
            vals.extend_from_slice(&k[count..2 * count]);
            outs.extend_from_slice(&k[2 * count..]);
        }
        (vals, Some((ins, outs)))
    } else {
        (flat, None)
    };
    Ok(Some(WeightChannel {
        node,
        count,
        times_s,
        values,
        step: sampler.interpolation == Checked::Valid(json::animation::Interpolation::Step),
        tangents,
    }))
}

/// Farthest a drawn vertex may lie from the scene's origin (m) for the scene to be
/// drawn: f32 spacing at 1e6 is 6.25 cm.
pub(super) const MAX_REACH_M: f32 = 1.0e6;

/// An upper bound on |world position| of any vertex at any time: per node the
/// largest scale component and translation length over its rest pose and every
/// keyframe (linear, step and spline-value interpolation stay within them;
/// rotations keep lengths), chained down the hierarchy, times the mesh bounds.
/// Finite values whose products overflow come out as infinity, which fails the check.
pub(super) fn reach_bound_m(
    nodes: &[Node],
    meshes: &[Mesh],
    channels: &[Channel],
    skins: &[Skin],
    weight_channels: &[WeightChannel],
) -> f32 {
    let mut scale: Vec<f32> = nodes.iter().map(|n| n.rest.scale.abs().max_element()).collect();
    let mut shift: Vec<f32> = nodes.iter().map(|n| n.rest.translation.length()).collect();
    for ch in channels {
        let (Some(s), Some(t)) = (scale.get_mut(ch.node), shift.get_mut(ch.node)) else { continue };
        // A cubic spline overshoots its values by at most 4/27 · Δt · (|m0| + |m1|)
        // (the largest of the Hermite tangent bases, at a third of the interval).
        let overshoot = ch.tangents.as_ref().map_or(0.0, |tg| {
            let dt_max = ch.times_s.windows(2).map(|w| w[1] - w[0]).fold(0.0f32, f32::max);
            let m_max =
                tg.iter().flat_map(|(a, b)| [a, b]).map(|m| Vec3::new(m[0], m[1], m[2]).length()).fold(0.0, f32::max);
            4.0 / 27.0 * dt_max * 2.0 * m_max
        });
        for v in &ch.values {
            let v3 = Vec3::new(v[0], v[1], v[2]);
            match ch.property {
                Property::Scale => *s = s.max(v3.abs().max_element() + overshoot),
                Property::Translation => *t = t.max(v3.length() + overshoot),
                Property::Rotation => {}
            }
        }
    }
    // (scale, shift) of world_from_node: S = s·S_parent, T = T_parent + S_parent·t.
    let chain = |mut i: usize| {
        let mut path = vec![i];
        while let Some(p) = nodes[i].parent {
            path.push(p);
            i = p;
        }
        path.iter().rev().fold((1.0f32, 0.0f32), |(s_acc, t_acc), &k| (s_acc * scale[k], t_acc + s_acc * shift[k]))
    };
    // Largest |weight| each node's morph channels reach (a cubic spline's
    // overshoot bounded as above).
    let mut weight_reach: HashMap<usize, f32> = HashMap::new();
    for ch in weight_channels {
        let dt_max = ch.times_s.windows(2).map(|w| w[1] - w[0]).fold(0.0f32, f32::max);
        let m_max = ch.tangents.as_ref().map_or(0.0, |(a, b)| a.iter().chain(b).fold(0.0f32, |m, x| m.max(x.abs())));
        let v_max = ch.values.iter().fold(0.0f32, |m, x| m.max(x.abs())) + 4.0 / 27.0 * dt_max * 2.0 * m_max;
        let e = weight_reach.entry(ch.node).or_insert(0.0);
        *e = e.max(v_max);
    }
    meshes
        .iter()
        .map(|m| {
            let mut r = m.bounds.0.abs().max(m.bounds.1.abs()).length();
            if let Some(d) = &m.deform {
                let w_anim = weight_reach.get(&m.node).copied().unwrap_or(0.0);
                for (k, t) in d.targets.iter().enumerate() {
                    let w = d.default_weights.get(k).map_or(0.0, |w| w.abs()).max(w_anim);
                    let dp = t.positions.iter().map(|p| Vec3::from(*p).length()).fold(0.0f32, f32::max);
                    r += w * dp;
                }
                if let Some(skin) = d.skin.and_then(|s| skins.get(s)) {
                    // A skinned vertex is a convex blend of joint transforms of the
                    // morphed vertex: |J·IBM·p| ≤ s_J·(‖IBM₃ₓ₃‖_F·r + |IBM_t|) + t_J,
                    // over the joints its vertices weight (a joint no vertex uses
                    // never moves one, whatever its matrix).
                    let mut used = vec![false; skin.joints.len()];
                    for (js, ws) in d.joints.iter().zip(&d.weights) {
                        for k in 0..4 {
                            if ws[k] > 0.0 {
                                if let Some(u) = used.get_mut(js[k] as usize) {
                                    *u = true;
                                }
                            }
                        }
                    }
                    return skin
                        .joints
                        .iter()
                        .zip(&skin.inverse_bind)
                        .zip(&used)
                        .filter(|(_, &u)| u)
                        .map(|((&j, ibm), _)| {
                            let (s, t) = chain(j);
                            let m3 = glam::Mat3::from_mat4(*ibm);
                            let frob =
                                (m3.x_axis.length_squared() + m3.y_axis.length_squared() + m3.z_axis.length_squared())
                                    .sqrt();
                            s * (frob * r + ibm.w_axis.truncate().length()) + t
                        })
                        .fold(0.0f32, |a, b| if b.is_nan() { f32::INFINITY } else { a.max(b) });
                }
            }
            let (s, t) = chain(m.node);
            s * r + t
        })
        .fold(0.0f32, |a, b| if b.is_nan() { f32::INFINITY } else { a.max(b) })
}
