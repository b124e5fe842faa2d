//! Dense two-sided Hausdorff measurement between two triangle sets: grid samples on each side
//! (spacing a fraction of the diagonal), each measured exactly against the other side. This is a
//! *measurement* (a lower estimate of the true distance that converges as the spacing shrinks),
//! used to compare simplifiers at equal triangle counts; the PM's stored error is a bound.
//! [`hausdorff_bound`] adds the samples' covering radius, which makes it an upper bound.

use super::bvh::TriangleBvh;
use super::geom::{grid_samples, v3};
use glam::DVec3;

/// Triangles as three points each.
pub type Soup = Vec<[DVec3; 3]>;

/// Triangles of an indexed mesh as point triples.
pub fn soup(positions: &[[f32; 3]], indices: &[u32]) -> Soup {
    indices
        .chunks_exact(3)
        .map(|t| [0, 1, 2].map(|k| v3(positions[t[k] as usize])))
        .collect()
}

/// Triangles of level `p` of a progressive mesh.
pub fn level_soup(pm: &super::PmMesh, p: usize) -> Soup {
    let mut idx = Vec::new();
    pm.indices_at(p, &mut idx);
    for w in &mut idx {
        *w = pm.wedge_position[*w as usize];
    }
    soup(&pm.positions, &idx)
}

/// Triangles of a welded mesh.
pub fn mesh_soup(mesh: &super::TriMesh) -> Soup {
    soup(&mesh.positions, &mesh.position_triangles().concat())
}

/// One direction: the largest distance from a grid sample of `from` to `to`, and the samples'
/// covering radius (every point of `from` lies within it of a sample).
fn sampled_side(from: &Soup, to: &TriangleBvh, spacing: f64) -> (f64, f64) {
    let mut points = Vec::new();
    let mut cover = 0.0f64;
    for [a, b, c] in from {
        cover = cover.max(grid_samples(*a, *b, *c, spacing, |p| points.push(p)));
    }
    (to.max_distance(points), cover)
}

/// [`sampled_side`] from `a` to `b` and from `b` to `a` (both non-empty).
fn both_sides(a: &Soup, b: &Soup, spacing: f64) -> [(f64, f64); 2] {
    let ta = TriangleBvh::new(a.clone());
    let tb = TriangleBvh::new(b.clone());
    [sampled_side(a, &tb, spacing), sampled_side(b, &ta, spacing)]
}

/// The distance when a side is empty: 0 between two empty sets, infinite to an empty one.
fn distance_if_empty(a: &Soup, b: &Soup) -> Option<f64> {
    match (a.is_empty(), b.is_empty()) {
        (true, true) => Some(0.0),
        (false, false) => None,
        _ => Some(f64::INFINITY),
    }
}

/// Two-sided measured Hausdorff distance between `a` and `b` (`INFINITY` if one is empty and the
/// other is not).
pub fn hausdorff(a: &Soup, b: &Soup, spacing: f64) -> f64 {
    distance_if_empty(a, b).unwrap_or_else(|| {
        let [ab, ba] = both_sides(a, b, spacing);
        ab.0.max(ba.0)
    })
}

/// An upper bound of the two-sided Hausdorff distance between `a` and `b`: on each side, the
/// largest exact distance from a grid sample to the other side plus the samples' covering radius
/// (every point lies within that radius of a sample, and the distance to a set is 1-Lipschitz).
pub fn hausdorff_bound(a: &Soup, b: &Soup, spacing: f64) -> f64 {
    distance_if_empty(a, b).unwrap_or_else(|| {
        let [ab, ba] = both_sides(a, b, spacing);
        (ab.0 + ab.1).max(ba.0 + ba.1)
    })
}
