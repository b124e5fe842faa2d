//! Section `terrain`: node bounds (error + AABB), grid mesh and TIN mesh per node, and the
//! CPU phases' throughput.

use crate::report::{Report, bar, throughput};
use engine::camera::Camera;
use engine::surface::World;
use engine::terrain::bounds::{self, BoundsCache};
use engine::terrain::mesh::{self};
use engine::terrain::quadtree::{NodeKey, QuadTree};
use engine::terrain::select::{SelectParams, select};
use engine::terrain::tiles::TileCache;
use engine::terrain::tin;
use std::time::Instant;

/// Nodes a flight would draw at tau = 2 px (a realistic mix of levels).
pub(crate) fn flight_nodes(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    limit: usize,
) -> Vec<NodeKey> {
    let mut cache = BoundsCache::new();
    let mut keys: Vec<NodeKey> = Vec::new();
    for cam in cams {
        let s = select(
            world,
            tree,
            &mut cache,
            cam,
            SelectParams::culled(2.0, tree),
        );
        keys.extend(s.nodes.iter().map(|n| n.key));
    }
    keys.sort();
    keys.dedup();
    // Spread the sample over the list, deterministically.
    let step = (keys.len() / limit.max(1)).max(1);
    keys.into_iter().step_by(step).take(limit).collect()
}

pub(crate) fn section_terrain(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
    workers: usize,
) {
    let keys = flight_nodes(
        world,
        tree,
        &cams[..cams.len().min(if quick { 2 } else { 16 })],
        if quick { 24 } else { 240 },
    );
    let b = bar(keys.len() as u64 * 3, "terrain nodes");
    let mut t_bounds = Vec::new();
    let mut t_mesh = Vec::new();
    let mut t_tin = Vec::new();
    let mut cache = BoundsCache::new();
    let mut tiles = TileCache::new();
    let (mut tri_grid, mut tri_tin) = (0usize, 0usize);
    // Per measurement as in the engine: a leaf's bounds come with its parent's measurement
    // where the parent is measured on the surface, so that parent is measured (once) instead.
    let measured: std::collections::BTreeSet<NodeKey> = keys
        .iter()
        .map(|&k| bounds::measured_with(world, tree, k))
        .collect();
    for &k in &measured {
        let t0 = Instant::now();
        std::hint::black_box(bounds::measure_with_leaves(world, tree, k));
        t_bounds.push(t0.elapsed().as_secs_f64());
    }
    let (mut raised, mut ratio_sum) = (0usize, 0.0f64);
    for &k in &keys {
        let own = bounds::measure(world, tree, k);
        let stored = cache.get(world, tree, k);
        if stored.error_m > own.mesh_error_m * (1.0 + 1e-12) {
            raised += 1;
        }
        ratio_sum += stored.error_m / own.mesh_error_m.max(1e-9);
        b.inc(1);
    }
    // Mesh time with bounds (own and neighbours') already known, as in the engine's jobs.
    for &k in &keys {
        mesh::build_with_tiles(world, tree, &mut cache, &mut tiles, k);
    }
    let mut meshes = Vec::new();
    for &k in &keys {
        let t0 = Instant::now();
        let m = mesh::build_with_tiles(world, tree, &mut cache, &mut tiles, k);
        t_mesh.push(t0.elapsed().as_secs_f64());
        meshes.push(m);
        b.inc(1);
    }
    for m in &meshes {
        let t0 = Instant::now();
        let (t, _) = tin::build(m, 0.5 * m.bounds.error_m);
        t_tin.push(t0.elapsed().as_secs_f64());
        tri_grid += m.surface_index_count as usize / 3;
        tri_tin += t.surface_index_count as usize / 3;
        b.inc(1);
    }
    b.finish_and_clear();
    let params = format!("{} nodes from the flight at tau 2", keys.len());
    let leaves_with_parent = keys
        .iter()
        .filter(|&&k| bounds::measured_with(world, tree, k) != k)
        .count();
    r.timings(
        "terrain",
        "node bounds (error + AABB)",
        t_bounds,
        &format!(
            "{params}: {} measurements, {leaves_with_parent} of the nodes are leaves whose \
             bounds come with their parent's (measured instead, with its four leaves)",
            measured.len()
        ),
    );
    let precomputed = keys
        .iter()
        .filter(|&&k| bounds::from_map_error(world, tree, k).is_some())
        .count();
    r.add(
        "terrain",
        "node bounds read from the map-error grids (no surface evaluation)",
        100.0 * precomputed as f64 / keys.len().max(1) as f64,
        "%",
        &format!("{params}; the rest are measured on their check lattice"),
    );
    load_rows(world, r);
    r.add(
        "terrain",
        "monotone step: nodes whose stored error exceeds their own mesh bound",
        100.0 * raised as f64 / keys.len().max(1) as f64,
        "%",
        &params,
    );
    r.add(
        "terrain",
        "monotone step: mean stored / own mesh error",
        ratio_sum / keys.len().max(1) as f64,
        "ratio",
        &params,
    );
    r.timings(
        "terrain",
        "node grid mesh (33x33 + skirts)",
        t_mesh,
        &params,
    );
    r.timings(
        "terrain",
        "node TIN mesh (target 0.5 x error)",
        t_tin,
        &params,
    );
    r.add(
        "terrain",
        "TIN / grid surface triangles",
        tri_tin as f64 / tri_grid.max(1) as f64,
        "ratio",
        &params,
    );
    let per = if quick { 4 } else { 24 };
    // Cold caches per node, except the ancestors' bounds (always known first in the engine),
    // and a leaf's that came with its parent's.
    let mut ancestors = BoundsCache::new();
    for &k in &keys {
        if let Some(p) = k.parent() {
            ancestors.get(world, tree, p);
        }
    }
    for &k in &keys {
        if bounds::measured_with(world, tree, k) == k {
            ancestors.remove(k);
        }
    }
    node_preparation(world, tree, &keys, &ancestors, r);
    for w in [1, workers] {
        let nps = throughput(w, per, &|i| {
            let mut c = ancestors.clone();
            let mut t = TileCache::new();
            let k = keys[i % keys.len()];
            std::hint::black_box(mesh::build_with_tiles(world, tree, &mut c, &mut t, k));
        });
        r.add(
            "terrain",
            &format!("node CPU phases (bounds + mesh), {w} worker(s)"),
            nps,
            "nodes/s",
            "cold caches per node",
        );
    }
}

/// What opening the map costs once per map: the map-error grids and the 32 m nodes' bounds (both
/// kept in the map's surface-error cache file afterwards).
fn load_rows(world: &World, r: &mut Report) {
    let t0 = Instant::now();
    let grids = engine::surface::map_error::MapErrorPyramid::new(world);
    r.add(
        "terrain",
        "map-error grids computed at load",
        t0.elapsed().as_secs_f64() * 1e3,
        "ms",
        &format!(
            "the map's own {} grids, on all cores, once per map",
            grids.level_count()
        ),
    );
    let t0 = Instant::now();
    if let Some(g) = engine::terrain::precomputed::measure(world, &worldgen::progress::Silent) {
        r.add(
            "terrain",
            "32 m nodes' bounds measured at load",
            t0.elapsed().as_secs_f64() * 1e3,
            "ms",
            &format!(
                "{} nodes (the finest map-error grid, {:.1} MiB), on all cores, once per map \
                 (kept in the map's surface-error cache file)",
                g.nodes,
                (g.blocks.len() * 16) as f64 / f64::from(1 << 20)
            ),
        );
    }
}

/// Node preparation, every CPU phase of a streaming job together (bounds, tiles and grid mesh,
/// vegetation), per node on one core, caches cold except the ancestors' bounds.
fn node_preparation(
    world: &World,
    tree: &QuadTree,
    keys: &[NodeKey],
    ancestors: &BoundsCache,
    r: &mut Report,
) {
    let placer = engine::vegetation::Placer::new(world);
    let mut times: Vec<f64> = keys
        .iter()
        .map(|&k| {
            let mut c = ancestors.clone();
            let mut t = TileCache::new();
            let start = Instant::now();
            std::hint::black_box(mesh::build_with_tiles(world, tree, &mut c, &mut t, k));
            std::hint::black_box(engine::vegetation::node_vegetation(world, &placer, tree, k));
            start.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let params = format!(
        "{} nodes from the flight at tau 2, bounds + tiles + grid mesh + vegetation, 1 core",
        keys.len()
    );
    for (name, q) in [("p50", 0.5), ("p99", 0.99)] {
        r.add(
            "terrain",
            &format!("node preparation, all CPU phases, {name}"),
            apps::percentile(&times, q) * 1e6,
            "µs",
            &params,
        );
    }
}
