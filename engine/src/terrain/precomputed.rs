//! The bounds of every node whose vertex spacing is a quarter of the map's height spacing (the
//! 32 m nodes of a 4 m map), measured once per map and kept with the map-error grids, so the
//! stream reads them instead of measuring them while the camera waits.
//!
//! [`crate::surface::map_error`] bounds the grids of spacing `hs 2^k`, `k >= -1`, on a check
//! lattice of a quarter of the height spacing; the grid of spacing `hs / 4` is that lattice
//! itself, where its argument only gives the between-points bound (loose). Those nodes are the
//! most numerous of a low flight's selection (91 of 240 prepared nodes at 40 m above ground on
//! the default map) and their measurement on their own 0.25 m check lattice costs about 1 ms
//! each at run time. Here every such node that lies wholly inside the map is measured once,
//! by exactly the run-time measurement ([`bounds::measured_blocks`], the module docs of
//! [`bounds`]), on all cores, and its blocks become the finest map-error grid: the stored values
//! are the run-time ones rounded outwards to f32, so the bounds stay proven and as tight.
//! Nodes on a partial edge of the map are still measured at run time.

use super::bounds::{self, BLOCKS, BLOCKS_PER_SIDE};
use super::quadtree::{NodeKey, QuadTree};
use crate::surface::World;
use std::path::Path;
use worldgen::progress::Progress;

/// Changes whenever the node measurement ([`bounds`], [`super::refine`]) changes what it stores:
/// part of the cache key of the map-error grids, so a cache written by another measurement is
/// not used.
pub const MEASUREMENT_VERSION: u64 = 1;

/// The level whose nodes have vertex spacing `hs / 4`, if the map has one that is neither a
/// leaf nor a parent of leaves (those take their bounds from their parent's lattice).
pub fn level(world: &World, tree: &QuadTree) -> Option<u8> {
    let quarter = world.cell_spacings_m().0 / 4.0;
    (0..tree.max_level.saturating_sub(1)).find(|&l| tree.spacing_m(l) == quarter)
}

/// The measured blocks of the nodes of [`level`] that lie wholly inside the map, as a map-error
/// grid.
#[derive(Debug, Clone)]
pub struct NodeGrid {
    /// Nodes measured.
    pub nodes: usize,
    /// Blocks per row and rows.
    pub per_row: usize,
    pub rows: usize,
    /// `[z_min, z_max, e(N), U(N)]` per block, row-major from the map's south-west corner.
    pub blocks: Vec<[f64; 4]>,
}

/// Measures the nodes of [`level`] inside the map, on all cores, reporting one unit of
/// `progress` per node; `None` where the map has no such level or no such node.
pub fn measure(world: &World, progress: &dyn Progress) -> Option<NodeGrid> {
    let tree = QuadTree::new(world.origin_m(), world.size_m());
    let level = level(world, &tree)?;
    let side_m = tree.node_size_m(level);
    let whole = |size_m: f64| ((size_m + 1e-9) / side_m).floor() as usize;
    let size = world.size_m();
    let (nx, ny) = (whole(size[0]), whole(size[1]));
    if nx == 0 || ny == 0 {
        return None;
    }
    progress.begin(&format!("bounds of {side_m} m nodes"), (nx * ny) as u64);
    let mut nodes = vec![[[0.0f64; 4]; BLOCKS]; nx * ny];
    worldgen::par::for_each_row(
        &mut nodes,
        1,
        worldgen::par::thread_count(0),
        |i, out| {
            let key = NodeKey {
                level,
                ix: (i % nx) as u32,
                iy: (i / nx) as u32,
            };
            out[0] = bounds::measured_blocks(world, &tree, key);
        },
        &|n| progress.advance(n),
    );
    progress.end();
    // Blocks row-major over the map: block (bx, by) is block (bx % 4, by % 4) of node
    // (bx / 4, by / 4).
    let (per_row, rows) = (nx * BLOCKS_PER_SIDE, ny * BLOCKS_PER_SIDE);
    let blocks = (0..rows)
        .flat_map(|by| (0..per_row).map(move |bx| (bx, by)))
        .map(|(bx, by)| {
            let node = &nodes[(by / BLOCKS_PER_SIDE) * nx + bx / BLOCKS_PER_SIDE];
            node[(by % BLOCKS_PER_SIDE) * BLOCKS_PER_SIDE + bx % BLOCKS_PER_SIDE]
        })
        .collect();
    Some(NodeGrid {
        nodes: nx * ny,
        per_row,
        rows,
        blocks,
    })
}

/// [`measure`]s the nodes and adds their blocks to `world`'s map-error grids as the finest grid
/// (after the map's own grids are computed).
fn add_to(world: &mut World, progress: &dyn Progress) {
    let t0 = std::time::Instant::now();
    if let Some(grid) = measure(world, progress) {
        world
            .map_error
            .insert_finer(grid.per_row, grid.rows, &grid.blocks);
        log::info!(
            "bounds of {} nodes measured in {:.1} s",
            grid.nodes,
            t0.elapsed().as_secs_f64()
        );
    }
}

/// Computes `world`'s map-error grids and adds this module's finest grid: what [`open`] keeps
/// in its cache file (the key of that file: [`MEASUREMENT_VERSION`]).
pub fn compute(world: &mut World, progress: &dyn Progress) {
    world.compute_error_grids();
    add_to(world, progress);
}

/// Opens `map` as the stream uses it: the map-error grids ([`World::new`]) and this module's
/// finest grid, kept in `cache_file` between runs when one is given (read back when it holds them
/// for this surface and this measurement, else computed and written).
pub fn open(map: worldgen::Map, cache_file: Option<&Path>, progress: &dyn Progress) -> World {
    open_world(World::without_error_grids(map), cache_file, progress)
}

/// [`open`] for a world already made without its error grids (for example with paged
/// max-pyramids, [`World::paged_without_error_grids`]).
pub fn open_world(mut world: World, cache_file: Option<&Path>, progress: &dyn Progress) -> World {
    let compute = |w: &mut World| compute(w, progress);
    if let Some(path) = cache_file {
        return World::with_error_cache(world, path, MEASUREMENT_VERSION, compute);
    }
    compute(&mut world);
    world
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::bounds::{from_map_error, measure_surface};
    use worldgen::progress::Silent;

    /// Every 32 m node of the tiny map reads its bounds from the finest grid, and they are the
    /// run-time measurement's, rounded outwards to f32 (never below, within f32 rounding above).
    #[test]
    fn stored_node_bounds_are_the_run_time_measurement_rounded_outwards() {
        let map = crate::test_maps::tiny_map();
        let world = open(map, None, &Silent);
        let tree = QuadTree::new(world.origin_m(), world.size_m());
        let level = level(&world, &tree).expect("the tiny map has 32 m nodes");
        assert_eq!(tree.node_size_m(level), 32.0);
        let n = 1u32 << level;
        let mut checked = 0;
        for iy in 0..n {
            for ix in (0..n).step_by(3) {
                let key = NodeKey { level, ix, iy };
                let stored = from_map_error(&world, &tree, key).expect("a stored node");
                let measured = measure_surface(&world, &tree, key, false).0;
                let close = |s: f64, m: f64| (s - m).abs() <= 1e-6 * (1.0 + m.abs());
                for (s, m) in stored.blocks.iter().zip(&measured.blocks) {
                    assert!(
                        s.error_m >= m.error_m && close(s.error_m, m.error_m),
                        "{key:?}: stored error {} m, measured {} m",
                        s.error_m,
                        m.error_m
                    );
                    assert!(s.z_min_m <= m.z_min_m && close(s.z_min_m, m.z_min_m));
                    assert!(s.z_max_m >= m.z_max_m && close(s.z_max_m, m.z_max_m));
                }
                assert!(stored.mesh_error_m >= measured.mesh_error_m);
                assert!(stored.descendants_error_m >= measured.descendants_error_m);
                checked += 1;
            }
        }
        assert!(checked > 60, "{checked} nodes");
    }
}
