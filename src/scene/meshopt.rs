//! EXT_meshopt_compression / KHR_meshopt_compression: buffer views stored by
//! meshoptimizer's codecs, decoded at load into the bytes the uncompressed view
//! would hold (the extension's README, "Decoding"), with the pure-Rust
//! `meshopt-rs` port of the reference decoders. Every size is checked before
//! anything is allocated; a malformed stream is an error naming the view.

use meshopt_rs::index::buffer::decode_index_buffer;
use meshopt_rs::index::sequence::decode_index_sequence;
use meshopt_rs::vertex::buffer::decode_vertex_buffer;
use meshopt_rs::vertex::filter::{decode_filter_exp, decode_filter_oct_16, decode_filter_oct_8, decode_filter_quat};
use std::collections::HashMap;

/// The extension names this module reads (same JSON, same codecs version 0).
pub(super) const NAMES: [&str; 2] = ["EXT_meshopt_compression", "KHR_meshopt_compression"];

/// Largest decoded view accepted: a malformed `count × byteStride` must not
/// allocate without bound (a 256 MiB view is far beyond what a headset draws).
const MAX_DECODED_BYTES: usize = 256 << 20;

/// One compressed view as the extension describes it.
#[derive(serde::Deserialize)]
struct Desc {
    buffer: usize,
    #[serde(rename = "byteOffset", default)]
    byte_offset: u64,
    #[serde(rename = "byteLength")]
    byte_length: u64,
    #[serde(rename = "byteStride")]
    byte_stride: usize,
    count: usize,
    mode: String,
    #[serde(default)]
    filter: Option<String>,
}

/// Decode every buffer view of the document (`value`, the file's JSON) that
/// carries the extension, reading compressed bytes from `buffers` (each buffer's
/// bytes, or why they could not be had). Returns decoded bytes per view index.
pub(super) fn decode_views(
    value: &serde_json::Value,
    buffers: &[Result<Vec<u8>, String>],
) -> Result<HashMap<usize, Vec<u8>>, String> {
    let mut out = HashMap::new();
    let Some(views) = value.get("bufferViews").and_then(|v| v.as_array()) else { return Ok(out) };
    for (ix, view) in views.iter().enumerate() {
        let Some((ext, raw)) =
            NAMES.iter().find_map(|n| view.get("extensions").and_then(|e| e.get(*n)).map(|d| (*n, d)))
        else {
            continue;
        };
        let what = format!("buffer view {ix} ({ext})");
        let desc: Desc = serde_json::from_value(raw.clone()).map_err(|e| format!("{what}: {e}"))?;
        let src = match buffers.get(desc.buffer) {
            Some(Ok(b)) => b,
            Some(Err(e)) => return Err(format!("{what}: {e}")),
            None => return Err(format!("{what}: buffer {} does not exist", desc.buffer)),
        };
        let start = usize::try_from(desc.byte_offset).map_err(|_| format!("{what}: byteOffset too large"))?;
        let len = usize::try_from(desc.byte_length).map_err(|_| format!("{what}: byteLength too large"))?;
        let compressed = start.checked_add(len).and_then(|end| src.get(start..end)).ok_or_else(|| {
            format!("{what}: bytes {start}..+{len} lie outside buffer {} ({} bytes)", desc.buffer, src.len())
        })?;
        let size = desc.count.checked_mul(desc.byte_stride).filter(|&s| s <= MAX_DECODED_BYTES).ok_or_else(|| {
            format!("{what}: {} elements of {} bytes exceed {MAX_DECODED_BYTES} bytes", desc.count, desc.byte_stride)
        })?;
        let bytes = decode(&desc, compressed, &what)?;
        debug_assert_eq!(bytes.len(), size);
        out.insert(ix, bytes);
    }
    Ok(out)
}

fn decode(desc: &Desc, src: &[u8], what: &str) -> Result<Vec<u8>, String> {
    let bad = |e: &dyn std::fmt::Debug| format!("{what}: the {} stream does not decode ({e:?})", desc.mode);
    let (n, s) = (desc.count, desc.byte_stride);
    match desc.mode.as_str() {
        "ATTRIBUTES" => {
            if s == 0 || s > 256 || s % 4 != 0 {
                return Err(format!("{what}: ATTRIBUTES byteStride {s} is not a multiple of 4 in 4..=256"));
            }
            let mut bytes =
                decode_vertices(s, n, src).ok_or_else(|| format!("{what}: byteStride {s}"))?.map_err(|e| bad(&e))?;
            filter(desc.filter.as_deref().unwrap_or("NONE"), s, &mut bytes, what)?;
            Ok(bytes)
        }
        "TRIANGLES" | "INDICES" => {
            if s != 2 && s != 4 {
                return Err(format!("{what}: {} byteStride {s}, must be 2 or 4", desc.mode));
            }
            if desc.filter.as_deref().is_some_and(|f| f != "NONE") {
                return Err(format!("{what}: a filter on an index stream"));
            }
            let mut idx = vec![0u32; n];
            if desc.mode == "TRIANGLES" {
                if n % 3 != 0 {
                    return Err(format!("{what}: TRIANGLES count {n} is not a multiple of 3"));
                }
                decode_index_buffer(&mut idx, src).map_err(|e| bad(&e))?;
            } else {
                decode_index_sequence(&mut idx, src).map_err(|e| bad(&e))?;
            }
            Ok(if s == 2 {
                idx.iter().flat_map(|&i| (i as u16).to_le_bytes()).collect()
            } else {
                idx.iter().flat_map(|&i| i.to_le_bytes()).collect()
            })
        }
        other => Err(format!("{what}: mode {other:?} (ATTRIBUTES, TRIANGLES or INDICES)")),
    }
}

/// The extension's filters, applied in place to decoded ATTRIBUTES bytes
/// (README, "Filters": octahedral normals in 4 or 8 bytes, quaternions in 8,
/// exponential floats in 4-byte components).
fn filter(name: &str, stride: usize, bytes: &mut Vec<u8>, what: &str) -> Result<(), String> {
    match (name, stride) {
        ("NONE", _) => {}
        ("OCTAHEDRAL", 4) => {
            let mut v: Vec<[u8; 4]> = bytemuck::pod_collect_to_vec(bytes);
            decode_filter_oct_8(&mut v);
            *bytes = bytemuck::cast_slice(&v).to_vec();
        }
        ("OCTAHEDRAL", 8) | ("QUATERNION", 8) => {
            let mut v: Vec<[u16; 4]> = bytemuck::pod_collect_to_vec(bytes);
            if name == "OCTAHEDRAL" {
                decode_filter_oct_16(&mut v);
            } else {
                decode_filter_quat(&mut v);
            }
            *bytes = bytemuck::cast_slice(&v).to_vec();
        }
        ("EXPONENTIAL", _) => {
            let mut v: Vec<u32> = bytemuck::pod_collect_to_vec(bytes);
            decode_filter_exp(&mut v);
            *bytes = bytemuck::cast_slice(&v).to_vec();
        }
        (f, s) => return Err(format!("{what}: filter {f} with byteStride {s} is not defined")),
    }
    Ok(())
}

/// `count` vertices of `N` bytes: the decoder takes the vertex size from its
/// element type, so each legal stride gets its own instance.
fn decode_n<const N: usize>(count: usize, src: &[u8]) -> Result<Vec<u8>, meshopt_rs::vertex::DecodeError> {
    let mut v = vec![[0u8; N]; count];
    decode_vertex_buffer(&mut v, src)?;
    Ok(v.concat())
}

macro_rules! by_stride {
    ($s:expr, $n:expr, $src:expr; $($k:literal)*) => {
        match $s { $($k => Some(decode_n::<$k>($n, $src)),)* _ => None }
    };
}

fn decode_vertices(
    stride: usize,
    count: usize,
    src: &[u8],
) -> Option<Result<Vec<u8>, meshopt_rs::vertex::DecodeError>> {
    by_stride!(stride, count, src;
        4 8 12 16 20 24 28 32 36 40 44 48 52 56 60 64 68 72 76 80 84 88 92 96 100 104 108 112 116 120 124 128
        132 136 140 144 148 152 156 160 164 168 172 176 180 184 188 192 196 200 204 208 212 216 220 224 228 232
        236 240 244 248 252 256)
}
