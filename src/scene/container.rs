//! A glTF file's container and resources: the JSON and BIN chunks of a `.glb`
//! (glTF 2.0 §4.4, every length checked against the bytes present), `data:` URIs
//! and relative URIs resolved in a folder or by a reader (an APK's assets).

use super::{invalid, SceneError};
use std::path::Path;

/// Where a file's external resources are looked up.
pub(super) enum Resources<'a> {
    /// Only the GLB chunk and `data:` URIs (a bundled asset).
    Embedded,
    /// Relative URIs resolved in this folder (the folder of the `.gltf`).
    Folder(&'a Path),
    /// Relative URIs (percent-decoded) handed to this reader: files of an app's
    /// bundle (the APK's assets) or any other store.
    Reader(&'a dyn Fn(&str) -> Result<Vec<u8>, String>),
}

pub(super) const GLB_MAGIC: &[u8; 4] = b"glTF";

/// The JSON chunk and the optional BIN chunk of a GLB (glTF 2.0 §4.4), every
/// length checked against the bytes present.
pub(super) fn split_glb<'a>(bytes: &'a [u8], name: &str) -> Result<(&'a [u8], Option<&'a [u8]>), SceneError> {
    let word = |at: usize| -> Option<u32> { Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?)) };
    let bad = |what: &str| invalid(name, format!("GLB container: {what}"));
    let version = word(4).ok_or_else(|| bad("shorter than its 12-byte header"))?;
    if version != 2 {
        return Err(bad(&format!("version {version}; only glTF 2.0 is read")));
    }
    let total = word(8).ok_or_else(|| bad("shorter than its 12-byte header"))? as usize;
    if total > bytes.len() || total < 12 {
        return Err(bad(&format!("header says {total} bytes, the file has {}", bytes.len())));
    }
    let mut at = 12;
    let mut chunks: Vec<(u32, &[u8])> = Vec::new();
    while at < total {
        let (Some(len), Some(ty)) = (word(at), word(at + 4)) else {
            return Err(bad(&format!("truncated chunk header at byte {at}")));
        };
        let start = at + 8;
        let end = start.checked_add(len as usize).filter(|&e| e <= total).ok_or_else(|| {
            bad(&format!("chunk at byte {at} claims {len} bytes; only {} remain", total.saturating_sub(start)))
        })?;
        chunks.push((ty, &bytes[start..end]));
        // §4.4.3: chunk lengths include their padding to 4 bytes, so the next
        // chunk starts right here; some writers leave the JSON unpadded, and
        // stepping to the next multiple of 4 would misread their BIN header.
        at = end;
    }
    const JSON: u32 = 0x4E4F_534A;
    const BIN: u32 = 0x004E_4942;
    match chunks.as_slice() {
        [(JSON, json), rest @ ..] => {
            // Chunks of unknown types are skipped (§4.4.3.1); a second BIN is not allowed.
            let bins: Vec<&[u8]> = rest.iter().filter(|(t, _)| *t == BIN).map(|(_, d)| *d).collect();
            if bins.len() > 1 {
                return Err(bad("more than one BIN chunk"));
            }
            Ok((json, bins.first().copied()))
        }
        _ => Err(bad("the first chunk is not JSON")),
    }
}

/// Percent-decoded relative URI, or an error for what is not fetched.
pub(super) fn relative_path(uri: &str, what: &str, name: &str) -> Result<String, SceneError> {
    if uri.contains("://") {
        return Err(invalid(name, format!("{what}: `{uri}` is a URL; only files beside the .gltf are read")));
    }
    let decoded = percent_encoding::percent_decode_str(uri)
        .decode_utf8()
        .map_err(|_| invalid(name, format!("{what}: URI `{uri}` is not UTF-8 once decoded")))?;
    if Path::new(decoded.as_ref()).is_absolute() {
        return Err(invalid(name, format!("{what}: `{uri}` is an absolute path; glTF URIs are relative")));
    }
    Ok(decoded.into_owned())
}

/// The bytes of a `data:` URI (RFC 2397): base64 or percent-encoded.
pub(super) fn data_uri(uri: &str, what: &str, name: &str) -> Result<Vec<u8>, SceneError> {
    let (header, payload) =
        uri.split_once(',').ok_or_else(|| invalid(name, format!("{what}: data URI without a comma")))?;
    if header.ends_with(";base64") {
        use base64::Engine as _;
        base64::engine::general_purpose::STANDARD
            .decode(payload.trim_end())
            .map_err(|e| invalid(name, format!("{what}: data URI is not valid base64 ({e})")))
    } else {
        Ok(percent_encoding::percent_decode_str(payload).collect())
    }
}

pub(super) fn fetch(uri: &str, what: &str, name: &str, resources: &Resources<'_>) -> Result<Vec<u8>, SceneError> {
    if uri.starts_with("data:") {
        return data_uri(uri, what, name);
    }
    let rel = relative_path(uri, what, name)?;
    match resources {
        Resources::Embedded => Err(invalid(
            name,
            format!("{what}: external file `{uri}`; load the .gltf from its folder, or embed it (.glb)"),
        )),
        Resources::Folder(dir) => {
            let path = dir.join(&rel);
            std::fs::read(&path).map_err(|e| invalid(name, format!("{what}: `{}`: {e}", path.display())))
        }
        Resources::Reader(read) => read(&rel).map_err(|e| invalid(name, format!("{what}: `{rel}`: {e}"))),
    }
}
