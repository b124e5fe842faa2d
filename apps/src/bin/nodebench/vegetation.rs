//! Section `vegetation`: the ranked Poisson tile against Bridson sampling, the vegetation phase
//! per node, instances and draw calls per frame, and the occlusion rows.

use crate::report::{Report, bar};
use crate::terrain::flight_nodes;
use engine::camera::Camera;
use engine::surface::World;
use engine::terrain::bounds::BoundsCache;
use engine::terrain::quadtree::{NodeKey, QuadTree};
use engine::terrain::select::{SelectParams, select};
use engine::vegetation::representation::group_dither;
use engine::vegetation::{self as veg, Placer};
use std::time::Instant;

pub(crate) fn section_vegetation(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
) {
    let placer = Placer::new(world);
    let walk = low_cameras(world, cams[0].viewport_px, 2, true);
    crate::switches::switch_rows(world, tree, &walk, r, quick);
    tile_against_bridson(world, r, quick, &placer);
    phase_per_node(world, tree, cams, r, quick, &placer);
    instances_per_frame(world, tree, cams, r, quick, &placer);
    occlusion(world, tree, cams, r, quick, &placer);
    occlusion_rendered(world, cams[0].viewport_px, r, quick);
}

/// Kept points per second of the ranked tile against Bridson sampling.
fn tile_against_bridson(world: &World, r: &mut Report, quick: bool, placer: &Placer) {
    // 1. Kept points per second, one core: the ranked tile (bare lookup, 16 m tiles, every tile
    // point kept) against Bridson sampling of the same area at the same minimum distance.
    let side_m = if quick { 128.0 } else { 512.0 };
    let reps: u32 = if quick { 2 } else { 8 };
    let o = world.origin_m();
    for s in 0..placer.species.len() {
        let sp = &placer.species[s];
        if sp.kind == veg::Kind::LargeTree {
            continue;
        }
        let params = format!(
            "{side_m} m square, min distance {} m, 1 core",
            sp.min_distance_m
        );
        let mut pts = Vec::new();
        let t0 = Instant::now();
        let mut kept = 0usize;
        for rep in 0..reps {
            let base = [o[0] + f64::from(rep) * side_m, o[1] + 1024.0];
            let mut y = 0.0;
            while y < side_m {
                let mut x = 0.0;
                while x < side_m {
                    let rect = engine::surface::world::Rect {
                        min: [base[0] + x, base[1] + y],
                        max: [base[0] + x + 16.0, base[1] + y + 16.0],
                    };
                    pts.clear();
                    placer.positions(s, rect, 1.0, &mut pts);
                    kept += pts.len();
                    x += 16.0;
                }
                y += 16.0;
            }
        }
        let tile_pps = kept as f64 / t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let mut bridson = 0usize;
        for rep in 0..reps {
            bridson += fast_poisson::Poisson2D::new()
                .with_dimensions([side_m, side_m], sp.min_distance_m)
                .with_seed(u64::from(rep) + 1)
                .iter()
                .count();
        }
        let bridson_pps = bridson as f64 / t0.elapsed().as_secs_f64();
        let name = &sp.name;
        r.add(
            "vegetation",
            &format!("{name}: ranked tile, kept points/s"),
            tile_pps,
            "points/s",
            &params,
        );
        r.add(
            "vegetation",
            &format!("{name}: Bridson (fast_poisson), points/s"),
            bridson_pps,
            "points/s",
            &params,
        );
        r.add(
            "vegetation",
            &format!("{name}: points per m², tile / Bridson"),
            kept as f64 / bridson.max(1) as f64,
            "ratio",
            &params,
        );
    }
}

/// Passes over the nodes in `phase_per_node`.
const PASSES: usize = 3;

/// The vegetation phase per node of the flight.
fn phase_per_node(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
    placer: &Placer,
) {
    // 2. The vegetation phase per node (placement, heights, exclusions, representation and
    // grouping), for the nodes a flight draws at tau 2.
    let keys = flight_nodes(
        world,
        tree,
        &cams[..cams.len().min(if quick { 2 } else { 16 })],
        if quick { 24 } else { 240 },
    );
    // Three passes over the nodes in turn: the first pass's times, and per node the median of
    // its three (a node comes back only after all the others, so its data has left the
    // core's caches; a pause of this virtual machine in one pass does not count).
    let b = bar((PASSES * keys.len()) as u64, "vegetation nodes");
    let mut times = vec![Vec::new(); PASSES];
    let mut instances = 0usize;
    for pass in &mut times {
        instances = 0;
        for &k in &keys {
            let t0 = Instant::now();
            let v = veg::node_vegetation(world, placer, tree, k);
            pass.push(t0.elapsed().as_secs_f64());
            instances += v.instances();
            b.inc(1);
        }
    }
    b.finish_and_clear();
    let medians = (0..keys.len())
        .map(|i| {
            let mut t: Vec<f64> = times.iter().map(|p| p[i]).collect();
            t.sort_by(f64::total_cmp);
            t[PASSES / 2]
        })
        .collect();
    let params = format!("{} nodes from the flight at tau 2", keys.len());
    r.timings(
        "vegetation",
        "node vegetation phase",
        times.swap_remove(0),
        &format!("{params}, first pass"),
    );
    r.timings(
        "vegetation",
        "node vegetation phase, median of 3 passes",
        medians,
        &format!("{params}: per node the median of {PASSES} passes over them all"),
    );
    r.add(
        "vegetation",
        "instances per node (mean)",
        instances as f64 / keys.len().max(1) as f64,
        "instances",
        &params,
    );
}

/// Instances and draw calls per frame of the flight.
fn instances_per_frame(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
    placer: &Placer,
) {
    // 3. Instances and draw calls per frame: every drawn node's groups plus its ancestors'
    // groups that are not replaced on split (each ancestor once).
    let mut cache = BoundsCache::new();
    let mut veg_cache: std::collections::HashMap<NodeKey, veg::NodeVegetation> =
        std::collections::HashMap::new();
    let frames = &cams[..cams.len().min(if quick { 2 } else { 32 })];
    let b = bar(frames.len() as u64, "vegetation frames");
    let (mut inst, mut draws, mut by_rep) = (Vec::new(), Vec::new(), [0usize; 3]);
    for cam in frames {
        let sel = select(
            world,
            tree,
            &mut cache,
            cam,
            SelectParams::culled(2.0, tree),
        );
        let mut ancestors: Vec<NodeKey> = Vec::new();
        let (mut n_inst, mut n_draw) = (0usize, 0usize);
        // Selected nodes are drawn; their ancestors draw what they keep (the renderer's rule).
        let mut count = |v: &veg::NodeVegetation, drawn: bool, by_rep: &mut [usize; 3]| {
            for g in &v.groups {
                if group_dither(g.replaced_on_split, drawn, !drawn).is_none() {
                    continue;
                }
                n_inst += g.items.len();
                n_draw += 1;
                by_rep[g.representation as usize] += g.items.len();
            }
        };
        for n in &sel.nodes {
            let v = veg_cache
                .entry(n.key)
                .or_insert_with(|| veg::node_vegetation(world, placer, tree, n.key));
            count(v, true, &mut by_rep);
            ancestors.extend(n.key.ancestors());
        }
        ancestors.sort();
        ancestors.dedup();
        for a in ancestors {
            let v = veg_cache
                .entry(a)
                .or_insert_with(|| veg::node_vegetation(world, placer, tree, a));
            count(v, false, &mut by_rep);
        }
        inst.push(n_inst as f64);
        draws.push(n_draw as f64);
        b.inc(1);
    }
    b.finish_and_clear();
    let params = format!(
        "tau 2 px, {} cameras of the flight, CPU count of what the selected nodes hold",
        frames.len()
    );
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            0.0
        } else {
            apps::percentile(&v, 0.5)
        }
    };
    r.add(
        "vegetation",
        "instances per frame (median)",
        median(inst),
        "instances",
        &params,
    );
    r.add(
        "vegetation",
        "instance draw calls per frame (median)",
        median(draws),
        "draws",
        &params,
    );
    let total = by_rep.iter().sum::<usize>().max(1) as f64;
    for (i, name) in ["meshes", "billboards", "group-billboard members"]
        .iter()
        .enumerate()
    {
        r.add(
            "vegetation",
            &format!("share of instances drawn as {name}"),
            100.0 * by_rep[i] as f64 / total,
            "%",
            &params,
        );
    }
}

/// `n` cameras of the low half of the automatic flyover (25 m above the valley floor), or with
/// `walk` of the same track at eye height (1.8 m above the ground).
fn low_cameras(world: &World, viewport_px: [u32; 2], n: u32, walk: bool) -> Vec<Camera> {
    (0..n)
        .map(|i| {
            let mut c =
                engine::flight::auto_flyover(world, 0.5 * f64::from(i) / f64::from(n), viewport_px);
            if walk {
                let p = c.position_m;
                c.position_m.z = world.height_m(p.x, p.y) + 1.8;
            }
            c
        })
        .collect()
}

/// Splitting less behind dense vegetation, on the low valley flight.
fn occlusion(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    r: &mut Report,
    quick: bool,
    placer: &Placer,
) {
    let mut cache = BoundsCache::new();
    // 4. Splitting less behind dense vegetation, on the low half of the automatic flyover
    // (25 m above the valley floor): nodes and triangles with and without, at tau 2.
    let canopy = veg::Canopy::new(world, placer);
    let vp = cams[0].viewport_px;
    let n_low: u32 = if quick { 4 } else { 48 };
    for walk in [false, true] {
        let low = low_cameras(world, vp, n_low, walk);
        let p = SelectParams::culled(2.0, tree);
        let (mut plain_nodes, mut occl_nodes, mut hidden, mut t_plain, mut t_occl) =
            (0usize, 0usize, 0usize, 0.0f64, 0.0f64);
        for cam in &low {
            // Bounds first, so the timings compare the traversals only.
            let _ = select(world, tree, &mut cache, cam, p);
            let _ = engine::terrain::select::select_occluded(
                world,
                tree,
                &mut cache,
                cam,
                p,
                Some(&canopy),
            );
            let t0 = Instant::now();
            let a = select(world, tree, &mut cache, cam, p);
            t_plain += t0.elapsed().as_secs_f64();
            let t0 = Instant::now();
            let b = engine::terrain::select::select_occluded(
                world,
                tree,
                &mut cache,
                cam,
                p,
                Some(&canopy),
            );
            t_occl += t0.elapsed().as_secs_f64();
            plain_nodes += a.nodes.len();
            occl_nodes += b.nodes.len();
            for n in &b.nodes {
                if n.error_px > p.tau_px && n.key.level < tree.max_level {
                    hidden += 1;
                }
            }
        }
        let per = |v: usize| v as f64 / low.len() as f64;
        let params = format!(
            "tau 2 px, {} cameras of the low valley flight (auto_flyover t < 0.5){}",
            low.len(),
            if walk {
                ", at 1.8 m eye height"
            } else {
                ", 25 m above the ground"
            }
        );
        r.add(
            "vegetation",
            "occlusion: nodes per frame without",
            per(plain_nodes),
            "nodes",
            &params,
        );
        r.add(
            "vegetation",
            "occlusion: nodes per frame with",
            per(occl_nodes),
            "nodes",
            &params,
        );
        r.add(
            "vegetation",
            "occlusion: terrain triangles saved",
            100.0 * (1.0 - occl_nodes as f64 / plain_nodes.max(1) as f64),
            "%",
            &params,
        );
        r.add(
            "vegetation",
            "occlusion: nodes over tau left unsplit because hidden (per frame)",
            per(hidden),
            "nodes",
            &params,
        );
        r.add(
            "vegetation",
            "occlusion: selection time with / without",
            t_occl / t_plain.max(1e-12),
            "ratio",
            &format!(
                "{params}; without {:.1} µs per frame",
                1e6 * t_plain / low.len() as f64
            ),
        );
    }
}

/// Whether splitting less behind dense vegetation shows: at eye height on the low valley flight,
/// each view settled with the rule off and on, drawn (terrain and vegetation) on the GPU, and the
/// drawn terrain's on-screen error measured over the samples the frame's depth shows
/// ([`engine::shown_error`]). Left out without a GPU adapter.
fn occlusion_rendered(world: &World, viewport_px: [u32; 2], r: &mut Report, quick: bool) {
    use engine::render::{COLOR_FORMAT, Target};
    use engine::shown_error::{ShownError, check_viewer, settled_view_error};
    let Some((g, adapter)) = crate::gpu::adapter() else {
        eprintln!("no GPU adapter: the rendered occlusion rows left out");
        return;
    };
    let n: u32 = if quick { 1 } else { 6 };
    // Spread over the low flight's first half, like the selection rows' 48 cameras.
    let cams = low_cameras(world, viewport_px, n, true);
    let target = Target::new(&g.device, viewport_px, COLOR_FORMAT);
    for tau_px in [2.0, 0.5] {
        let mut runs: Vec<Vec<ShownError>> = Vec::new();
        for occlusion in [false, true] {
            let mut v = check_viewer(&g, world, tau_px, 2, occlusion);
            let mut views = Vec::new();
            let b = bar(
                cams.len() as u64,
                &format!(
                    "occlusion drawn, tau {tau_px}, rule {}",
                    if occlusion { "on" } else { "off" }
                ),
            );
            for (i, cam) in cams.iter().enumerate() {
                match settled_view_error(&g, &mut v, &target, cam, 600.0) {
                    Ok(e) => views.push(e),
                    Err(e) => b.println(format!("occlusion rendered: camera {i}: {e}")),
                }
                b.inc(1);
            }
            b.finish_and_clear();
            runs.push(views);
        }
        let (off, on) = (&runs[0], &runs[1]);
        if off.is_empty() || on.is_empty() {
            continue;
        }
        let params = format!(
            "tau {tau_px} px, {} of {} cameras of the low valley flight at 1.8 m eye height \
             settled, drawn on {adapter} (terrain and vegetation) and measured over the drawn \
             meshes' samples ({} per quad) where the frame's depth shows them",
            on.len().min(off.len()),
            cams.len(),
            engine::shown_error::SAMPLES_PER_QUAD,
        );
        let per = |v: &[ShownError], f: fn(&ShownError) -> f64| {
            v.iter().map(f).sum::<f64>() / v.len() as f64
        };
        let most =
            |v: &[ShownError], f: fn(&ShownError) -> f64| v.iter().map(f).fold(0.0, f64::max);
        let tris = |e: &ShownError| e.triangles as f64;
        for (name, v) in [("without", off), ("with", on)] {
            r.add(
                "vegetation",
                &format!("occlusion, rendered: terrain triangles per frame {name} the rule"),
                per(v, tris),
                "triangles",
                &params,
            );
            r.add(
                "vegetation",
                &format!("occlusion, rendered: on-screen max error shown, {name} the rule"),
                most(v, |e| e.shown.max_px),
                "px",
                &params,
            );
            r.add(
                "vegetation",
                &format!(
                    "occlusion, rendered: on-screen max error over every drawn sample, hidden \
                     too, {name} the rule"
                ),
                most(v, |e| e.all.max_px),
                "px",
                &params,
            );
        }
        r.add(
            "vegetation",
            "occlusion, rendered: terrain triangles saved",
            100.0 * (1.0 - per(on, tris) / per(off, tris).max(1.0)),
            "%",
            &params,
        );
        r.add(
            "vegetation",
            "occlusion, rendered: drawn samples on the screen hidden, with the rule",
            100.0
                * per(on, |e| {
                    e.hidden_samples as f64 / (e.hidden_samples + e.shown.samples).max(1) as f64
                }),
            "%",
            &params,
        );
    }
}
