//! Checked reads of glTF accessors: every offset, length, stride and index in the
//! file is checked against the bytes actually present before it is used, so a
//! malformed file gives an error naming the accessor instead of a panic or a read
//! out of bounds. Handles every component type (normalized or not, as
//! KHR_mesh_quantization allows), interleaved views and sparse accessors.

use gltf::json;
use json::accessor::{ComponentType, Type};

/// An accessor without a buffer view is all zeros (glTF 2.0 §3.6.2.3); its count
/// is then bounded by nothing in the file, so it is capped here to keep a
/// malformed count from allocating without bound.
const MAX_ZERO_FILLED: u64 = 1 << 24;

/// The resolved bytes of every buffer of a document, in buffer order.
pub(super) struct Data<'a> {
    pub root: &'a json::Root,
    /// Each buffer's bytes, or why they could not be had (raised where read).
    pub buffers: &'a [Result<Vec<u8>, String>],
    /// Buffer views stored compressed (EXT_meshopt_compression), decoded: read
    /// in place of their (fallback or absent) uncompressed bytes.
    pub decoded: &'a std::collections::HashMap<usize, Vec<u8>>,
}

fn component_size(c: ComponentType) -> usize {
    match c {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// One component as f32: normalized integers map to [0, 1] / [-1, 1] as glTF 2.0
/// §3.11 ("Animations", normalized integers) and KHR_mesh_quantization define;
/// other integers keep their value.
fn component(bytes: &[u8], c: ComponentType, normalized: bool) -> f32 {
    let b = |i: usize| bytes.get(i).copied().unwrap_or(0);
    match c {
        ComponentType::I8 => {
            let v = b(0) as i8 as f32;
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
        ComponentType::U8 => {
            let v = b(0) as f32;
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        ComponentType::I16 => {
            let v = i16::from_le_bytes([b(0), b(1)]) as f32;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        ComponentType::U16 => {
            let v = u16::from_le_bytes([b(0), b(1)]) as f32;
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        ComponentType::U32 => u32::from_le_bytes([b(0), b(1), b(2), b(3)]) as f32,
        ComponentType::F32 => f32::from_le_bytes([b(0), b(1), b(2), b(3)]),
    }
}

fn index_component(bytes: &[u8], c: ComponentType) -> Option<u32> {
    let b = |i: usize| bytes.get(i).copied().unwrap_or(0);
    match c {
        ComponentType::U8 => Some(b(0) as u32),
        ComponentType::U16 => Some(u16::from_le_bytes([b(0), b(1)]) as u32),
        ComponentType::U32 => Some(u32::from_le_bytes([b(0), b(1), b(2), b(3)])),
        _ => None,
    }
}

impl Data<'_> {
    /// The bytes of buffer view `ix`, checked against its buffer.
    pub fn view_bytes(&self, ix: usize, what: &str) -> Result<&[u8], String> {
        self.view(ix, what).map(|(b, _)| b)
    }

    /// The bytes of buffer view `ix` and its stride, checked against its buffer.
    fn view(&self, ix: usize, what: &str) -> Result<(&[u8], Option<usize>), String> {
        let view = self.root.buffer_views.get(ix).ok_or_else(|| format!("{what}: buffer view {ix} does not exist"))?;
        if let Some(bytes) = self.decoded.get(&ix) {
            return Ok((bytes, view.byte_stride.map(|s| s.0)));
        }
        let buffer = view.buffer.value();
        let data = match self.buffers.get(buffer) {
            Some(Ok(d)) => d,
            Some(Err(e)) => return Err(format!("{what}: {e}")),
            None => return Err(format!("buffer view {ix}: buffer {buffer} does not exist")),
        };
        let start = view.byte_offset.map_or(0, |o| o.0);
        let end = start.checked_add(view.byte_length.0);
        let bytes = end.and_then(|end| data.get(usize::try_from(start).ok()?..usize::try_from(end).ok()?)).ok_or_else(
            || {
                format!(
                    "buffer view {ix}: bytes {start}..+{} lie outside buffer {buffer} ({} bytes)",
                    view.byte_length.0,
                    data.len()
                )
            },
        )?;
        Ok((bytes, view.byte_stride.map(|s| s.0)))
    }

    /// `count` elements of `elem_size` bytes from `bytes` at `offset` with `stride`:
    /// the byte range of each, all checked to lie inside `bytes`.
    fn elements<'b>(
        bytes: &'b [u8],
        offset: u64,
        count: u64,
        elem_size: usize,
        stride: usize,
        what: &str,
    ) -> Result<impl Iterator<Item = &'b [u8]> + 'b, String> {
        if count > 0 {
            let last_end = (count - 1)
                .checked_mul(stride as u64)
                .and_then(|s| s.checked_add(offset))
                .and_then(|s| s.checked_add(elem_size as u64));
            if !last_end.is_some_and(|e| e <= bytes.len() as u64) {
                return Err(format!(
                    "{what}: {count} elements of {elem_size} bytes every {stride} from byte {offset} overrun its \
                     buffer view ({} bytes)",
                    bytes.len()
                ));
            }
        }
        let offset = offset as usize;
        Ok((0..count as usize).map(move |i| &bytes[offset + i * stride..offset + i * stride + elem_size]))
    }

    fn accessor(&self, ix: usize, what: &str) -> Result<&json::Accessor, String> {
        self.root.accessors.get(ix).ok_or_else(|| format!("{what}: accessor {ix} does not exist"))
    }

    /// Accessor `ix` as `count × n` floats, where `n` is its type's component
    /// count and must be one of `allowed`. Non-finite values are refused: a NaN
    /// reaching the G-buffer spreads through every blur.
    pub fn read_f32(&self, ix: usize, allowed: &[Type], what: &str) -> Result<(Vec<f32>, usize), String> {
        let what = format!("{what} (accessor {ix})");
        let acc = self.accessor(ix, &what)?;
        let (json::validation::Checked::Valid(ty), json::validation::Checked::Valid(ct)) =
            (acc.type_, acc.component_type)
        else {
            return Err(format!("{what}: invalid type or component type"));
        };
        if !allowed.contains(&ty) {
            return Err(format!("{what}: type {ty:?}, expected one of {allowed:?}"));
        }
        let ct = ct.0;
        let n = ty.multiplicity();
        let csize = component_size(ct);
        // Matrix columns of 1- and 2-byte components are padded to 4 bytes
        // (glTF 2.0 §3.6.2.4); no matrix this reader is asked for uses them.
        if matches!(ty, Type::Mat2 | Type::Mat3 | Type::Mat4) && csize < 4 {
            return Err(format!("{what}: padded matrix columns are not read"));
        }
        let elem = n * csize;
        let count = acc.count.0;
        let mut out = match acc.buffer_view {
            Some(v) => {
                let (bytes, stride) = self.view(v.value(), &what)?;
                let stride = stride.unwrap_or(elem);
                if stride < elem {
                    return Err(format!("{what}: byte stride {stride} is shorter than an element ({elem} bytes)"));
                }
                let offset = acc.byte_offset.map_or(0, |o| o.0);
                let elements = Self::elements(bytes, offset, count, elem, stride, &what)?;
                let mut out = Vec::with_capacity(count as usize * n);
                for e in elements {
                    out.extend((0..n).map(|k| component(&e[k * csize..], ct, acc.normalized)));
                }
                out
            }
            None if count <= MAX_ZERO_FILLED => vec![0.0; count as usize * n],
            None => return Err(format!("{what}: {count} elements without a buffer view")),
        };
        if let Some(sparse) = &acc.sparse {
            let k = sparse.count.0;
            let json::validation::Checked::Valid(ict) = sparse.indices.component_type else {
                return Err(format!("{what}: invalid sparse index component type"));
            };
            let (ibytes, _) = self.view(sparse.indices.buffer_view.value(), &what)?;
            let isize = component_size(ict.0);
            let indices = Self::elements(ibytes, sparse.indices.byte_offset.0, k, isize, isize, &what)?;
            let (vbytes, _) = self.view(sparse.values.buffer_view.value(), &what)?;
            let values = Self::elements(vbytes, sparse.values.byte_offset.0, k, elem, elem, &what)?;
            for (i, v) in indices.zip(values) {
                let i = index_component(i, ict.0).ok_or_else(|| format!("{what}: bad sparse index type"))? as usize;
                let dst =
                    out.get_mut(i * n..i * n + n).ok_or_else(|| format!("{what}: sparse index {i} ≥ count {count}"))?;
                for (k, d) in dst.iter_mut().enumerate() {
                    *d = component(&v[k * csize..], ct, acc.normalized);
                }
            }
        }
        if out.iter().any(|v| !v.is_finite()) {
            return Err(format!("{what}: non-finite value"));
        }
        Ok((out, n))
    }

    /// Accessor `ix` read as vertex indices (unsigned SCALAR).
    pub fn read_indices(&self, ix: usize, what: &str) -> Result<Vec<u32>, String> {
        let what = format!("{what} (accessor {ix})");
        let acc = self.accessor(ix, &what)?;
        let (json::validation::Checked::Valid(Type::Scalar), json::validation::Checked::Valid(ct)) =
            (acc.type_, acc.component_type)
        else {
            return Err(format!("{what}: indices must be SCALAR"));
        };
        let ct = ct.0;
        if !matches!(ct, ComponentType::U8 | ComponentType::U16 | ComponentType::U32) {
            return Err(format!("{what}: indices must be unsigned integers, not {ct:?}"));
        }
        if acc.sparse.is_some() {
            // Allowed by the schema but meaningless for indices; read densely instead.
            let (v, _) = self.read_f32(ix, &[Type::Scalar], &what)?;
            return Ok(v.into_iter().map(|x| x as u32).collect());
        }
        let Some(view) = acc.buffer_view else {
            return Err(format!("{what}: indices without a buffer view"));
        };
        let (bytes, stride) = self.view(view.value(), &what)?;
        let size = component_size(ct);
        let stride = stride.unwrap_or(size).max(size);
        let offset = acc.byte_offset.map_or(0, |o| o.0);
        Ok(Self::elements(bytes, offset, acc.count.0, size, stride, &what)?
            .filter_map(|e| index_component(e, ct))
            .collect())
    }
}
