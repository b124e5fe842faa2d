//! Terrain quad tree hard cases: conservative bounds, pixel-error honesty, watertightness at
//! any level difference, cliffs / spikes / flat sea / borders, far from the origin, determinism.

use engine::camera::Camera;
use engine::surface::decals::FLAT_MARGIN_M;
use engine::surface::world::World;
use engine::terrain::bounds::{BoundsCache, parent_block};
use engine::terrain::mesh::NodeMesh;
use engine::terrain::quadtree::{NodeKey, QuadTree};
use engine::terrain::select::{SelectParams, select};
use engine::terrain::tiles::TileCache;
use glam::DVec3;
use std::collections::HashMap as Map;
use tests::terrain::{
    build_mesh, build_selection, cliff_world, measure_true_block_errors, measure_true_error,
    random_camera, ray_mesh, shifted, tiny_world, tree_of,
};
use worldgen::noise::unit3;

/// A measurement of each node's mesh as drawn (by node and decimation), made once.
struct PerDrawnMesh<T>(Map<(NodeKey, u8), T>);

impl<T> PerDrawnMesh<T> {
    fn get(
        &mut self,
        (world, tree): (&World, &QuadTree),
        (cache, tiles): (&mut BoundsCache, &mut TileCache),
        (key, decimation): (NodeKey, u8),
        measure: impl FnOnce(&NodeMesh) -> T,
    ) -> &T {
        self.0.entry((key, decimation)).or_insert_with(|| {
            measure(&build_mesh(world, tree, cache, tiles, key).decimated(decimation))
        })
    }
}

/// The block of `ancestor` that contains block `index` of `key` (a descendant of it, or itself).
fn covering_block(key: NodeKey, index: usize, ancestor: NodeKey) -> usize {
    let (mut k, mut i) = (key, index);
    while k != ancestor {
        i = parent_block(k, i);
        k = k.parent().expect("ancestor on the chain");
    }
    i
}

#[test]
fn bounds_are_conservative_on_hard_surfaces() {
    for (name, world) in [("tiny", tiny_world()), ("cliff", cliff_world())] {
        let tree = tree_of(&world);
        let mut cache = BoundsCache::new();
        let mut tiles = TileCache::new();
        let mut checked = 0;
        // Nodes at every level, at random places, plus the ones on the cliff, the spikes, the
        // sea edge and the map corners.
        let mut keys = Vec::new();
        for level in 0..=tree.max_level {
            let n = 1u32 << level;
            for i in 0..6i64 {
                let ix = (unit3(77, i, i64::from(level)) * f64::from(n)) as u32;
                let iy = (unit3(78, i, i64::from(level)) * f64::from(n)) as u32;
                keys.push(NodeKey { level, ix, iy });
            }
            for (x, y) in [
                (160.0, 300.0),
                (80.0, 360.0),
                (400.0, 400.0),
                (256.0, 200.0),
                (1.0, 1.0),
                (511.0, 511.0),
                (0.0, 511.0),
            ] {
                keys.extend(tree.key_at(level, world.origin_m()[0] + x, world.origin_m()[1] + y));
            }
            // On roads and paths (their shaping crosses the cliff in the cliff world).
            for d in &world.map.decals {
                let p = d.points[d.points.len() / 2];
                keys.extend(tree.key_at(level, p[0], p[1]));
            }
        }
        keys.sort();
        keys.dedup();
        for key in keys {
            let m = build_mesh(&world, &tree, &mut cache, &mut tiles, key);
            let (true_err, outside) = measure_true_error(&world, &tree, &m);
            assert!(
                true_err <= m.bounds.error_m,
                "{name} {key:?}: true error {true_err} m exceeds the bound {} m",
                m.bounds.error_m
            );
            assert!(
                outside <= 0.0,
                "{name} {key:?}: surface leaves the height range by {outside} m"
            );
            // And block by block: the selection projects each block's own bound.
            for (i, (err, out)) in measure_true_block_errors(&world, &tree, &m)
                .into_iter()
                .enumerate()
            {
                let b = m.bounds.blocks[i];
                assert!(
                    err <= b.error_m && out <= 0.0,
                    "{name} {key:?} block {i}: true error {err} m (bound {} m), outside {out} m",
                    b.error_m
                );
            }
            checked += 1;
        }
        assert!(checked > 40, "{name}: only {checked} nodes checked");
        // The bound is not absurdly loose at the finest level (it is measured, not guessed).
        let leaf = tree
            .key_at(
                tree.max_level,
                world.origin_m()[0] + 300.0,
                world.origin_m()[1] + 100.0,
            )
            .unwrap();
        let b = cache.get(&world, &tree, leaf);
        assert!(b.error_m < 0.05, "{name}: leaf bound {} m", b.error_m);
    }
}

/// Errors are monotone (a child's never exceeds its parent's) and a node's error bounds the true
/// error of its descendants' meshes too, on the test map and the cliff map (cliff, spikes, sea).
#[test]
fn errors_are_monotone_and_bound_every_descendant() {
    for (name, world) in [("tiny", tiny_world()), ("cliff", cliff_world())] {
        let tree = tree_of(&world);
        let mut cache = BoundsCache::new();
        let mut tiles = TileCache::new();
        let mut truth = PerDrawnMesh(Map::new());
        let (mut pairs, mut descendants, mut clamped) = (0usize, 0usize, 0usize);
        for i in 0..40i64 {
            // A random leaf (half of them on the cliff band, the spikes or a road) and its chain.
            let o = world.origin_m();
            let s = world.size_m();
            let (x, y) = if i % 2 == 0 {
                (o[0] + s[0] * unit3(91, i, 0), o[1] + s[1] * unit3(91, i, 1))
            } else {
                let d = &world.map.decals[(i as usize / 2) % world.map.decals.len()];
                let p = d.points[(i as usize * 7) % d.points.len()];
                match i % 4 {
                    1 => (p[0], p[1]),
                    _ => (
                        o[0] + 160.0 + unit3(92, i, 0),
                        o[1] + s[1] * unit3(92, i, 1),
                    ),
                }
            };
            let leaf = tree.key_at(tree.max_level, x, y).unwrap();
            let chain: Vec<_> = std::iter::once(leaf).chain(leaf.ancestors()).collect();
            for pair in chain.windows(2) {
                let (child, parent) = (pair[0], pair[1]);
                let (c, p) = (
                    cache.get(&world, &tree, child),
                    cache.get(&world, &tree, parent),
                );
                assert!(
                    c.error_m <= p.error_m,
                    "{name}: child {child:?} error {} m > parent {parent:?} error {} m",
                    c.error_m,
                    p.error_m
                );
                for (i, b) in c.blocks.iter().enumerate() {
                    let pb = p.blocks[parent_block(child, i)];
                    assert!(
                        b.error_m <= pb.error_m,
                        "{name}: {child:?} block {i} error {} m > its parent block's {} m",
                        b.error_m,
                        pb.error_m
                    );
                }
                if c.error_m < c.mesh_error_m {
                    clamped += 1;
                }
                pairs += 1;
            }
            // The true error of every node on the chain is bounded by each ancestor's error.
            for (d, &desc) in chain.iter().enumerate().step_by(3) {
                // Dense true errors per block of the descendant's mesh.
                let blocks =
                    *truth.get((&world, &tree), (&mut cache, &mut tiles), (desc, 0), |m| {
                        measure_true_block_errors(&world, &tree, m)
                    });
                for &anc in &chain[d..] {
                    let a = cache.get(&world, &tree, anc);
                    for (i, &(true_err, _)) in blocks.iter().enumerate() {
                        let e = a.blocks[covering_block(desc, i, anc)].error_m;
                        assert!(
                            true_err <= e && true_err <= a.error_m,
                            "{name}: descendant {desc:?} block {i} true error {true_err} m > \
                             ancestor {anc:?} block error {e} m"
                        );
                    }
                    descendants += 1;
                }
            }
        }
        assert!(
            pairs >= 240 && descendants > 100,
            "{name}: {pairs} pairs, {descendants} checks"
        );
        println!(
            "{name}: {pairs} parent/child pairs, {descendants} descendant checks, {clamped} clamped"
        );
    }
}

/// Every node of random leaf chains on the hard maps, whether its bounds come from the
/// precomputed map-error grids (nodes whose spacing is the height spacing times 2^k, k >= -1,
/// and the 32 m nodes of spacing a quarter of it, measured once per map) or are measured at run
/// time (the 16 m nodes, and the leaves from their parent's lattice): the bound of each block
/// covers the densely measured error, and the surface stays in the block's height range. The
/// precomputed path is really taken, for the 32 m nodes too.
#[test]
fn precomputed_and_measured_bounds_cover_the_dense_error_on_leaf_chains() {
    for (name, world) in [("tiny", tiny_world()), ("cliff", cliff_world())] {
        let tree = tree_of(&world);
        let mut cache = BoundsCache::new();
        let mut tiles = TileCache::new();
        let (o, s) = (world.origin_m(), world.size_m());
        let (mut precomputed, mut measured, mut derived) = (0usize, 0usize, 0usize);
        for i in 0..8i64 {
            // Half of the chains end on the cliff band (x = 160 m) of the cliff world.
            let x = if i % 2 == 0 {
                o[0] + s[0] * unit3(131, i, 0)
            } else {
                o[0] + 158.0 + 4.0 * unit3(131, i, 0)
            };
            let y = o[1] + s[1] * unit3(131, i, 1);
            let leaf = tree.key_at(tree.max_level, x, y).unwrap();
            for key in std::iter::once(leaf).chain(leaf.ancestors()) {
                match engine::terrain::bounds::from_map_error(&world, &tree, key) {
                    Some(_) => precomputed += 1,
                    None => measured += 1,
                }
                // A leaf whose parent is measured takes its bounds from the parent's lattice.
                derived += usize::from(
                    key.level == tree.max_level
                        && key.parent().is_some_and(|p| {
                            engine::terrain::bounds::from_map_error(&world, &tree, p).is_none()
                        }),
                );
                let m = build_mesh(&world, &tree, &mut cache, &mut tiles, key);
                for (b, (err, out)) in measure_true_block_errors(&world, &tree, &m)
                    .into_iter()
                    .enumerate()
                {
                    let bound = m.bounds.blocks[b].error_m;
                    assert!(
                        err <= bound && out <= 0.0,
                        "{name} {key:?} block {b}: dense error {err} m, bound {bound} m, \
                         outside the height range by {out} m"
                    );
                }
            }
        }
        // Per chain, levels 0 - 4 (512 m to 32 m) precomputed, the 16 m node and the leaf not.
        assert!(
            precomputed == 8 * 5 && measured == 8 * 2 && derived == 8,
            "{name}: {precomputed} precomputed, {measured} measured, {derived} leaves from \
             their parent's lattice"
        );
    }
}

#[test]
fn flat_sea_node_has_zero_error_and_a_flat_box() {
    let world = cliff_world();
    let tree = tree_of(&world);
    let mut cache = BoundsCache::new();
    // The south-east quarter is flat 0 m sea; a node well inside it is exact.
    let key = tree
        .key_at(3, world.origin_m()[0] + 400.0, world.origin_m()[1] + 60.0)
        .unwrap();
    let b = cache.get(&world, &tree, key);
    assert!(
        b.error_m < 1e-6 && b.z_min_m.abs() < 1e-6 && b.z_max_m.abs() < 1e-6,
        "{b:?}"
    );
}

#[test]
fn selected_nodes_respect_the_pixel_threshold() {
    for (name, world) in [("tiny", tiny_world()), ("cliff", cliff_world())] {
        let tree = tree_of(&world);
        let mut cache = BoundsCache::new();
        let mut tiles = TileCache::new();
        let mut truth = PerDrawnMesh(Map::new());
        let mut worst_ratio: f64 = 0.0;
        let (mut nodes, mut empty, mut finest_over) = (0usize, 0usize, 0usize);
        let mut decimated = [0usize; 3];
        for tau in [1.0, 2.0, 4.0] {
            for i in 0..50 {
                let cam = random_camera(&world, 5 + tau as u64, i, 30.0, 400.0, [320, 240]);
                let sel = select(
                    &world,
                    &tree,
                    &mut cache,
                    &cam,
                    SelectParams::culled(tau, &tree),
                );
                // A camera near the border looking out sees no ground; that is allowed, rarely.
                empty += usize::from(sel.nodes.is_empty());
                let mut over = 0;
                for s in &sel.nodes {
                    let finest = s.key.level == tree.max_level;
                    assert!(
                        s.error_px <= tau || finest,
                        "{name}: a coarser node over tau was kept"
                    );
                    over += u32::from(s.error_px > tau);
                    // The node's true error on the screen: dense samples of its mesh as drawn
                    // and of the surface, projected through the camera's matrices.
                    let samples = truth.get(
                        (&world, &tree),
                        (&mut cache, &mut tiles),
                        (s.key, s.decimation),
                        |m| engine::measure::node_error_samples(&world, &tree, m, 6),
                    );
                    let px = engine::measure::view_max_error_px(&[samples], &cam, false).max_px;
                    // Never worse than the engine claims; and the claim is <= tau except at the
                    // finest level, where the engine reports the excess.
                    assert!(
                        px <= s.error_px.max(tau),
                        "{name} tau {tau} camera {i}: {:?} shows {px:.3} px, claimed {:.3}",
                        s.key,
                        s.error_px
                    );
                    // A node drawn decimated shows an ancestor's mesh, allowed only within tau.
                    if !finest || s.decimation > 0 {
                        assert!(
                            px <= tau,
                            "{name} tau {tau} camera {i}: {:?} (decimation {}) shows {px:.3} px",
                            s.key,
                            s.decimation
                        );
                    }
                    worst_ratio = worst_ratio.max(px / tau);
                    nodes += 1;
                    decimated[usize::from(s.decimation)] += 1;
                }
                assert_eq!(over, sel.over_tau_at_finest);
                finest_over += over as usize;
            }
        }
        println!(
            "{name}: {nodes} selected nodes checked ({decimated:?} drawn with 0 / 1 / 2 halvings of their vertex spacing); worst true error = {worst_ratio:.3} of tau; {finest_over} finest-level nodes over tau (reported)"
        );
        assert!(nodes > 1000);
        // Both decimations occur, so the checks above cover them.
        assert!(
            decimated[1] > 100 && decimated[2] > 100,
            "{name}: decimations {decimated:?}"
        );
        if name == "tiny" {
            // Ordinary terrain seen from 30 m up never needs more than the finest level.
            assert_eq!(finest_over, 0);
            assert!(worst_ratio <= 1.0);
        }
        assert!(empty < 15, "{name}: {empty} of 150 cameras saw no ground");
    }
}

/// The selected node covering (x, y) and its mesh height there.
fn selected_height(
    tree: &QuadTree,
    meshes: &Map<NodeKey, NodeMesh>,
    x: f64,
    y: f64,
) -> Option<f64> {
    (0..=tree.max_level).rev().find_map(|l| {
        let k = tree.key_at(l, x, y)?;
        meshes.get(&k).map(|m| m.grid_height_at(tree, x, y))
    })
}

/// The same meshes without their skirts (surface triangles only), for the controls.
fn without_skirts(meshes: &Map<NodeKey, NodeMesh>) -> Map<NodeKey, NodeMesh> {
    meshes
        .iter()
        .map(|(k, m)| {
            let mut m = m.clone();
            m.indices = m.indices[..m.surface_index_count as usize].into();
            (*k, m)
        })
        .collect()
}

/// Casts a ray per pixel; wherever a ray that was above the selected surface (inside the map)
/// passes below it, it must have hit a triangle (surface or skirt) first. Rays that enter the
/// map from outside already below its border look under the world's edge, not through a crack,
/// and are not counted. Returns (rays that went below the surface, holes).
fn count_holes(
    world: &World,
    tree: &QuadTree,
    meshes: &Map<NodeKey, NodeMesh>,
    cam: &Camera,
) -> (usize, usize) {
    let [w, h] = cam.viewport_px;
    let ty = (cam.fovy_rad * 0.5).tan();
    let tx = ty * cam.aspect();
    let (o, s) = (world.origin_m(), world.size_m());
    let (mut below, mut holes) = (0, 0);
    for py in 0..h {
        for px in 0..w {
            let u = (2.0 * (f64::from(px) + 0.5) / f64::from(w) - 1.0) * tx;
            let v = (1.0 - 2.0 * (f64::from(py) + 0.5) / f64::from(h)) * ty;
            let d = (cam.forward + cam.right() * u + cam.up * v).normalize();
            // March to the first point below the selected surface.
            let mut t_below = None;
            let mut was_above = false;
            let mut t = 0.05;
            while t < 1500.0 {
                let p = cam.position_m + d * t;
                let inside = p.x >= o[0] && p.y >= o[1] && p.x <= o[0] + s[0] && p.y <= o[1] + s[1];
                if inside && let Some(hs) = selected_height(tree, meshes, p.x, p.y) {
                    if p.z >= hs {
                        was_above = true;
                    } else if p.z < hs - 1e-4 && was_above {
                        t_below = Some(t);
                        break;
                    }
                }
                t += 0.25 + t * 0.01;
            }
            let Some(tb) = t_below else { continue };
            below += 1;
            let hit = meshes
                .values()
                .filter_map(|m| ray_mesh(cam.position_m, d, m))
                .fold(f64::INFINITY, f64::min);
            if hit > tb + 1e-6 {
                holes += 1;
            }
        }
    }
    (below, holes)
}

/// Rays aimed into every gap between neighbouring selected meshes: along every shared border,
/// where the two meshes' edges differ in height, a ray from the camera to the middle of the gap
/// must hit a triangle (a skirt, or terrain in front). Returns (gaps tested, holes).
fn seam_holes(tree: &QuadTree, meshes: &Map<NodeKey, NodeMesh>, cam: &Camera) -> (usize, usize) {
    let (mut tested, mut holes) = (0, 0);
    for m in meshes.values() {
        let r = tree.rect(m.key);
        let size = r.max[0] - r.min[0];
        let eps = 1e-6 * size.max(1.0);
        for side in 0..4 {
            for k in 0..48 {
                let t = (f64::from(k) + 0.37) / 48.0;
                let (x, y, ox, oy) = match side {
                    0 => (r.min[0], r.min[1] + t * size, -eps, 0.0),
                    1 => (r.max[0], r.min[1] + t * size, eps, 0.0),
                    2 => (r.min[0] + t * size, r.min[1], 0.0, -eps),
                    _ => (r.min[0] + t * size, r.max[1], 0.0, eps),
                };
                let Some(nb) = (0..=tree.max_level).rev().find_map(|l| {
                    tree.key_at(l, x + ox, y + oy)
                        .filter(|k| meshes.contains_key(k))
                }) else {
                    continue;
                };
                let (ha, hb) = (
                    m.grid_height_at(tree, x, y),
                    meshes[&nb].grid_height_at(tree, x, y),
                );
                if (ha - hb).abs() < 1e-4 {
                    continue;
                }
                let target = DVec3::new(x, y, 0.5 * (ha + hb));
                let to = target - cam.position_m;
                let d = to.normalize();
                // Only gaps the camera faces and that lie in front of it.
                if d.dot(cam.forward) <= 0.1 {
                    continue;
                }
                let hit = meshes
                    .values()
                    .filter_map(|q| ray_mesh(cam.position_m, d, q))
                    .fold(f64::INFINITY, f64::min);
                // A gap behind nearer terrain is not visible: it is neither open nor closed.
                // Hits within the gap's own extent (its skirt) are at the gap.
                let gap_extent = (ha - hb).abs() + 1e-3 * to.length();
                if hit < to.length() - gap_extent {
                    continue;
                }
                tested += 1;
                if hit > to.length() + 1e-6 {
                    holes += 1;
                }
            }
        }
    }
    (tested, holes)
}

#[test]
fn selections_are_watertight_from_random_cameras() {
    for (name, world) in [("tiny", tiny_world()), ("cliff", cliff_world())] {
        let tree = tree_of(&world);
        let mut cache = BoundsCache::new();
        let mut tiles = TileCache::new();
        let (mut total_below, mut total_gaps) = (0, 0);
        for i in 0..8 {
            let cam = random_camera(&world, 91, i, 3.0, 120.0, [40, 30]);
            let sel = select(
                &world,
                &tree,
                &mut cache,
                &cam,
                SelectParams::culled(1.0, &tree),
            );
            let meshes = build_selection(&world, &tree, &mut cache, &mut tiles, &sel);
            let (below, holes) = count_holes(&world, &tree, &meshes, &cam);
            assert_eq!(
                holes, 0,
                "{name} camera {i}: {holes} of {below} ground rays fell through"
            );
            total_below += below;
            let (gaps, seam) = seam_holes(&tree, &meshes, &cam);
            assert_eq!(
                seam, 0,
                "{name} camera {i}: {seam} of {gaps} seam gaps are open"
            );
            total_gaps += gaps;
        }
        assert!(
            total_below > 2000,
            "{name}: too few ground rays ({total_below}) to mean anything"
        );
        assert!(
            total_gaps > 200,
            "{name}: too few seam gaps ({total_gaps}) to mean anything"
        );
    }
}

/// A partition that splits only along the path to one point: leaves there sit next to nodes up
/// to `max_level - 1` levels coarser.
fn path_partition(tree: &QuadTree, x: f64, y: f64) -> Vec<NodeKey> {
    let mut out = Vec::new();
    let mut key = NodeKey::ROOT;
    while key.level < tree.max_level {
        let next = tree.key_at(key.level + 1, x, y).unwrap();
        out.extend(key.children().into_iter().filter(|c| *c != next));
        key = next;
    }
    out.push(key);
    out
}

#[test]
fn watertight_where_neighbours_differ_by_many_levels() {
    for (name, world) in [("tiny", tiny_world()), ("cliff", cliff_world())] {
        let mut open_without_skirts = 0;
        let tree = tree_of(&world);
        let mut cache = BoundsCache::new();
        let mut tiles = TileCache::new();
        let o = world.origin_m();
        // Around the cliff edge and the spike, and at a map corner.
        for (k, (x, y)) in [(161.0, 300.0), (80.5, 360.5), (2.0, 2.0)]
            .into_iter()
            .enumerate()
        {
            let keys = path_partition(&tree, o[0] + x, o[1] + y);
            let max_diff = keys.iter().map(|k| tree.max_level - k.level).max().unwrap();
            assert!(max_diff >= 5);
            let full: Map<NodeKey, NodeMesh> = keys
                .iter()
                .map(|&k| (k, build_mesh(&world, &tree, &mut cache, &mut tiles, k)))
                .collect();
            // The same partition with nodes drawn through every 2nd or 4th vertex, mixed
            // (whatever the selection would choose): every neighbour pairing of lattices.
            let mixed: Map<NodeKey, NodeMesh> = full
                .iter()
                .map(|(&k, m)| {
                    let d = ((k.ix + 2 * k.iy + u32::from(k.level)) % 3) as u8;
                    (k, m.decimated(d.min(k.level)))
                })
                .collect();
            for (i, meshes) in (0..8i64).zip([&full, &mixed].into_iter().cycle()) {
                let z = world.height_m(o[0] + x, o[1] + y);
                let yaw = std::f64::consts::TAU * unit3(3, i, k as i64);
                let (ex, ey) = (o[0] + x - 30.0 * yaw.cos(), o[1] + y - 30.0 * yaw.sin());
                let ground = world.height_m(ex, ey).max(z);
                let eye = DVec3::new(ex, ey, ground + 12.0 + 20.0 * unit3(4, i, 0));
                let cam = Camera::look_at(
                    eye,
                    DVec3::new(o[0] + x, o[1] + y, z),
                    70f64.to_radians(),
                    [48, 36],
                );
                let (below, holes) = count_holes(&world, &tree, meshes, &cam);
                assert_eq!(
                    holes, 0,
                    "{name} point {k} view {i}: {holes} of {below} rays fell through"
                );
                assert!(
                    below > 200,
                    "{name} point {k} view {i}: only {below} ground rays"
                );
                let (gaps, seam) = seam_holes(&tree, meshes, &cam);
                assert_eq!(
                    seam, 0,
                    "{name} point {k} view {i}: {seam} of {gaps} seam gaps are open"
                );
                assert!(
                    gaps > 20,
                    "{name} point {k} view {i}: only {gaps} seam gaps"
                );
                // Control: the same views through the same meshes without skirts find open
                // seams, so the checks above can fail.
                let bare = without_skirts(meshes);
                open_without_skirts += seam_holes(&tree, &bare, &cam).1;
                open_without_skirts += count_holes(&world, &tree, &bare, &cam).1;
            }
        }
        assert!(
            open_without_skirts > 0,
            "{name}: removing the skirts opened no gap: the watertightness checks cannot fail"
        );
    }
}

/// A node drawn with `d` halvings of its vertex spacing shows exactly its level-`L - d`
/// ancestor's mesh over its square (what the selection bounds it by), read through its own
/// decimated triangles; and with all of them it differs (so the check can fail).
#[test]
fn a_decimated_node_draws_its_ancestors_mesh() {
    use engine::terrain::mesh_surface::MeshSurface;
    for world in [tiny_world(), cliff_world()] {
        let tree = tree_of(&world);
        let mut cache = BoundsCache::new();
        let mut tiles = TileCache::new();
        let o = world.origin_m();
        let (mut checked, mut full_differs) = (0, 0);
        for c in 0..12i64 {
            let (x, y) = (
                o[0] + world.size_m()[0] * unit3(21, c, 0),
                o[1] + world.size_m()[1] * unit3(21, c, 1),
            );
            for level in 2..=tree.max_level {
                let key = tree.key_at(level, x, y).unwrap();
                let own = build_mesh(&world, &tree, &mut cache, &mut tiles, key);
                let r = tree.rect(key);
                let mut ancestor = key;
                for d in 1..=engine::terrain::mesh::MAX_DECIMATION {
                    ancestor = ancestor.parent().unwrap();
                    let up = build_mesh(&world, &tree, &mut cache, &mut tiles, ancestor);
                    let drawn = own.decimated(d);
                    let surface = MeshSurface::new(&drawn, &tree);
                    let full = MeshSurface::new(&own, &tree);
                    for p in 0..40i64 {
                        let (px, py) = (
                            r.min[0] + (r.max[0] - r.min[0]) * unit3(22, p, c),
                            r.min[1] + (r.max[1] - r.min[1]) * unit3(23, p, c),
                        );
                        let want = up.grid_height_at(&tree, px, py);
                        let got = surface.height_at(px, py);
                        assert!(
                            (got - want).abs() <= 1e-4 * (1.0 + want.abs() * 1e-3),
                            "{key:?} decimated {d}: {got} against the ancestor's {want}"
                        );
                        assert!((drawn.grid_height_at(&tree, px, py) - want).abs() <= 1e-4);
                        full_differs += usize::from((full.height_at(px, py) - want).abs() > 1e-3);
                        checked += 1;
                    }
                }
            }
        }
        assert!(
            checked > 1000 && full_differs > 100,
            "{checked} {full_differs}"
        );
    }
}

#[test]
fn far_from_the_origin_camera_relative_vertices_agree_to_a_millimetre() {
    let near = tiny_world();
    for offset in [1.0e7, 1.0e7 + 0.1] {
        let far = shifted(&near, offset, -offset);
        let (tn, tf) = (tree_of(&near), tree_of(&far));
        let (mut cn, mut cf) = (BoundsCache::new(), BoundsCache::new());
        let (mut xn, mut xf) = (TileCache::new(), TileCache::new());
        // The same relative camera in both worlds.
        let rel = DVec3::new(200.0, 130.0, 250.0);
        let cam_n = near.origin_m();
        let cam_f = far.origin_m();
        for key in [
            NodeKey {
                level: 6,
                ix: 25,
                iy: 16,
            },
            NodeKey {
                level: 3,
                ix: 5,
                iy: 2,
            },
            NodeKey {
                level: 0,
                ix: 0,
                iy: 0,
            },
        ] {
            let mn = build_mesh(&near, &tn, &mut cn, &mut xn, key);
            let mf = build_mesh(&far, &tf, &mut cf, &mut xf, key);
            // The renderer's own f64 -> f32 step (node origin minus camera).
            let to_camera = |origin: [f64; 2], cam: [f64; 2]| {
                let c = DVec3::new(cam[0], cam[1], 0.0) + rel;
                glam::Vec3::from(engine::render::frame::node_offset_m(origin, c))
            };
            let (rn, rf) = (to_camera(mn.origin_m, cam_n), to_camera(mf.origin_m, cam_f));
            let mut worst = 0.0f32;
            for (a, b) in mn.positions.iter().zip(&mf.positions) {
                let pa = rn + glam::Vec3::from(*a);
                let pb = rf + glam::Vec3::from(*b);
                worst = worst.max((pa - pb).abs().max_element());
            }
            assert!(
                worst <= 1e-3,
                "offset {offset}, {key:?}: camera-relative vertices differ by {worst} m"
            );
        }
    }
}

#[test]
fn node_mesh_bytes_do_not_depend_on_generation_order_or_tiles() {
    let world = cliff_world();
    let tree = tree_of(&world);
    let target = NodeKey {
        level: 6,
        ix: 20,
        iy: 37,
    };
    let fresh = {
        let mut c = BoundsCache::new();
        let mut t = TileCache::new();
        build_mesh(&world, &tree, &mut c, &mut t, target)
    };
    let mut c = BoundsCache::new();
    let mut t = TileCache::new();
    for i in 0..40i64 {
        let level = (unit3(9, i, 0) * 7.0) as u8;
        let n = 1u32 << level;
        let key = NodeKey {
            level,
            ix: (unit3(9, i, 1) * f64::from(n)) as u32,
            iy: (unit3(9, i, 2) * f64::from(n)) as u32,
        };
        build_mesh(&world, &tree, &mut c, &mut t, key);
    }
    let later = build_mesh(&world, &tree, &mut c, &mut t, target);
    assert_eq!(fresh.content_hash(), later.content_hash());
    assert_eq!(fresh, later);
    // A leaf built from its 16 m tile equals one evaluated directly.
    let direct = engine::terrain::mesh::build(
        &world,
        &tree,
        &mut |k| c.get(&world, &tree, k),
        target,
        None,
    );
    assert_eq!(direct, later);
    // Every tile was released.
    assert_eq!(t.resident(), 0);
    assert!(t.generated > 0);
}

#[test]
fn tiles_are_shared_and_freed_when_unused() {
    let world = tiny_world();
    let mut tiles = TileCache::new();
    let k = engine::terrain::tiles::TileKey { tx: 3, ty: 4 };
    let a = tiles.acquire(&world, k);
    let b = tiles.acquire(&world, k);
    assert!(std::sync::Arc::ptr_eq(&a, &b));
    assert_eq!(
        (tiles.refcount(k), tiles.generated, tiles.resident()),
        (2, 1, 1)
    );
    assert!(tiles.release(k));
    assert_eq!(tiles.refcount(k), 1);
    assert!(tiles.release(k));
    assert_eq!(
        (tiles.refcount(k), tiles.resident(), tiles.bytes()),
        (0, 0, 0)
    );
    assert!(
        !tiles.release(k),
        "releasing an unheld tile must be reported"
    );
    // Tile samples are exactly the finest surface.
    let o = engine::terrain::tiles::Tile::sample_origin_m(&world, k);
    let n = engine::terrain::tiles::TILE_SAMPLES;
    for (i, j) in [(0, 0), (n - 1, n - 1), (10, 37)] {
        let want = world.height_m(o[0] + i as f64 * 0.25, o[1] + j as f64 * 0.25) as f32;
        assert_eq!(a.heights_m[j * n + i], want);
    }
}

#[test]
fn imported_srtm_sea_is_exact_and_the_coast_is_watertight() {
    let path = tests::test_data("dem/N57E011.hgt");
    let params = worldgen::dem::ImportParams::new(path);
    let (map, _) = worldgen::dem::import(&params, &mut Vec::new()).expect("import");
    let world = tests::terrain::world_of(map);
    let tree = tree_of(&world);
    let mut cache = BoundsCache::new();
    let mut tiles = TileCache::new();
    // A node far out in the open sea (west edge of the tile) has no error: its bounds, read
    // from the map-error grids (the import's 32 m spacing lines up with the node meshes), are
    // the grids' rounding guard alone (`1e-9 (1 + |F|)` a side: 2e-9 m).
    let sea = tree.key_at(7, 2000.0, 60_000.0).unwrap();
    let b = cache.get(&world, &tree, sea);
    assert!(
        b.error_m <= 1e-8 && b.z_min_m.abs() <= 1e-8 && b.z_max_m.abs() <= 1e-8,
        "{b:?}"
    );
    // Looking along the coast from 60 m up: honest and watertight. Find a coast point first.
    let (mut cx, cy) = (1000.0, 60_000.0);
    while world.height_m(cx, cy) <= 0.0 && cx < 55_000.0 {
        cx += 100.0;
    }
    assert!(cx < 55_000.0, "no coast found");
    let eye = DVec3::new(cx - 400.0, cy - 300.0, 60.0);
    let cam = Camera::look_at(eye, DVec3::new(cx, cy, 0.0), 60f64.to_radians(), [40, 30]);
    let sel = select(
        &world,
        &tree,
        &mut cache,
        &cam,
        SelectParams::culled(1.0, &tree),
    );
    let levels: std::collections::BTreeSet<u8> = sel.nodes.iter().map(|s| s.key.level).collect();
    assert!(
        levels.len() >= 3,
        "expected mixed levels along the coast, got {levels:?}"
    );
    let meshes = build_selection(&world, &tree, &mut cache, &mut tiles, &sel);
    for s in &sel.nodes {
        // A node drawn decimated shows its ancestor's mesh: that ancestor's bound holds.
        let mut bound_key = s.key;
        for _ in 0..s.decimation {
            bound_key = bound_key.parent().unwrap();
        }
        let bound = cache.get(&world, &tree, bound_key).error_m;
        let (true_err, outside) = measure_true_error(&world, &tree, &meshes[&s.key]);
        assert!(
            true_err <= bound && outside <= 0.0,
            "{:?} (decimation {}): {true_err} > {bound}",
            s.key,
            s.decimation
        );
    }
    let (below, holes) = count_holes(&world, &tree, &meshes, &cam);
    assert_eq!(
        holes, 0,
        "{holes} of {below} rays fell through at the coast"
    );
    let (gaps, seam) = seam_holes(&tree, &meshes, &cam);
    assert_eq!(seam, 0, "{seam} of {gaps} seam gaps open at the coast");
}

/// Distance to a decal's centre line and the line's z at the closest point.
fn closest_on_line(points: &[[f64; 3]], p: [f64; 2]) -> (f64, f64) {
    let mut best = (f64::INFINITY, 0.0);
    for s in points.windows(2) {
        let (a, b) = (s[0], s[1]);
        let (d, t) = worldgen::roads::segment_closest(p, [a[0], a[1]], [b[0], b[1]]);
        if d < best.0 {
            best = (d, a[2] + t * (b[2] - a[2]));
        }
    }
    best
}

#[test]
fn roads_and_paths_are_flattened_into_the_finest_surface() {
    let world = tiny_world();
    assert!(!world.map.decals.is_empty() && !world.decals.is_empty());
    let (mut checked, mut worst, mut moved) = (0, 0.0f64, 0.0f64);
    // Roads and paths (closed areas raise or keep the ground, they do not flatten it).
    for (k, d) in world
        .map
        .decals
        .iter()
        .enumerate()
        .filter(|(_, d)| !d.closed)
    {
        let half = f64::from(d.width_m) * 0.5;
        for (i, s) in d.points.windows(2).enumerate() {
            // Points scattered around the segment, up to the half width.
            for q in 0..6i64 {
                let t = unit3(91, i as i64 * 8 + q, k as i64);
                let off = (unit3(92, i as i64 * 8 + q, k as i64) * 2.0 - 1.0) * half;
                let (dx, dy) = (s[1][0] - s[0][0], s[1][1] - s[0][1]);
                let len = dx.hypot(dy).max(1e-9);
                let p = [
                    s[0][0] + t * dx - dy / len * off,
                    s[0][1] + t * dy + dx / len * off,
                ];
                let (dist, z) = closest_on_line(&d.points, p);
                let target = z + f64::from(d.height_offset_m);
                if dist <= half {
                    // Where another decal is also at full weight the earlier one wins (roads
                    // before paths at town junctions): skip those points.
                    let shared = world.map.decals.iter().enumerate().any(|(j, o)| {
                        j != k
                            && closest_on_line(&o.points, p).0
                                <= f64::from(o.width_m) * 0.5 + 2.0 * FLAT_MARGIN_M
                    });
                    if shared {
                        continue;
                    }
                    let e = (world.height_m(p[0], p[1]) - target).abs();
                    worst = worst.max(e);
                    moved = moved.max((world.map.height_bicubic_m(p[0], p[1]) - target).abs());
                    checked += 1;
                }
            }
        }
    }
    println!(
        "roads: {checked} points within the half width, max deviation {worst:.4} m, \
         map surface off by up to {moved:.3} m"
    );
    assert!(checked > 1000);
    // Not exactly 0: the stencil's samples have their own closest points (bends, ends) and the
    // bicubic map surface is not reproduced exactly between lattice samples.
    assert!(worst < 0.05, "road surface deviates by {worst} m");
    assert!(
        moved > 0.05,
        "the decals should actually move the ground ({moved} m)"
    );
}

/// The TIN variant is measured through its own triangles: on hilly nodes of the cliff map its
/// drawn surface differs from the grid surface of the same vertices (so a grid stand-in would
/// measure something else), and its true error stays within its bound (grid error + exact
/// TIN delta).
#[test]
fn tin_error_is_measured_on_its_own_triangles_and_stays_within_its_bound() {
    use engine::terrain::mesh_surface::MeshSurface;
    let world = cliff_world();
    let tree = tree_of(&world);
    let mut cache = BoundsCache::new();
    let mut tiles = TileCache::new();
    let (mut differs, mut checked) = (0, 0);
    for i in 0..12i64 {
        let (o, s) = (world.origin_m(), world.size_m());
        let (x, y) = (o[0] + s[0] * unit3(77, i, 0), o[1] + s[1] * unit3(77, i, 1));
        let level = tree.max_level.saturating_sub(1 + (i % 3) as u8);
        let key = tree.key_at(level, x, y).expect("inside the map");
        let grid = build_mesh(&world, &tree, &mut cache, &mut tiles, key);
        let (tin, _) = engine::terrain::tin::build(&grid, 0.5 * grid.bounds.error_m);
        let surface = MeshSurface::new(&tin, &tree);
        let r = tree.rect(key);
        let mut largest_gap = 0.0f64;
        for j in 0..40 {
            for k in 0..40 {
                let (px, py) = (
                    r.min[0] + (r.max[0] - r.min[0]) * (f64::from(k) + 0.3) / 40.0,
                    r.min[1] + (r.max[1] - r.min[1]) * (f64::from(j) + 0.6) / 40.0,
                );
                largest_gap = largest_gap
                    .max((surface.height_at(px, py) - tin.grid_height_at(&tree, px, py)).abs());
            }
        }
        differs += usize::from(largest_gap > 1e-3);
        let (true_err, _) = measure_true_error(&world, &tree, &tin);
        assert!(
            true_err <= tin.bounds.error_m + 1e-6,
            "{key:?}: TIN true error {true_err} m > its bound {} m",
            tin.bounds.error_m
        );
        checked += 1;
    }
    assert!(
        differs >= checked / 2,
        "only {differs} of {checked} TINs differ from the grid surface: the control is not sharp"
    );
}
