//! A baked map's layers and derived data (heights, ground types, their levels and max-pyramids
//! read page by page, the decal field tile by tile, the ground amplitude near roads): the same
//! surface, region bounds, height maxima, decal offsets, node meshes and node ground types as
//! the map held whole, bit for bit, under
//! budgets far below their size; a damaged page loosens only the bounds that read it (or
//! stands its heights at the fill value), is reported with its file and page, and never
//! panics; pages of another map are refused and computed instead.

use engine::ground::content::NodeGround;
use engine::ground::type_window::TypeWindow;
use engine::ground::types::TypeForm;
use engine::surface::{Rect, World};
use engine::terrain::bounds::BoundsCache;
use engine::terrain::quadtree::NodeKey;
use engine::terrain::tiles::TileCache;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use tests::terrain::{build_mesh, tree_of};

fn random_rect(rng: &mut SmallRng, w: &World, max_side_m: f64) -> Rect {
    let (o, s) = (w.origin_m(), w.size_m());
    let side = [
        max_side_m * rng.random::<f64>(),
        max_side_m * rng.random::<f64>(),
    ];
    let x = o[0] + (s[0] - side[0]).max(0.0) * rng.random::<f64>();
    let y = o[1] + (s[1] - side[1]).max(0.0) * rng.random::<f64>();
    Rect {
        min: [x, y],
        max: [
            (x + side[0]).min(o[0] + s[0]),
            (y + side[1]).min(o[1] + s[1]),
        ],
    }
}

#[test]
fn paged_pyramids_give_the_same_bounds_and_node_meshes_bit_for_bit() {
    let map = tests::generated(&tests::patches_map_params());
    let tmp = tempfile::tempdir().unwrap();
    let pages = tmp.path().join("pages");
    let whole = World::without_error_grids(map.clone());
    whole.write_derived_pages(&pages, 64).unwrap();
    // Eight pages of 64 x 64 f32: 128 KiB against 7 MiB of pyramids and 1 MiB of heights on
    // this 2 km map, shared by both.
    let budget = 8 * 64 * 64 * 4;
    let paging = worldgen::pages::Paging::new(budget);
    let map = tests::with_paged_layers(map, tmp.path(), 64, &paging);
    let paged = World::paged_without_error_grids(map, &pages, budget);
    let cache = paged.page_cache.clone().expect("the pyramids were paged");
    assert!(
        std::sync::Arc::ptr_eq(&cache, &paging.cache),
        "the heights and the pyramids share the world's page cache"
    );
    assert!(
        paged.decals.tile_stats().is_some() && !paged.decals.is_empty(),
        "the decal field was read from its tiles"
    );
    let mut rng = SmallRng::seed_from_u64(81);
    for i in 0..20_000 {
        let max_side = [1.0, 8.0, 64.0, 600.0, 2048.0][i % 5];
        let r = random_rect(&mut rng, &whole, max_side);
        assert_eq!(whole.region_bounds(r), paged.region_bounds(r), "{r:?}");
        let (hs, _) = whole.cell_spacings_m();
        let (cx, cy) = (
            (r.min[0] / hs).floor() * hs + hs * 0.25,
            (r.min[1] / hs).floor() * hs + hs * 0.25,
        );
        let cell = Rect {
            min: [cx, cy],
            max: [cx + hs * 0.25, cy + hs * 0.25],
        };
        assert_eq!(
            whole.cell_region_bounds(cell),
            paged.cell_region_bounds(cell)
        );
        // The surface (heights paged, read through the threads' pages at hand) at points and
        // on lattices, bit for bit.
        let (px, py) = (r.min[0] + (r.max[0] - r.min[0]) * 0.37, r.max[1]);
        assert_eq!(
            whole.height_m(px, py).to_bits(),
            paged.height_m(px, py).to_bits()
        );
        if i % 50 == 0 {
            let n = rng.random_range(2..70);
            let axis = |lo: f64, hi: f64| -> Vec<f64> {
                (0..n)
                    .map(|k| lo + (hi - lo) * f64::from(k) / f64::from(n))
                    .collect()
            };
            let (lx, ly) = (axis(r.min[0], r.max[0]), axis(r.min[1], r.max[1]));
            assert_eq!(
                whole.heights_on_lattice(&lx, &ly),
                paged.heights_on_lattice(&lx, &ly),
                "{r:?}"
            );
        }
        let xs = [rng.random_range(-5..520), rng.random_range(-5..520)];
        let ys = [rng.random_range(-5..520), rng.random_range(-5..520)];
        assert_eq!(
            whole.heights_max.max_in(xs, ys).to_bits(),
            paged.heights_max.max_in(xs, ys).to_bits()
        );
    }
    // Lattices on every 2^k-th height sample (as coarse nodes' vertices stand), beyond the
    // map's edges too: read from the baked coarse levels, bit for bit.
    let levels_before = cache.stats().page_ins;
    let (o, (hs, _)) = (whole.origin_m(), whole.cell_spacings_m());
    for k in 1..=7 {
        let stride = hs * f64::from(1u32 << k);
        for _ in 0..6 {
            let (i0, j0) = (rng.random_range(-3..40), rng.random_range(-3..40));
            let axis = |first: i64, o: f64| -> Vec<f64> {
                (first - 1..first + 66)
                    .map(|i| o + i as f64 * stride)
                    .collect()
            };
            let (lx, ly) = (axis(i0, o[0]), axis(j0, o[1]));
            let (a, b) = (
                whole.heights_on_lattice(&lx, &ly),
                paged.heights_on_lattice(&lx, &ly),
            );
            assert!(
                a.iter().zip(&b).all(|(a, b)| a.to_bits() == b.to_bits()),
                "stride 2^{k} lattice at ({i0}, {j0}) differs"
            );
            assert_eq!(
                whole.height_m(lx[5], ly[7]).to_bits(),
                paged.height_m(lx[5], ly[7]).to_bits()
            );
        }
    }
    assert!(
        cache.stats().page_ins > levels_before,
        "the levels were not read"
    );
    // Node meshes with their bounds measured at run time (no error grids): every level, a
    // sample of nodes per level.
    let tree = tree_of(&whole);
    let (mut ca, mut cb) = (BoundsCache::new(), BoundsCache::new());
    let (mut ta, mut tb) = (TileCache::new(), TileCache::new());
    for key in random_keys(&tree, 4, &mut rng) {
        let a = build_mesh(&whole, &tree, &mut ca, &mut ta, key);
        let b = build_mesh(&paged, &tree, &mut cb, &mut tb, key);
        assert!(a == b, "{key:?}: the paged world's mesh differs");
    }
    assert_same_ground_types(&whole, &paged, &tree, &mut rng);
    let s = cache.stats();
    assert!(s.evictions > 0 && s.peak_resident_bytes <= budget, "{s:?}");
    let d = paged.decals.tile_stats().expect("a baked decal field");
    assert!(d.tile_ins > 0 && d.evictions > 0, "{d:?}");
    assert!(paged.page_faults.list().is_empty());
    let parts = paged.memory_bytes();
    let part = |name: &str| parts.iter().find(|p| p.0.starts_with(name)).unwrap().1;
    let (whole_parts, paged_pyramids) = (whole.memory_bytes(), part("slope, curvature"));
    let whole_pyramids = whole_parts
        .iter()
        .find(|p| p.0.starts_with("slope, curvature"))
        .unwrap()
        .1;
    assert!(
        paged_pyramids * 20 < whole_pyramids,
        "paged pyramids keep {paged_pyramids} bytes in memory against {whole_pyramids}"
    );
}

#[test]
fn a_damaged_pyramid_page_loosens_only_its_bounds_and_is_reported() {
    let map = worldgen::Map::load(&tests::tiny_map_dir()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let pages = tmp.path().join("pages");
    let whole = World::without_error_grids(map.clone());
    whole.write_derived_pages(&pages, 16).unwrap();
    // Flip a sample of page (0, 0) of the finest slope level.
    let file = engine::surface::levels::level_path(&pages, "slope_g", 0);
    let mut bytes = std::fs::read(&file).unwrap();
    bytes[64 + 40] ^= 0x40;
    std::fs::write(&file, &bytes).unwrap();
    let paged = World::paged_without_error_grids(map.clone(), &pages, 1 << 20);
    assert!(
        paged
            .page_cache
            .as_ref()
            .is_some_and(|c| c.file_count() > 0)
    );
    let cell = |x: f64, y: f64| Rect {
        min: [x, y],
        max: [x + 1.0, y + 1.0],
    };
    // A cell in page (0, 0): its map-slope bound is unbounded, the other bounds as before.
    let (a, b) = (
        whole.cell_region_bounds(cell(5.0, 5.0)),
        paged.cell_region_bounds(cell(5.0, 5.0)),
    );
    assert!(b.slope_g.is_infinite() && a.slope_g.is_finite(), "{b:?}");
    assert_eq!((a.curvature_g, a.slope_h), (b.curvature_g, b.slope_h));
    assert!(
        b.between_m(1.0) >= a.between_m(1.0),
        "the loosened bound is below the true one"
    );
    // A cell in another page is untouched.
    let far = cell(300.0, 300.0);
    assert_eq!(whole.cell_region_bounds(far), paged.cell_region_bounds(far));
    let faults = paged.page_faults.list();
    assert_eq!(faults.len(), 1, "{faults:?}");
    assert!(
        faults[0].contains("slope_g.0.pages") && faults[0].contains("page (0, 0)"),
        "{faults:?}"
    );

    // Pages baked from another map are refused at open: the pyramids are computed instead.
    let mut other = map;
    let v = other.heights.get(20, 20);
    let hg = other.heights.grid_mut().expect("heights in memory");
    hg.set(20, 20, v + 5.0);
    let reopened = World::paged_without_error_grids(other.clone(), &pages, 1 << 20);
    let registered = reopened.page_cache.as_ref().map_or(0, |c| c.file_count());
    assert_eq!(registered, 0, "stale pages were used");
    let fresh = World::without_error_grids(other);
    let r = cell(80.0, 80.0);
    assert_eq!(fresh.cell_region_bounds(r), reopened.cell_region_bounds(r));
}

/// `per_level` random nodes of every level of `tree` (as many as a level has where it has fewer,
/// each drawn at random), coarsest level first.
fn random_keys(
    tree: &engine::terrain::quadtree::QuadTree,
    per_level: u32,
    rng: &mut SmallRng,
) -> Vec<NodeKey> {
    let mut keys = Vec::new();
    for level in 0..=tree.max_level {
        let n = 1u32 << level;
        for _ in 0..per_level.min(n * n) {
            let (ix, iy) = (rng.random_range(0..n), rng.random_range(0..n));
            keys.push(NodeKey { level, ix, iy });
        }
    }
    keys
}

/// The ground types read through their pages and their baked levels give every node's texture
/// types (levels' texels on the coarsest nodes, reached cells on the others), the camera
/// window's cells and the mean albedo of the layer held whole.
fn assert_same_ground_types(
    whole: &World,
    paged: &World,
    tree: &engine::terrain::quadtree::QuadTree,
    rng: &mut SmallRng,
) {
    assert!(paged.map.ground.paged().is_some());
    let coarsest = paged
        .ground_levels
        .coarsest()
        .expect("levels on a 2 km map");
    assert!(
        coarsest.paged().is_some(),
        "the levels were read from the bake"
    );
    assert!(
        paged.computed_at_open.is_empty(),
        "{:?}",
        paged.computed_at_open
    );
    let index = engine::ground::content::GroundContent::new(whole).index;
    let mut forms = [0; 2];
    for key in random_keys(tree, 3, rng) {
        let a = NodeGround::new(whole, &index, tree, key);
        let b = NodeGround::new(paged, &index, tree, key);
        assert!(a == b, "{key:?}: the paged world's ground types differ");
        forms[usize::from(a.types.form == TypeForm::Texels)] += 1;
    }
    assert!(
        forms[0] > 0 && forms[1] > 0,
        "{forms:?} nodes of either form"
    );
    let spacing_m = whole.map.manifest.ground.spacing_m;
    let cells = [whole.map.ground.width(), whole.map.ground.height()];
    for camera in [[10.0, 20.0], [300.0, 140.0], [511.0, 511.0]] {
        let window = TypeWindow::around(cells, spacing_m, camera);
        assert!(window.cells(&whole.map.ground) == window.cells(&paged.map.ground));
    }
    let albedo = engine::render::lighting::mean_ground_albedo;
    assert_eq!(albedo(whole), albedo(paged));
}

/// A camera `above` metres over the ground of `w` at (x, y), looking along `yaw` and down.
fn camera(w: &World, x: f64, y: f64, above: f64, yaw: f64) -> engine::camera::Camera {
    let p = glam::DVec3::new(x, y, w.height_m(x, y) + above);
    let dir = glam::DVec3::new(yaw.cos() * 0.8, yaw.sin() * 0.8, -0.6);
    engine::camera::Camera::look_at(p, p + dir, 60f64.to_radians(), [640, 360])
}

#[test]
fn pages_damaged_mid_flight_are_reported_and_the_world_keeps_streaming() {
    use engine::stream::{StreamSettings, Streamer};
    let map = worldgen::Map::load(&tests::tiny_map_dir()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let pages = tmp.path().join("pages");
    World::without_error_grids(map.clone())
        .write_derived_pages(&pages, 16)
        .unwrap();
    let reference = World::without_error_grids(map.clone());
    // A budget of four 16 x 16 pages: the flight reads pages again all the time.
    let budget = 4 * 16 * 16 * 4;
    let paging = worldgen::pages::Paging::new(budget);
    let map = tests::with_paged_layers(map, tmp.path(), 16, &paging);
    let paged = World::paged_without_error_grids(map, &pages, budget);
    let world = engine::terrain::precomputed::open_world(paged, None, &worldgen::progress::Silent);
    let (cache, faults) = (world.page_cache.clone().unwrap(), world.page_faults.clone());
    let kinds = engine::kinds::content_kinds(&world);
    let settings = StreamSettings {
        workers: 2,
        fade_s: 0.1,
        tau_px: 0.5,
        ..StreamSettings::default()
    };
    let mut s = Streamer::new(world, settings, kinds);
    assert!(s.settle(&camera(&reference, 60.0, 80.0, 30.0, 0.6), 120.0));
    assert!(faults.list().is_empty());

    // Mid-flight: the finest map-slope level loses its second half, a byte of the finest
    // height-maximum level flips, and nothing stays resident.
    let slope = engine::surface::levels::level_path(&pages, "slope_g", 0);
    let len = std::fs::metadata(&slope).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(&slope)
        .unwrap()
        .set_len(len / 2)
        .unwrap();
    let hmax = engine::surface::levels::level_path(&pages, "height_max", 0);
    let mut bytes = std::fs::read(&hmax).unwrap();
    bytes[64 + 8] ^= 0x20;
    std::fs::write(&hmax, &bytes).unwrap();
    // And a byte of the heights' page under the flight's last camera (samples 96..112 along x
    // and y: page (6, 6) of 9 x 9): the last settle must build the finest nodes there, which
    // nothing wanted before the damage (a page under the middle of the flight is read only if
    // the workers reach its nodes while the camera passes, which depends on their speed).
    let heights = tmp.path().join("heights.pages");
    let layout = worldgen::pages::PageFile::open(&heights).unwrap().layout();
    let offset = worldgen::pages::file::HEADER_BYTES
        + u64::from(layout.index(6, 6)) * layout.page_stride_bytes();
    let mut bytes = std::fs::read(&heights).unwrap();
    bytes[offset as usize + 40] ^= 0x01;
    std::fs::write(&heights, &bytes).unwrap();
    cache.clear();

    // Fly on across the map, low (fine nodes measure their bounds from the slope level).
    for i in 0..240 {
        let t = f64::from(i) / 240.0;
        let cam = camera(
            &reference,
            60.0 + 390.0 * t,
            80.0 + 350.0 * t,
            25.0 - 15.0 * t,
            0.6 + t,
        );
        s.update(&cam, 1.0 / 60.0);
        s.run_gpu_phases();
    }
    let last = camera(&reference, 440.0, 440.0, 8.0, 0.9);
    assert!(
        s.settle(&last, 120.0),
        "the flight did not settle: {:?}",
        s.stats
    );
    for k in s.wanted() {
        assert!(s.is_ready(*k), "{k:?} is wanted and not ready");
    }
    let seen = faults.list();
    assert!(
        seen.iter()
            .any(|f| f.contains("slope_g.0.pages") && f.contains("page (")),
        "the truncated level was not reported: {seen:?}"
    );
    assert!(
        seen.iter()
            .any(|f| f.contains("heights.pages") && f.contains("page (6, 6)")),
        "the damaged heights page was not reported: {seen:?}"
    );
    assert!(
        seen.iter()
            .all(|f| f.contains(".pages") && f.contains("page (")),
        "a fault names no file and page: {seen:?}"
    );
    assert!(cache.stats().failures > 0);
}

/// A baked map's surface error grids read page by page give every node of every level the
/// bounds of the grids computed at open, bit for bit, under a budget of a few pages; a damaged
/// page makes only the nodes over it measure their bounds on the surface (true bounds: they
/// contain the stored ones' measurement), and is reported with its file and page.
#[test]
fn paged_surface_error_grids_give_the_same_node_bounds_and_a_damaged_page_is_measured() {
    use engine::terrain::bounds::{from_map_error, measure};
    use engine::terrain::precomputed;
    let map = tests::generated(&tests::patches_map_params());
    let tmp = tempfile::tempdir().unwrap();
    let pages = tmp.path().join("pages");
    let whole = precomputed::open(map.clone(), None, &worldgen::progress::Silent);
    whole.write_derived_pages(&pages, 64).unwrap();
    let key =
        engine::surface::map_error_cache::surface_key(&whole, precomputed::MEASUREMENT_VERSION);
    whole.map_error.write_pages(&pages, 64, key).unwrap();
    let open = |budget: usize| {
        let w = World::paged_without_error_grids(map.clone(), &pages, budget);
        // No whole-map file: the grids can only come from the pages (or be computed).
        precomputed::open_world(
            w,
            Some(&tmp.path().join("none.bin")),
            &worldgen::progress::Silent,
        )
    };
    // Eight pages of 64 x 64 f32 against 7 MiB of pyramids and the grids.
    let paged = open(8 * 64 * 64 * 4);
    assert!(
        paged.map_error.bytes() * 20 < whole.map_error.bytes(),
        "only grids of one page are held in memory: {} of {} bytes",
        paged.map_error.bytes(),
        whole.map_error.bytes()
    );
    assert_eq!(paged.map_error.level_count(), whole.map_error.level_count());
    let tree = tree_of(&whole);
    let mut stored = 0;
    for level in 0..=tree.max_level {
        let n = 1u32 << level;
        for iy in 0..n {
            for ix in 0..n {
                let key = NodeKey { level, ix, iy };
                let (a, b) = (
                    from_map_error(&whole, &tree, key),
                    from_map_error(&paged, &tree, key),
                );
                assert_eq!(a, b, "{key:?}");
                stored += usize::from(a.is_some());
            }
        }
    }
    assert!(
        stored > 300,
        "{stored} nodes take their bounds from the grids"
    );
    assert!(
        paged.page_cache.as_ref().unwrap().stats().evictions > 0,
        "the budget was exceeded"
    );
    assert!(
        !tmp.path().join("none.bin").exists(),
        "nothing was computed"
    );

    // Flip a byte of page (0, 0) of the finest grid: the nodes over it are measured.
    let file = engine::surface::levels::level_path(&pages, "surface_error", 0);
    let mut bytes = std::fs::read(&file).unwrap();
    bytes[64 + 8] ^= 0x10;
    std::fs::write(&file, &bytes).unwrap();
    let damaged = open(1 << 20);
    let level = (0..=tree.max_level)
        .find(|&l| whole.map_error.level_of_spacing(tree.spacing_m(l)) == Some(0))
        .expect("a level on the finest grid");
    let corner = NodeKey {
        level,
        ix: 0,
        iy: 0,
    };
    assert!(from_map_error(&whole, &tree, corner).is_some());
    assert!(
        from_map_error(&damaged, &tree, corner).is_none(),
        "a damaged block was served"
    );
    let measured = measure(&damaged, &tree, corner);
    let true_bounds = engine::terrain::bounds::measure_surface(&whole, &tree, corner, false).0;
    assert_eq!(
        measured, true_bounds,
        "the damaged node is measured on the surface"
    );
    let far = NodeKey {
        level,
        ix: (1 << level) - 1,
        iy: (1 << level) - 1,
    };
    assert_eq!(
        from_map_error(&whole, &tree, far),
        from_map_error(&damaged, &tree, far)
    );
    let faults = damaged.page_faults.list();
    assert!(
        faults
            .iter()
            .any(|f| f.contains("surface_error.0.pages") && f.contains("page (0, 0)")),
        "{faults:?}"
    );
}
