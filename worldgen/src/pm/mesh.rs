//! The indexed triangle mesh every progressive-mesh input becomes: welded positions, wedges
//! (render vertices: a position plus the attributes of one side of a seam) and triangles over
//! wedges.
//!
//! Welding follows the seed's third option: corners at the same position share one *position*,
//! and corners that also agree on texture coordinates and normal share one *wedge*. A seam (UV or
//! normal crease) is therefore two wedges over one position; an edge collapse moves every wedge of
//! the removed position at once, so seams never tear.

use std::collections::{HashMap, HashSet};

/// One corner of an input polygon: a position and optional attributes, by value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    pub position: [f32; 3],
    pub uv: Option<[f32; 2]>,
    pub normal: Option<[f32; 3]>,
}

/// A welded triangle mesh.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Distinct positions (metres, or the model's unit).
    pub positions: Vec<[f32; 3]>,
    /// For every wedge, its position index.
    pub wedge_position: Vec<u32>,
    /// Per-wedge texture coordinates (empty when the input has none).
    pub uvs: Vec<[f32; 2]>,
    /// Per-wedge normals (empty when the input has none).
    pub normals: Vec<[f32; 3]>,
    /// Triangles over wedges, counter-clockwise seen from the front.
    pub triangles: Vec<[u32; 3]>,
}

/// What welding dropped, for the builder's report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WeldReport {
    /// Input triangles (after fan triangulation of polygons).
    pub input_triangles: usize,
    /// Triangles dropped because two corners share a position (they cannot be drawn).
    pub degenerate_dropped: usize,
    /// Triangles dropped because the same wedges already form a triangle in the same orientation.
    pub duplicates_dropped: usize,
    /// Input corners that welded onto an earlier position.
    pub welded_corners: usize,
}

/// Bit pattern of a float with -0.0 folded onto +0.0, so welding treats them as equal.
fn key(x: f32) -> u32 {
    if x == 0.0 { 0 } else { x.to_bits() }
}

impl TriMesh {
    /// Welds triangles given as corners by value. Positions weld when bit-equal (after folding
    /// -0.0); wedges weld when position, UV and normal are all equal. Position-degenerate and
    /// repeated triangles are dropped and counted.
    pub fn weld(triangles: &[[Corner; 3]]) -> (Self, WeldReport) {
        let has_uv = triangles.iter().flatten().any(|c| c.uv.is_some());
        let has_normal = triangles.iter().flatten().any(|c| c.normal.is_some());
        let mut mesh = TriMesh::default();
        let mut report = WeldReport {
            input_triangles: triangles.len(),
            ..WeldReport::default()
        };
        let mut position_ids: HashMap<[u32; 3], u32> = HashMap::new();
        let mut wedge_ids: HashMap<(u32, [u32; 2], [u32; 3]), u32> = HashMap::new();
        let mut seen: HashSet<[u32; 3]> = HashSet::new();
        for tri in triangles {
            let mut wedges = [0u32; 3];
            let mut positions = [0u32; 3];
            for (k, c) in tri.iter().enumerate() {
                let pk = c.position.map(key);
                let next = mesh.positions.len() as u32;
                let pid = *position_ids.entry(pk).or_insert_with(|| {
                    mesh.positions.push(c.position);
                    next
                });
                if pid != next {
                    report.welded_corners += 1;
                }
                let uv = if has_uv {
                    c.uv.unwrap_or([0.0; 2])
                } else {
                    [0.0; 2]
                };
                let normal = if has_normal {
                    c.normal.unwrap_or([0.0; 3])
                } else {
                    [0.0; 3]
                };
                let wk = (pid, uv.map(key), normal.map(key));
                let next_wedge = mesh.wedge_position.len() as u32;
                let wid = *wedge_ids.entry(wk).or_insert_with(|| {
                    mesh.wedge_position.push(pid);
                    if has_uv {
                        mesh.uvs.push(uv);
                    }
                    if has_normal {
                        mesh.normals.push(normal);
                    }
                    next_wedge
                });
                wedges[k] = wid;
                positions[k] = pid;
            }
            if positions[0] == positions[1]
                || positions[1] == positions[2]
                || positions[0] == positions[2]
            {
                report.degenerate_dropped += 1;
                continue;
            }
            // Same oriented triangle: rotate so the smallest wedge comes first.
            let r = (0..3).min_by_key(|&i| wedges[i]).unwrap_or(0);
            let canon = [wedges[r], wedges[(r + 1) % 3], wedges[(r + 2) % 3]];
            if !seen.insert(canon) {
                report.duplicates_dropped += 1;
                continue;
            }
            mesh.triangles.push(wedges);
        }
        (mesh, report)
    }

    /// Position of a wedge.
    pub fn wedge_xyz(&self, wedge: u32) -> [f32; 3] {
        self.positions[self.wedge_position[wedge as usize] as usize]
    }

    /// Triangles as position triples (what the geometry sees).
    pub fn position_triangles(&self) -> Vec<[u32; 3]> {
        self.triangles
            .iter()
            .map(|t| t.map(|w| self.wedge_position[w as usize]))
            .collect()
    }

    /// Axis-aligned bounds of the positions, `([0; 3], [0; 3])` when empty.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        if self.positions.is_empty() {
            return ([0.0; 3], [0.0; 3]);
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Length of the bounds' diagonal.
    pub fn diagonal(&self) -> f32 {
        let (lo, hi) = self.bounds();
        (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt()
    }
}
