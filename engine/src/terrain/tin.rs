//! An error-bounded TIN variant of a node mesh (spade Delaunay triangulation, greedy insertion
//! in the style of Garland and Heckbert's "Fast polygonal approximation of terrains").
//!
//! The TIN uses a subset of the node's grid vertices and keeps **every border vertex**, so its
//! borders are identical to the grid mesh's and the skirts (and the crack-freedom argument in
//! [`crate::terrain::mesh`]) carry over unchanged. Interior points are inserted in rounds (the worst point
//! of every triangle whose worst error exceeds the target) until every grid vertex is within the
//! target. Then `delta = max |TIN - grid mesh|` is computed exactly: both surfaces are piecewise
//! linear, so the maximum lies at a grid vertex or where a TIN edge crosses a grid line
//! (vertical, horizontal or diagonal), and all of those are evaluated. The TIN's error bound
//! against the finest surface is `grid error + delta` (triangle inequality).

use crate::terrain::bounds::interpolate_grid;
use crate::terrain::mesh::{NODE_VERTS, NodeMesh};
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

/// A grid vertex in grid units, with its index in the node mesh.
#[derive(Debug, Clone, Copy)]
struct GridPoint {
    i: u32,
    j: u32,
}

impl HasPosition for GridPoint {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        Point2::new(f64::from(self.i), f64::from(self.j))
    }
}

/// Statistics of one TIN build.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TinStats {
    pub vertices: usize,
    pub surface_triangles: usize,
    /// Exact max |TIN - grid mesh| (m).
    pub delta_m: f64,
}

/// Builds the TIN variant of `grid` with every grid vertex within `target_m` of the TIN. The
/// result has the same vertex buffer (unused vertices are simply not indexed), the TIN surface
/// triangles, the grid's skirts, and `bounds.error_m` increased by the exact delta.
pub fn build(grid: &NodeMesh, target_m: f64) -> (NodeMesh, TinStats) {
    let n = NODE_VERTS;
    let z: Vec<f32> = grid.positions[..n * n].iter().map(|p| p[2]).collect();
    let mut tri: DelaunayTriangulation<GridPoint> = DelaunayTriangulation::new();
    let mut inserted = vec![false; n * n];
    let insert = |tri: &mut DelaunayTriangulation<GridPoint>,
                  i: usize,
                  j: usize,
                  inserted: &mut Vec<bool>| {
        if !inserted[j * n + i] {
            // Grid points are distinct and finite, so insertion cannot fail.
            let _ = tri.insert(GridPoint {
                i: i as u32,
                j: j as u32,
            });
            inserted[j * n + i] = true;
        }
    };
    for t in 0..n {
        insert(&mut tri, t, 0, &mut inserted);
        insert(&mut tri, t, n - 1, &mut inserted);
        insert(&mut tri, 0, t, &mut inserted);
        insert(&mut tri, n - 1, t, &mut inserted);
    }
    loop {
        let mut worst: Vec<(usize, usize)> = Vec::new();
        for face in tri.inner_faces() {
            let v = face.vertices().map(|h| *h.data());
            let (mut best, mut at) = (target_m, None);
            for_each_grid_point_in(&v, |i, j| {
                if inserted[j * n + i] {
                    return;
                }
                let e =
                    (plane_value(&v, &z, n, i as f64, j as f64) - f64::from(z[j * n + i])).abs();
                if e > best {
                    best = e;
                    at = Some((i, j));
                }
            });
            worst.extend(at);
        }
        if worst.is_empty() {
            break;
        }
        worst.sort_unstable();
        worst.dedup();
        for (i, j) in worst {
            insert(&mut tri, i, j, &mut inserted);
        }
    }
    let delta_m = exact_delta(&tri, &z, n);
    let mut mesh = grid.clone();
    let mut indices = Vec::with_capacity(
        tri.num_inner_faces() * 3 + grid.indices.len() - grid.surface_index_count as usize,
    );
    for face in tri.inner_faces() {
        let v = face.vertices().map(|h| *h.data());
        indices.extend(v.iter().map(|p| p.j * n as u32 + p.i));
    }
    let surface = indices.len();
    indices.extend_from_slice(&grid.indices[grid.surface_index_count as usize..]);
    mesh.indices = indices.into();
    mesh.surface_index_count = surface as u32;
    mesh.bounds.error_m += delta_m;
    for b in &mut mesh.bounds.blocks {
        b.error_m += delta_m;
    }
    let stats = TinStats {
        vertices: tri.num_vertices(),
        surface_triangles: surface / 3,
        delta_m,
    };
    (mesh, stats)
}

/// The TIN triangle's plane at grid position (x, y).
fn plane_value(v: &[GridPoint; 3], z: &[f32], n: usize, x: f64, y: f64) -> f64 {
    let p = v.map(|g| {
        (
            f64::from(g.i),
            f64::from(g.j),
            f64::from(z[g.j as usize * n + g.i as usize]),
        )
    });
    let det = (p[1].1 - p[2].1) * (p[0].0 - p[2].0) + (p[2].0 - p[1].0) * (p[0].1 - p[2].1);
    let l0 = ((p[1].1 - p[2].1) * (x - p[2].0) + (p[2].0 - p[1].0) * (y - p[2].1)) / det;
    let l1 = ((p[2].1 - p[0].1) * (x - p[2].0) + (p[0].0 - p[2].0) * (y - p[2].1)) / det;
    l0 * p[0].2 + l1 * p[1].2 + (1.0 - l0 - l1) * p[2].2
}

/// Calls `f(i, j)` for every grid point inside or on the triangle.
fn for_each_grid_point_in(v: &[GridPoint; 3], mut f: impl FnMut(usize, usize)) {
    let xs = v.map(|g| g.i);
    let ys = v.map(|g| g.j);
    let (x0, x1) = (
        *xs.iter().min().unwrap_or(&0),
        *xs.iter().max().unwrap_or(&0),
    );
    let (y0, y1) = (
        *ys.iter().min().unwrap_or(&0),
        *ys.iter().max().unwrap_or(&0),
    );
    let p = v.map(|g| (i64::from(g.i), i64::from(g.j)));
    let edge = |a: (i64, i64), b: (i64, i64), x: i64, y: i64| {
        (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0)
    };
    for y in y0..=y1 {
        for x in x0..=x1 {
            let (x, y) = (i64::from(x), i64::from(y));
            let e = [
                edge(p[0], p[1], x, y),
                edge(p[1], p[2], x, y),
                edge(p[2], p[0], x, y),
            ];
            if e.iter().all(|&v| v >= 0) || e.iter().all(|&v| v <= 0) {
                f(x as usize, y as usize);
            }
        }
    }
}

/// Exact max |TIN - grid mesh|: at every grid vertex, and at every crossing of a TIN edge with
/// a grid line x = k, y = k or x - y = k.
fn exact_delta(tri: &DelaunayTriangulation<GridPoint>, z: &[f32], n: usize) -> f64 {
    let q = (n - 1) as f64;
    let mut delta = 0.0f64;
    for face in tri.inner_faces() {
        let v = face.vertices().map(|h| *h.data());
        for_each_grid_point_in(&v, |i, j| {
            delta = delta
                .max((plane_value(&v, z, n, i as f64, j as f64) - f64::from(z[j * n + i])).abs());
        });
        for e in 0..3 {
            let (a, b) = (v[e], v[(e + 1) % 3]);
            let (ax, ay, bx, by) = (
                f64::from(a.i),
                f64::from(a.j),
                f64::from(b.i),
                f64::from(b.j),
            );
            let mut check = |t: f64| {
                if t > 0.0 && t < 1.0 {
                    let (x, y) = (ax + t * (bx - ax), ay + t * (by - ay));
                    let tin = plane_value(&v, z, n, x, y);
                    let grid = interpolate_grid(z, n - 1, x.clamp(0.0, q), y.clamp(0.0, q));
                    delta = delta.max((tin - grid).abs());
                }
            };
            let (lo, hi) = (ax.min(bx).ceil() as i64, ax.max(bx).floor() as i64);
            for k in lo..=hi {
                if bx != ax {
                    check((k as f64 - ax) / (bx - ax));
                }
            }
            let (lo, hi) = (ay.min(by).ceil() as i64, ay.max(by).floor() as i64);
            for k in lo..=hi {
                if by != ay {
                    check((k as f64 - ay) / (by - ay));
                }
            }
            let (da, db) = (ax - ay, bx - by);
            let (lo, hi) = (da.min(db).ceil() as i64, da.max(db).floor() as i64);
            for k in lo..=hi {
                if db != da {
                    check((k as f64 - da) / (db - da));
                }
            }
        }
    }
    delta
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::bounds::NodeBounds;
    use crate::terrain::quadtree::NodeKey;

    fn grid_mesh(f: impl Fn(f64, f64) -> f32) -> NodeMesh {
        let n = NODE_VERTS;
        let mut positions = Vec::new();
        for j in 0..n {
            for i in 0..n {
                positions.push([i as f32, j as f32, f(i as f64, j as f64)]);
            }
        }
        NodeMesh {
            key: NodeKey::ROOT,
            origin_m: [0.0, 0.0],
            shading: vec![crate::terrain::mesh::pack_shading([0.0, 0.0, 1.0], 0); positions.len()],
            positions,
            indices: Vec::new().into(),
            surface_index_count: 0,
            bounds: NodeBounds::exact(0.0, 0.0),
            skirt_bottom_m: [0.0; 4],
            decimation: 0,
        }
    }

    #[test]
    fn a_plane_needs_only_the_border_and_a_bump_needs_more() {
        let (plane, s) = build(&grid_mesh(|x, y| (0.5 * x + 0.25 * y) as f32), 1e-4);
        assert!(s.delta_m < 1e-5, "{s:?}");
        assert_eq!(s.vertices, 4 * (NODE_VERTS - 1));
        assert_eq!(plane.indices.len() / 3, s.surface_triangles);
        let bump = |x: f64, y: f64| {
            (3.0 * (-((x - 16.0).powi(2) + (y - 16.0).powi(2)) / 20.0).exp()) as f32
        };
        let (_, s) = build(&grid_mesh(bump), 0.05);
        assert!(
            s.vertices > 4 * (NODE_VERTS - 1) && s.surface_triangles < 2 * 32 * 32,
            "{s:?}"
        );
        // The exact delta respects the target up to edge crossings, which it measures.
        assert!(s.delta_m < 0.2, "{s:?}");
    }
}
