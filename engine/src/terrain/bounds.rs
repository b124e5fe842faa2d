//! Per-node bounds: a height range (AABB) and a conservative geometric error.
//!
//! A node's mesh `M` is the linear interpolation (diagonals from (i, j) to (i+1, j+1)) of the
//! finest surface `F` at its `(NODE_QUADS + 1)^2` vertices. The error `max |M - F|` over the
//! node is bounded as follows. Evaluate `F` on a check lattice [`CHECK_SUBDIV`] times finer than
//! the mesh (spacing `c`), triangulated with the same diagonal direction, so every check
//! triangle lies inside one mesh triangle and `M` is linear on it. For `p` in a check triangle
//! with corners `v_i` and barycentric weights `l_i`:
//! `M(p) - F(p) = sum l_i (M - F)(v_i) + (Lin F - F)(p)`, and
//! `|Lin F(p) - F(p)| <= L_F * sum l_i |p - v_i| <= L_F * sqrt(sum l_i |p - v_i|^2) <= L_F c / sqrt(2)`
//! (the last sum is largest at the circumcentre of the right triangle, radius `c / sqrt(2)`),
//! or, where a part of `F` is C1 with a bounded piecewise-continuous Hessian over the cell, by
//! Taylor's theorem with integral remainder `|Lin F(p) - F(p)| <= (M2 / 2) sum l_i |p - v_i|^2
//! <= M2 c^2 / 4`, or for the detail part `H` (|H| <= A) simply `2 A`; see [`between_bound`].
//! The slope, curvature and amplitude bounds are local to the check cell
//! ([`World::region_bounds`]): a cliff only widens the bound next to it. So
//! `error <= max over check cells of (max |M - F| at its corners + between(cell))`; the height
//! range is widened per cell by the same term. The error is measured, then made an upper bound by proof; nothing is guessed.
//!
//! Monotone errors. The four children of `N` together mesh it with a grid of spacing `s / 2`
//! whose vertices are every `CHECK_SUBDIV / 2`-th check-lattice point, with the same diagonal
//! direction, so the argument above applied to that grid on the same check cells bounds every
//! child's error: `max over cells of (max |M_C - F| at its corners + between(cell))`. Every
//! deeper descendant's triangles lie inside one check cell with legs `<= c`, where its error is
//! at most `between(cell, c)` (its vertices are exact), and that is already inside the children's
//! term. So `U(N)`, that children's term (computed from the same lattice, no extra surface
//! evaluations), bounds the true error of every descendant's mesh. The stored error is
//! `E(N) = min(max(e(N), U(N)), E(parent))` ([`monotone`]): both terms of the `min` are proven
//! bounds of `N`'s true error (the parent's `E` bounds every descendant of the parent, by
//! induction from the root, where `E = max(e, U)`), and `E(child) <= E(parent)` by construction.
//! So errors are monotone and still never guessed; the price is `U(N)` where it exceeds `e(N)`
//! (where the children's between-points terms dominate), reported by `nodebench`.

use crate::surface::world::World;
use crate::terrain::quadtree::{NODE_QUADS, NodeKey, QuadTree};
use rustc_hash::FxHashMap;

/// Check-lattice points per mesh quad side.
pub const CHECK_SUBDIV: u32 = 4;
const _: () = assert!(
    CHECK_SUBDIV.is_multiple_of(2),
    "children's vertices must be lattice points"
);

/// Height range and error bound of one node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeBounds {
    pub z_min_m: f64,
    pub z_max_m: f64,
    /// Upper bound of the vertical distance between the node mesh and the finest surface, and of
    /// the same distance for every descendant's mesh; never larger than the parent's.
    pub error_m: f64,
    /// The measured bound `e(N)` of this node's own mesh (before the monotone step).
    pub mesh_error_m: f64,
    /// `U(N)`: a bound of the error of every descendant's mesh inside this node.
    pub descendants_error_m: f64,
    /// The vegetation representation error of this level where the node has vegetation (see
    /// [`crate::vegetation::representation::ERROR_PER_SPACING`]), else 0. Monotone like `error_m`.
    pub vegetation_error_m: f64,
}

impl NodeBounds {
    /// The error selection projects: terrain or vegetation, whichever is larger.
    pub fn selection_error_m(&self) -> f64 {
        self.error_m.max(self.vegetation_error_m)
    }
}

/// Linear interpolation of vertex heights `v` ((n+1)^2, row-major) at fractional grid position
/// (gx, gy), using the triangulation with diagonals from (i, j) to (i+1, j+1).
pub fn interpolate_grid(v: &[f32], n: usize, gx: f64, gy: f64) -> f64 {
    let i = (gx.floor() as usize).min(n - 1);
    let j = (gy.floor() as usize).min(n - 1);
    let (fx, fy) = (gx - i as f64, gy - j as f64);
    let w = n + 1;
    let h00 = f64::from(v[j * w + i]);
    let h10 = f64::from(v[j * w + i + 1]);
    let h01 = f64::from(v[(j + 1) * w + i]);
    let h11 = f64::from(v[(j + 1) * w + i + 1]);
    if fx >= fy {
        // Lower-right triangle (00, 10, 11).
        h00 + fx * (h10 - h00) + fy * (h11 - h10)
    } else {
        // Upper-left triangle (00, 11, 01).
        h00 + fy * (h01 - h00) + fx * (h11 - h01)
    }
}

/// A bound of `|Lin F(p) - F(p)|` inside a right check triangle with legs `c`, where `F = G + H + E`
/// (map surface + detail + decal shaping E) and the parts' bounds add. Each part takes the
/// smallest of its valid bounds: first order `slope c / sqrt(2)`, second order
/// `curvature c^2 / 4`, and for the detail also zero order `2 max |H|`.
pub fn between_bound(b: &crate::surface::world::RegionBounds, c: f64) -> f64 {
    let reach = c * std::f64::consts::FRAC_1_SQRT_2;
    let second = |m2: Option<f64>| m2.map_or(f64::INFINITY, |m| m * c * c * 0.25);
    let g = (b.slope_g * reach).min(second(b.curvature_g));
    let e = (b.decal.slope * reach).min(second(Some(b.decal.curvature)));
    let h = (b.slope_h * reach)
        .min(second(b.curvature_h))
        .min(2.0 * b.amplitude_max_m);
    g + h + e
}

/// The stored bounds of a node from its own measurement ([`measure`]) and its parent's stored
/// bounds (`None` at the root): `error_m = min(max(e, U), E(parent))`.
pub fn monotone(own: NodeBounds, parent: Option<NodeBounds>) -> NodeBounds {
    let mut error = own.mesh_error_m.max(own.descendants_error_m);
    if let Some(p) = parent {
        error = error.min(p.error_m);
    }
    NodeBounds {
        error_m: error,
        ..own
    }
}

/// Measures the height range, the error bound `e(N)` of one node's own mesh and the bound
/// `U(N)` of its descendants' meshes (see the module docs; `error_m` = `mesh_error_m` here, before
/// [`monotone`]). About 17k surface evaluations.
pub fn measure(world: &World, tree: &QuadTree, key: NodeKey) -> NodeBounds {
    let r = tree.rect(key);
    let n = NODE_QUADS as usize;
    let sub = CHECK_SUBDIV as usize;
    let s = tree.spacing_m(key.level);
    let c = s / f64::from(CHECK_SUBDIV);
    let m = n * sub;
    // F on the check lattice; mesh vertices are every `sub`-th lattice point.
    let mut lattice = Vec::with_capacity((m + 1) * (m + 1));
    for j in 0..=m {
        for i in 0..=m {
            lattice.push(world.height_m(r.min[0] + i as f64 * c, r.min[1] + j as f64 * c));
        }
    }
    let mut verts = Vec::with_capacity((n + 1) * (n + 1));
    for j in 0..=n {
        for i in 0..=n {
            verts.push(lattice[(j * sub) * (m + 1) + i * sub] as f32);
        }
    }
    // Per check cell: the largest |M - F| at its corners plus the local between-points bound.
    let err_at = |i: usize, j: usize| {
        let f = lattice[j * (m + 1) + i];
        (interpolate_grid(&verts, n, i as f64 / sub as f64, j as f64 / sub as f64) - f).abs()
    };
    let mut e_lattice = vec![0.0f64; (m + 1) * (m + 1)];
    for j in 0..=m {
        for i in 0..=m {
            e_lattice[j * (m + 1) + i] = err_at(i, j);
        }
    }
    // The four children together mesh the node with a (2n)^2 grid whose vertices are every
    // (sub / 2)-th lattice point: their |M_C - F| at every lattice point.
    let half = sub / 2;
    let nc = 2 * n;
    let mut child_verts = Vec::with_capacity((nc + 1) * (nc + 1));
    for j in 0..=nc {
        for i in 0..=nc {
            child_verts.push(lattice[(j * half) * (m + 1) + i * half] as f32);
        }
    }
    let mut e_child = vec![0.0f64; (m + 1) * (m + 1)];
    for j in 0..=m {
        for i in 0..=m {
            let f = lattice[j * (m + 1) + i];
            let g = interpolate_grid(
                &child_verts,
                nc,
                i as f64 / half as f64,
                j as f64 / half as f64,
            );
            e_child[j * (m + 1) + i] = (g - f).abs();
        }
    }
    // Fast path: when check cells tile the height and ground cells exactly (aligned, at most
    // one cell in size) and the node is inside the map, each check cell's bounds are its map
    // cells' values, read directly.
    let (hs, gs) = world.cell_spacings_m();
    let o = world.origin_m();
    let size = world.size_m();
    let divides = |big: f64| c <= big && ((big / c) - (big / c).round()).abs() < 1e-9;
    let block_m = crate::surface::decals::DECAL_BLOCK_M;
    let inside = r.max[0] <= o[0] + size[0] + 1e-9 && r.max[1] <= o[1] + size[1] + 1e-9;
    let direct = divides(hs) && divides(gs) && divides(block_m) && inside;
    let (mut lo, mut hi, mut error) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
    let mut descendants = 0.0f64;
    for j in 0..m {
        for i in 0..m {
            let cell = crate::surface::world::Rect {
                min: [r.min[0] + i as f64 * c, r.min[1] + j as f64 * c],
                max: [r.min[0] + (i + 1) as f64 * c, r.min[1] + (j + 1) as f64 * c],
            };
            let region = if direct {
                world.cell_region_bounds(cell)
            } else {
                world.region_bounds(cell)
            };
            let between = between_bound(&region, c);
            let corners = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)];
            let (mut e, mut ec) = (0.0f64, 0.0f64);
            for (ci, cj) in corners {
                let f = lattice[cj * (m + 1) + ci];
                lo = lo.min(f - between);
                hi = hi.max(f + between);
                e = e.max(e_lattice[cj * (m + 1) + ci]);
                ec = ec.max(e_child[cj * (m + 1) + ci]);
            }
            error = error.max(e + between);
            descendants = descendants.max(ec + between);
        }
    }
    // f32 vertex rounding: relative 2^-24 of the height magnitude, twice for safety (descendant
    // vertices lie in the same proven height range).
    let rounding = 2.0 * hi.abs().max(lo.abs()) * f64::from(f32::EPSILON);
    NodeBounds {
        z_min_m: lo,
        z_max_m: hi,
        error_m: error + rounding,
        mesh_error_m: error + rounding,
        vegetation_error_m: if crate::vegetation::representation::has_vegetation(world, r) {
            crate::vegetation::representation::ERROR_PER_SPACING * s
        } else {
            0.0
        },
        // Leaves have no descendants.
        descendants_error_m: if key.level < tree.max_level {
            descendants + rounding
        } else {
            0.0
        },
    }
}

/// Lazily computed bounds per node, shared by selection and mesh generation.
#[derive(Debug, Default, Clone)]
pub struct BoundsCache {
    map: FxHashMap<NodeKey, NodeBounds>,
    /// How many nodes were measured (cache misses).
    pub computed: u64,
}

impl BoundsCache {
    pub fn new() -> Self {
        Self::default()
    }

    /// The node's bounds, measured on first use (after its parent's, see [`monotone`]).
    pub fn get(&mut self, world: &World, tree: &QuadTree, key: NodeKey) -> NodeBounds {
        if let Some(b) = self.map.get(&key) {
            return *b;
        }
        let parent = key.parent().map(|p| self.get(world, tree, p));
        let b = monotone(measure(world, tree, key), parent);
        self.computed += 1;
        self.map.insert(key, b);
        b
    }

    /// Stores bounds measured elsewhere (they are a pure function of the key).
    pub fn insert(&mut self, key: NodeKey, b: NodeBounds) {
        self.map.insert(key, b);
    }

    /// Forgets one node's bounds (benchmarks measuring it again).
    pub fn remove(&mut self, key: NodeKey) {
        self.map.remove(&key);
    }

    /// The bounds if already measured.
    pub fn peek(&self, key: NodeKey) -> Option<NodeBounds> {
        self.map.get(&key).copied()
    }

    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_reproduces_vertices_and_is_linear_on_triangles() {
        // A plane z = 2x + 3y is reproduced everywhere.
        let n = 4;
        let v: Vec<f32> = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| (2 * i + 3 * j) as f32))
            .collect();
        for &(gx, gy) in &[(0.0, 0.0), (1.5, 2.25), (3.9, 0.1), (4.0, 4.0), (2.0, 3.0)] {
            assert!((interpolate_grid(&v, n, gx, gy) - (2.0 * gx + 3.0 * gy)).abs() < 1e-9);
        }
    }
}
