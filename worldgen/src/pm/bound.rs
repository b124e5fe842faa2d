//! The stored error of every prefix: an upper bound on the two-sided Hausdorff distance between
//! the mesh at that level and the full mesh, computed while replaying the collapse order.
//!
//! - **Full mesh to level.** The full mesh is covered by grid samples (every point within `r_a`
//!   of one, see [`grid_samples`]). Each sample keeps a face of the current level and its
//!   distance to it; when a collapse changes faces, their samples are reassigned to the nearest
//!   face around the kept vertex. The distance to one face is at least the distance to the whole
//!   level, so `max(sample bounds) + r_a` bounds this side (distance is 1-Lipschitz).
//! - **Level to full mesh.** Each face of the level, when it is created, is sampled on its own
//!   grid (spacing a quarter of the current error, never under the full mesh's spacing) and every
//!   sample is measured exactly against the full mesh ([`TriangleBvh`]); the face's bound is the
//!   largest sample distance plus the face's covering radius.
//!
//! The stored value is the larger side. It is never the collapse cost; tests compare it with an
//! independent dense measurement. A level without triangles draws nothing; it stores the
//! diagonal of the bounds.

use super::build::CollapseOrder;
use super::bvh::TriangleBvh;
use super::geom::{TriangleBall, grid_samples, point_triangle_distance_sq, v3};
use super::mesh::TriMesh;
use glam::DVec3;

/// Max-segment tree over faces.
struct MaxTree {
    n: usize,
    v: Vec<f64>,
}

impl MaxTree {
    fn new(n: usize) -> Self {
        MaxTree {
            n,
            v: vec![f64::NEG_INFINITY; 2 * n.max(1)],
        }
    }
    fn set(&mut self, i: usize, x: f64) {
        let mut k = i + self.n;
        self.v[k] = x;
        while k > 1 {
            k /= 2;
            self.v[k] = self.v[2 * k].max(self.v[2 * k + 1]);
        }
    }
    fn max(&self) -> f64 {
        if self.n == 0 {
            f64::NEG_INFINITY
        } else {
            self.v[1]
        }
    }
}

/// Largest local subset of the full mesh searched directly (beyond it, the hierarchy).
const LOCAL_LIMIT: usize = 256;

/// A triangle of the full mesh with its bounding ball.
type BallTriangle = ([DVec3; 3], TriangleBall);

/// Largest distance from `points` to the nearest of `tris` (exact over that subset), measuring
/// in full only points that could raise the running maximum. Each point starts from the triangle
/// nearest to the previous point (neighbouring samples), and triangles whose ball is already
/// farther than the best distance found are skipped: the result is the same as a full scan.
fn local_max_distance(points: &[DVec3], tris: &[BallTriangle]) -> f64 {
    if tris.is_empty() {
        return if points.is_empty() {
            0.0
        } else {
            f64::INFINITY
        };
    }
    let mut worst_sq = 0.0f64;
    let mut hint = 0usize;
    for &p in points {
        let [a, b, c] = tris[hint].0;
        let mut best = point_triangle_distance_sq(p, a, b, c);
        let mut best_i = hint;
        if best > worst_sq {
            for (i, ([a, b, c], ball)) in tris.iter().enumerate() {
                if i == hint || ball.lower_bound_sq(p) >= best {
                    continue;
                }
                let d = point_triangle_distance_sq(p, *a, *b, *c);
                if d < best {
                    best = d;
                    best_i = i;
                    if best <= worst_sq {
                        break;
                    }
                }
            }
        }
        hint = best_i;
        worst_sq = worst_sq.max(best);
    }
    worst_sq.sqrt()
}

/// The nearest of `cands` to `p` (lowest index among equal distances, as a scan in order would
/// find), starting from `hint`: candidates whose ball is farther than the best so far are skipped.
/// Returns (squared distance, index).
fn nearest_candidate(p: DVec3, cands: &[BallTriangle], hint: usize) -> (f64, usize) {
    let [a, b, c] = cands[hint].0;
    let mut best = (point_triangle_distance_sq(p, a, b, c), hint);
    for (k, ([a, b, c], ball)) in cands.iter().enumerate() {
        if k == hint || ball.lower_bound_sq(p) > best.0 {
            continue;
        }
        let d = point_triangle_distance_sq(p, *a, *b, *c);
        if d < best.0 || (d == best.0 && k < best.1) {
            best = (d, k);
        }
    }
    best
}

/// Moves each orphaned sample (with the face that held it) to its nearest candidate face,
/// recording its distance (`samples`: positions and distances); faces that receive samples are
/// added to `touched`.
fn reassign(
    orphans: &[(u32, u32)],
    candidates: &[u32],
    cand_points: &[BallTriangle],
    samples: (&[DVec3], &mut [f64]),
    face_samples: &mut [Vec<u32>],
    touched: &mut Vec<u32>,
) {
    let (sample_pos, sample_d) = samples;
    // Start from the sample's old face when it survived (moved), else from the previous
    // orphan's face (samples of one face are neighbours).
    let mut hint = 0usize;
    let mut last_face = u32::MAX;
    for &(smp, old_face) in orphans {
        if old_face != last_face {
            last_face = old_face;
            if let Some(k) = candidates.iter().position(|&t| t == old_face) {
                hint = k;
            }
        }
        let (best, k) = nearest_candidate(sample_pos[smp as usize], cand_points, hint);
        hint = k;
        let best_face = candidates[k];
        sample_d[smp as usize] = best.sqrt();
        face_samples[best_face as usize].push(smp);
        if !touched.contains(&best_face) {
            touched.push(best_face);
        }
    }
}

/// The original triangles near `faces` (the faces around the kept vertex) into `local`: those
/// around the faces' corners (`mesh`: the level's faces by position, and each original
/// position's original triangles), then those whose samples the faces hold (`samples`: each
/// face's samples, each sample's original triangle). Stops past [`LOCAL_LIMIT`], where the
/// caller uses the hierarchy whatever else the subset would hold. `marks` (per original
/// triangle, and this call's stamp) keeps each triangle once.
fn gather_local(
    faces: &[u32],
    mesh: (&[[u32; 3]], &[Vec<u32>]),
    samples: (&[Vec<u32>], &[u32]),
    full_balls: &[BallTriangle],
    marks: (&mut [u32], u32),
    local: &mut Vec<BallTriangle>,
) {
    let (tri_p, original_ring) = mesh;
    let (face_samples, sample_tri) = samples;
    let (mark, stamp) = marks;
    local.clear();
    let mut add = |o: u32, local: &mut Vec<BallTriangle>| {
        if mark[o as usize] != stamp {
            mark[o as usize] = stamp;
            local.push(full_balls[o as usize]);
        }
        local.len() > LOCAL_LIMIT
    };
    for &f in faces {
        for p in tri_p[f as usize] {
            for &o in &original_ring[p as usize] {
                if add(o, local) {
                    return;
                }
            }
        }
        for &smp in &face_samples[f as usize] {
            if add(sample_tri[smp as usize], local) {
                return;
            }
        }
    }
}

/// Per-level error bounds: `errors[s]` is the bound after `s` collapses (`errors[0] == 0`).
pub fn level_errors(
    mesh: &TriMesh,
    order: &CollapseOrder,
    sample_spacing: f64,
    progress: &mut dyn FnMut(usize),
) -> Vec<f64> {
    let pos: Vec<DVec3> = mesh.positions.iter().map(|&p| v3(p)).collect();
    let mut tri_p = mesh.position_triangles();
    let nt = tri_p.len();
    let diag = mesh.diagonal() as f64;
    let full: Vec<[DVec3; 3]> = tri_p.iter().map(|t| t.map(|i| pos[i as usize])).collect();
    let full_balls: Vec<BallTriangle> = full
        .iter()
        .map(|&[a, b, c]| ([a, b, c], TriangleBall::new(a, b, c)))
        .collect();
    let bvh = TriangleBvh::new(full.clone());
    let mut alive = vec![true; nt];
    let mut pos_tris = vec![Vec::new(); pos.len()];
    for (t, tri) in tri_p.iter().enumerate() {
        for &p in tri {
            pos_tris[p as usize].push(t as u32);
        }
    }
    let original_ring = pos_tris.clone();
    // Samples of the full mesh, each with its current face and distance bound.
    let mut sample_pos = Vec::new();
    let mut sample_tri: Vec<u32> = Vec::new();
    let mut face_samples: Vec<Vec<u32>> = vec![Vec::new(); nt];
    let mut r_a = 0.0f64;
    for (t, [a, b, c]) in full.iter().enumerate() {
        r_a = r_a.max(grid_samples(*a, *b, *c, sample_spacing, |p| {
            face_samples[t].push(sample_pos.len() as u32);
            sample_pos.push(p);
            sample_tri.push(t as u32);
        }));
    }
    let mut sample_d = vec![0.0f64; sample_pos.len()];
    let mut tree_a = MaxTree::new(nt);
    let mut tree_b = MaxTree::new(nt);
    for t in 0..nt {
        tree_a.set(t, 0.0);
        tree_b.set(t, 0.0);
    }
    let mut live_faces = nt;
    let mut errors = Vec::with_capacity(order.collapses.len() + 1);
    errors.push(0.0);
    let mut last = 0.0f64;
    let face_points = |tri: [u32; 3]| tri.map(|i| pos[i as usize]);
    let mut scratch: Vec<DVec3> = Vec::new();
    let mut local: Vec<BallTriangle> = Vec::new();
    // Orphaned samples with the face that held them.
    let mut orphans: Vec<(u32, u32)> = Vec::new();
    let mut mark = vec![0u32; nt];
    let mut stamp = 0u32;
    for (step, c) in order.collapses.iter().enumerate() {
        let (u, v) = (c.removed, c.kept);
        let tris_u = std::mem::take(&mut pos_tris[u as usize]);
        if tris_u.is_empty() {
            errors.push(if live_faces == 0 { diag } else { last });
            continue;
        }
        orphans.clear();
        let mut moved = Vec::new();
        for &t in &tris_u {
            orphans.extend(face_samples[t as usize].drain(..).map(|smp| (smp, t)));
            if tri_p[t as usize].contains(&v) {
                alive[t as usize] = false;
                live_faces -= 1;
                tree_a.set(t as usize, f64::NEG_INFINITY);
                tree_b.set(t as usize, f64::NEG_INFINITY);
                for p in tri_p[t as usize] {
                    if p != u {
                        pos_tris[p as usize].retain(|&x| x != t);
                    }
                }
            } else {
                for p in &mut tri_p[t as usize] {
                    if *p == u {
                        *p = v;
                    }
                }
                pos_tris[v as usize].push(t);
                moved.push(t);
            }
        }
        // Full -> level: reassign the orphaned samples to the nearest face around v.
        let candidates: Vec<u32> = if pos_tris[v as usize].is_empty() {
            (0..nt as u32).filter(|&t| alive[t as usize]).collect()
        } else {
            pos_tris[v as usize].clone()
        };
        let cand_points: Vec<BallTriangle> = candidates
            .iter()
            .map(|&t| {
                let [a, b, c] = face_points(tri_p[t as usize]);
                ([a, b, c], TriangleBall::new(a, b, c))
            })
            .collect();
        let mut touched: Vec<u32> = moved.clone();
        if !candidates.is_empty() {
            let samples = (&sample_pos[..], &mut sample_d[..]);
            reassign(
                &orphans,
                &candidates,
                &cand_points,
                samples,
                &mut face_samples,
                &mut touched,
            );
        }
        for t in touched {
            let m = face_samples[t as usize]
                .iter()
                .map(|&smp| sample_d[smp as usize])
                .fold(0.0f64, f64::max);
            tree_a.set(t as usize, m);
        }
        // Level -> full: sample each moved face at a spacing tied to the current error and
        // measure against the full mesh. Near the kept vertex the part of the full mesh that maps
        // here is the original triangles whose samples the faces around v hold; the distance to
        // that subset bounds the distance to the whole mesh from above. A large subset (coarse
        // levels) uses the hierarchy instead.
        let spacing_b = sample_spacing.max(0.25 * last);
        stamp += 1;
        gather_local(
            &pos_tris[v as usize],
            (&tri_p, &original_ring),
            (&face_samples, &sample_tri),
            &full_balls,
            (&mut mark, stamp),
            &mut local,
        );
        for &t in &moved {
            let [a, b, cc] = face_points(tri_p[t as usize]);
            scratch.clear();
            let r = grid_samples(a, b, cc, spacing_b, |p| scratch.push(p));
            let worst = if local.len() <= LOCAL_LIMIT {
                local_max_distance(&scratch, &local)
            } else {
                bvh.max_distance(scratch.iter().copied())
            };
            tree_b.set(t as usize, worst + r);
        }
        last = if live_faces == 0 {
            diag
        } else {
            (tree_a.max() + r_a).max(tree_b.max())
        };
        errors.push(last);
        if step % 256 == 0 {
            progress(step);
        }
    }
    errors
}
