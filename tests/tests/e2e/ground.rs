//! Ground textures on the software adapter: a node's texels do not depend on what was rendered
//! before, neighbours agree on their shared border texels, and roads land where the map says.

use engine::camera::Camera;
use engine::ground::content::NodeGround;
use engine::ground::content::TEXTURE_BYTES;
use engine::ground::decal_index::DecalIndex;
use engine::ground::layout::{BORDER, MIP_LEVELS, SIDE, TEXELS, texel_m};
use engine::render::Target;
use engine::render::ground::{GROUND_TEXTURE_FORMAT, GroundTexturer};
use engine::render::ground_pool::{FIRST_PAGE_LAYERS, GroundPool, LAYER_BYTES, LAYERS_PER_PAGE};
use engine::render::read_texels;
use engine::render::terrain::{TerrainNodeGpu, TerrainRenderer};
use engine::stream::StreamSettings;
use engine::terrain::quadtree::{NodeKey, QuadTree, Side};
use glam::DVec3;
use tests::gpu::device;
use tests::terrain::{tiny_world, tree_of};
use worldgen::map::DecalKind;
use worldgen::noise::unit3;

/// Renders node `key`'s ground texture and reads it back (RGBA8, top texel row first).
fn render(
    gpu: &engine::render::Gpu,
    t: &GroundTexturer,
    world: &engine::surface::World,
    index: &DecalIndex,
    tree: &QuadTree,
    key: NodeKey,
) -> Vec<u8> {
    let target = Target::new(&gpu.device, [SIDE, SIDE], GROUND_TEXTURE_FORMAT);
    let enc = record_node(gpu, t, &target.color_view, world, index, tree, key);
    t.submit(gpu, enc);
    target.read_rgba(gpu).expect("readback")
}

/// An encoder holding node `key`'s texture pass into `view` (level 0 only).
fn record_node(
    gpu: &engine::render::Gpu,
    t: &GroundTexturer,
    view: &wgpu::TextureView,
    world: &engine::surface::World,
    index: &DecalIndex,
    tree: &QuadTree,
    key: NodeKey,
) -> wgpu::CommandEncoder {
    let ground = NodeGround::new(world, index, tree, key);
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    t.record(gpu, &mut enc, view, tree, key, &ground, &world.map.decals);
    enc
}

/// Renders node `key`'s ground texture with its mip levels into a layer of `pool` and reads
/// every level back (level k: `SIDE >> k` texels a side, top row first).
fn render_levels(
    gpu: &engine::render::Gpu,
    t: &GroundTexturer,
    pool: &mut GroundPool,
    world: &engine::surface::World,
    index: &DecalIndex,
    tree: &QuadTree,
    key: NodeKey,
) -> Vec<Vec<u8>> {
    let slot = pool.lease(&gpu.device).expect("a free layer");
    let mut enc = record_node(gpu, t, &slot.view, world, index, tree, key);
    t.record_mips(&mut enc, std::slice::from_ref(&slot.mips));
    t.submit(gpu, enc);
    let page = pool.page(slot.page()).expect("the slot's page");
    (0..MIP_LEVELS)
        .map(|mip| {
            let source = wgpu::TexelCopyTextureInfo {
                texture: page,
                mip_level: mip,
                origin: wgpu::Origin3d {
                    x: 0,
                    y: 0,
                    z: slot.layer(),
                },
                aspect: wgpu::TextureAspect::All,
            };
            read_texels(gpu, source, [SIDE >> mip, SIDE >> mip]).expect("readback")
        })
        .collect()
}

fn texel(img: &[u8], i: u32, j: u32) -> [u8; 4] {
    texel_of(img, SIDE, i, j)
}

/// Texel (i east, j north) of an RGBA8 image `side` texels a side, top row first.
fn texel_of(img: &[u8], side: u32, i: u32, j: u32) -> [u8; 4] {
    let row = (side - 1 - j) as usize;
    let k = (row * side as usize + i as usize) * 4;
    [img[k], img[k + 1], img[k + 2], img[k + 3]]
}

/// The same node's bytes after other nodes were rendered; east and north neighbours of three
/// levels share every border texel bit for bit (the border ring of one node over the other).
#[test]
fn node_textures_do_not_depend_on_order_and_neighbours_share_border_texels() {
    let Some(gpu) = device() else { return };
    let world = tiny_world();
    let tree = tree_of(&world);
    let index = DecalIndex::new(&world.map.decals, world.origin_m(), world.size_m());
    let t = GroundTexturer::new(&gpu, &world);
    for level in [tree.max_level - 4, tree.max_level - 2, tree.max_level] {
        // A node that holds a road, so its texture has decal texels.
        let road = world
            .map
            .decals
            .iter()
            .find(|d| d.kind == DecalKind::Road)
            .expect("the tiny map has a road");
        let p = road.points[road.points.len() / 2];
        let a = tree.key_at(level, p[0], p[1]).expect("on the map");
        let first = render(&gpu, &t, &world, &index, &tree, a);
        let mut sides = 0;
        for side in [Side::East, Side::North] {
            let Some(b) = tree.neighbour_across(a, side, level) else {
                continue;
            };
            sides += 1;
            let other = render(&gpu, &t, &world, &index, &tree, b);
            for k in 0..BORDER {
                for s in 0..SIDE {
                    // a's texel over b, and b's texel over a, at the same world position.
                    let pairs = [(TEXELS + BORDER + k, BORDER + k), (TEXELS + k, k)];
                    for (ia, ib) in pairs {
                        let (ta, tb) = match side {
                            Side::East => (texel(&first, ia, s), texel(&other, ib, s)),
                            _ => (texel(&first, s, ia), texel(&other, s, ib)),
                        };
                        assert_eq!(ta, tb, "level {level} {side:?}: texel {ia}/{ib} row {s}");
                    }
                }
            }
        }
        assert!(
            sides > 0,
            "level {level}: {a:?} has no east or north neighbour to compare"
        );
        assert_eq!(
            render(&gpu, &t, &world, &index, &tree, a),
            first,
            "level {level}: the node's texture changed after rendering its neighbours"
        );
    }
}

/// Every mip level of neighbouring nodes' textures (as the renderer makes them, in pool
/// layers) agrees on the shared border texels bit for bit: level k has `BORDER >> k` border
/// texels and `TEXELS >> k` inner ones, and the 2 x 2 means never straddle a node edge.
#[test]
fn neighbours_share_border_texels_at_every_mip_level() {
    let Some(gpu) = device() else { return };
    let world = tiny_world();
    let tree = tree_of(&world);
    let index = DecalIndex::new(&world.map.decals, world.origin_m(), world.size_m());
    let t = GroundTexturer::new(&gpu, &world);
    let mut pool = GroundPool::new(0, t.mip_layout());
    let road = world
        .map
        .decals
        .iter()
        .find(|d| d.kind == DecalKind::Road)
        .expect("the tiny map has a road");
    let p = road.points[road.points.len() / 3];
    let mut compared = 0;
    for level in [tree.max_level - 3, tree.max_level] {
        let a = tree.key_at(level, p[0], p[1]).expect("on the map");
        let first = render_levels(&gpu, &t, &mut pool, &world, &index, &tree, a);
        for side in [Side::East, Side::North] {
            let Some(b) = tree.neighbour_across(a, side, level) else {
                continue;
            };
            let other = render_levels(&gpu, &t, &mut pool, &world, &index, &tree, b);
            for mip in 1..MIP_LEVELS {
                let (n, border, texels) = (SIDE >> mip, BORDER >> mip, TEXELS >> mip);
                for k in 0..border {
                    for s in 0..n {
                        let pairs = [(texels + border + k, border + k), (texels + k, k)];
                        for (ia, ib) in pairs {
                            let (ta, tb) = match side {
                                Side::East => (
                                    texel_of(&first[mip as usize], n, ia, s),
                                    texel_of(&other[mip as usize], n, ib, s),
                                ),
                                _ => (
                                    texel_of(&first[mip as usize], n, s, ia),
                                    texel_of(&other[mip as usize], n, s, ib),
                                ),
                            };
                            assert_eq!(
                                ta, tb,
                                "level {level} mip {mip} {side:?}: texel {ia}/{ib} row {s}"
                            );
                            compared += 1;
                        }
                    }
                }
            }
            // The mips are of this texture: a level-k texel is the mean of the 4^k level-0
            // texels under it in linear light (within sRGB rounding), so a mip level left
            // black or stale would fail here.
            for mip in 1..MIP_LEVELS {
                let n = 1u32 << mip;
                for (i, j) in [(5, 7), (60, 33), (100, 120), (31, 2)] {
                    let (i, j) = (i >> (mip - 1), j >> (mip - 1));
                    let m = texel_of(&other[mip as usize], SIDE >> mip, i, j);
                    for c in 0..3 {
                        let lin = engine::color::srgb_to_linear;
                        let mean = (0..n * n)
                            .map(
                                |q| lin(texel_of(&other[0], SIDE, n * i + q % n, n * j + q / n)[c]),
                            )
                            .sum::<f64>()
                            / f64::from(n * n);
                        let got = lin(m[c]);
                        assert!(
                            (got - mean).abs() <= 0.01 + 0.02 * mean,
                            "level {level} {side:?}: mip {mip} texel ({i}, {j}) channel {c} is \
                             {got}, the mean of its {} level-0 texels is {mean}",
                            n * n
                        );
                    }
                }
            }
        }
    }
    assert!(compared > 1000, "only {compared} mip texel pairs compared");
}

/// `road` (sRGB) is asphalt within `tolerance` per channel (linear 0.045 is sRGB ~61), and
/// `off_road`, 10 m to the side, differs from it by more than 15 in some channel; `at` names
/// the place in the failure message.
fn assert_road_and_off_road(road: &[u8], off_road: &[u8], tolerance: i32, at: &str) {
    for ch in 0..3 {
        assert!(
            (i32::from(road[ch]) - 61).abs() <= tolerance,
            "{at}: the road centre's {road:?} is not asphalt"
        );
    }
    let diff = (0..3)
        .map(|ch| (i32::from(road[ch]) - i32::from(off_road[ch])).abs())
        .max()
        .unwrap_or(0);
    assert!(
        diff > 15,
        "{at}: 10 m off the road {off_road:?} looks like the road {road:?}"
    );
}

/// Road texels where the map's road runs, ground texels 10 m to its side (positions from the
/// map's decal list; colours from the texture the GPU rendered).
#[test]
fn a_road_centre_is_road_and_ten_metres_off_is_not() {
    let Some(gpu) = device() else { return };
    let world = tiny_world();
    let tree = tree_of(&world);
    let index = DecalIndex::new(&world.map.decals, world.origin_m(), world.size_m());
    let t = GroundTexturer::new(&gpu, &world);
    let decals = &world.map.decals;
    // Distance beyond the soft edge of the nearest road or path (of the kinds in `kinds`).
    let dist_to = |kinds: &[DecalKind], x: f64, y: f64| {
        decals
            .iter()
            .filter(|d| kinds.contains(&d.kind))
            .flat_map(|d| d.points.windows(2).map(move |w| (d, w)))
            .map(|(d, w)| {
                let (dist, _) = worldgen::roads::segment_closest(
                    [x, y],
                    [w[0][0], w[0][1]],
                    [w[1][0], w[1][1]],
                );
                dist - 0.5 * f64::from(d.width_m) - f64::from(d.falloff_m)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let mut checked = 0;
    for d in decals.iter().filter(|d| d.kind == DecalKind::Road) {
        for w in d.points.windows(2).step_by(7) {
            let (a, b) = (w[0], w[1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            if len < 1.0 {
                continue;
            }
            let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
            let n = [-(b[1] - a[1]) / len, (b[0] - a[0]) / len];
            let off = [mid[0] + 10.0 * n[0], mid[1] + 10.0 * n[1]];
            let both = [DecalKind::Road, DecalKind::Path];
            if dist_to(&both, off[0], off[1]) < 1.0
                || dist_to(&[DecalKind::Path], mid[0], mid[1]) < 1.0
            {
                continue; // another road there, or a path drawn over this one
            }
            let level = tree.max_level - 3;
            let Some(key) = tree.key_at(level, mid[0], mid[1]) else {
                continue;
            };
            let r = tree.rect(key);
            let tm = texel_m(&tree, level);
            let at = |p: [f64; 2]| {
                let i = ((p[0] - r.min[0]) / tm).floor() as i64 + i64::from(BORDER);
                let j = ((p[1] - r.min[1]) / tm).floor() as i64 + i64::from(BORDER);
                (i >= 0 && j >= 0 && i < i64::from(SIDE) && j < i64::from(SIDE))
                    .then_some((i as u32, j as u32))
            };
            let (Some(c), Some(o)) = (at(mid), at(off)) else {
                continue;
            };
            let img = render(&gpu, &t, &world, &index, &tree, key);
            let road = texel(&img, c.0, c.1);
            let ground = texel(&img, o.0, o.1);
            assert_road_and_off_road(&road, &ground, 6, &format!("texels at {mid:?} / {off:?}"));
            checked += 1;
            if checked >= 6 {
                return;
            }
        }
    }
    assert!(checked >= 2, "only {checked} road points checked");
}

/// The pool hands out each layer once, as many as its budget holds (a small first page, then
/// pages of the largest size, the last one what is left), refuses when full, takes a layer back
/// when its slot drops (the next lease gets it), and never holds more than its budget.
#[test]
fn the_texture_pool_stays_in_its_budget_and_reuses_dropped_layers() {
    let Some(gpu) = device() else { return };
    let page = LAYERS_PER_PAGE as usize * LAYER_BYTES;
    let world = tiny_world();
    let t = GroundTexturer::new(&gpu, &world);
    let budget = page + page / 2;
    let capacity = budget / LAYER_BYTES;
    // 384 layers: the first page (128) and one of 256.
    assert_eq!(
        engine::render::ground_pool::page_layers(budget, LAYERS_PER_PAGE),
        vec![FIRST_PAGE_LAYERS, LAYERS_PER_PAGE]
    );
    let mut pool = GroundPool::new(budget, t.mip_layout());
    let mut slots: Vec<_> = (0..capacity)
        .map(|_| pool.lease(&gpu.device).expect("a free layer"))
        .collect();
    let mut layers: Vec<(u32, u32)> = slots.iter().map(|s| (s.page(), s.layer())).collect();
    layers.sort_unstable();
    layers.dedup();
    assert_eq!(layers.len(), capacity, "each layer leased once");
    assert!(
        pool.lease(&gpu.device).is_none(),
        "a 1.5-page budget holds 1.5 pages of layers"
    );
    assert_eq!(pool.layers_in_use(), capacity);
    let freed = slots.swap_remove(17);
    let layer = (freed.page(), freed.layer());
    drop(freed);
    assert_eq!(pool.layers_in_use(), capacity - 1);
    let again = pool
        .lease(&gpu.device)
        .expect("the dropped layer is free again");
    assert_eq!((again.page(), again.layer()), layer);
    assert!(pool.bytes() <= budget);
    drop(slots);
    drop(again);
    assert_eq!(pool.layers_in_use(), 0);
}

/// Layers of the viewer's ground pool in use, and resident nodes holding one.
fn layers_and_holders(v: &engine::viewer::Viewer) -> (usize, usize) {
    let terrain = v
        .scene
        .renderer::<TerrainRenderer>()
        .expect("the viewer has a terrain renderer");
    let s = &v.streamer;
    let holders = s
        .resident_keys()
        .iter()
        .filter_map(|&k| s.resident(k))
        .filter(|r| {
            r.work
                .gpu
                .get::<TerrainNodeGpu>()
                .is_some_and(|t| t.ground_slot().is_some())
        })
        .count();
    (terrain.ground_pool_use().0, holders)
}

/// A 10,000-frame storm of teleports and fast flights through the viewer (streaming and GPU
/// phases; ground textures rendered and submitted) leaves no pool layer leaked: at every
/// checkpoint and after settling, the layers in use are exactly those held by resident nodes,
/// and after settling they fit the node-cache budget that counts them.
#[test]
fn a_teleport_storm_leaks_no_ground_texture_layer() {
    let Some(g) = device() else { return };
    let budget = 96 << 20;
    let mut v = engine::viewer::Viewer::new(
        &g,
        engine::render::COLOR_FORMAT,
        tiny_world(),
        StreamSettings {
            workers: 2,
            cache_budget_bytes: budget,
            tau_px: 2.0,
            ..StreamSettings::default()
        },
    );
    let cam = |x: f64, y: f64, above: f64, yaw: f64| {
        let w = &v_world();
        let p = DVec3::new(x, y, w.height_m(x, y) + above);
        Camera::look_at(
            p,
            p + DVec3::new(yaw.cos(), yaw.sin(), -0.3),
            60f64.to_radians(),
            [320, 180],
        )
    };
    let mut max_layers = 0;
    // Resident nodes at most, and queued textures at most over that (the queue forgets dropped
    // nodes' textures in bulk: at most twice the live ones at the last sweep, plus a frame's).
    let (mut max_resident, mut max_queued_ratio) = (0usize, 0.0f64);
    for i in 0..10_000i64 {
        let c = if i % 400 < 200 {
            cam(
                512.0 * unit3(5, i, 0),
                512.0 * unit3(5, i, 1),
                3.0 + 200.0 * unit3(5, i, 2),
                6.3 * unit3(5, i, 3),
            )
        } else {
            let t = (i % 200) as f64 / 200.0;
            cam(20.0 + 470.0 * t, 256.0 + 180.0 * (t * 9.0).sin(), 10.0, 0.2)
        };
        v.stream_only(&g, &c, 1.0 / 60.0);
        // Every 1,000 frames the camera waits where it is until its view is ready, so the storm
        // has made textures whatever the workers' speed (the teleports after it drop them).
        if i % 1000 == 999 {
            let start = std::time::Instant::now();
            while !v.stream_only(&g, &c, 0.1) {
                assert!(start.elapsed().as_secs() < 180, "frame {i}: view not ready");
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
        }
        // Layers held, every frame.
        let terrain = v
            .scene
            .renderer::<TerrainRenderer>()
            .expect("terrain renderer");
        max_layers = max_layers.max(terrain.ground_pool_use().0);
        max_resident = max_resident.max(v.streamer.resident_keys().len());
        let queued = terrain.textures_queued();
        max_queued_ratio = max_queued_ratio.max(queued as f64 / max_resident.max(64) as f64);
        assert!(
            queued <= 3 * max_resident.max(64),
            "frame {i}: {queued} textures queued, at most {max_resident} nodes resident"
        );
        if i % 250 == 0 {
            let (layers, holders) = layers_and_holders(&v);
            assert_eq!(
                layers, holders,
                "frame {i}: layers in use vs resident holders"
            );
        }
    }
    assert!(max_layers > 20, "the storm made only {max_layers} textures");
    eprintln!("textures queued at most {max_queued_ratio:.2}x the resident nodes (at least 64)");
    let last = cam(250.0, 250.0, 30.0, 1.0);
    let start = std::time::Instant::now();
    while !v.stream_only(&g, &last, 0.1) {
        assert!(
            start.elapsed().as_secs() < 180,
            "did not settle after the storm"
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let (layers, holders) = layers_and_holders(&v);
    assert_eq!(layers, holders, "after settling");
    assert!(layers > 0, "the settled view has no textured node");
    let resident: usize = v.streamer.stats.resident_bytes;
    assert!(
        layers * TEXTURE_BYTES <= resident && resident <= budget.max(v.streamer.pinned_bytes()),
        "{layers} layers of {TEXTURE_BYTES} bytes, {resident} resident bytes, budget {budget}"
    );
}

/// Ground textures are made for the nodes the display needs, not for prefetched ones, and
/// each counts in its node's cache bytes once made: after a view settles with prefetch along a
/// path to the far side of the map, the prefetched nodes (resident, neither needed for display
/// nor drawn) hold no texture, every displayed one holds its own, and every resident node's
/// bytes are its payloads' plus a texture's exactly when it holds one.
#[test]
fn prefetched_nodes_get_no_ground_texture_and_textures_count_once_made() {
    let Some(g) = device() else { return };
    let mut v = tests::gpu::tiny_viewer(&g, 2.0);
    let cam = |x: f64, y: f64| {
        let p = DVec3::new(x, y, v_world().height_m(x, y) + 10.0);
        Camera::look_at(
            p,
            p + DVec3::new(1.0, 0.0, -0.3),
            60f64.to_radians(),
            [320, 180],
        )
    };
    let here = cam(60.0, 100.0);
    let future: Vec<(f64, Camera)> = engine::stream::predict::PREDICT_HORIZONS_S
        .iter()
        .enumerate()
        .map(|(i, &h)| (h, cam(60.0 + 130.0 * (i + 1) as f64, 420.0)))
        .collect();
    let start = std::time::Instant::now();
    while !v.stream_only_along(&g, &here, 0.1, &future) {
        assert!(start.elapsed().as_secs() < 180, "the view did not settle");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let s = &v.streamer;
    let mut displayed = s.needed().to_set();
    displayed.extend(s.draw_list().iter().map(|d| d.key));
    let (mut prefetched, mut textured) = (0, 0);
    for k in s.resident_keys() {
        let r = s.resident(k).expect("resident");
        let Some(node) = r.work.gpu.get::<TerrainNodeGpu>() else {
            continue;
        };
        let has_texture = node.ground_slot().is_some();
        assert_eq!(
            r.bytes,
            r.work.bytes() + if has_texture { TEXTURE_BYTES } else { 0 },
            "{k:?}: cache bytes against payloads and texture"
        );
        if displayed.contains(&k) {
            assert!(has_texture, "{k:?} is displayed without its own texture");
            textured += 1;
        } else {
            assert!(!has_texture, "{k:?} is only prefetched but has a texture");
            prefetched += 1;
        }
    }
    assert!(
        prefetched >= 10 && textured >= 10,
        "{prefetched} prefetched and {textured} displayed nodes: the test sees too few"
    );
}

fn v_world() -> &'static engine::surface::World {
    static WORLD: std::sync::OnceLock<engine::surface::World> = std::sync::OnceLock::new();
    WORLD.get_or_init(tiny_world)
}

/// The same through the viewer, in pixels of rendered views (streamed nodes, their textures
/// sampled by the terrain shading, "texture only" view): looking down from 40 m on points of
/// the map's roads, the road's centre is asphalt and the ground 10 m off the road is not.
#[test]
fn in_a_rendered_view_a_road_centre_is_road_and_ten_metres_off_is_not() {
    let Some(g) = device() else { return };
    let world = tiny_world();
    let decals = world.map.decals.clone();
    let mut v = tests::gpu::tiny_viewer(&g, 1.0);
    v.view.plants = false;
    v.view.ground_view = engine::render::frame::GroundView::TextureOnly;
    let size = [128u32, 128];
    let target = engine::render::Target::new(&g.device, size, engine::render::COLOR_FORMAT);
    let pixel = |cam: &Camera, p: DVec3| {
        let rel = p - cam.position_m;
        let z = rel.dot(cam.forward);
        let k = cam.k_px();
        let x = f64::from(size[0]) * 0.5 + k * rel.dot(cam.right()) / z;
        let y = f64::from(size[1]) * 0.5 - k * rel.dot(cam.up) / z;
        (x.floor() as usize, y.floor() as usize)
    };
    let mut checked = 0;
    for d in decals.iter().filter(|d| d.kind == DecalKind::Road) {
        for w in d.points.windows(2).step_by(11) {
            let (a, b) = (w[0], w[1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            if len < 1.0 {
                continue;
            }
            let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
            let n = [-(b[1] - a[1]) / len, (b[0] - a[0]) / len];
            let off = [mid[0] + 10.0 * n[0], mid[1] + 10.0 * n[1]];
            let near_other = decals.iter().any(|o| {
                o.points.windows(2).any(|s| {
                    let reach = 0.5 * f64::from(o.width_m) + f64::from(o.falloff_m) + 1.0;
                    let (d_off, _) = worldgen::roads::segment_closest(
                        off,
                        [s[0][0], s[0][1]],
                        [s[1][0], s[1][1]],
                    );
                    d_off < reach
                }) || (o.kind != DecalKind::Road
                    && o.points.windows(2).any(|s| {
                        worldgen::roads::segment_closest(
                            mid,
                            [s[0][0], s[0][1]],
                            [s[1][0], s[1][1]],
                        )
                        .0 < 0.5 * f64::from(o.width_m) + f64::from(o.falloff_m) + 1.0
                    }))
            });
            if near_other {
                continue; // another decal there, or one drawn over this road
            }
            let ground = DVec3::new(mid[0], mid[1], world.height_m(mid[0], mid[1]));
            let cam = Camera::look_at(
                ground + DVec3::new(0.0, 0.0, 40.0),
                ground,
                40f64.to_radians(),
                size,
            );
            tests::gpu::settle(&g, &mut v, &target, &cam);
            let img = target.read_rgba(&g).expect("readback");
            let at = |(x, y): (usize, usize)| {
                let k = (y * size[0] as usize + x) * 4;
                [img[k], img[k + 1], img[k + 2]]
            };
            let road = at(pixel(&cam, ground));
            let off_px = pixel(
                &cam,
                DVec3::new(off[0], off[1], world.height_m(off[0], off[1])),
            );
            let other = at(off_px);
            assert_road_and_off_road(
                &road,
                &other,
                8,
                &format!("pixels at {mid:?} / {off:?} (pixel {off_px:?})"),
            );
            checked += 1;
            if checked >= 4 {
                return;
            }
        }
    }
    assert!(checked >= 2, "only {checked} road points checked");
}

/// Closed areas (fields, dirt, rock patches, house pads) where the map puts them: around an
/// area's centre the texture has the kind's colour (nearer to it than to the legend colour of
/// the ground type there), and 4 m beyond the area's soft edge it has the ground's colour, not the kind's.
/// Colours are means over 5 x 5 texels (27 cm each) against the material and pattern noise.
#[test]
fn area_decals_are_drawn_inside_their_outline_and_not_beyond() {
    let Some(gpu) = device() else { return };
    let world = tests::terrain::patches_world();
    let tree = tree_of(&world);
    let index = DecalIndex::new(&world.map.decals, world.origin_m(), world.size_m());
    let t = GroundTexturer::new(&gpu, &world);
    let decals = &world.map.decals;
    let map = &world.map;
    let level = tree.max_level - 2;
    let tm = texel_m(&tree, level);
    let srgb = |l: f64| f64::from(engine::color::linear_to_srgb(l));
    // The kinds' mean linear albedo (the field's the mean of its two row tones).
    let kind_color = |k: DecalKind| {
        let lin = match k {
            DecalKind::RockPatch => [0.21, 0.2, 0.19],
            // A house pad is drawn as bare earth.
            DecalKind::Dirt | DecalKind::Pad => [0.2, 0.13, 0.075],
            _ => [0.28, 0.215, 0.07],
        };
        lin.map(srgb)
    };
    let legend_at = |p: [f64; 2]| {
        let s = map.manifest.ground.spacing_m;
        let x = ((p[0] - map.manifest.origin_m[0]) / s).round() as usize;
        let y = ((p[1] - map.manifest.origin_m[1]) / s).round() as usize;
        let g = map.ground.get(
            x.min(map.ground.width() - 1),
            y.min(map.ground.height() - 1),
        );
        map.manifest.ground.legend[g as usize].color.map(f64::from)
    };
    // The legend colour around `p` when the ground samples within 8 m are all one type.
    let uniform_legend_at = |p: [f64; 2]| {
        let s = map.manifest.ground.spacing_m;
        let x = ((p[0] - map.manifest.origin_m[0]) / s).round() as i64;
        let y = ((p[1] - map.manifest.origin_m[1]) / s).round() as i64;
        let reach = (8.0 / s).ceil() as i64;
        let g = map.ground.get_clamped(x, y);
        let same = (-reach..=reach)
            .all(|dy| (-reach..=reach).all(|dx| map.ground.get_clamped(x + dx, y + dy) == g));
        same.then(|| map.manifest.ground.legend[g as usize].color.map(f64::from))
    };
    // Mean colour of the 5 x 5 texels around `p` in the texture of the level's node there.
    let mean_at = |p: [f64; 2]| -> Option<[f64; 3]> {
        let key = tree.key_at(level, p[0], p[1])?;
        let r = tree.rect(key);
        let img = render(&gpu, &t, &world, &index, &tree, key);
        let ci = ((p[0] - r.min[0]) / tm).floor() as i64 + i64::from(BORDER);
        let cj = ((p[1] - r.min[1]) / tm).floor() as i64 + i64::from(BORDER);
        let mut sum = [0.0; 3];
        for dj in -2..=2 {
            for di in -2..=2 {
                let (i, j) = ((ci + di) as u32, (cj + dj) as u32);
                let px = texel(&img, i, j);
                for c in 0..3 {
                    sum[c] += f64::from(px[c]) / 25.0;
                }
            }
        }
        Some(sum)
    };
    let dist = |a: [f64; 3], b: [f64; 3]| {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    // How far `p` is from any decal's reach (negative: inside one).
    let clear_of_decals = |p: [f64; 2]| {
        decals.iter().all(|o| {
            let n = o.points.len();
            let segs = if o.closed { n } else { n - 1 };
            let reach = 0.5 * f64::from(o.width_m) + f64::from(o.falloff_m) + 2.0;
            !(o.closed && worldgen::roads::inside_polygon(p, &o.points))
                && (0..segs).all(|k| {
                    let (a, b) = (o.points[k], o.points[(k + 1) % n]);
                    worldgen::roads::point_segment_distance_m(p, [a[0], a[1]], [b[0], b[1]]) > reach
                })
        })
    };
    let mut checked = 0;
    let mut kinds = Vec::new();
    for d in decals.iter().filter(|d| d.closed) {
        let n = d.points.len() as f64;
        let c = [
            d.points.iter().map(|p| p[0]).sum::<f64>() / n,
            d.points.iter().map(|p| p[1]).sum::<f64>() / n,
        ];
        // The 5 x 5 block around the centre must lie inside the outline.
        let half_block = 2.5 * tm * std::f64::consts::SQRT_2;
        let inner = (0..d.points.len()).all(|k| {
            let (a, b) = (d.points[k], d.points[(k + 1) % d.points.len()]);
            worldgen::roads::point_segment_distance_m(c, [a[0], a[1]], [b[0], b[1]]) > half_block
        });
        if !worldgen::roads::inside_polygon(c, &d.points) || !inner {
            continue;
        }
        // Beyond the soft edge: past the farthest outline point plus the reach, plus 4 m.
        let rmax = d
            .points
            .iter()
            .map(|p| (p[0] - c[0]).hypot(p[1] - c[1]))
            .fold(0.0, f64::max);
        let out_r = rmax + 0.5 * f64::from(d.width_m) + f64::from(d.falloff_m) + 4.0;
        let out = (0..8).map(|k| {
            let a = std::f64::consts::TAU * f64::from(k) / 8.0;
            [c[0] + out_r * a.cos(), c[1] + out_r * a.sin()]
        });
        let size = world.size_m();
        let kind = kind_color(d.kind);
        // Outside, the ground must be one type all around (its texels then show that type
        // whatever the border noise) and that type must not look like the kind.
        let Some((out, ground_out)) = out
            .filter(|p| p[0] > 8.0 && p[1] > 8.0 && p[0] < size[0] - 8.0 && p[1] < size[1] - 8.0)
            .filter(|&p| clear_of_decals(p))
            .find_map(|p| {
                uniform_legend_at(p)
                    .filter(|g| dist(*g, kind) > 40.0)
                    .map(|g| (p, g))
            })
        else {
            continue;
        };
        let (Some(inside), Some(outside)) = (mean_at(c), mean_at(out)) else {
            continue;
        };
        assert!(
            dist(inside, kind) < dist(inside, legend_at(c)),
            "{:?} at {c:?}: texels {inside:?} are nearer the ground's {:?} than the kind's {kind:?}",
            d.kind,
            legend_at(c)
        );
        assert!(
            dist(outside, ground_out) < dist(outside, kind),
            "beyond the {:?} at {out:?}: texels {outside:?} look like the kind {kind:?}",
            d.kind
        );
        checked += 1;
        if !kinds.contains(&d.kind) {
            kinds.push(d.kind);
        }
    }
    assert!(checked >= 10, "only {checked} areas checked");
    assert_eq!(kinds.len(), 4, "only kinds {kinds:?} met");
}

/// The ground at a dry spot of the tiny map 12 m or more from every decal (on a 32 m lattice).
fn dry_spot(world: &engine::surface::World) -> DVec3 {
    let water = world.map.manifest.water_level_m;
    let spot = (1..16)
        .flat_map(|j| (1..16).map(move |i| [32.0 * f64::from(i), 32.0 * f64::from(j)]))
        .find(|&p| {
            world.height_m(p[0], p[1]) > water + 1.0
                && world.map.decals.iter().all(|d| {
                    d.points.windows(2).all(|s| {
                        let (dist, _) = worldgen::roads::segment_closest(
                            p,
                            [s[0][0], s[0][1]],
                            [s[1][0], s[1][1]],
                        );
                        dist > 12.0 + 0.5 * f64::from(d.width_m) + f64::from(d.falloff_m)
                    })
                })
        })
        .expect("a dry spot away from decals");
    DVec3::new(spot[0], spot[1], world.height_m(spot[0], spot[1]))
}

/// A close-up set-up on the tiny map: `image` as every ground type's material, a viewer without
/// plants, the ground at a [`dry_spot`] and a 128 x 128 target.
fn close_up(
    g: &engine::render::Gpu,
    mut world: engine::surface::World,
    image: worldgen::map::MaterialImage,
) -> (engine::viewer::Viewer, DVec3, Target) {
    world.map.materials = vec![Some(image); world.map.manifest.ground.legend.len()];
    let ground = dry_spot(&world);
    let mut v = tests::gpu::viewer(g, world, 1.0);
    v.view.plants = false;
    let target = Target::new(&g.device, [128, 128], engine::render::COLOR_FORMAT);
    (v, ground, target)
}

/// Close up the ground shows its material's own texels below the finest node texel. Every
/// ground type gets a material image of one-texel checks (7.8 mm at 512 texels over 4 m): the
/// node textures (3.3 cm texels at best) hold only the checks' grey mean, so the texture-only
/// view from 0.5 m is flat, while the lit view shows the checks as strong pixel contrast; from
/// 8 m (a pixel larger than the finest texel) the detail is gone again.
#[test]
fn close_up_the_ground_shows_the_material_below_the_finest_texel() {
    use engine::render::frame::GroundView;
    let Some(g) = device() else { return };
    let world = tiny_world();
    let side = engine::ground::materials::MATERIAL_TEXELS;
    let checks = worldgen::map::MaterialImage {
        side,
        rgba: (0..side * side)
            .map(|k| {
                if (k % side + k / side).is_multiple_of(2) {
                    [220, 220, 220, 255]
                } else {
                    [30, 30, 30, 255]
                }
            })
            .collect(),
    };
    let (mut v, ground, target) = close_up(&g, world, checks);
    let size = target.size;
    // Luma range (max - min) over the central 64 x 64 pixels of the view from `above` metres.
    let mut contrast = |above: f64, view: GroundView| {
        v.view.ground_view = view;
        let cam = Camera::look_at(
            ground + DVec3::new(0.0, 0.0, above),
            ground,
            40f64.to_radians(),
            size,
        );
        tests::gpu::settle(&g, &mut v, &target, &cam);
        let img = target.read_rgba(&g).expect("readback");
        let luma: Vec<f64> = (32..96)
            .flat_map(|y| (32..96).map(move |x| (y * size[0] as usize + x) * 4))
            .map(|k| {
                0.2126 * f64::from(img[k])
                    + 0.7152 * f64::from(img[k + 1])
                    + 0.0722 * f64::from(img[k + 2])
            })
            .collect();
        let lo = luma.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = luma.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        hi - lo
    };
    let texture_only = contrast(0.5, GroundView::TextureOnly);
    let close = contrast(0.5, GroundView::Shaded);
    let far = contrast(8.0, GroundView::Shaded);
    assert!(
        texture_only < 12.0,
        "the node texture should hold only the checks' mean: luma range {texture_only:.1}"
    );
    assert!(
        close > 80.0,
        "from 0.5 m the material's checks should show: luma range {close:.1}"
    );
    assert!(
        far < close / 3.0,
        "from 8 m the detail should be gone: luma range {far:.1} (close up {close:.1})"
    );
}

/// Close up, the material's detail height bends the ground's shading normal. Every ground type
/// gets a sawtooth image whose luminance (so its detail height, [`IMAGE_RELIEF_M`] over the
/// tooth) rises to the east over 15 of every 16 texel columns, or its mirror rising to the
/// west. From 0.5 m the ground under a sun in the west is brighter than under the same sun in
/// the east where the teeth face west, and darker where they face east; without the relief
/// both differences would be the terrain's own, equal for the two images.
#[test]
fn close_up_the_materials_relief_shades_the_ground() {
    use engine::ground::materials::{IMAGE_RELIEF_M, MATERIAL_TEXELS};
    use engine::lighting::grid::Sun;
    let Some(g) = device() else { return };
    let side = MATERIAL_TEXELS;
    // Mean luma (sRGB bytes) over the central 64 x 64 pixels from 0.5 m above, sun in the west
    // minus sun in the east, 40 degrees high; materials rising to the east or to the west.
    let difference = |rising_east: bool| {
        let world = tiny_world();
        let sawtooth = worldgen::map::MaterialImage {
            side,
            rgba: (0..side * side)
                .map(|k| {
                    let i = k % side % 16;
                    let step = if rising_east { i } else { 15 - i };
                    let l = (40 + 12 * step) as u8;
                    [l, l, l, 255]
                })
                .collect(),
        };
        let (mut v, ground, target) = close_up(&g, world, sawtooth);
        let size = target.size;
        let eye = ground + DVec3::new(0.0, 0.0, 0.5);
        let cam = Camera::look_at(eye, ground, 40f64.to_radians(), size);
        let mut mean = |azimuth_deg: f64| {
            let sun = Sun {
                azimuth_deg,
                elevation_deg: 40.0,
            };
            v.set_sun(sun, eye);
            tests::gpu::settle(&g, &mut v, &target, &cam);
            let img = target.read_rgba(&g).expect("readback");
            let sum: f64 = (32..96)
                .flat_map(|y| (32..96).map(move |x| (y * size[0] as usize + x) * 4))
                .map(|k| {
                    0.2126 * f64::from(img[k])
                        + 0.7152 * f64::from(img[k + 1])
                        + 0.0722 * f64::from(img[k + 2])
                })
                .sum();
            sum / 4096.0
        };
        let (west, east) = (mean(270.0), mean(90.0));
        west - east
    };
    let (facing_west, facing_east) = (difference(true), difference(false));
    // The teeth slope by IMAGE_RELIEF_M over 15 texels (~12 cm): 14 degrees at 3 cm, so the sun
    // meets them at 54 degrees from one side and 26 from the other.
    const { assert!(IMAGE_RELIEF_M >= 0.02) };
    assert!(
        facing_west > 8.0 && facing_east < -8.0,
        "teeth facing west should be brighter under a western sun and teeth facing east \
         darker: luma west - east {facing_west:.1} and {facing_east:.1}"
    );
}

/// The terrain renderer of [`a_node_without_its_own_texture_shows_its_ancestors`]: ground
/// textures in a pool of one page, so once the page is taken (coarsest nodes first) finer nodes
/// get no texture of their own.
fn one_page_terrain(
    gpu: &engine::render::Gpu,
    frame: &engine::render::frame::FrameResources,
    shared: &engine::stream::Shared,
) -> Box<dyn engine::render::scene::NodeRenderer> {
    let legend = engine::render::terrain::legend_srgb(&shared.world);
    Box::new(
        TerrainRenderer::new(gpu, frame, &legend).with_ground_textures(
            gpu,
            &shared.world,
            LAYERS_PER_PAGE as usize * LAYER_BYTES,
        ),
    )
}

/// A drawn node whose own ground texture is not made (queued, or here refused by a full pool)
/// shows its nearest resident ancestor's texture at the right place: in the texture-only view
/// the picture stays close to the one drawn with every node's own texture, much closer than
/// the legend colours the terrain had without textures, and no drawn node is left without one.
#[test]
fn a_node_without_its_own_texture_shows_its_ancestors() {
    use engine::render::frame::GroundView;
    use engine::render::{COLOR_FORMAT, Target};
    use engine::viewer::Viewer;
    let Some(g) = device() else { return };
    let world = tiny_world();
    let ground = dry_spot(&world);
    let eye = ground + DVec3::new(-40.0, -60.0, 45.0);
    let cam = Camera::look_at(eye, ground, 70f64.to_radians(), [480, 300]);
    let target = Target::new(&g.device, cam.viewport_px, COLOR_FORMAT);
    let settings = StreamSettings {
        workers: 1,
        tau_px: 0.3,
        ..StreamSettings::default()
    };
    // Texture-only pictures: every node's own texture, one page of textures, legend colours.
    let picture = |kinds: &[engine::kinds::Registration]| {
        let mut v = Viewer::with_kinds(&g, COLOR_FORMAT, world.clone(), settings, kinds);
        v.view.ground_view = GroundView::TextureOnly;
        v.view.plants = false;
        tests::gpu::settle(&g, &mut v, &target, &cam);
        let t = v
            .scene
            .renderer::<TerrainRenderer>()
            .expect("a terrain renderer");
        let counts = (t.borrowed_textures, t.untextured, t.ground_pool_use().0);
        (target.read_rgba(&g).expect("readback"), counts)
    };
    let all = engine::kinds::registered(&world);
    let one_page: Vec<_> = all
        .iter()
        .map(|r| engine::kinds::Registration {
            kind: r.kind.clone(),
            renderer: if r.kind.name() == "terrain" {
                Some(one_page_terrain as engine::kinds::RendererFactory)
            } else {
                r.renderer
            },
        })
        .collect();
    let legend: Vec<_> = all
        .iter()
        .filter(|r| r.kind.name() != engine::ground::content::GroundContent::NAME)
        .map(|r| engine::kinds::Registration {
            kind: r.kind.clone(),
            renderer: r.renderer,
        })
        .collect();
    let (own, (own_borrowed, _, own_layers)) = picture(&all);
    let (shared, (borrowed, bare, layers)) = picture(&one_page);
    let (colours, _) = picture(&legend);
    assert_eq!(
        own_borrowed, 0,
        "with room for every texture none is borrowed"
    );
    assert!(
        own_layers > LAYERS_PER_PAGE as usize,
        "the view needs more than one page of textures ({own_layers} layers)"
    );
    assert_eq!(layers, LAYERS_PER_PAGE as usize, "the small pool is full");
    assert!(
        borrowed >= 5,
        "only {borrowed} drawn nodes show an ancestor's texture"
    );
    assert_eq!(bare, 0, "drawn nodes with no texture at all: {bare}");
    let mean_difference = |a: &[u8], b: &[u8]| {
        a.chunks_exact(4)
            .zip(b.chunks_exact(4))
            .map(|(p, q)| (0..3).map(|c| f64::from(p[c].abs_diff(q[c]))).sum::<f64>() / 3.0)
            .sum::<f64>()
            / (a.len() / 4) as f64
    };
    let (to_shared, to_colours) = (
        mean_difference(&own, &shared),
        mean_difference(&own, &colours),
    );
    assert!(
        to_shared < 0.5 * to_colours,
        "ancestors' textures differ from the nodes' own by {to_shared:.2} / 255 on average, \
         the legend colours by {to_colours:.2}"
    );
}

/// The CPU's perturbed ground cell, which resolves the node textures' types
/// (`engine::ground::types`), is the prelude's, which the terrain's detail near the camera
/// evaluates on the GPU: on 16,384 positions at fine and coarse spacings over a 32 km map's
/// cells, the software adapter gives the same cell but for at most one position in a thousand,
/// and those one cell apart (where the two round an f32 operation differently).
#[test]
fn the_cpu_perturbation_is_the_shaders() {
    use engine::ground::types::perturbed_ground_cell;
    use wgpu::util::DeviceExt;
    let Some(gpu) = device() else { return };
    let points: Vec<[f32; 2]> = (0..16_384u32)
        .map(|k| {
            let step = if k < 8192 { 0.0371 } else { 3.17 };
            let i = (k % 8192) as f32;
            [
                (i % 128.0) * step + 11.3,
                (i / 128.0).floor() * step * 1.7 + 8000.0 * (k / 8192) as f32,
            ]
        })
        .collect();
    let source = format!(
        "{}\n{}",
        engine::render::shader::assemble("prelude alone", ""),
        "@group(3) @binding(0) var<storage, read> points: array<vec2<f32>>;
@group(3) @binding(1) var<storage, read_write> cells: array<vec2<i32>>;
@compute @workgroup_size(64)
fn cs_cells(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x < arrayLength(&points)) {
        cells[id.x] = perturbed_ground_cell(points[id.x]);
    }
}"
    );
    let device = &gpu.device;
    let module = engine::render::shader::module(device, "perturbation test", &source);
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: None,
        layout: None,
        module: &module,
        entry_point: Some("cs_cells"),
        compilation_options: wgpu::PipelineCompilationOptions::default(),
        cache: None,
    });
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(&points),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let bytes = (points.len() * 8) as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(3),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: output.as_entire_binding(),
            },
        ],
    });
    let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(3, &group, &[]);
        pass.dispatch_workgroups(points.len().div_ceil(64) as u32, 1, 1);
    }
    enc.copy_buffer_to_buffer(&output, 0, &readback, 0, bytes);
    gpu.queue.submit([enc.finish()]);
    let slice = readback.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    rx.recv().expect("map").expect("map");
    let gpu_cells: Vec<[i32; 2]> =
        bytemuck::cast_slice(&slice.get_mapped_range().expect("mapped")).to_vec();
    let mut differ = 0;
    for (p, g) in points.iter().zip(&gpu_cells) {
        let c = perturbed_ground_cell(*p);
        if c != *g {
            differ += 1;
            assert!(
                (0..2).all(|a| c[a] == g[a] || (c[a] - g[a]).abs() == 1),
                "{p:?}: CPU {c:?}, GPU {g:?}"
            );
        }
    }
    assert!(
        differ * 1000 <= points.len(),
        "{differ} of {} positions differ",
        points.len()
    );
}
