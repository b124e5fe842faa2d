//! Towns: houses stand clear of roads, water and each other, on ground flattened
//! under their footprint, with nothing growing inside; their meshes fill their footprints; bad
//! building rows, meshes and textures are refused naming the file, line and field.
//!
//! The geometry checks here sample footprints on a 0.25 m lattice and measure with plain
//! point-segment distances, not with worldgen's polygon distances that placed the houses.

use engine::objects::set::{ObjectSet, model_to_world};
use engine::surface::world::{Rect, World};
use engine::vegetation::Placer;
use glam::DVec3;
use tests::terrain::{patches_world, tiny_world};
use worldgen::map::{Building, DecalKind, Map};
use worldgen::roads::segment_closest;

/// Points of a footprint on a lattice of `step_m` (edges and corners included), world metres.
fn footprint_points(b: &Building, step_m: f64) -> Vec<[f64; 2]> {
    let (s, c) = b.yaw_deg.to_radians().sin_cos();
    let (w, d) = (b.spec.width_m, b.spec.depth_m);
    let (nu, nv) = ((w / step_m).ceil() as usize, (d / step_m).ceil() as usize);
    let mut out = Vec::new();
    for i in 0..=nu {
        for j in 0..=nv {
            let u = -w / 2.0 + w * i as f64 / nu as f64;
            let v = -d / 2.0 + d * j as f64 / nv as f64;
            out.push([b.x_m + c * u - s * v, b.y_m + s * u + c * v]);
        }
    }
    out
}

/// Whether a world point is inside a footprint (in the house's own frame).
fn inside(b: &Building, p: [f64; 2]) -> bool {
    let (s, c) = b.yaw_deg.to_radians().sin_cos();
    let (dx, dy) = (p[0] - b.x_m, p[1] - b.y_m);
    let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
    u.abs() <= b.spec.width_m / 2.0 && v.abs() <= b.spec.depth_m / 2.0
}

fn check_layout(name: &str, map: &Map) {
    let houses = &map.buildings;
    assert!(!houses.is_empty(), "{name}: no houses");
    let water = map.manifest.water_level_m;
    let mut closest_road = f64::INFINITY;
    for (i, b) in houses.iter().enumerate() {
        let points = footprint_points(b, 0.25);
        for d in &map.decals {
            if !matches!(d.kind, DecalKind::Road | DecalKind::Path) {
                continue;
            }
            let half = f64::from(d.width_m) / 2.0;
            for w in d.points.windows(2) {
                let (a, e) = ([w[0][0], w[0][1]], [w[1][0], w[1][1]]);
                for p in &points {
                    let clear = segment_closest(*p, a, e).0 - half;
                    closest_road = closest_road.min(clear);
                    assert!(
                        clear > 0.0,
                        "{name}: house {i} at ({}, {}) is on a {:?}",
                        b.x_m,
                        b.y_m,
                        d.kind
                    );
                }
                // A road crossing the footprint between lattice points has a vertex inside or
                // passes a lattice point within 0.25 m: covered above; its vertices too.
                assert!(
                    !inside(b, a) && !inside(b, e),
                    "{name}: road vertex in house {i}"
                );
            }
        }
        for p in &points {
            let g = map.height_bicubic_m(p[0], p[1]);
            assert!(
                g > water,
                "{name}: house {i} stands in water at {p:?} ({g} m)"
            );
        }
        for (j, o) in houses.iter().enumerate().skip(i + 1) {
            assert!(
                !points.iter().any(|p| inside(o, *p))
                    && !footprint_points(o, 0.25).iter().any(|p| inside(b, *p)),
                "{name}: houses {i} and {j} overlap"
            );
        }
        for t in &map.trees {
            let crown = f64::from(t.crown_radius_m);
            let near = points
                .iter()
                .map(|p| (p[0] - t.x_m).hypot(p[1] - t.y_m))
                .fold(f64::INFINITY, f64::min);
            assert!(
                near > crown,
                "{name}: a tree's crown ({crown} m) reaches house {i} ({near} m from its trunk)"
            );
        }
    }
    println!(
        "{name}: {} houses of {} types; the closest comes {closest_road:.2} m from a road's edge",
        houses.len(),
        map.building_models.len()
    );
}

#[test]
fn houses_keep_clear_of_roads_water_trees_and_each_other() {
    check_layout("tiny", &tiny_world().map);
    check_layout("2 km", &patches_world().map);
}

/// The finest surface under every footprint is flat (within 2 cm) at the house's floor
/// height, and no vegetation item stands inside a footprint.
#[test]
fn ground_is_flat_and_bare_under_houses() {
    const FLAT_M: f64 = 0.02;
    let world: World = tiny_world();
    let placer = Placer::new(&world);
    let (mut worst, mut items_near) = (0.0f64, 0usize);
    for (i, b) in world.map.buildings.iter().enumerate() {
        let points = footprint_points(b, 0.25);
        for p in &points {
            let z = world.height_m(p[0], p[1]);
            worst = worst.max((z - b.z_m).abs());
            assert!(
                (z - b.z_m).abs() <= FLAT_M,
                "house {i}: ground {z} m at {p:?}, floor {} m",
                b.z_m
            );
        }
        let (lo, hi) = points.iter().fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1])],
                    [hi[0].max(p[0]), hi[1].max(p[1])],
                )
            },
        );
        // Around the house too, so the check sees items that do grow nearby.
        let area = Rect {
            min: [lo[0] - 8.0, lo[1] - 8.0],
            max: [hi[0] + 8.0, hi[1] + 8.0],
        };
        for s in 0..placer.species.len() {
            let mut items = Vec::new();
            placer.place(&world, s, area, 1.0, &mut items);
            for it in &items {
                assert!(
                    !inside(b, [it.x_m, it.y_m]),
                    "house {i}: species {s} grows inside at ({}, {})",
                    it.x_m,
                    it.y_m
                );
                items_near += 1;
            }
        }
    }
    println!(
        "{} houses: ground within {worst:.4} m of the floor; {items_near} vegetation items within 8 m, none inside",
        world.map.buildings.len()
    );
    assert!(
        items_near > 0,
        "no vegetation near any house: the check saw nothing"
    );
}

/// Each instance's mesh covers its footprint: every vertex inside it (2 cm), the walls reaching
/// all four sides, the base on the floor height.
#[test]
fn house_meshes_fill_their_footprints() {
    let world = tiny_world();
    let set = ObjectSet::from_buildings(
        &world.map.buildings,
        &world.map.building_models,
        &world.map.building_textures,
    );
    assert_eq!(set.instances.len(), world.map.buildings.len());
    for (inst, b) in set.instances.iter().zip(&world.map.buildings) {
        let model = &set.models[inst.model as usize];
        let (s, c) = b.yaw_deg.to_radians().sin_cos();
        let (mut ulo, mut uhi, mut vlo, mut vhi, mut zlo) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
        );
        for p in &model.pm.positions {
            let w = model_to_world(DVec3::from(p.map(f64::from)), inst, model);
            let (dx, dy) = (w.x - b.x_m, w.y - b.y_m);
            let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
            ulo = ulo.min(u);
            uhi = uhi.max(u);
            vlo = vlo.min(v);
            vhi = vhi.max(v);
            zlo = zlo.min(w.z);
        }
        let (hw, hd) = (b.spec.width_m / 2.0, b.spec.depth_m / 2.0);
        for (got, want) in [(-ulo, hw), (uhi, hw), (-vlo, hd), (vhi, hd)] {
            assert!(
                (got - want).abs() <= 0.02,
                "{}: extent {got} m, footprint {want} m",
                b.type_name
            );
        }
        assert!(
            (zlo - b.z_m).abs() <= 1e-3,
            "{}: base {zlo} m, floor {} m",
            b.type_name,
            b.z_m
        );
    }
}

/// Copies the tiny map, edits `buildings.csv` (or a mesh) and expects `Map::load` to refuse it
/// with a message containing every `needles` entry.
fn refused(edit: impl FnOnce(&std::path::Path), needles: &[&str]) {
    let tmp = tempfile::tempdir().expect("temp dir");
    tests::copy_dir(&tests::tiny_map_dir(), tmp.path());
    edit(tmp.path());
    let err = Map::load(tmp.path()).expect_err("a bad building list must be refused");
    let msg = err.to_string();
    for n in needles {
        assert!(msg.contains(n), "{msg:?} lacks {n:?}");
    }
}

fn edit_row(dir: &std::path::Path, column: usize, value: &str) {
    let path = dir.join("buildings.csv");
    let text = std::fs::read_to_string(&path).expect("read");
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut cols: Vec<String> = lines[2].split(',').map(String::from).collect();
    cols[column] = value.to_string();
    lines[2] = cols.join(",");
    std::fs::write(&path, lines.join("\n") + "\n").expect("write");
}

#[test]
fn malformed_building_rows_and_meshes_are_refused() {
    refused(
        |d| edit_row(d, 9, "mansard"),
        &["buildings.csv", "line 3", "roof", "mansard"],
    );
    refused(
        |d| edit_row(d, 2, "NaN"),
        &["buildings.csv", "line 3", "y_m"],
    );
    refused(
        |d| edit_row(d, 1, "-50"),
        &["buildings.csv", "line 3", "outside the world"],
    );
    refused(
        |d| edit_row(d, 7, "0"),
        &["buildings.csv", "line 3", "storeys"],
    );
    refused(
        |d| edit_row(d, 11, "xyz"),
        &["buildings.csv", "line 3", "seed"],
    );
    refused(
        |d| edit_row(d, 0, "bad name"),
        &["buildings.csv", "line 3", "type"],
    );
    // Depth above width.
    refused(
        |d| edit_row(d, 6, "12.9"),
        &["buildings.csv", "line 3", "width_m"],
    );
    // One row of a type with other dimensions than the type's other rows.
    refused(
        |d| {
            let path = d.join("buildings.csv");
            let text = std::fs::read_to_string(&path).expect("read");
            let first = text.lines().nth(2).expect("a row").to_string();
            let mut cols: Vec<&str> = first.split(',').collect();
            cols[1] = "300";
            cols[2] = "300";
            cols[10] = "44";
            std::fs::write(&path, format!("{text}{}\n", cols.join(","))).expect("write");
        },
        &["buildings.csv", "line 22", "type \"house_5\"", "line 3"],
    );
    refused(
        |d| {
            let path = d.join("buildings.csv");
            let text = std::fs::read_to_string(&path).expect("read");
            let mut lines: Vec<&str> = text.lines().collect();
            lines.truncate(3);
            let short = lines[2].rsplit_once(',').expect("columns").0.to_string();
            std::fs::write(&path, format!("{}\n{}\n{short}\n", lines[0], lines[1])).expect("write");
        },
        &["buildings.csv", "line 3", "missing column `roof_texture`"],
    );
    refused(
        |d| edit_row(d, 12, "../map.toml"),
        &["buildings.csv", "line 3", "facade_texture"],
    );
    refused(
        |d| edit_row(d, 13, "roof.jpg"),
        &["buildings.csv", "line 3", "roof_texture"],
    );
    // A texture file missing, or not a power-of-two square or mip atlas.
    refused(
        |d| std::fs::remove_file(d.join("buildings/roof_1.png")).expect("remove"),
        &["buildings/roof_1.png", "cannot open"],
    );
    refused(
        |d| {
            let f = std::fs::File::create(d.join("buildings/roof_1.png")).expect("create");
            let mut enc = png::Encoder::new(f, 300, 200);
            enc.set_color(png::ColorType::Rgba);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().expect("header");
            w.write_image_data(&vec![128u8; 300 * 200 * 4])
                .expect("pixels");
        },
        &["buildings/roof_1.png", "300x200", "power-of-two"],
    );
    // A version 1 list with rows.
    refused(
        |d| {
            std::fs::write(
                d.join("buildings.csv"),
                "tvs-buildings 1\nmesh,x_m,y_m,z_m,yaw_deg,scale\nhouse.pm,10,10,0,0,1\n",
            )
            .expect("write");
        },
        &["buildings.csv", "line 3", "version 1"],
    );
    // A missing mesh, a corrupt one, and one of another type (stale after an edit).
    refused(
        |d| std::fs::remove_file(d.join("buildings/house_5.pm")).expect("remove"),
        &["buildings/house_5.pm"],
    );
    refused(
        |d| {
            let p = d.join("buildings/house_5.pm");
            let mut bytes = std::fs::read(&p).expect("read");
            let mid = bytes.len() / 2;
            bytes[mid] ^= 0x55;
            std::fs::write(&p, bytes).expect("write");
        },
        &["buildings/house_5.pm"],
    );
    refused(
        |d| {
            std::fs::copy(
                d.join("buildings/house_4.pm"),
                d.join("buildings/house_5.pm"),
            )
            .expect("copy");
        },
        &["buildings/house_5.pm", "house type house_5", "width_m"],
    );
}

/// The tiny map's town through the viewer (320 x 180): houses are drawn with their textures
/// from the texture cache (every drawn texture resident after settling, at least 4x fewer
/// bytes than at full resolution from 70 m), and the "colour by mip level" view turns the
/// houses' pixels into strong tints; with objects off in the view they are not drawn.
#[test]
fn houses_draw_their_textures_from_the_cache() {
    use engine::render::{COLOR_FORMAT, Target};
    use tests::gpu::{device, settle, tiny_viewer};
    let Some(g) = device() else { return };
    let eye = DVec3::new(190.0, 215.0, 100.0);
    let cam = engine::camera::Camera::look_at(
        eye,
        DVec3::new(243.0, 262.0, 71.0),
        60f64.to_radians(),
        [320, 180],
    );
    let target = Target::new(&g.device, cam.viewport_px, COLOR_FORMAT);
    let mut v = tiny_viewer(&g, 1.0);
    let st = settle(&g, &mut v, &target, &cam);
    let shaded = target.read_rgba(&g).expect("pixels");
    assert!(st.object_items >= 5, "{st:?}");
    assert!(st.texture_full_bytes > 0, "no textured house drawn");
    assert_eq!(
        st.texture_misses, 0,
        "a drawn texture is not resident after settling"
    );
    let saving = st.texture_full_bytes as f64 / st.texture_resident_bytes as f64;
    println!(
        "town from 70 m: {} houses, {} KiB resident of {} KiB at full resolution ({saving:.1}x)",
        st.object_items,
        st.texture_resident_bytes >> 10,
        st.texture_full_bytes >> 10
    );
    assert!(saving >= 4.0, "only {saving:.1}x saved");
    v.view.texture_mip_view = true;
    let st2 = settle(&g, &mut v, &target, &cam);
    assert_eq!(st2.object_items, st.object_items);
    let tinted = target.read_rgba(&g).expect("pixels");
    let mut house_pixels = 0;
    let mut saturated = 0;
    for (a, b) in shaded.chunks(4).zip(tinted.chunks(4)) {
        if a[..3] != b[..3] {
            house_pixels += 1;
            let (hi, lo) = (b[..3].iter().max().unwrap(), b[..3].iter().min().unwrap());
            saturated += usize::from(hi - lo > 60);
        }
    }
    println!("{house_pixels} pixels tinted, {saturated} of them strongly coloured");
    assert!(
        house_pixels > 300,
        "only {house_pixels} pixels changed in the mip view"
    );
    assert!(saturated * 2 > house_pixels, "the mip tint is not visible");
    // With objects off (the GPU reference's runs) the houses are gone: no draws, and the
    // pixels that were houses show what is behind them.
    v.view.texture_mip_view = false;
    v.view.objects = false;
    let st3 = settle(&g, &mut v, &target, &cam);
    assert_eq!((st3.object_items, st3.object_draw_calls), (0, 0), "{st3:?}");
    let bare = target.read_rgba(&g).expect("pixels");
    let changed = shaded
        .chunks(4)
        .zip(bare.chunks(4))
        .filter(|(a, b)| a[..3] != b[..3])
        .count();
    assert!(
        changed > 300,
        "only {changed} pixels changed without the houses"
    );
}

/// A wide node's merged far mesh (HLOD) of the tiny map's houses stays within its error budget
/// of the houses at full detail (two-sided Hausdorff bound measured by worldgen's sampling,
/// not by the levels' stored errors) with far fewer triangles.
#[test]
fn merged_far_meshes_stay_within_their_budget() {
    use engine::objects::hlod;
    use worldgen::pm::measure::hausdorff_bound;
    let world = tiny_world();
    let set = ObjectSet::from_buildings(
        &world.map.buildings,
        &world.map.building_models,
        &world.map.building_textures,
    );
    let means = engine::objects::texturing::mean_colors(&set);
    for side_m in [128.0, 256.0, 512.0] {
        let budget = hlod::error_budget_m(side_m);
        // The town of the first house.
        let first = set.instances[0].position_m;
        let ids: Vec<u32> = (0..set.instances.len() as u32)
            .filter(|&i| (set.instances[i as usize].position_m - first).length() < 80.0)
            .collect();
        let h = hlod::build(&set, &ids, [0.0, 0.0], budget, &means).expect("houses");
        let merged: Vec<[glam::DVec3; 3]> = h
            .vertices
            .chunks_exact(3)
            .map(|t| [0, 1, 2].map(|k| h.origin_m + glam::Vec3::from_slice(&t[k][..3]).as_dvec3()))
            .collect();
        let full: Vec<[glam::DVec3; 3]> = ids
            .iter()
            .map(|&i| &set.instances[i as usize])
            .flat_map(|inst| {
                let model = &set.models[inst.model as usize];
                let pm = &model.pm;
                pm.triangles
                    .iter()
                    .map(move |t| {
                        t.map(|w| {
                            let q = pm.positions[pm.wedge_position[w as usize] as usize];
                            model_to_world(DVec3::from(q.map(f64::from)), inst, model)
                        })
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        let spacing = 0.1;
        let d = hausdorff_bound(&full, &merged, spacing);
        println!(
            "{side_m} m node: {} of {} triangles, Hausdorff bound {d:.3} m, budget {budget} m",
            merged.len(),
            h.full_triangles
        );
        // The bound adds the samples' covering radius (under the spacing) to the true distance.
        assert!(d <= budget + spacing, "{d} m over the budget {budget} m");
        assert!(
            merged.len() * 4 < h.full_triangles,
            "{} triangles",
            merged.len()
        );
    }
}

/// From far away the tiny map's houses are drawn as their nodes' merged far meshes (HLOD):
/// fewer items (houses and far meshes) than with every house on its own, and the same picture up to the metric's
/// threshold along the houses' outlines (the frames' mean channel difference is small; the
/// merged meshes take the textures' mean colours).
#[test]
fn far_houses_draw_as_merged_meshes() {
    use engine::render::{COLOR_FORMAT, Target};
    use tests::gpu::{device, settle};
    let Some(g) = device() else { return };
    let town = DVec3::new(240.0, 260.0, 72.0);
    // About 1 km away: the far meshes' 4 m budget times K (371 px here) and the screen's
    // stretch of their boxes passes 2 px from about 800 m.
    let eye = town + DVec3::new(-780.0, -570.0, 330.0);
    let cam = engine::camera::Camera::look_at(eye, town, 40f64.to_radians(), [480, 270]);
    let target = Target::new(&g.device, cam.viewport_px, COLOR_FORMAT);
    let mut v = tests::gpu::viewer(&g, tiny_world(), 2.0);
    let merged = settle(&g, &mut v, &target, &cam);
    let a = target.read_rgba(&g).expect("pixels");
    v.view.hlod = false;
    let single = settle(&g, &mut v, &target, &cam);
    let b = target.read_rgba(&g).expect("pixels");
    let diff: u64 = a
        .chunks(4)
        .zip(b.chunks(4))
        .map(|(p, q)| (0..3).map(|c| u64::from(p[c].abs_diff(q[c]))).sum::<u64>())
        .sum();
    let mean = diff as f64 / (a.len() / 4 * 3) as f64;
    println!(
        "far town: merged {} items ({} HLOD), {} triangles; single {} items, {} triangles; mean difference {mean:.3} / 255",
        merged.object_items,
        merged.object_hlod_draws,
        merged.object_triangles,
        single.object_items,
        single.object_triangles
    );
    assert!(merged.object_hlod_draws > 0, "{merged:?}");
    assert_eq!(single.object_hlod_draws, 0);
    assert!(merged.object_items < single.object_items);
    assert!(mean < 1.0, "mean channel difference {mean} / 255");
}

/// Merged house draws (index lists, geomorph targets and far meshes in pooled pages, per-draw
/// data indexed by instance, one multi-draw per texture pair and page) draw exactly the pixels
/// of per-item draws (one draw call per house and per far mesh, the fallback path): the town
/// from 70 m with its textures resident, the same while houses geomorph after the camera
/// moved, and from far away with merged far meshes among single houses. And they merge: one
/// draw call per texture pair, not per house.
#[test]
fn merged_house_draws_draw_exactly_the_pixels_of_per_item_draws() {
    use engine::render::objects::ObjectsRenderer;
    use engine::render::{COLOR_FORMAT, Target};
    use tests::gpu::{frame, settle};
    let Some(g) = tests::gpu::multi_draw_device("merged house draws") else {
        return;
    };
    let town = DVec3::new(243.0, 262.0, 71.0);
    let size = [320u32, 180];
    let near = engine::camera::Camera::look_at(
        DVec3::new(190.0, 215.0, 100.0),
        town,
        60f64.to_radians(),
        size,
    );
    let back = engine::camera::Camera::look_at(
        DVec3::new(160.0, 180.0, 115.0),
        town,
        60f64.to_radians(),
        size,
    );
    let far = engine::camera::Camera::look_at(
        town + DVec3::new(-520.0, -380.0, 220.0),
        town,
        40f64.to_radians(),
        size,
    );
    let target = Target::new(&g.device, size, COLOR_FORMAT);
    let mut v = tests::gpu::viewer(&g, tiny_world(), 2.0);
    // Both ways from the same state: dt 0 (no fade or geomorph advances), after frames at dt 0
    // until nothing streams in, no light grid is being made and the texture cache uploads
    // nothing (two such frames in a row).
    let compare = |v: &mut engine::viewer::Viewer, cam: &engine::camera::Camera, what: &str| {
        let mut quiet = 0;
        for _ in 0..2_000 {
            if let Some(l) = v.lighting() {
                l.wait_idle();
            }
            let st = frame(&g, v, &target, cam, 0.0);
            let idle =
                v.streamer.in_flight() == 0 && v.textures_pending() == 0 && st.texture_uploads == 0;
            quiet = if idle { quiet + 1 } else { 0 };
            if quiet == 2 {
                break;
            }
        }
        assert_eq!(quiet, 2, "{what}: the view does not come to rest");
        let mut images = Vec::new();
        for merged in [true, false] {
            v.view.merged_draws = merged;
            let st = frame(&g, v, &target, cam, 0.0);
            images.push(target.read_rgba(&g).expect("readback"));
            println!(
                "{what}, merged {merged}: {} draw calls for {} houses and far meshes ({} far)",
                st.object_draw_calls, st.object_items, st.object_hlod_draws
            );
            assert!(st.object_items >= 5, "{what}: {st:?}");
            if merged {
                // One multi-draw per key: the tiny map's houses use 7 facade-and-roof pairs,
                // and the far meshes fit one page.
                assert!(
                    st.object_draw_calls < st.object_items && st.object_draw_calls <= 8,
                    "{what}: {} calls for {} items",
                    st.object_draw_calls,
                    st.object_items
                );
            } else {
                assert_eq!(st.object_draw_calls, st.object_items, "{what}");
            }
            v.view.merged_draws = true;
        }
        let differ = images[0]
            .chunks(4)
            .zip(images[1].chunks(4))
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(differ, 0, "{what}: {differ} pixels differ");
    };
    settle(&g, &mut v, &target, &near);
    compare(&mut v, &near, "town from 70 m");
    // Geomorphs: moving back coarsens houses over a second.
    v.view.pm_lod.morph_s = 1.0;
    let mut morphing = 0;
    for _ in 0..200 {
        frame(&g, &mut v, &target, &back, 0.05);
        let r = v.scene.renderer::<ObjectsRenderer>().expect("objects");
        morphing = r
            .morphs()
            .iter()
            .filter(|&&(_, t)| t > 0.1 && t < 0.9)
            .count();
        if morphing > 0 {
            break;
        }
    }
    assert!(
        morphing > 0,
        "no house geomorphs after the camera moved back"
    );
    compare(&mut v, &back, "mid-geomorph");
    v.view.pm_lod.morph_s = 0.0;
    settle(&g, &mut v, &target, &far);
    let st = frame(&g, &mut v, &target, &far, 0.0);
    assert!(st.object_hlod_draws > 0, "no merged far mesh: {st:?}");
    compare(&mut v, &far, "far town");
}
