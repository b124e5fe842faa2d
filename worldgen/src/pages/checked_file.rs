//! A small derived file read whole: a 32-byte header (an 8-byte magic, a version u32, four zero
//! bytes, the key of its inputs u64, a checksum of the payload u64), then the payload. Written
//! through a hidden partial file renamed into place; read back only when magic, version, key and
//! checksum all match, every refusal naming the file.

use super::{PageError, SourceKey};
use std::path::Path;

const HEADER_BYTES: usize = 32;

fn checksum(payload: &[u8]) -> u64 {
    let mut k = SourceKey::new(0xC4EC_0000);
    k.update(payload);
    k.finish()
}

/// Writes `payload` as the file `path` of `magic` and `version`, keyed by `key`.
pub fn write(
    path: &Path,
    magic: &[u8; 8],
    version: u32,
    key: u64,
    payload: &[u8],
) -> Result<(), PageError> {
    let mut bytes = Vec::with_capacity(HEADER_BYTES + payload.len());
    bytes.extend_from_slice(magic);
    bytes.extend_from_slice(&version.to_le_bytes());
    bytes.extend_from_slice(&[0; 4]);
    bytes.extend_from_slice(&key.to_le_bytes());
    bytes.extend_from_slice(&checksum(payload).to_le_bytes());
    bytes.extend_from_slice(payload);
    let partial = super::fresh_partial_path(path)?;
    let io = |action, source| PageError::Io {
        path: path.to_path_buf(),
        action,
        source,
    };
    std::fs::write(&partial, &bytes).map_err(|e| io("write", e))?;
    std::fs::rename(&partial, path).map_err(|e| io("move into place", e))
}

/// [`write()`] keyed by the payload itself (a [`SourceKey`] seeded with `seed`): for a file that
/// copies a source list into binary, whose key the record of sources ties to that list.
/// Returns the key.
pub fn write_keyed_by_payload(
    path: &Path,
    magic: &[u8; 8],
    version: u32,
    seed: u32,
    payload: &[u8],
) -> Result<u64, PageError> {
    let mut key = SourceKey::new(seed);
    key.update(payload);
    let key = key.finish();
    write(path, magic, version, key, payload)?;
    Ok(key)
}

/// The payload of the file `path`, refused unless it is a whole file of `magic` (`what` in the
/// message) and `version` written for `key`.
pub fn read(
    path: &Path,
    magic: &[u8; 8],
    version: u32,
    key: u64,
    what: &str,
) -> Result<Vec<u8>, PageError> {
    let bad = |problem: String| PageError::Header {
        path: path.to_path_buf(),
        problem,
    };
    let mut bytes = std::fs::read(path).map_err(|source| PageError::Io {
        path: path.to_path_buf(),
        action: "read",
        source,
    })?;
    if bytes.len() < HEADER_BYTES || &bytes[..8] != magic {
        return Err(bad(format!("not a file of {what}")));
    }
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
    let found = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if found != version {
        return Err(bad(format!(
            "version {found} is not {version}; bake the map again"
        )));
    }
    if u64_at(16) != key {
        return Err(bad(
            "baked from another map or another engine; bake the map again".into(),
        ));
    }
    let stored = u64_at(24);
    if checksum(&bytes[HEADER_BYTES..]) != stored {
        return Err(bad(
            "does not match its checksum (damaged or truncated); bake the map again".into(),
        ));
    }
    Ok(bytes.split_off(HEADER_BYTES))
}
