//! Node mesh generation: a regular grid of `(NODE_QUADS + 1)^2` vertices sampled from the
//! finest surface, positions relative to the node's south-west corner (x, y in f32; z absolute
//! metres), normals, ground types, and skirts that make the tiling watertight at any level
//! difference.
//!
//! **Why skirts of this depth close every crack.** Along a shared border, a coarser node `C`
//! and a finer node `N` each interpolate the finest surface `F` linearly between their own
//! border vertices. (1) Where `C`'s border lies above `N`'s: `N`'s border is a convex
//! combination of `F` samples on `C`'s border, so it is at least `C.z_min`; `C`'s skirt reaches
//! down to `C.z_min`. (2) Where `N`'s border lies above `C`'s: `C`'s border interpolates
//! its own border vertices, samples of `F`: `N`'s skirt on that side reaches below the lowest
//! point of every coarser neighbour's border along it, found exactly from a few samples of `F`
//! (the neighbour's border vertices bracketing and inside the side; [`skirt_bottoms`]), so no
//! neighbour's bounds are needed. Same-level neighbours share border vertices exactly.
//!
//! **Decimated drawing.** A node may be drawn through every `2^d`-th vertex ([`grid_indices`],
//! `d <=` [`MAX_DECIMATION`]): that surface is its level-`L - d` ancestor's mesh over the node,
//! since both interpolate `F` at the same points. Its border then interpolates the ancestor's
//! lattice along each side, so a neighbour's skirt must also reach below the lattices of the
//! node's own ancestors along that side. Those with a vertex spacing of at most the node's size
//! have their points among the node's border vertices (so above `z_min`); the coarser ones are
//! bracketed from outside the side and are measured like a coarser neighbour.

use crate::surface::world::World;
use crate::terrain::bounds::{BoundsCache, NodeBounds, interpolate_grid};
use crate::terrain::quadtree::{NODE_QUADS, NodeKey, QuadTree, Side};
use crate::terrain::tiles::{TILE_SIZE_M, TILE_SPACING_M, Tile, TileKey};
use std::sync::Arc;

/// Vertices per node side.
pub const NODE_VERTS: usize = NODE_QUADS as usize + 1;

/// Bytes a vertex takes on the GPU: its position and its [`pack_shading`] word.
pub const GPU_VERTEX_BYTES: usize = std::mem::size_of::<[f32; 3]>() + std::mem::size_of::<u32>();

/// Which index list a mesh draws at a decimation ([`NodeMesh::drawn_list`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DrawnList {
    /// [`grid_indices`] of this many halvings, the same for every grid node.
    Grid(u8),
    /// The mesh's own `indices`.
    Own,
}

/// The most halvings of a grid mesh's vertex spacing a node may be drawn with (see the module
/// docs): a node drawn with `d` halvings shows `(32 / 2^d)^2 x 2` surface triangles.
pub const MAX_DECIMATION: u8 = 2;
const _: () = assert!(
    (NODE_QUADS as usize).is_multiple_of(1 << MAX_DECIMATION)
        && crate::terrain::bounds::BLOCKS_PER_SIDE >= 1 << MAX_DECIMATION,
    "a decimated grid keeps whole quads, and an ancestor's blocks tile the node"
);

/// One node's mesh, ready to upload.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeMesh {
    pub key: NodeKey,
    /// World position of the node's south-west corner; vertex x, y are relative to it.
    pub origin_m: [f64; 2],
    pub positions: Vec<[f32; 3]>,
    /// Per vertex its normal and ground type (legend index) in one word, as the terrain shader
    /// reads them: see [`pack_shading`].
    pub shading: Vec<u32>,
    /// Triangles, counter-clockwise seen from above; the first `surface_index_count` indices are
    /// the surface, the rest are skirts. A grid mesh shares [`grid_indices`]' list (one for all
    /// nodes; see [`NodeMesh::shares_grid_indices`]).
    pub indices: Arc<[u32]>,
    pub surface_index_count: u32,
    pub bounds: NodeBounds,
    /// Skirt bottom height per side (West, East, South, North).
    pub skirt_bottom_m: [f64; 4],
    /// Halvings of the vertex spacing `indices` draw with (0: every vertex; see
    /// [`NodeMesh::decimated`]).
    pub decimation: u8,
}

impl NodeMesh {
    /// World-space box of the mesh, skirts included.
    pub fn aabb_m(&self, tree: &QuadTree) -> (glam::DVec3, glam::DVec3) {
        let size = tree.node_size_m(self.key.level);
        let skirt_min = self
            .skirt_bottom_m
            .iter()
            .copied()
            .fold(self.bounds.z_min_m, f64::min);
        let o = self.origin_m;
        (
            glam::DVec3::new(o[0], o[1], skirt_min),
            glam::DVec3::new(o[0] + size, o[1] + size, self.bounds.z_max_m),
        )
    }

    /// Height of the regular grid triangulation of the mesh's 33 x 33 vertices (every
    /// `2^decimation`-th of them) at a world position inside the node: the drawn surface of a
    /// grid mesh (as built here), not of a TIN. To measure any mesh through its own triangles
    /// use [`super::mesh_surface::MeshSurface`].
    pub fn grid_height_at(&self, tree: &QuadTree, x_m: f64, y_m: f64) -> f64 {
        let step = 1usize << self.decimation;
        let quads = NODE_QUADS as usize / step;
        let s = tree.spacing_m(self.key.level) * step as f64;
        let z: Vec<f32> = (0..=quads)
            .flat_map(|j| (0..=quads).map(move |i| (i * step, j * step)))
            .map(|(i, j)| self.positions[j * NODE_VERTS + i][2])
            .collect();
        let gx = ((x_m - self.origin_m[0]) / s).clamp(0.0, quads as f64);
        let gy = ((y_m - self.origin_m[1]) / s).clamp(0.0, quads as f64);
        interpolate_grid(&z, quads, gx, gy)
    }

    /// The same grid mesh drawn with `steps` halvings of its vertex spacing (the indices of
    /// [`grid_indices`]; the vertices are kept). Only for meshes built by [`build`].
    pub fn decimated(&self, steps: u8) -> NodeMesh {
        let g = grid_indices(steps);
        NodeMesh {
            indices: Arc::clone(&g.indices),
            surface_index_count: g.surface_index_count,
            decimation: steps,
            ..self.clone()
        }
    }

    /// Whether the mesh can be drawn decimated: all its vertices drawn, laid out as [`build`]
    /// lays them out (the grid, then the four skirts), so [`grid_indices`] apply to it.
    pub fn decimates(&self) -> bool {
        self.decimation == 0 && self.positions.len() == NODE_VERTS * NODE_VERTS + 4 * NODE_VERTS
    }

    /// The index list drawn with `decimation` halvings: the grid's decimated triangles where
    /// the mesh [`decimates`](Self::decimates), else its own indices, which may be the grid's
    /// shared list ([`Self::shares_grid_indices`]).
    pub fn drawn_list(&self, decimation: u8) -> DrawnList {
        if decimation > 0 && self.decimates() {
            DrawnList::Grid(decimation)
        } else if self.shares_grid_indices() {
            DrawnList::Grid(self.decimation)
        } else {
            DrawnList::Own
        }
    }

    /// The indices of [`Self::drawn_list`].
    pub fn drawn_indices(&self, decimation: u8) -> &[u32] {
        match self.drawn_list(decimation) {
            DrawnList::Grid(steps) => &grid_indices(steps).indices,
            DrawnList::Own => &self.indices,
        }
    }

    /// Whether `indices` is the list [`grid_indices`] keeps for this mesh's decimation (as
    /// [`build`] and [`Self::decimated`] make them): the same for every grid node, so a renderer
    /// can keep it once instead of per node.
    pub fn shares_grid_indices(&self) -> bool {
        self.decimation <= MAX_DECIMATION
            && Arc::ptr_eq(&self.indices, &grid_indices(self.decimation).indices)
    }

    /// Bytes of GPU data the mesh takes: [`GPU_VERTEX_BYTES`] a vertex, and 4 an index of its
    /// own (none when it [shares the grid's](Self::shares_grid_indices)).
    pub fn gpu_bytes(&self) -> usize {
        self.positions.len() * GPU_VERTEX_BYTES + self.own_gpu_indices().len() * 4
    }

    /// The indices a renderer keeps for this mesh alone: none when it shares the grid's list.
    pub fn own_gpu_indices(&self) -> &[u32] {
        if self.shares_grid_indices() {
            &[]
        } else {
            &self.indices
        }
    }

    /// A stable hash of every byte of the mesh (for determinism tests).
    pub fn content_hash(&self) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut feed = |b: &[u8]| {
            for &x in b {
                h ^= u64::from(x);
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
        };
        feed(&[self.key.level]);
        feed(&self.key.ix.to_le_bytes());
        feed(&self.key.iy.to_le_bytes());
        for p in &self.positions {
            for c in p {
                feed(&c.to_le_bytes());
            }
        }
        for w in &self.shading {
            feed(&w.to_le_bytes());
        }
        for i in self.indices.iter() {
            feed(&i.to_le_bytes());
        }
        h
    }
}

/// The tile a node takes its samples from: nodes of at most one tile's size whose vertex
/// spacing is a multiple of the tile spacing. Larger nodes evaluate the surface directly.
pub fn source_tile(world: &World, tree: &QuadTree, key: NodeKey) -> Option<TileKey> {
    let size = tree.node_size_m(key.level);
    let s = tree.spacing_m(key.level);
    if size > TILE_SIZE_M || s < TILE_SPACING_M {
        return None;
    }
    let r = tree.rect(key);
    let o = world.origin_m();
    Some(TileKey {
        tx: ((r.min[0] - o[0]) / TILE_SIZE_M).floor() as i32,
        ty: ((r.min[1] - o[1]) / TILE_SIZE_M).floor() as i32,
    })
}

/// Heights and ground types on the vertex grid plus a one-vertex ring (for normals):
/// `(NODE_VERTS + 2)^2` values, row-major, index (i + 1, j + 1) for vertex (i, j).
fn sample_grid(
    world: &World,
    tree: &QuadTree,
    key: NodeKey,
    tile: Option<&Tile>,
) -> (Vec<f32>, Vec<u8>) {
    let r = tree.rect(key);
    let s = tree.spacing_m(key.level);
    let Some(t) = tile else {
        let axis = |from: f64| -> Vec<f64> {
            (-1..=(NODE_VERTS as i64))
                .map(|i| from + i as f64 * s)
                .collect()
        };
        let (xs, ys) = (axis(r.min[0]), axis(r.min[1]));
        let h = world
            .heights_on_lattice(&xs, &ys)
            .iter()
            .map(|&z| z as f32)
            .collect();
        let g = ys
            .iter()
            .flat_map(|&y| xs.iter().map(move |&x| world.ground_type(x, y)))
            .collect();
        return (h, g);
    };
    let w = NODE_VERTS + 2;
    let mut h = Vec::with_capacity(w * w);
    let mut g = Vec::with_capacity(w * w);
    let step = (s / TILE_SPACING_M).round() as i64;
    let o = world.origin_m();
    let base_i =
        ((r.min[0] - o[0] - f64::from(t.key.tx) * TILE_SIZE_M) / TILE_SPACING_M).round() as i64;
    let base_j =
        ((r.min[1] - o[1] - f64::from(t.key.ty) * TILE_SIZE_M) / TILE_SPACING_M).round() as i64;
    for j in -1..=(NODE_VERTS as i64) {
        for i in -1..=(NODE_VERTS as i64) {
            h.push(t.height_at(base_i + i * step, base_j + j * step));
            g.push(t.ground_at(base_i + i * step, base_j + j * step));
        }
    }
    (h, g)
}

/// The depth each side's skirt must reach (see the module docs): below this node's height range
/// and below every coarser neighbour's border along that side, less a margin for f32 rounding.
pub fn skirt_bottoms(world: &World, tree: &QuadTree, key: NodeKey, b: &NodeBounds) -> [f64; 4] {
    let mut out = [b.z_min_m; 4];
    for (k, side) in Side::ALL.iter().enumerate() {
        let mut lowest = b.z_min_m;
        for level in 0..key.level {
            let Some(n) = tree.neighbour_across(key, *side, level) else {
                continue;
            };
            if !tree.overlaps_map(n) {
                continue;
            }
            // An ancestor's lattice along the side shows where a neighbour inside it is drawn
            // decimated (module docs); while its spacing is at most this node's size, its
            // points are this node's border vertices, all above `z_min`.
            if key.ancestors().any(|a| a == n) && 1u64 << (key.level - level) <= NODE_QUADS.into() {
                continue;
            }
            lowest = lowest.min(neighbour_border_min(world, tree, key, *side, n));
        }
        out[k] = lowest - (2.0 * lowest.abs() * f64::from(f32::EPSILON) + SKIRT_MARGIN_M);
    }
    out
}

/// Safety margin below the lowest neighbour border (m): vertex heights are f32 roundings of
/// the same surface values, possibly at positions an ulp apart.
const SKIRT_MARGIN_M: f64 = 1e-3;

/// The lowest height of coarser node `n`'s border mesh along `side` of `key`: that border is the
/// linear interpolation of `F` (as f32, like mesh vertices) at `n`'s border vertices, so its
/// minimum over the shared segment is at a segment end or at one of `n`'s vertices inside it.
fn neighbour_border_min(
    world: &World,
    tree: &QuadTree,
    key: NodeKey,
    side: Side,
    n: NodeKey,
) -> f64 {
    let r = tree.rect(key);
    let nr = tree.rect(n);
    let s = tree.spacing_m(n.level);
    // The shared line: x fixed for west / east sides, y fixed for south / north.
    let (along, fixed) = match side {
        Side::West => (1, r.min[0]),
        Side::East => (1, r.max[0]),
        Side::South => (0, r.min[1]),
        Side::North => (0, r.max[1]),
    };
    let (a, b) = (r.min[along], r.max[along]);
    let base = nr.min[along];
    let last = NODE_QUADS as f64;
    let k0 = ((a - base) / s).floor().clamp(0.0, last) as u32;
    let k1 = ((b - base) / s).ceil().clamp(0.0, last) as u32;
    let vertex = |k: u32| {
        let t = base + f64::from(k) * s;
        let z = if along == 1 {
            world.height_m(fixed, t)
        } else {
            world.height_m(t, fixed)
        };
        (t, f64::from(z as f32))
    };
    let points: Vec<(f64, f64)> = (k0..=k1).map(vertex).collect();
    let at = |t: f64| {
        points
            .windows(2)
            .find(|w| t >= w[0].0 && t <= w[1].0)
            .map_or(points[0].1, |w| {
                let f = (t - w[0].0) / (w[1].0 - w[0].0);
                w[0].1 + f * (w[1].1 - w[0].1)
            })
    };
    points
        .iter()
        .filter(|p| p.0 > a && p.0 < b)
        .map(|p| p.1)
        .fold(at(a).min(at(b)), f64::min)
}

/// Builds the mesh of `key`, taking its source tile (if any) from `tiles` for the duration.
pub fn build_with_tiles(
    world: &World,
    tree: &QuadTree,
    cache: &mut BoundsCache,
    tiles: &mut crate::terrain::tiles::TileCache,
    key: NodeKey,
) -> NodeMesh {
    let tile_key = source_tile(world, tree, key);
    let tile = tile_key.map(|k| tiles.acquire(world, k));
    let m = build(
        world,
        tree,
        &mut |k| cache.get(world, tree, k),
        key,
        tile.as_deref(),
    );
    if let Some(k) = tile_key {
        tiles.release(k);
    }
    m
}

/// Builds the mesh of `key`. `tile` must be [`source_tile`]'s tile when that is `Some`;
/// `bounds` gives node bounds (this node's and its coarser neighbours', for skirt depths).
pub fn build(
    world: &World,
    tree: &QuadTree,
    bounds: &mut dyn FnMut(NodeKey) -> NodeBounds,
    key: NodeKey,
    tile: Option<&Tile>,
) -> NodeMesh {
    let own = bounds(key);
    let skirt_bottom_m = skirt_bottoms(world, tree, key, &own);
    let r = tree.rect(key);
    let s = tree.spacing_m(key.level);
    let (h, g) = sample_grid(world, tree, key, tile);
    let w = NODE_VERTS + 2;
    let at = |i: usize, j: usize| h[(j + 1) * w + i + 1];
    let n = NODE_VERTS;
    let mut positions = Vec::with_capacity(n * n + 4 * n);
    let mut shading = Vec::with_capacity(n * n + 4 * n);
    for j in 0..n {
        for i in 0..n {
            positions.push([(i as f64 * s) as f32, (j as f64 * s) as f32, at(i, j)]);
            let dzdx =
                (f64::from(h[(j + 1) * w + i + 2]) - f64::from(h[(j + 1) * w + i])) / (2.0 * s);
            let dzdy =
                (f64::from(h[(j + 2) * w + i + 1]) - f64::from(h[j * w + i + 1])) / (2.0 * s);
            shading.push(pack_shading([-dzdx, -dzdy, 1.0], g[(j + 1) * w + i + 1]));
        }
    }
    // Skirts: per side, a copy of the border vertices at the skirt bottom (joined by
    // [`grid_indices`]).
    for (k, side) in Side::ALL.iter().enumerate() {
        for t in 0..n {
            let v = border_vertex(*side, t);
            let p = positions[v];
            positions.push([p[0], p[1], skirt_bottom_m[k] as f32]);
            shading.push(shading[v]);
        }
    }
    let g = grid_indices(0);
    NodeMesh {
        key,
        origin_m: r.min,
        positions,
        shading,
        indices: Arc::clone(&g.indices),
        surface_index_count: g.surface_index_count,
        bounds: own,
        skirt_bottom_m,
        decimation: 0,
    }
}

/// Quantization steps of each of a packed normal's two coordinates.
const NORMAL_STEPS: f64 = 4095.0;

/// One vertex's shading word: its normal `n` (any length, pointing up: `z >= 0`; a downward
/// part is dropped) as two 12-bit coordinates (bits 0 - 11 and 12 - 23) and its ground type
/// (bits 24 - 31). The coordinates are the normal's octahedral projection on the upper
/// hemisphere, `p = n.xy / (|x| + |y| + z)`, turned 45 degrees so that the diamond
/// `|p.x| + |p.y| <= 1` fills the square: `(p.x + p.y, p.x - p.y)`. Decoded within 0.04
/// degrees ([`unpack_normal`]; the terrain shader's `shading_normal` decodes the same way).
pub fn pack_shading(n: [f64; 3], ground: u8) -> u32 {
    let z = n[2].max(0.0);
    let l1 = n[0].abs() + n[1].abs() + z;
    let (px, py) = if l1 > 0.0 {
        (n[0] / l1, n[1] / l1)
    } else {
        (0.0, 0.0)
    };
    let q = |c: f64| ((c * 0.5 + 0.5).clamp(0.0, 1.0) * NORMAL_STEPS).round() as u32;
    q(px + py) | (q(px - py) << 12) | (u32::from(ground) << 24)
}

/// The unit normal a [`pack_shading`] word holds.
pub fn unpack_normal(word: u32) -> [f64; 3] {
    let c = |bits: u32| f64::from(bits & 0xfff) / NORMAL_STEPS * 2.0 - 1.0;
    let (u, v) = (c(word), c(word >> 12));
    let (x, y) = ((u + v) * 0.5, (u - v) * 0.5);
    let z = 1.0 - x.abs() - y.abs();
    let len = (x * x + y * y + z * z).sqrt();
    [x / len, y / len, z / len]
}

/// The ground type a [`pack_shading`] word holds.
pub fn ground_of(word: u32) -> u8 {
    (word >> 24) as u8
}

/// Index of grid vertex `t` along `side` (West and East run south to north, South and North
/// west to east).
fn border_vertex(side: Side, t: usize) -> usize {
    let n = NODE_VERTS;
    match side {
        Side::West => t * n,
        Side::East => t * n + n - 1,
        Side::South => t,
        Side::North => (n - 1) * n + t,
    }
}

/// The triangles of a grid mesh through every `2^steps`-th vertex (`steps <=`
/// [`MAX_DECIMATION`]).
#[derive(Debug)]
pub struct GridIndices {
    /// Counter-clockwise seen from above (skirts seen from outside).
    pub indices: Arc<[u32]>,
    /// How many of `indices` are the surface's (the skirts' follow).
    pub surface_index_count: u32,
}

/// The [`GridIndices`] of `steps` halvings, the same for every grid node (made once).
pub fn grid_indices(steps: u8) -> &'static GridIndices {
    static ALL: std::sync::OnceLock<[GridIndices; MAX_DECIMATION as usize + 1]> =
        std::sync::OnceLock::new();
    &ALL.get_or_init(|| std::array::from_fn(|d| grid_triangles(d as u8)))[usize::from(steps)]
}

/// The triangles of a grid mesh as [`build`] lays out its vertices (the grid row-major, then
/// each side's skirt vertices in [`Side::ALL`] order), through every `2^steps`-th vertex.
fn grid_triangles(steps: u8) -> GridIndices {
    let step = 1usize << steps;
    let n = NODE_VERTS;
    let quads = NODE_QUADS as usize / step;
    let mut indices = Vec::with_capacity((quads * quads + 4 * quads) * 6);
    let vid = |i: usize, j: usize| (j * step * n + i * step) as u32;
    for j in 0..quads {
        for i in 0..quads {
            let (a, b, c, d) = (vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1));
            indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    let surface_index_count = indices.len() as u32;
    for (k, side) in Side::ALL.iter().enumerate() {
        let base = (n * n + k * n) as u32;
        // Outward-facing: on West/North the border runs so that (top t, top t+1, bottom) is
        // counter-clockwise seen from outside.
        let flip = matches!(side, Side::East | Side::South);
        for q in 0..quads {
            let (t0, t1) = (q * step, (q + 1) * step);
            let (top0, top1) = (
                border_vertex(*side, t0) as u32,
                border_vertex(*side, t1) as u32,
            );
            let (bot0, bot1) = (base + t0 as u32, base + t1 as u32);
            if flip {
                indices.extend_from_slice(&[top0, bot0, bot1, top0, bot1, top1]);
            } else {
                indices.extend_from_slice(&[top0, top1, bot1, top0, bot1, bot0]);
            }
        }
    }
    GridIndices {
        indices: indices.into(),
        surface_index_count,
    }
}

#[cfg(test)]
mod tests {
    use super::{ground_of, pack_shading, unpack_normal};

    /// Normals over the whole upper hemisphere (flat ground to vertical cliffs, every
    /// direction, any length) come back from their shading word within 0.04 degrees, and the
    /// ground type unchanged.
    #[test]
    fn packed_normals_come_back_within_four_hundredths_of_a_degree() {
        let mut worst_deg = 0.0f64;
        for i in 0..=400u32 {
            let tilt = f64::from(i) / 400.0 * std::f64::consts::FRAC_PI_2;
            for k in 0..720u32 {
                let azimuth = (f64::from(k) / 2.0).to_radians() + 0.01;
                let n = [
                    tilt.sin() * azimuth.cos(),
                    tilt.sin() * azimuth.sin(),
                    tilt.cos(),
                ];
                let ground = ((i * 7 + k) % 256) as u8;
                let word = pack_shading(n.map(|c| c * 3.5), ground);
                assert_eq!(ground_of(word), ground);
                let back = unpack_normal(word);
                let dot: f64 = n.iter().zip(&back).map(|(a, b)| a * b).sum();
                worst_deg = worst_deg.max(dot.clamp(-1.0, 1.0).acos().to_degrees());
            }
        }
        assert!(worst_deg < 0.04, "worst {worst_deg} degrees");
    }
}
