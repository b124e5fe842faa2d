//! The decal list baked into binary, `pages/decals.list`: read in a fraction of the time the
//! text list takes to parse (33 MB of TOML on a 32 km map: about 4 s).
//!
//! A [`super::checked_file`] of magic `TVS-DLST` whose payload is (little-endian) the decal
//! count u32, then per decal: kind u8, closed u8, two zero bytes, width_m f32, falloff_m f32,
//! height_offset_m f32, point count u32, then the points as 3 f64 each. Its key is a
//! [`super::SourceKey`] of the payload: the record of sources ([`super::sources`]) ties it to the
//! text list it was baked from.

use super::{PageError, checked_file};
use crate::map::lists::{Decal, DecalKind};
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"TVS-DLST";
const VERSION: u32 = 1;
const KINDS: [DecalKind; 6] = [
    DecalKind::Road,
    DecalKind::Path,
    DecalKind::RockPatch,
    DecalKind::Field,
    DecalKind::Dirt,
    DecalKind::Pad,
];

/// `pages/decals.list` of the map in `map_dir`.
pub fn path(map_dir: &Path) -> PathBuf {
    super::bake::pages_dir(map_dir).join("decals.list")
}

fn body(decals: &[Decal]) -> Vec<u8> {
    let mut out = Vec::new();
    for d in decals {
        let kind = KINDS.iter().position(|&k| k == d.kind).unwrap_or(0) as u8;
        out.extend_from_slice(&[kind, u8::from(d.closed), 0, 0]);
        for v in [d.width_m, d.falloff_m, d.height_offset_m] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&(d.points.len() as u32).to_le_bytes());
        for p in &d.points {
            for v in p {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    out
}

/// Writes `decals` as the binary list `path` ([`super::checked_file`], keyed by the list's own
/// bytes) and returns its key.
pub fn write(path: &Path, decals: &[Decal]) -> Result<u64, PageError> {
    let mut payload = (decals.len() as u32).to_le_bytes().to_vec();
    payload.extend_from_slice(&body(decals));
    checked_file::write_keyed_by_payload(path, MAGIC, VERSION, 0xDEC0_0000, &payload)
}

/// Reads the binary list `path`, refused (naming the file) unless it is whole, matches its
/// checksum and was baked with `key`.
pub fn read(path: &Path, key: u64) -> Result<Vec<Decal>, PageError> {
    let data = checked_file::read(path, MAGIC, VERSION, key, "a binary decal list")?;
    let bad = |problem: String| PageError::Header {
        path: path.to_path_buf(),
        problem,
    };
    if data.len() < 4 {
        return Err(bad("holds no decal count".into()));
    }
    let count = u32::from_le_bytes(data[..4].try_into().expect("4 bytes")) as usize;
    let mut reader = Reader { data: &data, at: 4 };
    let mut decals = Vec::with_capacity(count.min(data.len() / 20));
    for i in 0..count {
        let decal = reader
            .decal()
            .ok_or_else(|| bad(format!("decal {i} of {count} is cut short or malformed")))?;
        decals.push(decal);
    }
    if reader.at != data.len() {
        return Err(bad("holds bytes past its last decal".into()));
    }
    Ok(decals)
}

struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let bytes = self.data.get(self.at..self.at + N)?;
        self.at += N;
        bytes.try_into().ok()
    }

    fn f32(&mut self) -> Option<f32> {
        self.take::<4>().map(f32::from_le_bytes)
    }

    fn decal(&mut self) -> Option<Decal> {
        let [kind, closed, _, _] = self.take::<4>()?;
        let kind = *KINDS.get(kind as usize)?;
        let (width_m, falloff_m, height_offset_m) = (self.f32()?, self.f32()?, self.f32()?);
        let n = u32::from_le_bytes(self.take::<4>()?) as usize;
        if n > (self.data.len() - self.at) / 24 {
            return None;
        }
        let mut points = Vec::with_capacity(n);
        for _ in 0..n {
            let mut p = [0.0; 3];
            for v in &mut p {
                *v = f64::from_le_bytes(self.take::<8>()?);
            }
            points.push(p);
        }
        Some(Decal {
            kind,
            closed: closed != 0,
            width_m,
            falloff_m,
            height_offset_m,
            points,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list() -> Vec<Decal> {
        vec![
            Decal {
                kind: DecalKind::Road,
                closed: false,
                width_m: 6.0,
                falloff_m: 4.0,
                height_offset_m: -0.25,
                points: vec![[1.0, 2.0, 3.5], [10.0, 2.5, 3.75], [20.0, 8.0, 4.0]],
            },
            Decal {
                kind: DecalKind::Pad,
                closed: true,
                width_m: 1.0,
                falloff_m: 2.0,
                height_offset_m: 0.0,
                points: vec![[0.0, 0.0, 7.0], [4.0, 0.0, 7.0], [4.0, 3.0, 7.0]],
            },
        ]
    }

    #[test]
    fn a_list_reads_back_equal_and_damage_is_refused_with_the_file_named() {
        let dir = std::env::temp_dir().join(format!("tvs-dlst-{}", std::process::id()));
        let path = dir.join("decals.list");
        let key = write(&path, &list()).expect("write");
        assert_eq!(read(&path, key).expect("read"), list());
        assert!(read(&path, key ^ 1).is_err(), "another key is refused");
        let bytes = std::fs::read(&path).expect("bytes");
        for damaged in [
            {
                let mut b = bytes.clone();
                b[40] ^= 4;
                b
            },
            bytes[..bytes.len() - 9].to_vec(),
            Vec::new(),
        ] {
            std::fs::write(&path, &damaged).expect("write damaged");
            let err = read(&path, key).expect_err("damaged list read");
            assert!(err.to_string().contains("decals.list"), "{err}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
