//! The large trees' list baked into binary, `pages/trees.list`: read in a fraction of the time
//! the CSV takes to parse (213,000 trees on a 32 km map: about 0.12 s of the open).
//!
//! A [`super::checked_file`] of magic `TVS-TLST` whose payload is (little-endian) the tree
//! count u32, then per tree: species u16, two zero bytes, x_m f64, y_m f64, height_m f32,
//! crown_radius_m f32. Its key is a [`super::SourceKey`] of the payload: the record of sources
//! ([`super::sources`]) ties it to the CSV it was baked from. A tree read back is checked
//! against the manifest like a row of the CSV ([`crate::map::lists::check_trees`]).

use super::{PageError, checked_file};
use crate::map::lists::Tree;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"TVS-TLST";
const VERSION: u32 = 1;
/// Bytes of one tree.
const TREE_BYTES: usize = 2 + 2 + 8 + 8 + 4 + 4;

/// `pages/trees.list` of the map in `map_dir`.
pub fn path(map_dir: &Path) -> PathBuf {
    super::bake::pages_dir(map_dir).join("trees.list")
}

/// Writes `trees` as the binary list `path` ([`super::checked_file`], keyed by the list's own
/// bytes) and returns its key.
pub fn write(path: &Path, trees: &[Tree]) -> Result<u64, PageError> {
    let mut payload = Vec::with_capacity(4 + trees.len() * TREE_BYTES);
    payload.extend_from_slice(&(trees.len() as u32).to_le_bytes());
    for t in trees {
        payload.extend_from_slice(&t.species.to_le_bytes());
        payload.extend_from_slice(&[0, 0]);
        payload.extend_from_slice(&t.x_m.to_le_bytes());
        payload.extend_from_slice(&t.y_m.to_le_bytes());
        payload.extend_from_slice(&t.height_m.to_le_bytes());
        payload.extend_from_slice(&t.crown_radius_m.to_le_bytes());
    }
    checked_file::write_keyed_by_payload(path, MAGIC, VERSION, 0x7EE5_0000, &payload)
}

/// Reads the binary list `path`, refused (naming the file) unless it is whole, matches its
/// checksum and was baked with `key`.
pub fn read(path: &Path, key: u64) -> Result<Vec<Tree>, PageError> {
    let data = checked_file::read(path, MAGIC, VERSION, key, "a binary tree list")?;
    let bad = |problem: String| PageError::Header {
        path: path.to_path_buf(),
        problem,
    };
    let (count, body) = data
        .split_first_chunk::<4>()
        .ok_or_else(|| bad("holds no tree count".into()))?;
    let count = u32::from_le_bytes(*count) as usize;
    if body.len() != count * TREE_BYTES {
        return Err(bad(format!(
            "holds {} bytes of trees where {count} trees take {}",
            body.len(),
            count * TREE_BYTES
        )));
    }
    let f64_at = |r: &[u8], at: usize| f64::from_le_bytes(r[at..at + 8].try_into().expect("8"));
    let f32_at = |r: &[u8], at: usize| f32::from_le_bytes(r[at..at + 4].try_into().expect("4"));
    Ok(body
        .chunks_exact(TREE_BYTES)
        .map(|r| Tree {
            species: u16::from_le_bytes([r[0], r[1]]),
            x_m: f64_at(r, 4),
            y_m: f64_at(r, 12),
            height_m: f32_at(r, 20),
            crown_radius_m: f32_at(r, 24),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list() -> Vec<Tree> {
        vec![
            Tree {
                species: 0,
                x_m: 12.5,
                y_m: -3.25,
                height_m: 21.0,
                crown_radius_m: 4.5,
            },
            Tree {
                species: 3,
                x_m: 1.0e4 + 1.0 / 3.0,
                y_m: 7.0,
                height_m: 0.75,
                crown_radius_m: 49.0,
            },
        ]
    }

    #[test]
    fn a_list_reads_back_equal_and_damage_is_refused_with_the_file_named() {
        let dir = std::env::temp_dir().join(format!("tvs-tlst-{}", std::process::id()));
        let path = dir.join("trees.list");
        let key = write(&path, &list()).expect("write");
        assert_eq!(read(&path, key).expect("read"), list());
        assert!(read(&path, key ^ 1).is_err(), "another key is refused");
        let empty_key = write(&path, &[]).expect("write an empty list");
        assert_eq!(read(&path, empty_key).expect("read"), Vec::new());
        let key = write(&path, &list()).expect("write");
        let bytes = std::fs::read(&path).expect("bytes");
        for damaged in [
            {
                let mut b = bytes.clone();
                b[44] ^= 4;
                b
            },
            bytes[..bytes.len() - 9].to_vec(),
            Vec::new(),
        ] {
            std::fs::write(&path, &damaged).expect("write damaged");
            let err = read(&path, key).expect_err("damaged list read");
            assert!(err.to_string().contains("trees.list"), "{err}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
