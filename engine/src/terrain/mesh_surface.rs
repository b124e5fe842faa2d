//! The surface a node mesh actually draws, sampled through its own triangles (grid or TIN
//! alike), so measurements see the mesh that is drawn and not a grid stand-in.

use super::mesh::NodeMesh;
use super::quadtree::{NODE_QUADS, QuadTree};

/// A node mesh's surface triangles bucketed over the node, for height look-ups.
#[derive(Debug)]
pub struct MeshSurface<'a> {
    mesh: &'a NodeMesh,
    size_m: f64,
    cell_m: f64,
    /// Per bucket cell (row-major from the south-west): first indices of the surface triangles
    /// whose box overlaps it.
    buckets: Vec<Vec<u32>>,
}

const CELLS: usize = NODE_QUADS as usize;

impl<'a> MeshSurface<'a> {
    pub fn new(mesh: &'a NodeMesh, tree: &QuadTree) -> Self {
        let size_m = tree.node_size_m(mesh.key.level);
        let cell_m = size_m / CELLS as f64;
        let mut buckets = vec![Vec::new(); CELLS * CELLS];
        let cell = |v: f64| ((v / cell_m).floor().max(0.0) as usize).min(CELLS - 1);
        for t in (0..mesh.surface_index_count as usize).step_by(3) {
            let p = mesh.indices[t..t + 3]
                .iter()
                .map(|&i| mesh.positions[i as usize]);
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for q in p {
                for a in 0..2 {
                    lo[a] = lo[a].min(f64::from(q[a]));
                    hi[a] = hi[a].max(f64::from(q[a]));
                }
            }
            for cy in cell(lo[1])..=cell(hi[1]) {
                for cx in cell(lo[0])..=cell(hi[0]) {
                    buckets[cy * CELLS + cx].push(t as u32);
                }
            }
        }
        Self {
            mesh,
            size_m,
            cell_m,
            buckets,
        }
    }

    /// Height (m) of the surface triangle under the world position (x, y), clamped into the
    /// node. On a shared edge either triangle gives the same height.
    pub fn height_at(&self, x_m: f64, y_m: f64) -> f64 {
        let m = self.mesh;
        let x = (x_m - m.origin_m[0]).clamp(0.0, self.size_m);
        let y = (y_m - m.origin_m[1]).clamp(0.0, self.size_m);
        let cell = |v: f64| ((v / self.cell_m).floor().max(0.0) as usize).min(CELLS - 1);
        // The triangle whose smallest barycentric coordinate is largest: the containing one
        // (>= 0), or the nearest when rounding puts the point just outside every candidate.
        let mut best = (f64::NEG_INFINITY, f64::NAN);
        for &t in &self.buckets[cell(y) * CELLS + cell(x)] {
            let t = t as usize;
            let [a, b, c] = [0, 1, 2].map(|k| {
                let p = m.positions[m.indices[t + k] as usize];
                [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]
            });
            let det = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1]);
            if det.abs() < 1e-12 {
                continue; // degenerate (zero-area) triangle: draws nothing
            }
            let wa = ((b[1] - c[1]) * (x - c[0]) + (c[0] - b[0]) * (y - c[1])) / det;
            let wb = ((c[1] - a[1]) * (x - c[0]) + (a[0] - c[0]) * (y - c[1])) / det;
            let wc = 1.0 - wa - wb;
            let inside = wa.min(wb).min(wc);
            if inside > best.0 {
                best = (inside, wa * a[2] + wb * b[2] + wc * c[2]);
            }
        }
        best.1
    }
}

#[cfg(test)]
mod tests {
    use super::MeshSurface;
    use crate::terrain::bounds::NodeBounds;
    use crate::terrain::mesh::NodeMesh;
    use crate::terrain::quadtree::{NodeKey, QuadTree};

    /// Two triangles over a 64 m node with the diagonal from the south-east to the north-west
    /// corner (the other way round from the grid's), heights 0, 0, 0 and 10 m at the north-east.
    fn two_triangles() -> (NodeMesh, QuadTree) {
        let tree = QuadTree::new([0.0, 0.0], [64.0, 64.0]);
        let s = tree.node_size_m(0) as f32;
        let mesh = NodeMesh {
            key: NodeKey::ROOT,
            origin_m: [0.0, 0.0],
            positions: vec![[0.0, 0.0, 0.0], [s, 0.0, 0.0], [0.0, s, 0.0], [s, s, 10.0]],
            shading: vec![crate::terrain::mesh::pack_shading([0.0, 0.0, 1.0], 0); 4],
            indices: vec![0, 1, 2, 1, 3, 2].into(),
            surface_index_count: 6,
            bounds: NodeBounds::exact(0.0, 10.0),
            skirt_bottom_m: [0.0; 4],
            decimation: 0,
        };
        (mesh, tree)
    }

    #[test]
    fn heights_follow_the_mesh_triangles() {
        let (mesh, tree) = two_triangles();
        let s = tree.node_size_m(0);
        let surf = MeshSurface::new(&mesh, &tree);
        // South-west triangle: flat at 0. North-east triangle: rises to 10 m at the corner.
        assert_eq!(surf.height_at(0.25 * s, 0.25 * s), 0.0);
        assert!((surf.height_at(s, s) - 10.0).abs() < 1e-9);
        assert!((surf.height_at(0.75 * s, 0.75 * s) - 5.0).abs() < 1e-9);
        // On the diagonal both triangles give 0; the grid's other diagonal would give 5 m at
        // the centre.
        assert!(surf.height_at(0.5 * s, 0.5 * s).abs() < 1e-9);
    }
}
