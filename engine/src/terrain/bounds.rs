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
//! <= M2 c^2 / 4`, or for the detail part `H` (|H| <= A) simply `2 A`; see
//! [`crate::surface::world::RegionBounds::between_m`].
//! The slope, curvature and amplitude bounds are local to the check cell
//! ([`World::region_bounds`]): a cliff only widens the bound next to it. So
//! `error <= max over check cells of (max |M - F| at its corners + between(cell))`; the height
//! range is widened per cell by the same term. The error is measured, then made an upper bound
//! by proof; nothing is guessed. Where `between` makes a cell's bound loose (more than
//! [`super::refine::SLACK`] over the error measured in its block), the cell is measured again on
//! finer sub-cells by branch and bound ([`super::refine`]), worst first, within a budget.
//!
//! Precomputed. Nodes whose vertex spacing is the map's height spacing times `2^k`, `k >= -1`
//! (on the default map every node of 64 m and more) do not measure at run time: the same
//! argument was applied once per map on a check lattice of a quarter of the height spacing
//! ([`crate::surface::map_error`]; for `k = -1` that is two check cells per quad, not four, so
//! those bounds are looser: 1.4x the measured ones on average on the default map's flight,
//! which costs 4 % more triangles at tau 2 px) and [`measure`] reads its blocks
//! ([`from_map_error`]). Nodes of spacing a quarter of the height spacing (32 m on the default
//! map) are measured by [`measured_blocks`], the run-time measurement itself, once per map into
//! the finest map-error grid ([`super::precomputed`]), and read the same way.
//!
//! Leaves. A node whose children are leaves computes their meshes' errors on its own lattice
//! anyway (the children's term of `U(N)` below); taken per child block, with each child's height
//! range from the same lattice, that is a proven bound of the leaf ([`measure_with_leaves`]), on
//! a lattice half as fine as the leaf's own, so looser. A leaf is never split, so its error
//! only bounds how it is drawn, and a stream gets five nodes' bounds from one lattice.
//!
//! Blocks. All of this is kept per block of `NODE_QUADS / BLOCKS_PER_SIDE` quads (height range
//! and error), and the node's values are the blocks' extremes: the selection projects each
//! block's error from the block's own box ([`super::select::projected_error_px`]).
//!
//! Monotone errors. The four children of `N` together mesh it with a grid of spacing `s / 2`
//! whose vertices are every `CHECK_SUBDIV / 2`-th check-lattice point, with the same diagonal
//! direction, so the argument above applied to that grid on the same check cells bounds every
//! child's error: `max over cells of (max |M_C - F| at its corners + between(cell))` (refined
//! like the node's own term). Every deeper descendant's triangles lie inside one check triangle
//! with legs `<= c`, where its error is at most `between(cell, c)` (its vertices are exact). So
//! `U(N)`, the larger of the children's term and that deeper term (computed from the same
//! lattice), bounds the true error of every descendant's mesh, block by block. The stored error is
//! `E(N) = min(max(e(N), U(N)), E(parent block))` per block ([`monotone`]): both terms of the `min` are proven
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

/// Bound blocks per node side: a node's error and height range are also kept for each of
/// `BLOCKS_PER_SIDE^2` blocks of `NODE_QUADS / BLOCKS_PER_SIDE` quads, so the selection projects
/// each block's error from that block's own distance (a large node seen from close by is no longer
/// charged its worst error at its nearest point).
pub const BLOCKS_PER_SIDE: usize = 4;
/// Bound blocks per node.
pub const BLOCKS: usize = BLOCKS_PER_SIDE * BLOCKS_PER_SIDE;
const _: () = assert!(
    (NODE_QUADS as usize).is_multiple_of(BLOCKS_PER_SIDE) && BLOCKS_PER_SIDE.is_multiple_of(2),
    "blocks are whole quads and a child's block lies in one block of its parent"
);

const _: () = assert!(
    NODE_QUADS as usize / BLOCKS_PER_SIDE == crate::surface::map_error::BLOCK_QUADS,
    "a node's blocks are the map-error grids' blocks"
);

/// Height range and error bound of one block of a node (row-major from the south-west,
/// `index = by * BLOCKS_PER_SIDE + bx`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockBounds {
    pub z_min_m: f64,
    pub z_max_m: f64,
    /// Upper bound of `|mesh - F|` inside the block for this node's mesh and every
    /// descendant's; never larger than the parent block's that contains it.
    pub error_m: f64,
}

/// Height range and error bound of one node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeBounds {
    pub z_min_m: f64,
    pub z_max_m: f64,
    /// Upper bound of the vertical distance between the node mesh and the finest surface, and of
    /// the same distance for every descendant's mesh; never larger than the parent's. The largest
    /// block error.
    pub error_m: f64,
    /// The measured bound `e(N)` of this node's own mesh (before the monotone step).
    pub mesh_error_m: f64,
    /// `U(N)`: a bound of the error of every descendant's mesh inside this node.
    pub descendants_error_m: f64,
    /// The vegetation representation error of this level where the node has vegetation (see
    /// [`crate::vegetation::representation::ERROR_PER_SPACING`]), else 0. Monotone like `error_m`.
    pub vegetation_error_m: f64,
    /// The same bounds per block (see [`BLOCKS_PER_SIDE`]).
    pub blocks: [BlockBounds; BLOCKS],
}

impl NodeBounds {
    /// Bounds of an exactly represented flat or constant-range patch (zero error), for tests and
    /// hand-made meshes.
    pub fn exact(z_min_m: f64, z_max_m: f64) -> Self {
        Self {
            z_min_m,
            z_max_m,
            error_m: 0.0,
            mesh_error_m: 0.0,
            descendants_error_m: 0.0,
            vegetation_error_m: 0.0,
            blocks: [BlockBounds {
                z_min_m,
                z_max_m,
                error_m: 0.0,
            }; BLOCKS],
        }
    }
}

/// The largest error of a node's blocks: the node's error.
fn largest_error(blocks: &[BlockBounds; BLOCKS]) -> f64 {
    blocks.iter().map(|b| b.error_m).fold(0.0, f64::max)
}

/// The rectangle of block `index` of a node.
pub fn block_rect(tree: &QuadTree, key: NodeKey, index: usize) -> crate::surface::world::Rect {
    let r = tree.rect(key);
    let side = (r.max[0] - r.min[0]) / BLOCKS_PER_SIDE as f64;
    let (bx, by) = (index % BLOCKS_PER_SIDE, index / BLOCKS_PER_SIDE);
    let min = [r.min[0] + bx as f64 * side, r.min[1] + by as f64 * side];
    crate::surface::world::Rect {
        min,
        max: [min[0] + side, min[1] + side],
    }
}

/// The index of the parent's block that contains block `index` of `key` (not the root).
pub fn parent_block(key: NodeKey, index: usize) -> usize {
    let (bx, by) = (index % BLOCKS_PER_SIDE, index / BLOCKS_PER_SIDE);
    let px = usize::midpoint((key.ix as usize & 1) * BLOCKS_PER_SIDE, bx);
    let py = usize::midpoint((key.iy as usize & 1) * BLOCKS_PER_SIDE, by);
    py * BLOCKS_PER_SIDE + px
}

/// Linear interpolation of vertex heights `v` ((n+1)^2, row-major) at fractional grid position
/// (gx, gy), using the triangulation with diagonals from (i, j) to (i+1, j+1).
pub fn interpolate_grid(v: &[f32], n: usize, gx: f64, gy: f64) -> f64 {
    // `as usize` truncates: the floor for the non-negative grid positions callers pass (and no
    // libm call).
    let i = (gx as usize).min(n - 1);
    let j = (gy as usize).min(n - 1);
    let w = n + 1;
    let corners = [
        j * w + i,
        j * w + i + 1,
        (j + 1) * w + i,
        (j + 1) * w + i + 1,
    ];
    crate::surface::map_error::lin(
        corners.map(|k| f64::from(v[k])),
        gx - i as f64,
        gy - j as f64,
    )
}

/// The stored bounds of a node from its own measurement ([`measure`]) and its parent's stored
/// bounds (`None` at the root): per block `error = min(max(e, U), E(parent block))`, and the
/// node's error the largest block error.
pub fn monotone(key: NodeKey, own: NodeBounds, parent: Option<NodeBounds>) -> NodeBounds {
    let mut out = own;
    if let Some(p) = parent {
        for (i, b) in out.blocks.iter_mut().enumerate() {
            b.error_m = b.error_m.min(p.blocks[parent_block(key, i)].error_m);
        }
        out.error_m = largest_error(&out.blocks);
    }
    out
}

/// Bounds of a node whose vertex spacing is one of the map-error grids
/// ([`crate::surface::map_error`], computed once at load): per block, the stored bound of the
/// grid's own error and of every finer grid's, and the stored height range; no surface
/// evaluation. `None` where the node's spacing is not such a grid or a block is not a whole
/// block of the map.
pub fn from_map_error(world: &World, tree: &QuadTree, key: NodeKey) -> Option<NodeBounds> {
    let k = world
        .map_error
        .level_of_spacing(tree.spacing_m(key.level))?;
    let stored_blocks =
        world
            .map_error
            .blocks_at(k, block_rect(tree, key, 0).min, BLOCKS_PER_SIDE)?;
    let mut blocks = [BlockMeasure::EMPTY; BLOCKS];
    for (b, stored) in blocks.iter_mut().zip(stored_blocks) {
        *b = BlockMeasure {
            lo: stored.z_min_m,
            hi: stored.z_max_m,
            own: stored.error_m,
            children: stored.finer_error_m,
            deeper: 0.0,
            measured: 0.0,
        };
    }
    let has_vegetation = crate::vegetation::representation::has_vegetation(world, tree.rect(key));
    Some(finish(tree, key, &blocks, has_vegetation))
}

/// The height range, the error bound `e(N)` of one node's own mesh and the bound `U(N)` of its
/// descendants' meshes, per block and for the whole node: from the map-error grids where the
/// node's spacing is one ([`from_map_error`], no surface evaluation), else measured
/// ([`measure_surface`], about 17k surface evaluations; see the module docs). The blocks'
/// `error_m` is `max(e, U)` here, before [`monotone`].
///
/// A leaf whose parent is measured on the surface takes its bounds from its parent's check
/// lattice ([`measure_with_leaves`]): the same lattice, twice as coarse as the leaf's own, so
/// they are looser, and a leaf's error only bounds how it is drawn (it is never split).
pub fn measure(world: &World, tree: &QuadTree, key: NodeKey) -> NodeBounds {
    if let Some(b) = from_map_error(world, tree, key) {
        return b;
    }
    let by = measured_with(world, tree, key);
    if by != key
        && let (_, Some(leaves)) = measure_surface(world, tree, by, true)
    {
        let q = (key.iy as usize & 1) * 2 + (key.ix as usize & 1);
        return leaves[q];
    }
    measure_surface(world, tree, key, false).0
}

/// The node whose measurement gives `key`'s bounds: its parent for a leaf whose parent is
/// measured on the surface (see [`measure_with_leaves`]), else `key` itself.
pub fn measured_with(world: &World, tree: &QuadTree, key: NodeKey) -> NodeKey {
    match key.parent() {
        Some(p) if key.level == tree.max_level && from_map_error(world, tree, p).is_none() => p,
        _ => key,
    }
}

/// [`measure`] of `key`, and where its children are leaves and it is measured on the surface,
/// theirs (in [`NodeKey::children`]'s order) from the same lattice, with no more surface
/// evaluations: a stream measures the four leaves for the price of their parent.
pub fn measure_with_leaves(
    world: &World,
    tree: &QuadTree,
    key: NodeKey,
) -> (NodeBounds, Option<[NodeBounds; 4]>) {
    if key.level + 1 != tree.max_level {
        return (measure(world, tree, key), None);
    }
    if let Some(b) = from_map_error(world, tree, key) {
        return (b, None);
    }
    measure_surface(world, tree, key, true)
}

/// What a bounds store keeps when it measures `key` after its parent's stored bounds
/// (`parent`, `None` at the root): `key`'s stored bounds ([`monotone`]), and those of the
/// leaves measured with it ([`measure_with_leaves`]), each made monotone against `key`'s.
pub fn measure_stored(
    world: &World,
    tree: &QuadTree,
    key: NodeKey,
    parent: Option<NodeBounds>,
) -> (NodeBounds, impl Iterator<Item = (NodeKey, NodeBounds)>) {
    let (own, leaves) = measure_with_leaves(world, tree, key);
    let stored = monotone(key, own, parent);
    let leaves = leaves.into_iter().flat_map(move |l| {
        key.children()
            .into_iter()
            .zip(l)
            .map(move |(k, own)| (k, monotone(k, own, Some(stored))))
    });
    (stored, leaves)
}

/// [`measure`] by evaluating the surface on the node's check lattice (the module docs); with
/// `leaves`, also its children's bounds as leaves (`leaf_children`).
pub fn measure_surface(
    world: &World,
    tree: &QuadTree,
    key: NodeKey,
    leaves: bool,
) -> (NodeBounds, Option<[NodeBounds; 4]>) {
    let measured = measure_lattice(world, tree, key);
    let has_vegetation = crate::vegetation::representation::has_vegetation(world, tree.rect(key));
    let node = finish(tree, key, &measured.blocks, has_vegetation);
    let leaves = (leaves && measured.depth_below >= 1).then(|| {
        let cells = ChildCells {
            lattice: &measured.lattice,
            children: &measured.children,
            m: measured.m,
            regions: &measured.regions,
            between: &measured.between,
        };
        let kids = key.children();
        std::array::from_fn(|q| leaf_children(world, tree, kids[q], &cells, &measured.blocks))
    });
    (node, leaves)
}

/// What a map-error grid keeps of `key`'s measurement on its check lattice
/// ([`measure_surface`]), per block: `[z_min, z_max, e(N), U(N)]` before the f32 rounding of
/// vertices that [`from_map_error`] adds, as for the grids computed in
/// [`crate::surface::map_error`] (see [`super::precomputed`]).
pub fn measured_blocks(world: &World, tree: &QuadTree, key: NodeKey) -> [[f64; 4]; BLOCKS] {
    let blocks = measure_lattice(world, tree, key).blocks;
    let leaf = key.level >= tree.max_level;
    blocks.map(|b| [b.lo, b.hi, b.own, b.descendants_m(leaf)])
}

/// A node's blocks measured on its check lattice, with what its leaves' bounds need.
struct LatticeMeasure {
    blocks: [BlockMeasure; BLOCKS],
    lattice: Vec<f64>,
    children: Vec<f64>,
    m: usize,
    regions: CellRegions,
    between: Vec<[f64; 2]>,
    depth_below: u8,
}

/// The module docs' measurement of `key` on its check lattice, refined where loose.
fn measure_lattice(world: &World, tree: &QuadTree, key: NodeKey) -> LatticeMeasure {
    let r = tree.rect(key);
    let sub = CHECK_SUBDIV as usize;
    let c = tree.spacing_m(key.level) / f64::from(CHECK_SUBDIV);
    let m = NODE_QUADS as usize * sub;
    let w = m + 1;
    // F on the check lattice; the mesh's vertices are every `sub`-th lattice point, the four
    // children's every `sub / 2`-th.
    let axis = |from: f64| -> Vec<f64> { (0..=m).map(|i| from + i as f64 * c).collect() };
    let lattice = world.heights_on_lattice(&axis(r.min[0]), &axis(r.min[1]));
    let own = lattice_errors(&lattice, m, sub);
    let children = lattice_errors(&lattice, m, sub / 2);
    let regions = region_bounds_of_cells(world, r, c, m);
    let cells_per_block = m / BLOCKS_PER_SIDE;
    let block_of =
        |i: usize, j: usize| (j / cells_per_block) * BLOCKS_PER_SIDE + i / cells_per_block;
    let corners = |i: usize, j: usize| {
        [
            j * w + i,
            j * w + i + 1,
            (j + 1) * w + i,
            (j + 1) * w + i + 1,
        ]
    };
    let depth_below = (tree.max_level - key.level.min(tree.max_level)).min(3);
    // The between-points bounds of a whole check cell and of half a one, per region group.
    let between: Vec<[f64; 2]> = regions
        .values
        .iter()
        .map(|r| [r.between_m(c), r.between_m(0.5 * c)])
        .collect();
    // The cells are visited in square tiles that share their region bounds and lie in one
    // block, so per-tile extremes give exactly the per-cell results below (subtracting or adding
    // the same `between` keeps the order of rounded values).
    let tile = regions.group.min(cells_per_block);
    debug_assert!(
        cells_per_block.is_multiple_of(tile) && regions.group.is_multiple_of(tile),
        "tiles must lie in one block and one region group"
    );
    let tiles = m / tile;
    let children_at = |at: usize| if depth_below >= 1 { children[at] } else { 0.0 };
    // Pass 1: height ranges, and the errors measured at lattice points (true values: lower
    // bounds of each block's error; the grandchildren's are 0 there, their vertices). Per tile
    // also its points' largest own and children's errors, for pass 2.
    let mut blocks = [BlockMeasure::EMPTY; BLOCKS];
    let mut tile_max = vec![[0.0f64; 2]; tiles * tiles];
    for tj in 0..tiles {
        for ti in 0..tiles {
            let (i0, j0) = (ti * tile, tj * tile);
            let [between, _] = between[regions.index(i0, j0)];
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            let [mut own_max, mut children_max] = [0.0f64; 2];
            for j in j0..=j0 + tile {
                for at in j * w + i0..=j * w + i0 + tile {
                    lo = lo.min(lattice[at]);
                    hi = hi.max(lattice[at]);
                    own_max = own_max.max(own[at]);
                    children_max = children_max.max(children_at(at));
                }
            }
            let block = &mut blocks[block_of(i0, j0)];
            block.lo = block.lo.min(lo - between);
            block.hi = block.hi.max(hi + between);
            block.measured = block.measured.max(own_max).max(children_max);
            tile_max[tj * tiles + ti] = [own_max, children_max];
        }
    }
    // Pass 2: per cell, corner errors plus the between-points bound; cells whose bound may be
    // more than `refine::SLACK` over their block's measured error are refined by branch and
    // bound ([`super::refine`]). A tile whose largest corner errors pass passes as a whole (each
    // cell's bound is at most the tile's); the others are taken cell by cell.
    let refiner = super::refine::Refiner {
        world,
        origin_m: r.min,
        check_m: c,
        vertices: vertex_heights(&lattice, m, sub),
        child_vertices: vertex_heights(&lattice, m, sub / 2),
        lattice_vertices: vertex_heights(&lattice, m, 1),
        depth_below,
        splits_per_block: if c > 0.25 * world.cell_spacings_m().0 {
            super::refine::SPLITS_PER_COARSE_BLOCK
        } else {
            super::refine::SPLITS_PER_BLOCK
        },
    };
    let mut loose: Vec<Vec<super::refine::Cell>> = vec![Vec::new(); BLOCKS];
    let take = |block: &mut BlockMeasure, e: super::refine::Errors| {
        block.own = block.own.max(e[0]);
        block.children = block.children.max(e[1]);
        block.deeper = block.deeper.max(e[2]);
    };
    let worst = |e: super::refine::Errors| e.iter().copied().fold(0.0, f64::max);
    for tj in 0..tiles {
        for ti in 0..tiles {
            let (i0, j0) = (ti * tile, tj * tile);
            let b = block_of(i0, j0);
            let [whole, half] = between[regions.index(i0, j0)];
            let [own_max, children_max] = tile_max[tj * tiles + ti];
            let e = refiner.bounds([own_max, children_max, 0.0], whole, half);
            if worst(e) <= blocks[b].measured * super::refine::SLACK {
                take(&mut blocks[b], e);
                continue;
            }
            for j in j0..j0 + tile {
                for i in i0..i0 + tile {
                    let ks = corners(i, j);
                    let (own_max, children_max) =
                        ks.iter().fold((0.0f64, 0.0f64), |(o, ch), &k| {
                            (o.max(own[k]), ch.max(children[k]))
                        });
                    let e = refiner.bounds([own_max, children_max, 0.0], whole, half);
                    if worst(e) > blocks[b].measured * super::refine::SLACK {
                        loose[b].push(super::refine::Cell {
                            x0: i as f64,
                            y0: j as f64,
                            size: 1.0,
                            corners: ks.map(|k| [own[k], children[k], 0.0]),
                            region: *regions.at(i, j),
                        });
                    } else {
                        take(&mut blocks[b], e);
                    }
                }
            }
        }
    }
    // Refined in row-major order of the cells, whatever the tiles' order (the refinement's ties
    // go by order).
    for cells in &mut loose {
        cells.sort_by(|a, b| a.y0.total_cmp(&b.y0).then(a.x0.total_cmp(&b.x0)));
    }
    for (b, cells) in loose.into_iter().enumerate() {
        if !cells.is_empty() {
            let e = refiner.refine_block(cells, blocks[b].measured);
            take(&mut blocks[b], e);
        }
    }
    LatticeMeasure {
        blocks,
        lattice,
        children,
        m,
        regions,
        between,
        depth_below,
    }
}

/// What a node's measurement knows of its children's meshes: the check lattice's heights and
/// the children's errors at its points (`(m + 1)^2` each), and the cells' between-points bounds
/// (whole cell, half cell) per region group.
struct ChildCells<'a> {
    lattice: &'a [f64],
    children: &'a [f64],
    m: usize,
    regions: &'a CellRegions,
    between: &'a [[f64; 2]],
}

/// The bounds of `child`, a leaf, from its parent's measurement (`parent_blocks`, `cells`):
/// the module docs' children's term, taken per block of the child. The child's mesh is the
/// grid of every `CHECK_SUBDIV / 2`-th lattice point, so per check cell of the child's square
/// its error is at most the largest error at the cell's corners plus the cell's between-points
/// bound, and its heights lie within the corners' range widened by the same bound; also at most
/// the parent block's children's term (refined there where it was loose).
///
/// The cells are taken in square tiles that lie in one block of the child and one region
/// group (one `between`), so each tile's extremes over its points give exactly the per-cell
/// results (adding or subtracting the same `between` keeps the order of rounded values), with
/// each lattice point read once per tile instead of once per cell corner.
fn leaf_children(
    world: &World,
    tree: &QuadTree,
    child: NodeKey,
    cells: &ChildCells,
    parent_blocks: &[BlockMeasure; BLOCKS],
) -> NodeBounds {
    let (m, w) = (cells.m, cells.m + 1);
    let half = m / 2;
    let per_block = half / BLOCKS_PER_SIDE;
    let tile = cells.regions.group.min(per_block);
    debug_assert!(
        per_block.is_multiple_of(tile) && cells.regions.group.is_multiple_of(tile),
        "tiles must lie in one block of the child and one region group"
    );
    let (i0, j0) = (
        (child.ix as usize & 1) * half,
        (child.iy as usize & 1) * half,
    );
    let mut blocks = [BlockMeasure::EMPTY; BLOCKS];
    for tj in (0..half).step_by(tile) {
        for ti in (0..half).step_by(tile) {
            let (gi, gj) = (i0 + ti, j0 + tj);
            let [between, _] = cells.between[cells.regions.index(gi, gj)];
            let (mut lo, mut hi, mut error) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
            for row in gj..=gj + tile {
                let at = row * w + gi;
                for (&z, &e) in cells.lattice[at..=at + tile]
                    .iter()
                    .zip(&cells.children[at..=at + tile])
                {
                    lo = lo.min(z);
                    hi = hi.max(z);
                    error = error.max(e);
                }
            }
            let b = &mut blocks[(tj / per_block) * BLOCKS_PER_SIDE + ti / per_block];
            b.lo = b.lo.min(lo - between);
            b.hi = b.hi.max(hi + between);
            b.own = b.own.max(error + between);
        }
    }
    for (i, b) in blocks.iter_mut().enumerate() {
        b.own = b.own.min(parent_blocks[parent_block(child, i)].children);
    }
    let has_vegetation = crate::vegetation::representation::has_vegetation(world, tree.rect(child));
    finish(tree, child, &blocks, has_vegetation)
}

/// One block's measurement: height range, own-mesh error bound, children's-mesh error bound,
/// the bound for deeper descendants, and the largest error measured at a lattice point (own or
/// children's).
#[derive(Clone, Copy)]
struct BlockMeasure {
    lo: f64,
    hi: f64,
    own: f64,
    children: f64,
    deeper: f64,
    measured: f64,
}

impl BlockMeasure {
    const EMPTY: Self = Self {
        lo: f64::INFINITY,
        hi: f64::NEG_INFINITY,
        own: 0.0,
        children: 0.0,
        deeper: 0.0,
        measured: 0.0,
    };

    /// The bound `U` of every descendant's mesh in the block (none for a leaf's).
    fn descendants_m(&self, leaf: bool) -> f64 {
        if leaf {
            0.0
        } else {
            self.children.max(self.deeper)
        }
    }
}

/// Node bounds from the blocks' measurements: f32 vertex rounding added (relative 2^-24 of the
/// height magnitude, twice for safety: descendant vertices lie in the same proven range); leaves
/// have no descendants.
fn finish(
    tree: &QuadTree,
    key: NodeKey,
    m: &[BlockMeasure; BLOCKS],
    vegetation: bool,
) -> NodeBounds {
    let lo = m.iter().map(|b| b.lo).fold(f64::INFINITY, f64::min);
    let hi = m.iter().map(|b| b.hi).fold(f64::NEG_INFINITY, f64::max);
    let rounding = 2.0 * hi.abs().max(lo.abs()) * f64::from(f32::EPSILON);
    let leaf = key.level >= tree.max_level;
    let descendants = |b: &BlockMeasure| {
        if leaf {
            0.0
        } else {
            b.descendants_m(leaf) + rounding
        }
    };
    let blocks: [BlockBounds; BLOCKS] = std::array::from_fn(|i| BlockBounds {
        z_min_m: m[i].lo,
        z_max_m: m[i].hi,
        error_m: (m[i].own + rounding).max(descendants(&m[i])),
    });
    NodeBounds {
        z_min_m: lo,
        z_max_m: hi,
        error_m: largest_error(&blocks),
        mesh_error_m: m.iter().map(|b| b.own + rounding).fold(0.0, f64::max),
        descendants_error_m: m.iter().map(descendants).fold(0.0, f64::max),
        vegetation_error_m: if vegetation {
            crate::vegetation::representation::ERROR_PER_SPACING * tree.spacing_m(key.level)
        } else {
            0.0
        },
        blocks,
    }
}

/// `|M - F|` at every point of the `(m + 1)^2` check lattice, where `M` interpolates the lattice
/// values at every `step`-th point (stored as f32, as meshes store them) with diagonals from
/// (i, j) to (i + 1, j + 1) ([`interpolate_grid`]'s triangulation).
fn lattice_errors(lattice: &[f64], m: usize, step: usize) -> Vec<f64> {
    let vertices = vertex_heights(lattice, m, step);
    let (quads, w, per) = (m / step, m + 1, step as f64);
    // [`interpolate_grid`]'s quad and fraction per lattice column (the same per row).
    let axis: Vec<(usize, f64)> = (0..w)
        .map(|i| {
            let g = i as f64 / per;
            let q = (g as usize).min(quads - 1);
            (q, g - q as f64)
        })
        .collect();
    let mut out = Vec::with_capacity(w * w);
    for (j, &(qj, fy)) in axis.iter().enumerate() {
        let (below, above) = (
            &vertices[qj * (quads + 1)..],
            &vertices[(qj + 1) * (quads + 1)..],
        );
        let row = &lattice[j * w..][..w];
        out.extend(axis.iter().zip(row).map(|(&(qi, fx), &f)| {
            let v = [below[qi], below[qi + 1], above[qi], above[qi + 1]].map(f64::from);
            (crate::surface::map_error::lin(v, fx, fy) - f).abs()
        }));
    }
    out
}

/// Mesh vertex heights (as f32, as meshes store them) of the grid with vertices every `step`-th
/// point of the `(m + 1)^2` lattice.
fn vertex_heights(lattice: &[f64], m: usize, step: usize) -> Vec<f32> {
    let w = m + 1;
    let mut out = Vec::with_capacity((m / step + 1) * (m / step + 1));
    for j in (0..=m).step_by(step) {
        out.extend(
            lattice[j * w..][..w]
                .iter()
                .step_by(step)
                .map(|&z| z as f32),
        );
    }
    out
}

/// The region bounds of every check cell of a node, stored per group of `group^2` cells that
/// share them.
struct CellRegions {
    group: usize,
    per_row: usize,
    values: Vec<crate::surface::world::RegionBounds>,
}

impl CellRegions {
    /// Index in `values` of check cell (i, j)'s group.
    fn index(&self, i: usize, j: usize) -> usize {
        (j / self.group) * self.per_row + i / self.group
    }

    fn at(&self, i: usize, j: usize) -> &crate::surface::world::RegionBounds {
        &self.values[self.index(i, j)]
    }
}

/// The region bounds of the `m^2` check cells (side `c`) of the node `r`. Where check cells
/// tile the height cells, ground cells and decal blocks exactly (aligned, at most one cell in
/// size) and the node is inside the map, a cell's region bounds are its map cells' values, read
/// directly, and they are the same for every check cell in the largest aligned group of `2^k`
/// cells that still lies inside one map cell of each kind, so they are read once per group.
/// Elsewhere each check cell's region is bounded on its own.
fn region_bounds_of_cells(
    world: &World,
    r: crate::surface::world::Rect,
    c: f64,
    m: usize,
) -> CellRegions {
    let (hs, gs) = world.cell_spacings_m();
    let o = world.origin_m();
    let size = world.size_m();
    let block_m = crate::surface::decals::DECAL_BLOCK_M;
    let divides = |len: f64| {
        [hs, gs, block_m]
            .iter()
            .all(|&big| len <= big && ((big / len) - (big / len).round()).abs() < 1e-9)
    };
    let inside = r.max[0] <= o[0] + size[0] + 1e-9 && r.max[1] <= o[1] + size[1] + 1e-9;
    let direct = divides(c) && inside;
    let mut group = 1;
    while direct && group * 2 <= m && divides(c * (group * 2) as f64) {
        group *= 2;
    }
    let per_row = m / group;
    let g = c * group as f64;
    let mut values = Vec::with_capacity(per_row * per_row);
    for j in 0..per_row {
        for i in 0..per_row {
            let cell = crate::surface::world::Rect {
                min: [r.min[0] + i as f64 * g, r.min[1] + j as f64 * g],
                max: [r.min[0] + (i + 1) as f64 * g, r.min[1] + (j + 1) as f64 * g],
            };
            values.push(if direct {
                world.cell_region_bounds(cell)
            } else {
                world.region_bounds(cell)
            });
        }
    }
    CellRegions {
        group,
        per_row,
        values,
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
        // Measuring a parent of leaves stored them too.
        if let Some(b) = self.map.get(&key) {
            return *b;
        }
        let (b, leaves) = measure_stored(world, tree, key, parent);
        self.computed += 1;
        self.map.insert(key, b);
        for (k, leaf) in leaves {
            self.map.entry(k).or_insert(leaf);
        }
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

    /// The bounds if already measured, lent (no copy).
    pub fn lend(&self, key: NodeKey) -> Option<&NodeBounds> {
        self.map.get(&key)
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
