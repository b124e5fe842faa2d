//! The stateless progressive-mesh data shared by every instance of an object, in the seed's
//! layout: positions and wedges sorted so that the first `p` positions (and their wedges) are the
//! ones alive at level `p`; every wedge names the lower wedge it collapses onto; triangles sorted
//! by when they vanish (last to vanish first) and stored with their full-detail corners.

use super::bound::level_errors;
use super::build::{CollapseOrder, CostKind, collapse_order};
use super::mesh::TriMesh;

/// One level of detail: `p` live positions (the level's index + 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Level {
    /// Wedges alive at this level: the first `wedges` of [`PmMesh::wedge_position`].
    pub wedges: u32,
    /// Triangles drawn at this level: the first `triangles` of [`PmMesh::triangles`].
    pub triangles: u32,
    /// Upper bound on the two-sided Hausdorff distance to the full mesh, model units.
    pub error: f32,
    /// Cost of the collapse that leads from this level to the next coarser one (0 at level 1).
    pub cost: f32,
    /// `FLAG_*` bits of that collapse.
    pub flags: u8,
}

/// A progressive mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct PmMesh {
    pub cost: CostKind,
    /// Spacing of the error samples on the full mesh, model units.
    pub sample_spacing: f32,
    /// Positions in level order.
    pub positions: Vec<[f32; 3]>,
    /// Position of every wedge, wedges in level order (non-decreasing).
    pub wedge_position: Vec<u32>,
    /// Per-wedge UVs (empty if none).
    pub uvs: Vec<[f32; 2]>,
    /// Per-wedge normals (empty if none).
    pub normals: Vec<[f32; 3]>,
    /// The wedge each wedge collapses onto, always of a lower position; `u32::MAX` for the wedges
    /// of position 0.
    pub collapse_to: Vec<u32>,
    /// Triangles (full-detail wedges), last to vanish first.
    pub triangles: Vec<[u32; 3]>,
    /// `levels[p - 1]` describes level `p`, for `p` in `1..=positions.len()`.
    pub levels: Vec<Level>,
}

/// What a build did and how long each part took.
#[derive(Debug, Clone, Copy, Default)]
pub struct BuildTimes {
    pub collapse_s: f64,
    pub error_s: f64,
    pub assemble_s: f64,
}

/// Progress callbacks of a build: (part name, done, total).
pub type BuildProgress<'a> = &'a mut dyn FnMut(&str, usize, usize);

impl PmMesh {
    /// Builds a progressive mesh: collapse order, per-level error bounds (samples spaced
    /// `sample_fraction` x the bounds' diagonal on the full mesh), then the level layout.
    pub fn build(
        mesh: &TriMesh,
        cost: CostKind,
        sample_fraction: f64,
        progress: BuildProgress<'_>,
    ) -> (Self, BuildTimes) {
        let mut times = BuildTimes::default();
        let total = mesh.positions.len().saturating_sub(1);
        let t0 = std::time::Instant::now();
        let order = collapse_order(mesh, cost, &mut |done| {
            progress("collapse order", done, total);
        });
        times.collapse_s = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        let spacing = (mesh.diagonal() as f64 * sample_fraction).max(f64::MIN_POSITIVE);
        let errors = level_errors(mesh, &order, spacing, &mut |done| {
            progress("error bounds", done, total);
        });
        times.error_s = t1.elapsed().as_secs_f64();
        let t2 = std::time::Instant::now();
        let pm = Self::assemble(mesh, &order, &errors, spacing as f32);
        times.assemble_s = t2.elapsed().as_secs_f64();
        (pm, times)
    }

    /// Lays out a collapse order (see the module documentation).
    pub fn assemble(
        mesh: &TriMesh,
        order: &CollapseOrder,
        errors: &[f64],
        sample_spacing: f32,
    ) -> Self {
        let np = mesh.positions.len();
        // Position order: survivor, then removed positions, last removed first.
        let mut pos_order = Vec::with_capacity(np);
        if np > 0 {
            pos_order.push(order.survivor);
        }
        pos_order.extend(order.collapses.iter().rev().map(|c| c.removed));
        let mut pos_new = vec![u32::MAX; np];
        for (i, &p) in pos_order.iter().enumerate() {
            pos_new[p as usize] = i as u32;
        }
        let mut wedges_of = vec![Vec::new(); np];
        for (w, &p) in mesh.wedge_position.iter().enumerate() {
            wedges_of[p as usize].push(w as u32);
        }
        let mut wedge_new = vec![u32::MAX; mesh.wedge_position.len()];
        let mut wedge_position = Vec::with_capacity(mesh.wedge_position.len());
        let mut wedges_at = Vec::with_capacity(np);
        for (i, &p) in pos_order.iter().enumerate() {
            for &w in &wedges_of[p as usize] {
                wedge_new[w as usize] = wedge_position.len() as u32;
                wedge_position.push(i as u32);
            }
            wedges_at.push(wedge_position.len() as u32);
        }
        let old_of: Vec<u32> = {
            let mut v = vec![0u32; wedge_new.len()];
            for (old, &new) in wedge_new.iter().enumerate() {
                v[new as usize] = old as u32;
            }
            v
        };
        let collapse_to = old_of
            .iter()
            .map(|&old| {
                let t = order.wedge_target[old as usize];
                if t == u32::MAX {
                    u32::MAX
                } else {
                    wedge_new[t as usize]
                }
            })
            .collect();
        let uvs = if mesh.uvs.is_empty() {
            Vec::new()
        } else {
            old_of.iter().map(|&o| mesh.uvs[o as usize]).collect()
        };
        let normals = if mesh.normals.is_empty() {
            Vec::new()
        } else {
            old_of.iter().map(|&o| mesh.normals[o as usize]).collect()
        };
        // Triangles: vanishing step descending (stable on the input order).
        let mut tri_order: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
        tri_order.sort_by(|&a, &b| {
            order.triangle_step[b as usize].cmp(&order.triangle_step[a as usize])
        });
        let triangles: Vec<[u32; 3]> = tri_order
            .iter()
            .map(|&t| mesh.triangles[t as usize].map(|w| wedge_new[w as usize]))
            .collect();
        let steps = order.collapses.len();
        // alive_after[s]: triangles that vanish at a step later than s.
        let mut alive_after = vec![0u32; steps + 2];
        for &st in &order.triangle_step {
            if st > 0 {
                alive_after[st as usize - 1] += 1;
            }
        }
        for s in (0..=steps).rev() {
            alive_after[s] += alive_after[s + 1];
        }
        let levels = (1..=np)
            .map(|p| {
                // Level p is reached after `np - p` collapses; triangles vanishing at step s are
                // alive while s > np - p.
                let s = np - p;
                let triangles = alive_after[s];
                let next = (p >= 2 && s < steps).then(|| order.collapses[s]);
                Level {
                    wedges: wedges_at[p - 1],
                    triangles,
                    error: if s == 0 { 0.0 } else { errors[s] as f32 },
                    cost: next.map_or(0.0, |c| c.cost as f32),
                    flags: next.map_or(0, |c| c.flags),
                }
            })
            .collect();
        PmMesh {
            cost: order.kind,
            sample_spacing,
            positions: pos_order
                .iter()
                .map(|&p| mesh.positions[p as usize])
                .collect(),
            wedge_position,
            uvs,
            normals,
            collapse_to,
            triangles,
            levels,
        }
    }

    /// Number of levels (= positions).
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }
}
