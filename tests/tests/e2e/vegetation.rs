//! Vegetation placement: minimum distances across tile seams and node borders, counts against
//! the integral of the density map, monotone thinning, order-independent output, nothing on
//! roads or in water.

use engine::surface::world::{Rect, World};
use engine::terrain::quadtree::QuadTree;
use engine::vegetation::{Item, Kind, Placer, Representation, node_vegetation, representation};
use std::collections::HashMap;
use tests::terrain::{cliff_world, tiny_world};
use worldgen::map::DecalKind;

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Rect {
    Rect {
        min: [x0, y0],
        max: [x1, y1],
    }
}

/// Items of species `s` placed tile by tile (16 m tiles) over `area`.
fn by_tiles(world: &World, p: &Placer, s: usize, area: Rect, scale: f64) -> Vec<Item> {
    let mut out = Vec::new();
    let mut y = area.min[1];
    while y < area.max[1] {
        let mut x = area.min[0];
        while x < area.max[0] {
            p.place(world, s, rect(x, y, x + 16.0, y + 16.0), scale, &mut out);
            x += 16.0;
        }
        y += 16.0;
    }
    out
}

/// Smallest distance between two items (grid hashing, cell = `cell_m`).
fn min_distance(items: &[Item], cell_m: f64) -> f64 {
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    let key = |it: &Item| {
        (
            (it.x_m / cell_m).floor() as i64,
            (it.y_m / cell_m).floor() as i64,
        )
    };
    for (i, it) in items.iter().enumerate() {
        grid.entry(key(it)).or_default().push(i);
    }
    let mut best = f64::INFINITY;
    for (i, a) in items.iter().enumerate() {
        let (cx, cy) = key(a);
        for dy in -1..=1 {
            for dx in -1..=1 {
                for &j in grid.get(&(cx + dx, cy + dy)).map_or(&[][..], Vec::as_slice) {
                    if j != i {
                        let b = &items[j];
                        best = best.min((a.x_m - b.x_m).hypot(a.y_m - b.y_m));
                    }
                }
            }
        }
    }
    best
}

fn small_species(p: &Placer) -> Vec<usize> {
    (0..p.species.len())
        .filter(|&s| p.species[s].kind != Kind::LargeTree)
        .collect()
}

fn area_for(world: &World, p: &Placer, s: usize) -> Rect {
    let o = world.origin_m();
    // Grass is dense: a 192 m square (about three tile periods); others the whole map.
    let side = if p.species[s].kind == Kind::GrassClump {
        192.0
    } else {
        world.size_m()[0]
    };
    rect(o[0], o[1], o[0] + side, o[1] + side)
}

#[test]
fn minimum_distance_holds_across_tile_seams_and_node_borders() {
    let world = tiny_world();
    let p = Placer::new(&world);
    for s in small_species(&p) {
        let d = p.species[s].min_distance_m;
        let area = area_for(&world, &p, s);
        assert!(
            area.max[0] - area.min[0] > p.species[s].tile_side_m,
            "{}: the area must cross tile seams in x and y",
            p.species[s].name
        );
        // Map density, and a density 50x higher (every tile point kept: the tightest packing).
        for scale in [1.0, 50.0] {
            let items = by_tiles(&world, &p, s, area, scale);
            assert!(
                items.len() > 200,
                "{}: only {} items",
                p.species[s].name,
                items.len()
            );
            let m = min_distance(&items, d);
            assert!(
                m >= d * (1.0 - 1e-9),
                "{} at scale {scale}: two items {m} m apart, minimum {d} m",
                p.species[s].name
            );
            // The same items whether placed per 16 m tile or per quad-tree node (64 m).
            let mut nodes = Vec::new();
            let tree = QuadTree::new(world.origin_m(), world.size_m());
            let level = (0..=tree.max_level)
                .find(|&l| (tree.node_size_m(l) - 64.0).abs() < 1e-9)
                .unwrap();
            for iy in 0..(1u32 << level) {
                for ix in 0..(1u32 << level) {
                    let r = tree.rect(engine::terrain::quadtree::NodeKey { level, ix, iy });
                    if r.min[0] < area.max[0] && r.min[1] < area.max[1] {
                        p.place(&world, s, r, scale, &mut nodes);
                    }
                }
            }
            let key = |it: &Item| (it.x_m.to_bits(), it.y_m.to_bits());
            let mut a: Vec<_> = items.iter().map(key).collect();
            let mut b: Vec<_> = nodes.iter().map(key).collect();
            a.sort_unstable();
            b.sort_unstable();
            assert!(
                a == b,
                "{}: tiles ({} items) and nodes ({} items) disagree",
                p.species[s].name,
                a.len(),
                b.len()
            );
        }
    }
}

/// The density layer of species `s` read straight from its PNG file (8-bit gray, north-up
/// rows) with the `png` crate, and evaluated bilinearly here: an oracle independent of the
/// engine's density code. Items per m² at a world position.
struct PngDensity {
    samples: Vec<u8>,
    width: usize,
    height: usize,
    spacing_m: f64,
    max_per_m2: f64,
    origin_m: [f64; 2],
}

impl PngDensity {
    fn load(world: &World, species: &str) -> Self {
        let spec = world
            .map
            .manifest
            .vegetation
            .iter()
            .find(|v| v.species == species)
            .expect("species in the manifest");
        let file = std::fs::File::open(tests::tiny_map_dir().join(&spec.file)).expect("layer file");
        let mut reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .expect("PNG header");
        let mut buf = vec![0; reader.output_buffer_size().expect("buffer size")];
        let info = reader.next_frame(&mut buf).expect("PNG data");
        assert_eq!(info.color_type, png::ColorType::Grayscale);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        buf.truncate(info.buffer_size());
        Self {
            samples: buf,
            width: info.width as usize,
            height: info.height as usize,
            spacing_m: spec.spacing_m,
            max_per_m2: spec.max_density_per_m2,
            origin_m: world.origin_m(),
        }
    }

    fn at(&self, x_m: f64, y_m: f64) -> f64 {
        let gx = (x_m - self.origin_m[0]) / self.spacing_m;
        let gy = (y_m - self.origin_m[1]) / self.spacing_m;
        let (w, h) = (self.width, self.height);
        // Row 0 of the file is the northern edge; grid row r (from the south) is file row h-1-r.
        let v = |x: usize, y: usize| f64::from(self.samples[(h - 1 - y) * w + x]);
        let (x0, y0) = (
            (gx.floor() as usize).min(w - 2),
            (gy.floor() as usize).min(h - 2),
        );
        let (fx, fy) = (gx - x0 as f64, gy - y0 as f64);
        let south = v(x0, y0) * (1.0 - fx) + v(x0 + 1, y0) * fx;
        let north = v(x0, y0 + 1) * (1.0 - fx) + v(x0 + 1, y0 + 1) * fx;
        (south * (1.0 - fy) + north * fy) / 255.0 * self.max_per_m2
    }
}

/// Midpoint-rule integral of the PNG density over the area where things may grow.
fn density_integral(world: &World, p: &Placer, d: &PngDensity, area: Rect, step_m: f64) -> f64 {
    let mut sum = 0.0;
    let mut y = area.min[1] + 0.5 * step_m;
    while y < area.max[1] {
        let mut x = area.min[0] + 0.5 * step_m;
        while x < area.max[0] {
            if !p.excluded(world, x, y) {
                sum += d.at(x, y);
            }
            x += step_m;
        }
        y += step_m;
    }
    sum * step_m * step_m
}

/// Item counts follow the density map read independently from its PNG: within 2% of the
/// integral for every small species (the ranked tile's prefixes are evenly spread, so the
/// count of a region follows its area far more closely than independent random points would).
#[test]
fn counts_match_the_integral_of_the_density_map() {
    let world = tiny_world();
    let p = Placer::new(&world);
    for s in small_species(&p) {
        let name = &p.species[s].name;
        let png = PngDensity::load(&world, name);
        let area = area_for(&world, &p, s);
        let items = by_tiles(&world, &p, s, area, 1.0);
        let expected = density_integral(&world, &p, &png, area, 0.5);
        let ratio = items.len() as f64 / expected;
        println!(
            "{name}: {} items, integral {expected:.1}, ratio {ratio:.4}",
            items.len()
        );
        assert!(expected > 300.0, "{name}: integral {expected}");
        assert!(
            (ratio - 1.0).abs() <= 0.02,
            "{name}: {} items vs integral {expected:.1} (ratio {ratio:.4})",
            items.len()
        );
    }
}

/// `place_where` (the early height filter a node's vegetation phase uses) places exactly the
/// items of `place` whose height passes the filter, for every species including the map's
/// large trees, on the tiny map and the cliff map.
#[test]
fn the_early_height_filter_keeps_exactly_the_filtered_items() {
    for world in [tiny_world(), cliff_world()] {
        let p = Placer::new(&world);
        let o = world.origin_m();
        let size = world.size_m();
        let area = rect(o[0], o[1], o[0] + size[0], o[1] + size[1]);
        let mut checked = 0;
        for s in 0..p.species.len() {
            let mut all = Vec::new();
            p.place(&world, s, area, 1.0, &mut all);
            if all.len() < 4 {
                continue;
            }
            // Keep the taller half (by the median height): both sides non-empty.
            let mut heights: Vec<f32> = all.iter().map(|it| it.height_m).collect();
            heights.sort_by(f32::total_cmp);
            let median = heights[heights.len() / 2];
            let keep = |h: f32| h >= median;
            let want: Vec<Item> = all.iter().copied().filter(|it| keep(it.height_m)).collect();
            let mut got = Vec::new();
            p.place_where(&world, s, area, 1.0, keep, &mut got);
            assert!(!want.is_empty() && want.len() < all.len() || heights[0] == median);
            assert_eq!(got.len(), want.len(), "{}", p.species[s].name);
            for (g, w) in got.iter().zip(&want) {
                assert_eq!(
                    (g.x_m, g.y_m, g.z_m, g.height_m, g.radius_m, g.yaw_rad),
                    (w.x_m, w.y_m, w.z_m, w.height_m, w.radius_m, w.yaw_rad),
                    "{}",
                    p.species[s].name
                );
            }
            checked += 1;
        }
        assert!(checked >= 2, "only {checked} species with items");
    }
}

#[test]
fn thinning_is_monotone() {
    let world = tiny_world();
    let p = Placer::new(&world);
    let key = |it: &Item| (it.x_m.to_bits(), it.y_m.to_bits());
    for s in small_species(&p) {
        let area = area_for(&world, &p, s);
        let mut previous: Option<std::collections::HashSet<(u64, u64)>> = None;
        for scale in [0.1, 0.3, 0.7, 1.0, 1.5, 4.0] {
            let now: std::collections::HashSet<_> = by_tiles(&world, &p, s, area, scale)
                .iter()
                .map(key)
                .collect();
            if let Some(prev) = &previous {
                assert!(
                    prev.is_subset(&now),
                    "{} at scale {scale}: {} items kept at a lower density are gone",
                    p.species[s].name,
                    prev.difference(&now).count()
                );
                assert!(now.len() >= prev.len());
            }
            previous = Some(now);
        }
    }
}

#[test]
fn output_does_not_depend_on_generation_order() {
    let world = tiny_world();
    let p = Placer::new(&world);
    let o = world.origin_m();
    let area = rect(o[0], o[1], o[0] + 96.0, o[1] + 96.0);
    let mut tiles: Vec<Rect> = Vec::new();
    for j in 0..6 {
        for i in 0..6 {
            let (x, y) = (o[0] + f64::from(i) * 16.0, o[1] + f64::from(j) * 16.0);
            tiles.push(rect(x, y, x + 16.0, y + 16.0));
        }
    }
    let run = |order: &[Rect], placer: &Placer| {
        let mut per: Vec<(usize, Vec<Item>)> = Vec::new();
        for (n, r) in order.iter().enumerate() {
            let mut v = Vec::new();
            placer.place_all(&world, *r, &mut v);
            per.push((n, v));
        }
        per
    };
    let forward = run(&tiles, &p);
    let mut reversed_tiles = tiles.clone();
    reversed_tiles.reverse();
    // A fresh placer, and the tiles the other way round, with other work in between.
    let q = Placer::new(&world);
    let mut scratch = Vec::new();
    q.place_all(&world, area, &mut scratch);
    let backward = run(&reversed_tiles, &q);
    for (n, items) in &forward {
        let m = tiles.len() - 1 - n;
        assert_eq!(items, &backward[m].1, "tile {n} differs");
    }
    // And the tiles together are exactly the area placed at once.
    let mut all: Vec<Item> = forward.into_iter().flat_map(|(_, v)| v).collect();
    let key = |it: &Item| (it.species, it.x_m.to_bits(), it.y_m.to_bits());
    all.sort_by_key(key);
    scratch.sort_by_key(key);
    assert_eq!(all, scratch);
    assert!(all.len() > 100, "{} items", all.len());
}

#[test]
fn nothing_grows_on_roads_or_in_water() {
    for (name, world) in [("tiny", tiny_world()), ("cliff", cliff_world())] {
        let p = Placer::new(&world);
        let o = world.origin_m();
        let s = world.size_m();
        let water = world
            .map
            .manifest
            .ground
            .legend
            .iter()
            .position(|g| g.name == "water")
            .unwrap() as u8;
        let mut items = Vec::new();
        let (mut near_road, mut checked) = (0usize, 0usize);
        for sp in 0..p.species.len() {
            let area = if p.species[sp].kind == Kind::GrassClump {
                // Grass along the roads and on the sea edge (dense: not the whole map).
                rect(o[0] + 180.0, o[1], o[0] + 340.0, o[1] + s[1])
            } else {
                rect(o[0], o[1], o[0] + s[0], o[1] + s[1])
            };
            items.extend(by_tiles(&world, &p, sp, area, 1.0));
        }
        for it in &items {
            checked += 1;
            assert!(
                it.z_m > world.map.manifest.water_level_m,
                "{name}: item at ({}, {}) is under water",
                it.x_m,
                it.y_m
            );
            assert_ne!(
                world.ground_type(it.x_m, it.y_m),
                water,
                "{name}: item on water ground"
            );
            for d in &world.map.decals {
                if !matches!(d.kind, DecalKind::Road | DecalKind::Path) {
                    continue;
                }
                for w in d.points.windows(2) {
                    let (dist, _) = worldgen::roads::segment_closest(
                        [it.x_m, it.y_m],
                        [w[0][0], w[0][1]],
                        [w[1][0], w[1][1]],
                    );
                    let core = 0.5 * f64::from(d.width_m);
                    assert!(
                        dist >= core,
                        "{name}: species {} at ({}, {}) is {dist} m from a {:?} centre line \
                         (half width {core} m)",
                        it.species,
                        it.x_m,
                        it.y_m,
                        d.kind
                    );
                    if dist < core + f64::from(d.falloff_m) + 3.0 {
                        near_road += 1;
                    }
                }
            }
        }
        println!("{name}: {checked} items checked, {near_road} within 3 m of a road's edge");
        assert!(
            checked > 1000 && near_road > 10,
            "{name}: {checked} / {near_road}"
        );
    }
}

/// Items drawn when `shown` nodes are displayed, by the rule the renderer applies
/// (`group_dither`: a shown node draws its groups, an ancestor of shown nodes the groups it keeps
/// through splits), as (species, x bits, y bits, representation).
fn drawn(
    world: &World,
    p: &Placer,
    tree: &QuadTree,
    shown: &[engine::terrain::quadtree::NodeKey],
) -> Vec<(u16, u64, u64, Representation)> {
    use engine::vegetation::representation::group_dither;
    let mut nodes: Vec<_> = shown.iter().flat_map(|k| k.ancestors()).collect();
    nodes.extend_from_slice(shown);
    nodes.sort();
    nodes.dedup();
    let mut out = Vec::new();
    for k in nodes {
        let is_shown = shown.contains(&k);
        let is_ancestor = shown.iter().any(|s| s.ancestors().any(|a| a == k));
        for g in node_vegetation(world, p, tree, k).groups {
            if group_dither(g.replaced_on_split, is_shown, is_ancestor).is_some() {
                out.extend(g.items.iter().map(|it| {
                    (
                        it.species,
                        it.x_m.to_bits(),
                        it.y_m.to_bits(),
                        g.representation,
                    )
                }));
            }
        }
    }
    out.sort_by_key(|d| (d.0, d.1, d.2));
    out
}

/// Whether a node is split or not, every item in it is drawn exactly once, in the
/// representation of the displayed level; a split does not redraw what the parent keeps.
#[test]
fn every_item_is_drawn_once_in_the_displayed_levels_representation() {
    let world = tiny_world();
    let p = Placer::new(&world);
    let tree = QuadTree::new(world.origin_m(), world.size_m());
    let (mut checked, mut kept_by_parent) = (0usize, 0usize);
    for level in 2..tree.max_level {
        let key = tree
            .key_at(
                level,
                world.origin_m()[0] + 200.0,
                world.origin_m()[1] + 300.0,
            )
            .unwrap();
        for (shown, lvl) in [(vec![key], level), (key.children().to_vec(), level + 1)] {
            // Ancestors draw their kept items over their whole area: look inside this node.
            let r = tree.rect(key);
            let inside = |d: &(u16, u64, u64, Representation)| {
                let (x, y) = (f64::from_bits(d.1), f64::from_bits(d.2));
                x >= r.min[0] && x < r.max[0] && y >= r.min[1] && y < r.max[1]
            };
            let d: Vec<_> = drawn(&world, &p, &tree, &shown)
                .into_iter()
                .filter(inside)
                .collect();
            for w in d.windows(2) {
                assert!(
                    (w[0].0, w[0].1, w[0].2) != (w[1].0, w[1].1, w[1].2),
                    "level {lvl}: an item is drawn twice: {:?} {:?}",
                    w[0],
                    w[1]
                );
            }
            // Exactly the items placed in the node that this level's representation keeps.
            let s_m = tree.spacing_m(lvl);
            let finest = lvl == tree.max_level;
            let mut want = Vec::new();
            for sp in 0..p.species.len() {
                let mut items = Vec::new();
                p.place(&world, sp, r, 1.0, &mut items);
                for it in items {
                    let kind = p.species[sp].kind;
                    if let Some(rep) = representation(kind, f64::from(it.height_m), s_m, finest) {
                        want.push((it.species, it.x_m.to_bits(), it.y_m.to_bits(), rep));
                    }
                }
            }
            want.sort_by_key(|d| (d.0, d.1, d.2));
            assert!(
                d == want,
                "level {lvl}: {} drawn, {} expected",
                d.len(),
                want.len()
            );
            checked += d.len();
        }
        kept_by_parent += node_vegetation(&world, &p, &tree, key)
            .groups
            .iter()
            .filter(|g| !g.replaced_on_split)
            .map(|g| g.items.len())
            .sum::<usize>();
    }
    assert!(
        checked > 500 && kept_by_parent > 0,
        "{checked} / {kept_by_parent}"
    );
}

/// The pixel metric holds for vegetation: in every selected node, an item drawn as a billboard
/// projects to at most 20 tau px and a group-billboard member to at most 4.8 tau px (the
/// representation error is part of each node's selection error).
#[test]
fn billboards_and_groups_stay_small_on_screen() {
    use engine::terrain::bounds::BoundsCache;
    use engine::terrain::select::{SelectParams, select};
    use engine::vegetation::representation::{BILLBOARD_RATIO, ERROR_PER_SPACING, MESH_RATIO};
    let world = tiny_world();
    let p = Placer::new(&world);
    let tree = QuadTree::new(world.origin_m(), world.size_m());
    let mut cache = BoundsCache::new();
    let tau = 2.0;
    let (mut billboards, mut groups) = (0usize, 0usize);
    for i in 0..12i64 {
        let cam = tests::terrain::random_camera(&world, 5, i, 2.0, 62.0, [640, 360]);
        let pos = cam.position_m;
        let sel = select(
            &world,
            &tree,
            &mut cache,
            &cam,
            SelectParams::culled(tau, &tree),
        );
        let k = cam.k_px();
        for n in &sel.nodes {
            for g in node_vegetation(&world, &p, &tree, n.key).groups {
                let limit = match g.representation {
                    Representation::Mesh => continue,
                    Representation::Billboard => MESH_RATIO * tau / ERROR_PER_SPACING,
                    Representation::Group => BILLBOARD_RATIO * tau / ERROR_PER_SPACING,
                };
                for it in &g.items {
                    let d = (glam::DVec3::new(it.x_m, it.y_m, it.z_m) - pos).length();
                    let px = f64::from(it.height_m) * k / d;
                    assert!(
                        px <= limit * (1.0 + 1e-9),
                        "{:?} of species {} at {d:.1} m projects to {px:.1} px (limit {limit} px)",
                        g.representation,
                        it.species
                    );
                    match g.representation {
                        Representation::Billboard => billboards += 1,
                        _ => groups += 1,
                    }
                }
            }
        }
    }
    assert!(billboards > 100 && groups > 100, "{billboards} / {groups}");
}

/// The line-of-sight model: clear above the canopy, more blocked the longer the path through
/// it, never more than fully clear.
#[test]
fn canopy_visibility_behaves() {
    use engine::vegetation::Canopy;
    use glam::DVec3;
    let world = tiny_world();
    let p = Placer::new(&world);
    let c = Canopy::new(&world, &p);
    let o = world.origin_m();
    let ground = |x: f64, y: f64| world.height_m(x, y);
    let (x0, y0) = (o[0] + 100.0, o[1] + 250.0);
    let eye = DVec3::new(x0, y0, ground(x0, y0) + 1.5);
    let mut last = 1.0;
    let mut blocked = false;
    for d in [20.0, 60.0, 120.0, 240.0, 380.0] {
        let t = DVec3::new(x0 + d, y0, ground(x0 + d, y0) + 1.5);
        let v = c.visibility(&world, eye, t);
        assert!((0.0..=1.0).contains(&v), "{v}");
        // Not a strict law with 16 samples, but over these lengths the path only grows.
        assert!(
            v <= last + 0.05,
            "visibility grew from {last} to {v} at {d} m"
        );
        blocked |= v < 0.5;
        last = v;
    }
    assert!(
        blocked,
        "a 380 m path at eye height through the tiny map's vegetation: {last}"
    );
    // High above the canopy nothing is hidden.
    let high = DVec3::new(x0, y0, ground(x0, y0) + c.top_m + 50.0);
    let r = Rect {
        min: [x0 + 200.0, y0],
        max: [x0 + 216.0, y0 + 16.0],
    };
    assert_eq!(
        c.error_factor(&world, high, r, ground(x0 + 208.0, y0 + 8.0), 250.0),
        1.0
    );
}
