//! Wavefront OBJ reader for progressive-mesh input: `v`, `vt`, `vn` and `f` lines (polygons are
//! fan-triangulated, negative indices count from the end); groups, smoothing groups, materials,
//! lines and points are ignored. Written by hand rather than with `tobj` so that every error
//! names the file and the line, and so that nothing but geometry is read. [`to_text`] writes
//! triangles back (positions and texture coordinates), e.g. for generated building meshes.

use super::mesh::{Corner, TriMesh, WeldReport};
use std::path::{Path, PathBuf};

/// Most vertices, attributes or faces an OBJ may declare (each kind), checked while reading.
pub const MAX_OBJ_ELEMENTS: usize = 50_000_000;

/// Why an OBJ could not be read. Every variant names the file; syntax errors name the line.
#[derive(Debug, thiserror::Error)]
pub enum ObjError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Syntax {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{path}: no triangles (the file declares {vertices} vertices and no usable `f` line)")]
    Empty { path: PathBuf, vertices: usize },
}

fn floats<const N: usize>(
    words: &mut std::str::SplitWhitespace<'_>,
    what: &str,
) -> Result<[f32; N], String> {
    let mut out = [0.0f32; N];
    for (k, slot) in out.iter_mut().enumerate() {
        let w = words
            .next()
            .ok_or_else(|| format!("`{what}` needs {N} numbers, found {k}"))?;
        let x: f32 = w
            .parse()
            .map_err(|_| format!("`{what}` component {}: {w:?} is not a number", k + 1))?;
        if !x.is_finite() {
            return Err(format!("`{what}` component {}: {w:?} is not finite", k + 1));
        }
        *slot = x;
    }
    Ok(out)
}

/// Resolves a 1-based (or negative, relative) OBJ index against `count` elements.
fn resolve(word: &str, count: usize, what: &str) -> Result<usize, String> {
    let i: i64 = word
        .parse()
        .map_err(|_| format!("{what} index {word:?} is not an integer"))?;
    let idx = match i.cmp(&0) {
        std::cmp::Ordering::Greater => i - 1,
        std::cmp::Ordering::Less => count as i64 + i,
        std::cmp::Ordering::Equal => {
            return Err(format!("{what} index 0 (OBJ indices start at 1)"));
        }
    };
    if idx < 0 || idx >= count as i64 {
        return Err(format!(
            "{what} index {i} is out of range ({count} declared so far)"
        ));
    }
    Ok(idx as usize)
}

/// Parses OBJ text into triangles of corners. `path` only names errors.
pub fn parse(text: &str, path: &Path) -> Result<Vec<[Corner; 3]>, ObjError> {
    let mut v: Vec<[f32; 3]> = Vec::new();
    let mut vt: Vec<[f32; 2]> = Vec::new();
    let mut vn: Vec<[f32; 3]> = Vec::new();
    let mut triangles: Vec<[Corner; 3]> = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        let syntax = |message: String| ObjError::Syntax {
            path: path.to_path_buf(),
            line: n + 1,
            message,
        };
        let line = raw.split('#').next().unwrap_or("");
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else { continue };
        let over = |len: usize| len >= MAX_OBJ_ELEMENTS;
        match tag {
            "v" => {
                if over(v.len()) {
                    return Err(syntax(format!("more than {MAX_OBJ_ELEMENTS} vertices")));
                }
                v.push(floats::<3>(&mut words, "v").map_err(syntax)?);
            }
            "vt" => {
                if over(vt.len()) {
                    return Err(syntax(format!("more than {MAX_OBJ_ELEMENTS} `vt`")));
                }
                // A missing v component defaults to 0 (1D textures).
                let u = floats::<1>(&mut words, "vt").map_err(syntax)?[0];
                let w = match words.next() {
                    Some(w) => {
                        w.parse::<f32>()
                            .ok()
                            .filter(|x| x.is_finite())
                            .ok_or_else(|| {
                                syntax(format!("`vt` component 2: {w:?} is not a number"))
                            })?
                    }
                    None => 0.0,
                };
                vt.push([u, w]);
            }
            "vn" => {
                if over(vn.len()) {
                    return Err(syntax(format!("more than {MAX_OBJ_ELEMENTS} `vn`")));
                }
                vn.push(floats::<3>(&mut words, "vn").map_err(syntax)?);
            }
            "f" => {
                if over(triangles.len()) {
                    return Err(syntax(format!("more than {MAX_OBJ_ELEMENTS} faces")));
                }
                let mut corners = Vec::with_capacity(4);
                for word in words {
                    let mut parts = word.split('/');
                    let vi =
                        resolve(parts.next().unwrap_or(""), v.len(), "vertex").map_err(syntax)?;
                    let ti = match parts.next() {
                        Some("") | None => None,
                        Some(t) => Some(resolve(t, vt.len(), "texture").map_err(syntax)?),
                    };
                    let ni = match parts.next() {
                        Some("") | None => None,
                        Some(t) => Some(resolve(t, vn.len(), "normal").map_err(syntax)?),
                    };
                    if parts.next().is_some() {
                        return Err(syntax(format!(
                            "face corner {word:?} has more than 3 indices"
                        )));
                    }
                    corners.push(Corner {
                        position: v[vi],
                        uv: ti.map(|t| vt[t]),
                        normal: ni.map(|t| vn[t]),
                    });
                }
                if corners.len() < 3 {
                    return Err(syntax(format!(
                        "a face needs at least 3 corners, found {}",
                        corners.len()
                    )));
                }
                for k in 1..corners.len() - 1 {
                    triangles.push([corners[0], corners[k], corners[k + 1]]);
                }
            }
            // Geometry we do not use and bookkeeping lines.
            "o" | "g" | "s" | "usemtl" | "mtllib" | "l" | "p" | "vp" => {}
            other => {
                return Err(syntax(format!(
                    "unknown statement {other:?} (expected v, vt, vn, f, o, g, s, usemtl, mtllib)"
                )));
            }
        }
    }
    Ok(triangles)
}

/// Reads and welds an OBJ file.
pub fn load(path: &Path) -> Result<(TriMesh, WeldReport), ObjError> {
    let bytes = std::fs::read(path).map_err(|source| ObjError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let text = String::from_utf8_lossy(&bytes);
    let triangles = parse(&text, path)?;
    let (mesh, report) = TriMesh::weld(&triangles);
    if mesh.triangles.is_empty() {
        return Err(ObjError::Empty {
            path: path.to_path_buf(),
            vertices: mesh.positions.len(),
        });
    }
    Ok((mesh, report))
}

/// OBJ text of `triangles`: `v`, `vt` and `vn` lines per corner (attributes where every corner
/// of the triangle has them) and an `f` line per triangle. Floats are written in their shortest
/// exact form, so reading the text back gives the same bits (and the same welding).
pub fn to_text(triangles: &[[Corner; 3]]) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let (mut uvs, mut normals) = (0usize, 0usize);
    for (t, tri) in triangles.iter().enumerate() {
        let with_uv = tri.iter().all(|c| c.uv.is_some());
        let with_normal = tri.iter().all(|c| c.normal.is_some());
        let mut refs = Vec::with_capacity(3);
        for (k, c) in tri.iter().enumerate() {
            let [x, y, z] = c.position;
            let _ = writeln!(out, "v {x:?} {y:?} {z:?}");
            let mut r = format!("{}", 3 * t + k + 1);
            match (c.uv.filter(|_| with_uv), c.normal.filter(|_| with_normal)) {
                (Some([u, v]), n) => {
                    let _ = writeln!(out, "vt {u:?} {v:?}");
                    uvs += 1;
                    let _ = write!(r, "/{uvs}");
                    if let Some([a, b, cc]) = n {
                        let _ = writeln!(out, "vn {a:?} {b:?} {cc:?}");
                        normals += 1;
                        let _ = write!(r, "/{normals}");
                    }
                }
                (None, Some([a, b, cc])) => {
                    let _ = writeln!(out, "vn {a:?} {b:?} {cc:?}");
                    normals += 1;
                    let _ = write!(r, "//{normals}");
                }
                (None, None) => {}
            }
            refs.push(r);
        }
        let _ = writeln!(out, "f {}", refs.join(" "));
    }
    out
}
