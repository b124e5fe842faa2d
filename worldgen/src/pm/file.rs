//! The `.pm` file: one progressive mesh, little-endian, versioned and checksummed.
//!
//! ```text
//! magic "TVSPMESH", version u32 (= 1)
//! cost u8 (0 longest-edge, 1 quadric, 2 melax), attributes u8 (bit 0 UVs, bit 1 normals), u16 0
//! positions P u32, wedges W u32, triangles T u32, sample spacing f32
//! positions P x 3 f32 | wedge_position W u32 | uvs W x 2 f32 | normals W x 3 f32
//! collapse_to W u32 | triangles T x 3 u32
//! levels P x (wedges u32, triangles u32, error f32, cost f32, flags u8)
//! FNV-1a 64 of everything before it, u64
//! ```
//!
//! [`read`] checks every field before it returns (see [`PmMesh::validate`]), so a loaded mesh
//! can be drawn at any level without further checks.

use super::build::CostKind;
use super::data::{Level, PmMesh};
use std::path::{Path, PathBuf};

pub const MAGIC: &[u8; 8] = b"TVSPMESH";
pub const VERSION: u32 = 1;
/// Most positions, wedges or triangles a file may declare.
pub const MAX_ELEMENTS: u32 = 100_000_000;
const HEADER_BYTES: usize = 8 + 4 + 4 + 12 + 4;
const LEVEL_BYTES: usize = 17;

/// Why a PM file could not be read or written. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum PmError {
    #[error("{path}: cannot {action}: {source}")]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error("{path}: not a progressive mesh (magic is not \"TVSPMESH\")")]
    Magic { path: PathBuf },
    #[error(
        "{path}: field `version` is {found}, this build reads version {VERSION}; rebuild it with `worldgen pm`"
    )]
    Version { path: PathBuf, found: u32 },
    #[error("{path}: {length} bytes, expected {expected} for the counts in the header")]
    Length {
        path: PathBuf,
        length: usize,
        expected: u64,
    },
    #[error(
        "{path}: checksum mismatch (stored {stored:016x}, computed {computed:016x}): the file is damaged"
    )]
    Checksum {
        path: PathBuf,
        stored: u64,
        computed: u64,
    },
    #[error("{path}: field `{field}`: {message}")]
    Field {
        path: PathBuf,
        field: &'static str,
        message: String,
    },
}

/// FNV-1a, 64 bit.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Serialises a PM (deterministic: the same mesh gives the same bytes).
pub fn to_bytes(pm: &PmMesh) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&VERSION.to_le_bytes());
    b.push(pm.cost.code());
    b.push(u8::from(!pm.uvs.is_empty()) | (u8::from(!pm.normals.is_empty()) << 1));
    b.extend_from_slice(&0u16.to_le_bytes());
    for n in [
        pm.positions.len(),
        pm.wedge_position.len(),
        pm.triangles.len(),
    ] {
        b.extend_from_slice(&(n as u32).to_le_bytes());
    }
    b.extend_from_slice(&pm.sample_spacing.to_le_bytes());
    let f = |b: &mut Vec<u8>, x: f32| b.extend_from_slice(&x.to_le_bytes());
    let u = |b: &mut Vec<u8>, x: u32| b.extend_from_slice(&x.to_le_bytes());
    pm.positions.iter().flatten().for_each(|&x| f(&mut b, x));
    pm.wedge_position.iter().for_each(|&x| u(&mut b, x));
    pm.uvs.iter().flatten().for_each(|&x| f(&mut b, x));
    pm.normals.iter().flatten().for_each(|&x| f(&mut b, x));
    pm.collapse_to.iter().for_each(|&x| u(&mut b, x));
    pm.triangles.iter().flatten().for_each(|&x| u(&mut b, x));
    for l in &pm.levels {
        u(&mut b, l.wedges);
        u(&mut b, l.triangles);
        f(&mut b, l.error);
        f(&mut b, l.cost);
        b.push(l.flags);
    }
    let sum = fnv1a(&b);
    b.extend_from_slice(&sum.to_le_bytes());
    b
}

/// Writes a PM file atomically (temporary file, then rename).
pub fn write(pm: &PmMesh, path: &Path) -> Result<(), PmError> {
    let io = |action, source| PmError::Io {
        path: path.to_path_buf(),
        action,
        source,
    };
    let tmp = path.with_extension("pm.tmp");
    std::fs::write(&tmp, to_bytes(pm)).map_err(|e| io("write", e))?;
    std::fs::rename(&tmp, path).map_err(|e| io("rename into place", e))
}

/// Reads and validates a PM file.
pub fn read(path: &Path) -> Result<PmMesh, PmError> {
    let bytes = std::fs::read(path).map_err(|source| PmError::Io {
        path: path.to_path_buf(),
        action: "read",
        source,
    })?;
    from_bytes(&bytes, path)
}

struct Cursor<'a> {
    b: &'a [u8],
    at: usize,
}

impl Cursor<'_> {
    fn u8(&mut self) -> u8 {
        self.at += 1;
        self.b[self.at - 1]
    }
    fn u32(&mut self) -> u32 {
        let v = u32::from_le_bytes(self.b[self.at..self.at + 4].try_into().unwrap_or([0; 4]));
        self.at += 4;
        v
    }
    fn f32(&mut self) -> f32 {
        f32::from_bits(self.u32())
    }
}

/// Parses and validates PM bytes; `path` only names errors.
pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<PmMesh, PmError> {
    let p = || path.to_path_buf();
    if bytes.len() < 8 || &bytes[..8] != MAGIC {
        return Err(PmError::Magic { path: p() });
    }
    if bytes.len() < HEADER_BYTES + 8 {
        return Err(PmError::Length {
            path: p(),
            length: bytes.len(),
            expected: (HEADER_BYTES + 8) as u64,
        });
    }
    let mut c = Cursor { b: bytes, at: 8 };
    let version = c.u32();
    if version != VERSION {
        return Err(PmError::Version {
            path: p(),
            found: version,
        });
    }
    let field = |field: &'static str, message: String| PmError::Field {
        path: p(),
        field,
        message,
    };
    let cost_code = c.u8();
    let cost = CostKind::from_code(cost_code)
        .ok_or_else(|| field("cost", format!("unknown cost code {cost_code} (0, 1 or 2)")))?;
    let attrs = c.u8();
    if attrs > 3 {
        return Err(field("attributes", format!("unknown bits in {attrs:#04x}")));
    }
    let _reserved = [c.u8(), c.u8()];
    let np = c.u32();
    let nw = c.u32();
    let nt = c.u32();
    for (name, n) in [("positions", np), ("wedges", nw), ("triangles", nt)] {
        if n > MAX_ELEMENTS {
            return Err(field(name, format!("{n} exceeds the limit {MAX_ELEMENTS}")));
        }
    }
    let (np, nw, nt) = (np as u64, nw as u64, nt as u64);
    let has_uv = attrs & 1 != 0;
    let has_normal = attrs & 2 != 0;
    let expected = HEADER_BYTES as u64
        + np * 12
        + nw * 4
        + if has_uv { nw * 8 } else { 0 }
        + if has_normal { nw * 12 } else { 0 }
        + nw * 4
        + nt * 12
        + np * LEVEL_BYTES as u64
        + 8;
    if bytes.len() as u64 != expected {
        return Err(PmError::Length {
            path: p(),
            length: bytes.len(),
            expected,
        });
    }
    let body = bytes.len() - 8;
    let stored = u64::from_le_bytes(bytes[body..].try_into().unwrap_or([0; 8]));
    let computed = fnv1a(&bytes[..body]);
    if stored != computed {
        return Err(PmError::Checksum {
            path: p(),
            stored,
            computed,
        });
    }
    let (np, nw, nt) = (np as usize, nw as usize, nt as usize);
    let sample_spacing = c.f32();
    let positions = (0..np).map(|_| [c.f32(), c.f32(), c.f32()]).collect();
    let wedge_position = (0..nw).map(|_| c.u32()).collect();
    let uvs = if has_uv {
        (0..nw).map(|_| [c.f32(), c.f32()]).collect()
    } else {
        Vec::new()
    };
    let normals = if has_normal {
        (0..nw).map(|_| [c.f32(), c.f32(), c.f32()]).collect()
    } else {
        Vec::new()
    };
    let collapse_to = (0..nw).map(|_| c.u32()).collect();
    let triangles = (0..nt).map(|_| [c.u32(), c.u32(), c.u32()]).collect();
    let levels = (0..np)
        .map(|_| Level {
            wedges: c.u32(),
            triangles: c.u32(),
            error: c.f32(),
            cost: c.f32(),
            flags: c.u8(),
        })
        .collect();
    let pm = PmMesh {
        cost,
        sample_spacing,
        positions,
        wedge_position,
        uvs,
        normals,
        collapse_to,
        triangles,
        levels,
    };
    pm.validate().map_err(|(f, m)| field(f, m))?;
    Ok(pm)
}

impl PmMesh {
    /// Checks every invariant the run time relies on; the error names the field.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let np = self.positions.len();
        let nw = self.wedge_position.len();
        if np == 0 {
            return Err(("positions", "no positions".into()));
        }
        if !(self.sample_spacing.is_finite() && self.sample_spacing > 0.0) {
            return Err((
                "sample_spacing",
                format!("{} is not a positive number", self.sample_spacing),
            ));
        }
        if let Some(i) = self
            .positions
            .iter()
            .position(|p| p.iter().any(|x| !x.is_finite()))
        {
            return Err(("positions", format!("position {i} is not finite")));
        }
        if self.levels.len() != np || self.collapse_to.len() != nw {
            return Err(("levels", "array lengths disagree with the header".into()));
        }
        if (!self.uvs.is_empty() && self.uvs.len() != nw)
            || (!self.normals.is_empty() && self.normals.len() != nw)
        {
            return Err((
                "attributes",
                "attribute arrays do not match the wedge count".into(),
            ));
        }
        if self
            .uvs
            .iter()
            .flatten()
            .chain(self.normals.iter().flatten())
            .any(|x| !x.is_finite())
        {
            return Err(("attributes", "a UV or normal is not finite".into()));
        }
        // Wedges grouped by position, every position with at least one wedge.
        let mut expect = 0u32;
        let mut first_of = vec![0u32; np + 1];
        for (w, &p) in self.wedge_position.iter().enumerate() {
            if p as usize >= np {
                return Err((
                    "wedge_position",
                    format!("wedge {w} has position {p}, beyond the {np} positions"),
                ));
            }
            if p == expect {
                first_of[p as usize] = w as u32;
                expect += 1;
            } else if expect == 0 || p != expect - 1 {
                return Err((
                    "wedge_position",
                    format!(
                        "wedge {w} has position {p}; wedges must be grouped by position in level order, every position having one"
                    ),
                ));
            }
        }
        if expect as usize != np {
            return Err((
                "wedge_position",
                format!("wedges cover {expect} of {np} positions"),
            ));
        }
        first_of[np] = nw as u32;
        for (i, l) in self.levels.iter().enumerate() {
            if l.wedges != first_of[i + 1] {
                return Err((
                    "levels.wedges",
                    format!(
                        "level {} has {} wedges, the layout gives {}",
                        i + 1,
                        l.wedges,
                        first_of[i + 1]
                    ),
                ));
            }
            if !(l.error.is_finite() && l.error >= 0.0 && l.cost.is_finite()) {
                return Err((
                    "levels.error",
                    format!("level {} has error {} and cost {}", i + 1, l.error, l.cost),
                ));
            }
            if l.flags > 3 {
                return Err((
                    "levels.flags",
                    format!("level {} has unknown flags {:#04x}", i + 1, l.flags),
                ));
            }
            if i > 0 && l.triangles < self.levels[i - 1].triangles {
                return Err((
                    "levels.triangles",
                    format!("level {} draws fewer triangles than level {i}", i + 1),
                ));
            }
        }
        if self.levels[0].triangles != 0
            || self.levels[np - 1].triangles as usize != self.triangles.len()
        {
            return Err((
                "levels.triangles",
                "level 1 must draw none and the last level all triangles".into(),
            ));
        }
        if self.levels[np - 1].error != 0.0 {
            return Err(("levels.error", "the full level must have error 0".into()));
        }
        for (w, &t) in self.collapse_to.iter().enumerate() {
            let p = self.wedge_position[w] as usize;
            let ok = if p == 0 {
                t == u32::MAX
            } else {
                t < first_of[p]
            };
            if !ok {
                return Err((
                    "collapse_to",
                    format!(
                        "wedge {w} (position {p}) collapses onto {t}, not a wedge of a lower position"
                    ),
                ));
            }
        }
        // Each triangle, at the last level that draws it, has three distinct positions (then it
        // has at every finer level too: levels only merge positions).
        let mut p = 1usize;
        for (t, tri) in self.triangles.iter().enumerate() {
            if tri.iter().any(|&w| w as usize >= nw) {
                return Err((
                    "triangles",
                    format!("triangle {t} names a wedge beyond {nw}"),
                ));
            }
            while self.levels[p - 1].triangles as usize <= t {
                p += 1;
            }
            let live = self.levels[p - 1].wedges;
            let pos = tri.map(|w| self.wedge_position[self.live_wedge(w, live) as usize]);
            if pos[0] == pos[1] || pos[1] == pos[2] || pos[0] == pos[2] {
                return Err((
                    "triangles",
                    format!(
                        "triangle {t} is degenerate at level {p}, the last level that draws it"
                    ),
                ));
            }
        }
        Ok(())
    }
}
