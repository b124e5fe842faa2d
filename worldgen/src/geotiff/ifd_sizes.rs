//! A check of the first TIFF directory's declared value sizes, run before the `tiff` crate reads
//! the file. The crate (0.11) allocates every tag value at its declared count before reading it
//! (its `Limits::ifd_value_size` is not enforced), so a damaged count of a few bytes would
//! allocate gigabytes; this reader refuses any entry whose values could not fit in the file.
//! Written by hand because it is twenty lines of the TIFF 6.0 / BigTIFF directory layout that no
//! crate exposes without first reading the values.

use std::io::{Read, Seek, SeekFrom};

/// Bytes per value of a TIFF field type (TIFF 6.0 section 2, BigTIFF's 16-18); None if unknown.
fn type_bytes(field_type: u16) -> Option<u64> {
    match field_type {
        1 | 2 | 6 | 7 => Some(1),
        3 | 8 => Some(2),
        4 | 9 | 11 | 13 => Some(4),
        5 | 10 | 12 | 16 | 17 | 18 => Some(8),
        _ => None,
    }
}

/// Most entries a directory may have (real GeoTIFFs have a few dozen).
const MAX_ENTRIES: u64 = 4096;

/// Every entry of the first directory of the TIFF in `file` (of `file_len` bytes) declares no
/// more value bytes than the file holds. The error names the tag.
pub fn check(file: &mut std::fs::File, file_len: u64) -> Result<(), String> {
    let mut read_at = |at: u64, n: usize| -> Result<Vec<u8>, String> {
        if at.checked_add(n as u64).is_none_or(|end| end > file_len) {
            return Err(format!(
                "the directory at byte {at} lies past the end of the file"
            ));
        }
        let mut b = vec![0u8; n];
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(&mut b))
            .map_err(|e| format!("cannot read the directory: {e}"))?;
        Ok(b)
    };
    let head = read_at(0, 8)?;
    let little = match &head[..2] {
        b"II" => true,
        b"MM" => false,
        _ => return Err("not a TIFF file (no II/MM byte-order mark)".into()),
    };
    let uint = |b: &[u8]| -> u64 {
        let mut v = 0u64;
        for (i, &x) in b.iter().enumerate() {
            let shift = if little { i } else { b.len() - 1 - i };
            v |= u64::from(x) << (8 * shift);
        }
        v
    };
    let (big, ifd) = match uint(&head[2..4]) {
        42 => (false, uint(&head[4..8])),
        43 => (true, uint(&read_at(8, 8)?)),
        m => return Err(format!("not a TIFF file (version {m}, expected 42 or 43)")),
    };
    let (count_bytes, entry_bytes, value_field) = if big { (8, 20, 8) } else { (2, 12, 4) };
    let entries = uint(&read_at(ifd, count_bytes)?);
    if entries > MAX_ENTRIES {
        return Err(format!(
            "the first directory declares {entries} entries (at most {MAX_ENTRIES})"
        ));
    }
    let table = read_at(ifd + count_bytes as u64, entries as usize * entry_bytes)?;
    for e in table.chunks_exact(entry_bytes) {
        let tag = uint(&e[0..2]);
        let Some(size) = type_bytes(uint(&e[2..4]) as u16) else {
            continue;
        };
        let count = uint(&e[4..4 + value_field]);
        let bytes = count.saturating_mul(size);
        if bytes > file_len {
            return Err(format!(
                "tag {tag} declares {count} values ({bytes} bytes), more than the whole \
                 {file_len}-byte file holds"
            ));
        }
    }
    Ok(())
}
