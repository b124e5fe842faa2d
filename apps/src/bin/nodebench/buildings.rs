//! Section `buildings`: town generation time per step; houses per node; house
//! triangles per frame at tau 2 against the same houses and all houses at full detail; the
//! texture cache's resident bytes against the drawn textures at full resolution, its misses and
//! its levels coarser than needed per frame. Frames come from the benchmark flight and from
//! orbits of the map's largest town at 20, 100, 400 and 1600 m (a fresh cache each); the
//! image error of the chosen levels on frames drawn from those orbits.

use crate::report::{Report, bar};
use engine::camera::Camera;
use engine::objects::lod::{PmLodSettings, choose, on_screen};
use engine::objects::set::ObjectSet;
use engine::objects::texturing;
use engine::surface::World;
use engine::terrain::quadtree::QuadTree;
use engine::terrain::screen_bound::ScreenBound;
use engine::texcache::pool::{PoolSettings, TexturePool};
use glam::DVec3;
use std::time::Instant;

/// Threshold of the triangle rows, pixels.
const TAU_PX: f64 = 2.0;

pub(crate) fn section_buildings(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
) {
    generation(r, quick);
    let map = &world.map;
    if map.buildings.is_empty() {
        r.add(
            "buildings",
            "houses on the map",
            0.0,
            "houses",
            "nothing more to measure",
        );
        return;
    }
    let t = Instant::now();
    let set =
        ObjectSet::from_buildings(&map.buildings, &map.building_models, &map.building_textures);
    r.add(
        "buildings",
        "house models and instances made at load",
        t.elapsed().as_secs_f64() * 1e3,
        "ms",
        &format!(
            "{} houses of {} types, {} textures",
            set.instances.len(),
            set.models.len(),
            set.textures.len()
        ),
    );
    per_node(world, tree, cams, &set, r);
    let viewport = cams[0].viewport_px;
    frames_rows(&set, cams, "benchmark flight", r);
    let mut orbits = Vec::new();
    for distance_m in [20.0, 100.0, 400.0, 1600.0] {
        let orbit = town_orbit(
            world,
            &set,
            viewport,
            distance_m,
            if quick { 4 } else { 16 },
        );
        frames_rows(&set, &orbit, &format!("town orbit at {distance_m} m"), r);
        // Every fourth camera of the orbit (quick: the first).
        let drawn = orbit.iter().step_by(4).take(if quick { 1 } else { 4 });
        orbits.push((distance_m, drawn.copied().collect::<Vec<_>>()));
    }
    crate::house_image::house_image_rows(world, &orbits, TAU_PX, r);
}

/// Times the town steps of generating a map (512 m with `quick`, else 2 km; seed 11).
fn generation(r: &mut Report, quick: bool) {
    let size_m = if quick { 512.0 } else { 2048.0 };
    let p = worldgen::generate::GenerateParams {
        name: "bench".into(),
        seed: 11,
        size_m,
        ..worldgen::generate::GenerateParams::default()
    };
    let mut times = Vec::new();
    let Ok(map) = worldgen::generate::generate(&p, &worldgen::progress::Silent, &mut times) else {
        return;
    };
    let params = format!(
        "{size_m} m map, seed 11: {} houses of {} types, {} textures",
        map.buildings.len(),
        map.building_models.len(),
        map.building_textures.len()
    );
    for t in times.iter().filter(|t| t.step.contains("house")) {
        r.add(
            "buildings",
            &format!("generation: {}", t.step),
            t.duration_s * 1e3,
            "ms",
            &params,
        );
    }
}

/// Houses per node over the nodes the flight selects at tau 2 (those holding any).
fn per_node(world: &World, tree: &QuadTree, cams: &[Camera], set: &ObjectSet, r: &mut Report) {
    let keys = crate::terrain::flight_nodes(world, tree, cams, usize::MAX);
    let counts: Vec<usize> = keys
        .iter()
        .map(|&k| {
            let rect = tree.rect(k);
            set.instances
                .iter()
                .filter(|i| rect.contains(i.position_m.x, i.position_m.y))
                .count()
        })
        .filter(|&n| n > 0)
        .collect();
    let params = format!(
        "{} of the {} nodes the benchmark flight selects at tau 2 hold houses",
        counts.len(),
        keys.len()
    );
    let mean = counts.iter().sum::<usize>() as f64 / counts.len().max(1) as f64;
    r.add(
        "buildings",
        "houses per node (mean)",
        mean,
        "houses",
        &params,
    );
    let max = counts.iter().copied().max().unwrap_or(0);
    r.add(
        "buildings",
        "houses per node (max)",
        max as f64,
        "houses",
        &params,
    );
}

/// Cameras circling the largest town (the house with the most houses within 200 m) at
/// `distance_m`, looking at it from about 27 degrees above the horizon.
fn town_orbit(
    world: &World,
    set: &ObjectSet,
    viewport: [u32; 2],
    distance_m: f64,
    azimuths: usize,
) -> Vec<Camera> {
    let centre = set
        .instances
        .iter()
        .max_by_key(|a| {
            set.instances
                .iter()
                .filter(|b| (a.position_m - b.position_m).truncate().length() < 200.0)
                .count()
        })
        .map_or(DVec3::ZERO, |i| i.position_m);
    (0..azimuths)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / azimuths as f64;
            let (s, c) = a.sin_cos();
            let mut eye = centre + DVec3::new(c * distance_m, s * distance_m, 0.0);
            eye.z = (centre.z + distance_m * 0.5).max(world.height_m(eye.x, eye.y) + 2.0);
            Camera::look_at(eye, centre, 60f64.to_radians(), viewport)
        })
        .collect()
}

/// Per frame: house triangles at tau 2 against full detail, and the texture cache run over the
/// frames in order.
fn frames_rows(set: &ObjectSet, cams: &[Camera], name: &str, r: &mut Report) {
    let settings = PmLodSettings::default();
    let units: Vec<[f64; 2]> = set
        .models
        .iter()
        .map(texturing::units_per_texture)
        .collect();
    let mut pool = TexturePool::new(PoolSettings::default());
    texturing::register(&mut pool, set);
    let all_full: u64 = set
        .instances
        .iter()
        .map(|i| set.models[i.model as usize].pm.triangles.len() as u64)
        .sum();
    let (mut drawn, mut full, mut visible) = (0u64, 0u64, 0usize);
    let (mut resident, mut full_bytes, mut misses, mut coarser) = (0u64, 0u64, 0usize, 0usize);
    let (mut max_misses, mut textured_frames) = (0usize, 0usize);
    let b = bar(cams.len() as u64, &format!("buildings: {name}"));
    for cam in cams {
        let frustum = cam.frustum();
        let screen = ScreenBound::new(cam);
        for (id, inst) in set.instances.iter().enumerate() {
            let (c, rad) = set.sphere(inst);
            if !frustum.intersects_aabb(c - DVec3::splat(rad), c + DVec3::splat(rad)) {
                continue;
            }
            let model = &set.models[inst.model as usize];
            let (distance_m, k_px) = on_screen(&screen, c, rad);
            let choice = choose(model, &settings, TAU_PX, distance_m, k_px, inst.scale);
            let pm = &model.option(choice.option).pm;
            drawn += pm
                .levels
                .get(choice.level.max(1) - 1)
                .map_or(0, |l| u64::from(l.triangles));
            full += model.pm.triangles.len() as u64;
            visible += 1;
            texturing::request_instance(&mut pool, set, &units, cam, id as u32, (c, rad));
        }
        pool.end_frame();
        let s = pool.stats();
        if s.drawn > 0 {
            textured_frames += 1;
            resident += s.resident_bytes;
            full_bytes += s.full_resolution_bytes;
            misses += s.misses;
            max_misses = max_misses.max(s.misses);
            coarser += s.coarser_than_needed;
        }
        b.inc(1);
    }
    b.finish_and_clear();
    let frames = cams.len().max(1) as f64;
    let params = format!(
        "{name}: {} frames {}x{}, tau {TAU_PX} px, {:.1} houses in view per frame",
        cams.len(),
        cams[0].viewport_px[0],
        cams[0].viewport_px[1],
        visible as f64 / frames
    );
    r.add(
        "buildings",
        "house triangles per frame",
        drawn as f64 / frames,
        "triangles",
        &params,
    );
    r.add(
        "buildings",
        "the same houses at full detail",
        full as f64 / frames,
        "triangles",
        &params,
    );
    r.add(
        "buildings",
        "every house at full detail",
        all_full as f64,
        "triangles",
        &params,
    );
    let tf = textured_frames.max(1) as f64;
    let tparams = format!(
        "{params}; texture cache {} MiB budget, {} MiB uploads a frame, over the {textured_frames} frames drawing textures",
        PoolSettings::default().budget_bytes >> 20,
        PoolSettings::default().upload_bytes_per_frame >> 20
    );
    r.add(
        "buildings",
        "texture cache resident",
        resident as f64 / tf / 1024.0,
        "KiB",
        &tparams,
    );
    r.add(
        "buildings",
        "drawn textures at full resolution",
        full_bytes as f64 / tf / 1024.0,
        "KiB",
        &tparams,
    );
    r.add(
        "buildings",
        "texture bytes saved (full resolution / resident)",
        full_bytes as f64 / resident.max(1) as f64,
        "x",
        &tparams,
    );
    r.add(
        "buildings",
        "texture misses per frame (mean)",
        misses as f64 / tf,
        "textures",
        &tparams,
    );
    r.add(
        "buildings",
        "texture misses per frame (max)",
        max_misses as f64,
        "textures",
        &tparams,
    );
    r.add(
        "buildings",
        "textures coarser than needed per frame (mean)",
        coarser as f64 / tf,
        "textures",
        &tparams,
    );
}
